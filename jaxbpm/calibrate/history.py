"""What a calibration returns: the answer, its errors, its cost and the full history (HDF5, plot)."""

from __future__ import annotations

import dataclasses
import json
import warnings
from typing import Any

import numpy as np

__all__ = ["History", "CalibrationResult", "plot_history", "load_history"]


@dataclasses.dataclass
class History:
    """One row per evaluated point: ``iteration`` (1-based), ``kind`` (``"initial"``, ``"estimate-1"``,
    ``"estimate-2"``, ``"adam"``, ``"closed-form"``, ``"check"``, ...), ``level`` (the solver), parameter
    ``values``, ``loss``, each target's relative ``errors`` (signed for a scalar target, the largest magnitude for a
    vector target), cumulative ``evaluations`` and the ``time`` [s]
    the iteration took."""

    parameter_names: list[str]
    target_names: list[str]
    rows: list[dict] = dataclasses.field(default_factory=list)

    def append(self, *, kind: str, level: str, values, loss: float, errors: np.ndarray, evaluations: int,
               time: float) -> dict:
        """Append one evaluated point.

        Args:
          kind: what the point is (``"initial"``, ``"adam"``, ``"narrow"``, ...).
          level: the solver (or level) it was evaluated on.
          values: parameter values ``[n]``.
          loss: the objective there.
          errors: each target's relative error ``[k]``.
          evaluations: solves so far.
          time: seconds the iteration took.

        Returns:
          The row appended (``iteration`` numbered from 1).
        """
        row = {"iteration": len(self.rows) + 1, "kind": kind, "level": level,
               "values": np.asarray(values, dtype=np.float64).copy(), "loss": float(loss),
               "errors": np.asarray(errors, dtype=np.float64).copy(), "evaluations": int(evaluations),
               "time": float(time)}
        self.rows.append(row)
        return row

    def extend(self, other: "History") -> None:
        """Append the rows of another history, renumbered after this one's.

        Args:
          other: a :class:`History` with the same parameters and targets.
        """
        for r in other.rows:
            self.rows.append({**r, "iteration": len(self.rows) + 1})

    def __len__(self) -> int:
        return len(self.rows)

    def plot(self, axes=None):
        """Draw the calibration's course (:func:`jaxbpm.plots.calibration`): the objective, each target's error,
        the parameters' path and the runs' wall time against the iteration.

        Args:
          axes: four Matplotlib ``Axes`` to draw on (``None``: a new 2 x 2 figure's).

        Returns:
          The four ``Axes``.
        """
        from jaxbpm.plots import calibration

        return calibration(self, axes)

    def column(self, name: str) -> np.ndarray:
        """One field of every row.

        Args:
          name: a row key (``"loss"``, ``"values"``, ``"errors"``, ``"evaluations"``, ...).

        Returns:
          The field of every row, stacked.
        """
        return np.asarray([r[name] for r in self.rows])

    def save(self, path, extra: dict | None = None):
        """Write the history to an HDF5 file atomically.

        Datasets ``/values [T, n]``, ``/loss``, ``/errors [T, k]`` (relative error per target), ``/evaluations``,
        ``/time``, ``/kind``, ``/level``; names and the result summary as JSON attributes.

        Args:
          path: the file.
          extra: a summary stored as the ``extra`` attribute (JSON).

        Returns:
          The path written.
        """
        import h5py

        from jaxbpm.io import atomic_write

        def write(tmp):
            with h5py.File(tmp, "w") as f:
                f.attrs["format"] = "jaxbpm-calibration-history"
                f.attrs["parameter_names"] = json.dumps(self.parameter_names)
                f.attrs["target_names"] = json.dumps(self.target_names)
                if extra:
                    f.attrs["extra"] = json.dumps(extra, default=_jsonable)
                n = len(self.parameter_names)
                f.create_dataset("iteration", data=self.column("iteration").astype(np.int64).reshape(-1))
                f.create_dataset("values", data=np.asarray([r["values"] for r in self.rows]).reshape(-1, n))
                f.create_dataset("loss", data=self.column("loss").astype(np.float64).reshape(-1))
                f.create_dataset("errors", data=np.asarray([r["errors"] for r in self.rows]).reshape(
                    -1, len(self.target_names)))
                f.create_dataset("evaluations", data=self.column("evaluations").astype(np.int64).reshape(-1))
                f.create_dataset("time", data=self.column("time").astype(np.float64).reshape(-1))
                f.create_dataset("kind", data=np.asarray([r["kind"] for r in self.rows], dtype="S"))
                f.create_dataset("level", data=np.asarray([r["level"] for r in self.rows], dtype="S"))

        return atomic_write(path, write)


def _jsonable(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.integer, np.floating, np.bool_)):
        return obj.item()
    return str(obj)


def load_history(path) -> History:
    """Read a history written by :meth:`History.save`.

    Args:
      path: the HDF5 file.

    Returns:
      The :class:`History`.
    """
    import h5py

    with h5py.File(path, "r") as f:
        h = History(json.loads(f.attrs["parameter_names"]), json.loads(f.attrs["target_names"]))
        for i in range(len(f["loss"])):
            h.rows.append({"iteration": int(f["iteration"][i]), "kind": f["kind"][i].decode(),
                           "level": f["level"][i].decode(), "values": np.asarray(f["values"][i]),
                           "loss": float(f["loss"][i]), "errors": np.asarray(f["errors"][i]),
                           "evaluations": int(f["evaluations"][i]), "time": float(f["time"][i])})
    return h


#: what a multi-fidelity level did (``CalibrationResult.levels[i]["action"]``), as :meth:`CalibrationResult.table`
#: explains it
_ACTIONS = {"calibrated": "the parameters calibrated on this solver",
            "corrected": "one free scale: the closed form applied to a solve of the previous answer, exact here",
            "accepted": "the previous level's answer was within tol on this solver, kept",
            "escalated": "the previous level's answer was not within tol on this solver, so it was calibrated here"}


@dataclasses.dataclass
class CalibrationResult:
    """Outcome of a calibration.

    values: ``{parameter name: calibrated value}``; params: the full parameter pytree to pass to
    :func:`jaxbpm.solve`. errors: ``{target name: signed relative error}`` at the answer (``(y - t) / s``; predicted
    by the surrogate for ``method="surrogate"``); converged: every target within ``tol``. method: the calibrator
    that produced the answer (``"closed-form"``, ``"adam"``, ``"surrogate"``, ``"multi-fidelity"``); solver: the
    solver it calibrated against (``"dsm"``, ``"ste"``, ``"dem"`` or a :class:`Forward`'s name). evaluations:
    solves (one parameter set on one scene); iterations: evaluated points (rows of ``history``). levels: per-solver
    cost of a multi-fidelity run. band: ``{name: (lo, hi)}`` (surrogate). notes: what was done and why (e.g. the
    closed-form shortcut). info: calibrator details.
    """

    values: dict[str, float]
    params: dict
    errors: dict[str, Any]
    converged: bool
    method: str
    solver: str
    evaluations: int
    iterations: int
    wall_time: float
    tol: float
    history: History
    notes: list[str] = dataclasses.field(default_factory=list)
    levels: list[dict] = dataclasses.field(default_factory=list)
    band: dict[str, tuple[float, float]] | None = None
    info: dict = dataclasses.field(default_factory=dict)

    @property
    def model(self) -> str:
        """Deprecated name of :attr:`solver` (a :class:`DeprecationWarning`); removed in the next release."""
        warnings.warn("CalibrationResult.model is deprecated and will be removed in the next release; use "
                      "CalibrationResult.solver", DeprecationWarning, stacklevel=2)
        return self.solver

    @property
    def max_error(self) -> float:
        return float(max(np.max(np.abs(np.asarray(e))) for e in self.errors.values()))

    def save(self, path):
        """Write the history (and a summary of this result) to an HDF5 file atomically.

        Args:
          path: the file.

        Returns:
          The path written.
        """
        extra = {"values": self.values, "errors": self.errors, "converged": self.converged, "method": self.method,
                 "model": self.solver, "evaluations": self.evaluations, "iterations": self.iterations,
                 "wall_time": self.wall_time, "tol": self.tol, "notes": self.notes, "levels": self.levels,
                 "band": self.band}
        return self.history.save(path, extra=extra)

    def plot(self, path=None, *, axes=None):
        """The course of the calibration (:meth:`History.plot`): a figure saved to ``path``, or drawn on ``axes``.

        Args:
          path: where to save the figure (the format from its suffix); None: not saved.
          axes: four Matplotlib ``Axes`` to draw on (then they are returned; ``path`` saves their figure).

        Returns:
          The :class:`matplotlib.figure.Figure` (:func:`plot_history`), or the four ``Axes`` when ``axes`` is given.
        """
        if axes is None:
            return plot_history(self.history, path)
        drawn = self.history.plot(axes)
        if path is not None:
            from jaxbpm.plots import save

            save(drawn[0], path)
        return drawn

    def table(self) -> str:
        """The answer, its errors, the calibrator and solver, the cost, each level and the notes, as text.

        Returns:
          The table, one line per row.
        """
        lines = [f"{'parameter':<16}{'value':>14}" + (f"{'band':>30}" if self.band else "")]
        for name, v in self.values.items():
            band = f"  [{self.band[name][0]:.5g}, {self.band[name][1]:.5g}]" if self.band else ""
            lines.append(f"{name:<16}{v:>14.6g}{band:>30}" if self.band else f"{name:<16}{v:>14.6g}")
        lines.append(f"{'target':<16}{'error':>14}")
        for name, e in self.errors.items():
            e = np.asarray(e)
            txt = f"{100 * float(e):+.3f} %" if e.ndim == 0 else f"max {100 * float(np.max(np.abs(e))):.3f} %"
            lines.append(f"{name:<16}{txt:>14}")
        lines.append(f"method {self.method} on {self.solver}: {'converged' if self.converged else 'NOT converged'} "
                     f"(tol {100 * self.tol:g} %), {self.iterations} iterations, {self.evaluations} evaluations, "
                     f"{self.wall_time:.2f} s")
        for lv in self.levels:
            lines.append(f"  level {lv['solver']:<8} {lv['action']:<11} {lv['evaluations']:>3} evaluations "
                         f"{lv['wall_time']:8.2f} s  max error {100 * lv['max_error']:.3f} %")
        actions = dict.fromkeys(lv["action"] for lv in self.levels if lv.get("action") in _ACTIONS)
        lines += [f"  ({action}: {_ACTIONS[action]})" for action in actions]
        for note in self.notes:
            lines.append(f"note: {note}")
        return "\n".join(lines)

    def __repr__(self) -> str:
        vals = ", ".join(f"{k}={v:.6g}" for k, v in self.values.items())
        return (f"CalibrationResult({vals}; method={self.method!r}, solver={self.solver!r}, "
                f"max_error={self.max_error:.3g}, evaluations={self.evaluations}, iterations={self.iterations})")


def plot_history(history: History, path=None):
    """The course of a calibration as a figure (:func:`jaxbpm.plots.calibration`: objective, each target's error,
    the parameters' path and the runs' wall time against the iteration), saved to ``path`` when given.

    The figure is made without pyplot or any global matplotlib state (in a notebook, show it as a cell's last
    expression). To draw on axes of your own, use :meth:`History.plot`.

    Args:
      history: a :class:`History`.
      path: where to save the figure (atomically, the format from its suffix); None: not saved.

    Returns:
      The :class:`matplotlib.figure.Figure`.
    """
    fig = history.plot()[0].figure
    if path is not None:
        from jaxbpm.plots import save

        save(fig, path)
    return fig
