"""Multi-fidelity calibration: cheap solvers first, dearer ones only while they change the answer.

Levels run from the cheapest to the most faithful solver, by default STE -> DSM (``jaxbpm.solve`` methods ``"ste"``
and ``"dsm"``; DEM can be appended as a last level, or asked for as a final check only). The first level is
calibrated; every later level first evaluates the current answer (one solve): if every target is within ``tol``
there, the answer is accepted at that level without calibrating it (early stop); else the level is calibrated
starting from the answer (escalation). With one free scale and bonds-only elasticity the check solve itself gives the
level's exact answer (every stiffness is proportional to the scale): the answer is corrected at no further solve. Each level is calibrated with the closed form where it applies (bonds-only
elasticity), else with Adam (autodiff gradients on pure models, forward differences otherwise). The result reports
the evaluations and time per level.
"""

from __future__ import annotations

import time
from typing import Sequence

import numpy as np

import jaxbpm.calibrate._common as _common
from jaxbpm.calibrate.adam import adam
from jaxbpm.calibrate.closed_form import closed_form, one_scale_answer
from jaxbpm.calibrate.objective import CalibrationError, Forward, ParameterSpace, Problem, forward_model
from jaxbpm.calibrate.history import CalibrationResult, History

__all__ = ["default_levels", "calibrate_level", "multifidelity"]


def default_levels() -> tuple[str, ...]:
    """The default multi-fidelity levels.

    Returns:
      ``("ste", "dsm")`` when the STE solver is available, else ``("dsm",)``.
    """
    from jaxbpm import solving as solve_mod

    return ("ste", "dsm") if "ste" in solve_mod.METHODS else ("dsm",)


def calibrate_level(problem: Problem, *, tol: float, shortcut: bool = True, progress=None,
                    adam_options: dict | None = None) -> CalibrationResult:
    """Calibrate one level: the closed form where it applies (and the targets determine the moduli), else Adam.

    Args:
      problem: the targets, parameters and the level's forward.
      tol: relative tolerance on every target.
      shortcut: use the closed form where it applies.
      progress: True (print), a callable ``(row, parameter_names, target_names)`` or None.
      adam_options: options of :func:`~jaxbpm.calibrate.adam.adam` (default gradient: autodiff on a differentiable
        forward, else forward differences).

    Returns:
      The level's :class:`CalibrationResult`.
    """
    ok, why = problem.closed_form_applies()
    m = sum(t.size for t in problem.targets)
    if shortcut and ok and m >= problem.space.n:
        return closed_form(problem, tol=tol, progress=progress)
    opts = {"gradient": "autodiff" if problem.differentiable else "fd-forward"}
    opts.update(adam_options or {})
    res = adam(problem, tol=tol, progress=progress, **opts)
    if shortcut and not ok:
        res.notes.append(f"no closed form: {why}")
    return res


def _forward(level, sample, scenes, solve_options) -> Forward:
    if isinstance(level, Forward):
        return level
    if isinstance(level, str):
        return forward_model(sample, scenes, level, **(solve_options or {}).get(level, {}))
    raise CalibrationError(f"a level must be a solver name or a Forward, got {level!r}")


def multifidelity(sample, scenes, targets, space: ParameterSpace, *, levels: Sequence | None = None,
                  tol: float = 0.05, shortcut: bool = True, solve_options: dict | None = None,
                  adam_options: dict | None = None, progress=None) -> CalibrationResult:
    """Calibrate through ``levels``, from the cheapest solver to the most faithful (see the module docstring).

    Args:
      sample: a :class:`~jaxbpm.Sample`, or ``{scene key: Sample}``.
      scenes: a scene or ``{key: scene}``.
      targets: :class:`Target` s or ``{observable: value}``.
      space: the free parameters.
      levels: solver names or :class:`Forward` s; default :func:`default_levels`.
      tol: relative tolerance on every target.
      shortcut: use the closed form where it applies.
      solve_options: ``{solver name: options for jaxbpm.solve}``.
      adam_options: options of :func:`~jaxbpm.calibrate.adam.adam` where a level needs it.
      progress: True (print), a callable ``(row, parameter_names, target_names)`` or None.

    Returns:
      The answer of the last level reached (``method="multi-fidelity"``), its ``levels`` one entry per level:
      ``solver``, ``action`` (``"calibrated"``, ``"corrected"``: one free scale, the closed form applied to the
      check solve of the previous answer, exact to that level at no further solve; ``"accepted"``: the previous
      answer was within ``tol`` there, or ``"escalated"``: it was not and the level was calibrated),
      ``evaluations``, ``wall_time``, ``max_error`` and ``errors``. ``info["answer_level"]`` names the level that
      gave the answer, ``info["error_vs_most_accurate"]`` its largest error against the last (most faithful) level
      that was solved.

    Raises:
      CalibrationError: no level, a level that is neither a solver name nor a :class:`Forward`, or a level's
        calibration that fails.
    """
    t_start = time.perf_counter()
    tol = _common.check_tol(tol)
    levels = list(default_levels() if levels is None else levels)
    if not levels:
        raise CalibrationError("levels must name at least one solver")
    progress = _common.progress_fn(progress)
    values = space.clip(space.initial)
    history = History(space.names, [])
    report, notes = [], []
    total = 0
    final = None
    for i, level in enumerate(levels):
        t0 = time.perf_counter()
        fwd = _forward(level, sample, scenes, solve_options)
        problem = Problem(fwd, targets, space.with_initial(values))
        if not history.target_names:
            history.target_names = problem.target_names
        if i > 0:
            y = problem.outputs(values[None, :])[0]
            e = np.asarray(problem.errors_of(y))
            _common.record(history, problem, progress, kind="check", values=values, errors=e,
                           time=time.perf_counter() - t0)
            if shortcut and space.n == 1 and problem.closed_form_applies()[0]:
                # one free scale: the check solve itself gives this level's exact answer (every output is
                # proportional to the scale), at no further solve
                values, pred = one_scale_answer(problem, values, y)
                e_new = np.asarray(problem.errors_of(pred))
                _common.record(history, problem, progress, kind="prediction", values=values, errors=e_new, time=0.0)
                final = _common.make_result(problem, History(space.names, problem.target_names), values, e_new,
                                            method="multi-fidelity", tol=tol, wall_time=0.0, evaluations=0)
                report.append({"solver": fwd.name, "action": "corrected", "evaluations": problem.evaluations,
                               "wall_time": time.perf_counter() - t0,
                               "max_error": float(problem.max_errors(e_new).max()),
                               "errors": problem.signed_errors(e_new), "error_before": problem.signed_errors(e)})
                notes.append(f"{fwd.name}: the closed form applied to the check solve (one free scale): exact to "
                             f"{fwd.name}, the previous level's answer was off by up to "
                             f"{100 * float(problem.max_errors(e).max()):.3g} %")
                total += problem.evaluations
                continue
            if np.all(problem.max_errors(e) <= tol):
                final = _common.make_result(problem, History(space.names, problem.target_names), values, e,
                                            method="multi-fidelity", tol=tol, wall_time=0.0, evaluations=0)
                report.append({"solver": fwd.name, "action": "accepted", "evaluations": problem.evaluations,
                               "wall_time": time.perf_counter() - t0, "max_error": float(problem.max_errors(e).max()),
                               "errors": problem.signed_errors(e)})
                total += problem.evaluations
                continue
        res = calibrate_level(problem, tol=tol, shortcut=shortcut, progress=progress, adam_options=adam_options)
        history.extend(res.history)
        values = np.asarray([res.values[n] for n in space.names])
        notes += [f"{fwd.name}: {n}" for n in res.notes]
        final = res
        report.append({"solver": fwd.name, "action": "calibrated" if i == 0 else "escalated",
                       "method": res.method, "evaluations": problem.evaluations, "wall_time": time.perf_counter() - t0,
                       "max_error": res.max_error, "errors": res.errors})
        total += problem.evaluations
    result = CalibrationResult(values=space.describe(values), params=final.params, errors=final.errors,
                               converged=bool(final.max_error <= tol), method="multi-fidelity",
                               solver=report[-1]["solver"], evaluations=total,
                               iterations=sum(r["kind"] != "prediction" for r in history.rows),
                               wall_time=time.perf_counter() - t_start, tol=tol,
                               history=history, notes=notes, levels=report,
                               info={"levels": [lv["solver"] for lv in report], "answer_level": report[-1]["solver"],
                                     "error_vs_most_accurate": float(final.max_error)})
    return result
