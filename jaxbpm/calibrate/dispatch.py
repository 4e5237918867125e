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
from jaxbpm.calibrate.result import CalibrationResult
from jaxbpm.calibrate.surrogate import surrogate

__all__ = ["METHODS", "calibrate", "default_parameters"]

METHODS = ("auto", "adam", "surrogate", "closed-form")


def default_parameters(sample) -> list[Parameter]:
    """One free parameter: a common bond modulus keeping the sample's modulus ratios between components."""
    E = np.asarray(sample.materials.E, dtype=np.float64).reshape(-1)
    if E.size == 1:
        return [Parameter("bond_E", index=None)]
    return [Parameter("bond_E", index=None, ratio=tuple(E / E[0]))]


def calibrate(sample, scene, targets, *, method: str = "auto", model: str = "dsm",
              parameters: Sequence[Parameter] | None = None, scaling: str = "log", tol: float = 0.05,
              shortcut: bool = True, levels: Sequence | None = None, check: str | None = None,
              solve_options: Mapping[str, dict] | None = None, progress=None, executor=None,
              **options) -> CalibrationResult:
    """Calibrate the bond parameters of ``sample`` so that ``scene`` reproduces ``targets``.

    Args:
      sample: a :class:`~jaxbpm.Sample`, or ``{scene key: Sample}`` when the tests use different specimens (e.g. a
        cylinder for ``"ucs"``, a beam for ``"tpb"``; the free parameters are set on every sample, the rest of
        each sample's table is its own).
      scene: a scene (e.g. :class:`~jaxbpm.scenes.UniaxialCompression`) or ``{key: scene}`` for targets measured on
        several tests (``Target(..., scene=key)``).
      targets: :class:`Target` s, or ``{observable: value}`` (e.g. ``{"youngs_modulus": 1.2e8}``).
      method: one of :data:`METHODS`.
      model: the solver for ``"adam"``, ``"surrogate"`` and ``"closed-form"`` (``"dsm"``, ``"ste"``, ``"dem"``).
      parameters: free :class:`Parameter` s; default :func:`default_parameters` (one common bond modulus).
      scaling: ``"log"`` or ``"target"`` (Qu et al. 2020, Eq. 10-11: each parameter over the target it is tied to).
      tol: relative tolerance on every target (default 5 %, Qu et al. 2020).
      shortcut: use the closed form wherever it applies (the result's ``method`` and ``notes`` say so).
      levels: multi-fidelity levels (``method="auto"``; default :func:`default_levels`).
      check: a model (e.g. ``"dem"``) solved once at the answer; its errors go to ``result.info["check"]``.
      solve_options: ``{model: options for jaxbpm.solve}``.
      progress: True to print each iteration (stderr), or a callable ``(row, parameter_names, target_names)``.
      executor: a :class:`concurrent.futures.Executor` (e.g. Dask's ``Client(...).get_executor()``) for the runs of
        a model that is not batched (DEM): the perturbed runs of a finite-difference gradient and a surrogate's run
        set become parallel tasks (:mod:`jaxbpm.parallel`). Batched models (STE, DSM elastic) ignore it.
      **options: passed to the calibrator (:func:`adam`, :func:`surrogate`, :func:`closed_form`; for ``"auto"``
        they are Adam's options).
    """
    from jaxbpm.sample import Sample

    if method not in METHODS:
        raise CalibrationError(f"unknown calibration method {method!r}; choose one of {METHODS}")
    from jaxbpm.parallel import check_executor

    check_executor(executor)
    several = isinstance(sample, Mapping)
    for s in (sample.values() if several else [sample]):
        if not isinstance(s, Sample):
            raise CalibrationError(f"sample must be a jaxbpm.Sample or {{scene key: Sample}}, got {type(s).__name__}")
    if several and not sample:
        raise CalibrationError("no sample given")
    first = next(iter(sample.values())) if several else sample
    targets = as_targets(targets)
    tol = _common.check_tol(tol)
    parameters = default_parameters(first) if parameters is None else list(parameters)
    if not all(isinstance(p, Parameter) for p in parameters):
        raise CalibrationError("parameters must be a list of Parameter")
    keys = sorted({p.key for p in parameters})
    base = base_params(first, keys, scene)
    if several:  # each sample keeps its own table; only the free entries are shared
        base = {k: base[k] for k in keys}
    space = ParameterSpace(parameters, base, scaling=scaling)
    solve_options = dict(solve_options or {})
    t0 = time.perf_counter()
    if method == "auto":
        result = multifidelity(sample, scene, targets, _target_scales(space, targets, options.get("tie")),
                               levels=levels, tol=tol, shortcut=shortcut, solve_options=solve_options,
                               adam_options=options, progress=progress)
    else:
        if levels is not None:
            raise CalibrationError("levels apply to method='auto' only")
        fwd = model if isinstance(model, Forward) else forward_model(sample, scene, model,
                                                                        **solve_options.get(model, {}))
        space = _target_scales(space, targets, options.get("tie"))
        problem = Problem(fwd, targets, space, executor=executor)
        if method == "closed-form":
            result = closed_form(problem, tol=tol, progress=progress, **options)
        elif method == "surrogate":
            result = surrogate(problem, tol=tol, progress=progress, **options)
        else:
            ok, why = problem.closed_form_applies()
            if shortcut and ok and sum(t.size for t in problem.targets) >= space.n:
                result = closed_form(problem, tol=tol, progress=progress)
                result.notes.insert(0, "closed-form shortcut used instead of Adam (shortcut=False forces Adam)")
            else:
                result = adam(problem, tol=tol, progress=progress, **options)
    if check is not None:
        fwd = forward_model(sample, scene, check, **solve_options.get(check, {}))
        problem = Problem(fwd, targets, space)
        tc = time.perf_counter()
        values = np.asarray([result.values[n] for n in space.names])
        e = np.asarray(problem.errors_of(problem.outputs(values[None, :])[0]))
        result.info["check"] = {"model": check, "errors": problem.signed_errors(e),
                                "max_error": float(problem.max_errors(e).max()), "evaluations": problem.evaluations,
                                "wall_time": time.perf_counter() - tc}
    result.wall_time = time.perf_counter() - t0
    return result


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
