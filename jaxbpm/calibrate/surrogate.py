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

import time

import numpy as np

import jaxbpm.calibrate._common as _common
from jaxbpm._renamed import batch_size_keyword
from jaxbpm.calibrate.objective import CalibrationError, Problem
from jaxbpm.calibrate.history import CalibrationResult, History
from jaxbpm.calibrate.ranges import _default_run_set, _defaulted, _describe_reach, _lhs, _log_mask, _reach, _trim
from jaxbpm.calibrate.runs import RunSet, latin_hypercube, run_set

__all__ = ["RunSet", "run_set", "fit_forests", "surrogate", "latin_hypercube"]

def _errors(problem: Problem, runs: RunSet, normalize: bool) -> np.ndarray:
    cols = []
    for t in problem.targets:
        y = runs.output(t.name, t.size)
        err = np.reshape(t.value, (1, -1)) - y
        cols.append(err / t.scale if normalize else err)
    return np.concatenate(cols, axis=1)


def fit_forests(X, err, *, n_trees=500, max_features=1 / 3, seed=0, n_jobs=None, regressor=None):
    """Fit the surrogate of the errors ``err`` on the parameter sets ``X``.

    Args:
      X: parameter sets ``[N, n]``.
      err: errors ``[N, m]`` (target minus run, per element).
      n_trees, max_features: the forests' trees and the fraction of the inputs per split.
      seed: ``random_state`` of the first forest (``seed + column`` for each column), or of ``regressor`` where its
        own is ``None``.
      n_jobs: parallel jobs, passed on where the model takes them.
      regressor: ``None``: one random forest per column of ``err`` (out-of-bag scores). Else a scikit-learn regressor,
        cloned and fitted once on all columns: natively where it supports several outputs, else wrapped in
        :class:`sklearn.multioutput.MultiOutputRegressor`.

    Returns:
      ``(models, oob_r2 [m], importance [m, n])``: ``oob_r2`` from the model's out-of-bag prediction (e.g. a forest
      with ``oob_score=True``), ``importance`` from its ``feature_importances_`` (one model for all columns: the same
      row for each); both NaN where the model reports none.
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
    them. scikit-learn's own ``predict`` dispatches every tree through joblib, a fixed cost per tree whatever the
    number of points, and the narrowing loop predicts twice per iteration."""
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


def surrogate(problem: Problem, *, runs: RunSet | None = None, n_runs: int = 100, I_e: float = 0.2, L_s: int = 1000,
              it_max: int = 50, n_trees: int = 500, max_features: float = 1 / 3, exclude: float = 0.05,
              normalize: bool = True, importance_threshold: float | None = None, resample_runs: int | None = None,
              seed: int = 0, tol: float = 0.05, verify: bool = False, n_jobs=None, batch_size: int | None = None,
              regressor=None, runs_file=None, progress=None, widen: int = 3, chunk: int | None = None
              ) -> CalibrationResult:
    """Calibrate with the random-forest surrogate of Irazabal et al. 2023 (see the module docstring).

    Ranges: a parameter with explicit ``bounds`` is sampled within them. A parameter without (the space's default
    ``(initial / 100, initial * 100)``) starts within a factor 2 either side of a cheap estimate -- the closed form
    where it applies (bonds-only elasticity: one solve), else its initial value -- sampled uniformly in log space
    (log scaling); where the runs' outputs do not reach a target, its range is widened by a factor 4 on the side
    that moves the output towards the target and ``n_runs // 2`` runs are added there (all runs are kept), at most
    ``widen`` rounds and never past the default bounds. The ranges of each round are in ``info["ranges"]`` and
    each widening is stated in the notes.

    Args:
      problem: the targets, parameters and forward.
      runs: a stored :class:`RunSet` to re-use (no new runs); else ``n_runs`` are solved.
      n_runs: the runs of the training set.
      I_e: initial admissible error (relative to each target's scale when ``normalize``, else in the output's
        units).
      L_s: combinations per iteration.
      it_max: iterations at most.
      n_trees, max_features: the forests (Irazabal et al. 2023: 500 and 1/3).
      exclude: the fraction cut off each end of the training ranges before the narrowing.
      normalize: train on errors divided by each target's scale.
      importance_threshold: drop parameters whose mean importance is below it.
      resample_runs: after dropping parameters, solve that many new runs on the remaining ones.
      seed: the seed of the Latin hypercubes and the forests.
      tol: relative tolerance on every target.
      verify: solve once at the answer and report the measured errors (else the surrogate's prediction).
      n_jobs: parallel jobs of the forests or of the regressor where it takes them.
      batch_size: solve the runs in batches of this many (bounds the memory of a ``vmap`` of large solves; ``None``:
        one batch).
      regressor: a scikit-learn regressor instance (e.g. ``ExtraTreesRegressor(n_estimators=200)``,
        ``KNeighborsRegressor(5)``) fitted instead of the forests, cloned per fit (see :func:`fit_forests`;
        n_trees and max_features then unused).
      runs_file: an HDF5 file the run set is stored in as its runs finish, and resumed from when called again (see
        :func:`run_set`; the runs go to the problem's ``executor`` where it has one).
      progress: True (a bar of the run set and a line per iteration), a callable
        ``(row, parameter_names, target_names)`` or None.
      widen: widening rounds at most for default ranges.
      chunk: deprecated name of ``batch_size`` (a :class:`DeprecationWarning`); removed in the next release.

    Returns:
      A :class:`CalibrationResult` at the median of the last admissible combinations, ``band`` their ranges.
      ``info`` holds ``oob_r2 [m]``, ``importance [m, n]``, ``mean_importance``, ``dropped``, ``narrowing`` (per
      iteration: admissible count, error bound, ranges), the fitted models (``models``), the run set (``runs``)
      and, for default ranges, the rounds of ``ranges`` (per round: lower, upper, runs so far, the parameters
      widened and the outputs the runs reach per target element).

    Raises:
      CalibrationError: an option out of range, a run set that does not fit the problem, or no admissible
        combination at the initial error ``I_e`` (the message gives the outputs the runs reach).
      TypeError: both ``batch_size`` and ``chunk``.
    """
    batch_size = batch_size_keyword(batch_size, chunk)
    t_start = time.perf_counter()
    tol, L_s, it_max, n_trees, widen = _check_options(tol=tol, L_s=L_s, it_max=it_max, n_trees=n_trees, I_e=I_e,
                                                      exclude=exclude, max_features=max_features,
                                                      regressor=regressor, widen=widen)
    show_runs = progress is True  # (a bar of the run set; iterations as lines)
    progress = _common.progress_fn(progress)
    evals0 = problem.evaluations
    notes = []
    space = problem.space
    runs, ranges = _training_runs(problem, runs, runs_file=runs_file, n_runs=n_runs, seed=seed, batch_size=batch_size,
                                  show_runs=show_runs, widen=widen, exclude=exclude, notes=notes)
    fit = dict(n_trees=n_trees, max_features=max_features, seed=seed, n_jobs=n_jobs, regressor=regressor)
    forests, r2, imp = fit_forests(runs.X, _errors(problem, runs, normalize), **fit)
    model = _Surrogate(forests, np.ones(space.n, bool), space.clip(space.initial), reduced=False)
    dropped = []
    if importance_threshold is not None:
        runs, model, r2, imp, dropped = _drop_unimportant(problem, runs, model, r2, imp, importance_threshold,
                                                          resample_runs, normalize=normalize, batch_size=batch_size,
                                                          show_runs=show_runs, fit=fit, notes=notes)
    active, fixed = model.active, model.fixed
    history = History(space.names, problem.target_names)
    kept, narrowing, stop = _narrow(problem, model, runs, ranges, history, progress, I_e=I_e, L_s=L_s, it_max=it_max,
                                    exclude=exclude, seed=seed, normalize=normalize)
    values = fixed.copy()
    values[active] = np.median(kept, axis=0)
    band = _band(space.names, values, active, kept)
    pred_err = model(values[active][None, :])[0]
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
            "narrowing": narrowing, "models": model.forests, "runs": runs, "n_runs": runs.n_runs, "stop": stop,
            "normalize": normalize}
    if ranges is not None:
        info["ranges"] = ranges
    return _common.make_result(problem, history, values, e, method="surrogate", tol=tol,
                               wall_time=time.perf_counter() - t_start, evaluations=problem.evaluations - evals0,
                               notes=notes, info=info, band=band)


def _check_options(*, tol, L_s, it_max, n_trees, I_e, exclude, max_features, regressor, widen):
    """The surrogate's options checked: ``(tol, L_s, it_max, n_trees, widen)`` as numbers."""
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
    return tol, L_s, it_max, n_trees, widen


def _training_runs(problem: Problem, runs, *, runs_file, n_runs, seed, batch_size, show_runs, widen, exclude, notes):
    """The training run set: ``runs`` (stored) as given, else solved (default ranges centred and widened, see
    :func:`_default_run_set`). Returns ``(runs, ranges)``, ``ranges`` None unless the ranges were defaulted."""
    space = problem.space
    if runs is not None and runs_file is not None:
        raise CalibrationError("give runs (a stored run set) or runs_file (where to solve and store one), not both")
    if runs is None and _defaulted(space).any():
        n_runs = _common.check_count("n_runs", n_runs, 2)
        return _default_run_set(problem, n_runs, seed=seed, batch_size=batch_size, progress=show_runs, path=runs_file,
                                widen=widen, exclude=exclude, notes=notes)
    if runs is None:
        return run_set(problem, n_runs, seed=seed, batch_size=batch_size, progress=show_runs, path=runs_file), None
    if not isinstance(runs, RunSet):
        raise CalibrationError(f"runs must be a RunSet, got {type(runs).__name__}")
    if runs.parameter_names != space.names:
        raise CalibrationError(f"the run set varies {runs.parameter_names}, the problem {space.names}")
    notes.append(f"re-used a stored run set of {runs.n_runs} runs (no new runs for training)")
    return runs, None


class _Surrogate:
    """The fitted models as a function of the active parameters ``Xa [N, n_active]``: predicted errors ``[N, m]``
    (the dropped parameters held at ``fixed``, unless the models were trained on the active ones only)."""

    def __init__(self, forests, active, fixed, *, reduced: bool):
        self.forests, self.active, self.fixed, self.reduced = forests, active, fixed, reduced

    def __call__(self, Xa) -> np.ndarray:
        if self.reduced:
            return _predict(self.forests, Xa)
        full = np.repeat(self.fixed[None, :], len(Xa), axis=0)
        full[:, self.active] = Xa
        return _predict(self.forests, full)


def _drop_unimportant(problem: Problem, runs, model: _Surrogate, r2, imp, threshold, resample_runs, *, normalize,
                      batch_size, show_runs, fit, notes):
    """Drop the parameters whose mean importance is below ``threshold`` (held at their initial values); with
    ``resample_runs``, solve that many new runs on the others and refit. Returns ``(runs, model, r2, imp,
    dropped)``."""
    space, fixed = problem.space, model.fixed
    mean_imp = imp.mean(axis=0)
    if np.isnan(mean_imp).any():
        raise CalibrationError(f"importance_threshold needs feature importances; the regressor "
                               f"{type(fit['regressor']).__name__} reports none")
    active = mean_imp >= threshold
    if not active.any():
        raise CalibrationError(f"every parameter's mean importance is below {threshold}")
    dropped = [n for n, a in zip(space.names, active) if not a]
    if not dropped:
        return runs, _Surrogate(model.forests, active, fixed, reduced=False), r2, imp, dropped
    notes.append(f"dropped parameters of low importance {dropped} (held at {fixed[~active].tolist()})")
    if not resample_runs:
        return runs, _Surrogate(model.forests, active, fixed, reduced=False), r2, imp, dropped
    sub = space.subspace([n for n, a in zip(space.names, active) if a], fixed)
    sub_problem = Problem(problem.forward, problem.targets, sub, executor=problem.executor, retries=problem.retries)
    sub_problem.evaluations = problem.evaluations
    sub_runs = run_set(sub_problem, resample_runs, seed=fit["seed"] + 1, batch_size=batch_size, progress=show_runs,
                       lower=runs.lower[active], upper=runs.upper[active])
    problem.evaluations = sub_problem.evaluations
    X_full = np.repeat(fixed[None, :], sub_runs.n_runs, axis=0)
    X_full[:, active] = sub_runs.X
    runs = RunSet(space.names, X_full, runs.lower, runs.upper, sub_runs.output_names, sub_runs.output_sizes,
                  sub_runs.Y, runs.solver, {**sub_runs.info, "resampled_from": runs.n_runs})
    err = _errors(problem, runs, normalize)
    forests, r2, imp_active = fit_forests(runs.X[:, active], err, **fit)
    imp = np.zeros((err.shape[1], space.n))
    imp[:, active] = imp_active
    notes.append(f"re-sampled {resample_runs} runs on the remaining parameters")
    return runs, _Surrogate(forests, active, fixed, reduced=True), r2, imp, dropped


def _narrow(problem: Problem, model: _Surrogate, runs: RunSet, ranges, history: History, progress, *, I_e, L_s,
            it_max, exclude, seed, normalize):
    """Iterative range narrowing (Irazabal et al. 2023): at iteration ``it`` keep the combinations whose predicted
    errors all lie within ``I_e / it`` and shrink the ranges to them. Returns ``(kept, narrowing, stop)``: the last
    admissible combinations ``[k, n_active]``, per iteration the bound, admissible count and ranges, and why it
    stopped."""
    space, active = problem.space, model.active
    logm = _log_mask(space)[active]  # default ranges narrow in log space; explicit bounds linearly
    lo, hi = _trim(runs.lower[active], runs.upper[active], logm, exclude)
    narrowing = []
    kept = None
    stop = "it_max reached"
    for it in range(1, it_max + 1):
        t0 = time.perf_counter()
        Xp = _lhs(L_s, lo, hi, logm, seed=seed + 1000 + it, optimize=False)
        P = model(Xp)
        bound = I_e / it
        adm = np.all(np.abs(P) <= bound, axis=1)
        narrowing.append({"iteration": it, "bound": bound, "admissible": int(adm.sum()),
                          "lower": lo.tolist(), "upper": hi.tolist()})
        if not adm.any():
            if kept is None:
                raise CalibrationError(_none_admissible(problem, runs, ranges, I_e))
            stop = f"no admissible combination at iteration {it} (bound {bound:.4g})"
            break
        kept = Xp[adm]
        lo, hi = kept.min(axis=0), kept.max(axis=0)
        med = np.median(kept, axis=0)
        full = model.fixed.copy()
        full[active] = med
        pred_err = model(med[None, :])[0]
        rel = -pred_err if normalize else -pred_err / np.concatenate([np.full(t.size, t.scale)
                                                                        for t in problem.targets])
        _common.record(history, problem, progress, kind="narrow", values=full, errors=rel,
                       time=time.perf_counter() - t0, level=f"{problem.forward.name}-surrogate")
    return kept, narrowing, stop


def _none_admissible(problem: Problem, runs: RunSet, ranges, I_e) -> str:
    """The message when no combination is admissible at the initial error: what the runs reach, and what to do."""
    reached = _describe_reach(_reach(problem, runs))
    hint = "widen the ranges or raise I_e"
    if ranges is not None:
        hint = (f"default ranges after {len(ranges) - 1} widening round(s)"
                + (", at the parameters' default bounds" if ranges[-1].get("at_bounds") else "")
                + "; give Parameter bounds, raise n_runs or widen, or raise I_e")
    return f"no parameter combination is admissible at the initial error I_e={I_e:g} ({reached}); {hint}"


def _band(names, values, active, kept) -> dict:
    """``{name: (lo, hi)}``: the range of the last admissible combinations (a dropped parameter: its value)."""
    band = {}
    for i, name in enumerate(names):
        if active[i]:
            j = int(np.sum(active[:i]))
            band[name] = (float(kept[:, j].min()), float(kept[:, j].max()))
        else:
            band[name] = (float(values[i]), float(values[i]))
    return band
