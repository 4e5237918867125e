"""Adam calibration driven by optax (Qu et al. 2020, section 3), with finite-difference or autodiff gradients.

The variable is ``z``, the free parameters in log form or target-scaled form (Qu et al. 2020, Eq. 10-11; see
:class:`~jaxbpm.calibrate.objective.ParameterSpace`). Each iteration evaluates the model at ``z``; once every target
lies within ``tol`` the calibration stops, else the gradient of the objective (Eq. 3) is taken and optax's Adam
(Eq. 4-8) makes the step (``optimizer=``: any other ``optax.GradientTransformation``; the step is applied with
``optax.apply_updates`` and the point then clipped to the parameter bounds). Options of Qu et al. 2020:

* ``loss_scaled``: the Adam step multiplied by the current loss L (Eq. 9): smaller steps near the target, larger far
  from it.
* ``first_estimate``: start from the targets themselves (Eq. 14: a bond modulus starts at the target Young's
  modulus). ``second_estimate``: after the first point, scale each parameter by target / model value of the target
  it is tied to (Eq. 15).
* ``simplified``: each parameter is tied to one target (``tie``) and the derivative of each parameter uses its tied
  target's term of L only (Eq. 16-19: a test does not depend on the parameters tied to the other tests).
  ``simplified=True`` (``"secant"``) runs one parameter set per iteration, as Qu et al. 2020 counts it: the step from
  the
  previous point perturbs every parameter at once, so the difference of each tied term between the two points over
  the parameter's change is its derivative (where a parameter moved by less than ``fd_step / 10`` since the previous
  point, or at the first point, one perturbed point is run instead). ``simplified="perturbed"`` always runs one
  perturbed point (all parameters perturbed at once) next to the point itself.

Gradients: ``"fd-forward"`` (n extra solves), ``"fd-central"`` (2n), run as one batch (``jax.vmap`` when the model
is a pure function, else one after another; Qu et al. 2020 Eq. 12-13), or ``"autodiff"`` (``jax.value_and_grad`` through
the model, one forward and one adjoint solve).
"""

from __future__ import annotations

import dataclasses
import time
from typing import Mapping

import jax
import jax.numpy as jnp
import numpy as np
import optax

import jaxbpm.calibrate._common as _common
from jaxbpm.calibrate.objective import CalibrationError, Problem
from jaxbpm.calibrate.history import CalibrationResult, History

__all__ = ["GRADIENTS", "adam", "loss_and_gradient", "tied_gradient"]

GRADIENTS = ("fd-forward", "fd-central", "autodiff")


def loss_and_gradient(problem: Problem, z, method: str = "autodiff", *, step: float = 1e-3,
                      tie: list[int] | None = None, base=None):
    """Loss, gradient ``dL/dz [n]`` and the relative errors at ``z``.

    Args:
      problem: the targets, parameters and forward.
      z: the point ``[n]`` in the optimisation variable.
      method: ``"autodiff"``, ``"fd-forward"`` or ``"fd-central"`` (perturbed points evaluated as one batch), or
        ``"simplified"`` (needs ``tie``: one point with every parameter perturbed, Qu et al. 2020 Eq. 16-19).
      step: the finite-difference step in ``z``.
      tie: the index of the target each parameter is tied to (the simplified scheme).
      base: the errors at ``z`` when already known (finite differences then skip the base solve).

    Returns:
      ``(loss, gradient [n], errors [m])``.

    Raises:
      CalibrationError: an unknown method, a step outside (0, 1), or the simplified scheme without ``tie``.
    """
    z = np.asarray(z, dtype=np.float64)
    n = z.size
    space = problem.space
    if method == "autodiff":
        loss, g, y = problem.value_and_grad(z)
        return loss, g, np.asarray(problem.errors_of(y))
    if not (isinstance(step, (int, float)) and 0 < step < 1):
        raise CalibrationError(f"fd_step must lie in (0, 1), got {step!r}")
    if method == "fd-forward":
        pts = z[None, :] + step * np.eye(n)
    elif method == "fd-central":
        pts = np.concatenate([z[None, :] + step * np.eye(n), z[None, :] - step * np.eye(n)])
    elif method == "simplified":
        if tie is None:
            raise CalibrationError("the simplified scheme needs a tie between each parameter and one target")
        pts = (z + step)[None, :]
    else:
        raise CalibrationError(f"unknown gradient {method!r}; choose one of {GRADIENTS}")
    if base is None and method != "fd-central":
        pts = np.concatenate([z[None, :], pts])
    y = problem.outputs(space.from_z(pts))
    errs = [np.asarray(problem.errors_of(row)) for row in y]
    if base is None and method != "fd-central":
        e0, errs = errs[0], errs[1:]
    elif base is None:
        e0 = np.asarray(problem.errors_of(problem.outputs(space.from_z(z[None, :]))[0]))
    else:
        e0 = np.asarray(base)
    loss0 = float(problem.loss_of(e0))
    if method == "fd-forward":
        g = np.array([(float(problem.loss_of(e)) - loss0) / step for e in errs])
    elif method == "fd-central":
        g = np.array([(float(problem.loss_of(errs[i])) - float(problem.loss_of(errs[n + i]))) / (2 * step)
                      for i in range(n)])
    else:
        g = tied_gradient(problem, e0, errs[0], np.full(n, step), tie)
    return loss0, g, e0


def tied_gradient(problem: Problem, e, e_other, dz, tie: list[int]) -> np.ndarray:
    """The simplified scheme's gradient (Qu et al. 2020, Eq. 16-19) at the point of errors ``e``: each parameter's
    derivative of its tied target's term ``w_k mean(e_k^2)``, by the chain rule with the errors' difference quotient,
    ``2 w_k mean(e_k (e'_k - e_k)) / dz_i``.

    The difference quotient of the squared errors themselves, ``(w_k mean(e'_k^2) - w_k mean(e_k^2)) / dz_i``, is
    the slope at the midpoint of the two points: where a target's error changes sign between them it has the wrong
    sign (the squared error can fall while the error passes through zero and grows on the other side).

    Args:
      problem: the targets (their weights and slices).
      e: the relative errors ``[m]`` at the point.
      e_other: the errors ``[m]`` at the other point (perturbed, or the previous point of the secant).
      dz: ``[n]`` the change of each parameter from the point to the other one.
      tie: the index of the target each parameter is tied to.

    Returns:
      ``[n]`` the gradient.
    """
    return _chain(problem, e, _slopes(problem, e, e_other, dz, tie), tie)


def _slopes(problem: Problem, e, e_other, dz, tie: list[int]) -> list[np.ndarray]:
    """Each parameter's difference quotient of its tied target's errors, ``(e'_k - e_k) / dz_i``."""
    diff = np.asarray(e_other, dtype=np.float64) - np.asarray(e, dtype=np.float64)
    return [diff[problem.slices[k]] / dz[i] for i, k in enumerate(tie)]


def _chain(problem: Problem, e, slopes: list[np.ndarray], tie: list[int]) -> np.ndarray:
    """``2 w_k mean(e_k slope_i)`` per parameter: the derivative of its tied target's term."""
    e = np.asarray(e, dtype=np.float64)
    return np.array([2.0 * problem.weights[k] * np.mean(e[problem.slices[k]] * slopes[i]) for i, k in enumerate(tie)])


def adam(problem: Problem, *, gradient: str = "fd-forward", learning_rate: float = 0.1, b1: float = 0.9,
         b2: float = 0.99, eps: float = 1e-8, tol: float = 0.05, max_iterations: int = 20, loss_scaled: bool = False,
         first_estimate: bool | None = None, second_estimate: bool | None = None, tie: Mapping[str, str] | None = None,
         simplified: bool = False, fd_step: float = 1e-3, optimizer: optax.GradientTransformation | None = None,
         progress=None) -> CalibrationResult:
    """Calibrate ``problem`` with Adam (Qu et al. 2020), stopping at the first point where every target is within
    ``tol``.

    Args:
      problem: the targets, parameters and forward.
      gradient: one of :data:`GRADIENTS`.
      learning_rate, b1, b2, eps: Adam's (Qu et al. 2020 uses b2 = 0.99); the step is in ``z`` (log form: a relative
        change).
      tol: stop when every target's relative error is within it (Qu et al. 2020 5.1.2: 5 %).
      max_iterations: evaluated points at most (estimates included).
      loss_scaled: the step multiplied by the loss (Eq. 9).
      first_estimate, second_estimate: Eq. 14 / 15; ``None`` = on where they make sense (a tie exists; Eq. 14 only
        when each parameter and its target share units, e.g. bond E and Young's modulus).
      tie: ``{parameter: target}`` (default: the only parameter to the only scalar target).
      simplified: Eq. 16-19 (needs ties): ``True``/``"secant"`` (one parameter set per iteration) or
        ``"perturbed"`` (one perturbed set per iteration).
      fd_step: the finite-difference step in ``z`` (target-scaled form: a fraction of the target).
      optimizer: an ``optax.GradientTransformation`` that makes the step instead (e.g. ``optax.sgd(0.05)``,
        ``optax.chain(optax.clip_by_global_norm(1.0), optax.adam(0.1))``; learning_rate, b1, b2 and eps are then
        unused); default ``optax.adam(learning_rate, b1=b1, b2=b2, eps=eps)``.
      progress: True (print), a callable ``(row, parameter_names, target_names)`` or None.

    Returns:
      A :class:`CalibrationResult` at the best point seen (``info``: the gradient, optimiser and options used).

    Raises:
      CalibrationError: an unknown gradient or optimiser, an option out of range, autodiff on a forward that is not
        differentiable, or an option that needs ties (estimates, the simplified scheme) without them.
    """
    t_start = time.perf_counter()
    plan = _plan(problem, gradient=gradient, learning_rate=learning_rate, b1=b1, b2=b2, eps=eps, tol=tol,
                 max_iterations=max_iterations, first_estimate=first_estimate, second_estimate=second_estimate,
                 tie=tie, simplified=simplified, optimizer=optimizer)
    progress = _common.progress_fn(progress)
    space = problem.space
    notes = []
    run = _Run(problem, plan, History(space.names, problem.target_names), progress)
    run.start(notes)
    evals0 = problem.evaluations
    for it in range(1, plan.max_iterations + 1):
        if run.iteration(last=it == plan.max_iterations, loss_scaled=loss_scaled, fd_step=fd_step, notes=notes):
            break
    _, values, e = run.best
    if loss_scaled:
        notes.append("step scaled by the loss (Qu et al. 2020, Eq. 9)")
    if simplified:
        notes.append("simplified scheme (Qu et al. 2020, Eq. 16-19): " + (
            f"one parameter set per iteration ({run.secants} secant gradients between successive points)"
            if plan.secant else "one perturbed point per iteration"))
    info = {"gradient": plan.grad_method, "optimizer": plan.opt_name,
            "learning_rate": learning_rate if plan.opt_name == "adam" else None, "scaling": space.scaling,
            "first_estimate": bool(plan.first_estimate), "second_estimate": bool(plan.second_estimate),
            "loss_scaled": bool(loss_scaled), "simplified": ("secant" if plan.secant else "perturbed") if simplified
            else False, "secant_gradients": run.secants, "fd_step": fd_step}
    return _common.make_result(problem, run.history, values, e, method="adam", tol=plan.tol,
                               wall_time=time.perf_counter() - t_start,
                               evaluations=problem.evaluations - evals0, notes=notes, info=info)


@dataclasses.dataclass(frozen=True)
class _Plan:
    """Adam's checked options: what to run, decided before the first solve."""

    tol: float
    max_iterations: int
    gradient: str
    grad_method: str  # the gradient the iterations take ("simplified" for the simplified scheme)
    optimizer: optax.GradientTransformation
    opt_name: str
    ties: list[int] | None
    secant: bool
    first_estimate: bool
    second_estimate: bool


def _plan(problem: Problem, *, gradient, learning_rate, b1, b2, eps, tol, max_iterations, first_estimate,
          second_estimate, tie, simplified, optimizer) -> _Plan:
    """Check Adam's options against ``problem`` and settle the defaults (the estimates, the optimiser)."""
    if gradient not in GRADIENTS:
        raise CalibrationError(f"unknown gradient {gradient!r}; choose one of {GRADIENTS}")
    tol = _common.check_tol(tol)
    max_iterations = _common.check_count("max_iterations", max_iterations)
    for name, v in (("learning_rate", learning_rate), ("b1", b1), ("b2", b2), ("eps", eps)):
        if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0) or (name in ("b1", "b2") and v >= 1):
            raise CalibrationError(f"{name} must be a number > 0{' and < 1' if name in ('b1', 'b2') else ''}, "
                                   f"got {v!r}")
    if optimizer is None:
        optimizer = optax.adam(learning_rate, b1=b1, b2=b2, eps=eps)
        opt_name = "adam"
    elif isinstance(optimizer, optax.GradientTransformation):
        opt_name = "custom"
    else:
        raise CalibrationError(f"optimizer must be an optax.GradientTransformation (e.g. optax.sgd(0.05)), got "
                               f"{type(optimizer).__name__}")
    if gradient == "autodiff" and not problem.differentiable:
        raise CalibrationError(f"gradient='autodiff' needs a pure (differentiable) model; the "
                               f"{problem.forward.name} model has none for targets {problem.target_names} "
                               "(use 'fd-forward' or 'fd-central')")
    ties = _common.resolve_tie(problem, tie)
    if simplified not in (False, True, "secant", "perturbed"):
        raise CalibrationError(f"simplified must be False, True / 'secant' or 'perturbed', got {simplified!r}")
    if simplified and ties is None:
        raise CalibrationError("simplified=True needs each parameter tied to one scalar target: pass "
                               "tie={parameter: target}")
    if simplified and gradient == "autodiff":
        raise CalibrationError("the simplified scheme is a finite-difference scheme; use gradient='fd-forward'")
    for flag, name in ((first_estimate, "first_estimate"), (second_estimate, "second_estimate")):
        if flag and ties is None:
            raise CalibrationError(f"{name}=True needs each parameter tied to one scalar target: pass "
                                   "tie={parameter: target}")
    if first_estimate is None:
        first_estimate = ties is not None and _common.same_units(problem, ties)
    if second_estimate is None:
        second_estimate = ties is not None
    return _Plan(tol=tol, max_iterations=max_iterations, gradient=gradient,
                 grad_method="simplified" if simplified else gradient, optimizer=optimizer, opt_name=opt_name,
                 ties=ties, secant=simplified in (True, "secant"), first_estimate=first_estimate,
                 second_estimate=second_estimate)


class _Run:
    """The state of one Adam calibration between iterations: the point ``z``, the optimiser's state, the best
    point seen, the previous point (the simplified scheme's secant) and the history."""

    def __init__(self, problem: Problem, plan: _Plan, history: History, progress):
        self.problem, self.plan, self.history, self.progress = problem, plan, history, progress
        self.best = None  # (loss, values, errors)
        self.previous = None  # (z, errors) of the last evaluated point
        self.secants = 0
        self.slopes: dict[int, np.ndarray] = {}  # the simplified scheme's last difference quotient per parameter
        self.pending_second = bool(plan.second_estimate)

    def start(self, notes: list[str]) -> None:
        """The first point: the initial values, or the targets themselves (Eq. 14)."""
        problem, space = self.problem, self.problem.space
        values = space.initial.copy()
        self.kind = "initial"
        if self.plan.first_estimate:
            values = space.clip([problem.targets[k].value for k in self.plan.ties])
            self.kind = "estimate-1"
            notes.append("first estimate (Qu et al. 2020, Eq. 14): each parameter starts at its target's value")
        self.z = space.to_z(values)
        self.state = self.plan.optimizer.init(jnp.asarray(self.z))

    def iteration(self, *, last: bool, loss_scaled: bool, fd_step: float, notes: list[str]) -> bool:
        """Evaluate the point ``z`` and move to the next one (the second estimate or an Adam step); True when the
        calibration stops here (every target within ``tol``, or the last iteration)."""
        t0 = time.perf_counter()
        loss, g, e = self._evaluate(last)
        values = self.problem.space.from_z(self.z)
        if self.best is None or loss < self.best[0]:
            self.best = (loss, values.copy(), e.copy())
        if bool(np.all(self.problem.max_errors(e) <= self.plan.tol)) or last:
            self._record(values, e, t0)
            return True
        if self.pending_second:
            self.pending_second = False
            if self._second_estimate(values, e, t0, notes):
                return False
            notes.append("second estimate skipped: a model value has the opposite sign of its target")
        if g is None:
            g = self._gradient(e, fd_step)
        self._record(values, e, t0)
        self._step(g, loss, e, loss_scaled)
        return False

    def _evaluate(self, last: bool):
        """Loss, gradient (autodiff only, else None) and errors at ``z``."""
        problem, z = self.problem, self.z
        if self.plan.gradient == "autodiff" and not self.pending_second and not last:
            return loss_and_gradient(problem, z, "autodiff")
        e = np.asarray(problem.errors_of(problem.outputs(problem.space.from_z(z[None, :]))[0]))
        return float(problem.loss_of(e)), None, e

    def _record(self, values, e, t0) -> None:
        _common.record(self.history, self.problem, self.progress, kind=self.kind, values=values, errors=e,
                       time=time.perf_counter() - t0)

    def _second_estimate(self, values, e, t0, notes) -> bool:
        """Scale each parameter by its tied target over the model value (Eq. 15); False where a model value has
        the opposite sign of its target (the estimate is skipped)."""
        problem, space = self.problem, self.problem.space
        ratio = np.array([problem.targets[k].value / (problem.targets[k].value + problem.targets[k].scale
                                                      * e[problem.slices[k]][0]) for k in self.plan.ties])
        if not np.all(ratio > 0):
            return False
        self._record(values, e, t0)
        self.previous = (self.z.copy(), e.copy())
        self.z = space.to_z(space.clip(values * ratio))
        self.kind = "estimate-2"
        if not any("Eq. 15" in n for n in notes):
            notes.append("second estimate (Qu et al. 2020, Eq. 15): parameters scaled by target / model value")
        return True

    def _gradient(self, e, fd_step):
        """The gradient at ``z``: the simplified scheme's secant between successive points (:func:`tied_gradient`;
        a parameter that moved by less than ``fd_step / 10`` keeps the last slope measured for it), else finite
        differences around ``z`` (the simplified scheme's one perturbed point where a parameter has no slope yet)."""
        problem, z, previous, ties = self.problem, self.z, self.previous, self.plan.ties
        if self.plan.secant and previous is not None:
            dz = previous[0] - z
            moved = np.abs(dz) >= 0.1 * fd_step
            if np.any(moved):
                fresh = _slopes(problem, e, previous[1], np.where(moved, dz, 1.0), ties)
                self.slopes.update({i: fresh[i] for i in np.flatnonzero(moved)})
            if len(self.slopes) == len(ties):
                self.secants += 1
                return _chain(problem, e, [self.slopes[i] for i in range(len(ties))], ties)
        if self.plan.grad_method == "simplified":  # one point, every parameter perturbed; its slopes are kept
            e1 = np.asarray(problem.errors_of(problem.outputs(problem.space.from_z((z + fd_step)[None, :]))[0]))
            self.slopes.update(enumerate(_slopes(problem, e, e1, np.full(z.size, fd_step), ties)))
            return _chain(problem, e, [self.slopes[i] for i in range(len(ties))], ties)
        _, g, _ = loss_and_gradient(problem, z, self.plan.grad_method, step=fd_step, tie=ties, base=e)
        return g

    def _step(self, g, loss, e, loss_scaled) -> None:
        """The optimiser's step from ``z`` (times the loss for Eq. 9), clipped to the parameter bounds."""
        space, z = self.problem.space, self.z
        with jax.numpy_dtype_promotion("standard"):  # optax mixes float decay rates with an int32 step count
            updates, self.state = self.plan.optimizer.update(jnp.asarray(g), self.state, jnp.asarray(z))
            updates = np.asarray(updates)
            if loss_scaled:
                updates = updates * loss
            stepped = np.asarray(optax.apply_updates(z, updates), dtype=np.float64)
        self.previous = (z.copy(), e.copy())
        self.z = space.to_z(space.clip(space.from_z(stepped)))
        self.kind = "adam"
