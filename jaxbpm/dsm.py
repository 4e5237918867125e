"""Direct stiffness method (DSM): the static equilibrium of the Model's forces, solved without a matrix.

Unknowns are the displacements (and, with 6 DOF per particle, the rotation vectors) of the free particles; the
clamped ones are prescribed by the scene. The residual is the Model's force function itself, so DSM and DEM differ
only by the approximations the method names: no inertia, small motion (linear DSM) and fixed contact candidates.

* **Linear** (bonds only): ``K_ff u_f = -K_fp u_p`` with ``K v`` applied bond by bond from per-bond Jacobians of the
  same bond law at rest (forward-mode derivatives, :func:`reduced_jacobians`; or a ``jax.jvp`` of the whole force
  function, ``operator="jvp"``; never an assembled matrix), solved by preconditioned CG (block-Jacobi from each
  particle's 6x6 (or 3x3) self-stiffness, plus by default a coarse space of the rigid modes of particle
  aggregates). The CG runs inside ``lax.custom_linear_solve``: derivatives with respect to the bond parameters come
  from implicit differentiation, not from unrolling the iterations; ``vmap`` over parameter sets works.
* **Nonlinear** (Hertz contacts, walls): Newton-Krylov, started from the linear bond solution; each Newton step
  solves the tangent system at the current state with GMRES (bonds and contacts element by element from their
  Jacobians there, walls by a jvp), then a backtracking line search on the residual norm. Contact candidates are the
  pairs within reach at rest (fixed in advance); a contact's tangential spring is the
  whole relative tangential displacement of its contact points since rest, capped by Coulomb (``|F_t| <= mu F_n``,
  ``slip=True``, the default) or not capped (``slip=False``: no slip, as Jarolin & Dosta 2020, 3.1.2, assumes); walls
  are ideal
  frictionless moving walls. Why slip by default: on contact-dominated samples most contacts slide in the DEM, and
  the no-slip assumption was the main error of the static solve (+16 % to +35 % on a 400-particle box at 0.2-2 %
  strain, +112 % on a bi-component agglomerate at 2 %; with slip -0.1 % to +0.0 % and +1.1 %).

Convergence is measured by the residual norm relative to the norm of the reaction forces. A solve that misses its
tolerance is reported (``converged=False`` in the stats and a warning), or raises :class:`ConvergenceError` with
``throw=True``. A sample whose free part is not held (a cluster that touches no clamped particle and no wall) raises
:class:`SceneError` naming the particles.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
import warnings
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm._compile import Program, SetupCache, capacity, compile_clock, put, size_class, traced
from jaxbpm.errors import ConvergenceError, SceneError
from jaxbpm.physics import bond as bond_mod
from jaxbpm.physics import contact as contact_mod
from jaxbpm.physics import rotation
from jaxbpm.physics import wall as wall_mod
from jaxbpm.physics.model import Model
from jaxbpm.physics.padding import pad_model, pad_rows

__all__ = ["bond_jacobians", "reduced_jacobians", "packed_jacobians", "block_diagonal", "stiffness_product",
           "tangent_operator", "linear_solve", "solve_scene", "stiffness_function", "load_cases"]


# ---------------------------------------------------------------------------------------------------- operators
def _configuration(model: Model, u):
    """Positions and orientations for a DOF array ``u [n, 3 or 6]``."""
    x = model.positions0 + u[:, :3]
    q = rotation.from_rotation_vector(u[:, 3:]) if model.rotations else None
    return x, q


def _contact_slip(model: Model, pairs, d, w):
    """Relative tangential displacement of the contact points of ``pairs [C, 2]`` since rest, as ``(x, y, z)``
    components: ``u_j - u_i + theta_j x (-r_j n) - theta_i x (r_i n)`` (the contact law keeps its tangential part),
    with ``d`` the current pair vectors (components) and ``w`` the pairs' reduced DOFs ``[3 or 9, C]``: ``u_j -
    u_i``, then (with rotations) ``theta_i`` and ``theta_j``."""
    dxi = tuple(w[c] for c in range(3))
    if not model.rotations:
        return dxi
    inv = 1.0 / jnp.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    n = tuple(c * inv for c in d)
    r_i, r_j = model.radii[pairs[:, 0]], model.radii[pairs[:, 1]]
    a = bond_mod._cross(tuple(w[6 + c] for c in range(3)), tuple(-r_j * n[c] for c in range(3)))
    b = bond_mod._cross(tuple(w[3 + c] for c in range(3)), tuple(r_i * n[c] for c in range(3)))
    return tuple(dxi[c] + a[c] - b[c] for c in range(3))


def _pair_dofs(model: Model, pairs, u):
    """The reduced DOFs of pairs ``[3 or 9, C]`` from a DOF array ``u [n, nd]``: ``u_j - u_i`` (and ``theta_i``,
    ``theta_j``), the only way the bond and contact laws see the displacements."""
    i, j = pairs[:, 0], pairs[:, 1]
    ut = u.T
    z = [ut[c, j] - ut[c, i] for c in range(3)]
    if model.rotations:
        z += [ut[3 + c, i] for c in range(3)] + [ut[3 + c, j] for c in range(3)]
    return jnp.stack(z)  # one gather per row: a concatenation of [3, P] gathers runs 4x slower on CPU


def _internal_forces(model: Model, params, u, contacts=None, walls=None):
    """Generalised forces ``[n, 3 or 6]`` (forces, then moments) at the DOF state ``u``."""
    x, q = _configuration(model, u)
    con = None
    if contacts is not None:
        pairs, valid = contacts
        i, j = pairs[:, 0], pairs[:, 1]
        dxi = jnp.stack(_contact_slip(model, pairs, tuple((x[j] - x[i]).T), _pair_dofs(model, pairs, u)), axis=1)
        zeros = jnp.zeros_like(dxi)
        con = (pairs, valid, zeros, dxi, zeros)
    wp, wn = (None, None) if walls is None else walls
    f, m, parts = model.forces(x, q, params, contacts=con, wall_points=wp, wall_normals=wn)
    gen = jnp.concatenate([f, m], axis=1) if model.rotations else f
    return gen, parts


def reduced_jacobians(model: Model, params, u=None) -> jnp.ndarray:
    """Per-bond force Jacobians at rest in the reduced form the solver stores, ``[ni, no, nb]`` (components first,
    bonds last): ``d (f_i, m_i, m_j) / d (d, theta_i, theta_j)`` with 6 DOF per particle (9 x 9 per bond), ``d f_i /
    d d`` with 3 (3 x 3), where ``d = r0 + u_j - u_i`` is the bond vector. The bond law sees the displacements only
    through ``d`` and ``f_j = -f_i``, so these numbers give the whole 12 x 12 (6 x 6) tangent (:func:`bond_jacobians`)
    in 56 % (25 %) of its memory.

    Forward-mode derivatives (one ``jax.jvp`` per input component, batched with ``vmap``) of the same bond law the
    DEM runs, on ``[nb]`` component arrays. A rotation enters as the quaternion ``(1, theta / 2)``: it agrees with the
    exact map to first order, which is all a Jacobian at rest sees. With a DOF state ``u`` ``[n, nd]`` the Jacobians
    are taken there instead (the tangent of a deformed configuration; rotations through the exact map).
    """
    k = model.stiffness(params)
    r0 = tuple(model.r0.T)
    nb = model.r0.shape[0]
    dtype = model.positions0.dtype
    ni = 9 if model.rotations else 3
    one, zero = jnp.ones(nb, dtype), jnp.zeros(nb, dtype)

    def law(z):
        d = tuple(r0[c] + z[c] for c in range(3))
        if not model.rotations:
            qi = qj = (one, zero, zero, zero)
        elif u is None:
            qi = (one,) + tuple(0.5 * z[3 + c] for c in range(3))
            qj = (one,) + tuple(0.5 * z[6 + c] for c in range(3))
        else:
            qi = tuple(rotation.from_rotation_vector(z[3:6].T).T)
            qj = tuple(rotation.from_rotation_vector(z[6:9].T).T)
        out = bond_mod._law(d, r0, qi, qj, k.kn, k.kt, k.ktw, k.kb)
        parts = (out.f_i + out.m_i + out.m_j) if model.rotations else out.f_i
        return jnp.stack(parts)

    z0 = jnp.zeros((ni, nb), dtype) if u is None else _pair_dofs(model, model.bonds, u)
    basis = jnp.broadcast_to(jnp.eye(ni, dtype=dtype)[:, :, None], (ni, ni, nb))
    return jax.vmap(lambda t: jax.jvp(law, (z0,), (t,))[1])(basis)


def _full_jacobians(jr) -> jnp.ndarray:
    """``[nb, 2nd, 2nd]`` stiffness (minus the force Jacobian), DOF order (u_i, theta_i, u_j, theta_j), from the
    reduced form of :func:`reduced_jacobians`."""
    J = jnp.moveaxis(jr, 2, 0).transpose(0, 2, 1)  # [nb, out, in]
    jd = J[:, :, :3]
    if J.shape[1] == 3:  # f_i from d; f_j = -f_i
        row = jnp.concatenate([-jd, jd], axis=2)
        return -jnp.concatenate([row, -row], axis=1)
    rows = jnp.concatenate([-jd, J[:, :, 3:6], jd, J[:, :, 6:9]], axis=2)  # rows f_i, m_i, m_j
    f_i, m_i, m_j = rows[:, 0:3], rows[:, 3:6], rows[:, 6:9]
    return -jnp.concatenate([f_i, m_i, -f_i, m_j], axis=1)


def bond_jacobians(model: Model, params) -> jnp.ndarray:
    """Per-bond tangent stiffness ``[nb, 12, 12]`` (or ``[nb, 6, 6]`` without rotations) at rest, in the global
    frame, DOF order (u_i, theta_i, u_j, theta_j): forward-mode derivatives of the same bond law
    (:func:`reduced_jacobians`), minus sign (stiffness)."""
    return _full_jacobians(reduced_jacobians(model, params))


@dataclasses.dataclass(frozen=True)
class BondGeometry:
    """The parameter-independent part of the bond Jacobians at rest, computed once per sample.

    The bond stiffnesses are the bond's Young's modulus times its geometry, the shear ones (k_t, k_tw) also times
    ``s = 1 / (2 (1 + nu))`` (:func:`jaxbpm.physics.bond.stiffness`), and the force Jacobians at rest are linear in
    the stiffnesses, so every bond's Jacobian is ``E_b (J_E + s_b J_G)``: ``reduced [2, ni, no, nb]`` holds ``J_E``
    and ``J_G`` in the form of :func:`reduced_jacobians` (forward-mode derivatives of the bond law, with unit
    modulus), ``packed [2, np, nb]`` the same in the form of :func:`packed_jacobians`. A solve then builds its
    Jacobians from the parameters with two multiply-adds per number instead of differentiating the bond law again.
    The preconditioner is linear in the Jacobians as well: ``blocks [M, 2, n, nd, nd]`` are each particle's
    self-stiffness blocks (:func:`block_diagonal`) and ``coarse [M, 2, 6 na, 6 na]`` the Galerkin coarse matrix of a
    :class:`CoarseSpace`, per bond material and part, so a solve only weighs and sums them (``coarse`` is ``None``
    without a coarse space; both are ``None`` when not built: no material count given, more than
    ``_MAX_PRECOMPUTED_MATERIALS`` materials, or more than ``_MAX_PRECOMPUTED_BYTES`` of memory).
    Build it with :func:`bond_geometry`.
    """

    reduced: Any
    packed: Any
    blocks: Any = None
    coarse: Any = None


jax.tree_util.register_dataclass(BondGeometry, data_fields=["reduced", "packed", "blocks", "coarse"],
                                 meta_fields=[])

_MAX_PRECOMPUTED_MATERIALS = 8
_MAX_PRECOMPUTED_BYTES = 2 ** 30  # memory for the preconditioner's parts; above it they are assembled per solve


def _unit_stiffnesses(model: Model, nu):
    """``(k(E=1, nu), s)``: the bond stiffnesses per unit modulus and the shear factor s(nu) of each bond, from the
    stiffness law itself."""
    one = jnp.ones_like(model.bond_length)
    k = bond_mod.stiffness(one, nu, model.bond_area, model.bond_I, model.bond_J, model.bond_length)
    return k, _shear_factor(nu)


def _shear_factor(nu):
    """``s(nu)``, the factor of the shear stiffnesses: k_t of a bar of unit modulus, area and length."""
    return bond_mod.stiffness(1.0, nu, 1.0, 1.0, 1.0, 1.0).kt


@jax.jit
def _geometry_parts(model: Model):
    dtype = model.positions0.dtype
    zero = jnp.zeros_like(model.bond_length)
    # the stiffness at two Poisson ratios separates the modulus part from the shear part: k = k_E + s k_G
    k0, s0 = _unit_stiffnesses(model, zero)
    k1, s1 = _unit_stiffnesses(model, zero + 1.0)
    kg = jax.tree_util.tree_map(lambda a, b: (a - b) / (s0 - s1), k0, k1)
    ke = jax.tree_util.tree_map(lambda a, g: a - s0 * g, k0, kg)
    # the decomposition must reproduce the law at another ratio (it does unless the stiffness law changes form)
    k2, s2 = _unit_stiffnesses(model, zero + 0.3)
    err = jnp.max(jnp.stack([jnp.max(jnp.abs(a - (e + s2 * g))) / jnp.maximum(jnp.max(jnp.abs(a)),
                                                                               jnp.finfo(dtype).tiny)
                             for a, e, g in zip(k2, ke, kg)]))
    reduced = jnp.stack([reduced_jacobians(model, ke), reduced_jacobians(model, kg)])
    return reduced, err


@functools.partial(jax.jit, static_argnames=("n_materials",))
def _preconditioner_parts(model: Model, reduced, coarse, n_materials):
    """Block diagonals and coarse matrices per (material, part) of :class:`BondGeometry`."""
    def one(mp):
        m, part = mp // 2, mp % 2
        jac = jnp.where(model.bond_material == m.astype(model.bond_material.dtype), jnp.take(reduced, part, axis=0),
                        0.0)
        a = None if coarse is None else _coarse_matrix(model, jac, coarse)
        return block_diagonal(model, None, jac), a

    blocks, mats = jax.lax.map(one, jnp.arange(2 * n_materials))
    blocks = blocks.reshape((n_materials, 2) + blocks.shape[1:])
    return blocks, None if coarse is None else mats.reshape((n_materials, 2) + mats.shape[1:])


def bond_geometry(model: Model, coarse: CoarseSpace | None = None, *, n_materials: int | None = None
                  ) -> BondGeometry | None:
    """:class:`BondGeometry` of the model's bonds (``None`` without bonds). With ``n_materials`` (the length of
    ``params["bond_E"]``; at most ``_MAX_PRECOMPUTED_MATERIALS``), the preconditioner's parts as well, for the
    :class:`CoarseSpace` ``coarse`` (or block-Jacobi alone with ``None``)."""
    if model.bonds.shape[0] == 0:
        return None
    reduced, err = _geometry_parts(model)
    if not float(err) < 1e-10:
        raise RuntimeError(f"bond stiffness is not of the form E (k_E + k_G / (2 (1 + nu))) (mismatch {err:.3g})")
    geometry = BondGeometry(reduced=reduced, packed=_packed_all(reduced))
    nd = 6 if model.rotations else 3
    per_material = 2 * (model.n * nd * nd + (0 if coarse is None else (6 * coarse.count) ** 2))
    if (n_materials is not None and 0 < n_materials <= _MAX_PRECOMPUTED_MATERIALS
            and n_materials * per_material * reduced.dtype.itemsize <= _MAX_PRECOMPUTED_BYTES):
        blocks, mats = _preconditioner_parts(model, reduced, coarse, int(n_materials))
        geometry = dataclasses.replace(geometry, blocks=blocks, coarse=mats)
    return geometry


def _weights(params):
    """``[M, 2]``: each material's weights ``(E, E s)`` of :class:`BondGeometry`'s two parts (the preconditioner's
    per-material sums are exact only for the material count they were built with)."""
    e = jnp.asarray(params["bond_E"])
    return jnp.stack([e, e * _shear_factor(jnp.asarray(params["bond_nu"]).astype(e.dtype))], axis=1)


def _bond_factors(model: Model, params):
    """Per-bond ``(E_b, E_b s_b)``: the material weights (:func:`_weights`) of each bond."""
    w = _weights(params)[model.bond_material]
    return w[:, 0], w[:, 1]


def _uses_geometry(geometry, params) -> bool:
    return geometry is not None and isinstance(params, dict) and {"bond_E", "bond_nu"} <= set(params) and not (
        "_stiffness" in params)


def _geometric_jacobians(model: Model, params, geometry: BondGeometry):
    """Reduced and packed Jacobians of the bonds at rest from :class:`BondGeometry` and the parameters."""
    a, b = _bond_factors(model, params)
    jr = a[None, None] * geometry.reduced[0] + b[None, None] * geometry.reduced[1]
    jp = a[None] * geometry.packed[0] + b[None] * geometry.packed[1]
    return jr, jp, (a, b)


def _geometric_operator(model: Model, params, geometry: BondGeometry):
    """``v -> K v`` of the bonds from :class:`BondGeometry` (and the reduced Jacobians, for the preconditioner).
    The value streams the packed Jacobians; the derivative with respect to the parameters goes through the two
    per-bond weights only (the product of each geometric part with ``v``, scaled bond by bond), so neither the
    packing nor the 81-number form is differentiated."""
    jr, jp, (a, b) = _geometric_jacobians(model, params, geometry)
    return (lambda v: _weighted_product(model, geometry.packed, a, b, jp, v)), jr


@jax.custom_jvp
def _weighted_product(model: Model, parts, a, b, jp, v):
    return stiffness_product(model, jp, v)


@_weighted_product.defjvp
def _weighted_product_jvp(primals, tangents):
    model, parts, a, b, jp, v = primals
    _, _, a_dot, b_dot, _, v_dot = tangents  # jp = a parts[0] + b parts[1]: its tangent follows from a_dot, b_dot
    bonds = model.bonds
    z = _pair_dofs(model, bonds, v)
    y_dot = a_dot[None] * _apply_packed(parts[0], z) + b_dot[None] * _apply_packed(parts[1], z)
    return (_weighted_product(model, parts, a, b, jp, v),
            _scatter_pairs(model, bonds[:, 0], bonds[:, 1], y_dot) + _weighted_product(model, parts, a, b, jp, v_dot))


def stiffness_product(model: Model, jr, v):
    """``K v`` for the whole sample from the reduced per-bond Jacobians ``jr`` (:func:`reduced_jacobians`, or their
    packed symmetric form at rest, :func:`packed_jacobians`), element by element: gather both ends of every bond, ``ni
    x no`` multiply-adds per bond on ``[nb]`` arrays, one scatter
    of both ends' rows (padded to 4 or 8 numbers, which XLA on CPU scatters fastest). No global matrix is formed;
    ``K`` is the positive (stiffness) sign of the force Jacobian."""
    b = model.bonds
    z = _pair_dofs(model, b, v)
    return _scatter_pairs(model, b[:, 0], b[:, 1], _apply_packed(jr, z) if jr.ndim == 2 else _apply(jr, z))


_UPPER3 = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def packed_jacobians(jr) -> jnp.ndarray:
    """The reduced Jacobians at rest (:func:`reduced_jacobians`) in the packed form the linear solve streams through
    at every CG iteration, ``[45, nb]`` (``[6, nb]`` with 3 DOF per particle): the bond stiffness is symmetric at rest
    (the bond law has a potential there), so of the 9 x 9 numbers ``J = d (f_i, m_i, m_j) / d (d, theta_i,
    theta_j)`` only the upper triangles of ``d f_i / d d``, ``d m_i / d theta_i``, ``d m_j / d theta_j`` and the full
    ``d f_i / d theta_i``, ``d f_i / d theta_j``, ``d m_i / d theta_j`` are kept (``d m_i / d d = -(d f_i /
    d theta_i)^T``, ``d m_j / d d = -(d f_i / d theta_j)^T``, ``d m_j / d theta_i = (d m_i / d theta_j)^T``). The
    product reads 56 % of the memory of the 9 x 9 form (the product is memory-bound on CPU). Not for a deformed
    state, whose tangent need not be symmetric."""
    def blk(ro, co, upper):
        idx = _UPPER3 if upper else tuple((a, b) for a in range(3) for b in range(3))
        return [jr[co + c, ro + o] for o, c in idx]

    parts = blk(0, 0, True)
    if jr.shape[0] == 9:
        parts += blk(0, 3, False) + blk(0, 6, False) + blk(3, 3, True) + blk(3, 6, False) + blk(6, 6, True)
    return jnp.stack(parts)


_packed_all = jax.jit(jax.vmap(packed_jacobians))


def _symmetrised(jr) -> jnp.ndarray:
    """The reduced Jacobians ``[ni, no, P]`` of the symmetric part of each pair's stiffness (for a preloaded contact
    linearised at an overlap, whose tangent is symmetric only up to its small geometric terms)."""
    J = [[jr[c, o] for c in range(jr.shape[0])] for o in range(jr.shape[1])]  # J[o][c]
    out = [[None] * len(J) for _ in J]
    blocks = [(0, 0)] if len(J) == 3 else [(0, 0), (3, 3), (6, 6)]
    for ro, co in blocks:  # diagonal blocks d f_i / d d, d m_i / d theta_i, d m_j / d theta_j: symmetric
        for a in range(3):
            for b in range(3):
                out[ro + a][co + b] = 0.5 * (J[ro + a][co + b] + J[ro + b][co + a])
    if len(J) == 9:
        for a in range(3):
            for b in range(3):
                # d m_i / d d = -(d f_i / d theta_i)^T, d m_j / d d = -(d f_i / d theta_j)^T,
                # d m_j / d theta_i = (d m_i / d theta_j)^T
                for (fr, fc), (tr, tc), sign in (((0, 3), (3, 0), -1.0), ((0, 6), (6, 0), -1.0),
                                                 ((3, 6), (6, 3), 1.0)):
                    v = 0.5 * (J[fr + a][fc + b] + sign * J[tr + b][tc + a])
                    out[fr + a][fc + b] = v
                    out[tr + b][tc + a] = sign * v
    return jnp.stack([jnp.stack([out[o][c] for o in range(len(J))]) for c in range(len(J))])


def _apply_packed(jp, z):
    """:func:`_apply` for :func:`packed_jacobians`: the force rates ``[no, P]``."""
    z = jax.lax.optimization_barrier(z)
    sym = {(a, b): k for k, (a, b) in enumerate(_UPPER3)}

    def s(base, o, c):  # symmetric block entry (o, c)
        return jp[base + sym[(min(o, c), max(o, c))]]

    def g(base, o, c):  # general block entry (o, c)
        return jp[base + 3 * o + c]

    def row(terms):
        out = None
        for coef, x in terms:
            out = coef * x if out is None else out + coef * x
        return out

    zd = [z[c] for c in range(3)]
    if jp.shape[0] == 6:
        return jnp.stack([row([(s(0, o, c), zd[c]) for c in range(3)]) for o in range(3)])
    zi, zj = [z[3 + c] for c in range(3)], [z[6 + c] for c in range(3)]
    a, b, c_, e, f, ii = 0, 6, 15, 24, 30, 39
    y_f = [row([(s(a, o, c), zd[c]) for c in range(3)] + [(g(b, o, c), zi[c]) for c in range(3)]
               + [(g(c_, o, c), zj[c]) for c in range(3)]) for o in range(3)]
    y_mi = [row([(-g(b, c, o), zd[c]) for c in range(3)] + [(s(e, o, c), zi[c]) for c in range(3)]
                + [(g(f, o, c), zj[c]) for c in range(3)]) for o in range(3)]
    y_mj = [row([(-g(c_, c, o), zd[c]) for c in range(3)] + [(g(f, c, o), zi[c]) for c in range(3)]
                + [(s(ii, o, c), zj[c]) for c in range(3)]) for o in range(3)]
    return jnp.stack(y_f + y_mi + y_mj)


def _apply(jr, z):
    """``sum_c jr[c] z[c]``: the force rates ``[no, P]`` of pairs from their reduced Jacobians ``[ni, no, P]`` and
    their reduced DOFs ``z``.

    The inputs ``z [ni, P]`` (:func:`_pair_dofs`) are materialised behind an optimisation barrier: fused into the
    multiply-adds, XLA on CPU would gather every input once per output row (``ni x no`` gathers per pair instead of
    ``ni``), which made the product 1.5x slower."""
    z = jax.lax.optimization_barrier(z)
    y = jr[0] * z[0][None]
    for c in range(1, len(z)):
        y = y + jr[c] * z[c][None]
    return y


def _packed_operator(model: Model, jac):
    """``v -> K v`` through the packed form of the reduced Jacobians ``jac`` (:func:`packed_jacobians`, computed once),
    differentiated through the reduced form: the tangent with respect to ``jac`` is the plain 81-term product of the
    tangent Jacobians. Differentiating the packing itself (45 strided slices, then 81 products reading them)
    gave reverse mode hundreds of small pads to transpose and compile (a gradient through the solve compiled 6x
    slower)."""
    packed = packed_jacobians(jac)
    return lambda v: _packed_product(model, jac, packed, v)


@jax.custom_jvp
def _packed_product(model: Model, jr, jp, v):
    return stiffness_product(model, jp, v)


@_packed_product.defjvp
def _packed_product_jvp(primals, tangents):
    model, jr, jp, v = primals
    _, jr_dot, _, v_dot = tangents  # jp is packed_jacobians(jr): its tangent follows from jr_dot
    return _packed_product(model, jr, jp, v), stiffness_product(model, jr_dot, v) + _packed_product(model, jr, jp,
                                                                                                    v_dot)


def _scatter_pairs(model: Model, i, j, y):
    """Stiffness product from pair force rates ``y`` = (f_i [, m_i, m_j]) ``[no, P]``: particle i gets minus
    (f_i [, m_i]), j gets (f_i [, -m_j]) (``f_j = -f_i``); one scatter of rows of 4 or 8 numbers."""
    zero = jnp.zeros_like(y[0])
    if model.rotations:
        rows_i = jnp.stack([-y[0], -y[1], -y[2], zero, -y[3], -y[4], -y[5], zero], axis=1)
        rows_j = jnp.stack([y[0], y[1], y[2], zero, -y[6], -y[7], -y[8], zero], axis=1)
    else:
        rows_i = jnp.stack([-y[0], -y[1], -y[2], zero], axis=1)
        rows_j = jnp.stack([y[0], y[1], y[2], zero], axis=1)
    total = jax.ops.segment_sum(jnp.concatenate([rows_i, rows_j]), jnp.concatenate([i, j]), model.n)
    return jnp.concatenate([total[:, :3], total[:, 4:7]], axis=1) if model.rotations else total[:, :3]


def _contact_jacobians(model: Model, pairs, u, d0=None, normal=False) -> jnp.ndarray:
    """Force Jacobians of the contact candidates ``pairs [C, 2]`` at the DOF state ``u`` in the reduced form of
    :func:`reduced_jacobians`, ``[ni, no, C]``: ``d (f_i [, m_i, m_j]) / d (u_j - u_i [, theta_i, theta_j])``, by
    jvps of the same contact law the DEM runs (the tangential spring is the contact points' relative tangential
    displacement since rest, :func:`_contact_slip`, as in :func:`_internal_forces`). ``d0 [C, 3]``: the pair
    vectors to linearise at instead of the rest positions (``u`` is then zero: the linearised contacts of the
    linear solve). ``normal=True``: also the Jacobians of the normal force alone (the law without its tangential
    spring: its moments vanish), ``(all, normal)``, from the same derivatives."""
    rot = model.rotations
    ni = 9 if rot else 3
    i, j = pairs[:, 0], pairs[:, 1]
    p0 = model.positions0.T
    base = [p0[c, j] - p0[c, i] for c in range(3)] if d0 is None else list(d0.T)
    r_i, r_j, m_i, m_j = model.radii[i], model.radii[j], model.mass[i], model.mass[j]
    zero = jnp.zeros(pairs.shape[0], model.positions0.dtype)
    z0 = jnp.zeros((ni, pairs.shape[0]), zero.dtype) if u is None else _pair_dofs(model, pairs, u)

    def law(z):
        d = tuple(base[c] + z[c] for c in range(3))
        dxi = _contact_slip(model, pairs, d, z)
        out = contact_mod._law(d, r_i, r_j, m_i, m_j, (zero,) * 3, dxi, (zero,) * 3, model.contact)
        parts = (out.f_i + out.m_i + out.m_j) if rot else out.f_i
        if normal:  # -F_n n: the force on i without the tangential spring
            dist = jnp.sqrt(contact_mod._dot(d, d))
            parts = parts + tuple(-out.normal * c / dist for c in d)
        return jnp.stack(parts)

    basis = jnp.broadcast_to(jnp.eye(ni, dtype=zero.dtype)[:, :, None], (ni, ni, pairs.shape[0]))
    jac = jax.vmap(lambda t: jax.jvp(law, (z0,), (t,))[1])(basis)
    if not normal:
        return jac
    no = jac.shape[1] - 3
    return jac[:, :no], jnp.concatenate([jac[:, no:], jnp.zeros_like(jac[:, 3:no])], axis=1)


def _linearised_contact_jacobians(model: Model, pairs, state) -> jnp.ndarray:
    """Symmetric positive semi-definite Jacobians (reduced form) of the contact candidates for the linear solve,
    at the DOF state ``state``: the Hertz normal stiffness at the overlap there, plus the Mindlin tangential
    stiffness scaled by the contact's secant factor ``|F_t| / |F_t without the Coulomb cap|`` at that state (1 while
    it sticks, less once it slides). A sliding contact's own tangent couples its tangential force to the normal
    displacement (not symmetric, and its symmetric part need not be positive), so CG could not use it."""
    i, j = pairs[:, 0], pairs[:, 1]
    w = _pair_dofs(model, pairs, state)
    p0 = model.positions0.T
    d = tuple(p0[c, j] - p0[c, i] + w[c] for c in range(3))
    slip = _contact_slip(model, pairs, d, w)
    zero = (jnp.zeros(pairs.shape[0], w.dtype),) * 3
    args = (d, model.radii[i], model.radii[j], model.mass[i], model.mass[j], zero, slip, zero)
    capped = contact_mod._law(*args, model.contact).spring
    free = contact_mod._law(*args, model.contact._replace(friction=jnp.asarray(1e30, w.dtype))).spring
    num, den = jnp.sqrt(bond_mod._dot(capped, capped)), jnp.sqrt(bond_mod._dot(free, free))
    secant = jnp.where(den > 0, num / jnp.where(den > 0, den, 1.0), 1.0)
    stick, normal = _contact_jacobians(model, pairs, None, jnp.stack(d, axis=1), normal=True)
    return _symmetrised(normal + secant[None, None] * (stick - normal))


def _contact_product(model: Model, pairs, jc, v):
    """``K v`` of the contacts from :func:`_contact_jacobians` (a contact's tangent need not be symmetric: sliding
    contacts, so the 9 x 9 form)."""
    return _scatter_pairs(model, pairs[:, 0], pairs[:, 1], _apply(jc, _pair_dofs(model, pairs, v)))


def block_diagonal(model: Model, params, jac=None) -> jnp.ndarray:
    """Each particle's self-stiffness block ``[n, nd, nd]`` summed over its bonds (``jac``: the reduced Jacobians
    of :func:`reduced_jacobians`)."""
    jr = reduced_jacobians(model, params) if jac is None else jac
    J = jnp.moveaxis(jr, 2, 0).transpose(0, 2, 1)  # [nb, out, in]
    if J.shape[1] == 3:
        return (jax.ops.segment_sum(J, model.bonds[:, 0], model.n)
                + jax.ops.segment_sum(J, model.bonds[:, 1], model.n))
    # K_ii = [[J(f_i, d), -J(f_i, th_i)], [J(m_i, d), -J(m_i, th_i)]]
    # K_jj = [[J(f_i, d), J(f_i, th_j)], [-J(m_j, d), -J(m_j, th_j)]]
    k_ii = jnp.concatenate([jnp.concatenate([J[:, 0:3, 0:3], -J[:, 0:3, 3:6]], axis=2),
                            jnp.concatenate([J[:, 3:6, 0:3], -J[:, 3:6, 3:6]], axis=2)], axis=1)
    k_jj = jnp.concatenate([jnp.concatenate([J[:, 0:3, 0:3], J[:, 0:3, 6:9]], axis=2),
                            jnp.concatenate([-J[:, 6:9, 0:3], -J[:, 6:9, 6:9]], axis=2)], axis=1)
    return jax.ops.segment_sum(k_ii, model.bonds[:, 0], model.n) + jax.ops.segment_sum(k_jj, model.bonds[:, 1],
                                                                                       model.n)


@dataclasses.dataclass(frozen=True)
class CoarseSpace:
    """Rigid-body modes of aggregates of particles: the coarse level of the two-level preconditioner.

    The particles are grouped into aggregates by a regular grid of cells; each aggregate contributes its six rigid
    motions (three translations, three rotations about its centroid), restricted to the free DOFs. Build it with
    :func:`coarse_space`.
    """

    labels: Any   # [n] aggregate of each particle
    basis: Any    # [n, nd, 6] each particle's DOFs for a unit rigid mode of its aggregate (zero rows: prescribed)
    bonds: Any    # [m] bonds that can couple rigid modes (ends in different aggregates or on a prescribed DOF)
    count: int    # number of aggregates


jax.tree_util.register_dataclass(CoarseSpace, data_fields=["labels", "basis", "bonds"], meta_fields=["count"])


def coarse_space(model: Model, free, *, aggregate_size=None) -> CoarseSpace:
    """Aggregates of about ``aggregate_size`` particles (default ``max(100, n / 250)``: at most ~1500 coarse DOFs,
    whose dense Cholesky factor costs little) from a grid over the sample's bounding box."""
    pos = np.asarray(model.positions0)
    free = np.asarray(free)
    n, nd = free.shape
    per = max(100.0, n / 250.0) if aggregate_size is None else float(aggregate_size)
    if not per >= 1:
        raise ValueError(f"aggregate_size must be at least 1 particle, got {aggregate_size!r}")
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    ext = np.maximum(hi - lo, 1e-300)
    # cells of (about) equal sides, ~per particles each
    side = (np.prod(ext) * per / n) ** (1.0 / 3.0)
    cells = np.maximum(np.round(ext / side), 1).astype(np.int64)
    g = np.minimum(((pos - lo) / ext * cells).astype(np.int64), cells - 1)
    _, labels = np.unique((g[:, 0] * cells[1] + g[:, 1]) * cells[2] + g[:, 2], return_inverse=True)
    labels = labels.reshape(-1)
    count = int(labels.max()) + 1
    weight = np.bincount(labels, minlength=count).astype(float)
    centroid = np.stack([np.bincount(labels, pos[:, k], minlength=count) / weight for k in range(3)], axis=1)
    r = pos - centroid[labels]
    basis = np.zeros((n, nd, 6))
    basis[:, :3, :3] = np.eye(3)
    # rotation w about the centroid: u = w x r = -[r]x w, theta = w
    basis[:, 0, 4], basis[:, 0, 5] = r[:, 2], -r[:, 1]
    basis[:, 1, 3], basis[:, 1, 5] = -r[:, 2], r[:, 0]
    basis[:, 2, 3], basis[:, 2, 4] = r[:, 1], -r[:, 0]
    if nd == 6:
        basis[:, 3:, 3:] = np.eye(3)
    basis *= free[:, :, None]
    b = np.asarray(model.bonds)
    held = ~free.all(axis=1)
    # a bond inside one aggregate with both ends free moves rigidly under every coarse mode: it adds nothing
    coupling = np.flatnonzero((labels[b[:, 0]] != labels[b[:, 1]]) | held[b[:, 0]] | held[b[:, 1]])
    dtype = model.positions0.dtype
    return CoarseSpace(labels=put(labels, np.int32), basis=put(basis, dtype),
                       bonds=put(coupling, np.int32), count=count)


def _coarse_factor(model: Model, jac, coarse: CoarseSpace):
    """Cholesky factor of the Galerkin coarse matrix ``P^T K_ff P`` [6 na, 6 na] (:func:`_coarse_matrix`)."""
    return _factor_coarse(_coarse_matrix(model, jac, coarse))


def _coarse_matrix(model: Model, jac, coarse: CoarseSpace):
    """The Galerkin coarse matrix ``P^T K_ff P`` [6 na, 6 na], assembled bond by bond from the coupling bonds
    (``jac``: reduced Jacobians of every bond, :func:`reduced_jacobians`)."""
    na = coarse.count
    sel = coarse.bonds
    jb = _full_jacobians(jac[:, :, sel])
    nd = jb.shape[1] // 2
    i, j = model.bonds[sel, 0], model.bonds[sel, 1]
    pi, pj = coarse.basis[i], coarse.basis[j]
    ai, aj = coarse.labels[i], coarse.labels[j]
    ti, tj = jnp.swapaxes(pi, 1, 2), jnp.swapaxes(pj, 1, 2)
    # batched `@` (4x faster on CPU than the same three-operand einsum, which XLA runs as two generic dots)
    blocks = [(ai, ai, ti @ (jb[:, :nd, :nd] @ pi)), (ai, aj, ti @ (jb[:, :nd, nd:] @ pj)),
              (aj, ai, tj @ (jb[:, nd:, :nd] @ pi)), (aj, aj, tj @ (jb[:, nd:, nd:] @ pj))]
    keys = jnp.concatenate([r * na + c for r, c, _ in blocks])
    dense = jax.ops.segment_sum(jnp.concatenate([g for _, _, g in blocks]), keys, na * na)
    return dense.reshape(na, na, 6, 6).transpose(0, 2, 1, 3).reshape(6 * na, 6 * na)


def _factor_coarse(a):
    a = 0.5 * (a + a.T)
    diag = jnp.diagonal(a)
    # modes without any free DOF (an aggregate inside a clamped layer) get a unit diagonal; a tiny shift keeps the
    # factorisation safe when an aggregate has too few free particles for six independent rigid modes (3 DOF)
    a = a + jnp.diag(jnp.where(diag > 0, 1e-10 * jnp.max(diag), 1.0))
    return jnp.linalg.cholesky(a)


def _coarse_for(model: Model, free, preconditioner, aggregate_size):
    """The coarse space a linear solve uses: ``"two-level"`` and ``"auto"`` build one, ``"jacobi"`` none."""
    if preconditioner not in ("auto", "two-level", "jacobi"):
        raise ValueError(f"preconditioner must be 'auto', 'two-level' or 'jacobi', got {preconditioner!r}")
    if preconditioner == "jacobi" or model.bonds.shape[0] == 0:
        return None
    return coarse_space(model, free, aggregate_size=aggregate_size)


def _preconditioner(model: Model, params, free, jac=None, coarse: CoarseSpace | None = None,
                    geometry: BondGeometry | None = None, extra=None):
    """Block-Jacobi: inverse of each particle's self-stiffness on its free DOFs (identity on the rest); with a
    :class:`CoarseSpace`, plus the coarse correction ``P (P^T K_ff P)^-1 P^T`` (additive two-level). With a
    ``geometry`` that holds the preconditioner's parts (built for this ``coarse``), they are weighed by the
    parameters instead of being assembled from the Jacobians. ``extra``: ``(pair_model, pair_jac, pair_coarse)``,
    further springs (the linearised contacts: a model whose ``bonds`` are the pairs, their reduced Jacobians, and the
    coarse space with ``bonds`` indexing the pairs that couple its modes) added to the blocks and coarse matrix."""
    precomputed = (_uses_geometry(geometry, params) and geometry.blocks is not None
                   and geometry.blocks.shape[0] == jnp.shape(params["bond_E"])[0]
                   and (coarse is None or geometry.coarse is not None))
    if precomputed:
        w = jax.lax.stop_gradient(_weights(params))
        blocks = jnp.einsum("mp,mpnab->nab", w, geometry.blocks)
        coarse_matrix = None if coarse is None else jnp.einsum("mp,mpab->ab", w, geometry.coarse)
    else:
        if jac is None and coarse is not None:
            jac = reduced_jacobians(model, params)
        jac = None if jac is None else jax.lax.stop_gradient(jac)
        blocks = jax.lax.stop_gradient(block_diagonal(model, params, jac))
        coarse_matrix = None if coarse is None else _coarse_matrix(model, jac, coarse)
    if extra is not None:
        pair_model, pair_jac, pair_coarse = extra
        pair_jac = jax.lax.stop_gradient(pair_jac)
        blocks = blocks + block_diagonal(pair_model, None, pair_jac)
        if coarse is not None:
            coarse_matrix = coarse_matrix + _coarse_matrix(pair_model, pair_jac, pair_coarse)
    nd = blocks.shape[1]
    eye = jnp.eye(nd, dtype=blocks.dtype)
    mask = free[:, :, None] & free[:, None, :]
    blocks = jnp.where(mask, blocks, eye[None])
    # particles without bonds (contacts only): a scalar guess from the mean bond diagonal keeps the block regular
    scale = jnp.mean(jnp.abs(jnp.diagonal(blocks, axis1=1, axis2=2)), axis=0)
    empty = jnp.all(jnp.abs(jnp.where(mask, blocks, 0.0)) == 0, axis=(1, 2))
    blocks = jnp.where(empty[:, None, None], jnp.diag(scale)[None], blocks)
    inv = jnp.linalg.inv(blocks)
    factor = None if coarse is None else _CholeskyBlocks.of(_factor_coarse(coarse_matrix))
    return Preconditioner(inv=inv, free=free, factor=factor, coarse=coarse)


_preconditioner_jit = jax.jit(_preconditioner)


@dataclasses.dataclass(frozen=True)
class _CholeskyBlocks:
    """A lower Cholesky factor ``L`` cut into diagonal blocks of ``size`` rows, for ``A^-1 r`` by blocked forward
    and back substitution: the inverses of the diagonal blocks and the off-diagonal panels are taken once, and every
    application is a few matrix-vector products (4x faster on CPU than a triangular solve with one right-hand side,
    which XLA runs as a scalar loop)."""

    inv_diag: Any   # list of [b, b]: inverses of the diagonal blocks of L
    rows: Any       # list of [b, start]: L[block, :start] (row panel left of each diagonal block)
    cols_t: Any     # list of [b, m - end]: L[end:, block]^T (column panel below each diagonal block, transposed)

    size = 96

    @classmethod
    def of(cls, factor):
        m = factor.shape[0]
        e = list(range(0, m, cls.size)) + [m]
        eye = jnp.eye(cls.size, dtype=factor.dtype)
        inv_diag = [jax.scipy.linalg.solve_triangular(factor[a:b, a:b], eye[:b - a, :b - a], lower=True)
                    for a, b in zip(e[:-1], e[1:])]
        rows = [factor[a:b, :a] for a, b in zip(e[:-1], e[1:])]
        cols_t = [factor[b:, a:b].T for a, b in zip(e[:-1], e[1:])]
        return cls(inv_diag=inv_diag, rows=rows, cols_t=cols_t)

    def solve(self, r):
        """``(L L^T)^-1 r``."""
        nb = len(self.inv_diag)
        ys = []
        for k in range(nb):
            a = sum(y.shape[0] for y in ys)
            rb = r[a:a + self.inv_diag[k].shape[0]]
            if k:
                rb = rb - self.rows[k] @ jnp.concatenate(ys)
            ys.append(self.inv_diag[k] @ rb)
        xs = [None] * nb
        for k in reversed(range(nb)):
            yb = ys[k]
            if k < nb - 1:
                yb = yb - self.cols_t[k] @ jnp.concatenate(xs[k + 1:])
            xs[k] = self.inv_diag[k].T @ yb
        return jnp.concatenate(xs)


jax.tree_util.register_dataclass(_CholeskyBlocks, data_fields=["inv_diag", "rows", "cols_t"], meta_fields=[])


@dataclasses.dataclass(frozen=True)
class Preconditioner:
    """``v -> M v``: block-Jacobi (``inv`` [n, nd, nd] on the free DOFs, identity on the rest), plus the coarse
    correction when ``coarse`` is set. A pytree, so jitted solvers take it as an argument (no recompilation)."""

    inv: Any
    free: Any
    factor: Any = None
    coarse: CoarseSpace | None = None

    def __call__(self, v):
        # block-Jacobi as nd broadcast products (elementwise; a batched einsum of 6x6 blocks is slower on CPU)
        out = self.inv[:, :, 0] * v[:, None, 0]
        for c in range(1, v.shape[1]):
            out = out + self.inv[:, :, c] * v[:, None, c]
        out = jnp.where(self.free, out, v)
        if self.coarse is None:
            return out
        c = self.coarse
        vf = jnp.where(self.free, v, 0.0)
        rc = jax.ops.segment_sum(jnp.einsum("nkc,nk->nc", c.basis, vf), c.labels, c.count).reshape(-1)
        y = self.factor.solve(rc).reshape(c.count, 6)
        return out + jnp.einsum("nkc,nc->nk", c.basis, y[c.labels])


jax.tree_util.register_dataclass(Preconditioner, data_fields=["inv", "free", "factor", "coarse"], meta_fields=[])


# ---------------------------------------------------------------------------------------------------- linear solve
def tangent_operator(model: Model, params, *, operator="auto", walls=None, geometry: BondGeometry | None = None):
    """The stiffness operator at rest, ``v -> K v`` on all DOFs (``[n, nd]`` in and out), and the reduced per-bond
    Jacobians it uses (:func:`reduced_jacobians`; ``None`` for ``"jvp"``).

    operator: ``"jacobians"`` (per-bond Jacobians of the bond law at rest, applied element by element:
    :func:`stiffness_product`; bonds only), ``"jvp"`` (a Jacobian-vector product of the whole force function at
    every application; any interaction) or ``"auto"`` (``"jacobians"`` unless the model has walls or contacts). Both
    give the same operator to round-off: the Jacobians are forward-mode derivatives of the same bond law. The
    element-by-element product is several times cheaper per application; it streams the packed symmetric form
    (:func:`packed_jacobians`: 45 numbers per bond with 6 DOF per particle, 6 with 3) at every application, and the
    reduced Jacobians (81 or 9 numbers per bond) are returned for the preconditioner. With ``geometry``
    (:func:`bond_geometry`, computed once per sample) and ``params`` as ``{"bond_E", "bond_nu"}``, the Jacobians are
    built from it instead of differentiating the bond law again (same numbers to round-off).
    """
    if operator == "auto":
        operator = "jvp" if (walls is not None or model.walls is not None or model.contacts) else "jacobians"
    if operator == "jacobians":
        if walls is not None or model.walls is not None or model.contacts:
            raise SceneError("the 'jacobians' operator covers bonds only; use operator='jvp' with walls or contacts")
        if _uses_geometry(geometry, params):
            return _geometric_operator(model, params, geometry)
        jac = reduced_jacobians(model, params)
        return _packed_operator(model, jac), jac
    if operator != "jvp":
        raise ValueError(f"operator must be 'auto', 'jacobians' or 'jvp', got {operator!r}")
    nd = 6 if model.rotations else 3
    u0 = jnp.zeros((model.n, nd), model.positions0.dtype)

    def f(u):
        return _internal_forces(model, params, u, walls=walls)[0]

    return (lambda v: -jax.jvp(f, (u0,), (v,))[1]), None


def linear_solve(model: Model, params, free, u_prescribed, *, tol=1e-6, maxiter=None, walls=None,
                 operator="auto", stiffness_tol=None, coarse: CoarseSpace | None = None,
                 geometry: BondGeometry | None = None):
    """Solve the linearised equilibrium for one load case.

    free: ``[n, nd]`` bool, u_prescribed: ``[n, nd]`` (zero on free DOFs); operator: see :func:`tangent_operator`;
    stiffness_tol: also stop once the strain energy has settled to this relative change (see :func:`_cg`);
    coarse: a :class:`CoarseSpace` for the two-level preconditioner (``None``: block-Jacobi alone); geometry: a
    :class:`BondGeometry` (:func:`bond_geometry`) to build the bond Jacobians from.
    Returns ``(u, info)`` with the full displacement field and ``info = {"residual": relative residual,
    "iterations": CG iterations}``.
    Differentiable with respect to ``params``; ``vmap``-able over ``params`` or ``u_prescribed``.
    """
    full, jac = tangent_operator(model, params, operator=operator, walls=walls, geometry=geometry)
    precond = _preconditioner(model, params, free, jac, coarse, geometry)
    u, res, iterations, _ = _cg(full, precond, free, u_prescribed, tol, maxiter, stiffness_tol)
    return u, {"residual": res, "iterations": iterations}


def _cg(full, precond, free, u_prescribed, tol, maxiter, stiffness_tol=None, delay=5, x0=None):
    """Preconditioned CG on the free DOFs for the prescribed displacements ``u_prescribed``.

    Stops when the relative residual ``|K_ff v - b| / |b|`` reaches ``tol`` or, with ``stiffness_tol``, when the
    strain energy -- hence the stiffness -- has settled: CG lowers the energy of its iterate monotonically, by
    ``alpha_k gamma_k / 2`` in step ``k``, and the sum of the last ``delay`` decreases estimates the error still left
    (the Hestenes-Stiefel estimate; it over-estimates the true error in practice). The energy converges
    quadratically while the residual converges linearly, so this stops several times sooner for the same stiffness.

    x0: a first guess of the displacements (``[n, nd]``, its free DOFs are used; ``None``: zero there).

    Returns ``(u, residual, iterations, energy)``. Wrapped in ``lax.custom_linear_solve``: derivatives come from
    implicit differentiation (an adjoint solve stopped by the residual), not from unrolling the iterations.
    """
    def matvec(v):
        # identity on the prescribed DOFs keeps the operator regular, so that the adjoint (transpose) solve of
        # reverse-mode differentiation stays consistent whatever cotangent reaches those DOFs
        return jnp.where(free, full(jnp.where(free, v, 0.0)), v)

    rhs = jnp.where(free, -full(u_prescribed), 0.0)
    energy0 = 0.5 * jnp.vdot(u_prescribed, full(u_prescribed))
    limit = 10 * rhs.size if maxiter is None else maxiter

    def run(mv, b, energy_test, guess=True):
        atol2 = jnp.square(tol) * jnp.vdot(b, b)
        # the energy and the guess belong to the system K v = rhs; custom_linear_solve also calls this solve for the
        # tangents of forward-mode derivatives (K v' = b'), which get the residual test from zero
        primal = jnp.all(b == rhs) if (energy_test or (guess and x0 is not None)) else False
        x_0, r_0, e_0 = jnp.zeros_like(b), b, energy0
        if guess and x0 is not None:
            # the energy of the guess: E(x) = E(0) - x.b + x.K x / 2 = E(0) - x.(b + r) / 2 with r = b - K x
            x_0 = jnp.where(free & primal, jax.lax.stop_gradient(x0), 0.0)
            r_0 = b - mv(x_0)
            e_0 = energy0 - 0.5 * jnp.vdot(x_0, b + r_0)
        z0 = precond(r_0)
        window = jnp.zeros(delay, b.dtype)

        def done(c):
            _, r, _, _, k, energy, win = c
            small = jnp.vdot(r, r) <= atol2
            if energy_test:
                small |= primal & (k >= delay) & (jnp.sum(win) <= stiffness_tol * energy)
            return small | (k >= limit)

        def body(c):
            x, r, g, p, k, energy, win = c
            ap = mv(p)
            alpha = g / jnp.vdot(p, ap)
            x, r = x + alpha * p, r - alpha * ap
            z = precond(r)
            g2 = jnp.vdot(r, z)
            drop = 0.5 * alpha * g
            return x, r, g2, z + (g2 / g) * p, k + 1, energy - drop, win.at[k % delay].set(drop)

        init = (x_0, r_0, jnp.vdot(r_0, z0), z0, 0, e_0, window)
        x, _, _, _, k, energy, _ = jax.lax.while_loop(lambda c: ~done(c), body, init)
        return x, (k, energy)

    v, (iterations, energy) = jax.lax.custom_linear_solve(
        matvec, rhs, lambda mv, b: run(mv, b, stiffness_tol is not None),
        transpose_solve=lambda mv, b: run(mv, b, False, False), symmetric=True, has_aux=True)
    res = jnp.linalg.norm(matvec(v) - rhs) / jnp.maximum(jnp.linalg.norm(rhs), jnp.finfo(rhs.dtype).tiny)
    return u_prescribed + v, res, iterations, energy


# ---------------------------------------------------------------------------------------------------- scenes
def _free_mask(model: Model, scene, sample):
    nd = 6 if model.rotations else 3
    n = model.n
    free = np.ones((n, nd), bool)
    if scene.uses_walls:
        # frictionless walls hold the sample along the axis only: pin the lateral rigid-body motions with the least
        # constraints possible (two lateral DOFs of one bottom particle, one of another), which carry no load
        ax = scene.axis
        pos = np.asarray(sample.positions)
        lat = [k for k in range(3) if k != ax]
        bottom = np.flatnonzero(pos[:, ax] - np.asarray(sample.radii) <= (pos[:, ax] - np.asarray(sample.radii)).min()
                                + 1e-9 + float(np.mean(sample.radii)))
        c = pos[bottom].mean(axis=0)
        p0 = bottom[np.argmin(np.linalg.norm(pos[bottom] - c, axis=1))]
        p1 = bottom[np.argmax(np.linalg.norm(pos[bottom] - pos[p0], axis=1))]
        free[p0, lat] = False
        arm = pos[p1] - pos[p0]
        free[p1, lat[int(np.argmin(np.abs(arm[lat])))]] = False
        return free, np.zeros(n, bool), np.zeros(n, bool)
    fixed, driven = scene.layers(sample)
    free[fixed | driven] = False
    return free, fixed, driven


def _check_held(sample, model, free, clamped, contact_pairs=None, wall_touching=None):
    """Raise SceneError if a cluster of bonded (or touching) particles is held by nothing."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = model.n
    b = np.asarray(sample.bonds)
    if contact_pairs is not None and len(contact_pairs):
        b = np.concatenate([b, contact_pairs])
    graph = coo_matrix((np.ones(len(b)), (b[:, 0], b[:, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    held = clamped | (~free).any(axis=1)
    if wall_touching is not None:
        held = held | wall_touching
    ok = np.zeros(labels.max() + 1, bool)
    ok[labels[held]] = True
    loose = np.flatnonzero(~ok[labels])
    if loose.size:
        raise SceneError(
            f"the system is singular: {loose.size} particles belong to clusters held by no clamped particle or wall "
            f"(floating), e.g. particles {loose[:10].tolist()}; remove them or clamp part of each cluster")


def _contact_candidates(sample, model, skin):
    from scipy.spatial import cKDTree

    pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
    tree = cKDTree(pos)
    pairs = np.array(sorted(tree.query_pairs(2 * rad.max() + skin)), dtype=np.int64).reshape(-1, 2)
    if len(pairs):
        gap = np.linalg.norm(pos[pairs[:, 1]] - pos[pairs[:, 0]], axis=1) - rad[pairs[:, 0]] - rad[pairs[:, 1]]
        pairs = pairs[gap < skin]
    if sample.bond_contact == "replace" and len(pairs):
        bonded = np.asarray(model.bonded(put(pairs, np.int32)))
        pairs = pairs[~bonded]
    return pairs.astype(np.int32)


# the linearised contacts' default candidate reach, in affine approaches of two touching mean-sized particles at the
# linearisation state
_LINEAR_REACH = 4.0


def _check_contact_skin(sample, pairs, disp, skin, stats):
    """Record how many candidates touch at the linearisation state ``disp`` [n, 3] and the largest gap at rest of
    one that does; True when it comes near the candidate skin (pairs beyond it were never candidates)."""
    pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
    i, j = pairs[:, 0], pairs[:, 1]
    x = pos + disp
    touching = np.linalg.norm(x[j] - x[i], axis=1) < rad[i] + rad[j]
    gap = np.linalg.norm(pos[j] - pos[i], axis=1) - rad[i] - rad[j]
    widest = float(gap[touching].max()) if touching.any() else 0.0
    stats.update(contact_skin=float(skin), contacts_touching=int(touching.sum()), contact_gap_max=widest)
    return widest > 0.5 * skin


def _affine_field(sample, model: Model, ax, delta):
    """``[n, nd]``: the displacements of a uniform strain that moves the top of the sample by ``-delta`` along ``ax``
    and holds its bottom (no rotations, no lateral motion)."""
    x = np.asarray(sample.positions)[:, ax]
    u = np.zeros((model.n, 6 if model.rotations else 3))
    u[:, ax] = -delta * (x - x.min()) / max(x.max() - x.min(), 1e-300)
    return jnp.asarray(u, model.positions0.dtype)


def solve_scene(sample, scene, params, *, dofs=None, nonlinear=None, tol=None, linear_tol=1e-6, maxiter=None,
                newton_maxiter=30, stiffness_tol="auto", contact_skin=None, load_steps=4, throw=False,
                operator="auto", preconditioner="auto", aggregate_size=None, slip=True, contact_fraction=None,
                contact_passes=2, pad=True, _auto_skin=None):
    """Solve a :class:`~jaxbpm.scenes.UniaxialCompression` statically. See :func:`jaxbpm.solve`.

    pad: the linear bonds-only solve pads the sample to its size class (:func:`jaxbpm._compile.size_class`: held
    padding particles joined by bonds of zero stiffness), so that samples of similar size share one compiled
    program; the result is the same to round-off. Its setup (model, coarse space, bond geometry) is kept for the
    last few samples solved (:class:`jaxbpm._compile.SetupCache`): solving one sample again costs the solve alone.
    """
    arguments = dict(locals())  # for a second try with a wider contact reach
    from jaxbpm.physics.model import default_params
    from jaxbpm.result import Result

    t0 = time.perf_counter()
    rotations = None if dofs is None else {3: False, 6: True}.get(int(dofs))
    if dofs is not None and rotations is None:
        raise SceneError(f"dofs must be 3 or 6 per particle, got {dofs!r}")
    if nonlinear is None:
        nonlinear = bool(scene.contacts or scene.uses_walls)
    if not nonlinear and not scene.contacts and not scene.uses_walls:
        stiffness_tol = _linear_stiffness_tol(stiffness_tol)
        return _solve_linear(sample, scene, params, rotations=rotations, linear_tol=linear_tol, maxiter=maxiter,
                             stiffness_tol=stiffness_tol, throw=throw, operator=operator,
                             preconditioner=preconditioner, aggregate_size=aggregate_size, pad=pad, t0=t0)
    if isinstance(stiffness_tol, str) and stiffness_tol == "auto":  # the default of the linear bonds-only solve
        stiffness_tol = None
    model = scene.model(sample, rotations=rotations, contacts=False)
    if scene.uses_walls and not nonlinear:
        raise SceneError("a scene with walls needs the nonlinear DSM (walls are contacts); use nonlinear=True")
    params = default_params(sample) if params is None else params
    length, area = scene.geometry(sample)
    delta = scene.strain * length
    free_np, fixed, driven = _free_mask(model, scene, sample)
    clamped = fixed | driven
    nd = free_np.shape[1]
    ax = scene.axis
    u_p = np.zeros((model.n, nd))
    u_p[driven, ax] = -delta
    walls = None
    if scene.uses_walls:
        load = scene.loading(sample, speed=1.0)
        walls = (load.wall_points0 + load.wall_velocity * delta, load.wall_normals)  # top wall moved by delta
    frac = None
    if scene.contacts and not nonlinear:
        # the linear solve takes the contact candidates as springs linearised at `contact_fraction` of the target
        # strain (the middle of the fit range by default): first at the affine displacement field, then
        # (`contact_passes` - 1 times) at the previous solution, which puts the overlaps where the sample's
        # non-affine motion puts them
        if operator not in ("auto", "jacobians"):
            raise SceneError("linearised contacts need operator='jacobians' (or 'auto')")
        frac = float(np.mean(scene.fit_range)) if contact_fraction is None else float(contact_fraction)
        if not (0 < frac <= 1):
            raise SceneError(f"contact_fraction must lie in (0, 1], got {contact_fraction!r}")
        if int(contact_passes) < 1:
            raise SceneError(f"contact_passes must be at least 1, got {contact_passes!r}")
    pairs = lin = None
    if scene.contacts:
        skin = contact_skin if _auto_skin is None else _auto_skin
        widest_skin = 0.5 * float(np.mean(sample.radii))  # the default reach, and the most the linear path widens to
        if skin is None:
            # the linearised contacts only see the state at `contact_fraction` of the strain: four times the affine
            # approach of two touching mean-sized particles there (0.1 mean radii at 2 % strain); it doubles while a
            # touching pair comes near it (below)
            skin = widest_skin if frac is None else min(
                widest_skin, _LINEAR_REACH * frac * scene.strain * 2.0 * float(np.mean(sample.radii)))
        pairs = _contact_candidates(sample, model, skin)
        if frac is not None:
            lin = [put(pairs, np.int32), _affine_field(sample, model, ax, delta),
                   jnp.asarray(frac, model.positions0.dtype), None]
    touching = None
    if scene.uses_walls:
        pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
        reach = float(np.mean(rad)) * 0.5 + delta
        touching = ((pos[:, ax] - rad) <= (pos[:, ax] - rad).min() + reach) | (
            (pos[:, ax] + rad) >= (pos[:, ax] + rad).max() - reach)
    _check_held(sample, model, free_np, clamped, pairs, touching)
    free = jnp.asarray(free_np)
    u_p = jnp.asarray(u_p, model.positions0.dtype)

    stats = {"dofs": nd, "nonlinear": nonlinear, "free_dofs": int(free_np.sum())}
    tc = time.perf_counter()
    if not nonlinear:
        springs = model if lin is None else dataclasses.replace(model, bonds=jnp.concatenate([model.bonds, lin[0]]))
        if lin is not None:
            stats.update(contact_candidates=int(lin[0].shape[0]), contact_fraction=frac,
                         contact_passes=int(contact_passes))
        coarse = _coarse_for(springs, free_np, preconditioner, aggregate_size)
        if lin is not None and coarse is not None:
            # one coarse space (its aggregates do not depend on the springs): the bonds' part of the coarse matrix
            # comes from the bond geometry, the contacts' part is assembled from the pairs that couple its modes
            nb, cb = model.bonds.shape[0], np.asarray(coarse.bonds)
            lin[3] = dataclasses.replace(coarse, bonds=put(cb[cb >= nb] - nb, np.int32))
            coarse = dataclasses.replace(coarse, bonds=put(cb[cb < nb], np.int32))
        lin = None if lin is None else tuple(_pad_candidates(lin, sample, ax))
        geometry = None
        if operator in ("auto", "jacobians"):
            # parameter-independent, once per sample: the bond Jacobians and the preconditioner's parts per unit
            # modulus (BondGeometry); its own compilation on a new size is part of this time
            geometry = jax.block_until_ready(bond_geometry(
                model, coarse, n_materials=int(jnp.shape(params["bond_E"])[0])))
        stats["setup_time"] = time.perf_counter() - tc
        # CG starts from the affine field of the prescribed strain (the linearised contacts' first pass too)
        guess = None if lin is not None else _affine_field(sample, model, ax, delta)
        (u, force_total, force_boundary, res, iterations), compile_time, run_time = _contacts_program(
            model, params, free, u_p, linear_tol, _energy_test(stiffness_tol), coarse, lin, geometry, guess,
            maxiter=maxiter, operator=operator, contact_passes=int(contact_passes))
        res, iterations = float(res), int(iterations)
        limit = 10 * int(free_np.size) if maxiter is None else int(maxiter)
        # converged: the residual test, or (with stiffness_tol) the energy test before the iteration limit
        converged = res <= linear_tol * 1.01 or (stiffness_tol is not None and iterations < limit)
        stats.update(residual=res, residual_history=[res], converged=converged, iterations=iterations,
                     operator=operator, stiffness_tol=stiffness_tol,
                     preconditioner="jacobi" if coarse is None else "two-level",
                     aggregates=0 if coarse is None else coarse.count,
                     stiffness_boundary=float(force_boundary) / delta)
        reaction = float(force_total)
        if lin is not None and _check_contact_skin(sample, pairs, frac * np.asarray(u)[:, :3], skin, stats):
            if contact_skin is None and skin < widest_skin:
                # the default reach was too short for this sample's motion: again with twice the reach, the time
                # spent on this try counted in
                spent = time.perf_counter() - t0  # this try
                again = solve_scene(**{**arguments, "_auto_skin": min(widest_skin, 2.0 * skin)})
                retries = again.stats.get("contact_skin_retries", 0) + 1
                return dataclasses.replace(
                    again, wall_time=again.wall_time + spent, run_time=again.run_time + run_time,
                    compile_time=again.compile_time + compile_time,
                    setup_time=again.setup_time + max(spent - run_time - compile_time, 0.0),
                    stats={**again.stats, "contact_skin_retries": retries})
            warnings.warn(f"linearised contacts: a pair {stats['contact_gap_max']:.3g} m apart at rest touches at "
                          f"the linearisation state, near the candidate reach (contact_skin {skin:.3g} m): pairs "
                          f"beyond it may touch too; pass a larger contact_skin", stacklevel=3)
    else:
        tol = 1e-3 if tol is None else tol
        u, disps, forces, info, compile_time, run_time = _newton(
            model, params, free, u_p, pairs, walls, scene, tol, linear_tol, maxiter, newton_maxiter, stiffness_tol,
            driven, delta, load_steps, preconditioner, aggregate_size, slip)
        converged = info["converged"]
        stats.update(info)
    _report_convergence(converged, stats["residual"], tol if nonlinear else linear_tol, throw, stacklevel=4)
    if nonlinear:
        # the same measure as the DEM: least-squares slope of the load steps within the scene's fit range
        stiffness = scene.fit_stiffness(disps, forces, delta) if load_steps > 1 else float(forces[-1] / delta)
        disps, forces = np.concatenate([[0.0], disps]), np.concatenate([[0.0], forces])
    else:
        stiffness = reaction / delta
        disps, forces = np.array([0.0, delta]), np.array([0.0, reaction])
    stats.update(bond_forces=_bond_forces_at(dataclasses.replace(model, walls=None), params, u))
    wall = time.perf_counter() - t0
    # everything but the solver's compilation and run (model, candidates, geometry, Newton's host loop) is setup
    return Result(method="dsm", stiffness=stiffness, youngs_modulus=stiffness * length / area, gauge_length=length,
                  area=area, displacement=disps, force=forces, wall_time=wall,
                  setup_time=max(wall - compile_time - run_time, 0.0), compile_time=compile_time,
                  run_time=run_time, stats=stats, state=u)


class _LinearSetup(NamedTuple):
    """What a linear bonds-only solve of one sample needs besides the parameters (built once per sample and options,
    possibly padded to a size class): the Model, the free-DOF mask and prescribed displacements ``[n, nd]``, the
    coarse space, the bond geometry and the first guess (the affine field); the real particle and bond counts, the
    free DOF count and the target displacement."""

    model: Any
    free: Any
    u_p: Any
    coarse: Any
    geometry: Any
    guess: Any
    n: int
    nb: int
    free_dofs: int
    delta: float


def _linear_setup(sample, scene, rotations, operator, preconditioner, aggregate_size, n_materials, pad):
    model = scene.model(sample, rotations=rotations, contacts=False)
    free_np, fixed, driven = _free_mask(model, scene, sample)
    _check_held(sample, model, free_np, fixed | driven)
    nd = free_np.shape[1]
    length, _ = scene.geometry(sample)
    delta = scene.strain * length
    u_p = np.zeros((model.n, nd))
    u_p[driven, scene.axis] = -delta
    guess = np.asarray(_affine_field(sample, model, scene.axis, delta))
    n, nb = model.n, int(model.bonds.shape[0])
    free_dofs = int(free_np.sum())
    coarse = _coarse_for(model, free_np, preconditioner, aggregate_size)
    if pad:
        n_cap, nb_cap, _ = size_class(n, nb)
        model = pad_model(model, n_cap, nb_cap)
        free_np, u_p, guess = pad_rows(free_np, n_cap, False), pad_rows(u_p, n_cap), pad_rows(guess, n_cap)
        coarse = None if coarse is None else _pad_coarse(coarse, n_cap, nb, nb_cap, aggregate_size)
    geometry = None
    if operator in ("auto", "jacobians"):
        geometry = bond_geometry(model, coarse, n_materials=n_materials)
    dtype = model.positions0.dtype
    return _LinearSetup(model=model, free=put(free_np), u_p=put(u_p, dtype), coarse=coarse,
                        geometry=geometry, guess=put(guess, dtype), n=n, nb=nb, free_dofs=free_dofs,
                        delta=delta)


def _pad_coarse(coarse: CoarseSpace, n_cap: int, nb: int, nb_cap: int, aggregate_size=None) -> CoarseSpace:
    """The coarse space of a model padded to ``n_cap`` particles and ``nb_cap`` bonds (bonds from ``nb`` on are
    padding). The padding particles form no mode (zero basis rows, in the last aggregate); the aggregate count
    rounds up to a capacity that depends on the size class alone (the aggregates of the default size
    that ``n_cap`` particles make, or more when the sample has more), empty aggregates getting a unit coarse
    diagonal; the coupling bonds are padded with the padding bond ``nb`` up to ``nb_cap`` (they are only read when
    the preconditioner's parts are built, once per sample)."""
    per = max(100.0, n_cap / 250.0) if aggregate_size is None else float(aggregate_size)
    count = capacity(max(coarse.count, math.ceil(n_cap / per)), minimum=4)
    labels = pad_rows(coarse.labels, n_cap, count - 1)
    basis = pad_rows(coarse.basis, n_cap, 0.0)
    bonds = pad_rows(coarse.bonds, nb_cap, nb)
    return CoarseSpace(labels=put(labels, np.int32),
                       basis=put(basis, coarse.basis.dtype),
                       bonds=put(bonds, np.int32), count=count)


def _linear_outputs(model, params, free, u_p, tol, stiffness_tol, coarse, geometry, guess, maxiter, operator):
    """One linear solve (:func:`_linear_fn`) and the bond forces at its solution."""
    out = _linear_fn(model, params, free, u_p, tol, maxiter, operator, stiffness_tol, coarse, geometry=geometry,
                     guess=guess)
    return out, _internal_forces(model, params, out[0])[1]["bonds"]


_linear_program = Program(_linear_outputs, static_argnames=("maxiter", "operator"))
_linear_setups = SetupCache()


def _solve_linear(sample, scene, params, *, rotations, linear_tol, maxiter, stiffness_tol, throw, operator,
                  preconditioner, aggregate_size, pad, t0):
    """The linear DSM on a bonds-only scene with clamped layers (see :func:`solve_scene`): setup (kept per sample),
    one compiled program (per size class), one run."""
    from jaxbpm.physics.model import default_params
    from jaxbpm.result import Result

    params = default_params(sample) if params is None else params
    n_materials = int(jnp.shape(params["bond_E"])[0])
    key = (scene, rotations, operator, preconditioner, aggregate_size, n_materials, bool(pad))
    with compile_clock() as setup_compile:  # programs the setup compiles count as compilation
        setup = _linear_setups.get(sample, key, lambda: _linear_setup(
            sample, scene, rotations, operator, preconditioner, aggregate_size, n_materials, pad))
    setup_time = time.perf_counter() - t0 - setup_compile.seconds
    ((u, force_total, force_boundary, res, iterations), bond_forces), compile_time, _ = _linear_program(
        setup.model, params, setup.free, setup.u_p, linear_tol, _energy_test(stiffness_tol), setup.coarse,
        setup.geometry, setup.guess, maxiter=maxiter, operator=operator)
    compile_time += setup_compile.seconds
    n, nb, delta = setup.n, setup.nb, setup.delta
    res, iterations, reaction = float(res), int(iterations), float(force_total)
    u = np.asarray(u)[:n]
    limit = 10 * int(setup.free.size) if maxiter is None else int(maxiter)
    # converged: the residual test, or (with stiffness_tol) the energy test before the iteration limit
    converged = res <= linear_tol * 1.01 or (stiffness_tol is not None and iterations < limit)
    coarse = setup.coarse
    stats = {"dofs": int(setup.free.shape[1]), "nonlinear": False, "free_dofs": setup.free_dofs,
             "setup_time": setup_time, "residual": res, "residual_history": [res], "converged": converged,
             "iterations": iterations, "operator": operator, "stiffness_tol": stiffness_tol,
             "preconditioner": "jacobi" if coarse is None else "two-level",
             "aggregates": 0 if coarse is None else coarse.count,
             "stiffness_boundary": float(force_boundary) / delta,
             "size_class": [setup.model.n, int(setup.model.bonds.shape[0])],
             "bond_forces": jax.tree_util.tree_map(lambda a: np.asarray(a)[:nb], bond_forces)}
    _report_convergence(converged, res, linear_tol, throw, stacklevel=5)
    length, area = scene.geometry(sample)
    stiffness = reaction / delta
    wall = time.perf_counter() - t0
    # what is neither setup nor compilation (the run, moving its outputs to the host) is the run time
    return Result(method="dsm", stiffness=stiffness, youngs_modulus=stiffness * length / area, gauge_length=length,
                  area=area, displacement=np.array([0.0, delta]), force=np.array([0.0, reaction]), wall_time=wall,
                  setup_time=setup_time, compile_time=compile_time, run_time=wall - setup_time - compile_time,
                  stats=stats, state=u)


def _report_convergence(converged, residual, tol, throw, stacklevel):
    if converged:
        return
    msg = f"DSM did not converge: relative residual {residual:.3g} above tolerance {tol:.3g}"
    if throw:
        raise ConvergenceError(msg)
    warnings.warn(msg, stacklevel=stacklevel)


@jax.jit
def _bond_forces_at(model, params, u):
    """Per-bond forces (:class:`BondForces`) at the DOF state ``u``."""
    return _internal_forces(model, params, u)[1]["bonds"]


def _linear_fn(model, params, free, u_p, tol, maxiter, operator="auto", stiffness_tol=None, coarse=None,
               contacts=None, contact_passes=2, geometry=None, guess=None):
    """Linear solve of one load case; returns ``(u, reaction, boundary reaction, residual, iterations)``.

    reaction = ``u . K u / delta`` (twice the strain energy over the prescribed displacement ``delta``): at
    equilibrium it equals the force on the driven layer, and it is variational -- the CG iterate minimises the
    energy, so its error is quadratic in the error of ``u`` and a loose tolerance still gives an accurate stiffness.
    boundary reaction = mean of the axial forces on the driven and (minus) the resting clamped layer, the measure
    the DEM uses; the two agree to the solver's tolerance.
    contacts: ``(pairs [C, 2], u_lin [n, nd], fraction, pair_coarse)``: contact candidates linearised at the state
    ``fraction * u_lin`` (:func:`_linearised_contact_jacobians`; a pair that does not touch there adds nothing),
    added to the bonds as further springs (operator and preconditioner alike; ``pair_coarse``: ``coarse`` with
    ``bonds`` indexing the pairs that couple its modes). ``contact_passes`` solves: each later one re-linearises the
    contacts at ``fraction`` times the previous solution and starts from it; every pass but the last only places
    the contacts, and stops once the strain energy has settled to ``_PLACING_TOL`` (or at the final tolerances, if
    looser). Iterations are summed over the passes.
    geometry: :class:`BondGeometry` of the bonds (or ``None``: the Jacobians by differentiating the bond law).
    """
    if contacts is None:
        full, jac = tangent_operator(model, params, operator=operator, geometry=geometry)
        precond = _preconditioner(model, params, free, jac, coarse, geometry)
        return _linear_once(free, u_p, tol, maxiter, stiffness_tol, full, precond, guess)
    pairs, u_lin, fraction, pair_coarse = contacts
    pair_model = dataclasses.replace(model, bonds=pairs.astype(model.bonds.dtype))
    bond_op, jb = tangent_operator(model, params, operator="jacobians", geometry=geometry)
    total, x0 = 0, u_lin
    placing_tol = _PLACING_TOL if stiffness_tol is None else jnp.maximum(_PLACING_TOL, stiffness_tol)
    for k in range(contact_passes):
        last = k == contact_passes - 1
        jc = _linearised_contact_jacobians(model, pairs, fraction * u_lin)
        contact_op = _packed_operator(pair_model, jc)
        if k == 0:  # the first pass's preconditioner serves the later ones (the contacts move little)
            precond = _preconditioner(model, params, free, jb, coarse, geometry, (pair_model, jc, pair_coarse))
        out = _linear_once(free, u_p, tol, maxiter, stiffness_tol if last else placing_tol,
                           lambda v, c=contact_op: bond_op(v) + c(v), precond, x0)
        u_lin = x0 = jax.lax.stop_gradient(out[0])
        total = total + out[4]
    return out[:4] + (total,)


_linear_jit = jax.jit(_linear_fn, static_argnames=("maxiter", "operator", "contact_passes"))


def _contacts_outputs(model, params, free, u_p, tol, stiffness_tol, coarse, contacts, geometry, guess, maxiter,
                      operator, contact_passes):
    return _linear_fn(model, params, free, u_p, tol, maxiter, operator, stiffness_tol, coarse, contacts,
                      contact_passes, geometry, guess)


def _pad_candidates(lin, sample, axis):
    """The linearised contacts' candidates (and their coarse couplings) padded to a :func:`capacity`, so that samples
    and reaches with about as many candidates share the compiled solve: the padding pairs join the two particles
    farthest apart along ``axis``, which never touch (no stiffness). Left as they are when those two are not far
    enough apart."""
    pairs = np.asarray(lin[0])
    pos, rad = np.asarray(sample.positions)[:, axis], np.asarray(sample.radii)
    i, j = int(np.argmin(pos)), int(np.argmax(pos))
    if len(pairs) == 0 or pos[j] - pos[i] <= 4.0 * (rad[i] + rad[j]):
        return lin
    c = len(pairs)
    cap = capacity(c + 1)
    lin = list(lin)
    lin[0] = put(np.concatenate([pairs, np.tile(np.array([[i, j]], pairs.dtype), (cap - c, 1))]), np.int32)
    if lin[3] is not None:
        cb = np.asarray(lin[3].bonds)
        lin[3] = dataclasses.replace(lin[3], bonds=put(pad_rows(cb, capacity(len(cb) + 1), c), np.int32))
    return lin


LINEAR_STIFFNESS_TOL = 1e-6
"""The linear bonds-only solve's default ``stiffness_tol``: CG stops once the strain energy (the stiffness) has
settled to 1e-6 by the Hestenes-Stiefel estimate, which over-estimates the error: K is then within about 1e-7 of the
fully converged answer (4e-8 measured on a 3k-particle box, 26 CG iterations instead of 39 for the 1e-6 residual;
the displacement field's residual is about 3e-5). ``stiffness_tol=None`` stops on the residual alone."""


def _linear_stiffness_tol(stiffness_tol):
    """``stiffness_tol`` of a linear bonds-only solve: ``"auto"`` is :data:`LINEAR_STIFFNESS_TOL`."""
    return LINEAR_STIFFNESS_TOL if isinstance(stiffness_tol, str) and stiffness_tol == "auto" else stiffness_tol


def _energy_test(stiffness_tol):
    """``stiffness_tol`` as the programs take it: always a number (-1 turns the energy test off: the energy drops are
    never negative), so that solves with and without it share their compiled program."""
    return -1.0 if stiffness_tol is None else float(stiffness_tol)


# the linear solve with linearised contacts, compiled once per shape (its static options last)
_contacts_program = Program(_contacts_outputs, static_argnames=("maxiter", "operator", "contact_passes"))

# how far the passes that only place the linearised contacts converge (relative change of the strain energy)
_PLACING_TOL = 1e-2


def _linear_once(free, u_p, tol, maxiter, stiffness_tol, full, precond, x0=None):
    u, res, iterations, _ = _cg(full, precond, free, u_p, tol, maxiter, stiffness_tol, x0=x0)
    gen = -full(u)  # linearised internal forces
    delta = jnp.max(jnp.abs(u_p))
    energy_reaction = -jnp.vdot(u, gen) / delta
    clamped = ~jnp.any(free, axis=1)
    moving = clamped & jnp.any(u_p != 0, axis=1)
    resting = clamped & ~moving
    ax = jnp.argmax(jnp.any(u_p != 0, axis=0))
    comp = jnp.take(gen, ax, axis=1)
    reaction = 0.5 * (jnp.sum(jnp.where(moving, comp, 0.0)) - jnp.sum(jnp.where(resting, comp, 0.0)))
    return u, energy_reaction, reaction, res, iterations


@dataclasses.dataclass(frozen=True)
class _NewtonSystem:
    """Everything a Newton step needs, as one pytree (the jitted steps below compile once per shape)."""

    model: Model
    params: Any
    free: Any
    pairs: Any           # [C, 2] contact candidates (or None)
    normals: Any         # [W, 3] wall normals (or None)
    moving: Any          # [n] driven clamped particles (layers)
    resting: Any         # [n] fixed clamped particles (layers)
    precond: Preconditioner
    axis: int
    maxiter: int


jax.tree_util.register_dataclass(_NewtonSystem, data_fields=["model", "params", "free", "pairs", "normals", "moving",
                                                             "resting", "precond"],
                                 meta_fields=["axis", "maxiter"])


def _newton_residual(sys: _NewtonSystem, u, wall_points):
    con = None if sys.pairs is None else (sys.pairs, jnp.ones(sys.pairs.shape[0], bool))
    walls = None if sys.normals is None else (wall_points, sys.normals)
    gen, parts = _internal_forces(sys.model, sys.params, u, con, walls)
    return jnp.where(sys.free, gen, 0.0), gen, parts


@jax.jit
def _newton_evaluate(sys: _NewtonSystem, u, wall_points):
    """Residual norm, its scale (the external forces: reactions of clamped DOFs and of the walls) and the reaction."""
    r, gen, parts = _newton_residual(sys, u, wall_points)
    scale = jnp.linalg.norm(jnp.where(sys.free, 0.0, gen))
    if sys.normals is not None:
        scale = scale + jnp.linalg.norm(parts["walls"])
        reaction = 0.5 * (parts["walls"][1, sys.axis] - parts["walls"][0, sys.axis])
    else:
        comp = gen[:, sys.axis]
        reaction = 0.5 * (jnp.sum(jnp.where(sys.moving, comp, 0.0)) - jnp.sum(jnp.where(sys.resting, comp, 0.0)))
    scale = scale + jnp.finfo(gen.dtype).tiny
    return jnp.linalg.norm(r), scale, reaction


@jax.jit
def _newton_step(sys: _NewtonSystem, u, wall_points, krylov_tol):
    """The Newton correction: GMRES on the tangent at ``u`` (element by element for bonds and contacts, a jvp for
    walls), right-preconditioned."""
    r = _newton_residual(sys, u, wall_points)[0]
    free = sys.free
    # the tangent at u, element by element: bonds and contacts from their Jacobians at u (batched jvps of the same
    # laws, once per step; XLA on CPU runs a jvp of a pair law inside the Krylov loop several times slower), walls
    # by a jvp
    jac = reduced_jacobians(sys.model, sys.params, u)
    jc = None if sys.pairs is None else _contact_jacobians(sys.model, sys.pairs, u)

    def matvec(v):
        vf = jnp.where(free, v, 0.0)
        kv = stiffness_product(sys.model, jac, vf)
        if jc is not None:
            kv = kv + _contact_product(sys.model, sys.pairs, jc, vf)
        if sys.normals is not None:  # walls push on translations only
            m = sys.model
            fw = jax.jvp(lambda x: wall_mod.wall_forces(x, m.radii, wall_points, sys.normals, m.walls,
                                                        m.wall_stiffness)[0],
                         (m.positions0 + u[:, :3],), (vf[:, :3],))[1]
            kv = kv.at[:, :3].add(-fw)
        return jnp.where(free, kv, v)

    # right preconditioning (A M y = r, du = M y): jax's gmres measures a left-preconditioned residual against the
    # unpreconditioned right-hand side, which stops it at once when M carries units (1 / stiffness)
    # on a flat vector: with [n, nd] vectors jax's gmres keeps its Krylov basis as [n, nd, restart + 1] and XLA on
    # CPU transposed the whole basis for the Gram-Schmidt products at every iteration
    shape = r.shape
    y, _ = jax.scipy.sparse.linalg.gmres(lambda y: matvec(sys.precond(y.reshape(shape))).reshape(-1), r.reshape(-1),
                                         tol=krylov_tol, restart=40, maxiter=sys.maxiter, solve_method="batched")
    return jnp.where(free, sys.precond(y.reshape(shape)), 0.0)


def _newton(model, params, free, u_p, pairs, walls, scene, tol, linear_tol, maxiter, newton_maxiter, stiffness_tol,
            driven, delta, load_steps, preconditioner="auto", aggregate_size=None, slip=True):
    """Newton-Krylov with backtracking line search, over ``load_steps`` equal load increments.

    Returns displacement field, per-step displacements and reactions, info, compile and run time.
    """
    model_c = dataclasses.replace(model, contacts=pairs is not None and len(pairs) > 0)
    if model_c.contacts and not slip:
        # no slip (Jarolin & Dosta 2020): the Coulomb limit is lifted for the static solve
        model_c = dataclasses.replace(model_c, contact=model_c.contact._replace(
            friction=jnp.asarray(jnp.inf, model.positions0.dtype)))
    # with slip, the tangential spring of a contact is its whole relative tangential displacement since rest, capped by
    # Coulomb (|F_t| <= mu F_n): path-independent, so one residual function of u, and equal to the DEM's incremental
    # law under monotonic loading that does not turn the contacts' sliding direction
    ax = scene.axis
    uses_walls = walls is not None
    clamped = ~np.asarray(free).any(axis=1)
    wall_base = walls[0] if uses_walls else None
    # the two-level preconditioner from the bonds (contacts only add stiffness); not with walls alone holding the
    # sample along the axis, where the bonds' coarse matrix is singular
    coarse = None if uses_walls else _coarse_for(model, np.asarray(free), preconditioner, aggregate_size)
    precond = _preconditioner_jit(model, params, free, None, coarse)
    sys = _NewtonSystem(model=model_c, params=params, free=free,
                        pairs=jnp.asarray(pairs) if model_c.contacts else None,
                        normals=walls[1] if uses_walls else None,
                        moving=jnp.asarray(driven), resting=jnp.asarray(clamped & ~np.asarray(driven)),
                        precond=precond, axis=int(ax), maxiter=int(maxiter or 10))
    fractions = np.arange(1, load_steps + 1) / load_steps

    def walls_at(frac):
        # the top wall (index 1) moves by frac * delta against the axis; wall_base holds it at the full delta
        if not uses_walls:
            return jnp.zeros((0, 3), u_p.dtype)
        shift = jnp.zeros_like(wall_base).at[1, ax].set((1.0 - frac) * delta)
        return wall_base + shift

    tc = time.perf_counter()
    frac0 = fractions[0]
    if uses_walls:
        # start from the bond system with the wall-touching particles moved axially so that each wall overlaps them
        # a little (Jarolin & Dosta 2020 starts Newton from the pure bond solution; without overlap the walls add no
        # stiffness
        # and the first Newton system would be singular)
        z, rad = np.asarray(model.positions0[:, ax]), np.asarray(model.radii)
        lo, hi = (z - rad).min(), (z + rad).max()
        reach = 0.25 * float(rad.mean())
        beta = 0.1
        bottom, top = (z - rad) <= lo + reach, (z + rad) >= hi - reach
        guess = np.zeros(u_p.shape)
        guess[bottom, ax] = -0.5 * beta * frac0 * delta
        guess[top, ax] = -(1.0 - 0.5 * beta) * frac0 * delta
        free_lin = np.asarray(free).copy()
        free_lin[bottom | top, ax] = False
        start_args = (dataclasses.replace(model, walls=None), params, jnp.asarray(free_lin),
                      jnp.asarray(guess, u_p.dtype), linear_tol, None)
    else:
        start_args = (model, params, free, frac0 * u_p, linear_tol, None, "auto", None, coarse)
    # the programs compile when first called (the clock takes their compilation out of the run time): nothing is run
    # twice to time it
    with compile_clock() as compiling:
        u, history, step_reactions, converged_all, iterations, norm, scale = _newton_run(
            sys, start_args, fractions, walls_at, tol, newton_maxiter, stiffness_tol)
    compile_time = compiling.seconds
    run_time = time.perf_counter() - tc - compile_time
    info = {"residual": float(norm / scale), "residual_history": history, "iterations": iterations,
            "converged": bool(converged_all), "contacts": int(0 if pairs is None else len(pairs)), "slip": bool(slip),
            "load_steps": int(load_steps)}
    return u, fractions * delta, np.asarray(step_reactions), info, compile_time, run_time


def _newton_run(sys, start_args, fractions, walls_at, tol, newton_maxiter, stiffness_tol):
    """The load steps of :func:`_newton` from the bond solution ``_linear_jit(*start_args)``."""
    u = _linear_jit(*start_args)[0]
    history, step_reactions, converged_all, iterations = [], [], True, 0
    prev = None
    for frac in fractions:
        wp = walls_at(frac)
        if prev is not None:
            u = u * (frac / prev)  # proportional extrapolation; prescribed DOFs land exactly on frac * u_p
        prev = frac
        norm, scale, react = _newton_evaluate(sys, u, wp)
        history.append(float(norm / scale))
        reactions = [float(react)]
        converged = False
        for _ in range(newton_maxiter):
            rel = float(norm / scale)
            if rel <= tol or (stiffness_tol is not None and len(reactions) > 1 and
                              abs(reactions[-1] - reactions[-2]) <= stiffness_tol * abs(reactions[-1])):
                converged = True
                break
            du = _newton_step(sys, u, wp, min(0.1, max(rel * 0.1, 1e-8)))
            alpha = 1.0
            for _ in range(12):
                trial = u + alpha * du
                t_norm, t_scale, t_react = _newton_evaluate(sys, trial, wp)
                if np.isfinite(float(t_norm)) and float(t_norm) < (1 - 1e-4 * alpha) * float(norm):
                    break
                alpha *= 0.5
            u, norm, scale, react = trial, t_norm, t_scale, t_react
            history.append(float(norm / scale))
            reactions.append(float(react))
            iterations += 1
        else:
            converged = float(norm / scale) <= tol
        converged_all &= converged
        step_reactions.append(float(react))
    jax.block_until_ready(u)
    return u, history, step_reactions, converged_all, iterations, norm, scale


# ---------------------------------------------------------------------------------------------------- pure functions
def stiffness_function(sample, scene, *, dofs=None, tol=1e-6, maxiter=None, operator="auto", stiffness_tol="auto",
                       preconditioner="auto", aggregate_size=None, n_materials=None, pad=True):
    """A pure function ``params -> K`` [N/m] of the linear DSM on ``scene`` (clamped layers, bonds only).

    It can be ``jit``-ed, differentiated (``jax.grad``: implicit differentiation through the CG solve) and
    ``vmap``-ped over parameter sets, e.g. ``jax.vmap(f)({"bond_E": E_batch, "bond_nu": nu_batch})``.
    n_materials: the length of ``params["bond_E"]`` (default: the sample's material count); pad: pad the sample to
    its size class (same values to round-off; samples of one class then share compilations). A call with concrete
    parameters runs the program :func:`solve_scene` compiles (none is compiled when the process solved a sample of
    that class with these options before); a traced call (``jit``, ``grad``, ``vmap``) traces the solve.
    """
    if scene.uses_walls or scene.contacts:
        raise SceneError("stiffness_function covers the linear DSM (clamped layers, bonds only)")
    rotations = None if dofs is None else {3: False, 6: True}[int(dofs)]
    stiffness_tol = _linear_stiffness_tol(stiffness_tol)
    m = sample.n_materials if n_materials is None else int(n_materials)
    key = (scene, rotations, operator, preconditioner, aggregate_size, m, bool(pad))
    setup = _linear_setups.get(sample, key, lambda: _linear_setup(sample, scene, rotations, operator, preconditioner,
                                                                   aggregate_size, m, pad))

    def stiffness(params):
        if not traced(params):
            out = _linear_program(setup.model, params, setup.free, setup.u_p, tol, _energy_test(stiffness_tol),
                                  setup.coarse, setup.geometry, setup.guess, maxiter=maxiter, operator=operator)[0]
            return out[0][1] / setup.delta
        return _linear_jit(setup.model, params, setup.free, setup.u_p, tol, maxiter, operator, stiffness_tol,
                           setup.coarse, geometry=setup.geometry, guess=setup.guess)[1] / setup.delta

    return stiffness


def load_cases(sample, scene, directions, params=None, *, dofs=None, tol=1e-8, preconditioner="auto",
               aggregate_size=None):
    """Reactions of several load cases on the same operator: the driven layer moved by ``strain * l`` along each
    unit vector in ``directions [L, 3]`` (e.g. the three axes: compression and two shears), all solved at once with
    ``vmap``. Returns the ``[L, 3]`` matrix of reaction forces per unit displacement [N/m] (row: load case)."""
    from jaxbpm.physics.model import default_params

    rotations = None if dofs is None else {3: False, 6: True}[int(dofs)]
    model = scene.model(sample, rotations=rotations, contacts=False)
    params = default_params(sample) if params is None else params
    free_np, fixed, driven = _free_mask(model, scene, sample)
    _check_held(sample, model, free_np, fixed | driven)
    length, _ = scene.geometry(sample)
    delta = scene.strain * length
    dirs = np.asarray(directions, float).reshape(-1, 3)
    u_p = np.zeros((len(dirs),) + free_np.shape)
    u_p[:, driven, :3] = delta * dirs[:, None, :]
    free = jnp.asarray(free_np)
    coarse = _coarse_for(model, free_np, preconditioner, aggregate_size)
    geometry = bond_geometry(model, coarse, n_materials=sample.n_materials)

    out = _load_case_reactions(model, params, free, coarse, geometry, jnp.asarray(driven),
                               jnp.asarray(u_p, model.positions0.dtype), tol)
    return np.asarray(out) / delta


@jax.jit
def _load_case_reactions(model, params, free, coarse, geometry, driven, u_p, tol):
    """Reaction on the driven layer ``[L, 3]`` of each load case ``u_p [L, n, nd]`` (one operator, vmapped CG)."""
    full, jac = tangent_operator(model, params, geometry=geometry)
    precond = _preconditioner(model, params, free, jac, coarse, geometry)

    def one(up):
        u = _cg(full, precond, free, up, tol, None)[0]
        gen = -full(u)
        # force the machine applies to the driven layer = minus the internal force on it
        return -jnp.sum(jnp.where(driven[:, None], gen[:, :3], 0.0), axis=0)

    return jax.vmap(one)(u_p)
