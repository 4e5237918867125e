"""CSV samples: ``NAME.csv`` (particles, with each particle's type) and ``NAME_bonds.csv`` (bonds); see
:mod:`jaxbpm.interop.formats`.

A particles file written by jaxbpm ends with the comment line ``# crc32=XXXXXXXX bonds_crc32=YYYYYYYY``: the CRC-32
(zlib, 8 hex digits) of the particles file without that line, and of the whole bonds file. The reader checks both
when the line is there (a damaged, cut or swapped file is an error) and reads files without it (from other programs,
or with the line deleted after an intended hand edit) as they are."""

from __future__ import annotations

import csv
import pathlib
import re
from typing import NamedTuple

import numpy as np

from jaxbpm._atomic import atomic_write
from jaxbpm.errors import SampleFileError
from jaxbpm.interop import conventions
from jaxbpm.interop._meta import (checksums, crc32, domain_of, exact_text, meta_line, meta_of, names_file, parse_meta,
                                  read_text, verify, without_line)
from jaxbpm.interop.lammps import materials_from_bonds
from jaxbpm.sample import Sample


def _bonds_path(path: pathlib.Path) -> pathlib.Path:
    return path.with_name(f"{path.stem}_bonds{path.suffix}")


def write_csv(path, sample: Sample) -> tuple[pathlib.Path, pathlib.Path]:
    """Write particles to ``path`` and bonds to ``<stem>_bonds.csv`` next to it (both atomic; exact decimals).

    A two-dimensional sample (discs) has the columns ``id,x,y,radius,type`` (no ``z``), its thickness in the header
    comment.

    Args:
      path: the particles file.
      sample: the sample.

    Returns:
      The particles and bonds files.
    """
    if not isinstance(sample, Sample):
        raise TypeError(f"write_csv expects a jaxbpm Sample, got {type(sample).__name__}")
    path = pathlib.Path(path)
    bpath = _bonds_path(path)
    meta = meta_of(sample, bonds_file=bpath.name, particles=sample.n_particles, bonds=sample.n_bonds)
    pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
    types = np.ones(sample.n_particles, np.int64) if sample.types is None else np.asarray(sample.types, np.int64)
    axes = "xyz"[:pos.shape[1]]  # a 2D sample (discs): x,y only
    plines = [meta_line(meta), f"id,{','.join(axes)},radius,type"]
    plines += [f"{i}," + "".join(f"{exact_text(pos[i, c])}," for c in range(len(axes))) + f"{exact_text(rad[i])},"
               f"{types[i]}" for i in range(sample.n_particles)]
    b, rb, bm = np.asarray(sample.bonds), np.asarray(sample.bond_radius), np.asarray(sample.bond_material)
    m = sample.materials
    blines = ["i,j,bond_radius,material,E,nu,tensile_strength,shear_strength"]
    blines += [f"{b[k, 0]},{b[k, 1]},{exact_text(rb[k])},{bm[k]},{exact_text(m.E[bm[k]])},{exact_text(m.nu[bm[k]])},"
               f"{exact_text(m.tensile_strength[bm[k]])},{exact_text(m.shear_strength[bm[k]])}" for k in range(sample.n_bonds)]
    btext = "\n".join(blines) + "\n"
    ptext = "\n".join(plines) + "\n"
    ptext += f"# crc32={crc32(ptext)} bonds_crc32={crc32(btext)}\n"
    out_b = atomic_write(bpath, lambda tmp: pathlib.Path(tmp).write_text(btext, encoding="utf-8"))
    out_p = atomic_write(path, lambda tmp: pathlib.Path(tmp).write_text(ptext, encoding="utf-8"))
    return out_p, out_b


_CHECKSUM_LINE = re.compile(r"#\s*crc32=")


class _Rows(NamedTuple):
    """A CSV file read: its text, metadata, column names, ``(line number, values)`` rows and checksum line."""

    text: str
    meta: dict | None
    header: list[str]
    rows: list[tuple[int, list[str]]]
    crc_line: tuple[int, str] | None


def _csv_rows(path: pathlib.Path) -> _Rows:
    text = read_text(path)
    meta, rows, header, crc_line = None, [], None, None
    for no, line in enumerate(text.splitlines(), start=1):
        if line.lstrip().startswith("#"):
            if crc_line is None and _CHECKSUM_LINE.match(line.strip()):
                crc_line = (no, line)
            meta = meta or parse_meta(line.strip(), f"{path}:{no}")
            continue
        try:
            row = next(csv.reader([line]), [])
        except csv.Error as exc:
            raise SampleFileError(f"{path}:{no}: not a CSV line ({exc}): {line.strip()!r}") from None
        if not row or all(not c.strip() for c in row):
            continue
        if header is None:
            header = [c.strip() for c in row]
            continue
        if len(row) != len(header):
            raise SampleFileError(f"{path}:{no}: {len(row)} values, expected {len(header)} ({','.join(header)})")
        rows.append((no, [c.strip() for c in row]))
    if header is None:
        raise SampleFileError(f"{path}: no header line (column names)")
    return _Rows(text, meta, header, rows, crc_line)


def _whole_lines(path: pathlib.Path, text: str) -> None:
    """A file jaxbpm wrote ends with a line break: one that does not was cut in the middle of a line."""
    if text and not text.endswith(("\n", "\r")):
        last = text.splitlines()[-1]
        raise SampleFileError(f"{path}:{len(text.splitlines())}: the file ends in the middle of a line "
                              f"(truncated?): {last.strip()!r}")


def _column(path, header, rows, names, cast=float, required=True):
    for name in names:
        if name in header:
            c = header.index(name)
            out = np.zeros(len(rows), dtype=np.int64 if cast is int else np.float64)
            for k, (no, row) in enumerate(rows):
                try:
                    out[k] = cast(row[c])
                except (ValueError, OverflowError):
                    raise SampleFileError(f"{path}:{no}: column {name!r} must hold "
                                          f"{'whole numbers' if cast is int else 'numbers'}, got {row[c]!r}") from None
            return out, name
    if required:
        raise SampleFileError(f"{path}: missing column {' or '.join(repr(n) for n in names)} (columns: "
                              f"{','.join(header)})")
    return None, None


def _particles(path, header, rows) -> tuple[np.ndarray, np.ndarray, dict[int, int], np.ndarray | None]:
    """The particles file's centres ``[n, 3]`` (``[n, 2]`` without a ``z`` column: discs), radii ``[n]``,
    ``{particle id: row index}`` and types ``[n]`` (a ``type``, ``group`` or ``material`` column; ``None`` without
    one)."""
    axes = "xyz" if "z" in header or "Z" in header else "xy"
    pos = np.stack([_column(path, header, rows, (c, c.upper()))[0] for c in axes], axis=1)
    rad, rname = _column(path, header, rows, ("radius", "r", "diameter", "d"))
    if rname in ("diameter", "d"):
        rad = rad / 2.0
    ids, _ = _column(path, header, rows, ("id", "ID"), cast=int, required=False)
    if ids is None:
        ids = np.arange(len(rows))
    index = {}
    for k, (no, _) in enumerate(rows):
        if int(ids[k]) in index:
            raise SampleFileError(f"{path}:{no}: duplicate particle id {ids[k]}")
        index[int(ids[k])] = k
    types, _ = _column(path, header, rows, ("type", "group", "material"), cast=int, required=False)
    return pos, rad, index, types


def _bond_pairs(path, bpath, bheader, brows, ends, index: dict[int, int]) -> np.ndarray:
    """The bonds ``[nb, 2]`` as particle row indices, from the bonds file's particle id columns ``ends``."""
    if not ends:
        raise SampleFileError(f"{bpath}: missing particle columns i,j (or id1,id2) (columns: {','.join(bheader)})")
    bonds = np.zeros((len(brows), 2), np.int64)
    for k, (no, _) in enumerate(brows):
        for c in range(2):
            pid = int(ends[c][k])
            if pid not in index:
                raise SampleFileError(f"{bpath}:{no}: bond refers to particle id {pid}, which is not in {path.name}")
            bonds[k, c] = index[pid]
    return bonds


def _check_bond_columns(bpath, brows, props: dict, bm: np.ndarray, mats: dict) -> None:
    """The bonds file's material property columns ``props`` agree with the metadata's table ``mats``."""
    for k, v in props.items():
        if v is not None and len(v):
            want = np.asarray(mats[k], float)[np.clip(bm, 0, len(mats[k]) - 1)]
            bad = np.flatnonzero(~((v == want) | (np.isnan(v) & np.isnan(want))))
            if bad.size:
                no = brows[bad[0]][0]
                raise SampleFileError(f"{bpath}:{no}: {k} = {float(v[bad[0]])!r} disagrees with material "
                                      f"{int(bm[bad[0]])}'s {float(want[bad[0]])!r} in the header")


@names_file
def read_csv(path, bonds_path=None, *, bond_radius_ratio: float | None = None, **sample_kw) -> Sample:
    """Read particles (``path``) and bonds (``bonds_path``, default ``<stem>_bonds.csv`` beside it, else the bonds
    file named in the particles file's metadata) CSV files.

    See the module docstring for the columns. A particles file without a ``z`` column is a two-dimensional sample
    (discs; ``thickness=`` as a keyword, else the header comment's, else 1 m).

    Args:
      path: the particles file.
      bonds_path: the bonds file (default: see above).
      bond_radius_ratio: needed when the bonds file has no ``bond_radius``/``bond_diameter`` column.
      **sample_kw: more :meth:`Sample.from_arrays` keywords.

    Returns:
      The sample.

    Raises:
      SampleFileError: a missing or malformed file (the line is named).
      SampleError: the content does not make a valid sample.
    """
    path = pathlib.Path(path)
    prows = _csv_rows(path)
    meta, header, rows = prows.meta, prows.header, prows.rows
    if meta is not None:
        _whole_lines(path, prows.text)
    if not rows:
        raise SampleFileError(f"{path}: no particles")
    # the bonds file next to the particles file by its own name first (a copied or renamed pair of files reads its
    # own bonds), then the name stored in the metadata
    bpath = pathlib.Path(bonds_path) if bonds_path is not None else _bonds_path(path)
    if bonds_path is None and not bpath.exists() and meta and meta.get("bonds_file"):
        bpath = path.with_name(meta["bonds_file"])
    pos, rad, index, types = _particles(path, header, rows)
    kw = dict(sample_kw)
    kw.setdefault("types", types)
    if pos.shape[1] == 2 and meta is not None and "thickness" in meta:
        kw.setdefault("thickness", meta["thickness"])
    if meta is not None:
        kw.setdefault("particle_material", meta["particle_material"])
        kw.setdefault("bond_contact", meta["bond_contact"])
        kw.setdefault("domain", domain_of(meta))
    sums = None
    if prows.crc_line is not None:
        no, line = prows.crc_line
        sums = checksums(line, f"{path}:{no}", ("crc32", "bonds_crc32"))
    if not bpath.exists():
        if meta is not None or sums is not None:
            raise SampleFileError(f"{bpath}: no such file (the bonds of {path})")
        return Sample.from_arrays(pos, rad, np.zeros((0, 2), int), np.zeros(0), **kw)
    if bpath.is_dir():
        raise SampleFileError(f"{bpath}: is a directory, not the bonds file of {path}")
    brows_all = _csv_rows(bpath)
    bheader, brows = brows_all.header, brows_all.rows
    if meta is not None:
        _whole_lines(bpath, brows_all.text)
    nb = len(brows)
    # the counts the metadata declares (files written by jaxbpm) must be what was read: a cut file is an error
    for what, declared, read, where in (("particles", meta and meta.get("particles"), len(rows), path),
                                        ("bonds", meta and meta.get("bonds"), nb, bpath)):
        if declared is not None and int(declared) != read:
            raise SampleFileError(f"{where}: {read} {what} read, but {path.name}'s metadata declares {declared} "
                                  "(truncated or edited?)")
    ends = []
    for pair in (("i", "j"), ("id1", "id2"), ("particle1", "particle2")):
        if pair[0] in bheader:
            ends = [_column(bpath, bheader, brows, (p,), cast=int)[0] for p in pair]
            break
    if sums is not None:  # the files read well: are they the ones jaxbpm wrote?
        no, line = prows.crc_line
        how = f"delete line {no} ({line.strip()!r}) of {path.name}"
        verify(without_line(prows.text, no - 1), "crc32", sums["crc32"], path, f"line {no}", how)
        verify(brows_all.text, "bonds_crc32", sums["bonds_crc32"], bpath, f"line {no} of {path.name}", how)
    bonds = _bond_pairs(path, bpath, bheader, brows, ends, index)
    rb, rbname = _column(bpath, bheader, brows, ("bond_radius", "bond_diameter"), required=False)
    if rbname == "bond_diameter":
        rb = rb / 2.0
    if rb is None and bond_radius_ratio is None:
        raise SampleFileError(f"{bpath}: no bond_radius or bond_diameter column; give bond_radius_ratio=")
    geom = {"bond_radius_ratio": bond_radius_ratio} if rb is None else {"bond_radius": rb}
    bm, _ = _column(bpath, bheader, brows, ("material",), cast=int, required=False)
    props = {k: _column(bpath, bheader, brows, (k,), required=False)[0]
             for k in ("E", "nu", "tensile_strength", "shear_strength")}
    if meta is not None and bm is not None and "materials" not in kw:
        mats = meta["materials"]
        _check_bond_columns(bpath, brows, props, bm, mats)
        return Sample.from_arrays(pos, rad, bonds, bond_material=bm, materials=mats, **geom, **kw)
    if "materials" in kw:
        return Sample.from_arrays(pos, rad, bonds, bond_material=bm, **geom, **kw)
    defaults = {"E": 1.0e9, "nu": 0.25, "tensile_strength": np.inf, "shear_strength": np.inf}
    cols = {k: (v if v is not None else np.full(nb, defaults[k])) for k, v in props.items()}
    mats, bm_auto = materials_from_bonds(conventions.JaxbpmBond(cols["E"], cols["nu"], np.ones(nb),
                                                                 cols["tensile_strength"], cols["shear_strength"]))
    return Sample.from_arrays(pos, rad, bonds, bond_material=bm_auto, materials=mats, **geom, **kw)
