"""The elastic bond law, written once for one bond and lifted to all bonds with ``vmap``.

Stiffnesses (Potyondy & Cundall 2004; Jarolin & Dosta 2020, Eq. 1-4), for a bond of initial length L, cross-section
A = pi r_b^2 and second moments I = pi r_b^4 / 4, J = pi r_b^4 / 2 made of a material (E, nu)::

    k_n  = E A / L                 normal      [N/m]
    k_t  = E A / (2 L (1 + nu))    tangential  [N/m]
    k_tw = E J / (2 L (1 + nu))    twisting    [N m/rad]
    k_b  = E I / L                 bending     [N m/rad]

Kinematics are written in total (not incremental) form, so the same function serves time integration (DEM), static
solves (DSM, through its Jacobian) and the stiffness tensor (STE)::

    d      = x_j - x_i,  n = d / |d|                            current bond axis
    a_i    = q_i (r0 / 2),  a_j = q_j (r0 / 2)                  bond half-vectors carried by each particle
    delta  = d - a_i - a_j                                      relative displacement of the two bond ends
    F_n    = k_n (|d| - L)                                      (tension > 0)
    F_t    = k_t (delta - (delta . n) n)                        tangential part
    phi    = rotation vector of q_j q_i^-1                      relative rotation
    M_tw   = k_tw (phi . n) n,  M_b = k_b (phi - (phi . n) n)

Forces and moments on particle i: ``f_i = F_n n + F_t``, ``m_i = (d/2) x F_t + M_tw + M_b``; on particle j:
``f_j = -f_i``, ``m_j = (d/2) x F_t - M_tw - M_b``. Linear and angular momentum are conserved exactly, and any rigid
translation and rotation of the pair (q_i = q_j, d = q r0) gives exactly zero force and moment. To first order in
the displacements the law is the incremental law of Eq. 1-4.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxbpm.physics import rotation

__all__ = ["BondStiffness", "BondForces", "stiffness", "bond_law", "bond_forces", "bond_energy"]


class BondStiffness(NamedTuple):
    """Per-bond stiffnesses ``[nb]``: normal and tangential [N/m], twisting and bending [N m/rad]."""

    kn: jnp.ndarray
    kt: jnp.ndarray
    ktw: jnp.ndarray
    kb: jnp.ndarray


class BondForces(NamedTuple):
    """Output of :func:`bond_law` for one bond (or ``[nb, ...]`` after vmap).

    f_i: force on particle i [N] (on j it is -f_i); m_i, m_j: moments on i and j [N m];
    normal: normal force, tension > 0 [N]; shear: tangential force vector on i [N];
    twist: twisting moment (signed, about the bond axis) [N m]; bend: bending moment vector on i [N m].
    """

    f_i: jnp.ndarray
    m_i: jnp.ndarray
    m_j: jnp.ndarray
    normal: jnp.ndarray
    shear: jnp.ndarray
    twist: jnp.ndarray
    bend: jnp.ndarray


def stiffness(E, nu, area, inertia, polar, length) -> BondStiffness:
    """Bond stiffnesses (Eq. 1-4) from per-bond material and geometry arrays (all broadcastable)."""
    shear_factor = 1.0 / (2.0 * length * (1.0 + nu))
    return BondStiffness(kn=E * area / length, kt=E * area * shear_factor, ktw=E * polar * shear_factor,
                         kb=E * inertia / length)


def bond_law(d, r0, q_i, q_j, kn, kt, ktw, kb) -> BondForces:
    """Forces and moments of ONE bond.

    Args:
      d: ``[3]`` current vector x_j - x_i [m]. r0: ``[3]`` the same vector in the reference state.
      q_i, q_j: ``[4]`` orientations of the particles relative to the reference state (unit quaternions).
      kn, kt, ktw, kb: scalar stiffnesses.
    """
    length0 = jnp.sqrt(jnp.dot(r0, r0))
    length = jnp.sqrt(jnp.dot(d, d))
    n = d / length
    normal = kn * (length - length0)
    delta = d - rotation.rotate(q_i, 0.5 * r0) - rotation.rotate(q_j, 0.5 * r0)
    shear = kt * (delta - jnp.dot(delta, n) * n)
    phi = rotation.small_angle_vector(rotation.multiply(q_j, rotation.conjugate(q_i)))
    phi_n = jnp.dot(phi, n)
    bend = kb * (phi - phi_n * n)
    moment = ktw * phi_n * n + bend
    lever = jnp.cross(0.5 * d, shear)
    return BondForces(f_i=normal * n + shear, m_i=lever + moment, m_j=lever - moment, normal=normal, shear=shear,
                      twist=ktw * phi_n, bend=bend)


_bond_law_all = jax.vmap(bond_law)


def bond_forces(positions, orientations, bonds, r0, k: BondStiffness, intact=None) -> tuple[jnp.ndarray, jnp.ndarray,
                                                                                             BondForces]:
    """Per-particle force and moment sums ``([n, 3], [n, 3])`` of all intact bonds, and the per-bond forces.

    positions ``[n, 3]``, orientations ``[n, 4]`` (or ``None``: no rotational degrees of freedom, particles keep their
    reference orientation), bonds ``[nb, 2]``, r0 ``[nb, 3]`` reference bond vectors, intact ``[nb]`` bool or None.
    """
    i, j = bonds[:, 0], bonds[:, 1]
    d = positions[j] - positions[i]
    if orientations is None:
        q_i = q_j = rotation.identity(bonds.shape[0], positions.dtype)
    else:
        q_i, q_j = orientations[i], orientations[j]
    bf = _bond_law_all(d, r0, q_i, q_j, k.kn, k.kt, k.ktw, k.kb)
    if intact is not None:
        bf = jax.tree_util.tree_map(lambda a: _mask(a, intact), bf)
    n = positions.shape[0]
    force = jax.ops.segment_sum(jnp.concatenate([bf.f_i, -bf.f_i]), jnp.concatenate([i, j]), n)
    moment = jax.ops.segment_sum(jnp.concatenate([bf.m_i, bf.m_j]), jnp.concatenate([i, j]), n)
    return force, moment, bf


def _mask(a, intact):
    shape = intact.shape + (1,) * (a.ndim - 1)
    return jnp.where(intact.reshape(shape), a, jnp.zeros_like(a))


def bond_energy(positions, orientations, bonds, r0, k: BondStiffness, intact=None):
    """Elastic energy stored in the bonds [J]: 1/2 (F_n^2/k_n + |F_t|^2/k_t + M_tw^2/k_tw + |M_b|^2/k_b)."""
    _, _, bf = bond_forces(positions, orientations, bonds, r0, k, intact)
    e = 0.5 * (bf.normal**2 / k.kn + jnp.sum(bf.shear**2, axis=-1) / k.kt + bf.twist**2 / k.ktw
               + jnp.sum(bf.bend**2, axis=-1) / k.kb)
    return jnp.sum(e)
