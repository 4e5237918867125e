#!/usr/bin/env python
"""STE vs DSM vs DEM: time and stiffness error of the stiffness tensor estimate, and its scaling.

Usage::

    python benchmarks/ste.py                              # 2k, 10k, 50k random packings; FCC 2k to 500k
    python benchmarks/ste.py --quick                      # smoke run
    python benchmarks/ste.py --dem-max 10000 --dsm-max 100000 --cache-dir results/samples

Samples
-------
* ``random``: ``jaxbpm.generate.box(n, seed).largest_cluster()`` (FIRE-packed polydisperse spheres, bonds at contacts)
  at ``--random-sizes`` (default 2k, 10k, 50k): the accuracy points (``--cache-dir``: samples saved there and
  reused, the files ``benchmarks/dsm_vs_dem.py`` writes).
* ``fcc``: an FCC lattice (``jaxbpm.generate.lattice``) with every centre moved at random by up to 5 % of the radius
  (bonds kept), at ``--fcc-sizes`` (default ~2k to ~500k): the scaling points. The FIRE packer is too slow for
  500k particles on this machine, so the large sizes use this cheap generator; the output says which sample is which.

Methods (scene: ``UniaxialCompression(strain=0.002)``, clamped layers, bonds only)
---------------------------------------------------------------------------------
* STE (3 DOF, Eq. 32; ``--boundary``: the library's default ``clamped`` form or the paper's ``free`` one, see
  ``docs/ste.md``): ``jaxbpm.ste.scene_stiffness`` jitted; compile time (``lower().compile()``) and run time
  (min of ``--repeats`` calls, ``block_until_ready``) separately; the estimator setup (NumPy: fabric, volumes) is
  timed as ``setup``. Twice: in float64 (the default) and with ``precision="float32"`` (columns ``ste32_*``).
* DSM (linear, 3 DOF = the STE's model, and 6 DOF = the DEM's model) up to ``--dsm-max`` particles.
* DEM (6 DOF, the reference, ``jaxbpm.solve(..., "dem")`` defaults) up to ``--dem-max`` particles.
Speed-up = DEM run time / STE run time (compilation excluded on both sides). Timing: one core (the least busy, unless
``--cpu``), XLA single-threaded (``--threads``), as in ``dsm_vs_dem.py``. Exponent: least-squares slope of
log(run time) against log(particles) over the sizes >= 10k.
"""

from __future__ import annotations

import argparse
import sys
import time

from _common import cached_box, enable_x64, machine_info, machine_load, pin, save_png, table, write_json


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def fcc_sample(n_target, seed=0, radius=1e-3):
    import numpy as np

    import jaxbpm

    cells = max(1, int(round((n_target / 4.0) ** (1.0 / 3.0))))
    s = jaxbpm.generate.lattice("fcc", (cells, cells, cells), radius, bond_radius_ratio=0.5,
                                materials={"E": 1e9, "nu": 0.25})
    rng = np.random.default_rng(seed)
    pos = np.asarray(s.positions) + rng.uniform(-0.05, 0.05, (s.n_particles, 3)) * radius
    return jaxbpm.Sample.from_arrays(pos, s.radii, s.bonds, s.bond_radius, materials=s.materials, domain=s.domain)


def time_ste(sample, scene, repeats, precision="float64", boundary="clamped"):
    import jax

    from jaxbpm import ste
    from jaxbpm.physics.model import default_params

    params = default_params(sample)
    t = time.perf_counter()
    est = ste.estimator(sample, scene, precision=precision, boundary=boundary)
    setup = time.perf_counter() - t

    def k_of(est, params):
        return ste.scene_stiffness(est, params, sample, scene)[0]

    t = time.perf_counter()
    compiled = jax.jit(k_of).lower(est, params).compile()
    compile_s = time.perf_counter() - t
    runs = []
    for _ in range(repeats):
        t = time.perf_counter()
        k = jax.block_until_ready(compiled(est, params))
        runs.append(time.perf_counter() - t)
    return {"K": float(k), "setup_s": setup, "compile_s": compile_s, "run_s": min(runs), "skipped": est.skipped,
            "surface": est.surface}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--random-sizes", type=int, nargs="*", default=[2000, 10000, 50000])
    ap.add_argument("--fcc-sizes", type=int, nargs="*", default=[2000, 10000, 100000, 500000])
    ap.add_argument("--dem-max", type=int, default=50000)
    ap.add_argument("--dsm-max", type=int, default=100000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--cpu", type=int, default=None, help="core to pin to (default: the least busy)")
    ap.add_argument("--threads", type=int, default=1, help="cores (XLA threads); 1 pins to one core")
    ap.add_argument("--cache-dir", default=None, help="reuse/save the random samples here (box_<n>_seed0.h5)")
    ap.add_argument("--boundary", choices=("clamped", "free"), default="clamped",
                    help="the STE's boundary form (default: the library's, clamped)")
    ap.add_argument("--out", default="results/ste.json")
    args = ap.parse_args(argv)
    if args.quick:
        args.random_sizes, args.fcc_sizes, args.dem_max, args.dsm_max = [500], [500, 2000], 500, 2000
    load_before = machine_load(1.0)
    args.cpu = pin(args.cpu, args.threads)
    enable_x64()
    import numpy as np

    import jaxbpm
    from jaxbpm.scenes import UniaxialCompression

    scene = UniaxialCompression(strain=0.002)
    rows = []
    t_all = time.perf_counter()
    jobs = [("random", n) for n in args.random_sizes] + [("fcc", n) for n in args.fcc_sizes]
    for kind, n in jobs:
        t = time.perf_counter()
        s = cached_box(n, 0, args.cache_dir)[0] if kind == "random" else fcc_sample(n)
        gen = time.perf_counter() - t
        log(f"{kind} {s.n_particles} particles, {s.n_bonds} bonds (generated in {gen:.1f} s)")
        row = {"sample": kind, "particles": s.n_particles, "bonds": s.n_bonds, "gen_s": gen}
        st = time_ste(s, scene, args.repeats, boundary=args.boundary)
        row.update({f"ste_{k}": v for k, v in st.items()})
        log(f"  STE K={st['K']:.5g} compile {st['compile_s']:.2f} s run {st['run_s'] * 1e3:.2f} ms")
        st32 = time_ste(s, scene, args.repeats, "float32", args.boundary)
        row.update({f"ste32_{k}": v for k, v in st32.items() if k in ("K", "compile_s", "run_s")})
        row["ste32_vs_ste64_rel"] = st32["K"] / st["K"] - 1
        log(f"  STE float32 K={st32['K']:.7g} ({row['ste32_vs_ste64_rel']:+.1e}) run {st32['run_s'] * 1e3:.2f} ms")
        if s.n_particles <= args.dsm_max:
            for dofs in (3, 6):
                r = jaxbpm.solve(s, scene, method="dsm", dofs=dofs)
                row[f"dsm{dofs}_K"], row[f"dsm{dofs}_run_s"] = r.stiffness, r.run_time
                row[f"err_vs_dsm{dofs}_%"] = 100 * (st["K"] / r.stiffness - 1)
                log(f"  DSM{dofs} K={r.stiffness:.5g} run {r.run_time:.2f} s")
        if s.n_particles <= args.dem_max:
            r = jaxbpm.solve(s, scene, method="dem")
            row.update(dem_K=r.stiffness, dem_run_s=r.run_time, dem_compile_s=r.compile_time,
                       dem_steps=r.stats.get("steps"))
            row["err_vs_dem_%"] = 100 * (st["K"] / r.stiffness - 1)
            row["speedup_vs_dem"] = r.run_time / st["run_s"]
            row["speedup32_vs_dem"] = r.run_time / st32["run_s"]
            log(f"  DEM K={r.stiffness:.5g} run {r.run_time:.2f} s -> speed-up {row['speedup_vs_dem']:.0f}x "
                f"(float32 {row['speedup32_vs_dem']:.0f}x)")
        rows.append(row)

    fcc = [r for r in rows if r["sample"] == "fcc" and r["particles"] >= 10000]
    exponent = exponent32 = None
    if len(fcc) >= 2:
        logn = np.log([r["particles"] for r in fcc])
        exponent = float(np.polyfit(logn, np.log([r["ste_run_s"] for r in fcc]), 1)[0])
        exponent32 = float(np.polyfit(logn, np.log([r["ste32_run_s"] for r in fcc]), 1)[0])
    cols = ["sample", "particles", "bonds", "ste_compile_s", "ste_run_s", "ste32_run_s", "dsm3_run_s", "dsm6_run_s",
            "dem_run_s", "err_vs_dsm3_%", "err_vs_dsm6_%", "err_vs_dem_%", "speedup_vs_dem", "speedup32_vs_dem"]
    table(rows, cols)
    print(f"STE run-time scaling exponent (fcc, >= 10k particles): float64 {exponent}, float32 {exponent32}")
    print(f"DEM run above {args.dem_max} particles and DSM above {args.dsm_max} skipped (time budget); "
          "fcc = perturbed FCC lattice (cheap generator for the scaling points), random = FIRE packing")
    load_after = machine_load(1.0)
    print(f"machine load (busy fraction per core) before {load_before['cpu_busy']} after {load_after['cpu_busy']}; "
          f"pinned to core {args.cpu}")
    out = {"benchmark": "ste", "machine": machine_info(), "settings": vars(args), "rows": rows,
           "scaling_exponent": exponent, "scaling_exponent_float32": exponent32,
           "load": {"before": load_before, "after": load_after}, "total_time_s": time.perf_counter() - t_all,
           "notes": f"STE 3 DOF (Eq. 32), boundary={args.boundary!r}, default surface_depth (one diameter); "
                    "speed-up = DEM run / STE run"}
    write_json(args.out, out)
    _plot(rows, exponent, args.out.replace(".json", ".png"))


def _plot(rows, exponent, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4.5))
    for kind, marker in (("fcc", "o"), ("random", "s")):
        rr = [r for r in rows if r["sample"] == kind]
        if not rr:
            continue
        n = [r["particles"] for r in rr]
        ax.loglog(n, [r["ste_run_s"] for r in rr], marker + "-", label=f"STE run ({kind})")
        ax.loglog(n, [r["ste32_run_s"] for r in rr], marker + "-", alpha=0.5, label=f"STE float32 run ({kind})")
        dem = [(r["particles"], r["dem_run_s"]) for r in rr if "dem_run_s" in r]
        if dem:
            ax.loglog(*zip(*dem), marker + "--", label=f"DEM run ({kind})")
        dsm = [(r["particles"], r["dsm6_run_s"]) for r in rr if "dsm6_run_s" in r]
        if dsm:
            ax.loglog(*zip(*dsm), marker + ":", label=f"DSM 6 DOF run ({kind})")
    ax.set_xlabel("particles")
    ax.set_ylabel("run time [s]")
    ax.set_title(f"STE scaling (exponent {exponent:.2f})" if exponent is not None else "STE scaling")
    ax.legend(fontsize=8)
    save_png(fig, path, dpi=120)


if __name__ == "__main__":
    main()
