"""The layout of a LAMMPS data file as jaxbpm reads it: the section names and the counts of their rows, the header
lines, the atom styles' columns, and the parsing steps that the line-by-line reader (:mod:`jaxbpm.interop.lammps`)
and the one-go reader (:mod:`jaxbpm.interop._lammps_fast`) share. Errors name the file and line."""

from __future__ import annotations

import dataclasses
import re
from typing import Mapping

import numpy as np

from jaxbpm._geometry import DEFAULT_THICKNESS
from jaxbpm.errors import SampleFileError
from jaxbpm.interop._meta import N_COEFFS, checksums, parse_meta

__all__ = ["SECTIONS", "HEADER", "ATOM_COLUMNS", "Line", "coeff_row", "table_arrays", "last_wins", "header",
           "head_meta", "coeffs_head", "split", "planar_positions"]

SECTIONS = {"Atoms": "atoms", "Velocities": "atoms", "Masses": "atom types", "Bonds": "bonds",
             "Bond Coeffs": "bond types", "Pair Coeffs": "atom types", "Angles": "angles", "Dihedrals": "dihedrals",
             "Impropers": "impropers", "Ellipsoids": "ellipsoids", "Lines": "lines", "Triangles": "triangles",
             "Bodies": "bodies", "Angle Coeffs": "angle types", "Dihedral Coeffs": "dihedral types",
             "Improper Coeffs": "improper types"}
HEADER = re.compile(r"^\s*([-+0-9.eE]+)(?:\s+([-+0-9.eE]+))?(?:\s+([-+0-9.eE]+))?\s+([a-z][a-z /]*[a-z])\s*$")
ATOM_COLUMNS = {"bpm/sphere": 8, "sphere": 7}


@dataclasses.dataclass(frozen=True)
class Line:
    """One line of a data file: its number (from 1), its words before any ``#``, and the comment after it."""

    no: int
    words: list[str]
    comment: str


def coeff_row(words: list[str], where: str) -> tuple[int, np.ndarray]:
    """One ``bpm/rotational`` coefficient row: a bond type and 12 values (or 8, the dampings then 0).

    Args:
      words: the type and the values, as text.
      where: ``file:line`` for messages.

    Returns:
      ``(type, [12] float64)``.

    Raises:
      SampleFileError: a wrong count, values that are not numbers, or stiffnesses that are not finite.
    """
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
    if np.isnan(row).any() or not np.isfinite(row[:4]).all():
        raise SampleFileError(f"{where}: bond coefficients must be numbers, the stiffnesses Kr Ks Kt Kb finite; got "
                              f"{' '.join(words)!r}")
    if len(row) == 8:
        row = np.concatenate([row, np.zeros(4)])
    return t, row


def table_arrays(table: Mapping[int, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """A coefficient table as arrays.

    Args:
      table: ``{type: [12] coefficients}``.

    Returns:
      ``(types [k] int64 sorted, rows [k, 12])``; types outside int64 name no bond and are dropped.
    """
    keys = sorted(t for t in table if -2 ** 63 <= t < 2 ** 63)
    return (np.array(keys, np.int64).reshape(-1),
            np.array([table[t] for t in keys], np.float64).reshape(-1, N_COEFFS))


def last_wins(keys: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rows a dict filled in order would keep: for each distinct key, its last row.

    Args:
      keys: ``[m]`` integer keys.
      rows: ``[m, ...]`` their rows.

    Returns:
      ``(distinct keys sorted, the row of each one's last occurrence)``.
    """
    u, idx = np.unique(keys[::-1], return_index=True)
    return u, rows[::-1][idx]


def header(path, numbered) -> tuple[dict[str, int], int]:
    """Read the header of a data file.

    Args:
      path: the file, for messages.
      numbered: ``(line number, text)`` of its lines from line 2 on.

    Returns:
      ``({"atoms": n, "bonds": nb, "bond types": k, ...}, index of the first section's line, from 0)``.

    Raises:
      SampleFileError: an unreadable header line or count, no Atoms section, or no atom count.
    """
    counts: dict[str, int] = {}
    body_start = None
    for no, s in numbered:
        words = split(s)[0]
        if not words:
            continue
        name = " ".join(words)
        if name in SECTIONS:
            body_start = no - 1
            break
        m = HEADER.match(name)
        if not m:
            raise SampleFileError(f"{path}:{no}: cannot read header line {s.strip()!r}")
        key = m.group(4)
        if m.group(2) is None:
            try:
                counts[key] = int(m.group(1))
            except ValueError:
                raise SampleFileError(f"{path}:{no}: the count of {key!r} must be a whole number") from None
    if body_start is None:
        raise SampleFileError(f"{path}: no Atoms section")
    for key in ("atoms",):
        if key not in counts:
            raise SampleFileError(f"{path}: header lacks the '{key}' count")
    return counts, body_start


def head_meta(path, first: list[str]):
    """The checksum on the title line and jaxbpm's metadata line among the first lines.

    Args:
      path: the file, for messages.
      first: its first lines (up to 6 are read).

    Returns:
      ``(crc32 hex or None, metadata dict or None)``.

    Raises:
      SampleFileError: a malformed checksum or metadata line.
    """
    crc = checksums(first[0], f"{path}:1", ("crc32",))["crc32"] if first and "crc32=" in first[0] else None
    meta = None
    for no, line in enumerate(first[:6], start=1):
        meta = meta or parse_meta(line.strip(), f"{path}:{no}")
    return crc, meta


def coeffs_head(path, no: int, comment: str) -> None:
    """Check the style named on a ``Bond Coeffs`` line.

    Args:
      path: the file, for messages.
      no: the line's number.
      comment: the text after ``#`` (none, or ``bpm/rotational``).

    Raises:
      SampleFileError: another bond style.
    """
    if comment.strip() and comment.strip() != "bpm/rotational":
        raise SampleFileError(f"{path}:{no}: Bond Coeffs are for {comment.strip()!r}; jaxbpm reads bpm/rotational")


def split(s: str) -> tuple[list[str], str]:
    """A line's words before ``#`` and the comment after it.

    Args:
      s: the line.

    Returns:
      ``(words, comment)``.
    """
    body, _, comment = s.partition("#")
    return body.split(), comment


def planar_positions(path, pos: np.ndarray, meta: dict | None, dim: int | None, kw: dict) -> np.ndarray:
    """The positions of a data file as a sample has them: ``[n, 2]`` for discs (``dimension 2``), else ``[n, 3]``.
    A 2D file's thickness goes into ``kw`` (given there, else jaxbpm's header's, else 1 m).

    Args:
      path: the file, for messages.
      pos: ``[n, 3]`` positions read.
      meta: jaxbpm's header comment, or ``None``.
      dim: 2, 3, or ``None`` (the header's, else 3).
      kw: the :meth:`Sample.from_arrays` keywords, updated.

    Returns:
      The positions.

    Raises:
      SampleFileError: ``dim`` not 2, 3 or ``None``, or ``dim=2`` with unequal z (the first named).
    """
    if dim not in (None, 2, 3) or isinstance(dim, bool):
        raise SampleFileError(f"{path}: dim must be 2 (discs, LAMMPS dimension 2), 3 (spheres) or None, got {dim!r}")
    flat = bool(np.all(pos[:, 2] == pos[0, 2]))
    if dim is None:
        dim = int(meta.get("dim", 3)) if meta is not None else 3
    if dim == 3:
        return pos
    if not flat:
        k = int(np.flatnonzero(pos[:, 2] != pos[0, 2])[0])
        raise SampleFileError(f"{path}: dim=2 needs every atom at one z (LAMMPS dimension 2: z = 0), but atom "
                              f"{k + 1} (by ID order) has z = {pos[k, 2]!r}, the first {pos[0, 2]!r}")
    kw.setdefault("thickness", meta.get("thickness", DEFAULT_THICKNESS) if meta is not None else DEFAULT_THICKNESS)
    return np.ascontiguousarray(pos[:, :2])
