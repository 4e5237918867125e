"""The stop after the peak: DEM runs to failure with ``stop_after_peak=0.7`` against the full strain (``None``).

For UCS (a bonded cylinder of aspect 2), the Brazilian disc (aspect 0.5) and three-point bending (a beam), each of
``--n`` particles with finite bond strengths (the lab workflow's true parameters: E = 1 GPa, nu = 0.2, sigma_c =
4 MPa, tau_c = 8 MPa; Hertz-Mindlin contacts, breakage), the script runs each scene once to compile, then with the
stop and without (same process, one after the other, ``--repeat`` pairs, the best time of each), and reports the
steps, the wall and kernel times, the peak force, the strain at the peak and at the stop, and whether the peak, the
stiffness and the curve up to the stop are the full run's. A second part runs a batch (``solve_batch``, ``lax.map``)
of bonds-only UCS members with different strengths with the stop, against their single runs: each member stops on
its own at its own peak.

    python benchmarks/peak_stop.py [--n 1500] [--transits 30] [--fraction 0.7] [--repeat 2] [--quick]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(__file__))
from _common import enable_x64, machine_info, table, write_json  # noqa: E402

TRUE = {"E": 1e9, "nu": 0.2, "tensile_strength": 4e6, "shear_strength": 8e6}


def _run(jaxbpm, sample, scene, transits):
    t = time.perf_counter()
    res = jaxbpm.solve(sample, scene, "dem", transits=transits, max_records=10**8)  # every record: curves compared
    return res, time.perf_counter() - t


def _scenes(args):
    import dataclasses

    import numpy as np

    import jaxbpm
    from jaxbpm.scenes import BrazilianDisc, ThreePointBending, UniaxialCompression

    samples = {"ucs": jaxbpm.generate.cylinder(args.n, seed=0, materials=TRUE).largest_cluster(),
               "bts": jaxbpm.generate.cylinder(args.n, seed=1, aspect=0.5, materials=TRUE).largest_cluster(),
               "flexural": jaxbpm.generate.beam(args.n, seed=2, materials=TRUE).largest_cluster()}
    scenes = {"ucs": UniaxialCompression.to_failure(strain=0.02), "bts": BrazilianDisc(),
              "flexural": ThreePointBending(strain=0.1)}
    rows = []
    for key, sample in samples.items():
        stop = dataclasses.replace(scenes[key], stop_after_peak=args.fraction)
        full = dataclasses.replace(scenes[key], stop_after_peak=None)
        _, first = _run(jaxbpm, sample, stop, args.transits)  # compiles
        best = {"stop": (None, float("inf")), "full": (None, float("inf"))}
        for _ in range(args.repeat):  # alternately, the best of each (a shared machine)
            for name, scene in (("stop", stop), ("full", full)):
                res, t = _run(jaxbpm, sample, scene, args.transits)
                best[name] = min(best[name], (res, t), key=lambda rt: rt[1])
        (a, t_stop), (b, t_full) = best["stop"], best["full"]
        n = len(a.force)
        row = {"scene": key, "particles": sample.n_particles, "bonds": sample.n_bonds,
               "steps_stop": a.stats["steps"], "steps_full": b.stats["steps"],
               "steps_ratio": a.stats["steps"] / b.stats["steps"], "wall_stop_s": t_stop, "wall_full_s": t_full,
               "wall_ratio": t_stop / t_full, "first_solve_s": first,
               "kernel_stop_s": a.stats["kernel_time"], "kernel_full_s": b.stats["kernel_time"],
               "setup_stop_s": a.setup_time, "setup_full_s": b.setup_time, "stop_reason": a.stats["stop_reason"],
               "peak_stop": a.stats["peak_force"], "peak_full": b.stats["peak_force"],
               "strength_stop": a.stats["strength"], "strength_full": b.stats["strength"],
               "strain_at_peak": a.stats["strain_at_peak"], "stop_strain": float(a.displacement[-1]) / a.gauge_length,
               "target_strain": scenes[key].strain, "stiffness_stop": a.stiffness, "stiffness_full": b.stiffness,
               "same_peak": a.stats["peak_force"] == b.stats["peak_force"],
               "same_stiffness": a.stiffness == b.stiffness,
               "force_end_over_peak": float(a.force[-1] / a.stats["peak_force"]),
               "full_end_over_peak": float(b.force[-1] / b.stats["peak_force"]),
               "curve_equal_to_stop": bool(np.array_equal(a.force, b.force[:n]))}
        rows.append(row)
        print(f"{key}: stop {row['steps_stop']} / {row['steps_full']} steps, {t_stop:.2f} / {t_full:.2f} s, peak "
              f"{row['peak_stop']:.6g} / {row['peak_full']:.6g} N, same {row['same_peak']}", flush=True)
    return rows


def _batch(args):
    import numpy as np

    import jaxbpm
    from jaxbpm.dem.batched import solve_batch
    from jaxbpm.physics.model import default_params
    from jaxbpm.scenes import UniaxialCompression

    sample = jaxbpm.generate.cylinder(args.batch_n, seed=0, materials=TRUE).largest_cluster()
    p0 = default_params(sample)
    members = [dict(p0, bond_tensile_strength=np.array([s]), bond_shear_strength=np.array([2 * s]))
               for s in np.linspace(3e6, 6e6, args.batch)]
    scene = UniaxialCompression.to_failure(strain=0.03, contacts=False, stop_after_peak=args.fraction)
    solve_batch(sample, scene, members, transits=args.transits)  # compiles
    t = time.perf_counter()
    out = solve_batch(sample, scene, members, transits=args.transits)
    t_batch = time.perf_counter() - t
    rows = []
    for p, r in zip(members, out):
        b = r.stats["batch"]
        single = jaxbpm.solve(sample, scene, "dem", params=p, dt=b["dt"], loading_time=b["loading_time"],
                              chunk=b["chunk"])
        rows.append({"tensile_strength": float(p["bond_tensile_strength"][0]), "steps": r.stats["steps"],
                     "steps_single": single.stats["steps"], "stop_reason": r.stats["stop_reason"],
                     "peak": r.stats["peak_force"], "peak_single": single.stats["peak_force"],
                     "same": bool(r.stats["peak_force"] == single.stats["peak_force"]
                                  and r.stats["steps"] == single.stats["steps"])})
    print(f"batch of {len(members)} ({sample.n_particles} particles, bonds only): {t_batch:.2f} s", flush=True)
    return {"particles": sample.n_particles, "members": rows, "wall_s": t_batch,
            "steps_planned": out[0].stats.get("steps_planned", out[0].stats["steps"])}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1500, help="particles per specimen")
    ap.add_argument("--transits", type=float, default=30.0)
    ap.add_argument("--fraction", type=float, default=0.7, help="stop_after_peak")
    ap.add_argument("--repeat", type=int, default=2, help="timed pairs per scene (the best of each is reported)")
    ap.add_argument("--batch", type=int, default=4, help="members of the batch part (0: none)")
    ap.add_argument("--batch-n", type=int, default=500, help="particles of the batch part's sample")
    ap.add_argument("--quick", action="store_true", help="500 particles, batch of 3 on 300")
    ap.add_argument("--out", default="results/peak_stop.json")
    args = ap.parse_args(argv)
    if args.quick:
        args.n, args.batch, args.batch_n = 500, 3, 300
    enable_x64()
    rows = _scenes(args)
    table(rows, ["scene", "particles", "steps_stop", "steps_full", "steps_ratio", "wall_stop_s", "wall_full_s",
                 "wall_ratio", "kernel_stop_s", "kernel_full_s", "peak_stop", "peak_full", "same_peak",
                 "same_stiffness", "curve_equal_to_stop", "strain_at_peak",
                 "stop_strain"])
    batch = _batch(args) if args.batch else None
    if batch:
        table(batch["members"], ["tensile_strength", "steps", "steps_single", "stop_reason", "peak", "peak_single",
                                 "same"])
    write_json(args.out, {"benchmark": "peak_stop", "machine": machine_info(), "n": args.n,
                          "transits": args.transits, "fraction": args.fraction, "scenes": rows, "batch": batch})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
