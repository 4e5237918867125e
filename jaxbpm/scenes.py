"""Scenes: a lab test = boundary conditions + loading + observables, applied to a sample.

:class:`UniaxialCompression` squeezes a sample along one axis, either between two plane walls or by clamping a
bottom layer of particles and moving a top layer rigidly, to a target strain (default 2 %, as in seed 000).
Observables: the force-displacement curve, the stiffness K (least-squares slope over the linear range) and Young's
modulus E = K l / A.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from jaxbpm.errors import SceneError
from jaxbpm.sample import Sample

__all__ = ["UniaxialCompression"]


@dataclasses.dataclass(frozen=True)
class UniaxialCompression:
    """Uniaxial compression along ``axis`` (0, 1 or 2) to ``strain``.

    boundary: ``"layers"`` (clamp the particles within ``layer_thickness`` of the bottom, move those within it of
      the top; every DOF of both prescribed, the top translated rigidly, no rotation) or ``"walls"`` (two frictionless
      plane walls touching the outermost spheres; the top one moves).
    fixed, driven: explicit ``[n]`` boolean masks of clamped particles (override the layers; implies "layers").
    layer_thickness: [m], default one mean particle radius: every particle whose centre lies within it of the
      lowest (highest) centre is clamped (driven).
    gauge_length, area: explicit l [m] and A [m^2]; defaults: l = distance between the mean centres of the clamped
      layers (walls: the initial wall gap), A = cross-section of the sample's domain (or the bounding box of its
      spheres) normal to the axis.
    contacts: Hertz-Mindlin particle contacts on (True) or off. rotations: None = the Model decides.
    wall_law, wall_stiffness: see :func:`jaxbpm.physics.model.build_model`.
    fit_range: the part of the loading (fractions of the target strain) over which K is fitted.
    """

    axis: int = 2
    strain: float = 0.02
    boundary: str = "layers"
    fixed: np.ndarray | None = None
    driven: np.ndarray | None = None
    layer_thickness: float | None = None
    gauge_length: float | None = None
    area: float | None = None
    contacts: bool = False
    rotations: bool | None = None
    wall_law: str = "hertz"
    wall_stiffness: float | None = None
    fit_range: tuple[float, float] = (0.25, 1.0)

    def __post_init__(self):
        if self.axis not in (0, 1, 2):
            raise SceneError(f"axis must be 0, 1 or 2, got {self.axis!r}")
        if not (0 < self.strain < 0.5):
            raise SceneError(f"strain must lie in (0, 0.5), got {self.strain!r}")
        if self.boundary not in ("layers", "walls"):
            raise SceneError(f"boundary must be 'layers' or 'walls', got {self.boundary!r}")
        if (self.fixed is None) != (self.driven is None):
            raise SceneError("give both fixed and driven masks, or neither")
        lo, hi = self.fit_range
        if not (0 <= lo < hi <= 1):
            raise SceneError(f"fit_range must satisfy 0 <= lo < hi <= 1, got {self.fit_range!r}")

    # ------------------------------------------------------------------ geometry
    def layers(self, sample: Sample) -> tuple[np.ndarray, np.ndarray]:
        """Boolean masks ``(fixed, driven)`` of the clamped particles."""
        n = sample.n_particles
        if self.fixed is not None:
            fixed, driven = np.asarray(self.fixed, bool), np.asarray(self.driven, bool)
            for name, m in (("fixed", fixed), ("driven", driven)):
                if m.shape != (n,):
                    raise SceneError(f"{name} mask must have shape [{n}], got {m.shape}")
        else:
            z = np.asarray(sample.positions)[:, self.axis]
            t = self.layer_thickness if self.layer_thickness is not None else float(np.mean(sample.radii))
            fixed, driven = z <= z.min() + t, z >= z.max() - t
        if not fixed.any() or not driven.any():
            raise SceneError("the fixed and the driven set must each hold at least one particle")
        if (fixed & driven).any():
            raise SceneError(f"particles {np.flatnonzero(fixed & driven)[:10].tolist()} are both fixed and driven; "
                             "use a thinner layer_thickness")
        return fixed, driven

    def geometry(self, sample: Sample) -> tuple[float, float]:
        """Gauge length l [m] and cross-section A [m^2]."""
        pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
        ax = self.axis
        others = [k for k in range(3) if k != ax]
        if self.gauge_length is not None:
            length = float(self.gauge_length)
        elif self.boundary == "walls" and self.fixed is None:
            length = float((pos[:, ax] + rad).max() - (pos[:, ax] - rad).min())
        else:
            fixed, driven = self.layers(sample)
            length = float(pos[driven, ax].mean() - pos[fixed, ax].mean())
        if self.area is not None:
            area = float(self.area)
        elif sample.domain is not None:
            size = np.subtract(sample.domain.hi, sample.domain.lo)
            area = float(size[others[0]] * size[others[1]])
            if sample.domain.kind == "cylinder" and ax == 2:
                area *= np.pi / 4.0
        else:
            size = (pos + rad[:, None]).max(axis=0) - (pos - rad[:, None]).min(axis=0)
            area = float(size[others[0]] * size[others[1]])
        if not (length > 0 and area > 0):
            raise SceneError(f"gauge length ({length:.4g} m) and area ({area:.4g} m^2) must be positive")
        return length, area

    def model(self, sample: Sample, **overrides):
        """The :class:`~jaxbpm.physics.model.Model` this scene needs."""
        from jaxbpm.physics.model import build_model

        kw = dict(contacts=self.contacts, walls=self.wall_law if self.uses_walls else None, rotations=self.rotations,
                  wall_stiffness=self.wall_stiffness)
        kw.update(overrides)
        return build_model(sample, **kw)

    @property
    def uses_walls(self) -> bool:
        return self.boundary == "walls" and self.fixed is None

    def loading(self, sample: Sample, speed: float):
        """DEM boundary conditions for a compression at ``speed`` [m/s] of the driven set / top wall."""
        from jaxbpm.dem import Loading

        n, ax = sample.n_particles, self.axis
        dtype = jnp.asarray(1.0).dtype
        e = np.zeros(3)
        e[ax] = 1.0
        if self.uses_walls:
            pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
            lo, hi = (pos[:, ax] - rad).min(), (pos[:, ax] + rad).max()
            points = np.stack([lo * e, hi * e])
            normals = np.stack([e, -e])
            return Loading(clamped=jnp.zeros(n, bool), velocity=jnp.zeros((n, 3), dtype),
                           wall_points0=jnp.asarray(points, dtype), wall_normals=jnp.asarray(normals, dtype),
                           wall_velocity=jnp.asarray(np.stack([0 * e, -speed * e]), dtype))
        fixed, driven = self.layers(sample)
        vel = np.zeros((n, 3))
        vel[driven] = -speed * e
        empty = jnp.zeros((0, 3), dtype)
        return Loading(clamped=jnp.asarray(fixed | driven), velocity=jnp.asarray(vel, dtype), wall_points0=empty,
                       wall_normals=empty, wall_velocity=empty)

    def compressive_force(self, reaction: np.ndarray) -> np.ndarray:
        """Compressive force [N] per record from the DEM reactions ``[steps, W+2, 3]`` (mean of both ends)."""
        ax = self.axis
        if self.uses_walls:
            return 0.5 * (reaction[:, 1, ax] - reaction[:, 0, ax])
        return 0.5 * (reaction[:, 0, ax] - reaction[:, 1, ax])

    def fit_stiffness(self, displacement: np.ndarray, force: np.ndarray, target: float) -> float:
        """Least-squares slope dF/du over ``fit_range`` of the target displacement."""
        lo, hi = self.fit_range
        sel = (displacement >= lo * target) & (displacement <= hi * target * (1 + 1e-9))
        if sel.sum() < 2:
            raise SceneError("too few records in fit_range to fit a stiffness")
        return float(np.polyfit(displacement[sel], force[sel], 1)[0])
