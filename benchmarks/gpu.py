"""Every benchmark's GPU-relevant part in one command, with the figures written beside the CPU ones.

    pip install -e '.[cuda]'            # JAX's CUDA 12 wheels
    python benchmarks/gpu.py            # the whole table (about an hour on one GPU)
    python benchmarks/gpu.py --quick    # each case at its --quick size (minutes)
    python benchmarks/gpu.py --only dem_throughput ste --precision float32

Each case runs in a process of its own (a clean device and compilation state) on JAX's default device, in float64
and, where single precision makes sense (the DEM's explicit steps, the STE's estimate), in float32 too
(``JAXBPM_BENCH_X64=0``). Results go to ``results/gpu/<case>_<precision>.json`` (``--out-dir``); the summary
``results/gpu/summary.json`` lists every case with its status, wall time and the CPU result file it should be read
beside (``results/<case>.json``). A case that fails is recorded with its error's tail and the rest go on.

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
    ap.add_argument("--timeout", type=float, default=3600.0, help="seconds per case and precision")
    ap.add_argument("--allow-cpu", action="store_true", help="run even where JAX's default device is not a GPU")
    ap.add_argument("--dry-run", action="store_true", help="print the commands only")
    args = ap.parse_args(argv)
    from _common import table, write_json

    device = _device()
    if device["platform"] != "gpu" and not (args.allow_cpu or args.dry_run):
        sys.exit(f"JAX's default device is {device['platform']} ({device['device']}), not a GPU: install the CUDA "
                 "wheels (pip install -e '.[cuda]') or pass --allow-cpu")
    os.makedirs(args.out_dir, exist_ok=True)
    rows = []
    for case in args.only:
        script, extra, precisions = CASES[case]
        for precision in (p for p in args.precision if p in precisions):
            out = os.path.join(args.out_dir, f"{case}_{precision}.json")
            cmd = [sys.executable, os.path.join(HERE, script)] + (["--quick"] if args.quick else extra)
            cmd += ["--out", out]
            env = dict(os.environ, JAXBPM_BENCH_X64="1" if precision == "float64" else "0")
            print(f"== {case} ({precision}): {' '.join(cmd[1:])}", flush=True)
            if args.dry_run:
                continue
            t0 = time.perf_counter()
            try:
                done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=args.timeout)
                status, tail = ("ok" if done.returncode == 0 else f"exit {done.returncode}"), done.stderr[-2000:]
                print(done.stdout[-4000:], flush=True)
            except subprocess.TimeoutExpired as exc:
                status, tail = "timeout", (exc.stderr or b"")[-2000:].decode(errors="replace")
            wall = time.perf_counter() - t0
            if status != "ok":
                print(f"   {status}:\n{tail}", flush=True)
            cpu = os.path.join("results", f"{case}.json")
            rows.append({"case": case, "precision": precision, "status": status, "wall_s": wall, "out": out,
                         "cpu_result": cpu if os.path.exists(cpu) else None,
                         "error": None if status == "ok" else tail})
    if args.dry_run:
        return 0
    print()
    table(rows, ["case", "precision", "status", "wall_s", "out", "cpu_result"])
    write_json(os.path.join(args.out_dir, "summary.json"),
               {"benchmark": "gpu", "device": device, "quick": args.quick, "cases": rows})
    print(f"wrote {os.path.join(args.out_dir, 'summary.json')}")
    return 0 if all(r["status"] == "ok" for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
