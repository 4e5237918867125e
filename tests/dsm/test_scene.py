"""The DSM on a scene (:mod:`jaxbpm.dsm.scene`): closed forms, agreement with the DEM, linearised contacts and their
reach, failure reports, options checked against the scene.
"""

import dataclasses
import warnings

import jax
import numpy as np
import pytest

import jaxbpm
from jaxbpm import ConvergenceError, dsm, SceneError
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression
from tests.dsm.conftest import KN, R, SHARED


@pytest.mark.parametrize("dofs", [3, 6])
def test_simple_cubic_lattice_is_exact(column, dofs):
    res = jaxbpm.solve(column, UniaxialCompression(strain=0.002), method="dsm", dofs=dofs)
    assert res.stats["converged"] and res.stats["dofs"] == dofs
    np.testing.assert_allclose(res.stiffness, 9 * KN / 5, rtol=1e-6)
    np.testing.assert_allclose(res.youngs_modulus, KN / (2 * R), rtol=1e-6)


def test_dsm_in_float32_agrees_with_float64(packing):
    # the bond-geometry split is exact up to rounding: float32's rounding must not be taken for a changed bond law
    scene = UniaxialCompression(strain=0.002)
    ref = jaxbpm.solve(packing, scene, method="dsm").stiffness
    with jax.enable_x64(False), warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the float32 warning
        res = jaxbpm.solve(packing, scene, method="dsm", tol=1e-5)
    assert res.stats["converged"]
    assert abs(res.stiffness / ref - 1) < 1e-3, (res.stiffness, ref)


def test_dsm_matches_dem_bonds_only(packing):
    scene = UniaxialCompression(strain=0.002)
    a = jaxbpm.solve(packing, scene, method="dsm")
    b = jaxbpm.solve(packing, scene, method="dem")
    assert abs(a.stiffness / b.stiffness - 1) < 1e-2, (a.stiffness, b.stiffness)


@pytest.mark.xdist_group(SHARED)
def test_linear_dsm_linearises_the_contacts(packing):
    # stiffer particles: the contacts carry ~20 % of the stiffness (the nonlinear DSM is the reference here: it
    # matches the DEM with contacts, test_nonlinear_dsm_matches_dem)
    s = packing.replace(particle_material=dataclasses.replace(packing.particle_material, E=5e9))
    scene = UniaxialCompression(strain=0.002, contacts=True)
    ref = jaxbpm.solve(s, scene, method="dsm")
    bonds = jaxbpm.solve(s, UniaxialCompression(strain=0.002), method="dsm")
    lin = jaxbpm.solve(s, scene, method="dsm", nonlinear=False)
    assert not lin.stats["nonlinear"] and lin.stats["contact_candidates"] > 0 and lin.stats["converged"]
    assert ref.stats["converged"]
    share = 1 - bonds.stiffness / ref.stiffness  # the contacts' share of the stiffness
    err = lin.stiffness / ref.stiffness - 1
    assert share > 0.1 and abs(err) < share / 3, (share, err)
    # Hertz: a later linearisation point (a larger overlap) is stiffer
    late = jaxbpm.solve(s, scene, method="dsm", nonlinear=False, contact_fraction=1.0)
    assert late.stiffness > lin.stiffness
    with pytest.raises(SceneError, match="contact_passes"):
        jaxbpm.solve(s, scene, method="dsm", nonlinear=False, contact_passes=0)
    # the candidates of the linear solve reach only as far as the strain can close a gap (0.01 mean radii here):
    # the pairs left out never touch, so a wider reach gives the same answer (3x: more candidates, the same size
    # class, so the same compiled solve; test_linearised_contacts_widen_a_short_default_reach reaches half a radius)
    r = float(np.mean(s.radii))
    wide = jaxbpm.solve(s, scene, method="dsm", nonlinear=False, contact_skin=3.0 * lin.stats["contact_skin"])
    assert lin.stats["contact_candidates"] < wide.stats["contact_candidates"]
    assert lin.stats["contacts_touching"] == wide.stats["contacts_touching"] > 0
    assert lin.stats["contact_gap_max"] < 0.5 * lin.stats["contact_skin"] < 0.01 * r
    np.testing.assert_allclose(lin.stiffness, wide.stiffness, rtol=1e-9)
    # a reach that misses touching pairs is reported
    with pytest.warns(UserWarning, match="contact_skin"):
        jaxbpm.solve(s, scene, method="dsm", nonlinear=False, contact_skin=0.9 * lin.stats["contact_gap_max"])


@pytest.mark.xdist_group(SHARED)
def test_linearised_contacts_widen_a_short_default_reach(packing, monkeypatch):
    s = packing.replace(particle_material=dataclasses.replace(packing.particle_material, E=5e9))
    scene = UniaxialCompression(strain=0.002, contacts=True)
    wide = jaxbpm.solve(s, scene, method="dsm", nonlinear=False, contact_skin=0.5 * float(np.mean(s.radii)))
    # a default reach of one affine approach (a quarter of the default): touching pairs lie near it, so it doubles
    # until they do not
    monkeypatch.setattr(dsm.scene, "LINEAR_REACH", 1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        short = jaxbpm.solve(s, scene, method="dsm", nonlinear=False)
    assert short.stats["contact_skin_retries"] >= 1
    assert short.stats["contact_gap_max"] < 0.5 * short.stats["contact_skin"]
    assert short.stats["contacts_touching"] == wide.stats["contacts_touching"]
    np.testing.assert_allclose(short.stiffness, wide.stiffness, rtol=1e-9)


def test_stiffness_is_linear_in_common_E(packing):
    scene = UniaxialCompression(strain=0.002)
    a = jaxbpm.solve(packing, scene, method="dsm")
    p = default_params(packing)
    b = jaxbpm.solve(packing, scene, method="dsm", params={**p, "bond_E": 3.0 * p["bond_E"]})
    np.testing.assert_allclose(b.stiffness, 3.0 * a.stiffness, rtol=1e-9)


@pytest.mark.xdist_group(SHARED)
def test_non_convergence_is_reported(packing):
    scene = UniaxialCompression(strain=0.002, contacts=True)
    # failure as data: the status, no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = jaxbpm.solve(packing, scene, method="dsm", newton_maxiter=1, tol=1e-12, throw=False)
    assert res.status == "max_iterations" and not res.ok and "relative residual" in res.stats["failure"]
    assert res.stats["converged"] is False and res.stats["residual"] > 1e-12
    # throw=True is the default: the error carries the result
    with pytest.raises(ConvergenceError, match="relative residual") as err:
        jaxbpm.solve(packing, scene, jaxbpm.DSM(newton_maxiter=1, tol=1e-12))
    assert err.value.result.status == "max_iterations" and err.value.result.stiffness == res.stiffness
    # the linear solve too, with an iteration budget too small for its tolerance
    lin = jaxbpm.solve(packing, UniaxialCompression(strain=0.002), "dsm", maxiter=2, stiffness_tol=None, throw=False)
    assert lin.status == "max_iterations" and lin.stats["iterations"] == 2
    with pytest.raises(ConvergenceError):
        jaxbpm.solve(packing, UniaxialCompression(strain=0.002), "dsm", maxiter=2, stiffness_tol=None)
    ok = jaxbpm.solve(packing, UniaxialCompression(strain=0.002), "dsm")
    assert ok.status == "converged" and ok.ok


def test_walls_need_the_nonlinear_solver(column):
    with pytest.raises(SceneError, match="nonlinear"):
        jaxbpm.solve(column, UniaxialCompression(boundary="walls"), method="dsm", nonlinear=False)


def test_bad_solver_options_are_named(packing):
    scene = UniaxialCompression(strain=0.002)
    with pytest.raises(ValueError, match="preconditioner"):
        jaxbpm.solve(packing, scene, method="dsm", preconditioner="ilu")
    with pytest.raises(ValueError, match="operator"):
        jaxbpm.solve(packing, scene, method="dsm", operator="dense")
    model = UniaxialCompression(contacts=True).model(packing, contacts=True)
    with pytest.raises(SceneError, match="bonds only"):
        dsm.tangent_operator(model, default_params(packing), operator="jacobians")
