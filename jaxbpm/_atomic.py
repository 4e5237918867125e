"""Atomic file writes: a temporary file beside the target, renamed onto it only once complete, so that an error or
a crash never leaves a half-written file behind; and JSON written that way. Every writer of jaxbpm goes through
:func:`atomic_write`."""

from __future__ import annotations

import contextlib
import errno
import os
import pathlib
import tempfile
from typing import Callable

import numpy as np

__all__ = ["atomic_write", "check_writable", "write_json", "STALE_AFTER_S"]


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_writable(path) -> pathlib.Path:
    """Check that a file can be written at ``path``: its folder exists and it is not itself a folder.

    Callers check before long work (e.g. a packing); :func:`atomic_write` checks again before it writes.

    Args:
      path: the target file.

    Returns:
      ``path`` as a :class:`pathlib.Path`.

    Raises:
      FileNotFoundError: the folder is missing (naming ``path``).
      IsADirectoryError: ``path`` is a folder.
    """
    target = pathlib.Path(path)
    if not target.parent.is_dir():
        raise FileNotFoundError(errno.ENOENT, f"cannot write {target}: no such directory", str(target.parent))
    if target.is_dir():
        raise IsADirectoryError(errno.EISDIR, f"cannot write {target}: it is a directory (give a file name)",
                                str(target))
    return target


def _naming_target(err: OSError, target: pathlib.Path) -> OSError:
    """``err`` again, naming ``target`` (what the OS reports names the hidden temporary file)."""
    return type(err)(err.errno, f"cannot write {target}: {err.strerror}", str(target))


def atomic_write(path, write: Callable[[str], None]) -> pathlib.Path:
    """Call ``write(tmp_name)`` on a fresh temporary file next to ``path``, then rename it onto ``path``.

    On any exception (including KeyboardInterrupt) the temporary file is deleted and the exception re-raised;
    ``path`` is then exactly as it was before. Temporary files that a killed write left beside ``path`` are removed
    once older than :data:`STALE_AFTER_S`.

    Args:
      path: the target file.
      write: writes the content to the file name it is given.

    Returns:
      ``path`` as a :class:`pathlib.Path`.

    Raises:
      OSError: ``path`` cannot be written (its folder is missing, it is a folder, ...), naming ``path``.
    """
    target = check_writable(path)
    _remove_stale_temporaries(target)
    try:
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    except OSError as err:
        raise _naming_target(err, target) from err
    os.close(fd)
    try:
        write(tmp)
        with open(tmp, "rb+") as fh:  # make the content durable before it replaces the target
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~_current_umask())  # mkstemp creates 0600; give the usual permissions
        os.replace(tmp, target)
    except BaseException as err:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(err, OSError) and err.errno is not None and tmp in str(err):
            raise _naming_target(err, target) from err
        raise
    return target


STALE_AFTER_S = 3600.0  # a temporary file of a save this old was left by a killed process


def _remove_stale_temporaries(target: pathlib.Path) -> None:
    """Remove the temporary files an interrupted (killed) save of ``target`` left beside it, once they are older
    than :data:`STALE_AFTER_S` (younger ones may belong to a save still running in another process)."""
    import glob
    import time

    now = time.time()
    for old in target.parent.glob(f".{glob.escape(target.name)}.*.tmp"):
        with contextlib.suppress(OSError):
            if now - old.stat().st_mtime > STALE_AFTER_S:
                old.unlink()


def write_json(path, data) -> pathlib.Path:
    """Write ``data`` as indented JSON to ``path`` atomically, creating missing parent directories.

    NumPy scalars and arrays are converted; anything else unknown is written as its ``float``.

    Args:
      path: the target file.
      data: JSON-serialisable data (with NumPy scalars and arrays).

    Returns:
      ``path`` as a :class:`pathlib.Path`.
    """
    import json

    def convert(obj):
        if isinstance(obj, np.ndarray):
            return obj.tolist()
        if isinstance(obj, (np.integer, np.bool_)):
            return obj.item()
        return float(obj)

    target = pathlib.Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)

    def write(tmp):
        with open(tmp, "w") as fh:
            json.dump(data, fh, indent=2, default=convert)
            fh.write("\n")

    return atomic_write(target, write)
