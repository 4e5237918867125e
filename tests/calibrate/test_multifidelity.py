"""Multi-fidelity calibration: early acceptance at a dearer level, escalation where the cheap answer is off."""

import numpy as np
import pytest

from jaxbpm import calibrate as cal
from jaxbpm.calibrate import Forward, ParameterSpace
from jaxbpm.physics.model import default_params
from tests.calibrate._cases import SCENE, SOLVE, _modulus

# one xdist worker for the calibration tests: those that calibrate `one` and `two` share their compiled solves
pytestmark = pytest.mark.xdist_group("calibrate-module")


def _biased(sample, factor):
    """A deliberately biased low-fidelity model: the DSM stiffness times ``factor``."""
    from jaxbpm import dsm

    f = dsm.stiffness_function(sample, SCENE)
    length, area = SCENE.geometry(sample)

    def pure(params):
        k = f(params) * factor
        return {"main": {"stiffness": k, "youngs_modulus": k * length / area}}

    def evaluate(params):
        return {"main": {k: np.asarray(v) for k, v in pure(params)["main"].items()}}

    return Forward(name=f"biased-{factor:g}", evaluate=evaluate, pure=pure, homogeneous=True)


def test_multifidelity_stops_early_and_escalates(one):
    target = 1.3 * _modulus(one, None)
    if "ste" in SOLVE.METHODS:
        low = cal.forward_model(one, SCENE, "ste")
        p = default_params(one)
        diff = abs(float(low.pure(p)["main"]["youngs_modulus"]) / _modulus(one, p) - 1)
    else:
        low, diff = _biased(one, 1.08), 0.08
    if diff < 2e-3:  # the cheap model is too close to the DSM here to show an escalation
        low, diff = _biased(one, 1.08), 0.08
    space = ParameterSpace(cal.default_parameters(one), default_params(one))
    # tolerance wider than the gap: the DSM check accepts the cheap answer (one DSM solve)
    early = cal.multifidelity(one, SCENE, {"youngs_modulus": target}, space, levels=(low, "dsm"), tol=2 * diff)
    assert [lv["action"] for lv in early.levels] == ["calibrated", "accepted"]
    assert early.levels[1]["evaluations"] == 1 and early.solver == "dsm"
    assert abs(early.errors["youngs_modulus"]) <= 2 * diff
    # tolerance narrower than the gap: DSM is calibrated from the cheap answer
    esc = cal.multifidelity(one, SCENE, {"youngs_modulus": target}, space, levels=(low, "dsm"), tol=diff / 4)
    assert [lv["action"] for lv in esc.levels] == ["calibrated", "escalated"]
    assert esc.converged and esc.levels[1]["evaluations"] >= 1
    assert abs(_modulus(one, esc.params) / target - 1) < diff / 4
    assert esc.evaluations == sum(lv["evaluations"] for lv in esc.levels)
