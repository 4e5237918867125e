"""The objective's pieces: the parameter pytree of a sample and a scene, and the problem's checks."""

import pytest

import jaxbpm
from jaxbpm import calibrate as cal
from jaxbpm.calibrate import CalibrationError, Parameter, ParameterSpace, Problem, Target
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression

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


def test_problem_errors(one, dsm_forward):
    space = ParameterSpace([Parameter("bond_E")], default_params(one))
    with pytest.raises(CalibrationError, match="does not report 'strength'"):
        Problem(dsm_forward, [Target("strength", 1e6)], space).outputs([[1e9]])
    with pytest.raises(CalibrationError, match="scene 'x'"):
        Problem(dsm_forward, [Target("stiffness", 1.0, scene="x")], space)
