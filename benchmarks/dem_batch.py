"""Batched DEM runs: B parameter sets one after another (``jaxbpm.solve``) against one ``solve_batch`` of B.

For a bonds-only uniaxial compression -- elastic (no breakage) and to failure (breakage, ``contacts=False``) -- on a
random bonded box of ``--particles`` particles, with B = 1, 4, 16 members (bond modulus and tensile strength
perturbed as a finite-difference calibration does), the script times

- ``sequential``: B ``jaxbpm.solve`` calls with the batch's time step, loading time and chunk, after a warm-up
  solve that compiles;
- ``map``: one ``solve_batch(..., vectorize=False)`` (the default: ``lax.map`` over the members inside the
  program), after a warm-up batch of the same B that compiles;
- ``vmap``: the same with ``vectorize=True`` (``jax.vmap``).

and reports the wall time per run, the speedup over sequential and the compile time of each warm-up.

    python benchmarks/dem_batch.py [--particles 2000] [--batches 1 4 16] [--threads N] [--quick]
"""

from __future__ import annotations

import argparse
import sys
import time

from _common import enable_x64, machine_info, pin_threads, table, write_json


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--particles", type=int, default=2000)
    ap.add_argument("--batches", type=int, nargs="+", default=[1, 4, 16])
    ap.add_argument("--transits", type=float, default=40.0, help="loading time in elastic-wave transits")
    ap.add_argument("--threads", type=int, default=None, help="pin to this many cores (default: all)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sequential-max", type=int, default=None,
                    help="time at most this many of the B sequential runs (their time per run is what is reported)")
    ap.add_argument("--no-vmap", action="store_true", help="leave the vectorised (jax.vmap) batch out")
    ap.add_argument("--quick", action="store_true", help="500 particles, 20 transits")
    ap.add_argument("--out", default="results/dem_batch.json")
    args = ap.parse_args(argv)
    if args.quick:
        args.particles, args.transits = 500, 20.0
        if args.out == "results/dem_batch.json":
            args.out = "results/dem_batch_quick.json"
    pin_threads(args.threads)
    enable_x64()

    import numpy as np

    import jaxbpm
    from jaxbpm.physics.model import default_params
    from jaxbpm.scenes import UniaxialCompression

    sample = jaxbpm.generate.box(args.particles, seed=args.seed, mean_radius=1e-3,
                                 materials={"E": 1e9, "nu": 0.25, "tensile_strength": 5e6, "shear_strength": 1e7})
    scenes = {"elastic": UniaxialCompression(strain=0.002, breakage=False),
              "failure": UniaxialCompression.to_failure(strain=0.01, contacts=False)}
    p0 = default_params(sample)

    def members(b):
        # perturbed as the runs of a finite-difference gradient: +-1e-3 relative steps
        return [dict(p0, bond_E=np.array([1e9 * (1 + 1e-3 * k)]), bond_nu=np.array([0.25]),
                     bond_tensile_strength=np.array([5e6 * (1 - 1e-3 * k)]), bond_shear_strength=np.array([1e7]))
                for k in range(b)]

    modes = ["map"] + ([] if args.no_vmap else ["vmap"])
    rows = []
    for name, scene in scenes.items():
        for b in args.batches:
            params = members(b)
            row = {"scene": name, "particles": sample.n_particles, "bonds": sample.n_bonds, "B": b}
            for mode in modes:
                t = time.perf_counter()
                warm = jaxbpm.dem.solve_batch(sample, scene, params, transits=args.transits, vectorize=mode == "vmap")
                row[f"{mode}_warmup_s"] = time.perf_counter() - t
                row[f"{mode}_compile_s"] = warm[0].stats["batch"]["compile_time"]
                t = time.perf_counter()
                out = jaxbpm.dem.solve_batch(sample, scene, params, transits=args.transits, vectorize=mode == "vmap")
                row[f"{mode}_per_run_s"] = (time.perf_counter() - t) / b
                if mode == "map":
                    batch = out[0].stats["batch"]
                    row.update(steps=out[0].stats["steps"], dt=batch["dt"])
                    stiff = [r.stiffness for r in out]
            fixed = dict(dt=batch["dt"], loading_time=batch["loading_time"], chunk=batch["chunk"])
            t = time.perf_counter()
            jaxbpm.solve(sample, scene, params=params[0], **fixed)
            row["sequential_warmup_s"] = time.perf_counter() - t
            seq = params[:args.sequential_max] if args.sequential_max else params
            t = time.perf_counter()
            single = [jaxbpm.solve(sample, scene, params=p, **fixed) for p in seq]
            row["sequential_per_run_s"] = (time.perf_counter() - t) / len(seq)
            row["sequential_runs"] = len(seq)
            row["max_rel_diff_map"] = float(max(abs(r.stiffness / s - 1) for r, s in zip(single, stiff)))
            for mode in modes:
                row[f"{mode}_speedup"] = row["sequential_per_run_s"] / row[f"{mode}_per_run_s"]
            rows.append(row)
            print(f"{name} B={b}: sequential {row['sequential_per_run_s']:.3g} s/run, map "
                  f"{row['map_per_run_s']:.3g} s/run" + ("" if args.no_vmap else
                                                         f", vmap {row['vmap_per_run_s']:.3g} s/run"),
                  file=sys.stderr)

    columns = ["scene", "B", "steps", "sequential_per_run_s"] + [f"{m}_{k}" for m in modes
                                                                  for k in ("per_run_s", "speedup", "compile_s")]
    table(rows, columns + ["max_rel_diff_map"])
    write_json(args.out, {"benchmark": "dem_batch", "machine": machine_info(), "particles": sample.n_particles,
                          "bonds": sample.n_bonds, "transits": args.transits, "rows": rows})
    print(f"wrote {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
