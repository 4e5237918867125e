"""The boundary conditions of a run: clamped particles with prescribed velocities and moving plane walls. Scenes
build them (:meth:`jaxbpm.scenes.UniaxialCompression.loading`); the DEM integrates under them (``jaxbpm.dem.Loading``
is this class)."""

from __future__ import annotations

import dataclasses
from typing import Any

import jax

__all__ = ["Loading"]


@dataclasses.dataclass(frozen=True)
class Loading:
    """Boundary conditions of a DEM run (a pytree).

    Attributes:
        clamped: ``[n]`` bool, particles whose every DOF is prescribed (translation ``x0 + velocity t``, no
            rotation).
        velocity: ``[n, 3]`` prescribed velocity of clamped particles [m/s] (zero for fixed ones).
        wall_points0: ``[W, 3]`` a point of each plane wall at time 0 [m] (W may be 0).
        wall_normals: ``[W, 3]`` the walls' unit normals, pointing to the particles' side.
        wall_velocity: ``[W, 3]`` the walls' velocities [m/s].
    """

    clamped: Any
    velocity: Any
    wall_points0: Any
    wall_normals: Any
    wall_velocity: Any


jax.tree_util.register_dataclass(Loading, data_fields=["clamped", "velocity", "wall_points0", "wall_normals",
                                                       "wall_velocity"], meta_fields=[])
