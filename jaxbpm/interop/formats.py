"""Exchange formats: LAMMPS data and dump files, CSV particles + bonds, VTU time series for ParaView.

All writers are atomic (a temporary file next to the target, renamed onto it when complete). Readers raise
:class:`~jaxbpm.errors.SampleFileError` naming the file and line of a malformed entry.

Checksums: jaxbpm's text files carry a CRC-32 (zlib) of what they hold -- a LAMMPS data file at the end of its title
line (``crc32=XXXXXXXX``, of the text after that line), a CSV pair on the last line of the particles file (``#
crc32=XXXXXXXX bonds_crc32=YYYYYYYY``, of the particles file without that line and of the bonds file). The readers
check them, so a damaged, cut or swapped file is an error, not a silently different sample; files without them (from
other programs) are read as they are. To accept an intended hand edit, delete the checksum (the error says where).

LAMMPS data (:func:`write_lammps_data`, :func:`read_lammps_data`)
    ``atom_style bpm/sphere`` (``id mol type diameter density x y z``; ``sphere``: ``id type diameter density x y
    z``; optional image flags), ``Bonds`` (``id type atom1 atom2``) and a ``Bond Coeffs # bpm/rotational`` section
    (``type Kr Ks Kt Kb Fcr Fcs Tct Tcb gamma_r gamma_s gamma_t gamma_b``, see :mod:`jaxbpm.interop.conventions`). LAMMPS
    can only define ``bond_style bpm/rotational`` after the box exists, so read the file in LAMMPS with
    ``read_data FILE nocoeff`` followed by the ``bond_style``/``bond_coeff`` lines of :func:`write_lammps_coeffs`.
    jaxbpm also writes its exact parameters as comments (a ``# jaxbpm {...}`` JSON header line; per bond ``#
    bond_radius material``), which LAMMPS ignores and which make jaxbpm -> LAMMPS data -> jaxbpm exact. Files
    without them are translated from the coefficients (one material component per distinct (E, nu, strengths)).
LAMMPS dump (:func:`read_lammps_dump`)
    text dumps: ``ITEM: ATOMS`` frames (positions from x/y/z, xu/yu/zu or scaled xs/ys/zs, any other columns) and
    ``ITEM: ENTRIES`` frames of ``dump local`` (bond lists from ``compute property/local batom1 batom2 btype``).
CSV (:func:`write_csv`, :func:`read_csv`)
    ``NAME.csv`` (particles: ``id,x,y,z,radius``) and ``NAME_bonds.csv`` (``i,j,bond_radius,material,E,nu,
    tensile_strength,shear_strength``, i and j particle ids); a ``# jaxbpm {...}`` first line keeps what the columns
    cannot (particle material, material table, bond_contact, domain). Foreign files may use ``diameter`` instead of
    ``radius``, ``bond_diameter`` instead of ``bond_radius``, ``id1,id2`` instead of ``i,j``, and may leave out the
    material columns (then one component per distinct (E, nu, strengths), defaults 1 GPa, 0.25, unbreakable).
VTU series (:class:`VTUSeries`, :func:`write_vtu_series`)
    one ``.vtu`` per time (meshio) and a ``.pvd`` collection for ParaView.
"""

from __future__ import annotations

import pathlib

import numpy as np

from jaxbpm.errors import SampleFileError
from jaxbpm.interop.csvfiles import read_csv, write_csv
from jaxbpm.interop.dump import DumpFrame, read_lammps_dump
from jaxbpm.interop.lammps import (lammps_coefficients, read_lammps_coeffs, read_lammps_data, write_lammps_coeffs,
                                   write_lammps_data)
from jaxbpm.interop.vtu import VTUSeries, write_vtu_series
from jaxbpm.io import export_vtk, load_sample, save_sample
from jaxbpm.sample import Sample

__all__ = ["write_lammps_data", "read_lammps_data", "write_lammps_coeffs", "read_lammps_coeffs", "lammps_coefficients",
           "read_lammps_dump", "DumpFrame", "write_csv", "read_csv", "VTUSeries", "write_vtu_series", "read_sample",
           "write_sample", "convert", "FORMATS"]



FORMATS = {".h5": "jaxbpm HDF5 sample", ".hdf5": "jaxbpm HDF5 sample", ".data": "LAMMPS data file",
           ".lmp": "LAMMPS data file", ".csv": "CSV particles + <stem>_bonds.csv",
           ".vtu": "VTK XML (write only)", ".vtk": "legacy VTK (write only)",
           ".pvd": "VTU time series from a LAMMPS dump (write only, needs a sample)",
           ".dump": "LAMMPS text dump (read only, to .pvd)", ".lammpstrj": "LAMMPS text dump (read only, to .pvd)"}


def _kind(path: pathlib.Path, what: str) -> str:
    ext = path.suffix.lower()
    if ext not in FORMATS:
        raise SampleFileError(f"{path}: cannot tell the format from the suffix {ext!r}; known: "
                              f"{', '.join(sorted(FORMATS))}")
    return ext


def read_sample(path, **kw) -> Sample:
    """Read a sample from any readable format, chosen by suffix (``.h5``, ``.data``/``.lmp``, ``.csv``)."""
    path = pathlib.Path(path)
    ext = _kind(path, "input")
    if ext in (".h5", ".hdf5"):
        return load_sample(path)
    if ext in (".data", ".lmp"):
        return read_lammps_data(path, **kw)
    if ext == ".csv":
        return read_csv(path, **kw)
    raise SampleFileError(f"{path}: {FORMATS[ext]} is not a sample format that can be read")


def write_sample(path, sample: Sample, **kw) -> list[pathlib.Path]:
    """Write a sample in the format chosen by suffix (``.h5``, ``.data``/``.lmp``, ``.csv``, ``.vtu``/``.vtk``);
    returns the files written."""
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


def convert(src, dst, *, sample=None, **kw) -> list[pathlib.Path]:
    """Convert ``src`` to ``dst``, formats by suffix. A LAMMPS dump (``.dump``/``.lammpstrj``) converts to a
    ``.pvd`` VTU series and needs ``sample`` (a Sample or a sample file) for radii and bonds; its atom IDs must be
    particle index + 1 (as :func:`write_lammps_data` numbers them). Returns the files written."""
    src, dst = pathlib.Path(src), pathlib.Path(dst)
    sext, dext = _kind(src, "input"), _kind(dst, "output")
    if sext in (".dump", ".lammpstrj"):
        if dext != ".pvd":
            raise SampleFileError(f"{dst}: a LAMMPS dump converts to a .pvd VTU series only")
        if sample is None:
            raise SampleFileError(f"{src}: converting a dump needs the sample (radii and bonds), e.g. --sample")
        ref = sample if isinstance(sample, Sample) else read_sample(sample)
        frames = [f for f in read_lammps_dump(src) if f.kind == "atoms"]
        series = VTUSeries(dst, ref)
        for f in frames:
            if len(f.ids) != ref.n_particles or np.any(f.ids != np.arange(1, ref.n_particles + 1)):
                raise SampleFileError(f"{src}: timestep {f.timestep} has atom IDs that are not 1..{ref.n_particles} "
                                      f"(the sample's particles)")
            series.write(f.timestep, positions=f.positions)
        if not series.steps:
            raise SampleFileError(f"{src}: no ATOMS frames")
        return [series.path] + [dst.with_name(name) for _, name in series.steps]
    if dext == ".pvd":
        raise SampleFileError(f"{dst}: a .pvd series is written from a LAMMPS dump (.dump/.lammpstrj) only")
    return write_sample(dst, read_sample(src, **kw))
