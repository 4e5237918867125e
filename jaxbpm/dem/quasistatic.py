"""Whether a DEM run's answer is quasi-static: physics, not a step count.

A stiffness, a modulus or a strength is a static answer; the DEM gets it by loading slowly enough that the sample is
in equilibrium at every record. :func:`measures` tells from the run's own records how far it was from that over the
part of the curve the answer is taken from:

* **balance**: the two loaded ends (the driven and the fixed group, or the two walls) carry opposite forces in
  equilibrium; ``imbalance`` is the RMS of ``|R_a + R_b|`` over the RMS of the load ``|R_a - R_b| / 2``;
* **speed**: in a quasi-static run no particle moves much faster than the loading; ``speed_ratio`` is the largest
  particle speed over the loading speed;
* **linearity**: the fitted curve is a line where it is fitted; ``fit_residual`` is the RMS residual of the
  least-squares line over the RMS force there.

:func:`verdict` compares them with :data:`LIMITS` and, for a run that fails, estimates the ``transits`` (loading time
in elastic-wave transits) that would pass: the imbalance of a run loaded over ``T`` transits falls at least as
``1/T``.
"""

from __future__ import annotations

import numpy as np

from jaxbpm.status import Status

__all__ = ["LIMITS", "measures", "verdict", "check"]

#: the largest values of a quasi-static run: the ends' forces balanced to 25 % of the load (RMS over the fit range; a
#: default run, 40 transits, balances to about 1 %, and where the imbalance is under 25 % the stiffness is within 2 %
#: of the static one), and, where the model is linear (bonds only, no breakage), the fitted curve a line to 2 %. The
#: largest particle speed is reported, not judged (a loose particle may rattle in a quasi-static run)
LIMITS = {"imbalance": 0.25, "fit_residual": 0.02}


def measures(scene, records: dict, displacement: np.ndarray, force: np.ndarray, target: float, speed: float,
             elastic: bool) -> dict:
    """The quasi-static measures of a run over the part of its curve the answer comes from.

    Args:
        scene: the scene (its load axis and fit range).
        records: the run's per-step records (``reaction [steps, W + 2, 3]``, ``vmax [steps]``).
        displacement: ``[steps]`` the displacement of each record [m].
        force: ``[steps]`` the scene's load [N].
        target: the target displacement [m].
        speed: the loading speed [m/s].
        elastic: whether the answer is the elastic fit (the records of the fit range); else the whole loading up
            to the peak load (a strength).

    Returns:
        ``imbalance``, ``speed_ratio``, ``fit_residual`` (NaN where there are fewer than three records) and
        ``quasi_static_records`` (how many records they were taken over).
    """
    nan = {"imbalance": float("nan"), "speed_ratio": float("nan"), "fit_residual": float("nan"),
           "quasi_static_records": 0}
    if not records or len(force) < 3:
        return nan
    if elastic:
        sel = scene.fit_mask(displacement, target)
    else:  # up to the peak: the strength is read there
        peak = int(np.argmax(force))
        sel = (np.arange(len(force)) <= peak) & (displacement >= 0.05 * displacement[peak])
    if sel.sum() < 3:
        return nan
    r = np.asarray(records["reaction"])[sel]
    ax = scene.axis
    a, b = r[:, 0, ax], r[:, 1, ax]
    load = np.sqrt(np.mean((0.5 * (a - b)) ** 2))
    imbalance = float(np.sqrt(np.mean((a + b) ** 2)) / load) if load > 0 else float("inf")
    speed_ratio = float(np.max(np.asarray(records["vmax"])[sel]) / speed) if speed > 0 else float("nan")
    residual = float("nan")
    if elastic:  # (a failure run's curve is no line)
        u, f = displacement[sel], force[sel]
        scale = np.sqrt(np.mean(f ** 2))
        misfit = np.sqrt(np.mean((np.polyval(np.polyfit(u, f, 1), u) - f) ** 2))
        residual = float(misfit / scale) if scale > 0 else float("inf")
    return {"imbalance": imbalance, "speed_ratio": speed_ratio, "fit_residual": residual,
            "quasi_static_records": int(sel.sum())}


def verdict(found: dict, transits: float | None, linear: bool) -> tuple[bool, str]:
    """Whether the measures pass :data:`LIMITS`, and a message naming what failed.

    Args:
        found: :func:`measures`' output.
        transits: the run's loading time in elastic-wave transits (``None``: not known).
        linear: whether the model is linear (bonds only, no breakage): its curve must then be a line.

    Returns:
        ``(passed, message)``; the message is empty when the run passed, else it names each measure over its limit
        and the ``transits`` that would pass.
    """
    limits = {k: v for k, v in LIMITS.items() if linear or k != "fit_residual"}
    over = [k for k, limit in limits.items() if np.isfinite(found.get(k, np.nan)) and found[k] > limit]
    if found.get("quasi_static_records", 0) < 3:
        over.append("quasi_static_records")
    if not over:
        return True, ""
    parts = []
    for k in over:
        if k == "quasi_static_records":
            parts.append(f"only {found.get('quasi_static_records', 0)} records where the answer is read (3 needed)")
        else:
            parts.append(f"{k} {found[k]:.3g} (limit {LIMITS[k]:g})")
    msg = "the DEM run was not quasi-static: " + "; ".join(parts)
    if transits is not None and np.isfinite(found.get("imbalance", np.nan)):
        # the imbalance falls at least as 1 / transits; below about 8 transits no run balances
        need = max(transits * found["imbalance"] / LIMITS["imbalance"], 2 * transits, 8.0)
        msg += f"; load it more slowly: transits={need:.3g} or more (this run: {transits:.3g}; the default is 40)"
    else:
        msg += "; load it more slowly (a larger transits= or loading_time=; the default is 40 transits)"
    return False, msg


def check(scene, the_plan, records: dict, displacement, force, stats: dict, status: Status) -> Status:
    """The quasi-static check of a DEM scene run: its measures into ``stats`` (with ``quasi_static`` and the run's
    ``transits``) and its status.

    Args:
        scene: the scene.
        the_plan: the run's :class:`~jaxbpm.dem.plan.Plan`.
        records: the run's per-step records.
        displacement, force: ``[steps]`` its curve [m], [N].
        stats: the result's statistics (updated).
        status: the run's status so far.

    Returns:
        ``status``, or ``NOT_QUASI_STATIC`` for an elastic run of a bonded sample that ran to its end but fails
        :func:`verdict` (``stats``' ``failure`` says why and which ``transits`` would pass). A failure run (bonds
        break) keeps its status: its ``quasi_static`` says whether its peak was reached quasi-statically
        (``quasi_static_note`` why not); so does a granular sample (no bonds, or the cohesive law).
    """
    found = measures(scene, records, displacement, force, the_plan.target, the_plan.speed,
                     elastic=not the_plan.breakage)
    crossing = the_plan.transit_time
    transits = the_plan.n_steps * the_plan.dt / crossing if crossing > 0 else None
    model = the_plan.model
    passed, why = verdict(found, transits, linear=not the_plan.breakage and not model.contacts and not model.walls)
    stats.update(found, quasi_static=passed, transits=transits)
    if passed or status != Status.CONVERGED:
        return status
    if the_plan.breakage or not model.bonds.shape[0] or model.contact_law == "cohesive":
        # a failure run, or a granular sample (no bonds; the cohesive law): its curve is no elastic answer and its
        # ends may carry next to nothing; the measures and the note are reported, the status kept
        stats["quasi_static_note"] = why
        return status
    stats["failure"] = why
    return Status.NOT_QUASI_STATIC
