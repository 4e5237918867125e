"""Hertz-Mindlin particle-particle contacts, written for one pair and lifted with ``vmap``.

Effective properties of two spheres of one material (E, nu)::

    E* = E / (2 (1 - nu^2)),   G* = G / (2 (2 - nu)),  G = E / (2 (1 + nu)),   R* = r_i r_j / (r_i + r_j)

Normal force (overlap delta > 0): ``F_n = 4/3 E* sqrt(R*) delta^(3/2)`` (repulsive).
Tangential: a spring ``xi`` (the accumulated relative tangential displacement of the contact points, kept in the
tangent plane) with Mindlin's stiffness ``k_t = 8 G* sqrt(R* delta)``; ``F_t = -k_t xi`` on particle j, capped by
Coulomb ``|F_t| <= mu F_n`` (the spring is shortened to match when the contact slides).
Optional damping (Tsuji et al.): ``c = 2 sqrt(5/6) beta sqrt(S m*)`` with ``beta = ln e / sqrt(ln^2 e + pi^2)``,
``S_n = 2 E* sqrt(R* delta)``, ``S_t = k_t``.

The DEM passes each step's relative displacement of the contact points; a static solve (no-slip, seed 000 3.1.2)
passes the whole displacement since the reference state with an empty spring.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

__all__ = ["ContactParams", "ContactForces", "contact_params", "hertz_mindlin", "hertz_normal_force",
           "pair_forces"]


class ContactParams(NamedTuple):
    """Scalars of the particle material: E* and G* of a like pair [Pa], friction mu, damping factor beta."""

    E_star: jnp.ndarray
    G_star: jnp.ndarray
    friction: jnp.ndarray
    beta: jnp.ndarray


class ContactForces(NamedTuple):
    f_i: jnp.ndarray       # [3] force on particle i (on j: -f_i)
    m_i: jnp.ndarray       # [3] moment on i
    m_j: jnp.ndarray       # [3] moment on j
    normal: jnp.ndarray    # scalar normal force magnitude (repulsion > 0)
    spring: jnp.ndarray    # [3] updated tangential spring
    sliding: jnp.ndarray   # bool, Coulomb limit reached
    active: jnp.ndarray    # bool, in contact


def contact_params(E, nu, friction, restitution, damping: bool = False) -> ContactParams:
    """Contact parameters of a particle material; ``damping=False`` gives beta = 0."""
    G = E / (2.0 * (1.0 + nu))
    log_e = jnp.log(restitution)
    beta = jnp.where(damping, -log_e / jnp.sqrt(log_e**2 + jnp.pi**2), 0.0)
    return ContactParams(E_star=E / (2.0 * (1.0 - nu**2)), G_star=G / (2.0 * (2.0 - nu)),
                         friction=jnp.asarray(friction), beta=beta)


def hertz_normal_force(overlap, r_star, E_star):
    """Hertz normal force ``4/3 E* sqrt(R*) delta^1.5`` (zero without overlap)."""
    delta = jnp.maximum(overlap, 0.0)
    return 4.0 / 3.0 * E_star * jnp.sqrt(r_star) * delta * _safe_sqrt(delta)


def _safe_sqrt(x):
    """sqrt with a zero (not NaN) derivative at 0: 0 * inf in a jvp would poison Newton solves."""
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def hertz_mindlin(d, r_i, r_j, m_i, m_j, spring, dxi, v_rel, p: ContactParams) -> ContactForces:
    """Forces of ONE contact.

    Args:
      d: ``[3]`` x_j - x_i. r_i, r_j: radii. m_i, m_j: masses (for damping).
      spring: ``[3]`` tangential spring carried from the last step. dxi: ``[3]`` relative displacement of the contact
        point of j with respect to that of i since then. v_rel: ``[3]`` relative velocity of the contact points
        (zeros for a static solve).
    """
    dist = jnp.sqrt(jnp.dot(d, d))
    n = d / dist
    overlap = r_i + r_j - dist
    active = overlap > 0
    delta = jnp.where(active, overlap, 0.0)
    r_star = r_i * r_j / (r_i + r_j)
    m_star = m_i * m_j / (m_i + m_j)
    sqrt_rd = _safe_sqrt(r_star * delta)
    damp = 2.0 * jnp.sqrt(5.0 / 6.0) * p.beta
    v_n = jnp.dot(v_rel, n)
    fn = 4.0 / 3.0 * p.E_star * sqrt_rd * delta - damp * _safe_sqrt(2.0 * p.E_star * sqrt_rd * m_star) * v_n
    fn = jnp.where(active, jnp.maximum(fn, 0.0), 0.0)

    # tangential spring: keep it in the current tangent plane (same length), then add this step's slip
    old = spring - jnp.dot(spring, n) * n
    old_len, proj_len = _safe_sqrt(jnp.dot(spring, spring)), _safe_sqrt(jnp.dot(old, old))
    old = old * jnp.where(proj_len > 0, old_len / jnp.where(proj_len > 0, proj_len, 1.0), 0.0)
    xi = old + dxi - jnp.dot(dxi, n) * n
    kt = 8.0 * p.G_star * sqrt_rd
    v_t = v_rel - v_n * n
    ft_j = -kt * xi - damp * _safe_sqrt(kt * m_star) * v_t
    ft_len = _safe_sqrt(jnp.dot(ft_j, ft_j))
    limit = p.friction * fn
    sliding = ft_len > limit
    scale = jnp.where(sliding, limit / jnp.where(ft_len > 0, ft_len, 1.0), 1.0)
    ft_j = ft_j * scale
    xi = jnp.where(sliding, -ft_j / jnp.where(kt > 0, kt, 1.0), xi)
    xi = jnp.where(active, xi, 0.0)
    ft_j = jnp.where(active, ft_j, 0.0)

    f_i = -fn * n - ft_j
    arm_i = (r_i - 0.5 * delta) * n
    arm_j = -(r_j - 0.5 * delta) * n
    return ContactForces(f_i=f_i, m_i=jnp.cross(arm_i, -ft_j), m_j=jnp.cross(arm_j, ft_j), normal=fn, spring=xi,
                         sliding=sliding & active, active=active)


_hertz_mindlin_all = jax.vmap(hertz_mindlin, in_axes=(0, 0, 0, 0, 0, 0, 0, 0, None))


def pair_forces(positions, pairs, valid, radii, mass, spring, dxi, v_rel, p: ContactParams):
    """Contacts of all candidate pairs ``[C, 2]`` (``valid [C]`` masks padding and excluded pairs).

    Returns per-particle force and moment sums ``([n, 3], [n, 3])`` and the per-pair :class:`ContactForces`.
    """
    n = positions.shape[0]
    i = jnp.where(valid, pairs[:, 0], 0)
    j = jnp.where(valid, pairs[:, 1], 1 % n)
    d = positions[j] - positions[i]
    d = jnp.where(valid[:, None], d, jnp.ones_like(d))  # keep padding finite
    cf = _hertz_mindlin_all(d, radii[i], radii[j], mass[i], mass[j], spring, dxi, v_rel, p)
    keep = valid & cf.active
    cf = cf._replace(
        f_i=jnp.where(keep[:, None], cf.f_i, 0.0), m_i=jnp.where(keep[:, None], cf.m_i, 0.0),
        m_j=jnp.where(keep[:, None], cf.m_j, 0.0), normal=jnp.where(keep, cf.normal, 0.0),
        spring=jnp.where(keep[:, None], cf.spring, 0.0), sliding=cf.sliding & keep, active=keep)
    idx = jnp.concatenate([i, j])
    force = jax.ops.segment_sum(jnp.concatenate([cf.f_i, -cf.f_i]), idx, n)
    moment = jax.ops.segment_sum(jnp.concatenate([cf.m_i, cf.m_j]), idx, n)
    return force, moment, cf
