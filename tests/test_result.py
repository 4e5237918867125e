"""What a solve returns (:mod:`jaxbpm.result`): the timings of :func:`timed_result`, the status that
:func:`settle` gives, the loading curve's accessors."""

import time

import numpy as np
import pytest

from jaxbpm.errors import ConvergenceError, NotFiniteError
from jaxbpm.result import Result, settle, STATUSES, timed_result, Timings
from jaxbpm.status import Status


def _result(t0, **kw):
    args = dict(stiffness=2.0, gauge_length=0.5, area=0.25, displacement=np.array([0.0, 1e-3]),
                force=np.array([0.0, 2e-3]), compile_time=0.25)
    return timed_result("dsm", t0, **{**args, **kw})


def test_the_times_add_up_to_the_wall_time():
    t0 = time.perf_counter() - 2.0  # a solve that started two seconds ago
    given_setup = _result(t0, setup_time=0.5)
    assert 2.0 <= given_setup.wall_time < 3.0 and given_setup.setup_time == 0.5
    assert given_setup.run_time == pytest.approx(given_setup.wall_time - 0.75, abs=1e-12)
    given_run = _result(t0, run_time=1.0)
    assert given_run.run_time == 1.0
    assert given_run.setup_time == pytest.approx(given_run.wall_time - 1.25, abs=1e-12)
    # all the time in compiling and running: no negative setup
    assert _result(time.perf_counter(), run_time=10.0).setup_time == 0.0
    with pytest.raises(ValueError, match="setup_time or run_time"):
        _result(t0, setup_time=0.5, run_time=1.0)


def test_given_timings_and_their_shares():
    """A result of timings measured already (a batch member's share of the batch's): taken as they are."""
    t = Timings(wall_time=4.0, setup_time=1.0, compile_time=2.0, run_time=1.0)
    assert t.share(4) == Timings(wall_time=1.0, setup_time=0.25, compile_time=0.5, run_time=0.25)
    r = timed_result("dem", timings=t.share(2), stiffness=2.0, gauge_length=0.5, area=0.25,
                     displacement=np.array([0.0, 1e-3]), force=np.array([0.0, 2e-3]), youngs_modulus=3.0)
    assert (r.wall_time, r.setup_time, r.compile_time, r.run_time) == (2.0, 0.5, 1.0, 0.5)
    assert r.youngs_modulus == 3.0 and r.method == "dem"
    measured = Timings.since(time.perf_counter() - 2.0, 0.25, setup_time=0.5)
    assert measured.run_time == pytest.approx(measured.wall_time - 0.75, abs=1e-12) and measured.wall_time >= 2.0
    with pytest.raises(ValueError, match="not both"):
        _result(time.perf_counter(), setup_time=0.5, timings=t)
    with pytest.raises(ValueError, match="t0 and compile_time, or the timings"):
        timed_result("dem", stiffness=2.0, gauge_length=0.5, area=0.25, displacement=np.zeros(1), force=np.zeros(1))


def test_the_modulus_defaults_to_k_l_over_a():
    r = _result(time.perf_counter(), setup_time=0.0)
    assert r.youngs_modulus == 2.0 * 0.5 / 0.25 and r.method == "dsm" and r.stats == {}
    assert r.status is Status.CONVERGED and r.ok
    np.testing.assert_allclose(r.strain, [0.0, 2e-3])
    np.testing.assert_allclose(r.stress, [0.0, 8e-3])
    np.testing.assert_allclose(r.stress_at([1e-3]), [4e-3])


def test_settle_reads_the_solver_report():
    converged = settle(_result(time.perf_counter(), setup_time=0.0), throw=True)
    assert converged.status == "converged" and converged.status is Status.CONVERGED
    stopped = _result(time.perf_counter(), setup_time=0.0, stats={"converged": False, "failure": "CG stopped"})
    assert settle(stopped, throw=False).status is Status.MAX_ITERATIONS and not stopped.ok
    with pytest.raises(ConvergenceError, match="CG stopped.*max_iterations") as err:
        settle(_result(time.perf_counter(), setup_time=0.0, stats={"converged": False, "failure": "CG stopped"}),
               throw=True)
    assert err.value.result.status == "max_iterations"
    nan = _result(time.perf_counter(), setup_time=0.0, stiffness=float("nan"))
    with pytest.raises(NotFiniteError):
        settle(nan, throw=True)
    assert nan.status is Status.NOT_FINITE and "failure" in nan.stats
    interrupted = _result(time.perf_counter(), setup_time=0.0, interrupted=True)
    assert settle(interrupted, throw=True).status is Status.INTERRUPTED  # raised by the DEM itself, not here


def test_a_status_is_one_of_the_statuses():
    assert STATUSES == tuple(s.value for s in Status)
    r = Result(method="ste", stiffness=1.0, youngs_modulus=1.0, gauge_length=1.0, area=1.0,
               displacement=np.zeros(2), force=np.zeros(2), wall_time=0.0, compile_time=0.0, run_time=0.0,
               status="unstable")
    assert r.status is Status.UNSTABLE and "status='unstable'" in repr(r)
    with pytest.raises(ValueError):
        Result(method="ste", stiffness=1.0, youngs_modulus=1.0, gauge_length=1.0, area=1.0,
               displacement=np.zeros(2), force=np.zeros(2), wall_time=0.0, compile_time=0.0, run_time=0.0,
               status="exploded")
