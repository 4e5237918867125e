"""PFC's linear contact model (Itasca's ``linear`` contact model with its deformability method), written for one pair
and lifted with ``vmap``, in any dimension: vectors are tuples of components, one per axis.

Stiffness (PFC's deformability method: ``emod`` the effective modulus E*, ``kratio`` the normal-to-shear stiffness
ratio)::

    k_n = E* A / L,   A = pi r^2 (3D) or 2 r t (2D, t = 1: PFC2D's unit thickness),   r = min(r_i, r_j),
    L = r_i + r_j,    k_s = k_n / kratio

constant over the life of the contact (A and L are those of the two particles, not of the overlap). Forces, for an
overlap ``delta = r_i + r_j - |x_j - x_i| > 0``::

    F_n = k_n delta                        (repulsion > 0; the dashpot below may add to it, never pull)
    F_s <- F_s (turned into the tangent plane) - k_s ds      (incremental: ds the shear slip of a step)
    |F_s| <= mu F_n                        (Coulomb: the force is scaled onto the limit and kept there)

With a constant k_s the incremental shear force is ``-k_s xi`` with ``xi`` the accumulated tangential slip, so the
law carries the slip ``xi`` [m] as Hertz-Mindlin does (:mod:`jaxbpm.physics.contact`): the DEM's and the DSM's
contact state is the same for both laws. A sliding contact's slip is shortened to ``-F_s / k_s``.

Optional viscous damping (PFC's dashpots with ``dp_nratio = dp_sratio = beta``): ``c = 2 beta sqrt(m* k)`` with
``m* = m_i m_j / (m_i + m_j)`` and ``beta = -ln e / sqrt(ln^2 e + pi^2)`` from the coefficient of restitution e
(exact for the linear spring-dashpot: a collision rebounds with e). The normal force is kept >= 0 (no pull) and the
Coulomb limit is ``mu k_n delta`` (the spring part, as PFC's ``F_s^mu = -mu F_n^l``).

A walkthrough: two spheres of radius 1 mm pressed 1 um into each other push apart with ``k_n delta``; a small
tangential slip is held by ``k_s``, a large one slides at the Coulomb limit.

Examples:
    >>> import jax
    >>> jax.config.update("jax_enable_x64", True)
    >>> import jax.numpy as jnp
    >>> from jaxbpm.physics import linear
    >>> p = linear.linear_params(emod=1e9, kratio=1.5, friction=0.5)
    >>> r, delta = 1e-3, 1e-6
    >>> kn = float(linear.normal_stiffness(r, r, p.emod))              # 1e9 pi r^2 / (2 r)
    >>> d = (jnp.asarray(2 * r - delta), jnp.asarray(0.0), jnp.asarray(0.0))
    >>> zero = (jnp.asarray(0.0),) * 3
    >>> out = linear.law_components(d, r, r, 1.0, 1.0, zero, zero, zero, p)
    >>> print(f"{float(out.normal) / (kn * delta):.9f}, f_i along -x: {float(out.f_i[0]) < 0}")
    1.000000000, f_i along -x: True
    >>> slide = linear.law_components(d, r, r, 1.0, 1.0, zero, (0.0, 1e-4, 0.0), zero, p)
    >>> print(bool(slide.sliding), f"{abs(float(slide.f_i[1])) / float(slide.normal):.9f}")
    True 0.500000000
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from typing import Any, NamedTuple

import jax.numpy as jnp
import numpy as np

from jaxbpm.errors import SceneError
from jaxbpm.physics.vec import cross, once, safe_sqrt

__all__ = ["LinearLaw", "LinearParams", "LinearForces", "linear_params", "default_kratio", "contact_area",
           "normal_stiffness", "law_components"]


@dataclasses.dataclass(frozen=True)
class LinearLaw:
    """Parameters of PFC's linear contact model (PFC's names in brackets); ``None`` takes a default from the sample's
    :class:`~jaxbpm.sample.ParticleMaterial`.

    Attributes:
        emod: the effective modulus E* [Pa] (``emod``); default the particles' Young's modulus E.
        kratio: the normal-to-shear stiffness ratio k_n / k_s (``kratio``); default ``(2 - nu) / (2 (1 - nu))``,
            the ratio of Hertz-Mindlin's stiffnesses at small overlap for the particles' Poisson's ratio nu
            (:func:`default_kratio`).
        friction: the friction coefficient mu (``fric``); default the particles' friction.
        restitution: the coefficient of restitution of the dashpots (with contact damping); default the particles'.

    Raises:
        SceneError: a parameter out of its range (not a finite number, emod or kratio not > 0, friction < 0,
            restitution outside (0, 1]).
    """

    emod: float | None = None
    kratio: float | None = None
    friction: float | None = None
    restitution: float | None = None

    def __post_init__(self):
        checks = {"emod": (lambda v: v > 0, "must be > 0 [Pa]"), "kratio": (lambda v: v > 0, "must be > 0"),
                  "friction": (lambda v: v >= 0, "must be >= 0"),
                  "restitution": (lambda v: 0 < v <= 1, "must lie in (0, 1]")}
        for name, (ok, why) in checks.items():
            v = getattr(self, name)
            if v is None:
                continue
            if not (isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v) and ok(v)):
                raise SceneError(f"linear contact law: {name}={v!r} {why}")

    def params(self, particle_material, dtype=None, damping: bool = False, thickness: float = 1.0) -> "LinearParams":
        """The law's scalars as JAX arrays.

        Args:
            particle_material: the sample's :class:`~jaxbpm.sample.ParticleMaterial`, for the values left ``None``.
            dtype: the arrays' type (default JAX's).
            damping: the dashpots on (``beta`` from the restitution) or off (``beta`` ``None``).
            thickness: the discs' thickness t [m] of a two-dimensional sample (the contact area ``2 r t``).

        Returns:
            The :class:`LinearParams`.
        """
        pm = particle_material
        emod = float(pm.E) if self.emod is None else self.emod
        kratio = float(default_kratio(float(pm.nu))) if self.kratio is None else self.kratio
        friction = float(pm.friction) if self.friction is None else self.friction
        restitution = float(pm.restitution) if self.restitution is None else self.restitution
        return linear_params(emod, kratio, friction, restitution, damping, dtype, thickness)


class LinearParams(NamedTuple):
    """The linear law's scalars (a pytree; :meth:`jaxbpm.physics.model.Model.hertz_params` overrides them from a
    params dict).

    Attributes:
        emod: the effective modulus E* [Pa].
        kratio: k_n / k_s.
        friction: the friction coefficient mu.
        beta: the dashpots' fraction of critical damping, or ``None``: no damping (no damping terms computed).
        thickness: the discs' thickness t [m] in 2D (the contact area ``2 r t``; not read in 3D).
    """

    emod: Any
    kratio: Any
    friction: Any
    beta: Any
    thickness: Any = 1.0


class LinearForces(NamedTuple):
    """Forces of a linear contact, the fields of :class:`jaxbpm.physics.contact.ContactForces` (which
    :func:`jaxbpm.physics.contact.law_components` returns for both laws).

    Attributes:
        f_i: force on particle i [N] (on j: ``-f_i``).
        m_i: moment on i [N m].
        m_j: moment on j [N m].
        normal: normal force magnitude, repulsion > 0 [N].
        spring: the updated tangential slip [m].
        sliding: bool, the Coulomb limit is reached.
        active: bool, the pair is in contact.
    """

    f_i: Any
    m_i: Any
    m_j: Any
    normal: Any
    spring: Any
    sliding: Any
    active: Any


def linear_params(emod, kratio, friction, restitution=1.0, damping: bool = False, dtype=None,
                  thickness: float = 1.0) -> LinearParams:
    """The linear law's scalars.

    Args:
        emod: the effective modulus E* [Pa].
        kratio: k_n / k_s.
        friction: the friction coefficient mu.
        restitution: the coefficient of restitution e (with ``damping``).
        damping: the dashpots on: ``beta = -ln e / sqrt(ln^2 e + pi^2)``; off: ``beta`` ``None``.
        dtype: the arrays' type (default JAX's).
        thickness: the discs' thickness t [m] (2D).

    Returns:
        The :class:`LinearParams` (host values are moved to the device as they are: no program is compiled).
    """
    def put(v):
        return jnp.asarray(np.asarray(v, dtype)) if isinstance(v, numbers.Real) else jnp.asarray(v, dtype)

    beta = None
    if damping:
        log_e = math.log(float(restitution))
        beta = put(-log_e / math.sqrt(log_e**2 + math.pi**2))
    return LinearParams(emod=put(emod), kratio=put(kratio), friction=put(friction), beta=beta,
                        thickness=put(thickness))


def default_kratio(nu):
    """The default k_n / k_s: Hertz-Mindlin's ``k_n / k_t = E* / (4 G*) = (2 - nu) / (2 (1 - nu))`` at small overlap.

    Args:
        nu: the particles' Poisson's ratio.

    Returns:
        ``(2 - nu) / (2 (1 - nu))``.
    """
    return (2.0 - nu) / (2.0 * (1.0 - nu))


def contact_area(r_i, r_j, dim: int = 3, thickness=1.0):
    """The area of PFC's deformability method.

    Args:
        r_i, r_j: the radii [m].
        dim: the spatial dimension: 3 (spheres) or 2 (discs).
        thickness: the discs' thickness t [m] (2D; PFC2D's unit thickness by default).

    Returns:
        ``pi r^2`` (3D) or ``2 r t`` (2D), ``r = min(r_i, r_j)`` [m^2].
    """
    r = jnp.minimum(r_i, r_j)
    return jnp.pi * r * r if dim == 3 else 2.0 * r * thickness


def normal_stiffness(r_i, r_j, emod, dim: int = 3, thickness=1.0):
    """The normal stiffness ``k_n = E* A / (r_i + r_j)``.

    Args:
        r_i, r_j: the radii [m].
        emod: the effective modulus E* [Pa].
        dim: the spatial dimension (see :func:`contact_area`).
        thickness: the discs' thickness t [m] (2D).

    Returns:
        k_n [N/m].
    """
    return emod * contact_area(r_i, r_j, dim, thickness) / (r_i + r_j)


def _dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def _moment(n, f):
    """``n x f``: three components in 3D, the one out-of-plane component in 2D."""
    return cross(n, f) if len(n) == 3 else (n[0] * f[1] - n[1] * f[0],)


def law_components(d, r_i, r_j, m_i, m_j, spring, dxi, v_rel, p: LinearParams, valid=True):
    """The linear law on components, for one pair (scalars) or all pairs at once (``[C]`` arrays).

    Written like :func:`jaxbpm.physics.contact.law_components` (which calls it for :class:`LinearParams`), on
    component tuples of any length (the dimension).

    Args:
        d: the components of x_j - x_i [m].
        r_i, r_j: the radii [m].
        m_i, m_j: the masses [kg] (for damping).
        spring: the tangential slip ``xi`` carried from the last step [m] (components).
        dxi: the relative displacement of the contact points since then [m] (components).
        v_rel: the relative velocity of the contact points [m/s] (components).
        p: the law's scalars.
        valid: bool, ``False`` on padding.

    Returns:
        A :class:`LinearForces` whose vectors are component tuples (moments: three in 3D, one in 2D), zero where the
        pair is not in contact.
    """
    dim = len(d)
    one = p.emod / p.emod
    one = jnp.where(jnp.isfinite(one), one, 1.0)
    dist = jnp.sqrt(_dot(d, d))
    n = tuple(c / dist for c in d)
    overlap = r_i + r_j - dist
    delta = once(jnp.where((overlap > 0) & valid, overlap, 0.0), one)
    active = delta > 0
    kn = once(normal_stiffness(r_i, r_j, p.emod, dim, p.thickness), one)
    ks = kn / p.kratio
    spring_n = kn * delta  # PFC's F_n^l: the Coulomb limit's normal force
    fn = spring_n
    if p.beta is not None:
        damp = once(2.0 * p.beta * safe_sqrt(m_i * m_j / (m_i + m_j) * kn), one)  # c_n = 2 beta sqrt(m* k_n)
        v_n = _dot(v_rel, n)
        fn = fn - damp * v_n
    fn = once(jnp.where(active, jnp.maximum(fn, 0.0), 0.0), one)

    # the slip: kept in the current tangent plane (same length), plus this step's tangential slip
    s_n = _dot(spring, n)
    old = tuple(spring[k] - s_n * n[k] for k in range(dim))
    old_len2, proj_len2 = _dot(spring, spring), _dot(old, old)
    pos = proj_len2 > 0
    stretch = jnp.where(pos, safe_sqrt(old_len2 / jnp.where(pos, proj_len2, 1.0)), 0.0)
    dxi_n = _dot(dxi, n)
    xi = tuple(once(old[k] * stretch + dxi[k] - dxi_n * n[k], one) for k in range(dim))
    ft_j = tuple(-ks * xi[k] for k in range(dim))
    if p.beta is not None:
        c_s = damp / jnp.sqrt(p.kratio)  # 2 beta sqrt(m* k_s)
        ft_j = tuple(ft_j[k] - c_s * (v_rel[k] - v_n * n[k]) for k in range(dim))
    ft_len = safe_sqrt(_dot(ft_j, ft_j))
    limit = p.friction * spring_n
    sliding = (ft_len > limit) & active
    num = jnp.where(active, jnp.where(sliding, limit, 1.0), 0.0)
    den = jnp.where(sliding, ft_len, 1.0)
    ft_j = tuple(c * num / den for c in ft_j)
    back = jnp.where(sliding, ks, 1.0)
    xi = tuple(jnp.where(sliding, -ft_j[k], jnp.where(active, xi[k], 0.0)) / back for k in range(dim))

    f_i = tuple(-fn * n[k] - ft_j[k] for k in range(dim))
    # moments about the centres, the contact point in the middle of the overlap: arms (r - delta/2) along +-n
    twist = _moment(n, ft_j)
    arm_i, arm_j = 0.5 * delta - r_i, 0.5 * delta - r_j
    return LinearForces(f_i=f_i, m_i=tuple(arm_i * c for c in twist), m_j=tuple(arm_j * c for c in twist),
                       normal=fn, spring=xi, sliding=sliding, active=active)
