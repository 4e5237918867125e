"""Default ranges of the surrogate's run set (:mod:`~jaxbpm.calibrate.surrogate`) for parameters given no bounds.

A parameter without bounds (the space's default ``(initial / 100, initial * 100)``) starts within a factor
``_START_FACTOR`` either side of a cheap estimate (the closed form where it applies, else the initial value), sampled
uniformly in log space under log scaling. Where the runs' outputs do not reach a target, the range of each parameter
that moves the output towards it is widened by ``_WIDEN_FACTOR`` on that side and new runs are added there (all runs
are kept), a given number of rounds at most and never past the default bounds.
"""

from __future__ import annotations

import pathlib
import time

import numpy as np

from jaxbpm.calibrate.objective import CalibrationError, Problem
from jaxbpm.calibrate.runs import RunSet, latin_hypercube, run_missing

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


def _solve_runs(problem: Problem, X, lower, upper, *, seed, batch_size, progress, path, info, previous=None) -> RunSet:
    """Solve the parameter sets ``X`` whose leading rows may be solved already: those of ``previous`` (a run set)
    and those in ``path``'s run set (same leading rows) are not solved again; each finished row is stored there as
    it arrives, like :func:`run_set`."""
    space = problem.space
    sizes = [t.size for t in problem.targets]
    n = len(X)
    runs = RunSet(parameter_names=space.names, X=X, lower=np.asarray(lower, dtype=np.float64),
                  upper=np.asarray(upper, dtype=np.float64), output_names=problem.target_names, output_sizes=sizes,
                  Y=np.full((n, int(np.sum(sizes))), np.nan), solver=problem.forward.name,
                  info={"seed": seed, "batch_size": batch_size, **info}, done=np.zeros(n, bool))
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

    run_missing(problem, runs, X, todo, path, batch_size, progress)
    runs.info.update(wall_time=time.perf_counter() - t0, evaluations=problem.evaluations - evals0,
                     resumed=from_file)
    if path is not None and len(todo) and n >= stored_rows:
        runs.save(path)
    return runs


def _default_run_set(problem: Problem, n_runs, *, seed, batch_size, progress, path, widen, exclude, notes):
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
    runs = _solve_runs(problem, X, lo, hi, seed=seed, batch_size=batch_size, progress=progress, path=path, info=info)
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
        runs = _solve_runs(problem, np.concatenate([runs.X] + parts), lo, hi, seed=seed, batch_size=batch_size,
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


