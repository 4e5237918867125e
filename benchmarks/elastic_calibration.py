"""Calibrate Young's modulus and Poisson's ratio together on a large sample: DSM solves, then one DEM check.

A bonded cylinder of ``--n`` particles (aspect 2, 5 % radius spread, bond radius ratio 0.5) in uniaxial
compression (0.1 %, clamped end layers, the lateral strain of the middle third). Targets are set relative to what
the sample gives at its default bonds (``E0``, ``nu0``, from one DSM solve not counted): by default
``(1.5 E0, 0.8 nu0)`` and ``(0.7 E0, 1.05 nu0)`` (a bonds-only sample reaches about 1.1 nu0 at most, with
the default bond radius ratio). Per target pair: the DSM solves that
:func:`jaxbpm.calibrate.calibrate_elastic` needed, its errors, the DEM's errors at the answer (the check), and wall
times. Goal (issue on lab calibration): E and nu within 2 % by the DEM check in <= 4 DSM solves at 10k particles.

    python benchmarks/elastic_calibration.py [--n 10000] [--quick]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(__file__))
from _common import enable_x64, machine_info, peak_rss_gib, table, write_json  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--tol", type=float, default=0.01, help="tolerance of the DSM iteration")
    ap.add_argument("--targets", type=float, nargs="+", default=[1.5, 0.8, 0.7, 1.05],
                    help="pairs (E / E0, nu / nu0)")
    ap.add_argument("--quick", action="store_true", help="800 particles (smoke test)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    if args.quick:
        args.n = 800
    if len(args.targets) % 2:
        ap.error("--targets takes pairs (E / E0, nu / nu0)")
    out = args.out or ("results/elastic_calibration_quick.json" if args.quick else "results/elastic_calibration.json")
    enable_x64()
    import jaxbpm
    from jaxbpm.calibrate import calibrate_elastic

    t0 = time.perf_counter()
    sample = jaxbpm.generate.cylinder(args.n, seed=args.seed, materials={"E": 1e9, "nu": 0.25}).largest_cluster()
    t_generate = time.perf_counter() - t0
    scene = jaxbpm.scenes.UniaxialCompression(strain=1e-3)
    t0 = time.perf_counter()
    now = jaxbpm.solve(sample, scene, method="dsm")
    t_first = time.perf_counter() - t0
    E0, nu0 = now.youngs_modulus, now.poisson_ratio
    print(f"{sample.n_particles} particles, {sample.n_bonds} bonds (generated in {t_generate:.1f} s); default bonds: "
          f"E0 = {E0:.5g} Pa, nu0 = {nu0:.4f} (DSM, first call {t_first:.1f} s)", flush=True)
    rows = []
    for fe, fn in zip(args.targets[::2], args.targets[1::2]):
        E_t, nu_t = fe * E0, fn * nu0
        t0 = time.perf_counter()
        res = calibrate_elastic(sample, scene, E=E_t, nu=nu_t, tol=args.tol, check="dem", progress=True)
        wall = time.perf_counter() - t0
        check = res.info["check"]
        row = {"E_target": E_t, "nu_target": nu_t, "E_over_E0": fe, "nu_over_nu0": fn,
               "dsm_solves": res.evaluations, "converged": bool(res.converged),
               "dsm_err_E": res.errors["youngs_modulus"], "dsm_err_nu": res.errors["poisson_ratio"],
               "dem_err_E": check["errors"]["youngs_modulus"], "dem_err_nu": check["errors"]["poisson_ratio"],
               "bond_E": res.values["bond_E"], "bond_nu": res.values["bond_nu"],
               "dsm_s": res.wall_time, "dem_check_s": check["wall_time"], "wall_s": wall,
               "goal_met": bool(res.evaluations <= 4 and check["max_error"] <= 0.02)}
        rows.append(row)
        print(f"E x{fe:g}, nu x{fn:g}: {res.evaluations} DSM solves ({res.wall_time:.1f} s), DEM check "
              f"E {100 * row['dem_err_E']:+.2f} %, nu {100 * row['dem_err_nu']:+.2f} % ({check['wall_time']:.1f} s)",
              flush=True)
    table(rows, ["E_over_E0", "nu_over_nu0", "dsm_solves", "dsm_err_E", "dsm_err_nu", "dem_err_E", "dem_err_nu",
                 "dsm_s", "dem_check_s", "goal_met"])
    write_json(out, {"benchmark": "elastic_calibration", "machine": machine_info(), "n": sample.n_particles,
                     "n_bonds": sample.n_bonds, "generate_s": t_generate, "first_dsm_s": t_first, "E0": E0,
                     "nu0": nu0, "tol": args.tol, "rows": rows, "peak_rss_gib": peak_rss_gib()})
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
