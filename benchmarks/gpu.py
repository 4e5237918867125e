"""Every benchmark's GPU-relevant part in one command, with the figures written beside the CPU ones.

    pip install -e '.[cuda]'            # JAX's CUDA 12 wheels
    python benchmarks/gpu.py            # the whole table (about an hour on one GPU)
    python benchmarks/gpu.py --quick    # each case at its --quick size (minutes)
    python benchmarks/gpu.py --only dem_throughput ste --precision float32
    python benchmarks/gpu.py --short --budget 540   # a first look in under ten minutes (smaller sizes)

Each case runs in a process of its own (a clean device and compilation state) on JAX's default device, in float64
and, where single precision makes sense (the DEM's explicit steps, the STE's estimate), in float32 too
(``JAXBPM_BENCH_X64=0``). Results go to ``results/gpu/<case>_<precision>.json`` (``--out-dir``); the summary
``results/gpu/summary.json`` lists every case with its status, wall time and the CPU result file it should be read
beside (``results/<case>.json``). A case that fails is recorded with its error's tail and the rest go on. The
summary is written again after every case, so a run stopped early keeps what it measured.

``--short`` runs the cases in the order of what they tell (the DEM's throughput first, then the STE, the scaling
of STE and DSM, batched DEM runs, time to answer, the DSM against the DEM) at sizes that fit a ten-minute first
look; ``--budget SECONDS`` stops starting cases when the time is spent and cuts the last one short (``status``
"skipped (budget)" / "timeout").

Not in the list: benchmarks about CPU processes and cores (``parallel_runs``, ``size_classes``, ``vs_lammps``: LAMMPS
runs on the CPU), and the calibration benchmarks (their cost is the solves measured here).

``--allow-cpu`` runs the same commands on a machine without a GPU (to check the script; the figures are then CPU
figures, labelled with the device they ran on).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

# case: (script, full-size arguments, precisions). The sizes go to 1M where the CPU runs stop short of it.
CASES = {
    "dem_throughput": ("dem_throughput.py", ["--sizes", "10000", "100000", "1000000", "--steps", "2000"],
                       ("float64", "float32")),
    "scaling": ("scaling.py", ["--sizes", "10000", "100000", "300000", "1000000", "--dem-max", "1000000"],
                ("float64",)),
    "ste": ("ste.py", ["--random-sizes", "10000", "100000", "--fcc-sizes", "100000", "1000000"],
            ("float64", "float32")),
    "dsm_vs_dem": ("dsm_vs_dem.py", [], ("float64",)),
    "time_to_answer": ("time_to_answer.py", [], ("float64",)),
    "dem_batch": ("dem_batch.py", ["--batches", "1", "4", "16", "64"], ("float64", "float32")),
    "pareto": ("pareto.py", [], ("float64",)),
}

# --short: the same cases at sizes that fit a first look of about ten minutes on one GPU, most telling first.
SHORT = {
    "dem_throughput": ["--sizes", "10000", "100000", "--steps", "1000",
                       "--profile", os.path.join(tempfile.gettempdir(), "jaxbpm-gpu-traces")],
    "ste": ["--random-sizes", "10000", "--fcc-sizes", "100000", "1000000", "--dem-max", "10000",
            "--dsm-max", "10000"],
    "scaling": ["--sizes", "10000", "100000", "300000", "--methods", "ste", "dsm", "--dsm-stiffness-tol", "1e-2"],
    "dem_batch": ["--batches", "1", "16", "64", "--sequential-max", "4"],
    "time_to_answer": ["--sizes", "3000", "--skip-demo", "--skip-calibrate"],
    "dsm_vs_dem": ["--sizes", "10000", "50000", "--dem-max", "10000", "--splu-max", "0", "--no-contacts"],
    "pareto": ["--quick"],
}


def _device() -> dict:
    import jax

    dev = jax.devices()[0]
    return {"platform": dev.platform, "device": getattr(dev, "device_kind", str(dev)), "count": jax.device_count(),
            "jax": jax.__version__}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", choices=list(CASES), default=list(CASES), help="cases to run")
    ap.add_argument("--precision", nargs="+", choices=["float64", "float32"], default=["float64", "float32"])
    ap.add_argument("--quick", action="store_true", help="each case with --quick")
    ap.add_argument("--out-dir", default="results/gpu")
    ap.add_argument("--short", action="store_true", help="each case at the sizes of a ten-minute first look")
    ap.add_argument("--timeout", type=float, default=3600.0, help="seconds per case and precision")
    ap.add_argument("--budget", type=float, default=None, help="seconds for the whole table (no case starts after)")
    ap.add_argument("--allow-cpu", action="store_true", help="run even where JAX's default device is not a GPU")
    ap.add_argument("--dry-run", action="store_true", help="print the commands only")
    args = ap.parse_args(argv)
    from _common import table, write_json

    device = _device()
    if device["platform"] != "gpu" and not (args.allow_cpu or args.dry_run):
        sys.exit(f"JAX's default device is {device['platform']} ({device['device']}), not a GPU: install the CUDA "
                 "wheels (pip install -e '.[cuda]') or pass --allow-cpu")
    if args.quick and args.short:
        ap.error("--quick and --short are two sizes: pick one")
    os.makedirs(args.out_dir, exist_ok=True)
    order = [c for c in SHORT if c in args.only] if args.short else args.only
    summary = os.path.join(args.out_dir, "summary.json")
    start, rows = time.perf_counter(), []
    for case in order:
        script, extra, precisions = CASES[case]
        for precision in (p for p in args.precision if p in precisions):
            out = os.path.join(args.out_dir, f"{case}_{precision}.json")
            sizes = ["--quick"] if args.quick else SHORT[case] if args.short else extra
            cmd = [sys.executable, os.path.join(HERE, script)] + sizes + ["--out", out]
            env = dict(os.environ, JAXBPM_BENCH_X64="1" if precision == "float64" else "0")
            print(f"== {case} ({precision}): {' '.join(cmd[1:])}", flush=True)
            if args.dry_run:
                continue
            left = args.timeout if args.budget is None else min(args.timeout, args.budget - (time.perf_counter() - start))
            if left < 20.0:
                print("   skipped: the budget is spent", flush=True)
                rows.append({"case": case, "precision": precision, "status": "skipped (budget)", "wall_s": 0.0,
                             "out": None, "cpu_result": None, "error": None})
                continue
            t0 = time.perf_counter()
            try:
                done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=left)
                status, tail = ("ok" if done.returncode == 0 else f"exit {done.returncode}"), done.stderr[-2000:]
                print(done.stdout[-4000:], flush=True)
            except subprocess.TimeoutExpired as exc:
                def text(b):
                    return (b or b"").decode(errors="replace") if isinstance(b or b"", bytes) else b
                status, tail = "timeout", text(exc.stderr)[-2000:]
                print(text(exc.stdout)[-4000:], flush=True)  # what the case had printed before it was stopped
            wall = time.perf_counter() - t0
            if status != "ok":
                print(f"   {status}:\n{tail}", flush=True)
            cpu = os.path.join("results", f"{case}.json")
            rows.append({"case": case, "precision": precision, "status": status, "wall_s": wall, "out": out,
                         "cpu_result": cpu if os.path.exists(cpu) else None,
                         "error": None if status == "ok" else tail})
            write_json(summary, {"benchmark": "gpu", "device": device, "quick": args.quick, "short": args.short,
                                 "cases": rows})
    if args.dry_run:
        return 0
    print()
    table(rows, ["case", "precision", "status", "wall_s", "out", "cpu_result"])
    print(f"wrote {summary}")
    return 0 if all(r["status"] == "ok" for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
