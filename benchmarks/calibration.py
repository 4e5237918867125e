"""Calibrate the bond modulus of a random sample to a target Young's modulus, per calibrator, checked by the DEM.

Samples: a random box of ``--n`` particles (largest bonded cluster), one component, and the same sample with two
components (moduli 1:4, mixed 50/50; the ratio is kept and the common scale calibrated). Per method: model
evaluations (solves, the DEM check excluded), iterations, wall time and the final error of a DEM run at the answer.

Methods: Adam-FD on DEM (few iterations: a DEM run of this size costs seconds to tens of seconds), Adam-FD on DSM,
Adam-autodiff on DSM (both with Qu et al.'s initial estimates, the closed-form shortcut off), the random-forest
surrogate on DSM (a small run set, solved ``--batch-size`` runs per ``vmap`` batch so that the batch's memory stays
bounded), and the multi-fidelity default (``method="auto"``: STE, then DSM where needed,
closed form on each level). Goal: within 1 % of the target checked by DEM, <= 6 iterations, <= 8 evaluations.

    python benchmarks/calibration.py [--n 5000] [--quick]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(__file__))
from _common import enable_x64, machine_info, table, write_json  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=5000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--target-E", type=float, default=1.2e8, dest="target_E")
    ap.add_argument("--tol", type=float, default=0.01)
    ap.add_argument("--dem-iterations", type=int, default=3, dest="dem_iterations")
    ap.add_argument("--surrogate-runs", type=int, default=24, dest="surrogate_runs")
    ap.add_argument("--batch-size", "--chunk", type=int, default=4, dest="batch_size",
                    help="surrogate runs solved per vmap batch (memory bound; --chunk: its former name)")
    ap.add_argument("--quick", action="store_true", help="500 particles (smoke test)")
    ap.add_argument("--out", default="results/calibration.json")
    args = ap.parse_args(argv)
    if args.quick:
        args.n = 500
    enable_x64()
    import numpy as np

    import jaxbpm
    from jaxbpm import calibrate as cal
    from jaxbpm.scenes import UniaxialCompression

    t_all = time.perf_counter()
    scene = UniaxialCompression(strain=0.002)
    base = jaxbpm.generate.box(args.n, seed=args.seed).largest_cluster()
    samples = {"one": base,
               "two": jaxbpm.generate.mix_materials(base, [0.5, 0.5], seed=1,
                                                    materials={"E": [1e9, 4e9], "nu": 0.25})}
    target = {"youngs_modulus": args.target_E}
    rows = []
    for sname, sample in samples.items():
        E0 = float(np.asarray(sample.materials.E)[0])
        ratio = tuple(np.asarray(sample.materials.E) / E0)
        params = [cal.Parameter("bond_E", index=None, ratio=ratio if len(ratio) > 1 else None,
                                bounds=(E0 / 10, E0 * 10))]
        runs = {
            "adam-fd/dem": dict(method="adam", solver="dem", shortcut=False, gradient="fd-forward", fd_step=1e-2,
                                max_iterations=args.dem_iterations),
            "adam-fd/dsm": dict(method="adam", solver="dsm", shortcut=False, gradient="fd-forward",
                                max_iterations=6),
            "adam-autodiff/dsm": dict(method="adam", solver="dsm", shortcut=False, gradient="autodiff",
                                      max_iterations=6),
            "surrogate/dsm": dict(method="surrogate", solver="dsm", n_runs=args.surrogate_runs, n_trees=200,
                                  L_s=500, it_max=20, I_e=0.2, batch_size=args.batch_size,
                                  parameters=[cal.Parameter("bond_E", index=None,
                                                            ratio=ratio if len(ratio) > 1 else None,
                                                            bounds=(E0 / 10, E0 * 2))]),
            "multi-fidelity": dict(method="auto"),
        }
        for name, kw in runs.items():
            kw = dict(kw)
            kw.setdefault("parameters", params)
            print(f"\n== {sname} component(s), {sample.n_particles} particles: {name}", flush=True)
            try:
                res = cal.calibrate(sample, scene, target, tol=args.tol, check="dem", progress=True, **kw)
            except cal.CalibrationError as exc:
                print(f"failed: {exc}", flush=True)
                rows.append({"sample": sname, "method": name, "error": str(exc)})
                continue
            chk = res.info["check"]
            err = chk["errors"]["youngs_modulus"]
            row = {"sample": sname, "particles": sample.n_particles, "method": name, "answer_bond_E":
                   float(res.params["bond_E"][0]), "evaluations": res.evaluations, "iterations": res.iterations,
                   "wall_s": res.wall_time - chk["wall_time"], "model_error": res.max_error,
                   "dem_error": err, "dem_check_s": chk["wall_time"], "converged": res.converged,
                   "goal_met": bool(abs(err) <= 0.01 and res.iterations <= 6 and res.evaluations <= 8),
                   "levels": [{k: v for k, v in lv.items() if k != "errors"} for lv in res.levels],
                   "notes": res.notes}
            rows.append(row)
            print(res.table(), flush=True)
            print(f"DEM check: {100 * err:+.3f} % ({chk['wall_time']:.1f} s)", flush=True)
    print()
    table([{**r, "dem_error_%": 100 * r["dem_error"], "model_error_%": 100 * r["model_error"]} for r in rows
           if "error" not in r],
          ["sample", "method", "evaluations", "iterations", "wall_s", "model_error_%", "dem_error_%", "goal_met"])
    write_json(args.out, {"benchmark": "calibration", "machine": machine_info(), "settings": vars(args),
                          "target": target, "total_time_s": time.perf_counter() - t_all, "results": rows})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
