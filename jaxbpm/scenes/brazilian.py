"""The Brazilian test: a bonded disc squeezed across a diameter until it splits.

Observables of :class:`BrazilianDisc`: the load-displacement curve of the platen, its stiffness and the Brazilian
tensile strength BTS = 2 F_peak / (pi D t).
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar

import numpy as np

from jaxbpm.errors import SceneError
from jaxbpm.sample import Sample
from jaxbpm.scenes.base import (AxialScene, _check_failure_rule, _check_fit_range, _check_stop_after_peak,
                                _extent, _is_axis)
from jaxbpm.scenes.groups import _spec, clamped_groups

__all__ = ["BrazilianDisc"]


def _is_length(v) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and v > 0


@dataclasses.dataclass(frozen=True, kw_only=True, repr=False)
class BrazilianDisc(AxialScene):
    """Brazilian (diametral compression) test of a bonded disc: a short cylinder squeezed across a diameter until it
    splits.

    The disc's axis is ``disc_axis`` (default z, the axis of :func:`jaxbpm.generate.cylinder`; a disc is
    ``generate.cylinder(n, aspect=t / D)``, ISRM: t / D = 0.5); the load acts along ``axis`` (default x, normal to
    the disc axis). The bottom platen stays, the top one moves against ``axis`` to a displacement of ``strain`` x D.
    A flat platen touches a rough rim at a few particles only: on discs of ten or so particles across, the rim
    crushes there first and the force keeps rising (no clean peak); the clamped strips, the default, split the disc
    along the loaded diameter.

    Observables: the load-displacement curve of the platen, the stiffness K = dF/du over ``fit_range`` [N/m] and
    the Brazilian tensile strength BTS = 2 F_peak / (pi D t) at the peak force (Hondros' solution for a disc under
    diametral line loads: the tensile stress across the loaded diameter). ``modulus`` is NaN: the platen
    displacement of a disc is mostly the deformation near the loaded arcs, so K is no measure of Young's modulus.
    The curve's strain is u / D and its stress F / (D t) (``Result.area`` = D t), so stress x 2 / pi is the
    tensile stress of Hondros' solution. DEM only (:attr:`methods`): the static solvers (DSM, STE) raise
    :class:`~jaxbpm.errors.SceneError`.

    Args:
      axis: the load axis (default x).
      disc_axis: the disc's axis (default z).
      strain: the platen displacement over the diameter, in (0, 0.5). The default (2 % of D) goes past the peak of
        discs whose bond strength is a few thousandths of their bond modulus; stronger bonds need more.
      diameter: D [m], default the diameter of the sample's cylinder domain (a sample without one: the spheres'
        extent along ``axis``).
      thickness: t [m], default the domain's height (the spheres' extent along ``disc_axis``). Give both when the
        disc is not a generated z-axis cylinder.
      contacts: Hertz-Mindlin contacts between particles (on: broken bonds fall back to them).
      rotations: rotational DOFs (``None``: the Model decides).
      wall_law, wall_stiffness: (``platens="walls"``) ``"hertz"`` (the particle material on a rigid plane) or
        ``"linear"`` with ``wall_stiffness`` [N/m]; see :func:`jaxbpm.physics.model.build_model`.
      fit_range: the part of the loading (fractions of the target displacement) over which K is fitted.
      breakage: bonds break when their stresses exceed their strengths (on by default; ``None``: when the sample's
        material table has a finite strength).
      contact_law, cohesive: as in :class:`~jaxbpm.scenes.UniaxialCompression`.
      platens: ``"strips"`` (default): two rigid loading strips, the particles of the rim within
        ``layer_thickness`` of its lowest (highest) point along ``axis`` and within half of ``strip_width`` of the
        loaded diameter, clamped and moved rigidly (every DOF prescribed, as the layers of
        :class:`~jaxbpm.scenes.UniaxialCompression`). ``"walls"``: two flat frictionless plane walls normal to
        ``axis`` touching the outermost spheres (law ``wall_law``).
      strip_width: [m], default D / 5: a contact arc 2 alpha of about 23 degrees, as the curved ISRM jaws and
        flattened discs give.
      layer_thickness: [m], the depth of the strips (default one mean radius).
      failure_rule: as in :class:`~jaxbpm.scenes.UniaxialCompression`.
      fixed, driven: the held and the moved particles, in place of the strips (give both or neither; they imply
        clamped platens, as ``platens="strips"``): each a boolean mask ``[n]``, a list of particle indices, a type, a
        region or a combination (see :mod:`jaxbpm.scenes.groups`). Kept as given.
      stop_after_peak: as in :class:`~jaxbpm.scenes.UniaxialCompression` (the run stops once the platen force has
        fallen to ``stop_after_peak`` of its peak, default 0.7; ``None``: the full ``strain``).

    Raises:
      SceneError: an argument out of its range.
    """

    _FIELD_ORDER: ClassVar[tuple[str, ...]] = (
        "axis", "disc_axis", "strain", "diameter", "thickness", "contacts", "rotations", "wall_law", "wall_stiffness",
        "fit_range", "breakage", "contact_law", "cohesive", "platens", "strip_width", "layer_thickness",
        "failure_rule", "stop_after_peak",
        "fixed", "driven")

    axis: int = 0
    disc_axis: int = 2
    diameter: float | None = None
    thickness: float | None = None
    contacts: bool = True
    fit_range: tuple[float, float] = (0.05, 0.25)
    breakage: bool | None = True
    platens: str = "strips"
    strip_width: float | None = None
    fixed: Any = None
    driven: Any = None

    #: the solvers that model this scene: a disc between platens is a contact problem loaded to failure, which the
    #: static solvers (DSM, STE) do not model
    methods = ("dem",)

    def __post_init__(self):
        _check_failure_rule(self.failure_rule)
        _check_stop_after_peak(self.stop_after_peak)
        if not _is_axis(self.axis) or not _is_axis(self.disc_axis) or self.axis == self.disc_axis:
            raise SceneError(f"axis (the load) and disc_axis must be two different axes of 0, 1, 2, got "
                             f"{self.axis!r} and {self.disc_axis!r}")
        if not (isinstance(self.strain, (int, float, np.integer, np.floating)) and 0 < self.strain < 0.5):
            raise SceneError(f"strain (platen displacement / disc diameter) must lie in (0, 0.5), got {self.strain!r}")
        for name in ("diameter", "thickness"):
            v = getattr(self, name)
            if v is not None and not (_is_length(v) and np.isfinite(v)):
                raise SceneError(f"{name} must be a positive length [m], got {v!r}")
        if self.wall_law not in ("hertz", "linear"):
            raise SceneError(f"wall_law must be 'hertz' or 'linear', got {self.wall_law!r}")
        if self.wall_law == "linear" and self.wall_stiffness is None:
            raise SceneError("wall_law='linear' needs wall_stiffness [N/m]")
        if self.wall_stiffness is not None and not self.wall_stiffness > 0:
            raise SceneError(f"wall_stiffness must be positive, got {self.wall_stiffness!r}")
        _check_fit_range(self.fit_range)
        self._check_contacts()
        if self.platens not in ("walls", "strips"):
            raise SceneError(f"platens must be 'walls' or 'strips', got {self.platens!r}")
        for name in ("strip_width", "layer_thickness"):
            v = getattr(self, name)
            if v is not None and not _is_length(v):
                raise SceneError(f"{name} must be a positive length [m], got {v!r}")
        if (self.fixed is None) != (self.driven is None):
            raise SceneError("give both fixed and driven, or neither")
        for group in (self.fixed, self.driven):
            if group is not None:
                _spec(group)  # a group of no known form is an error here, not at the solve

    @property
    def boundary(self) -> str:
        """``"walls"`` (flat platens) or ``"layers"`` (clamped strips), as :class:`UniaxialCompression` says it."""
        return "walls" if self.uses_walls else "layers"

    @property
    def uses_walls(self) -> bool:
        """Whether the platens are plane walls (``platens="walls"`` without groups given)."""
        return self.platens == "walls" and self.fixed is None

    def layers(self, sample: Sample) -> tuple[np.ndarray, np.ndarray]:
        """The loading strips' particles (``platens="strips"``).

        Args:
          sample: the disc.

        Returns:
          ``(fixed [n], driven [n])``: boolean masks of the bottom and the top strip.

        Raises:
          SceneError: an empty strip, or a particle in both; for groups given, a :class:`~jaxbpm.errors.GroupError`
            naming the group and the particles.
        """
        if self.fixed is not None:
            return clamped_groups(sample, self.fixed, self.driven, axis=self.axis, layer_thickness=self.layer_thickness)
        pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
        d = self.dimensions(sample)[0]
        lo, hi = _extent(sample)
        lat = 3 - self.axis - self.disc_axis
        centre = 0.5 * (lo[lat] + hi[lat])
        width = self.strip_width if self.strip_width is not None else 0.2 * d
        t = self.layer_thickness if self.layer_thickness is not None else float(np.mean(rad))
        x = pos[:, self.axis]
        inside = np.abs(pos[:, lat] - centre) <= 0.5 * width
        fixed = inside & (x - rad <= lo[self.axis] + t)
        driven = inside & (x + rad >= hi[self.axis] - t)
        if not fixed.any() or not driven.any():
            raise SceneError("Brazilian disc: no particle found in a loading strip; widen strip_width or "
                             "layer_thickness")
        if (fixed & driven).any():
            raise SceneError("Brazilian disc: a particle lies in both loading strips; use a thinner layer_thickness")
        return fixed, driven

    def dimensions(self, sample: Sample) -> tuple[float, float]:
        """The disc's dimensions.

        Args:
          sample: the disc.

        Returns:
          ``(D, t)``: diameter and thickness [m].

        Raises:
          SceneError: a z-axis cylinder domain with another ``disc_axis`` (and no explicit dimensions), or a
            dimension that is not positive. A two-dimensional sample (discs in the x-y plane) has ``disc_axis`` 2 and
            the thickness of its discs (``Sample.thickness``) unless ``thickness`` is given.
        """
        domain = sample.domain
        cylinder = domain is not None and domain.kind == "cylinder"
        if sample.dim == 2:  # discs in the x-y plane: the disc's axis is z, its thickness the discs'
            if self.disc_axis != 2 or self.axis == 2:
                raise SceneError("a two-dimensional sample lies in the x-y plane: its disc's axis is z (disc_axis=2) "
                                 "and the load along x or y (axis=0 or 1)")
            t = float(sample.thickness) if self.thickness is None else float(self.thickness)
            size = np.subtract(domain.hi, domain.lo) if cylinder else np.subtract(*_extent(sample)[::-1])
            return float(size[self.axis]) if self.diameter is None else float(self.diameter), t
        if cylinder and self.disc_axis != 2 and (self.diameter is None or self.thickness is None):
            raise SceneError(f"the sample's domain is a cylinder along z, but disc_axis is {self.disc_axis}: give "
                             "disc_axis=2 (or diameter and thickness)")
        lo, hi = _extent(sample)
        size = np.subtract(domain.hi, domain.lo) if cylinder else hi - lo
        d = float(self.diameter) if self.diameter is not None else float(size[self.axis])
        t = float(self.thickness) if self.thickness is not None else float(size[self.disc_axis])
        if not (d > 0 and t > 0):
            raise SceneError(f"disc diameter ({d:.4g} m) and thickness ({t:.4g} m) must be positive")
        return d, t

    def geometry(self, sample: Sample) -> tuple[float, float]:
        """The diameter D (the displacement scale: strain = u / D) and the diametral section D t.

        Args:
          sample: the disc.

        Returns:
          ``(D, D t)``: the diameter [m] and the diametral section [m^2].

        Raises:
          SceneError: a disc whose size cannot be read (see :meth:`dimensions`).
        """
        d, t = self.dimensions(sample)
        return d, d * t

    def modulus(self, stiffness: float, sample: Sample) -> float:
        """NaN: the platen stiffness of a disc is mostly its contact flattening, not a measure of E.

        Args:
          stiffness: the fitted stiffness [N/m] (unused).
          sample: the disc (unused).

        Returns:
          NaN.
        """
        return float("nan")

    def strength(self, peak_force: float, sample: Sample) -> float:
        """Brazilian tensile strength BTS = 2 F / (pi D t).

        Args:
          peak_force: the peak platen force F [N].
          sample: the disc.

        Returns:
          BTS [Pa].

        Raises:
          SceneError: a disc whose size cannot be read (see :meth:`dimensions`).
        """
        d, t = self.dimensions(sample)
        return 2.0 * peak_force / (np.pi * d * t)
