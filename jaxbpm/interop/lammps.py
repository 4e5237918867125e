"""LAMMPS data files (``atom_style bpm/sphere`` or ``sphere``, ``Bonds``, ``Bond Coeffs # bpm/rotational``) and
``bpm/rotational`` coefficient files; see :mod:`jaxbpm.interop.formats` for the layout.

A data file written by jaxbpm ends its title line with ``crc32=XXXXXXXX``, the CRC-32 (zlib, 8 hex digits) of the
file's text after the title line; the reader checks it when present (a damaged or cut file is an error) and reads
files without it (from LAMMPS or other programs, or with the checksum deleted after an intended hand edit) as they
are."""

from __future__ import annotations

import dataclasses
import pathlib
import warnings
from typing import Any, Mapping

import numpy as np

from jaxbpm._atomic import atomic_write
from jaxbpm.errors import SampleError, SampleFileError
from jaxbpm.interop import conventions
from jaxbpm.interop._lammps_fast import parse_fast
from jaxbpm.interop._lammps_layout import (ATOM_COLUMNS, SECTIONS, Line, coeff_row, coeffs_head, head_meta, header,
                                           last_wins, planar_positions, split, table_arrays)
from jaxbpm.interop._meta import (BIG, N_COEFFS, crc32, domain_of, exact_text, meta_line, meta_of, names_file,
                                  read_text, verify, without_line)
from jaxbpm.sample import ParticleMaterial, Sample


def lammps_coefficients(sample: Sample, *, normalize: bool = False) -> np.ndarray:
    """Per-bond ``bpm/rotational`` coefficients of a sample: exact translations of its bond law
    (:func:`jaxbpm.interop.conventions.to_lammps`).

    Args:
      sample: the sample.
      normalize: coefficients for LAMMPS's ``normalize yes`` (stiffnesses per unit length).

    Returns:
      ``[nb, 12]``: Kr Ks Kt Kb Fcr Fcs Tct Tcb and the dampings (0); infinite strengths become 1e300.
    """
    bond, length, _, _ = conventions.sample_bonds(sample)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", conventions.InexactTranslationWarning)  # stated in the docs
        p = conventions.to_lammps(bond, length, normalize=normalize)
    c = p.coefficients().reshape(-1, 8)
    c = np.where(np.isfinite(c), c, BIG)
    return np.concatenate([c, np.zeros((c.shape[0], 4))], axis=1)


def _group_types(coeffs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """1-based type per bond (bonds with bit-identical coefficients share one, numbered by first appearance) and
    the ``[ntypes, 12]`` table."""
    if len(coeffs) == 0:
        return np.zeros(0, np.int64), np.zeros((0, N_COEFFS))
    coeffs = np.ascontiguousarray(coeffs, dtype=np.float64)
    bits = coeffs.view(np.uint64)
    # a 64-bit hash of each row's bits groups the rows; the groups are exact when every row equals its group's first
    # row bit for bit (else a hash collision: group by the whole rows)
    key = bits[:, 0].copy()
    for c in range(1, bits.shape[1]):
        key *= np.uint64(0x100000001B3)
        key ^= bits[:, c]
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    if not np.array_equal(bits, bits[first[inv]]):
        keys = coeffs.view(np.dtype((np.void, coeffs.dtype.itemsize * coeffs.shape[1]))).ravel()
        _, first, inv = np.unique(keys, return_index=True, return_inverse=True)
        inv = inv.reshape(-1)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return rank[inv] + 1, coeffs[first[order]]


def _rows(fmt: str, columns: list) -> str:
    """``fmt`` (``%``-format of one line, ``%s`` for each float column) applied to each row of ``columns`` (lists
    of Python ints, or float arrays, written as :func:`exact_text` does), each line ended by a newline: one formatting call
    for all rows."""
    n = len(columns[0])
    if n == 0:
        return ""
    flat = [None] * (n * len(columns))
    for c, col in enumerate(columns):
        flat[c::len(columns)] = col if isinstance(col, list) else _reprs(col)
    return ((fmt + "\n") * n) % tuple(flat)


def _reprs(values: np.ndarray) -> list[str]:
    """``[exact_text(v) for v in values]``, each distinct value (bit for bit) formatted once."""
    values = np.asarray(values).astype(np.float64)
    uniq, inv = np.unique(values.view(np.uint64), return_inverse=True)
    if 2 * len(uniq) > len(values):
        return list(map(repr, values.tolist()))
    return np.array(list(map(repr, uniq.view(np.float64).tolist())), dtype=object)[inv.reshape(-1)].tolist()


def _coeff_line(t: int, row) -> str:
    return f"{t} " + " ".join(exact_text(v) for v in row)


def write_lammps_coeffs(path, table, *, bond_style: str | None = "bpm/rotational break yes smooth no") -> pathlib.Path:
    """Write an include file for a LAMMPS input, atomically.

    Args:
      path: the file.
      table: ``[ntypes, 8 or 12]`` coefficients, one ``bond_coeff`` line per row (missing dampings are 0).
      bond_style: the ``bond_style`` line written first; ``None``: coefficients only.

    Returns:
      ``path`` as a :class:`pathlib.Path`.
    """
    table = np.asarray(table, dtype=np.float64)
    if table.ndim != 2 or table.shape[1] not in (8, N_COEFFS):
        raise SampleError(f"bond coefficient table must have shape [ntypes, 8] or [ntypes, 12], got {table.shape}")
    if table.shape[1] == 8:
        table = np.concatenate([table, np.zeros((len(table), 4))], axis=1)
    lines = [] if bond_style is None else [f"bond_style {bond_style}"]
    lines += ["bond_coeff " + _coeff_line(t, row) for t, row in enumerate(table, start=1)]

    def write(tmp):
        pathlib.Path(tmp).write_text("\n".join(lines) + "\n")

    return atomic_write(path, write)


def read_lammps_coeffs(path) -> tuple[dict[int, np.ndarray], bool]:
    """Read the ``bond_coeff`` lines of a LAMMPS input file.

    Args:
      path: the input file.

    Returns:
      ``({type: 12 coefficients}, normalize)``, ``normalize`` from a ``bond_style bpm/rotational ... normalize yes``
      line.

    Raises:
      SampleFileError: a missing file, another bond style or a malformed line (named).
    """
    path = pathlib.Path(path)
    text = read_text(path)
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
            t, row = coeff_row(words[1:], f"{path}:{no}")
            coeffs[t] = row
    return coeffs, normalize


def write_lammps_data(path, sample: Sample, *, normalize: bool = False, atom_types=None, bond_types=None,
                      coefficients: bool = True, title: str | None = None) -> pathlib.Path:
    """Write ``sample`` as a LAMMPS data file (``atom_style bpm/sphere``, units si), atomically.

    A two-dimensional sample (discs, ``sample.dim == 2``) is written for ``dimension 2``: positions at z = 0, the box
    ``zlo zhi`` a slab of the discs' thickness around z = 0, the bond coefficients of the ``2 r_b x t`` rectangular
    sections (:func:`lammps_coefficients`), and the thickness in jaxbpm's header comment. The density column is the
    material's density; LAMMPS computes sphere masses from it, so give discs their masses ``rho pi R^2 t`` in the
    input with ``set group all density/disc`` (rho t) and integrate with ``fix nve/bpm/sphere disc``.

    Args:
      path: the data file. Atom IDs are particle index + 1, bond IDs bond index + 1.
      sample: the sample.
      normalize: coefficients for ``bond_style bpm/rotational normalize yes`` (Kr, Ks multiplied by L).
      atom_types: ``[n]`` LAMMPS atom type per particle, each >= 1 (default: ``sample.types``, so groups by type
        travel with the file).
      bond_types: ``[nb]`` 1-based bond type per bond (default: bonds with identical coefficients share a type).
        Bonds forced into one type get the coefficients of its first bond (a warning states the largest
        difference).
      coefficients: write the ``Bond Coeffs # bpm/rotational`` section (read it in LAMMPS with ``nocoeff`` and
        include :func:`write_lammps_coeffs`'s lines instead, since the bond style must follow the box).
      title: first line of the file (one line; jaxbpm appends its checksum ``crc32=XXXXXXXX``).

    Returns:
      ``path`` as a :class:`pathlib.Path`.
    """
    if not isinstance(sample, Sample):
        raise TypeError(f"write_lammps_data expects a jaxbpm Sample, got {type(sample).__name__}")
    if title and (not isinstance(title, str) or title.splitlines() != [title] or "crc32=" in title):
        raise SampleError(f"title must be one line of text (without 'crc32='), got {title!r}")
    n, nb = sample.n_particles, sample.n_bonds
    pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
    b = np.asarray(sample.bonds)
    coeffs = lammps_coefficients(sample, normalize=normalize) if nb else np.zeros((0, N_COEFFS))
    if bond_types is None:
        btype, table = _group_types(coeffs)
    else:
        btype = np.asarray(bond_types).astype(np.int64).reshape(-1)
        if btype.shape != (nb,) or (nb and btype.min() < 1):
            raise SampleError(f"bond_types must hold {nb} types >= 1, got shape {btype.shape}")
        ntype = int(btype.max()) if nb else 0
        table = np.zeros((ntype, N_COEFFS))
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
    if atom_types is None:
        atom_types = np.ones(n, np.int64) if sample.types is None else sample.types
    atype = np.asarray(atom_types).astype(np.int64).reshape(-1)
    if atype.shape != (n,) or atype.min() < 1:
        where = "" if atype.shape != (n,) else (f" (type {int(atype.min())} at particles "
                                                f"{np.flatnonzero(atype < 1)[:10].tolist()}; LAMMPS's atom types count "
                                                f"from 1: write atom_types=sample.types + 1)")
        raise SampleError(f"atom_types must hold {n} types >= 1, got shape {atype.shape}{where}")
    density = float(sample.particle_material.density)
    pad = 10.0 * rad.max()
    lo, hi = pos.min(axis=0) - pad, pos.max(axis=0) + pad
    if sample.dim == 2:  # dimension 2: z = 0, a slab of the discs' thickness around it (LAMMPS needs zlo < 0 < zhi)
        pos = np.concatenate([pos, np.zeros((n, 1))], axis=1)
        lo, hi = np.append(lo, -0.5 * sample.thickness), np.append(hi, 0.5 * sample.thickness)
    from jaxbpm._version import __version__

    lines = [meta_line(meta_of(sample, normalize=bool(normalize))), "",
             f"{n} atoms", f"{int(atype.max())} atom types", f"{nb} bonds", f"{max(len(table), 1)} bond types", "",
             *(f"{exact_text(lo[c])} {exact_text(hi[c])} {a}lo {a}hi" for c, a in enumerate("xyz")), "",
             "Atoms # bpm/sphere", ""]
    # the text is what the line-by-line form "\n".join(lines) + "\n" gives (ids, types: %d; floats: repr, i.e. exact_text),
    # formatted a whole section at a time
    parts = ["\n".join(lines) + "\n",
             _rows(f"%d 1 %d %s {exact_text(density)} %s %s %s",
                   [list(range(1, n + 1)), atype.tolist(), 2.0 * rad, *(pos[:, c] for c in range(3))])]
    if coefficients and len(table):
        parts.append("\nBond Coeffs # bpm/rotational\n\n" + _rows("%d" + " %s" * N_COEFFS, [
            list(range(1, len(table) + 1)), *np.asarray(table, np.float64).T]))
    if nb:
        rb, bm = np.asarray(sample.bond_radius), np.asarray(sample.bond_material)
        parts.append("\nBonds\n\n" + _rows("%d %d %d %d # %s %d", [
            list(range(1, nb + 1)), btype.tolist(), (b[:, 0].astype(np.int64) + 1).tolist(),
            (b[:, 1].astype(np.int64) + 1).tolist(), rb, bm.astype(np.int64).tolist()]))
    body = "".join(parts)
    head = title or (f"LAMMPS data file (atom_style bpm/sphere, bond_style bpm/rotational, units si"
                     f"{', dimension 2' if sample.dim == 2 else ''}) written by jaxbpm {__version__}")
    text = f"{head} crc32={crc32(body)}\n{body}"

    def write(tmp):
        pathlib.Path(tmp).write_text(text, encoding="utf-8")

    return atomic_write(path, write)


@names_file
def read_lammps_data(path, *, coeffs=None, normalize: bool | None = None, atom_style: str | None = None,
                     breaking: bool = True, bond_radius_ratio: float | None = None,
                     materials: Mapping[str, Any] | None = None, dim: int | None = None, **sample_kw) -> Sample:
    """Read a LAMMPS data file with spheres and bonds into a :class:`Sample`.

    Particles are ordered by atom ID; their atom types become ``Sample.types`` (groups by type:
    :class:`jaxbpm.scenes.groups.Type`). Bond parameters come, in this order of preference, from jaxbpm's own comments
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
      dim: 2 reads a ``dimension 2`` file as discs (positions ``[n, 2]``; every z must be equal), 3 as spheres;
        default: jaxbpm's header comment, else 3 (a data file does not say its dimension, and spheres in one plane
        are a 3D sample too: pass ``dim=2`` for LAMMPS's own 2D files).
      **sample_kw: more :meth:`Sample.from_arrays` keywords (``particle_material``, ``bond_contact``, ``types`` in
        place of the atom types, ``thickness`` of 2D discs (default: jaxbpm's header comment, else 1 m), ...).

    Returns:
      The sample, particles in the order of their atom IDs.

    Raises:
      SampleFileError: the file is missing or malformed (the message names the line).
      SampleError: the content does not make a valid sample.
      ConventionError: the coefficients have no jaxbpm counterpart.
    """
    path = pathlib.Path(path)
    text = read_text(path)
    got = parse_fast(path, text, atom_style)
    crc, body, meta, pos, dia, dens, bonds, btype, rb_c, mat_c, table, atom_types = \
        got if got is not None else _parse_lines(path, text, atom_style)
    nb = len(bonds)
    if crc is not None:  # the file read well: is it the one jaxbpm wrote?
        verify(body, "crc32", crc, path, "line 1", f"delete 'crc32={crc}' from line 1 of {path.name}")
    if coeffs is not None:
        if isinstance(coeffs, (str, pathlib.Path)):
            extra_table, extra_norm = read_lammps_coeffs(coeffs)
            if normalize is None:
                normalize = extra_norm
        else:
            extra_table = {}
            for t, v in coeffs.items():
                _, extra_table[int(t)] = coeff_row([str(t)] + [repr(float(x)) for x in v], f"coeffs[{t}]")
        extra_keys, extra_rows = table_arrays(extra_table)
        table = last_wins(np.concatenate([table[0], extra_keys]), np.concatenate([table[1], extra_rows]))
    if normalize is None:
        normalize = bool(meta.get("normalize", False)) if meta else False
    kw = dict(sample_kw)
    pos = planar_positions(path, pos, meta, dim, kw)
    kw.setdefault("types", atom_types)
    if meta is not None:
        kw.setdefault("particle_material", meta["particle_material"])
        kw.setdefault("bond_contact", meta["bond_contact"])
        kw.setdefault("domain", domain_of(meta))
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
    tkeys, tvals = table  # (keys sorted)
    at = np.minimum(np.searchsorted(tkeys, btype), max(len(tkeys) - 1, 0))
    found = tkeys[at] == btype if len(tkeys) else np.zeros(nb, bool)
    if not found.all():
        missing = np.unique(btype[~found]).tolist()
        raise SampleFileError(f"{path}: no bpm/rotational coefficients for bond types {missing[:10]} (no Bond Coeffs "
                              f"section or coeffs= file); give coeffs=, or bond_radius_ratio= and materials=")
    coef = tvals[at]
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
    limits = np.where(coef[:, 4:8] >= 0.999 * BIG, np.inf, coef[:, 4:8])  # jaxbpm's "unbreakable"
    p = conventions.LammpsBpmRotational(*(coef[:, c] for c in range(4)), *(limits[:, c] for c in range(4)),
                                        normalize=normalize)
    bond = conventions.from_lammps(p, length, breaking=breaking and bool(np.isfinite(limits).any()),
                                   thickness=kw.get("thickness") if pos.shape[1] == 2 else None)
    mats, bm = materials_from_bonds(bond)
    return Sample.from_arrays(pos, radii, bonds, bond.bond_radius, bond_material=bm, materials=mats,
                              particle_material=pm, **kw)


def _line_sections(path, raw: list[str], counts: dict[str, int], body_start: int) -> dict[str, tuple[Line, list[Line]]]:
    """``{name: (its name's line, its rows)}`` of the sections from line ``body_start`` on, each with the row count
    the header declares; errors name the line."""
    lines = [Line(i + 1, *split(s)) for i, s in enumerate(raw)]
    sections: dict[str, tuple[Line, list[Line]]] = {}
    i = body_start
    while i < len(lines):
        ln = lines[i]
        if not ln.words:
            i += 1
            continue
        name = " ".join(ln.words)
        if name not in SECTIONS:
            raise SampleFileError(f"{path}:{ln.no}: unknown section {raw[ln.no - 1].strip()!r} (or a "
                                  f"{'section line too many' if sections else 'misplaced line'})")
        want = counts.get(SECTIONS[name], 0)
        rows, i = [], i + 1
        while len(rows) < want:
            if i >= len(lines):
                raise SampleFileError(f"{path}:{len(lines)}: section {name} ended after {len(rows)} of {want} lines")
            if lines[i].words:
                if " ".join(lines[i].words) in SECTIONS:
                    raise SampleFileError(f"{path}:{lines[i].no}: section {name} ended after {len(rows)} of {want} "
                                          f"lines")
                rows.append(lines[i])
            i += 1
        sections[name] = (ln, rows)
    return sections


def _check_complete(path, text: str, raw: list[str], counts: dict[str, int], sections) -> None:
    """Raise a :class:`SampleFileError` for a file cut short: a section the header declares rows for is missing (a
    file cut before its Bonds section would otherwise read as a sample without bonds), or the last line is cut."""
    for name, key in (("Atoms", "atoms"), ("Bonds", "bonds")):
        if counts.get(key, 0) > 0 and name not in sections:
            raise SampleFileError(f"{path}: the header declares {counts[key]} {key} but the file has no {name} section "
                                  "(truncated?)")
    if text and not text.endswith(("\n", "\r")) and raw[-1].split("#")[0].strip():
        raise SampleFileError(f"{path}:{len(raw)}: the file ends in the middle of a line (truncated?): "
                              f"{raw[-1].strip()!r}")


def _atom_style(path, sections, atom_style) -> str | None:
    """The atom style given, or named by the Atoms section's comment; ``None``: from each line's column count."""
    head, _ = sections.get("Atoms", (None, []))
    style = atom_style or (head.comment.strip() if head is not None and head.comment.strip() else None)
    if style is not None and style not in ATOM_COLUMNS:
        raise SampleFileError(f"{path}:{head.no if head else 1}: atom style {style!r} is not supported (bpm/sphere "
                              f"or sphere)")
    return style


def _atom_rows(path, raw: list[str], rows: list[Line], style: str | None):
    """``(ids, dia, dens, pos, types)`` of the Atoms rows in file order; errors name the line."""
    n = len(rows)
    ids, types = np.zeros(n, np.int64), np.zeros(n, np.int64)
    dia, dens, pos = np.zeros(n), np.zeros(n), np.zeros((n, 3))
    for k, ln in enumerate(rows):
        st = style or {7: "sphere", 10: "sphere", 8: "bpm/sphere", 11: "bpm/sphere"}.get(len(ln.words))
        ncol = ATOM_COLUMNS.get(st)
        if ncol is None or len(ln.words) not in (ncol, ncol + 3):
            raise SampleFileError(
                f"{path}:{ln.no}: Atoms line has {len(ln.words)} values, expected 8 (bpm/sphere: id mol type "
                f"diameter density x y z) or 7 (sphere: id type diameter density x y z), optionally + 3 image flags")
        off = ncol - 7
        try:
            ids[k], types[k] = int(ln.words[0]), int(ln.words[1 + off])
            dia[k], dens[k] = float(ln.words[2 + off]), float(ln.words[3 + off])
            pos[k] = [float(w) for w in ln.words[4 + off:7 + off]]
        except (ValueError, OverflowError):
            raise SampleFileError(f"{path}:{ln.no}: Atoms line has a non-numeric value: "
                                  f"{raw[ln.no - 1].strip()!r}") from None
        if not (dia[k] > 0 and np.isfinite(dia[k])):
            raise SampleFileError(f"{path}:{ln.no}: atom {ids[k]} has diameter {float(dia[k])!r}; jaxbpm needs "
                                  f"spheres with a finite diameter > 0")
        if not np.all(np.isfinite(pos[k])):
            raise SampleFileError(f"{path}:{ln.no}: atom {ids[k]} has a coordinate that is not finite: "
                                  f"{raw[ln.no - 1].strip()!r}")
    return ids, dia, dens, pos, types


def _atoms_by_line(path, raw: list[str], sections, atom_style, counts: dict[str, int]):
    """``(ids, dia, dens, pos, types)`` of the Atoms section sorted by ID: unique IDs, one density, types within the
    header's ``atom types``; errors name the line."""
    style = _atom_style(path, sections, atom_style)
    _, rows = sections.get("Atoms", (None, []))
    if not rows:
        raise SampleFileError(f"{path}: the Atoms section is empty")
    ids, dia, dens, pos, types = _atom_rows(path, raw, rows, style)
    n_types = counts.get("atom types")
    bad = np.flatnonzero((types < 1) | (types > (n_types if n_types is not None else np.inf)))
    if bad.size:
        k = int(bad[0])
        raise SampleFileError(f"{path}:{rows[k].no}: atom {ids[k]} has type {types[k]}, outside "
                              f"1..{n_types if n_types is not None else 'N'} (header 'atom types'); LAMMPS refuses it")
    order = np.argsort(ids, kind="stable")
    dup = np.flatnonzero(np.diff(ids[order]) == 0)
    if dup.size:
        raise SampleFileError(f"{path}:{rows[order[dup[0] + 1]].no}: duplicate atom ID {ids[order[dup[0]]]}")
    ids, dia, dens, pos, types = ids[order], dia[order], dens[order], pos[order], types[order]
    atom_line = np.array([rows[o].no for o in order])
    if np.any(dens != dens[0]):
        k = int(np.flatnonzero(dens != dens[0])[0])
        raise SampleFileError(f"{path}:{atom_line[k]}: atom density {float(dens[k])!r} differs from "
                              f"{float(dens[0])!r}; a jaxbpm sample has one particle density")
    return ids, dia, dens, pos, types


def _bonds_by_line(path, raw: list[str], sections, ids: np.ndarray, counts: dict[str, int]):
    """``(bonds [nb, 2] as particle indices, types, bond radii and materials from jaxbpm's comments)`` of the
    Bonds section; errors name the line."""
    index = {int(a): k for k, a in enumerate(ids)}
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
        if not 1 <= t <= counts.get("bond types", 0):
            raise SampleFileError(f"{path}:{ln.no}: bond type {t} is outside 1..{counts.get('bond types', 0)} "
                                  "(header 'bond types')")
        bonds[k], btype[k] = (index[a1], index[a2]), t
        extra = ln.comment.split()
        if len(extra) == 2:
            try:
                rb_c[k], mat_c[k] = float(extra[0]), int(extra[1])
            except (ValueError, OverflowError):  # not jaxbpm's comment: the coefficients are translated
                rb_c[k], mat_c[k] = np.nan, -1
    return bonds, btype, rb_c, mat_c


def _coeffs_by_line(path, sections) -> tuple[np.ndarray, np.ndarray]:
    """The Bond Coeffs section as ``(types, coefficients)`` (:func:`table_arrays`); errors name the line."""
    table: dict[int, np.ndarray] = {}
    if "Bond Coeffs" in sections:
        head, crows = sections["Bond Coeffs"]
        coeffs_head(path, head.no, head.comment)
        for ln in crows:
            t, row = coeff_row(ln.words, f"{path}:{ln.no}")
            table[t] = row
    return table_arrays(table)


def _parse_lines(path, text: str, atom_style):
    """The content of a data file read line by line: ``(crc, checksummed text, meta, pos, dia, dens, bonds, btype,
    rb_c, mat_c, (types, coefficients), atom types)``, particles sorted by ID. Errors name the line."""
    raw = text.splitlines()
    # jaxbpm's checksum ends the title line; the metadata line follows it (or is first, in a file without a title)
    crc, meta = head_meta(path, raw[:6])
    counts, body_start = header(path, enumerate(raw[1:], start=2))
    sections = _line_sections(path, raw, counts, body_start)
    _check_complete(path, text, raw, counts, sections)
    ids, dia, dens, pos, atom_types = _atoms_by_line(path, raw, sections, atom_style, counts)
    bonds = _bonds_by_line(path, raw, sections, ids, counts)
    return (crc, without_line(text, 0), meta, pos, dia, dens, *bonds, _coeffs_by_line(path, sections), atom_types)


def materials_from_bonds(bond: conventions.JaxbpmBond) -> tuple[dict, np.ndarray]:
    """A material table for translated bonds: one component per distinct (E, nu, tensile, shear) (to 1e-12
    relative), numbered in the order of their first bond.

    Args:
      bond: per-bond jaxbpm parameters (arrays ``[nb]`` or scalars).

    Returns:
      ``(materials, bond_material)``: ``{"E", "nu", "tensile_strength", "shear_strength": [k]}`` and ``[nb]`` int32
      component indices.
    """
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
