"""Young's modulus and Poisson's ratio together: the bond modulus in closed form, the bond Poisson ratio by secant."""

import numpy as np
import pytest

from jaxbpm import calibrate as cal
from jaxbpm.calibrate import CalibrationError
from jaxbpm.calibrate.elastic import _NU_BOUNDS, _next_bond_nu
from tests.calibrate._cases import SCENE, _modulus

pytestmark = pytest.mark.xdist_group("calibrate-module")


def test_youngs_modulus_alone_in_one_or_two_solves(one):
    """Bonds only: E is proportional to the bond modulus, so the second solve (at most) is exact; the answer is
    checked by an independent solve."""
    target = 1.7 * _modulus(one, None)
    res = cal.calibrate_elastic(one, SCENE, E=target, tol=1e-6)
    assert res.converged and res.method == "elastic" and res.solver == "dsm" and res.evaluations <= 2
    assert abs(_modulus(one, res.params) / target - 1) < 1e-6
    np.testing.assert_allclose(res.values["bond_E"], 1.7 * float(one.materials.E[0]), rtol=1e-6)
    with pytest.warns(DeprecationWarning, match="solver="):
        old = cal.calibrate_elastic(one, SCENE, E=target, tol=1e-6, model="dsm")
    assert old.values == res.values


def test_the_bond_poisson_ratio_steps_by_secant():
    # the first step from the typical slope 0.1: 0.25 + (0.12 - 0.10) / 0.1
    assert _next_bond_nu([(0.25, 0.10)], 0.12) == pytest.approx(0.45, rel=1e-12)
    # then the secant through the last two points: slope (0.11 - 0.10) / (0.35 - 0.25) = 0.1 -> 0.35 + 0.01 / 0.1
    assert _next_bond_nu([(0.25, 0.10), (0.35, 0.11)], 0.12) == pytest.approx(0.45, rel=1e-12)
    # kept in the material range
    assert _next_bond_nu([(0.25, 0.10)], 0.30) == _NU_BOUNDS[1]
    with pytest.raises(CalibrationError, match="out of this sample's reach"):
        _next_bond_nu([(0.25, 0.10), (_NU_BOUNDS[1], 0.15)], 0.30)


def test_elastic_errors(one):
    with pytest.raises(CalibrationError, match="give a Young's modulus E"):
        cal.calibrate_elastic(one, SCENE)
    with pytest.raises(CalibrationError, match="nu must be a Poisson ratio"):
        cal.calibrate_elastic(one, SCENE, nu=0.7)
