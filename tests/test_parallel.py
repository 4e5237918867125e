"""Runs spread over executors (jaxbpm.parallel): the same answers as one after another, run sets that resume, workers
that die."""

import concurrent.futures as cf
import functools
import multiprocessing
import os

import numpy as np
import pytest

import jaxbpm
from jaxbpm.calibrate import CalibrationError, Forward, Parameter, ParameterSpace, Problem, Target, run_set
from jaxbpm.calibrate.objective import forward_model
from jaxbpm.calibrate.runs import RunSet
from jaxbpm.parallel import WorkerLost, check_executor

pytestmark = pytest.mark.xdist_group("parallel")  # one xdist worker: the clusters' processes need the cores


def _quadratic(params, *, calls=None, fail_at=None):
    """A cheap model with two observables (a plain NumPy function: ``pure=False``)."""
    a = float(np.asarray(params["a"]).reshape(-1)[0])
    if calls is not None:
        with open(calls, "a") as fh:
            fh.write(f"{a!r}\n")
        if fail_at is not None and sum(1 for _ in open(calls)) == fail_at:
            raise RuntimeError(f"run {fail_at} failed")
    return {"y": np.asarray([a * a, 3.0 * a])}


def _dies_once(params, *, marker):
    """Kills its worker process the first time it runs anywhere, then answers like :func:`_quadratic`."""
    if not os.path.exists(marker):
        open(marker, "w").close()
        os._exit(3)
    return _quadratic(params)


def _settings_probe(params):
    import jax

    return {"y": np.asarray([float(jax.config.jax_enable_x64),
                             float(bool(jax.config.jax_compilation_cache_dir))])}


def _problem(fn, executor=None, size=2):
    fwd = Forward.from_function(fn, name="quadratic", pure=False)
    space = ParameterSpace([Parameter("a", bounds=(0.5, 2.0))], {"a": np.asarray([1.0])})
    return Problem(fwd, [Target("y", np.ones(size))], space, executor=executor)


def _lines(path):
    return open(path).read().split() if os.path.exists(path) else []


def test_bad_executor_and_retries_named():
    with pytest.raises(TypeError, match="concurrent.futures.Executor"):
        check_executor("dask")
    with pytest.raises(TypeError, match="concurrent.futures.Executor"):
        check_executor(cf.ThreadPoolExecutor)  # the class, not an instance
    with pytest.raises(ValueError, match="retries"):
        Problem(_problem(_quadratic).forward, [Target("y", np.ones(2))], _problem(_quadratic).space, retries=-1)


def test_run_set_stored_as_it_goes_and_resumed(tmp_path):
    """A run set that fails at its 5th run keeps the 4 before it in the file; called again, it solves the other 8 only
    and equals the run set solved in one go."""
    calls, path = tmp_path / "calls.txt", tmp_path / "runs.h5"
    whole = run_set(_problem(_quadratic), 12, seed=3)
    with pytest.raises(RuntimeError, match="run 5 failed"):
        run_set(_problem(functools.partial(_quadratic, calls=calls, fail_at=5)), 12, seed=3, path=path)
    partial = RunSet.load(path, partial=True)
    assert int(partial.done.sum()) == 4 and np.isnan(partial.Y[~partial.done]).all()
    with pytest.raises(CalibrationError, match="interrupted run set .4 of 12"):
        RunSet.load(path)
    first = _lines(calls)
    os.remove(calls)
    runs = run_set(_problem(functools.partial(_quadratic, calls=calls)), 12, seed=3, path=path)
    again = _lines(calls)
    assert len(again) == 8 and not set(again) & set(first[:4])
    assert runs.info["resumed"] == 4
    np.testing.assert_array_equal(runs.Y, whole.Y)
    np.testing.assert_array_equal(RunSet.load(path).Y, whole.Y)
    # a complete file: nothing is solved again; another design is refused, the file kept
    os.remove(calls)
    run_set(_problem(functools.partial(_quadratic, calls=calls)), 12, seed=3, path=path)
    assert _lines(calls) == []
    with pytest.raises(CalibrationError, match="holds another run set .its parameter sets"):
        run_set(_problem(_quadratic), 12, seed=4, path=path)
    np.testing.assert_array_equal(RunSet.load(path).Y, whole.Y)


def test_thread_executor_run_error_not_retried(tmp_path):
    """An error of the run itself is raised (not retried); the runs that finished are in the file."""
    calls, path = tmp_path / "calls.txt", tmp_path / "runs.h5"
    with cf.ThreadPoolExecutor(1) as ex:
        with pytest.raises(RuntimeError, match="run 3 failed"):
            run_set(_problem(functools.partial(_quadratic, calls=calls, fail_at=3), ex), 6, seed=0, path=path)
        lines = _lines(calls)
        assert len(lines) == len(set(lines)) >= 3  # none submitted twice
        # every run that finished (all but the failed one) is in the file
        assert int(RunSet.load(path, partial=True).done.sum()) == len(lines) - 1
        runs = run_set(_problem(_quadratic, ex), 6, seed=0, path=path)
    np.testing.assert_array_equal(runs.Y, run_set(_problem(_quadratic), 6, seed=0).Y)


def test_process_pool_takes_the_jax_settings():
    """A spawned worker runs with the submitting process's float64 setting and compilation cache."""
    with cf.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as ex:
        y = _problem(_settings_probe, ex).outputs(np.asarray([[1.0], [1.5]]))
    np.testing.assert_array_equal(y, np.ones((2, 2)))


def test_broken_process_pool_is_named(tmp_path):
    """A process pool whose worker dies breaks (it cannot take the run again): a clear WorkerLost, and the runs
    that finished before are in the file."""
    marker = tmp_path / "died"
    with cf.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as ex:
        with pytest.raises(WorkerLost, match="executor broke"):
            run_set(_problem(functools.partial(_dies_once, marker=str(marker)), ex), 4, seed=0,
                    path=tmp_path / "runs.h5")


@pytest.fixture(scope="module")
def dask_client():
    import distributed  # the "test" extra installs it
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=40) as cluster, distributed.Client(cluster) as client:
        yield client


def test_dask_worker_death_resubmitted(dask_client, tmp_path):
    """A worker that dies in the middle of a run set: the run goes to another worker; the answers are the serial
    ones."""
    marker = tmp_path / "died"
    ex = dask_client.get_executor()
    runs = run_set(_problem(functools.partial(_dies_once, marker=str(marker)), ex), 6, seed=1)
    assert marker.exists()
    np.testing.assert_array_equal(runs.Y, run_set(_problem(_quadratic), 6, seed=1).Y)


def test_dask_dem_runs_equal_serial(dask_client, tmp_path):
    """DEM runs (one task per parameter set and scene) on a 2-worker LocalCluster give exactly the serial numbers."""
    R = 1e-3
    s = jaxbpm.generate.box(60, seed=2, mean_radius=R, packing_fraction=0.45).largest_cluster()
    scenes = {"a": jaxbpm.scenes.UniaxialCompression(strain=1e-4), "b": jaxbpm.scenes.UniaxialCompression(strain=2e-4)}
    fwd = forward_model(s, scenes, "dem", transits=8)
    space = ParameterSpace([Parameter("bond_E", bounds=(5e8, 2e9))], {"bond_E": np.asarray(s.materials.E)})
    targets = [Target("stiffness", 1.0, scene="a"), Target("stiffness", 1.0, scene="b")]
    X = np.asarray([[6e8], [1e9], [1.9e9]])
    serial = Problem(fwd, targets, space).outputs(X)
    spread = Problem(fwd, targets, space, executor=dask_client.get_executor())
    np.testing.assert_array_equal(spread.outputs(X), serial)
    assert spread.evaluations == 6
