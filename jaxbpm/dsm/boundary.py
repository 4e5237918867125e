"""What a scene prescribes to the DSM: the free degrees of freedom, the check that every free cluster is held, contact
candidates within reach and the affine displacement field.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from jaxbpm._compile import put
from jaxbpm._geometry import check_three_d
from jaxbpm.errors import SceneError
from jaxbpm.physics.model import Model


def free_mask(model: Model, scene, sample):
    """The DOFs the solve moves and the scene's clamped and driven particles.

    Between walls, only the lateral rigid-body motions are pinned (three DOFs of two bottom particles, which carry
    no load); with clamped layers, every DOF of the fixed and driven particles is prescribed.

    Args:
      model: the model (its DOFs per particle).
      scene: the scene.
      sample: the bonded sample.

    Returns:
      ``(free [n, nd], fixed [n], driven [n])``.

    Raises:
      SceneError: a two-dimensional sample between walls.
    """
    if scene.uses_walls:
        check_three_d(sample, "the DSM between walls")
    nd = model.dofs
    n = model.n
    free = np.ones((n, nd), bool)
    if scene.uses_walls:
        # frictionless walls hold the sample along the axis only: pin the lateral rigid-body motions with the least
        # constraints possible (two lateral DOFs of one bottom particle, one of another), which carry no load
        ax = scene.axis
        pos = np.asarray(sample.positions)
        lat = [k for k in range(3) if k != ax]
        bottom = np.flatnonzero(pos[:, ax] - np.asarray(sample.radii) <= (pos[:, ax] - np.asarray(sample.radii)).min()
                                + 1e-9 + float(np.mean(sample.radii)))
        c = pos[bottom].mean(axis=0)
        p0 = bottom[np.argmin(np.linalg.norm(pos[bottom] - c, axis=1))]
        p1 = bottom[np.argmax(np.linalg.norm(pos[bottom] - pos[p0], axis=1))]
        free[p0, lat] = False
        arm = pos[p1] - pos[p0]
        free[p1, lat[int(np.argmin(np.abs(arm[lat])))]] = False
        return free, np.zeros(n, bool), np.zeros(n, bool)
    fixed, driven = scene.layers(sample)
    free[fixed | driven] = False
    return free, fixed, driven


def _check_held(sample, model, free, clamped, contact_pairs=None, wall_touching=None):
    """Raise SceneError if a cluster of bonded (or touching) particles is held by nothing."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = model.n
    b = np.asarray(sample.bonds)
    if contact_pairs is not None and len(contact_pairs):
        b = np.concatenate([b, contact_pairs])
    graph = coo_matrix((np.ones(len(b)), (b[:, 0], b[:, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    held = clamped | (~free).any(axis=1)
    if wall_touching is not None:
        held = held | wall_touching
    ok = np.zeros(labels.max() + 1, bool)
    ok[labels[held]] = True
    loose = np.flatnonzero(~ok[labels])
    if loose.size:
        raise SceneError(
            f"the system is singular: {loose.size} particles belong to clusters held by no clamped particle or wall "
            f"(floating), e.g. particles {loose[:10].tolist()}; remove them or clamp part of each cluster")


def contact_candidates(sample, model, skin):
    """The contacts the solve may close.

    Args:
      sample: the bonded sample.
      model: the model (which pairs are bonded).
      skin: the largest gap at rest [m].

    Returns:
      ``[C, 2]`` the particle pairs whose gap at rest is below ``skin``, bonded pairs left out when the sample's
      bonds replace their contacts (``bond_contact="replace"``).
    """
    from scipy.spatial import cKDTree

    pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
    tree = cKDTree(pos)
    pairs = np.array(sorted(tree.query_pairs(2 * rad.max() + skin)), dtype=np.int64).reshape(-1, 2)
    if len(pairs):
        gap = np.linalg.norm(pos[pairs[:, 1]] - pos[pairs[:, 0]], axis=1) - rad[pairs[:, 0]] - rad[pairs[:, 1]]
        pairs = pairs[gap < skin]
    if sample.bond_contact == "replace" and len(pairs):
        bonded = np.asarray(model.bonded(put(pairs, np.int32)))
        pairs = pairs[~bonded]
    return pairs.astype(np.int32)


# the linearised contacts' default candidate reach, in affine approaches of two touching mean-sized particles at the
# linearisation state
LINEAR_REACH = 4.0


def _check_contact_skin(sample, pairs, disp, skin, stats):
    """Record how many candidates touch at the linearisation state ``disp`` [n, 3] and the largest gap at rest of
    one that does; True when it comes near the candidate skin (pairs beyond it were never candidates)."""
    pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
    i, j = pairs[:, 0], pairs[:, 1]
    x = pos + disp
    touching = np.linalg.norm(x[j] - x[i], axis=1) < rad[i] + rad[j]
    gap = np.linalg.norm(pos[j] - pos[i], axis=1) - rad[i] - rad[j]
    widest = float(gap[touching].max()) if touching.any() else 0.0
    stats.update(contact_skin=float(skin), contacts_touching=int(touching.sum()), contact_gap_max=widest)
    return widest > 0.5 * skin


def affine_field(sample, model: Model, ax, delta):
    """The displacements of a uniform strain (no rotations, no lateral motion).

    Args:
      sample: the bonded sample.
      model: the model (its DOFs per particle).
      ax: the load axis.
      delta: how far the top of the sample moves against ``ax`` [m] (the bottom stays).

    Returns:
      ``[n, nd]`` the displacements.
    """
    x = np.asarray(sample.positions)[:, ax]
    u = np.zeros((model.n, model.dofs))
    u[:, ax] = -delta * (x - x.min()) / max(x.max() - x.min(), 1e-300)
    return jnp.asarray(u, model.positions0.dtype)
