"""The STE on a scene (:mod:`jaxbpm.ste.scene`): against the DSM, gradients, walls and layers in series, contacts, a
stiffness that is not finite.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import ste
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression
from tests.ste.conftest import D, R


def test_ste_matches_dsm_bonds_only(packing, plain):
    # the default (3 DOF per particle, the scene's clamped layers followed) and the paper's form (boundary="free")
    # against the DSM of the same model (3 DOF) on a random packing: within 5 % (measured +0.6 % and -4.3 %)
    a = plain
    b = jaxbpm.solve(packing, UniaxialCompression(strain=0.002), method="dsm", dofs=3)
    assert a.method == "ste" and a.compile_time > 0 and a.run_time > 0
    assert a.stats["boundary"] == "clamped" and a.stats["clamped"] > 0
    assert abs(a.stiffness / b.stiffness - 1) < 0.05, (a.stiffness, b.stiffness)
    np.testing.assert_allclose(a.youngs_modulus, a.stats["E_z"], rtol=1e-12)  # K = E A / l
    free = jaxbpm.solve(packing, UniaxialCompression(strain=0.002), method="ste", boundary="free")
    assert free.stats["boundary"] == "free" and free.stats["clamped"] == 0
    assert abs(free.stiffness / b.stiffness - 1) < 0.05, (free.stiffness, b.stiffness)


def test_clamped_particles_as_masks_give_the_layers_stiffness(packing, plain):
    # a random packing's default layers passed as fixed/driven masks (with the layers' gauge length and area): the
    # same clamped particles, the same K to round-off
    scene = UniaxialCompression(strain=0.002)
    fixed, driven = scene.layers(packing)
    length, area = scene.geometry(packing)
    masks = UniaxialCompression(strain=0.002, fixed=fixed, driven=driven, gauge_length=length, area=area)
    res = jaxbpm.solve(packing, masks, method="ste")
    assert 0 < res.stats["clamped"] == plain.stats["clamped"] <= int(np.sum(fixed | driven))  # singular ones apart
    np.testing.assert_allclose(res.stiffness, plain.stiffness, rtol=1e-12)


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


def test_walls_in_series(packing):
    k = 1e5  # soft linear walls: 1/K = 1/K_body + 1/(n_bottom k) + 1/(n_top k)
    walls = UniaxialCompression(strain=0.002, boundary="walls", wall_law="linear", wall_stiffness=k)
    soft = jaxbpm.solve(packing, walls, method="ste")
    st = soft.stats
    # walls clamp no particle: the free form runs, and asking for it by name is the same setup (nothing built)
    assert st["boundary"] == "free" and st["clamped"] == 0
    built = ste.scene._setups.builds
    with jaxbpm.count_compilations() as c:
        free = jaxbpm.solve(packing, walls, method="ste", boundary="free")
    assert ste.scene._setups.builds == built and c.count == 0 and free.stiffness == soft.stiffness
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
    # the paper's form, every particle averaged, layers two rows thick (measured -15 %)
    opts = dict(surface_depth=0.0, first_neighbour=True, boundary="free")
    layered = jaxbpm.solve(soft, scene, method="ste", layered=True, layer_thickness=2 * D, **opts)
    plain = jaxbpm.solve(soft, scene, method="ste", **opts)
    assert abs(layered.stiffness / exact - 1) < 0.2, (layered.stiffness, exact)
    assert plain.stiffness > 3 * exact
    # the default form: the clamped end rows are out of the averages, so layers one row thick (measured -8 %)
    layered = jaxbpm.solve(soft, scene, method="ste", layered=True, layer_thickness=D, first_neighbour=True)
    assert abs(layered.stiffness / exact - 1) < 0.2, (layered.stiffness, exact)


def test_contacts_add_stiffness(packing, plain):
    scene = UniaxialCompression(strain=0.002, contacts=True)
    with_c = jaxbpm.solve(packing, scene, method="ste")
    without = plain
    assert with_c.stats["contacts"] > 0 and with_c.stiffness > without.stiffness


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
