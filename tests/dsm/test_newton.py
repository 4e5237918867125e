"""The nonlinear DSM (:mod:`jaxbpm.dsm.newton`): Newton over load steps against the DEM, with and without slip."""

import dataclasses

import numpy as np
import pytest

import jaxbpm
from jaxbpm.scenes import UniaxialCompression
from tests.dsm.conftest import R, SHARED


@pytest.mark.parametrize("scene", [
    # (with contacts alone: the nonlinear solve of the linearised-contacts tests, compiled once on one worker)
    pytest.param(UniaxialCompression(strain=0.002, contacts=True), marks=pytest.mark.xdist_group(SHARED)),
    UniaxialCompression(strain=0.002, boundary="walls"),
    UniaxialCompression(strain=0.002, boundary="walls", contacts=True)], ids=["contacts", "walls", "contacts+walls"])
def test_nonlinear_dsm_matches_dem(packing, scene):
    a = jaxbpm.solve(packing, scene, method="dsm")
    b = jaxbpm.solve(packing, scene, method="dem")
    assert a.stats["converged"] and a.stats["nonlinear"]
    assert abs(a.stiffness / b.stiffness - 1) < 6e-2, (a.stiffness, b.stiffness)


@pytest.mark.xdist_group(SHARED)
def test_sliding_contacts_match_the_dem_where_no_slip_does_not(packing):
    # stiff particles, soft bonds: contacts carry the load and most of them slide in the DEM (friction 0.5)
    s = jaxbpm.generate.box(200, seed=3, mean_radius=R, packing_fraction=0.5, materials={"E": 1e8, "nu": 0.25},
                            particle_material={"E": 1e10, "nu": 0.25, "density": 2500.0, "friction": 0.5,
                                               "restitution": 0.5}).largest_cluster()
    scene = UniaxialCompression(strain=0.005, contacts=True)
    dem = jaxbpm.solve(s, scene, method="dem")
    slip = jaxbpm.solve(s, scene, method="dsm")
    stick = jaxbpm.solve(s, scene, method="dsm", slip=False, throw=False)
    assert stick.status == "max_iterations"  # Newton stalls without slip here (a known limit)
    assert slip.stats["slip"] and not stick.stats["slip"]
    err_slip, err_stick = slip.stiffness / dem.stiffness - 1, stick.stiffness / dem.stiffness - 1
    assert abs(err_slip) < 0.03 and err_stick > 0.1, (err_slip, err_stick)
    # with a friction no contact reaches, the two are the same law (on a sample where both converge tightly)
    scene = UniaxialCompression(strain=0.002, contacts=True)
    rough = packing.replace(particle_material=dataclasses.replace(packing.particle_material, friction=1e3))
    a = jaxbpm.solve(rough, scene, method="dsm", tol=1e-6)
    b = jaxbpm.solve(packing, scene, method="dsm", slip=False, tol=1e-6)
    assert a.stats["converged"] and b.stats["converged"]
    np.testing.assert_allclose(a.stiffness, b.stiffness, rtol=1e-5)


@pytest.mark.xdist_group(SHARED)
@pytest.mark.filterwarnings("ignore:linear contacts:UserWarning")  # the packing overlaps at rest
def test_linear_contacts_dsm_matches_dem(packing):
    """PFC's linear contacts: the DSM (the same law, static) against the DEM on a packing whose contacts carry most
    of the stiffness (half of its bonded pairs overlap slightly at rest: a linear contact is stiff from first touch)."""
    scene = UniaxialCompression(strain=0.002, contacts=True, contact_law="linear")
    a = jaxbpm.solve(packing, scene, method="dsm")
    b = jaxbpm.solve(packing, scene, method="dem")
    bonds = jaxbpm.solve(packing, UniaxialCompression(strain=0.002), method="dsm")
    assert a.stats["converged"] and a.stats["nonlinear"]
    share = 1 - bonds.stiffness / a.stiffness  # the contacts' share
    assert share > 0.5, share
    assert abs(a.stiffness / b.stiffness - 1) < 0.01, (a.stiffness, b.stiffness)
