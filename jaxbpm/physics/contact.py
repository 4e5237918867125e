"""Hertz-Mindlin particle-particle contacts, written for one pair and lifted with ``vmap``; the same entry points
(:func:`law_components`, :func:`hertz_mindlin`, :func:`pair_forces`) run PFC's linear contact model
(:mod:`jaxbpm.physics.linear`) when given its :class:`~jaxbpm.physics.linear.LinearParams`.

Effective properties of two spheres of one material (E, nu)::

    E* = E / (2 (1 - nu^2)),   G* = G / (2 (2 - nu)),  G = E / (2 (1 + nu)),   R* = r_i r_j / (r_i + r_j)

Normal force (overlap delta > 0): ``F_n = 4/3 E* sqrt(R*) delta^(3/2)`` (repulsive).
Tangential: a spring ``xi`` (the accumulated relative tangential displacement of the contact points, kept in the
tangent plane) with Mindlin's stiffness ``k_t = 8 G* sqrt(R* delta)``; ``F_t = -k_t xi`` on particle j, capped by
Coulomb ``|F_t| <= mu F_n`` (the spring is shortened to match when the contact slides).
Optional damping (Tsuji et al.): ``c = 2 sqrt(5/6) beta sqrt(S m*)`` with ``beta = ln e / sqrt(ln^2 e + pi^2)``,
``S_n = 2 E* sqrt(R* delta)``, ``S_t = k_t``.

The DEM passes each step's relative displacement of the contact points; a static solve (no-slip, Jarolin & Dosta 2020
3.1.2) passes the whole displacement since the reference state with an empty spring.

A walkthrough: two spheres of radius 1 mm pressed 1 um into each other push apart with Hertz's force; a small
tangential displacement is held by Mindlin's spring, a large one slides at the Coulomb limit.

Examples:
    >>> import jax
    >>> jax.config.update("jax_enable_x64", True)
    >>> import jax.numpy as jnp
    >>> from jaxbpm.physics import contact
    >>> p = contact.contact_params(E=1e9, nu=0.25, friction=0.5, restitution=0.5)
    >>> r, delta = 1e-3, 1e-6
    >>> d = jnp.array([2 * r - delta, 0.0, 0.0])              # x_j - x_i
    >>> zero = jnp.zeros(3)
    >>> out = contact.hertz_mindlin(d, r, r, 1.0, 1.0, zero, zero, zero, p)
    >>> hertz = 4 / 3 * float(p.E_star) * (r / 2) ** 0.5 * delta**1.5
    >>> print(f"{float(out.normal) / hertz:.9f}, f_i along -x: {float(out.f_i[0]) < 0}")
    1.000000000, f_i along -x: True
    >>> slide = contact.hertz_mindlin(d, r, r, 1.0, 1.0, zero, jnp.array([0.0, 1e-4, 0.0]), zero, p)
    >>> print(bool(slide.sliding), f"{float(jnp.linalg.norm(slide.f_i[1:]) / slide.normal):.9f}")
    True 0.500000000
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm.physics import linear as linear_mod
from jaxbpm.physics.vec import cross, dot, once, safe_sqrt, stack

__all__ = ["law_components", "ContactParams", "ContactForces", "contact_params", "hertz_mindlin", "hertz_normal_force",
           "pair_forces", "pair_vectors"]


class ContactParams(NamedTuple):
    """Scalars of the particle material.

    Attributes:
        E_star: E* of a like pair [Pa].
        G_star: G* of a like pair [Pa].
        friction: the friction coefficient mu.
        beta: the damping factor, or ``None``: no damping, and the law computes none of its terms.
    """

    E_star: jnp.ndarray
    G_star: jnp.ndarray
    friction: jnp.ndarray
    beta: jnp.ndarray | None


class ContactForces(NamedTuple):
    """Forces of a contact: :func:`hertz_mindlin`'s output for one pair, ``[C, ...]`` for all of them.

    Attributes:
        f_i: ``[3]`` force on particle i [N] (on j: ``-f_i``).
        m_i: ``[3]`` moment on i [N m].
        m_j: ``[3]`` moment on j [N m].
        normal: normal force magnitude, repulsion > 0 [N].
        spring: ``[3]`` the updated tangential spring [m].
        sliding: bool, the Coulomb limit is reached.
        active: bool, the pair is in contact.
    """

    f_i: jnp.ndarray
    m_i: jnp.ndarray
    m_j: jnp.ndarray
    normal: jnp.ndarray
    spring: jnp.ndarray
    sliding: jnp.ndarray
    active: jnp.ndarray


def contact_params(E, nu, friction, restitution, damping: bool = False) -> ContactParams:
    """Contact parameters of a particle material.

    Args:
        E: Young's modulus of the particles [Pa].
        nu: Poisson's ratio of the particles.
        friction: the friction coefficient mu.
        restitution: the coefficient of restitution e (used with ``damping``).
        damping: ``False``: no damping (beta ``None``); ``True`` or a traced bool: Tsuji damping (beta = 0 where a
            traced ``damping`` is false).

    Returns:
        The :class:`ContactParams`.
    """
    G = E / (2.0 * (1.0 + nu))
    if isinstance(damping, (bool, np.bool_)) and not damping:
        beta = None
    else:
        log_e = jnp.log(restitution)
        beta = jnp.where(damping, -log_e / jnp.sqrt(log_e**2 + jnp.pi**2), 0.0)
    return ContactParams(E_star=E / (2.0 * (1.0 - nu**2)), G_star=G / (2.0 * (2.0 - nu)),
                         friction=jnp.asarray(friction), beta=beta)


def hertz_normal_force(overlap, r_star, E_star):
    """Hertz normal force ``4/3 E* sqrt(R*) delta^1.5``.

    Args:
        overlap: the overlap delta [m] (no force where it is not positive).
        r_star: the effective radius R* [m].
        E_star: the effective modulus E* [Pa].

    Returns:
        The repulsive force [N], shaped as the arguments broadcast.
    """
    delta = jnp.maximum(overlap, 0.0)
    return 4.0 / 3.0 * E_star * jnp.sqrt(r_star) * delta * safe_sqrt(delta)


def law_components(d, r_i, r_j, m_i, m_j, spring, dxi, v_rel, p: ContactParams, valid=True):
    """The contact law on components, for one pair (scalars) or all pairs at once (``[C]`` arrays).

    Written like the bond law (:func:`jaxbpm.physics.bond.law_components`), elementwise on components. XLA's CPU fusion
    copies cheap elementwise producers into every consumer (gathers included) but computes a division or a square root
    once into memory; the law is arranged so that every value with several consumers ends in one (``_once`` adds an
    exact division by one where none is natural).

    Args:
        d: ``(x, y, z)``, x_j - x_i [m].
        r_i, r_j: the radii [m].
        m_i, m_j: the masses [kg] (for damping).
        spring: ``(x, y, z)``, the tangential spring carried from the last step [m].
        dxi: ``(x, y, z)``, the relative displacement of the contact points since then [m].
        v_rel: ``(x, y, z)``, the relative velocity of the contact points [m/s].
        p: the contact parameters (a :class:`~jaxbpm.physics.linear.LinearParams`: PFC's linear law,
            :func:`jaxbpm.physics.linear.law_components`).
        valid: bool, ``False`` on padding.

    Returns:
        A :class:`ContactForces` whose vectors are ``(x, y, z)`` component tuples, zero where the pair is not in
        contact.
    """
    if isinstance(p, linear_mod.LinearParams):
        return ContactForces(*linear_mod.law_components(d, r_i, r_j, m_i, m_j, spring, dxi, v_rel, p, valid))
    one = _one(p)
    dist = jnp.sqrt(dot(d, d))
    n = tuple(c / dist for c in d)
    overlap = r_i + r_j - dist
    delta = once(jnp.where((overlap > 0) & valid, overlap, 0.0), one)
    active = delta > 0
    sqrt_rd = safe_sqrt(r_i * r_j / (r_i + r_j) * delta)  # sqrt(R* delta)
    fn = 4.0 / 3.0 * p.E_star * sqrt_rd * delta
    if p.beta is not None:
        # Tsuji damping: c_n = damp sqrt(2 E* sqrt(R* delta) m*), c_t = damp sqrt(k_t m*), one square root for both
        damp = 2.0 * jnp.sqrt(5.0 / 6.0) * p.beta * safe_sqrt(sqrt_rd * (m_i * m_j / (m_i + m_j)))
        v_n = dot(v_rel, n)
        fn = fn - damp * jnp.sqrt(2.0 * p.E_star) * v_n
    fn = once(jnp.where(active, jnp.maximum(fn, 0.0), 0.0), one)

    # tangential spring: keep it in the current tangent plane (same length), then add this step's slip
    s_n = dot(spring, n)
    old = tuple(spring[k] - s_n * n[k] for k in range(3))
    old_len2, proj_len2 = dot(spring, spring), dot(old, old)
    pos = proj_len2 > 0
    stretch = jnp.where(pos, safe_sqrt(old_len2 / jnp.where(pos, proj_len2, 1.0)), 0.0)
    dxi_n = dot(dxi, n)
    xi = tuple(once(old[k] * stretch + dxi[k] - dxi_n * n[k], one) for k in range(3))
    kt = 8.0 * p.G_star * sqrt_rd
    ft_j = tuple(-kt * xi[k] for k in range(3))
    if p.beta is not None:
        c_t = damp * jnp.sqrt(8.0 * p.G_star)
        ft_j = tuple(ft_j[k] - c_t * (v_rel[k] - v_n * n[k]) for k in range(3))
    ft_len = safe_sqrt(dot(ft_j, ft_j))
    limit = p.friction * fn
    sliding = (ft_len > limit) & active
    # scale by limit / |ft| when sliding, by 1 when sticking, by 0 out of contact (one division, computed once)
    scale = jnp.where(active, jnp.where(sliding, limit, 1.0), 0.0) / jnp.where(sliding, ft_len, 1.0)
    ft_j = tuple(c * scale for c in ft_j)
    # a sliding spring is shortened to match the Coulomb force, -ft_j / kt: without damping that is xi scaled alike
    if p.beta is None:
        xi = tuple(once(c * scale, one) for c in xi)
    else:
        back = jnp.where(sliding, kt, 1.0)
        xi = tuple(jnp.where(sliding, -ft_j[k], jnp.where(active, xi[k], 0.0)) / back for k in range(3))

    f_i = tuple(-fn * n[k] - ft_j[k] for k in range(3))
    # moments (r_i - delta/2) n x (-ft_j) on i and -(r_j - delta/2) n x ft_j on j
    twist = cross(n, ft_j)
    arm_i, arm_j = 0.5 * delta - r_i, 0.5 * delta - r_j
    return ContactForces(f_i=f_i, m_i=tuple(arm_i * c for c in twist), m_j=tuple(arm_j * c for c in twist),
                         normal=fn, spring=xi, sliding=sliding, active=active)


def _one(p: ContactParams):
    """A run-time 1.0 (XLA cannot fold it away)."""
    ratio = p.E_star / p.E_star
    return jnp.where(jnp.isfinite(ratio), ratio, 1.0)


def hertz_mindlin(d, r_i, r_j, m_i, m_j, spring, dxi, v_rel, p: ContactParams) -> ContactForces:
    """Forces of one contact (PFC's linear law where ``p`` is a :class:`~jaxbpm.physics.linear.LinearParams`).

    Args:
        d: ``[3]`` x_j - x_i [m].
        r_i, r_j: the radii [m].
        m_i, m_j: the masses [kg] (for damping).
        spring: ``[3]`` tangential spring carried from the last step [m].
        dxi: ``[3]`` relative displacement of the contact point of j with respect to that of i since then [m].
        v_rel: ``[3]`` relative velocity of the contact points [m/s] (zeros for a static solve).
        p: the contact parameters.

    Returns:
        The contact's :class:`ContactForces`, vectors ``[3]``.
    """
    return stack(law_components(tuple(d), r_i, r_j, m_i, m_j, tuple(spring), tuple(dxi), tuple(v_rel), p))


def _components(a):
    """``[C, 3]`` rows (or a tuple of three ``[C]`` arrays) as a tuple of three ``[C]`` component arrays."""
    return tuple(a) if isinstance(a, tuple) else tuple(a.T)


def pair_vectors(positions, pairs, valid):
    """Particle indices and pair vectors of the candidate pairs.

    Args:
        positions: ``[n, 3]`` particle positions [m] (or ``[n, 2]``: discs).
        pairs: ``[C, 2]`` candidate pairs.
        valid: ``[C]`` bool, ``False`` on padding and excluded pairs.

    Returns:
        ``(i, j, d)``: ``[C]`` uint32 indices (padding and excluded pairs point at particles 0 and 1) and the
        components ``(x, y, z)`` of ``d = x_j - x_i``, ``[C]`` each (ones on padding, keeping them finite).
    """
    n = positions.shape[0]
    # unsigned indices: no wrapping of negative ones to compute in every gather
    i = jnp.where(valid, pairs[:, 0], 0).astype(jnp.uint32)
    j = jnp.where(valid, pairs[:, 1], 1 % n).astype(jnp.uint32)
    # gather columns of the transposed [dim, n] positions: the law runs on [C] component arrays
    x_t = positions.T
    return i, j, tuple(jnp.where(valid, x_t[k][j] - x_t[k][i], 1.0) for k in range(positions.shape[1]))


def pair_forces(positions, pairs, valid, radii, mass, spring, dxi, v_rel, p: ContactParams):
    """Contacts of all candidate pairs and their sums per particle.

    Args:
        positions: ``[n, 3]`` particle positions [m].
        pairs: ``[C, 2]`` candidate pairs.
        valid: ``[C]`` bool, ``False`` on padding and excluded pairs.
        radii: ``[n]`` radii [m].
        mass: ``[n]`` masses [kg].
        spring, dxi, v_rel: ``[C, 3]`` (or tuples of their three ``[C]`` columns), as for :func:`hertz_mindlin`.
        p: the contact parameters.

    Returns:
        ``(forces, moments, per_pair)``: ``[n, 3]`` [N], ``[n, 3]`` [N m] (2D, the linear law: ``[n, 2]`` and
        ``[n, 1]``) and the pairs' :class:`ContactForces` (``[C, ...]``).
    """
    n = positions.shape[0]
    i, j, d = pair_vectors(positions, pairs, valid)
    cf = law_components(d, radii[i], radii[j], mass[i], mass[j], _components(spring), _components(dxi),
                        _components(v_rel), p, valid)
    # one scatter of (force, 0, moment, 0) rows for both ends (see jaxbpm.physics.bond.bond_forces; 2D: rows
    # (f_x, f_y, m, 0))
    zero = (jnp.zeros_like(cf.normal),)
    pad, tail = (zero, zero) if len(cf.f_i) == 3 else ((), zero)
    rows_i = jnp.stack(cf.f_i + pad + cf.m_i + tail, axis=1)
    rows_j = jnp.stack(tuple(-f for f in cf.f_i) + pad + cf.m_j + tail, axis=1)
    total = jax.ops.segment_sum(jnp.concatenate([rows_i, rows_j]), jnp.concatenate([i, j]), n)
    dim = len(cf.f_i)
    return total[:, :dim], total[:, dim + len(pad):dim + len(pad) + len(cf.m_i)], stack(cf)
