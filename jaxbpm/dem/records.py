"""Run records written as they arrive: an HDF5 file that a long DEM run appends to chunk by chunk.

Layout of a record file (``jaxbpm.solve(..., "dem", record_to="run.h5")``)::

    /records/time          [steps]          simulated time [s]
    /records/displacement  [steps]          scene displacement [m] (compression positive)
    /records/force         [steps]          scene force [N] (compression positive)
    /records/reaction      [steps, W+2, 3]  reactions (walls, then the moving and the resting clamped particles) [N]
    /records/vmax          [steps]          largest speed [m/s]
    /records/broken        [steps, 2]       cumulative broken bonds (tensile, shear), with breakage
    /checkpoint/*                          the DEM state after the last row (an interrupted run only: what
                                            ``jaxbpm.solve(..., resume="run.h5")`` continues from)
    attributes of /:  format ("jaxbpm-records"), version, status ("running", "complete" or "interrupted"),
                      steps (rows written), steps_planned, resumed (times continued), and the run's scalars (dt,
                      speed, gauge_length, area, the sample's size and digest, ...)

Every :meth:`RecordFile.append` opens the file, grows the datasets, writes the rows, updates ``steps`` and closes
it, so the file on disk is valid HDF5 between chunks; a Ctrl-C arriving during a write is held back until the write
is finished (then raised). :func:`read_records` reads one back (also while the run is going on).
"""

from __future__ import annotations

import contextlib
import errno
import pathlib
import signal
import threading
from typing import Any, Mapping

import numpy as np

from jaxbpm.errors import SampleFileError

__all__ = ["RecordFile", "RecordLockedError", "read_records"]

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


class RecordLockedError(SampleFileError):
    """A record file that another process holds open (HDF5 locks a file while it is open for writing): two runs
    recording to one file, or a reader while a run writes. ``path``: the file."""

    def __init__(self, path):
        super().__init__(f"{path}: the record file is held by another process (HDF5 file lock): one file takes one "
                         "run at a time; give each run its own record_to path, or wait for the other to finish")
        self.path = pathlib.Path(path)


def _locked(err: OSError) -> bool:
    return isinstance(err, BlockingIOError) or err.errno in (errno.EAGAIN, errno.EWOULDBLOCK) \
        or "unable to lock file" in str(err)


@contextlib.contextmanager
def _h5(path, mode: str):
    """``h5py.File(path, mode)``, a file locked by another process raising :class:`RecordLockedError`."""
    import h5py

    try:
        f = h5py.File(path, mode)
    except OSError as err:
        if _locked(err):
            raise RecordLockedError(path) from err
        raise
    with f:
        yield f


def _scalar(v):
    if isinstance(v, (bool, np.bool_)):
        return int(v)
    if isinstance(v, (int, float, str, np.integer, np.floating)):
        return v
    return None


# the attributes that say two runs are the same run (a record of it may be replaced by running it again)
SAME_RUN = ("method", "scene", "dt", "speed", "gauge_length", "area", "target_displacement", "damping")
# and the ones a resumed run must share besides (the chunks, the sample and the padding)
RESUME_SAME = ("chunk", "steps_planned", "particles", "bonds", "sample_digest", "padded_particles", "padded_bonds",
               "breakage", "contact_law", "failure_rule")


def _differing(stored: Mapping[str, Any], attrs: Mapping[str, Any], keys) -> list[str]:
    """The ``keys`` whose scalar value in the run's ``attrs`` is not the one a record file ``stored``."""
    return [k for k in keys if k in attrs and _scalar(attrs[k]) is not None
            and (k not in stored or stored[k] != _scalar(attrs[k]))]


def _same_run(path: pathlib.Path, attrs: Mapping[str, Any]) -> bool:
    """Whether ``path`` is a jaxbpm record file of the run ``attrs`` describes."""
    try:
        with _h5(path, "r") as f:
            return f.attrs.get("format") == FORMAT and not _differing(f.attrs, attrs, SAME_RUN)
    except RecordLockedError:
        raise
    except (OSError, KeyError, ValueError):
        return False


class RecordFile:
    """An HDF5 record file, created with the run's scalar attributes.

    Args:
      path: the file (``.h5`` or ``.hdf5``). An existing file there is replaced only when it is a record of the same
        run (the attributes in :data:`SAME_RUN` agree: running it again) or with ``overwrite``; any other file is
        an error, left as it was.
      attrs: the run's attributes (scalars are stored, other values left out).
      steps_planned: the steps the run plans.
      overwrite: replace any file at ``path``.

    Raises:
      SampleFileError: a path that is not ``.h5``, a missing directory, or another file in the way.
    """

    def __init__(self, path, attrs: Mapping[str, Any] | None = None, *, steps_planned: int | None = None,
                 overwrite: bool = False):
        self.path = pathlib.Path(path)
        if self.path.suffix.lower() not in (".h5", ".hdf5"):
            raise SampleFileError(f"{self.path}: a record file must end in .h5 or .hdf5")
        if not self.path.parent.is_dir():
            raise SampleFileError(f"{self.path}: no such directory {self.path.parent}")
        if self.path.exists() and not overwrite and not _same_run(self.path, attrs or {}):
            raise SampleFileError(f"{self.path} exists and is not a record of this run: not replaced (choose another "
                                  "path, or pass overwrite=True to replace it)")
        self.steps = 0
        with _hold_interrupts(), _h5(self.path, "w") as f:
            f.attrs.update(format=FORMAT, version=VERSION, status="running", steps=0,
                           steps_planned=-1 if steps_planned is None else int(steps_planned))
            for k, v in (attrs or {}).items():
                if _scalar(v) is not None:
                    f.attrs[k] = _scalar(v)
            f.create_group("records")

    def append(self, rows: Mapping[str, Any]) -> int:
        """Append rows to the named arrays (the first call fixes the names).

        Args:
          rows: ``{name: [m, ...]}`` arrays, all ``m`` rows long.

        Returns:
          The steps written so far.

        Raises:
          ValueError: arrays of different lengths.
        """
        rows = {k: np.asarray(v) for k, v in rows.items()}
        lengths = {len(v) for v in rows.values()}
        if len(lengths) != 1:
            raise ValueError(f"RecordFile.append: arrays of different lengths {sorted(lengths)}")
        m = lengths.pop()
        with _hold_interrupts(), _h5(self.path, "a") as f:
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

    @classmethod
    def resume(cls, path, attrs: Mapping[str, Any]) -> tuple["RecordFile", dict, dict | None]:
        """Reopen the record of an interrupted run to append to it.

        Args:
          path: the record file.
          attrs: the resumed run's attributes: those in :data:`SAME_RUN` and :data:`RESUME_SAME` must agree with
            the file's (the same sample, scene, time step, speed, damping, chunk, ...).

        Returns:
          ``(record_file, records, checkpoint)``: the file, the rows written so far and the state saved at the
          interruption (:meth:`checkpoint`; ``None`` when the run was interrupted before its first chunk).

        Raises:
          SampleFileError: a file of another run (naming the attributes that differ), a complete run, or one that
            cannot be resumed (no saved state, or a file changed after the interruption).
        """
        records, stored = read_records(path)
        self = cls.__new__(cls)
        self.path, self.steps = pathlib.Path(path), int(stored["steps"])
        from jaxbpm._text import shown as _shown

        differ = [f"{k} (file {_shown(stored.get(k))}, this run {_shown(attrs[k])})"
                  for k in _differing(stored, attrs, SAME_RUN + RESUME_SAME)]
        if differ:
            raise SampleFileError(f"{path}: not a record of this run, cannot resume it: " + "; ".join(differ))
        status = stored.get("status")
        if status == "complete":
            raise SampleFileError(f"{path}: the run is complete ({self.steps} steps): nothing to resume")
        checkpoint = None
        with _h5(self.path, "r") as f:
            if "checkpoint" in f:
                g = f["checkpoint"]
                checkpoint = {k: np.asarray(d[()]) for k, d in g.items()}
                if int(g.attrs["steps"]) != self.steps:
                    raise SampleFileError(f"{path}: the saved state is of step {int(g.attrs['steps'])}, the records "
                                          f"end at step {self.steps}: the file was changed after the interruption")
        if status != "interrupted" or (checkpoint is None and self.steps):
            raise SampleFileError(f"{path}: the run has status {status!r} and {self.steps} steps without a saved state "
                                  "(a run saves its state when interrupted by Ctrl-C, not when killed): it cannot be "
                                  "resumed; run it again")
        with _hold_interrupts(), _h5(self.path, "a") as f:
            f.attrs["status"] = "running"
            f.attrs["resumed"] = int(f.attrs.get("resumed", 0)) + 1
        return self, records, checkpoint

    def checkpoint(self, arrays: Mapping[str, Any]) -> None:
        """Save the run's state after the rows written so far, replacing an earlier one: :meth:`resume` continues from
        it.

        Args:
          arrays: ``{name: array}`` (``/checkpoint``, one dataset per name).
        """
        with _hold_interrupts(), _h5(self.path, "a") as f:
            if "checkpoint" in f:
                del f["checkpoint"]
            g = f.create_group("checkpoint")
            g.attrs["steps"] = self.steps
            for k, v in arrays.items():
                v = np.asarray(v)
                g.create_dataset(k, data=v, fletcher32=v.ndim >= 1 and v.size > 0)

    def finish(self, status: str = "complete", attrs: Mapping[str, Any] | None = None) -> None:
        """Set the final status and add scalar results to the attributes.

        Args:
          status: ``"complete"``, ``"interrupted"`` (the checkpoint is kept) or ``"unstable"``.
          attrs: results to store (scalars only).
        """
        with _hold_interrupts(), _h5(self.path, "a") as f:
            f.attrs["status"] = status
            if status != "interrupted" and "checkpoint" in f:  # (only an interrupted run is resumed)
                del f["checkpoint"]
            for k, v in (attrs or {}).items():
                if _scalar(v) is not None:
                    f.attrs[k] = _scalar(v)


def read_records(path) -> tuple[dict, dict]:
    """Read a record file (also while its run is going on).

    Args:
      path: the record file.

    Returns:
      ``(records, attrs)``: the arrays of ``/records`` (the rows written so far) and the file's attributes.

    Raises:
      SampleFileError: a missing or unreadable file, or not a jaxbpm record file.
    """
    path = pathlib.Path(path)
    if not path.is_file():
        raise SampleFileError(f"{path}: no such record file")
    try:
        with _h5(path, "r") as f:
            attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
            if attrs.get("format") != FORMAT:
                raise SampleFileError(f"{path}: not a jaxbpm record file (format {attrs.get('format')!r})")
            steps = int(attrs["steps"])
            records = {k: d[:steps] for k, d in f["records"].items()}
    except RecordLockedError:
        raise
    except OSError as err:
        raise SampleFileError(f"{path}: cannot read the record file ({err})") from err
    return records, attrs
