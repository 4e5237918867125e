"""The closed-form shortcut for bonds-only elasticity.

With bonds only and a linear (small-strain) scene, every stiffness is homogeneous of degree one in the bond
moduli: ``K(s E) = s K(E)``. Hence:

* **one free scale** (one material component, or several whose moduli keep given ratios): one solve at the current
  moduli gives the response per unit modulus, and the weighted least-squares factor on the targets is the answer;
* **several free components**: by Euler's theorem ``K(E) = sum_c E_c dK/dE_c`` exactly, so the targets give a small
  linear least-squares problem in the moduli on the linear responses ``dK/dE_c`` (one Jacobian: forward-mode
  autodiff of a pure model, or finite differences batched). The responses depend on the modulus ratios only, so
  the step is repeated from the new moduli until it changes them by less than ``step_tol`` (2-3 solves).
"""

from __future__ import annotations

import time

import numpy as np

import jaxbpm.calibrate._common as _common
from jaxbpm.calibrate.objective import CalibrationError, Problem
from jaxbpm.calibrate.history import CalibrationResult, History

__all__ = ["closed_form", "one_scale_answer"]


def _weighted_rows(problem: Problem):
    """Per-element row weights ``sqrt(w_k / m_k) / s_k`` and the target values ``[m]``."""
    rows, t = [], []
    for tg, w in zip(problem.targets, problem.weights):
        rows.append(np.full(tg.size, np.sqrt(w / tg.size) / tg.scale))
        t.append(np.reshape(tg.value, -1))
    return np.concatenate(rows), np.concatenate(t)


def one_scale_answer(problem: Problem, values: np.ndarray, outputs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The closed-form answer of one free scale from one solve: every output is proportional to the scale, so the
    outputs ``y`` at ``values`` give the weighted least-squares scale on the targets at no further solve.

    Args:
      problem: a problem whose closed form applies, with one free parameter.
      values: ``[1]`` the parameter value of the solve.
      outputs: ``[m]`` that solve's outputs.

    Returns:
      ``(answer [1], predicted outputs [m])`` (exact for one free scale).
    """
    return _least_squares(problem, (np.asarray(outputs) / values[0])[:, None])


def _least_squares(problem: Problem, jac: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The moduli (clipped to their bounds) whose linear responses ``jac [m, n]`` best meet the weighted targets, and
    the outputs they give, ``jac @ moduli``."""
    r, t = _weighted_rows(problem)
    answer = problem.space.clip(np.linalg.lstsq(r[:, None] * jac, r * t, rcond=None)[0])
    return answer, jac @ answer


def closed_form(problem: Problem, *, tol: float = 0.05, max_iterations: int = 6, step_tol: float = 1e-4,
                verify: bool = False, fd_step: float = 1e-4, progress=None) -> CalibrationResult:
    """Calibrate the bond moduli of a bonds-only elastic problem in closed form (see the module docstring).

    Args:
      problem: the targets, parameters (bond moduli only) and a forward linear in them.
      tol: relative tolerance on every target.
      max_iterations: linearisations at most (one for one free scale).
      step_tol: stop when the relative change of the moduli falls below it.
      verify: solve once more at the answer and report the measured errors (else the linear prediction, exact for
        one free scale).
      fd_step: the relative finite-difference step of the Jacobian where the forward is not differentiable.
      progress: True (print), a callable ``(row, parameter_names, target_names)`` or None.

    Returns:
      A :class:`CalibrationResult` (``method="closed-form"``).

    Raises:
      CalibrationError: the closed form does not apply (the message says why) or the targets do not determine the
        free moduli.
    """
    t_start = time.perf_counter()
    tol = _common.check_tol(tol)
    max_iterations = _common.check_count("max_iterations", max_iterations)
    ok, why = problem.closed_form_applies()
    if not ok:
        raise CalibrationError(f"the closed form does not apply: {why}")
    space = problem.space
    n = space.n
    m = sum(t.size for t in problem.targets)
    if m < n:
        raise CalibrationError(f"{n} free moduli but only {m} target value(s): the targets do not determine them; "
                               "tie components with Parameter(index=None, ratio=...) or add targets")
    progress = _common.progress_fn(progress)
    history = History(space.names, problem.target_names)
    evals0 = problem.evaluations
    r, _ = _weighted_rows(problem)  # (the rows weight the rank check)
    v = space.initial.copy()
    notes = [f"closed form: {why}"]
    answer = pred = None
    solves = 0
    for _ in range(max_iterations):
        solves += 1
        t0 = time.perf_counter()
        if n == 1:
            y = problem.outputs(v[None, :])[0]
            jac = (y / v[0])[:, None]
        elif problem.differentiable:
            y, jac = problem.jacobian(v)
        else:
            pts = v[None, :] * (1.0 + fd_step * np.eye(n))
            ys = problem.outputs(np.concatenate([v[None, :], pts]))
            y = ys[0]
            jac = (ys[1:] - y[None, :]).T / (fd_step * v[None, :])
        e = np.asarray(problem.errors_of(y))
        _common.record(history, problem, progress, kind="closed-form", values=v, errors=e,
                       time=time.perf_counter() - t0)
        a = r[:, None] * jac
        if np.linalg.matrix_rank(a, tol=1e-10 * np.abs(a).max()) < n:
            raise CalibrationError("the targets do not determine the free moduli (their responses are linearly "
                                   "dependent); tie components or add targets on other scenes")
        new, pred = _least_squares(problem, jac)
        change = np.max(np.abs(new / v - 1.0))
        answer = new
        if n == 1 or change < step_tol:
            break
        v = new
    e_pred = np.asarray(problem.errors_of(pred))
    t0 = time.perf_counter()
    if verify:
        e_pred = np.asarray(problem.errors_of(problem.outputs(answer[None, :])[0]))
        kind = "verify"
    else:
        kind = "prediction"
        notes.append("errors at the answer are the linear prediction (exact for one free scale)")
    _common.record(history, problem, progress, kind=kind, values=answer, errors=e_pred,
                   time=time.perf_counter() - t0)
    info = {"jacobian": "scaling" if n == 1 else ("autodiff" if problem.differentiable else "fd"),
            "verified": bool(verify)}
    return _common.make_result(problem, history, answer, e_pred, method="closed-form", tol=tol,
                               wall_time=time.perf_counter() - t_start,
                               evaluations=problem.evaluations - evals0, notes=notes, info=info,
                               iterations=solves + int(verify))
