"""Stress-dependent cohesive contacts (the DEM model of Irazabal et al. 2023, Eq. 2-17).

A linear spring-dashpot contact with an attractive cohesive stress that remembers the largest compressive stress the
contact has carried. For two spheres ``i, j`` with overlap ``delta = r_i + r_j - |x_j - x_i|`` (Eq. 2) in contact
(``delta > 0``)::

    l   = r_i + r_j - delta                                    contact length              (Eq. 10)
    A   = pi r_ij^2 (r_i + r_j) / l,   r_ij = (r_i + r_j) / 2   contact area               (Eq. 11)
    k_N = E^ A / l,                    E^ = E_i E_j / (E_i + E_j) = E / 2 for one material  (Eq. 4)
    d_N = 2 gamma sqrt(m^ k_N),        m^ = m_i m_j / (m_i + m_j)                          (Eq. 5, 6)
    gamma = -ln(COR) / sqrt(pi^2 + ln^2(COR))                                               (Eq. 7)
    F_N = k_N delta + d_N d(delta)/dt - c^ A                   (repulsion > 0)             (Eq. 3, 12)

so the stiffness grows with the indentation (``A / l``). The cohesive stress ``c^`` of each contact (Eq. 14, Fig. 7):

* contacts that exist when the run starts (overlap, or a surface gap up to ``initial_gap``) start with
  ``c^ = c_0``; contacts formed (or re-formed, after the particles separated) later start with ``c^ = 0``;
* after every step ``c^ <- min(c_max, max(c^, k_c sigma_N))`` with ``sigma_N = F_N / A`` (Eq. 13), so that
  ``c^ = min(c_max, max(c_0 or 0, k_c max_t sigma_N(t)))`` over the steps before the current one (Eq. 14 uses the
  stresses up to step ``nt - 1``): it never decreases while the particles touch (unloading keeps it), is capped at
  ``c_max``, and is lost when they separate.

``sigma_N`` (and the Coulomb limit below) use the compressive spring-dashpot part ``max(k_N delta + d_N
d(delta)/dt, 0)`` of F_N, i.e. the contact pressure without the cohesive pull (as in the reference implementation
of the law, ``DEM_D_Stress_Dependent_Cohesive`` of the Kratos DEM application): with the net force the cohesion of a
contact at rest would balance its own pressure and never grow, and a cohesive contact at rest would have no
friction. The normal dashpot is not clipped, so the restitution of a collision is exactly the COR of Eq. 7 (for small
indentations, where k_N is nearly constant).

Tangential force (Eq. 15-17), regularised Coulomb::

    k_T = kappa k_N,  kappa = 2 (1 - nu) / (2 - nu),   d_T = 2 gamma sqrt(m^ k_T)
    F_T^(n+1) = F_T^n + k_T dxi - d_T dxi/dt   (on j; dxi: slip of j's contact point relative to i's in this step)

limited by ``|F_T| <= mu max(k_N delta + d_N d(delta)/dt, 0)``; when the limit is reached the force is scaled onto
it and the stored elastic force becomes the limit force. The stored elastic force is kept in the current tangent
plane (same length) as the contact turns. Particles do not rotate in Irazabal et al. 2023 (models with this law
default to 3 DOF per particle); when they do, the tangential force gives moments as in :mod:`jaxbpm.physics.contact`.

Per-contact state carried by the DEM: the elastic tangential force ``spring`` ``[C, 3]`` [N] and the cohesion
history ``cohesion`` ``[C]`` [Pa]. A negative value ``-c_0`` marks an initial contact that has not touched yet (it
will start at ``c_0``); ``0`` a new contact.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from typing import Any, Mapping, NamedTuple

import jax.numpy as jnp

from jaxbpm.errors import SceneError
from jaxbpm.physics.vec import cross, dot, once, safe_sqrt, stack

__all__ = ["law_components",
           "CohesiveLaw", "CohesiveParams", "CohesiveForces", "resolve_contact_law", "restitution_damping",
           "cohesive_contact", "normal_stiffness", "contact_area", "pair_forces", "update_cohesion"]


@dataclasses.dataclass(frozen=True)
class CohesiveLaw:
    """Parameters of the stress-dependent cohesive contact law (Irazabal et al. 2023, Table 1 names them).

    With ``c0 = kc = c_max = 0`` the law is the plain linear spring-dashpot law with Coulomb friction.

    Attributes:
        c0: initial cohesion c_0 [Pa] of the contacts present at the start.
        kc: amount of cohesion from stress k_c [-].
        c_max: maximum cohesion [Pa] (``>= c0``).
        E: Young's modulus of the particles [Pa]; ``None`` takes it from the sample's
            :class:`~jaxbpm.sample.ParticleMaterial`, like the three below.
        nu: Poisson's ratio of the particles.
        friction: local friction coefficient mu.
        restitution: coefficient of restitution (COR).
        initial_gap: pairs whose surface gap is at most this [m] when the run starts count as initial contacts
            (default 0: only overlapping pairs).

    Raises:
        SceneError: a parameter out of its range (negative, not finite, ``c_max < c0``, ...).
    """

    c0: float = 0.0
    kc: float = 0.0
    c_max: float = 0.0
    E: float | None = None
    nu: float | None = None
    friction: float | None = None
    restitution: float | None = None
    initial_gap: float = 0.0

    def __post_init__(self):
        def bad(name, why):
            raise SceneError(f"cohesive contact law: {name}={getattr(self, name)!r} {why}")

        for name in ("c0", "kc", "c_max", "initial_gap"):
            v = getattr(self, name)
            if not (isinstance(v, numbers.Real) and math.isfinite(v) and v >= 0):
                bad(name, "must be a finite number >= 0")
        if self.c_max < self.c0:
            raise SceneError(f"cohesive contact law: c_max ({self.c_max!r} Pa) must be at least c0 ({self.c0!r} Pa)")
        checks = {"E": lambda v: v > 0, "nu": lambda v: -1 < v < 0.5, "friction": lambda v: v >= 0,
                  "restitution": lambda v: 0 < v <= 1}
        for name, ok in checks.items():
            v = getattr(self, name)
            if v is not None and not (isinstance(v, numbers.Real) and math.isfinite(v) and ok(v)):
                bad(name, {"E": "must be > 0 [Pa]", "nu": "must lie in (-1, 0.5)", "friction": "must be >= 0",
                           "restitution": "must lie in (0, 1]"}[name])

    def params(self, particle_material, dtype=None) -> "CohesiveParams":
        """The law's scalars as JAX arrays.

        Args:
            particle_material: the sample's :class:`~jaxbpm.sample.ParticleMaterial`, for the values left ``None``.
            dtype: the arrays' type (default JAX's).

        Returns:
            The :class:`CohesiveParams`.
        """
        pm = particle_material
        get = lambda name: float(getattr(pm, name) if getattr(self, name) is None else getattr(self, name))  # noqa
        a = lambda v: jnp.asarray(v, dtype)  # noqa: E731
        return CohesiveParams(E=a(get("E")), nu=a(get("nu")), friction=a(get("friction")),
                              restitution=a(get("restitution")), c0=a(self.c0), kc=a(self.kc), c_max=a(self.c_max),
                              initial_gap=a(self.initial_gap))


def resolve_contact_law(contact_law: Any = "hertz", cohesive: CohesiveLaw | Mapping | None = None):
    """The contact law a scene asks for.

    Args:
        contact_law: ``"hertz"`` (default), ``"linear"`` (PFC's linear contact model,
            :mod:`jaxbpm.physics.linear`), ``"cohesive"``, a :class:`~jaxbpm.physics.linear.LinearLaw` or a
            :class:`CohesiveLaw`.
        cohesive: the law's parameters (a :class:`CohesiveLaw` or a mapping of its fields) for
            ``contact_law="cohesive"``.

    Returns:
        ``None`` for Hertz-Mindlin contacts, else the :class:`~jaxbpm.physics.linear.LinearLaw` or the
        :class:`CohesiveLaw`.

    Raises:
        SceneError: an unknown law or parameter, or cohesive parameters given twice or for another law.
    """
    from jaxbpm.physics.linear import LinearLaw

    if isinstance(contact_law, CohesiveLaw):
        if cohesive is not None:
            raise SceneError("give the cohesive parameters either as contact_law=CohesiveLaw(...) or as cohesive=..., "
                             "not both")
        return contact_law
    if isinstance(contact_law, LinearLaw) or contact_law in ("hertz", "linear"):
        if cohesive is not None:
            name = contact_law if isinstance(contact_law, str) else "LinearLaw(...)"
            raise SceneError(f"cohesive contact parameters were given with contact_law={name!r}; use "
                             "contact_law='cohesive'")
        return LinearLaw() if contact_law == "linear" else (None if contact_law == "hertz" else contact_law)
    if contact_law != "cohesive":
        raise SceneError(f"unknown contact law {contact_law!r}; use 'hertz', 'linear', 'cohesive', a LinearLaw or a "
                         "CohesiveLaw")
    if cohesive is None:
        return CohesiveLaw()
    if isinstance(cohesive, CohesiveLaw):
        return cohesive
    if isinstance(cohesive, Mapping):
        unknown = set(cohesive) - {f.name for f in dataclasses.fields(CohesiveLaw)}
        if unknown:
            raise SceneError(f"cohesive contact law: unknown parameters {sorted(unknown)}; known: "
                             f"{[f.name for f in dataclasses.fields(CohesiveLaw)]}")
        return CohesiveLaw(**cohesive)
    raise SceneError(f"cohesive must be a CohesiveLaw or a mapping of its fields, got {type(cohesive).__name__}")


class CohesiveParams(NamedTuple):
    """The law's scalars (a pytree; calibrators may override any of them through the Model's params).

    Attributes:
        E: particle Young's modulus [Pa] (E^ = E / 2).
        nu: Poisson's ratio (kappa = 2 (1 - nu) / (2 - nu)).
        friction: mu.
        restitution: the COR.
        c0: initial cohesion [Pa].
        kc: amount of cohesion from stress [-].
        c_max: maximum cohesion [Pa].
        initial_gap: [m].
    """

    E: Any
    nu: Any
    friction: Any
    restitution: Any
    c0: Any
    kc: Any
    c_max: Any
    initial_gap: Any


class CohesiveForces(NamedTuple):
    """Forces of a cohesive contact: :func:`cohesive_contact`'s output for one pair, ``[C, ...]`` for all.

    Attributes:
        f_i: ``[3]`` force on particle i [N] (on j: ``-f_i``).
        m_i: ``[3]`` moment on i [N m].
        m_j: ``[3]`` moment on j [N m].
        normal: F_N [N] (repulsion > 0; negative when cohesion pulls).
        spring: ``[3]`` stored elastic tangential force on j [N].
        sliding: bool, the Coulomb limit is reached.
        active: bool, the pair is in contact.
        cohesion: the cohesion history after this step (see the module docstring).
        stress: sigma_N [Pa] of this step (compressive part over A; 0 out of contact).
    """

    f_i: Any
    m_i: Any
    m_j: Any
    normal: Any
    spring: Any
    sliding: Any
    active: Any
    cohesion: Any
    stress: Any


def restitution_damping(restitution):
    """The fraction of critical damping that gives a coefficient of restitution (Eq. 7).

    Args:
        restitution: the COR, in (0, 1].

    Returns:
        gamma = -ln(COR) / sqrt(pi^2 + ln^2(COR)).
    """
    log_e = jnp.log(restitution)
    return -log_e / jnp.sqrt(jnp.pi**2 + log_e**2)


def contact_area(r_i, r_j, overlap):
    """The contact area (Eq. 11).

    Args:
        r_i, r_j: the radii [m].
        overlap: the overlap delta [m].

    Returns:
        A = pi ((r_i + r_j) / 2)^2 (r_i + r_j) / (r_i + r_j - delta) [m^2].
    """
    rsum = r_i + r_j
    return jnp.pi * (0.5 * rsum) ** 2 * rsum / (rsum - overlap)


def normal_stiffness(r_i, r_j, overlap, E):
    """The normal stiffness (Eq. 4, 10, 11).

    Args:
        r_i, r_j: the radii [m].
        overlap: the overlap delta [m].
        E: the particles' Young's modulus [Pa].

    Returns:
        k_N = E^ A / l [N/m], with E^ = E / 2 and l = r_i + r_j - delta.
    """
    return 0.5 * E * contact_area(r_i, r_j, overlap) / (r_i + r_j - overlap)


def update_cohesion(history, active, stress, p: CohesiveParams):
    """The cohesion history after a step (Eq. 14 with the cap, Fig. 7).

    Args:
        history: ``[C]`` the cohesion history (``-c_0``: a pending initial contact).
        active: ``[C]`` bool, in contact.
        stress: ``[C]`` sigma_N of this step [Pa].
        p: the law's scalars.

    Returns:
        ``[C]``: in contact ``min(c_max, max(c, k_c sigma))`` with ``c = |history|`` (a pending initial contact
        starts at c_0); out of contact 0 (pending ones stay).
    """
    grown = jnp.minimum(p.c_max, jnp.maximum(jnp.abs(history), p.kc * stress))
    return jnp.where(active, grown, jnp.where(history < 0, history, 0.0))


def law_components(d, r_i, r_j, m_i, m_j, spring, dxi, v_rel, history, p: CohesiveParams, valid=True):
    """The law on components, for one pair (scalars) or all pairs at once (``[C]`` arrays).

    Written like :func:`jaxbpm.physics.contact.law_components`.

    Args:
        d: ``(x, y, z)``, x_j - x_i [m].
        r_i, r_j: the radii [m].
        m_i, m_j: the masses [kg].
        spring: ``(x, y, z)``, the stored tangential force on j [N].
        dxi: ``(x, y, z)``, the slip of j's contact point relative to i's in this step [m].
        v_rel: ``(x, y, z)``, the relative velocity of the contact points [m/s].
        history: the cohesion history (see the module docstring).
        p: the law's scalars.
        valid: bool, ``False`` on padding.

    Returns:
        A :class:`CohesiveForces` whose vectors are ``(x, y, z)`` component tuples, zero where the pair is not in
        contact.
    """
    one = p.E / p.E
    one = jnp.where(jnp.isfinite(one), one, 1.0)
    gamma = restitution_damping(p.restitution)
    kappa = 2.0 * (1.0 - p.nu) / (2.0 - p.nu)
    dist = jnp.sqrt(dot(d, d))
    n = tuple(c / dist for c in d)
    overlap = r_i + r_j - dist
    active = (overlap > 0) & valid
    delta = once(jnp.where(active, overlap, 0.0), one)
    rsum = r_i + r_j
    length = rsum - delta
    area = once(jnp.pi * (0.5 * rsum) ** 2 * rsum / length, one)
    kn = once(0.5 * p.E * area / length, one)
    m_hat = m_i * m_j / (m_i + m_j)
    dn = 2.0 * gamma * jnp.sqrt(m_hat * kn)
    v_n = dot(v_rel, n)  # > 0 separating: d(delta)/dt = -v_n
    pressure = kn * delta - dn * v_n  # spring-dashpot part of F_N
    cohesion = jnp.abs(history)
    fn = once(jnp.where(active, pressure - cohesion * area, 0.0), one)
    compressive = once(jnp.where(active, jnp.maximum(pressure, 0.0), 0.0), one)
    stress = compressive / area
    new_history = update_cohesion(history, active, stress, p)

    # elastic tangential force: turned into the current tangent plane (same length), plus this step's increment
    s_n = dot(spring, n)
    old = tuple(spring[k] - s_n * n[k] for k in range(3))
    old_len2, proj_len2 = dot(spring, spring), dot(old, old)
    pos = proj_len2 > 0
    stretch = jnp.where(pos, safe_sqrt(old_len2 / jnp.where(pos, proj_len2, 1.0)), 0.0)
    kt = kappa * kn
    dxi_n = dot(dxi, n)
    fs = tuple(once(old[k] * stretch - kt * (dxi[k] - dxi_n * n[k]), one) for k in range(3))
    d_t = dn * jnp.sqrt(kappa)  # 2 gamma sqrt(m^ k_T)
    ft_j = tuple(fs[k] - d_t * (v_rel[k] - v_n * n[k]) for k in range(3))
    ft_len = safe_sqrt(dot(ft_j, ft_j))
    limit = p.friction * compressive
    sliding = (ft_len > limit) & active
    num = jnp.where(active, jnp.where(sliding, limit, 1.0), 0.0)
    den = jnp.where(sliding, ft_len, 1.0)
    ft_j = tuple(once(c * num / den, one) for c in ft_j)
    new_spring = tuple(jnp.where(sliding, ft_j[k], jnp.where(active, fs[k], 0.0)) for k in range(3))

    f_i = tuple(-fn * n[k] - ft_j[k] for k in range(3))
    twist = cross(n, ft_j)
    arm_i, arm_j = 0.5 * delta - r_i, 0.5 * delta - r_j
    return CohesiveForces(f_i=f_i, m_i=tuple(arm_i * c for c in twist), m_j=tuple(arm_j * c for c in twist),
                          normal=fn, spring=new_spring, sliding=sliding, active=active, cohesion=new_history,
                          stress=stress)


def cohesive_contact(d, r_i, r_j, m_i, m_j, spring, dxi, v_rel, history, p: CohesiveParams) -> CohesiveForces:
    """Forces of one cohesive contact.

    Args:
        d: ``[3]`` x_j - x_i [m].
        r_i, r_j: the radii [m].
        m_i, m_j: the masses [kg].
        spring: ``[3]`` the stored tangential force on j [N].
        dxi: ``[3]`` the slip of j's contact point relative to i's in this step [m].
        v_rel: ``[3]`` the relative velocity of the contact points [m/s].
        history: the cohesion history.
        p: the law's scalars.

    Returns:
        The contact's :class:`CohesiveForces`, vectors ``[3]``.
    """
    return stack(law_components(tuple(d), r_i, r_j, m_i, m_j, tuple(spring), tuple(dxi), tuple(v_rel), history, p))


def pair_forces(positions, pairs, valid, radii, mass, spring, dxi, v_rel, history, p: CohesiveParams):
    """Cohesive contacts of all candidate pairs and their sums per particle.

    Args:
        positions, pairs, valid, radii, mass, spring, dxi, v_rel: as for :func:`jaxbpm.physics.contact.pair_forces`.
        history: ``[C]`` the cohesion histories.
        p: the law's scalars.

    Returns:
        ``(forces, moments, per_pair)``: ``[n, 3]`` [N], ``[n, 3]`` [N m] and the pairs' :class:`CohesiveForces`
        (``[C, ...]``).
    """
    import jax

    from jaxbpm.physics.contact import _components, pair_vectors

    n = positions.shape[0]
    i, j, d = pair_vectors(positions, pairs, valid)
    cf = law_components(d, radii[i], radii[j], mass[i], mass[j], _components(spring), _components(dxi),
                        _components(v_rel), history, p, valid)
    zero = jnp.zeros_like(cf.normal)
    rows_i = jnp.stack(cf.f_i + (zero,) + cf.m_i + (zero,), axis=1)
    rows_j = jnp.stack(tuple(-f for f in cf.f_i) + (zero,) + cf.m_j + (zero,), axis=1)
    total = jax.ops.segment_sum(jnp.concatenate([rows_i, rows_j]), jnp.concatenate([i, j]), n)
    return total[:, :3], total[:, 4:7], stack(cf)
