"""Scenes: a lab test = boundary conditions + loading + observables, applied to a sample.

:class:`UniaxialCompression` squeezes a sample along one axis, either between two plane walls or by clamping a
bottom layer of particles and moving a top layer rigidly, to a target strain (default 2 %, as in Jarolin & Dosta 2020).
Observables: the force-displacement curve, the stiffness K (least-squares slope over the linear range) and Young's
modulus E = K l / A.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import numpy as np

from jaxbpm.errors import SceneError
from jaxbpm.sample import Sample

__all__ = ["UniaxialCompression", "ThreePointBending", "BrazilianDisc", "sample_breaks"]


def sample_breaks(sample: Sample, breakage) -> bool:
    """Resolve a scene's ``breakage`` switch: ``None`` means "when the material table has a finite strength"."""
    if breakage is not None:
        return bool(breakage)
    m = sample.materials
    return bool(np.isfinite(m.tensile_strength).any() or np.isfinite(m.shear_strength).any())


def _check_failure_rule(rule):
    from jaxbpm.physics.bond import check_failure_rule

    check_failure_rule(rule, SceneError)


def lateral_stats(scene, sample: Sample, displacement) -> dict:
    """``scene.lateral_strain(sample, displacement)`` where the scene measures one and the displacements are finite,
    else ``{}`` (the result then has no Poisson ratio)."""
    if displacement is None or not hasattr(scene, "lateral_strain"):
        return {}
    u = np.asarray(displacement)
    if u.ndim != 2 or not np.all(np.isfinite(u[:sample.n_particles, :3])):
        return {}
    try:
        out = scene.lateral_strain(sample, u)
    except SceneError:
        return {}
    return out if np.isfinite(out["poisson_ratio"]) else {}


def _is_axis(axis) -> bool:
    """Whether ``axis`` is 0, 1 or 2 as a whole number (not ``2.0``, ``True`` or ``"2"``: they would index wrongly)."""
    return isinstance(axis, (int, np.integer)) and not isinstance(axis, bool) and int(axis) in (0, 1, 2)


def _loading(clamped, velocity, wall_points=None, wall_normals=None, wall_velocity=None):
    """A :class:`~jaxbpm.physics.loading.Loading` from NumPy arrays (moved to the device as they are: no program is
    compiled)."""
    from jaxbpm.physics.loading import Loading

    dtype = np.dtype(jax.dtypes.canonicalize_dtype(np.float64))
    empty = np.zeros((0, 3))
    put = lambda a, t=dtype: jax.device_put(np.asarray(empty if a is None else a, t))  # noqa: E731
    return Loading(clamped=put(clamped, bool), velocity=put(velocity), wall_points0=put(wall_points),
                   wall_normals=put(wall_normals), wall_velocity=put(wall_velocity))


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
    contacts: particle contacts on (True) or off. rotations: None = the Model decides.
    contact_law: ``"hertz"`` (Hertz-Mindlin, default) or ``"cohesive"`` (the stress-dependent cohesive law of seed
      002, for cohesive granular samples; DEM only), with its parameters in ``cohesive`` (a
      :class:`~jaxbpm.physics.cohesive.CohesiveLaw` or a mapping of its fields: ``c0``, ``kc``, ``c_max``, and
      optionally ``E``, ``nu``, ``friction``, ``restitution``, ``initial_gap``). ``contact_law`` may also be a
      ``CohesiveLaw`` itself.
    wall_law, wall_stiffness: see :func:`jaxbpm.physics.model.build_model`.
    fit_range: the part of the loading (fractions of the target strain) over which K is fitted.
    breakage: bonds break in the DEM when their stresses exceed their strengths (``None``: when the sample's material
      table has a finite strength). Loading past the peak gives the uniaxial compressive strength (UCS = peak
      stress); see :meth:`to_failure`. The static solvers (DSM, STE) always model the elastic range.
    failure_rule: how a bond's stresses combine when it breaks: ``"separate"`` (default; tension and shear checked
      apart, the parallel bond of PFC and MUSEN), ``"summed"`` (LAMMPS ``bpm/rotational``: all four utilisations
      summed) or ``"max"`` (Yade's ``CohFrictPhys``: each load on its own); see
      :data:`jaxbpm.physics.bond.FAILURE_RULES`. Choose the rule of the code the calibrated strengths are for.
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
    breakage: bool | None = None
    contact_law: Any = "hertz"
    cohesive: Any = None
    failure_rule: str = "separate"

    @classmethod
    def to_failure(cls, strain: float = 0.02, **kw) -> "UniaxialCompression":
        """A compression past the peak: bonds break, particles whose bond broke interact by Hertz-Mindlin contacts,
        and E is fitted over the first 5-25 % of the loading (the elastic part)."""
        kw.setdefault("contacts", True)
        kw.setdefault("fit_range", (0.05, 0.25))
        return cls(strain=strain, breakage=True, **kw)

    def __post_init__(self):
        _check_failure_rule(self.failure_rule)
        if not _is_axis(self.axis):
            raise SceneError(f"axis must be the whole number 0, 1 or 2, got {self.axis!r}")
        if not (0 < self.strain < 0.5):
            raise SceneError(f"strain must lie in (0, 0.5), got {self.strain!r}")
        if self.boundary not in ("layers", "walls"):
            raise SceneError(f"boundary must be 'layers' or 'walls', got {self.boundary!r}")
        if (self.fixed is None) != (self.driven is None):
            raise SceneError("give both fixed and driven masks, or neither")
        lo, hi = self.fit_range
        if not (0 <= lo < hi <= 1):
            raise SceneError(f"fit_range must satisfy 0 <= lo < hi <= 1, got {self.fit_range!r}")
        if self.cohesive_law is not None and not self.contacts:
            raise SceneError("contact_law='cohesive' needs contacts=True")

    @property
    def cohesive_law(self):
        """The :class:`~jaxbpm.physics.cohesive.CohesiveLaw` of the scene, or ``None`` (Hertz contacts)."""
        from jaxbpm.physics.cohesive import resolve_contact_law

        return resolve_contact_law(self.contact_law, self.cohesive)

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
        return _build_model(self, sample, overrides)

    @property
    def uses_walls(self) -> bool:
        return self.boundary == "walls" and self.fixed is None

    def loading(self, sample: Sample, speed: float):
        """DEM boundary conditions for a compression at ``speed`` [m/s] of the driven set / top wall."""
        n, ax = sample.n_particles, self.axis
        e = np.zeros(3)
        e[ax] = 1.0
        if self.uses_walls:
            pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
            lo, hi = (pos[:, ax] - rad).min(), (pos[:, ax] + rad).max()
            return _loading(np.zeros(n, bool), np.zeros((n, 3)), np.stack([lo * e, hi * e]), np.stack([e, -e]),
                            np.stack([0 * e, -speed * e]))
        fixed, driven = self.layers(sample)
        vel = np.zeros((n, 3))
        vel[driven] = -speed * e
        return _loading(fixed | driven, vel)

    def modulus(self, stiffness: float, sample: Sample) -> float:
        """Young's modulus E = K l / A [Pa]."""
        length, area = self.geometry(sample)
        return stiffness * length / area

    def strength(self, peak_force: float, sample: Sample) -> float:
        """Uniaxial compressive strength: peak force over the cross-section [Pa]."""
        return peak_force / self.geometry(sample)[1]

    def compressive_force(self, reaction: np.ndarray) -> np.ndarray:
        """Compressive force [N] per record from the DEM reactions ``[steps, W+2, 3]`` (mean of both ends)."""
        ax = self.axis
        if self.uses_walls:
            return 0.5 * (reaction[:, 1, ax] - reaction[:, 0, ax])
        return 0.5 * (reaction[:, 0, ax] - reaction[:, 1, ax])

    def fit_mask(self, displacement: np.ndarray, target: float) -> np.ndarray:
        """The records within ``fit_range`` of the target displacement."""
        lo, hi = self.fit_range
        return (displacement >= lo * target) & (displacement <= hi * target * (1 + 1e-9))

    def fit_stiffness(self, displacement: np.ndarray, force: np.ndarray, target: float) -> float:
        """Least-squares slope dF/du over ``fit_range`` of the target displacement."""
        sel = UniaxialCompression.fit_mask(self, displacement, target)  # also for ThreePointBending
        if sel.sum() < 2:
            raise SceneError("too few records in fit_range to fit a stiffness")
        return float(np.polyfit(displacement[sel], force[sel], 1)[0])

    def lateral_strain(self, sample: Sample, displacement) -> dict:
        """Axial and lateral strain in the middle third of the sample and the Poisson ratio they give.

        displacement: ``[n, >=3]`` particle displacements (a static solution, or a DEM run's positions less the
        initial ones; extra rows, e.g. a size class's padding, are ignored). Over the particles whose centres lie in
        the middle third of the sample along the axis (away from the clamped or pressed ends, whose constraint holds
        the lateral expansion back), least-squares slopes of ``u_axis`` against ``x_axis`` (the axial strain) and of
        each lateral ``u_k`` against ``x_k`` (two lateral strains; their intercepts take rigid translations).
        Returns ``{"axial_strain", "lateral_strain" (the mean of the two), "lateral_strains" [2],
        "poisson_ratio" = -lateral / axial}``. The end layers of ``boundary="layers"`` are clamped laterally too:
        on stubby samples (length / width below ~2) the middle third still feels them (a lower ratio); frictionless
        walls (``boundary="walls"``) leave the ends free.
        """
        pos = np.asarray(sample.positions, np.float64)
        n = len(pos)
        u = np.asarray(displacement, np.float64)[:n, :3]
        ax = self.axis
        lateral = [k for k in range(3) if k != ax]
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


@dataclasses.dataclass(frozen=True)
class ThreePointBending:
    """Three-point bending of a bonded beam: two supports under its ends, a punch pressed down at mid-span.

    The beam spans ``span_axis`` (default x); the load acts against ``axis`` (default z, downwards). The supports are
    the particles of the bottom layer (``layer_thickness``, default one mean radius) within ``support_width`` of the
    points ``centre -/+ span / 2``; the punch is the top-layer particles within ``punch_width`` of mid-span. Both
    are clamped (every DOF prescribed): the supports fixed, the punch moved down at constant speed to a deflection
    of ``strain`` x beam height. (A clamped row of particles stands for a roller or a cylindrical punch; it also
    holds rotation, which matters little when the supports are narrow against the span.)

    Observables: load-deflection curve, stiffness K = dF/dw over ``fit_range``, the beam modulus
    E = K S^3 / (48 I) with I = b h^3 / 12, and the flexural strength sigma_f = 3 F_peak S / (2 b h^2) (S: span,
    b: width, h: height).
    span: [m], default 80 % of the beam length. support_width, punch_width: [m], default one mean diameter.
    contacts: Hertz-Mindlin contacts (on by default: broken bonds fall back to them).
    breakage, failure_rule: as in :class:`UniaxialCompression`.
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

    boundary = "layers"
    wall_law = "hertz"
    wall_stiffness = None

    def __post_init__(self):
        _check_failure_rule(self.failure_rule)
        if not _is_axis(self.axis) or not _is_axis(self.span_axis) or self.axis == self.span_axis:
            raise SceneError(f"axis and span_axis must be two different axes of 0, 1, 2, got {self.axis!r} and "
                             f"{self.span_axis!r}")
        if not (0 < self.strain < 1):
            raise SceneError(f"strain (deflection / beam height) must lie in (0, 1), got {self.strain!r}")
        lo, hi = self.fit_range
        if not (0 <= lo < hi <= 1):
            raise SceneError(f"fit_range must satisfy 0 <= lo < hi <= 1, got {self.fit_range!r}")
        for name in ("span", "support_width", "punch_width", "layer_thickness"):
            v = getattr(self, name)
            if v is not None and not v > 0:
                raise SceneError(f"{name} must be positive [m], got {v!r}")

    @property
    def uses_walls(self) -> bool:
        return False

    def _extent(self, sample: Sample):
        pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
        return (pos - rad[:, None]).min(axis=0), (pos + rad[:, None]).max(axis=0)

    def dimensions(self, sample: Sample) -> tuple[float, float, float]:
        """Span S, width b and height h of the beam [m]."""
        lo, hi = self._extent(sample)
        size = hi - lo
        width_axis = 3 - self.axis - self.span_axis
        span = self.span if self.span is not None else 0.8 * float(size[self.span_axis])
        if span >= size[self.span_axis]:
            raise SceneError(f"span {span:.4g} m must be shorter than the beam ({size[self.span_axis]:.4g} m)")
        return float(span), float(size[width_axis]), float(size[self.axis])

    def layers(self, sample: Sample) -> tuple[np.ndarray, np.ndarray]:
        """Boolean masks ``(supports, punch)`` of the clamped particles."""
        pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
        d = 2.0 * float(np.mean(rad))
        t = self.layer_thickness if self.layer_thickness is not None else 0.5 * d
        z, x = pos[:, self.axis], pos[:, self.span_axis]
        lo, hi = self._extent(sample)
        mid = 0.5 * (lo[self.span_axis] + hi[self.span_axis])
        span = self.dimensions(sample)[0]
        ws = self.support_width if self.support_width is not None else d
        wp = self.punch_width if self.punch_width is not None else d
        bottom, top = z <= z.min() + t, z >= z.max() - t
        supports = bottom & ((np.abs(x - (mid - 0.5 * span)) <= 0.5 * ws) | (np.abs(x - (mid + 0.5 * span)) <= 0.5 * ws))
        punch = top & (np.abs(x - mid) <= 0.5 * wp)
        left, right = supports & (x < mid), supports & (x > mid)
        if not left.any() or not right.any() or not punch.any():
            raise SceneError("three-point bending: no particle found under a support or under the punch; widen "
                             "support_width / punch_width or layer_thickness")
        return supports, punch

    def geometry(self, sample: Sample) -> tuple[float, float]:
        """Beam height h (the deflection scale) and the cross-section b h [m^2]."""
        span, width, height = self.dimensions(sample)
        return height, width * height

    def transit_length(self, sample: Sample) -> float:
        """The span: the DEM's default loading time counts elastic-wave transits along it."""
        return self.dimensions(sample)[0]

    def model(self, sample: Sample, **overrides):
        from jaxbpm.physics.model import build_model

        kw = dict(contacts=self.contacts, walls=None, rotations=self.rotations, failure_rule=self.failure_rule)
        kw.update(overrides)
        return build_model(sample, **kw)

    def loading(self, sample: Sample, speed: float):
        """DEM boundary conditions: supports fixed, punch moved down at ``speed`` [m/s]."""
        supports, punch = self.layers(sample)
        vel = np.zeros((sample.n_particles, 3))
        vel[punch, self.axis] = -speed
        return _loading(supports | punch, vel)

    def compressive_force(self, reaction: np.ndarray) -> np.ndarray:
        """Punch force [N] (mean of the punch's push and the supports' reaction)."""
        ax = self.axis
        return 0.5 * (reaction[:, 0, ax] - reaction[:, 1, ax])

    def fit_stiffness(self, displacement, force, target) -> float:
        return UniaxialCompression.fit_stiffness(self, displacement, force, target)

    def modulus(self, stiffness: float, sample: Sample) -> float:
        """Beam modulus E = K S^3 / (48 I), I = b h^3 / 12 [Pa] (Euler-Bernoulli, simply supported)."""
        span, b, h = self.dimensions(sample)
        return stiffness * span**3 / (48.0 * b * h**3 / 12.0)

    def strength(self, peak_force: float, sample: Sample) -> float:
        """Flexural strength sigma_f = 3 F S / (2 b h^2) [Pa]."""
        span, b, h = self.dimensions(sample)
        return 3.0 * peak_force * span / (2.0 * b * h**2)


@dataclasses.dataclass(frozen=True)
class BrazilianDisc:
    """Brazilian (diametral compression) test of a bonded disc: a short cylinder squeezed across a diameter until it
    splits.

    The disc's axis is ``disc_axis`` (default z, the axis of :func:`jaxbpm.generate.cylinder`; a disc is
    ``generate.cylinder(n, aspect=t / D)``, ISRM: t / D = 0.5); the load acts along ``axis`` (default x, normal to
    the disc axis). The bottom platen stays, the top one moves against ``axis`` to a displacement of ``strain`` x D.
    platens: ``"strips"`` (default): two rigid loading strips, the particles of the rim within ``layer_thickness``
    (default one mean radius) of its lowest (highest) point along ``axis`` and within half of ``strip_width``
    (default D / 5: a contact arc 2 alpha of about 23 degrees, as the curved ISRM jaws and flattened discs give) of
    the loaded diameter, clamped and moved rigidly (every DOF prescribed, as the layers of :class:`UniaxialCompression`).
    ``"walls"``: two flat frictionless plane walls normal to ``axis`` touching the outermost spheres (the walls of
    ``UniaxialCompression(boundary="walls")``, law ``wall_law``). A flat platen touches a rough rim at a few
    particles only: on discs of ten or so particles across the rim crushes there first and the force keeps rising
    (no clean peak), which is why the strips are the default; on the discs measured the strips split the disc along
    the loaded diameter, tensile breaks only.

    Observables: the load-displacement curve of the platen, the stiffness K = dF/du over ``fit_range`` [N/m] and
    the Brazilian tensile strength BTS = 2 F_peak / (pi D t) at the peak force (Hondros' solution for a disc under
    diametral line loads: the tensile stress across the loaded diameter). ``modulus`` is NaN: the platen
    displacement of a disc is mostly the deformation near the loaded arcs, so K is no measure of Young's modulus.
    The curve's strain is u / D and its stress F / (D t) (``Result.area`` = D t), so stress x 2 / pi is the
    tensile stress of Hondros' solution.

    D: ``diameter`` [m], default the diameter of the sample's cylinder domain (a sample without one: the spheres'
    extent along ``axis``). t: ``thickness`` [m], default the domain's height (the spheres' extent along
    ``disc_axis``). Give both when the disc is not a generated z-axis cylinder.
    contacts: Hertz-Mindlin contacts between particles (on: broken bonds fall back to them), or ``contact_law`` /
    ``cohesive`` as in :class:`UniaxialCompression`. rotations: None = the Model decides.
    wall_law, wall_stiffness (``platens="walls"``): ``"hertz"`` (the particle material on a rigid plane) or
    ``"linear"`` with ``wall_stiffness`` [N/m]; see :func:`jaxbpm.physics.model.build_model`.
    breakage: bonds break when their stresses exceed their strengths (on by default; ``None``: when the sample's
    material table has a finite strength). The default ``strain`` (2 % of D) goes past the peak of the discs
    measured (E = 1 GPa bonds of 5 MPa tensile strength peak at about 1.2 %); stronger bonds need more.
    DEM only: the static solvers (DSM, STE) raise :class:`~jaxbpm.errors.SceneError`.
    failure_rule: as in :class:`UniaxialCompression`.
    """

    axis: int = 0
    disc_axis: int = 2
    strain: float = 0.02
    diameter: float | None = None
    thickness: float | None = None
    contacts: bool = True
    rotations: bool | None = None
    wall_law: str = "hertz"
    wall_stiffness: float | None = None
    fit_range: tuple[float, float] = (0.05, 0.25)
    breakage: bool | None = True
    contact_law: Any = "hertz"
    cohesive: Any = None
    platens: str = "strips"
    strip_width: float | None = None
    layer_thickness: float | None = None
    failure_rule: str = "separate"

    fixed = None
    driven = None

    def __post_init__(self):
        _check_failure_rule(self.failure_rule)
        if not _is_axis(self.axis) or not _is_axis(self.disc_axis) or self.axis == self.disc_axis:
            raise SceneError(f"axis (the load) and disc_axis must be two different axes of 0, 1, 2, got "
                             f"{self.axis!r} and {self.disc_axis!r}")
        if not (isinstance(self.strain, (int, float, np.integer, np.floating)) and 0 < self.strain < 0.5):
            raise SceneError(f"strain (platen displacement / disc diameter) must lie in (0, 0.5), got {self.strain!r}")
        for name in ("diameter", "thickness"):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, (int, float, np.integer, np.floating)) and np.isfinite(v)
                                      and v > 0):
                raise SceneError(f"{name} must be a positive length [m], got {v!r}")
        if self.wall_law not in ("hertz", "linear"):
            raise SceneError(f"wall_law must be 'hertz' or 'linear', got {self.wall_law!r}")
        if self.wall_law == "linear" and self.wall_stiffness is None:
            raise SceneError("wall_law='linear' needs wall_stiffness [N/m]")
        if self.wall_stiffness is not None and not self.wall_stiffness > 0:
            raise SceneError(f"wall_stiffness must be positive, got {self.wall_stiffness!r}")
        lo, hi = self.fit_range
        if not (0 <= lo < hi <= 1):
            raise SceneError(f"fit_range must satisfy 0 <= lo < hi <= 1, got {self.fit_range!r}")
        if self.cohesive_law is not None and not self.contacts:
            raise SceneError("contact_law='cohesive' needs contacts=True")
        if self.platens not in ("walls", "strips"):
            raise SceneError(f"platens must be 'walls' or 'strips', got {self.platens!r}")
        for name in ("strip_width", "layer_thickness"):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, (int, float, np.integer, np.floating)) and v > 0):
                raise SceneError(f"{name} must be a positive length [m], got {v!r}")

    @property
    def boundary(self) -> str:
        """``"walls"`` (flat platens) or ``"layers"`` (clamped strips), as :class:`UniaxialCompression` says it."""
        return "walls" if self.platens == "walls" else "layers"

    @property
    def cohesive_law(self):
        """The :class:`~jaxbpm.physics.cohesive.CohesiveLaw` of the scene, or ``None`` (Hertz contacts)."""
        from jaxbpm.physics.cohesive import resolve_contact_law

        return resolve_contact_law(self.contact_law, self.cohesive)

    @property
    def uses_walls(self) -> bool:
        """Whether the platens are plane walls (``platens="walls"``)."""
        return self.platens == "walls"

    def layers(self, sample: Sample) -> tuple[np.ndarray, np.ndarray]:
        """``platens="strips"``: boolean masks ``(fixed, driven)`` of the bottom and the top strip's particles."""
        pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
        d = self.dimensions(sample)[0]
        lo, hi = self._extent(sample)
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

    def _extent(self, sample: Sample):
        pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
        return (pos - rad[:, None]).min(axis=0), (pos + rad[:, None]).max(axis=0)

    def dimensions(self, sample: Sample) -> tuple[float, float]:
        """Disc diameter D and thickness t [m]."""
        domain = sample.domain
        cylinder = domain is not None and domain.kind == "cylinder"
        if cylinder and self.disc_axis != 2 and (self.diameter is None or self.thickness is None):
            raise SceneError(f"the sample's domain is a cylinder along z, but disc_axis is {self.disc_axis}: give "
                             "disc_axis=2 (or diameter and thickness)")
        lo, hi = self._extent(sample)
        size = np.subtract(domain.hi, domain.lo) if cylinder else hi - lo
        d = float(self.diameter) if self.diameter is not None else float(size[self.axis])
        t = float(self.thickness) if self.thickness is not None else float(size[self.disc_axis])
        if not (d > 0 and t > 0):
            raise SceneError(f"disc diameter ({d:.4g} m) and thickness ({t:.4g} m) must be positive")
        return d, t

    def geometry(self, sample: Sample) -> tuple[float, float]:
        """The diameter D (the displacement scale: strain = u / D) and the diametral section D t [m^2]."""
        d, t = self.dimensions(sample)
        return d, d * t

    def transit_length(self, sample: Sample) -> float:
        """The diameter: the DEM's default loading time counts elastic-wave transits across it."""
        return self.dimensions(sample)[0]

    #: the solvers that model this scene: a disc between platens is a contact problem loaded to failure, which the
    #: static solvers (DSM, STE) do not model
    methods = ("dem",)

    def model(self, sample: Sample, **overrides):
        """The :class:`~jaxbpm.physics.model.Model` this scene needs (the DEM's: :attr:`methods`)."""
        return _build_model(self, sample, overrides)

    def loading(self, sample: Sample, speed: float):
        """DEM boundary conditions: the platens touch the rim; the top one moves at ``speed`` [m/s] against
        ``axis``."""
        n, ax = sample.n_particles, self.axis
        e = np.zeros(3)
        e[ax] = 1.0
        if not self.uses_walls:
            fixed, driven = self.layers(sample)
            vel = np.zeros((n, 3))
            vel[driven] = -speed * e
            return _loading(fixed | driven, vel)
        lo, hi = self._extent(sample)
        return _loading(np.zeros(n, bool), np.zeros((n, 3)), np.stack([lo[ax] * e, hi[ax] * e]), np.stack([e, -e]),
                        np.stack([0 * e, -speed * e]))

    def compressive_force(self, reaction: np.ndarray) -> np.ndarray:
        """Platen force [N] per record from the DEM reactions ``[steps, W+2, 3]`` (mean of both platens)."""
        ax = self.axis
        if self.uses_walls:
            return 0.5 * (reaction[:, 1, ax] - reaction[:, 0, ax])
        return 0.5 * (reaction[:, 0, ax] - reaction[:, 1, ax])

    def fit_stiffness(self, displacement, force, target) -> float:
        """Least-squares slope dF/du [N/m] over ``fit_range`` of the target displacement."""
        return UniaxialCompression.fit_stiffness(self, displacement, force, target)

    def modulus(self, stiffness: float, sample: Sample) -> float:
        """NaN: the platen stiffness of a disc is mostly its contact flattening, not a measure of E."""
        return float("nan")

    def strength(self, peak_force: float, sample: Sample) -> float:
        """Brazilian tensile strength BTS = 2 F / (pi D t) [Pa]."""
        d, t = self.dimensions(sample)
        return 2.0 * peak_force / (np.pi * d * t)


def _build_model(scene, sample: Sample, overrides: dict):
    """The :class:`~jaxbpm.physics.model.Model` of ``sample`` that ``scene`` needs (its contacts, walls, rotations,
    contact law), with ``overrides`` passed on to :func:`~jaxbpm.physics.model.build_model`."""
    from jaxbpm.physics.model import build_model

    kw = dict(contacts=scene.contacts, walls=scene.wall_law if scene.uses_walls else None, rotations=scene.rotations,
              wall_stiffness=scene.wall_stiffness, failure_rule=scene.failure_rule)
    law = scene.cohesive_law
    if law is not None and overrides.get("contacts", True):
        kw["contact_law"] = law
    kw.update(overrides)
    return build_model(sample, **kw)
