"""Forwards: a function or a solve as the map from parameters to observables, and its runs as tasks."""

import jax.numpy as jnp
import numpy as np
import pytest

from jaxbpm.calibrate import CalibrationError, Forward
from jaxbpm.calibrate.forward import _checked
from jaxbpm.status import Status

pytestmark = pytest.mark.xdist_group("calibrate-module")


def _fn(params):
    e = params["bond_E"]
    return {"youngs_modulus": 3 * e[0], "stiffness": 2 * e[1] + 0.01 * e[0]}


def test_a_function_becomes_a_forward():
    params = {"bond_E": jnp.array([2.0, 5.0])}
    pure = Forward.from_function(_fn, name="analytic")
    out = pure.evaluate(params)
    assert list(out) == ["main"] and isinstance(out["main"]["stiffness"], np.ndarray)
    np.testing.assert_allclose([out["main"]["youngs_modulus"], out["main"]["stiffness"]], [6.0, 10.02], rtol=1e-15)
    traced = pure.pure(params)["main"]
    np.testing.assert_allclose([traced["youngs_modulus"], traced["stiffness"]], [6.0, 10.02], rtol=1e-15)
    assert pure.tasks(params) == []  # a jitted function stays in this process
    plain = Forward.from_function(_fn, pure=False)
    assert plain.pure is None
    ((scene, task),) = plain.tasks({"bond_E": np.array([2.0, 5.0])})
    assert scene == "main"
    np.testing.assert_allclose(task.fn(*task.args)["stiffness"], 10.02, rtol=1e-15)  # what a worker runs
    with pytest.raises(CalibrationError, match="must be callable"):
        Forward.from_function(3.0)


class _Result:
    method, stats = "dsm", {"failure": "the CG stopped at its iteration budget"}

    def __init__(self, status):
        self.status = status


def test_a_solve_that_did_not_converge_is_an_error():
    for status in (Status.CONVERGED, "converged"):  # a Status, or its string
        ok = _Result(status)
        assert _checked(ok, "main", {"bond_E": np.array([1e9])}) is ok
    for status in (Status.MAX_ITERATIONS, "max_iterations"):
        with pytest.raises(CalibrationError, match="DSM solve of scene 'main' at .* status 'max_iterations': the CG"):
            _checked(_Result(status), "main", {"bond_E": np.array([1e9])})
