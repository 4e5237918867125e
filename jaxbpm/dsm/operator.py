"""The tangent operator, element by element: per-bond (and per-contact) Jacobians of the force laws, their packed form,
the stiffness product ``K v`` and each particle's self-stiffness blocks -- never an assembled matrix.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp

from jaxbpm._compile import setup_jit
from jaxbpm.physics import bond as bond_mod, contact as contact_mod, rotation, tangent, vec
from jaxbpm.physics.blocks import block_length, fold_blocks
from jaxbpm.physics.model import Model


def _configuration(model: Model, u):
    """Positions and orientations for a DOF array ``u [n, 3 or 6]`` (2D: ``[n, 2 or 3]``, the rotation an angle)."""
    dim = model.dim
    x = model.positions0 + u[:, :dim]
    if not model.rotations:
        return x, None
    return x, (u[:, 2:3] if dim == 2 else rotation.from_rotation_vector(u[:, 3:]))


def _contact_slip(model: Model, pairs, d, w):
    """Relative tangential displacement of the contact points of ``pairs [C, 2]`` since rest, as ``(x, y, z)``
    components: ``u_j - u_i + theta_j x (-r_j n) - theta_i x (r_i n)`` (the contact law keeps its tangential part),
    with ``d`` the current pair vectors (components) and ``w`` the pairs' reduced DOFs ``[3 or 9, C]``: ``u_j -
    u_i``, then (with rotations) ``theta_i`` and ``theta_j``.

    With the linear law (:mod:`jaxbpm.physics.linear`), whose shear stiffness does not vanish as a contact closes, a
    pair apart at rest counts only the slip since it touched: the share ``delta / approach`` of it (overlap over the
    approach of the centres since rest), exact where the pair's relative motion is proportional along the load path.
    Hertz-Mindlin's k_t grows from zero with the overlap and takes the whole slip."""
    dxi = tuple(w[c] for c in range(3))
    if model.rotations:
        inv = 1.0 / jnp.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        n = tuple(c * inv for c in d)
        r_i, r_j = model.radii[pairs[:, 0]], model.radii[pairs[:, 1]]
        a = vec.cross(tuple(w[6 + c] for c in range(3)), tuple(-r_j * n[c] for c in range(3)))
        b = vec.cross(tuple(w[3 + c] for c in range(3)), tuple(r_i * n[c] for c in range(3)))
        dxi = tuple(dxi[c] + a[c] - b[c] for c in range(3))
    if model.contact_law != "linear":
        return dxi
    i, j = pairs[:, 0], pairs[:, 1]
    p0 = model.positions0.T
    rest = jnp.sqrt(sum((p0[c, j] - p0[c, i]) ** 2 for c in range(3)))
    dist = jnp.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    reach = model.radii[i] + model.radii[j]
    approach = rest - dist
    since = jnp.clip((reach - dist) / jnp.where(approach > 0, approach, 1.0), 0.0, 1.0)
    share = jnp.where(rest <= reach, 1.0, since)
    return tuple(share * c for c in dxi)


def _pair_dofs(model: Model, pairs, u):
    """The reduced DOFs of pairs ``[3 or 9, C]`` (2D: ``[2 or 4, C]``) from a DOF array ``u [n, nd]``: ``u_j - u_i``
    (and ``theta_i``, ``theta_j``), the only way the bond and contact laws see the displacements."""
    i, j = pairs[:, 0], pairs[:, 1]
    ut = u.T
    dim = model.dim
    z = [ut[c, j] - ut[c, i] for c in range(dim)]
    if model.rotations:
        rot = model.dofs - dim
        z += [ut[dim + c, i] for c in range(rot)] + [ut[dim + c, j] for c in range(rot)]
    return jnp.stack(z)  # one gather per row: a concatenation of [3, P] gathers runs 4x slower on CPU


def internal_forces(model: Model, params, u, contacts=None, walls=None):
    """Generalised forces (forces, then moments) at the DOF state ``u``.

    Args:
      model: the model.
      params: the parameters.
      u: ``[n, 3 or 6]`` the DOF state: displacements [m] (then rotation vectors [rad]).
      contacts: ``(pairs [C, 2], valid [C])`` the contact candidates (``None``: no contacts).
      walls: ``(points, normals)`` of the walls (``None``: no walls).

    Returns:
      ``(forces, parts)``: ``[n, 3 or 6]`` the generalised forces [N] (and moments [N m]), and the ``parts`` dict of
      :meth:`~jaxbpm.physics.model.Model.forces`.
    """
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
    """Per-bond force Jacobians in the reduced form the solver stores.

    The form of :func:`jaxbpm.physics.tangent.bond_reduced`, the tangent the STE uses too.

    Args:
      model: the model.
      params: the parameters, or a :class:`~jaxbpm.physics.bond.BondStiffness`
        (:meth:`~jaxbpm.physics.model.Model.stiffness`).
      u: ``[n, nd]`` a DOF state to linearise at (the tangent of a deformed configuration); ``None``: at rest.

    Returns:
      ``[ni, no, nb]`` (``ni = no = 9`` with rotations, else 3).
    """
    z0 = None if u is None else _pair_dofs(model, model.bonds, u)
    return tangent.bond_reduced(model.r0, model.stiffness(params), model.rotations, z0)


full_jacobians = tangent.full


def bond_jacobians(model: Model, params) -> jnp.ndarray:
    """Per-bond tangent stiffness at rest, in the global frame.

    Forward-mode derivatives of the same bond law (:func:`reduced_jacobians`), minus sign (stiffness).

    Args:
      model: the model.
      params: the parameters.

    Returns:
      ``[nb, 12, 12]`` in the DOF order (u_i, theta_i, u_j, theta_j), or ``[nb, 6, 6]`` without rotations.
    """
    return full_jacobians(reduced_jacobians(model, params))


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
    ``_MAX_PRECOMPUTED_MATERIALS`` materials, or more than ``_MAX_PRECOMPUTED_BYTES`` of memory). Once they are
    built, ``reduced`` is ``None``: only the preconditioner read it.
    Build it with :func:`bond_geometry`.
    """

    reduced: Any
    packed: Any
    blocks: Any = None
    coarse: Any = None


jax.tree_util.register_dataclass(BondGeometry, data_fields=["reduced", "packed", "blocks", "coarse"],
                                 meta_fields=[])


def _unit_stiffnesses(model: Model, nu):
    """``(k(E=1, nu), s)``: the bond stiffnesses per unit modulus and the shear factor s(nu) of each bond, from the
    stiffness law itself."""
    one = jnp.ones_like(model.bond_length)
    k = bond_mod.stiffness(one, nu, model.bond_area, model.bond_I, model.bond_J, model.bond_length)
    return k, _shear_factor(nu)


def _shear_factor(nu):
    """``s(nu)``, the factor of the shear stiffnesses: k_t of a bar of unit modulus, area and length."""
    return bond_mod.stiffness(1.0, nu, 1.0, 1.0, 1.0, 1.0).kt


_BOND_FIELDS = ("bonds", "r0", "bond_material", "bond_area", "bond_I", "bond_J", "bond_length", "bond_keys",
                "bond_key_index", "bond_radius")


def bond_subset(model: Model, idx) -> Model:
    """The model with some of its bonds only; its bond keys are not the sample's.

    Args:
      model: the model.
      idx: ``[m]`` the bonds to keep (indices or a mask); ``None``: all of them.

    Returns:
      The :class:`~jaxbpm.physics.model.Model` with those bonds.
    """
    if idx is None:
        return model
    return dataclasses.replace(model, **{k: getattr(model, k)[idx] for k in _BOND_FIELDS})


def over_bonds(fn, model: Model, block: int | None = None):
    """``fn(model)`` for a per-bond function whose outputs have the bond axis last, run over blocks of bonds
    (:func:`~jaxbpm.physics.blocks.fold_blocks`; each block's outputs written in place) when the model has more
    bonds than one block: each block's temporaries (the bond law's forward-mode derivatives, tens of numbers per
    bond) are then reused from block to block instead of being allocated for every bond at once. Within a block the
    model holds that block's bonds only (:func:`bond_subset`; the last block's padding repeats the last bond).

    Args:
      fn: a function of a :class:`~jaxbpm.physics.model.Model` whose outputs (a pytree) have the bond axis last.
      model: the model over all bonds.
      block: the largest block length (default :data:`~jaxbpm.physics.blocks.BLOCK`).

    Returns:
      ``fn(model)``: the outputs over all bonds.
    """
    nb = model.bonds.shape[0]
    length = block_length(nb, block)
    if nb <= length:
        return fn(model)
    size = -(-nb // length) * length
    shapes = jax.eval_shape(lambda: fn(bond_subset(model, jnp.arange(length))))
    out = jax.tree_util.tree_map(lambda t: jnp.zeros(t.shape[:-1] + (size,), t.dtype), shapes)

    def step(acc, idx, _):  # idx[0]: the block's first bond
        return jax.tree_util.tree_map(lambda o, r: jax.lax.dynamic_update_slice_in_dim(o, r, idx[0], axis=o.ndim - 1),
                                      acc, fn(bond_subset(model, idx)))

    out = fold_blocks(step, out, nb, block)
    return jax.tree_util.tree_map(lambda o: o[..., :nb], out) if size != nb else out


def _geometry_block(model: Model):
    zero = jnp.zeros_like(model.bond_length)
    # the stiffness at two Poisson ratios separates the modulus part from the shear part: k = k_E + s k_G
    k0, s0 = _unit_stiffnesses(model, zero)
    k1, s1 = _unit_stiffnesses(model, zero + 1.0)
    kg = jax.tree_util.tree_map(lambda a, b: (a - b) / (s0 - s1), k0, k1)
    ke = jax.tree_util.tree_map(lambda a, g: a - s0 * g, k0, kg)
    # the decomposition must reproduce the law at another ratio (it does unless the stiffness law changes form)
    k2, s2 = _unit_stiffnesses(model, zero + 0.3)
    mismatch = jnp.stack([jnp.abs(a - (e + s2 * g)) for a, e, g in zip(k2, ke, kg)])
    scale = jnp.stack([jnp.abs(a) for a in k2])
    return jnp.stack([reduced_jacobians(model, ke), reduced_jacobians(model, kg)]), mismatch, scale


@setup_jit
def _geometry_parts(model: Model):
    reduced, mismatch, scale = over_bonds(_geometry_block, model)
    err = jnp.max(jnp.max(mismatch, axis=1) / jnp.maximum(jnp.max(scale, axis=1), jnp.finfo(reduced.dtype).tiny))
    return reduced, err


def material_weights(params):
    """Each material's weights ``(E, E s)`` of :class:`BondGeometry`'s two parts.

    The preconditioner's per-material sums are exact only for the material count they were built with.

    Args:
      params: the parameters, with ``"bond_E"`` [Pa] and ``"bond_nu"``, ``[M]`` each.

    Returns:
      ``[M, 2]`` the weights [Pa].
    """
    e = jnp.asarray(params["bond_E"])
    return jnp.stack([e, e * _shear_factor(jnp.asarray(params["bond_nu"]).astype(e.dtype))], axis=1)


def _bond_factors(model: Model, params):
    """Per-bond ``(E_b, E_b s_b)``: the material weights (:func:`material_weights`) of each bond."""
    w = material_weights(params)[model.bond_material]
    return w[:, 0], w[:, 1]


def _uses_geometry(geometry, params) -> bool:
    return geometry is not None and isinstance(params, dict) and {"bond_E", "bond_nu"} <= set(params) and not (
        "_stiffness" in params)


def geometric_jacobians(model: Model, params, geometry: BondGeometry):
    """Reduced and packed Jacobians of the bonds at rest from :class:`BondGeometry` and the parameters.

    Args:
      model: the model.
      params: the parameters, with ``"bond_E"`` and ``"bond_nu"`` per material.
      geometry: the model's :class:`BondGeometry`.

    Returns:
      ``(reduced, packed, (a, b))``: ``[ni, no, nb]`` (``None`` when the geometry no longer holds the reduced
      form), ``[np, nb]`` (:func:`packed_jacobians`), and the per-bond weights ``[nb]`` of the two parts.
    """
    a, b = _bond_factors(model, params)
    jr = None if geometry.reduced is None else a[None, None] * geometry.reduced[0] + b[None, None] * geometry.reduced[1]
    jp = a[None] * geometry.packed[0] + b[None] * geometry.packed[1]
    return jr, jp, (a, b)


def _geometric_operator(model: Model, params, geometry: BondGeometry):
    """``v -> K v`` of the bonds from :class:`BondGeometry` (and the reduced Jacobians, for the preconditioner).
    The value streams the packed Jacobians; the derivative with respect to the parameters goes through the two
    per-bond weights only (the product of each geometric part with ``v``, scaled bond by bond), so neither the
    packing nor the 81-number form is differentiated."""
    jr, jp, (a, b) = geometric_jacobians(model, params, geometry)
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
    """``K v`` for the whole sample from the per-bond Jacobians, element by element.

    Gather both ends of every bond, ``ni x no`` multiply-adds per bond on ``[nb]`` arrays, one scatter of both ends'
    rows (padded to 4 or 8 numbers, which XLA on CPU scatters fastest). No global matrix is formed; ``K`` is the
    positive (stiffness) sign of the force Jacobian.

    Args:
      model: the model.
      jr: ``[ni, no, nb]`` the reduced Jacobians (:func:`reduced_jacobians`), or ``[np, nb]`` their packed symmetric
        form at rest (:func:`packed_jacobians`).
      v: ``[n, nd]`` the DOF vector.

    Returns:
      ``[n, nd]`` the product.
    """
    b = model.bonds
    z = _pair_dofs(model, b, v)
    return _scatter_pairs(model, b[:, 0], b[:, 1], _apply_packed(jr, z) if jr.ndim == 2 else _apply(jr, z))


_UPPER3 = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def packed_jacobians(jr) -> jnp.ndarray:
    """The reduced Jacobians at rest in the packed form the linear solve streams through at every CG iteration.

    The bond stiffness is symmetric at rest (the bond law has a potential there), so of the 9 x 9 numbers ``J = d
    (f_i, m_i, m_j) / d (d, theta_i, theta_j)`` only the upper triangles of ``d f_i / d d``, ``d m_i / d theta_i``,
    ``d m_j / d theta_j`` and the full ``d f_i / d theta_i``, ``d f_i / d theta_j``, ``d m_i / d theta_j`` are kept
    (``d m_i / d d = -(d f_i / d theta_i)^T``, ``d m_j / d d = -(d f_i / d theta_j)^T``, ``d m_j / d theta_i = (d
    m_i / d theta_j)^T``). The product reads 45 / 81 (56 %) of the memory of the 9 x 9 form (the product is
    memory-bound on CPU). Not for a deformed state, whose tangent need not be symmetric.

    Args:
      jr: ``[9, 9, nb]`` or ``[3, 3, nb]`` the reduced Jacobians at rest (:func:`reduced_jacobians`).

    Returns:
      ``[45, nb]`` (``[6, nb]`` with 3 DOF per particle).
    """
    def blk(ro, co, upper):
        idx = _UPPER3 if upper else tuple((a, b) for a in range(3) for b in range(3))
        return [jr[co + c, ro + o] for o, c in idx]

    parts = blk(0, 0, True)
    if jr.shape[0] == 9:
        parts += blk(0, 3, False) + blk(0, 6, False) + blk(3, 3, True) + blk(3, 6, False) + blk(6, 6, True)
    return jnp.stack(parts)


_packed_all = setup_jit(jax.vmap(packed_jacobians))


def symmetrised(jr) -> jnp.ndarray:
    """The reduced Jacobians of the symmetric part of each pair's stiffness.

    For a preloaded contact linearised at an overlap, whose tangent is symmetric only up to its small geometric terms.

    Args:
      jr: ``[ni, no, P]`` the reduced Jacobians (``ni = no = 9`` or 3).

    Returns:
      ``[ni, no, P]`` those of the symmetric part.
    """
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
    (f_i [, m_i]), j gets (f_i [, -m_j]) (``f_j = -f_i``); one scatter of rows of 4 or 8 numbers (2D: 4 or 2)."""
    zero = jnp.zeros_like(y[0])
    if model.dim == 2:
        if model.rotations:
            rows_i = jnp.stack([-y[0], -y[1], -y[2], zero], axis=1)
            rows_j = jnp.stack([y[0], y[1], -y[3], zero], axis=1)
        else:
            rows_i, rows_j = jnp.stack([-y[0], -y[1]], axis=1), jnp.stack([y[0], y[1]], axis=1)
        total = jax.ops.segment_sum(jnp.concatenate([rows_i, rows_j]), jnp.concatenate([i, j]), model.n)
        return total[:, :model.dofs]
    if model.rotations:
        rows_i = jnp.stack([-y[0], -y[1], -y[2], zero, -y[3], -y[4], -y[5], zero], axis=1)
        rows_j = jnp.stack([y[0], y[1], y[2], zero, -y[6], -y[7], -y[8], zero], axis=1)
    else:
        rows_i = jnp.stack([-y[0], -y[1], -y[2], zero], axis=1)
        rows_j = jnp.stack([y[0], y[1], y[2], zero], axis=1)
    total = jax.ops.segment_sum(jnp.concatenate([rows_i, rows_j]), jnp.concatenate([i, j]), model.n)
    return jnp.concatenate([total[:, :3], total[:, 4:7]], axis=1) if model.rotations else total[:, :3]


def contact_jacobians(model: Model, pairs, u, d0=None, normal=False) -> jnp.ndarray:
    """Force Jacobians of the contact candidates in the reduced form of :func:`reduced_jacobians`.

    ``d (f_i [, m_i, m_j]) / d (u_j - u_i [, theta_i, theta_j])``, by jvps of the same contact law the DEM runs (the
    tangential spring is the contact points' relative tangential displacement since rest, :func:`_contact_slip`, as
    in :func:`internal_forces`).

    Args:
      model: the model.
      pairs: ``[C, 2]`` the contact candidates.
      u: ``[n, nd]`` the DOF state to linearise at (``None``: zero).
      d0: ``[C, 3]`` the pair vectors [m] to linearise at instead of the rest positions (``u`` is then zero: the
        linearised contacts of the linear solve).
      normal: also the Jacobians of the normal force alone (the law without its tangential spring: its moments
        vanish), from the same derivatives.

    Returns:
      ``[ni, no, C]``; with ``normal``, ``(all, normal)``, two such arrays.
    """
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
        out = contact_mod.law_components(d, r_i, r_j, m_i, m_j, (zero,) * 3, dxi, (zero,) * 3, model.contact)
        parts = (out.f_i + out.m_i + out.m_j) if rot else out.f_i
        if normal:  # -F_n n: the force on i without the tangential spring
            dist = jnp.sqrt(vec.dot(d, d))
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
    capped = contact_mod.law_components(*args, model.contact).spring
    free = contact_mod.law_components(*args, model.contact._replace(friction=jnp.asarray(1e30, w.dtype))).spring
    num, den = jnp.sqrt(vec.dot(capped, capped)), jnp.sqrt(vec.dot(free, free))
    secant = jnp.where(den > 0, num / jnp.where(den > 0, den, 1.0), 1.0)
    stick, normal = contact_jacobians(model, pairs, None, jnp.stack(d, axis=1), normal=True)
    return symmetrised(normal + secant[None, None] * (stick - normal))


def _contact_product(model: Model, pairs, jc, v):
    """``K v`` of the contacts from :func:`contact_jacobians` (a contact's tangent need not be symmetric: sliding
    contacts, so the 9 x 9 form)."""
    return _scatter_pairs(model, pairs[:, 0], pairs[:, 1], _apply(jc, _pair_dofs(model, pairs, v)))


def block_diagonal(model: Model, params, jac=None) -> jnp.ndarray:
    """Each particle's self-stiffness block, summed over its bonds.

    Args:
      model: the model (its ``bonds`` may be any pairs, e.g. the linearised contacts).
      params: the parameters (unused when ``jac`` is given).
      jac: ``[ni, no, nb]`` the reduced Jacobians of :func:`reduced_jacobians` (``None``: computed from
        ``params`` at rest).

    Returns:
      ``[n, nd, nd]`` the blocks (the translational part in [N/m]).
    """
    jr = reduced_jacobians(model, params) if jac is None else jac
    J = jnp.moveaxis(jr, 2, 0).transpose(0, 2, 1)  # [nb, out, in]
    if not model.rotations:
        return (jax.ops.segment_sum(J, model.bonds[:, 0], model.n)
                + jax.ops.segment_sum(J, model.bonds[:, 1], model.n))
    # K_ii = [[J(f_i, d), -J(f_i, th_i)], [J(m_i, d), -J(m_i, th_i)]]
    # K_jj = [[J(f_i, d), J(f_i, th_j)], [-J(m_j, d), -J(m_j, th_j)]]
    d, r = model.dim, model.dofs - model.dim  # translations, rotations (3, 3; 2D: 2, 1)
    f, mi, mj = slice(0, d), slice(d, d + r), slice(d + r, d + 2 * r)
    k_ii = jnp.concatenate([jnp.concatenate([J[:, f, f], -J[:, f, mi]], axis=2),
                            jnp.concatenate([J[:, mi, f], -J[:, mi, mi]], axis=2)], axis=1)
    k_jj = jnp.concatenate([jnp.concatenate([J[:, f, f], J[:, f, mj]], axis=2),
                            jnp.concatenate([-J[:, mj, f], -J[:, mj, mj]], axis=2)], axis=1)
    return jax.ops.segment_sum(k_ii, model.bonds[:, 0], model.n) + jax.ops.segment_sum(k_jj, model.bonds[:, 1],
                                                                                       model.n)
