"""Run sets: parameter sets solved once and kept (HDF5), the training data of the surrogate (and of any study
over a parameter range).

:func:`run_set` solves a Latin hypercube of parameter sets as one batch (``jax.vmap`` for pure models) or, for models
that are not batched (DEM), one after another or on the problem's executor (:mod:`jaxbpm.parallel`); with a file it
stores each run as it finishes and resumes an interrupted run set without repeating runs. :class:`RunSet` holds the
inputs and outputs and re-serves them to other targets on the same specimen.
"""

from __future__ import annotations

import dataclasses
import json
import pathlib
import time
import warnings

import numpy as np

import jaxbpm.calibrate._common as _common
from jaxbpm._renamed import batch_size_keyword
from jaxbpm.calibrate.objective import CalibrationError, Problem

__all__ = ["RunSet", "run_set", "latin_hypercube", "RUNSET_FORMAT"]

RUNSET_FORMAT = "jaxbpm-runset"


def latin_hypercube(n: int, lower, upper, *, seed=0, optimize: bool = True) -> np.ndarray:
    """A (centred-discrepancy optimised) Latin hypercube.

    Args:
      n: points.
      lower, upper: the box ``[d]``.
      seed: the sampler's seed.
      optimize: optimise the centred discrepancy (``"random-cd"``, two dimensions or more).

    Returns:
      ``[n, d]`` points within ``[lower, upper]``.
    """
    from scipy.stats import qmc

    lower, upper = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
    d = lower.size
    engine = qmc.LatinHypercube(d, optimization="random-cd" if optimize and d >= 2 else None, rng=seed)
    return qmc.scale(engine.random(n), lower, upper) if d else np.zeros((n, 0))


@dataclasses.dataclass
class RunSet:
    """Solved parameter sets: inputs ``X [N, n]`` (named ``parameter_names``, sampled in ``[lower, upper]``) and
    outputs ``Y [N, m]``, the solver's values of the named outputs (``output_names``, each ``output_sizes`` long;
    a target re-uses an output of the same name and size). solver: the name of the forward that solved them
    (``"dsm"``, ``"ste"``, ``"dem"`` or a :class:`~jaxbpm.calibrate.Forward`'s name; stored as the file's
    ``model`` attribute)."""

    parameter_names: list[str]
    X: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    output_names: list[str]
    output_sizes: list[int]
    Y: np.ndarray
    solver: str = ""
    info: dict = dataclasses.field(default_factory=dict)
    done: np.ndarray | None = None  # [N] bool: the runs solved so far (None: all); rows of the others are NaN

    @property
    def model(self) -> str:
        """Deprecated name of :attr:`solver` (a :class:`DeprecationWarning`); removed in the next release."""
        warnings.warn("RunSet.model is deprecated and will be removed in the next release; use RunSet.solver",
                      DeprecationWarning, stacklevel=2)
        return self.solver

    @property
    def n_runs(self) -> int:
        return int(self.X.shape[0])

    @property
    def complete(self) -> bool:
        return self.done is None or bool(np.all(self.done))

    def output(self, name: str, size: int) -> np.ndarray:
        """The columns of one named output.

        Args:
          name: the output (a target's name).
          size: its number of values.

        Returns:
          ``[N, size]``.

        Raises:
          CalibrationError: the run set has no such output, or one of another size.
        """
        if name not in self.output_names:
            raise CalibrationError(f"the run set has no output {name!r} (outputs: {self.output_names}); a second "
                                   "target must be of a quantity the runs recorded")
        k = self.output_names.index(name)
        if self.output_sizes[k] != size:
            raise CalibrationError(f"output {name!r} of the run set has {self.output_sizes[k]} values, the target "
                                   f"{size}")
        a = int(np.sum(self.output_sizes[:k]))
        return self.Y[:, a:a + size]

    def save(self, path):
        """Write the run set to an HDF5 file atomically.

        Args:
          path: the file.

        Returns:
          The path written.
        """
        import h5py

        from jaxbpm.io import atomic_write

        def write(tmp):
            with h5py.File(tmp, "w") as f:
                f.attrs["format"] = RUNSET_FORMAT
                f.attrs["parameter_names"] = json.dumps(self.parameter_names)
                f.attrs["output_names"] = json.dumps(self.output_names)
                f.attrs["output_sizes"] = json.dumps([int(s) for s in self.output_sizes])
                f.attrs["model"] = self.solver
                f.attrs["info"] = json.dumps(self.info, default=float)
                for name in ("X", "lower", "upper", "Y"):
                    f.create_dataset(name, data=np.asarray(getattr(self, name), dtype=np.float64))
                f.attrs["complete"] = self.complete
                if not self.complete:
                    f.create_dataset("done", data=np.asarray(self.done, dtype=bool))

        return atomic_write(path, write)

    @classmethod
    def load(cls, path, *, partial: bool = False) -> "RunSet":
        """Read a run set file.

        Args:
          path: the HDF5 file.
          partial: also accept one whose runs are not all solved (an interrupted run set; ``done`` says which are).

        Returns:
          The :class:`RunSet`.

        Raises:
          CalibrationError: not a run set file, or an interrupted one without ``partial`` (the message says how to
            finish it).
        """
        import h5py

        try:
            with h5py.File(path, "r") as f:
                if f.attrs.get("format") != RUNSET_FORMAT:
                    raise CalibrationError(f"{path}: not a jaxbpm run set file")
                runs = cls(parameter_names=json.loads(f.attrs["parameter_names"]), X=np.asarray(f["X"]),
                           lower=np.asarray(f["lower"]), upper=np.asarray(f["upper"]),
                           output_names=json.loads(f.attrs["output_names"]),
                           output_sizes=json.loads(f.attrs["output_sizes"]), Y=np.asarray(f["Y"]),
                           solver=str(f.attrs["model"]), info=_info(json.loads(f.attrs["info"])),
                           done=np.asarray(f["done"], dtype=bool) if "done" in f else None)
        except OSError as exc:
            raise CalibrationError(f"{path}: not a readable run set file ({exc})") from exc
        if not (partial or runs.complete):
            raise CalibrationError(f"{path}: an interrupted run set ({int(runs.done.sum())} of {runs.n_runs} runs "
                                   "solved); finish it with run_set(problem, n_runs, seed=..., path=...) (the runs "
                                   "already solved are not repeated)")
        return runs


def _info(info: dict) -> dict:
    """A stored run set's ``info`` with the key ``"chunk"`` of older files read as ``"batch_size"``."""
    if "chunk" in info:
        info = dict(info)
        batch_size = info.pop("chunk")
        info.setdefault("batch_size", batch_size)
    return info


def run_set(problem: Problem, n_runs: int, *, seed: int = 0, lower=None, upper=None,
            batch_size: int | None = None, progress: bool = False, path=None, chunk: int | None = None) -> RunSet:
    """Solve ``n_runs`` Latin-hypercube parameter sets of ``problem`` and record the outputs its targets need.

    The runs of a forward that is not batched (DEM) go one after another, or to the problem's ``executor`` (e.g. a
    Dask cluster, :mod:`jaxbpm.parallel`). With ``path``, each finished run is stored as it arrives (the file is
    replaced atomically), so that a run set interrupted (Ctrl-C, a killed process, a failed run) resumes when called
    again with the same arguments: runs already in the file are not repeated.

    Args:
      problem: the targets, parameters and forward.
      n_runs: parameter sets (at least 2).
      seed: the Latin hypercube's seed.
      lower, upper: the ranges ``[n]`` (default: the parameters' bounds).
      batch_size: solve in batches of this many (``None``: one batch; see :meth:`Problem.outputs`).
      progress: a bar of the runs solved (where they are solved in parts).
      path: an HDF5 file that holds the run set.
      chunk: deprecated name of ``batch_size`` (a :class:`DeprecationWarning`); removed in the next release.

    Returns:
      The :class:`RunSet` (``info["batch_size"]`` records ``batch_size``).

    Raises:
      CalibrationError: bad ranges or ``n_runs``, or a file at ``path`` that holds a different run set (other
        parameters, ranges, seed or outputs; never overwritten).
      TypeError: both ``batch_size`` and ``chunk``.
    """
    batch_size = batch_size_keyword(batch_size, chunk)
    n_runs = _common.check_count("n_runs", n_runs, 2)
    space = problem.space
    lower = space.lower if lower is None else np.asarray(lower, dtype=np.float64)
    upper = space.upper if upper is None else np.asarray(upper, dtype=np.float64)
    if lower.shape != (space.n,) or upper.shape != (space.n,) or np.any(~(lower < upper)):
        raise CalibrationError(f"ranges must be {space.n} pairs with lower < upper")
    t0 = time.perf_counter()
    evals0 = problem.evaluations
    X = latin_hypercube(n_runs, lower, upper, seed=seed)
    sizes = [t.size for t in problem.targets]
    runs = RunSet(parameter_names=space.names, X=X, lower=lower, upper=upper, output_names=problem.target_names,
                  output_sizes=sizes, Y=np.full((n_runs, int(np.sum(sizes))), np.nan), solver=problem.forward.name,
                  info={"seed": seed, "batch_size": batch_size}, done=np.zeros(n_runs, bool))
    if path is not None and pathlib.Path(path).exists():
        runs = _resumable(path, runs)
    todo = np.flatnonzero(~runs.done) if runs.done is not None else np.zeros(0, int)
    resumed = n_runs - len(todo)

    run_missing(problem, runs, X, todo, path, batch_size, progress)
    runs.info.update(wall_time=time.perf_counter() - t0, evaluations=problem.evaluations - evals0,
                     resumed=resumed)
    if path is not None and len(todo):
        runs.save(path)
    return runs


def _resumable(path, planned: RunSet) -> RunSet:
    """The run set stored at ``path`` if it is ``planned`` (same inputs, ranges, outputs and solver), with its solved
    runs; else an error naming what differs."""
    stored = RunSet.load(path, partial=True)
    same = {"parameter names": stored.parameter_names == planned.parameter_names,
            "output names": stored.output_names == planned.output_names,
            "output sizes": list(stored.output_sizes) == list(planned.output_sizes),
            "solver": stored.solver == planned.solver,
            "ranges": np.array_equal(stored.lower, planned.lower) and np.array_equal(stored.upper, planned.upper),
            "parameter sets (n_runs or seed)": stored.X.shape == planned.X.shape and np.array_equal(stored.X,
                                                                                                    planned.X)}
    differ = [name for name, ok in same.items() if not ok]
    if differ:
        raise CalibrationError(f"{path} holds another run set (its {', '.join(differ)} differ); give another path, "
                               "or delete the file to solve the new run set")
    stored.info = {**stored.info, **planned.info}
    if stored.done is None:
        stored.done = np.ones(stored.n_runs, bool)
    return stored


def run_missing(problem, runs: RunSet, X, todo, path, batch_size, progress) -> None:
    """Run the rows ``todo`` of ``X`` into ``runs.Y``; ``runs.done`` is cleared at the end.

    Args:
      problem: the :class:`~jaxbpm.calibrate.objective.Problem` that solves them.
      runs: the run set filled.
      X: its parameter sets ``[N, n]``.
      todo: the indices of the rows to solve.
      path: an HDF5 file each row is stored in as it arrives (so that an interrupted run set resumes without
        repeating them), or None.
      batch_size: solve in batches of this many.
      progress: a bar of the runs solved.
    """
    def store(k, row):
        runs.Y[todo[k]], runs.done[todo[k]] = row, True
        runs.save(path)

    if len(todo):
        Y = problem.outputs(X[todo], batch_size=batch_size, progress=progress, on_row=None if path is None else store)
        runs.Y[todo] = np.asarray(Y)
    runs.done = None
