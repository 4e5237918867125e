"""The tangent of the force laws at rest: per-bond (and per-contact) Jacobians, from the laws themselves by
forward-mode differentiation, in the forms the solvers store. The DSM's operator and preconditioner and the STE's
tensors all start here, so the three solvers integrate, linearise and estimate one and the same bond law.

Forms (``nd`` DOF per particle, 3 or 6; in 2D 2 or 3; DOF order of a pair ``(u_i, theta_i, u_j, theta_j)``):

* reduced ``[ni, no, nb]`` (:func:`bond_reduced`): ``d (f_i, m_i, m_j) / d (d, theta_i, theta_j)`` with rotations
  (9 x 9), ``d f_i / d d`` without (3 x 3), ``d = r0 + u_j - u_i`` the bond vector. The bond law sees the
  displacements only through ``d`` and ``f_j = -f_i``, so these numbers give the whole pair tangent. In 2D
  (:mod:`jaxbpm.physics.bond2d`): ``d (f_i, m_i, m_j) / d (d, theta_i, theta_j)`` 4 x 4, or 2 x 2 without rotations.
* full ``[nb, 2 nd, 2 nd]`` (:func:`full`): the pair's stiffness (minus the force Jacobian).
* unit ``[4, nb, 9]`` (:func:`bond_unit`): ``d f_i / d d`` row-major with one of (k_n, k_t, k_tw, k_b) set to one and
  the others to zero. The law is linear in its stiffnesses, so ``d f_i / d d = sum_s k_s unit[s]`` for any bond
  parameters: the STE's ``K^nm``.

A walkthrough: the stiffness of one bond along x, without rotations, has k_n along the bond and k_t across it, is
symmetric, and a rigid translation of the pair costs nothing.

Examples:
    >>> import jax
    >>> jax.config.update("jax_enable_x64", True)
    >>> import jax.numpy as jnp
    >>> from jaxbpm.physics import bond, tangent
    >>> r0 = jnp.array([[2e-3, 0.0, 0.0]])
    >>> k = bond.BondStiffness(*(jnp.array([v]) for v in (4e5, 1.6e5, 1e-3, 2e-3)))
    >>> K = tangent.bond_full(r0, k, rotations=False)[0]      # [6, 6], DOF order (u_i, u_j)
    >>> K.shape
    (6, 6)
    >>> [round(float(v) / 1e5, 9) for v in jnp.diag(K)[:3]]
    [4.0, 1.6, 1.6]
    >>> bool(jnp.allclose(K, K.T)), bool(jnp.allclose(K @ jnp.tile(jnp.array([1.0, 2.0, 3.0]), 2), 0.0))
    (True, True)
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxbpm.physics import bond as bond_mod, bond2d, contact as contact_mod, rotation

__all__ = ["bond_reduced", "full", "bond_full", "bond_unit", "contact_full"]


def bond_reduced(r0, k: bond_mod.BondStiffness, rotations: bool, z0=None) -> jnp.ndarray:
    """Reduced per-bond Jacobians of the bond law (components first, bonds last).

    One ``jax.jvp`` per input component, batched with ``vmap``, on ``[nb]`` component arrays. At rest (``z0``
    ``None``) a rotation enters as the quaternion ``(1, theta / 2)``: it agrees with the exact map to first order,
    which is all a Jacobian at rest sees. ``z0 [ni, nb]`` (``u_j - u_i``, then ``theta_i``, ``theta_j``) takes the
    Jacobians at that state instead (rotations through the exact map).

    Args:
        r0: ``[nb, 3]`` rest vectors of the bonds [m] (``[nb, 2]``: discs, the 2D law).
        k: the bonds' stiffnesses (``[nb]`` arrays).
        rotations: with the rotational DOF (``ni = no = 9``; 2D: 4) or without (3; 2D: 2).
        z0: ``[ni, nb]`` the state to take the Jacobians at, or ``None``: at rest.

    Returns:
        ``[ni, no, nb]``: ``d (f_i, m_i, m_j) / d (d, theta_i, theta_j)`` (``d f_i / d d`` without rotations).
    """
    r0c = tuple(jnp.asarray(r0).T)
    nb = r0.shape[0]
    dtype = r0.dtype
    if len(r0c) == 2:
        law, ni = _law_2d(r0c, k, rotations), (4 if rotations else 2)
    else:
        law, ni = _law_3d(r0c, k, rotations, z0), (9 if rotations else 3)
    z = jnp.zeros((ni, nb), dtype) if z0 is None else z0
    basis = jnp.broadcast_to(jnp.eye(ni, dtype=dtype)[:, :, None], (ni, ni, nb))
    return jax.vmap(lambda t: jax.jvp(law, (z,), (t,))[1])(basis)


def _law_2d(r0c, k, rotations: bool):
    """The 2D bond law as a function of the reduced DOFs ``z [2 or 4, nb]`` (``u_j - u_i``, then ``theta_i``,
    ``theta_j``) giving ``(f_i, m_i, m_j)`` (``f_i`` without rotations), stacked."""
    def law(z):
        d = (r0c[0] + z[0], r0c[1] + z[1])
        th_i, th_j = (z[2], z[3]) if rotations else (0.0, 0.0)
        f_i, m_i, m_j, *_ = bond2d.law_components(d, r0c, th_i, th_j, k.kn, k.kt, k.kb)
        return jnp.stack(f_i + m_i + m_j if rotations else f_i)

    return law


def _law_3d(r0c, k, rotations: bool, z0):
    """The 3D bond law as a function of the reduced DOFs ``z [3 or 9, nb]`` (see :func:`bond_reduced`)."""
    nb, dtype = r0c[0].shape[0], r0c[0].dtype
    one, zero = jnp.ones(nb, dtype), jnp.zeros(nb, dtype)

    def law(z):
        d = tuple(r0c[c] + z[c] for c in range(3))
        if not rotations:
            qi = qj = (one, zero, zero, zero)
        elif z0 is None:
            qi = (one,) + tuple(0.5 * z[3 + c] for c in range(3))
            qj = (one,) + tuple(0.5 * z[6 + c] for c in range(3))
        else:
            qi = tuple(rotation.from_rotation_vector(z[3:6].T).T)
            qj = tuple(rotation.from_rotation_vector(z[6:9].T).T)
        out = bond_mod.law_components(d, r0c, qi, qj, k.kn, k.kt, k.ktw, k.kb)
        parts = (out.f_i + out.m_i + out.m_j) if rotations else out.f_i
        return jnp.stack(parts)

    return law


def full(jr) -> jnp.ndarray:
    """The pair stiffness (minus the force Jacobian) from the reduced form.

    Args:
        jr: ``[ni, no, nb]``, :func:`bond_reduced`'s Jacobians.

    Returns:
        ``[nb, 2 nd, 2 nd]``, DOF order ``(u_i, theta_i, u_j, theta_j)`` (``(u_i, u_j)`` without rotations).
    """
    J = jnp.moveaxis(jr, 2, 0).transpose(0, 2, 1)  # [nb, out, in]
    size = J.shape[1]
    if size in (2, 3):  # f_i from d; f_j = -f_i
        row = jnp.concatenate([-J, J], axis=2)
        return -jnp.concatenate([row, -row], axis=1)
    dim, rot = (3, 3) if size == 9 else (2, 1)  # 9: 3D (d, theta_i, theta_j); 4: 2D (d_x, d_y, theta_i, theta_j)
    jd = J[:, :, :dim]
    rows = jnp.concatenate([-jd, J[:, :, dim:dim + rot], jd, J[:, :, dim + rot:]], axis=2)  # rows f_i, m_i, m_j
    f_i, m_i, m_j = rows[:, :dim], rows[:, dim:dim + rot], rows[:, dim + rot:]
    return -jnp.concatenate([f_i, m_i, -f_i, m_j], axis=1)


def bond_full(r0, k: bond_mod.BondStiffness, rotations: bool) -> jnp.ndarray:
    """Per-bond stiffness at rest: :func:`full` of :func:`bond_reduced`.

    Args:
        r0: ``[nb, 3]`` rest vectors of the bonds [m].
        k: the bonds' stiffnesses (``[nb]`` arrays).
        rotations: with the rotational DOF (``nd = 6``) or without (3).

    Returns:
        ``[nb, 2 nd, 2 nd]``.
    """
    return full(bond_reduced(r0, k, rotations))


def bond_unit(r0) -> jnp.ndarray:
    """Unit Jacobians: ``d f_i / d d`` of every bond at rest, without rotations, per stiffness.

    Args:
        r0: ``[nb, 3]`` rest vectors of the bonds [m] (``[nb, 2]``: discs).

    Returns:
        ``[4, nb, 9]`` (2D: ``[4, nb, 4]``): ``d f_i / d d`` (row-major) with (k_n, k_t, k_tw, k_b) set to each unit
        vector in turn.
    """
    nb, dim = r0.shape
    out = []
    for s in range(4):
        k = bond_mod.BondStiffness(*(jnp.full(nb, 1.0 if t == s else 0.0, r0.dtype) for t in range(4)))
        out.append(jnp.moveaxis(bond_reduced(r0, k, rotations=False), 2, 0).transpose(0, 2, 1).reshape(nb, dim * dim))
    return jnp.stack(out)


def contact_full(d0, radii, params: contact_mod.ContactParams, dofs: int) -> jnp.ndarray:
    """Per-contact stiffness: minus the Jacobian of the Hertz-Mindlin law (no slip, empty tangential spring).

    With 6 DOF the contact point moves with the particles' rotations (levers ``-r_j n``, ``r_i n``).

    Args:
        d0: ``[C, 3]`` pair vectors x_j - x_i [m]; their overlap is the linearisation point.
        radii: ``[C, 2]`` the pairs' radii [m].
        params: the contact parameters.
        dofs: DOF per particle, 3 or 6.

    Returns:
        ``[C, 2 nd, 2 nd]``, DOF order ``(u_i, theta_i, u_j, theta_j)``.
    """
    nd = int(dofs)
    dtype = d0.dtype

    def one(d, rad):
        ri, rj = rad[0], rad[1]

        def f(z):
            ui, uj = z[:3], z[nd:nd + 3]
            dxi = uj - ui
            if nd == 6:
                nrm = d / jnp.linalg.norm(d)
                dxi = dxi + jnp.cross(z[9:12], -rj * nrm) - jnp.cross(z[3:6], ri * nrm)
            zero = jnp.zeros(3, dtype)
            out = contact_mod.hertz_mindlin(d + uj - ui, ri, rj, 1.0, 1.0, zero, dxi, zero, params)
            parts = [out.f_i, out.m_i, -out.f_i, out.m_j] if nd == 6 else [out.f_i, -out.f_i]
            return jnp.concatenate(parts)

        return -jax.jacfwd(f)(jnp.zeros(2 * nd, dtype))

    return jax.vmap(one)(d0, radii)
