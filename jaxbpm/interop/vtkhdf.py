"""VTKHDF time series for ParaView (>= 5.11): one HDF5 file holding every step, the topology written once.

The file is a transient ``VTKHDF`` UnstructuredGrid (format version 2.1): the group ``/VTKHDF`` holds the cells once --
a ``vertex`` cell per particle, then a ``line`` cell per bond (``Offsets``, ``Connectivity``, ``Types``,
``NumberOfCells``, ``NumberOfConnectivityIds``) -- and grows by one block of ``Points`` and of each point and cell
data array per step. ``/VTKHDF/Steps`` says where each step starts: ``Values`` (the times), ``PointOffsets``,
``PointDataOffsets/<name>``, ``CellDataOffsets/<name>``; ``CellOffsets``, ``ConnectivityIdOffsets`` and
``PartOffsets`` are 0 for every step, so every step reuses the one topology. Arrays that do not change
(``radius``, ``type``, ``material``) are stored once too (their offsets stay 0). A broken bond keeps its line cell, with
``intact`` 0, so breaking needs no topology change. The datasets are compressed with HDF5's gzip filter (which
VTK's reader, like every HDF5 program, reads).

The arrays are those of :class:`jaxbpm.interop.vtu.VTUSeries`. The file is flushed after each step and the step
count (``Steps`` attribute ``NSteps``) is raised last, so a run that stops leaves a file with its complete steps.
"""

from __future__ import annotations

import pathlib
from typing import Any, Mapping

import numpy as np

from jaxbpm.errors import SampleError, SampleFileError
from jaxbpm.interop.vtu import step_arrays
from jaxbpm.sample import Sample

__all__ = ["VTKHDFSeries", "SUFFIXES"]

SUFFIXES = (".vtkhdf", ".hdf")  # the suffixes ParaView opens with its VTKHDF reader
_VERTEX, _LINE = 1, 3  # VTK cell types
_STATIC = {"radius", "material", "type"}  # arrays written once (offset 0 at every step)
_PACK = {"compression": "gzip", "compression_opts": 4, "shuffle": True}  # HDF5's own filters: VTK reads them


class VTKHDFSeries:
    """A VTKHDF time series for ParaView, written step by step; use it as a context manager (or call
    :meth:`close`).

    Args:
      path: the new file (``.vtkhdf``; an existing file is not overwritten).
      sample: the sample whose particles and bonds every step shows.
    """

    def __init__(self, path, sample: Sample):
        import h5py

        if not isinstance(sample, Sample):
            raise TypeError(f"VTKHDFSeries expects a jaxbpm Sample, got {type(sample).__name__}")
        self.path = pathlib.Path(path)
        if self.path.suffix.lower() not in SUFFIXES:
            raise SampleFileError(f"{self.path}: a VTKHDF series is named .vtkhdf (ParaView also opens .hdf)")
        if not self.path.parent.is_dir():
            raise SampleFileError(f"{self.path}: no such directory {self.path.parent}")
        if self.path.exists():
            raise SampleFileError(f"{self.path}: the file exists; a VTKHDF series is not written over another file "
                                  "(delete it or choose another name)")
        self.sample = sample
        self.times: list[float] = []
        self._names: tuple[list[str], list[str]] | None = None
        self._file = h5py.File(self.path, "w-")
        try:
            self._topology()
        except BaseException:
            self.close()
            raise

    def __enter__(self) -> "VTKHDFSeries":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Close the file (the steps written stay readable); further writes are errors."""
        if self._file is not None:
            self._file.close()
            self._file = None

    def _topology(self) -> None:
        import h5py

        s = self.sample
        n, nb = s.n_particles, s.n_bonds
        root = self._file.create_group("VTKHDF")
        root.attrs["Version"] = np.array([2, 1], np.int64)
        kind = b"UnstructuredGrid"
        root.attrs.create("Type", kind, dtype=h5py.string_dtype("ascii", len(kind)))
        conn = np.concatenate([np.arange(n, dtype=np.int64), np.asarray(s.bonds, np.int64).reshape(-1)])
        offsets = np.concatenate([np.arange(n + 1, dtype=np.int64), n + 2 * np.arange(1, nb + 1, dtype=np.int64)])
        types = np.concatenate([np.full(n, _VERTEX, np.uint8), np.full(nb, _LINE, np.uint8)])
        for name, value in (("NumberOfPoints", [n]), ("NumberOfCells", [n + nb]),
                            ("NumberOfConnectivityIds", [len(conn)]), ("Offsets", offsets),
                            ("Connectivity", conn), ("Types", types)):
            data = np.asarray(value, np.uint8 if name == "Types" else np.int64)
            root.create_dataset(name, data=data, **(_PACK if data.size > 1 else {}))
        root.create_dataset("Points", (0, 3), maxshape=(None, 3), dtype=np.float64, chunks=(max(n, 1), 3), **_PACK)
        for group in ("PointData", "CellData"):
            root.create_group(group)
        steps = root.create_group("Steps")
        steps.attrs["NSteps"] = np.int64(0)
        for name in ("Values", "PartOffsets", "NumberOfParts", "PointOffsets", "CellOffsets",
                     "ConnectivityIdOffsets"):
            steps.create_dataset(name, (0,), maxshape=(None,), dtype=np.float64 if name == "Values" else np.int64)
        for group in ("PointDataOffsets", "CellDataOffsets"):
            steps.create_group(group)
        self._file.flush()

    def write(self, time: float, *, positions=None, displacement=None, intact=None,
              point_data: Mapping[str, Any] | None = None, bond_data: Mapping[str, Any] | None = None) -> int:
        """Append one step and flush the file.

        Args:
          time: the step's time [s].
          positions, displacement, intact, point_data, bond_data: as :meth:`jaxbpm.interop.vtu.VTUSeries.write`;
            every step must give the same ``point_data`` and ``bond_data`` names.

        Returns:
          The step's index.
        """
        if self._file is None:
            raise SampleFileError(f"{self.path}: the series is closed")
        s = self.sample
        pos, pdata, bdata = step_arrays(s, "VTKHDFSeries.write", positions, displacement, intact, point_data,
                                        bond_data)
        cdata = {name: _with_vertices(arr, s.n_particles) for name, arr in bdata.items()}
        names = (sorted(pdata), sorted(cdata))
        if self._names is None:
            self._names = names
        elif names != self._names:
            raise SampleError(f"VTKHDFSeries.write: step {len(self.times)} gives the arrays {names}, the first step "
                              f"gave {self._names}; every step of a series has the same arrays")
        root, k = self._file["VTKHDF"], len(self.times)
        steps = root["Steps"]
        point_at = _append(root["Points"], pos)
        offsets = {"Values": float(time), "PartOffsets": 0, "NumberOfParts": 1, "PointOffsets": point_at,
                   "CellOffsets": 0, "ConnectivityIdOffsets": 0}
        for group, data in (("PointData", pdata), ("CellData", cdata)):
            for name, arr in data.items():
                at = self._array(root[group], name, arr, k)
                _append(_offsets(steps[f"{group}Offsets"], name), np.array([at], np.int64))
        for name, value in offsets.items():
            _append(steps[name], np.array([value]))
        steps.attrs["NSteps"] = np.int64(k + 1)  # last: a step is complete once counted
        self._file.flush()
        self.times.append(float(time))
        return k

    def _array(self, group, name: str, arr: np.ndarray, k: int) -> int:
        """Store ``arr`` in ``group[name]`` (appended; once for the arrays that do not change) and return its
        offset."""
        if name not in group:
            shape = arr.shape[1:]
            group.create_dataset(name, (0,) + shape, maxshape=(None,) + shape, dtype=arr.dtype,
                                 chunks=(max(len(arr), 1),) + shape, **_PACK)
        if name in _STATIC and k > 0:
            return 0
        return _append(group[name], arr)


def _with_vertices(arr: np.ndarray, n: int) -> np.ndarray:
    """Bond data ``arr`` as cell data: the particles' vertex cells first, with NaN (-1 for integers)."""
    filler = np.full((n,) + arr.shape[1:], -1 if np.issubdtype(arr.dtype, np.integer) else np.nan, arr.dtype)
    return np.concatenate([filler, arr])


def _offsets(group, name: str):
    if name not in group:
        group.create_dataset(name, (0,), maxshape=(None,), dtype=np.int64)
    return group[name]


def _append(dataset, rows: np.ndarray) -> int:
    """Append ``rows`` to the resizable ``dataset``; returns the index of the first."""
    at = dataset.shape[0]
    dataset.resize(at + len(rows), axis=0)
    dataset[at:] = rows
    return at
