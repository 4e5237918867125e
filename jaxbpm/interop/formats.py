"""Exchange formats: LAMMPS data and dump files, CSV particles + bonds, VTU time series for ParaView.

All writers are atomic (a temporary file next to the target, renamed onto it when complete). Readers raise
:class:`~jaxbpm.errors.SampleFileError` naming the file and line of a malformed entry.

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

import csv
import dataclasses
import json
import pathlib
import re
import warnings
from typing import Any, Iterable, Mapping

import numpy as np

from jaxbpm.interop import conventions
from jaxbpm.errors import SampleError, SampleFileError
from jaxbpm.io import atomic_write, _user_data, load_sample, save_sample, export_vtk
from jaxbpm.sample import Domain, ParticleMaterial, Sample

__all__ = ["write_lammps_data", "read_lammps_data", "write_lammps_coeffs", "read_lammps_coeffs", "lammps_coefficients",
           "read_lammps_dump", "DumpFrame", "write_csv", "read_csv", "VTUSeries", "write_vtu_series", "read_sample",
           "write_sample", "convert", "FORMATS"]

_META = "# jaxbpm "
_N_COEFFS = 12  # Kr Ks Kt Kb Fcr Fcs Tct Tcb gamma_r gamma_s gamma_t gamma_b
_BIG = 1.0e300  # LAMMPS thresholds for unbreakable bonds (LAMMPS needs finite numbers)


def _r(x) -> str:
    """Shortest exact decimal of a float."""
    return repr(float(x))


def _meta(sample: Sample, **extra) -> dict:
    from jaxbpm._version import __version__

    pm = sample.particle_material
    m = sample.materials
    out = {"format": "jaxbpm-exchange", "version": 1, "jaxbpm": __version__, "bond_contact": sample.bond_contact,
           "particle_material": {f.name: float(getattr(pm, f.name)) for f in dataclasses.fields(pm)},
           "materials": {k: [float(v) for v in np.asarray(getattr(m, k))] for k in
                         ("E", "nu", "tensile_strength", "shear_strength")},
           "domain": None if sample.domain is None else
           {"kind": sample.domain.kind, "lo": list(map(float, sample.domain.lo)),
            "hi": list(map(float, sample.domain.hi))}}
    out.update(extra)
    return out


def _meta_line(meta: dict) -> str:
    return _META + json.dumps(meta, separators=(",", ":"))


def _parse_meta(text: str, where: str) -> dict | None:
    if not text.startswith(_META):
        return None
    try:
        meta = json.loads(text[len(_META):])
    except ValueError as exc:
        raise SampleFileError(f"{where}: unreadable jaxbpm header comment ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != "jaxbpm-exchange":
        raise SampleFileError(f"{where}: the '# jaxbpm' header comment is not a jaxbpm exchange header")
    return meta


def _domain(meta: dict | None):
    d = None if meta is None else meta.get("domain")
    return None if d is None else Domain(d["kind"], tuple(d["lo"]), tuple(d["hi"]))


# ============================================================================================== LAMMPS data
def lammps_coefficients(sample: Sample, *, normalize: bool = False) -> np.ndarray:
    """Per-bond ``bpm/rotational`` coefficients ``[nb, 12]`` (Kr Ks Kt Kb Fcr Fcs Tct Tcb, dampings 0) of a sample,
    exact translations of its bond law (:func:`jaxbpm.interop.conventions.to_lammps`); infinite strengths become 1e300."""
    bond, length, _, _ = conventions.sample_bonds(sample)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", conventions.InexactTranslationWarning)  # stated in the docs
        p = conventions.to_lammps(bond, length, normalize=normalize)
    c = p.coefficients().reshape(-1, 8)
    c = np.where(np.isfinite(c), c, _BIG)
    return np.concatenate([c, np.zeros((c.shape[0], 4))], axis=1)


def _group_types(coeffs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """1-based type per bond (bonds with bit-identical coefficients share one, numbered by first appearance) and
    the ``[ntypes, 12]`` table."""
    if len(coeffs) == 0:
        return np.zeros(0, np.int64), np.zeros((0, _N_COEFFS))
    keys = np.ascontiguousarray(coeffs).view(np.dtype((np.void, coeffs.dtype.itemsize * coeffs.shape[1]))).ravel()
    _, first, inv = np.unique(keys, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return rank[inv.reshape(-1)] + 1, coeffs[first[order]]


def _coeff_line(t: int, row) -> str:
    return f"{t} " + " ".join(_r(v) for v in row)


def write_lammps_coeffs(path, table, *, bond_style: str | None = "bpm/rotational break yes smooth no") -> pathlib.Path:
    """Write an include file for a LAMMPS input: an optional ``bond_style`` line, then one ``bond_coeff`` line per
    row of ``table`` (``[ntypes, 8 or 12]``; missing dampings are 0). ``bond_style=None`` writes coefficients only."""
    table = np.asarray(table, dtype=np.float64)
    if table.ndim != 2 or table.shape[1] not in (8, _N_COEFFS):
        raise SampleError(f"bond coefficient table must have shape [ntypes, 8] or [ntypes, 12], got {table.shape}")
    if table.shape[1] == 8:
        table = np.concatenate([table, np.zeros((len(table), 4))], axis=1)
    lines = [] if bond_style is None else [f"bond_style {bond_style}"]
    lines += ["bond_coeff " + _coeff_line(t, row) for t, row in enumerate(table, start=1)]

    def write(tmp):
        pathlib.Path(tmp).write_text("\n".join(lines) + "\n")

    return atomic_write(path, write)


def read_lammps_coeffs(path) -> tuple[dict[int, np.ndarray], bool]:
    """``bond_coeff`` lines of a LAMMPS input file: ``({type: 12 coefficients}, normalize)`` (``normalize`` from a
    ``bond_style bpm/rotational ... normalize yes`` line). Errors name the line."""
    path = pathlib.Path(path)
    text = _read_text(path)
    coeffs, normalize = {}, False
    for no, raw in enumerate(text.splitlines(), start=1):
        words = raw.split("#", 1)[0].split()
        if not words:
            continue
        if words[0] == "bond_style":
            if len(words) < 2 or words[1] != "bpm/rotational":
                raise SampleFileError(f"{path}:{no}: bond_style {' '.join(words[1:])!r} is not bpm/rotational")
            kw = words[2:]
            normalize = "normalize" in kw and kw.index("normalize") + 1 < len(kw) and \
                kw[kw.index("normalize") + 1] in ("yes", "1", "true")
        elif words[0] == "bond_coeff":
            t, row = _coeff_row(words[1:], f"{path}:{no}")
            coeffs[t] = row
    return coeffs, normalize


def _coeff_row(words: list[str], where: str) -> tuple[int, np.ndarray]:
    if len(words) not in (9, 13):
        raise SampleFileError(f"{where}: bpm/rotational coefficients need a type and 12 values (Kr Ks Kt Kb Fcr Fcs "
                              f"Tct Tcb gamma_r gamma_s gamma_t gamma_b) or 8 without dampings; got "
                              f"{len(words) - 1} values")
    try:
        t = int(words[0])
        row = np.array([float(w) for w in words[1:]])
    except ValueError:
        raise SampleFileError(f"{where}: bond coefficients must be a type number and numbers, got "
                              f"{' '.join(words)!r}") from None
    if len(row) == 8:
        row = np.concatenate([row, np.zeros(4)])
    return t, row


def write_lammps_data(path, sample: Sample, *, normalize: bool = False, atom_types=None, bond_types=None,
                      coefficients: bool = True, title: str | None = None) -> pathlib.Path:
    """Write ``sample`` as a LAMMPS data file (``atom_style bpm/sphere``, units si), atomically.

    Args:
      path: the data file. Atom IDs are particle index + 1, bond IDs bond index + 1.
      sample: the sample.
      normalize: coefficients for ``bond_style bpm/rotational normalize yes`` (Kr, Ks multiplied by L).
      atom_types: ``[n]`` LAMMPS atom type per particle (default all 1), e.g. to make groups.
      bond_types: ``[nb]`` 1-based bond type per bond (default: bonds with identical coefficients share a type).
        Bonds forced into one type get the coefficients of its first bond (a warning states the largest
        difference).
      coefficients: write the ``Bond Coeffs # bpm/rotational`` section (read it in LAMMPS with ``nocoeff`` and
        include :func:`write_lammps_coeffs`'s lines instead, since the bond style must follow the box).
      title: first line of the file.

    Returns:
      ``path`` as a :class:`pathlib.Path`.
    """
    if not isinstance(sample, Sample):
        raise TypeError(f"write_lammps_data expects a jaxbpm Sample, got {type(sample).__name__}")
    n, nb = sample.n_particles, sample.n_bonds
    pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
    b = np.asarray(sample.bonds)
    coeffs = lammps_coefficients(sample, normalize=normalize) if nb else np.zeros((0, _N_COEFFS))
    if bond_types is None:
        btype, table = _group_types(coeffs)
    else:
        btype = np.asarray(bond_types).astype(np.int64).reshape(-1)
        if btype.shape != (nb,) or (nb and btype.min() < 1):
            raise SampleError(f"bond_types must hold {nb} types >= 1, got shape {btype.shape}")
        ntype = int(btype.max()) if nb else 0
        table = np.zeros((ntype, _N_COEFFS))
        first = np.full(ntype, -1)
        for k in range(nb - 1, -1, -1):
            first[btype[k] - 1] = k
        used = first >= 0
        table[used] = coeffs[first[used]]
        if nb:
            off = np.max(np.abs(coeffs - table[btype - 1]) / np.maximum(np.abs(coeffs), 1e-300))
            if coefficients and off > 1e-12:
                warnings.warn(f"bond types given to write_lammps_data merge bonds whose coefficients differ by up to "
                              f"{100 * off:.3g} %; each type gets its first bond's coefficients",
                              conventions.InexactTranslationWarning, stacklevel=2)
    atype = np.ones(n, np.int64) if atom_types is None else np.asarray(atom_types).astype(np.int64).reshape(-1)
    if atype.shape != (n,) or atype.min() < 1:
        raise SampleError(f"atom_types must hold {n} types >= 1, got shape {atype.shape}")
    density = float(sample.particle_material.density)
    pad = 10.0 * rad.max()
    lo, hi = pos.min(axis=0) - pad, pos.max(axis=0) + pad
    from jaxbpm._version import __version__

    lines = [title or f"LAMMPS data file (atom_style bpm/sphere, bond_style bpm/rotational, units si) written by "
                      f"jaxbpm {__version__}",
             _meta_line(_meta(sample, normalize=bool(normalize))), "",
             f"{n} atoms", f"{int(atype.max())} atom types", f"{nb} bonds", f"{max(len(table), 1)} bond types", "",
             *(f"{_r(lo[c])} {_r(hi[c])} {a}lo {a}hi" for c, a in enumerate("xyz")), "",
             "Atoms # bpm/sphere", ""]
    lines += [f"{i + 1} 1 {atype[i]} {_r(2.0 * rad[i])} {_r(density)} {_r(pos[i, 0])} {_r(pos[i, 1])} {_r(pos[i, 2])}"
              for i in range(n)]
    if coefficients and len(table):
        lines += ["", "Bond Coeffs # bpm/rotational", ""]
        lines += [_coeff_line(t, row) for t, row in enumerate(table, start=1)]
    if nb:
        rb, bm = np.asarray(sample.bond_radius), np.asarray(sample.bond_material)
        lines += ["", "Bonds", ""]
        lines += [f"{k + 1} {btype[k]} {b[k, 0] + 1} {b[k, 1] + 1} # {_r(rb[k])} {bm[k]}" for k in range(nb)]

    def write(tmp):
        pathlib.Path(tmp).write_text("\n".join(lines) + "\n")

    return atomic_write(path, write)


def _read_text(path: pathlib.Path) -> str:
    if not path.exists():
        raise SampleFileError(f"{path}: no such file")
    if path.is_dir():
        raise SampleFileError(f"{path}: is a directory, not a file")
    try:
        return path.read_text()
    except UnicodeDecodeError as exc:
        raise SampleFileError(f"{path}: not a text file ({exc})") from None


_SECTIONS = {"Atoms": "atoms", "Velocities": "atoms", "Masses": "atom types", "Bonds": "bonds",
             "Bond Coeffs": "bond types", "Pair Coeffs": "atom types", "Angles": "angles", "Dihedrals": "dihedrals",
             "Impropers": "impropers", "Ellipsoids": "ellipsoids", "Lines": "lines", "Triangles": "triangles",
             "Bodies": "bodies", "Angle Coeffs": "angle types", "Dihedral Coeffs": "dihedral types",
             "Improper Coeffs": "improper types"}
_HEADER = re.compile(r"^\s*([-+0-9.eE]+)(?:\s+([-+0-9.eE]+))?(?:\s+([-+0-9.eE]+))?\s+([a-z][a-z /]*[a-z])\s*$")
_ATOM_COLUMNS = {"bpm/sphere": 8, "sphere": 7}


@dataclasses.dataclass(frozen=True)
class _Line:
    no: int
    words: list[str]
    comment: str


def read_lammps_data(path, *, coeffs=None, normalize: bool | None = None, atom_style: str | None = None,
                     breaking: bool = True, bond_radius_ratio: float | None = None,
                     materials: Mapping[str, Any] | None = None, **sample_kw) -> Sample:
    """Read a LAMMPS data file with spheres and bonds into a :class:`Sample`.

    Particles are ordered by atom ID. Bond parameters come, in this order of preference, from jaxbpm's own comments
    (exact, when they agree with the coefficients), from ``Bond Coeffs`` / ``coeffs`` translated by
    :func:`jaxbpm.interop.conventions.from_lammps`, or from ``bond_radius_ratio`` + ``materials`` (geometry only).

    Args:
      path: the data file.
      coeffs: an input file with ``bond_coeff`` lines (:func:`read_lammps_coeffs`) or ``{type: values}``; used
        when the data file has no ``Bond Coeffs`` section.
      normalize: whether the coefficients are for ``normalize yes`` (default: from the file's jaxbpm header or the
        coefficient file's ``bond_style`` line, else no).
      atom_style: ``"bpm/sphere"`` or ``"sphere"`` (default: from the ``Atoms # style`` comment or the column count).
      breaking: ``False`` ignores the failure thresholds (LAMMPS ``break no``).
      bond_radius_ratio, materials: ignore the coefficients; bond radius ratio and material table as in
        :meth:`Sample.from_arrays`.
      **sample_kw: more :meth:`Sample.from_arrays` keywords (``particle_material``, ``bond_contact``, ...).

    Raises:
      SampleFileError: the file is missing or malformed (the message names the line).
      SampleError: the content does not make a valid sample.
      ConventionError: the coefficients have no jaxbpm counterpart.
    """
    path = pathlib.Path(path)
    text = _read_text(path)
    raw = text.splitlines()
    meta = None
    for no, line in enumerate(raw[1:6], start=2):
        meta = meta or _parse_meta(line.strip(), f"{path}:{no}")
    # header
    counts: dict[str, int] = {}
    lines = [_Line(i + 1, *_split(s)) for i, s in enumerate(raw)]
    body_start = None
    for ln in lines[1:]:
        if not ln.words:
            continue
        name = " ".join(ln.words)
        if name in _SECTIONS:
            body_start = ln.no - 1
            break
        m = _HEADER.match(" ".join(ln.words))
        if not m:
            raise SampleFileError(f"{path}:{ln.no}: cannot read header line {raw[ln.no - 1].strip()!r}")
        key = m.group(4)
        if m.group(2) is None:
            try:
                counts[key] = int(m.group(1))
            except ValueError:
                raise SampleFileError(f"{path}:{ln.no}: the count of {key!r} must be a whole number") from None
    if body_start is None:
        raise SampleFileError(f"{path}: no Atoms section")
    for key in ("atoms",):
        if key not in counts:
            raise SampleFileError(f"{path}: header lacks the '{key}' count")
    sections: dict[str, tuple[_Line, list[_Line]]] = {}
    i = body_start
    while i < len(lines):
        ln = lines[i]
        if not ln.words:
            i += 1
            continue
        name = " ".join(ln.words)
        if name not in _SECTIONS:
            raise SampleFileError(f"{path}:{ln.no}: unknown section {raw[ln.no - 1].strip()!r} (or a "
                                  f"{'section line too many' if sections else 'misplaced line'})")
        want = counts.get(_SECTIONS[name], 0)
        rows, i = [], i + 1
        while len(rows) < want:
            if i >= len(lines):
                raise SampleFileError(f"{path}:{len(lines)}: section {name} ended after {len(rows)} of {want} lines")
            if lines[i].words:
                if " ".join(lines[i].words) in _SECTIONS:
                    raise SampleFileError(f"{path}:{lines[i].no}: section {name} ended after {len(rows)} of {want} "
                                          f"lines")
                rows.append(lines[i])
            i += 1
        sections[name] = (ln, rows)
    # a count the header declares is a section the file must hold (a file cut before its Bonds section would
    # otherwise read as a sample without bonds)
    for name, key in (("Atoms", "atoms"), ("Bonds", "bonds")):
        if counts.get(key, 0) > 0 and name not in sections:
            raise SampleFileError(f"{path}: the header declares {counts[key]} {key} but the file has no {name} section "
                                  "(truncated?)")
    if text and not text.endswith(("\n", "\r")) and raw[-1].split("#")[0].strip():
        raise SampleFileError(f"{path}:{len(raw)}: the file ends in the middle of a line (truncated?): "
                              f"{raw[-1].strip()!r}")
    # atoms
    head, rows = sections.get("Atoms", (None, []))
    style = atom_style or (head.comment.strip() if head is not None and head.comment.strip() else None)
    if style is not None and style not in _ATOM_COLUMNS:
        raise SampleFileError(f"{path}:{head.no if head else 1}: atom style {style!r} is not supported (bpm/sphere "
                              f"or sphere)")
    n = len(rows)
    if n == 0:
        raise SampleFileError(f"{path}: the Atoms section is empty")
    ids, dia, dens, pos = np.zeros(n, np.int64), np.zeros(n), np.zeros(n), np.zeros((n, 3))
    for k, ln in enumerate(rows):
        st = style or {7: "sphere", 10: "sphere", 8: "bpm/sphere", 11: "bpm/sphere"}.get(len(ln.words))
        ncol = _ATOM_COLUMNS.get(st)
        if ncol is None or len(ln.words) not in (ncol, ncol + 3):
            raise SampleFileError(
                f"{path}:{ln.no}: Atoms line has {len(ln.words)} values, expected 8 (bpm/sphere: id mol type "
                f"diameter density x y z) or 7 (sphere: id type diameter density x y z), optionally + 3 image flags")
        off = ncol - 7
        try:
            ids[k] = int(ln.words[0])
            dia[k], dens[k] = float(ln.words[2 + off]), float(ln.words[3 + off])
            pos[k] = [float(w) for w in ln.words[4 + off:7 + off]]
        except ValueError:
            raise SampleFileError(f"{path}:{ln.no}: Atoms line has a non-numeric value: "
                                  f"{raw[ln.no - 1].strip()!r}") from None
        if not (dia[k] > 0 and np.isfinite(dia[k])):
            raise SampleFileError(f"{path}:{ln.no}: atom {ids[k]} has diameter {dia[k]!r}; jaxbpm needs spheres "
                                  f"with a finite diameter > 0")
        if not np.all(np.isfinite(pos[k])):
            raise SampleFileError(f"{path}:{ln.no}: atom {ids[k]} has a coordinate that is not finite: "
                                  f"{raw[ln.no - 1].strip()!r}")
    order = np.argsort(ids, kind="stable")
    dup = np.flatnonzero(np.diff(ids[order]) == 0)
    if dup.size:
        raise SampleFileError(f"{path}:{rows[order[dup[0] + 1]].no}: duplicate atom ID {ids[order[dup[0]]]}")
    ids, dia, dens, pos = ids[order], dia[order], dens[order], pos[order]
    atom_line = np.array([rows[o].no for o in order])
    if np.any(dens != dens[0]):
        k = int(np.flatnonzero(dens != dens[0])[0])
        raise SampleFileError(f"{path}:{atom_line[k]}: atom density {dens[k]!r} differs from {dens[0]!r}; a jaxbpm "
                              f"sample has one particle density")
    index = {int(a): k for k, a in enumerate(ids)}
    # bonds
    _, brows = sections.get("Bonds", (None, []))
    nb = len(brows)
    bonds, btype = np.zeros((nb, 2), np.int64), np.zeros(nb, np.int64)
    rb_c, mat_c = np.full(nb, np.nan), np.full(nb, -1)
    for k, ln in enumerate(brows):
        if len(ln.words) != 4:
            raise SampleFileError(f"{path}:{ln.no}: Bonds line has {len(ln.words)} values, expected 4 (id type atom1 "
                                  f"atom2)")
        try:
            _, t, a1, a2 = (int(w) for w in ln.words)
        except ValueError:
            raise SampleFileError(f"{path}:{ln.no}: Bonds line must hold 4 whole numbers, got "
                                  f"{raw[ln.no - 1].strip()!r}") from None
        for a in (a1, a2):
            if a not in index:
                raise SampleFileError(f"{path}:{ln.no}: bond {ln.words[0]} refers to atom {a}, which is not in Atoms")
        if a1 == a2:
            raise SampleFileError(f"{path}:{ln.no}: bond {ln.words[0]} joins atom {a1} to itself")
        bonds[k], btype[k] = (index[a1], index[a2]), t
        extra = ln.comment.split()
        if len(extra) == 2:
            try:
                rb_c[k], mat_c[k] = float(extra[0]), int(extra[1])
            except ValueError:
                pass
    ntypes = counts.get("bond types", 0)
    if nb and (btype.min() < 1 or btype.max() > ntypes):
        k = int(np.flatnonzero((btype < 1) | (btype > ntypes))[0])
        raise SampleFileError(f"{path}:{brows[k].no}: bond type {btype[k]} is outside 1..{ntypes} (header 'bond "
                              f"types')")
    # coefficients
    table: dict[int, np.ndarray] = {}
    table_line: dict[int, int] = {}
    if "Bond Coeffs" in sections:
        head, crows = sections["Bond Coeffs"]
        if head.comment.strip() and head.comment.strip() != "bpm/rotational":
            raise SampleFileError(f"{path}:{head.no}: Bond Coeffs are for {head.comment.strip()!r}; jaxbpm reads "
                                  f"bpm/rotational")
        for ln in crows:
            t, row = _coeff_row(ln.words, f"{path}:{ln.no}")
            table[t], table_line[t] = row, ln.no
    if coeffs is not None:
        if isinstance(coeffs, (str, pathlib.Path)):
            extra_table, extra_norm = read_lammps_coeffs(coeffs)
            if normalize is None:
                normalize = extra_norm
        else:
            extra_table = {}
            for t, v in coeffs.items():
                _, extra_table[int(t)] = _coeff_row([str(t)] + [repr(float(x)) for x in v], f"coeffs[{t}]")
        table.update(extra_table)
    if normalize is None:
        normalize = bool(meta.get("normalize", False)) if meta else False
    kw = dict(sample_kw)
    if meta is not None:
        kw.setdefault("particle_material", meta["particle_material"])
        kw.setdefault("bond_contact", meta["bond_contact"])
        kw.setdefault("domain", _domain(meta))
    pm = kw.pop("particle_material", None) or {}
    if isinstance(pm, ParticleMaterial):
        pm = {f.name: getattr(pm, f.name) for f in dataclasses.fields(ParticleMaterial)}
    pm = dict(pm)
    pm["density"] = float(dens[0])
    radii = dia / 2.0
    if bond_radius_ratio is not None or materials is not None:
        if bond_radius_ratio is None:
            raise SampleError("read_lammps_data: materials= also needs bond_radius_ratio= (geometry only)")
        return Sample.from_arrays(pos, radii, bonds, bond_radius_ratio=bond_radius_ratio, materials=materials,
                                  particle_material=pm, **kw)
    if nb == 0:
        mats = meta["materials"] if meta else None
        return Sample.from_arrays(pos, radii, bonds, np.zeros(0), materials=mats, particle_material=pm, **kw)
    missing = sorted(set(btype.tolist()) - set(table))
    if missing:
        raise SampleFileError(f"{path}: no bpm/rotational coefficients for bond types {missing[:10]} (no Bond Coeffs "
                              f"section or coeffs= file); give coeffs=, or bond_radius_ratio= and materials=")
    coef = np.stack([table[t] for t in btype])
    length = np.linalg.norm(pos[bonds[:, 1]] - pos[bonds[:, 0]], axis=1)
    if meta is not None and not np.isnan(rb_c).any() and (mat_c >= 0).all():
        mats = meta["materials"]
        try:
            trial = Sample.from_arrays(pos, radii, bonds, rb_c, bond_material=mat_c, materials=mats,
                                       particle_material=pm, **kw)
        except SampleError:
            trial = None
        if trial is not None:
            mine = lammps_coefficients(trial, normalize=normalize)
            same = np.allclose(mine[:, :8], coef[:, :8], rtol=1e-9, atol=0)
            if same:
                return trial
            warnings.warn(f"{path}: jaxbpm's comments disagree with the bond coefficients; the coefficients (what "
                          f"LAMMPS uses) are translated instead", conventions.InexactTranslationWarning, stacklevel=2)
    if np.any(coef[:, 8:] != 0):
        t = int(btype[np.flatnonzero(np.any(coef[:, 8:] != 0, axis=1))[0]])
        warnings.warn(f"{path}: bond type {t} has bond damping (gamma) coefficients; jaxbpm's bonds are undamped and "
                      f"ignores them", conventions.InexactTranslationWarning, stacklevel=2)
    limits = np.where(coef[:, 4:8] >= 0.999 * _BIG, np.inf, coef[:, 4:8])  # jaxbpm's "unbreakable"
    p = conventions.LammpsBpmRotational(*(coef[:, c] for c in range(4)), *(limits[:, c] for c in range(4)),
                                        normalize=normalize)
    bond = conventions.from_lammps(p, length, breaking=breaking and bool(np.isfinite(limits).any()))
    mats, bm = _materials_from_bonds(bond)
    return Sample.from_arrays(pos, radii, bonds, bond.bond_radius, bond_material=bm, materials=mats,
                              particle_material=pm, **kw)


def _split(s: str) -> tuple[list[str], str]:
    body, _, comment = s.partition("#")
    return body.split(), comment


def _materials_from_bonds(bond: conventions.JaxbpmBond) -> tuple[dict, np.ndarray]:
    """One material component per distinct (E, nu, tensile, shear) (to 1e-12 relative), numbered by first bond."""
    cols = [np.broadcast_to(np.asarray(getattr(bond, k), float), np.shape(bond.bond_radius))
            for k in ("E", "nu", "tensile_strength", "shear_strength")]
    table = np.stack(cols, axis=1)
    scale = np.where(np.isfinite(table), np.abs(table), 1.0).max(axis=0)
    scale[scale == 0] = 1.0
    key = np.where(np.isfinite(table), np.round(table / scale * 1e12), np.inf)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    rows = table[first[order]]
    mats = {k: rows[:, c] for c, k in enumerate(("E", "nu", "tensile_strength", "shear_strength"))}
    return mats, rank[inv.reshape(-1)].astype(np.int32)


# ============================================================================================== LAMMPS dump
@dataclasses.dataclass(frozen=True)
class DumpFrame:
    """One frame of a LAMMPS text dump.

    timestep; box ``[3, 2]`` (lo, hi; orthogonal part of the bounds); kind: ``"atoms"`` or ``"local"``;
    columns: ``{name: [rows]}`` as float64 (IDs and types are whole numbers). For atoms frames, ``ids`` ``[n]`` and
    ``positions`` ``[n, 3]`` are sorted by atom ID; for local frames ``bond_atoms`` ``[nb, 2]`` holds the atom IDs
    of each bond (``batom1``/``batom2`` columns, else the first two).
    """

    timestep: int
    box: np.ndarray
    kind: str
    columns: dict[str, np.ndarray]

    @property
    def ids(self) -> np.ndarray:
        return np.sort(self.columns["id"].astype(np.int64))

    @property
    def positions(self) -> np.ndarray:
        order = np.argsort(self.columns["id"], kind="stable")
        for names, scaled in ((("x", "y", "z"), False), (("xu", "yu", "zu"), False), (("xs", "ys", "zs"), True)):
            if all(c in self.columns for c in names):
                pos = np.stack([self.columns[c] for c in names], axis=1)[order]
                return self.box[:, 0] + pos * (self.box[:, 1] - self.box[:, 0]) if scaled else pos
        raise SampleFileError(f"dump frame at timestep {self.timestep} has no position columns (x y z, xu yu zu or "
                              f"xs ys zs); columns: {list(self.columns)}")

    @property
    def bond_atoms(self) -> np.ndarray:
        names = list(self.columns)
        a = next((c for c in names if "batom1" in c), names[0])
        b = next((c for c in names if "batom2" in c), names[1])
        return np.stack([self.columns[a], self.columns[b]], axis=1).astype(np.int64)

    def bonds(self, ids) -> np.ndarray:
        """``bond_atoms`` as 0-based indices into particles with atom IDs ``ids`` (e.g. ``frame.ids`` of an atoms
        frame, or particle index + 1 for a file written by :func:`write_lammps_data`)."""
        ids = np.asarray(ids, np.int64)
        order = np.argsort(ids)
        ba = self.bond_atoms
        pos = np.searchsorted(ids[order], ba)
        pos = np.clip(pos, 0, len(ids) - 1)
        ok = ids[order][pos] == ba
        if not ok.all():
            raise SampleFileError(f"dump local frame at timestep {self.timestep}: bond atom IDs "
                                  f"{np.unique(ba[~ok])[:10].tolist()} are not among the given atom IDs")
        return order[pos]


def read_lammps_dump(path) -> list[DumpFrame]:
    """All frames of a LAMMPS text dump (``dump atom/custom`` or ``dump local``); errors name the line."""
    path = pathlib.Path(path)
    lines = _read_text(path).splitlines()
    frames, i = [], 0

    def expect(k: int, prefix: str) -> str:
        if k >= len(lines):
            raise SampleFileError(f"{path}:{len(lines)}: the file ends where '{prefix}' was expected")
        if not lines[k].startswith(prefix):
            raise SampleFileError(f"{path}:{k + 1}: expected '{prefix}', got {lines[k].strip()!r}")
        return lines[k][len(prefix):].strip()

    def number(k: int, cast=int):
        try:
            return cast(lines[k].split()[0])
        except (ValueError, IndexError):
            raise SampleFileError(f"{path}:{k + 1}: expected a number, got {lines[k].strip() if k < len(lines) else ''!r}") from None

    while i < len(lines):
        if not lines[i].strip():
            i += 1
            continue
        expect(i, "ITEM: TIMESTEP")
        step = number(i + 1)
        if i + 2 >= len(lines):
            raise SampleFileError(f"{path}:{len(lines)}: the frame at timestep {step} is cut short")
        kind = "atoms" if lines[i + 2].startswith("ITEM: NUMBER OF ATOMS") else "local"
        expect(i + 2, "ITEM: NUMBER OF ATOMS" if kind == "atoms" else "ITEM: NUMBER OF ENTRIES")
        count = number(i + 3)
        expect(i + 4, "ITEM: BOX BOUNDS")
        box = np.zeros((3, 2))
        for c in range(3):
            if i + 5 + c >= len(lines):
                raise SampleFileError(f"{path}:{len(lines)}: the box bounds are cut short")
            try:
                box[c] = [float(w) for w in lines[i + 5 + c].split()[:2]]
            except ValueError:
                raise SampleFileError(f"{path}:{i + 6 + c}: box bounds must be numbers") from None
        names = expect(i + 8, "ITEM: ATOMS" if kind == "atoms" else "ITEM: ENTRIES").split()
        if not names:
            raise SampleFileError(f"{path}:{i + 9}: the ITEM line names no columns")
        data = np.zeros((count, len(names)))
        for r in range(count):
            k = i + 9 + r
            if k >= len(lines):
                raise SampleFileError(f"{path}:{len(lines)}: the frame at timestep {step} ends after {r} of {count} "
                                      f"rows")
            words = lines[k].split()
            if len(words) != len(names):
                raise SampleFileError(f"{path}:{k + 1}: {len(words)} values, expected {len(names)} ({' '.join(names)})")
            try:
                data[r] = [float(w) for w in words]
            except ValueError:
                raise SampleFileError(f"{path}:{k + 1}: a value is not a number: {lines[k].strip()!r}") from None
        cols = {name: data[:, c] for c, name in enumerate(names)}
        if kind == "atoms" and "id" not in cols:
            raise SampleFileError(f"{path}:{i + 9}: an ATOMS frame needs an 'id' column")
        frames.append(DumpFrame(step, box, kind, cols))
        i += 9 + count
    if not frames:
        raise SampleFileError(f"{path}: no frames (not a LAMMPS text dump?)")
    return frames


# ============================================================================================== CSV
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


# ============================================================================================== VTU series
class VTUSeries:
    """A VTU time series for ParaView: one ``<stem>_NNNNNN.vtu`` per :meth:`write` (through meshio) and the
    collection ``<stem>.pvd`` (rewritten atomically after every step, so it is valid even if a run stops).

    Each step: points = particle centres (``positions`` or reference + ``displacement``), a ``vertex`` cell per
    particle and a ``line`` cell per bond (broken bonds stay, with ``intact`` 0, so every step has the same cells).
    Point data: ``radius``, ``displacement`` [m], ``broken_bonds`` (count per particle), ``coordination`` (intact
    bonds), then ``point_data`` (e.g. velocity, force, local stiffness). Cell data per bond: ``intact``,
    ``material``, then ``bond_data`` (e.g. force, break_mode); vertex cells carry NaN (-1 for integers).
    """

    def __init__(self, pvd_path, sample: Sample):
        if not isinstance(sample, Sample):
            raise TypeError(f"VTUSeries expects a jaxbpm Sample, got {type(sample).__name__}")
        self.path = pathlib.Path(pvd_path)
        if self.path.suffix.lower() != ".pvd":
            raise SampleFileError(f"{self.path}: a VTU series is named by its .pvd collection file")
        if not self.path.parent.is_dir():
            raise SampleFileError(f"{self.path}: no such directory {self.path.parent}")
        self.sample = sample
        self.steps: list[tuple[float, str]] = []

    def write(self, time: float, *, positions=None, displacement=None, intact=None,
              point_data: Mapping[str, Any] | None = None, bond_data: Mapping[str, Any] | None = None) -> pathlib.Path:
        """Write one step (atomically) and update the collection; returns the ``.vtu`` path."""
        import meshio

        s = self.sample
        n, nb = s.n_particles, s.n_bonds
        ref = np.asarray(s.positions, np.float64)
        if positions is not None and displacement is not None:
            raise SampleError("VTUSeries.write: give positions or displacement, not both")
        if positions is not None:
            pos = np.asarray(positions, np.float64)
            if pos.shape != (n, 3):
                raise SampleError(f"VTUSeries.write: positions must have shape [{n}, 3], got {pos.shape}")
            disp = pos - ref
        else:
            disp = np.zeros((n, 3)) if displacement is None else np.asarray(displacement, np.float64)
            if disp.shape != (n, 3):
                raise SampleError(f"VTUSeries.write: displacement must have shape [{n}, 3], got {disp.shape}")
            pos = ref + disp
        ok = np.ones(nb, bool) if intact is None else np.asarray(intact, bool).reshape(-1)
        if ok.shape != (nb,):
            raise SampleError(f"VTUSeries.write: intact must have shape [{nb}], got {ok.shape}")
        b = np.asarray(s.bonds)
        broken = np.bincount(b[~ok].ravel(), minlength=n).astype(np.int32)
        pdata = {"radius": np.asarray(s.radii, np.float64), "displacement": disp, "broken_bonds": broken,
                 "coordination": np.bincount(b[ok].ravel(), minlength=n).astype(np.int32)}
        pdata.update(_user_data("point_data", point_data, n, "particle", set(pdata)))
        bdata = {"intact": ok.astype(np.int32), "material": np.asarray(s.bond_material, np.int32)}
        bdata.update({k: v.astype(np.float64) for k, v in
                      _user_data("bond_data", bond_data, nb, "bond", set(bdata)).items()})
        cells = [("vertex", np.arange(n, dtype=np.int64)[:, None])]
        if nb:
            cells.append(("line", b.astype(np.int64)))
        cell_data = {}
        for name, arr in bdata.items():
            integer = np.issubdtype(arr.dtype, np.integer)
            filler = np.full((n,) + arr.shape[1:], -1 if integer else np.nan, dtype=arr.dtype)
            cell_data[name] = [filler, arr] if nb else [filler]
        mesh = meshio.Mesh(pos, cells, point_data=pdata, cell_data=cell_data)
        vtu = self.path.with_name(f"{self.path.stem}_{len(self.steps):06d}.vtu")
        atomic_write(vtu, lambda tmp: meshio.write(tmp, mesh, file_format="vtu"))
        self.steps.append((float(time), vtu.name))
        self._write_pvd()
        return vtu

    def _write_pvd(self) -> None:
        import xml.etree.ElementTree as ET

        root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
        coll = ET.SubElement(root, "Collection")
        for t, name in self.steps:
            ET.SubElement(coll, "DataSet", timestep=_r(t), group="", part="0", file=name)
        tree = ET.ElementTree(root)
        ET.indent(tree)
        atomic_write(self.path, lambda tmp: tree.write(tmp, encoding="utf-8", xml_declaration=True))


def write_vtu_series(pvd_path, sample: Sample, frames: Iterable[Mapping[str, Any]]) -> pathlib.Path:
    """Write ``frames`` (mappings with ``time`` and the keywords of :meth:`VTUSeries.write`) as a VTU series;
    returns the ``.pvd`` path."""
    series = VTUSeries(pvd_path, sample)
    for frame in frames:
        frame = dict(frame)
        if "time" not in frame:
            raise SampleError("write_vtu_series: every frame needs a 'time'")
        series.write(frame.pop("time"), **frame)
    if not series.steps:
        raise SampleError("write_vtu_series: no frames")
    return series.path


# ============================================================================================== by extension
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
