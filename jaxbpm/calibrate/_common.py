"""Helpers shared by the calibrators: ties between parameters and targets, results, progress output, renamed
keywords. It imports no calibrator and not the problem (``problem`` arguments are
:class:`~jaxbpm.calibrate.objective.Problem` s), so that every module of the package can use it."""

from __future__ import annotations

import warnings
from typing import Callable, Mapping

import numpy as np

from jaxbpm.calibrate.space import CalibrationError
from jaxbpm.calibrate.history import CalibrationResult, History

# parameter key -> observables measured in the same units (Qu et al. 2020, Eq. 14: the macroscopic value is a first
# estimate of the microscopic one)
_SAME_UNITS = {"bond_E": ("youngs_modulus",), "bond_nu": ("poisson_ratio",),
               "bond_tensile_strength": ("strength",), "bond_shear_strength": ("strength",)}


def resolve_tie(problem, tie: Mapping[str, str] | None) -> list[int] | None:
    """Index of the target each parameter is tied to (Qu et al. 2020, 3.5-3.6), or None when there is no tie.

    Args:
      problem: a :class:`~jaxbpm.calibrate.objective.Problem`.
      tie: ``{parameter name: target name}``; ``None`` ties the only parameter to the only target when the problem
        has one of each (a scalar target).

    Returns:
      One target index per parameter, or None.

    Raises:
      CalibrationError: a tie that is not a mapping, names an unknown parameter or target, leaves a parameter out or
        ties one to a vector target.
    """
    names, targets = problem.space.names, problem.target_names
    if tie is None:
        if problem.space.n == 1 and len(problem.targets) == 1 and problem.targets[0].size == 1:
            return [0]
        return None
    if not isinstance(tie, Mapping):
        raise CalibrationError(f"tie must map parameter names to target names, got {tie!r}")
    unknown = sorted(set(tie) - set(names))
    if unknown:
        raise CalibrationError(f"tie: unknown parameters {unknown} (parameters: {names})")
    missing = [n for n in names if n not in tie]
    if missing:
        raise CalibrationError(f"tie: every parameter needs a target; missing {missing}")
    out = []
    for n in names:
        if tie[n] not in targets:
            raise CalibrationError(f"tie: parameter {n!r} tied to unknown target {tie[n]!r} (targets: {targets})")
        k = targets.index(tie[n])
        if problem.targets[k].size != 1:
            raise CalibrationError(f"tie: parameter {n!r} tied to the vector target {tie[n]!r}; ties need scalar "
                                   "targets")
        out.append(k)
    return out


def same_units(problem, ties: list[int]) -> bool:
    """Whether each parameter shares the units of its tied target (bond E and Young's modulus, bond strengths and
    strengths): Qu et al. 2020's Eq. 14 then starts each parameter at its target's value.

    Args:
      problem: a :class:`~jaxbpm.calibrate.objective.Problem`.
      ties: the target index of each parameter (:func:`resolve_tie`).

    Returns:
      True when every parameter shares its target's units.
    """
    return all(problem.targets[k].observable in _SAME_UNITS.get(p.key, ())
               for p, k in zip(problem.space.parameters, ties))


def printer(prefix: str = "") -> Callable[[dict, list[str], list[str]], None]:
    """A progress callback printing one line per iteration on stderr (:func:`jaxbpm.progress.say`: above any progress
    bar, beside the packing's and the DEM's progress).

    Args:
      prefix: text before each line.

    Returns:
      A callable ``(row, parameter_names, target_names)``.
    """
    from jaxbpm.progress import say

    def show(row, parameter_names, target_names):
        vals = " ".join(f"{n}={v:.6g}" for n, v in zip(parameter_names, row["values"]))
        errs = " ".join(f"{n}={100 * e:+.3f}%" for n, e in zip(target_names, row["errors"]))
        say(f"{prefix}[{row['level']}] it {row['iteration']:>3} {row['kind']:<12} {vals}  loss={row['loss']:.3e}  "
            f"{errs}  evals={row['evaluations']}  {row['time']:.2f} s")

    return show


def progress_fn(progress):
    """The progress callback that a calibrator's ``progress=`` asks for.

    Args:
      progress: True (print a line per iteration), None or False (nothing), or a callable.

    Returns:
      A callable ``(row, parameter_names, target_names)``, or None.

    Raises:
      CalibrationError: anything else.
    """
    if progress is True:
        return printer()
    if progress in (None, False):
        return None
    if callable(progress):
        return progress
    raise CalibrationError(f"progress must be True, False or a callable, got {progress!r}")


def record(history: History, problem, progress, *, kind, values, errors, time, level=None) -> dict:
    """Append one evaluated point to ``history`` and report it to ``progress``.

    Args:
      history: the calibration's :class:`~jaxbpm.calibrate.history.History`.
      problem: the :class:`~jaxbpm.calibrate.objective.Problem` (its loss, per-target errors and solve count).
      progress: a callable ``(row, parameter_names, target_names)``, or None.
      kind: what the point is (``"initial"``, ``"adam"``, ``"narrow"``, ...).
      values: the parameter values ``[n]``.
      errors: the relative errors ``[m]`` of every target element.
      time: seconds the iteration took.
      level: the level's name (default: the forward's name).

    Returns:
      The row appended.
    """
    row = history.append(kind=kind, level=level or problem.forward.name, values=values,
                         loss=float(problem.loss_of(np.asarray(errors))), errors=problem.per_target(errors),
                         evaluations=problem.evaluations, time=time)
    if progress is not None:
        progress(row, history.parameter_names, history.target_names)
    return row


def make_result(problem, history: History, values, errors, *, method: str, tol: float, wall_time: float,
                evaluations: int, notes=(), info=None, band=None, converged=None,
                iterations: int | None = None) -> CalibrationResult:
    """The :class:`~jaxbpm.calibrate.history.CalibrationResult` of a calibrator's answer.

    Args:
      problem: the :class:`~jaxbpm.calibrate.objective.Problem`.
      history: the evaluated points.
      values: the answer ``[n]``.
      errors: its relative errors ``[m]``.
      method: the calibrator's name.
      tol: the relative tolerance.
      wall_time: seconds the calibration took.
      evaluations: solves it ran.
      notes, info, band: the result's notes, details and uncertainty band.
      converged: whether it converged (default: every target within ``tol``).
      iterations: evaluated points (default: the rows of ``history``).

    Returns:
      The result, its ``solver`` the forward's name.
    """
    values = np.asarray(values, dtype=np.float64)
    params = {k: np.asarray(v) for k, v in problem.space.to_params(values).items()}
    if converged is None:
        converged = bool(np.all(problem.max_errors(errors) <= tol))
    info = dict(info or {})
    out_of_reach = [] if converged else unreachable(problem, values, errors, tol)
    if out_of_reach:
        info["unreachable"] = out_of_reach
        notes = list(notes) + [entry["message"] for entry in out_of_reach]
    return CalibrationResult(values=problem.space.describe(values), params=params,
                             errors=problem.signed_errors(errors), converged=bool(converged), method=method,
                             solver=problem.forward.name, evaluations=int(evaluations),
                             iterations=len(history) if iterations is None else int(iterations),
                             wall_time=float(wall_time), tol=float(tol), history=history, notes=list(notes),
                             band=band, info=info)


def unreachable(problem, values, errors, tol: float) -> list[dict]:
    """The targets missed (error above ``tol``) while parameters sit at a bound of their range: out of reach of the
    parameter range, not of the iterations.

    Args:
      problem: the :class:`~jaxbpm.calibrate.objective.Problem`.
      values: the answer ``[n]``.
      errors: its relative errors ``[m]``.
      tol: the relative tolerance.

    Returns:
      One entry per missed target: ``{"target", "value", "closest", "error", "pinned": [(parameter, "lower" or
      "upper", bound)], "message"}``. ``closest``: the value reached at the answer (the element of largest error
      for a vector target): the solve's own output where the answer was the last point solved, else from the
      error, ``None`` where that is below 1e-9 of the target (lost to rounding). Empty where no parameter is at a
      bound.
    """
    space = problem.space
    values = np.asarray(values, dtype=np.float64)
    pinned = [(name, side, float(bound)) for name, v, lo, hi in zip(space.names, values, space.lower, space.upper)
              for side, bound in (("lower", lo), ("upper", hi)) if abs(v - bound) <= 1e-6 * abs(bound)]
    if not pinned:
        return []
    last = getattr(problem, "_last", None)  # (values, outputs) of the last point solved
    outputs = np.asarray(last[1]) if last is not None and np.array_equal(last[0], values) else None
    e = np.asarray(errors, dtype=np.float64)
    at = ", ".join(f"{name} at its {side} bound {bound:.6g}" for name, side, bound in pinned)
    out = []
    for t, s, worst in zip(problem.targets, problem.slices, problem.max_errors(e)):
        if not worst > tol:
            continue
        k = int(np.argmax(np.abs(e[s])))
        target = float(np.reshape(np.asarray(t.value, dtype=np.float64), (-1,))[k])
        closest = float(outputs[s][k]) if outputs is not None else target + float(e[s][k]) * float(t.scale)
        if outputs is None and not abs(closest) > 1e-9 * abs(target):
            closest = None
        reached = (f"the closest value reached is {closest:.6g}" if closest is not None else
                   "the value reached there is under 1e-09 of the target")
        out.append({"target": t.name, "value": target, "closest": closest, "error": float(e[s][k]),
                    "pinned": pinned, "message": f"target {t.name} = {target:.6g} is out of reach of the parameter "
                    f"range: {at}; {reached} ({100 * float(e[s][k]):+.3f} %); widen the bounds (Parameter bounds) "
                    "or check the target"})
    return out


def check_tol(tol) -> float:
    """A relative tolerance checked.

    Args:
      tol: a number in (0, 1).

    Returns:
      ``tol`` as a float.

    Raises:
      CalibrationError: anything else.
    """
    if not (isinstance(tol, (int, float, np.number)) and 0 < tol < 1):
        raise CalibrationError(f"tol must be a relative tolerance in (0, 1), got {tol!r}")
    return float(tol)


def check_count(name, value, minimum=1) -> int:
    """A whole-number option checked.

    Args:
      name: the option's name (in the message).
      value: its value.
      minimum: the smallest value allowed.

    Returns:
      ``value`` as an int.

    Raises:
      CalibrationError: a value that is not a whole number (booleans included) or is below ``minimum``.
    """
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise CalibrationError(f"{name} must be a whole number >= {minimum}, got {value!r}")
    return int(value)


def renamed_keyword(value, old_value, *, new: str, old: str):
    """The value of the keyword ``new``, or of its deprecated name ``old`` where that was given.

    Args:
      value: the value given as ``new`` (or its default).
      old_value: the value given as ``old``; ``None`` when it was not given.
      new, old: the keyword's name and its deprecated name.

    Returns:
      ``old_value`` where it was given (with a :class:`DeprecationWarning` naming ``new``), else ``value``.
    """
    if old_value is None:
        return value
    warnings.warn(f"{old}= is deprecated and will be removed in the next release; use {new}= (the same value)",
                  DeprecationWarning, stacklevel=3)
    return old_value
