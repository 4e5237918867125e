"""The elastic bond law, written once on vector components: the same code runs for one bond (scalars) and for all
bonds at once (elementwise on ``[nb]`` arrays).

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

A walkthrough: a bond of radius 0.5 mm between two spheres 2 mm apart has the axial stiffness k_n = E A / L, and a
stretch of 1 um pulls particle i towards j with k_n times the stretch; a rigid turn of the pair gives no force.

Examples:
    >>> import math
    >>> import jax
    >>> jax.config.update("jax_enable_x64", True)  # stiffness work wants float64
    >>> import jax.numpy as jnp
    >>> from jaxbpm.physics import bond, rotation
    >>> E, nu, r_b, L = 1e9, 0.25, 0.5e-3, 2e-3
    >>> A, I = math.pi * r_b**2, math.pi * r_b**4 / 4
    >>> k = bond.stiffness(E, nu, A, I, 2 * I, L)
    >>> math.isclose(k.kn, E * A / L)
    True
    >>> print(f"k_n = {k.kn:.4g} N/m, k_t = {k.kt:.4g} N/m")
    k_n = 3.927e+05 N/m, k_t = 1.571e+05 N/m
    >>> r0 = jnp.array([L, 0.0, 0.0])
    >>> still = rotation.identity(1)[0]
    >>> out = bond.bond_law(r0 + jnp.array([1e-6, 0.0, 0.0]), r0, still, still, *k)
    >>> print(f"{float(out.f_i[0]) / (k.kn * 1e-6):.6f}")  # pulled along +x, towards j
    1.000000
    >>> turn = rotation.from_rotation_vector(jnp.array([0.0, 0.0, 0.3]))
    >>> out = bond.bond_law(rotation.rotate(turn, r0), r0, turn, turn, *k)
    >>> bool(jnp.max(jnp.abs(out.f_i)) < 1e-9 * k.kn * 1e-6)
    True
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxbpm.physics import bond2d, rotation
from jaxbpm.physics.vec import cross, dot, stack

__all__ = ["law_components",
           "BondStiffness", "BondForces", "BondStrength", "stiffness", "bond_law", "bond_forces", "bond_energy",
           "bond_stresses", "bond_failure", "check_failure_rule", "FAILURE_RULES", "TENSILE", "SHEAR"]

TENSILE, SHEAR = 1, 2  # break modes (0: intact)


class BondStiffness(NamedTuple):
    """Per-bond stiffnesses (see the module docstring for their formulas).

    Attributes:
        kn: ``[nb]`` normal stiffness [N/m].
        kt: ``[nb]`` tangential stiffness [N/m].
        ktw: ``[nb]`` twisting stiffness [N m/rad].
        kb: ``[nb]`` bending stiffness [N m/rad].
    """

    kn: jnp.ndarray
    kt: jnp.ndarray
    ktw: jnp.ndarray
    kb: jnp.ndarray


class BondForces(NamedTuple):
    """Forces and moments of a bond: :func:`bond_law`'s output for one bond, ``[nb, ...]`` for all of them.

    Attributes:
        f_i: ``[3]`` force on particle i [N] (on j it is ``-f_i``).
        m_i: ``[3]`` moment on particle i [N m].
        m_j: ``[3]`` moment on particle j [N m].
        normal: normal force, tension > 0 [N].
        shear: ``[3]`` tangential force on i [N].
        twist: twisting moment, signed about the bond axis [N m].
        bend: ``[3]`` bending moment on i [N m].
    """

    f_i: jnp.ndarray
    m_i: jnp.ndarray
    m_j: jnp.ndarray
    normal: jnp.ndarray
    shear: jnp.ndarray
    twist: jnp.ndarray
    bend: jnp.ndarray


class BondStrength(NamedTuple):
    """Per-bond strengths (parallel-bond style, Potyondy & Cundall 2004) and the bond's cross-section.

    The shear strength is tau_c = c - sigma_n tan(phi) (phi = 0: a constant tau_c = c).

    Attributes:
        tensile: ``[nb]`` tensile strength sigma_c [Pa].
        cohesion: ``[nb]`` cohesion c [Pa].
        tan_phi: ``[nb]`` tan(phi) of the shear strength.
        radius: ``[nb]`` bond radius r_b [m].
        area: ``[nb]`` cross-section A [m^2].
        inertia: ``[nb]`` second moment of area I [m^4].
        polar: ``[nb]`` polar moment of area J [m^4].
        moment_factor: the moment contribution factor beta in [0, 1] (PFC's ``pb_mcf``: the share of the bending and
            twisting moments in the rim stresses; 1: all), a scalar or ``[nb]``.
    """

    tensile: jnp.ndarray
    cohesion: jnp.ndarray
    tan_phi: jnp.ndarray
    radius: jnp.ndarray
    area: jnp.ndarray
    inertia: jnp.ndarray
    polar: jnp.ndarray
    moment_factor: jnp.ndarray | float = 1.0


def bond_stresses(normal, shear, twist, bend, s: BondStrength):
    """Largest normal and shear stress at the bond's rim and the mean normal stress.

    sigma = F_n / A + beta |M_b| r_b / I (tension > 0), tau = |F_t| / A + beta |M_t| r_b / J, beta the moment
    contribution factor (1 unless set), sigma_n = F_n / A.

    Args:
        normal: ``[nb]`` normal forces [N], tension > 0.
        shear: tangential forces [N], an ``(x, y, z)`` tuple of ``[nb]`` arrays or ``[nb, 3]`` rows (2D: ``(x, y)``
            or ``[nb, 2]``).
        twist: ``[nb]`` twisting moments [N m] (2D: zeros).
        bend: bending moments [N m], an ``(x, y, z)`` tuple of ``[nb]`` arrays or ``[nb, 3]`` rows (2D: the moment
            about z, ``(m,)`` or ``[nb, 1]``: sigma = F_n / A + beta |M| r_b / I, PFC2D's rule with the rectangular
            section of :mod:`jaxbpm.physics.bond2d`).
        s: the bonds' strengths and cross-sections.

    Returns:
        ``(sigma, tau, sigma_n)``, each ``[nb]`` [Pa].
    """
    sigma_n = normal / s.area
    sigma = sigma_n + s.moment_factor * _norm(bend) * s.radius / s.inertia
    tau = _norm(shear) / s.area + s.moment_factor * jnp.abs(twist) * s.radius / s.polar
    return sigma, tau, sigma_n


#: the failure rules (``u_*`` are utilisations, a force or moment over its single-mode limit: ``u_n = F_n / (sigma_c
#: A)`` signed (tension > 0), ``u_b = |M_b| r_b / (sigma_c I)``, ``u_s = |F_t| / (tau_c A)``, ``u_t = |M_tw| r_b /
#: (tau_c J)``): a bond breaks when its rule's value reaches 1
FAILURE_RULES = {
    "separate": "max(u_n + u_b, u_s + u_t): tension and shear checked apart (parallel bond: Potyondy & Cundall "
                "2004, PFC with pb_mcf 1, MUSEN's first criterion)",
    "summed": "u_n + u_b + u_s + u_t, u_n signed (LAMMPS bond_style bpm/rotational: Fr/Fcr + Fs/Fcs + Tb/Tcb + "
              "Tt/Tct >= 1)",
    "max": "max(u_n, u_b, u_s, u_t): each load on its own (Yade's CohFrictPhys, MUSEN's second criterion)",
}


def check_failure_rule(rule, error=ValueError) -> str:
    """Check a bond failure rule's name.

    Args:
        rule: the name to check, one of :data:`FAILURE_RULES`.
        error: the exception class to raise (the caller's).

    Returns:
        ``rule``.

    Raises:
        error: ``rule`` names no failure rule (the message lists the choices).
    """
    if not isinstance(rule, str) or rule not in FAILURE_RULES:
        raise error(f"failure_rule: unknown bond failure rule {rule!r}; use one of "
                    + "; ".join(f"{k!r}: {v}" for k, v in FAILURE_RULES.items()))
    return rule


def bond_failure(normal, shear, twist, bend, s: BondStrength, rule: str = "separate"):
    """Break mode per bond by a failure rule: 0 intact, :data:`TENSILE` or :data:`SHEAR`.

    The shear strength is tau_c = c - sigma_n tan(phi). ``"separate"`` (default): sigma > sigma_c (tension, checked
    first) or tau > tau_c (shear), with the rim stresses of :func:`bond_stresses`. ``"summed"``: sigma / sigma_c + tau /
    tau_c >= 1, which is LAMMPS's Fr/Fcr + Fs/Fcs + Tb/Tcb + Tt/Tct with Fcr = sigma_c A, Tcb = sigma_c I / r_b, Fcs =
    tau_c A, Tct = tau_c J / r_b (a compressed bond carries more shear). ``"max"``: any single load at its limit. Under
    the two last rules the mode is the larger of the tensile (normal and bending) and shear (shear and twist) parts. A
    bond whose shear strength tau_c is not positive (tension beyond c / tan(phi)) breaks in shear under every rule.

    Args:
        normal, shear, twist, bend: the bonds' forces and moments, as for :func:`bond_stresses`.
        s: the bonds' strengths and cross-sections.
        rule: the failure rule, a key of :data:`FAILURE_RULES`.

    Returns:
        ``(mode, sigma, tau, tau_c)``: ``[nb]`` int8 break modes, the rim stresses of :func:`bond_stresses` and the
        shear strengths [Pa].

    Raises:
        ValueError: ``rule`` names no failure rule.
    """
    check_failure_rule(rule)
    sigma, tau, sigma_n = bond_stresses(normal, shear, twist, bend, s)
    tau_c = s.cohesion - sigma_n * s.tan_phi
    if rule == "separate":
        mode = jnp.where(sigma > s.tensile, TENSILE, jnp.where(tau > tau_c, SHEAR, 0)).astype(jnp.int8)
        return mode, sigma, tau, tau_c
    gone = tau_c <= 0
    tau_c_safe = jnp.where(gone, 1.0, tau_c)
    if rule == "summed":
        u_tension, u_shear = sigma / s.tensile, tau / tau_c_safe
        breaks = u_tension + u_shear >= 1.0
    else:
        tau_s = _norm(shear) / s.area
        u_n = sigma_n / s.tensile
        u_b = (sigma - sigma_n) / s.tensile
        u_s = tau_s / tau_c_safe
        u_t = (tau - tau_s) / tau_c_safe
        u_tension, u_shear = jnp.maximum(u_n, u_b), jnp.maximum(u_s, u_t)
        breaks = jnp.maximum(u_tension, u_shear) >= 1.0
    mode = jnp.where(gone, SHEAR, jnp.where(breaks, jnp.where(u_tension >= u_shear, TENSILE, SHEAR), 0))
    return mode.astype(jnp.int8), sigma, tau, tau_c


def _norm(v):
    """The length of vectors given as component tuples (one component in 2D: a moment about z) or ``[..., k]``."""
    if isinstance(v, tuple):
        if len(v) == 1:
            return jnp.abs(v[0])
        return jnp.sqrt(sum(c * c for c in v))
    if v.shape[-1] == 1:
        return jnp.abs(v[..., 0])
    return jnp.linalg.norm(v, axis=-1)


def stiffness(E, nu, area, inertia, polar, length) -> BondStiffness:
    """Bond stiffnesses (Eq. 1-4) from per-bond material and geometry.

    Args:
        E: Young's modulus of the bond material [Pa].
        nu: Poisson's ratio of the bond material.
        area: cross-section A [m^2].
        inertia: second moment of area I [m^4].
        polar: polar moment of area J [m^4].
        length: initial bond length L [m].

    All are scalars or ``[nb]`` arrays (broadcastable).

    Returns:
        The bonds' :class:`BondStiffness`, shaped as the arguments broadcast.
    """
    shear_factor = 1.0 / (2.0 * length * (1.0 + nu))
    return BondStiffness(kn=E * area / length, kt=E * area * shear_factor, ktw=E * polar * shear_factor,
                         kb=E * inertia / length)


def law_components(d, r0, q_i, q_j, kn, kt, ktw, kb):
    """The bond law on components, for one bond (scalars) or all bonds at once (``[nb]`` arrays).

    Written on components rather than on ``[..., 3]`` rows (see :mod:`jaxbpm.physics.rotation`), and it divides by
    ``|d|`` in the two axial projections instead of multiplying by ``n``: XLA on CPU copies cheap intermediates into
    every consumer it fuses them with, so the six force and moment components would each recompute the rotations,
    while it keeps a division as a separate loop, computing the rotations and projections once per bond.

    Args:
        d: ``(x, y, z)``, the current vector x_j - x_i [m].
        r0: ``(x, y, z)``, the same vector in the reference state [m].
        q_i, q_j: ``(w, x, y, z)``, the particles' orientations relative to the reference state (unit quaternions).
        kn, kt, ktw, kb: the stiffnesses.

    Returns:
        A :class:`BondForces` whose vectors are ``(x, y, z)`` component tuples.
    """
    h = tuple(0.5 * c for c in r0)
    length0 = jnp.sqrt(dot(r0, r0))
    length = jnp.sqrt(dot(d, d))
    inv = 1.0 / length
    n = tuple(c * inv for c in d)
    normal = kn * (length - length0)
    a_i, a_j = rotation.rotate(q_i, h), rotation.rotate(q_j, h)
    delta = tuple(d[k] - a_i[k] - a_j[k] for k in range(3))
    delta_n = dot(delta, d) / length  # = delta . n (see the docstring for the division)
    shear = tuple(kt * (delta[k] - delta_n * n[k]) for k in range(3))
    phi = rotation.small_angle_vector(rotation.multiply(q_j, rotation.conjugate(q_i)))
    phi_n = dot(phi, d) / length  # = phi . n
    bend = tuple(kb * (phi[k] - phi_n * n[k]) for k in range(3))
    twist = ktw * phi_n
    moment = tuple(twist * n[k] + bend[k] for k in range(3))
    lever = cross(tuple(0.5 * c for c in d), shear)
    return BondForces(f_i=tuple(normal * n[k] + shear[k] for k in range(3)),
                      m_i=tuple(lever[k] + moment[k] for k in range(3)),
                      m_j=tuple(lever[k] - moment[k] for k in range(3)),
                      normal=normal, shear=shear, twist=twist, bend=bend)



def bond_law(d, r0, q_i, q_j, kn, kt, ktw, kb) -> BondForces:
    """Forces and moments of one bond.

    Args:
        d: ``[3]`` current vector x_j - x_i [m].
        r0: ``[3]`` the same vector in the reference state [m].
        q_i: ``[4]`` orientation of particle i relative to the reference state (a unit quaternion).
        q_j: ``[4]`` the same for particle j.
        kn, kt, ktw, kb: the bond's stiffnesses (scalars).

    Returns:
        The bond's :class:`BondForces`, vectors ``[3]``.
    """
    return stack(law_components(tuple(d), tuple(r0), tuple(q_i), tuple(q_j), kn, kt, ktw, kb))


def bond_forces(positions, orientations, bonds, r0, k: BondStiffness, intact=None, strength=None):
    """Per-particle sums of the forces and moments of all intact bonds, and the per-bond forces.

    Args:
        positions: ``[n, 3]`` particle positions [m] (``[n, 2]``: discs, the 2D law of :mod:`jaxbpm.physics.bond2d`).
        orientations: ``[n, 4]`` orientations (unit quaternions; 2D: ``[n, 1]`` rotation angles [rad]), or ``None``:
            no rotational degrees of freedom, particles keep their reference orientation.
        bonds: ``[nb, 2]`` particle indices of the bonds.
        r0: ``[nb, 3]`` reference bond vectors [m].
        k: the bonds' stiffnesses.
        intact: ``[nb]`` bool, or ``None``: all bonds intact.
        strength: a :class:`BondStrength` to break bonds: a bond whose stresses exceed its strength in this
            evaluation carries no force from it on (:func:`bond_forces_breaking` gives the new ``intact`` mask and
            the break modes); ``None``: bonds never break.

    Returns:
        ``(forces, moments, per_bond)``: ``[n, 3]`` [N], ``[n, 3]`` [N m] (2D: ``[n, 2]`` and ``[n, 1]``) and the
        bonds' :class:`BondForces` (``[nb, ...]``).
    """
    return bond_forces_breaking(positions, orientations, bonds, r0, k, intact, strength)[:3]


def bond_forces_breaking(positions, orientations, bonds, r0, k: BondStiffness, intact=None, strength=None,
                         rule: str = "separate", extra=None, block: int | None = None):
    """:func:`bond_forces` plus the new ``intact`` mask and the break mode of each bond in this evaluation.

    Args:
        positions, orientations, bonds, r0, k, intact, strength: as for :func:`bond_forces`.
        rule: the failure rule (see :func:`bond_failure`).
        extra: ``None``, or a function ``extra(i, j, d, take)`` of the bonds' particle indices ``i, j`` and vectors
            ``d = x_j - x_i`` (an ``(x, y, z)`` tuple) returning ``(f_i, m_i, m_j, aux)``: more forces and moments
            on the same pairs (component tuples; the contact law of the bonded pairs), computed in the same pass and
            scattered to the particles after the bonds' (whatever the bond's state); ``take(a)`` gives the rows of a
            per-bond array ``[nb, ...]`` that ``i, j, d`` are for.
        block: ``None`` (one pass over all bonds), or pass over the bonds in blocks of this many: the same forces to
            round-off with less memory traffic on large samples; the per-bond forces are then ``None``.

    Returns:
        ``(forces, moments, per_bond, intact, mode)``, and ``aux`` (``extra``'s pytree of per-bond arrays) sixth
        when ``extra`` is given: ``mode`` is ``[nb]`` int8 (0: none; ``None`` without ``strength``).
    """
    nb = bonds.shape[0]
    if block is not None and nb >= 2 * block:
        return _blocked(positions, orientations, bonds, r0, k, intact, strength, rule, extra, int(block))
    # the law runs on [nb] component arrays: gather columns of the transposed [3, n] and [4, n] arrays
    x_t = positions.T
    q_t = _disc_turns(orientations, positions.shape[1])
    rows, out, intact, mode, aux = _bond_pass(x_t, q_t, bonds[:, 0], bonds[:, 1], r0, k, intact, strength, rule,
                                              extra, lambda a: a)
    ends = jnp.concatenate([bonds[:, 0], bonds[:, 1]])
    total = jax.ops.segment_sum(rows[0], ends, positions.shape[0])
    for more in rows[1:]:
        total = total.at[ends].add(more)
    result = _split(total) + (stack(out), intact, mode)
    return result if extra is None else result + (aux,)


def _bond_pass(x_t, q_t, i, j, r0, k, intact, strength, rule, extra, take):
    """The bond law, breakage and ``extra`` on the bonds ``i, j`` (the rows ``take`` gives of the per-bond arrays):
    the ``[2 nb, 8]`` rows of (force, 0, moment, 0) for the scatter to ``i`` then ``j``, the per-bond forces, the new
    intact mask, the break modes and ``extra``'s aux."""
    d = x_t[:, j] - x_t[:, i]
    if x_t.shape[0] == 2:  # discs: one rotation angle each, with its cosine and sine (:func:`_disc_turns`)
        th_i, th_j, turn_i, turn_j = (0.0, 0.0, None, None) if q_t is None else (
            q_t[0, i], q_t[0, j], (q_t[1, i], q_t[2, i]), (q_t[1, j], q_t[2, j]))
        kn, kt, _, kb = (take(a) for a in k)
        out = BondForces(*bond2d.law_components(tuple(d), tuple(take(r0).T), th_i, th_j, kn, kt, kb, turn_i, turn_j))
    else:
        q_i, q_j = ((1.0, 0.0, 0.0, 0.0),) * 2 if q_t is None else (tuple(q_t[:, i]), tuple(q_t[:, j]))
        out = law_components(tuple(d), tuple(take(r0).T), q_i, q_j, *(take(a) for a in k))
    mode = None
    if intact is not None:
        intact = take(intact)
    if strength is not None:
        mode, *_ = bond_failure(out.normal, out.shear, out.twist, out.bend,
                                jax.tree_util.tree_map(take, strength), rule)
        was = jnp.ones(i.shape[0], bool) if intact is None else intact
        mode = jnp.where(was, mode, 0).astype(jnp.int8)
        intact = was & (mode == 0)
    # one scatter of (force, 0, moment, 0) rows for both ends: XLA's CPU scatter is several times faster for rows of
    # 4 or 8 doubles than for rows of 3 or 6 (2D: rows (f_x, f_y, m, 0))
    zero = (jnp.zeros_like(out.normal),)
    pad, tail = (zero, zero) if len(out.f_i) == 3 else ((), zero)

    def rows(f_i, m_i, m_j):
        return jnp.concatenate([jnp.stack(f_i + pad + m_i + tail, axis=1),
                                jnp.stack(tuple(-f for f in f_i) + pad + m_j + tail, axis=1)])

    total = rows(out.f_i, out.m_i, out.m_j)
    if intact is not None:
        # the broken bonds' rows masked once, on the rows: masked one field at a time, XLA fused each mask with its
        # own copy of the law (the 2D bond pass ran 2.6x slower with a mask than without)
        total = jnp.where(jnp.concatenate([intact, intact])[:, None], total, 0.0)
        out = jax.tree_util.tree_map(lambda a: _mask(a, intact), out)
    aux, total = None, (total,)
    if extra is not None:
        # extra's rows scattered on their own: added to the bond's rows before the scatter, XLA fused both laws
        # into the one loop that writes the rows, computing them again for each of the 16 columns of a bond
        e_f, e_mi, e_mj, aux = extra(i, j, tuple(d), take)
        total = total + (rows(e_f, e_mi, e_mj),)
    return total, out, intact, mode, aux


def _blocked(positions, orientations, bonds, r0, k, intact, strength, rule, extra, block):
    """:func:`bond_forces_breaking` in a loop over blocks of ``block`` bonds, each scattered into the particle sums
    as it is done. On a large sample the all-bonds pass keeps every intermediate of the law (some 40 values a bond) in
    memory between its loops; a block's stay in the caches. The last block is the last ``block`` bonds: the bonds it
    shares with the one before are computed again
    (to the same values) and scattered once."""
    nb = bonds.shape[0]
    count = -(-nb // block)
    x_t = positions.T
    q_t = _disc_turns(orientations, positions.shape[1])

    def run(b, carry):
        total, per_bond = carry
        start = jnp.minimum(b * block, nb - block)
        # the block's per-bond floats divided by a run-time one, so that XLA slices each once: left to its
        # consumers, the slice (and the break test) was computed again for every column of the block's rows
        one = (start + 1) / (start + 1)

        def piece(a):
            a = jax.lax.dynamic_slice_in_dim(a, start, block)
            return a / one.astype(a.dtype) if jnp.issubdtype(a.dtype, jnp.floating) else a

        take = _taker(nb, piece)
        pair = take(bonds)
        i, j = pair[:, 0], pair[:, 1]
        rows, _, new_intact, mode, aux = _bond_pass(x_t, q_t, i, j, r0, k, intact, strength, rule, extra, take)
        fresh = start + jnp.arange(block) >= b * block
        ends = jnp.concatenate([i, j])
        for part in rows:
            total = total.at[ends].add(jnp.where(jnp.concatenate([fresh, fresh])[:, None], part, 0.0))
        put = functools.partial(jax.lax.dynamic_update_slice_in_dim, start_index=start, axis=0)
        per_bond = jax.tree_util.tree_map(lambda whole, part: put(whole, part), per_bond, (new_intact, mode, aux))
        return total, per_bond

    # the per-bond outputs (intact mask, break modes, aux), shaped after one block's
    first = _taker(nb, lambda a: a[:block])
    shapes = jax.eval_shape(lambda: _bond_pass(x_t, q_t, bonds[:block, 0], bonds[:block, 1], r0, k, intact, strength,
                                               rule, extra, first)[2:])
    per_bond = jax.tree_util.tree_map(lambda a: jnp.zeros((nb,) + a.shape[1:], a.dtype), shapes)
    total = jnp.zeros((positions.shape[0], 8 if positions.shape[1] == 3 else 4), positions.dtype)
    total, (intact, mode, aux) = jax.lax.fori_loop(0, count, run, (total, per_bond))
    result = _split(total) + (None, intact, mode)
    return result if extra is None else result + (aux,)


def _disc_turns(orientations, dim):
    """The orientations transposed for the bond pass: ``[4, n]`` quaternions, or for discs ``[3, n]`` rows (theta,
    cos theta, sin theta) by :func:`jaxbpm.physics.bond2d.cos_sin` (arithmetic: XLA copies the rows into the gathers
    of both ends of every bond, where ``jnp.cos`` and ``jnp.sin`` cost library calls per bond); ``None`` without
    rotations."""
    if orientations is None:
        return None
    if dim == 2:
        theta = orientations[:, 0]
        return jnp.stack([theta, *bond2d.cos_sin(theta)])
    return orientations.T


def _split(total):
    """``(forces, moments)`` from the scattered rows: ``[n, 8]`` (3D: f, 0, m, 0) or ``[n, 4]`` (2D: f_x, f_y, m,
    0)."""
    if total.shape[1] == 4:
        return total[:, :2], total[:, 2:3]
    return total[:, :3], total[:, 4:7]


def _taker(nb, pick):
    """``take`` for :func:`_bond_pass`: ``pick`` on per-bond arrays (leading dimension ``nb``), others as they are."""
    def take(a):
        return pick(a) if jnp.ndim(a) > 0 and a.shape[0] == nb else a
    return take


def _mask(a, intact):
    shape = intact.shape + (1,) * (a.ndim - 1)
    return jnp.where(intact.reshape(shape), a, jnp.zeros_like(a))


def bond_energy(positions, orientations, bonds, r0, k: BondStiffness, intact=None):
    """Elastic energy stored in the bonds: 1/2 (F_n^2/k_n + |F_t|^2/k_t + M_tw^2/k_tw + |M_b|^2/k_b) summed.

    Args:
        positions, orientations, bonds, r0, k, intact: as for :func:`bond_forces`.

    Returns:
        The energy [J], a scalar.
    """
    _, _, bf = bond_forces(positions, orientations, bonds, r0, k, intact)
    e = 0.5 * (bf.normal**2 / k.kn + jnp.sum(bf.shear**2, axis=-1) / k.kt + bf.twist**2 / k.ktw
               + jnp.sum(bf.bend**2, axis=-1) / k.kb)
    return jnp.sum(e)
