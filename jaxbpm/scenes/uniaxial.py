"""Uniaxial compression: a sample squeezed along one axis between clamped layers or plane walls.

:class:`UniaxialCompression` loads to a target strain (default 2 %, as in Jarolin & Dosta 2020). Observables: the
force-displacement curve, the stiffness K (least-squares slope over the fit range), Young's modulus E = K l / A, the
Poisson ratio from the lateral strain of the middle third, and past the peak the uniaxial compressive strength.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar

import numpy as np

from jaxbpm.errors import SceneError
from jaxbpm.sample import Sample
from jaxbpm.scenes.base import (AxialScene, _check_failure_rule, _check_fit_range, _check_stop_after_peak,
                                _is_axis)
from jaxbpm.scenes.groups import _spec, clamped_groups

__all__ = ["UniaxialCompression"]


@dataclasses.dataclass(frozen=True, kw_only=True, repr=False)
class UniaxialCompression(AxialScene):
    """Uniaxial compression along ``axis`` (0, 1 or 2) to ``strain``.

    Served by every solver. With ``breakage``, loading past the peak gives the uniaxial compressive strength (UCS =
    peak stress; see :meth:`to_failure`), by the DEM only: the static solvers (DSM, STE) model the elastic range, and
    ``jaxbpm.solve`` refuses them a scene with ``breakage=True``.

    Args:
      axis: the load axis (default z). A two-dimensional sample lies in the x-y plane: load it along 1 (y) or 0 (x).
      strain: the target strain, in (0, 0.5).
      boundary: ``"layers"`` (clamp the particles within ``layer_thickness`` of the bottom, move those within it of
        the top; every DOF of both prescribed, the top translated rigidly, no rotation) or ``"walls"`` (two
        frictionless plane walls touching the outermost spheres; the top one moves).
      fixed, driven: the clamped (held) and the driven (moved) particles, in place of the layers (and implying
        "layers"): each a boolean mask ``[n]``, a list of particle indices, a particle type (:class:`~jaxbpm.scenes.
        groups.Type`), a region (:class:`~jaxbpm.scenes.groups.Region`), a :class:`~jaxbpm.scenes.groups.Layer` or a
        combination of them (see :mod:`jaxbpm.scenes.groups`). Kept as given; resolved (and checked) by ``layers``.
      layer_thickness: [m], default one mean particle radius: every particle whose centre lies within it of the
        lowest (highest) centre is clamped (driven).
      gauge_length, area: explicit l [m] and A [m^2]; defaults: l = distance between the mean centres of the
        clamped layers (walls: the initial wall gap), A = cross-section of the sample's domain (or the bounding box
        of its spheres) normal to the axis (2D: the width across the axis times the discs' thickness).
      contacts: particle contacts on (True) or off.
      rotations: rotational DOFs (``None``: the Model decides).
      wall_law, wall_stiffness: see :func:`jaxbpm.physics.model.build_model`.
      fit_range: the part of the loading (fractions of the target strain) over which K is fitted.
      breakage: bonds break in the DEM when their stresses exceed their strengths (``None``: when the sample's
        material table has a finite strength).
      contact_law: ``"hertz"`` (Hertz-Mindlin, default), ``"linear"`` (PFC's linear contact model,
        :mod:`jaxbpm.physics.linear`; or a :class:`~jaxbpm.physics.linear.LinearLaw` itself) or ``"cohesive"``
        (the stress-dependent cohesive law of :mod:`jaxbpm.physics.cohesive`, for cohesive granular samples; DEM
        only), with its parameters in ``cohesive``; or a :class:`~jaxbpm.physics.cohesive.CohesiveLaw` itself.
      cohesive: a :class:`~jaxbpm.physics.cohesive.CohesiveLaw` or a mapping of its fields: ``c0``, ``kc``,
        ``c_max``, and optionally ``E``, ``nu``, ``friction``, ``restitution``, ``initial_gap``.
      failure_rule: how a bond's stresses combine when it breaks: ``"separate"`` (default; tension and shear
        checked apart, the parallel bond of PFC and MUSEN), ``"summed"`` (LAMMPS ``bpm/rotational``: all four
        utilisations summed) or ``"max"`` (Yade's ``CohFrictPhys``: each load on its own); see
        :data:`jaxbpm.physics.bond.FAILURE_RULES`. Choose the rule of the code the calibrated strengths are for.
      stop_after_peak: with breakage, the DEM run stops once the force has fallen to this fraction of its peak, in
        (0, 1) (default 0.7); ``None``: it runs to the full ``strain``. See :class:`~jaxbpm.scenes.base.AxialScene`.

    Raises:
      SceneError: an argument out of its range.
    """

    _FIELD_ORDER: ClassVar[tuple[str, ...]] = (
        "axis", "strain", "boundary", "fixed", "driven", "layer_thickness", "gauge_length", "area", "contacts",
        "rotations", "wall_law", "wall_stiffness", "fit_range", "breakage", "contact_law", "cohesive", "failure_rule",
        "stop_after_peak")

    boundary: str = "layers"
    fixed: Any = None
    driven: Any = None
    gauge_length: float | None = None
    area: float | None = None

    @classmethod
    def to_failure(cls, strain: float = 0.02, **kw) -> "UniaxialCompression":
        """A compression past the peak.

        Bonds break, particles whose bond broke interact by Hertz-Mindlin contacts, and E is fitted over the first
        5-25 % of the loading (the elastic part).

        Args:
          strain: the target strain.
          **kw: other fields (``contacts`` defaults to True, ``fit_range`` to ``(0.05, 0.25)``).

        Returns:
          The scene.
        """
        kw.setdefault("contacts", True)
        kw.setdefault("fit_range", (0.05, 0.25))
        return cls(strain=strain, breakage=True, **kw)

    def __post_init__(self):
        _check_failure_rule(self.failure_rule)
        _check_stop_after_peak(self.stop_after_peak)
        if not _is_axis(self.axis):
            raise SceneError(f"axis must be the whole number 0, 1 or 2, got {self.axis!r}")
        if not (0 < self.strain < 0.5):
            raise SceneError(f"strain must lie in (0, 0.5), got {self.strain!r}")
        if self.boundary not in ("layers", "walls"):
            raise SceneError(f"boundary must be 'layers' or 'walls', got {self.boundary!r}")
        if (self.fixed is None) != (self.driven is None):
            raise SceneError("give both fixed and driven masks, or neither")
        for group in (self.fixed, self.driven):
            if group is not None:
                _spec(group)  # a group of no known form is an error here, not at the solve
        _check_fit_range(self.fit_range)
        self._check_contacts()

    @property
    def uses_walls(self) -> bool:
        """Whether plane walls load the sample (``boundary="walls"`` without explicit masks)."""
        return self.boundary == "walls" and self.fixed is None

    def layers(self, sample: Sample) -> tuple[np.ndarray, np.ndarray]:
        """The clamped particles.

        Args:
          sample: the specimen.

        Returns:
          ``(fixed [n], driven [n])``: boolean masks of the bottom and the top layer (or of the groups given).

        Raises:
          SceneError: an empty set, or a particle in both; for groups given, a
            :class:`~jaxbpm.errors.GroupError` naming the group and the particles (see
            :func:`~jaxbpm.scenes.groups.clamped_groups`).
        """
        if self.fixed is not None:
            return clamped_groups(sample, self.fixed, self.driven, axis=self.axis, layer_thickness=self.layer_thickness)
        z = np.asarray(sample.positions)[:, _plane_axis(self.axis, sample)]
        t = self.layer_thickness if self.layer_thickness is not None else float(np.mean(sample.radii))
        fixed, driven = z <= z.min() + t, z >= z.max() - t
        if not fixed.any() or not driven.any():
            raise SceneError("the fixed and the driven set must each hold at least one particle")
        if (fixed & driven).any():
            raise SceneError(f"particles {np.flatnonzero(fixed & driven)[:10].tolist()} are both fixed and driven; "
                             "use a thinner layer_thickness")
        return fixed, driven

    def geometry(self, sample: Sample) -> tuple[float, float]:
        """The gauge length and the cross-section.

        Args:
          sample: the specimen.

        Returns:
          ``(l, A)``: gauge length [m] and cross-section [m^2].

        Raises:
          SceneError: a length or an area that is not positive.
        """
        pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
        ax = _plane_axis(self.axis, sample)
        others = [k for k in range(sample.dim) if k != ax]
        if self.gauge_length is not None:
            length = float(self.gauge_length)
        elif self.boundary == "walls" and self.fixed is None:
            length = float((pos[:, ax] + rad).max() - (pos[:, ax] - rad).min())
        else:
            fixed, driven = self.layers(sample)
            length = float(pos[driven, ax].mean() - pos[fixed, ax].mean())
        if self.area is not None:
            area = float(self.area)
        elif sample.dim == 2:  # the width across the axis times the discs' thickness
            box = (np.subtract(sample.domain.hi, sample.domain.lo) if sample.domain is not None else
                   (pos + rad[:, None]).max(axis=0) - (pos - rad[:, None]).min(axis=0))
            area = float(box[others[0]] * sample.thickness)
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

    def lateral_strain(self, sample: Sample, displacement) -> dict:
        """Axial and lateral strain in the middle third of the sample and the Poisson ratio they give.

        Over the particles whose centres lie in the middle third of the sample along the axis (away from the
        clamped or pressed ends, whose constraint holds the lateral expansion back), least-squares slopes of
        ``u_axis`` against ``x_axis`` (the axial strain) and of each lateral ``u_k`` against ``x_k`` (two lateral
        strains; their intercepts take rigid translations). The end layers of ``boundary="layers"`` are clamped
        laterally too: on stubby samples (length / width below ~2) the middle third still feels them (a lower
        ratio); frictionless walls (``boundary="walls"``) leave the ends free.

        Args:
          sample: the specimen.
          displacement: ``[n, >=3]`` particle displacements (a static solution, or a DEM run's positions less the
            initial ones; extra rows, e.g. a size class's padding, are ignored).

        Returns:
          ``{"axial_strain", "lateral_strain" (the mean of the two), "lateral_strains" [2],
          "poisson_ratio" = -lateral / axial}``.

        Raises:
          SceneError: too few particles in the middle third, or all at one lateral coordinate.
        """
        pos = np.asarray(sample.positions, np.float64)
        n, dim = pos.shape
        u = np.asarray(displacement, np.float64)[:n, :dim]
        ax = _plane_axis(self.axis, sample)
        lateral = [k for k in range(dim) if k != ax]
        z = pos[:, ax]
        lo, hi = z.min(), z.max()
        mid = (z >= lo + (hi - lo) / 3.0) & (z <= hi - (hi - lo) / 3.0)
        if mid.sum() < 4:
            raise SceneError("too few particles in the middle third of the sample to measure a lateral strain")

        def slope(x, y):
            x = x - x.mean()
            spread = float(np.dot(x, x))
            if not spread > 0:  # e.g. a column one particle wide: no lateral strain to measure
                raise SceneError("the particles of the middle third all lie at one coordinate across the load: no "
                                 "lateral strain to measure")
            return float(np.dot(x, y - y.mean()) / spread)

        axial = slope(pos[mid, ax], u[mid, ax])
        lat = [slope(pos[mid, k], u[mid, k]) for k in lateral]
        mean = float(np.mean(lat))
        return {"axial_strain": axial, "lateral_strain": mean, "lateral_strains": lat,
                "poisson_ratio": -mean / axial if axial != 0 else float("nan")}


def _plane_axis(axis: int, sample: Sample) -> int:
    """``axis``, checked against a two-dimensional sample (whose discs lie in the x-y plane)."""
    if sample.dim == 2 and axis == 2:
        raise SceneError("a two-dimensional sample lies in the x-y plane: load it along axis=1 (y) or axis=0 (x), "
                         "e.g. UniaxialCompression(axis=1)")
    return axis
