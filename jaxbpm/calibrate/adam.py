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

import time
from typing import Mapping

import jax
import jax.numpy as jnp
import numpy as np
import optax

import jaxbpm.calibrate._common as _common
from jaxbpm.calibrate.objective import CalibrationError, Problem
from jaxbpm.calibrate.result import CalibrationResult, History

__all__ = ["GRADIENTS", "adam", "loss_and_gradient"]

GRADIENTS = ("fd-forward", "fd-central", "autodiff")


def loss_and_gradient(problem: Problem, z, method: str = "autodiff", *, step: float = 1e-3,
                      tie: list[int] | None = None, base=None):
    """Loss, gradient ``dL/dz [n]`` and the relative errors at ``z``.

    method: ``"autodiff"``, ``"fd-forward"`` or ``"fd-central"`` (perturbed points evaluated as one batch), or
    ``"simplified"`` (needs ``tie``: one point with every parameter perturbed, Qu et al. 2020 Eq. 16-19).
    base: the errors at ``z`` when already known (finite differences then skip the base solve).
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
        parts0, parts1 = problem.target_losses(e0), problem.target_losses(errs[0])
        g = np.array([(parts1[k] - parts0[k]) / step for k in tie])
    return loss0, g, e0


def adam(problem: Problem, *, gradient: str = "fd-forward", learning_rate: float = 0.1, b1: float = 0.9,
         b2: float = 0.99, eps: float = 1e-8, tol: float = 0.05, max_iterations: int = 20, loss_scaled: bool = False,
         first_estimate: bool | None = None, second_estimate: bool | None = None, tie: Mapping[str, str] | None = None,
         simplified: bool = False, fd_step: float = 1e-3, optimizer: optax.GradientTransformation | None = None,
         progress=None) -> CalibrationResult:
    """Calibrate ``problem`` with Adam (Qu et al. 2020). Returns a :class:`CalibrationResult` at the best point seen.

    gradient: one of :data:`GRADIENTS`. learning_rate, b1, b2, eps: Adam's (Qu et al. 2020 uses b2 = 0.99); the step is
    in ``z`` (log form: a relative change). optimizer: an ``optax.GradientTransformation`` that makes the step instead
    (e.g. ``optax.sgd(0.05)``, ``optax.chain(optax.clip_by_global_norm(1.0), optax.adam(0.1))``; learning_rate, b1,
    b2 and eps are then unused); default ``optax.adam(learning_rate, b1=b1, b2=b2, eps=eps)``. tol: stop when every
    target's relative error is within it (Qu et al. 2020 5.1.2: 5 %). max_iterations: evaluated points at most
    (estimates included). loss_scaled: Eq. 9.
    first_estimate / second_estimate: Eq. 14 / 15; ``None`` = on where they make sense (a tie exists; Eq. 14 only
    when each parameter and its target share units, e.g. bond E and Young's modulus). tie: ``{parameter: target}``
    (default: the only parameter to the only scalar target). simplified: Eq. 16-19 (needs ties): ``True``/``"secant"``
    (one parameter set per iteration) or ``"perturbed"`` (one perturbed set per iteration). fd_step: step in ``z``
    (target-scaled form: a fraction of the target). progress: True (print), a callable
    ``(row, parameter_names, target_names)`` or None.
    """
    t_start = time.perf_counter()
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
    secant = simplified in (True, "secant")
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
    progress = _common.progress_fn(progress)
    space = problem.space
    notes = []
    grad_method = "simplified" if simplified else gradient

    values = space.initial.copy()
    kind = "initial"
    if first_estimate:
        values = space.clip([problem.targets[k].value for k in ties])
        kind = "estimate-1"
        notes.append("first estimate (Qu et al. 2020, Eq. 14): each parameter starts at its target's value")
    z = space.to_z(values)
    state = optimizer.init(jnp.asarray(z))
    pending_second = bool(second_estimate)
    history = History(space.names, problem.target_names)
    evals0 = problem.evaluations
    best = None
    previous = None  # (z, errors) of the last evaluated point: the simplified scheme's secant
    secants = 0
    for it in range(1, max_iterations + 1):
        t0 = time.perf_counter()
        last = it == max_iterations
        if gradient == "autodiff" and not pending_second and not last:
            loss, g, e = loss_and_gradient(problem, z, "autodiff")
        else:
            g = None
            e = np.asarray(problem.errors_of(problem.outputs(space.from_z(z[None, :]))[0]))
            loss = float(problem.loss_of(e))
        err = problem.max_errors(e)
        done = bool(np.all(err <= tol))
        values = space.from_z(z)
        if best is None or loss < best[0]:
            best = (loss, values.copy(), e.copy())
        if done or last:
            _common.record(history, problem, progress, kind=kind, values=values, errors=e,
                           time=time.perf_counter() - t0)
            break
        if pending_second:
            pending_second = False
            ratio = np.array([problem.targets[k].value / (problem.targets[k].value + problem.targets[k].scale
                                                          * e[problem.slices[k]][0]) for k in ties])
            if np.all(ratio > 0):
                _common.record(history, problem, progress, kind=kind, values=values, errors=e,
                               time=time.perf_counter() - t0)
                previous = (z.copy(), e.copy())
                z = space.to_z(space.clip(values * ratio))
                kind = "estimate-2"
                if not any("Eq. 15" in n for n in notes):
                    notes.append("second estimate (Qu et al. 2020, Eq. 15): parameters scaled by target / model value")
                continue
            notes.append("second estimate skipped: a model value has the opposite sign of its target")
        if g is None and secant and previous is not None and np.all(np.abs(z - previous[0]) >= 0.1 * fd_step):
            parts, parts0 = problem.target_losses(e), problem.target_losses(previous[1])
            g = np.array([(parts[k] - parts0[k]) / (z[i] - previous[0][i]) for i, k in enumerate(ties)])
            secants += 1
        if g is None:
            _, g, _ = loss_and_gradient(problem, z, grad_method, step=fd_step, tie=ties, base=e)
        _common.record(history, problem, progress, kind=kind, values=values, errors=e,
                       time=time.perf_counter() - t0)
        with jax.numpy_dtype_promotion("standard"):  # optax mixes float decay rates with an int32 step count
            updates, state = optimizer.update(jnp.asarray(g), state, jnp.asarray(z))
            updates = np.asarray(updates)
            if loss_scaled:
                updates = updates * loss
            stepped = np.asarray(optax.apply_updates(z, updates), dtype=np.float64)
        previous = (z.copy(), e.copy())
        z = space.to_z(space.clip(space.from_z(stepped)))
        kind = "adam"
    _, values, e = best
    if loss_scaled:
        notes.append("step scaled by the loss (Qu et al. 2020, Eq. 9)")
    if simplified:
        notes.append("simplified scheme (Qu et al. 2020, Eq. 16-19): " + (
            f"one parameter set per iteration ({secants} secant gradients between successive points)" if secant
            else "one perturbed point per iteration"))
    info = {"gradient": grad_method, "optimizer": opt_name,
            "learning_rate": learning_rate if opt_name == "adam" else None, "scaling": space.scaling,
            "first_estimate": bool(first_estimate), "second_estimate": bool(second_estimate),
            "loss_scaled": bool(loss_scaled), "simplified": ("secant" if secant else "perturbed") if simplified
            else False, "secant_gradients": secants, "fd_step": fd_step}
    return _common.make_result(problem, history, values, e, method="adam", tol=tol,
                               wall_time=time.perf_counter() - t_start,
                               evaluations=problem.evaluations - evals0, notes=notes, info=info)
