"""A DEM run set spread over a Dask cluster: wall time against the same runs one after another, and a run set killed
halfway that resumes.

The run set: ``--runs`` Latin-hypercube parameter sets (bond tensile and shear strength) of a UCS test to failure on
a small bonded cylinder (``--particles``; bonds, Hertz contacts and breakage: a surrogate's training set for a
strength calibration). Three parts, each in its own process so that none borrows another's compiled programs:

1. serial: ``run_set(problem, N)`` in one process (its first run compiles);
2. Dask: the same call with ``Problem(..., executor=Client(LocalCluster(n_workers=W)).get_executor())``; each
   worker compiles once (the cluster's start-up is reported apart); the outputs must equal the serial ones exactly;
3. resume: the serial run set with a file, killed (SIGKILL) once half its runs are stored, then called again: the
   runs it solves on the second call are counted.

Goal (issue "scale"): on a 2-worker LocalCluster, <= 0.6x the serial wall time; the resumed run set repeats none of
the stored runs.

    python benchmarks/parallel_runs.py [--runs 32] [--workers 2] [--particles 250] [--quick]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(__file__))
from _common import machine_info, table, write_json  # noqa: E402


def _problem(particles: int, executor=None):
    import numpy as np

    import jaxbpm
    from jaxbpm.calibrate import Parameter, ParameterSpace, Problem, Target
    from jaxbpm.calibrate.objective import base_params, forward_model
    from jaxbpm.scenes import UniaxialCompression

    mats = {"E": 1e9, "nu": 0.25, "tensile_strength": 4e6, "shear_strength": 8e6}
    cyl = jaxbpm.generate.cylinder(particles, seed=0, packing_fraction=0.5, materials=mats).largest_cluster()
    keys = ["bond_tensile_strength", "bond_shear_strength"]
    base = base_params(cyl, keys)
    space = ParameterSpace([Parameter("bond_tensile_strength", bounds=(2e6, 8e6)),
                            Parameter("bond_shear_strength", bounds=(4e6, 16e6))], {k: base[k] for k in keys})
    fwd = forward_model(cyl, {"ucs": UniaxialCompression.to_failure(strain=0.02)}, "dem", transits=30)
    targets = [Target(o, 1.0, scene="ucs") for o in ("strength", "peak_force")]
    return Problem(fwd, targets, space, executor=executor), cyl, np


def _part(args) -> dict:
    """One part, in this (fresh) process; prints a JSON line."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxbpm
    from jaxbpm.calibrate import run_set

    jaxbpm.enable_compilation_cache(args.cache)
    t_start = time.perf_counter()
    if args.part == "dask":
        from distributed import Client, LocalCluster

        cluster = LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=40)
        client = Client(cluster)
        startup = time.perf_counter() - t_start
        problem, cyl, np = _problem(args.particles, client.get_executor())
    else:
        startup = 0.0
        problem, cyl, np = _problem(args.particles)
    t0 = time.perf_counter()
    runs = run_set(problem, args.runs, seed=0, path=args.path)
    wall = time.perf_counter() - t0
    if args.part == "dask":
        client.close()
        cluster.close()
    print(json.dumps({"part": args.part, "wall_s": wall, "startup_s": startup, "Y": runs.Y.tolist(),
                      "resumed": runs.info["resumed"], "particles": cyl.n_particles, "bonds": cyl.n_bonds}),
          flush=True)
    return {}


def _run_part(args, part, path=None, cache=None) -> dict:
    cmd = [sys.executable, __file__, "--part", part, "--runs", str(args.runs), "--workers", str(args.workers),
           "--particles", str(args.particles), "--cache", cache or tempfile.mkdtemp(prefix="jaxbpm-bench-xla-")]
    if path:
        cmd += ["--path", path]
    t0 = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode:
        sys.exit(f"the {part} part failed:\n{done.stderr[-3000:]}")
    out = done.stdout
    row = json.loads(out.strip().splitlines()[-1])
    row["process_s"] = time.perf_counter() - t0
    return row


def _killed_halfway(args, path: str) -> int:
    """Start the serial run set with a file and SIGKILL it once half its runs are stored; the runs stored."""
    from jaxbpm.calibrate.runs import RunSet

    cmd = [sys.executable, __file__, "--part", "serial", "--runs", str(args.runs), "--particles",
           str(args.particles), "--cache", tempfile.mkdtemp(prefix="jaxbpm-bench-xla-"), "--path", path]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    stored = 0
    while proc.poll() is None:
        time.sleep(0.2)
        try:
            stored = int(RunSet.load(path, partial=True).done.sum()) if os.path.exists(path) else 0
        except Exception:  # noqa: BLE001 - the file is being replaced; look again
            continue
        if stored >= args.runs // 2:
            proc.send_signal(signal.SIGKILL)
            proc.wait()
            break
    return int(RunSet.load(path, partial=True).done.sum())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=32)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--particles", type=int, default=250)
    ap.add_argument("--quick", action="store_true", help="8 runs on 150 particles")
    ap.add_argument("--out", default="results/parallel_runs.json")
    ap.add_argument("--part", choices=["serial", "dask"], help=argparse.SUPPRESS)
    ap.add_argument("--path", help=argparse.SUPPRESS)
    ap.add_argument("--cache", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.part:
        return _part(args)
    if args.quick:
        args.runs, args.particles = 8, 150
        if args.out == "results/parallel_runs.json":
            args.out = "results/parallel_runs_quick.json"
    import numpy as np

    print(f"{args.runs} DEM runs (UCS to failure, ~{args.particles} particles); serial vs {args.workers}-worker "
          "Dask LocalCluster", flush=True)
    serial = _run_part(args, "serial")
    print(f"serial: {serial['wall_s']:.1f} s", flush=True)
    dask = _run_part(args, "dask")
    print(f"dask: {dask['wall_s']:.1f} s (+ {dask['startup_s']:.1f} s cluster start-up)", flush=True)
    equal = bool(np.array_equal(np.asarray(serial["Y"]), np.asarray(dask["Y"])))
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "runs.h5")
        stored = _killed_halfway(args, path)
        resumed = _run_part(args, "serial", path=path)
    resumed_equal = bool(np.array_equal(np.asarray(serial["Y"]), np.asarray(resumed["Y"])))
    rows = [{"part": "serial", "wall_s": serial["wall_s"], "ratio": 1.0},
            {"part": f"dask {args.workers} workers", "wall_s": dask["wall_s"],
             "ratio": dask["wall_s"] / serial["wall_s"], "startup_s": dask["startup_s"]},
            {"part": f"resumed after kill ({stored} stored)", "wall_s": resumed["wall_s"],
             "ratio": resumed["wall_s"] / serial["wall_s"], "solved": args.runs - resumed["resumed"]}]
    table(rows, ["part", "wall_s", "ratio", "startup_s", "solved"])
    print(f"dask outputs == serial outputs: {equal}; resumed outputs == serial: {resumed_equal}; "
          f"runs repeated on resume: {args.runs - resumed['resumed'] - (args.runs - stored)}")
    write_json(args.out, {"benchmark": "parallel_runs", "machine": machine_info(), "settings": vars(args),
                          "particles": serial["particles"], "bonds": serial["bonds"], "results": rows,
                          "dask_equals_serial": equal, "resumed_equals_serial": resumed_equal,
                          "stored_before_kill": stored, "solved_on_resume": args.runs - resumed["resumed"],
                          "goal_ratio": 0.6, "goal_met": bool(dask["wall_s"] <= 0.6 * serial["wall_s"])})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
