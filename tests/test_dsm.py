"""Direct stiffness method: closed forms, agreement with the DEM, gradients, linearity, failure reports."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import ConvergenceError, SceneError, dsm
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression

R = 1e-3
KN = 1e9 * np.pi * (0.5 * R) ** 2 / (2 * R)


@pytest.fixture(scope="module")
def column():
    return jaxbpm.generate.lattice("sc", (3, 3, 6), R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})


@pytest.fixture(scope="module")
def packing():
    s = jaxbpm.generate.box(200, seed=3, mean_radius=R, packing_fraction=0.5)
    return s.largest_cluster()


@pytest.mark.parametrize("dofs", [3, 6])
def test_simple_cubic_lattice_is_exact(column, dofs):
    res = jaxbpm.solve(column, UniaxialCompression(strain=0.002), method="dsm", dofs=dofs)
    assert res.stats["converged"] and res.stats["dofs"] == dofs
    np.testing.assert_allclose(res.stiffness, 9 * KN / 5, rtol=1e-6)
    np.testing.assert_allclose(res.youngs_modulus, KN / (2 * R), rtol=1e-6)


def test_dsm_matches_dem_bonds_only(packing):
    scene = UniaxialCompression(strain=0.002)
    a = jaxbpm.solve(packing, scene, method="dsm")
    b = jaxbpm.solve(packing, scene, method="dem")
    assert abs(a.stiffness / b.stiffness - 1) < 1e-2, (a.stiffness, b.stiffness)


@pytest.mark.parametrize("scene", [UniaxialCompression(strain=0.002, contacts=True),
                                   UniaxialCompression(strain=0.002, boundary="walls"),
                                   UniaxialCompression(strain=0.002, boundary="walls", contacts=True)],
                         ids=["contacts", "walls", "contacts+walls"])
def test_nonlinear_dsm_matches_dem(packing, scene):
    a = jaxbpm.solve(packing, scene, method="dsm")
    b = jaxbpm.solve(packing, scene, method="dem")
    assert a.stats["converged"] and a.stats["nonlinear"]
    assert abs(a.stiffness / b.stiffness - 1) < 6e-2, (a.stiffness, b.stiffness)


def test_gradient_matches_central_differences():
    s = jaxbpm.generate.lattice("fcc", (2, 2, 3), R, bond_radius_ratio=0.5, materials={"E": [1e9, 2e9], "nu": 0.3})
    s = jaxbpm.generate.mix_materials(s, [0.4, 0.6], seed=1)
    f = jax.jit(dsm.stiffness_function(s, UniaxialCompression(strain=0.002)))
    p = default_params(s)
    g = jax.grad(f)(p)["bond_E"]
    for c in range(2):
        h = 1e-4 * p["bond_E"][c]
        up = {**p, "bond_E": p["bond_E"].at[c].add(h)}
        dn = {**p, "bond_E": p["bond_E"].at[c].add(-h)}
        fd = (f(up) - f(dn)) / (2 * h)
        np.testing.assert_allclose(g[c], fd, rtol=1e-5)
    assert float(g[0]) > 0 and float(g[1]) > 0
    # vmap over parameter sets: K is linear in a common factor on E
    batch = {"bond_E": p["bond_E"][None, :] * jnp.array([[1.0], [2.0], [3.0]]),
             "bond_nu": jnp.broadcast_to(p["bond_nu"], (3, 2))}
    ks = jax.vmap(f)(batch)
    np.testing.assert_allclose(ks, f(p) * np.array([1.0, 2.0, 3.0]), rtol=1e-9)


def test_stiffness_is_linear_in_common_E(packing):
    scene = UniaxialCompression(strain=0.002)
    a = jaxbpm.solve(packing, scene, method="dsm")
    p = default_params(packing)
    b = jaxbpm.solve(packing, scene, method="dsm", params={**p, "bond_E": 3.0 * p["bond_E"]})
    np.testing.assert_allclose(b.stiffness, 3.0 * a.stiffness, rtol=1e-9)


def test_three_load_cases_share_one_operator(column):
    k = dsm.load_cases(column, UniaxialCompression(strain=0.002), np.eye(3))
    np.testing.assert_allclose(k[2, 2], 9 * KN / 5, rtol=1e-6)  # pulling the top layer up takes an upward force
    assert abs(k[0, 0]) > 0 and abs(k[0, 0] - k[1, 1]) < 1e-6 * abs(k[0, 0])  # shear x and y alike by symmetry
    np.testing.assert_allclose(k - np.diag(np.diag(k)), 0.0, atol=1e-9 * abs(k[2, 2]))


def test_non_convergence_is_reported(packing):
    scene = UniaxialCompression(strain=0.002, contacts=True)
    with pytest.warns(UserWarning, match="did not converge"):
        res = jaxbpm.solve(packing, scene, method="dsm", newton_maxiter=1, tol=1e-12)
    assert res.stats["converged"] is False and res.stats["residual"] > 1e-12
    with pytest.raises(ConvergenceError, match="relative residual"):
        jaxbpm.solve(packing, scene, method="dsm", newton_maxiter=1, tol=1e-12, throw=True)


def test_floating_cluster_is_reported(column):
    pos = np.concatenate([np.asarray(column.positions), [[0.1, 0.1, 0.005], [0.1, 0.1 + 2 * R, 0.005]]])
    n = column.n_particles
    bonds = np.concatenate([np.asarray(column.bonds), [[n, n + 1]]])
    s = jaxbpm.Sample.from_arrays(pos, R, bonds, bond_radius_ratio=0.5)
    with pytest.raises(SceneError, match=r"singular: 2 particles .*floating.*\[%d, %d\]" % (n, n + 1)):
        jaxbpm.solve(s, UniaxialCompression(strain=0.002), method="dsm")


def test_walls_need_the_nonlinear_solver(column):
    with pytest.raises(SceneError, match="nonlinear"):
        jaxbpm.solve(column, UniaxialCompression(boundary="walls"), method="dsm", nonlinear=False)
