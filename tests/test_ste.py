"""Stiffness tensor estimation: lattice closed forms, symmetries, isotropy, agreement with the DSM, gradients."""

import h5py
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import SampleError, SceneError, ste
from jaxbpm.physics import blocks
from jaxbpm.physics.bond import BondStiffness
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression

R = 1e-3
D = 2 * R  # bond length of the lattices


@pytest.fixture(scope="module")
def lattice():
    return jaxbpm.generate.lattice("sc", (5, 5, 5), R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})


@pytest.fixture(scope="module")
def packing():
    s = jaxbpm.generate.box(1000, seed=3, mean_radius=R, packing_fraction=0.58, materials={"E": 1e9, "nu": 0.25})
    return s.largest_cluster()


@pytest.fixture(scope="module")
def plain(packing):
    return jaxbpm.solve(packing, UniaxialCompression(strain=0.002), method="ste")


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
    # the affine field is the exact solution: the DSM gives the closed form to round-off, and so does the STE when
    # the clamped end layers follow the affine field (clamp_layers; default, first-neighbour, 6 DOF and layered forms)
    s, scene, exact, kn = _clamped_lattice((4, 4, 8))
    dsm = jaxbpm.solve(s, scene, method="dsm")
    np.testing.assert_allclose(dsm.stiffness, exact, rtol=1e-12)
    res = jaxbpm.solve(s, scene, method="ste", clamp_layers=True)
    np.testing.assert_allclose(res.stiffness, exact, rtol=1e-9)  # measured 1e-16
    assert res.stats["clamped"] == 32 and res.stats["surface"] == 104 and res.stats["skipped"] == 0
    np.testing.assert_allclose(res.stats["E_z"], kn / D, rtol=1e-9)
    for opts in ({"first_neighbour": True}, {"dofs": 6}, {"layered": True}):
        np.testing.assert_allclose(jaxbpm.solve(s, scene, method="ste", clamp_layers=True, **opts).stiffness,
                                   exact, rtol=1e-9)
    # without clamp_layers (the paper's form) the end layers relax: 1 - 5 / (13 (n_z - 2)) (see below)
    np.testing.assert_allclose(jaxbpm.solve(s, scene, method="ste").stiffness / exact, 1 - 5 / 78, rtol=1e-12)
    # every included particle has the interior tensor's C_33 = k_n / d (C_13 = C_23 = 0)
    est = ste.estimator(s, scene, clamp_layers=True)
    c = np.asarray(jax.jit(ste.local_tensors)(est, default_params(s)))[np.asarray(est.include)]
    np.testing.assert_allclose(c[:, 2, 2], kn / D, rtol=1e-12)
    np.testing.assert_allclose(c[:, :2, 2], 0.0, atol=1e-12 * kn / D)


def test_paper_form_on_the_clamped_lattice():
    # what the other forms give where the affine field is exact (docs/ste.md tabulates them)
    s, scene, exact, kn = _clamped_lattice((4, 4, 8))
    p = default_params(s)
    # every particle averaged: the clamped layers count with whole cells, but the gauge length runs between their
    # centres: (n_z - 1) / n_z; half a cell for them (their part inside the gauge length) makes it exact
    every = jaxbpm.solve(s, scene, method="ste", surface_depth=0.0, clamp_layers=True)
    np.testing.assert_allclose(every.stiffness / exact, 7 / 8, rtol=1e-12)
    fixed, driven = scene.layers(s)
    half = np.where(fixed | driven, 0.5, 1.0) * D**3
    np.testing.assert_allclose(jaxbpm.solve(s, scene, method="ste", surface_depth=0.0, volumes=half,
                                            clamp_layers=True).stiffness, exact, rtol=1e-9)

    def unclamped(**opts):  # nothing clamped (no scene): the end layers relax as one-sided surface particles
        est = ste.estimator(s, **opts)
        return float(ste.scene_stiffness(est, p, s, scene)[0]) / exact

    # the default: the layer next to each end inherits the end's relaxation through Eq. 29 and K Gamma^m
    # and loses 5/26 of its C_33 (k_t = 0.4 k_n); two layers of n_z - 2 averaged: 1 - 5 / (13 (n_z - 2))
    np.testing.assert_allclose(unclamped(), 1 - 5 / 78, rtol=1e-12)
    # the paper's form (nothing clamped, every particle averaged): both effects, -27.1 % here (-10.3 % on 10x10x20)
    assert abs(unclamped(surface_depth=0.0) - (1 - 0.2708)) < 1e-3


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
    res = plain
    e = np.array([res.stats[k] for k in ("E_x", "E_y", "E_z")])
    assert e.max() / e.min() - 1 < 0.05, e
    assert abs(res.stats["E_iso"] / e.mean() - 1) < 0.05
    assert 0.0 < res.stats["nu_iso"] < 0.5
    assert res.stats["skipped"] < 0.05 * packing.n_particles and res.stats["surface"] > 0
    assert res.stats["clamped"] == 0  # the end layers relax (clamp_layers=False)


def test_ste_matches_dsm_bonds_only(packing, plain):
    # the paper's form (3 DOF per particle) against the DSM of the same model
    a = plain
    b = jaxbpm.solve(packing, UniaxialCompression(strain=0.002), method="dsm", dofs=3)
    assert a.method == "ste" and a.compile_time > 0 and a.run_time > 0
    assert abs(a.stiffness / b.stiffness - 1) < 0.10, (a.stiffness, b.stiffness)
    np.testing.assert_allclose(a.youngs_modulus, a.stats["E_z"], rtol=1e-12)  # K = E A / l


def test_gradient_matches_finite_differences_and_vmap(lattice):
    s = jaxbpm.generate.mix_materials(lattice, [0.4, 0.6], seed=1, materials={"E": [1e9, 2e9], "nu": 0.3})
    f = ste.stiffness_function(s, UniaxialCompression(strain=0.002))
    p = default_params(s)
    g = jax.jit(jax.grad(f))(p)
    # every evaluation in one vmapped call: central differences in E (per material) and nu, and a scaled batch
    h = 1e-4 * p["bond_E"]
    hn = 1e-5
    E0 = p["bond_E"][None, :]
    E = jnp.concatenate([E0 + jnp.diag(h), E0 - jnp.diag(h), jnp.tile(p["bond_E"], (2, 1)),
                         E0 * jnp.array([[1.0], [2.0], [3.0]])])
    nu = jnp.concatenate([jnp.tile(p["bond_nu"], (4, 1)), p["bond_nu"][None, :] + jnp.array([[hn], [-hn]]),
                          jnp.tile(p["bond_nu"], (3, 1))])
    k = np.asarray(jax.jit(jax.vmap(f))({"bond_E": E, "bond_nu": nu}))
    for c in range(2):
        np.testing.assert_allclose(g["bond_E"][c], (k[c] - k[2 + c]) / (2 * h[c]), rtol=1e-6)
        assert float(g["bond_E"][c]) > 0
    np.testing.assert_allclose(jnp.sum(g["bond_nu"]), (k[4] - k[5]) / (2 * hn), rtol=1e-5)
    np.testing.assert_allclose(k[6:], k[6] * np.array([1.0, 2.0, 3.0]), rtol=1e-10)


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
def test_pair_sums_over_chunks_equal_one_pass(packing, monkeypatch, first_neighbour):
    # large samples fold the pair sums over chunks of pairs (padding weighed zero): the same tensor and gradient as
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
    assert pairs > 2 * 97 and pairs % blocks.block_length(pairs) != 0  # several chunks, the last padded
    folded, g_folded = jax.jit(lambda e, q: tensor_and_grad(e, q))(est, p)  # a new function: traced again
    np.testing.assert_allclose(folded, one, rtol=0, atol=1e-12 * float(jnp.abs(one).max()))
    for name in ("bond_E", "bond_nu"):
        np.testing.assert_allclose(g_folded[name], g_one[name], rtol=1e-10)


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


def test_walls_in_series(packing):
    k = 1e5  # soft linear walls: 1/K = 1/K_body + 1/(n_bottom k) + 1/(n_top k)
    soft = jaxbpm.solve(packing, UniaxialCompression(strain=0.002, boundary="walls", wall_law="linear",
                                                     wall_stiffness=k), method="ste")
    st = soft.stats
    expected = 1.0 / (1.0 / st["K_body"] + 1.0 / (st["n_bottom"] * k) + 1.0 / (st["n_top"] * k))
    np.testing.assert_allclose(soft.stiffness, expected, rtol=1e-12)
    assert st["n_bottom"] > 0 and st["n_top"] > 0
    est = ste.estimator(packing, UniaxialCompression(boundary="walls"))
    k_hertz, parts = ste.wall_series(1e6, est, UniaxialCompression(boundary="walls"), packing)
    assert 0 < float(k_hertz) < 1e6 and float(parts["k_bottom"]) > 0


def test_layers_see_a_soft_layer(lattice):
    # a band 100x softer across the load axis: the columns of the lattice are springs in series, two stiff bonds
    # and two soft ones each (closed form); the layered model sees it, a homogeneous average does not
    soft = jaxbpm.generate.materials_by_region(
        lattice, lambda x: (np.abs(x[:, 2] - 4 * R) < 2.5 * R).astype(int), materials={"E": [1e9, 1e7], "nu": 0.25})
    kn = float(ste.estimator(lattice).model.stiffness(default_params(lattice)).kn[0])
    exact = 25 * kn / (2 + 2 * 100)
    scene = UniaxialCompression(strain=0.002)
    opts = dict(surface_depth=0.0, first_neighbour=True)
    layered = jaxbpm.solve(soft, scene, method="ste", layered=True, layer_thickness=2 * D, **opts)
    plain = jaxbpm.solve(soft, scene, method="ste", **opts)
    assert abs(layered.stiffness / exact - 1) < 0.2, (layered.stiffness, exact)
    assert plain.stiffness > 3 * exact


def test_contacts_add_stiffness(packing, plain):
    scene = UniaxialCompression(strain=0.002, contacts=True)
    with_c = jaxbpm.solve(packing, scene, method="ste")
    without = plain
    assert with_c.stats["contacts"] > 0 and with_c.stiffness > without.stiffness


def test_local_map_files(packing, tmp_path):
    lm = ste.local_map(packing)
    assert lm.E.shape == (packing.n_particles, 3) and np.isfinite(lm.E).mean() > 0.95
    np.testing.assert_allclose(np.nanmean(lm.deviation, axis=0), 0.0, atol=1e-12)
    assert np.nanmax(np.abs(lm.deviation)) < 1.0
    path = jaxbpm.io.save_local_map(tmp_path / "map.h5", lm)
    with h5py.File(path) as f:
        np.testing.assert_array_equal(f["E"][...], lm.E)
        assert f.attrs["format"] == "jaxbpm-ste-map"
    import meshio

    mesh = meshio.read(jaxbpm.io.export_local_map_vtk(tmp_path / "map.vtu", packing, lm))
    np.testing.assert_allclose(mesh.point_data["deviation"], lm.deviation)
    png = jaxbpm.io.plot_local_map(tmp_path / "map.png", lm)
    assert png.stat().st_size > 1000
    # the old names (jaxbpm.ste) still work for a release, with a deprecation warning
    with pytest.warns(DeprecationWarning, match="jaxbpm.io.save_local_map"):
        assert ste.save_local_map is jaxbpm.io.save_local_map
    with pytest.raises(AttributeError, match="no_such_thing"):
        ste.no_such_thing


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


def test_a_stiffness_that_is_not_finite_is_a_status_or_an_error(lattice):
    from jaxbpm.result import Result, settle

    good = jaxbpm.solve(lattice, UniaxialCompression(strain=0.002), "ste")
    assert good.status == "converged" and good.ok

    def nan_result():
        return Result(method="ste", stiffness=float("nan"), youngs_modulus=float("nan"), gauge_length=1.0, area=1.0,
                      displacement=np.zeros(2), force=np.zeros(2), wall_time=0.0, compile_time=0.0, run_time=0.0)

    res = settle(nan_result(), throw=False)
    assert res.status == "not_finite" and not res.ok and "nu" in res.stats["failure"]
    with pytest.raises(jaxbpm.NotFiniteError, match="not_finite") as err:
        settle(nan_result(), throw=True)
    assert err.value.result.status == "not_finite" and isinstance(err.value, jaxbpm.SolveError)
