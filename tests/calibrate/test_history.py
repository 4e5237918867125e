"""A calibration's result: its history saved to HDF5, read back and plotted."""

import numpy as np
import pytest

from jaxbpm import calibrate as cal
from jaxbpm.calibrate import Target
from tests.calibrate._cases import _analytic_problem

# one xdist worker for the calibration tests: those that calibrate `one` and `two` share their compiled solves
pytestmark = pytest.mark.xdist_group("calibrate-module")


def test_history_saved_and_plotted(tmp_path):
    pb = _analytic_problem([Target("youngs_modulus", 30.0)])
    res = cal.adam(pb, gradient="fd-central", tol=1e-3, max_iterations=6, first_estimate=False,
                   second_estimate=False, learning_rate=0.3)
    path = res.save(tmp_path / "history.h5")
    h = cal.load_history(path)
    assert len(h) == len(res.history) == 6
    np.testing.assert_allclose(h.column("loss"), res.history.column("loss"))
    assert list(h.column("evaluations")) == [3 * i for i in range(1, 6)] + [16]
    assert np.all(h.column("time") >= 0)
    res.plot(tmp_path / "history.png")
    assert (tmp_path / "history.png").stat().st_size > 1000
