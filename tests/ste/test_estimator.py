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
