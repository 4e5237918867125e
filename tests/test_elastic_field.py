"""The DSM's elastic state for the DEM's elastic start: the DSM's own field, and the first-break scale the closed
form of the separate failure rule gives on it."""

import dataclasses

import numpy as np
import pytest

import jaxbpm
from jaxbpm.elastic_field import dsm_field
from jaxbpm.physics import bond as bond_mod, rotation
from jaxbpm.physics.model import build_model, default_params
from jaxbpm.scenes import UniaxialCompression

ROCK = {"E": 1e9, "nu": 0.2, "tensile_strength": 4e6, "shear_strength": 8e6}


def test_the_field_is_the_dsm_and_the_first_break_its_weakest_bond():
    s = jaxbpm.generate.cylinder(200, seed=3, materials=ROCK).largest_cluster()
    scene = UniaxialCompression.to_failure(strain=0.02, contacts=False)
    u, first, info = dsm_field(s, scene, None)
    assert info["dsm"] == "linear" and info["dsm_solves"] == 1
    dsm = jaxbpm.solve(s, dataclasses.replace(scene, breakage=False), "dsm")  # (its elastic range)
    np.testing.assert_allclose(u, np.asarray(dsm.state)[:s.n_particles], rtol=0, atol=1e-12 * np.abs(u).max())
    # the separate rule in closed form on the bond forces at the field: sigma_c / sigma and c / tau per bond
    model = build_model(s)
    x = np.asarray(s.positions) + first * u[:, :3]
    f = bond_mod.bond_forces(x, rotation.from_rotation_vector(first * u[:, 3:]), model.bonds, model.r0,
                             model.stiffness(default_params(s)))[2]
    area, r, inertia = (np.asarray(a) for a in (s.bond_area, s.bond_radius, s.bond_I))
    sigma = np.asarray(f.normal) / area + np.linalg.norm(np.asarray(f.bend), axis=1) * r / inertia
    tau = np.linalg.norm(np.asarray(f.shear), axis=1) / area + np.abs(np.asarray(f.twist)) * r / (2 * inertia)
    utilisation = np.maximum(sigma / 4e6, tau / 8e6)
    assert utilisation.max() == pytest.approx(1.0, rel=1e-6)  # at s*, the weakest bond is at its strength
    assert 0 < first < 1


def test_a_scene_where_no_bond_reaches_its_strength_gives_a_reason():
    s = jaxbpm.generate.lattice("sc", (2, 2, 4), 1e-3, materials={"E": 1e9, "nu": 0.25, "tensile_strength": 1e30,
                                                                  "shear_strength": 1e30})
    reason = dsm_field(s, UniaxialCompression(strain=0.002, breakage=True), None)
    assert isinstance(reason, str) and "no bond reaches its strength" in reason
