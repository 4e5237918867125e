"""The DSM's elastic state for the DEM's elastic start (``jaxbpm.DEM(start="elastic")``): the solvers do not import
one another, so the DSM's field reaches the DEM from here (:func:`jaxbpm.solve` passes :func:`dsm_field` to
:func:`jaxbpm.dem.solve_scene`)."""

from __future__ import annotations

import numpy as np

from jaxbpm.dem.elastic_start import first_break_scale, SAFETY
from jaxbpm.dsm.options import DSM
from jaxbpm.dsm.scene import solve_scene
from jaxbpm.physics.model import default_params

__all__ = ["dsm_field"]


def dsm_field(sample, scene, params, safety: float = SAFETY):
    """The DSM's elastic state of ``scene`` for a DEM run that starts there (``DEM(start="elastic")``).

    The linear DSM (bonds only), or with Hertz-Mindlin contacts the DSM with linearised contacts, solved again with
    the contacts linearised at the start's scale (``safety`` x the first-break scale) when the first solve's
    linearisation state differs from it by more than a quarter (the same candidates: nothing compiled again).

    Args:
        sample: the sample.
        scene: the scene (clamped particles, no walls).
        params: the parameters (checked; ``None``: the sample's own).
        safety: the start's fraction of the first-break scale.

    Returns:
        ``(u, s_first, info)``: the displacements and rotation vectors ``[n, 3 or 6]`` at the scene's target
        displacement, the fraction of it at which the first bond reaches its strength
        (:func:`jaxbpm.dem.elastic_start.first_break_scale`) and what the solve was (``dsm``: ``"linear"`` or
        ``"linearised contacts"``, ``dsm_time`` [s], ``dsm_solves``, ``contact_fraction``); or a string, the reason
        the DSM gives no start (a solve that did not converge, no bond that reaches its strength).
    """
    params = default_params(sample) if params is None else params
    options = DSM(throw=False, nonlinear=False) if scene.contacts else DSM(throw=False)
    res = solve_scene(sample, scene, params, options)
    seconds, solves = res.wall_time, 1
    if str(res.status) != "converged":
        return f"the DSM did not converge ({res.status})"
    model = scene.model(sample, contacts=False, breakage=True)
    u = np.asarray(res.state, np.float64)[:sample.n_particles]
    first = first_break_scale(model, params, u)
    if scene.contacts and np.isfinite(first):
        frac = float(np.clip(safety * min(first, 1.0), 1e-3, 1.0))
        if abs(frac / res.stats["contact_fraction"] - 1.0) > 0.25:
            # the same candidates (the first solve's reach): the same program, nothing compiled again
            res = solve_scene(sample, scene, params,
                              options.replace(contact_fraction=frac, contact_skin=res.stats["contact_skin"]))
            seconds, solves = seconds + res.wall_time, 2
            if str(res.status) != "converged":
                return f"the DSM did not converge ({res.status})"
            u = np.asarray(res.state, np.float64)[:sample.n_particles]
            first = first_break_scale(model, params, u)
    if not np.isfinite(first):
        return "no bond reaches its strength under the DSM's load"
    kind = "linearised contacts" if scene.contacts else "linear"
    return u, first, {"dsm": kind, "dsm_time": seconds, "dsm_solves": solves,
                      "contact_fraction": res.stats.get("contact_fraction")}
