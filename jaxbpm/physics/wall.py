"""Frictionless plane walls with a prescribed motion.

A wall is a point ``p`` and a unit normal ``n`` pointing into the half-space where the particles are. A particle of
radius r at x overlaps the wall by ``delta = r - (x - p) . n``; it is pushed along ``n`` by

* ``"hertz"``: ``F = 4/3 E* sqrt(r) delta^(3/2)`` with ``E* = E / (1 - nu^2)`` (sphere on a rigid plane), or
* ``"linear"``: ``F = k delta``.

The reaction on each wall is minus the sum of the forces it exerts.
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = ["wall_forces"]


def wall_forces(positions, radii, points, normals, law: str, stiffness):
    """Forces of plane walls on the particles and the walls' reactions.

    Args:
        positions: ``[n, 3]`` particle positions [m].
        radii: ``[n]`` radii [m].
        points: ``[W, 3]`` a point of each wall [m].
        normals: ``[W, 3]`` unit normals, pointing to the particles' side.
        law: ``"hertz"`` or ``"linear"``.
        stiffness: for ``"hertz"`` E* of a particle on a rigid wall [Pa], for ``"linear"`` k [N/m].

    Returns:
        ``(forces, reactions)``: ``[n, 3]`` on the particles and ``[W, 3]`` on the walls [N].

    Raises:
        ValueError: an unknown ``law``.
    """
    gap = jnp.einsum("nk,wk->nw", positions, normals) - jnp.sum(points * normals, axis=1)[None, :]
    delta = jnp.maximum(radii[:, None] - gap, 0.0)
    if law == "hertz":
        # sqrt of a safe argument: the derivative of sqrt at 0 is infinite, and 0 * inf would make jvps NaN
        root = jnp.where(delta > 0, jnp.sqrt(jnp.where(delta > 0, delta, 1.0)), 0.0)
        mag = 4.0 / 3.0 * stiffness * jnp.sqrt(radii)[:, None] * delta * root
    elif law == "linear":
        mag = stiffness * delta
    else:
        raise ValueError(f"unknown wall law {law!r}; use 'hertz' or 'linear'")
    per_pair = mag[:, :, None] * normals[None, :, :]
    return per_pair.sum(axis=1), -per_pair.sum(axis=0)
