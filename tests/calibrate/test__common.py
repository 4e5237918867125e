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


def test_a_target_out_of_the_parameter_range_is_reported():
    """A target of 1e30 Pa ended ``converged=False`` with the parameter at its bound and no word about it."""
    import numpy as np

    from jaxbpm.calibrate.history import History

    fwd = Forward.from_function(lambda p: {"youngs_modulus": 3 * p["bond_E"][0]})
    space = ParameterSpace([Parameter("bond_E", 0, bounds=(0.1, 10.0))], {"bond_E": jnp.array([1.0])})

    def result(target, value):
        problem = Problem(fwd, [Target("youngs_modulus", target)], space)
        e = problem.errors_of(np.asarray(problem.outputs(np.array([[value]]))[0]))
        return common.make_result(problem, History(space.names, problem.target_names), [value], e, method="x",
                                  tol=0.01, wall_time=0.0, evaluations=1)

    for target, bound, side in ((1e30, 10.0, "upper"), (1e-30, 0.1, "lower")):
        res = result(target, bound)
        assert not res.converged
        (entry,) = res.info["unreachable"]
        assert entry["target"] == "youngs_modulus" and entry["value"] == target
        assert entry["pinned"] == [(space.names[0], side, bound)]
        np.testing.assert_allclose(entry["closest"], 3 * bound, rtol=1e-6)  # the model's value at the bound
        assert any(f"out of reach of the parameter range: {space.names[0]} at its {side} bound" in n
                   for n in res.notes)
    assert "unreachable" not in result(1e30, 5.0).info  # not at a bound: short of iterations, not of range
    # the answer not solved (a predicted error): the value reached from the error, unless rounding lost it
    problem = Problem(fwd, [Target("youngs_modulus", 100.0)], space)
    res = common.make_result(problem, History(space.names, problem.target_names), [10.0], [-0.7], method="x",
                             tol=0.01, wall_time=0.0, evaluations=0)
    np.testing.assert_allclose(res.info["unreachable"][0]["closest"], 30.0, rtol=1e-12)
    problem = Problem(fwd, [Target("youngs_modulus", 1e30)], space)
    res = common.make_result(problem, History(space.names, problem.target_names), [10.0], [-1.0], method="x",
                             tol=0.01, wall_time=0.0, evaluations=0)
    assert res.info["unreachable"][0]["closest"] is None and "under 1e-09 of the target" in res.notes[-1]
    assert "unreachable" not in result(30.0, 10.0).info  # at the bound, but the target is met
