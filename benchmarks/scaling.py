#!/usr/bin/env python
"""Time against particle count: DEM, DSM and STE on the same random boxes (Jarolin & Dosta's Fig. 5, redone).

Usage::

    python benchmarks/scaling.py --quick                         # 1k, 2k, 4k, 8k particles
    python benchmarks/scaling.py --cache-dir results/samples     # 1k ... 200k particles (the full run)
    python benchmarks/scaling.py --sizes 1000 10000 --methods dsm ste --dem-max 10000

Samples: ``jaxbpm.generate.box(n, seed=0, packing_fraction=0.55).largest_cluster()`` -- FIRE-packed polydisperse
spheres (5 % radius spread), bonds at contacts (gap < 0.05 mean radii), bond E = 1e9 Pa, nu = 0.25. The packing
fraction is fixed (``--packing-fraction``) so that every size has the same microstructure (the generator's automatic
choice would change it with the size, and small boxes spend most of their generation time jamming at 0.60 first).
Generation is timed separately, after a warm-up packing of 300 particles that absorbs most of the generator's
compilation (timed as ``generator_warmup_s`` in the record of the first generated size); with
``--cache-dir`` samples are stored as HDF5 (``jaxbpm.io.save_sample``) with the measured generation time beside
them (``box_<n>_phi<phi>_seed<s>.json``) and read back (``jaxbpm.io.load_sample``) by later runs, which then report
the stored generation time and the load time.

Scene: ``UniaxialCompression(strain=0.002)``: bottom layer clamped, top layer driven, bonds only (no contacts).

Methods (each through ``jaxbpm.solve``; compile and run time as the library reports them, ``block_until_ready``
included):

* ``DEM``: defaults (6 DOF, local damping 0.7, time step 0.5 x critical, loading over 40 wave transits; the step
  count grows like N^(1/3)); run once. run = median chunk time x chunks; compile = first chunk minus a typical one.
  Skipped above ``--dem-max`` particles (default 50 000) and when the power law fitted to the sizes so far predicts
  a run time above ``--time-cap`` seconds; the skip and its reason are printed and stored per size
  (``skipped`` in each method's record, and ``skipped`` at the top level of the JSON).
* ``DSM``: linear, library defaults (6 DOF, two-level preconditioned CG, relative residual 1e-6). The library
  compiles on the first call of a sample size and times a second call as the run time; ``--repeats`` calls, run
  time = the minimum, compile time from the first call.
* ``STE``: defaults (3 DOF, Eq. 32, particles within one diameter of the surface left out). Every call compiles
  again; ``--repeats`` calls, run time = the minimum, compile time = the minimum.

Wall time (the whole ``solve`` call: model building, time-step estimate, setup, compilation, run) is stored as well.
Exponents: least-squares slope of log(time) against log(particles) over the sizes >= ``--fit-min`` (default 10 000
in the full run; every size in ``--quick``), per method, for run, compile and wall time and for generation.
JSON to ``results/scaling.json`` (``--quick``: ``results/scaling_quick.json``), log-log PNG beside it
(``scaling.png`` / ``scaling_quick.png``).

Measured (``--quick``, ``time python benchmarks/scaling.py --quick``, no cache, both cores of a 2-core CPU shared
with other jobs, load average 7-8 during the run): real 3m25s, user 1m38s (a first run under lighter load, with 2
repeats: real 2m43s). Run-time exponents over 1k-8k: DEM 2.02, DSM 1.33, STE 0.98 (the first run: 1.52, 1.19,
0.43); generation 0.35 (each size compiles the packer again). At these sizes and this load the small run times are
noisy (the 2k DSM run took 0.69 s, the 4k one 0.30 s): fixed overheads and other jobs dominate, so the quick
exponents are not the asymptotic ones -- the full run fits over >= 10k.

Full run (``python benchmarks/scaling.py --cache-dir results/samples --threads 1``, empty cache, one core, the
other core busy with another benchmark): 12 min 38 s. Sizes 1k, 2k, 5k, 10k, 20k, 50k, 100k, 200k; DEM up to 50k
(``--dem-max``), DSM and STE at every size, 3 repeats, time cap 1800 s per predicted run. Run times at 1k / 10k / 50k
/ 200k particles: DEM 0.34 s / 6.2 s / 71.6 s / skipped; DSM 0.046 s / 0.74 s / 6.5 s / 38.7 s; STE 3.8 ms /
45 ms / 0.24 s / 1.37 s; generation 6.4 s / 8.9 s / 19.6 s / 96.7 s. Exponents over >= 10k (20k-200k): DEM 1.51
(20k-50k only), DSM 1.25, STE 1.18, generation 1.10.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings

from _common import enable_x64, machine_info, peak_rss_gib, pin_threads, save_png, table, write_json

FULL_SIZES = [1000, 2000, 5000, 10000, 20000, 50000, 100000, 200000]
QUICK_SIZES = [1000, 2000, 4000, 8000]
METHODS = ("dem", "dsm", "ste")
LABEL = {"dem": "DEM", "dsm": "DSM", "ste": "STE"}


_WARM: list = []  # time of the generator's warm-up call, once per process


def log(msg):
    print(msg, file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------------------------------- samples
def get_sample(n, args):
    """The sample of size ``n`` and a record of where it came from and what it cost."""
    import json

    import jaxbpm

    rec = {"n_requested": n}
    name = f"box_{n}_phi{args.packing_fraction:g}_seed{args.seed}"
    path = os.path.join(args.cache_dir, name + ".h5") if args.cache_dir else None
    meta = os.path.join(args.cache_dir, name + ".json") if args.cache_dir else None
    if path and os.path.exists(path):
        t = time.perf_counter()
        sample = jaxbpm.io.load_sample(path)
        rec.update(source=path, load_s=time.perf_counter() - t, generate_s=None)
        if os.path.exists(meta):
            with open(meta) as f:
                rec["generate_s"] = json.load(f).get("generate_s")
            rec["generate_s_from"] = "cache (measured when the sample was generated)"
        return sample, rec
    if not _WARM:
        # a small packing first: it absorbs most of the generator's one-off compilation (timed, reported apart)
        t = time.perf_counter()
        jaxbpm.generate.box(300, seed=args.seed, packing_fraction=0.5)
        _WARM.append(time.perf_counter() - t)
        rec["generator_warmup_s"] = _WARM[0]
    t = time.perf_counter()
    sample = jaxbpm.generate.box(n, seed=args.seed, packing_fraction=args.packing_fraction,
                                 materials={"E": 1e9, "nu": 0.25})
    gen = time.perf_counter() - t
    t = time.perf_counter()
    sample = sample.largest_cluster()
    gen += time.perf_counter() - t
    rec.update(source=f"generate.box({n}, seed={args.seed}, packing_fraction={args.packing_fraction})"
                      ".largest_cluster()", generate_s=gen, generate_s_from="this run", load_s=None)
    if path:
        os.makedirs(args.cache_dir, exist_ok=True)
        t = time.perf_counter()
        jaxbpm.io.save_sample(path, sample)
        rec["save_s"] = time.perf_counter() - t
        write_json(meta, {"generate_s": gen, "particles": sample.n_particles, "bonds": sample.n_bonds,
                          "source": rec["source"]})
    return sample, rec


# ---------------------------------------------------------------------------------------------------- one method
def fit_power(ns, ts):
    """Exponent b and prefactor a of t = a N^b (least squares in log-log); None with fewer than 2 points."""
    import numpy as np

    pts = [(n, t) for n, t in zip(ns, ts) if t is not None and t > 0]
    if len(pts) < 2 or len({n for n, _ in pts}) < 2:
        return None
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    b, a = np.polyfit(x, y, 1)
    return {"exponent": float(b), "prefactor": float(np.exp(a)), "points": len(pts),
            "range": [int(min(p[0] for p in pts)), int(max(p[0] for p in pts))]}


def predicted_run(method, n, done):
    """Run time of ``method`` at ``n`` particles predicted from the power law through the sizes done so far."""
    pts = [(r["particles"], r[method]["run_s"]) for r in done if r.get(method, {}).get("run_s")]
    if not pts:
        return None
    if len(pts) == 1:
        (n0, t0), b = pts[0], 1.5
    else:
        f = fit_power([p[0] for p in pts[-3:]], [p[1] for p in pts[-3:]])
        n0, t0, b = pts[-1][0], pts[-1][1], max(f["exponent"], 1.0)
    return t0 * (n / n0) ** b


def run_method(method, sample, scene, repeats, options=None):
    import jaxbpm

    calls = 1 if method == "dem" else repeats
    results, walls = [], []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(calls):
            t = time.perf_counter()
            results.append(jaxbpm.solve(sample, scene, method, **(options or {})))
            walls.append(time.perf_counter() - t)
    r0 = results[0]
    runs = [r.run_time for r in results]
    compiles = [r.compile_time for r in results]
    rec = {"K": r0.stiffness, "run_s": min(runs), "run_s_all": runs,
           "compile_s": compiles[0] if method != "ste" else min(compiles), "compile_s_all": compiles,
           "wall_s": walls[0], "wall_s_all": walls,
           "warnings": sorted({str(w.message)[:200] for w in caught})}
    if method == "dem":
        rec.update(steps=r0.stats["steps"], dt=r0.stats["dt"], steps_per_s=r0.stats.get("steps_per_second"))
    elif method == "dsm":
        rec.update(iterations=r0.stats["iterations"], converged=bool(r0.stats["converged"]),
                   residual=r0.stats["residual"], preconditioner=r0.stats["preconditioner"], dofs=r0.stats["dofs"])
    else:
        rec.update(skipped_particles=r0.stats["skipped"], surface_particles=r0.stats["surface"])
    return rec


# ---------------------------------------------------------------------------------------------------- plot
def plot(results, fits, path, note, skipped):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(figsize=(8, 6))
    colours = {"dem": "C3", "dsm": "C0", "ste": "C2"}
    allx = [r["particles"] for r in results]
    for m in METHODS:
        pts = [(r["particles"], r[m]["run_s"], r[m]["compile_s"]) for r in results if r.get(m, {}).get("run_s")]
        if not pts:
            continue
        x = np.array([p[0] for p in pts], float)
        f = fits.get(m, {}).get("run_s")
        lab = f"{LABEL[m]} run" + (f"  ~ N^{f['exponent']:.2f}" if f else "")
        ax.loglog(x, [p[1] for p in pts], "o", color=colours[m], mec="k", ms=7, label=lab)
        if f:
            xf = np.geomspace(f["range"][0], f["range"][1], 50)
            ax.loglog(xf, f["prefactor"] * xf ** f["exponent"], "-", color=colours[m], lw=1.5)
        ax.loglog(x, [p[2] for p in pts], "s--", color=colours[m], mfc="none", ms=6, lw=0.8,
                  label=f"{LABEL[m]} compile")
    gen = [(r["particles"], r["generate_s"]) for r in results if r.get("generate_s")]
    if gen:
        f = fits.get("generate_s")
        ax.loglog([g[0] for g in gen], [g[1] for g in gen], "^:", color="0.5", mfc="none",
                  label="generation" + (f"  ~ N^{f['exponent']:.2f}" if f else ""))
    for m, sizes in skipped.items():
        for n, why in sizes:
            ax.annotate(f"{LABEL[m]} skipped\n({why})", (n, ax.get_ylim()[0]), xytext=(0, 12),
                        textcoords="offset points", fontsize=6.5, ha="center", color=colours[m], rotation=90,
                        va="bottom")
    ax.set_xlabel("number of particles N")
    ax.set_ylabel("time [s]")
    ax.set_xlim(min(allx) / 1.3, max(allx) * 1.3)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title("Computation time against particle count, uniaxial compression, bonds only\n"
                 "(Jarolin & Dosta 2020, Fig. 5 style; lines: power laws fitted to the run times)", fontsize=10)
    return save_png(fig, path, note)


# ---------------------------------------------------------------------------------------------------- main
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=None, help=f"particle counts (default {FULL_SIZES})")
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    ap.add_argument("--dem-max", type=int, default=50000, help="no DEM above this many particles")
    ap.add_argument("--time-cap", type=float, default=1800.0,
                    help="skip a method at a size where its predicted run time exceeds this [s]")
    ap.add_argument("--repeats", type=int, default=3, help="calls of DSM and STE per size (DEM: one)")
    ap.add_argument("--fit-min", type=int, default=None, help="fit exponents over sizes >= this (default 10000)")
    ap.add_argument("--packing-fraction", type=float, default=0.55)
    ap.add_argument("--strain", type=float, default=0.002)
    ap.add_argument("--dsm-stiffness-tol", type=float, default=None,
                    help="the DSM's stiffness_tol (default: the library's: residual tolerance alone)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cache-dir", default=None, help="read samples from / store them in this folder (HDF5)")
    ap.add_argument("--threads", type=int, default=None, help="restrict to this many cores")
    ap.add_argument("--quick", action="store_true", help=f"sizes {QUICK_SIZES}, 3 repeats, fit over every size")
    ap.add_argument("--out", default="results/scaling.json")
    args = ap.parse_args(argv)
    if args.quick:
        args.sizes = args.sizes or QUICK_SIZES
        args.repeats = min(args.repeats, 3)
        args.fit_min = 0 if args.fit_min is None else args.fit_min
        if args.out == "results/scaling.json":
            args.out = "results/scaling_quick.json"
    args.sizes = sorted(args.sizes or FULL_SIZES)
    args.fit_min = 10000 if args.fit_min is None else args.fit_min
    pin_threads(args.threads)
    enable_x64()
    import numpy as np

    import jaxbpm

    t_start = time.perf_counter()
    scene = jaxbpm.scenes.UniaxialCompression(strain=args.strain)
    results, skipped = [], {m: [] for m in METHODS}
    for n in args.sizes:
        sample, rec = get_sample(n, args)
        rec.update(particles=sample.n_particles, bonds=sample.n_bonds,
                   coordination=float(np.mean(sample.coordination())))
        gtxt = f"{rec['generate_s']:.1f} s" if rec.get("generate_s") is not None else "unknown"
        log(f"== {sample.n_particles} particles, {sample.n_bonds} bonds (generation {gtxt}"
            + (f", loaded in {rec['load_s']:.2f} s" if rec.get("load_s") is not None else "") + ")")
        for m in args.methods:
            why = None
            if m == "dem" and sample.n_particles > args.dem_max:
                why = f"N > --dem-max {args.dem_max}"
            else:
                pred = predicted_run(m, sample.n_particles, results)
                if pred is not None and pred > args.time_cap:
                    why = f"predicted run {pred:.0f} s > --time-cap {args.time_cap:g} s"
            if why:
                rec[m] = {"skipped": why}
                skipped[m].append((sample.n_particles, why))
                log(f"  {LABEL[m]}: skipped ({why})")
                continue
            try:
                rec[m] = run_method(m, sample, scene, args.repeats,
                                    {"stiffness_tol": args.dsm_stiffness_tol} if m == "dsm" and args.dsm_stiffness_tol else None)
            except Exception as exc:  # recorded, not fatal
                rec[m] = {"error": f"{type(exc).__name__}: {exc}"}
                log(f"  {LABEL[m]}: FAILED {type(exc).__name__}: {exc}")
                continue
            r = rec[m]
            r["peak_rss_gib"] = peak_rss_gib()  # the process's high-water mark after this method (sizes increase)
            log(f"  {LABEL[m]}: K={r['K']:.6g}  compile {r['compile_s']:.2f} s  run {r['run_s']:.4g} s  "
                f"wall {r['wall_s']:.2f} s  peak RSS {r['peak_rss_gib']:.2f} GiB")
        ref = rec.get("dem", {}).get("K")
        for m in ("dsm", "ste"):
            if ref and rec.get(m, {}).get("K"):
                rec[m]["dK_vs_DEM"] = rec[m]["K"] / ref - 1
                rec[m]["speedup_run_vs_DEM"] = rec["dem"]["run_s"] / max(rec[m]["run_s"], 1e-12)
        results.append(rec)
        del sample

    # exponents
    fits = {}
    fit_rows = [r for r in results if r["particles"] >= args.fit_min]
    for m in args.methods:
        fits[m] = {}
        for key in ("run_s", "compile_s", "wall_s"):
            ok = [r for r in fit_rows if r.get(m, {}).get(key)]
            fits[m][key] = fit_power([r["particles"] for r in ok], [r[m][key] for r in ok])
    gen_rows = [r for r in fit_rows if r.get("generate_s")]
    fits["generate_s"] = fit_power([r["particles"] for r in gen_rows], [r["generate_s"] for r in gen_rows])

    rows = []
    for r in results:
        row = {"particles": r["particles"], "bonds": r["bonds"], "gen_s": r.get("generate_s") or "",
               "load_s": r.get("load_s") or ""}
        for m in METHODS:
            d = r.get(m, {})
            if "run_s" in d:
                row[f"{LABEL[m]}_compile_s"], row[f"{LABEL[m]}_run_s"] = d["compile_s"], d["run_s"]
            else:
                row[f"{LABEL[m]}_compile_s"] = ""
                row[f"{LABEL[m]}_run_s"] = "skipped" if "skipped" in d else ("FAILED" if "error" in d else "")
        row["peak_rss_GiB"] = max((r[m].get("peak_rss_gib") or 0.0 for m in METHODS if isinstance(r.get(m), dict)),
                                  default="")
        for m in ("dsm", "ste"):
            d = r.get(m, {})
            row[f"{LABEL[m]}_dK_%"] = 100 * d["dK_vs_DEM"] if "dK_vs_DEM" in d else ""
            row[f"{LABEL[m]}_x_DEM"] = d.get("speedup_run_vs_DEM", "")
        rows.append(row)
    print("\nTime against particle count (bonds only, uniaxial compression; run time: min over repeats, DEM once; "
          "dK: stiffness vs DEM; x_DEM: DEM run / method run)")
    table(rows, list(rows[0]))
    erows = []
    for m in args.methods:
        erows.append({"method": LABEL[m], **{k.replace("_s", "") + " exponent":
                                             (fits[m][k]["exponent"] if fits[m][k] else "") for k in fits[m]},
                      "points": fits[m]["run_s"]["points"] if fits[m]["run_s"] else 0,
                      "range": "-".join(map(str, fits[m]["run_s"]["range"])) if fits[m]["run_s"] else ""})
    if fits["generate_s"]:
        erows.append({"method": "generation", "run exponent": fits["generate_s"]["exponent"],
                      "points": fits["generate_s"]["points"], "range": "-".join(map(str, fits["generate_s"]["range"]))})
    print(f"\nPower-law exponents b of t = a N^b (least squares, log-log, sizes >= {args.fit_min})")
    table(erows, ["method", "run exponent", "compile exponent", "wall exponent", "points", "range"])
    skip_list = {m: v for m, v in skipped.items() if v}
    for m, v in skip_list.items():
        print(f"  {LABEL[m]} skipped at " + ", ".join(f"{n} ({why})" for n, why in v))
    total = time.perf_counter() - t_start
    print(f"total {total:.1f} s.")

    info = machine_info()
    out = {"benchmark": "scaling", "machine": info, "settings": vars(args), "total_time_s": total,
           "scene": f"UniaxialCompression(strain={args.strain}), clamped layers, bonds only",
           "results": results, "rows": rows, "fits": fits,
           "skipped": {LABEL[m]: [{"particles": n, "reason": why} for n, why in v] for m, v in skip_list.items()},
           "dem_max": args.dem_max, "time_cap_s": args.time_cap,
           "notes": "run_s: library run time (DSM, STE: min over repeats; DEM: one run, median chunk x chunks); "
                    "compile_s: library compile time; wall_s: whole solve call of the first repeat; generate_s: "
                    "generator + largest_cluster, after a 300-particle warm-up call (generator_warmup_s)"}
    path = write_json(args.out, out)
    print(f"wrote {path}")
    png = os.path.splitext(args.out)[0] + ".png"
    note = (f"{info['device']} ({info['cpu_count']} cores, affinity {info['affinity']}), jax {info['jax']}, float64, "
            f"strain {args.strain}, packing fraction {args.packing_fraction}, seed {args.seed}")
    print(f"wrote {plot(results, fits, png, note, skip_list)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
