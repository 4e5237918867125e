"""The closed form: bonds-only elasticity, stiffness linear in the bond moduli."""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import calibrate as cal
from jaxbpm.calibrate import CalibrationError, Parameter, ParameterSpace, Problem, Target
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression
from tests.calibrate._cases import SCENE, _modulus

# one xdist worker for the calibration tests: those that calibrate `one` and `two` share their compiled solves
pytestmark = pytest.mark.xdist_group("calibrate-module")


def test_closed_form_shortcut_is_used_and_says_so(two):
    p = default_params(two)
    target = _modulus(two, {**p, "bond_E": p["bond_E"] * 0.37})
    res = cal.calibrate(two, SCENE, {"youngs_modulus": target}, method="adam")
    assert res.method == "closed-form" and res.evaluations == 1
    assert any("linear" in n for n in res.notes) and any("shortcut" in n for n in res.notes)
    np.testing.assert_allclose(res.params["bond_E"], p["bond_E"] * 0.37, rtol=1e-6)


def test_closed_form_least_squares_on_two_scenes(two):
    """Two free components, two tests: the least squares on the linear responses recovers both."""
    scenes = {"z": SCENE, "x": UniaxialCompression(axis=0, strain=0.002)}
    true = {**default_params(two), "bond_E": jnp.array([1.3e9, 4.4e9])}
    targets = [Target("youngs_modulus", jaxbpm.solve(two, scenes[k], "dsm", params=true).youngs_modulus, scene=k)
               for k in scenes]
    start = [Parameter("bond_E", 0, initial=1.1e9), Parameter("bond_E", 1, initial=4.0e9)]
    res = cal.calibrate(two, scenes, targets, method="closed-form", parameters=start, verify=True)
    assert res.converged and res.info["verified"]
    np.testing.assert_allclose([res.values["bond_E[0]"], res.values["bond_E[1]"]], [1.3e9, 4.4e9], rtol=1e-3)


def test_closed_form_errors(one):
    p = default_params(one)
    two_free = ParameterSpace([Parameter("bond_E", 0)], {**p, "bond_E": jnp.array([1e9, 1e9])})
    with pytest.raises(CalibrationError, match="held fixed"):
        cal.closed_form(Problem(cal.forward_model(one, SCENE, "dsm"), [Target("stiffness", 1.0)], two_free))


def test_an_unreachable_target_names_the_bound_and_the_closest_value(one):
    """``calibrate`` with a target far out of the bond modulus range: not converged, and the result says which
    parameter sits at which bound and the closest modulus reached (a DSM solve at that bound gives the same)."""
    p = default_params(one)
    for target, side in ((1e15, "upper"), (1e2, "lower")):
        res = cal.calibrate(one, SCENE, {"youngs_modulus": target}, method="closed-form")
        assert not res.converged
        (entry,) = res.info["unreachable"]
        ((name, pinned_side, bound),) = entry["pinned"]
        assert pinned_side == side and res.values[name] == bound and entry["target"] == "youngs_modulus"
        np.testing.assert_allclose(entry["closest"],
                                   _modulus(one, {**p, "bond_E": jnp.full_like(p["bond_E"], bound)}), rtol=1e-6)
        assert any(f"at its {side} bound" in n for n in res.notes) and "out of reach" in res.table()
    # 1e30 Pa: the modulus reached is lost to rounding against the target; the bound is still named
    res = cal.calibrate(one, SCENE, {"youngs_modulus": 1e30}, method="closed-form")
    assert "at its upper bound" in res.info["unreachable"][0]["message"]
