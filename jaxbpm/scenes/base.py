"""The scene protocol, the answers the scenes share and their helpers.

A scene is a lab test: boundary conditions, a loading and its observables, applied to a
:class:`~jaxbpm.sample.Sample`. :class:`Scene` states everything a solver asks of one; any class with those members is
a scene, without a jaxbpm base class. :class:`BaseScene` holds the answers most scenes share (the solvers, the fit,
the modulus E = K l / A, ...); :class:`AxialScene` the fields and the loading of the scenes pressed along one axis
between two clamped layers or two plane walls.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, Protocol, runtime_checkable

import jax
import numpy as np

from jaxbpm.errors import SceneError
from jaxbpm.physics.bond import check_failure_rule
from jaxbpm.physics.cohesive import CohesiveLaw, resolve_contact_law
from jaxbpm.physics.linear import LinearLaw
from jaxbpm.physics.loading import Loading
from jaxbpm.physics.model import Model, build_model
from jaxbpm.sample import Sample

__all__ = ["Scene", "BaseScene", "AxialScene", "METHODS", "sample_breaks", "lateral_stats", "force_weights"]

#: every solver of a scene: the explicit DEM, the static DSM, the stiffness tensor estimate STE
METHODS = ("dem", "dsm", "ste")


@runtime_checkable
class Scene(Protocol):
    """What the solvers ask of a scene: the contract of ``jaxbpm.solve(sample, scene, method)``.

    A scene prescribes the motion of some particles (``layers``) or of plane walls (``loading``) along ``axis`` to a
    target displacement ``strain x geometry(sample)[0]``, builds the :class:`~jaxbpm.physics.model.Model` of the
    sample it needs and turns the measured force-displacement curve into its observables (stiffness, modulus,
    strength, lateral strain). The DEM uses ``model``, ``loading``, ``compressive_force`` and the observables; the
    DSM ``model``, ``layers`` (or ``loading``'s walls) and the fit; the STE ``geometry``, ``layers`` and the walls'
    law. ``isinstance(x, Scene)`` checks that ``x`` has every member.

    Attributes:
      methods: the solvers that model the scene, some of ``("dem", "dsm", "ste")``; ``jaxbpm.solve`` refuses the
        others and ``method="auto"`` chooses a static solver only for scenes that list both ``"dsm"`` and ``"ste"``.
      axis: the load axis (0, 1 or 2): the driven particles or wall move against it.
      strain: the target displacement over the displacement scale ``geometry(sample)[0]``.
      fit_range: ``(lo, hi)``, the part of the loading (fractions of the target displacement) over which the
        stiffness is fitted.
      contacts: whether particles also interact by contacts (not only by their bonds).
      breakage: whether bonds break (``None``: when the sample's material table has a finite strength; see
        :func:`sample_breaks`).
      cohesive_law: the :class:`~jaxbpm.physics.cohesive.CohesiveLaw` of the contacts, or ``None`` (Hertz-Mindlin
        or the linear law). A scene may also have ``linear_law``: the :class:`~jaxbpm.physics.linear.LinearLaw` of
        its contacts (PFC's linear contact model), or ``None``.
      uses_walls: whether plane walls load the sample (else clamped particles, ``layers``).
      wall_law, wall_stiffness: the walls' contact law (``"hertz"`` or ``"linear"``) and the linear law's stiffness
        [N/m] (``None``: the default of :func:`~jaxbpm.physics.model.build_model`).
      failure_rule: how a bond's stresses combine when it breaks (:data:`jaxbpm.physics.bond.FAILURE_RULES`).

    A scene may also have ``stop_after_peak`` (the strength scenes do): the DEM stops a run with breakage once the
    force has fallen to that fraction of its peak (see :attr:`AxialScene.stop_after_peak`); a scene without it runs
    to its full strain. A scene that adds particles to the sample (the rollers of
    ``ThreePointBending(rollers=True)``) has ``stage(sample) -> (specimen, scene)``: :func:`jaxbpm.solve` calls it
    first and the solvers see the specimen, the added particles last (``stats["added_particles"]`` counts them).
    """

    methods: tuple[str, ...]
    axis: int
    strain: float
    fit_range: tuple[float, float]
    contacts: bool
    breakage: bool | None
    cohesive_law: CohesiveLaw | None
    uses_walls: bool
    wall_law: str
    wall_stiffness: float | None
    failure_rule: str

    def geometry(self, sample: Sample) -> tuple[float, float]:
        """The displacement scale and the section of the sample.

        Args:
          sample: the specimen.

        Returns:
          ``(length, area)``: the length [m] that ``strain`` is a fraction of, and the area [m^2] a force is
          divided by to give a stress.
        """
        ...

    def layers(self, sample: Sample) -> tuple[np.ndarray, np.ndarray]:
        """The clamped particles.

        Args:
          sample: the specimen.

        Returns:
          ``(fixed [n], driven [n])``: boolean masks of the particles held in place and of those moved against
          ``axis`` (every DOF of both prescribed).
        """
        ...

    def model(self, sample: Sample, **overrides) -> Model:
        """The model of the sample this scene needs.

        Args:
          sample: the specimen.
          **overrides: keywords of :func:`~jaxbpm.physics.model.build_model` that replace the scene's (e.g.
            ``contacts=False``, ``breakage=True``, ``pad_to=``).

        Returns:
          The :class:`~jaxbpm.physics.model.Model`.
        """
        ...

    def loading(self, sample: Sample, speed: float) -> Loading:
        """The DEM's boundary conditions.

        Args:
          sample: the specimen.
          speed: the speed [m/s] of the driven particles or wall.

        Returns:
          The :class:`~jaxbpm.physics.loading.Loading` (clamped particles and their velocities, the walls).
        """
        ...

    def compressive_force(self, reaction: np.ndarray) -> np.ndarray:
        """The load on the sample.

        Args:
          reaction: ``[records, W + 2, 3]`` the DEM's reactions (walls, then the fixed and the driven set).

        Returns:
          ``[records]`` the force [N] the scene is loaded by.
        """
        ...

    def fit_mask(self, displacement: np.ndarray, target: float) -> np.ndarray:
        """The records within ``fit_range``.

        Args:
          displacement: ``[records]`` the displacement [m] of each record.
          target: the target displacement [m].

        Returns:
          ``[records]`` boolean mask.
        """
        ...

    def fit_stiffness(self, displacement: np.ndarray, force: np.ndarray, target: float) -> float:
        """The stiffness of a force-displacement curve.

        Args:
          displacement, force: ``[records]`` the curve [m], [N].
          target: the target displacement [m].

        Returns:
          The stiffness K = dF/du [N/m] over ``fit_range``.
        """
        ...

    def modulus(self, stiffness: float, sample: Sample) -> float:
        """The modulus the stiffness of ``sample`` gives.

        Args:
          stiffness: the fitted stiffness K [N/m].
          sample: the specimen.

        Returns:
          The modulus [Pa] (NaN where the scene gives none).
        """
        ...

    def strength(self, peak_force: float, sample: Sample) -> float:
        """The strength the peak force on ``sample`` gives.

        Args:
          peak_force: the peak load [N].
          sample: the specimen.

        Returns:
          The strength [Pa].
        """
        ...

    def transit_length(self, sample: Sample) -> float:
        """The length the DEM's default loading time counts elastic-wave transits along.

        Args:
          sample: the specimen.

        Returns:
          The length [m].
        """
        ...

    def lateral_strain(self, sample: Sample, displacement: np.ndarray) -> dict:
        """The lateral strain and the Poisson ratio of a displacement field.

        Args:
          sample: the specimen.
          displacement: ``[n, >=3]`` particle displacements [m].

        Returns:
          ``{"axial_strain", "lateral_strain", "lateral_strains", "poisson_ratio"}``.

        Raises:
          SceneError: the scene measures no lateral strain, or not on this field.
        """
        ...


def sample_breaks(sample: Sample, breakage: bool | None) -> bool:
    """Whether the bonds of ``sample`` break under a scene's ``breakage`` switch.

    Args:
      sample: the specimen.
      breakage: the scene's switch; ``None`` means "when the material table has a finite strength".

    Returns:
      Whether bonds break.
    """
    if breakage is not None:
        return bool(breakage)
    m = sample.materials
    return bool(np.isfinite(m.tensile_strength).any() or np.isfinite(m.shear_strength).any())


def lateral_stats(scene: Scene, sample: Sample, displacement) -> dict:
    """The scene's lateral strain of a displacement field, where it measures one.

    Args:
      scene: the scene.
      sample: the specimen.
      displacement: ``[n', >=3]`` particle displacements (rows past ``n`` ignored), or ``None``.

    Returns:
      ``scene.lateral_strain(sample, displacement)`` where the displacements are finite, the scene measures a
      lateral strain and the Poisson ratio is finite; else ``{}`` (the result then has no Poisson ratio).
    """
    if displacement is None:
        return {}
    u = np.asarray(displacement)
    if u.ndim != 2 or not np.all(np.isfinite(u[:sample.n_particles, :3])):
        return {}
    try:
        out = scene.lateral_strain(sample, u)
    except SceneError:
        return {}
    return out if np.isfinite(out["poisson_ratio"]) else {}


def force_weights(scene: Scene, n_reactions: int, dim: int = 3) -> np.ndarray:
    """The weights that make a scene's load out of one step's reactions, so that a compiled run can measure it.

    The load of every jaxbpm scene is a fixed linear combination of the reactions (``compressive_force``); the
    weights are read by giving ``compressive_force`` each unit reaction in turn, and checked on a random one.

    Args:
      scene: the scene.
      n_reactions: ``W + 2``, the reactions of one step (walls, then the fixed and the driven set).
      dim: the reactions' components (2 for a two-dimensional sample).

    Returns:
      ``[n_reactions, dim]`` weights ``w`` with ``compressive_force(r) = sum(w * r[k])`` for every record ``k``.

    Raises:
      SceneError: a scene whose load is not linear in the reactions (set its ``stop_after_peak`` to ``None``).
    """
    size = dim * n_reactions
    basis = np.eye(size).reshape(size, n_reactions, dim)
    unit = np.asarray(scene.compressive_force(basis), np.float64)
    weights = unit.reshape(n_reactions, dim) if unit.shape == (size,) else np.zeros((n_reactions, dim))
    probe = np.random.default_rng(0).standard_normal((2, n_reactions, dim))
    got = np.asarray(scene.compressive_force(probe), np.float64)
    linear = got.shape == (2,) and np.allclose(got, np.einsum("krc,rc->k", probe, weights), rtol=1e-12, atol=1e-12)
    if unit.shape != (size,) or not linear:
        raise SceneError(f"{type(scene).__name__}.compressive_force is not a linear combination of the reactions: a "
                         "run cannot track its peak while it runs; give the scene stop_after_peak=None")
    return weights


def _check_stop_after_peak(value):
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool) and 0 < value < 1
    if value is not None and not ok:
        raise SceneError(f"stop_after_peak must be a fraction of the peak force in (0, 1), or None (the full strain), "
                         f"got {value!r}")


def _check_failure_rule(rule):
    check_failure_rule(rule, SceneError)


def _check_fit_range(fit_range):
    lo, hi = fit_range
    if not (0 <= lo < hi <= 1):
        raise SceneError(f"fit_range must satisfy 0 <= lo < hi <= 1, got {fit_range!r}")


def _is_axis(axis) -> bool:
    """Whether ``axis`` is 0, 1 or 2 as a whole number (not ``2.0``, ``True`` or ``"2"``: they would index wrongly)."""
    return isinstance(axis, (int, np.integer)) and not isinstance(axis, bool) and int(axis) in (0, 1, 2)


def _extent(sample: Sample) -> tuple[np.ndarray, np.ndarray]:
    """``(lo [3], hi [3])``: the bounding box of the sample's spheres."""
    pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
    return (pos - rad[:, None]).min(axis=0), (pos + rad[:, None]).max(axis=0)


def _loading(clamped, velocity, wall_points=None, wall_normals=None, wall_velocity=None) -> Loading:
    """A :class:`~jaxbpm.physics.loading.Loading` from NumPy arrays (moved to the device as they are: no program is
    compiled)."""
    dtype = np.dtype(jax.dtypes.canonicalize_dtype(np.float64))
    empty = np.zeros((0, 3))
    put = lambda a, t=dtype: jax.device_put(np.asarray(empty if a is None else a, t))  # noqa: E731
    return Loading(clamped=put(clamped, bool), velocity=put(velocity), wall_points0=put(wall_points),
                   wall_normals=put(wall_normals), wall_velocity=put(wall_velocity))


def _build_model(scene: Scene, sample: Sample, overrides: dict) -> Model:
    """The :class:`~jaxbpm.physics.model.Model` of ``sample`` that ``scene`` needs (its contacts, walls, rotations,
    contact law), with ``overrides`` passed on to :func:`~jaxbpm.physics.model.build_model`."""
    kw = dict(contacts=scene.contacts, walls=scene.wall_law if scene.uses_walls else None, rotations=scene.rotations,
              wall_stiffness=scene.wall_stiffness, failure_rule=scene.failure_rule)
    law = scene.cohesive_law
    if law is not None and overrides.get("contacts", True):
        kw["contact_law"] = law
    # the linear law's scalars go with the model even without contacts: a static solve switches them on later
    linear = getattr(scene, "linear_law", None)
    if linear is not None:
        kw["contact_law"] = linear
    kw.update(overrides)
    return build_model(sample, **kw)


class BaseScene:
    """The answers of :class:`Scene` that most scenes share; a scene class overrides those that differ.

    Served by every solver (:data:`METHODS`), Hertz-Mindlin contacts (no cohesive law), the stiffness fitted over
    ``fit_range``, E = K l / A and the strength F / A over the ``(l, A)`` of ``geometry``, the waves' path the
    length ``l``, and no lateral strain. A subclass provides ``axis``, ``strain``, ``fit_range``, ``contacts``,
    ``rotations``, ``breakage``, ``uses_walls``, ``wall_law``, ``wall_stiffness``, ``failure_rule``, ``geometry`` and
    ``layers``.
    """

    methods: ClassVar[tuple[str, ...]] = METHODS
    cohesive_law: ClassVar[CohesiveLaw | None] = None
    linear_law: ClassVar[LinearLaw | None] = None

    def model(self, sample: Sample, **overrides) -> Model:
        """The model of the sample this scene needs.

        Args:
          sample: the specimen.
          **overrides: keywords of :func:`~jaxbpm.physics.model.build_model` that replace the scene's.

        Returns:
          The :class:`~jaxbpm.physics.model.Model` (the scene's contacts, walls, rotations, contact law and failure
          rule).
        """
        return _build_model(self, sample, overrides)

    def compressive_force(self, reaction: np.ndarray) -> np.ndarray:
        """The load along ``axis``: the mean of the pushing and the holding end.

        Args:
          reaction: ``[records, W + 2, 3]`` the DEM's reactions (walls, then the fixed and the driven set).

        Returns:
          ``[records]`` the compressive force [N].
        """
        ax = self.axis
        if self.uses_walls:
            return 0.5 * (reaction[:, 1, ax] - reaction[:, 0, ax])
        return 0.5 * (reaction[:, 0, ax] - reaction[:, 1, ax])

    def fit_mask(self, displacement: np.ndarray, target: float) -> np.ndarray:
        """The records within ``fit_range`` of the target displacement (its ends included, to 1e-9 relative).

        Args:
          displacement: ``[records]`` [m].
          target: the target displacement [m].

        Returns:
          ``[records]`` boolean mask.
        """
        # both ends with a margin of 1e-9: a record that lies on an end (the run's records are evenly spaced, and
        # the ends are round fractions) is in whatever the last bit of its displacement
        lo, hi = self.fit_range
        return (displacement >= lo * target * (1 - 1e-9)) & (displacement <= hi * target * (1 + 1e-9))

    def fit_stiffness(self, displacement: np.ndarray, force: np.ndarray, target: float) -> float:
        """The least-squares slope dF/du [N/m] over ``fit_range`` of the target displacement.

        Args:
          displacement, force: ``[records]`` the curve [m], [N].
          target: the target displacement [m].

        Returns:
          The stiffness K.

        Raises:
          SceneError: fewer than two records within ``fit_range``.
        """
        sel = self.fit_mask(displacement, target)
        if sel.sum() < 2:
            raise SceneError("too few records in fit_range to fit a stiffness")
        return float(np.polyfit(displacement[sel], force[sel], 1)[0])

    def modulus(self, stiffness: float, sample: Sample) -> float:
        """Young's modulus E = K l / A (``l, A = geometry(sample)``).

        Args:
          stiffness: the fitted stiffness K [N/m].
          sample: the specimen.

        Returns:
          E [Pa].
        """
        length, area = self.geometry(sample)
        return stiffness * length / area

    def strength(self, peak_force: float, sample: Sample) -> float:
        """The peak force over the cross-section A of ``geometry``.

        Args:
          peak_force: the peak load [N].
          sample: the specimen.

        Returns:
          The strength [Pa].
        """
        return peak_force / self.geometry(sample)[1]

    def transit_length(self, sample: Sample) -> float:
        """The length l of ``geometry``: the DEM's default loading time counts elastic-wave transits along it.

        Args:
          sample: the specimen.

        Returns:
          l [m].
        """
        return self.geometry(sample)[0]

    def lateral_strain(self, sample: Sample, displacement) -> dict:
        """No lateral strain: a scene that measures one overrides this.

        Args:
          sample: the specimen.
          displacement: ``[n, >=3]`` particle displacements [m].

        Raises:
          SceneError: always.
        """
        raise SceneError(f"{type(self).__name__} measures no lateral strain")


@dataclasses.dataclass(frozen=True, kw_only=True, repr=False)
class AxialScene(BaseScene):
    """The fields and the loading of a scene pressed along ``axis`` between clamped layers or plane walls.

    A subclass adds its own fields, lists them all in ``_FIELD_ORDER`` (the order of its ``repr``) and provides
    ``boundary``, ``uses_walls``, ``layers`` and ``geometry``. Its fields are keyword-only.

    Args:
      axis: the load axis (0, 1 or 2).
      strain: the target displacement over the displacement scale of ``geometry``.
      layer_thickness: [m], the depth of the clamped layers (default one mean particle radius).
      contacts: particle contacts on (True) or off.
      rotations: rotational DOFs (``None``: the Model decides).
      wall_law, wall_stiffness: the walls' law, ``"hertz"`` (the particle material on a rigid plane) or ``"linear"``
        with ``wall_stiffness`` [N/m]; see :func:`jaxbpm.physics.model.build_model`.
      fit_range: the part of the loading (fractions of the target displacement) over which K is fitted.
      breakage: bonds break in the DEM when their stresses exceed their strengths (``None``: when the sample's
        material table has a finite strength).
      contact_law: ``"hertz"`` (Hertz-Mindlin), ``"linear"`` (PFC's linear contact model,
        :mod:`jaxbpm.physics.linear`, its parameters from the particle material and the params ``contact_emod``,
        ``contact_kratio``, ``friction``; or a :class:`~jaxbpm.physics.linear.LinearLaw` itself) or ``"cohesive"``
        (the stress-dependent cohesive law of :mod:`jaxbpm.physics.cohesive`; DEM only), with its parameters in
        ``cohesive``; or a :class:`~jaxbpm.physics.cohesive.CohesiveLaw` itself.
      cohesive: a :class:`~jaxbpm.physics.cohesive.CohesiveLaw` or a mapping of its fields (``c0``, ``kc``,
        ``c_max``, and optionally ``E``, ``nu``, ``friction``, ``restitution``, ``initial_gap``).
      failure_rule: how a bond's stresses combine when it breaks: ``"separate"`` (tension and shear checked apart,
        the parallel bond of PFC and MUSEN), ``"summed"`` (LAMMPS ``bpm/rotational``) or ``"max"`` (Yade's
        ``CohFrictPhys``); see :data:`jaxbpm.physics.bond.FAILURE_RULES`.
      stop_after_peak: a DEM run with breakage stops once the force has fallen to this fraction of its peak, in
        (0, 1) (default 0.7; PFC's usual stop is at 70-80 % of the peak); ``None``: it runs to the full strain.
        The stop is armed once a bond has broken and the loading is past ``fit_range``, so the stiffness, the peak
        and the curve up to the stop are those of the full run; the run's ``stats["stop_reason"]`` says why it
        ended (:func:`jaxbpm.dem.peak.peak_stop`).
    """

    _FIELD_ORDER: ClassVar[tuple[str, ...]] = ()

    axis: int = 2
    strain: float = 0.02
    layer_thickness: float | None = None
    contacts: bool = False
    rotations: bool | None = None
    wall_law: str = "hertz"
    wall_stiffness: float | None = None
    fit_range: tuple[float, float] = (0.25, 1.0)
    breakage: bool | None = None
    contact_law: Any = "hertz"
    cohesive: Any = None
    failure_rule: str = "separate"
    stop_after_peak: float | None = 0.7

    def __repr__(self) -> str:
        names = self._FIELD_ORDER or tuple(f.name for f in dataclasses.fields(self))
        return f"{type(self).__qualname__}({', '.join(f'{n}={getattr(self, n)!r}' for n in names)})"

    def _check_contacts(self):
        law = resolve_contact_law(self.contact_law, self.cohesive)
        if law is not None and not self.contacts:
            name = "cohesive" if isinstance(law, CohesiveLaw) else "linear"
            raise SceneError(f"contact_law={name!r} needs contacts=True")

    @property
    def cohesive_law(self) -> CohesiveLaw | None:
        """The :class:`~jaxbpm.physics.cohesive.CohesiveLaw` of the scene, or ``None`` (Hertz or linear contacts)."""
        law = resolve_contact_law(self.contact_law, self.cohesive)
        return law if isinstance(law, CohesiveLaw) else None

    @property
    def linear_law(self) -> LinearLaw | None:
        """The :class:`~jaxbpm.physics.linear.LinearLaw` of the scene, or ``None`` (Hertz or cohesive contacts)."""
        law = resolve_contact_law(self.contact_law, self.cohesive)
        return law if isinstance(law, LinearLaw) else None

    def loading(self, sample: Sample, speed: float) -> Loading:
        """The DEM's boundary conditions: the driven layer or the top wall moves against ``axis``.

        Args:
          sample: the specimen.
          speed: [m/s] of the driven layer (moved rigidly) or of the top wall.

        Returns:
          The :class:`~jaxbpm.physics.loading.Loading`: with walls two frictionless planes normal to ``axis``
          touching the outermost spheres, the top one moving; else the fixed and the driven layer clamped.
        """
        n, ax = sample.n_particles, self.axis
        e = np.zeros(sample.dim)
        e[ax] = 1.0
        if self.uses_walls:
            lo, hi = _extent(sample)
            return _loading(np.zeros(n, bool), np.zeros((n, 3)), np.stack([lo[ax] * e, hi[ax] * e]),
                            np.stack([e, -e]), np.stack([0 * e, -speed * e]))
        fixed, driven = self.layers(sample)
        vel = np.zeros((n, sample.dim))
        vel[driven] = -speed * e
        return _loading(fixed | driven, vel)
