"""The preconditioner of the linear solves: block-Jacobi (each particle's self-stiffness) plus, by default, a coarse
space of the rigid modes of particle aggregates (two-level additive Schwarz), and the per-material parts of it a
:class:`~jaxbpm.dsm.operator.BondGeometry` keeps.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm._compile import put, setup_jit
from jaxbpm.dsm.operator import (
    _geometry_parts, _packed_all, _uses_geometry, block_diagonal, bond_subset, BondGeometry, full_jacobians,
    material_weights, reduced_jacobians)
from jaxbpm.physics.blocks import sum_blocks
from jaxbpm.physics.model import Model


_MAX_PRECOMPUTED_MATERIALS = 8
_MAX_PRECOMPUTED_BYTES = 2 ** 30  # memory for the preconditioner's parts; above it they are assembled per solve


@setup_jit(static_argnames=("n_materials",))
def _preconditioner_parts(model: Model, reduced, coarse, n_materials):
    """Block diagonals and coarse matrices per (material, part) of :class:`BondGeometry` (over blocks of bonds on
    large samples)."""
    def one(mp):
        m, part = mp // 2, mp % 2
        whole = jnp.take(reduced, part, axis=0)

        def jacobians(sub, idx, w):
            jac = whole if idx is None else whole[:, :, idx]
            keep = sub.bond_material == m.astype(sub.bond_material.dtype)
            return jnp.where(keep if w is None else keep & w, jac, 0.0)

        def blocks_of(idx, w):
            sub = bond_subset(model, idx)
            return block_diagonal(sub, None, jacobians(sub, idx, w))

        blocks = sum_blocks(blocks_of, model.bonds.shape[0])
        if coarse is None:
            return blocks, None

        def coarse_of(idx, w):  # over the coupling bonds only
            sel = coarse.bonds if idx is None else coarse.bonds[idx]
            sub = bond_subset(model, sel)
            local = dataclasses.replace(coarse, bonds=jnp.arange(sel.shape[0], dtype=coarse.bonds.dtype))
            return coarse_matrix(sub, jacobians(sub, sel, w), local)

        return blocks, sum_blocks(coarse_of, coarse.bonds.shape[0])

    blocks, mats = jax.lax.map(one, jnp.arange(2 * n_materials))
    blocks = blocks.reshape((n_materials, 2) + blocks.shape[1:])
    return blocks, None if coarse is None else mats.reshape((n_materials, 2) + mats.shape[1:])


def bond_geometry(model: Model, coarse: CoarseSpace | None = None, *, n_materials: int | None = None
                  ) -> BondGeometry | None:
    """:class:`~jaxbpm.dsm.operator.BondGeometry` of the model's bonds.

    With ``n_materials``, the preconditioner's parts as well, and then without the reduced form (which nothing else
    reads).

    Args:
      model: the model.
      coarse: the :class:`CoarseSpace` the preconditioner's parts are built for (``None``: block-Jacobi alone).
      n_materials: the length of ``params["bond_E"]`` (at most ``_MAX_PRECOMPUTED_MATERIALS``, and within
        ``_MAX_PRECOMPUTED_BYTES`` of memory, or the parts are not built); ``None``: no preconditioner's parts.

    Returns:
      The :class:`~jaxbpm.dsm.operator.BondGeometry`; ``None`` without bonds.

    Raises:
      RuntimeError: a bond stiffness law that is not of the form ``E (k_E + k_G / (2 (1 + nu)))``.
    """
    if model.bonds.shape[0] == 0:
        return None
    reduced, err = _geometry_parts(model)
    # the split is exact up to rounding: 1e-10 in float64; in float32 (eps 1.2e-7) rounding alone reaches ~1e-7
    if not float(err) < max(1e-10, 1e3 * float(jnp.finfo(reduced.dtype).eps)):
        raise RuntimeError(f"bond stiffness is not of the form E (k_E + k_G / (2 (1 + nu))) (mismatch {err:.3g})")
    geometry = BondGeometry(reduced=reduced, packed=_packed_all(reduced))
    nd = 6 if model.rotations else 3
    per_material = 2 * (model.n * nd * nd + (0 if coarse is None else (6 * coarse.count) ** 2))
    if (n_materials is not None and 0 < n_materials <= _MAX_PRECOMPUTED_MATERIALS
            and n_materials * per_material * reduced.dtype.itemsize <= _MAX_PRECOMPUTED_BYTES):
        blocks, mats = _preconditioner_parts(model, reduced, coarse, int(n_materials))
        # the reduced form was kept for the preconditioner only (2 x 81 numbers a bond); a solve with another
        # material count builds its Jacobians from the bond law instead
        geometry = dataclasses.replace(geometry, reduced=None, blocks=blocks, coarse=mats)
    return geometry


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
    """Aggregates of particles from a grid of cells over the sample's bounding box, and their rigid modes.

    Args:
      model: the model.
      free: ``[n, nd]`` boolean mask of the free DOFs (the modes are zero on the others).
      aggregate_size: the particles per aggregate, about (default ``max(100, n / 250)``: at most ~1500 coarse
        DOFs, whose dense Cholesky factor costs little).

    Returns:
      The :class:`CoarseSpace`.

    Raises:
      ValueError: ``aggregate_size`` below 1.
    """
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


def coarse_factor(model: Model, jac, coarse: CoarseSpace):
    """Cholesky factor of the Galerkin coarse matrix ``P^T K_ff P`` (:func:`coarse_matrix`).

    Args:
      model: the model.
      jac: ``[ni, no, nb]`` the reduced Jacobians of every bond (:func:`~jaxbpm.dsm.operator.reduced_jacobians`).
      coarse: the coarse space.

    Returns:
      ``[6 na, 6 na]`` the lower factor (``na``: the aggregates).
    """
    return _factor_coarse(coarse_matrix(model, jac, coarse))


def coarse_matrix(model: Model, jac, coarse: CoarseSpace):
    """The Galerkin coarse matrix ``P^T K_ff P``, assembled bond by bond from the coupling bonds.

    Args:
      model: the model.
      jac: ``[ni, no, nb]`` the reduced Jacobians of every bond (:func:`~jaxbpm.dsm.operator.reduced_jacobians`).
      coarse: the coarse space (its ``bonds`` index ``jac``'s last axis).

    Returns:
      ``[6 na, 6 na]`` the matrix (``na``: the aggregates).
    """
    na = coarse.count
    sel = coarse.bonds
    jb = full_jacobians(jac[:, :, sel])
    nd = jb.shape[1] // 2
    i, j = model.bonds[sel, 0], model.bonds[sel, 1]
    pi, pj = coarse.basis[i], coarse.basis[j]
    ai, aj = coarse.labels[i], coarse.labels[j]
    ti, tj = jnp.swapaxes(pi, 1, 2), jnp.swapaxes(pj, 1, 2)
    # batched `@` (faster on CPU than the same three-operand einsum, which XLA runs as two generic dots)
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


def build_preconditioner(model: Model, params, free, jac=None, coarse: CoarseSpace | None = None,
                    geometry: BondGeometry | None = None, extra=None):
    """Block-Jacobi, plus the coarse correction ``P (P^T K_ff P)^-1 P^T`` with a coarse space (additive two-level).

    Block-Jacobi is the inverse of each particle's self-stiffness on its free DOFs (identity on the rest). With a
    ``geometry`` that holds the preconditioner's parts (built for this ``coarse``), they are weighed by the
    parameters instead of being assembled from the Jacobians.

    Args:
      model: the model.
      params: the parameters.
      free: ``[n, nd]`` boolean mask of the free DOFs.
      jac: ``[ni, no, nb]`` the reduced Jacobians of the bonds (``None``: computed at rest when needed).
      coarse: the :class:`CoarseSpace` (``None``: block-Jacobi alone).
      geometry: the model's :class:`~jaxbpm.dsm.operator.BondGeometry` (``None``: none).
      extra: ``(pair_model, pair_jac, pair_coarse)``, further springs added to the blocks and the coarse matrix
        (the linearised contacts: a model whose ``bonds`` are the pairs, their reduced Jacobians, and the coarse
        space with ``bonds`` indexing the pairs that couple its modes); ``None``: none.

    Returns:
      The :class:`Preconditioner`.
    """
    precomputed = (_uses_geometry(geometry, params) and geometry.blocks is not None
                   and geometry.blocks.shape[0] == jnp.shape(params["bond_E"])[0]
                   and (coarse is None or geometry.coarse is not None))
    if precomputed:
        w = jax.lax.stop_gradient(material_weights(params))
        blocks = jnp.einsum("mp,mpnab->nab", w, geometry.blocks)
        a_coarse = None if coarse is None else jnp.einsum("mp,mpab->ab", w, geometry.coarse)
    else:
        if jac is None and coarse is not None:
            jac = reduced_jacobians(model, params)
        jac = None if jac is None else jax.lax.stop_gradient(jac)
        blocks = jax.lax.stop_gradient(block_diagonal(model, params, jac))
        a_coarse = None if coarse is None else coarse_matrix(model, jac, coarse)
    if extra is not None:
        pair_model, pair_jac, pair_coarse = extra
        pair_jac = jax.lax.stop_gradient(pair_jac)
        blocks = blocks + block_diagonal(pair_model, None, pair_jac)
        if coarse is not None:
            a_coarse = a_coarse + coarse_matrix(pair_model, pair_jac, pair_coarse)
    nd = blocks.shape[1]
    eye = jnp.eye(nd, dtype=blocks.dtype)
    mask = free[:, :, None] & free[:, None, :]
    blocks = jnp.where(mask, blocks, eye[None])
    # particles without bonds (contacts only): a scalar guess from the mean bond diagonal keeps the block regular
    scale = jnp.mean(jnp.abs(jnp.diagonal(blocks, axis1=1, axis2=2)), axis=0)
    empty = jnp.all(jnp.abs(jnp.where(mask, blocks, 0.0)) == 0, axis=(1, 2))
    blocks = jnp.where(empty[:, None, None], jnp.diag(scale)[None], blocks)
    inv = jnp.linalg.inv(blocks)
    factor = None if coarse is None else _coarse_blocks(jax.lax.stop_gradient(a_coarse))
    return Preconditioner(inv=inv, free=free, factor=factor, coarse=coarse)


_build_preconditioner_jit = jax.jit(build_preconditioner)


@jax.custom_batching.custom_vmap
def _coarse_blocks(a):
    """:class:`CholeskyBlocks` of the coarse matrix ``a``. Batched (``vmap`` over parameter sets), the matrices are
    factorised one after another (``lax.map``), not as one batched LAPACK call: XLA's CPU runtime (jax 0.10) hangs
    now and then on the batched Cholesky and triangular solves inside the batched solve (all threads idle)."""
    return CholeskyBlocks.of(_factor_coarse(a))


@_coarse_blocks.def_vmap
def _coarse_blocks_batched(axis_size, in_batched, a):
    if not in_batched[0]:
        out = CholeskyBlocks.of(_factor_coarse(a))
        return out, jax.tree_util.tree_map(lambda _: False, out)
    out = jax.lax.map(lambda one: CholeskyBlocks.of(_factor_coarse(one)), a)
    return out, jax.tree_util.tree_map(lambda _: True, out)


@dataclasses.dataclass(frozen=True)
class CholeskyBlocks:
    """A lower Cholesky factor ``L`` cut into diagonal blocks of ``size`` rows, for ``A^-1 r`` by blocked forward
    and back substitution: the inverses of the diagonal blocks and the off-diagonal panels are taken once, and every
    application is a few matrix-vector products (faster on CPU than a triangular solve with one right-hand side,
    which XLA runs as a scalar loop)."""

    inv_diag: Any   # list of [b, b]: inverses of the diagonal blocks of L
    rows: Any       # list of [b, start]: L[block, :start] (row panel left of each diagonal block)
    cols_t: Any     # list of [b, m - end]: L[end:, block]^T (column panel below each diagonal block, transposed)

    size = 96

    @classmethod
    def of(cls, factor):
        """The blocks of a lower Cholesky factor.

        Args:
          factor: ``[m, m]`` the lower factor ``L``.

        Returns:
          The :class:`CholeskyBlocks`.
        """
        m = factor.shape[0]
        e = list(range(0, m, cls.size)) + [m]
        eye = jnp.eye(cls.size, dtype=factor.dtype)
        inv_diag = [jax.scipy.linalg.solve_triangular(factor[a:b, a:b], eye[:b - a, :b - a], lower=True)
                    for a, b in zip(e[:-1], e[1:])]
        rows = [factor[a:b, :a] for a, b in zip(e[:-1], e[1:])]
        cols_t = [factor[b:, a:b].T for a, b in zip(e[:-1], e[1:])]
        return cls(inv_diag=inv_diag, rows=rows, cols_t=cols_t)

    def solve(self, r):
        """``(L L^T)^-1 r``.

        Args:
          r: ``[m]`` the right-hand side.

        Returns:
          ``[m]`` the solution.
        """
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


jax.tree_util.register_dataclass(CholeskyBlocks, data_fields=["inv_diag", "rows", "cols_t"], meta_fields=[])


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
