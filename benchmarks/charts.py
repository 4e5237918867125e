"""Charts of the benchmark results for docs/benchmarks.md.

Reads the JSON files under ``results/`` that the benchmark scripts wrote (only those present: a chart whose files
are all missing is skipped, a series whose file is missing is left out) and writes one PNG per chart under
``docs/img/``. Every chart names its source files in :data:`SOURCES`, which the page repeats beside it.

    python benchmarks/charts.py                       # results/ -> docs/img/
    python benchmarks/charts.py --results R --out D   # elsewhere

Plain matplotlib objects (``matplotlib.figure.Figure`` on the Agg canvas), no pyplot state.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

ROOT = Path(__file__).resolve().parent.parent

#: chart name -> the results files it reads (relative to the results directory)
SOURCES = {
    "dem_throughput": ["dem_throughput_3k_100k_1core.json", "dem_throughput_scaling_10k_1m_1core.json",
                       "dem_throughput_1m_contacts_1core.json", "gpu/dem_throughput_float64.json",
                       "gpu/dem_throughput_1m_float64.json", "gpu/dem_throughput_float32.json",
                       "gpu/dem_throughput_1m_float32.json"],
    "vs_lammps": ["vs_lammps.json", "vs_lammps_contacts_8k.json", "vs_lammps_contacts_100k.json"],
    "solver_scaling": ["scaling_10k_1m.json", "gpu/scaling_float64.json"],
}


def _load(results: Path, name: str):
    path = results / name
    return json.loads(path.read_text()) if path.is_file() else None


def _figure(width=6.4, height=4.2):
    fig = Figure(figsize=(width, height), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def throughput_points(results: Path) -> dict[str, list[tuple[int, float]]]:
    """DEM bond-steps per second against particle count, per device, precision and physics.

    Args:
        results: the results directory.

    Returns:
        ``{series label: [(particles, bond-steps/s), ...]}`` sorted by particles, for the files that exist.
    """
    series: dict[str, dict[int, float]] = {}
    cpu = ("dem_throughput_3k_100k_1core.json", "dem_throughput_scaling_10k_1m_1core.json",
           "dem_throughput_1m_contacts_1core.json")
    for name in SOURCES["dem_throughput"]:
        data = _load(results, name)
        if data is None:
            continue
        if name in cpu:
            device = "CPU, one core, float64"
        else:
            device = "GPU (H200), " + ("float64" if "float64" in name else "float32")
        for row in data["results"]:
            physics = "bonds only" if row["physics"] == "bonds" else "with contacts"
            series.setdefault(f"{device}, {physics}", {})[int(row["particles"])] = float(row["bond_steps_per_s"])
    return {label: sorted(points.items()) for label, points in series.items()}


def dem_throughput(results: Path) -> Figure | None:
    """Bond-steps per second against particle count (log-log), CPU and GPU, bonds only and with contacts."""
    series = throughput_points(results)
    if not series:
        return None
    fig = _figure()
    ax = fig.add_subplot()
    for label, points in sorted(series.items()):
        n, rate = zip(*points)
        ax.plot(n, rate, "o-" if "bonds only" in label else "s--", label=label,
                color="C0" if "CPU" in label else ("C1" if "float64" in label else "C2"))
    ax.set(xscale="log", yscale="log", xlabel="particles", ylabel="bond-steps per second",
           title="DEM throughput (dem_throughput.py)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    return fig


def lammps_pairs(results: Path) -> list[tuple[str, float, float]]:
    """jaxbpm's and LAMMPS's bond-steps per second on the same runs, one thread each.

    Args:
        results: the results directory.

    Returns:
        ``[(run, jaxbpm, lammps), ...]`` for the files that exist.
    """
    out = []
    data = _load(results, "vs_lammps.json")
    if data is not None:
        t = data["throughput"]
        out.append((f"{data['sample']['n_particles'] // 1000}k box, compression,\nbonds only",
                    t["jaxbpm"]["bond_steps_per_second"], t["lammps"]["bond_steps_per_second"]))
    for name in ("vs_lammps_contacts_8k.json", "vs_lammps_contacts_100k.json"):
        data = _load(results, name)
        if data is not None:
            n = round(data["sample"]["n_particles"], -3) // 1000
            out.append((f"{n}k cylinder, UCS,\nwith contacts", data["jaxbpm"]["bond_steps_per_second"],
                        data["lammps"]["bond_steps_per_second"]))
    return out


def vs_lammps(results: Path) -> Figure | None:
    """Bars of jaxbpm's and LAMMPS's bond-steps per second (``vs_lammps.py``)."""
    pairs = lammps_pairs(results)
    if not pairs:
        return None
    fig = _figure()
    ax = fig.add_subplot()
    x = range(len(pairs))
    ax.bar([k - 0.2 for k in x], [p[1] for p in pairs], 0.4, label="jaxbpm", color="C0")
    ax.bar([k + 0.2 for k in x], [p[2] for p in pairs], 0.4, label="LAMMPS bpm/rotational", color="C7")
    for k, (_, ours, theirs) in enumerate(pairs):
        ax.annotate(f"{ours / theirs:.2f}x", (k - 0.2, ours), ha="center", va="bottom", fontsize=8)
    ax.set_xticks(list(x), [p[0] for p in pairs], fontsize=8)
    ax.set(ylabel="bond-steps per second", title="DEM against LAMMPS, one thread each (vs_lammps.py)")
    ax.legend(fontsize=8)
    return fig


def scaling_points(results: Path, name: str = "scaling_10k_1m.json") -> dict[str, list[tuple[int, float]]]:
    """Run time against particle count per solver, and the fitted exponents.

    Args:
        results: the results directory.
        name: the ``scaling.py`` results file (the GPU's: ``gpu/scaling_float64.json``).

    Returns:
        ``{solver: [(particles, run seconds), ...]}`` from ``name`` (empty when it is missing).
    """
    data = _load(results, name)
    if data is None:
        return {}
    out: dict[str, list[tuple[int, float]]] = {}
    for row in data["results"]:
        for method in ("dem", "dsm", "ste"):
            if row.get(method):
                out.setdefault(method, []).append((int(row["particles"]), float(row[method]["run_s"])))
    return out


def solver_scaling(results: Path) -> Figure | None:
    """Run time of the DSM and the STE against particle count (log-log) with the fitted exponents, on the CPU and
    (dashed, where ``gpu/scaling_float64.json`` exists) on the GPU."""
    points = scaling_points(results)
    if not points:
        return None
    fits = _load(results, "scaling_10k_1m.json").get("fits", {})
    gpu = scaling_points(results, "gpu/scaling_float64.json")
    fig = _figure()
    ax = fig.add_subplot()
    for k, (method, pts) in enumerate(sorted(points.items())):
        n, run = zip(*pts)
        fit = (fits.get(method) or {}).get("run_s")
        label = method.upper() + ", CPU" + (f" (~ n^{fit['exponent']:.2f})" if fit else "")
        ax.plot(n, run, "o-", label=label, color=f"C{k}")
        if gpu.get(method):
            n, run = zip(*gpu[method])
            ax.plot(n, run, "s--", label=f"{method.upper()}, GPU float64", color=f"C{k}", alpha=0.7)
    ax.set(xscale="log", yscale="log", xlabel="particles", ylabel="run time [s]",
           title="Run time against size: CPU (2 cores), GPU (H200) (scaling.py)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return fig


CHARTS = {"dem_throughput": dem_throughput, "vs_lammps": vs_lammps, "solver_scaling": solver_scaling}


def main(argv=None) -> list[Path]:
    """Write every chart whose results exist.

    Args:
        argv: the command line (default ``sys.argv[1:]``).

    Returns:
        The paths of the PNGs written.
    """
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--results", type=Path, default=ROOT / "results", help="the results directory")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "img", help="where the PNGs go")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, chart in CHARTS.items():
        fig = chart(args.results)
        if fig is None:
            print(f"{name}: no results ({', '.join(SOURCES[name])} missing), skipped")
            continue
        path = args.out / f"{name}.png"
        fig.savefig(path)
        written.append(path)
        print(f"{name}: {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}")
    return written


if __name__ == "__main__":
    main()
