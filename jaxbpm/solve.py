"""``jaxbpm.solve(sample, scene, method=...)``: one entry point for every solver."""

from __future__ import annotations

import time

import numpy as np

from jaxbpm.errors import SceneError
from jaxbpm.result import Result
from jaxbpm.sample import Sample

__all__ = ["solve", "METHODS"]

METHODS = ("dem", "dsm", "ste")


def solve(sample: Sample, scene, method: str = "dem", *, params=None, **options) -> Result:
    """Solve ``scene`` on ``sample`` with ``method`` and return a :class:`~jaxbpm.result.Result`.

    params: ``{"bond_E": [...], "bond_nu": [...]}`` overriding the sample's material table (for calibration).
    options for ``"dem"``: ``dt`` (time step [s], default ``safety`` x critical), ``safety`` (0.5), ``damping`` (local
    damping coefficient alpha, 0.7), ``loading_time`` [s] (default ``transits`` x the time a wave needs to cross the
    sample along the axis, estimated from the mean bond; ``transits`` = 40), ``chunk`` (steps per jitted chunk),
    ``progress`` (print progress), ``neighbors`` (:class:`~jaxbpm.dem.NeighborSettings`), ``max_records`` (points
    kept in the returned curve, 2000).
    options for ``"dsm"``: ``dofs`` (3 or 6 per particle; default: the Model's choice, 6 with bonds), ``nonlinear``
    (default: True when the scene has contacts or walls), ``tol`` (nonlinear relative residual, 1e-3),
    ``linear_tol`` (CG relative residual, 1e-6), ``maxiter``, ``newton_maxiter`` (30), ``stiffness_tol`` (stop
    Newton when the reaction changes less than this, relative), ``contact_skin`` [m], ``load_steps`` (nonlinear:
    equal load increments, 4; K is their least-squares slope over the scene's fit range, as for the DEM), ``throw``
    (raise :class:`ConvergenceError` instead of warning when a solve misses its tolerance).
    options for ``"ste"`` (stiffness tensor estimation, no displacement computed): ``dofs`` (3, the paper's
    translations-only form, or 6), ``first_neighbour`` (Eq. 33-35 instead of Eq. 32), ``layered`` (layered
    springs in series along the load, for porous or shaped bodies), ``layer_thickness`` [m], ``contact_fraction``
    (contacts: fraction of the target strain at which Hertz contacts are linearised), ``volumes`` (``[n]`` particle
    volumes V^n). The stats hold the Voigt tensor, E_x, E_y, E_z, nu, an isotropic fit and the skipped particles.
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {METHODS}")
    if not isinstance(sample, Sample):
        raise TypeError(f"sample must be a jaxbpm.Sample, got {type(sample).__name__}")
    if method == "dsm":
        from jaxbpm import dsm

        return dsm.solve_scene(sample, scene, params, **options)
    if method == "ste":
        from jaxbpm import ste

        return ste.solve_scene(sample, scene, params, **options)
    return _solve_dem(sample, scene, params, **options)


def _solve_dem(sample, scene, params, *, dt=None, safety=0.5, damping=0.7, loading_time=None, transits=40.0,
               chunk=None, progress=False, neighbors=None, max_records=2000) -> Result:
    from jaxbpm import dem
    from jaxbpm.physics.model import default_params

    from jaxbpm.scenes import sample_breaks

    t0 = time.perf_counter()
    breaks = sample_breaks(sample, getattr(scene, "breakage", False))
    model = scene.model(sample, breakage=breaks)
    params = default_params(sample) if params is None else params
    dt_crit = dem.critical_time_step(model, params)
    if dt is None:
        if not (0 < safety <= 1):
            raise SceneError(f"safety must lie in (0, 1], got {safety!r}")
        dt = safety * dt_crit
    elif not (dt > 0 and np.isfinite(dt)):
        raise SceneError(f"dt must be a positive time step in seconds, got {dt!r}")
    length, area = scene.geometry(sample)
    target = scene.strain * length
    if loading_time is None:
        # a wave crossing the sample along its longest loaded path (the gauge length; a beam's span)
        path = scene.transit_length(sample) if hasattr(scene, "transit_length") else length
        loading_time = transits * _transit_time(model, params, path)
    n_steps = int(np.ceil(loading_time / dt))
    speed = target / (n_steps * dt)
    chunk = chunk or int(np.clip(n_steps // 20, 50, 5000))
    n_steps = -(-n_steps // chunk) * chunk
    load = scene.loading(sample, speed)
    if progress is True:
        progress = dem.progress_printer(strain_per_step=speed * dt / length)
    state, rec, stats = dem.simulate(model, params, load, dt=float(dt), n_steps=n_steps, alpha=damping, chunk=chunk,
                                     neighbors=neighbors, progress=progress, dt_crit=dt_crit)
    disp = speed * rec["time"]
    force = scene.compressive_force(rec["reaction"])
    stiffness = scene.fit_stiffness(disp, force, target)
    keep = np.unique(np.linspace(0, len(disp) - 1, min(max_records, len(disp))).astype(int))
    stats.update(dt=float(dt), dt_crit=float(dt_crit), loading_time=float(n_steps * dt), speed=float(speed),
                 damping=float(damping), rotations=model.rotations, contacts=model.contacts, breakage=breaks)
    peak = int(np.argmax(force))
    stats.update(peak_force=float(force[peak]), displacement_at_peak=float(disp[peak]))
    if hasattr(scene, "strength"):
        stats["strength"] = float(scene.strength(float(force[peak]), sample))
    if breaks:
        counts = rec["broken"]  # [steps, 2]: tensile, shear (cumulative)
        stats.update(broken_tensile=int(counts[-1, 0]), broken_shear=int(counts[-1, 1]),
                     broken_curve=counts[keep], broken_at_peak=int(counts[peak].sum()))
        # the curve points are the loading's; peaks inside the first or last record mean the run stopped too early
        stats["past_peak"] = bool(peak < len(force) - 1 and force[-1] < force[peak])
    modulus = scene.modulus(stiffness, sample) if hasattr(scene, "modulus") else stiffness * length / area
    return Result(method="dem", stiffness=stiffness, youngs_modulus=modulus, gauge_length=length,
                  area=area, displacement=disp[keep], force=force[keep], wall_time=time.perf_counter() - t0,
                  compile_time=stats["compile_time"], run_time=stats["run_time"], stats=stats, state=state)


def _transit_time(model, params, length) -> float:
    """Time for an elastic wave to cross ``length``, from the mean bond (or contact) stiffness and particle mass."""
    m = float(np.mean(model.mass))
    if model.bonds.shape[0]:
        k = model.stiffness(params)
        kn, spacing = float(np.mean(k.kn)), float(np.mean(model.bond_length))
    else:
        r = float(np.mean(model.radii))
        kn, spacing = 2.0 * float(model.contact.E_star) * np.sqrt(0.5 * r * 0.01 * r), 2.0 * r
    return length / spacing * np.sqrt(m / kn)
