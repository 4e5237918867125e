"""Three-point bending of a bonded beam: two supports under its ends, a punch pressed down at mid-span.

Observables of :class:`ThreePointBending`: the load-deflection curve, the stiffness K = dF/dw, the beam modulus
E = K S^3 / (48 I) and the flexural strength sigma_f = 3 F_peak S / (2 b h^2).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from jaxbpm.errors import SceneError
from jaxbpm.physics.cohesive import CohesiveLaw, resolve_contact_law
from jaxbpm.physics.linear import LinearLaw
from jaxbpm.physics.loading import Loading
from jaxbpm.sample import Sample
from jaxbpm.scenes.base import (BaseScene, _check_failure_rule, _check_fit_range, _check_stop_after_peak,
                                _extent, _is_axis, _loading)
from jaxbpm.scenes.groups import _spec, clamped_groups

__all__ = ["ThreePointBending"]


@dataclasses.dataclass(frozen=True)
class ThreePointBending(BaseScene):
    """Three-point bending of a bonded beam: two supports under its ends, a punch pressed down at mid-span.

    The beam spans ``span_axis`` (default x); the load acts against ``axis`` (default z, downwards). The supports are
    the particles of the bottom layer (``layer_thickness``, default one mean radius) within ``support_width`` of the
    points ``centre -/+ span / 2``; the punch is the top-layer particles within ``punch_width`` of mid-span. Both
    are clamped (every DOF prescribed): the supports fixed, the punch moved down at constant speed to a deflection
    of ``strain`` x beam height. A clamped row of particles stands for a roller or a cylindrical punch; it also
    holds rotation, which matters little when the supports are narrow against the span.

    Observables: load-deflection curve, stiffness K = dF/dw over ``fit_range``, the beam modulus
    E = K S^3 / (48 I) with I = b h^3 / 12, and the flexural strength sigma_f = 3 F_peak S / (2 b h^2) (S: span,
    b: width, h: height). Served by the DEM and the DSM (:attr:`methods`).

    Args:
      span: [m], default 80 % of the beam length.
      axis: the load axis (default z).
      span_axis: the beam's axis (default x).
      strain: the punch deflection over the beam height, in (0, 1).
      support_width, punch_width: [m], default one mean diameter.
      layer_thickness: [m], the depth of the support and punch layers (default one mean radius).
      contacts: particle contacts (on by default: broken bonds fall back to them), by ``contact_law``.
      rotations: rotational DOFs (``None``: the Model decides).
      fit_range: the part of the loading (fractions of the target deflection) over which K is fitted.
      breakage, failure_rule: as in :class:`~jaxbpm.scenes.UniaxialCompression`.
      supports, punch: the held and the pressed particles, in place of those found from the widths (give both or
        neither): each a boolean mask ``[n]``, a list of particle indices, a type, a region or a combination (see
        :mod:`jaxbpm.scenes.groups`; a :class:`~jaxbpm.scenes.groups.Layer` measures along ``axis``). Kept as given.
      stop_after_peak: with breakage, the DEM run stops once the punch force has fallen to this fraction of its
        peak, in (0, 1) (default 0.7); ``None``: it runs to the full ``strain`` (see
        :class:`~jaxbpm.scenes.UniaxialCompression`).
      contact_law: ``"hertz"`` (Hertz-Mindlin, default) or ``"linear"`` (PFC's linear contact model,
        :mod:`jaxbpm.physics.linear`; or a :class:`~jaxbpm.physics.linear.LinearLaw` itself).

    Raises:
      SceneError: an argument out of its range.
    """

    span: float | None = None
    axis: int = 2
    span_axis: int = 0
    strain: float = 0.1
    support_width: float | None = None
    punch_width: float | None = None
    layer_thickness: float | None = None
    contacts: bool = True
    rotations: bool | None = None
    fit_range: tuple[float, float] = (0.02, 0.1)
    breakage: bool | None = None
    failure_rule: str = "separate"
    supports: Any = None
    punch: Any = None
    stop_after_peak: float | None = 0.7
    contact_law: Any = "hertz"

    #: the solvers that model this scene (the STE models uniaxial compression only)
    methods = ("dem", "dsm")
    boundary = "layers"
    wall_law = "hertz"
    wall_stiffness = None

    def __post_init__(self):
        law = resolve_contact_law(self.contact_law)
        if isinstance(law, CohesiveLaw):
            raise SceneError("ThreePointBending takes contact_law='hertz' or 'linear' (or a LinearLaw), not the "
                             "cohesive law")
        if law is not None and not self.contacts:
            raise SceneError("contact_law='linear' needs contacts=True")
        _check_failure_rule(self.failure_rule)
        _check_stop_after_peak(self.stop_after_peak)
        if not _is_axis(self.axis) or not _is_axis(self.span_axis) or self.axis == self.span_axis:
            raise SceneError(f"axis and span_axis must be two different axes of 0, 1, 2, got {self.axis!r} and "
                             f"{self.span_axis!r}")
        if not (0 < self.strain < 1):
            raise SceneError(f"strain (deflection / beam height) must lie in (0, 1), got {self.strain!r}")
        _check_fit_range(self.fit_range)
        for name in ("span", "support_width", "punch_width", "layer_thickness"):
            v = getattr(self, name)
            if v is not None and not v > 0:
                raise SceneError(f"{name} must be positive [m], got {v!r}")
        if (self.supports is None) != (self.punch is None):
            raise SceneError("give both supports and punch, or neither")
        for group in (self.supports, self.punch):
            if group is not None:
                _spec(group)  # a group of no known form is an error here, not at the solve

    @property
    def linear_law(self) -> LinearLaw | None:
        """The :class:`~jaxbpm.physics.linear.LinearLaw` of the contacts, or ``None`` (Hertz-Mindlin)."""
        return resolve_contact_law(self.contact_law)

    @property
    def uses_walls(self) -> bool:
        """False: clamped supports and punch, no walls."""
        return False

    def dimensions(self, sample: Sample) -> tuple[float, float, float]:
        """The beam's dimensions.

        Args:
          sample: the beam.

        Returns:
          ``(S, b, h)``: span, width and height [m].

        Raises:
          SceneError: a span not shorter than the beam, or a two-dimensional beam loaded out of its plane.

        A two-dimensional beam (discs in the x-y plane) has the width of its discs' thickness (``Sample.thickness``)
        and is loaded and spanned along x and y (``axis=1, span_axis=0``, or the other way).
        """
        lo, hi = _extent(sample)
        size = hi - lo
        width_axis = 3 - self.axis - self.span_axis
        if sample.dim == 2 and width_axis != 2:
            raise SceneError("a two-dimensional beam lies in the x-y plane: load it along y and span it along x "
                             "(ThreePointBending(axis=1, span_axis=0)) or the other way")
        span = self.span if self.span is not None else 0.8 * float(size[self.span_axis])
        if span >= size[self.span_axis]:
            raise SceneError(f"span {span:.4g} m must be shorter than the beam ({size[self.span_axis]:.4g} m)")
        width = float(sample.thickness) if sample.dim == 2 else float(size[width_axis])
        return float(span), width, float(size[self.axis])

    def layers(self, sample: Sample) -> tuple[np.ndarray, np.ndarray]:
        """The clamped particles.

        Args:
          sample: the beam.

        Returns:
          ``(supports [n], punch [n])``: boolean masks (of the groups given, or found from the widths).

        Raises:
          SceneError: no particle under a support or under the punch; for groups given, a
            :class:`~jaxbpm.errors.GroupError` naming the group and the particles.
        """
        if self.supports is not None:
            return clamped_groups(sample, self.supports, self.punch, axis=self.axis,
                                  layer_thickness=self.layer_thickness, names=("supports", "punch"))
        pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
        d = 2.0 * float(np.mean(rad))
        t = self.layer_thickness if self.layer_thickness is not None else 0.5 * d
        z, x = pos[:, self.axis], pos[:, self.span_axis]
        lo, hi = _extent(sample)
        mid = 0.5 * (lo[self.span_axis] + hi[self.span_axis])
        span = self.dimensions(sample)[0]
        ws = self.support_width if self.support_width is not None else d
        wp = self.punch_width if self.punch_width is not None else d
        bottom, top = z <= z.min() + t, z >= z.max() - t
        near = lambda c: np.abs(x - c) <= 0.5 * ws  # noqa: E731
        supports = bottom & (near(mid - 0.5 * span) | near(mid + 0.5 * span))
        punch = top & (np.abs(x - mid) <= 0.5 * wp)
        left, right = supports & (x < mid), supports & (x > mid)
        if not left.any() or not right.any() or not punch.any():
            raise SceneError("three-point bending: no particle found under a support or under the punch; widen "
                             "support_width / punch_width or layer_thickness")
        return supports, punch

    def geometry(self, sample: Sample) -> tuple[float, float]:
        """Beam height h (the deflection scale) and the cross-section b h.

        Args:
          sample: the beam.

        Returns:
          ``(h, b h)``: the height [m] and the cross-section [m^2].

        Raises:
          SceneError: a span that does not fit the beam (see :meth:`dimensions`).
        """
        span, width, height = self.dimensions(sample)
        return height, width * height

    def transit_length(self, sample: Sample) -> float:
        """The span: the DEM's default loading time counts elastic-wave transits along it.

        Args:
          sample: the beam.

        Returns:
          The span S [m].

        Raises:
          SceneError: a span that does not fit the beam (see :meth:`dimensions`).
        """
        return self.dimensions(sample)[0]

    def loading(self, sample: Sample, speed: float) -> Loading:
        """The DEM's boundary conditions: supports fixed, punch moved down at ``speed`` [m/s].

        Args:
          sample: the beam.
          speed: [m/s] of the punch.

        Returns:
          The :class:`~jaxbpm.physics.loading.Loading`.
        """
        supports, punch = self.layers(sample)
        vel = np.zeros((sample.n_particles, sample.dim))
        vel[punch, self.axis] = -speed
        return _loading(supports | punch, vel)

    def modulus(self, stiffness: float, sample: Sample) -> float:
        """Beam modulus E = K S^3 / (48 I), I = b h^3 / 12 (Euler-Bernoulli, simply supported).

        Args:
          stiffness: the fitted stiffness K [N/m] (punch force over deflection).
          sample: the beam.

        Returns:
          E [Pa].

        Raises:
          SceneError: a span that does not fit the beam (see :meth:`dimensions`).
        """
        span, b, h = self.dimensions(sample)
        return stiffness * span**3 / (48.0 * b * h**3 / 12.0)

    def strength(self, peak_force: float, sample: Sample) -> float:
        """Flexural strength sigma_f = 3 F S / (2 b h^2).

        Args:
          peak_force: the peak punch force F [N].
          sample: the beam.

        Returns:
          sigma_f [Pa].

        Raises:
          SceneError: a span that does not fit the beam (see :meth:`dimensions`).
        """
        span, b, h = self.dimensions(sample)
        return 3.0 * peak_force * span / (2.0 * b * h**2)
