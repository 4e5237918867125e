"""``calibrate``: the default multi-fidelity route with a check, the solver keyword and its old name, errors."""

import numpy as np
import pytest

from jaxbpm import calibrate as cal
from jaxbpm.calibrate import CalibrationError
from tests.calibrate._cases import SCENE, SOLVE, _modulus

# one xdist worker for the calibration tests: those that calibrate `one` and `two` share their compiled solves
pytestmark = pytest.mark.xdist_group("calibrate-module")


def test_auto_is_the_default_and_checks(one):
    target = 0.8 * _modulus(one, None)
    res = cal.calibrate(one, SCENE, {"youngs_modulus": target}, tol=0.01, check="dsm")
    assert res.method == "multi-fidelity" and res.converged
    assert res.levels[0]["solver"] == ("ste" if "ste" in SOLVE.METHODS else "dsm")
    assert res.info["check"]["max_error"] < 0.01


def test_model_keyword_still_works_with_a_deprecation_warning(one):
    """``model=`` is the old name of ``solver=``: it warns, naming ``solver=``, and gives the same answer."""
    target = 1.3 * _modulus(one, None)
    kw = dict(method="adam", shortcut=False, gradient="autodiff", tol=0.01, max_iterations=4)
    new = cal.calibrate(one, SCENE, {"youngs_modulus": target}, solver="dsm", **kw)
    with pytest.warns(DeprecationWarning, match="solver="):
        old = cal.calibrate(one, SCENE, {"youngs_modulus": target}, model="dsm", **kw)
    assert old.solver == new.solver == "dsm"
    assert old.values == new.values and old.errors == new.errors
    np.testing.assert_array_equal(old.history.column("values"), new.history.column("values"))
    with pytest.warns(DeprecationWarning, match="CalibrationResult.solver"):
        assert old.model == "dsm"
    with pytest.warns(DeprecationWarning, match="solver="):
        fwd = cal.forward_model(one, SCENE, model="ste")
    assert fwd is cal.forward_model(one, SCENE, "ste") and fwd.name == "ste"


def test_calibrate_errors(one):
    with pytest.raises(CalibrationError, match="unknown calibration method"):
        cal.calibrate(one, SCENE, {"youngs_modulus": 1e8}, method="newton")
    with pytest.raises(CalibrationError, match="unknown solver"):
        cal.calibrate(one, SCENE, {"youngs_modulus": 1e8}, method="adam", solver="fem")
