"""Block-Jacobi and the coarse space (:mod:`jaxbpm.dsm.preconditioner`)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import dsm
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression


def test_coarse_matrix_needs_only_the_coupling_bonds(packing):
    model = UniaxialCompression().model(packing)
    free = dsm.free_mask(model, UniaxialCompression(), packing)[0]
    coarse = dsm.coarse_space(model, free, aggregate_size=25)
    assert 4 <= coarse.count <= 16 and 0 < coarse.bonds.shape[0] < model.bonds.shape[0]
    jac = dsm.reduced_jacobians(model, default_params(packing))
    every = dataclasses.replace(coarse, bonds=jnp.arange(model.bonds.shape[0]))
    a, b = dsm.preconditioner.coarse_factor(model, jac, coarse), dsm.preconditioner.coarse_factor(model, jac, every)
    np.testing.assert_allclose(a @ a.T, b @ b.T, rtol=1e-8, atol=1e-10 * float(jnp.abs(b @ b.T).max()))
    # and it is P^T K_ff P: compare with the operator applied to the coarse basis (one column per rigid mode)
    basis = np.zeros((coarse.count * 6,) + free.shape)
    for a_ in range(coarse.count):
        members = np.asarray(coarse.labels) == a_
        basis[6 * a_:6 * a_ + 6, members] = np.moveaxis(np.asarray(coarse.basis)[members], 2, 0)
    full, _ = dsm.tangent_operator(model, default_params(packing))
    kp = jax.vmap(full)(jnp.asarray(basis))
    direct = jnp.einsum("aij,bij->ab", jnp.asarray(basis), kp)
    d = jnp.diag(direct)
    direct = direct + jnp.diag(jnp.where(d > 0, 1e-10 * d.max(), 1.0))  # the factor's documented shift
    np.testing.assert_allclose(b @ b.T, direct, atol=1e-9 * float(jnp.abs(direct).max()))


def test_two_level_preconditioner_same_answer_fewer_iterations(packing):
    scene = UniaxialCompression(strain=0.002)
    # the residual test alone: iterations to the same residual
    a = jaxbpm.solve(packing, scene, method="dsm", preconditioner="jacobi", linear_tol=1e-10, stiffness_tol=None)
    b = jaxbpm.solve(packing, scene, method="dsm", preconditioner="two-level", aggregate_size=25, linear_tol=1e-10,
                     stiffness_tol=None)
    assert a.stats["preconditioner"] == "jacobi" and b.stats["preconditioner"] == "two-level"
    assert b.stats["aggregates"] >= 4
    np.testing.assert_allclose(b.stiffness, a.stiffness, rtol=1e-8)
    assert b.stats["iterations"] < 0.7 * a.stats["iterations"], (a.stats["iterations"], b.stats["iterations"])
    # the energy measure of K and the DEM's boundary measure agree at convergence
    np.testing.assert_allclose(a.stats["stiffness_boundary"], a.stiffness, rtol=1e-7)


@pytest.mark.parametrize("m", [5, 96, 250])
def test_preconditioner_building_blocks_match_dense_linear_algebra(m):
    rng = np.random.default_rng(m)
    # blocked Cholesky substitution (block size 96: one partial block, exactly one block, two full and a partial one)
    x = rng.normal(size=(m, m))
    a = x @ x.T + m * np.eye(m)
    r = rng.normal(size=m)
    got = dsm.CholeskyBlocks.of(jnp.linalg.cholesky(jnp.asarray(a))).solve(jnp.asarray(r))
    np.testing.assert_allclose(got, np.linalg.solve(a, r), rtol=1e-10, atol=1e-12 * np.abs(np.linalg.solve(a, r)).max())
