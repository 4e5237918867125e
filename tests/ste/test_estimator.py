"""The STE's estimator (:mod:`jaxbpm.ste.estimator`): clamped layers, the paper's form, float32, bad input."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import SampleError, SceneError, ste
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression
from tests.ste.conftest import D, R


def _clamped_lattice(cells):
    """An SC lattice clamped at its end layers through fixed/driven masks, l = (n_z - 1) d, A = n_x n_y d^2, and
    its closed-form stiffness: n_x n_y chains of n_z - 1 bonds in parallel."""
    nx, ny, nz = cells
    s = jaxbpm.generate.lattice("sc", cells, R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})
    z = np.asarray(s.positions)[:, 2]
    fixed, driven = np.isclose(z, z.min()), np.isclose(z, z.max())
    scene = UniaxialCompression(strain=0.002, fixed=fixed, driven=driven, gauge_length=(nz - 1) * D,
                                area=nx * ny * D**2)
    kn = float(ste.estimator(s).model.stiffness(default_params(s)).kn[0])
    return s, scene, nx * ny * kn / (nz - 1), kn


def test_clamped_simple_cubic_lattice_is_exact():
    # the affine field is the exact solution: the DSM gives the closed form to round-off, and so does the STE's
    # default (boundary="clamped": the clamped end layers follow the affine field and bound the sample), in every
    # form (first-neighbour, 6 DOF, layered) and with every non-clamped particle averaged (surface_depth=0)
    s, scene, exact, kn = _clamped_lattice((4, 4, 8))
    dsm = jaxbpm.solve(s, scene, method="dsm")
    np.testing.assert_allclose(dsm.stiffness, exact, rtol=1e-12)
    res = jaxbpm.solve(s, scene, method="ste")
    np.testing.assert_allclose(res.stiffness, exact, rtol=1e-9)  # measured 1e-16
    np.testing.assert_allclose(res.stiffness, dsm.stiffness, rtol=1e-9)
    # the end layers are clamped and out of the averages; the free surface is the four faces parallel to the load
    # (the outer ring of each of the 6 inner layers: 12 x 6 particles)
    st = res.stats
    assert st["boundary"] == "clamped" and st["clamped"] == 32 and st["surface"] == 72 and st["skipped"] == 0
    np.testing.assert_allclose(st["E_z"], kn / D, rtol=1e-9)
    for opts in ({"first_neighbour": True}, {"dofs": 6}, {"layered": True}, {"surface_depth": 0.0}):
        np.testing.assert_allclose(jaxbpm.solve(s, scene, method="ste", **opts).stiffness, exact, rtol=1e-9)
    # every included particle has the interior tensor's C_33 = k_n / d (C_13 = C_23 = 0)
    est = ste.estimator(s, scene)
    assert est.clamped == 32 and not np.any(np.asarray(est.include) & ~np.asarray(est.free))
    c = np.asarray(jax.jit(ste.local_tensors)(est, default_params(s)))[np.asarray(est.include)]
    np.testing.assert_allclose(c[:, 2, 2], kn / D, rtol=1e-12)
    np.testing.assert_allclose(c[:, :2, 2], 0.0, atol=1e-12 * kn / D)


def test_clamped_particles_as_layers_or_masks_give_the_same_stiffness():
    # the scene's default layers and the same particles given as fixed/driven masks: one clamped form, one K
    s, masks, exact, _ = _clamped_lattice((3, 3, 6))
    layers = UniaxialCompression(strain=0.002)
    fixed, driven = layers.layers(s)
    assert np.array_equal(fixed, masks.fixed) and np.array_equal(driven, masks.driven)
    assert layers.geometry(s) == pytest.approx(masks.geometry(s), rel=1e-12)
    a, b = (jaxbpm.solve(s, sc, method="ste") for sc in (layers, masks))
    np.testing.assert_allclose(a.stiffness, exact, rtol=1e-9)
    np.testing.assert_allclose(b.stiffness, a.stiffness, rtol=1e-12)
    assert a.stats["clamped"] == b.stats["clamped"] == 18


def test_paper_form_on_the_clamped_lattice():
    # boundary="free", the paper's form: the clamped end layers relax as one-sided surface particles (docs/ste.md
    # tabulates it); the layer next to each end inherits their relaxation through Eq. 29 and K Gamma^m and loses
    # 5/26 of its C_33 (k_t = 0.4 k_n); two layers of n_z - 2 averaged: 1 - 5 / (13 (n_z - 2))
    s, scene, exact, kn = _clamped_lattice((4, 4, 8))
    free = jaxbpm.solve(s, scene, method="ste", boundary="free")
    np.testing.assert_allclose(free.stiffness / exact, 1 - 5 / 78, rtol=1e-12)
    assert free.stats["boundary"] == "free" and free.stats["clamped"] == 0 and free.stats["surface"] == 104
    # an estimator without a scene clamps nothing: the same form
    p = default_params(s)
    np.testing.assert_allclose(float(ste.scene_stiffness(ste.estimator(s), p, s, scene)[0]), free.stiffness,
                               rtol=1e-12)
    # every particle averaged (surface_depth=0): the clamped layers also count with whole cells while the gauge
    # length runs between their centres, (n_z - 1) / n_z: -27.1 % here (-10.3 % on 10 x 10 x 20)
    every = jaxbpm.solve(s, scene, method="ste", boundary="free", surface_depth=0.0)
    assert abs(every.stiffness / exact - (1 - 0.2708)) < 1e-3


def test_clamp_layers_is_the_deprecated_spelling_of_boundary():
    s, scene, exact, _ = _clamped_lattice((3, 3, 6))
    for old, new in ((True, "clamped"), (False, "free")):
        with pytest.warns(DeprecationWarning, match=f"use boundary='{new}'") as caught:
            res = jaxbpm.solve(s, scene, method="ste", clamp_layers=old)
        assert caught[0].filename == __file__  # the warning names the caller, not jaxbpm
        # the same options: the setup the old spelling built serves the new one (nothing built, nothing compiled)
        built = ste.scene._setups.builds
        with jaxbpm.count_compilations() as c:
            assert res.stiffness == jaxbpm.solve(s, scene, method="ste", boundary=new).stiffness
        assert ste.scene._setups.builds == built and c.count == 0
        with pytest.warns(DeprecationWarning):
            est = ste.estimator(s, scene, clamp_layers=old)
        assert est.clamped == (18 if old else 0)
    with pytest.raises(SceneError, match="clamp_layers must be True or False"):
        ste.estimator(s, scene, clamp_layers="yes")
    with pytest.raises(SceneError, match="boundary must be 'clamped' or 'free'"):
        ste.estimator(s, scene, boundary="walls")


def test_float32_estimate_matches_float64(packing, plain):
    # precision="float32": the same estimate in single precision (tensor, walls, layered model, contacts, and the
    # gradient, which reverse mode takes through the cast)
    scene = UniaxialCompression(strain=0.002)
    single = jaxbpm.solve(packing, scene, method="ste", precision="float32")
    assert single.stats["precision"] == "float32" and plain.stats["precision"] == "float64"
    np.testing.assert_allclose(single.stiffness, plain.stiffness, rtol=1e-5)
    np.testing.assert_allclose(single.stats["tensor"], plain.stats["tensor"], rtol=0,
                               atol=1e-5 * np.abs(plain.stats["tensor"]).max())
    for kw in ({"layered": True}, {"scene": UniaxialCompression(strain=0.002, contacts=True, boundary="walls")}):
        sc = kw.pop("scene", scene)
        a = jaxbpm.solve(packing, sc, method="ste", **kw)
        b = jaxbpm.solve(packing, sc, method="ste", precision="float32", **kw)
        np.testing.assert_allclose(b.stiffness, a.stiffness, rtol=1e-5)
    p = default_params(packing)
    g64 = jax.jit(jax.grad(ste.stiffness_function(packing, scene)))(p)["bond_E"]
    g32 = jax.jit(jax.grad(ste.stiffness_function(packing, scene, precision="float32")))(p)["bond_E"]
    np.testing.assert_allclose(g32, g64, rtol=1e-2)  # measured 2.1e-3: the backward pass cancels terms
    assert g32.dtype == p["bond_E"].dtype  # the cotangent comes back in the parameters' type
    with pytest.raises(SceneError, match="precision must be"):
        ste.estimator(packing, precision="half")


def test_bad_input_is_reported(lattice, packing):
    scene = UniaxialCompression(strain=0.002)
    with pytest.raises(SceneError, match="dofs must be 3 or 6"):
        jaxbpm.solve(lattice, scene, method="ste", dofs=4)
    with pytest.raises(SceneError, match=r"bond_E.*shape \[1\]"):
        jaxbpm.solve(lattice, scene, method="ste", params={"bond_E": jnp.ones(2), "bond_nu": jnp.ones(1) * 0.2})
    with pytest.raises(SceneError, match="finite and > 0"):
        jaxbpm.solve(lattice, scene, method="ste", params={"bond_E": -jnp.ones(1), "bond_nu": jnp.ones(1) * 0.2})
    with pytest.raises(SceneError, match="surface_depth"):
        jaxbpm.solve(lattice, scene, method="ste", surface_depth=1.0)
    with pytest.raises(SceneError, match="UniaxialCompression"):
        ste.stiffness_function(lattice, object())
    with pytest.raises(TypeError, match="jaxbpm.Sample"):
        ste.estimator("sample.h5")
    with pytest.raises(SceneError, match="volumes"):
        ste.estimator(lattice, volumes=np.ones(3))
    lonely = jaxbpm.Sample.from_arrays(np.array([[0, 0, 0], [1, 0, 0.0]]), 0.5, np.zeros((0, 2), int),
                                       bond_radius=0.1)
    with pytest.raises(SampleError, match="no bonds"):
        ste.estimator(lonely)


def test_linear_contacts_enter_with_their_own_stiffness():
    """contact_law="linear": each active contact's K^nm is the linear law's (k_n along n, k_s across, less the
    normal force's turn F_n / |d| across), not Hertz-Mindlin's."""
    from jaxbpm.physics.linear import LinearLaw, normal_stiffness

    s = jaxbpm.generate.lattice("sc", (3, 3, 3), R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})
    law = LinearLaw(emod=2e9, kratio=1.5)
    est = ste.estimator(s, UniaxialCompression(strain=0.002, contacts=True, contact_law=law))
    hertz = ste.estimator(s, UniaxialCompression(strain=0.002, contacts=True))
    nc = est.contacts
    assert nc > 0 and nc == hertz.contacts
    d = np.asarray(est.contact_d)[:nc]
    dist = np.linalg.norm(d, axis=1)
    n = d / dist[:, None]
    kn = float(normal_stiffness(R, R, 2e9))
    fn = kn * (2 * R - dist)
    across = np.eye(3)[None] - n[:, :, None] * n[:, None, :]
    expected = kn * n[:, :, None] * n[:, None, :] + (kn / 1.5 - fn / dist)[:, None, None] * across
    k = np.asarray(est.contact_k)[:nc].reshape(nc, 3, 3)
    np.testing.assert_allclose(k, expected, rtol=1e-9, atol=1e-9 * kn)
    assert not np.allclose(np.abs(np.asarray(hertz.contact_k)[:nc]), np.abs(k.reshape(nc, 9)), rtol=1e-3)
