"""Random-forest surrogate calibration (Irazabal et al. 2023, section 2).

1. A run set: N parameter sets by optimised Latin hypercube sampling (``scipy.stats.qmc``) within the parameter
   ranges, all solved as one batch (``jax.vmap`` for pure models). It is stored in HDF5 (:meth:`RunSet.save`) and
   re-used for other targets on the same specimen without new runs.
2. One :class:`sklearn.ensemble.RandomForestRegressor` per element of the output vector (``regressor=``: any
   scikit-learn regressor instead, one model for all elements), trained on
   ``err = y_target - y_run`` (Irazabal et al. 2023, Eq. 1; divided by the target's scale when ``normalize``), 500
   trees and a
   third of the inputs per split by default; out-of-bag R^2 and the impurity importance of each parameter per element
   and on average. Parameters whose mean importance is below ``importance_threshold`` can be dropped (held at their
   initial value) and the run set re-sampled on the rest.
3. Iterative range narrowing: start from the training ranges with the outer ``exclude`` (5 %) cut off; at iteration
   ``it`` draw ``L_s`` combinations (LHS) in the current ranges, keep those whose predicted errors all lie within
   ``I_e / it`` and shrink the ranges to them; stop at ``it_max`` or when no combination is admissible. The answer is
   the median of the last admissible combinations and their ranges are its uncertainty band.
"""

from __future__ import annotations

import pathlib
import time

import numpy as np

import jaxbpm.calibrate._common as _common
from jaxbpm.calibrate.objective import CalibrationError, Problem
from jaxbpm.calibrate.result import CalibrationResult, History
from jaxbpm.calibrate.runs import RunSet, latin_hypercube, run_missing, run_set

__all__ = ["RunSet", "run_set", "fit_forests", "surrogate", "latin_hypercube"]

def _errors(problem: Problem, runs: RunSet, normalize: bool) -> np.ndarray:
    cols = []
    for t in problem.targets:
        y = runs.output(t.name, t.size)
        err = np.reshape(t.value, (1, -1)) - y
        cols.append(err / t.scale if normalize else err)
    return np.concatenate(cols, axis=1)


def fit_forests(X, err, *, n_trees=500, max_features=1 / 3, seed=0, n_jobs=None, regressor=None):
    """Fit the surrogate of ``err [N, m]`` on ``X [N, n]``; returns ``(models, oob_r2 [m], importance [m, n])``.

    regressor ``None``: one random forest per column of ``err`` (``n_trees`` trees, ``max_features``, out-of-bag
    scores, ``random_state = seed + column``). Else a scikit-learn regressor, cloned and fitted once on all columns:
    natively where it supports several outputs, else wrapped in :class:`sklearn.multioutput.MultiOutputRegressor`;
    its ``random_state`` (when ``None``) becomes ``seed`` and ``n_jobs`` is passed on where it has that parameter.
    ``oob_r2`` comes from the model's out-of-bag prediction (e.g. a forest with ``oob_score=True``) and
    ``importance`` from its ``feature_importances_`` (one model for all columns: the same row for each); both are
    NaN where the model reports none.
    """
    if regressor is not None:
        return _fit_regressor(regressor, X, err, seed=seed, n_jobs=n_jobs)
    from sklearn.ensemble import RandomForestRegressor

    forests, r2, imp = [], [], []
    for j in range(err.shape[1]):
        rf = RandomForestRegressor(n_estimators=n_trees, max_features=max_features, oob_score=True,
                                   random_state=seed + j, n_jobs=n_jobs)
        rf.fit(X, err[:, j])
        forests.append(rf)
        r2.append(float(rf.oob_score_))
        imp.append(rf.feature_importances_)
    return forests, np.asarray(r2), np.asarray(imp)


def _check_regressor(regressor):
    """Raise :class:`CalibrationError` unless ``regressor`` is a scikit-learn regressor instance."""
    from sklearn.base import is_regressor

    if isinstance(regressor, type) or not (hasattr(regressor, "fit") and hasattr(regressor, "predict")
                                           and hasattr(regressor, "get_params") and is_regressor(regressor)):
        what = regressor.__name__ if isinstance(regressor, type) else type(regressor).__name__
        raise CalibrationError(f"regressor must be a scikit-learn regressor instance (e.g. "
                               f"ExtraTreesRegressor(n_estimators=200)), got {what}")


def _multi_output(est) -> bool:
    try:
        from sklearn.utils import get_tags  # scikit-learn >= 1.6
    except ImportError:
        return bool(est._get_tags().get("multioutput", False))
    return bool(get_tags(est).target_tags.multi_output)


def _fit_regressor(regressor, X, err, *, seed=0, n_jobs=None):
    from sklearn.base import clone
    from sklearn.metrics import r2_score
    from sklearn.multioutput import MultiOutputRegressor

    _check_regressor(regressor)
    est = clone(regressor)
    params = est.get_params(deep=False)
    if "random_state" in params and params["random_state"] is None:
        est.set_params(random_state=seed)
    if n_jobs is not None and "n_jobs" in params:
        est.set_params(n_jobs=n_jobs)
    if not _multi_output(est):
        est = MultiOutputRegressor(est, n_jobs=n_jobs)
    est.fit(X, err)
    m, n = err.shape[1], X.shape[1]
    parts = est.estimators_ if isinstance(est, MultiOutputRegressor) else [est]
    imp = [getattr(p, "feature_importances_", None) for p in parts]
    imp = (np.full((m, n), np.nan) if any(i is None for i in imp)
           else np.broadcast_to(np.asarray(imp, dtype=np.float64).reshape(len(parts), n), (m, n)).copy())
    oob = [getattr(p, "oob_prediction_", None) for p in parts]
    if any(o is None for o in oob):
        r2 = np.full(m, np.nan)
    else:
        oob = np.concatenate([np.reshape(o, (len(X), -1)) for o in oob], axis=1)
        r2 = np.array([r2_score(err[:, j], oob[:, j]) for j in range(m)])
    return [est], r2, imp


def _predict(models, X) -> np.ndarray:
    return np.concatenate([np.reshape(_predict_one(f, X), (len(X), -1)) for f in models], axis=1)


def _predict_one(model, X) -> np.ndarray:
    """``model.predict(X)``; for a fitted random forest or extra-trees regressor, the mean of its trees' predictions
    taken from each tree's array form directly (``tree_.predict``), summed in the trees' order as scikit-learn sums
    them. scikit-learn's own ``predict`` dispatches every tree through joblib (about 0.3 ms a tree whatever the
    number of points): the narrowing loop predicts twice per iteration, and a 500-tree forest spent 14 of a 21-s
    calibration there; this takes a fifth of that."""
    from sklearn.ensemble import ExtraTreesRegressor, RandomForestRegressor

    trees = getattr(model, "estimators_", None)
    if type(model) not in (RandomForestRegressor, ExtraTreesRegressor) or not trees:
        return model.predict(X)
    Xf = np.ascontiguousarray(X, dtype=np.float32)  # the dtype the trees split on
    out = np.zeros((len(Xf), model.n_outputs_))
    for tree in trees:
        out += tree.tree_.predict(Xf).reshape(out.shape)
    out /= len(trees)
    return out[:, 0] if model.n_outputs_ == 1 else out


# ---------------------------------------------------------------------------------------------------- default ranges
_START_FACTOR = 2.0  # default ranges start at (c / 2, 2 c) around the estimate c
_WIDEN_FACTOR = 4.0  # each widening round moves one side by this factor (capped at the parameter's bounds)


def _defaulted(space) -> np.ndarray:
    """``[n]`` bool: the parameters whose bounds were not given (``Parameter.bounds is None``: the space's default
    ``(initial / 100, initial * 100)``, positive)."""
    return np.array([p.bounds is None for p in space.parameters], dtype=bool)


def _log_mask(space) -> np.ndarray:
    """``[n]`` bool: the parameters sampled uniformly in log space (defaulted bounds and log scaling)."""
    return _defaulted(space) & (space.scaling == "log")


def _to_u(v, logm):
    v = np.asarray(v, dtype=np.float64)
    return np.where(logm, np.log(np.where(logm, v, 1.0)), v)


def _from_u(u, logm):
    u = np.asarray(u, dtype=np.float64)
    return np.where(logm, np.exp(np.where(logm, u, 0.0)), u)


def _lhs(n, lo, hi, logm, *, seed, optimize=True) -> np.ndarray:
    """A Latin hypercube in ``[lo, hi]``, uniform in log space for the parameters of ``logm``."""
    return _from_u(latin_hypercube(n, _to_u(lo, logm), _to_u(hi, logm), seed=seed, optimize=optimize), logm)


def _trim(lo, hi, logm, exclude):
    """``[lo, hi]`` with the outer ``exclude`` of each range cut off (in log space for ``logm``)."""
    ul, uh = _to_u(lo, logm), _to_u(hi, logm)
    w = uh - ul
    return _from_u(ul + exclude * w, logm), _from_u(uh - exclude * w, logm)


def _estimate(problem: Problem):
    """A cheap first answer to centre the default ranges on: the closed form where it applies (bonds-only
    elasticity; one solve for one free scale), else the initial values. Returns ``(values, what)``."""
    space = problem.space
    ok, _ = problem.closed_form_applies()
    if ok and sum(t.size for t in problem.targets) >= space.n:
        from jaxbpm.calibrate.closed_form import closed_form

        try:
            res = closed_form(problem)
        except CalibrationError:
            pass
        else:
            values = np.array([res.values[n] for n in space.names])
            if np.all(np.isfinite(values)) and np.all(values > 0):
                return space.clip(values), "the closed-form estimate"
    return space.clip(space.initial), "the initial values"


def _reach(problem: Problem, runs: RunSet, rows=None) -> list[dict]:
    """Per target element: the range of the runs' outputs (over ``rows``; default all) and whether the target lies
    within it."""
    out = []
    for t in problem.targets:
        y = runs.output(t.name, t.size)
        if rows is not None and np.any(rows):
            y = y[rows]
        tv = np.reshape(t.value, -1)
        for k in range(t.size):
            lo, hi = float(np.nanmin(y[:, k])), float(np.nanmax(y[:, k]))
            out.append({"target": t.name if t.size == 1 else f"{t.name}[{k}]", "value": float(tv[k]),
                        "min": lo, "max": hi, "inside": bool(lo <= tv[k] <= hi), "column": len(out)})
    return out


def _describe_reach(reach) -> str:
    return "; ".join(f"{r['target']}: the runs reach [{r['min']:.4g}, {r['max']:.4g}], the target is "
                     f"{r['value']:.4g}" + ("" if r["inside"] else " (outside)") for r in reach)


def _in_box(X, lo, hi) -> np.ndarray:
    return np.all((X >= lo) & (X <= hi), axis=1)


def _widenings(problem, runs, reach, auto, logm, lo, hi, bounds_lo, bounds_hi):
    """``[(parameter index, side +1/-1)]`` that move the run set's outputs towards the targets it does not reach:
    per target element outside, each defaulted parameter that correlates with it (``|r|`` at least half the
    strongest), on the side that raises (or lowers) the output; all defaulted parameters, both sides, when none
    correlates."""
    U = _to_u(runs.X, logm)
    Yall = np.concatenate([runs.output(t.name, t.size) for t in problem.targets], axis=1)
    moves = set()
    for r in reach:
        if r["inside"]:
            continue
        y = Yall[:, r["column"]]
        need = 1.0 if r["value"] > r["max"] else -1.0
        corr = np.zeros(len(auto))
        for i in np.flatnonzero(auto):
            if np.std(U[:, i]) > 0 and np.std(y) > 0:
                corr[i] = np.corrcoef(U[:, i], y)[0, 1]
        strongest = np.max(np.abs(corr)) if auto.any() else 0.0
        if strongest < 0.1:
            cand = [(i, s) for i in np.flatnonzero(auto) for s in (1, -1)]
        else:
            cand = [(i, int(np.sign(corr[i] * need))) for i in np.flatnonzero(auto)
                    if abs(corr[i]) >= 0.5 * strongest]
        for i, side in cand:
            if (side > 0 and hi[i] < bounds_hi[i]) or (side < 0 and lo[i] > bounds_lo[i]):
                moves.add((int(i), side))
    return sorted(moves)


def _solve_runs(problem: Problem, X, lower, upper, *, seed, chunk, progress, path, info, previous=None) -> RunSet:
    """Solve the parameter sets ``X`` whose leading rows may be solved already: those of ``previous`` (a run set)
    and those in ``path``'s run set (same leading rows) are not solved again; each finished row is stored there as
    it arrives, like :func:`run_set`."""
    space = problem.space
    sizes = [t.size for t in problem.targets]
    n = len(X)
    runs = RunSet(parameter_names=space.names, X=X, lower=np.asarray(lower, dtype=np.float64),
                  upper=np.asarray(upper, dtype=np.float64), output_names=problem.target_names, output_sizes=sizes,
                  Y=np.full((n, int(np.sum(sizes))), np.nan), solver=problem.forward.name,
                  info={"seed": seed, "chunk": chunk, **info}, done=np.zeros(n, bool))
    stored_rows = from_file = 0
    if path is not None and pathlib.Path(path).exists():
        stored = RunSet.load(path, partial=True)
        k = min(stored.n_runs, n)
        same = (stored.parameter_names == runs.parameter_names and stored.output_names == runs.output_names
                and list(stored.output_sizes) == sizes and stored.solver == runs.solver
                and np.array_equal(stored.X[:k], X[:k]))
        if not same:
            raise CalibrationError(f"{path} holds another run set (its parameters, outputs, model or parameter sets "
                                   "differ); give another path, or delete the file to solve the new run set")
        done = np.ones(stored.n_runs, bool) if stored.done is None else stored.done
        runs.Y[:k], runs.done[:k] = stored.Y[:k], done[:k]
        stored_rows, from_file = stored.n_runs, int(np.sum(done[:k]))
    if previous is not None:
        k = previous.n_runs
        runs.Y[:k], runs.done[:k] = previous.Y, True
    todo = np.flatnonzero(~runs.done)
    t0 = time.perf_counter()
    evals0 = problem.evaluations

    run_missing(problem, runs, X, todo, path, chunk, progress)
    runs.info.update(wall_time=time.perf_counter() - t0, evaluations=problem.evaluations - evals0,
                     resumed=from_file)
    if path is not None and len(todo) and n >= stored_rows:
        runs.save(path)
    return runs


def _default_run_set(problem: Problem, n_runs, *, seed, chunk, progress, path, widen, exclude, notes):
    """The run set of a problem with defaulted parameter ranges: centred on a cheap estimate, a factor
    ``_START_FACTOR`` either side (in log space), then widened by ``_WIDEN_FACTOR`` on the side of each target the
    runs do not reach, with new runs there (all runs kept), ``widen`` rounds at most. Returns ``(runs, ranges)``."""
    space = problem.space
    auto, logm = _defaulted(space), _log_mask(space)
    centre, what = _estimate(problem)
    lo, hi = space.lower.copy(), space.upper.copy()
    lo[auto] = np.maximum(centre[auto] / _START_FACTOR, space.lower[auto])
    hi[auto] = np.minimum(centre[auto] * _START_FACTOR, space.upper[auto])
    names = [n for n, a in zip(space.names, auto) if a]
    notes.append(f"default ranges of {names}: a factor {_START_FACTOR:g} either side of {what} "
                 f"({', '.join(f'{n} in [{lo[i]:.4g}, {hi[i]:.4g}]' for i, n in enumerate(space.names) if auto[i])})"
                 + (", sampled in log space" if logm.any() else ""))
    X = _lhs(n_runs, lo, hi, logm, seed=seed)
    info = {"ranges": "default", "centre": centre.tolist()}
    runs = _solve_runs(problem, X, lo, hi, seed=seed, chunk=chunk, progress=progress, path=path, info=info)
    ranges = [{"round": 0, "lower": lo.tolist(), "upper": hi.tolist(), "runs": n_runs, "centre": centre.tolist(),
               "from": what, "widened": []}]
    n_new = max(n_runs // 2, 2)
    for rnd in range(1, widen + 1):
        tl, th = _trim(lo, hi, logm, exclude)
        reach = _reach(problem, runs, _in_box(runs.X, tl, th))
        ranges[-1]["reach"] = reach
        if all(r["inside"] for r in reach):
            break
        moves = _widenings(problem, runs, reach, auto, logm, lo, hi, space.lower, space.upper)
        if not moves:
            ranges[-1]["at_bounds"] = True
            notes.append(f"the runs do not reach every target and the default ranges are at the parameters' bounds "
                         f"({_describe_reach(reach)})")
            break
        new_lo, new_hi = lo.copy(), hi.copy()
        for i, side in moves:
            if side > 0:
                new_hi[i] = min(hi[i] * _WIDEN_FACTOR, space.upper[i])
            else:
                new_lo[i] = max(lo[i] / _WIDEN_FACTOR, space.lower[i])
        parts = []
        for k, (i, side) in enumerate(moves):
            sl, sh = new_lo.copy(), new_hi.copy()
            if side > 0:
                sl[i] = hi[i]
            else:
                sh[i] = lo[i]
            parts.append(_lhs(n_new, sl, sh, logm, seed=seed + 100 * rnd + k))
        said = [f"{space.names[i]} {'up' if side > 0 else 'down'} to "
                f"{new_hi[i] if side > 0 else new_lo[i]:.4g}" for i, side in moves]
        missed = "; ".join(f"{r['target']} {r['value']:.4g} outside the runs' [{r['min']:.4g}, {r['max']:.4g}]"
                           for r in reach if not r["inside"])
        notes.append(f"widening round {rnd}: {missed}; widened {', '.join(said)} (+{n_new * len(moves)} runs)")
        lo, hi = new_lo, new_hi
        runs = _solve_runs(problem, np.concatenate([runs.X] + parts), lo, hi, seed=seed, chunk=chunk,
                           progress=progress, path=path, info=info, previous=runs)
        ranges.append({"round": rnd, "lower": lo.tolist(), "upper": hi.tolist(), "runs": runs.n_runs,
                       "widened": [(space.names[i], "upper" if side > 0 else "lower") for i, side in moves]})
    else:  # every round used: say whether the targets are reached now
        tl, th = _trim(lo, hi, logm, exclude)
        reach = ranges[-1]["reach"] = _reach(problem, runs, _in_box(runs.X, tl, th))
        if not all(r["inside"] for r in reach):
            at_bounds = not _widenings(problem, runs, reach, auto, logm, lo, hi, space.lower, space.upper)
            ranges[-1]["at_bounds"] = at_bounds
            notes.append(f"the runs do not reach every target after {widen} widening round(s)"
                         + (" (the default ranges are at the parameters' bounds)" if at_bounds else "")
                         + f": {_describe_reach(reach)}")
    runs.info["ranges"] = "default"
    return runs, ranges


def surrogate(problem: Problem, *, runs: RunSet | None = None, n_runs: int = 100, I_e: float = 0.2, L_s: int = 1000,
              it_max: int = 50, n_trees: int = 500, max_features: float = 1 / 3, exclude: float = 0.05,
              normalize: bool = True, importance_threshold: float | None = None, resample_runs: int | None = None,
              seed: int = 0, tol: float = 0.05, verify: bool = False, n_jobs=None, chunk: int | None = None,
              regressor=None, runs_file=None, progress=None, widen: int = 3) -> CalibrationResult:
    """Calibrate with the random-forest surrogate of Irazabal et al. 2023 (see the module docstring).

    runs: a stored :class:`RunSet` to re-use (no new runs); else ``n_runs`` are solved.

    Ranges: a parameter with explicit ``bounds`` is sampled within them. A parameter without (the space's default
    ``(initial / 100, initial * 100)``) starts within a factor 2 either side of a cheap estimate -- the closed form
    where it applies (bonds-only elasticity: one solve), else its initial value -- sampled uniformly in log space
    (log scaling); where the runs' outputs do not reach a target, its range is widened by a factor 4 on the side
    that moves the output towards the target and ``n_runs // 2`` runs are added there (all runs are kept), at most
    ``widen`` rounds and never past the default bounds. The ranges of each round are in ``info["ranges"]`` and
    each widening is stated in the notes.

    I_e: initial admissible
    error (relative to each target's scale when ``normalize``, else in the output's units); L_s: combinations per
    iteration; it_max: iterations at most. n_trees, max_features: the forests (Irazabal et al. 2023: 500 and 1/3).
    regressor: a scikit-learn regressor instance (e.g. ``ExtraTreesRegressor(n_estimators=200)``,
    ``KNeighborsRegressor(5)``) fitted instead of the forests, cloned per fit (see :func:`fit_forests`; n_trees and
    max_features then unused). n_jobs: parallel jobs of the forests or of the regressor where it takes them.
    importance_threshold: drop parameters whose mean importance is below it; resample_runs: then solve that many new
    runs on the remaining parameters. chunk: solve the runs in batches of this many (bounds the memory of a
    ``vmap`` of large solves; ``None``: one batch). verify: solve once at the answer and report the measured errors
    (else the surrogate's prediction). runs_file: an HDF5 file the run set is stored in as its runs finish, and
    resumed from when called again (see :func:`run_set`; the runs go to the problem's ``executor`` where it has
    one). The result's ``info`` holds ``oob_r2 [m]``, ``importance [m, n]``,
    ``mean_importance``, ``dropped``, ``narrowing`` (per iteration: admissible count, error bound, ranges), the fitted
    models (``models``), the run set (``runs``) and, for default ranges, the rounds of ``ranges`` (per round: lower,
    upper, runs so far, the parameters widened and the outputs the runs reach per target element).
    """
    t_start = time.perf_counter()
    tol = _common.check_tol(tol)
    L_s = _common.check_count("L_s", L_s, 2)
    it_max = _common.check_count("it_max", it_max)
    n_trees = _common.check_count("n_trees", n_trees)
    if not (isinstance(I_e, (int, float)) and np.isfinite(I_e) and I_e > 0):
        raise CalibrationError(f"I_e must be a number > 0, got {I_e!r}")
    if not (isinstance(exclude, (int, float)) and 0 <= exclude < 0.5):
        raise CalibrationError(f"exclude must lie in [0, 0.5), got {exclude!r}")
    if not (isinstance(max_features, (int, float)) and 0 < max_features <= 1):
        raise CalibrationError(f"max_features must be a fraction in (0, 1], got {max_features!r}")
    if regressor is not None:
        _check_regressor(regressor)
    widen = _common.check_count("widen", widen, 0)
    show_runs = progress is True  # (a bar of the run set; iterations as lines)
    progress = _common.progress_fn(progress)
    evals0 = problem.evaluations
    notes = []
    space = problem.space
    if runs is not None and runs_file is not None:
        raise CalibrationError("give runs (a stored run set) or runs_file (where to solve and store one), not both")
    ranges = None
    if runs is None and _defaulted(space).any():
        n_runs = _common.check_count("n_runs", n_runs, 2)
        runs, ranges = _default_run_set(problem, n_runs, seed=seed, chunk=chunk, progress=show_runs, path=runs_file,
                                        widen=widen, exclude=exclude, notes=notes)
    elif runs is None:
        runs = run_set(problem, n_runs, seed=seed, chunk=chunk, progress=show_runs, path=runs_file)
    else:
        if not isinstance(runs, RunSet):
            raise CalibrationError(f"runs must be a RunSet, got {type(runs).__name__}")
        if runs.parameter_names != space.names:
            raise CalibrationError(f"the run set varies {runs.parameter_names}, the problem {space.names}")
        notes.append(f"re-used a stored run set of {runs.n_runs} runs (no new runs for training)")
    err = _errors(problem, runs, normalize)
    forests, r2, imp = fit_forests(runs.X, err, n_trees=n_trees, max_features=max_features, seed=seed,
                                   n_jobs=n_jobs, regressor=regressor)
    mean_imp = imp.mean(axis=0)
    dropped = []
    active = np.ones(space.n, bool)
    fixed = space.clip(space.initial)
    if importance_threshold is not None:
        if np.isnan(mean_imp).any():
            raise CalibrationError(f"importance_threshold needs feature importances; the regressor "
                                   f"{type(regressor).__name__} reports none")
        active = mean_imp >= importance_threshold
        if not active.any():
            raise CalibrationError(f"every parameter's mean importance is below {importance_threshold}")
        dropped = [n for n, a in zip(space.names, active) if not a]
        if dropped:
            notes.append(f"dropped parameters of low importance {dropped} (held at {fixed[~active].tolist()})")
            if resample_runs:
                sub = space.subspace([n for n, a in zip(space.names, active) if a], fixed)
                sub_problem = Problem(problem.forward, problem.targets, sub, executor=problem.executor,
                                      retries=problem.retries)
                sub_problem.evaluations = problem.evaluations
                sub_runs = run_set(sub_problem, resample_runs, seed=seed + 1, chunk=chunk, progress=show_runs,
                                   lower=runs.lower[active],
                                   upper=runs.upper[active])
                problem.evaluations = sub_problem.evaluations
                X_full = np.repeat(fixed[None, :], sub_runs.n_runs, axis=0)
                X_full[:, active] = sub_runs.X
                runs = RunSet(space.names, X_full, runs.lower, runs.upper, sub_runs.output_names,
                              sub_runs.output_sizes, sub_runs.Y, runs.solver,
                              {**sub_runs.info, "resampled_from": runs.n_runs})
                err = _errors(problem, runs, normalize)
                forests, r2, imp_active = fit_forests(runs.X[:, active], err, n_trees=n_trees,
                                                      max_features=max_features, seed=seed, n_jobs=n_jobs,
                                                      regressor=regressor)
                imp = np.zeros((err.shape[1], space.n))
                imp[:, active] = imp_active
                notes.append(f"re-sampled {resample_runs} runs on the remaining parameters")

    reduced = bool(dropped and resample_runs)  # forests trained on the active parameters only

    def predict(Xa):
        if reduced:
            return _predict(forests, Xa)
        full = np.repeat(fixed[None, :], len(Xa), axis=0)
        full[:, active] = Xa
        return _predict(forests, full)

    logm = _log_mask(space)[active]  # default ranges narrow in log space; explicit bounds linearly
    lo, hi = _trim(runs.lower[active], runs.upper[active], logm, exclude)
    history = History(space.names, problem.target_names)
    narrowing = []
    kept = None
    stop = "it_max reached"
    for it in range(1, it_max + 1):
        t0 = time.perf_counter()
        Xp = _lhs(L_s, lo, hi, logm, seed=seed + 1000 + it, optimize=False)
        P = predict(Xp)
        bound = I_e / it
        adm = np.all(np.abs(P) <= bound, axis=1)
        narrowing.append({"iteration": it, "bound": bound, "admissible": int(adm.sum()),
                          "lower": lo.tolist(), "upper": hi.tolist()})
        if not adm.any():
            if kept is None:
                reached = _describe_reach(_reach(problem, runs))
                hint = "widen the ranges or raise I_e"
                if ranges is not None:
                    hint = (f"default ranges after {len(ranges) - 1} widening round(s)"
                            + (", at the parameters' default bounds" if ranges[-1].get("at_bounds") else "")
                            + "; give Parameter bounds, raise n_runs or widen, or raise I_e")
                raise CalibrationError(f"no parameter combination is admissible at the initial error I_e={I_e:g} "
                                       f"({reached}); {hint}")
            stop = f"no admissible combination at iteration {it} (bound {bound:.4g})"
            break
        kept = Xp[adm]
        lo, hi = kept.min(axis=0), kept.max(axis=0)
        med = np.median(kept, axis=0)
        full = fixed.copy()
        full[active] = med
        pred_err = predict(med[None, :])[0]
        rel = -pred_err if normalize else -pred_err / np.concatenate([np.full(t.size, t.scale)
                                                                        for t in problem.targets])
        _common.record(history, problem, progress, kind="narrow", values=full, errors=rel,
                       time=time.perf_counter() - t0, level=f"{problem.forward.name}-surrogate")
    values = fixed.copy()
    values[active] = np.median(kept, axis=0)
    band = {}
    for i, name in enumerate(space.names):
        if active[i]:
            j = int(np.sum(active[:i]))
            band[name] = (float(kept[:, j].min()), float(kept[:, j].max()))
        else:
            band[name] = (float(values[i]), float(values[i]))
    pred_err = predict(values[active][None, :])[0]
    e = -pred_err if normalize else -pred_err / np.concatenate([np.full(t.size, t.scale) for t in problem.targets])
    if verify:
        t0 = time.perf_counter()
        e = np.asarray(problem.errors_of(problem.outputs(values[None, :])[0]))
        _common.record(history, problem, progress, kind="verify", values=values, errors=e,
                       time=time.perf_counter() - t0)
    else:
        notes.append("errors at the answer are the surrogate's prediction")
    notes.append(f"range narrowing stopped: {stop}")
    info = {"oob_r2": r2, "importance": imp, "mean_importance": imp.mean(axis=0), "dropped": dropped,
            "narrowing": narrowing, "models": forests, "runs": runs, "n_runs": runs.n_runs, "stop": stop,
            "normalize": normalize}
    if ranges is not None:
        info["ranges"] = ranges
    return _common.make_result(problem, history, values, e, method="surrogate", tol=tol,
                               wall_time=time.perf_counter() - t_start, evaluations=problem.evaluations - evals0,
                               notes=notes, info=info, band=band)
