"""Targets and the parameter space: the optimisation variable in log and target-scaled form, and the checks."""

import jax.numpy as jnp
import numpy as np
import pytest

from jaxbpm.calibrate import CalibrationError, Parameter, ParameterSpace, Target
from jaxbpm.physics.model import default_params

# one xdist worker for the calibration tests: those that calibrate `one` and `two` share their compiled solves
pytestmark = pytest.mark.xdist_group("calibrate-module")


def test_target_and_space_errors(one):
    p = default_params(one)
    with pytest.raises(CalibrationError, match="must be > 0"):
        Target("youngs_modulus", -1.0)
    with pytest.raises(CalibrationError, match="finite"):
        Target("stiffness", float("nan"))
    with pytest.raises(CalibrationError, match="needs 'at'"):
        Target("stress", [1.0, 2.0])
    with pytest.raises(CalibrationError, match="weight"):
        Target("stiffness", 1.0, weight=0)
    with pytest.raises(CalibrationError, match="out of range"):
        ParameterSpace([Parameter("bond_E", 3)], p)
    with pytest.raises(CalibrationError, match="outside its bounds"):
        ParameterSpace([Parameter("bond_E", 0, bounds=(1.0, 2.0))], p)
    with pytest.raises(CalibrationError, match="no entry"):
        ParameterSpace([Parameter("friction")], p)
    with pytest.raises(CalibrationError, match="both set"):
        ParameterSpace([Parameter("bond_E"), Parameter("bond_E", 0)], p)


def test_the_optimisation_variable_in_log_and_target_scaled_form():
    """Qu et al. 2020, Eq. 10-11: ``z = log(v / v0)`` in log form, ``z = v / scale`` in target-scaled form; default
    bounds two decades either side of the initial value; ``to_params`` writes a common factor through ``ratio``."""
    base = {"bond_E": jnp.array([2.0, 8.0]), "bond_nu": jnp.array([0.25, 0.25])}
    log = ParameterSpace([Parameter("bond_E", index=None, ratio=(1.0, 4.0))], base)
    assert log.names == ["bond_E"] and log.initial.tolist() == [2.0]
    assert log.lower.tolist() == [0.02] and log.upper.tolist() == [200.0]
    v = np.array([5.0])
    np.testing.assert_allclose(log.to_z(v), [np.log(2.5)], rtol=1e-15)
    np.testing.assert_allclose(log.from_z(log.to_z(v)), v, rtol=1e-15)
    np.testing.assert_allclose(log.to_params(v)["bond_E"], [5.0, 20.0], rtol=1e-15)
    assert log.clip([1e6]).tolist() == [200.0]
    scaled = ParameterSpace([Parameter("bond_E", 1), Parameter("bond_nu", 0, bounds=(0.0, 0.4))], base,
                            scaling="target", scales=[4.0, 0.1])
    np.testing.assert_allclose(scaled.to_z(np.array([6.0, 0.3])), [1.5, 3.0], rtol=1e-15)
    out = scaled.to_params(np.array([6.0, 0.3]))
    np.testing.assert_allclose(out["bond_E"], [2.0, 6.0])
    np.testing.assert_allclose(out["bond_nu"], [0.3, 0.25])
    assert scaled.describe([6.0, 0.3]) == {"bond_E[1]": 6.0, "bond_nu[0]": 0.3}
    with pytest.raises(CalibrationError, match="log form needs positive bounds"):
        ParameterSpace([Parameter("bond_nu", 0, bounds=(0.0, 0.4))], base)
