"""The record file format: rows appended chunk by chunk read back as written, a checkpoint that a resume returns, the
final status and attributes, and the files it refuses."""

import h5py
import numpy as np
import pytest

from jaxbpm import SampleFileError
from jaxbpm.dem.records import RecordFile, read_records

ATTRS = {"method": "dem", "scene": "UniaxialCompression", "dt": 1e-7, "speed": 0.05, "damping": 0.7,
         "chunk": 4, "breakage": True, "note": [1, 2]}  # (a list is no scalar: not stored)


def _rows(start, m):
    t = np.arange(start, start + m, dtype=np.float64)
    return {"time": t, "reaction": np.stack([t * k for k in range(6)], axis=1).reshape(m, 2, 3),
            "broken": np.stack([t, 2 * t], axis=1).astype(np.int32)}


def test_rows_checkpoint_and_status_round_trip(tmp_path):
    path = tmp_path / "run.h5"
    rec = RecordFile(path, ATTRS, steps_planned=12)
    assert rec.append(_rows(0, 4)) == 4 and rec.append(_rows(4, 4)) == 8
    state = {"positions": np.random.default_rng(0).normal(size=(5, 3)), "intact": np.array([True, False])}
    rec.checkpoint(state)
    rec.finish("interrupted", {"peak_force": 3.5, "curve": np.zeros(3)})

    rows, attrs = read_records(path)
    expected = {k: np.concatenate([a, b]) for (k, a), b in zip(_rows(0, 4).items(), _rows(4, 4).values())}
    assert set(rows) == set(expected)
    for k in expected:
        np.testing.assert_array_equal(rows[k], expected[k])
        assert rows[k].dtype == expected[k].dtype
    assert attrs["format"] == "jaxbpm-records" and attrs["status"] == "interrupted"
    assert attrs["steps"] == 8 and attrs["steps_planned"] == 12 and attrs["peak_force"] == 3.5
    assert attrs["breakage"] == 1 and "note" not in attrs and "curve" not in attrs

    again, prior, saved = RecordFile.resume(path, ATTRS)
    assert again.steps == 8 and read_records(path)[1]["status"] == "running" and read_records(path)[1]["resumed"] == 1
    np.testing.assert_array_equal(prior["time"], expected["time"])
    np.testing.assert_array_equal(saved["positions"], state["positions"])
    np.testing.assert_array_equal(saved["intact"], state["intact"])
    assert again.append(_rows(8, 4)) == 12
    again.finish("complete")
    rows, attrs = read_records(path)
    np.testing.assert_array_equal(rows["time"], np.arange(12.0))
    assert attrs["status"] == "complete"
    with h5py.File(path, "r") as f:
        assert "checkpoint" not in f  # only an interrupted run keeps its state


def test_files_it_refuses(tmp_path):
    with pytest.raises(SampleFileError, match=r"must end in \.h5"):
        RecordFile(tmp_path / "run.txt", ATTRS)
    with pytest.raises(SampleFileError, match="no such directory"):
        RecordFile(tmp_path / "missing" / "run.h5", ATTRS)
    with pytest.raises(SampleFileError, match="no such record file"):
        read_records(tmp_path / "missing.h5")
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f.attrs["format"] = "something-else"
    with pytest.raises(SampleFileError, match="not a jaxbpm record file"):
        read_records(other)
    with pytest.raises(SampleFileError, match="not a record of this run"):
        RecordFile(other, ATTRS)
    RecordFile(other, ATTRS, overwrite=True)
    RecordFile(other, ATTRS)  # the same run again replaces its own record
    with pytest.raises(SampleFileError, match=r"not a record of this run, cannot resume it: damping"):
        RecordFile.resume(other, {**ATTRS, "damping": 0.5})
    with pytest.raises(ValueError, match="different lengths"):
        RecordFile(tmp_path / "run.h5", ATTRS).append({"time": np.zeros(3), "vmax": np.zeros(2)})


def test_a_record_file_locked_by_another_process_is_a_named_error(tmp_path):
    """HDF5 locks a file while it is open (flock); a second run recording to it, or a reader, got a raw
    ``BlockingIOError``. The lock is taken here by flock on another file descriptor, as another process holds it."""
    import fcntl

    from jaxbpm.dem.records import RecordLockedError

    path = tmp_path / "run.h5"
    rec = RecordFile(path, ATTRS, steps_planned=8)
    rec.append(_rows(0, 4))
    with open(path, "rb") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        for attempt in (lambda: rec.append(_rows(4, 4)), lambda: read_records(path),
                        lambda: RecordFile(path, ATTRS, steps_planned=8), lambda: rec.finish("complete")):
            with pytest.raises(RecordLockedError, match="held by another process") as err:
                attempt()
            assert isinstance(err.value, SampleFileError) and err.value.path == path and str(path) in str(err.value)
        fcntl.flock(fh, fcntl.LOCK_UN)
    assert rec.append(_rows(4, 4)) == 8  # released: the run goes on
    assert len(read_records(path)[0]["time"]) == 8
