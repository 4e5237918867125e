"""jaxbpm's exceptions (:mod:`jaxbpm.errors`): the hierarchy callers catch, and what the errors carry."""

import pytest

import jaxbpm
from jaxbpm import errors


def test_the_hierarchy():
    assert issubclass(errors.OptionsError, errors.SceneError) and issubclass(errors.OptionsError, ValueError)
    assert jaxbpm.OptionsError is errors.OptionsError
    for cls in (errors.SampleError, errors.SampleFileError, errors.SceneError, errors.SolveError):
        assert issubclass(cls, errors.JaxbpmError)
    for cls in (errors.InstabilityError, errors.ConvergenceError, errors.NotFiniteError):
        assert issubclass(cls, errors.SolveError) and issubclass(cls, RuntimeError)
    assert issubclass(errors.SimulationInterrupted, KeyboardInterrupt)


def test_a_solve_error_carries_its_result():
    assert errors.ConvergenceError("stopped").result is None
    err = errors.NotFiniteError("nan", result="the result")
    assert err.result == "the result" and str(err) == "nan"


def test_an_interruption_says_how_far_the_run_got():
    stop = errors.SimulationInterrupted("state", {"time": []}, {"steps": 40, "steps_planned": 100})
    assert "after 40 of 100 steps" in str(stop) and stop.state == "state" and stop.result is None
    with pytest.raises(KeyboardInterrupt):
        raise stop
