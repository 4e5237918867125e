"""The problem: weights, errors and the objective (Qu et al. 2020, Eq. 3), the solve count, and its checks."""

import numpy as np
import pytest

from jaxbpm.calibrate import CalibrationError, Parameter, ParameterSpace, Problem, Target
from jaxbpm.physics.model import default_params
from tests.calibrate._cases import _analytic_problem

pytestmark = pytest.mark.xdist_group("calibrate-module")


def test_the_objective_by_hand():
    """E = 3 bond_E[0] and K = 6 bond_E[1] + 0.01 bond_E[0] at bond_E = (1, 1): y = (3, 6.01)."""
    pb = _analytic_problem([Target("youngs_modulus", 30.0), Target("stiffness", 12.0, weight=3.0)], n=2)
    np.testing.assert_allclose(pb.weights, [0.25, 0.75], rtol=1e-15)
    y = pb.outputs([[1.0, 1.0]])
    np.testing.assert_allclose(y, [[3.0, 6.01]], rtol=1e-12)
    e = pb.errors_of(y[0])
    np.testing.assert_allclose(e, [(3 - 30) / 30, (6.01 - 12) / 12], rtol=1e-12)
    np.testing.assert_allclose(pb.loss_of(e), 0.25 * e[0] ** 2 + 0.75 * e[1] ** 2, rtol=1e-12)
    np.testing.assert_allclose(pb.max_errors(e), np.abs(e), rtol=1e-15)
    assert pb.signed_errors(e) == {"youngs_modulus": float(e[0]), "stiffness": float(e[1])}
    assert pb.evaluations == 1 and pb.outputs([[1.0, 1.0]]).shape == (1, 2) and pb.evaluations == 1  # repeated
    pb.outputs([[1.0, 1.0], [2.0, 1.0], [1.0, 2.0]])  # one batch of three sets
    assert pb.evaluations == 4
    loss, g, y1 = pb.value_and_grad(np.zeros(2))
    np.testing.assert_allclose(loss, pb.loss_of(e), rtol=1e-12)
    assert g.shape == (2,) and np.all(g < 0)  # both outputs are below their targets: raising either helps


def test_problem_errors(one, dsm_forward):
    space = ParameterSpace([Parameter("bond_E")], default_params(one))
    with pytest.raises(CalibrationError, match="does not report 'strength'"):
        Problem(dsm_forward, [Target("strength", 1e6)], space).outputs([[1e9]])
    with pytest.raises(CalibrationError, match="scene 'x'"):
        Problem(dsm_forward, [Target("stiffness", 1.0, scene="x")], space)


def test_chunk_is_a_deprecated_name_of_batch_size():
    pb = _analytic_problem([Target("youngs_modulus", 30.0), Target("stiffness", 12.0)], n=2)
    X = [[1.0, 1.0], [2.0, 1.0], [1.0, 2.0], [3.0, 0.5], [0.5, 3.0]]
    new = pb.outputs(X, batch_size=2)
    np.testing.assert_allclose(new, pb.outputs(X), rtol=1e-14)  # batches of two: the answer of one batch
    with pytest.warns(DeprecationWarning, match="batch_size="):
        old = pb.outputs(X, chunk=2)
    np.testing.assert_array_equal(old, new)
    with pytest.raises(TypeError, match="batch_size= only"):
        pb.outputs(X, batch_size=2, chunk=2)
    with pytest.raises(CalibrationError, match="batch_size must be"):
        pb.outputs(X, batch_size=0)
