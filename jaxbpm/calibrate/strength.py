"""Strength calibration (Qu et al. 2020): the bond tensile and shear strengths from the UCS and the flexural strength.

The bond tensile strength ``sigma_c`` and the bond shear strength ``tau_c`` (the cohesion of the shear criterion) are
calibrated against the uniaxial compressive strength (UCS, a cylinder compressed to failure) and the flexural strength
(a beam in three-point bending) with Adam and finite-difference gradients (:func:`~jaxbpm.calibrate.adam.adam`):

* objective: ``L = l1 (UCS / UCS_t - 1)^2 + l2 (f / f_t - 1)^2`` with ``l1 + l2 = 1`` (Eq. 3);
* feature scaling: ``sigma_c / f_t`` and ``tau_c / UCS_t`` (Eq. 10-11);
* first estimate ``tau_c := UCS_t``, ``sigma_c := f_t`` (Eq. 14); second estimate: each scaled by target / model
  value (Eq. 15);
* ``scheme="original"``: each iteration runs the point and one perturbed point per parameter (3 parameter sets: 3 UCS
  and 3 bending runs, Eq. 12-13); ``scheme="simplified"``: ``sigma_c`` is tied to the flexural strength and
  ``tau_c`` to the UCS (Eq. 16-19), one parameter set per iteration.

The runs are DEM runs with bond breakage: those of one iteration run one after another (a failure run cannot be
batched). A parameter set is one UCS run plus one bending run; Qu et al. 2020 counts "models" in parameter sets
(Table 6: 19 for the original scheme, 4 for the simplified one). :func:`strength_table` gives the history in the form
of Qu et al.'s Tables 4 and 5.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

import jaxbpm.calibrate._common as _common
from jaxbpm.calibrate.adam import adam
from jaxbpm.calibrate.objective import (CalibrationError, Forward, Parameter, ParameterSpace, Problem,
                                        Target)
from jaxbpm.calibrate.history import CalibrationResult

__all__ = ["STRENGTH_KEYS", "STRENGTH_SCHEMES", "calibrate_strength", "strength_table", "format_strength_table"]

STRENGTH_KEYS = ("bond_tensile_strength", "bond_shear_strength")
STRENGTH_SCHEMES = ("original", "simplified")
UCS, TPB = "ucs", "tpb"
TIE = {"bond_tensile_strength": f"{TPB}.strength", "bond_shear_strength": f"{UCS}.strength"}


def _positive(name, v) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.number)) or not (np.isfinite(v) and v > 0):
        raise CalibrationError(f"{name} must be a finite number > 0, got {v!r}")
    return float(v)


def calibrate_strength(ucs_sample, tpb_sample, *, ucs: float, flexural: float, scheme: str = "original",
                       ucs_scene=None, tpb_scene=None, solver="dem", first_estimate: bool = True,
                       second_estimate: bool = True, initial: Mapping[str, float] | None = None,
                       learning_rate: float = 0.05, fd_step: float = 0.05, loss_scaled: bool = False,
                       weights=(0.5, 0.5), tol: float = 0.05, max_iterations: int = 8, bounds: float = 100.0,
                       solve_options: Mapping | None = None, progress=None, executor=None,
                       model=None) -> CalibrationResult:
    """Calibrate ``sigma_c`` and ``tau_c`` so that the UCS and the flexural strength reach their targets (Qu et al.).

    Args:
      ucs_sample: the specimen of the compression test (e.g. ``jaxbpm.generate.cylinder``).
      tpb_sample: the specimen of the bending test (e.g. ``jaxbpm.generate.beam``); may be the same sample.
      ucs, flexural: the targets [Pa].
      scheme: ``"original"`` or ``"simplified"`` (see the module docstring).
      ucs_scene, tpb_scene: default ``UniaxialCompression.to_failure(strain=0.02)`` and
        ``ThreePointBending(strain=0.1)``.
      solver: ``"dem"`` (the solver for ``jaxbpm.solve``) or a :class:`~jaxbpm.calibrate.Forward` with scenes
        ``"ucs"`` and ``"tpb"`` reporting ``"strength"`` (e.g. a cheap stand-in function).
      first_estimate, second_estimate: Eq. 14 / Eq. 15. initial: ``{"bond_tensile_strength": ...,
        "bond_shear_strength": ...}`` start values when ``first_estimate=False`` (default: the sample's table).
      learning_rate, fd_step, loss_scaled: Adam's step, the finite-difference step (a fraction of the target in the
        scaled form) and Eq. 9. weights: ``(l1, l2)`` of the UCS and the flexural strength (normalised).
      tol: relative tolerance on both strengths (default 5 %, Qu et al. 2020). max_iterations: evaluated points at most
        (estimates included). bounds: each strength is kept within ``[target / bounds, target * bounds]``.
      solve_options: options of ``jaxbpm.solve`` (default ``{"transits": 30}``).
      progress: True to print each iteration (stderr), or a callable.
      executor: a :class:`concurrent.futures.Executor` (e.g. Dask's ``Client(...).get_executor()``): the runs of one
        iteration (the point and its perturbed points, each a UCS and a bending run) go to it as parallel tasks
        (:mod:`jaxbpm.parallel`); the answer is the same as without it.
      model: deprecated name of ``solver`` (a :class:`DeprecationWarning`); removed in the next release.

    Returns:
      A :class:`~jaxbpm.calibrate.CalibrationResult`; ``info["targets"]`` holds the targets and ``info["scheme"]``
      the scheme; :func:`strength_table` gives its history table.

    Raises:
      CalibrationError: an unknown scheme, invalid targets, weights, bounds or initial values, or a
        :class:`~jaxbpm.calibrate.Forward` without the scenes ``"ucs"`` and ``"tpb"``.
    """
    from jaxbpm.calibrate.dispatch import calibrate

    solver = _common.renamed_keyword(solver, model, new="solver", old="model")

    if scheme not in STRENGTH_SCHEMES:
        raise CalibrationError(f"unknown strength calibration scheme {scheme!r}; choose one of {STRENGTH_SCHEMES}")
    ucs, flexural = _positive("ucs", ucs), _positive("flexural", flexural)
    bounds = _positive("bounds", bounds)
    if bounds <= 1:
        raise CalibrationError(f"bounds must be > 1 (a factor around each target), got {bounds!r}")
    w = np.asarray(weights, dtype=np.float64).reshape(-1)
    if w.shape != (2,) or not np.all(np.isfinite(w) & (w > 0)):
        raise CalibrationError(f"weights must be two numbers > 0 (UCS, flexural), got {weights!r}")
    targets = [Target("strength", ucs, weight=float(w[0]), scene=UCS),
               Target("strength", flexural, weight=float(w[1]), scene=TPB)]
    scale = {"bond_tensile_strength": flexural, "bond_shear_strength": ucs}
    start = dict(scale)
    if initial is not None:
        unknown = sorted(set(initial) - set(STRENGTH_KEYS))
        if unknown:
            raise CalibrationError(f"initial: unknown entries {unknown} (entries: {list(STRENGTH_KEYS)})")
        start.update({k: _positive(f"initial {k}", v) for k, v in initial.items()})
    elif not first_estimate and not isinstance(solver, Forward):
        for k, attr in zip(STRENGTH_KEYS, ("tensile_strength", "shear_strength")):
            v = float(np.asarray(getattr(ucs_sample.materials, attr), dtype=np.float64).reshape(-1)[0])
            if np.isfinite(v) and v > 0:
                start[k] = v
    parameters = [Parameter(k, bounds=(scale[k] / bounds, scale[k] * bounds),
                            initial=float(np.clip(start[k], scale[k] / bounds, scale[k] * bounds)), scale=scale[k])
                  for k in STRENGTH_KEYS]
    options = dict(gradient="fd-forward", learning_rate=learning_rate, fd_step=fd_step, loss_scaled=loss_scaled,
                   first_estimate=first_estimate, second_estimate=second_estimate, tie=dict(TIE),
                   simplified="secant" if scheme == "simplified" else False, max_iterations=max_iterations)
    if isinstance(solver, Forward):
        if set(solver.scenes) != {UCS, TPB}:
            raise CalibrationError(f"a strength model needs the scenes {UCS!r} and {TPB!r}, got {solver.scenes}")
        base = {k: np.asarray([start[k]]) for k in STRENGTH_KEYS}
        problem = Problem(solver, targets, ParameterSpace(parameters, base, scaling="target"), executor=executor)
        result = adam(problem, tol=tol, progress=progress, **options)
    else:
        from jaxbpm.scenes import ThreePointBending, UniaxialCompression

        scenes = {UCS: ucs_scene if ucs_scene is not None else UniaxialCompression.to_failure(strain=0.02),
                  TPB: tpb_scene if tpb_scene is not None else ThreePointBending(strain=0.1)}
        opts = {"transits": 30} if solve_options is None else dict(solve_options)
        result = calibrate({UCS: ucs_sample, TPB: tpb_sample}, scenes, targets, method="adam", solver=solver,
                           parameters=parameters, scaling="target", tol=tol, shortcut=False,
                           solve_options={solver: opts}, progress=progress, executor=executor, **options)
    result.info.update(scheme=scheme, targets={UCS: ucs, TPB: flexural}, parameter_sets=result.evaluations // 2)
    ratio = result.values["bond_tensile_strength"] / result.values["bond_shear_strength"]
    if scheme == "simplified" and ratio >= 0.8:
        result.notes.append(f"sigma_c / tau_c = {ratio:.2f}: Qu et al. 2020 restricts the simplified scheme to ratios "
                            "below 0.8 (above, the UCS depends on sigma_c too); check with scheme='original'")
    return result


def strength_table(result: CalibrationResult) -> list[dict]:
    """The history of a strength calibration as in Qu et al.'s Tables 4 and 5.

    Args:
      result: the result of :func:`calibrate_strength`.

    Returns:
      One row per evaluated point: the iteration (from 0), its kind, ``sigma_c``, ``tau_c``, the flexural strength
      and the UCS, their errors, and the cost so far: ``models`` (parameter sets, Qu et al.'s count: one UCS and one
      bending run each) and ``runs`` (solves).

    Raises:
      CalibrationError: ``result`` is not the result of :func:`calibrate_strength`.
    """
    if not isinstance(result, CalibrationResult) or "targets" not in result.info:
        raise CalibrationError("strength_table needs the result of calibrate_strength")
    h = result.history
    names, tnames = h.parameter_names, h.target_names
    t = result.info["targets"]
    i_s, i_t = names.index("bond_tensile_strength"), names.index("bond_shear_strength")
    k_u, k_f = tnames.index(f"{UCS}.strength"), tnames.index(f"{TPB}.strength")
    rows = []
    for r in h.rows:
        e = r["errors"]
        rows.append({"iteration": r["iteration"] - 1, "kind": r["kind"], "sigma_c": float(r["values"][i_s]),
                     "tau_c": float(r["values"][i_t]), "flexural": t[TPB] * (1 + float(e[k_f])),
                     "ucs": t[UCS] * (1 + float(e[k_u])), "flexural_error": float(e[k_f]),
                     "ucs_error": float(e[k_u]), "models": r["evaluations"] // 2, "runs": r["evaluations"],
                     "time": r["time"]})
    return rows


def format_strength_table(rows: list[dict]) -> str:
    """:func:`strength_table` rows as text.

    Args:
      rows: the rows of :func:`strength_table`.

    Returns:
      The table, a header and one line per row.
    """
    head = (f"{'it':>3} {'kind':<11} {'sigma_c [Pa]':>13} {'tau_c [Pa]':>13} {'flexural [Pa]':>14} {'UCS [Pa]':>13} "
            f"{'err f':>8} {'err UCS':>8} {'models':>6} {'runs':>5}")
    lines = [head]
    for r in rows:
        lines.append(f"{r['iteration']:>3} {r['kind']:<11} {r['sigma_c']:>13.6g} {r['tau_c']:>13.6g} "
                     f"{r['flexural']:>14.6g} {r['ucs']:>13.6g} {100 * r['flexural_error']:>+7.1f}% "
                     f"{100 * r['ucs_error']:>+7.1f}% {r['models']:>6} {r['runs']:>5}")
    return "\n".join(lines)

