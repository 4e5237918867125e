"""The stop after the peak: a DEM run to failure ends once the scene's force has fallen to a fraction of its peak.

The chunk program (:func:`jaxbpm.dem.chunk._run_chunk`) carries a :class:`Tracker` (the running peak of the force
and a stopped flag) and updates it every step from the step's reactions with the scene's :class:`PeakStop`: no host
round trip per step. A stopped run skips the rest of its chunk (the chunk's loop ends there); the host reads the
flag when the chunk returns, as it reads the chunk's other checks, and ends the run.

The stop is armed once a bond has broken and the loading is past the scene's fit range: up to then the force of a
run from rest may swing with the elastic waves of its start, and the stiffness fit needs the whole fit range. So a
stopped run's stiffness, peak and curve up to the stop are those of the full run.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm.scenes import force_weights

__all__ = ["PeakStop", "Tracker", "peak_stop", "tracker", "STOP_REASONS"]

#: why a DEM run ended: the force fell past the peak, the loading reached the full strain, the run blew up, or it was
#: interrupted
STOP_REASONS = ("after_peak", "full_strain", "unstable", "interrupted")


class PeakStop(NamedTuple):
    """What the chunk needs to measure the force and decide the stop (device arrays: another fraction compiles
    nothing new).

    Attributes:
        weights: ``[W+2, 3]`` the force of a step is ``sum(weights * reaction)`` (:func:`jaxbpm.scenes.force_weights`).
        fraction: ``[]`` the run stops once the force is at or below ``fraction`` x the peak; ``-inf``: never.
        arm_time: ``[]`` the stop is armed from this time of the run on [s] (the end of the scene's fit range).
    """

    weights: jax.Array
    fraction: jax.Array
    arm_time: jax.Array


class Tracker(NamedTuple):
    """The running peak of the force [N] and whether the run has stopped (device scalars, carried from chunk to
    chunk; one per member of a batch)."""

    peak: jax.Array
    stopped: jax.Array


def peak_stop(scene, model, load, the_plan) -> PeakStop:
    """The stop of a run of ``scene``.

    Args:
        scene: the scene (its ``stop_after_peak``, ``compressive_force`` and ``fit_range``).
        model: the run's model (whether bonds break).
        load: the run's loading (its walls).
        the_plan: the run's :class:`~jaxbpm.dem.plan.Plan` (the loading's speed and target).

    Returns:
        The :class:`PeakStop`: the fraction ``-inf`` (never) for a scene without ``stop_after_peak`` (or ``None``)
        and for a model whose bonds do not break.

    Raises:
        SceneError: a stop on a scene whose force is not linear in the reactions.
    """
    n_walls = load.wall_points0.shape[0] if model.walls is not None else 0
    dtype = model.positions0.dtype
    fraction = getattr(scene, "stop_after_peak", None)
    if fraction is None or not model.breakage:
        weights, fraction = np.zeros((n_walls + 2, model.dim)), -np.inf
    else:
        weights = force_weights(scene, n_walls + 2, model.dim)
    fit_end = float(getattr(scene, "fit_range", (0.0, 0.0))[1]) * the_plan.target
    arm_time = fit_end / the_plan.speed
    put = lambda a: jax.device_put(np.asarray(a, dtype))  # noqa: E731
    return PeakStop(put(weights), put(fraction), put(arm_time))


def tracker(peak: float = -np.inf, dtype=np.float64) -> Tracker:
    """A tracker at the start of a run.

    Args:
        peak: the peak so far (a resumed run's; ``-inf``: none yet).
        dtype: the force's floating-point type.

    Returns:
        The :class:`Tracker` (not stopped).
    """
    return Tracker(jax.device_put(np.asarray(peak, jax.dtypes.canonicalize_dtype(dtype))),
                   jax.device_put(np.zeros((), bool)))


def _track(t: Tracker, record: dict, stop: PeakStop) -> Tracker:
    """The tracker after a step with ``record`` (traced: inside the chunk's loop)."""
    force = jnp.sum(stop.weights * record["reaction"])
    peak = jnp.maximum(t.peak, force)
    armed = record["time"] >= stop.arm_time
    if "broken" in record:
        armed = armed & (jnp.sum(record["broken"]) > 0)
    fell = armed & (peak > 0) & (force <= stop.fraction * peak)
    return Tracker(peak, t.stopped | fell)
