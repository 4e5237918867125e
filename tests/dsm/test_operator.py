"""The tangent element by element (:mod:`jaxbpm.dsm.operator`): Jacobians, their symmetric part, the operator against
the force function's jvp, the bond geometry.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import dsm
from jaxbpm.physics import blocks
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression


@pytest.mark.parametrize("dofs", [3, 6])
def test_symmetrised_jacobians_are_the_symmetric_part(packing, dofs):
    model = UniaxialCompression().model(packing, rotations=dofs == 6)
    jr = dsm.reduced_jacobians(model, default_params(packing))
    np.testing.assert_allclose(dsm.symmetrised(jr), jr, atol=1e-12 * float(jnp.abs(jr).max()))  # bonds at rest
    pairs = jnp.asarray(np.asarray(model.bonds)[:50])
    d = (model.positions0[pairs[:, 1]] - model.positions0[pairs[:, 0]]) * 0.999  # a small overlap
    jc = dsm.contact_jacobians(model, pairs, None, d)
    full, sym = dsm.full_jacobians(jc), dsm.full_jacobians(dsm.symmetrised(jc))
    np.testing.assert_allclose(sym, 0.5 * (full + jnp.swapaxes(full, 1, 2)), atol=1e-12 * float(jnp.abs(full).max()))
    assert float(jnp.abs(full - jnp.swapaxes(full, 1, 2)).max()) > 0  # the preloaded contact is not symmetric


@pytest.mark.parametrize("dofs", [3, 6])
def test_element_by_element_operator_equals_the_force_jvp(packing, dofs):
    model = UniaxialCompression().model(packing, rotations=dofs == 6)
    p = default_params(packing)
    v = jnp.asarray(np.random.default_rng(0).normal(size=(model.n, dofs)) * 1e-6)
    ebe, jac = dsm.tangent_operator(model, p, operator="jacobians")
    jvp, none = dsm.tangent_operator(model, p, operator="jvp")
    ni = 9 if dofs == 6 else 3
    assert jac.shape == (ni, ni, model.bonds.shape[0]) and none is None
    a, b = ebe(v), jvp(v)
    np.testing.assert_allclose(a, b, atol=1e-12 * float(jnp.abs(b).max()))
    # the full per-bond Jacobians are symmetric (the bond law has a potential at rest) and give the same product
    full = dsm.bond_jacobians(model, p)
    assert full.shape == (model.bonds.shape[0], 2 * dofs, 2 * dofs)
    np.testing.assert_allclose(full, jnp.swapaxes(full, 1, 2), atol=1e-9 * float(jnp.abs(full).max()))
    bonds = np.asarray(model.bonds)
    z = jnp.concatenate([v[bonds[:, 0]], v[bonds[:, 1]]], axis=1)
    y = jnp.einsum("bij,bj->bi", full, z)
    c = jax.ops.segment_sum(jnp.concatenate([y[:, :dofs], y[:, dofs:]]), jnp.concatenate([bonds[:, 0], bonds[:, 1]]),
                            model.n)
    np.testing.assert_allclose(c, b, atol=1e-12 * float(jnp.abs(b).max()))
    # and each particle's self block is the sum of its bonds' diagonal blocks
    blocks = dsm.block_diagonal(model, p, jac)
    ref = (jax.ops.segment_sum(full[:, :dofs, :dofs], bonds[:, 0], model.n)
           + jax.ops.segment_sum(full[:, dofs:, dofs:], bonds[:, 1], model.n))
    np.testing.assert_allclose(blocks, ref, atol=1e-12 * float(jnp.abs(ref).max()))


@pytest.mark.parametrize("dofs", [3, 6])
def test_bond_geometry_reproduces_the_jacobians_and_the_preconditioner(packing, dofs):
    # two materials with different E and nu: E_b (J_E + s(nu_b) J_G) is the forward-mode Jacobian of the bond law,
    # and the weighed per-material parts are the block diagonal and the coarse matrix assembled from it
    s = jaxbpm.generate.mix_materials(packing, [0.5, 0.5], seed=2, materials={"E": [1e9, 3e9], "nu": [0.2, 0.35]})
    scene = UniaxialCompression(strain=0.002)
    model = scene.model(s, rotations=dofs == 6)
    free = dsm.free_mask(model, scene, s)[0]
    coarse = dsm.coarse_space(model, free, aggregate_size=25)
    geo = dsm.bond_geometry(model, coarse, n_materials=2)
    assert geo.reduced is None  # read by the preconditioner's parts only
    p = default_params(s)
    ref = dsm.reduced_jacobians(model, p)
    jr, jp, _ = dsm.operator.geometric_jacobians(model, p, dsm.bond_geometry(model, coarse))
    scale = float(jnp.abs(ref).max())
    np.testing.assert_allclose(jr, ref, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(jp, dsm.packed_jacobians(ref), rtol=0, atol=1e-12 * scale)
    w = dsm.operator.material_weights(p)
    np.testing.assert_allclose(jnp.einsum("mp,mpnab->nab", w, geo.blocks), dsm.block_diagonal(model, p, ref),
                               rtol=0, atol=1e-12 * scale)
    direct = dsm.preconditioner.coarse_matrix(model, ref, coarse)
    np.testing.assert_allclose(jnp.einsum("mp,mpab->ab", w, geo.coarse), direct, rtol=0,
                               atol=1e-12 * float(jnp.abs(direct).max()))
    # the solve through the geometry equals the one that differentiates the bond law, and so do its gradients
    free_j = jnp.asarray(free)
    u_p = np.zeros(free.shape)
    u_p[~free.all(axis=1) & (np.asarray(s.positions)[:, 2] > np.asarray(s.positions)[:, 2].mean()), 2] = -1e-6

    def k(p, geometry):
        u, _ = dsm.linear_solve(model, p, free_j, jnp.asarray(u_p), tol=1e-10, coarse=coarse, geometry=geometry)
        return jnp.vdot(u, dsm.tangent_operator(model, p)[0](u))

    k_and_grad = jax.jit(jax.value_and_grad(k))  # (one program per operator, not a trace op by op)
    (k_geo, g_geo), (k_ref, g_ref) = k_and_grad(p, geo), k_and_grad(p, None)
    np.testing.assert_allclose(k_geo, k_ref, rtol=1e-9)
    for name in ("bond_E", "bond_nu"):
        np.testing.assert_allclose(g_geo[name], g_ref[name], rtol=1e-7)


@pytest.mark.parametrize("dofs", [3, 6])
def test_setup_over_bond_blocks_equals_the_whole_sample(packing, dofs, monkeypatch):
    # large samples build the bonds' geometric parts block by block (lax.map over padded blocks): same numbers as
    # one pass over all bonds, the padding cut off
    block = blocks.BLOCK
    assert blocks.block_length(7 * block) == block and blocks.block_length(11 * block // 4) == block // 4
    assert blocks.block_length(7 * block + 1) == block  # no divisor: padded
    model = UniaxialCompression(strain=0.002).model(packing, rotations=dofs == 6)
    nb = model.bonds.shape[0]
    whole = jax.jit(dsm.operator._geometry_block)(model)
    blocked = jax.jit(lambda m: dsm.operator.over_bonds(dsm.operator._geometry_block, m, block=97))(model)
    assert nb % blocks.block_length(nb, 97) != 0 and nb > 2 * 97  # padded
    for a, b in zip(whole, blocked):
        assert a.shape == b.shape and a.shape[-1] == nb
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-14 * float(jnp.abs(a).max()))
    # the preconditioner's parts, sums over bonds and over the coupling bonds, block by block
    s = jaxbpm.generate.mix_materials(packing, [0.5, 0.5], seed=2, materials={"E": [1e9, 3e9], "nu": [0.2, 0.35]})
    model = UniaxialCompression(strain=0.002).model(s, rotations=dofs == 6)
    free = dsm.free_mask(model, UniaxialCompression(strain=0.002), s)[0]
    coarse = dsm.coarse_space(model, free, aggregate_size=25)
    reduced = dsm.operator._geometry_parts(model)[0]
    parts = dsm.preconditioner._preconditioner_parts.__wrapped__
    ref = jax.jit(parts, static_argnums=3)(model, reduced, coarse, 2)
    monkeypatch.setattr(blocks, "BLOCK", 53)
    assert coarse.bonds.shape[0] > 2 * 53
    got = jax.jit(parts, static_argnums=3)(model, reduced, coarse, 2)
    for a, b in zip(ref, got):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-13 * float(jnp.abs(a).max()))
