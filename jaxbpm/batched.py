"""Batched DEM runs: B parameter sets on the same sample in one program, the chunk mapped over the members.

The perturbed runs of a finite-difference gradient, or a chunk of a run set, differ only in their parameters (bond
stiffness and strength): the geometry, the loading and the number of steps are shared, so one jitted chunk, mapped
over the parameters and the states (:func:`jaxbpm.dem._run_chunk`; the model and the loading unmapped), advances all
of them. Two ways to map (``solve_batch(vectorize=...)``):

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

import functools
import time
import warnings
from collections.abc import Mapping, Sequence

import jax
import numpy as np

from jaxbpm.errors import SceneError, SimulationInterrupted, SolveError
from jaxbpm.result import Result
from jaxbpm.sample import Sample

__all__ = ["solve_batch"]

# the options of jaxbpm.solve(method="dem") a batch does not take: they write one file per run
_PER_RUN = ("record_to", "snapshots", "vtu", "resume", "overwrite")


def solve_batch(sample: Sample, scene, params_batch, *, method="dem", vectorize: bool = False,
                **options) -> list[Result]:
    """Solve ``scene`` on ``sample`` once per parameter set of ``params_batch``, all in one DEM program; returns one :class:`~jaxbpm.result.Result` per member, in order.

    params_batch: a list of parameter dicts, each one that :func:`jaxbpm.solve` takes as ``params`` (e.g.
    :func:`jaxbpm.physics.model.default_params` with ``bond_E``, ``bond_nu``, ``bond_tensile_strength`` or
    ``bond_shear_strength`` overridden), or one dict of arrays whose every entry has a leading batch axis (``bond_E``
    ``[B, n_materials]``, a scalar contact parameter ``[B]``). Every member is checked as ``solve`` checks ``params``.

    One program serves all members, so they share the number of steps and the time step: ``dt`` (default
    ``safety`` x the smallest critical time step of the members) and ``loading_time`` (default ``transits`` x the
    longest elastic-wave transit time of the members: the softest member's) and ``chunk`` (default from the number
    of steps, as for ``solve``). Each member's result is then the one ``jaxbpm.solve(sample, scene, params=p,
    dt=dt, loading_time=loading_time, chunk=chunk)`` gives (to the last bit; with ``vectorize=True`` to the DEM's
    round-off sensitivity, see :mod:`jaxbpm.batched`); those three values are in ``result.stats["batch"]``, with
    the batch size, the member's index, the mapping and the batch's wall, compile and kernel times. The
    timings of each result (``wall_time``, ``setup_time``, ``compile_time``, ``run_time``, ``kernel_time``) are its
    share of the batch's: the batch's divided by B.

    vectorize: False (default): ``lax.map`` over the members inside the program, each exactly as its single run;
    True: ``jax.vmap``, one vectorised program (for accelerators; on CPU slower, and equal to the single runs only
    to round-off amplified by the local damping).
    method: ``"dem"`` or a ``jaxbpm.DEM(...)`` options object (the DSM and STE have no batched form). options: those
    of ``solve`` for ``"dem"`` -- ``dt``, ``safety``, ``damping``, ``loading_time``, ``transits``, ``chunk``,
    ``progress``, ``max_records``, ``pad``, ``throw`` (``neighbors`` is accepted and unused); not ``record_to``,
    ``snapshots``, ``vtu`` or ``resume`` (files are written per run: use ``solve``).

    Scenes: bonds only -- ``contacts=False``, with or without breakage and with clamped layers or plane walls
    (``UniaxialCompression()``, ``UniaxialCompression.to_failure(contacts=False)``,
    ``ThreePointBending(contacts=False)``). A scene with contacts (``UniaxialCompression.to_failure()``,
    ``ThreePointBending()``) raises :class:`~jaxbpm.errors.SceneError`: its neighbour list depends on how each
    member's particles move; run those one by one with ``solve``.

    Failure per member: a member that blows up stops being checked and gets the ``"unstable"`` result ``solve``
    would give it (the curve up to the chunk before the blow-up); the others run on. With ``throw`` (default True)
    the first failing member's :class:`~jaxbpm.errors.SolveError` is raised once all have run, carrying that
    member's ``result`` and every member's in ``results``; ``throw=False`` returns them all and each has its
    ``status``. A ``KeyboardInterrupt`` raises :class:`~jaxbpm.errors.SimulationInterrupted` whose ``results`` hold
    every member's result of the chunks completed (``result`` is the first member's).
    """
    from jaxbpm import _interrupt

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
def _run_chunks(model, params, load, state, dt, alpha, origin, n_steps, vectorize=True):
    """:func:`jaxbpm.dem._run_chunk` mapped over the leading axis of ``params`` (precomputed) and ``state``; the
    model, the loading, the time step and the damping are shared. ``vectorize``: ``jax.vmap`` (one vectorised
    program); else ``lax.map`` (the members one after another inside the program, each by the single run's code)."""
    from jaxbpm import dem

    def one(p, s):
        return dem._run_chunk(model, p, load, s, dt, alpha, origin, n_steps)

    if vectorize:
        return jax.vmap(one)(params, state)
    return jax.lax.map(lambda ps: one(*ps), (params, state))


def _solve_batch(sample, scene, method, params_batch, vectorize, options) -> list[Result]:
    from jaxbpm._options import resolve_options
    from jaxbpm.result import settle

    resolved = resolve_options(method, options)
    method, options = resolved.method, resolved.asdict()
    if method != "dem":
        raise SceneError(f"solve_batch runs the DEM only, not {method!r}: solve the {method.upper()} runs one by one "
                         "with jaxbpm.solve (each is one linear solve; there are no time steps to share)")
    if not isinstance(sample, Sample):
        raise TypeError(f"sample must be a jaxbpm.Sample, got {type(sample).__name__}")
    given = [k for k in _PER_RUN if options.get(k) is not None and options.get(k) is not False]
    if given:
        raise SceneError(f"solve_batch does not take {', '.join(given)} (files written per run): run those members "
                         "one by one with jaxbpm.solve")
    if getattr(scene, "contacts", False):
        raise SceneError(
            f"solve_batch runs bonds-only scenes, and this {type(scene).__name__} has contacts=True: its neighbour "
            "list (buffer size, rebuilds) depends on how each member's particles move, so the members cannot share "
            "one program. Run them one by one with jaxbpm.solve, or give the scene contacts=False (e.g. "
            "UniaxialCompression.to_failure(contacts=False), ThreePointBending(contacts=False)) where broken bonds "
            "need no contacts")
    members = _members(params_batch, sample)
    options = {k: v for k, v in options.items() if k not in _PER_RUN}
    throw = options.pop("throw", True)
    t0 = time.perf_counter()
    from jaxbpm._compile import compile_clock

    with compile_clock() as compiling:
        results = _run_batch(t0, compiling, sample, scene, members, bool(vectorize), **options)
    for r in results:
        settle(r, False)
    failed = [r for r in results if r.status in ("unstable", "not_finite")]
    if throw and failed:
        # the error settle raises for the first failing member, carrying every member's result
        try:
            settle(failed[0], True)
        except SolveError as err:
            err.results = results
            raise
    return results


def _run_batch(t0, compiling, sample, scene, members, vectorize, *, dt=None, safety=0.5, damping=0.7, loading_time=None,
               transits=40.0, chunk=None, progress=False, neighbors=None, max_records=2000, pad=True):
    from jaxbpm import _interrupt, dem
    from jaxbpm._compile import size_class
    from jaxbpm.scenes import sample_breaks
    from jaxbpm.solving import _default_chunk, _dem_curve, _dem_modulus, _dem_peak_stats, _transit_time

    n_batch = len(members)
    breaks = sample_breaks(sample, getattr(scene, "breakage", False))
    size = None
    if pad and not getattr(scene, "uses_walls", True):
        size = size_class(sample.n_particles, sample.n_bonds)
    model = scene.model(sample, breakage=breaks, **({} if size is None else {"pad_to": size}))
    dt_crit = [dem.critical_time_step(model, p) for p in members]
    if dt is None:
        if not (0 < safety <= 1):
            raise SceneError(f"safety must lie in (0, 1], got {safety!r}")
        dt = safety * min(dt_crit)
    elif not (dt > 0 and np.isfinite(dt)):
        raise SceneError(f"dt must be a positive time step in seconds, got {dt!r}")
    elif dt > min(dt_crit):
        worst = int(np.argmin(dt_crit))
        warnings.warn(f"time step dt = {dt:.4g} s is above the critical time step estimate {dt_crit[worst]:.4g} s "
                      f"of member {worst} ({dt / dt_crit[worst]:.2f}x): that member may blow up; keep dt <= 0.5 x "
                      "the smallest estimate (the default)", stacklevel=4)
    dt = float(dt)
    length, area = scene.geometry(sample)
    target = scene.strain * length
    if loading_time is None:
        path = scene.transit_length(sample) if hasattr(scene, "transit_length") else length
        loading_time = transits * max(_transit_time(sample, model, p, path) for p in members)
    loading_time = float(loading_time)
    n_steps = int(np.ceil(loading_time / dt))
    if chunk is None:
        chunk = _default_chunk(n_steps)
    n_steps = -(-n_steps // chunk) * chunk
    speed = target / (n_steps * dt)
    n_chunks = n_steps // chunk
    load = scene.loading(sample, speed)
    if size is not None:
        load = dem.pad_loading(load, size.particles)
    if progress is True:
        progress = dem.progress_printer(strain_per_step=speed * dt / length)
    report = dem._progress_fn(progress)

    # the members' initial states and per-run constants, each by the program a single run uses, then stacked
    started = [dem._start(model, p, load, None) for p in members]
    state = _stack([s for s, _ in started])
    pre = _stack([c for _, c in started])
    origin = jax.device_put(np.zeros(3, model.positions0.dtype))
    jax.block_until_ready((state, pre))
    _interrupt.check()
    r_min = float(np.min(np.asarray(model.radii)))
    t_loop, setup_compile = time.perf_counter(), compiling.seconds
    records, kernel = [], []  # host records of each completed chunk ([B, chunk, ...]); each chunk's run time
    failure = [None] * n_batch  # per member: (chunks completed, its state then, the message) once it blew up
    done = state
    interrupted = False
    try:
        while len(records) < n_chunks and any(f is None for f in failure):
            _interrupt.check()
            tc, compiled = time.perf_counter(), compiling.seconds
            new, rec, _, finite, _, _, _ = _run_chunks(model, pre, load, state, dt, damping, origin, chunk,
                                                    vectorize=vectorize)
            jax.block_until_ready(new.positions)
            kernel.append(time.perf_counter() - tc - (compiling.seconds - compiled))
            rec = jax.device_get(rec)
            vmax = np.max(rec["vmax"], axis=1)
            finite = np.asarray(finite)
            k = len(records)
            for b in range(n_batch):
                if failure[b] is None and (not np.isfinite(vmax[b]) or not finite[b] or vmax[b] * dt > 0.25 * r_min):
                    failure[b] = (k, done, (
                        f"DEM run became unstable within steps {k * chunk}..{(k + 1) * chunk} (non-finite or runaway "
                        f"motion, max speed {vmax[b]:.3g} m/s): time step dt = {dt:.4g} s, critical time step "
                        f"estimate = {dt_crit[b]:.4g} s. Use a smaller time step (or a smaller safety factor)."))
            state = done = new
            records.append(rec)
            report(len(records) * chunk, n_chunks * chunk, time.perf_counter() - t0)
    except KeyboardInterrupt:
        _interrupt.clear()
        interrupted = True

    # the members' results; the timings are each member's share of the batch's
    wall = time.perf_counter() - t0
    compile_time = compiling.seconds
    setup = t_loop - t0 - setup_compile
    run = wall - setup - compile_time
    per_chunk = float(np.median(kernel)) if kernel else float("nan")
    host = jax.tree_util.tree_map(np.asarray, done)
    results = []
    for b in range(n_batch):
        completed, member_state, message = len(records), host, None
        if failure[b] is not None:
            completed, failed_state, message = failure[b]
            member_state = jax.tree_util.tree_map(np.asarray, failed_state)
        member_state = jax.tree_util.tree_map(lambda x: jax.device_put(x[b]), member_state)
        if size is not None:
            member_state = dem.unpad_state(member_state, sample.n_particles, sample.n_bonds)
        rec = ({key: np.concatenate([r[key][b] for r in records[:completed]]) for key in records[0]}
               if completed else {})
        status = "unstable" if message is not None else "converged"
        disp, force, stiffness, keep = _dem_curve(scene, rec, speed, target, max_records,
                                                  strict=not interrupted and status == "converged")
        stats = {"setup_time": setup / n_batch, "compile_time": compile_time / n_batch, "run_time": run / n_batch,
                 "wall_time": wall / n_batch, "kernel_time": float(np.sum(kernel)) / n_batch,
                 "steps": completed * chunk, "steps_per_second": chunk / per_chunk, "reallocations": 0,
                 "contact_capacity": 0}
        if message is not None:
            stats.update(unstable=True, steps_planned=n_steps, failure=message)
        elif interrupted:
            stats.update(interrupted=True, steps_planned=n_steps)
        stats.update(dt=dt, dt_crit=float(dt_crit[b]), loading_time=float(n_steps * dt), speed=float(speed),
                     damping=float(damping), rotations=model.rotations, contacts=model.contacts, breakage=breaks,
                     contact_law=model.contact_law, failure_rule=model.failure_rule, interrupted=interrupted,
                     padded_to=None if size is None else (size.particles, size.bonds))
        stats.update(_dem_peak_stats(scene, sample, rec, disp, force, keep, breaks))
        stats["batch"] = {"size": n_batch, "index": b, "vectorize": vectorize, "dt": dt, "loading_time": loading_time, "chunk": chunk,
                          "wall_time": wall, "compile_time": compile_time, "kernel_time": float(np.sum(kernel))}
        results.append(Result(method="dem", stiffness=stiffness,
                              youngs_modulus=_dem_modulus(scene, sample, stiffness, length, area),
                              gauge_length=length, area=area, displacement=disp[keep], force=force[keep],
                              wall_time=wall / n_batch, setup_time=setup / n_batch,
                              compile_time=compile_time / n_batch, run_time=run / n_batch, stats=stats,
                              state=member_state, interrupted=interrupted,
                              status="interrupted" if interrupted else status))
    if interrupted:
        stop = SimulationInterrupted([r.state for r in results], None,
                                     {"steps": len(records) * chunk, "steps_planned": n_steps, "interrupted": True},
                                     result=results[0])
        stop.results = results
        raise stop
    return results
