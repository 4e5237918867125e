"""Three-point bending of a bonded beam: two supports under its ends, a punch pressed down at mid-span.

The supports and the punch are clamped rows of the beam's particles, or (``rollers=True``) roller discs or spheres the
scene adds to the sample, which touch the beam through its contacts alone.

Observables of :class:`ThreePointBending`: the load-deflection curve, the stiffness K = dF/dw, the beam modulus
E = K S^3 / (48 I) and the flexural strength sigma_f = 3 F_peak S / (2 b h^2).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from jaxbpm._compile import SetupCache
from jaxbpm.errors import SceneError
from jaxbpm.physics.cohesive import CohesiveLaw, resolve_contact_law
from jaxbpm.physics.linear import LinearLaw
from jaxbpm.physics.loading import Loading
from jaxbpm.sample import Sample
from jaxbpm.scenes.base import (BaseScene, _check_failure_rule, _check_fit_range, _check_stop_after_peak,
                                _extent, _is_axis, _loading)
from jaxbpm.scenes.groups import _spec, clamped_groups

__all__ = ["ThreePointBending", "ROLLER_RADII"]

#: the rollers' default radius, in mean particle radii
ROLLER_RADII = 5.0

_STAGED = SetupCache(maxsize=16)  # (beam, scene) -> (the beam with its rollers, the scene bound to it)


@dataclasses.dataclass(frozen=True)
class ThreePointBending(BaseScene):
    """Three-point bending of a bonded beam: two supports under its ends, a punch pressed down at mid-span.

    The beam spans ``span_axis`` (default x); the load acts against ``axis`` (default z, downwards). The supports are
    the particles of the bottom layer (``layer_thickness``, default one mean radius) within ``support_width`` of the
    points ``centre -/+ span / 2``; the punch is the top-layer particles within ``punch_width`` of mid-span. Where
    the default width (one mean diameter) finds no particle of the layer at a point (a sparse layer, a packing of
    fine particles), the band around that point is widened to the layer's nearest particles: those within one mean
    radius of the nearest one's distance to the point. An explicit width that finds none is an error. Both are
    clamped (every DOF prescribed): the supports fixed, the punch moved down at constant speed to a deflection of
    ``strain`` x beam height. A clamped row of particles holds the beam's ends along the span and in rotation, as
    a roller does not: the arching that follows raises the flexural strength (1.7x on a 2,250-disc beam of
    ``benchmarks/seed_case_qu2020_2d.py``).

    With ``rollers=True`` the scene adds the supports and the punch to the sample instead: three discs of radius
    ``roller_radius`` in 2D, three rows of spheres across the beam's width in 3D (as many as fit, at least one),
    each placed to touch the beam (the lowest particle under each support point, the highest at mid-span). They
    carry the load through the scene's contacts only (no bond joins them to the beam; ``contacts`` must be on): the
    supports fixed, the punch rollers moved down. :func:`jaxbpm.solve` adds them (:meth:`stage`): the solvers see
    the sample with the rollers last (their type one above the sample's largest, so that a VTU frame tells them
    apart), the result's ``stats["added_particles"]`` says how many, and the per-particle outputs (``state``, VTU
    frames, record files) have those rows last. The beam's dimensions (span, width, height) and its observables
    are those of the beam without the rollers.

    Observables: load-deflection curve, stiffness K = dF/dw over ``fit_range``, the beam modulus
    E = K S^3 / (48 I) with I = b h^3 / 12, and the flexural strength sigma_f = 3 F_peak S / (2 b h^2) (S: span,
    b: width, h: height). Served by the DEM and the DSM (:attr:`methods`); with ``rollers``, by the DEM alone.

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
        With ``contacts``, a group's particle that touches another at rest is joined to it (roller discs of the
        sample resting on the beam need no bond to it).
      stop_after_peak: with breakage, the DEM run stops once the punch force has fallen to this fraction of its
        peak, in (0, 1) (default 0.7); ``None``: it runs to the full ``strain`` (see
        :class:`~jaxbpm.scenes.UniaxialCompression`).
      contact_law: ``"hertz"`` (Hertz-Mindlin, default) or ``"linear"`` (PFC's linear contact model,
        :mod:`jaxbpm.physics.linear`; or a :class:`~jaxbpm.physics.linear.LinearLaw` itself).
      rollers: the scene adds roller supports and a roller punch (see above) in place of the clamped rows.
      roller_radius: [m], the rollers' radius (default :data:`ROLLER_RADII` mean particle radii).
      beam_particles: set by :meth:`stage` (leave it ``None``): the scene is bound to a sample whose first
        ``beam_particles`` particles are the beam and the rest its rollers.

    Raises:
      SceneError: an argument out of its range; ``rollers`` without contacts, with ``supports`` / ``punch`` or
        ``roller_radius`` without ``rollers``.
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
    rollers: bool = False
    roller_radius: float | None = None
    beam_particles: int | None = None

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
        self._check_rollers()

    def _check_rollers(self):
        if not isinstance(self.rollers, (bool, np.bool_)):
            raise SceneError(f"rollers must be True or False, got {self.rollers!r}")
        r = self.roller_radius
        if r is not None and not (isinstance(r, (int, float, np.integer, np.floating)) and r > 0 and np.isfinite(r)):
            raise SceneError(f"roller_radius must be a positive length [m], got {r!r}")
        if not self.rollers:
            if r is not None or self.beam_particles is not None:
                raise SceneError("roller_radius and beam_particles are for rollers=True")
            return
        if not self.contacts:
            raise SceneError("rollers=True needs contacts=True: the rollers touch the beam through contacts only")
        # the DSM's linearised contacts do not hold a beam that rests on its rollers: the DEM alone models it
        object.__setattr__(self, "methods", ("dem",))
        if self.supports is not None:
            raise SceneError("rollers=True adds its own supports and punch: leave supports and punch out (or give "
                             "them, clamped, with rollers=False)")
        nb = self.beam_particles
        if nb is not None and not (isinstance(nb, (int, np.integer)) and not isinstance(nb, bool) and nb > 0):
            raise SceneError(f"beam_particles must be a positive whole number (set by stage), got {nb!r}")

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
        lo, hi = self._beam_extent(sample)
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
          sample: the beam (with ``rollers``: the beam with its rollers, as :meth:`stage` gives it).

        Returns:
          ``(supports [n], punch [n])``: boolean masks (of the groups given, of the rollers, or found from the
          widths).

        Raises:
          SceneError: an explicit ``support_width`` or ``punch_width`` that finds no particle (the message names the
            width and the distance of the nearest particle); with ``rollers``, a sample not staged by
            :meth:`stage` or rollers that do not touch the beam; for groups given, a
            :class:`~jaxbpm.errors.GroupError` naming the group and the particles.
        """
        if self.rollers:
            return self._roller_layers(sample)
        if self.supports is not None:
            return clamped_groups(sample, self.supports, self.punch, axis=self.axis,
                                  layer_thickness=self.layer_thickness, names=("supports", "punch"),
                                  contacts=self.contacts)
        pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
        r = float(np.mean(rad))
        t = self.layer_thickness if self.layer_thickness is not None else r
        z, x = pos[:, self.axis], pos[:, self.span_axis]
        lo, hi = _extent(sample)
        mid = 0.5 * (lo[self.span_axis] + hi[self.span_axis])
        span = self.dimensions(sample)[0]
        bottom, top = z <= z.min() + t, z >= z.max() - t
        supports = (_under(x, bottom, mid - 0.5 * span, self.support_width, r, "support_width", "left support")
                    | _under(x, bottom, mid + 0.5 * span, self.support_width, r, "support_width", "right support"))
        punch = _under(x, top, mid, self.punch_width, r, "punch_width", "punch")
        return supports, punch

    def stage(self, sample: Sample) -> tuple[Sample, "ThreePointBending"]:
        """The specimen the solvers see, and the scene bound to it: with ``rollers``, the beam with its rollers.

        :func:`jaxbpm.solve` calls this first. The rollers (radius ``roller_radius``, default :data:`ROLLER_RADII`
        mean radii) come after the beam's particles, without bonds, with the sample's particle material and a type
        one above the sample's largest; each touches the beam: a support roller the lowest particle within its reach
        under ``centre -/+ span / 2``, the punch roller the highest at mid-span. In 3D each is a row of spheres
        across the beam's width (``round(width / (2 roller_radius))``, at least one, evenly spaced). Staging the
        same sample again gives the same objects (cached).

        Args:
          sample: the beam.

        Returns:
          ``(specimen, scene)``: without ``rollers`` the sample and this scene as they are; else the beam with the
          rollers last and this scene with ``beam_particles`` set (a sample already staged for it is returned as
          it is).

        Raises:
          SceneError: a span that does not fit the beam, or a roller point with no particle within reach.
        """
        if not self.rollers:
            return sample, self
        if self.beam_particles is not None:
            if sample.n_particles > self.beam_particles:
                return sample, self
            return dataclasses.replace(self, beam_particles=None).stage(sample)
        return _STAGED.get(sample, self, lambda: (_with_rollers(sample, self),
                                                  dataclasses.replace(self, beam_particles=sample.n_particles)))

    def _beam_extent(self, sample: Sample) -> tuple[np.ndarray, np.ndarray]:
        """The bounding box of the beam: the sample's, less the rollers of a bound scene."""
        nb = self.beam_particles
        if nb is None or nb >= sample.n_particles:
            return _extent(sample)
        pos, rad = np.asarray(sample.positions)[:nb], np.asarray(sample.radii)[:nb]
        return (pos - rad[:, None]).min(axis=0), (pos + rad[:, None]).max(axis=0)

    def _roller_layers(self, sample: Sample) -> tuple[np.ndarray, np.ndarray]:
        """The rollers of a staged sample: those below the beam's centre hold it, those above press it; each checked
        to touch the beam (a path of bonds and contacts from the supports to the punch)."""
        nb, n = self.beam_particles, sample.n_particles
        if nb is None or n <= nb:
            raise SceneError("ThreePointBending(rollers=True) adds its rollers to the sample: solve it with "
                             "jaxbpm.solve, which adds them, or stage the sample first: sample, scene = "
                             "scene.stage(sample)")
        lo, hi = self._beam_extent(sample)
        z = np.asarray(sample.positions)[:, self.axis]
        added = np.arange(n) >= nb
        centre = 0.5 * (lo[self.axis] + hi[self.axis])
        supports, punch = added & (z < centre), added & (z > centre)
        if not supports.any() or not punch.any():
            raise SceneError(f"the particles past the beam's {nb} are not its rollers (below and above the beam): "
                             "stage the beam with scene.stage(sample)")
        return clamped_groups(sample, supports, punch, axis=self.axis, names=("supports", "punch"), contacts=True)

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


def _under(x: np.ndarray, layer: np.ndarray, centre: float, width: float | None, mean_radius: float, name: str,
           what: str) -> np.ndarray:
    """The particles of ``layer`` within ``width / 2`` of ``centre`` along the span (default width: one mean
    diameter, widened to the nearest particles of the layer where it finds none)."""
    dist = np.where(layer, np.abs(x - centre), np.inf)
    half = 0.5 * width if width is not None else mean_radius
    found = dist <= half
    if found.any():
        return found
    nearest = float(dist.min())
    if width is not None:
        raise SceneError(f"three-point bending: {name}={width:.4g} m finds no particle of its layer under the {what} "
                         f"(at {centre:.6g} m along the span); the nearest lies {nearest:.4g} m from it: widen "
                         f"{name} to more than {2 * nearest:.4g} m, leave it None (the nearest particles), or thicken "
                         "layer_thickness")
    return dist <= nearest + mean_radius


def _with_rollers(sample: Sample, scene: ThreePointBending) -> Sample:
    """The beam with the scene's rollers appended (see :meth:`ThreePointBending.stage`)."""
    pos, rad = np.asarray(sample.positions, np.float64), np.asarray(sample.radii, np.float64)
    radius = float(scene.roller_radius) if scene.roller_radius is not None else ROLLER_RADII * float(np.mean(rad))
    span, width, _ = scene.dimensions(sample)
    lo, hi = _extent(sample)
    ax, sa = scene.axis, scene.span_axis
    mid = 0.5 * (lo[sa] + hi[sa])
    rows = [(mid - 0.5 * span, True), (mid + 0.5 * span, True), (mid, False)]
    if sample.dim == 3:  # a row of spheres across the width
        wa = 3 - ax - sa
        count = max(1, int(round(width / (2.0 * radius))))
        across = [(wa, lo[wa] + (k + 0.5) * width / count) for k in range(count)]
    else:
        across = [(None, 0.0)]
    centres = np.array([_touching(pos, rad, radius, ax, {sa: x, **({} if wa is None else {wa: w})}, below)
                        for x, below in rows for wa, w in across])
    types = np.ones(sample.n_particles, np.int64) if sample.types is None else np.asarray(sample.types, np.int64)
    m = len(centres)
    return sample.replace(positions=np.vstack([pos, centres]), radii=np.concatenate([rad, np.full(m, radius)]),
                          types=np.concatenate([types, np.full(m, types.max() + 1)]), wide_bonds=True)


def _touching(pos: np.ndarray, rad: np.ndarray, radius: float, axis: int, at: dict, below: bool) -> np.ndarray:
    """The centre of a roller of ``radius`` at the coordinates ``at`` (``{axis: value}`` across the load axis),
    moved along ``axis`` until it touches the beam from below (``below``) or above."""
    dh2 = sum((pos[:, k] - v) ** 2 for k, v in at.items())
    reach = dh2 < (radius + rad) ** 2
    if not reach.any():
        raise SceneError(f"three-point bending: no particle of the beam within a roller's reach at {at}: a larger "
                         "roller_radius")
    dz = np.sqrt((radius + rad[reach]) ** 2 - dh2[reach])
    centre = np.zeros(pos.shape[1])
    for k, v in at.items():
        centre[k] = v
    centre[axis] = (pos[reach, axis] - dz).min() if below else (pos[reach, axis] + dz).max()
    return centre
