"""Run sets: a Latin hypercube of parameter sets solved in batches, with a bar of the runs only when asked."""

import json

import numpy as np
import pytest

import jaxbpm
from jaxbpm import calibrate as cal
from jaxbpm.scenes import UniaxialCompression
from tests.calibrate._cases import _analytic_problem

# one xdist worker for the calibration tests: those that calibrate `one` and `two` share their compiled solves
pytestmark = pytest.mark.xdist_group("calibrate-module")


def test_run_set_shows_a_progress_bar_only_when_asked(capsys):
    from jaxbpm.calibrate.runs import run_set

    s = jaxbpm.generate.lattice("sc", (3, 3, 4), 1e-3, materials={"E": 1e9, "nu": 0.25})
    problem = cal.Problem(cal.forward_model(s, UniaxialCompression(strain=0.002), solver="ste"),
                          [cal.Target("stiffness", 1.0)],
                          cal.ParameterSpace([cal.Parameter("bond_E", index=0)], cal.base_params(s)))
    quiet = run_set(problem, 6, batch_size=4)
    assert capsys.readouterr().err == ""
    shown = run_set(problem, 6, batch_size=4, progress=True)
    err = capsys.readouterr().err
    assert "run set" in err and "6/6" in err  # a bar of the runs, on stderr
    np.testing.assert_array_equal(shown.Y, quiet.Y)


def test_chunk_is_a_deprecated_name_of_batch_size():
    from jaxbpm.calibrate.runs import run_set

    problem = _analytic_problem([cal.Target("youngs_modulus", 30.0), cal.Target("stiffness", 12.0)], n=2)
    new = run_set(problem, 5, batch_size=2, seed=3)
    with pytest.warns(DeprecationWarning, match="batch_size="):
        old = run_set(problem, 5, chunk=2, seed=3)
    np.testing.assert_array_equal(old.X, new.X)
    np.testing.assert_array_equal(old.Y, new.Y)
    assert old.info["batch_size"] == new.info["batch_size"] == 2 and "chunk" not in old.info
    with pytest.raises(TypeError, match="batch_size= only"):
        run_set(problem, 5, batch_size=2, chunk=2)


def test_a_stored_chunk_is_read_as_batch_size(tmp_path):
    import h5py

    from jaxbpm.calibrate.runs import RunSet, run_set

    problem = _analytic_problem([cal.Target("youngs_modulus", 30.0)], n=1)
    path = run_set(problem, 3, batch_size=2).save(tmp_path / "runs.h5")
    with h5py.File(path, "r+") as f:  # the key of older files
        info = json.loads(f.attrs["info"])
        info["chunk"] = info.pop("batch_size")
        f.attrs["info"] = json.dumps(info)
    loaded = RunSet.load(path)
    assert loaded.info["batch_size"] == 2 and "chunk" not in loaded.info
    loaded.save(path)
    with h5py.File(path, "r") as f:
        assert "chunk" not in json.loads(f.attrs["info"])
