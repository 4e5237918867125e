"""One status for every solver (:mod:`jaxbpm.status`): values, messages, error classes."""

import pickle

import pytest

from jaxbpm import errors
from jaxbpm.status import Status


def test_the_members_are_the_strings_results_always_had():
    assert [s.value for s in Status] == ["converged", "max_iterations", "unstable", "interrupted", "not_finite",
                                         "not_quasi_static"]
    for s in Status:
        assert s == s.value and isinstance(s, str) and str(s) == s.value and f"{s}" == s.value
        assert repr(s) == repr(s.value) and hash(s) == hash(s.value)
        assert Status(s.value) is s and pickle.loads(pickle.dumps(s)) is s
        assert isinstance(s.message, str) and len(s.message) > 10


def test_each_failure_carries_the_error_throw_raises():
    assert Status.CONVERGED.error is None and Status.INTERRUPTED.error is None  # the DEM raises its interruption
    assert Status.MAX_ITERATIONS.error is errors.ConvergenceError
    assert Status.UNSTABLE.error is errors.InstabilityError
    assert Status.NOT_FINITE.error is errors.NotFiniteError
    assert Status.NOT_QUASI_STATIC.error is errors.NotQuasiStaticError
    assert all(issubclass(s.error, errors.SolveError) for s in Status if s.error is not None)


def test_only_converged_is_ok():
    assert [s for s in Status if s.ok] == [Status.CONVERGED]
    with pytest.raises(ValueError):
        Status("diverged")


def test_the_module_walkthrough_runs():
    import doctest

    from jaxbpm import status

    assert doctest.testmod(status).failed == 0
