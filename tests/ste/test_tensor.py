"""The STE's tensors (:mod:`jaxbpm.ste.tensor`): lattice closed forms, symmetries, rotation, isotropy, the pair and edge
forms, sums over blocks of pairs.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import ste
from jaxbpm.physics import blocks
from jaxbpm.physics.bond import BondStiffness
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression
from tests.ste.conftest import D, R


def _centre(sample):
    pos = np.asarray(sample.positions)
    return int(np.argmin(np.linalg.norm(pos - pos.mean(axis=0), axis=1)))


def _rotate4(c, rot):
    return np.einsum("ia,jb,kc,ld,abcd->ijkl", rot, rot, rot, rot, c)


@pytest.mark.parametrize("dofs", [3, 6])
@pytest.mark.parametrize("first_neighbour", [False, True])
def test_simple_cubic_interior_tensor_is_exact(lattice, dofs, first_neighbour):
    p = default_params(lattice)
    est = ste.estimator(lattice, dofs=dofs, first_neighbour=first_neighbour)
    k = est.model.stiffness(p)
    kn, kt = float(k.kn[0]), float(k.kt[0])
    c = np.asarray(jax.jit(ste.local_tensors)(est, p))[_centre(lattice)]
    expected = np.diag([kn / D] * 3 + [kt / (2 * D)] * 3)  # C_11 = k_n/d, C_12 = 0, C_44 = k_t/(2d)
    np.testing.assert_allclose(c, expected, rtol=1e-12, atol=1e-12 * kn / D)
    m = ste.moduli(jnp.asarray(c))
    np.testing.assert_allclose(m["E"], kn / D, rtol=1e-12)
    np.testing.assert_allclose(m["nu"][0, 1], 0.0, atol=1e-12)
    # off-axis: cubic symmetry, 1/E(111) = S11 - 2 (S11 - S12 - S44/2) / 3 with S12 = 0, S44 = 2d/k_t
    s11, s44 = D / kn, 2 * D / kt
    np.testing.assert_allclose(ste.directional_modulus(jnp.asarray(c), [1.0, 1.0, 1.0]),
                               1.0 / (s11 - 2.0 * (s11 - s44 / 2) / 3.0), rtol=1e-12)
    assert est.skipped == 0


def test_normal_springs_only_give_full_symmetry_and_poisson_zero(lattice):
    est = ste.estimator(lattice, dofs=3, surface_depth=0.0)
    k = est.model.stiffness(default_params(lattice))
    springs = BondStiffness(kn=k.kn, kt=0.0 * k.kt, ktw=0.0 * k.ktw, kb=0.0 * k.kb)
    c = np.asarray(jax.jit(ste.local_tensors)(est, springs))[_centre(lattice)]
    np.testing.assert_allclose(c[:3, :3], np.eye(3) * float(k.kn[0]) / D, rtol=1e-12)
    np.testing.assert_allclose(c[3:, 3:], 0.0, atol=1e-9)
    raw = np.asarray(jax.jit(ste.raw_body_tensor)(est, springs))
    scale = np.abs(raw).max()
    np.testing.assert_allclose(raw, raw.transpose(1, 0, 2, 3), atol=1e-12 * scale)  # central forces: minor
    np.testing.assert_allclose(raw, raw.transpose(0, 1, 3, 2), atol=1e-12 * scale)


@pytest.mark.parametrize("dofs", [3, 6])
def test_body_tensor_has_major_and_minor_symmetries(lattice, dofs):
    # a randomly perturbed lattice (no singular particle), every particle averaged: Eq. 32 with Gamma^ from
    # Eq. 29 is major-symmetric by construction, nothing imposed
    rng = np.random.default_rng(1)
    pos = np.asarray(lattice.positions) + rng.uniform(-0.1, 0.1, (lattice.n_particles, 3)) * R
    shaken = jaxbpm.Sample.from_arrays(pos, lattice.radii, lattice.bonds, lattice.bond_radius,
                                       materials=lattice.materials, domain=lattice.domain)
    p = default_params(shaken)
    est = ste.estimator(shaken, dofs=dofs, surface_depth=0.0)
    assert est.skipped == 0
    raw = np.asarray(jax.jit(ste.raw_body_tensor)(est, p))
    scale = np.abs(raw).max()
    np.testing.assert_allclose(raw, raw.transpose(2, 3, 0, 1), atol=1e-12 * scale)
    assert np.abs(raw - raw.transpose(1, 0, 2, 3)).max() > 1e-6 * scale  # 3-DOF shear springs: not minor
    c6 = np.asarray(jax.jit(ste.body_tensor)(est, p))
    c = np.asarray(ste.tensor_from_voigt(c6))
    for perm in [(1, 0, 2, 3), (0, 1, 3, 2), (2, 3, 0, 1)]:
        np.testing.assert_allclose(c, np.transpose(c, perm), atol=1e-12 * np.abs(c).max())
    assert np.all(np.linalg.eigvalsh(c6) > 0)


def test_packing_tensor_is_nearly_major_symmetric(packing):
    # default averages (singular and surface particles left out): the symmetry of Eq. 32 holds to a fraction of 1 %
    est = ste.estimator(packing)
    raw = np.asarray(jax.jit(ste.raw_body_tensor)(est, default_params(packing)))
    assert np.abs(raw - raw.transpose(2, 3, 0, 1)).max() < 1e-2 * np.abs(raw).max()
    assert est.skipped > 0 and est.surface > 0


def test_rotating_the_sample_rotates_the_tensor(packing):
    rng = np.random.default_rng(0)
    rot, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    rot *= np.sign(np.linalg.det(rot))
    vol = 4.0 / 3.0 * np.pi * np.asarray(packing.radii) ** 3 / 0.58
    turned = jaxbpm.Sample.from_arrays(np.asarray(packing.positions) @ rot.T, packing.radii, packing.bonds,
                                       packing.bond_radius, materials=packing.materials)
    p = default_params(packing)
    a = jax.jit(ste.raw_body_tensor)(ste.estimator(packing, volumes=vol, surface_depth=0.0), p)
    b = jax.jit(ste.raw_body_tensor)(ste.estimator(turned, volumes=vol, surface_depth=0.0), p)
    np.testing.assert_allclose(b, _rotate4(np.asarray(a), rot), atol=1e-9 * float(jnp.abs(a).max()))


def test_random_packing_is_isotropic(packing, plain):
    # the sample's own tensor (boundary="free": nothing clamped, every surface free) is isotropic
    res = jaxbpm.solve(packing, UniaxialCompression(strain=0.002), method="ste", boundary="free")
    e = np.array([res.stats[k] for k in ("E_x", "E_y", "E_z")])
    assert e.max() / e.min() - 1 < 0.05, e
    assert abs(res.stats["E_iso"] / e.mean() - 1) < 0.05
    assert 0.0 < res.stats["nu_iso"] < 0.5
    assert res.stats["skipped"] < 0.05 * packing.n_particles and res.stats["surface"] > 0
    assert res.stats["clamped"] == 0  # the end layers relax
    # the default clamps the scene's end layers: the modulus along the load is the clamped sample's, stiffer than
    # across it (measured +6 %), where the clamps hold no particle
    e_clamped = np.array([plain.stats[k] for k in ("E_x", "E_y", "E_z")])
    assert plain.stats["clamped"] > 0 and e_clamped[2] > e_clamped[:2].max() and e_clamped[2] > e[2]


def test_pair_form_matches_edge_form(packing):
    # the 3-DOF pair form (K^nm from the stored unit-stiffness Jacobians, sums regrouped into matrix products) gives
    # the per-edge computation of Eq. 23-32 to round-off, bonds and contacts, full and first-neighbour forms
    scene = UniaxialCompression(strain=0.002, contacts=True)
    p = default_params(packing)

    def full(est, p):
        return (ste.raw_body_tensor(est, p), ste.tensor.raw_body_tensor_edges(est, p), ste.local_tensors(est, p),
                ste.tensor.local_tensors_edges(est, p), ste.tensor.coupling(est, p), ste.pair_stiffness(est, p))

    est = ste.estimator(packing, scene)
    assert est.n_contacts > 0 and est.terms == (0, 1)
    fast, ref, loc, loc_ref, k, jac = jax.jit(full)(est, p)
    np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-12 * float(jnp.abs(ref).max()))
    np.testing.assert_array_equal(np.isnan(loc), np.isnan(loc_ref))
    np.testing.assert_allclose(loc, loc_ref, rtol=0, atol=1e-12 * float(jnp.nanmax(jnp.abs(loc_ref))))
    # K^nm = sum_s k_s G_s is the Jacobian of the bond law with the actual stiffnesses (and of the contact law)
    np.testing.assert_allclose(k, -jac[:, :3, 3:], rtol=0, atol=1e-12 * float(jnp.abs(k).max()))
    first = ste.estimator(packing, scene, first_neighbour=True)
    fast, ref = jax.jit(lambda e, p: (ste.raw_body_tensor(e, p), ste.tensor.raw_body_tensor_edges(e, p)))(first, p)
    np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-12 * float(jnp.abs(ref).max()))


@pytest.mark.parametrize("first_neighbour", [False, True])
def test_pair_sums_over_blocks_equal_one_pass(packing, monkeypatch, first_neighbour):
    # large samples fold the pair sums over blocks of pairs (padding weighed zero): the same tensor and gradient as
    # one pass over all pairs, bonds and contacts
    scene = UniaxialCompression(strain=0.002, contacts=True)
    est = ste.estimator(packing, scene, first_neighbour=first_neighbour)
    p = default_params(packing)

    def tensor_and_grad(e, p):
        t = ste.raw_body_tensor(e, p)
        return t, jax.grad(lambda q: ste.raw_body_tensor(e, q)[2, 2, 2, 2])(p)

    one, g_one = jax.jit(tensor_and_grad)(est, p)
    pairs = est.pairs.shape[0]
    monkeypatch.setattr(blocks, "BLOCK", 97)
    assert pairs > 2 * 97 and pairs % blocks.block_length(pairs) != 0  # several blocks, the last padded
    folded, g_folded = jax.jit(lambda e, q: tensor_and_grad(e, q))(est, p)  # a new function: traced again
    np.testing.assert_allclose(folded, one, rtol=0, atol=1e-12 * float(jnp.abs(one).max()))
    for name in ("bond_E", "bond_nu"):
        np.testing.assert_allclose(g_folded[name], g_one[name], rtol=1e-10)
