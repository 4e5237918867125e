"""Plots of results: the stress-strain curve of a solve, the crack pattern of a failure run, speed against accuracy
of several solves and the course of a calibration.

Each function draws on the Matplotlib ``Axes`` it is given, or on a new :class:`~matplotlib.figure.Figure` of its
own (never pyplot's current figure, never a backend switch), and returns the ``Axes``. Every artist that carries
data has a ``gid`` naming it (``"curve DEM"``, ``"peak DEM"``, ``"modulus DSM"``, ``"broken DEM"``,
``"bonds tension"``, ``"pareto front"``, ...); :func:`drawn` reads them back as arrays, so what a plot shows can be
checked. In a notebook, show ``ax.figure``; to save, ``ax.figure.savefig("plot.png")``.

Calls that draw on one ``Axes`` combine: ``ax = dem.plot(); dsm.plot(ax=ax); ste.plot(ax=ax)`` puts the DSM's and
the STE's modulus beside the DEM's curve, and the legend lists all of them.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ["METHOD_NAMES", "BREAK_MODES", "stress_strain", "crack_pattern", "speed_accuracy", "pareto_front",
           "calibration", "drawn", "new_axes", "method_label", "save"]

#: the solvers' names as a legend spells them out
METHOD_NAMES = {"dem": "DEM (explicit discrete element method)", "dsm": "DSM (direct stiffness method: static solve)",
                "ste": "STE (stiffness tensor estimate)"}
#: the break modes of a bond (``DEMState.broken``; :data:`jaxbpm.physics.bond.TENSILE`, ``SHEAR``): code -> name
BREAK_MODES = {1: "tension", 2: "shear"}
_MODE_COLOURS = {"intact": "0.75", "tension": "C3", "shear": "C0"}


def new_axes(ax=None, size: tuple[float, float] = (6.4, 4.4)):
    """``ax``, or the ``Axes`` of a new :class:`~matplotlib.figure.Figure` (constrained layout, no pyplot).

    Args:
      ax: an ``Axes`` to draw on, or ``None``.
      size: the new figure's size [inches].

    Returns:
      The ``Axes``.
    """
    if ax is not None:
        return ax
    from matplotlib.figure import Figure

    return Figure(figsize=size, layout="constrained").add_subplot()


def save(figure, path, dpi: int = 120):
    """Save a figure atomically (never a half-written file), the format from the path's suffix.

    Args:
      figure: a :class:`~matplotlib.figure.Figure`, or an ``Axes`` (its figure is saved).
      path: the file (``.png``, ``.svg``, ``.pdf``, ...; no suffix: PNG).
      dpi: the resolution of a raster format.

    Returns:
      The path written (:class:`pathlib.Path`).
    """
    import pathlib

    from matplotlib.figure import Figure

    from jaxbpm._atomic import atomic_write

    fig = figure if isinstance(figure, Figure) else figure.figure
    suffix = pathlib.Path(path).suffix.lstrip(".") or "png"
    return atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format=suffix))


def method_label(method: str) -> str:
    """The short name of a solver in a legend (``"DEM"``), or the name as given when it is no solver's.

    Args:
      method: ``"dem"``, ``"dsm"``, ``"ste"`` or any label.

    Returns:
      The label.
    """
    return method.upper() if method in METHOD_NAMES else method


_TWIN = "broken bonds axis"  # the gid of the twin axes :func:`stress_strain` draws the broken bonds on


def _siblings(ax) -> list:
    """``ax`` and its twin (the broken bonds' y axis, where there is one), ``ax`` first."""
    return [ax] + [a for a in ax.get_shared_x_axes().get_siblings(ax) if a is not ax and a.get_gid() == _TWIN
                   and a.get_position().bounds == ax.get_position().bounds]


def drawn(ax) -> dict[str, np.ndarray]:
    """The data a jaxbpm plot drew on ``ax`` (and on its twin axes), by the artists' ``gid``.

    Args:
      ax: an ``Axes`` returned by a function of this module.

    Returns:
      ``{gid: array}``: a line's ``[m, 2]`` points (x, y as drawn: stress in MPa), a scatter's ``[m, 2]`` offsets,
      a collection of segments' ``[m, 2, 2]`` ends, bars' ``[m, 2]`` (centre, height); a second artist of the same
      gid gets ``" #2"`` appended.
    """
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D
    from matplotlib.patches import Rectangle

    found: list[tuple[str, np.ndarray]] = []
    bars: dict[str, list] = {}
    for a in _siblings(ax):
        for artist in list(a.lines) + list(a.collections) + list(a.patches):
            gid = artist.get_gid()
            if not gid:
                continue
            if isinstance(artist, Line2D):
                found.append((gid, np.asarray(artist.get_xydata(), np.float64)))
            elif isinstance(artist, LineCollection):
                found.append((gid, np.asarray(artist.get_segments(), np.float64).reshape(-1, 2, 2)))
            elif isinstance(artist, Rectangle):
                bars.setdefault(gid, []).append((artist.get_x() + 0.5 * artist.get_width(), artist.get_height()))
            else:
                found.append((gid, np.asarray(artist.get_offsets(), np.float64).reshape(-1, 2)))
    found += [(gid, np.asarray(rows, np.float64)) for gid, rows in bars.items()]
    out: dict[str, np.ndarray] = {}
    for gid, data in found:
        key, k = gid, 1
        while key in out:
            k += 1
            key = f"{gid} #{k}"
        out[key] = data
    return out


def _legend(ax) -> None:
    """One legend on ``ax`` for the labelled artists of ``ax`` and its twins."""
    handles, labels = [], []
    for a in _siblings(ax):
        h, lab = a.get_legend_handles_labels()
        handles += h
        labels += lab
    if handles:  # below the axes: it covers no data (a constrained layout makes room for it)
        ax.legend(handles, labels, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncols=1)


# ------------------------------------------------------------------------------------------------ stress-strain
def stress_strain(result, ax=None, *, label: str | None = None):
    """The loading curve of a solve: stress [MPa] against strain.

    A DEM result draws its curve (the records kept in ``result.strain``, ``result.stress``), the least-squares line
    that gives its modulus E (over the scene's ``fit_range``: ``stats["fit_strain"]``, ``stats["fit_stress"]``),
    its peak where bonds break, and the count of broken bonds (tension + shear) on a second y axis. A DSM or STE
    result (a linear answer) draws a line of slope E from the origin to its strain, ended by a point. Drawn on
    the same ``ax``, the results compare.

    Args:
      result: a :class:`~jaxbpm.result.Result`.
      ax: the ``Axes`` to draw on (``None``: a new figure's).
      label: the result's name in the legend (default: its method, ``"DEM"``).

    Returns:
      The ``Axes``; :func:`drawn` gives ``"curve <label>"``, ``"modulus <label>"``, ``"peak <label>"``,
      ``"broken <label>"`` (broken bonds against strain, on the twin axis).
    """
    ax = new_axes(ax, (6.4, 6.4))
    name = method_label(result.method) if label is None else label
    spelt = METHOD_NAMES.get(result.method, name) if label is None else label  # (the first legend entry's)
    strain, stress = np.asarray(result.strain, np.float64), np.asarray(result.stress, np.float64) / 1e6
    stats = result.stats if isinstance(result.stats, dict) else {}
    modulus = float(result.youngs_modulus)
    if result.method == "dem" and len(strain) > 2:
        line, = ax.plot(strain, stress, "-", lw=1.5, gid=f"curve {name}", label=f"{spelt}: stress-strain curve")
        colour = line.get_color()
        if "fit_strain" in stats:
            e, s = np.asarray(stats["fit_strain"], np.float64), np.asarray(stats["fit_stress"], np.float64) / 1e6
            ax.plot(e, s, "--", color="k", lw=1.2, gid=f"modulus {name}",
                    label=f"{name}: E = {_pa(modulus)} (least-squares line over the fit range)")
        if "broken_tensile" in stats:
            _peak(ax, result, name, colour)
            _broken(ax, strain, stats, name)
    else:
        end = float(strain[-1]) if len(strain) else 0.0
        e = np.array([0.0, end])
        line, = ax.plot(e, modulus * e / 1e6, "-", lw=1.2, gid=f"modulus {name}",
                        label=f"{spelt}: E = {_pa(modulus)} (a line of slope E)")
        ax.plot([end], [modulus * end / 1e6], "o", color=line.get_color(), gid=f"end {name}")
    ax.set_xlabel("strain [-] (compression positive)")
    ax.set_ylabel("stress [MPa]")
    ax.grid(True, alpha=0.3)
    _legend(ax)
    return ax


def _pa(value: float) -> str:
    """A modulus or stress with its unit: ``1.2 GPa``, ``350 MPa``."""
    return f"{value / 1e9:.4g} GPa" if abs(value) >= 1e9 else f"{value / 1e6:.4g} MPa"


def _peak(ax, result, name: str, colour) -> None:
    """The peak of a DEM curve, marked."""
    stats = result.stats
    e = float(stats["displacement_at_peak"]) / result.gauge_length
    s = float(stats["peak_force"]) / result.area / 1e6
    ax.plot([e], [s], "*", ms=12, color=colour, mec="k", gid=f"peak {name}",
            label=f"{name}: peak {s:.4g} MPa at strain {e:.3g}")


def _broken(ax, strain, stats: dict, name: str) -> None:
    """The broken bonds along a DEM curve on the twin y axis of ``ax`` (made once, shared by later calls)."""
    count = np.asarray(stats.get("broken_curve", np.zeros((len(strain), 2))), np.float64).reshape(len(strain), -1)
    twins = _siblings(ax)[1:]
    twin = twins[0] if twins else ax.twinx()
    twin.set_gid(_TWIN)
    total = int(stats["broken_tensile"]) + int(stats["broken_shear"])
    twin.plot(strain, count.sum(axis=1), ":", color="0.35", lw=1.3, gid=f"broken {name}",
              label=f"{name}: broken bonds, right axis ({int(stats['broken_tensile'])} tension, "
                    f"{int(stats['broken_shear'])} shear, {total} in all)")
    twin.set_ylabel("broken bonds")
    twin.set_ylim(bottom=0)


# ------------------------------------------------------------------------------------------------ crack pattern
def crack_pattern(sample, modes, ax=None, *, positions=None, normal: int = 1, origin: float | None = None,
                  thickness: float | None = None):
    """The broken bonds of a failure run by mode, in a section through the sample.

    The bonds whose midpoints lie within a slab of ``thickness`` around the plane ``x[normal] = origin`` are drawn
    projected on that plane: intact bonds in light grey, bonds broken in tension red, in shear blue.

    Args:
      sample: the :class:`~jaxbpm.sample.Sample` the run was of.
      modes: ``[nb]`` each bond's break mode: 0 intact, 1 tension, 2 shear (``result.state.broken`` of a DEM run;
        :meth:`jaxbpm.result.Result.plot_cracks` passes it).
      ax: the ``Axes`` to draw on (``None``: a new figure's).
      positions: ``[n, 3]`` the particles' centres to draw (default: the sample's, at rest; e.g.
        ``result.state.positions`` for the deformed sample).
      normal: the axis (0, 1, 2) normal to the section plane (default 1: the x-z plane, the load axis z upright).
      origin: the plane's coordinate along ``normal`` [m] (default: the middle of the sample's extent).
      thickness: the slab's width [m] (default: two mean particle diameters; ``numpy.inf``: every bond, projected).

    Returns:
      The ``Axes``; :func:`drawn` gives the segments ``"bonds intact"``, ``"bonds tension"``, ``"bonds shear"``
      (``[m, 2, 2]``, in the plane's coordinates [m]).

    Raises:
      ValueError: ``modes`` of another length than the sample's bonds, an unknown mode, positions of another shape,
        or a bad ``normal`` or ``thickness``.
    """
    from matplotlib.collections import LineCollection

    modes = np.asarray(modes).reshape(-1).astype(np.int64)
    bonds = np.asarray(sample.bonds, np.int64).reshape(-1, 2)
    if modes.shape[0] != bonds.shape[0]:
        raise ValueError(f"crack_pattern: {modes.shape[0]} break modes for a sample of {bonds.shape[0]} bonds")
    if np.any((modes < 0) | (modes > max(BREAK_MODES))):
        raise ValueError(f"crack_pattern: break modes are 0 (intact) or {BREAK_MODES}, got {np.unique(modes)}")
    x = np.asarray(sample.positions if positions is None else positions, np.float64)
    ax = new_axes(ax, (5.0, 6.5))
    inside, axes, where = _slab(sample, x, bonds, normal, origin, thickness)
    for code, name in [(0, "intact")] + sorted(BREAK_MODES.items()):
        pick = inside & (modes == code)
        segments = x[bonds[pick]][:, :, axes]
        total = int(np.sum(modes == code))
        label = f"{name}: {int(pick.sum())} in the section, {total} in all"
        ax.add_collection(LineCollection(segments, colors=_MODE_COLOURS[name], linewidths=0.6 if code == 0 else 2.0,
                                         gid=f"bonds {name}", label=label, zorder=1 if code == 0 else 2))
    names = "xyz"
    ax.set_xlabel(f"{names[axes[0]]} [m]")
    ax.set_ylabel(f"{names[axes[1]]} [m]")
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_title(f"broken bonds by mode\n{where}", fontsize=9)
    _legend(ax)
    return ax


def _slab(sample, x, bonds, normal, origin, thickness):
    """The bonds within the slab, the two axes of the plane and the title's words for the section."""
    if x.shape != (int(sample.n_particles), 3):
        raise ValueError(f"crack_pattern: positions must be [{int(sample.n_particles)}, 3], got {x.shape}")
    if normal not in (0, 1, 2):
        raise ValueError(f"crack_pattern: normal is the axis normal to the section, 0, 1 or 2; got {normal!r}")
    if thickness is None:
        thickness = 4.0 * float(np.mean(np.asarray(sample.radii)))
    if not thickness > 0:
        raise ValueError(f"crack_pattern: thickness must be > 0 [m] (numpy.inf: every bond), got {thickness!r}")
    if origin is None:
        origin = 0.5 * float(x[:, normal].min() + x[:, normal].max())
    mid = 0.5 * (x[bonds[:, 0], normal] + x[bonds[:, 1], normal])
    inside = np.abs(mid - origin) <= 0.5 * thickness
    axes = [a for a in range(3) if a != normal]
    name = "xyz"[normal]
    where = (f"all bonds projected along {name}" if not np.isfinite(thickness) else
             f"section {name} = {origin:.3g} m, {thickness:.3g} m thick")
    return inside, axes, where


# ------------------------------------------------------------------------------------------------ speed vs accuracy
def pareto_front(times: Sequence[float], errors: Sequence[float], tie: float = 0.0) -> list[int]:
    """The points no other point beats in both time and error (non-dominated), fastest first.

    Args:
      times: ``[m]`` each point's time.
      errors: ``[m]`` each point's error (non-negative).
      tie: a point joins the front only when its error is below ``(1 - tie)`` x the best error of the faster
        points (``tie=0``: any smaller error counts).

    Returns:
      The indices of the front's points, by increasing time (of points equal in time and error, the first).

    Raises:
      ValueError: ``times`` and ``errors`` of different lengths.
    """
    t, e = np.asarray(times, np.float64).reshape(-1), np.asarray(errors, np.float64).reshape(-1)
    if t.shape != e.shape:
        raise ValueError(f"pareto_front: {t.shape[0]} times and {e.shape[0]} errors")
    front, best = [], np.inf
    for i in np.lexsort((np.arange(len(t)), e, t)):
        if e[i] < best * (1.0 - tie):
            front.append(int(i))
            best = e[i]
    return front


def _named(results) -> list[tuple[str, Any]]:
    """``[(label, result)]`` of a mapping or a sequence of results (labelled by their method spelt out, numbered when
    repeated)."""
    if isinstance(results, Mapping):
        return [(str(k), r) for k, r in results.items()]
    out, seen = [], {}
    for r in results:
        base = METHOD_NAMES.get(r.method, r.method)
        seen[base] = seen.get(base, 0) + 1
        out.append((base if seen[base] == 1 else f"{base} #{seen[base]}", r))
    return out


def _faster(t: float, t_ref: float, ref: str) -> str:
    """How a time compares with the reference's, in words."""
    if not (t > 0 and t_ref > 0):
        return ""
    ratio = t_ref / t
    return f"{ratio:.3g}x faster than {ref}" if ratio >= 1 else f"{1 / ratio:.3g}x slower than {ref}"


def speed_accuracy(results, reference, ax=None, *, run_time: bool = False):
    """Wall time against the relative error of Young's modulus, one point per result, with the Pareto front.

    x: each solve's wall time [s] (setup + compile + run, what a user waits for; log scale); y: ``|E / E_ref - 1|``
    (log scale). The front (no other point both faster and more accurate) is a step line through its points,
    which are ringed. The reference, when it is a result, is not a point (its error is 0 by definition): a dotted
    vertical line marks its wall time. Each legend entry gives the times and their ratio to the reference's.

    Args:
      results: ``{label: Result}`` or a sequence of results (labelled by their method, e.g. ``"DSM (direct stiffness
        method: static solve)"``).
      reference: a :class:`~jaxbpm.result.Result` (one of ``results`` or another), or the reference E [Pa] (a
        measured modulus).
      ax: the ``Axes`` to draw on (``None``: a new figure's).
      run_time: also draw each run time (the compiled program alone: setup and compilation excluded) as a hollow
        marker joined to its wall-time point.

    Returns:
      The ``Axes``; :func:`drawn` gives ``"point <label>"`` (wall time, error), ``"run <label>"``, ``"pareto front"``
      (the front's points, fastest first) and ``"reference"``.

    Raises:
      ValueError: no results, or a reference modulus that is not a positive number.
    """
    named = _named(results)
    if not named:
        raise ValueError("speed_accuracy: no results to draw")
    ref_result = None if isinstance(reference, (int, float, np.integer, np.floating)) else reference
    e_ref = float(reference if ref_result is None else ref_result.youngs_modulus)
    if not (np.isfinite(e_ref) and e_ref > 0):
        raise ValueError(f"speed_accuracy: the reference modulus must be a positive number, got {e_ref!r}")
    ax = new_axes(ax, (7.5, 7.0))
    ref_name = "the reference" if ref_result is None else method_label(ref_result.method)
    points = [(lab, r, abs(float(r.youngs_modulus) / e_ref - 1.0)) for lab, r in named if r is not ref_result]
    positive = [err for _, _, err in points if err > 0]
    floor = min(positive) / 10 if positive else 1e-12  # (an error of 0 drawn at the bottom, as a triangle)
    for k, (lab, r, err) in enumerate(points):
        _point(ax, k, lab, r, max(err, floor), err == 0, ref_result, ref_name, run_time)
    if ref_result is not None:
        ax.axvline(ref_result.wall_time, ls=":", color="k", lw=1, gid="reference",
                   label=f"reference {ref_name}: wall {ref_result.wall_time:.3g} s (its own error is 0)")
    front = pareto_front([r.wall_time for _, r, _ in points], [err for _, _, err in points])
    if front:
        xs = [points[i][1].wall_time for i in front]
        ys = [max(points[i][2], floor) for i in front]
        ax.step(xs, ys, where="post", color="0.3", lw=1.2, gid="pareto front",
                label="Pareto front: no other point both faster and more accurate")
        ax.scatter(xs, ys, s=170, facecolors="none", edgecolors="0.3", lw=1.2, zorder=2)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time [s] (setup + compile + run)" + (", hollow: run time alone" if run_time else ""))
    ax.set_ylabel(f"relative error of E, |E / E_ref - 1| (E_ref = {_pa(e_ref)}, {ref_name})")
    ax.grid(True, which="both", alpha=0.3)
    _legend(ax)
    return ax


def _point(ax, k, lab, r, y, zero, ref_result, ref_name, run_time) -> None:
    """One result on the speed-accuracy chart (with its run time, hollow, when asked)."""
    import textwrap

    colour = f"C{k % 10}"
    text = textwrap.fill(lab, 90) + f"\n    wall {r.wall_time:.3g} s"
    if ref_result is not None:
        text += f" ({_faster(r.wall_time, ref_result.wall_time, ref_name)} in wall time)"
    if run_time:
        text += f", run {r.run_time:.3g} s"
        if ref_result is not None:
            text += f" ({_faster(r.run_time, ref_result.run_time, ref_name)} in run time)"
    if zero:
        text += "; error 0, drawn at the bottom"
    ax.scatter([r.wall_time], [y], s=60, color=colour, marker="v" if zero else "o", zorder=3, gid=f"point {lab}",
               label=text)
    if run_time and r.run_time > 0:
        ax.scatter([r.run_time], [y], s=60, facecolors="none", edgecolors=colour, zorder=3, gid=f"run {lab}")
        ax.plot([r.run_time, r.wall_time], [y, y], color=colour, lw=1, alpha=0.5)


# ------------------------------------------------------------------------------------------------ calibration
def calibration(history, axes=None):
    """The course of a calibration against its iterations: the objective, each target's error, the parameters'
    path and the wall time of the runs (coloured by the solver that ran them).

    Args:
      history: a :class:`~jaxbpm.calibrate.History` (``CalibrationResult.history``).
      axes: four ``Axes`` to draw on (``None``: a new 2 x 2 figure's).

    Returns:
      The four ``Axes`` (objective, targets, parameters, wall time); :func:`drawn` gives ``"loss"``,
      ``"error <target>"`` (|relative error| in %), ``"parameter <name>"`` (value / first value) and
      ``"time <solver>"`` (the iterations run on that solver and their seconds).

    Raises:
      ValueError: an empty history, or not four axes.
    """
    from matplotlib.ticker import MaxNLocator

    if not len(history):
        raise ValueError("calibration plot: the history has no rows")
    if axes is None:
        from matplotlib.figure import Figure

        axes = Figure(figsize=(10, 7), layout="constrained").subplots(2, 2).ravel()
    axes = list(np.asarray(axes, dtype=object).ravel())
    if len(axes) != 4:
        raise ValueError(f"calibration plot: give four axes, got {len(axes)}")
    it = history.column("iteration").astype(np.float64)
    axes[0].semilogy(it, np.maximum(history.column("loss"), 1e-300), "o-", gid="loss")
    axes[0].set(xlabel="iteration", ylabel="objective L", title="objective")
    errs = np.abs(np.asarray([r["errors"] for r in history.rows], np.float64).reshape(len(it), -1))
    for k, name in enumerate(history.target_names):
        axes[1].semilogy(it, np.maximum(errs[:, k], 1e-300) * 100, "o-", label=name, gid=f"error {name}")
    axes[1].set(xlabel="iteration", ylabel="|relative error| [%]", title="each target")
    vals = np.asarray([r["values"] for r in history.rows], np.float64).reshape(len(it), -1)
    for k, name in enumerate(history.parameter_names):
        axes[2].plot(it, vals[:, k] / vals[0, k], "o-", label=f"{name} (first {vals[0, k]:.4g})",
                     gid=f"parameter {name}")
    axes[2].set(xlabel="iteration", ylabel="value / first value", title="parameters")
    times, levels = history.column("time").astype(np.float64), [str(r["level"]) for r in history.rows]
    for k, level in enumerate(dict.fromkeys(levels)):
        pick = np.array([lv == level for lv in levels])
        axes[3].bar(it[pick], times[pick], color=f"C{k}", label=method_label(level), gid=f"time {level}")
    axes[3].set(xlabel="iteration", ylabel="wall time [s]",
                title=f"runs' wall time ({times.sum():.3g} s in all)")
    for a in axes[1:]:
        a.legend(fontsize=7)
    for a in axes:
        a.grid(True, alpha=0.3)
        a.xaxis.set_major_locator(MaxNLocator(integer=True))
    return axes
