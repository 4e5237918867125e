"""Calibrate the bond tensile and shear strengths (sigma_c, tau_c) to a target UCS and flexural strength (Qu et al.).

Specimens: a bonded cylinder (``--ucs-n`` particles) compressed to failure for the UCS and a bonded beam (``--tpb-n``
particles) in three-point bending for the flexural strength, both with breakable bonds (DEM). The targets are the
strengths the same DEM gives for known strengths (``--sigma``, ``--tau``; sigma_c / tau_c = 0.5 by default, inside
the range where Qu et al. 2020 allows its simplified scheme). Both schemes of Qu et al. 2020 (original: 3 parameter
sets per
iteration; simplified: 1) start from the first and second estimates (Eq. 14-15) and stop when both strengths are
within ``--tol``. A parameter set is one UCS run plus one bending run, as Qu et al. 2020 counts "models".
Goal: both strengths within 5 % in no more models than Qu et al.'s Table 6 (19 original, 4 simplified).

    python benchmarks/strength_calibration.py [--ucs-n 250] [--tpb-n 300]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(__file__))
from _common import enable_x64, machine_info, table, write_json  # noqa: E402

QU2020_MODELS = {"original": 19, "simplified": 4}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ucs-n", type=int, default=250, dest="ucs_n")
    ap.add_argument("--tpb-n", type=int, default=300, dest="tpb_n")
    ap.add_argument("--sigma", type=float, default=4e6, help="true bond tensile strength [Pa]")
    ap.add_argument("--tau", type=float, default=8e6, help="true bond shear strength [Pa]")
    ap.add_argument("--tol", type=float, default=0.05)
    ap.add_argument("--learning-rate", type=float, default=0.2, dest="learning_rate")
    ap.add_argument("--fd-step", type=float, default=0.2, dest="fd_step")
    ap.add_argument("--transits", type=float, default=30.0)
    ap.add_argument("--schemes", default="simplified,original")
    ap.add_argument("--quick", action="store_true", help="the simplified scheme only (the full run takes ~2 min)")
    ap.add_argument("--out", default="results/strength_calibration.json")
    args = ap.parse_args(argv)
    if args.quick:
        args.schemes = "simplified"
        if args.out == "results/strength_calibration.json":
            args.out = "results/strength_calibration_quick.json"
    enable_x64()
    import numpy as np

    import jaxbpm
    from jaxbpm import calibrate as cal
    from jaxbpm.physics.model import default_params
    from jaxbpm.scenes import ThreePointBending, UniaxialCompression

    t_all = time.perf_counter()
    mats = {"E": 1e9, "nu": 0.25, "tensile_strength": args.sigma, "shear_strength": args.tau}
    cyl = jaxbpm.generate.cylinder(args.ucs_n, seed=0, materials=mats).largest_cluster()
    beam = jaxbpm.generate.beam(args.tpb_n, seed=1, packing_fraction=0.52, materials=mats).largest_cluster()
    ucs_scene, tpb_scene = UniaxialCompression.to_failure(strain=0.02), ThreePointBending(strain=0.1)
    print(f"cylinder {cyl.n_particles} particles / {cyl.n_bonds} bonds, beam {beam.n_particles} particles / "
          f"{beam.n_bonds} bonds", flush=True)
    t0 = time.perf_counter()
    true = {"bond_tensile_strength": np.array([args.sigma]), "bond_shear_strength": np.array([args.tau])}
    r_ucs = jaxbpm.solve(cyl, ucs_scene, "dem", params={**default_params(cyl), **true}, transits=args.transits)
    r_tpb = jaxbpm.solve(beam, tpb_scene, "dem", params={**default_params(beam), **true}, transits=args.transits)
    targets = {"ucs": float(r_ucs.stats["strength"]), "flexural": float(r_tpb.stats["strength"])}
    target_time = time.perf_counter() - t0
    print(f"targets from sigma_c = {args.sigma:.4g} Pa, tau_c = {args.tau:.4g} Pa: UCS {targets['ucs']:.6g} Pa "
          f"(broken {r_ucs.stats['broken_tensile']} tensile / {r_ucs.stats['broken_shear']} shear), flexural "
          f"{targets['flexural']:.6g} Pa (broken {r_tpb.stats['broken_tensile']} / {r_tpb.stats['broken_shear']}); "
          f"{target_time:.1f} s", flush=True)

    rows, out = [], {}
    for scheme in args.schemes.split(","):
        # the original scheme spends 3 parameter sets per Adam iteration: 7 points = 2 estimates + 5 iterations
        # = 17 sets; the simplified scheme one per point: 4 points = 4 sets (Qu et al.'s budgets: 19 and 4)
        max_it = 7 if scheme == "original" else 4
        print(f"\n== {scheme} scheme (at most {max_it} points)", flush=True)
        res = cal.calibrate_strength(cyl, beam, ucs=targets["ucs"], flexural=targets["flexural"], scheme=scheme,
                                     ucs_scene=ucs_scene, tpb_scene=tpb_scene, tol=args.tol,
                                     learning_rate=args.learning_rate, fd_step=args.fd_step,
                                     max_iterations=max_it, solve_options={"transits": args.transits},
                                     progress=True)
        hist = cal.strength_table(res)
        print(cal.format_strength_table(hist), flush=True)
        print(res.table(), flush=True)
        models = res.info["parameter_sets"]
        # the sets run until the first point within tolerance (the result is the best point seen)
        first_ok = next((h for h in hist if max(abs(h["ucs_error"]), abs(h["flexural_error"])) <= args.tol), None)
        row = {"scheme": scheme, "converged": res.converged, "iterations": res.iterations, "models": models,
               "dem_runs": res.evaluations, "wall_s": res.wall_time,
               "ucs_error": res.errors["ucs.strength"], "flexural_error": res.errors["tpb.strength"],
               "sigma_c": res.values["bond_tensile_strength"], "tau_c": res.values["bond_shear_strength"],
               "sigma_c_vs_true": res.values["bond_tensile_strength"] / args.sigma - 1,
               "tau_c_vs_true": res.values["bond_shear_strength"] / args.tau - 1,
               "qu2020_models": QU2020_MODELS[scheme],
               "goal_met": bool(first_ok is not None and first_ok["models"] <= QU2020_MODELS[scheme]),
               "notes": res.notes, "history": hist}
        rows.append(row)
        out[scheme] = row
    print()
    table([{**r, "ucs_error_%": 100 * r["ucs_error"], "flexural_error_%": 100 * r["flexural_error"]} for r in rows],
          ["scheme", "iterations", "models", "dem_runs", "wall_s", "ucs_error_%", "flexural_error_%",
           "qu2020_models", "goal_met"])
    write_json(args.out, {"benchmark": "strength_calibration", "machine": machine_info(), "settings": vars(args),
                          "specimens": {"ucs": {"particles": cyl.n_particles, "bonds": cyl.n_bonds},
                                        "tpb": {"particles": beam.n_particles, "bonds": beam.n_bonds}},
                          "targets": targets, "target_time_s": target_time,
                          "total_time_s": time.perf_counter() - t_all, "results": rows})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
