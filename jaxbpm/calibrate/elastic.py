"""Young's modulus and Poisson's ratio together, in a handful of solves.

Bonds-only elasticity has two facts that make this cheap:

* the macroscopic Poisson ratio does not depend on the bond modulus (every stiffness scales with it), only on the
  bond Poisson ratio (the ratio ``k_t / k_n = 1 / (2 (1 + nu_b))``), the bond radius ratio and the packing;
* at a fixed bond Poisson ratio, E is proportional to the bond modulus (the closed form).

So :func:`calibrate_elastic` runs a secant iteration on the bond Poisson ratio alone (the macroscopic nu rises with
it, monotonically, see ``benchmarks/poisson.py``), scaling the bond modulus by ``E_target / E`` after each solve:
the modulus comes out exact at the last solve, and the Poisson ratio within ``tol`` after 2-4 solves. Where contacts
or walls break the homogeneity, the same update is a fixed-point iteration that converges as long as E depends
weakly on the scale. Each solve measures both (``Result.poisson_ratio``: the DSM's static solution, the DEM's
loaded state, the STE's tensor).

A bonds-only BPM spans a limited range of macroscopic Poisson ratios (``benchmarks/poisson.py`` maps it against the
bond Poisson ratio): a target outside it is reported with the range the sample reaches, not chased.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Mapping

import numpy as np

import jaxbpm.calibrate._common as _common
from jaxbpm.calibrate.objective import CalibrationError, Parameter, ParameterSpace, Problem, Target, forward_model
from jaxbpm.calibrate.history import CalibrationResult, History

__all__ = ["calibrate_elastic"]

_NU_BOUNDS = (-0.9, 0.499)  # bond Poisson ratios the iteration may use (the material range is (-1, 0.5))
_FIRST_SLOPE = 0.1  # a typical d nu / d nu_bond of random packings, to size the first step


def calibrate_elastic(sample, scene, *, E: float | None = None, nu: float | None = None, solver: str = "dsm",
                      tol: float = 0.01, max_solves: int = 6, check: str | None = None,
                      solve_options: Mapping | None = None, progress=None,
                      model: str | None = None) -> CalibrationResult:
    """Calibrate the bond modulus and the bond Poisson ratio so that ``scene`` gives Young's modulus ``E`` [Pa]
    and Poisson's ratio ``nu`` (either may be left out).

    Args:
      sample, scene: the specimen and a :class:`~jaxbpm.scenes.UniaxialCompression` (a slender one, length / width
        >= 2, or frictionless walls: the lateral strain is measured in the middle third).
      solver: the solver (``"dsm"``, ``"dem"`` or ``"ste"``).
      tol: relative tolerance on each target. max_solves: solves at most.
      check: a solver (e.g. ``"dem"``) run once at the answer; its errors go to ``result.info["check"]``.
      solve_options: options of ``jaxbpm.solve`` for ``solver``.
      progress: True to print each solve (stderr), or a callable.
      model: deprecated name of ``solver`` (a :class:`DeprecationWarning`); removed in the next release.

    Every bond material keeps its modulus ratios and gets one bond Poisson ratio.

    Returns:
      A :class:`~jaxbpm.calibrate.CalibrationResult` (``method="elastic"``; ``info["bond_nu_path"]``: the bond and
      macroscopic Poisson ratios of each solve, ``info["check"]``: the errors on ``check``).

    Raises:
      CalibrationError: no target given, a target out of range, a Poisson ratio target outside what the sample
        reaches (the message gives the range), or no answer within ``max_solves``.
    """
    from jaxbpm.calibrate.dispatch import default_parameters

    solver = _common.renamed_keyword(solver, model, new="solver", old="model")

    t_start = time.perf_counter()
    tol = _common.check_tol(tol)
    max_solves = _common.check_count("max_solves", max_solves, 2)
    if E is None and nu is None:
        raise CalibrationError("give a Young's modulus E, a Poisson ratio nu, or both")
    targets = []
    if E is not None:
        targets.append(Target("youngs_modulus", _positive("E", E)))
    if nu is not None:
        if isinstance(nu, bool) or not isinstance(nu, (int, float, np.number)) or not -1.0 < nu < 0.5:
            raise CalibrationError(f"nu must be a Poisson ratio in (-1, 0.5), got {nu!r}")
        targets.append(Target("poisson_ratio", float(nu), scale=max(abs(float(nu)), 0.05)))
    base_e = default_parameters(sample)[0]
    mats = sample.materials
    nu0 = float(np.mean(np.asarray(mats.nu, dtype=np.float64)))
    parameters = [base_e]
    if nu is not None:  # (without a nu target the bond nu stays as it is)
        parameters.append(Parameter("bond_nu", index=None, bounds=_NU_BOUNDS, initial=float(np.clip(nu0, *_NU_BOUNDS)),
                                    ratio=None if np.size(mats.nu) == 1 else tuple(np.ones(np.size(mats.nu)))))
    from jaxbpm.calibrate.objective import base_params

    base = base_params(sample)
    if dataclasses.is_dataclass(scene) and scene.breakage is not True:
        scene = dataclasses.replace(scene, breakage=False)  # elastic properties: no bond may break on the way
    space = ParameterSpace(parameters, base, scaling="log" if nu is None else "target")
    fwd = forward_model(sample, scene, solver, **dict(solve_options or {}))
    problem = Problem(fwd, targets, space)
    progress = _common.progress_fn(progress)
    history = History(space.names, problem.target_names)
    names = problem.target_names
    v = space.initial.copy()
    seen: list[tuple[float, float]] = []  # (bond nu, macroscopic nu)
    notes, e = [], None
    for k in range(max_solves):
        t0 = time.perf_counter()
        y = problem.outputs(v[None, :])[0]
        e = np.asarray(problem.errors_of(y))
        _common.record(history, problem, progress, kind="solve", values=v, errors=e, time=time.perf_counter() - t0,
                       level=solver)
        got = dict(zip(names, y))
        if nu is not None:
            seen.append((float(v[1]), float(got["poisson_ratio"])))
        if np.all(np.abs(e) <= tol):
            break
        if E is not None:  # exact at this bond nu (bonds only): K is proportional to the bond modulus
            v[0] *= float(E) / float(got["youngs_modulus"])
        if nu is not None and abs(got["poisson_ratio"] / nu - 1) > tol:
            v[1] = _next_bond_nu(seen, float(nu))
    else:
        raise CalibrationError(f"no answer within tol={tol:g} after {max_solves} solves (errors "
                               f"{dict(zip(names, np.round(e, 4)))}); raise max_solves")
    result = _common.make_result(problem, history, v, e, method="elastic", tol=tol,
                                 wall_time=time.perf_counter() - t_start, evaluations=problem.evaluations,
                                 notes=notes, info={"bond_nu_path": seen})
    if check is not None:
        tc = time.perf_counter()
        check_problem = Problem(forward_model(sample, scene, check), targets, space)
        ec = np.asarray(check_problem.errors_of(check_problem.outputs(v[None, :])[0]))
        result.info["check"] = {"solver": check, "errors": check_problem.signed_errors(ec),
                                "max_error": float(np.max(np.abs(ec))), "wall_time": time.perf_counter() - tc}
    return result


def _next_bond_nu(seen: list[tuple[float, float]], target: float) -> float:
    """The next bond Poisson ratio: a secant step on the last two points (the first step from a typical slope),
    kept in the material range; an error when the target lies beyond what the bounds reach."""
    (b1, n1) = seen[-1]
    slope = _FIRST_SLOPE
    if len(seen) > 1:
        b0, n0 = seen[-2]
        if b1 != b0 and (n1 - n0) / (b1 - b0) > 1e-6:
            slope = (n1 - n0) / (b1 - b0)
    step = float(np.clip(b1 + (target - n1) / slope, *_NU_BOUNDS))
    at_bound = [(b, n) for b, n in seen if b in _NU_BOUNDS]
    for b, n in at_bound:  # the macroscopic nu rises with the bond nu
        if (b == _NU_BOUNDS[1] and target > n) or (b == _NU_BOUNDS[0] and target < n):
            lo = min(n for _, n in seen)
            hi = max(n for _, n in seen)
            raise CalibrationError(
                f"Poisson's ratio {target:g} is out of this sample's reach: bond Poisson ratios in "
                f"[{_NU_BOUNDS[0]}, {_NU_BOUNDS[1]}] give {lo:.4g} to {hi:.4g} (measured so far). Bonded-particle "
                "samples span a limited range; a smaller bond radius ratio raises it a little, a denser packing or "
                "a different contact network more")
    return step


def _positive(name, v) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.number)) or not (np.isfinite(v) and v > 0):
        raise CalibrationError(f"{name} must be a finite number > 0, got {v!r}")
    return float(v)
