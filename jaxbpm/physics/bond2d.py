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

import math

import jax.numpy as jnp

__all__ = ["law_components", "rotate", "cos_sin"]

#: pi / 2 in three parts of 33 significant bits or fewer (fdlibm's pio2_1, pio2_2 and pio2_2t): ``k`` times each is
#: exact for ``|k| < 2^20``, so ``theta - k pi / 2`` is the remainder to the last bit of the double
_PIO2 = (1.57079632673412561417e+00, 6.07710050630396597660e-11, 2.02226624879595063154e-21)
#: the Taylor coefficients of sin(r) / r and cos(r) in r^2, up to r^18: below 1e-17 of the value for |r| <= pi / 4
_SIN = tuple((-1) ** k / math.factorial(2 * k + 1) for k in range(10))
_COS = tuple((-1) ** k / math.factorial(2 * k) for k in range(10))


def cos_sin(theta):
    """The cosine and sine of angles, by arithmetic alone: the remainder ``r`` of ``theta`` modulo pi / 2 (Cody and
    Waite's three-part reduction), the Taylor polynomials of ``cos r`` and ``sin r`` and the quadrant's swap.

    In float64 the values are those of ``jnp.cos`` and ``jnp.sin`` to a few units in the last place (absolute errors
    below 3e-16) for ``|theta| < 1e6`` rad (160,000 turns). XLA on CPU computes those by a library call per element,
    and some programs (a bond pass compiled on its own) copy them into the gathers of both ends of every bond: several
    calls per bond. The polynomial is arithmetic that XLA vectorises, wherever it places it.

    In float32 (x64 off), where the three-part reduction is not exact, it is ``jnp.cos`` and ``jnp.sin``.

    Args:
        theta: angles [rad], any shape.

    Returns:
        ``(cos theta, sin theta)``, each shaped as ``theta``.
    """
    theta = jnp.asarray(theta)
    if theta.dtype != jnp.float64:
        return jnp.cos(theta), jnp.sin(theta)
    k = jnp.round(theta * (2.0 / math.pi))
    r = ((theta - k * _PIO2[0]) - k * _PIO2[1]) - k * _PIO2[2]
    r2 = r * r
    s, c = _SIN[-1], _COS[-1]
    for a, b in zip(_SIN[-2::-1], _COS[-2::-1]):
        s, c = a + r2 * s, b + r2 * c
    s = r * s
    quarter = k - 4.0 * jnp.floor(0.25 * k)  # 0, 1, 2 or 3: theta = r + quarter pi / 2 (mod 2 pi)
    cos = jnp.where(quarter == 0, c, jnp.where(quarter == 1, -s, jnp.where(quarter == 2, -c, s)))
    sin = jnp.where(quarter == 0, s, jnp.where(quarter == 1, c, jnp.where(quarter == 2, -s, -c)))
    return cos, sin


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
            bond); ``None``: :func:`cos_sin` of the angles.

    Returns:
        ``(f_i, m_i, m_j, normal, shear, twist, bend)``, the fields of
        :class:`~jaxbpm.physics.bond.BondForces`: ``f_i`` and ``shear`` ``(x, y)`` tuples [N], the moments ``m_i``,
        ``m_j`` and ``bend`` one-component tuples ``(z,)`` [N m], ``normal`` [N] (tension > 0) and ``twist`` (zero:
        a disc has no twist).
    """
    length0 = jnp.sqrt(r0[0] * r0[0] + r0[1] * r0[1])
    dd = d[0] * d[0] + d[1] * d[1]
    length = jnp.sqrt(dd)
    h = (0.5 * r0[0], 0.5 * r0[1])
    a_i, a_j = _turn(theta_i, turn_i, h), _turn(theta_j, turn_j, h)
    delta = (d[0] - a_i[0] - a_j[0], d[1] - a_i[1] - a_j[1])
    # F_s = k_t (delta . t) t with t = (-d_y, d_x) / |d|: the forces and moments are d's components times the two
    # divisions below, which XLA on CPU computes once per bond in loops of their own (products it copies into every
    # force and moment component it fuses them with: the rotations and projections six times a bond)
    across = kt * (d[0] * delta[1] - d[1] * delta[0]) / dd  # k_t (delta . t) / |d|
    normal = kn * (length - length0)
    stretch = normal / length
    shear = (-across * d[1], across * d[0])
    bend = kb * (theta_j - theta_i)
    lever = 0.5 * across * dd  # (d / 2) x F_s
    f_i = (stretch * d[0] + shear[0], stretch * d[1] + shear[1])
    return f_i, (lever + bend,), (lever - bend,), normal, shear, jnp.zeros_like(normal), (bend,)


def _turn(theta, turn, v):
    """:func:`rotate`, with ``turn = (cos theta, sin theta)`` when known (``None``: :func:`cos_sin` of ``theta``)."""
    c, s = cos_sin(theta) if turn is None else turn
    return c * v[0] - s * v[1], s * v[0] + c * v[1]
