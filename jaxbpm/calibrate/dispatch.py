"""``calibrate``: pick a calibrator for the targets and run it on a solver (the package's front door)."""

from __future__ import annotations

import time
from typing import Mapping, Sequence

import numpy as np

import jaxbpm.calibrate._common as _common
from jaxbpm.calibrate.adam import adam
from jaxbpm.calibrate.closed_form import closed_form
from jaxbpm.calibrate.multifidelity import multifidelity
from jaxbpm.calibrate.objective import (CalibrationError, Forward, Parameter, ParameterSpace, Problem, as_targets,
                                        base_params, forward_model)
from jaxbpm.calibrate.history import CalibrationResult
from jaxbpm.calibrate.surrogate import surrogate

__all__ = ["METHODS", "ELASTIC_TOL", "TOL", "calibrate", "default_parameters", "default_tol"]

METHODS = ("auto", "adam", "surrogate", "closed-form")


def default_parameters(sample) -> list[Parameter]:
    """One free parameter: a common bond modulus keeping the sample's modulus ratios between components.

    Args:
      sample: a :class:`~jaxbpm.Sample`.

    Returns:
      ``[Parameter("bond_E", index=None, ratio=...)]``: every bond material's modulus scaled by one factor (no
      ``ratio`` when the sample has one bond material).
    """
    E = np.asarray(sample.materials.E, dtype=np.float64).reshape(-1)
    if E.size == 1:
        return [Parameter("bond_E", index=None)]
    return [Parameter("bond_E", index=None, ratio=tuple(E / E[0]))]


#: the default tolerance of an elastic calibration: the accuracy of the static solvers it runs (the DSM solves the
#: DEM's equilibrium exactly, to its CG tolerance; a calibration need not stop short of what its solves give)
ELASTIC_TOL = 0.005
#: the default tolerance where a target is not elastic (a strength: Qu et al. 2020's 5 %)
TOL = 0.05


def default_tol(targets, method: str = "auto") -> float:
    """The default tolerance of a calibration on ``targets``.

    Args:
      targets: :class:`Target` s.
      method: the calibrator.

    Returns:
      :data:`ELASTIC_TOL` where every target is a stiffness, a modulus or a Poisson ratio and the calibrator solves
      (not ``"surrogate"``, whose answer is as good as its regression), else :data:`TOL`.
    """
    elastic = ("stiffness", "youngs_modulus", "poisson_ratio")
    solves = method != "surrogate"
    return ELASTIC_TOL if solves and all(t.observable in elastic for t in targets) else TOL


def calibrate(sample, scene, targets, *, method: str = "auto", solver: str | Forward = "dsm",
              parameters: Sequence[Parameter] | None = None, scaling: str = "log", tol: float | None = None,
              shortcut: bool = True, levels: Sequence | None = None, check: str | None = None,
              solve_options: Mapping[str, dict] | None = None, progress=None, executor=None, model=None,
              **options) -> CalibrationResult:
    """Calibrate the bond parameters of ``sample`` so that ``scene`` reproduces ``targets``.

    Args:
      sample: a :class:`~jaxbpm.Sample`, or ``{scene key: Sample}`` when the tests use different specimens (e.g. a
        cylinder for ``"ucs"``, a beam for ``"tpb"``; the free parameters are set on every sample, the rest of
        each sample's table is its own).
      scene: a scene (e.g. :class:`~jaxbpm.scenes.UniaxialCompression`) or ``{key: scene}`` for targets measured on
        several tests (``Target(..., scene=key)``).
      targets: :class:`Target` s, or ``{observable: value}`` (e.g. ``{"youngs_modulus": 1.2e8}``).
      method: the calibrator, one of :data:`METHODS`.
      solver: the solver that ``"adam"``, ``"surrogate"`` and ``"closed-form"`` run (``"dsm"``, ``"ste"``,
        ``"dem"``), or a :class:`Forward`. ``method="auto"`` runs the solvers of ``levels``.
      parameters: free :class:`Parameter` s; default :func:`default_parameters` (one common bond modulus).
      scaling: ``"log"`` or ``"target"`` (Qu et al. 2020, Eq. 10-11: each parameter over the target it is tied to).
      tol: relative tolerance on every target (default :data:`ELASTIC_TOL`, 0.5 %, where every target is a
        stiffness, a modulus or a Poisson ratio and the calibrator solves: the accuracy of the static solvers the
        elastic levels run; else 5 %, Qu et al. 2020; see :func:`default_tol`).
      shortcut: use the closed form wherever it applies (the result's ``method`` and ``notes`` say so).
      levels: multi-fidelity levels (``method="auto"``; default :func:`default_levels`).
      check: a solver (e.g. ``"dem"``) run once at the answer; its errors go to ``result.info["check"]``.
      solve_options: ``{solver: options for jaxbpm.solve}``.
      progress: True to print each iteration (stderr), or a callable ``(row, parameter_names, target_names)``.
      executor: a :class:`concurrent.futures.Executor` (e.g. Dask's ``Client(...).get_executor()``) for the runs of
        a solver that is not batched (DEM): the perturbed runs of a finite-difference gradient and a surrogate's run
        set become parallel tasks (:mod:`jaxbpm.parallel`). Batched solvers (STE, DSM elastic) ignore it.
      model: deprecated name of ``solver`` (a :class:`DeprecationWarning`); removed in the next release.
      **options: passed to the calibrator (:func:`adam`, :func:`surrogate`, :func:`closed_form`; for ``"auto"``
        they are Adam's options).

    Returns:
      A :class:`CalibrationResult`: the answer, its errors, the calibrator and solver used, the cost and the
      history.

    Raises:
      CalibrationError: an unknown method, sample, parameter or option; a calibrator that finds no answer (see
        each calibrator).
    """
    solver = _common.renamed_keyword(solver, model, new="solver", old="model")
    if method not in METHODS:
        raise CalibrationError(f"unknown calibration method {method!r}; choose one of {METHODS}")
    from jaxbpm.parallel import check_executor

    check_executor(executor)
    first = _first_sample(sample)
    targets = as_targets(targets)
    tol = _common.check_tol(default_tol(targets, method) if tol is None else tol)
    space = _space(sample, first, scene, parameters, scaling)
    solve_options = dict(solve_options or {})
    t0 = time.perf_counter()
    if method == "auto":
        result = multifidelity(sample, scene, targets, _target_scales(space, targets, options.get("tie")),
                               levels=levels, tol=tol, shortcut=shortcut, solve_options=solve_options,
                               adam_options=options, progress=progress)
    else:
        if levels is not None:
            raise CalibrationError("levels apply to method='auto' only")
        fwd = solver if isinstance(solver, Forward) else forward_model(sample, scene, solver,
                                                                          **solve_options.get(solver, {}))
        space = _target_scales(space, targets, options.get("tie"))
        problem = Problem(fwd, targets, space, executor=executor)
        result = _run_calibrator(problem, method, tol=tol, shortcut=shortcut, progress=progress, options=options)
    if check is not None:
        result.info["check"] = _check_answer(result, sample, scene, targets, space, check,
                                             solve_options.get(check, {}))
    result.wall_time = time.perf_counter() - t0
    return result


def _first_sample(sample):
    """The sample (or the first of ``{scene key: Sample}``) whose table gives the base parameters."""
    from jaxbpm.sample import Sample

    several = isinstance(sample, Mapping)
    for s in (sample.values() if several else [sample]):
        if not isinstance(s, Sample):
            raise CalibrationError(f"sample must be a jaxbpm.Sample or {{scene key: Sample}}, got {type(s).__name__}")
    if several and not sample:
        raise CalibrationError("no sample given")
    return next(iter(sample.values())) if several else sample


def _space(sample, first, scene, parameters, scaling) -> ParameterSpace:
    """The parameter space of ``parameters`` (default: :func:`default_parameters`) around the first sample's
    table; with several samples only the free entries are shared, each sample keeping the rest of its table."""
    parameters = default_parameters(first) if parameters is None else list(parameters)
    if not all(isinstance(p, Parameter) for p in parameters):
        raise CalibrationError("parameters must be a list of Parameter")
    keys = sorted({p.key for p in parameters})
    base = base_params(first, keys, scene)
    if isinstance(sample, Mapping):
        base = {k: base[k] for k in keys}
    return ParameterSpace(parameters, base, scaling=scaling)


def _run_calibrator(problem: Problem, method: str, *, tol, shortcut, progress, options) -> CalibrationResult:
    """Run the calibrator ``method`` (not ``"auto"``) on ``problem``; Adam gives way to the closed form where it
    applies and ``shortcut`` allows it."""
    if method == "closed-form":
        return closed_form(problem, tol=tol, progress=progress, **options)
    if method == "surrogate":
        return surrogate(problem, tol=tol, progress=progress, **options)
    ok, _ = problem.closed_form_applies()
    if shortcut and ok and sum(t.size for t in problem.targets) >= problem.space.n:
        result = closed_form(problem, tol=tol, progress=progress)
        result.notes.insert(0, "closed-form shortcut used instead of Adam (shortcut=False forces Adam)")
        return result
    return adam(problem, tol=tol, progress=progress, **options)


def _check_answer(result, sample, scene, targets, space, check: str, solve_options) -> dict:
    """The errors of ``result``'s answer on the solver ``check`` (one solve): ``result.info["check"]``."""
    problem = Problem(forward_model(sample, scene, check, **solve_options), targets, space)
    tc = time.perf_counter()
    values = np.asarray([result.values[n] for n in space.names])
    e = np.asarray(problem.errors_of(problem.outputs(values[None, :])[0]))
    return {"solver": check, "errors": problem.signed_errors(e), "max_error": float(problem.max_errors(e).max()),
            "evaluations": problem.evaluations, "wall_time": time.perf_counter() - tc}


def _target_scales(space: ParameterSpace, targets, tie) -> ParameterSpace:
    """For ``scaling="target"``: each parameter's scale is its tied target's value (Qu et al. 2020, Eq. 10)."""
    if space.scaling != "target":
        return space
    scalar = [t for t in targets if t.size == 1]
    if tie is None and space.n == 1 and len(targets) == 1 and scalar:
        tie = {space.names[0]: targets[0].name}
    if tie is None:
        return space
    by_name = {t.name: t for t in targets}
    scales = [abs(by_name[tie[n]].value) if (n in tie and tie[n] in by_name and p.scale is None) else s
              for n, p, s in zip(space.names, space.parameters, space.scales)]
    return space.with_scales(scales)
