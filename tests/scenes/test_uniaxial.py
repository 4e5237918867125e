"""The uniaxial compression scene: geometry, boundary conditions, walls in series, bad input, and the lateral strain
and Poisson ratio it measures (DEM, DSM and STE)."""

import numpy as np
import pytest

import jaxbpm
from jaxbpm import SceneError
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression

R = 1e-3
# one worker for the whole module under pytest-xdist (loadgroup): its specimens (module fixtures) are built once
pytestmark = pytest.mark.xdist_group("uniaxial")


@pytest.fixture(scope="module")
def column():
    return jaxbpm.generate.lattice("sc", (2, 2, 6), R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})


def test_layers_and_geometry(column):
    scene = UniaxialCompression()
    fixed, driven = scene.layers(column)
    z = np.asarray(column.positions)[:, 2]
    np.testing.assert_array_equal(fixed, z == z.min())
    np.testing.assert_array_equal(driven, z == z.max())
    length, area = scene.geometry(column)
    np.testing.assert_allclose(length, 5 * 2 * R)
    np.testing.assert_allclose(area, (4 * R) ** 2)
    length, area = UniaxialCompression(gauge_length=1.0, area=2.0).geometry(column)
    assert (length, area) == (1.0, 2.0)


def test_linear_walls_act_as_springs_in_series(column):
    """Two linear walls of stiffness k_w per particle in series with the column: 1/K = 1/K_col + 2/(4 k_w)."""
    kn = 1e9 * np.pi * (0.5 * R) ** 2 / (2 * R)
    k_w = 2.0 * kn
    scene = UniaxialCompression(strain=0.002, boundary="walls", wall_law="linear", wall_stiffness=k_w)
    res = jaxbpm.solve(column, scene)
    k_col = 4 * kn / 5  # four chains of five bonds in series
    expected = 1.0 / (1.0 / k_col + 2.0 / (4 * k_w))
    np.testing.assert_allclose(res.stiffness, expected, rtol=1e-2)
    np.testing.assert_allclose(res.gauge_length, 12 * R)  # wall gap


def test_explicit_masks_reproduce_layers(column):
    fixed, driven = UniaxialCompression().layers(column)
    a = jaxbpm.solve(column, UniaxialCompression(strain=0.002))
    b = jaxbpm.solve(column, UniaxialCompression(strain=0.002, fixed=fixed, driven=driven))
    np.testing.assert_allclose(a.stiffness, b.stiffness, rtol=1e-12)


def test_compression_along_x_matches_z():
    s = jaxbpm.generate.lattice("sc", (6, 2, 2), R, bond_radius_ratio=0.5)
    t = jaxbpm.generate.lattice("sc", (2, 2, 6), R, bond_radius_ratio=0.5)
    ref = jaxbpm.solve(t, UniaxialCompression(axis=2, strain=0.002))
    same = dict(dt=ref.stats["dt"], loading_time=ref.stats["loading_time"])  # identical protocol
    ez = jaxbpm.solve(t, UniaxialCompression(axis=2, strain=0.002), **same).youngs_modulus
    ex = jaxbpm.solve(s, UniaxialCompression(axis=0, strain=0.002), **same).youngs_modulus
    np.testing.assert_allclose(ex, ez, rtol=1e-9)


@pytest.mark.parametrize("kw, message", [
    (dict(axis=3), "axis must be the whole number 0, 1 or 2"),
    (dict(axis=2.0), r"axis must be the whole number 0, 1 or 2, got 2\.0"),
    (dict(axis=True), "axis must be the whole number 0, 1 or 2, got True"),
    (dict(strain=0.0), "strain must lie in"),
    (dict(boundary="plates"), "boundary must be"),
    (dict(fixed=np.ones(3, bool)), "give both fixed and driven"),
    (dict(fit_range=(0.5, 0.2)), "fit_range"),
])
def test_bad_scene_arguments(kw, message):
    with pytest.raises(SceneError, match=message):
        UniaxialCompression(**kw)


def test_bad_masks(column):
    n = column.n_particles
    with pytest.raises(SceneError, match=r"fixed mask must have shape"):
        UniaxialCompression(fixed=np.ones(3, bool), driven=np.ones(3, bool)).layers(column)
    both = np.zeros(n, bool)
    both[0] = True
    with pytest.raises(SceneError, match="both fixed and driven"):
        UniaxialCompression(fixed=both, driven=both).layers(column)
    with pytest.raises(SceneError, match="at least one particle"):
        UniaxialCompression(fixed=np.zeros(n, bool), driven=both).layers(column)


def test_bad_time_step(column):
    with pytest.raises(SceneError, match="dt must be a positive"):
        jaxbpm.solve(column, UniaxialCompression(), dt=-1.0)
    with pytest.raises(ValueError, match="unknown method"):
        jaxbpm.solve(column, UniaxialCompression(), method="fem")


def test_simple_cubic_lattice_has_no_lateral_strain():
    # central and shear springs on a simple-cubic lattice: C_12 = 0, so a uniaxial load strains nothing sideways
    s = jaxbpm.generate.lattice("sc", (3, 3, 8), R, materials={"E": 1e9, "nu": 0.25})
    scene = jaxbpm.scenes.UniaxialCompression(strain=1e-3)
    dsm = jaxbpm.solve(s, scene, method="dsm")
    assert abs(dsm.poisson_ratio) < 1e-12
    np.testing.assert_allclose(dsm.stats["axial_strain"], -1e-3, rtol=1e-9)  # the middle third strains uniformly
    assert abs(jaxbpm.solve(s, scene, method="ste").poisson_ratio) < 1e-12


@pytest.fixture(scope="module")
def cylinder():
    return jaxbpm.generate.cylinder(600, seed=1, mean_radius=R, materials={"E": 1e9, "nu": 0.25}).largest_cluster()


def test_dem_and_dsm_agree_and_follow_the_bond_ratio(cylinder):
    """The DEM's loaded state and the DSM's static solution give the same Poisson ratio (they solve one model);
    a softer bond shear (higher bond nu, k_t / k_n = 1 / (2 (1 + nu))) lets the sample bulge more."""
    scene = jaxbpm.scenes.UniaxialCompression(strain=1e-3)
    dsm = jaxbpm.solve(cylinder, scene, method="dsm")
    dem = jaxbpm.solve(cylinder, scene, method="dem")
    assert 0.05 < dsm.poisson_ratio < 0.45
    assert abs(dem.poisson_ratio / dsm.poisson_ratio - 1) < 0.02, (dem.poisson_ratio, dsm.poisson_ratio)
    # lateral strains: both positive (the sample bulges under compression), the axial one negative
    assert dsm.stats["axial_strain"] < 0 and min(dsm.stats["lateral_strains"]) > 0
    p = default_params(cylinder)
    nus = [jaxbpm.solve(cylinder, scene, method="dsm", params={**p, "bond_nu": np.array([v])}).poisson_ratio
           for v in (0.05, 0.25, 0.45)]
    assert nus[0] < nus[1] < nus[2], nus
    # the STE reports one from its tensor, in the same range
    ste = jaxbpm.solve(cylinder, scene, method="ste")
    assert 0.5 * dsm.poisson_ratio < ste.poisson_ratio < 1.5 * dsm.poisson_ratio


def test_scale_free_in_the_bond_modulus_and_errors(cylinder):
    scene = jaxbpm.scenes.UniaxialCompression(strain=1e-3)
    p = default_params(cylinder)
    a = jaxbpm.solve(cylinder, scene, method="dsm")
    b = jaxbpm.solve(cylinder, scene, method="dsm", params={**p, "bond_E": 3 * p["bond_E"]})
    np.testing.assert_allclose(b.poisson_ratio, a.poisson_ratio, rtol=1e-6)
    # a result without the measurement says None; a sample too short for a middle third is an error
    empty = jaxbpm.result.Result("dem", 1.0, 1.0, 1.0, 1.0, np.zeros(2), np.zeros(2), 0.0, 0.0, 0.0)
    assert empty.poisson_ratio is None
    with pytest.raises(jaxbpm.SceneError, match="middle third"):
        scene.lateral_strain(jaxbpm.generate.lattice("sc", (1, 1, 2), R), np.zeros((2, 3)))


def test_calibrate_E_and_nu_together(cylinder):
    """E and nu within 1 % in at most 4 DSM solves, and the DEM at the answer agrees within 2 %."""
    from jaxbpm.calibrate import calibrate_elastic

    scene = jaxbpm.scenes.UniaxialCompression(strain=1e-3)
    now = jaxbpm.solve(cylinder, scene, method="dsm")
    E_t, nu_t = 1.7 * now.youngs_modulus, 0.8 * now.poisson_ratio
    res = calibrate_elastic(cylinder, scene, E=E_t, nu=nu_t, tol=0.01, check="dem")
    assert res.converged and res.evaluations <= 4, (res.evaluations, res.errors)
    assert max(abs(v) for v in res.errors.values()) <= 0.01
    assert res.info["check"]["max_error"] < 0.02, res.info["check"]
    # a lower target nu needs a lower bond nu (the macroscopic one rises with it)
    assert res.values["bond_nu"] < float(cylinder.materials.nu[0])
    # out of reach: the range the sample spans is named
    with pytest.raises(jaxbpm.calibrate.CalibrationError, match="out of this sample's reach"):
        calibrate_elastic(cylinder, scene, nu=0.3, max_solves=8)
