"""``jaxbpm.solve(sample, scene, method=...)``: one entry point for every solver."""

from __future__ import annotations

import pathlib
import time
import warnings

import numpy as np

from jaxbpm import dsm, ste
from jaxbpm._options import METHODS, resolve_options, SolverOptions
from jaxbpm.auto import solve_auto
from jaxbpm.errors import InstabilityError, SceneError
from jaxbpm.physics.model import check_params
from jaxbpm.result import Result
from jaxbpm.sample import Sample

__all__ = ["solve", "METHODS"]


def solve(sample: Sample, scene, method="dem", *, params=None, **options) -> Result:
    """Solve ``scene`` on ``sample`` with a solver and return a :class:`~jaxbpm.result.Result`.

    The solver and its options: a name with keyword options (``method="dsm", tol=1e-6``) or an options object,
    :class:`jaxbpm.DEM`, :class:`jaxbpm.DSM` or :class:`jaxbpm.STE` (where each option is documented), whose values
    keyword options override (``solve(sample, scene, jaxbpm.DSM(dofs=3), tol=1e-6)``). ``method="auto"`` (options
    ``tol``, the relative stiffness error allowed against the DEM, default 0.01; ``throw``; ``progress``) runs the
    cheapest solver expected to meet ``tol`` on this scene (:mod:`jaxbpm.auto`) and says which and why in
    ``stats["method_choice"]``.

    Failure is data: ``Result.status`` is a :class:`~jaxbpm.status.Status`, the same for every solver. ``throw``
    (every solver, default True) raises the status's error (a :class:`~jaxbpm.errors.SolveError` carrying the result
    in its ``result``); ``throw=False`` returns the result and the caller reads its status (``stats["failure"]``
    says what went wrong). An interruption always raises :class:`~jaxbpm.errors.SimulationInterrupted`.

    Args:
      sample: the bonded sample.
      scene: the scene (boundary conditions and loading), e.g. :class:`~jaxbpm.scenes.UniaxialCompression`.
      method: ``"dem"``, ``"dsm"``, ``"ste"``, ``"auto"`` or an options object.
      params: ``{"bond_E": [...], "bond_nu": [...], ...}`` overriding the sample's material table (for
        calibration; see :func:`jaxbpm.physics.model.check_params`).
      **options: the solver's options (the fields of its options class).

    Returns:
      The :class:`~jaxbpm.result.Result`.

    Raises:
      OptionsError: an unknown solver or option (with the closest names) or an option out of its range.
      SceneError: a scene the solver does not model, or parameters that do not fit the sample.
      SolveError: with ``throw=True``, a solve that did not converge.
    """
    from jaxbpm import _interrupt

    with _interrupt.guard():  # a Ctrl-C swallowed on the way (in a garbage-collection callback) still stops it
        result = _solve(sample, scene, method, params, options)
        _interrupt.check()
    return result


def _solve(sample, scene, method, params, options) -> Result:
    """:func:`solve` without the interrupt guard: checks the options, the sample, the scene and the parameters, once,
    then runs the solver."""
    if isinstance(method, str) and method == "auto":  # the cheapest solver expected to meet tol: jaxbpm.auto
        return solve_auto(sample, scene, params, options, solve=_dispatch)
    method = resolve_options(method, options)
    if not isinstance(sample, Sample):
        raise TypeError(f"sample must be a jaxbpm.Sample, got {type(sample).__name__}")
    _check_supported(scene, method.method)
    if params is not None:  # one validation path for every solver, once per solve
        params = check_params(params, sample)
    return _dispatch(sample, scene, params, method)


def _check_supported(scene, name: str) -> None:
    """Raise :class:`SceneError` where the solver ``name`` does not model ``scene``."""
    allowed = getattr(scene, "methods", None)
    if allowed is not None and name not in allowed:
        raise SceneError(f"{type(scene).__name__} needs method={allowed[0]!r}"
                         f"{'' if len(allowed) == 1 else f' (or one of {allowed[1:]})'}: the {name.upper()} does "
                         "not model it")
    if name != "dem" and getattr(scene, "contacts", False) and getattr(scene, "cohesive_law", None) is not None:
        raise SceneError(f"the cohesive contact law depends on the loading history: it needs method='dem', not "
                         f"{name!r}")


def _dispatch(sample, scene, params, options: SolverOptions) -> Result:
    """Run the solver of ``options`` on ``scene`` (one it models) with checked ``params`` (``None``: the sample's
    own)."""
    if options.method == "dsm":
        return dsm.solve_scene(sample, scene, params, options)
    if options.method == "ste":
        return ste.solve_scene(sample, scene, params, options)
    return _solve_dem(sample, scene, params, **options.asdict())


def _solve_dem(sample, scene, params, *, dt=None, safety=0.5, damping=0.7, loading_time=None, transits=40.0,
               chunk=None, progress=False, neighbors=None, max_records=2000, record_to=None, snapshots=None,
               vtu=None, pad=True, throw=True, overwrite=False, resume=None) -> Result:
    t0 = time.perf_counter()
    from jaxbpm._compile import compile_clock
    from jaxbpm.result import settle

    try:
        with compile_clock() as compiling:  # (the setup's compilations count as compile time)
            result = _run_dem(t0, compiling, sample, scene, params, dt=dt, safety=safety, damping=damping,
                              loading_time=loading_time, transits=transits, chunk=chunk, progress=progress,
                              neighbors=neighbors, max_records=max_records, record_to=record_to,
                              snapshots=snapshots, vtu=vtu, pad=pad, overwrite=overwrite, resume=resume)
    except InstabilityError as err:
        if throw or err.result is None:
            raise
        return err.result
    return settle(result, throw)


def _run_dem(t0, compiling, sample, scene, params, *, dt, safety, damping, loading_time, transits, chunk, progress,
             neighbors, max_records, record_to, snapshots, vtu, pad, overwrite, resume) -> Result:
    from jaxbpm import dem
    from jaxbpm._compile import size_class
    from jaxbpm.errors import SimulationInterrupted
    from jaxbpm.physics.model import default_params

    from jaxbpm.scenes import lateral_stats, sample_breaks

    breaks = sample_breaks(sample, getattr(scene, "breakage", False))
    # bonds only (no contacts, no walls): the model is padded to the sample's size class, so that the next sample of
    # that class reuses the compiled programs (the extra particles and bonds never act: see build_model's pad_to)
    size = None
    if pad and not getattr(scene, "contacts", True) and not getattr(scene, "uses_walls", True):
        size = size_class(sample.n_particles, sample.n_bonds)
    model = scene.model(sample, breakage=breaks, **({} if size is None else {"pad_to": size}))
    params = default_params(sample) if params is None else params
    if (snapshots is None) != (vtu is None):
        raise SceneError("snapshots=K and vtu='dir/run.pvd' go together: give both or neither")
    if snapshots is not None and not (isinstance(snapshots, (int, np.integer)) and snapshots >= 1):
        raise SceneError(f"snapshots must be a whole number >= 1 of VTU frames, got {snapshots!r}")
    dt_crit = dem.critical_time_step(model, params)
    if dt is None:
        if not (0 < safety <= 1):
            raise SceneError(f"safety must lie in (0, 1], got {safety!r}")
        dt = safety * dt_crit
    elif not (dt > 0 and np.isfinite(dt)):
        raise SceneError(f"dt must be a positive time step in seconds, got {dt!r}")
    elif dt > dt_crit:
        # bonds alone blow up soon after (InstabilityError); with Hertz contacts, whose stiffness grows with the
        # overlap, runs up to ~1.75x the estimate can finish and be 6-13 % too soft without any error
        warnings.warn(f"time step dt = {dt:.4g} s is above the critical time step estimate {dt_crit:.4g} s "
                      f"({dt / dt_crit:.2f}x): the run may blow up or, with contacts, finish with a wrong stiffness; "
                      "keep dt <= 0.5 x the estimate (the default)", stacklevel=3)
    length, area = scene.geometry(sample)
    target = scene.strain * length
    if loading_time is None:
        # a wave crossing the sample along its longest loaded path (the gauge length; a beam's span)
        path = scene.transit_length(sample) if hasattr(scene, "transit_length") else length
        loading_time = transits * _transit_time(sample, model, params, path)
    n_steps = int(np.ceil(loading_time / dt))
    if chunk is None:
        chunk = _default_chunk(n_steps, snapshots)
    n_steps = -(-n_steps // chunk) * chunk
    # the speed from the steps actually run (whole chunks): the run ends exactly at the target
    speed = target / (n_steps * dt)
    n_chunks = n_steps // chunk
    load = scene.loading(sample, speed)
    if size is not None:
        load = dem.pad_loading(load, size.particles)
    if progress is True:
        progress = dem.progress_printer(strain_per_step=speed * dt / length)
    run_attrs = dict(method="dem", scene=type(scene).__name__, dt=float(dt), dt_crit=float(dt_crit),
                     speed=float(speed), gauge_length=length, area=area, target_displacement=target,
                     damping=float(damping), chunk=chunk, contact_law=model.contact_law, breakage=breaks,
                     failure_rule=model.failure_rule)

    writers = []
    recorder, prior, saved = None, {}, None
    if resume is not None:
        if record_to is not None and pathlib.Path(record_to) != pathlib.Path(resume):
            raise SceneError(f"resume={str(resume)!r} appends to its own record file: leave record_to out")
        if snapshots is not None:
            raise SceneError("resume does not continue a VTU series: leave snapshots and vtu out")
        record_to = resume
    if record_to is not None:
        from jaxbpm.records import RecordFile

        run_attrs.update(particles=sample.n_particles, bonds=sample.n_bonds, sample_digest=_digest(sample),
                         padded_particles=-1 if size is None else size.particles,
                         padded_bonds=-1 if size is None else size.bonds)
        if resume is None:
            recorder = RecordFile(record_to, run_attrs, steps_planned=n_steps, overwrite=overwrite)
        else:
            recorder, prior, saved = RecordFile.resume(resume, {**run_attrs, "steps_planned": n_steps})

        def write_records(done, state, rec):
            rows = {"time": rec["time"], "displacement": speed * rec["time"],
                    "force": scene.compressive_force(rec["reaction"]), "reaction": rec["reaction"],
                    "vmax": rec["vmax"]}
            if "broken" in rec:
                rows["broken"] = rec["broken"]
            recorder.append(rows)

        writers.append(write_records)
    if snapshots is not None:
        series, frames = _snapshot_writer(sample, model, vtu, snapshots, n_chunks, chunk)
        if snapshots > 1:  # the first frame: the sample at rest
            _write_frame(series, model, None, sample, 0.0)
        writers.append(lambda done, state, rec: _write_frame(series, model, state, sample, float(state.time))
                       if done // chunk in frames else None)

    def on_chunk(done, state, rec):
        for w in writers:
            w(done, state, rec)

    def unpadded(state):
        return state if size is None else dem.unpad_state(state, sample.n_particles, sample.n_bonds)

    def finish(state, rec, stats, interrupted, status="converged"):
        if prior:  # a resumed run: the rows of the earlier part first
            rec = {k: np.concatenate([prior[k], rec[k]]) for k in rec} if rec else {k: prior[k] for k in
                                                                                   ("time", "reaction", "vmax",
                                                                                    "broken") if k in prior}
            stats.update(steps=recorder.steps, resumed_at=len(prior["time"]))
        disp, force, stiffness, keep = _dem_curve(scene, rec, speed, target, max_records,
                                                  strict=not interrupted and status == "converged")
        stats.update(dt=float(dt), dt_crit=float(dt_crit), loading_time=float(n_steps * dt), speed=float(speed),
                     damping=float(damping), rotations=model.rotations, contacts=model.contacts, breakage=breaks,
                     contact_law=model.contact_law, failure_rule=model.failure_rule, interrupted=interrupted,
                     padded_to=None if size is None else (size.particles, size.bonds))
        # wall = setup (before the first chunk, less the compilations in it) + compile + run (the rest)
        setup = t_sim - t0 - setup_compile + stats["setup_time"]
        compile_time = compiling.seconds
        stats.update(setup_time=setup, compile_time=compile_time)
        if record_to is not None:
            stats["record_file"] = str(record_to)
        if snapshots is not None:
            stats["vtu"] = str(series.path)
            stats["vtu_frames"] = len(series.steps)
        stats.update(_dem_peak_stats(scene, sample, rec, disp, force, keep, breaks))
        intact = not breaks or stats.get("broken_tensile", 0) + stats.get("broken_shear", 0) == 0
        if intact and not interrupted and status == "converged" and state is not None:
            # the lateral strain of the loaded state (no bond broke: a broken sample's would mean nothing)
            stats.update(lateral_stats(scene, sample, np.asarray(state.positions)[:sample.n_particles]
                                       - np.asarray(sample.positions)))
        modulus = _dem_modulus(scene, sample, stiffness, length, area)
        if recorder is not None:
            wall = time.perf_counter() - t0
            stats.update(wall_time=wall, run_time=wall - setup - compile_time)
            recorder.finish("interrupted" if interrupted else ("complete" if status == "converged" else status),
                            {k: v for k, v in stats.items() if k not in ("broken_curve", "padded_to")})
        wall = time.perf_counter() - t0
        stats.update(wall_time=wall, run_time=wall - setup - compile_time)
        return Result(method="dem", stiffness=stiffness, youngs_modulus=modulus, gauge_length=length,
                      area=area, displacement=disp[keep], force=force[keep], wall_time=wall,
                      setup_time=setup, compile_time=compile_time, run_time=wall - setup - compile_time,
                      stats=stats, state=state, interrupted=interrupted,
                      status="interrupted" if interrupted else status)

    t_sim, setup_compile = time.perf_counter(), compiling.seconds
    start = None if saved is None else _restore_state(saved)
    done_before = 0 if recorder is None else recorder.steps
    try:
        state, rec, stats = dem.simulate(model, params, load, dt=float(dt), n_steps=n_steps - done_before,
                                         alpha=damping, chunk=chunk, neighbors=neighbors, progress=progress,
                                         dt_crit=dt_crit, on_chunk=on_chunk if writers else None, state=start)
    except SimulationInterrupted as stop:
        if recorder is not None and recorder.steps > done_before:  # what resume= continues from
            recorder.checkpoint(_state_arrays(stop.state))
        stop.state = unpadded(stop.state)
        stop.result = finish(stop.state, stop.records, stop.stats, True)
        raise
    except InstabilityError as err:
        if getattr(err, "stats", None) is not None:  # a Result of what was run before the blow-up
            err.stats["failure"] = str(err)
            err.result = finish(unpadded(err.state), err.records, err.stats, False, status="unstable")
        raise
    except KeyboardInterrupt:  # before the first chunk: the record says so (a resumed one keeps its saved state)
        if recorder is not None:
            recorder.finish("interrupted")
        raise
    return finish(unpadded(state), rec, stats, False)


def _default_chunk(n_steps: int, snapshots=None) -> int:
    """The default DEM chunk: a power of two (32 to 4096 steps, about 20 chunks a run), so that samples with about
    the same number of steps share the compiled chunk; with ``snapshots`` at least one chunk per frame after the
    first."""
    chunk = 1 << int(np.log2(np.clip(n_steps // 20, 32, 4096)))
    if snapshots is not None and snapshots > 1:
        chunk = max(1, min(chunk, n_steps // (snapshots - 1)))
    return chunk


def _dem_curve(scene, rec, speed, target, max_records, strict=True):
    """The displacement and force of every record, the stiffness fitted over the scene's fit range and the indices
    of the (at most ``max_records``) records kept in the returned curve. A curve too short for the fit raises
    :class:`SceneError` when ``strict``, else gives a NaN stiffness (a run stopped before the fit range was
    loaded)."""
    disp = speed * rec["time"] if rec else np.zeros(0)
    force = scene.compressive_force(rec["reaction"]) if rec else np.zeros(0)
    try:
        stiffness = scene.fit_stiffness(disp, force, target)
    except SceneError:
        if strict:
            raise
        stiffness = float("nan")
    keep = np.unique(np.linspace(0, len(disp) - 1, min(max_records, len(disp))).astype(int))
    return disp, force, stiffness, keep


def _dem_peak_stats(scene, sample, rec, disp, force, keep, breaks) -> dict:
    """The peak force, the displacement there and the scene's strength; with breakage the broken-bond counts (at
    the end, along the kept curve, at the peak) and whether the run went past the peak. Empty without records."""
    stats = {}
    if len(force):
        peak = int(np.argmax(force))
        stats.update(peak_force=float(force[peak]), displacement_at_peak=float(disp[peak]))
        if hasattr(scene, "strength"):
            stats["strength"] = float(scene.strength(float(force[peak]), sample))
        if breaks:
            counts = rec["broken"]  # [steps, 2]: tensile, shear (cumulative)
            stats.update(broken_tensile=int(counts[-1, 0]), broken_shear=int(counts[-1, 1]),
                         broken_curve=counts[keep], broken_at_peak=int(counts[peak].sum()))
            # the curve points are the loading's; peaks inside the first or last record mean the run stopped
            # too early
            stats["past_peak"] = bool(peak < len(force) - 1 and force[-1] < force[peak])
    return stats


def _dem_modulus(scene, sample, stiffness, length, area) -> float:
    """The scene's modulus of a stiffness (E = K l / A for a scene without its own rule)."""
    return scene.modulus(stiffness, sample) if hasattr(scene, "modulus") else stiffness * length / area


def _state_fields() -> list[str]:
    """The array fields of a DEM state (all but the neighbour list, which a resumed run rebuilds)."""
    import dataclasses

    from jaxbpm.dem import DEMState

    return [f.name for f in dataclasses.fields(DEMState) if f.name != "nbrs"]


def _state_arrays(state) -> dict:
    """The arrays of a DEM state (and its neighbour list's pairs), as a record file's checkpoint holds them."""
    out = {k: np.asarray(getattr(state, k)) for k in _state_fields() if getattr(state, k) is not None}
    if state.nbrs is not None:
        out["nbrs_idx"] = np.asarray(state.nbrs.idx)
    return out


def _restore_state(arrays):
    """The DEM state of a checkpoint (:func:`_state_arrays`); its neighbour list is rebuilt by the run, which
    carries the contact history over from the saved pairs."""
    import types

    from jaxbpm._compile import put
    from jaxbpm.dem import DEMState

    fields = {k: put(arrays[k]) if k in arrays else None for k in _state_fields()}
    nbrs = types.SimpleNamespace(idx=put(arrays["nbrs_idx"])) if "nbrs_idx" in arrays else None
    return DEMState(nbrs=nbrs, **fields)


def _digest(sample) -> str:
    """A short fingerprint of the sample's geometry (a resumed run must be of the same sample)."""
    import hashlib

    h = hashlib.sha1()
    for a in (sample.positions, sample.radii, sample.bonds, sample.bond_radius):
        h.update(np.ascontiguousarray(np.asarray(a)).tobytes())
    return h.hexdigest()[:16]


def _snapshot_writer(sample, model, vtu, snapshots, n_chunks, chunk):
    """The VTU series and the chunk numbers after which a frame is written: ``snapshots`` frames evenly spaced in
    time, the first the sample at rest and the last the end of the run (one frame: the end only)."""
    from jaxbpm.interop.formats import VTUSeries

    if snapshots - 1 > n_chunks:
        raise SceneError(f"snapshots={snapshots} needs at least {snapshots - 1} chunks, the run has {n_chunks} of "
                         f"{chunk} steps; give a smaller chunk")
    series = VTUSeries(vtu, sample)
    if snapshots == 1:
        return series, {n_chunks}
    return series, set(np.round(np.linspace(0, n_chunks, snapshots)).astype(int)[1:].tolist())


def _write_frame(series, model, state, sample, t):
    """One VTU frame: positions, velocity and force per particle, broken bonds per particle by mode, and per bond
    ``intact``, ``break_mode`` (0 intact, 1 tensile, 2 shear) and ``broken_time`` (NaN while intact)."""
    n, nb = sample.n_particles, sample.n_bonds
    if state is None:  # at rest
        pos, vel, frc = np.asarray(sample.positions), np.zeros((n, 3)), np.zeros((n, 3))
        mode, when = np.zeros(nb, np.int32), np.full(nb, np.nan)
    else:  # (the state of a padded run holds the sample's particles and bonds first)
        pos, vel, frc = (np.asarray(a, np.float64)[:n] for a in (state.positions, state.velocities, state.force))
        mode = np.asarray(state.broken, np.int32)[:nb]
        when = np.asarray(state.broken_time, np.float64)[:nb]
    b = np.asarray(sample.bonds)
    point = {"velocity": vel, "force": frc,
             "broken_tensile": np.bincount(b[mode == 1].ravel(), minlength=n).astype(np.int32),
             "broken_shear": np.bincount(b[mode == 2].ravel(), minlength=n).astype(np.int32)}
    series.write(t, positions=pos, intact=mode == 0, point_data=point,
                 bond_data={"break_mode": mode, "broken_time": when})


def _transit_time(sample, model, params, length) -> float:
    """Time for an elastic wave to cross ``length``, from the sample's mean bond (or contact) stiffness and particle
    mass (NumPy on the host: the model may be padded)."""
    from jaxbpm.physics.bond import stiffness as bond_stiffness

    m = float(np.mean(sample.mass))
    if sample.n_bonds:
        mat = np.asarray(sample.bond_material)
        E, nu = (np.asarray(params[key], np.float64)[mat] for key in ("bond_E", "bond_nu"))
        k = bond_stiffness(E, nu, sample.bond_area, sample.bond_I, sample.bond_J, sample.bond_length)
        kn, spacing = float(np.mean(k.kn)), float(np.mean(sample.bond_length))
    else:
        r = float(np.mean(sample.radii))
        if model.contact_law == "cohesive":
            from jaxbpm.physics.cohesive import normal_stiffness

            kn = float(normal_stiffness(r, r, 0.01 * r, float(model.cohesive.E)))
        else:
            kn = 2.0 * float(model.contact.E_star) * np.sqrt(0.5 * r * 0.01 * r)
        spacing = 2.0 * r
    return length / spacing * np.sqrt(m / kn)
