"""The layout of a LAMMPS data file as jaxbpm reads it: the section names and the counts of their rows, the header
lines, the atom styles' columns, and the parsing steps that the line-by-line reader (:mod:`jaxbpm.interop.lammps`)
and the one-go reader (:mod:`jaxbpm.interop._lammps_fast`) share. Errors name the file and line."""

from __future__ import annotations

import dataclasses
import re
from typing import Mapping

import numpy as np

from jaxbpm.errors import SampleFileError
from jaxbpm.interop._meta import N_COEFFS, checksums, parse_meta

__all__ = ["SECTIONS", "HEADER", "ATOM_COLUMNS", "Line", "coeff_row", "table_arrays", "last_wins", "header",
           "head_meta", "coeffs_head", "split"]

SECTIONS = {"Atoms": "atoms", "Velocities": "atoms", "Masses": "atom types", "Bonds": "bonds",
             "Bond Coeffs": "bond types", "Pair Coeffs": "atom types", "Angles": "angles", "Dihedrals": "dihedrals",
             "Impropers": "impropers", "Ellipsoids": "ellipsoids", "Lines": "lines", "Triangles": "triangles",
             "Bodies": "bodies", "Angle Coeffs": "angle types", "Dihedral Coeffs": "dihedral types",
             "Improper Coeffs": "improper types"}
HEADER = re.compile(r"^\s*([-+0-9.eE]+)(?:\s+([-+0-9.eE]+))?(?:\s+([-+0-9.eE]+))?\s+([a-z][a-z /]*[a-z])\s*$")
ATOM_COLUMNS = {"bpm/sphere": 8, "sphere": 7}


@dataclasses.dataclass(frozen=True)
class Line:
    no: int
    words: list[str]
    comment: str



def coeff_row(words: list[str], where: str) -> tuple[int, np.ndarray]:
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
    """``{type: 12 coefficients}`` as sorted types and their rows (types outside int64 name no bond: dropped)."""
    keys = sorted(t for t in table if -2 ** 63 <= t < 2 ** 63)
    return (np.array(keys, np.int64).reshape(-1),
            np.array([table[t] for t in keys], np.float64).reshape(-1, N_COEFFS))


def last_wins(keys: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sorted distinct ``keys`` and, for each, the row of its last occurrence (as a dict filled in order keeps)."""
    u, idx = np.unique(keys[::-1], return_index=True)
    return u, rows[::-1][idx]


def header(path, numbered) -> tuple[dict[str, int], int]:
    """The counts of the header lines ``numbered`` (``(line number, text)`` from line 2 on) and the index of the
    line of the first section."""
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
    """The checksum of the title line and the jaxbpm metadata of the first (up to 6) lines ``first``."""
    crc = checksums(first[0], f"{path}:1", ("crc32",))["crc32"] if first and "crc32=" in first[0] else None
    meta = None
    for no, line in enumerate(first[:6], start=1):
        meta = meta or parse_meta(line.strip(), f"{path}:{no}")
    return crc, meta


def coeffs_head(path, no: int, comment: str) -> None:
    if comment.strip() and comment.strip() != "bpm/rotational":
        raise SampleFileError(f"{path}:{no}: Bond Coeffs are for {comment.strip()!r}; jaxbpm reads bpm/rotational")


def split(s: str) -> tuple[list[str], str]:
    body, _, comment = s.partition("#")
    return body.split(), comment


