"""The output paths of a ``jaxbpm`` command, checked together before any work: no output is an input of the same
command (refused even with ``--force``), no two outputs name the same file, an existing sample or record (any HDF5
file, any file of a sample format) is replaced only with ``--force``, and each output can be written (its folder
exists, it is not a folder). The library's writers are not concerned: they replace their target as documented."""

from __future__ import annotations

import os
import pathlib

from jaxbpm._atomic import check_writable
from jaxbpm.errors import JaxbpmError

__all__ = ["OutputPathError", "check_outputs", "is_data_file", "SAMPLE_SUFFIXES"]

# suffixes of the files jaxbpm reads as samples (jaxbpm.interop.formats): an existing one is a sample
SAMPLE_SUFFIXES = (".h5", ".hdf5", ".data", ".lmp", ".csv")
_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


class OutputPathError(JaxbpmError, OSError):
    """An output path of a command names one of its inputs, another of its outputs, or (without ``--force``) an
    existing sample or record. An :class:`OSError`, like the other errors of the files a command writes."""


def is_data_file(path) -> bool:
    """Whether ``path`` is an existing sample or record: an HDF5 file (samples, DEM records, calibration histories
    and run sets are HDF5) or a file with a sample suffix (:data:`SAMPLE_SUFFIXES`).

    Args:
      path: the file.

    Returns:
      True for an existing file of those kinds.
    """
    path = pathlib.Path(path)
    if not path.is_file():
        return False
    if path.suffix.lower() in SAMPLE_SUFFIXES:
        return True
    try:
        with open(path, "rb") as fh:
            return fh.read(len(_HDF5_SIGNATURE)) == _HDF5_SIGNATURE
    except OSError:
        return False


def _same_file(a: pathlib.Path, b: pathlib.Path) -> bool:
    """Whether ``a`` and ``b`` name the same file: equal resolved paths, or (both existing) the same inode."""
    if a.resolve() == b.resolve():
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def check_outputs(outputs: dict, inputs: dict, force: bool = False, resumable: dict | None = None) -> None:
    """Check the output paths of a command before it starts its work.

    Args:
      outputs: ``{label: path}``, the files the command writes (label: the option, e.g. ``"--history"``); ``None``
        paths are skipped.
      inputs: ``{label: path}``, the files the command reads; ``None`` paths are skipped.
      force: allow replacing an existing sample or record that is not an input (``--force``).
      resumable: ``{label: path}``, files the command reads back and extends (a run set resumed): they may exist,
        but must be neither an input nor another output.

    Raises:
      OutputPathError: an output is an input (even with ``force``), two outputs name the same file, or an output
        names an existing sample or record without ``force``.
      OSError: an output's folder is missing or the output is a folder.
    """
    outs = {k: pathlib.Path(p) for k, p in outputs.items() if p is not None}
    ins = {k: pathlib.Path(p) for k, p in inputs.items() if p is not None}
    kept = {k: pathlib.Path(p) for k, p in (resumable or {}).items() if p is not None}
    written = list(outs.items()) + list(kept.items())
    for label, path in written:
        for in_label, source in ins.items():
            if _same_file(path, source):
                same = "" if str(source) == str(path) else f" ({source})"
                raise OutputPathError(f"{label} {path}: it is the command's input {in_label}{same}; an input is never "
                                      "overwritten (not even with --force): give another path")
    for i, (label, path) in enumerate(written):
        for other, second in written[i + 1:]:
            if _same_file(path, second):
                raise OutputPathError(f"{label} {path} and {other} {second} name the same file: give two paths")
    for label, path in outs.items():
        check_writable(path)
        if not force and is_data_file(path):
            raise OutputPathError(f"{label} {path}: the file exists and holds a sample or record; pass --force to "
                                  "replace it, or give another path")
