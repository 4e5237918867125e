"""The static failure solver (sequentially linear analysis, :func:`jaxbpm.dsm.failure_solve`) against the DEM's
failure runs: peak force, strength and wall time on the Brazilian disc, three-point bending and UCS.

The specimens and bond parameters of ``benchmarks/lab_strengths.py`` (E = 1 GPa, nu = 0.2, sigma_c = 4 MPa, tau_c =
8 MPa; a disc of aspect 0.5, a beam, a cylinder of aspect 2), the scenes' default settings (contacts on, the
separate failure rule). The DEM runs from rest over each ``--transits`` (its default loading time is 30 elastic-wave
transits; slower loading shows how far its peak is from the quasi-static one). Prints a table and saves JSON.

    python benchmarks/static_failure.py [--n 2000] [--cases bts,flexural,ucs] [--transits 30,300] [--max-events 600]
        [--tol 1e-6] [--group-tol 0]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(__file__))
from _common import enable_x64, machine_info, peak_rss_gib, pin_threads, write_json  # noqa: E402

TRUE = {"E": 1e9, "nu": 0.2, "tensile_strength": 4e6, "shear_strength": 8e6}


def specimen(key: str, n: int):
    """The sample and the DEM's failure scene of a case (those of ``benchmarks/lab_strengths.py``)."""
    import jaxbpm
    from jaxbpm.scenes import BrazilianDisc, ThreePointBending, UniaxialCompression

    if key == "bts":
        return jaxbpm.generate.cylinder(n, seed=1, aspect=0.5, materials=TRUE).largest_cluster(), BrazilianDisc()
    if key == "flexural":
        return jaxbpm.generate.beam(n, seed=2, materials=TRUE).largest_cluster(), ThreePointBending(strain=0.1)
    if key == "ucs":
        return (jaxbpm.generate.cylinder(n, seed=0, materials=TRUE).largest_cluster(),
                UniaxialCompression.to_failure(strain=0.02))
    raise SystemExit(f"unknown case {key!r}: use bts, flexural or ucs")


def run_case(key: str, n: int, transits, options) -> dict:
    """The static solve and the DEM runs of one case."""
    import numpy as np

    import jaxbpm
    from jaxbpm.dsm import failure_solve

    t0 = time.perf_counter()
    sample, scene = specimen(key, n)
    out = {"particles": sample.n_particles, "bonds": sample.n_bonds, "generate_s": time.perf_counter() - t0}
    sla = failure_solve(sample, scene, None, options)
    cg = sla.cg_iterations
    to_peak = sla.kernel_time * float(cg[:sla.peak_event + 1].sum()) / max(float(cg.sum()), 1.0)
    out["static"] = {"peak": sla.peak_force, "strength": sla.strength, "peak_displacement": sla.peak_displacement,
                     "events": sla.events, "peak_event": sla.peak_event, "status": sla.status,
                     "bonds_broken_to_peak": sla.stats["bonds_broken_to_peak"], "stiffness": sla.stiffness,
                     "wall_s": sla.wall_time, "setup_s": sla.setup_time, "compile_s": sla.compile_time,
                     "kernel_s": sla.kernel_time, "cg_iterations": sla.stats["cg_iterations"],
                     "kernel_to_peak_s": to_peak,
                     "closed_at_end": int(sla.closed[-1]), "force": sla.force.tolist(),
                     "displacement": sla.displacement.tolist()}
    print(f"{key}: {sample.n_particles} particles, {sample.n_bonds} bonds; static: peak {sla.peak_force:.4g} N "
          f"({sla.events} events, peak at {sla.peak_event}, {sla.status}) in {sla.wall_time:.1f} s (compile "
          f"{sla.compile_time:.1f} s, kernel {sla.kernel_time:.1f} s, of which to the peak ~{to_peak:.1f} s by CG "
          "iterations)", flush=True)
    out["dem"] = {}
    for tr in transits:
        dem = jaxbpm.solve(sample, scene, "dem", transits=tr)
        f = np.asarray(dem.force)
        k = int(np.argmax(f))
        broken = np.asarray(dem.stats["broken_curve"]).sum(axis=1)
        gap = sla.peak_force / float(f[k]) - 1.0
        out["dem"][str(tr)] = {"peak": float(f[k]), "strength": float(dem.stats["strength"]),
                               "peak_displacement": float(dem.displacement[k]), "bonds_broken_to_peak": int(broken[k]),
                               "stiffness": float(dem.stiffness), "wall_s": dem.wall_time,
                               "compile_s": dem.compile_time, "static_gap": gap,
                               "static_wall_ratio": sla.wall_time / dem.wall_time}
        print(f"  DEM over {tr:g} transits: peak {f[k]:.4g} N in {dem.wall_time:.1f} s (compile "
              f"{dem.compile_time:.1f} s); static - DEM {100 * gap:+.2f} %, static wall / DEM wall "
              f"{sla.wall_time / dem.wall_time:.2f}", flush=True)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=2000, help="particles per specimen")
    ap.add_argument("--cases", default="bts,flexural,ucs")
    ap.add_argument("--transits", default="30,300", help="the DEM's loading times, comma-separated ('' : none)")
    ap.add_argument("--group-tol", type=float, default=0.0, help="StaticFailure.group_tol")
    ap.add_argument("--no-contacts", action="store_true", help="broken bonds never close (StaticFailure.contacts)")
    ap.add_argument("--max-events", type=int, default=600, help="StaticFailure.max_events")
    ap.add_argument("--tol", type=float, default=1e-6, help="StaticFailure.tol (the CG's relative residual)")
    ap.add_argument("--threads", type=int, default=None, help="pin to this many cores")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    pin_threads(args.threads)
    enable_x64()
    from jaxbpm.dsm import StaticFailure

    options = StaticFailure(group_tol=args.group_tol, contacts=not args.no_contacts, max_events=args.max_events,
                            tol=args.tol)
    transits = [float(t) for t in args.transits.split(",") if t.strip()]
    out = args.out or f"results/static_failure_{args.n}.json"
    cases = {}
    for key in args.cases.split(","):  # saved after each case
        cases[key] = run_case(key, args.n, transits, options)
        write_json(out, {"benchmark": "static_failure", "machine": machine_info(), "n": args.n, "cases": cases,
                         "options": {"group_tol": args.group_tol, "contacts": not args.no_contacts,
                                     "max_events": args.max_events, "tol": args.tol},
                         "transits": transits, "peak_rss_gib": peak_rss_gib()})
    print(f"\n{'case':9s} {'static N':>9s} {'events':>7s} {'static s':>9s} " + " ".join(
        f"{'DEM' + format(t, 'g') + ' N':>10s} {'gap %':>7s} {'DEM s':>7s}" for t in transits))
    for key, c in cases.items():
        s = c["static"]
        row = f"{key:9s} {s['peak']:9.4g} {s['events']:7d} {s['wall_s']:9.1f} "
        row += " ".join(f"{d['peak']:10.4g} {100 * d['static_gap']:+7.2f} {d['wall_s']:7.1f}"
                        for d in c["dem"].values())
        print(row)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
