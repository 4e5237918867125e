"""Shared helpers of the benchmark scripts: thread pinning, x64, atomic JSON output, a results table."""

from __future__ import annotations

import os
import platform
import sys
import time


def pin_threads(threads: int | None) -> None:
    """Restrict this process (and XLA) to ``threads`` CPU cores; call before importing jax."""
    if not threads:
        return
    if hasattr(os, "sched_setaffinity"):
        cores = sorted(os.sched_getaffinity(0))[:threads]
        os.sched_setaffinity(0, cores)
    flags = os.environ.get("XLA_FLAGS", "")
    if threads == 1 and "multi_thread_eigen" not in flags:
        os.environ["XLA_FLAGS"] = (flags + " --xla_cpu_multi_thread_eigen=false").strip()
    os.environ.setdefault("OMP_NUM_THREADS", str(threads))


def enable_x64():
    """float64 (the default of every benchmark); ``JAXBPM_BENCH_X64=0`` leaves JAX in float32 (``benchmarks/gpu.py``
    runs the cases where single precision makes sense both ways)."""
    import jax

    if os.environ.get("JAXBPM_BENCH_X64", "1") != "0":
        jax.config.update("jax_enable_x64", True)
    return jax


def machine_info() -> dict:
    import jax

    dev = jax.devices()[0]
    return {"python": platform.python_version(), "jax": jax.__version__, "platform": dev.platform,
            "device": getattr(dev, "device_kind", str(dev)), "cpu_count": os.cpu_count(),
            "affinity": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
            "xla_flags": os.environ.get("XLA_FLAGS", ""),
            "precision": "float64" if jax.config.jax_enable_x64 else "float32"}


def peak_rss_gib() -> float | None:
    """This process's peak resident set so far [GiB] (the high-water mark: cases run in one process in increasing
    size report what the largest so far needed); ``None`` where the platform does not say."""
    try:
        import resource
    except ImportError:  # Windows
        return None
    kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return kib / 2**20 if sys.platform != "darwin" else kib / 2**30  # Linux: KiB, macOS: bytes


def device_peak_gib() -> float | None:
    """The peak memory in use on JAX's default device so far [GiB], where that device is an accelerator that says
    (GPUs do); ``None`` on the CPU (its figure is ``peak_rss_gib``) or where JAX has not been imported."""
    jax = sys.modules.get("jax")
    if jax is None:
        return None
    try:
        dev = jax.devices()[0]
        stats = dev.memory_stats() if dev.platform != "cpu" else None
    except Exception:  # a backend without memory statistics
        return None
    peak = (stats or {}).get("peak_bytes_in_use")
    return None if peak is None else peak / 2**30


# spans that hold other spans (Python frames, the executor, loops, conditionals, whole programs)
_PROFILE_CONTAINERS = ("$", "ThunkExecutor", "while", "conditional", "PjitFunction", "CommonPjRt", "PjRt")


def profile_top(trace_dir: str, steps: int, top: int = 25) -> list[dict]:
    """The ``top`` operations that took longest in the trace JAX's profiler wrote under ``trace_dir``
    (``jax.profiler.trace(..., create_perfetto_trace=True)``): XLA's fusions and thunks on the CPU, the kernels on a
    GPU; Python frames and the executor's own spans left out. Each with its total per step (the trace covers
    ``steps`` steps) and how often it ran per step."""
    import collections
    import glob
    import gzip
    import json

    files = glob.glob(os.path.join(trace_dir, "**", "*.trace.json.gz"), recursive=True)
    if not files:
        return []
    with gzip.open(max(files, key=os.path.getmtime)) as fh:
        events = json.load(fh).get("traceEvents", [])
    total, count = collections.Counter(), collections.Counter()
    for e in events:
        name = e.get("name", "")
        if e.get("ph") != "X" or name.startswith(_PROFILE_CONTAINERS):
            continue
        total[name] += e.get("dur", 0.0)
        count[name] += 1
    return [{"name": name, "ms_per_step": t / 1e3 / steps, "calls_per_step": count[name] / steps}
            for name, t in total.most_common(top)]


def write_json(path, data):
    """Write ``data`` as JSON atomically (temporary file, then rename): never a half-written result. Adds the
    process's peak resident set (``peak_rss_gib``) where ``data`` is a dict without one, and on an accelerator the
    device's peak memory in use (``device_peak_gib``)."""
    from jaxbpm.io import write_json as _write

    if isinstance(data, dict) and "peak_rss_gib" not in data:
        data = {**data, "peak_rss_gib": peak_rss_gib()}
    if isinstance(data, dict) and "device_peak_gib" not in data:
        dev_peak = device_peak_gib()
        if dev_peak is not None:
            data = {**data, "device_peak_gib": dev_peak}
    return _write(path, data)


def table(rows: list[dict], columns: list[str], file=sys.stdout) -> None:
    """Print rows as an aligned text table."""
    def fmt(v):
        if isinstance(v, float):
            return f"{v:.4g}"
        return str(v)

    cells = [[fmt(r.get(c, "")) for c in columns] for r in rows]
    widths = [max(len(c), *(len(row[k]) for row in cells)) for k, c in enumerate(columns)]
    print("  ".join(c.rjust(w) for c, w in zip(columns, widths)), file=file)
    for row in cells:
        print("  ".join(v.rjust(w) for v, w in zip(row, widths)), file=file)


def save_png(fig, path, note: str | None = None, dpi: int = 130):
    """Lay out ``fig`` (with ``note``, e.g. the machine, in small print at the bottom), write it to ``path``
    atomically (never a half-written image) and close it. Returns the path."""
    import matplotlib.pyplot as plt

    from jaxbpm.io import atomic_write

    if note:
        fig.text(0.01, 0.005, note, fontsize=6.5, alpha=0.8)
    fig.tight_layout(rect=(0, 0.03, 1, 1) if note else None)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format="png"))
    plt.close(fig)
    return path


# ---------------------------------------------------------------------------------------------------- machine load
def cpu_busy(interval: float = 1.0) -> list[float]:
    """Busy fraction of every core over ``interval`` seconds (from /proc/stat); [] where unavailable."""
    def read():
        rows = {}
        try:
            with open("/proc/stat") as f:
                for line in f:
                    if line.startswith("cpu") and line[3].isdigit():
                        name, *vals = line.split()
                        vals = [int(v) for v in vals]
                        idle = vals[3] + (vals[4] if len(vals) > 4 else 0)
                        rows[int(name[3:])] = (sum(vals), idle)
        except OSError:
            pass
        return rows

    a = read()
    time.sleep(interval)
    b = read()
    return [round(1.0 - (b[k][1] - a[k][1]) / max(b[k][0] - a[k][0], 1), 3) for k in sorted(b) if k in a]


def machine_load(interval: float = 1.0) -> dict:
    load = {"cpu_busy": cpu_busy(interval)}
    if hasattr(os, "getloadavg"):
        load["loadavg"] = [round(x, 2) for x in os.getloadavg()]
    return load


def pin(cpu, threads):
    """Pin to ``threads`` cores; with one thread to core ``cpu`` (default: the least busy core)."""
    if threads == 1 and hasattr(os, "sched_setaffinity"):
        allowed = sorted(os.sched_getaffinity(0))
        if cpu is None:
            busy = cpu_busy(1.0)
            cpu = min(allowed, key=lambda c: busy[c] if c < len(busy) else 1.0)
        os.sched_setaffinity(0, {cpu})
    pin_threads(threads)
    return cpu


def cached_box(n: int, seed: int = 0, cache_dir: str | None = None):
    """``(sample, source)``: ``jaxbpm.generate.box(n, seed).largest_cluster()``, read from / saved to
    ``<cache_dir>/box_<n>_seed<seed>.h5`` when ``cache_dir`` is given (call after enabling x64)."""
    import jaxbpm

    path = os.path.join(cache_dir, f"box_{n}_seed{seed}.h5") if cache_dir else None
    if path and os.path.exists(path):
        return jaxbpm.io.load_sample(path), path
    sample = jaxbpm.generate.box(n, seed=seed).largest_cluster()
    if path:
        os.makedirs(cache_dir, exist_ok=True)
        jaxbpm.io.save_sample(path, sample)
    return sample, f"generate.box({n}, seed={seed}).largest_cluster()"


def foreign_packing(n: int, seed: int, path: str, *, slab: float = 0.08, gap: float = 0.05) -> dict:
    """Write a bonded random packing made WITHOUT jaxbpm to a LAMMPS data file, as a sample from another code arrives.

    ``n`` spheres (radii uniform in [0.8, 1.2] mm) at random places in a cube sized for a solid fraction of 0.55, their
    overlaps relaxed away by a plain NumPy/SciPy push-apart loop (not :mod:`jaxbpm.generate`), bonds between the pairs
    closer than ``gap`` x the smaller radius, particles in a random order. Atom types mark the groups, as LAMMPS's
    ``region`` + ``group`` would: 2 for the particles whose centre is within ``slab`` x the height of the lowest
    centre, 3 within it of the highest, 1 elsewhere. Written ``atom_style bpm/sphere``, ``units si``, without
    ``Bond Coeffs`` (read it with a bond radius ratio and a material table).

    Args:
      n: spheres.
      seed: the random seed.
      path: the data file to write.
      slab: the depth of the end groups, a fraction of the height.
      gap: the bonding distance, a fraction of the smaller radius.

    Returns:
      ``{"particles", "bonds", "types": counts per type, "seconds"}``.
    """
    import numpy as np
    from scipy.spatial import cKDTree

    t = time.perf_counter()
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.8e-3, 1.2e-3, n)
    side = (4.0 / 3.0 * np.pi * np.sum(r**3) / 0.55) ** (1.0 / 3.0)
    x = rng.uniform(0.0, side, (n, 3))
    for _ in range(400):  # push overlapping pairs apart along their line of centres, walls keep the spheres inside
        i, j = cKDTree(x).query_pairs(2.0 * r.max(), output_type="ndarray").T
        d = x[j] - x[i]
        dist = np.linalg.norm(d, axis=1)
        over = r[i] + r[j] - dist
        hit = over > 1e-4 * r.min()
        if not hit.any():
            break
        push = 0.5 * (over[hit] / dist[hit])[:, None] * d[hit]
        move = np.zeros_like(x)
        np.add.at(move, i[hit], -push)
        np.add.at(move, j[hit], push)
        x = np.clip(x + move, r[:, None], side - r[:, None])
    i, j = cKDTree(x).query_pairs(2.0 * r.max() * (1 + gap), output_type="ndarray").T
    dist = np.linalg.norm(x[j] - x[i], axis=1)
    bonded = dist < r[i] + r[j] + gap * np.minimum(r[i], r[j])
    bonds = np.stack([i[bonded], j[bonded]], axis=1)
    # keep the largest bonded cluster (a packing made for a test is one body), in a random order
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    _, label = connected_components(coo_matrix((np.ones(len(bonds)), bonds.T), shape=(n, n)), directed=False)
    keep = label == np.bincount(label).argmax()
    order = rng.permutation(np.flatnonzero(keep))
    new = np.full(n, -1)
    new[order] = np.arange(len(order))
    x, r = x[order], r[order]
    bonds = new[bonds[keep[bonds].all(axis=1)]]
    z = x[:, 2]
    height = z.max() - z.min()
    types = np.ones(len(x), int)
    types[z <= z.min() + slab * height] = 2
    types[z >= z.max() - slab * height] = 3
    lo, hi = (x - r[:, None]).min(axis=0), (x + r[:, None]).max(axis=0)
    lines = ["LAMMPS data file: a bonded random packing (push-apart relaxation), groups as atom types", "",
             f"{len(x)} atoms", "3 atom types", f"{len(bonds)} bonds", "1 bond types", ""]
    lines += [f"{float(a)!r} {float(b)!r} {c}lo {c}hi" for a, b, c in zip(lo, hi, "xyz")]
    lines += ["", "Atoms # bpm/sphere", ""]
    lines += [f"{k + 1} 1 {types[k]} {float(2 * r[k])!r} 2500.0 " + " ".join(repr(float(c)) for c in x[k])
              for k in range(len(x))]
    lines += ["", "Bonds", ""]
    lines += [f"{k + 1} 1 {a + 1} {b + 1}" for k, (a, b) in enumerate(bonds)]
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    return {"particles": len(x), "bonds": len(bonds), "types": {int(k): int((types == k).sum()) for k in (1, 2, 3)},
            "seconds": time.perf_counter() - t}


def read_foreign_packing(path):
    """``(sample, seconds)``: the packing of :func:`foreign_packing` read from its LAMMPS data file as a user would
    (``read_lammps_data`` with a bond radius ratio of 0.5 and bonds of E 1 GPa, nu 0.25; the file has no coefficients).
    Call after enabling x64."""
    import jaxbpm.interop.formats

    t = time.perf_counter()
    sample = jaxbpm.interop.formats.read_lammps_data(path, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})
    return sample, time.perf_counter() - t
