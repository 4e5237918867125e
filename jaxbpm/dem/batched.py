"""Batched DEM runs: B parameter sets on the same sample in one program, the chunk mapped over the members.

The perturbed runs of a finite-difference gradient, or a chunk of a run set, differ only in their parameters (bond
stiffness and strength): the geometry, the loading and the number of steps are shared, so one jitted chunk, mapped
over the parameters and the states (:func:`jaxbpm.dem.chunk._run_chunk`; the model and the loading unmapped),
advances all of them. Two ways to map (``solve_batch(vectorize=...)``):

- ``lax.map`` (default): inside the program the members run one after another, each by the single run's code, so
  each result is the one :func:`jaxbpm.solve` gives for it alone to the last bit. It saves the per-run setup (time
  step estimate, initial state, compilation of new chunk lengths) and host work between chunks.
- ``jax.vmap`` (``vectorize=True``): one vectorised program. XLA's CPU code for it rounds some bond-law results
  differently (by an ulp), and the local damping's ``sign(v)`` of nearly resting particles turns that into
  differences of about 1e-5 in the stiffness and 1e-4 in the force curve (more after bonds break: other bonds may
  break) -- the DEM's own sensitivity to round-off, not an error of either run. On CPU it is also slower than
  ``lax.map`` (the gathers and scatters of a batched layout); it is meant for accelerators.

See ``benchmarks/dem_batch.py`` for where batching pays. Bonds-only scenes only (``contacts=False``; plane walls
are fine): a scene with contacts keeps a neighbour list whose buffer and rebuilds depend on how each member's
particles move, so its members cannot share one program.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Mapping, Sequence
from typing import Any

import jax
import numpy as np

from jaxbpm import _interrupt
from jaxbpm._compile import compile_clock
from jaxbpm.dem import quasistatic
from jaxbpm.dem.chunk import _run_chunk
from jaxbpm.dem.curve import curve, fit_line, peak_stats, plan_stats
from jaxbpm.dem.integrator import _progress_fn
from jaxbpm.dem.peak import peak_stop, tracker
from jaxbpm.dem.plan import Plan, plan
from jaxbpm.dem.state import unpad_state
from jaxbpm.dem.stepper import _start
from jaxbpm.errors import SceneError, SimulationInterrupted, SolveError
from jaxbpm.result import Result, settle, timed_result, Timings
from jaxbpm.sample import Sample
from jaxbpm.status import Status

__all__ = ["solve_batch"]

# the options of jaxbpm.solve(method="dem") a batch does not take: they write one file per run
_PER_RUN = ("record_to", "snapshots", "vtu", "resume", "overwrite")


def solve_batch(sample: Sample, scene, params_batch, *, method="dem", vectorize: bool = False,
                **options) -> list[Result]:
    """Solve ``scene`` on ``sample`` once per parameter set of ``params_batch``, all in one DEM program.

    One program serves all members, so they share the number of steps and the time step: ``dt`` (default
    ``safety`` x the smallest critical time step of the members), ``loading_time`` (default ``transits`` x the
    longest elastic-wave transit time of the members: the softest member's) and ``chunk`` (default from the number
    of steps, as for ``solve``): one :func:`~jaxbpm.dem.plan.plan` for all. Each member's result is then the one
    ``jaxbpm.solve(sample, scene, params=p, dt=dt, loading_time=loading_time, chunk=chunk)`` gives (to the last bit;
    with ``vectorize=True`` to the DEM's round-off sensitivity, see :mod:`jaxbpm.dem.batched`); those three values
    are in ``result.stats["batch"]``, with the batch size, the member's index, the mapping and the batch's wall,
    compile and kernel times. The timings of each result (``wall_time``, ``setup_time``, ``compile_time``,
    ``run_time``, ``kernel_time``) are its share of the batch's: the batch's divided by B.

    Scenes: bonds only -- ``contacts=False``, with or without breakage and with clamped layers or plane walls
    (``UniaxialCompression()``, ``UniaxialCompression.to_failure(contacts=False)``,
    ``ThreePointBending(contacts=False)``). A scene with contacts has a neighbour list that depends on how each
    member's particles move; run those one by one with ``solve``.

    Failure per member: a member that blows up stops being checked and gets the ``"unstable"`` result ``solve``
    would give it (the curve up to the chunk before the blow-up); the others run on.

    Stop after the peak per member: with the scene's ``stop_after_peak`` (:mod:`jaxbpm.dem.peak`) each member tracks
    its own peak and stops on its own, as its single run would (its records end there, its ``stats["stop_reason"]``
    says ``"after_peak"``); the batch ends when every member has stopped, failed or reached the full strain. With
    ``lax.map`` a stopped member runs no more steps; with ``vectorize=True`` it is frozen while the others run.

    Args:
      sample: the bonded sample.
      scene: a bonds-only scene.
      params_batch: a list of parameter dicts, each one that :func:`jaxbpm.solve` takes as ``params`` (e.g.
        :func:`jaxbpm.physics.model.default_params` with ``bond_E``, ``bond_nu``, ``bond_tensile_strength`` or
        ``bond_shear_strength`` overridden), or one dict of arrays whose every entry has a leading batch axis
        (``bond_E [B, n_materials]``, a scalar contact parameter ``[B]``). Every member is checked as ``solve``
        checks ``params``.
      method: ``"dem"`` or a :class:`~jaxbpm.dem.options.DEM` options object (the DSM and STE have no batched
        form).
      vectorize: False: ``lax.map`` over the members inside the program, each exactly as its single run; True:
        ``jax.vmap``, one vectorised program (for accelerators; on CPU slower, and equal to the single runs only to
        round-off amplified by the local damping).
      **options: the DEM's options (:class:`~jaxbpm.dem.options.DEM`; ``neighbors`` is accepted and unused), not
        ``record_to``, ``snapshots``, ``vtu``, ``resume`` or ``overwrite`` (files are written per run: use
        ``solve``), nor ``start="elastic"`` (the members start from rest).

    Returns:
      One :class:`~jaxbpm.result.Result` per member, in order, each with its status.

    Raises:
      SceneError: another solver, an option that writes files, a scene with contacts, a malformed batch.
      SolveError: with ``throw`` (the default), the first failing member's error, once all have run, carrying that
        member's ``result`` and every member's in ``results``.
      SimulationInterrupted: a ``KeyboardInterrupt``; its ``results`` hold every member's result of the chunks
        completed (``result`` is the first member's).
    """
    with _interrupt.guard():
        results = _solve_batch(sample, scene, method, params_batch, vectorize, options)
        _interrupt.check()
    return results


def _members(params_batch, sample: Sample) -> list[dict]:
    """The checked parameter dicts of a batch (a list of dicts, or a dict of arrays with a leading batch axis)."""
    from jaxbpm.physics.model import check_params

    if isinstance(params_batch, Mapping):
        sizes = {k: np.shape(v)[0] if np.ndim(v) else None for k, v in params_batch.items()}
        if not sizes or None in sizes.values() or len(set(sizes.values())) != 1:
            raise SceneError("a dict params_batch needs a leading batch axis of one length on every entry, got "
                             f"shapes { {k: np.shape(v) for k, v in params_batch.items()} }")
        size = next(iter(sizes.values()))
        members = [{k: np.asarray(v)[b] for k, v in params_batch.items()} for b in range(size)]
    elif isinstance(params_batch, Sequence) and not isinstance(params_batch, (str, bytes)):
        members = list(params_batch)
    else:
        raise SceneError(f"params_batch must be a list of parameter dicts or a dict of arrays with a leading batch "
                         f"axis, got {type(params_batch).__name__}")
    if not members:
        raise SceneError("params_batch is empty: give at least one parameter set")
    return [check_params(p, sample) for p in members]


def _stack(trees):
    """One pytree of ``trees`` stacked along a new leading axis (on the host: no program is compiled)."""
    structures = {jax.tree_util.tree_structure(t) for t in trees}
    if len(structures) != 1:
        raise SceneError("the members of params_batch give different parameter structures; give every member the "
                         "same keys")
    return jax.tree_util.tree_map(lambda *xs: jax.device_put(np.stack([np.asarray(x) for x in xs])), *trees)


@functools.partial(jax.jit, static_argnames=("n_steps", "vectorize"))
def _run_chunks(model, params, load, state, dt, damping, origin, n_steps, vectorize=True, stop=None, track=None):
    """:func:`jaxbpm.dem.chunk._run_chunk` mapped over the leading axis of ``params`` (precomputed), ``state`` and the
    peak trackers ``track``; the model, the loading, the time step, the damping and the ``stop`` are shared.
    ``vectorize``: ``jax.vmap`` (one vectorised program: a member that stopped is frozen while the others run);
    else ``lax.map`` (the members one after another inside the program, each by the single run's code: a member that
    stopped runs no step)."""
    def one(p, s, t):
        return _run_chunk(model, p, load, s, dt, damping, origin, n_steps, stop=stop, track=t)

    if vectorize:
        return jax.vmap(one)(params, state, track)
    return jax.lax.map(lambda pst: one(*pst), (params, state, track))


def _solve_batch(sample, scene, method, params_batch, vectorize, options) -> list[Result]:
    from jaxbpm._options import resolve_options

    options = resolve_options(method, options)
    _check(sample, scene, options)
    members = _members(params_batch, sample)
    t0 = time.perf_counter()
    with compile_clock() as compiling:
        results = _run_batch(t0, compiling, sample, scene, members, bool(vectorize), options)
    for r in results:
        settle(r, False)
    failed = [r for r in results if r.status in (Status.UNSTABLE, Status.NOT_FINITE)]
    if options.throw and failed:
        # the error settle raises for the first failing member, carrying every member's result
        try:
            settle(failed[0], True)
        except SolveError as err:
            err.results = results
            raise
    return results


def _check(sample, scene, options) -> None:
    """What a batch cannot run: another method, a file per run, a scene with contacts."""
    method, options = options.method, options.asdict()
    if method != "dem":
        raise SceneError(f"solve_batch runs the DEM only, not {method!r}: solve the {method.upper()} runs one by one "
                         "with jaxbpm.solve (each is one linear solve; there are no time steps to share)")
    if not isinstance(sample, Sample):
        raise TypeError(f"sample must be a jaxbpm.Sample, got {type(sample).__name__}")
    given = [k for k in _PER_RUN if options.get(k) is not None and options.get(k) is not False]
    if given:
        raise SceneError(f"solve_batch does not take {', '.join(given)} (files written per run): run those members "
                         "one by one with jaxbpm.solve")
    if options.get("start", "rest") != "rest":
        raise SceneError("solve_batch starts its members from rest: run start='elastic' one by one with jaxbpm.solve")
    if scene.contacts:
        raise SceneError(
            f"solve_batch runs bonds-only scenes, and this {type(scene).__name__} has contacts=True: its neighbour "
            "list (buffer size, rebuilds) depends on how each member's particles move, so the members cannot share "
            "one program. Run them one by one with jaxbpm.solve, or give the scene contacts=False (e.g. "
            "UniaxialCompression.to_failure(contacts=False), ThreePointBending(contacts=False)) where broken bonds "
            "need no contacts")


@dataclasses.dataclass
class _Chunks:
    """The chunks a batch ran: host records of each completed chunk (``[B, chunk, ...]``), each chunk's kernel time,
    per member ``(chunks completed, its state then, the message)`` once it blew up, the state after the last
    completed chunk, whether the batch was interrupted, the steps each member ran in each chunk (``[B]`` per chunk:
    fewer where it stopped after the peak, none after) and which members stopped."""

    records: list
    kernel: list
    failure: list
    done: Any
    interrupted: bool = False
    steps: list = dataclasses.field(default_factory=list)
    stopped: Any = None

    def going(self) -> bool:
        """Whether a member is neither failed nor stopped."""
        return any(f is None and not s for f, s in zip(self.failure, self.stopped))


def _run_batch(t0, compiling, sample, scene, members, vectorize, options) -> list[Result]:
    """The batch's plan, its members' initial states, its chunks and every member's result."""
    the_plan = plan(sample, scene, members, dt=options.dt, safety=options.safety, damping=options.damping,
                    loading_time=options.loading_time, transits=options.transits, chunk=options.chunk,
                    pad=options.pad)
    report = _progress_fn(the_plan.progress(options.progress))
    # the members' initial states and per-run constants, each by the program a single run uses, then stacked
    started = [_start(the_plan.model, p, the_plan.load, None) for p in members]
    state, pre = _stack([s for s, _ in started]), _stack([c for _, c in started])
    jax.block_until_ready((state, pre))
    _interrupt.check()
    t_loop, setup_compile = time.perf_counter(), compiling.seconds
    stop = peak_stop(scene, the_plan.model, the_plan.load, the_plan)
    track = _stack([tracker(dtype=the_plan.model.positions0.dtype)] * len(members))
    ran = _run_chunks_until_done(the_plan, pre, state, vectorize, report, t0, compiling, (stop, track))
    # the members' results; the timings are each member's share of the batch's
    timing = Timings.since(t0, compiling.seconds, setup_time=t_loop - t0 - setup_compile)
    host = jax.tree_util.tree_map(np.asarray, ran.done)
    results = [_member_result(sample, scene, the_plan, ran, host, b, timing, vectorize, options.max_records)
               for b in range(len(members))]
    if ran.interrupted:
        stop = SimulationInterrupted([r.state for r in results], None,
                                     {"steps": len(ran.records) * the_plan.chunk, "steps_planned": the_plan.n_steps,
                                      "interrupted": True}, result=results[0])
        stop.results = results
        raise stop
    return results


def _run_chunks_until_done(the_plan: Plan, pre, state, vectorize, report, t0, compiling, watch) -> _Chunks:
    """Run the batch's chunks until all are done, every member failed or stopped after its peak, or an
    interruption. ``watch``: the stop after the peak and the members' trackers."""
    model, dt, chunk = the_plan.model, the_plan.dt, the_plan.chunk
    origin = jax.device_put(np.zeros(3, model.positions0.dtype))
    r_min = float(np.min(np.asarray(model.radii)))
    stop, track = watch
    n_batch = int(np.shape(track.stopped)[0])
    ran = _Chunks([], [], [None] * n_batch, state, stopped=np.zeros(n_batch, bool))
    try:
        while len(ran.records) < the_plan.n_chunks and ran.going():
            _interrupt.check()
            tc, compiled = time.perf_counter(), compiling.seconds
            new, rec, _, finite, _, _, counts, track = _run_chunks(model, pre, the_plan.load, state, dt,
                                                                   the_plan.damping, origin, chunk,
                                                                   vectorize=vectorize, stop=stop, track=track)
            jax.block_until_ready(new.positions)
            ran.kernel.append(time.perf_counter() - tc - (compiling.seconds - compiled))
            rec = jax.device_get(rec)
            _check_members(ran, rec, np.asarray(finite), the_plan, r_min)
            state = ran.done = new
            ran.records.append(rec)
            ran.steps.append(np.asarray(counts)[:, 0])
            ran.stopped = np.asarray(track.stopped)
            report(len(ran.records) * chunk, the_plan.n_chunks * chunk, time.perf_counter() - t0)
    except KeyboardInterrupt:
        _interrupt.clear()
        ran.interrupted = True
    return ran


def _check_members(ran: _Chunks, rec, finite, the_plan: Plan, r_min: float) -> None:
    """Mark the members that blew up in the chunk just run (from then on they are no longer checked)."""
    vmax = np.max(rec["vmax"], axis=1)
    k, chunk, dt = len(ran.records), the_plan.chunk, the_plan.dt
    for b in range(len(ran.failure)):
        if ran.failure[b] is None and (not np.isfinite(vmax[b]) or not finite[b] or vmax[b] * dt > 0.25 * r_min):
            ran.failure[b] = (k, ran.done, (
                f"DEM run became unstable within steps {k * chunk}..{(k + 1) * chunk} (non-finite or runaway "
                f"motion, max speed {vmax[b]:.3g} m/s): time step dt = {dt:.4g} s, critical time step "
                f"estimate = {the_plan.dt_crit[b]:.4g} s. Use a smaller time step (or a smaller safety factor)."))


def _member_result(sample, scene, the_plan: Plan, ran: _Chunks, host, b: int, timing: Timings, vectorize: bool,
                   max_records: int) -> Result:
    """Member ``b``'s result: its records up to its failure, if any, and its share of the batch's timings."""
    n_batch, chunk, kernel = len(ran.failure), the_plan.chunk, ran.kernel
    completed, member_state, message = len(ran.records), host, None
    if ran.failure[b] is not None:
        completed, failed_state, message = ran.failure[b]
        member_state = jax.tree_util.tree_map(np.asarray, failed_state)
    member_state = jax.tree_util.tree_map(lambda x: jax.device_put(x[b]), member_state)
    if the_plan.size is not None:
        member_state = unpad_state(member_state, sample.n_particles, sample.n_bonds)
    steps = [int(k[b]) for k in ran.steps[:completed]]  # (fewer in the chunk where the member stopped, then none)
    rec = ({key: np.concatenate([r[key][b][:k] for r, k in zip(ran.records, steps)]) for key in ran.records[0]}
           if completed else {})
    status = Status.UNSTABLE if message is not None else Status.CONVERGED
    disp, force, stiffness, keep = curve(scene, rec, the_plan.speed, the_plan.target, max_records, strict=False)
    per_chunk = float(np.median(kernel)) if kernel else float("nan")
    share = timing.share(n_batch)
    stats = {"setup_time": share.setup_time, "compile_time": share.compile_time, "run_time": share.run_time,
             "wall_time": share.wall_time, "kernel_time": float(np.sum(kernel)) / n_batch,
             "steps": sum(steps), "steps_per_second": chunk / per_chunk, "reallocations": 0,
             "contact_capacity": 0, "stop_reason": "full_strain"}
    if message is not None:
        stats.update(unstable=True, steps_planned=the_plan.n_steps, failure=message, stop_reason="unstable")
    elif ran.interrupted:
        stats.update(interrupted=True, steps_planned=the_plan.n_steps, stop_reason="interrupted")
    elif ran.stopped[b]:
        stats.update(steps_planned=the_plan.n_steps, stop_reason="after_peak")
    stats.update(plan_stats(the_plan, the_plan.dt_crit[b], ran.interrupted))
    stats.update(peak_stats(scene, sample, rec, disp, force, keep, the_plan.breakage))
    stats.update(fit_line(scene, disp, force, the_plan.target, the_plan.gauge_length, the_plan.area))
    if not ran.interrupted:
        status = quasistatic.check(scene, the_plan, rec, disp, force, stats, status)
    stats["batch"] = {"size": n_batch, "index": b, "vectorize": vectorize, "dt": the_plan.dt,
                      "loading_time": the_plan.loading_time, "chunk": chunk, "wall_time": timing.wall_time,
                      "compile_time": timing.compile_time, "kernel_time": float(np.sum(kernel))}
    length, area = the_plan.gauge_length, the_plan.area
    return timed_result("dem", timings=share, stiffness=stiffness, youngs_modulus=scene.modulus(stiffness, sample),
                        gauge_length=length, area=area, displacement=disp[keep], force=force[keep], stats=stats,
                        state=member_state, interrupted=ran.interrupted,
                        status=Status.INTERRUPTED if ran.interrupted else status)
