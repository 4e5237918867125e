#!/usr/bin/env python
"""Size classes: how many compilations a series of samples of about the same size costs, per solver.

Usage::

    python benchmarks/size_classes.py                                   # the goal: 20 samples, n in [2500, 3500]
    python benchmarks/size_classes.py --quick --methods ste dsm         # a smoke run: 3 samples, n in [400, 600]

Goal (from the issue): 20 samples ``jaxbpm.generate.box(n, seed=s)`` (largest cluster) with ``n`` drawn uniformly
between 2500 and 3500 cost at most 3 compilations per method in all -- cache misses are counted, not timed.

What is measured
----------------
``--count`` values ``n`` are drawn uniformly in ``[--low, --high]`` (``numpy.random.default_rng(--seed)``), sample
``k`` (1-based) is ``generate.box(n_k, seed=k).largest_cluster()``, generated once and kept in ``--sample-cache``
(:func:`_common.cached_box`). Scene: ``UniaxialCompression(axis=2, strain=0.002)``. For every method (``--methods``)
the samples are solved in order, in this one process, each inside ``jaxbpm.count_compilations()``: ``compilations``
is the number of XLA programs JAX lowered during the call (the setup's small programs and the eager operations
included; see :func:`jaxbpm._compile.compile_clock`), ``compile_s`` the time spent on them. No persistent compilation
cache is used unless ``--cache-dir`` is given (a read from it would count as a lowering too, but not cost a compile).

Beside the count, every compiled program is attributed:

* ``new_programs``: the module-level compiled functions of ``jaxbpm`` that gained an executable during the call
  (``Program.compilations`` of :class:`jaxbpm._compile.Program`, the cache size of plain ``jax.jit`` functions);
* ``compiled``: every program JAX lowered (its name from JAX's ``jax_log_compiles`` record) with the innermost
  ``jaxbpm`` source line on the stack when it was lowered (``file:line (function)``): this also names eager
  operations and functions jitted inside other functions.

The size class of a sample is ``Result.stats["size_class"]`` where the solver reports it (STE, DSM), else
:func:`jaxbpm._compile.size_class` of its particle and bond counts. The first sample of a method also compiles the
one-off programs every solve needs; a later sample should compile only when its size class is new. Reported per
method: the lowerings of all samples, of the samples after the first, how many samples compiled at all, the distinct
size classes, the compilations of the solver's size-dependent program(s) (``ste.scene.solve_program``,
``dsm.linear.linear_program``, ``dem.chunk._run_chunk``), and the samples that compiled although their size class had been seen
(with what compiled, and where). The goal is met when the solver's size-dependent program compiled at most
``--limit`` (3) times; the table also says whether the samples after the first compiled only on new size classes.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import time
import traceback

from _common import cached_box, enable_x64, machine_info, machine_load, pin, table, write_json

METHODS = ("ste", "dsm", "dem")
STRAIN = 0.002
# the compiled programs that depend on the size class, per method (module-level names)
SOLVER_PROGRAMS = {"ste": ("jaxbpm.ste.scene.solve_program",),
                   "dsm": ("jaxbpm.dsm.linear.linear_program", "jaxbpm.dsm.linear.contacts_program"),
                   "dem": ("jaxbpm.dem.chunk._run_chunk",)}
_HERE = os.path.dirname(os.path.abspath(__file__))


def log(msg):
    print(msg, file=sys.stderr, flush=True)


# ============================================================================================ what compiled, where
class CompileLog(logging.Handler):
    """Collects JAX's "Compiling <name> ..." records (``jax_log_compiles``) with the innermost ``jaxbpm`` frame of
    the stack at that moment (the lowering runs synchronously in the caller's thread)."""

    LOGGER = "jax._src.interpreters.pxla"

    def __init__(self, root: str):
        super().__init__(logging.DEBUG)
        self.root = root  # the jaxbpm package directory
        self.records: list[dict] = []

    def emit(self, record):
        msg = record.getMessage()
        if not msg.startswith("Compiling "):
            return
        name = msg[len("Compiling "):].split(" ", 1)[0]
        at, outer = None, None
        for fr in reversed(traceback.extract_stack()):
            if fr.filename.startswith(self.root):
                where = f"{os.path.relpath(fr.filename, os.path.dirname(self.root))}:{fr.lineno} ({fr.name})"
                if at is None and os.path.basename(fr.filename) != "_compile.py":  # Program's caller, not Program
                    at = where
                outer = where
        self.records.append({"name": name, "at": at, "entry": outer})

    def install(self):
        import jax

        jax.config.update("jax_log_compiles", True)
        logger = logging.getLogger(self.LOGGER)
        logger.addHandler(self)
        logger.setLevel(logging.DEBUG)
        logger.propagate = False  # no WARNING lines on stderr: the records go to the report
        # jax_log_compiles also raises JAX's timing and persistent-cache lines to WARNING: keep them off stderr
        for name in ("jax._src.dispatch", "jax._src.compiler", "jax._src.compilation_cache"):
            logging.getLogger(name).addFilter(_quiet_compile_logs)

    def take(self) -> list[dict]:
        out, self.records = self.records, []
        return out


def _quiet_compile_logs(record) -> bool:
    """False (drop) for the records ``jax_log_compiles`` raises to WARNING: timings, persistent-cache hits and misses."""
    if record.levelno != logging.WARNING:
        return True
    msg = record.getMessage()
    return not (msg.startswith("Finished ") or "cache" in msg.lower())


def program_counts() -> dict[str, int]:
    """``{"module.name": executables}`` for every module-level compiled function of the loaded ``jaxbpm`` modules."""
    from jaxbpm._compile import Program

    counts = {}
    for mod_name, mod in list(sys.modules.items()):
        if not mod_name.startswith("jaxbpm") or mod is None:
            continue
        for attr, obj in list(vars(mod).items()):
            key = f"{mod_name}.{attr}"
            try:
                if isinstance(obj, Program) and getattr(obj.fn, "__module__", None) == mod_name:  # (not imports)
                    counts[key] = obj.compilations
                elif callable(getattr(obj, "_cache_size", None)) and getattr(obj, "__module__", None) == mod_name:
                    counts[key] = int(obj._cache_size())
            except Exception:  # noqa: BLE001 - an odd object is not worth failing the benchmark for
                continue
    return counts


def grown(before: dict, after: dict) -> dict[str, int]:
    return {k: v - before.get(k, 0) for k, v in sorted(after.items()) if v > before.get(k, 0)}


# ================================================================================================ measurement
def solve_all(jaxbpm, method, samples, scene, clog):
    """Solve every sample with ``method`` in order; one row per sample."""
    from jaxbpm._compile import size_class

    rows, seen = [], set()
    for k, (spec, sample) in enumerate(samples):
        before = program_counts()
        clog.take()
        t = time.perf_counter()
        with jaxbpm.count_compilations() as c:
            r = jaxbpm.solve(sample, scene, method=method)
        call = time.perf_counter() - t
        compiled = clog.take()
        new = grown(before, program_counts())
        nc = sample.n_particles, sample.n_bonds
        reported = r.stats.get("size_class")
        cls = tuple(int(v) for v in reported) if reported is not None else tuple(size_class(*nc))
        new_class = cls not in seen
        seen.add(cls)
        solver = sum(new.get(p, 0) for p in SOLVER_PROGRAMS[method])
        row = {"sample": k + 1, "seed": spec["seed"], "n": spec["n"], "particles": nc[0], "bonds": nc[1],
               "bonds_per_particle": nc[1] / max(nc[0], 1), "size_class": list(cls),
               "size_class_from": "stats" if reported is not None else "size_class(n, nb)",
               "new_class": new_class, "compilations": c.count, "compile_s": c.seconds,
               "solver_compilations": solver, "result_compile_s": r.compile_time, "setup_s": r.setup_time,
               "run_s": r.run_time, "wall_s": r.wall_time, "call_s": call, "stiffness": r.stiffness,
               "new_programs": new, "compiled": compiled,
               "unexpected": bool(k > 0 and not new_class and c.count > 0)}
        rows.append(row)
        flag = "  <-- compiled on a seen size class" if row["unexpected"] else ""
        log(f"  {method} sample {k + 1:2d}: n={nc[0]} bonds={nc[1]} class={list(cls)} compilations={c.count} "
            f"({c.seconds:.2f} s) wall {r.wall_time:.2f} s{flag}")
    return rows


def summarize(method, rows, limit):
    later = rows[1:]
    classes = {tuple(r["size_class"]) for r in rows}
    solver = sum(r["solver_compilations"] for r in rows)
    unexpected = [r["sample"] for r in rows if r["unexpected"]]
    return {"method": method, "samples": len(rows),
            "lowerings_total": sum(r["compilations"] for r in rows),
            "lowerings_first": rows[0]["compilations"] if rows else 0,
            "lowerings_after_first": sum(r["compilations"] for r in later),
            "samples_compiling": sum(1 for r in rows if r["compilations"] > 0),
            "distinct_size_classes": len(classes), "size_classes": sorted(list(c) for c in classes),
            "solver_programs": list(SOLVER_PROGRAMS[method]), "solver_compilations": solver,
            "compile_s_total": sum(r["compile_s"] for r in rows),
            "compile_s_after_first": sum(r["compile_s"] for r in later),
            "unexpected_samples": unexpected,
            "later_only_on_new_class": not unexpected,
            "limit": limit, "goal_met": solver <= limit}


# ================================================================================================ main
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--count", type=int, default=20, help="samples")
    ap.add_argument("--low", type=int, default=2500, help="smallest requested n")
    ap.add_argument("--high", type=int, default=3500, help="largest requested n (inclusive)")
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    ap.add_argument("--seed", type=int, default=0, help="seed of the RNG drawing n (the samples use seeds 1..count)")
    ap.add_argument("--limit", type=int, default=3, help="the goal: at most this many solver compilations per method")
    ap.add_argument("--sample-cache", default="results/samples", help="samples saved here and reused ('' : none)")
    ap.add_argument("--cache-dir", default=None,
                    help="turn JAX's persistent compilation cache on in this directory (default: off, every "
                         "compilation a real miss)")
    ap.add_argument("--threads", type=int, default=1, help="cores (XLA threads); 1 pins to one core")
    ap.add_argument("--cpu", type=int, default=None, help="core to pin to with one thread (default: the least busy)")
    ap.add_argument("--out", default=None, help="JSON report (default results/size_classes.json; "
                                                "results/size_classes_quick.json with --quick)")
    ap.add_argument("--quick", action="store_true", help="smoke run: --count 3, n in [400, 600]")
    args = ap.parse_args(argv)
    if args.quick:
        args.count, args.low, args.high = 3, 400, 600
    if args.out is None:
        args.out = "results/size_classes_quick.json" if args.quick else "results/size_classes.json"
    if args.low > args.high or args.count < 1:
        ap.error("need --count >= 1 and --low <= --high")

    if not args.cache_dir:  # JAX reads this variable itself: no persistent cache unless asked for
        os.environ.pop("JAX_COMPILATION_CACHE_DIR", None)
    load_before = machine_load(1.0)
    cpu = pin(args.cpu, args.threads)
    log(f"pinned to core {cpu}, {args.threads} thread(s); core load before: {load_before['cpu_busy']}")
    enable_x64()
    import numpy as np

    import jaxbpm

    if args.cache_dir:
        jaxbpm.enable_compilation_cache(args.cache_dir)
    cache = jaxbpm.compilation_cache_dir()
    clog = CompileLog(os.path.dirname(os.path.abspath(jaxbpm.__file__)))
    clog.install()

    t_start = time.time()
    ns = np.random.default_rng(args.seed).integers(args.low, args.high, size=args.count, endpoint=True)
    samples, sample_rows = [], []
    for k, n in enumerate(ns.tolist()):
        t = time.perf_counter()
        sample, source = cached_box(int(n), k + 1, args.sample_cache or None)
        spec = {"n": int(n), "seed": k + 1}
        samples.append((spec, sample))
        sample_rows.append({**spec, "particles": sample.n_particles, "bonds": sample.n_bonds, "source": str(source),
                            "seconds": time.perf_counter() - t})
        log(f"sample {k + 1}/{args.count}: box({n}, seed={k + 1}) -> {sample.n_particles} particles, "
            f"{sample.n_bonds} bonds ({time.perf_counter() - t:.1f} s, {source})")
    clog.take()  # (what generating or loading compiled is not the solvers')

    scene = jaxbpm.scenes.UniaxialCompression(axis=2, strain=STRAIN)
    report = {"benchmark": "size_classes", "complete": False, "settings": vars(args), "draws": ns.tolist(),
              "scene": f"UniaxialCompression(axis=2, strain={STRAIN})", "samples": sample_rows,
              "persistent_cache": None if cache is None else str(cache), "runs": {}, "summary": {}}

    def save():
        write_json(args.out, report)

    for m in args.methods:
        log(f"{m}: {args.count} samples ...")
        t = time.perf_counter()
        rows = solve_all(jaxbpm, m, samples, scene, clog)
        report["runs"][m] = rows
        report["summary"][m] = dict(summarize(m, rows, args.limit), seconds=time.perf_counter() - t)
        save()

    load_after = machine_load(1.0)
    report.update(complete=True, total_time_s=time.time() - t_start,
                  machine={**machine_info(), "pinned_core": cpu, "load_before": load_before,
                           "load_after": load_after})
    save()

    for m in args.methods:
        print(f"\n{m}: UniaxialCompression(axis=2, strain={STRAIN}), {args.count} samples, n in "
              f"[{args.low}, {args.high}]")
        rows = [dict(r, size_class="x".join(str(v) for v in r["size_class"]) + ("" if r["new_class"] else " (seen)"),
                     solver=r["solver_compilations"]) for r in report["runs"][m]]
        table(rows, ["sample", "n", "particles", "bonds", "size_class", "compilations", "solver", "compile_s",
                     "wall_s", "stiffness"])
    print(f"\nSummary (goal: at most {args.limit} compilations of the solver's size-dependent program per method; "
          "lowerings = every XLA program built, setup and eager operations included)")
    srows = []
    for m in args.methods:
        s = report["summary"][m]
        srows.append({"method": m, "lowerings": s["lowerings_total"], "first": s["lowerings_first"],
                      "after_first": s["lowerings_after_first"], "samples_compiling": s["samples_compiling"],
                      "size_classes": s["distinct_size_classes"], "solver_compilations": s["solver_compilations"],
                      "compile_s": s["compile_s_total"],
                      "only_new_classes": "yes" if s["later_only_on_new_class"] else
                      "no: " + ",".join(map(str, s["unexpected_samples"])),
                      "goal_met": f"yes ({s['solver_compilations']} <= {args.limit})" if s["goal_met"]
                      else f"NO ({s['solver_compilations']} > {args.limit})"})
    table(srows, ["method", "lowerings", "first", "after_first", "samples_compiling", "size_classes",
                  "solver_compilations", "compile_s", "only_new_classes", "goal_met"])
    for m in args.methods:
        for r in report["runs"][m]:
            if r["unexpected"]:
                print(f"\n{m} sample {r['sample']} (class {r['size_class']}, seen before) compiled "
                      f"{r['compilations']} program(s): new executables {r['new_programs'] or '-'}")
                for c in r["compiled"]:
                    print(f"    {c['name']:<40s} at {c['at']}  (entered at {c['entry']})")
    print(f"\nmachine load (busy fraction per core) before {load_before['cpu_busy']} after {load_after['cpu_busy']}; "
          f"pinned to core {cpu}; persistent compilation cache: {cache or 'off'}")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
