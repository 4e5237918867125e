"""Atomic writes (jaxbpm._atomic): the target is either as before or complete, temporary files never stay."""

import errno
import os

import numpy as np
import pytest

from jaxbpm import _atomic, io


def _listing(folder):
    return sorted(p.name for p in folder.iterdir())


def test_atomic_write_replaces_the_target_only_when_complete(tmp_path):
    target = tmp_path / "a.txt"
    assert _atomic.atomic_write(target, lambda tmp: open(tmp, "w").write("one")) == target
    assert target.read_text() == "one" and oct(target.stat().st_mode & 0o777) == oct(0o666 & ~_atomic._current_umask())

    def half(tmp):
        with open(tmp, "w") as fh:
            fh.write("tw")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        _atomic.atomic_write(target, half)
    assert target.read_text() == "one" and _listing(tmp_path) == ["a.txt"]


def test_check_writable_names_the_target(tmp_path):
    assert _atomic.check_writable(tmp_path / "x.h5") == tmp_path / "x.h5"
    with pytest.raises(FileNotFoundError, match="no such directory") as err:
        _atomic.check_writable(tmp_path / "missing" / "x.h5")
    assert err.value.errno == errno.ENOENT
    with pytest.raises(IsADirectoryError, match="it is a directory"):
        _atomic.atomic_write(tmp_path, lambda tmp: None)
    assert _listing(tmp_path) == []


def test_io_reexports_the_atomic_writers():
    assert io.atomic_write is _atomic.atomic_write and io.write_json is _atomic.write_json
    assert io.check_writable is _atomic.check_writable and io.STALE_AFTER_S == _atomic.STALE_AFTER_S
    assert os.path.basename(_atomic.__file__) == "_atomic.py"


def test_write_json_round_trip_and_atomic(tmp_path, monkeypatch):
    import json

    target = tmp_path / "deep" / "r.json"
    _atomic.write_json(target, {"a": np.float64(1.5), "b": np.arange(3), "c": np.int32(4), "d": True})
    assert json.loads(target.read_text()) == {"a": 1.5, "b": [0, 1, 2], "c": 4, "d": True}
    before = target.read_bytes()

    def boom(*a, **k):
        raise RuntimeError("crash mid-write")

    monkeypatch.setattr(json, "dump", boom)
    with pytest.raises(RuntimeError, match="crash mid-write"):
        _atomic.write_json(target, {"a": 2})
    assert target.read_bytes() == before and sorted(p.name for p in target.parent.iterdir()) == ["r.json"]
