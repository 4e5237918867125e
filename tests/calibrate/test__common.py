"""The calibrators' shared helpers: ties between parameters and targets, checks, renamed keywords."""

import warnings

import jax.numpy as jnp
import pytest

import jaxbpm.calibrate._common as common
from jaxbpm.calibrate import CalibrationError, Forward, Parameter, ParameterSpace, Problem, Target


def _problem(targets, n):
    fwd = Forward.from_function(lambda p: {"youngs_modulus": 3 * p["bond_E"][0], "stiffness": p["bond_E"][1]})
    base = {"bond_E": jnp.array([1.0, 1.0]), "bond_nu": jnp.array([0.3, 0.3])}
    return Problem(fwd, targets, ParameterSpace([Parameter("bond_E", i) for i in range(n)], base))


def test_ties_name_one_scalar_target_per_parameter():
    one = _problem([Target("youngs_modulus", 30.0)], 1)
    assert common.resolve_tie(one, None) == [0]  # the only parameter to the only target
    assert common.same_units(one, [0])  # bond E and Young's modulus: Pa
    two = _problem([Target("youngs_modulus", 30.0), Target("stiffness", 2.0)], 2)
    assert common.resolve_tie(two, None) is None
    assert common.resolve_tie(two, {"bond_E[0]": "stiffness", "bond_E[1]": "youngs_modulus"}) == [1, 0]
    assert not common.same_units(two, [1, 0])  # bond E tied to a stiffness [N/m]
    with pytest.raises(CalibrationError, match="missing"):
        common.resolve_tie(two, {"bond_E[0]": "stiffness"})
    with pytest.raises(CalibrationError, match="unknown target"):
        common.resolve_tie(two, {"bond_E[0]": "strength", "bond_E[1]": "stiffness"})


def test_checks_and_renamed_keywords():
    assert common.check_tol(0.05) == 0.05 and common.check_count("n", 3, 2) == 3
    for bad in (0, 1, 1.5, "5 %"):
        with pytest.raises(CalibrationError, match="tol"):
            common.check_tol(bad)
    with pytest.raises(CalibrationError, match="whole number >= 2"):
        common.check_count("n_runs", True, 2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert common.renamed_keyword("dsm", None, new="solver", old="model") == "dsm"  # no warning
    with pytest.warns(DeprecationWarning, match="model= is deprecated.*use solver="):
        assert common.renamed_keyword("dsm", "ste", new="solver", old="model") == "ste"
