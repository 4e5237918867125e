"""The bond law in two dimensions: PFC2D's parallel bond between discs in the x-y plane, written on components like
the 3D law (:func:`jaxbpm.physics.bond.law_components`), for one bond (scalars) or all bonds at once (``[nb]``).

Each disc has two translations and one rotation ``theta`` (about z). The bond is a beam of rectangular cross-section
``2 r_b x t`` (``A = 2 r_b t``, ``I = (2 r_b)^3 t / 12``, :mod:`jaxbpm._geometry`), with the stiffnesses of the 3D
bond, :func:`jaxbpm.physics.bond.stiffness`::

    k_n = E A / L      normal      [N/m]
    k_t = E A / (2 L (1 + nu))   shear  [N/m]   (PFC's k_s = k_n / kratio: kratio = 2 (1 + nu))
    k_b = E I / L      bending     [N m/rad]

Kinematics in total form, as in 3D (the 3D law restricted to the plane, with the relative rotation taken exactly)::

    d     = x_j - x_i,  n = d / |d|,  t = (-n_y, n_x)
    a_i   = R(theta_i) r0 / 2,  a_j = R(theta_j) r0 / 2         bond half-vectors carried by each disc
    delta = d - a_i - a_j
    F_n   = k_n (|d| - L)                                      (tension > 0)
    F_s   = k_t (delta . t) t                                  shear force on i
    M     = k_b (theta_j - theta_i)                            bending moment on i

Forces and moments: ``f_i = F_n n + F_s``, ``f_j = -f_i``, ``m_i = (d / 2) x F_s + M``, ``m_j = (d / 2) x F_s - M``
(``x``: the scalar cross product ``a_x b_y - a_y b_x``). Linear and angular momentum are conserved exactly, and a
rigid motion of the pair gives exactly zero force and moment. To first order this is PFC2D's linear parallel bond
(Potyondy & Cundall 2004): ``dF_n = k_n dU_n``, ``dF_s = -k_s dU_s``, ``dM = -k_b dtheta``.

A walkthrough: two discs 2 mm apart along x, bond radius 0.5 mm, unit thickness: ``A = 1e-3 m^2``; a stretch of
1 um pulls disc i towards j with ``k_n`` times it.

Examples:
    >>> import jax
    >>> jax.config.update("jax_enable_x64", True)
    >>> from jaxbpm.physics import bond, bond2d
    >>> E, nu, r_b, t, L = 1e9, 0.25, 0.5e-3, 1.0, 2e-3
    >>> A, I = 2 * r_b * t, (2 * r_b) ** 3 * t / 12
    >>> k = bond.stiffness(E, nu, A, I, 1.0, L)
    >>> f_i, m_i, m_j, normal, *_ = bond2d.law_components((L + 1e-6, 0.0), (L, 0.0), 0.0, 0.0, k.kn, k.kt, k.kb)
    >>> print(f"{float(f_i[0]) / (k.kn * 1e-6):.6f}")
    1.000000
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = ["law_components", "rotate"]


def rotate(theta, v):
    """A plane vector turned by the angle ``theta``.

    Args:
        theta: the angle [rad] (scalar or ``[nb]``).
        v: ``(x, y)`` components.

    Returns:
        ``R(theta) v`` as ``(x, y)`` components.
    """
    return _turn(theta, None, v)


def law_components(d, r0, theta_i, theta_j, kn, kt, kb, turn_i=None, turn_j=None):
    """The 2D bond law on components, for one bond (scalars) or all bonds at once (``[nb]`` arrays).

    Args:
        d: ``(x, y)``, the current vector x_j - x_i [m].
        r0: ``(x, y)``, the same vector in the reference state [m].
        theta_i, theta_j: the discs' rotations from the reference state [rad].
        kn, kt, kb: the normal, shear and bending stiffnesses.
        turn_i, turn_j: ``(cos theta, sin theta)`` of each disc when known (computed once per disc and gathered per
            bond, they spare the bond pass four sines and cosines a bond); ``None``: computed here.

    Returns:
        ``(f_i, m_i, m_j, normal, shear, twist, bend)``, the fields of
        :class:`~jaxbpm.physics.bond.BondForces`: ``f_i`` and ``shear`` ``(x, y)`` tuples [N], the moments ``m_i``,
        ``m_j`` and ``bend`` one-component tuples ``(z,)`` [N m], ``normal`` [N] (tension > 0) and ``twist`` (zero:
        a disc has no twist).
    """
    length0 = jnp.sqrt(r0[0] * r0[0] + r0[1] * r0[1])
    length = jnp.sqrt(d[0] * d[0] + d[1] * d[1])
    inv = 1.0 / length
    n = (d[0] * inv, d[1] * inv)
    h = (0.5 * r0[0], 0.5 * r0[1])
    a_i, a_j = _turn(theta_i, turn_i, h), _turn(theta_j, turn_j, h)
    delta = (d[0] - a_i[0] - a_j[0], d[1] - a_i[1] - a_j[1])
    slide = kt * (n[0] * delta[1] - n[1] * delta[0])  # k_t (delta . t), t = (-n_y, n_x)
    shear = (-slide * n[1], slide * n[0])
    normal = kn * (length - length0)
    bend = kb * (theta_j - theta_i)
    lever = 0.5 * (d[0] * shear[1] - d[1] * shear[0])
    f_i = (normal * n[0] + shear[0], normal * n[1] + shear[1])
    return f_i, (lever + bend,), (lever - bend,), normal, shear, jnp.zeros_like(normal), (bend,)


def _turn(theta, turn, v):
    """:func:`rotate`, with ``turn = (cos theta, sin theta)`` when known (``None``: computed from ``theta``)."""
    c, s = (jnp.cos(theta), jnp.sin(theta)) if turn is None else turn
    return c * v[0] - s * v[1], s * v[0] + c * v[1]
