"""The local stiffness map (Jarolin & Dosta 2020, 4.4): per particle, moduli averaged over a neighbourhood. Its writers
are in :mod:`jaxbpm.io`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from jaxbpm.errors import SceneError
from jaxbpm.physics.model import check_params, default_params
from jaxbpm.sample import Sample
from jaxbpm.ste.estimator import estimator
from jaxbpm.ste.tensor import _local_tensors_jit

__all__ = ["LocalMap", "local_map"]


class LocalMap(NamedTuple):
    """The local stiffness map (Jarolin & Dosta 2020, 4.4): per particle, moduli averaged over a neighbourhood.

    positions ``[n, 3]`` [m]; E ``[n, 3]``: Young's moduli along x, y, z of the V-weighted mean tensor of the
    non-singular particles within ``radius`` of each particle [Pa] (NaN where there is none); deviation ``[n, 3]``:
    Eq. 36, ``(mean(E) - E) / mean(E)`` per direction; valid ``[n]``: particle not singular; radius [m].
    """

    positions: np.ndarray
    E: np.ndarray
    deviation: np.ndarray
    valid: np.ndarray
    radius: float


def local_map(sample: Sample, params=None, *, scene=None, radius: float | None = None, **options) -> LocalMap:
    """Local moduli averaged over spheres and their deviation from the mean (Eq. 36).

    Args:
      sample: the bonded sample.
      params: the bond parameters (``None``: the sample's own).
      scene: the scene the estimator is built for (``None``: none, the z axis).
      radius: the spheres' radius [m] (default 1.5 mean particle diameters, i.e. neighbourhoods three diameters
        across, as in Jarolin & Dosta 2020).
      **options: the estimator's options (:func:`~jaxbpm.ste.estimator`).

    Returns:
      The :class:`LocalMap`.

    Raises:
      SceneError: a radius that is not a positive length.
    """
    from scipy.sparse import coo_matrix, identity
    from scipy.spatial import cKDTree

    params = default_params(sample) if params is None else params
    params = check_params(params, sample)
    est = estimator(sample, scene, pad=True, **options)
    c = np.asarray(_local_tensors_jit(est, params))[:sample.n_particles]
    rad = np.asarray(sample.radii)
    radius = 3.0 * float(np.mean(rad)) if radius is None else float(radius)
    if not (radius > 0 and np.isfinite(radius)):
        raise SceneError(f"radius must be a positive length, got {radius!r}")
    pos = np.asarray(sample.positions)
    n = sample.n_particles
    pairs = cKDTree(pos).query_pairs(radius, output_type="ndarray")
    adj = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    adj = (adj + adj.T + identity(n)).tocsr()
    valid = np.asarray(est.valid)[:n]
    w = np.where(valid, np.asarray(est.volume)[:n], 0.0)
    cw = np.where(valid[:, None, None], c, 0.0) * w[:, None, None]  # the map shows the surface too
    wsum = adj @ w
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (adj @ cw.reshape(n, 36)).reshape(n, 6, 6) / wsum[:, None, None]
        ok = wsum > 0
        e = np.full((n, 3), np.nan)
        e[ok] = 1.0 / np.diagonal(np.linalg.inv(mean[ok]), axis1=1, axis2=2)[:, :3]
        avg = np.nanmean(e, axis=0)
        deviation = (avg - e) / avg
    return LocalMap(positions=pos, E=e, deviation=deviation, valid=valid, radius=radius)
