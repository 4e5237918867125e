"""Run sets: a Latin hypercube of parameter sets solved in chunks, with a bar of the runs only when asked."""

import numpy as np
import pytest

import jaxbpm
from jaxbpm import calibrate as cal
from jaxbpm.scenes import UniaxialCompression

# one xdist worker for the calibration tests: those that calibrate `one` and `two` share their compiled solves
pytestmark = pytest.mark.xdist_group("calibrate-module")


def test_run_set_shows_a_progress_bar_only_when_asked(capsys):
    from jaxbpm.calibrate.runs import run_set

    s = jaxbpm.generate.lattice("sc", (3, 3, 4), 1e-3, materials={"E": 1e9, "nu": 0.25})
    problem = cal.Problem(cal.forward_model(s, UniaxialCompression(strain=0.002), solver="ste"),
                          [cal.Target("stiffness", 1.0)],
                          cal.ParameterSpace([cal.Parameter("bond_E", index=0)], cal.base_params(s)))
    quiet = run_set(problem, 6, chunk=4)
    assert capsys.readouterr().err == ""
    shown = run_set(problem, 6, chunk=4, progress=True)
    err = capsys.readouterr().err
    assert "run set" in err and "6/6" in err  # a bar of the runs, on stderr
    np.testing.assert_array_equal(shown.Y, quiet.Y)
