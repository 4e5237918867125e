"""Forwards built from solvers and the parameter pytree of a sample and a scene."""

import pytest

import jaxbpm
from jaxbpm import calibrate as cal
from jaxbpm.calibrate import CalibrationError
from jaxbpm.scenes import UniaxialCompression
from tests.calibrate._cases import SCENE

# one xdist worker for the calibration tests: those that calibrate `one` and `two` share their compiled solves
pytestmark = pytest.mark.xdist_group("calibrate-module")


def test_base_params_reads_particle_and_cohesive_entries():
    s = jaxbpm.generate.lattice("sc", (2, 2, 2), 1e-3, particle_material={"E": 3e8, "friction": 0.3})
    law = {"c0": 2e4, "kc": 0.25, "c_max": 6e4}
    scene = UniaxialCompression(strain=0.01, contacts=True, contact_law="cohesive", cohesive=law)
    base = cal.base_params(s, ["contact_E", "friction", "cohesion_initial", "cohesion_max"], scene)
    assert float(base["contact_E"]) == 3e8 and float(base["friction"]) == 0.3
    assert float(base["cohesion_initial"]) == 2e4 and float(base["cohesion_max"]) == 6e4
    with pytest.raises(CalibrationError, match="cohesive contact law"):
        cal.base_params(s, ["cohesion_max"], UniaxialCompression(strain=0.01))
    with pytest.raises(CalibrationError, match="no parameter entry 'bond_colour'"):
        cal.base_params(s, ["bond_colour"])


def test_base_params_reads_the_linear_contact_law():
    from jaxbpm.physics.linear import LinearLaw

    s = jaxbpm.generate.lattice("sc", (2, 2, 2), 1e-3, particle_material={"E": 3e8, "nu": 0.2})
    scene = UniaxialCompression(strain=0.01, contacts=True, contact_law=LinearLaw(emod=2e9, kratio=1.21))
    base = cal.base_params(s, ["contact_emod", "contact_kratio"], {"a": UniaxialCompression(), "b": scene})
    assert float(base["contact_emod"]) == 2e9 and float(base["contact_kratio"]) == 1.21
    plain = cal.base_params(s, ["contact_emod", "contact_kratio"])  # the law's defaults for the particle material
    assert float(plain["contact_emod"]) == 3e8 and float(plain["contact_kratio"]) == (2 - 0.2) / (2 * (1 - 0.2))


def test_forward_model_is_cached_and_checks_its_arguments(one):
    fwd = cal.forward_model(one, SCENE, "dsm")
    assert fwd is cal.forward_model(one, SCENE, "dsm") and fwd.name == "dsm" and fwd.scenes == ("main",)
    assert fwd.homogeneous and fwd.pure is not None  # bonds only: linear in the bond moduli, a pure stiffness
    assert cal.forward_model(one, SCENE, "ste") is not fwd
    with pytest.raises(CalibrationError, match="unknown solver 'fem'"):
        cal.forward_model(one, SCENE, "fem")
    with pytest.raises(CalibrationError, match="no scene given"):
        cal.forward_model(one, {}, "dsm")
    with pytest.raises(CalibrationError, match="one sample per scene"):
        cal.forward_model({"a": one}, {"b": SCENE}, "dsm")
