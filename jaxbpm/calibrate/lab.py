"""What a laboratory measures, calibrated in one staged workflow: Young's modulus, Poisson's ratio, UCS, Brazilian
tensile strength and flexural strength.

:func:`lab` runs the stages a modeller would, each with the cheapest solver that is accurate enough:

1. **Elastic** (``E``, ``nu``): :func:`~jaxbpm.calibrate.elastic.calibrate_elastic` on the elastic specimen with the
   DSM (the bond Poisson ratio by secant, the bond modulus in closed form; 2-4 solves), checked once by the DEM. The
   bond modulus and Poisson ratio then hold for every specimen.
2. **Strength** (``ucs``, ``bts``, ``flexural``): the bond tensile strength ``sigma_c`` and shear strength ``tau_c`` by
   DEM failure runs: Qu et al.'s two estimates, then Gauss-Newton steps in log space (the Jacobian from the estimates'
   secant and finite differences across it, then the plane through every set seen; one parameter set per
   iteration): ``tau_c`` is tied to the UCS (compression fails the bonds in shear), ``sigma_c`` to the BTS where
   given, else to the flexural strength (both
   fail in tension). A strength target without its tied parameter's partner leaves the other at its current value. The
   failure runs of one iteration go to ``executor`` when given (:mod:`jaxbpm.parallel`).
3. **Translation**: the answer as the parameters of LAMMPS, PFC, Yade and MUSEN (:mod:`jaxbpm.interop.conventions`)
   for the specimen's mean particle pair.

Any subset of targets works. A target a stage cannot reach (a Poisson ratio beyond what the packing spans, a
strength calibration that runs out of iterations) is reported in ``result.unreached`` with the reason, and the
other stages go on. :meth:`LabResult.report` writes a one-page report (Markdown table + chart).
"""

from __future__ import annotations

import dataclasses
import pathlib
import time
from typing import Any, Mapping

import numpy as np

import jaxbpm.calibrate._common as _common
from jaxbpm.calibrate.objective import CalibrationError

__all__ = ["lab", "LabResult", "LAB_TARGETS"]

LAB_TARGETS = ("E", "nu", "ucs", "bts", "flexural")
_SCENE_OF = {"ucs": "ucs", "bts": "bts", "flexural": "tpb"}


@dataclasses.dataclass
class LabResult:
    """The outcome of :func:`lab`.

    params: ``{"bond_E", "bond_nu", "bond_tensile_strength", "bond_shear_strength"}`` (one value each, for every bond
    material scaled alike). achieved: ``{target: (value, relative error)}`` by the method that checked it (DEM for
    strengths and, with ``check``, for the elastic targets). stages: each stage's
    :class:`~jaxbpm.calibrate.CalibrationResult`. unreached: ``{target: reason}``. conventions: the answer in other
    codes' parameters (a 2D sample: LAMMPS ``dimension 2`` and PFC2D from the bonds' ``2 r_b x t`` section, and
    ``{"2D": why}`` for the codes without a disc form, Yade and MUSEN). curves: the stress-strain curves of the
    strength runs at the answer. failure_rule: the bond failure rule the strengths were calibrated under
    (:data:`jaxbpm.physics.bond.FAILURE_RULES`).
    """

    targets: dict
    params: dict
    achieved: dict
    stages: dict
    unreached: dict
    conventions: dict
    curves: dict
    wall_time: float
    solves: dict
    failure_rule: str = "separate"

    @property
    def converged(self) -> bool:
        return not self.unreached and all(abs(e) <= self.tol_of(k) for k, (_, e) in self.achieved.items())

    def tol_of(self, key) -> float:
        """The tolerance a target was calibrated to.

        Args:
          key: a lab target (``"E"``, ``"nu"``, ``"ucs"``, ``"bts"``, ``"flexural"``).

        Returns:
          The tolerance of its stage (0 where the stage did not run).
        """
        stage = self.stages.get("elastic" if key in ("E", "nu") else "strength")
        return float(stage.tol) if stage is not None else 0.0

    def table(self) -> str:
        """Targets, what the answer gives and its error, then the bond parameters, as text.

        Returns:
          The table, one line per row.
        """
        lines = [f"{'target':<10} {'wanted':>12} {'achieved':>12} {'error':>8}"]
        for key in LAB_TARGETS:
            if key not in self.targets:
                continue
            if key in self.achieved:
                value, err = self.achieved[key]
                lines.append(f"{key:<10} {self.targets[key]:>12.5g} {value:>12.5g} {100 * err:>+7.2f}%")
            else:
                lines.append(f"{key:<10} {self.targets[key]:>12.5g} {'-':>12} {'-':>8}  {self.unreached.get(key, '')}")
        lines.append("")
        lines += [f"{k:<24} {v:.6g}" for k, v in self.params.items()]
        return "\n".join(lines)

    def report(self, path) -> pathlib.Path:
        """Write a one-page report and its chart, both atomically.

        ``path`` gets the Markdown (targets, parameters, other codes' parameters, solves); ``<stem>.png`` beside it the
        chart (each stage's error history, the stress-strain curves at the answer).

        Args:
          path: the Markdown file.

        Returns:
          The Markdown path.
        """
        from jaxbpm.io import atomic_write

        path = pathlib.Path(path)
        png = path.with_suffix(".png")
        self._figure(png)
        rows = ["# Calibration report", "", "| target | wanted | achieved | error |", "| --- | --- | --- | --- |"]
        for key in LAB_TARGETS:
            if key in self.targets:
                value, err = self.achieved.get(key, (float("nan"), float("nan")))
                rows.append(f"| {key} | {self.targets[key]:.5g} | {value:.5g} | {100 * err:+.2f} % |")
        rows += ["", "| bond parameter | value |", "| --- | --- |"]
        rows += [f"| {k} | {v:.6g} |" for k, v in self.params.items()]
        if self.unreached:
            rows += ["", "Not reached:", ""] + [f"- **{k}**: {why}" for k, why in self.unreached.items()]
        rows += ["", "## In other codes (mean particle pair)", "", _rule_note(self.failure_rule), ""]
        for code, values in self.conventions.items():
            shown = ", ".join(f"{k} = {v:.6g}" if isinstance(v, float) else f"{k}: {v}" for k, v in values.items())
            rows.append(f"- **{code}**: {shown}")
        rows += ["", f"Solves: {self.solves}; wall time {self.wall_time:.1f} s.", "", f"![charts]({png.name})", ""]
        text = "\n".join(rows)
        atomic_write(path, lambda tmp: pathlib.Path(tmp).write_text(text))
        return path

    def _figure(self, png):
        from matplotlib.figure import Figure

        from jaxbpm.io import atomic_write

        fig = Figure(figsize=(10, 4))
        ax1, ax2 = fig.subplots(1, 2)
        for name, stage in self.stages.items():
            rows = stage.history.rows
            for k, target in enumerate(stage.history.target_names):
                ax1.plot(range(1, len(rows) + 1), [100 * abs(r["errors"][k]) for r in rows], "o-",
                         label=f"{name}: {target}")
        ax1.axhline(100 * max((s.tol for s in self.stages.values()), default=0.05), color="0.6", ls="--", lw=1)
        ax1.set(xlabel="parameter set solved", ylabel="|error| [%]", yscale="log", title="errors per stage")
        ax1.xaxis.get_major_locator().set_params(integer=True)
        ax1.legend(fontsize=7)
        for key, (strain, stress) in self.curves.items():
            ax2.plot(100 * np.asarray(strain), np.asarray(stress) / 1e6, label=key)
        ax2.set(xlabel="platen travel / specimen length [%]", ylabel="stress of the test [MPa]",
                title="failure runs at the answer")
        if self.curves:
            ax2.legend(fontsize=8)
        fig.tight_layout()
        atomic_write(png, lambda tmp: fig.savefig(tmp, dpi=120, format="png"))


def lab(samples: Mapping[str, Any], targets: Mapping[str, float], *, scenes: Mapping[str, Any] | None = None,
        elastic_solver: str = "dsm", check: str | None = "dem", elastic_tol: float = 0.02, tol: float = 0.05,
        max_iterations: int = 6, fd_step: float = 0.2,
        solve_options: Mapping | None = None, executor=None, progress=None,
        failure_rule: str | None = None, elastic_model: str | None = None) -> LabResult:
    """Calibrate bond parameters to laboratory targets in stages (see the module docstring).

    Args:
      samples: specimens by test: ``{"ucs": cylinder, "bts": disc, "flexural": beam}`` for the strength targets
        given, and ``"elastic"`` for E and nu (default: the UCS cylinder). One sample may serve several tests.
      targets: any of ``{"E": Pa, "nu": -, "ucs": Pa, "bts": Pa, "flexural": Pa}``.
      scenes: override the tests' scenes (``"elastic"``, ``"ucs"``, ``"bts"``, ``"flexural"``); defaults
        ``UniaxialCompression(strain=1e-3)``, ``UniaxialCompression.to_failure(strain=0.02)``,
        ``BrazilianDisc()``, ``ThreePointBending(strain=0.1)``; for 2D specimens (discs) the same loaded in the
        plane (``axis=1``; the beam ``span_axis=0``) with ``contact_law="linear"``.
      elastic_solver: the elastic stage's solver; check: the solver that checks its answer (``None``: none).
      elastic_tol, tol: relative tolerances of the elastic and the strength targets.
      max_iterations, fd_step: the strength stage's Gauss-Newton iterations after the two estimates, and its
        finite-difference step (a fraction of each bond strength).
      solve_options: ``jaxbpm.solve`` options of the failure runs (default ``{"transits": 30}``).
      executor: a :class:`concurrent.futures.Executor` for the failure runs of each iteration.
      progress: True to print each solve and iteration (stderr).
      failure_rule: the bond failure rule of the strength scenes: ``"separate"`` (PFC's parallel bond, MUSEN),
        ``"summed"`` (LAMMPS ``bpm/rotational``) or ``"max"`` (Yade), so that the strengths found hold in the code
        they are for (:data:`jaxbpm.physics.bond.FAILURE_RULES`); ``None``: the scenes' own (default ``"separate"``).
      elastic_model: deprecated name of ``elastic_solver`` (a :class:`DeprecationWarning`); removed in the next
        release.

    Returns:
      A :class:`LabResult`: the parameters, what each target reached, each stage's result, the targets not reached
      and why, and the parameters in other codes' conventions.

    Raises:
      CalibrationError: unknown or invalid targets, a missing specimen, 2D and 3D specimens mixed, strength scenes
        with different failure rules, or a stage that fails for a reason other than an unreachable target.
    """
    elastic_solver = _common.renamed_keyword(elastic_solver, elastic_model, new="elastic_solver", old="elastic_model")
    t0 = time.perf_counter()
    targets = _checked_targets(targets)
    samples, need = _specimens(samples, targets)
    scene_of = {**_default_scenes(samples), **dict(scenes or {})}
    if failure_rule is not None:
        from jaxbpm.physics.bond import check_failure_rule

        check_failure_rule(failure_rule, CalibrationError)
        scene_of = {k: (dataclasses.replace(v, failure_rule=failure_rule) if k in _SCENE_OF else v)
                    for k, v in scene_of.items()}
    rules = sorted({scene_of[k].failure_rule for k in _SCENE_OF if k in targets})
    if len(rules) > 1:
        raise CalibrationError(f"the strength scenes break bonds by different failure rules {rules}: one set of bond "
                               "strengths holds under one rule; give failure_rule=")
    stages, unreached, achieved, solves = {}, {}, {}, {}
    params = _current(samples[sorted(need)[0]])

    if {"E", "nu"} & set(targets):
        _elastic_stage(samples["elastic"], scene_of["elastic"], targets, params, stages, unreached, achieved, solves,
                       solver=elastic_solver, tol=elastic_tol, check=check, progress=progress)
    samples = {k: _with(s, params) for k, s in samples.items()}  # every specimen takes the elastic answer
    curves = {}
    wanted = [k for k in ("ucs", "bts", "flexural") if k in targets]
    if wanted:
        curves = _strengths(samples, scene_of, targets, wanted, params, stages, unreached, achieved, solves, tol=tol,
                            max_iterations=max_iterations, fd_step=fd_step, solve_options=solve_options,
                            executor=executor, progress=progress)
    conventions = _translations(samples[sorted(need)[0]], params)
    return LabResult(targets=targets, params={k: float(v) for k, v in params.items()}, achieved=achieved,
                     stages=stages, unreached=unreached, conventions=conventions, curves=curves,
                     wall_time=time.perf_counter() - t0, solves=solves,
                     failure_rule=rules[0] if rules else "separate")


def _default_scenes(samples) -> dict:
    """The tests' default scenes for the specimens' dimension: in 3D loaded along z with Hertz-Mindlin contacts; in
    2D (discs in the x-y plane) the UCS along y and the beam bent along y, with PFC's linear contacts (the only
    contacts between discs)."""
    from jaxbpm.scenes import BrazilianDisc, ThreePointBending, UniaxialCompression

    dims = {int(getattr(s, "dim", 3)) for s in samples.values()}
    if len(dims) > 1:
        kinds = ", ".join(f"{k}: {getattr(s, 'dim', 3)}D" for k, s in samples.items())
        raise CalibrationError(f"the specimens mix 2D and 3D samples ({kinds}); calibrate discs and spheres apart")
    if dims == {2}:
        return {"elastic": UniaxialCompression(strain=1e-3, axis=1),
                "ucs": UniaxialCompression.to_failure(strain=0.02, axis=1, contact_law="linear"),
                "bts": BrazilianDisc(contact_law="linear"),
                "flexural": ThreePointBending(strain=0.1, axis=1, span_axis=0, contact_law="linear")}
    return {"elastic": UniaxialCompression(strain=1e-3), "ucs": UniaxialCompression.to_failure(strain=0.02),
            "bts": BrazilianDisc(), "flexural": ThreePointBending(strain=0.1)}


def _checked_targets(targets) -> dict:
    """The lab targets as a dict, each checked (a number > 0 [Pa], or a Poisson ratio in (-1, 0.5))."""
    targets = dict(targets)
    unknown = sorted(set(targets) - set(LAB_TARGETS))
    if unknown or not targets:
        raise CalibrationError(f"lab targets must be some of {LAB_TARGETS}, got {sorted(targets)}")
    for key, value in targets.items():
        ok = isinstance(value, (int, float, np.number)) and not isinstance(value, bool) and np.isfinite(value)
        if not ok or (key != "nu" and value <= 0) or (key == "nu" and not -1 < value < 0.5):
            raise CalibrationError(f"target {key!r} must be {'in (-1, 0.5)' if key == 'nu' else 'a number > 0'} "
                                   f"[{'-' if key == 'nu' else 'Pa'}], got {value!r}")
    return targets


def _specimens(samples, targets):
    """``(samples, need)``: the specimens by test (the elastic one defaults to the UCS cylinder) and the tests the
    targets need, each checked to be a :class:`~jaxbpm.Sample`."""
    from jaxbpm.sample import Sample

    samples = dict(samples)
    if "elastic" not in samples and "ucs" in samples:
        samples["elastic"] = samples["ucs"]
    need = ({"elastic"} if {"E", "nu"} & set(targets) else set()) | {k for k in _SCENE_OF if k in targets}
    missing = sorted(need - set(samples))
    if missing:
        raise CalibrationError(f"no specimen for {missing}: pass samples={{{', '.join(repr(m) for m in missing)}: "
                               "Sample, ...}} (the elastic targets default to the 'ucs' specimen)")
    for key in need:
        if not isinstance(samples[key], Sample):
            raise CalibrationError(f"samples[{key!r}] must be a jaxbpm.Sample, got {type(samples[key]).__name__}")
    return samples, need


def _elastic_stage(sample, scene, targets, params, stages, unreached, achieved, solves, *, solver, tol, check,
                   progress) -> None:
    """Stage 1: E and nu by :func:`~jaxbpm.calibrate.elastic.calibrate_elastic` (E alone where nu is out of the
    sample's reach); its answer goes into ``params`` and its record into ``stages``, ``unreached``, ``achieved`` and
    ``solves``."""
    from jaxbpm.calibrate.elastic import calibrate_elastic

    try:
        res = calibrate_elastic(sample, scene, E=targets.get("E"), nu=targets.get("nu"), solver=solver, tol=tol,
                                check=check, progress=progress)
    except CalibrationError as err:
        if "nu" not in targets or "out of this sample's reach" not in str(err):
            raise
        unreached["nu"] = str(err)
        res = (calibrate_elastic(sample, scene, E=targets["E"], solver=solver, tol=tol, check=check,
                                 progress=progress) if "E" in targets else None)
    if res is None:
        return
    stages["elastic"] = res
    params.update(bond_E=res.values["bond_E"], bond_nu=res.values.get("bond_nu", params["bond_nu"]))
    solves["elastic"] = res.evaluations
    errors = res.info["check"]["errors"] if "check" in res.info else res.errors
    for key, name in (("E", "youngs_modulus"), ("nu", "poisson_ratio")):
        if key in targets and name in errors:
            achieved[key] = (targets[key] * (1 + errors[name]), float(errors[name]))


def _strengths(samples, scene_of, targets, wanted, params, stages, unreached, achieved, solves, *, tol,
               max_iterations, fd_step, solve_options, executor, progress) -> dict:
    """Stage 2: the bond strengths by DEM failure runs (:func:`_strength_stage`), then one failure run per test at
    the answer; the answer goes into ``params`` and its record into ``stages``, ``unreached``, ``achieved`` and
    ``solves``. Returns the stress-strain curves of the runs at the answer."""
    kept: dict = {}
    res = _strength_stage(samples, scene_of, targets, wanted, params, tol=tol, max_iterations=max_iterations,
                          fd_step=fd_step, solve_options=dict(solve_options or {"transits": 30}),
                          executor=executor, progress=progress, kept=kept)
    stages["strength"] = res
    solves["strength (DEM failure runs)"] = res.evaluations
    params.update(bond_tensile_strength=res.values.get("bond_tensile_strength", params["bond_tensile_strength"]),
                  bond_shear_strength=res.values.get("bond_shear_strength", params["bond_shear_strength"]))
    if not res.converged:
        out_of_reach = {u["target"]: u for u in res.info.get("unreachable", [])}
        for k in wanted:
            name = f"{_SCENE_OF[k]}.strength"
            if abs(res.errors[name]) > tol:
                best = f"best {res.errors[name]:+.1%}"
                unreached[k] = f"not within {tol:.0%} after {res.iterations} iterations ({best}); raise max_iterations"
                if name in out_of_reach:  # a bond strength at a bound of its range: iterations will not help
                    pinned = ", ".join(f"{p} at its {side} bound {b:.4g}"
                                       for p, side, b in out_of_reach[name]["pinned"])
                    unreached[k] = f"out of reach of the bond strength range ({best}): {pinned}; more iterations " \
                                   "will not reach it"
    curves, ran = _curves(samples, scene_of, wanted, params, dict(solve_options or {"transits": 30}), achieved,
                          targets, kept)
    solves["answer runs (DEM)"] = ran
    return curves


def _current(sample) -> dict:
    m = sample.materials
    first = lambda a: float(np.asarray(a, dtype=np.float64).reshape(-1)[0])  # noqa: E731
    return {"bond_E": first(m.E), "bond_nu": first(m.nu), "bond_tensile_strength": first(m.tensile_strength),
            "bond_shear_strength": first(m.shear_strength)}


def _with(sample, params):
    """``sample`` with the calibrated bond parameters in its material table (every material scaled alike)."""
    from jaxbpm.sample import BondMaterials

    E = np.asarray(sample.materials.E, dtype=np.float64).reshape(-1)
    full = lambda key: np.full(E.shape, params[key])  # noqa: E731
    return sample.replace(materials=BondMaterials.create(
        E * (params["bond_E"] / E[0]), full("bond_nu"), tensile_strength=full("bond_tensile_strength"),
        shear_strength=full("bond_shear_strength")))


def _strength_stage(samples, scene_of, targets, wanted, params, *, tol, max_iterations, fd_step, solve_options,
                    executor, progress, kept=None):
    """Bond strengths by DEM failure runs: Qu et al.'s two estimates, then Gauss-Newton steps in log space on a
    Jacobian from the two estimates' secant along their direction and finite differences across it
    (:func:`_first_jacobian`; its perturbed runs batched: one task each on ``executor``), then by the plane fitted
    to every set seen (:func:`_fitted_jacobian`) after every step (one parameter set per iteration). ``kept`` (a
    dict) receives the observations of the answer's own runs by scene, where they are still held
    (:attr:`Problem.observed`). Elastic-brittle strengths are close to
    homogeneous of degree one in (sigma_c, tau_c) together, so log strengths are close to linear in log strengths of
    the bonds: the steps converge in a few iterations where Adam's fixed learning rate crawls (a BTS is ~0.1
    sigma_c, so Qu et al.'s scaling by the target makes Adam's steps 10x too short)."""
    from jaxbpm.calibrate.objective import Parameter, ParameterSpace, Problem, Target, base_params, forward_model
    from jaxbpm.calibrate.history import History

    t_start = time.perf_counter()
    tie = {}
    if "ucs" in targets:
        tie["bond_shear_strength"] = "ucs"
    tension = "bts" if "bts" in targets else ("flexural" if "flexural" in targets else None)
    if tension is not None:
        tie["bond_tensile_strength"] = tension
    keys = [k for k in ("bond_tensile_strength", "bond_shear_strength") if k in tie]
    scenes = {_SCENE_OF[k]: scene_of[k] for k in wanted}
    sample_map = {_SCENE_OF[k]: samples[k] for k in wanted}
    tgts = [Target("strength", targets[k], scene=_SCENE_OF[k]) for k in wanted]
    first = samples[wanted[0]]
    bounds = 1e3
    parameters = [Parameter(k, bounds=(targets[tie[k]] / bounds, targets[tie[k]] * bounds)) for k in keys]
    base = {k: v for k, v in base_params(first, keys).items() if k in keys}
    base = {k: np.asarray([targets[tie[k]]]) for k in base}  # (the first estimate: each at its target, Eq. 14)
    space = ParameterSpace(parameters, base)
    problem = Problem(forward_model(sample_map, scenes, "dem", **solve_options), tgts, space, executor=executor)
    show = _common.progress_fn(progress)
    history = History(space.names, problem.target_names)
    t_values = np.asarray([targets[k] for k in wanted])
    tied = [wanted.index(tie[k]) for k in keys]
    lo, hi = np.log(space.lower), np.log(space.upper)

    def run(points, kind):  # log parameter sets [B, n] -> log(strength / target) [B, m], recorded
        t0 = time.perf_counter()
        y = problem.outputs(np.exp(points))
        if np.any(~np.isfinite(y)) or np.any(y <= 0):
            raise CalibrationError(f"a failure run reported no strength at {np.exp(points).tolist()}")
        r = np.log(y / t_values[None, :])
        seen.extend(zip(points, r))
        for p, row in zip(points, y):
            _common.record(history, problem, show, kind=kind, values=np.exp(p), errors=row / t_values - 1,
                           time=(time.perf_counter() - t0) / len(points), level="dem")
        return r

    seen = []  # every set evaluated: (log bond strengths, log(strength / target))
    x = np.log(space.initial)  # estimate 1 (Qu et al. 2020, Eq. 14)
    r = run(x[None], "estimate-1")[0]
    best = (np.max(np.abs(np.expm1(r))), x, r)
    if best[0] > tol:  # estimate 2 (Eq. 15): each parameter scaled by its tied target / model value
        x = np.clip(x - r[tied], lo, hi)
        r = run(x[None], "estimate-2")[0]
        best = min(best, (np.max(np.abs(np.expm1(r))), x, r), key=lambda b: b[0])
    J = None
    iterations, length, stalled, probed = 0, 1.0, None, set()
    while best[0] > tol and iterations < max_iterations:
        iterations += 1
        x, r = best[1], best[2]  # every step starts from the best set so far
        if J is None:
            J = _first_jacobian(run, x, r, list(seen), np.log1p(fd_step))
            # a perturbed set that meets every target is an answer as good as any
            best = min([best] + [(np.max(np.abs(np.expm1(ro))), xo, ro) for xo, ro in seen], key=lambda b: b[0])
            if best[0] <= tol:
                break
        # directions the strengths barely follow (singular values under 5 % of the largest) are left alone
        newton = np.linalg.lstsq(J, -r, rcond=0.05)[0]
        dx = length * np.clip(newton, -1.0, 1.0)  # at most a factor e per step, shortened after a step that did worse
        kind = "newton"
        if np.max(np.abs(dx)) < 0.01:
            dx = _probe_step(J, r, tied, probed, tol)
            if dx is None:
                stalled = np.expm1(r + J @ newton)
                break
            kind = "probe"
        x_new = np.clip(x + dx, lo, hi)
        r_new = run(x_new[None], kind)[0]
        J = _fitted_jacobian(seen, J)  # the plane through every set seen: it learns from the step just taken
        error = np.max(np.abs(np.expm1(r_new)))
        length = 1.0 if error < best[0] else 0.5 * length  # a worse set is not kept: the next step is half as long
        best = min(best, (error, x_new, r_new), key=lambda b: b[0])
    _, x, r = best
    if kept is not None:  # the answer's own runs (their curves): no run again at the answer
        kept.update(problem.observed.get(tuple(np.exp(x).tolist()), {}))
    notes = ["estimates 1 and 2 of Qu et al. 2020 (Eq. 14-15), then Gauss-Newton steps in log space from the best "
             "set so far (Jacobian by the estimates' secant and finite differences across it, then the plane "
             "through every set seen; a step that does worse halves the next; a bond strength the strengths do not "
             "follow is probed by a factor 2 before the stage stops)"]
    if stalled is not None:
        notes.append("stopped: no step of 1 % or more is left to take from the best set; these targets are not "
                     "reached together by the bond strengths on these specimens (the linearised model's best: "
                     + ", ".join(f"{w} {e:+.1%}" for w, e in zip(wanted, stalled)) + ")")
    for j, key in enumerate(keys):
        if J is not None and np.max(np.abs(J[:, j])) < 0.05:
            notes.append(f"{key} is barely determined by these targets (the strengths change by < "
                         f"{0.05 * fd_step:.0%} when it changes by {fd_step:.0%}): it stays near its estimate; other "
                         "values fit as well")
    return _common.make_result(problem, history, np.exp(x), np.expm1(r), method="lab-strength", tol=tol,
                               wall_time=time.perf_counter() - t_start, evaluations=problem.evaluations, notes=notes,
                               iterations=iterations + 2)


def _first_jacobian(run, x, r, seen, step):
    """The Jacobian ``[m, n]`` of log strength against log bond strength at ``x`` (where the strengths are ``r``).

    Qu et al.'s second estimate moves every bond strength at once, by a factor of the order of the first estimate's
    error: along that direction the secant between the two estimates gives the Jacobian, and finite differences
    (``step`` in log space, the perturbed sets batched) give it across, in ``n - 1`` parameter sets instead of ``n``.
    Without another evaluated set at least ``step`` away (a single estimate), every axis is perturbed.
    """
    n = len(x)
    far = [(xo - x, ro - r) for xo, ro in seen if np.linalg.norm(xo - x) >= step]
    if not far:
        rs = run(x[None, :] + step * np.eye(n), "fd")
        return (rs - r[None, :]).T / step
    dx, dr = far[0]
    # an orthonormal basis whose first vector is the secant's direction
    q = np.linalg.qr(np.column_stack([dx / np.linalg.norm(dx), np.eye(n)]))[0][:, :n]
    across = step * q[:, 1:].T  # [n - 1, n]
    moves, changes = [dx], [dr]
    if n > 1:
        rs = run(x[None, :] + across, "fd")
        moves, changes = moves + list(across), changes + list(rs - r[None, :])
    # J @ moves^T = changes^T
    return np.linalg.solve(np.asarray(moves), np.asarray(changes)).T


def _probe_step(J, r, tied, probed: set, tol: float):
    """A step of a factor 2 in one bond strength that the strengths barely follow where it stands (its column of
    ``J`` under 0.05) while its tied target is missed, in the direction that target asks for (strengths rise with
    bond strengths); ``None`` when there is none left to probe (each is probed once; ``probed`` is updated).

    A strength can be flat in a bond strength over a range and follow it beyond (a UCS limited by tension does not
    move with ``tau_c`` until ``tau_c`` falls far enough for the bonds to fail in shear): the Gauss-Newton step sees
    only the flat part and stops; the probe reaches past it, and the plane through the sets then bridges the two.
    """
    for j, k in enumerate(tied):
        if j not in probed and np.max(np.abs(J[:, j])) < 0.05 and abs(np.expm1(r[k])) > tol:
            probed.add(j)
            dx = np.zeros(J.shape[1])
            dx[j] = -np.sign(r[k]) * np.log(2.0)
            return dx
    return None


def _fitted_jacobian(seen, J):
    """The Jacobian ``[m, n]`` of the plane fitted by least squares to every set seen (log bond strengths against
    log strength over target), or ``J`` where those sets do not span the ``n`` parameters (fewer than ``n + 1``, or
    on one line).

    A rank-one (Broyden) update keeps only the last step's slope along its direction; where a strength bends (a UCS
    that stops rising with ``tau_c`` once it is tension-limited), two steps along one direction that land on either
    side of a target then leave a slope that points nowhere, and the iteration stalls. The plane through all the
    sets bridges them.
    """
    X = np.array([xo for xo, _ in seen])
    A = np.column_stack([np.ones(len(X)), X - X.mean(axis=0)])
    if len(X) < A.shape[1] or np.linalg.matrix_rank(A) < A.shape[1]:
        return J
    coef = np.linalg.lstsq(A, np.array([ro for _, ro in seen]), rcond=None)[0]
    return coef[1:].T


def _curves(samples, scene_of, wanted, params, solve_options, achieved, targets, kept=None) -> tuple[dict, int]:
    """The failure runs at the answer: stress-strain curves and the strengths they give (the check). A test whose
    run at the answer the strength stage already made (``kept``: its observations by scene) is not run again.
    Returns the curves and the number of runs made."""
    from jaxbpm.physics.model import default_params
    from jaxbpm.solving import solve

    out, ran = {}, 0
    for key in wanted:
        s = samples[key]
        obs = (kept or {}).get(_SCENE_OF[key])
        if obs is None or "force" not in obs:
            p = {**default_params(s), "bond_tensile_strength": np.asarray([params["bond_tensile_strength"]]),
                 "bond_shear_strength": np.asarray([params["bond_shear_strength"]])}
            r = solve(s, scene_of[key], method="dem", params=p, throw=False, **solve_options)
            obs, ran = {"strain": r.strain, "force": r.force, "strength": r.stats.get("strength", np.nan)}, ran + 1
        strength = float(obs.get("strength", np.nan))
        achieved[key] = (strength, strength / targets[key] - 1.0)
        # the test's own stress measure (UCS: F / A; BTS: 2 F / (pi D t); bending: the flexural formula)
        out[key] = (np.asarray(obs["strain"]), np.asarray(scene_of[key].strength(np.asarray(obs["force"]), s)))
    return out, ran


#: the codes whose bonds break by each failure rule (their strength translation is exact only under it)
_RULE_CODES = {"separate": "PFC (parallel bond, pb_mcf 1) and MUSEN (criterion 1)", "summed": "LAMMPS (bpm/rotational)",
               "max": "Yade (CohFrictPhys) and MUSEN (criterion 2)"}


def _rule_note(rule) -> str:
    others = ", ".join(v for k, v in _RULE_CODES.items() if k != rule)
    return (f"Strengths calibrated under the failure rule '{rule}': they hold as they are in {_RULE_CODES[rule]}; "
            f"{others} break bonds under mixed loads by another rule (calibrate again with that code's "
            "failure_rule for its strengths).")


def _translations(sample, params) -> dict:
    """The answer in other codes' parameters, for the sample's mean particle pair (touching, mean radius). A 2D
    sample's bonds are ``2 r_b x t`` rectangles (PFC2D's; LAMMPS ``dimension 2``); codes with no 2D form get
    ``{"2D": "why"}`` instead of numbers."""
    import warnings

    from jaxbpm.interop import conventions as cv
    from jaxbpm.interop._codes import NO_2D

    r = float(np.mean(sample.radii))
    ratio = float(np.median(np.asarray(sample.bond_radius) / np.minimum(*np.asarray(sample.radii)[
        np.asarray(sample.bonds)].T))) if sample.n_bonds else 0.5
    bond = cv.JaxbpmBond(E=params["bond_E"], nu=params["bond_nu"], bond_radius=ratio * r,
                         tensile_strength=params["bond_tensile_strength"],
                         shear_strength=params["bond_shear_strength"], thickness=sample.thickness)
    out = {"jaxbpm": {"E": params["bond_E"], "nu": params["bond_nu"], "bond_radius_ratio": ratio,
                      "tensile_strength": params["bond_tensile_strength"],
                      "shear_strength": params["bond_shear_strength"]}}
    if sample.dim == 2:
        out["jaxbpm"]["thickness"] = sample.thickness
    makers = {"lammps": lambda: cv.to_lammps(bond, 2 * r), "pfc": lambda: cv.to_pfc(bond, 2 * r, r, r),
              "yade": lambda: cv.to_yade(bond, 2 * r, r, r), "musen": lambda: cv.to_musen(bond)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cv.InexactTranslationWarning)
        for name, make in makers.items():
            if sample.dim == 2 and name in NO_2D:
                out[name] = {"2D": NO_2D[name]}
                continue
            out[name] = {k: float(np.asarray(v).reshape(-1)[0]) for k, v in dataclasses.asdict(make()).items()
                         if k != "thickness" and (np.ndim(v) == 0 or np.size(v) == 1) and v is not None}
    return out
