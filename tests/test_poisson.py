"""Lateral strain and Poisson's ratio of the uniaxial scene: DEM, DSM and STE."""

import numpy as np
import pytest

import jaxbpm
from jaxbpm.physics.model import default_params

R = 1e-3
pytestmark = pytest.mark.xdist_group("poisson")


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
    assert jaxbpm.result.Result("dem", 1.0, 1.0, 1.0, 1.0, np.zeros(2), np.zeros(2), 0.0, 0.0, 0.0).poisson_ratio is None
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
