"""CSV samples: ``NAME.csv`` (particles) and ``NAME_bonds.csv`` (bonds); see :mod:`jaxbpm.interop.formats`."""

from __future__ import annotations

import csv
import pathlib

import numpy as np

from jaxbpm.interop import conventions
from jaxbpm.errors import SampleFileError
from jaxbpm.io import atomic_write
from jaxbpm.sample import Sample
from jaxbpm.interop._meta import _r, _meta, _meta_line, _parse_meta, _domain
from jaxbpm.interop.lammps import _materials_from_bonds
from jaxbpm.interop.lammps import _read_text


def _bonds_path(path: pathlib.Path) -> pathlib.Path:
    return path.with_name(f"{path.stem}_bonds{path.suffix}")


def write_csv(path, sample: Sample) -> tuple[pathlib.Path, pathlib.Path]:
    """Write particles to ``path`` and bonds to ``<stem>_bonds.csv`` next to it (both atomic; exact decimals).

    Returns the two paths.
    """
    if not isinstance(sample, Sample):
        raise TypeError(f"write_csv expects a jaxbpm Sample, got {type(sample).__name__}")
    path = pathlib.Path(path)
    bpath = _bonds_path(path)
    meta = _meta(sample, bonds_file=bpath.name, particles=sample.n_particles, bonds=sample.n_bonds)
    pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
    plines = [_meta_line(meta), "id,x,y,z,radius"]
    plines += [f"{i},{_r(pos[i, 0])},{_r(pos[i, 1])},{_r(pos[i, 2])},{_r(rad[i])}" for i in range(sample.n_particles)]
    b, rb, bm = np.asarray(sample.bonds), np.asarray(sample.bond_radius), np.asarray(sample.bond_material)
    m = sample.materials
    blines = ["i,j,bond_radius,material,E,nu,tensile_strength,shear_strength"]
    blines += [f"{b[k, 0]},{b[k, 1]},{_r(rb[k])},{bm[k]},{_r(m.E[bm[k]])},{_r(m.nu[bm[k]])},"
               f"{_r(m.tensile_strength[bm[k]])},{_r(m.shear_strength[bm[k]])}" for k in range(sample.n_bonds)]
    out_b = atomic_write(bpath, lambda tmp: pathlib.Path(tmp).write_text("\n".join(blines) + "\n"))
    out_p = atomic_write(path, lambda tmp: pathlib.Path(tmp).write_text("\n".join(plines) + "\n"))
    return out_p, out_b


def _csv_rows(path: pathlib.Path) -> tuple[dict | None, list[str], list[tuple[int, list[str]]]]:
    text = _read_text(path)
    meta, rows, header = None, [], None
    for no, line in enumerate(text.splitlines(), start=1):
        if line.lstrip().startswith("#"):
            meta = meta or _parse_meta(line.strip(), f"{path}:{no}")
            continue
        row = next(csv.reader([line]), [])
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
    return meta, header, rows


def _column(path, header, rows, names, cast=float, required=True):
    for name in names:
        if name in header:
            c = header.index(name)
            out = []
            for no, row in rows:
                try:
                    out.append(cast(row[c]))
                except ValueError:
                    raise SampleFileError(f"{path}:{no}: column {name!r} must hold "
                                          f"{'whole numbers' if cast is int else 'numbers'}, got {row[c]!r}") from None
            return np.asarray(out, dtype=np.int64 if cast is int else np.float64), name
    if required:
        raise SampleFileError(f"{path}: missing column {' or '.join(repr(n) for n in names)} (columns: "
                              f"{','.join(header)})")
    return None, None


def read_csv(path, bonds_path=None, *, bond_radius_ratio: float | None = None, **sample_kw) -> Sample:
    """Read particles (``path``) and bonds (``bonds_path``, default ``<stem>_bonds.csv`` beside it, else the bonds
    file named in the particles file's metadata) CSV files.

    See the module docstring for the columns. ``bond_radius_ratio`` is needed when the bonds file has no
    ``bond_radius``/``bond_diameter`` column; ``sample_kw`` go to :meth:`Sample.from_arrays`.
    """
    path = pathlib.Path(path)
    meta, header, rows = _csv_rows(path)
    if not rows:
        raise SampleFileError(f"{path}: no particles")
    # the bonds file next to the particles file by its own name first (a copied or renamed pair of files reads its
    # own bonds), then the name stored in the metadata
    bpath = pathlib.Path(bonds_path) if bonds_path is not None else _bonds_path(path)
    if bonds_path is None and not bpath.exists() and meta and meta.get("bonds_file"):
        bpath = path.with_name(meta["bonds_file"])
    pos = np.stack([_column(path, header, rows, (c, c.upper()))[0] for c in "xyz"], axis=1)
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
    kw = dict(sample_kw)
    if meta is not None:
        kw.setdefault("particle_material", meta["particle_material"])
        kw.setdefault("bond_contact", meta["bond_contact"])
        kw.setdefault("domain", _domain(meta))
    if not bpath.exists():
        if meta is not None:
            raise SampleFileError(f"{bpath}: no such file (the bonds of {path})")
        return Sample.from_arrays(pos, rad, np.zeros((0, 2), int), np.zeros(0), **kw)
    _, bheader, brows = _csv_rows(bpath)
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
    if not ends:
        raise SampleFileError(f"{bpath}: missing particle columns i,j (or id1,id2) (columns: {','.join(bheader)})")
    bonds = np.zeros((nb, 2), np.int64)
    for k, (no, _) in enumerate(brows):
        for c in range(2):
            pid = int(ends[c][k])
            if pid not in index:
                raise SampleFileError(f"{bpath}:{no}: bond refers to particle id {pid}, which is not in {path.name}")
            bonds[k, c] = index[pid]
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
        for k, v in props.items():
            if v is not None and len(v):
                want = np.asarray(mats[k], float)[np.clip(bm, 0, len(mats[k]) - 1)]
                bad = np.flatnonzero(~((v == want) | (np.isnan(v) & np.isnan(want))))
                if bad.size:
                    no = brows[bad[0]][0]
                    raise SampleFileError(f"{bpath}:{no}: {k} = {v[bad[0]]!r} disagrees with material "
                                          f"{bm[bad[0]]}'s {want[bad[0]]!r} in the header")
        return Sample.from_arrays(pos, rad, bonds, bond_material=bm, materials=mats, **geom, **kw)
    if "materials" in kw:
        return Sample.from_arrays(pos, rad, bonds, bond_material=bm, **geom, **kw)
    defaults = {"E": 1.0e9, "nu": 0.25, "tensile_strength": np.inf, "shear_strength": np.inf}
    cols = {k: (v if v is not None else np.full(nb, defaults[k])) for k, v in props.items()}
    mats, bm_auto = _materials_from_bonds(conventions.JaxbpmBond(cols["E"], cols["nu"], np.ones(nb),
                                                                 cols["tensile_strength"], cols["shear_strength"]))
    return Sample.from_arrays(pos, rad, bonds, bond_material=bm_auto, materials=mats, **geom, **kw)
