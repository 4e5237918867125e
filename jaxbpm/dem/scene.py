"""The DEM scene driver: :func:`solve_scene`, what ``jaxbpm.solve(..., method="dem")`` runs.

A run is four steps: :func:`~jaxbpm.dem.plan.plan` (model, time step, loading, steps, chunk), its
:func:`~jaxbpm.dem.writers.writers` (record file, VTU frames), :func:`~jaxbpm.dem.integrator.integrate` (the
chunks, ending in an :class:`~jaxbpm.dem.integrator.Outcome` whatever happened) and :func:`finish` (the
:class:`~jaxbpm.result.Result` with the outcome's status). Failure is data: an unstable run is a result with status
``"unstable"`` that :func:`jaxbpm.result.settle` raises with ``throw=True``; an interruption raises
:class:`~jaxbpm.errors.SimulationInterrupted` carrying the result of the part that was run.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np

from jaxbpm._compile import compile_clock
from jaxbpm._geometry import check_three_d
from jaxbpm.dem import quasistatic as quasi_static
from jaxbpm.dem.curve import curve, fit_line, peak_stats, plan_stats
from jaxbpm.dem.elastic_start import elastic_start, with_segment
from jaxbpm.dem.integrator import integrate, Outcome
from jaxbpm.dem.options import DEM
from jaxbpm.dem.peak import peak_stop
from jaxbpm.dem.plan import Plan, plan
from jaxbpm.dem.state import restore_state, state_arrays, unpad_state
from jaxbpm.dem.writers import check_frames, write_frame, Writers, writers
from jaxbpm.errors import OptionsError, SimulationInterrupted
from jaxbpm.physics.model import default_params
from jaxbpm.result import Result, settle, timed_result
from jaxbpm.scenes import lateral_stats
from jaxbpm.status import Status

__all__ = ["solve_scene", "finish"]


def solve_scene(sample, scene, params=None, options: DEM | None = None, *, static=None) -> Result:
    """Run the DEM on ``scene`` and return its result.

    Args:
      sample: the bonded sample.
      scene: the scene.
      params: parameters checked by :func:`jaxbpm.physics.model.check_params` (``None``: the sample's own).
      options: the :class:`~jaxbpm.dem.options.DEM` options (``None``: the defaults).
      static: with ``start="elastic"``, the static solve that gives the start (see
        :func:`jaxbpm.dem.elastic_start.elastic_start`; :func:`jaxbpm.solve` passes the DSM's,
        :func:`jaxbpm.elastic_field.dsm_field`).

    Returns:
      The :class:`~jaxbpm.result.Result` (``state``: the :class:`~jaxbpm.dem.DEMState` at the end), with its status.

    Raises:
      OptionsError: ``start="elastic"`` without ``static``.
      SceneError: options that do not fit the scene or the run (on a two-dimensional sample: ``start="elastic"``,
        contacts or walls, not yet available in 2D).
      InstabilityError: with ``options.throw``, a run that blew up (carrying the result of what ran before).
      SimulationInterrupted: a ``KeyboardInterrupt`` during the run, carrying the result of the part that was run.
    """
    options = DEM() if options is None else options
    if options.start == "elastic" and sample.dim == 2:
        check_three_d(sample, "the DEM's start='elastic'")
    if options.start == "elastic" and static is None:
        raise OptionsError("start='elastic' needs the static solve that gives the start: run it with jaxbpm.solve, "
                           "or pass static=jaxbpm.elastic_field.dsm_field")
    t0 = time.perf_counter()
    with compile_clock() as compiling:  # (the setup's compilations count as compile time)
        check_frames(options.snapshots, options.vtu)
        params = default_params(sample) if params is None else params
        the_plan = plan(sample, scene, params, dt=options.dt, safety=options.safety, damping=options.damping,
                        loading_time=options.loading_time, transits=options.transits, chunk=options.chunk,
                        snapshots=options.snapshots, pad=options.pad)
        out = writers(sample, scene, the_plan, record_to=options.record_to, snapshots=options.snapshots,
                      vtu=options.vtu, overwrite=options.overwrite, resume=options.resume)
        the_plan = the_plan.starting_from(None if out.saved is None else restore_state(out.saved), out.steps_done)
        the_plan, start = _elastic(sample, scene, params, the_plan, out, options, static)
        clock = _Clock(t0, time.perf_counter(), compiling.seconds, compiling)
        run = _simulate(sample, the_plan, params, out, progress=options.progress, neighbors=options.neighbors,
                        stop=_stop(scene, the_plan, out))
        if start is not None:
            run.stats.update(start.stats)
            run = run._replace(records=with_segment(run.records, start.records))
        stop = SimulationInterrupted(run.state, run.records, run.stats) if run.status == Status.INTERRUPTED else None
        result = finish(sample, scene, the_plan, run, out, clock, options.max_records)
    if stop is not None:
        stop.result = result
        raise stop
    return settle(result, options.throw)


def _elastic(sample, scene, params, the_plan: Plan, out: Writers, options: DEM, static):
    """The plan started from the DSM's elastic state (``start="elastic"``, not a resumed run) and that start (its
    segment written to the record file as the first rows); else the plan as it is and ``None``."""
    if options.start != "elastic" or out.saved is not None:
        return the_plan, None
    start = elastic_start(sample, scene, params, the_plan, static, safety=options.start_safety)
    if start.state is not None and out.on_chunk is not None:
        out.on_chunk(start.steps_done, start.state, start.records)
    return the_plan.starting_from(start.state, start.steps_done), start


@dataclasses.dataclass(frozen=True)
class _Clock:
    """When the solve started, when its run started, the compile time before the run and the solve's clock."""

    t0: float
    t_sim: float
    setup_compile: float
    compiling: Any


def _stop(scene, the_plan: Plan, out: Writers) -> tuple:
    """The run's stop after the peak (:func:`jaxbpm.dem.peak.peak_stop`) and the peak before its start (a resumed
    run's, from its record's earlier rows; else ``None``)."""
    stop = peak_stop(scene, the_plan.model, the_plan.load, the_plan)
    prior = out.prior
    peak = float(np.max(scene.compressive_force(prior["reaction"]))) if prior and len(prior["reaction"]) else None
    return stop, peak


def _simulate(sample, the_plan: Plan, params, out: Writers, *, progress, neighbors, stop=(None, None)) -> Outcome:
    """The run of the plan. Its outcome holds the sample's state (a padded run's cut to the sample); where it was
    interrupted the (padded) state is saved in the record file. A ``KeyboardInterrupt`` before the first chunk is
    raised (the record file says so)."""
    on_chunk, before = out.on_chunk, the_plan.steps_done
    if on_chunk is not None and before:  # the writers count the steps of the whole run (VTU frames)
        on_chunk = lambda done, state, rec, call=on_chunk: call(done + before, state, rec)  # noqa: E731
    try:
        run = integrate(the_plan.model, params, the_plan.load, dt=the_plan.dt, n_steps=the_plan.steps_left,
                        damping=the_plan.damping, chunk=the_plan.chunk, neighbors=neighbors,
                        progress=the_plan.progress(progress), dt_crit=the_plan.dt_crit[0], state=the_plan.start,
                        on_chunk=on_chunk, stop=stop[0], peak=stop[1])
    except KeyboardInterrupt:  # before the first chunk (a resumed run's record keeps its saved state)
        if out.recorder is not None:
            out.recorder.finish("interrupted")
        raise
    if run.status == Status.INTERRUPTED and out.recorder is not None and out.recorder.steps > the_plan.steps_done:
        out.recorder.checkpoint(state_arrays(run.state))  # what resume= continues from
    if run.stats.get("stop_reason") == "after_peak" and out.series is not None:
        t = float(run.state.time)
        if not out.series.steps or out.series.steps[-1][0] != t:  # the last frame: where the run stopped
            write_frame(out.series, run.state, sample, t)
    if the_plan.size is None:
        return run
    return run._replace(state=unpad_state(run.state, sample.n_particles, sample.n_bonds))


def finish(sample, scene, the_plan: Plan, run: Outcome, out: Writers, clock, max_records: int) -> Result:
    """The result of a run, whatever its status; the record file gets its final status and the scalar results.

    Args:
        sample: the sample.
        scene: the scene.
        the_plan: the run's plan.
        run: the run's outcome (the sample's state).
        out: the run's writers.
        clock: the solve's timings so far (:class:`_Clock`).
        max_records: the most points kept in the returned curve.

    Returns:
        The :class:`~jaxbpm.result.Result` (status ``"converged"``, ``"not_quasi_static"`` (loaded too fast: see
        :mod:`jaxbpm.dem.quasistatic`), ``"unstable"`` or ``"interrupted"``; a converged one may still be found not
        finite by :func:`jaxbpm.result.settle`).
    """
    status, stats = run.status, run.stats
    interrupted = status == Status.INTERRUPTED
    rec = _whole_records(run, out)
    disp, force, stiffness, keep = curve(scene, rec, the_plan.speed, the_plan.target, max_records,
                                         strict=False)  # (too few records: not quasi-static, below)
    stats.update(plan_stats(the_plan, the_plan.dt_crit[0], interrupted))
    if "steps_planned" in stats:  # the whole run's (integrate plans the steps left of a resumed or started run)
        stats["steps_planned"] = the_plan.n_steps
    # wall = setup (before the first chunk, less the compilations in it) + compile + run (the rest)
    setup = clock.t_sim - clock.t0 - clock.setup_compile + stats["setup_time"]
    compile_time = clock.compiling.seconds
    stats.update(setup_time=setup, compile_time=compile_time)
    if out.path is not None:
        stats["record_file"] = str(out.path)
    if out.series is not None:
        stats["vtu"] = str(out.series.path)
        stats["vtu_frames"] = len(out.series.steps)
    stats.update(peak_stats(scene, sample, rec, disp, force, keep, the_plan.breakage))
    stats.update(fit_line(scene, disp, force, the_plan.target, the_plan.gauge_length, the_plan.area))
    status = quasi_static.check(scene, the_plan, rec, disp, force, stats, status)
    stats.update(_lateral(scene, sample, run.state, stats, the_plan.breakage, status))
    youngs = scene.modulus(stiffness, sample)
    if out.recorder is not None:
        wall = time.perf_counter() - clock.t0
        stats.update(wall_time=wall, run_time=wall - setup - compile_time)
        # (steps_planned is the record's own, set when it was made: a resumed run's integrate plans fewer)
        out.recorder.finish("complete" if status == Status.CONVERGED else str(status),
                            {k: v for k, v in stats.items() if k not in ("broken_curve", "padded_to", "steps_planned")})
    result = timed_result("dem", clock.t0, stiffness=stiffness, youngs_modulus=youngs,
                          gauge_length=the_plan.gauge_length, area=the_plan.area, displacement=disp[keep],
                          force=force[keep], setup_time=setup, compile_time=compile_time, stats=stats,
                          state=run.state, interrupted=interrupted, status=status)
    stats.update(wall_time=result.wall_time, run_time=result.run_time)
    return result


def _whole_records(run: Outcome, out: Writers) -> dict:
    """The records of the whole run: a resumed run's earlier rows first (its stats then count every step)."""
    rec, prior = run.records, out.prior
    if not prior:
        return rec
    run.stats.update(steps=out.recorder.steps, resumed_at=len(prior["time"]))
    if rec:
        return {k: np.concatenate([prior[k], rec[k]]) for k in rec}
    return {k: prior[k] for k in ("time", "reaction", "vmax", "broken") if k in prior}


def _lateral(scene, sample, state, stats, breakage, status) -> dict:
    """The lateral strain of the loaded state of a converged run where no bond broke (a broken sample's would mean
    nothing)."""
    intact = not breakage or stats.get("broken_tensile", 0) + stats.get("broken_shear", 0) == 0
    if not intact or status != Status.CONVERGED or state is None:
        return {}
    return lateral_stats(scene, sample, np.asarray(state.positions)[:sample.n_particles] - np.asarray(sample.positions))
