"""The stiffness tensors: per-interaction stiffness, the particles' fluctuations (Eq. 20-29), the local tensors (Eq.
32) and the body tensor, in Voigt form; moduli and the isotropic fit.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm.physics import tangent
from jaxbpm.physics.blocks import fold_blocks
from jaxbpm.ste.estimator import _contact_jacobians, Estimator

__all__ = ["pair_stiffness", "local_tensors", "body_tensor", "raw_body_tensor", "voigt", "tensor_from_voigt",
           "moduli", "directional_modulus", "isotropic_fit", "VOIGT", "VOIGT_2D", "coupling", "local_tensors_edges",
           "raw_body_tensor_edges"]


VOIGT = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))
"""Index pairs of the Voigt components, in order."""

VOIGT_2D = ((0, 0), (1, 1), (0, 1))
"""Index pairs of the Voigt components of a two-dimensional sample (11, 22, 12), in order."""


def _voigt_pairs(k: int):
    """The Voigt index pairs of ``k``-dimensional tensors."""
    return VOIGT_2D if k == 2 else VOIGT


def _bond_jacobians(est: Estimator, params) -> jnp.ndarray:
    """Per-bond stiffness ``[nb, 2nd, 2nd]`` at rest, DOF order (u_i, theta_i, u_j, theta_j): minus the Jacobian of
    the bond law (:func:`jaxbpm.physics.tangent.bond_full`, the tangent the DSM uses too)."""
    model = est.model
    return tangent.bond_full(model.r0, model.stiffness(params), rotations=est.dofs == 6)  # (2D: translations)


def pair_stiffness(est: Estimator, params) -> jnp.ndarray:
    """Stiffness ``[P, 2nd, 2nd]`` of every interaction (bonds, then contacts) at rest, global frame.

    The 3x3 block ``[:3, nd:nd+3]`` with its sign flipped is ``K^nm`` of the paper (force on i per displacement of j).

    Args:
      est: the estimator (:func:`~jaxbpm.ste.estimator`).
      params: the bond parameters.

    Returns:
      ``[P, 2nd, 2nd]`` the pairs' stiffness matrices.
    """
    jac = _bond_jacobians(est, params)
    if est.n_contacts:
        jac = jnp.concatenate([jac, _contact_jacobians(est).astype(jac.dtype)])
    return jac


class _Edges(NamedTuple):
    src: Any   # [E] particle n
    dst: Any   # [E] neighbour m
    d: Any     # [E, 3] d^nm = x^m - x^n
    h_nn: Any  # [E, nd, nd] self block of the interaction on n
    k_nm: Any  # [E, nd, nd] coupling: generalised force on n per DOF of m (K^nm)


def _edges(est: Estimator, params) -> _Edges:
    jac = pair_stiffness(est, params)
    nd = est.dofs
    i, j = est.pairs[:, 0], est.pairs[:, 1]
    jac = jac.astype(est.d.dtype)
    return _Edges(src=jnp.concatenate([i, j]), dst=jnp.concatenate([j, i]), d=jnp.concatenate([est.d, -est.d]),
                  h_nn=jnp.concatenate([jac[:, :nd, :nd], jac[:, nd:, nd:]]),
                  k_nm=-jnp.concatenate([jac[:, :nd, nd:], jac[:, nd:, :nd]]))


def _edge_forces(est: Estimator, params) -> tuple[_Edges, jnp.ndarray]:
    """Edges and the force on n of each edge per unit displacement gradient, ``f [E, 3, 3, 3]`` (j; l, k)."""
    e = _edges(est, params)
    n, nd = est.n, est.dofs
    valid = est.valid
    eye = jnp.eye(nd, dtype=e.d.dtype)
    D = jax.ops.segment_sum(e.h_nn, e.src, n)
    D = jnp.where(valid[:, None, None], D, eye)
    A = jnp.linalg.inv(D)
    # affine load: generalised force on n per G_lk, sum_m K^nm[:, l] d_k
    B = jax.ops.segment_sum(e.k_nm[:, :, :3, None] * e.d[:, None, None, :], e.src, n)
    free = est.relaxing[:, None, None, None]  # clamped and singular particles follow the affine field
    gamma = jnp.where(free, jnp.einsum("nab,nblk->nalk", A, B), 0.0)  # Eq. 23
    affine = e.k_nm[:, :3, :3, None] * e.d[:, None, None, :]
    if est.first_neighbour:
        phi_n = gamma
        f = affine - jnp.einsum("eja,ealk->ejlk", e.h_nn[:, :3, :], phi_n[e.src])
    else:
        gamma_m = gamma[e.dst]
        hat = jax.ops.segment_sum(jnp.einsum("eab,eblk->ealk", e.k_nm, gamma_m), e.src, n)
        hat = jnp.where(free, jnp.einsum("nab,nblk->nalk", A, hat), 0.0)  # Eq. 24 + 29
        phi_n = gamma + hat
        f = (affine - jnp.einsum("eja,ealk->ejlk", e.h_nn[:, :3, :], phi_n[e.src])
             + jnp.einsum("eja,ealk->ejlk", e.k_nm[:, :3, :], gamma_m))
    return e, f


# Three DOF per particle (the paper's form, the default): every pair has one coupling block K = K^nm = d f^i / d u^j
# (the same for both directions; the self block of the pair on either end is K as well). The algebra below is written
# on [P, ...] rows of the pairs and [n, ...] rows of the particles: broadcast products summed term by term
# (elementwise loops, no tiny batched matrix products, which XLA on CPU runs one small dot at a time), per-particle
# sums as scatters of materialised rows, and every sum over all pairs or particles that the body tensor needs as one
# matrix product with the pairs (particles) as the contracted dimension.
def _mul(a, b):
    """``[..., p, q] x [..., q, r] -> [..., p, r]`` as a sum of ``q`` broadcast products."""
    out = a[..., :, 0, None] * b[..., None, 0, :]
    for c in range(1, a.shape[-1]):
        out = out + a[..., :, c, None] * b[..., None, c, :]
    return out


def _gram(a, b):
    """``a^T b`` for ``a [m, p]``, ``b [m, q]`` (the long axis ``m`` contracted)."""
    return jax.lax.dot_general(a, b, (((0,), (0,)), ((), ())))


def _inverse3(D):
    """Inverse of ``[n, 3, 3]`` (or ``[n, 2, 2]``) matrices by cofactors (elementwise)."""
    if D.shape[-1] == 2:
        a, b, c, d = D[:, 0, 0], D[:, 0, 1], D[:, 1, 0], D[:, 1, 1]
        inv_det = 1.0 / (a * d - b * c)
        return jnp.stack([jnp.stack([d, -b], axis=-1), jnp.stack([-c, a], axis=-1)], axis=1) * inv_det[:, None, None]
    a = [[D[:, r, c] for c in range(3)] for r in range(3)]
    cof = [[a[(r + 1) % 3][(c + 1) % 3] * a[(r + 2) % 3][(c + 2) % 3]
            - a[(r + 1) % 3][(c + 2) % 3] * a[(r + 2) % 3][(c + 1) % 3] for c in range(3)] for r in range(3)]
    inv_det = 1.0 / (a[0][0] * cof[0][0] + a[0][1] * cof[0][1] + a[0][2] * cof[0][2])
    return jnp.stack([jnp.stack([cof[c][r] * inv_det for c in range(3)], axis=-1) for r in range(3)], axis=1)


def coupling(est: Estimator, params) -> jnp.ndarray:
    """The coupling ``K^nm`` of every pair (3 DOF; 2 in 2D): ``sum_s k_s G_s`` for the bonds, then the contacts.

    Args:
      est: the estimator (:func:`~jaxbpm.ste.estimator`).
      params: the bond parameters.

    Returns:
      ``[P, 3, 3]`` (2D: ``[P, 2, 2]``) one matrix [N/m] per pair, the ``n_bonds`` bonds first, then the
      ``n_contacts`` contacts.
    """
    k = est.model.stiffness(params)
    ks = tuple(jnp.asarray(x).astype(est.d.dtype) for x in (k.kn, k.kt, k.ktw, k.kb))
    nb, dim = est.n_bonds, est.d.shape[1]
    K = jnp.zeros((nb, dim * dim), est.d.dtype)
    for t, s in enumerate(est.terms):
        K = K + jnp.broadcast_to(ks[s], (nb,))[:, None] * est.geometry[t]
    if est.n_contacts:
        K = jnp.concatenate([K, est.contact_k.astype(K.dtype)])
    return K.reshape(-1, dim, dim)


class _Fluct3(NamedTuple):
    K: Any       # [P, 3, 3] K^nm
    B: Any       # [n, 3, 3, 3] sum_m K^nm[a, l] d^nm_k (a, l, k); also the lever sum M^n[i, j, a] = B[j, a, i]
    N: Any       # [n, 3, 3, 3] sum over the pairs into m of w^n d^nm_i K^nm[j, b] (i, j, b), weighted only
    gamma: Any   # [n, 3, 9] Gamma^n per G_lk (l * 3 + k)
    phi: Any     # [n, 3, 9] fluctuation of n
    q_i: Any     # [P, 3, 9] K Gamma^j (neighbour term on i), None in the first-neighbour form
    q_j: Any     # [P, 3, 9] K Gamma^i (neighbour term on j)


def _fluctuations3(est: Estimator, params, weighted: bool = False) -> _Fluct3:
    K = coupling(est, params)
    n, d = est.n, est.d
    k = d.shape[1]  # 3 (2 in 2D)
    i, j = est.pairs[:, 0], est.pairs[:, 1]
    valid = est.valid[:, None, None]
    free = est.relaxing[:, None, None]  # clamped and singular particles follow the affine field
    kd = (K[:, :, :, None] * d[:, None, None, :]).reshape(-1, k ** 3)  # K[a, l] d_k
    rows = jnp.concatenate([K.reshape(-1, k * k), kd], axis=1)
    s_i = jax.ops.segment_sum(rows, i, n)
    s_j = jax.ops.segment_sum(rows, j, n)  # d^nm = -d on the j end
    D = jnp.where(valid, (s_i[:, :k * k] + s_j[:, :k * k]).reshape(n, k, k), jnp.eye(k, dtype=d.dtype))
    B = (s_i[:, k * k:] - s_j[:, k * k:]).reshape(n, k, k * k)
    N = None
    if weighted and not est.first_neighbour:  # N^m: on m = j from the edge (i -> j), weight w^i; on i, -w^j
        w = est.include.astype(d.dtype)
        N = (jax.ops.segment_sum(w[i][:, None] * kd, j, n) - jax.ops.segment_sum(w[j][:, None] * kd, i, n))
        N = N.reshape(n, k, k, k).transpose(0, 3, 1, 2)
    A = _inverse3(D)
    gamma = jnp.where(free, _mul(A, B), 0.0)  # Eq. 23
    B = B.reshape(n, k, k, k)
    if est.first_neighbour:
        return _Fluct3(K, B, N, gamma, gamma, None, None)
    q_i, q_j = _mul(K, gamma[j]), _mul(K, gamma[i])
    hat = (jax.ops.segment_sum(q_i.reshape(-1, k ** 3), i, n) + jax.ops.segment_sum(q_j.reshape(-1, k ** 3), j, n))
    hat = jnp.where(free, _mul(A, hat.reshape(n, k, k * k)), 0.0)  # Eq. 24 + 29
    return _Fluct3(K, B, N, gamma, gamma + hat, q_i, q_j)


def _raw_body_tensor3(est: Estimator, params) -> jnp.ndarray:
    """``sum_n w^n sum_m d_i f^nm[j; l, k]`` with ``f^nm = K^nm G d - K phi^n + K Gamma^m``: the affine term as a
    matrix product over the pairs (both ends), the self term ``-w^n M^n phi^n`` and the neighbour term
    ``sum_m N^m Gamma^m`` (regrouped by the neighbour) over the particles.

    The algebra of :func:`_fluctuations3` (which the local tensors use) with the per-particle sums D, B and N
    gathered by one scatter per pair end into one ``[n, 63]`` array (fewer scatters than one per sum). The two passes
    over the pairs fold over blocks of pairs on large samples (:func:`~jaxbpm.physics.blocks.fold_blocks`), which
    bounds the per-pair scratch memory."""
    n, d, dtype = est.n, est.d, est.d.dtype
    k = d.shape[1]  # 3 (2 in 2D)
    k2, k3 = k * k, k ** 3
    K = coupling(est, params).reshape(-1, k2)
    pairs = est.pairs
    w = est.include.astype(dtype)
    valid = est.valid[:, None, None]
    free = est.relaxing[:, None, None]  # clamped and singular particles follow the affine field
    neighbours = not est.first_neighbour

    def block_of(idx, keep):
        """The pairs ``idx`` (all: ``None``): their ends, vectors and stiffness (zero on padding)."""
        p, dc, kc = (pairs, d, K) if idx is None else (pairs[idx], d[idx], K[idx])
        if keep is not None:
            kc = jnp.where(keep[:, None], kc, 0.0)
        return p[:, 0], p[:, 1], dc, kc

    def sums(carry, idx, keep):
        acc, gram = carry
        i, j, dc, kc = block_of(idx, keep)
        kd = (kc[:, :, None] * dc[:, None, :]).reshape(-1, k3)  # K[a, l] d_k
        wi, wj = w[i][:, None], w[j][:, None]
        # on i: (K, K d, N^i -= w^j K d); on j, where d^nm = -d: (K, -K d, N^j += w^i K d)
        acc = acc.at[i].add(jnp.concatenate([kc, kd] + ([-wj * kd] if neighbours else []), axis=1))
        acc = acc.at[j].add(jnp.concatenate([kc, -kd] + ([wi * kd] if neighbours else []), axis=1))
        dd = ((wi + wj)[:, :, None] * dc[:, :, None] * dc[:, None, :]).reshape(-1, k2)  # (i, k)
        return acc, gram + _gram(dd, kc)

    init = (jnp.zeros((n, k2 + (2 if neighbours else 1) * k3), dtype), jnp.zeros((k2, k2), dtype))
    acc, gram = fold_blocks(sums, init, K.shape[0])
    D = jnp.where(valid, acc[:, :k2].reshape(n, k, k), jnp.eye(k, dtype=dtype))
    B = acc[:, k2:k2 + k3].reshape(n, k, k2)
    A = _inverse3(D)
    gamma = jnp.where(free, _mul(A, B), 0.0)  # Eq. 23
    phi = gamma
    if neighbours:
        def neighbour_sums(hat, idx, keep):
            i, j, _, kc = block_of(idx, keep)
            km = kc.reshape(-1, k, k)
            return hat.at[i].add(_mul(km, gamma[j])).at[j].add(_mul(km, gamma[i]))

        hat = fold_blocks(neighbour_sums, jnp.zeros((n, k, k2), dtype), K.shape[0])
        phi = gamma + jnp.where(free, _mul(A, hat), 0.0)  # Eq. 24 + 29
    t = gram.reshape(k, k, k, k).transpose(0, 2, 1, 3)
    # sum_n w B[j, a, i] phi[a, (l, k)] and sum_n N[i, j, b] Gamma[b, (l, k)]: one matrix product each that
    # contracts (particle, a) -- rows [n * 3, 9] on both sides (faster on CPU than per-particle products summed)
    bw = (w[:, None, None, None] * B.reshape(n, k, k, k)).transpose(0, 2, 3, 1).reshape(k * n, k2)
    t = t - _gram(bw, phi.reshape(k * n, k2)).reshape(k, k, k, k).transpose(0, 1, 3, 2)
    if neighbours:
        nb_ = acc[:, k2 + k3:].reshape(n, k, k, k).transpose(0, 2, 3, 1).reshape(k * n, k2)  # [(n, b), (i, j)]
        t = t + _gram(nb_, gamma.reshape(k * n, k2)).reshape(k, k, k, k).transpose(0, 1, 3, 2)
    return t / (2.0 * jnp.sum(jnp.where(est.include, est.volume, 0.0)))


def _local_tensors3(est: Estimator, params) -> jnp.ndarray:
    fl = _fluctuations3(est, params)
    n, d = est.n, est.d
    k = d.shape[1]  # 3 (2 in 2D)
    m = len(_voigt_pairs(k))
    i, j = est.pairs[:, 0], est.pairs[:, 1]
    kd = fl.K[:, :, :, None] * d[:, None, None, :]  # [P, j, l, k]
    g_i, g_j = kd, kd  # d_i f on the i end; on the j end (-d_i) (-K d + K Gamma^i) = d_i (K d - K Gamma^i)
    if fl.q_i is not None:
        g_i, g_j = kd + fl.q_i.reshape(-1, k, k, k), kd - fl.q_j.reshape(-1, k, k, k)

    def edge(g):
        return voigt(_symmetrise(d[:, :, None, None, None] * jnp.swapaxes(g, -2, -1)[:, None])).reshape(-1, m * m)

    c = jax.ops.segment_sum(edge(g_i), i, n) + jax.ops.segment_sum(edge(g_j), j, n)
    s = jnp.einsum("njai,nalk->nijkl", fl.B, fl.phi.reshape(n, k, k, k))
    c = c.reshape(n, m, m) - voigt(_symmetrise(s))
    return c / (2.0 * est.volume[:, None, None])


def _symmetrise(c):
    """Minor-symmetrise ``[..., 3, 3, 3, 3]``."""
    c = 0.5 * (c + jnp.swapaxes(c, -4, -3))
    return 0.5 * (c + jnp.swapaxes(c, -2, -1))


def raw_body_tensor(est: Estimator, params) -> jnp.ndarray:
    """The body tensor before minor symmetrisation: ``C[i,j,k,l] = d sigma_ij / d G_lk``, the V-weighted mean of
    Eq. 32 over the included particles (non-singular, not at the surface).

    Args:
      est: the estimator (:func:`~jaxbpm.ste.estimator`).
      params: the bond parameters.

    Returns:
      ``[3, 3, 3, 3]`` the tensor [Pa].
    """
    if est.dofs == est.model.dim:
        return _raw_body_tensor3(est, params)
    return raw_body_tensor_edges(est, params)


def raw_body_tensor_edges(est: Estimator, params) -> jnp.ndarray:
    """:func:`raw_body_tensor` through the per-edge forces, for any ``dofs``.

    The 6-DOF path; with 3 DOF the reference the pair form is checked against.

    Args:
      est: the estimator (:func:`~jaxbpm.ste.estimator`).
      params: the bond parameters.

    Returns:
      ``[3, 3, 3, 3]`` the tensor ``C[i,j,k,l] = d sigma_ij / d G_lk`` [Pa], not symmetrised.
    """
    e, f = _edge_forces(est, params)
    w = est.include[e.src].astype(f.dtype)
    t = jnp.einsum("ei,ejlk->ijkl", e.d * w[:, None], f)
    return t / (2.0 * jnp.sum(jnp.where(est.include, est.volume, 0.0)))


def body_tensor(est: Estimator, params) -> jnp.ndarray:
    """The body's stiffness in Voigt form ``[6, 6]`` [Pa]: V-weighted mean of the local tensors (Eq. 32), with
    the minor and major symmetries.

    Averaged over every particle, nothing clamped, the mean of Eq. 32 is major-symmetric by construction; leaving
    out the singular and surface particles, or clamping the scene's end layers, breaks that slightly (a fraction of
    a percent of the largest component on random packings, up to 2 % with 6 DOF and clamped ends), and that small
    antisymmetric part is removed here.

    Args:
      est: the estimator (:func:`~jaxbpm.ste.estimator`).
      params: the bond parameters.

    Returns:
      ``[6, 6]`` the Voigt stiffness [Pa].
    """
    c6 = voigt(_symmetrise(raw_body_tensor(est, params)))
    return 0.5 * (c6 + c6.T)


def local_tensors(est: Estimator, params) -> jnp.ndarray:
    """Local stiffness tensors ``C^n`` in Voigt form (Eq. 32, or Eq. 33-35 with ``first_neighbour``),
    minor-symmetrised.

    Args:
      est: the estimator (:func:`~jaxbpm.ste.estimator`).
      params: the bond parameters.

    Returns:
      ``[n, 6, 6]`` [Pa]; NaN for singular (skipped) particles.
    """
    if est.dofs == est.model.dim:
        return jnp.where(est.valid[:, None, None], _local_tensors3(est, params), jnp.nan)
    return local_tensors_edges(est, params)


_local_tensors_jit = jax.jit(local_tensors)


def local_tensors_edges(est: Estimator, params) -> jnp.ndarray:
    """:func:`local_tensors` through the per-edge forces, for any ``dofs`` (the 6-DOF path).

    Args:
      est: the estimator (:func:`~jaxbpm.ste.estimator`).
      params: the bond parameters.

    Returns:
      ``[n, 6, 6]`` the minor-symmetrised Voigt tensors [Pa]; NaN for singular (skipped) particles.
    """
    e, f = _edge_forces(est, params)
    vi = np.array([p[0] for p in VOIGT])
    vj = np.array([p[1] for p in VOIGT])
    # edge contribution in Voigt form: sym_ij sym_kl d_i f_{j; l k}
    fs = 0.5 * (f + jnp.swapaxes(f, -2, -1))  # symmetric in (l, k)
    fs = fs[:, :, vj, vi]                       # [E, 3, 6]
    c = 0.5 * (e.d[:, vi, None] * fs[:, vj, :] + e.d[:, vj, None] * fs[:, vi, :])  # [E, 6, 6]
    c = jax.ops.segment_sum(c, e.src, est.n) / (2.0 * est.volume[:, None, None])
    return jnp.where(est.valid[:, None, None], c, jnp.nan)


def voigt(c) -> jnp.ndarray:
    """A fourth-order tensor in Voigt form (order 11, 22, 33, 23, 13, 12; in 2D 11, 22, 12).

    Args:
      c: ``[..., 3, 3, 3, 3]`` (2D: ``[..., 2, 2, 2, 2]``) the tensor.

    Returns:
      ``[..., 6, 6]`` (2D: ``[..., 3, 3]``).
    """
    pairs = _voigt_pairs(c.shape[-1])
    i = np.array([p[0] for p in pairs])
    j = np.array([p[1] for p in pairs])
    return c[..., i[:, None], j[:, None], i[None, :], j[None, :]]


def tensor_from_voigt(c6) -> jnp.ndarray:
    """A Voigt stiffness as a fourth-order tensor with the minor symmetries.

    Args:
      c6: ``[..., 6, 6]`` the Voigt form (2D: ``[..., 3, 3]``).

    Returns:
      ``[..., 3, 3, 3, 3]`` (2D: ``[..., 2, 2, 2, 2]``).
    """
    dim = 2 if c6.shape[-1] == 3 else 3
    idx = np.zeros((dim, dim), int)
    for k, (a, b) in enumerate(_voigt_pairs(dim)):
        idx[a, b] = idx[b, a] = k
    return c6[..., idx[:, :, None, None], idx[None, None, :, :]]


def moduli(c6) -> dict:
    """Engineering constants of a Voigt stiffness.

    Args:
      c6: ``[..., 6, 6]`` the Voigt stiffness [Pa].

    Returns:
      ``{"E": [..., 3]`` Young's moduli along x, y, z; ``"nu": [..., 3, 3]`` Poisson ratios nu_ij = -S_ij / S_ii
      (lateral strain j per axial strain i); ``"G": [..., 3]`` shear moduli G_23, G_13, G_12;
      ``"compliance": [..., 6, 6]}``. In 2D (``c6 [..., 3, 3]``): the in-plane (plane-stress) ``E [..., 2]``,
      ``nu [..., 2, 2]`` and ``G [..., 1]`` (G_12).
    """
    s = jnp.linalg.inv(c6)
    diag = jnp.diagonal(s, axis1=-2, axis2=-1)
    k = 2 if c6.shape[-1] == 3 else 3
    return {"E": 1.0 / diag[..., :k], "nu": -s[..., :k, :k] / diag[..., :k, None], "G": 1.0 / diag[..., k:],
            "compliance": s}


def directional_modulus(c6, direction) -> jnp.ndarray:
    """Young's modulus along a direction: ``1 / (b^T S b)``, ``b`` the Voigt form of ``n n^T`` with ``n`` the unit
    direction.

    Args:
      c6: ``[6, 6]`` the Voigt stiffness [Pa].
      direction: ``[3]`` the direction (any length).

    Returns:
      The modulus [Pa].
    """
    n = jnp.asarray(direction, c6.dtype)
    n = n / jnp.linalg.norm(n)
    b = jnp.stack([n[0] ** 2, n[1] ** 2, n[2] ** 2, n[1] * n[2], n[0] * n[2], n[0] * n[1]])
    return 1.0 / (b @ jnp.linalg.inv(c6) @ b)


def isotropic_fit(c6) -> tuple[jnp.ndarray, jnp.ndarray]:
    """The isotropic tensor nearest to ``c6`` (least squares over the 81 components).

    Args:
      c6: ``[6, 6]`` the Voigt stiffness [Pa].

    Returns:
      ``(E, nu)``: its Young's modulus [Pa] and Poisson's ratio (2D, ``c6 [3, 3]``: the isotropic plane-stress
      tensor's in-plane E and nu).
    """
    c = tensor_from_voigt(c6)
    a = jnp.einsum("...iijj->...", c)   # 9 lambda + 6 mu
    b = jnp.einsum("...ijij->...", c)   # 3 lambda + 12 mu
    if c6.shape[-1] == 3:  # 2D: a = 4 lambda + 4 mu, b = 2 lambda + 6 mu; plane stress E, nu of (lambda, mu)
        mu = (2.0 * b - a) / 8.0
        lam = a / 4.0 - mu
        return 4.0 * mu * (lam + mu) / (lam + 2.0 * mu), lam / (lam + 2.0 * mu)
    mu = (3.0 * b - a) / 30.0
    lam = (a - 6.0 * mu) / 9.0
    return mu * (3.0 * lam + 2.0 * mu) / (lam + mu), lam / (2.0 * (lam + mu))
