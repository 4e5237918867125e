"""Exchange formats: LAMMPS data and dump files, CSV particles + bonds, VTU and VTKHDF time series for ParaView,
LIGGGHTS data files and dumps, Yade sphere lists.

All writers are atomic (a temporary file next to the target, renamed onto it when complete). Readers raise
:class:`~jaxbpm.errors.SampleFileError` naming the file and line of a malformed entry.

Checksums: jaxbpm's text files carry a CRC-32 (zlib) of what they hold -- a LAMMPS data file at the end of its title
line (``crc32=XXXXXXXX``, of the text after that line), a CSV pair on the last line of the particles file (``#
crc32=XXXXXXXX bonds_crc32=YYYYYYYY``, of the particles file without that line and of the bonds file). The readers
check them, so a damaged, cut or swapped file is an error, not a silently different sample; files without them (from
other programs) are read as they are. To accept an intended hand edit, delete the checksum (the error says where).

LAMMPS data (:func:`write_lammps_data`, :func:`read_lammps_data`)
    ``atom_style bpm/sphere`` (``id mol type diameter density x y z``; ``sphere``: ``id type diameter density x y
    z``; optional image flags; the atom types are ``Sample.types``, written from it by default), ``Bonds`` (``id
    type atom1 atom2``) and a ``Bond Coeffs # bpm/rotational`` section
    (``type Kr Ks Kt Kb Fcr Fcs Tct Tcb gamma_r gamma_s gamma_t gamma_b``, see :mod:`jaxbpm.interop.conventions`). LAMMPS
    can only define ``bond_style bpm/rotational`` after the box exists, so read the file in LAMMPS with
    ``read_data FILE nocoeff`` followed by the ``bond_style``/``bond_coeff`` lines of :func:`write_lammps_coeffs`.
    A 2D sample (discs) is written for ``dimension 2`` (z = 0, ``zlo zhi`` a slab of its thickness, the coefficients
    of its ``2 r_b x t`` bond sections); read LAMMPS's own 2D files with ``dim=2``.
    jaxbpm also writes its exact parameters as comments (a ``# jaxbpm {...}`` JSON header line; per bond ``#
    bond_radius material``), which LAMMPS ignores and which make jaxbpm -> LAMMPS data -> jaxbpm exact. Files
    without them are translated from the coefficients (one material component per distinct (E, nu, strengths)).
LAMMPS dump (:func:`read_lammps_dump`)
    text dumps: ``ITEM: ATOMS`` frames (positions from x/y/z, xu/yu/zu or scaled xs/ys/zs, atom types from
    ``type``: :attr:`DumpFrame.types`, any other columns) and
    ``ITEM: ENTRIES`` frames of ``dump local`` (bond lists from ``compute property/local batom1 batom2 btype``).
CSV (:func:`write_csv`, :func:`read_csv`)
    ``NAME.csv`` (particles: ``id,x,y,z,radius,type``, a 2D sample's ``id,x,y,radius,type``; foreign files: the type from a ``type``, ``group`` or
    ``material`` column, else 1) and ``NAME_bonds.csv`` (``i,j,bond_radius,material,E,nu,
    tensile_strength,shear_strength``, i and j particle ids); a ``# jaxbpm {...}`` first line keeps what the columns
    cannot (particle material, material table, bond_contact, domain). Foreign files may use ``diameter`` instead of
    ``radius``, ``bond_diameter`` instead of ``bond_radius``, ``id1,id2`` instead of ``i,j``, and may leave out the
    material columns (then one component per distinct (E, nu, strengths), defaults 1 GPa, 0.25, unbreakable).
VTU series (:class:`VTUSeries`, :func:`write_vtu_series`)
    one ``.vtu`` per time (meshio) and a ``.pvd`` collection for ParaView.
VTKHDF series (:class:`VTKHDFSeries`, :mod:`jaxbpm.interop.vtkhdf`)
    one ``.vtkhdf`` file (HDF5) for all times, which ParaView >= 5.11 opens: the cells (a vertex per particle, a
    line per bond) are stored once, each step adds only the points and the data arrays.
LIGGGHTS (:func:`read_liggghts_data`, :func:`read_liggghts_dump`), Yade (:func:`read_yade_text`, ...)
    see :mod:`jaxbpm.interop.othercodes`. Their files have no suffix of their own (``.data`` is also LAMMPS',
    ``.txt`` anything), so :func:`read_sample` and :func:`convert` read them only when told: ``format="liggghts"``
    or ``format="yade"``.
"""

from __future__ import annotations

import pathlib

import numpy as np

from jaxbpm.errors import SampleFileError
from jaxbpm.interop._registry import FORMATS, READERS  # (kept JAX-free for the CLI's help)
from jaxbpm.interop.csvfiles import read_csv, write_csv
from jaxbpm.interop.dump import DumpFrame, read_lammps_dump
from jaxbpm.interop.lammps import (lammps_coefficients, read_lammps_coeffs, read_lammps_data, write_lammps_coeffs,
                                   write_lammps_data)
from jaxbpm.interop.othercodes import read_liggghts_data, read_liggghts_dump, read_yade_text, write_yade_text
from jaxbpm.interop.vtkhdf import VTKHDFSeries
from jaxbpm.interop.vtu import VTUSeries, write_vtu_series
from jaxbpm.io import export_vtk, load_sample, save_sample
from jaxbpm.sample import Sample

__all__ = ["write_lammps_data", "read_lammps_data", "write_lammps_coeffs", "read_lammps_coeffs", "lammps_coefficients",
           "read_lammps_dump", "DumpFrame", "write_csv", "read_csv", "VTUSeries", "write_vtu_series", "VTKHDFSeries",
           "read_liggghts_data", "read_liggghts_dump", "read_yade_text", "write_yade_text", "read_sample",
           "write_sample", "convert", "FORMATS", "READERS"]


def _kind(path: pathlib.Path, what: str) -> str:
    ext = path.suffix.lower()
    if ext not in FORMATS:
        raise SampleFileError(f"{path}: cannot tell the format from the suffix {ext!r}; known: "
                              f"{', '.join(sorted(FORMATS))} (or name the input's format, format= / --format: "
                              f"{', '.join(READERS)})")
    return ext


def read_sample(path, *, format: str | None = None, **kw) -> Sample:
    """Read a sample from any readable format.

    Args:
      path: the file; its suffix gives the format (``.h5``, ``.data``/``.lmp``, ``.csv``) unless ``format`` does.
      format: a key of :data:`READERS` (``"liggghts"``, ``"yade"``, ...), whatever the suffix.
      **kw: the reader's keywords.

    Returns:
      The sample.

    Raises:
      SampleFileError: an unknown suffix or format, or a file the reader rejects.
    """
    path = pathlib.Path(path)
    if format is not None:
        return _read_as(path, format, **kw)
    ext = _kind(path, "input")
    if ext in (".h5", ".hdf5"):
        return load_sample(path)
    if ext in (".data", ".lmp"):
        return read_lammps_data(path, **kw)
    if ext == ".csv":
        return read_csv(path, **kw)
    raise SampleFileError(f"{path}: {FORMATS[ext]} is not a sample format that can be read")


def _read_as(path: pathlib.Path, format: str, **kw) -> Sample:
    readers = {"hdf5": load_sample, "lammps": read_lammps_data, "csv": read_csv, "liggghts": read_liggghts_data,
               "yade": read_yade_text}
    if format not in readers:
        raise SampleFileError(f"{path}: unknown format {format!r}; known: {', '.join(READERS)}")
    return readers[format](path, **kw)


def write_sample(path, sample: Sample, **kw) -> list[pathlib.Path]:
    """Write a sample in the format its suffix names.

    Args:
      path: the file (``.h5``, ``.data``/``.lmp``, ``.csv``, ``.vtu``/``.vtk``).
      sample: the sample.
      **kw: the writer's keywords.

    Returns:
      The files written (a CSV sample is two files).

    Raises:
      SampleFileError: a suffix with no sample writer.
    """
    path = pathlib.Path(path)
    ext = _kind(path, "output")
    if ext in (".h5", ".hdf5"):
        return [save_sample(path, sample)]
    if ext in (".data", ".lmp"):
        return [write_lammps_data(path, sample, **kw)]
    if ext == ".csv":
        return list(write_csv(path, sample))
    if ext in (".vtu", ".vtk"):
        return [export_vtk(path, sample)]
    raise SampleFileError(f"{path}: {FORMATS[ext]} cannot be written from a sample alone")


def convert(src, dst, *, sample=None, format: str | None = None, **kw) -> list[pathlib.Path]:
    """Convert a file to another format, formats by suffix.

    A LAMMPS dump (``.dump``/``.lammpstrj``) converts to a ``.pvd`` VTU series or a ``.vtkhdf`` series and needs
    ``sample`` for radii and bonds; its atom IDs must be particle index + 1 (as :func:`write_lammps_data` numbers
    them).

    Args:
      src: the input file.
      dst: the output file.
      sample: a :class:`Sample` or a sample file (for a dump only).
      format: read ``src`` as this key of :data:`READERS`, whatever its suffix.
      **kw: the reader's keywords.

    Returns:
      The files written.

    Raises:
      SampleFileError: unknown formats, a dump without ``sample``, or a file the reader rejects.
    """
    src, dst = pathlib.Path(src), pathlib.Path(dst)
    if format is not None:
        _kind(dst, "output")
        if dst.suffix.lower() in _SERIES:
            raise SampleFileError(f"{dst}: a series is written from a LAMMPS dump (.dump/.lammpstrj) only")
        return write_sample(dst, read_sample(src, format=format, **kw))
    sext, dext = _kind(src, "input"), _kind(dst, "output")
    if sext in (".dump", ".lammpstrj"):
        return _dump_series(src, dst, dext, sample)
    if dext in _SERIES:
        raise SampleFileError(f"{dst}: a {dext} series is written from a LAMMPS dump (.dump/.lammpstrj) only")
    return write_sample(dst, read_sample(src, **kw))


_SERIES = (".pvd", ".vtkhdf")


def _dump_series(src: pathlib.Path, dst: pathlib.Path, dext: str, sample) -> list[pathlib.Path]:
    if dext not in _SERIES:
        raise SampleFileError(f"{dst}: a LAMMPS dump converts to a .pvd VTU series or a .vtkhdf series only")
    if sample is None:
        raise SampleFileError(f"{src}: converting a dump needs the sample (radii and bonds), e.g. --sample")
    ref = sample if isinstance(sample, Sample) else read_sample(sample)
    frames = [f for f in read_lammps_dump(src) if f.kind == "atoms"]
    if not frames:
        raise SampleFileError(f"{src}: no ATOMS frames")
    for f in frames:
        if len(f.ids) != ref.n_particles or np.any(f.ids != np.arange(1, ref.n_particles + 1)):
            raise SampleFileError(f"{src}: timestep {f.timestep} has atom IDs that are not 1..{ref.n_particles} "
                                  f"(the sample's particles)")
    positions = [_in_plane(src, f, ref) for f in frames]
    if dext == ".vtkhdf":
        with VTKHDFSeries(dst, ref) as series:
            for f, pos in zip(frames, positions):
                series.write(f.timestep, positions=pos)
        return [dst]
    series = VTUSeries(dst, ref)
    for f, pos in zip(frames, positions):
        series.write(f.timestep, positions=pos)
    return [series.path] + [dst.with_name(name) for _, name in series.steps]


def _in_plane(src, frame, ref: Sample) -> np.ndarray:
    """A dump frame's positions for the reference sample: ``[n, 2]`` for a 2D sample (a ``dimension 2`` run's
    atoms, all at one z), else as they are."""
    pos = np.asarray(frame.positions, np.float64)
    if ref.dim == 3 or pos.shape[1] == 2:
        return pos
    if np.any(pos[:, 2] != pos[0, 2]):
        raise SampleFileError(f"{src}: timestep {frame.timestep} has atoms at different z, but the sample is 2D "
                              f"(discs; a LAMMPS dimension 2 run keeps every z = 0)")
    return pos[:, :2]
