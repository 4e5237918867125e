"""What a DEM scene run's records give: the loading curve, the stiffness fitted on it, the peak and the broken bonds,
the modulus, and the run's statistics that every DEM result carries."""

from __future__ import annotations

import numpy as np

from jaxbpm.errors import SceneError

__all__ = ["curve", "fit_line", "peak_stats", "modulus", "plan_stats"]


def curve(scene, records: dict, speed: float, target: float, max_records: int, strict: bool = True):
    """The loading curve of a run and its stiffness.

    Args:
        scene: the scene (its force and stiffness fit).
        records: the run's per-step records (empty: no chunk completed).
        speed: the loading speed [m/s].
        target: the displacement at the end of the loading [m].
        max_records: the most points kept in the returned curve.
        strict: a curve too short for the fit raises; else its stiffness is NaN (a run stopped early).

    Returns:
        ``(displacement, force, stiffness, keep)``: every record's displacement [m] and force [N], the stiffness
        fitted over the scene's fit range [N/m] and the indices of the records kept in the returned curve.

    Raises:
        SceneError: the curve is too short for the fit and ``strict``.
    """
    disp = speed * records["time"] if records else np.zeros(0)
    force = scene.compressive_force(records["reaction"]) if records else np.zeros(0)
    try:
        stiffness = scene.fit_stiffness(disp, force, target)
    except SceneError:
        if strict:
            raise
        stiffness = float("nan")
    keep = np.unique(np.linspace(0, len(disp) - 1, min(max_records, len(disp))).astype(int))
    return disp, force, stiffness, keep


def fit_line(scene, disp, force, target: float, gauge_length: float, area: float) -> dict:
    """The least-squares line that gives the stiffness (over the scene's fit range), as strain and stress at its ends.

    Args:
        scene: the scene (its fit range).
        disp: ``[steps]`` displacements [m].
        force: ``[steps]`` forces [N].
        target: the displacement at the end of the loading [m].
        gauge_length: the strain's length [m].
        area: the stress's section [m^2].

    Returns:
        ``fit_strain`` and ``fit_stress`` [Pa]: ``(first, last)`` of the records in the fit range, on the line
        (its slope in stress over strain is the modulus ``K l / A``); empty with fewer than two records there.
    """
    disp, force = np.asarray(disp, np.float64), np.asarray(force, np.float64)
    sel = scene.fit_mask(disp, target) if len(disp) else np.zeros(0, bool)
    if sel.sum() < 2:
        return {}
    slope, intercept = np.polyfit(disp[sel], force[sel], 1)
    ends = np.array([disp[sel].min(), disp[sel].max()])
    stress = (slope * ends + intercept) / area
    return {"fit_strain": (float(ends[0] / gauge_length), float(ends[1] / gauge_length)),
            "fit_stress": (float(stress[0]), float(stress[1]))}


def peak_stats(scene, sample, records: dict, disp, force, keep, breakage: bool) -> dict:
    """The peak of the curve and the broken bonds.

    Args:
        scene: the scene (its strength, where it has one).
        sample: the sample.
        records: the run's per-step records.
        disp: ``[steps]`` displacements [m].
        force: ``[steps]`` forces [N].
        keep: the indices of the records kept in the returned curve.
        breakage: whether bonds break.

    Returns:
        ``peak_force``, ``displacement_at_peak``, ``strain_at_peak`` (over the scene's displacement scale
        ``geometry(sample)[0]``) and the scene's ``strength``; with breakage the broken-bond counts
        (``broken_tensile``, ``broken_shear`` at the end, ``broken_curve`` along the kept curve, ``broken_at_peak``)
        and whether the run went past the peak (``past_peak``). Empty without records.
    """
    stats = {}
    if len(force):
        peak = int(np.argmax(force))
        stats.update(peak_force=float(force[peak]), displacement_at_peak=float(disp[peak]),
                     strain_at_peak=float(disp[peak]) / float(scene.geometry(sample)[0]))
        stats["strength"] = float(scene.strength(float(force[peak]), sample))
        if breakage:
            counts = records["broken"]  # [steps, 2]: tensile, shear (cumulative)
            stats.update(broken_tensile=int(counts[-1, 0]), broken_shear=int(counts[-1, 1]),
                         broken_curve=counts[keep], broken_at_peak=int(counts[peak].sum()))
            # the curve points are the loading's; a peak at the last record means the run stopped too early
            stats["past_peak"] = bool(peak < len(force) - 1 and force[-1] < force[peak])
    return stats


def plan_stats(plan, dt_crit: float, interrupted: bool) -> dict:
    """The statistics of a DEM result that its plan gives.

    Args:
        plan: the run's :class:`~jaxbpm.dem.plan.Plan`.
        dt_crit: the run's critical time step [s] (a batch member's own).
        interrupted: whether the run was interrupted.

    Returns:
        ``dt``, ``dt_crit``, ``loading_time`` (of the steps planned), ``speed``, ``damping``, what the model holds
        (``rotations``, ``contacts``, ``breakage``, ``contact_law``, ``failure_rule``), ``interrupted`` and
        ``padded_to`` (the size class, or ``None``).
    """
    model, size = plan.model, plan.size
    return dict(dt=float(plan.dt), dt_crit=float(dt_crit), loading_time=float(plan.n_steps * plan.dt),
                speed=float(plan.speed), damping=float(plan.damping), rotations=model.rotations,
                contacts=model.contacts, breakage=plan.breakage, contact_law=model.contact_law,
                failure_rule=model.failure_rule, interrupted=interrupted,
                padded_to=None if size is None else (size.particles, size.bonds))
