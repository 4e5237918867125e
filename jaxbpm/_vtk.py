"""VTK export of a sample for ParaView (``.vtu`` XML or ``.vtk`` legacy, through meshio), and the check of the extra
per-particle and per-bond fields a user adds to it (also used by the VTU series of :mod:`jaxbpm.interop.vtu`).
:func:`export_vtk` is public as :func:`jaxbpm.io.export_vtk`."""

from __future__ import annotations

import pathlib
from typing import Any, Mapping

import numpy as np

from jaxbpm._atomic import atomic_write
from jaxbpm.errors import SampleError, SampleFileError
from jaxbpm.sample import Sample

__all__ = ["export_vtk", "user_data", "points_3d"]

_VTK_FORMATS = {".vtu": "vtu", ".vtk": "vtk"}


def user_data(kind: str, data: Mapping[str, Any] | None, count: int, what: str,
              reserved: set[str]) -> dict[str, np.ndarray]:
    """Check the extra fields a user adds to a VTK file (:func:`export_vtk`, the VTU series).

    Args:
      kind: the argument's name for messages (``"point_data"``, ``"bond_data"``).
      data: ``{name: [count] or [count, k]}`` real (or boolean) arrays, or ``None``.
      count: the rows each field must have.
      what: what a row is, for messages (``"particle"``, ``"bond"``).
      reserved: the names of the built-in fields, which a user field may not take.

    Returns:
      ``{name: array}`` (booleans as uint8).

    Raises:
      SampleError: a field has a bad name, type or shape (the field is named).
    """
    out: dict[str, np.ndarray] = {}
    for name, value in (data or {}).items():
        if not isinstance(name, str) or not name:
            raise SampleError(f"{kind}: field names must be non-empty strings, got {name!r}")
        if name in reserved:
            raise SampleError(f"{kind}[{name!r}]: the name is taken by a built-in field ({sorted(reserved)})")
        arr = np.asarray(value)
        if arr.dtype == bool:
            arr = arr.astype(np.uint8)
        if not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
            raise SampleError(f"{kind}[{name!r}]: must be a real numeric array, got dtype {arr.dtype}")
        if arr.ndim not in (1, 2) or arr.shape[0] != count or (arr.ndim == 2 and arr.shape[1] < 1):
            raise SampleError(
                f"{kind}[{name!r}]: expected shape [{count}] or [{count}, k] (one row per {what}), got {arr.shape}")
        out[name] = arr
    return out


def points_3d(positions) -> np.ndarray:
    """Points as VTK stores them: ``[n, 3]`` float64, a two-dimensional sample's ``[n, 2]`` discs at z = 0.

    Args:
      positions: ``[n, 3]`` or ``[n, 2]`` centres [m].

    Returns:
      ``[n, 3]`` float64.
    """
    pos = np.asarray(positions, dtype=np.float64)
    if pos.shape[1] == 2:
        pos = np.column_stack([pos, np.zeros(len(pos))])
    return pos


def _types(sample: Sample) -> np.ndarray:
    """The particle types as int32 (1 where the sample has none)."""
    return np.ones(sample.n_particles, np.int32) if sample.types is None else np.asarray(sample.types, np.int32)


def export_vtk(path, sample: Sample, *, point_data: Mapping[str, Any] | None = None,
               bond_data: Mapping[str, Any] | None = None, break_mode=None) -> pathlib.Path:
    """Write particles and bonds to a VTK file for ParaView, atomically.

    The points are the particle centres [m]. Two cell blocks: ``vertex`` (one cell per particle, in particle
    order) and ``line`` (one cell per bond, in bond order; left out when the sample has no bonds, since legacy
    VTK cannot hold an empty block).

    Point data: ``radius`` [m], ``mass`` [kg], ``coordination`` (bonds per particle), ``type`` (``Sample.types``),
    then ``point_data``.
    Cell data, per bond: ``bond_radius`` [m], ``material`` (component index), ``length`` [m] (initial bond
    length), with ``break_mode`` also ``broken`` (1: the bond broke) and ``break_mode`` (0 intact, 1 tension,
    2 shear), then ``bond_data``. VTK stores cell data for every cell, so the vertex cells carry fillers: NaN for
    the float fields (user ``bond_data`` is written as float64 so it can hold NaN) and -1 for the integer ones.
    In ParaView, glyph the points with spheres scaled by ``radius`` and show the lines as tubes; colour them by
    ``break_mode`` (or threshold ``broken`` at 1) to see the cracks of a failure run. A two-dimensional
    sample's discs are points at z = 0 (VTK's points have three coordinates) with their ``radius``: glyph them with
    ParaView's 2D Glyph (a filled circle) scaled by ``radius``, or with spheres, which cut the plane z = 0 in the
    discs.

    Args:
      path: ``*.vtu`` (VTK XML unstructured grid, preferred) or ``*.vtk`` (legacy); the suffix picks the format.
      sample: the sample.
      point_data: ``{name: [n] or [n, k]}`` extra per-particle fields (e.g. displacement ``[n, 3]``).
      bond_data: ``{name: [nb] or [nb, k]}`` extra per-bond fields (e.g. bond force ``[nb]``).
      break_mode: ``[nb]`` how each bond broke, 0 intact, 1 tension, 2 shear (a DEM result's ``state.broken``), or
        ``None``.

    Returns:
      ``path`` as a :class:`pathlib.Path`.

    Raises:
      SampleError: a user field has the wrong shape or type, or reuses a built-in name (the field is named); a
        ``break_mode`` of the wrong length or with a code other than 0, 1, 2.
      SampleFileError: the suffix is neither ``.vtu`` nor ``.vtk``.
      TypeError: ``sample`` is not a :class:`Sample`.
    """
    import meshio

    if not isinstance(sample, Sample):
        raise TypeError(f"export_vtk expects a jaxbpm Sample, got {type(sample).__name__}")
    target = pathlib.Path(path)
    file_format = _VTK_FORMATS.get(target.suffix.lower())
    if file_format is None:
        raise SampleFileError(
            f"{target}: cannot tell the VTK format from the suffix {target.suffix!r}; use .vtu (XML) or .vtk (legacy)")

    n, nb = sample.n_particles, sample.n_bonds
    pdata = {
        "radius": np.asarray(sample.radii, dtype=np.float64),
        "mass": np.asarray(sample.mass, dtype=np.float64),
        "coordination": np.asarray(sample.coordination(), dtype=np.int32),
        "type": _types(sample),
    }
    pdata.update(user_data("point_data", point_data, n, "particle", set(pdata)))
    bdata = {
        "bond_radius": np.asarray(sample.bond_radius, dtype=np.float64),
        "material": np.asarray(sample.bond_material, dtype=np.int32),
        "length": np.asarray(sample.bond_length, dtype=np.float64),
    }
    if break_mode is not None:
        mode = np.asarray(break_mode).reshape(-1)
        if mode.shape != (nb,) or not np.all(np.isin(mode, (0, 1, 2))):
            raise SampleError(f"break_mode: expected [{nb}] codes 0 (intact), 1 (tension), 2 (shear), got shape "
                              f"{mode.shape} with values {np.unique(mode)[:5]}")
        bdata.update(broken=(mode != 0).astype(np.int32), break_mode=mode.astype(np.int32))
    bdata.update({k: v.astype(np.float64) for k, v in
                  user_data("bond_data", bond_data, nb, "bond", set(bdata)).items()})

    cells = [("vertex", np.arange(n, dtype=np.int64)[:, None])]
    if nb:
        cells.append(("line", np.asarray(sample.bonds, dtype=np.int64)))
    cell_data = {}
    for name, arr in bdata.items():
        filler = np.full((n,) + arr.shape[1:], -1 if np.issubdtype(arr.dtype, np.integer) else np.nan, dtype=arr.dtype)
        cell_data[name] = [filler, arr] if nb else [filler]
    mesh = meshio.Mesh(points_3d(sample.positions), cells, point_data=pdata, cell_data=cell_data)
    return atomic_write(target, lambda tmp: meshio.write(tmp, mesh, file_format=file_format))
