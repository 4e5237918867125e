"""Run records written as they arrive: an HDF5 file that a long DEM run appends to chunk by chunk.

Layout of a record file (``jaxbpm.solve(..., "dem", record_to="run.h5")``)::

    /records/time          [steps]          simulated time [s]
    /records/displacement  [steps]          scene displacement [m] (compression positive)
    /records/force         [steps]          scene force [N] (compression positive)
    /records/reaction      [steps, W+2, 3]  reactions (walls, then the moving and the resting clamped particles) [N]
    /records/vmax          [steps]          largest speed [m/s]
    /records/broken        [steps, 2]       cumulative broken bonds (tensile, shear), with breakage
    attributes of /:  format ("jaxbpm-records"), version, status ("running", "complete" or "interrupted"),
                      steps (rows written), steps_planned, and the run's scalars (dt, speed, gauge_length, area, ...)

Every :meth:`RecordFile.append` opens the file, grows the datasets, writes the rows, updates ``steps`` and closes
it, so the file on disk is valid HDF5 between chunks; a Ctrl-C arriving during a write is held back until the write
is finished (then raised). :func:`read_records` reads one back (also while the run is going on).
"""

from __future__ import annotations

import contextlib
import pathlib
import signal
import threading
from typing import Any, Mapping

import numpy as np

from jaxbpm.errors import SampleFileError

__all__ = ["RecordFile", "read_records"]

FORMAT = "jaxbpm-records"
VERSION = 1


@contextlib.contextmanager
def _hold_interrupts():
    """Delay SIGINT (Ctrl-C) until the block is done (main thread only; elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught = []
    try:
        previous = signal.signal(signal.SIGINT, lambda sig, frame: caught.append(sig))
    except ValueError:  # not the main interpreter
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler if previous is None else previous)
        if caught:
            raise KeyboardInterrupt


def _scalar(v):
    if isinstance(v, (bool, np.bool_)):
        return int(v)
    if isinstance(v, (int, float, str, np.integer, np.floating)):
        return v
    return None


# the attributes that say two runs are the same run (a record of it may be replaced by running it again)
SAME_RUN = ("method", "scene", "dt", "speed", "gauge_length", "area", "target_displacement", "damping")


def _same_run(path: pathlib.Path, attrs: Mapping[str, Any]) -> bool:
    """Whether ``path`` is a jaxbpm record file of the run ``attrs`` describes."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            if f.attrs.get("format") != FORMAT:
                return False
            return all(k in f.attrs and _scalar(attrs[k]) == f.attrs[k] for k in SAME_RUN if k in attrs)
    except (OSError, KeyError, ValueError):
        return False


class RecordFile:
    """An HDF5 record file, created with the run's scalar ``attrs``. An existing file at ``path`` is replaced only
    when it is a record of the same run (the attributes in :data:`SAME_RUN` agree: running it again) or with
    ``overwrite=True``; any other file is an error, left as it was."""

    def __init__(self, path, attrs: Mapping[str, Any] | None = None, *, steps_planned: int | None = None,
                 overwrite: bool = False):
        import h5py

        self.path = pathlib.Path(path)
        if self.path.suffix.lower() not in (".h5", ".hdf5"):
            raise SampleFileError(f"{self.path}: a record file must end in .h5 or .hdf5")
        if not self.path.parent.is_dir():
            raise SampleFileError(f"{self.path}: no such directory {self.path.parent}")
        if self.path.exists() and not overwrite and not _same_run(self.path, attrs or {}):
            raise SampleFileError(f"{self.path} exists and is not a record of this run: not replaced (choose another "
                                  "path, or pass overwrite=True to replace it)")
        self.steps = 0
        with _hold_interrupts(), h5py.File(self.path, "w") as f:
            f.attrs.update(format=FORMAT, version=VERSION, status="running", steps=0,
                           steps_planned=-1 if steps_planned is None else int(steps_planned))
            for k, v in (attrs or {}).items():
                if _scalar(v) is not None:
                    f.attrs[k] = _scalar(v)
            f.create_group("records")

    def append(self, rows: Mapping[str, Any]) -> int:
        """Append equally long rows of each named array (the first call fixes the names); returns the steps so
        far."""
        import h5py

        rows = {k: np.asarray(v) for k, v in rows.items()}
        lengths = {len(v) for v in rows.values()}
        if len(lengths) != 1:
            raise ValueError(f"RecordFile.append: arrays of different lengths {sorted(lengths)}")
        m = lengths.pop()
        with _hold_interrupts(), h5py.File(self.path, "a") as f:
            g = f["records"]
            for k, v in rows.items():
                if k not in g:
                    g.create_dataset(k, shape=(0,) + v.shape[1:], maxshape=(None,) + v.shape[1:], dtype=v.dtype,
                                     chunks=(max(m, 1),) + v.shape[1:])
                d = g[k]
                d.resize(self.steps + m, axis=0)
                d[self.steps:] = v
            self.steps += m
            f.attrs["steps"] = self.steps
        return self.steps

    def finish(self, status: str = "complete", attrs: Mapping[str, Any] | None = None) -> None:
        """Set the final ``status`` (``"complete"`` or ``"interrupted"``) and add scalar results to the attributes."""
        import h5py

        with _hold_interrupts(), h5py.File(self.path, "a") as f:
            f.attrs["status"] = status
            for k, v in (attrs or {}).items():
                if _scalar(v) is not None:
                    f.attrs[k] = _scalar(v)


def read_records(path) -> tuple[dict, dict]:
    """``(records, attrs)`` of a record file: the arrays of ``/records`` and the file's attributes."""
    import h5py

    path = pathlib.Path(path)
    if not path.is_file():
        raise SampleFileError(f"{path}: no such record file")
    try:
        with h5py.File(path, "r") as f:
            attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
            if attrs.get("format") != FORMAT:
                raise SampleFileError(f"{path}: not a jaxbpm record file (format {attrs.get('format')!r})")
            steps = int(attrs["steps"])
            records = {k: d[:steps] for k, d in f["records"].items()}
    except OSError as err:
        raise SampleFileError(f"{path}: cannot read the record file ({err})") from err
    return records, attrs
