#!/usr/bin/env python
"""Validate ``method="auto"``: does the method it picks meet ``tol`` against the DEM, and is it the fastest that does?

Usage::

    python benchmarks/auto_method.py --quick     # 400 particles, 8 cases x 2 tolerances
    python benchmarks/auto_method.py             # 1200 particles, 14 cases x 2 tolerances

Cases, modelled on ``stability.py``, ``pareto.py`` and ``methods.py`` (uniaxial compression between clamped layers
unless said otherwise; bond nu 0.25):

* ``bonds 0.2 %`` / ``bonds 2 %``: the dense stability box (bonds at contacts, E_b = 1e9 Pa), bonds only.
* ``contacts E_b=...``: the same box with Hertz-Mindlin contacts superimposed on the bonds (particle E = 1e10 Pa,
  friction 0.5), strain 0.5 %, the bond modulus E_b varied as in ``stability.py`` so that the contacts carry from a
  few per cent to almost all of the stiffness.
* ``pareto hertz 1 %``: ``pareto.py``'s contact case (packing fraction 0.55, particle E 1e10 Pa, strain 1 %).
* ``case 1 porous 2 %``: ``methods.py``'s bond-dominated porous cylinder (packing 0.45, bond gap 0.6, particle E 1e9
  Pa) with contacts, strain 2 %.
* ``walls bonds 0.2 %``: the stability box, bonds only, between frictionless walls.
* full run only: E_b = 1e7, 3e8, 3e9 Pa, ``case 2 agglomerate`` (1:4 at 40 %, soft bonds against stiff particles),
  ``case 3 shaped`` (pores, contacts of bonded pairs replaced by the bonds), ``walls contacts 0.5 %``.

Per case every candidate runs once to compile and once to time (the DEM once): STE, linear DSM on the bonds alone
(``stiffness_tol=1e-2``, as auto runs it for tol >= 0.01), linear DSM with the contacts linearised, nonlinear DSM,
DEM (the reference: errors are |K / K_DEM - 1|). The time of a method is its second call's wall time less
compilation. Then, per tolerance (0.01 and 0.05), ``jaxbpm.solve(..., method="auto", tol=tol)``: its choice, its
error against the DEM, its wall time (probe included; the programs are compiled by then), whether it met ``tol`` and
whether its method is the fastest that did (``fastest``: the fastest candidate meeting tol, run time within 25 %,
which absorbs the timing noise of the small samples; ``fastest strict``: the very same method).

JSON to ``results/auto_method.json`` (``--quick``: ``results/auto_method_quick.json``).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
import warnings

from _common import enable_x64, machine_info, pin_threads, table, write_json

TOLS = (0.01, 0.05)
PARTICLE = {"E": 1e10, "nu": 0.25, "density": 2500.0, "friction": 0.5, "restitution": 0.5}
ROUTES = ("ste", "dsm_bonds", "dsm_bonds_corrected", "dsm_linearised", "dsm_nonlinear", "dem")
NOISE = 1.25


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def fmt_err(exc) -> str:
    return f"{type(exc).__name__}: {str(exc).splitlines()[0][:200]}"


# ------------------------------------------------------------------------------------------------------ cases
def build_cases(args):
    """``[(name, sample, scene, params)]``."""
    import numpy as np

    import jaxbpm
    from jaxbpm.scenes import UniaxialCompression as UC

    def eb(E):
        return {"bond_E": np.array([float(E)]), "bond_nu": np.array([0.25])}

    box = jaxbpm.generate.box(args.n, seed=args.seed, materials={"E": 1e9, "nu": 0.25},
                              particle_material=PARTICLE).largest_cluster()
    cases = [("bonds 0.2 %", box, UC(strain=0.002), None), ("bonds 2 %", box, UC(strain=0.02), None)]
    shares = (1e10, 1e9, 1e8) if args.quick else (1e10, 3e9, 1e9, 3e8, 1e8, 1e7)
    cases += [(f"contacts E_b={E:.0e}", box, UC(strain=0.005, contacts=True), eb(E)) for E in shares]
    hertz = jaxbpm.generate.box(args.n, seed=args.seed, packing_fraction=0.55, materials={"E": 1e9, "nu": 0.25},
                                particle_material=PARTICLE, bond_contact="superimpose").largest_cluster()
    cases.append(("pareto hertz 1 %", hertz, UC(strain=0.01, contacts=True), None))
    porous = jaxbpm.generate.cylinder(args.n, seed=args.seed, packing_fraction=0.45, bond_gap=0.6,
                                      materials={"E": 1e9, "nu": 0.25},
                                      particle_material={**PARTICLE, "E": 1e9, "density": 1000.0}).largest_cluster()
    cases.append(("case 1 porous 2 %", porous, UC(strain=0.02, contacts=True), None))
    cases.append(("walls bonds 0.2 %", box, UC(strain=0.002, boundary="walls"), None))
    if not args.quick:
        agg = jaxbpm.generate.box(args.n, seed=args.seed, materials={"E": [1e8, 4e8], "nu": 0.25},
                                  particle_material=PARTICLE)
        agg = jaxbpm.generate.mix_materials(agg, [0.6, 0.4], seed=args.seed).largest_cluster()
        cases.append(("case 2 agglomerate 2 %", agg, UC(strain=0.02, contacts=True), None))
        shaped = jaxbpm.generate.box(args.n, seed=args.seed, materials={"E": 1e9, "nu": 0.25}, bond_contact="replace",
                                     particle_material={**PARTICLE, "E": 1e9})
        pos = np.asarray(shaped.positions)
        lo, hi = pos.min(axis=0), pos.max(axis=0)
        cell = (hi - lo) / 2.0
        keep = np.ones(shaped.n_particles, bool)
        for i in range(2):
            for j in range(2):
                for k in range(2):
                    keep &= np.linalg.norm(pos - (lo + cell * (np.array([i, j, k]) + 0.5)), axis=1) > 0.4 * cell.min()
        cases.append(("case 3 shaped 2 %", shaped.subset(keep).largest_cluster(), UC(strain=0.02, contacts=True),
                      None))
        cases.append(("walls contacts 0.5 %", box, UC(strain=0.005, contacts=True, boundary="walls"), None))
    return cases


def candidates(scene):
    """``{route: (scene, method, options)}`` as auto would run each route (tol >= 0.01)."""
    from jaxbpm import auto

    lin = {"nonlinear": False, **auto._linear_options(0.01)}
    out = {"ste": (scene, "ste", {}), "dem": (scene, "dem", {}), "dsm_nonlinear": (scene, "dsm", {"nonlinear": True})}
    if not scene.uses_walls:
        out["dsm_bonds"] = (dataclasses.replace(scene, contacts=False), "dsm", lin)
        out["dsm_bonds_corrected"] = (dataclasses.replace(scene, contacts=False), "dsm",
                                      {**lin, "geometric_correction": True})
        if scene.contacts:
            out["dsm_linearised"] = (scene, "dsm", lin)
    return out


def run_method(sample, scene, method, params, opts, calls):
    import jaxbpm

    t = time.perf_counter()
    try:
        for _ in range(calls):
            r = jaxbpm.solve(sample, scene, method, params=params, **({} if method == "dem" else {"throw": False}),
                             **opts)
    except Exception as exc:  # recorded, not fatal
        return {"error": fmt_err(exc), "wall_s": time.perf_counter() - t}
    return {"K": float(r.stiffness), "time_s": float(r.wall_time - r.compile_time), "status": r.status,
            "compile_s": float(r.compile_time)}


def run_case(name, sample, scene, params):
    import jaxbpm

    log(f"== {name}: {sample.n_particles} particles, {sample.n_bonds} bonds")
    runs = {}
    for route, (sc, method, opts) in candidates(scene).items():
        runs[route] = run_method(sample, sc, method, params, opts, 1 if method == "dem" else 2)
        rec = runs[route]
        log(f"   {route:15s} " + (f"K={rec['K']:.6g} {rec['time_s']:.4f} s ({rec['status']})" if "K" in rec
                                  else f"FAILED {rec['error']}"))
    ref = runs["dem"].get("K")
    if ref is None:
        return {"case": name, "error": f"DEM failed: {runs['dem']['error']}", "runs": runs}
    for rec in runs.values():
        if "K" in rec:
            rec["error"] = abs(rec["K"] / ref - 1.0) if rec["status"] == "converged" else None
    share = None
    if "dsm_bonds" in runs and "dsm_linearised" in runs and "K" in runs["dsm_bonds"] and "K" in runs.get(
            "dsm_linearised", {}):
        share = 1.0 - runs["dsm_bonds"]["K"] / runs["dsm_linearised"]["K"]
    rows = []
    for tol in TOLS:
        t = time.perf_counter()
        try:
            r = jaxbpm.solve(sample, scene, "auto", tol=tol, params=params, throw=False)
        except Exception as exc:
            rows.append({"case": name, "tol": tol, "error_message": fmt_err(exc)})
            log(f"   auto tol {tol}: FAILED {fmt_err(exc)}")
            continue
        wall = time.perf_counter() - t
        choice = r.stats["method_choice"]
        err = abs(r.stiffness / ref - 1.0)
        meeting = {k: v["time_s"] for k, v in runs.items() if v.get("error") is not None and v["error"] <= tol}
        fastest = min(meeting, key=meeting.get)
        route = choice["route"]
        chosen_time = runs.get(route, {}).get("time_s")
        met = err <= tol
        row = {"case": name, "tol": tol, "contact_share": choice["contact_share"], "choice": route,
               "auto_error": err, "auto_wall_s": wall, "probe_s": choice["probe_time"], "met": met,
               "fastest_meeting": fastest, "fastest_strict": route == fastest,
               "fastest": bool(met and chosen_time is not None and chosen_time <= NOISE * meeting[fastest]),
               "why": choice["why"], "expected_error": choice["expected_error"]}
        rows.append(row)
        log(f"   auto tol {tol}: {route} err {100 * err:.3g} % ({'met' if met else 'MISSED'}), fastest meeting "
            f"{fastest}; {choice['why']}")
    return {"case": name, "particles": sample.n_particles, "bonds": sample.n_bonds, "scene": repr(scene),
            "bond_E": None if params is None else float(params["bond_E"][0]), "contact_share_linear": share,
            "runs": runs, "rows": rows}


def pct(v):
    return "n/a" if v is None else f"{100 * v:.3g}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=1200, help="particles per sample (before largest_cluster)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=None, help="restrict to this many cores")
    ap.add_argument("--quick", action="store_true", help="400 particles, 8 cases")
    ap.add_argument("--out", default="results/auto_method.json")
    args = ap.parse_args(argv)
    if args.quick:
        args.n = min(args.n, 400)
        if args.out == "results/auto_method.json":
            args.out = "results/auto_method_quick.json"
    pin_threads(args.threads)
    enable_x64()
    t0 = time.perf_counter()
    cases = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (the DSM's contact-reach notes; the results keep the statuses)
        for name, sample, scene, params in build_cases(args):
            cases.append(run_case(name, sample, scene, params))
            write_json(args.out, {"benchmark": "auto_method", "partial": True, "cases": cases})
    rows = [r for c in cases for r in c.get("rows", []) if "error_message" not in r]
    table_rows = []
    for c in cases:
        for r in c.get("rows", []):
            if "error_message" in r:
                table_rows.append({"case": r["case"], "tol": r["tol"], "choice": "FAILED"})
                continue
            runs = c["runs"]
            table_rows.append({"case": r["case"], "tol": r["tol"], "share %": pct(r["contact_share"]),
                               "choice": r["choice"], "err %": pct(r["auto_error"]), "met": "yes" if r["met"] else "NO",
                               "fastest meeting": r["fastest_meeting"],
                               "fastest": "yes" if r["fastest"] else "no",
                               **{f"{k} err %": pct(runs[k].get("error")) if k in runs else "-" for k in ROUTES[:-1]},
                               **{f"{k} s": runs[k]["time_s"] if "time_s" in runs.get(k, {}) else "-" for k in ROUTES},
                               "auto s": r["auto_wall_s"]})
    print("\nmethod='auto' against every method (errors |K / K_DEM - 1| in %, times: wall less compilation)")
    if table_rows:
        table(table_rows, list(max(table_rows, key=len)))
    n = len(rows) + sum(1 for c in cases for r in c.get("rows", []) if "error_message" in r)
    met = sum(r["met"] for r in rows)
    fastest = sum(r["fastest"] for r in rows)
    strict = sum(r["fastest_strict"] and r["met"] for r in rows)
    summary = {"decisions": n, "met_tol": met, "met_tol_fraction": met / n if n else None, "fastest": fastest,
               "fastest_fraction": fastest / n if n else None, "fastest_strict": strict,
               "fastest_strict_fraction": strict / n if n else None,
               "missed": [{"case": r["case"], "tol": r["tol"], "choice": r["choice"], "error": r["auto_error"]}
                          for r in rows if not r["met"]],
               "not_fastest": [{"case": r["case"], "tol": r["tol"], "choice": r["choice"],
                                "fastest_meeting": r["fastest_meeting"]} for r in rows if not r["fastest"]]}
    print(f"\nmet tol: {met}/{n} ({100 * met / max(n, 1):.0f} %, target >= 95 %); fastest that met it: {fastest}/{n} "
          f"({100 * fastest / max(n, 1):.0f} %, within {NOISE:g}x of the fastest; strict {strict}/{n}; target >= 80 %)")
    for m in summary["missed"]:
        print(f"  missed: {m['case']} tol {m['tol']}: {m['choice']} {100 * m['error']:.3g} %")
    for m in summary["not_fastest"]:
        print(f"  not the fastest: {m['case']} tol {m['tol']}: {m['choice']} (fastest meeting: {m['fastest_meeting']})")
    total = time.perf_counter() - t0
    print(f"total {total:.0f} s")
    write_json(args.out, {"benchmark": "auto_method", "machine": machine_info(), "settings": vars(args),
                          "total_time_s": total, "summary": summary, "cases": cases, "table": table_rows})
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
