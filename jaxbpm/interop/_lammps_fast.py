"""The fast path of :func:`jaxbpm.interop.lammps.read_lammps_data`: every numeric section of a plainly well-formed
data file parsed in one go (``np.loadtxt`` with a type per column, checks vectorised). Anything irregular or
wrong returns ``None`` and the file is read line by line, whose errors name the line."""

from __future__ import annotations

import bisect
import io

import numpy as np

from jaxbpm.interop._meta import N_COEFFS
from jaxbpm.interop._lammps_layout import (ATOM_COLUMNS, SECTIONS, coeff_row, coeffs_head, head_meta, header,
                                           last_wins, split, table_arrays)

__all__ = ["parse_fast"]


# characters str.splitlines breaks lines at besides "\n"
_BREAKS = "\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"
_DATA_START = np.zeros(256, bool)
_DATA_START[np.frombuffer(b"0123456789+-.", np.uint8)] = True


def _table(block: bytes, dtype) -> np.ndarray | None:
    """The whitespace-separated rows of ``block`` (ASCII) as a structured array of ``dtype`` (each row exactly its
    fields, integers as integers), or ``None`` where they are not."""
    try:
        return np.loadtxt(io.StringIO(block.decode("ascii")), dtype=dtype, comments=None, ndmin=1)
    except (ValueError, OverflowError, UnicodeDecodeError):
        return None


class _Lines:
    """The lines of a data file as byte ranges, and which of them do not start like a number (blank lines, section
    names, comments, the header: few in a well-formed file)."""

    def __init__(self, data: bytes, buf: np.ndarray, nl: np.ndarray):
        self.data, self.nl, self.count = data, nl, len(nl)
        self.starts = np.empty(self.count, np.int64)
        self.starts[0], self.starts[1:] = 0, nl[:-1] + 1
        self.special = np.flatnonzero(~_DATA_START[buf[self.starts]]).tolist()
        self.special_set = set(self.special)

    def line(self, k: int) -> str:
        """Line ``k`` (from 0) without its end."""
        return self.data[self.starts[k]:self.nl[k]].decode("utf-8", "surrogatepass")

    def block(self, rows: tuple[int, int]) -> bytes:
        """Lines ``rows[0]`` to ``rows[1] - 1`` with their ends."""
        return self.data[self.starts[rows[0]]:self.nl[rows[1] - 1] + 1]


def _lines(text: str) -> _Lines | None:
    """The lines of ``text``, or ``None`` when it has line breaks other than ``\n``, other control characters than
    tabs, no final newline, or over 10 000 lines that do not start like a number."""
    if not text.endswith("\n") or any(c in text for c in _BREAKS):
        return None
    data = text.encode("utf-8", "surrogatepass")
    buf = np.frombuffer(data, np.uint8)
    nl = np.flatnonzero(buf == 10)
    if np.count_nonzero(buf < 32) != len(nl) + text.count("\t"):  # other control characters
        return None
    lines = _Lines(data, buf, nl)
    return None if len(lines.special) > 10_000 else lines


def _sections(lines: _Lines, counts: dict[str, int], i: int) -> dict[str, tuple[int, str, tuple[int, int]]] | None:
    """``{name: (line number of its name, its comment, (first row, end row))}`` of the sections from line ``i``, or
    ``None`` when a section is unknown, cut short or holds a line that is not a row."""
    sections: dict[str, tuple[int, str, tuple[int, int]]] = {}
    special, special_set = lines.special, lines.special_set
    while i < lines.count:
        if i not in special_set:
            return None
        words, comment = split(lines.line(i))
        if not words:
            i += 1
            continue
        name = " ".join(words)
        if name not in SECTIONS:
            return None
        want, j = counts.get(SECTIONS[name], 0), i + 1
        if want:
            while j < lines.count and j in special_set:  # blank lines before the rows
                if split(lines.line(j))[0]:
                    return None
                j += 1
            nxt = bisect.bisect_left(special, j)
            if j + want > lines.count or (nxt < len(special) and special[nxt] < j + want):
                return None
        sections[name] = (i + 1, comment, (j, j + want))
        i = j + want
    if any(counts.get(key, 0) > 0 and name not in sections for name, key in (("Atoms", "atoms"), ("Bonds", "bonds"))):
        return None
    return sections


def _atoms(lines: _Lines, sections, atom_style):
    """``(ids, dia, dens, pos, types)`` of the Atoms section sorted by ID, or ``None`` where it is not plainly well
    formed (unknown style, comments, a bad value, duplicate IDs, more than one density)."""
    if "Atoms" not in sections:
        return None
    _, comment, rows = sections["Atoms"]
    style = atom_style or (comment.strip() or None)
    n = rows[1] - rows[0]
    if (style is not None and style not in ATOM_COLUMNS) or n == 0:
        return None
    text_rows = lines.block(rows)
    ncols = len(lines.line(rows[0]).split())
    ncol = ATOM_COLUMNS.get(style or {7: "sphere", 10: "sphere", 8: "bpm/sphere", 11: "bpm/sphere"}.get(ncols))
    if b"#" in text_rows or ncol is None or ncols not in (ncol, ncol + 3):
        return None
    off = ncol - 7
    got = _table(text_rows, [(f"c{k}", "f8" if 2 + off <= k <= 6 + off else "i8") for k in range(ncols)])
    if got is None or len(got) != n:
        return None
    ids, dia, dens, types = got["c0"], got[f"c{2 + off}"], got[f"c{3 + off}"], got[f"c{1 + off}"]
    pos = np.stack([got[f"c{k + 4 + off}"] for k in range(3)], axis=1)
    if not (np.all((dia > 0) & np.isfinite(dia)) and np.all(np.isfinite(pos))):
        return None
    order = np.argsort(ids, kind="stable")
    ids, dia, dens, pos, types = ids[order], dia[order], dens[order], pos[order], types[order]
    if np.any(np.diff(ids) == 0) or np.any(dens != dens[0]):
        return None
    return ids, dia, dens, pos, np.asarray(types, np.int64)


def _bond_rows(lines: _Lines, sections):
    """The Bonds section's rows ``id type atom1 atom2``, each with jaxbpm's comment ``# bond_radius material``
    (columns ``rb``, ``m``) or none without; ``None`` where they are not so."""
    _, _, rows = sections.get("Bonds", (0, "", (0, 0)))
    nb = rows[1] - rows[0]
    text_rows = lines.block(rows) if nb else b""
    hashes = text_rows.count(b"#")
    fields = [("id", "i8"), ("t", "i8"), ("a1", "i8"), ("a2", "i8")]
    if nb == 0:
        got = np.zeros(0, fields)
    elif hashes == 0:
        got = _table(text_rows, fields)
    elif hashes == nb:
        # "#" becomes a column "nan" that only the 5th may hold: with one "#" a line, each is after the 4th value
        got = _table(text_rows.replace(b"#", b" nan "), fields + [("h", "f8"), ("rb", "f8"), ("m", "i8")])
        if got is not None and not (np.all(np.isnan(got["h"])) and not np.any(np.isnan(got["rb"]))):
            return None
    else:
        return None
    return None if got is None or len(got) != nb else got


def _bonds(lines: _Lines, sections, ids: np.ndarray, counts: dict[str, int]):
    """``(bonds [nb, 2] as particle indices, types, bond radii from the comments, materials from the comments)``,
    or ``None`` where a bond names a missing atom, joins an atom to itself or has a type outside the header's."""
    got = _bond_rows(lines, sections)
    if got is None:
        return None
    n, nb, t = len(ids), len(got), got["t"]
    bonds = np.zeros((nb, 2), np.int64)
    for c, a in enumerate((got["a1"], got["a2"])):
        k = np.minimum(np.searchsorted(ids, a), n - 1)
        if np.any(ids[k] != a):
            return None
        bonds[:, c] = k
    if np.any(got["a1"] == got["a2"]) or np.any((t < 1) | (t > counts.get("bond types", 0))):
        return None
    if "rb" in got.dtype.names and nb:
        rb_c, mat_c = np.ascontiguousarray(got["rb"]), np.ascontiguousarray(got["m"])
    else:
        rb_c, mat_c = np.full(nb, np.nan), np.full(nb, -1)
    return bonds, np.asarray(t, np.int64), rb_c, mat_c


def _coeffs(path, lines: _Lines, sections):
    """The Bond Coeffs section as ``(types, coefficients)`` (:func:`table_arrays`): in one go when plainly well
    formed, else line by line (whose error names the line)."""
    if "Bond Coeffs" not in sections:
        return table_arrays({})
    no, comment, rows = sections["Bond Coeffs"]
    coeffs_head(path, no, comment)
    text_rows = lines.block(rows) if rows[1] > rows[0] else b""
    width = len(lines.line(rows[0]).split()) if text_rows else 13
    got = None if b"#" in text_rows or width not in (9, 13) else \
        _table(text_rows, [("t", "i8")] + [(f"c{k}", "f8") for k in range(width - 1)]) if text_rows else \
        np.zeros(0, [("t", "i8")] + [(f"c{k}", "f8") for k in range(12)])
    if got is not None and len(got) == rows[1] - rows[0]:
        vals = np.zeros((len(got), N_COEFFS))
        for k in range(width - 1):
            vals[:, k] = got[f"c{k}"]
        if not (np.any(np.isnan(vals)) or not np.all(np.isfinite(vals[:, :4]))):
            return last_wins(got["t"], vals)
    tab = {}
    for k in range(*rows):
        key, row = coeff_row(split(lines.line(k))[0], f"{path}:{k + 1}")
        tab[key] = row
    return table_arrays(tab)


def parse_fast(path, text: str, atom_style):
    """What :func:`jaxbpm.interop.lammps.read_lammps_data` reads line by line, each numeric section parsed in one go.

    Only the checksum, metadata and header errors, which come first, are raised here; any other irregularity
    returns ``None``, and the file is then read line by line (whose error names the line).

    Args:
      path: the file, for messages.
      text: its text.
      atom_style: ``"bpm/sphere"``, ``"sphere"`` or ``None`` (from the Atoms comment or the column count).

    Returns:
      ``(crc, checksummed text, meta, pos, dia, dens, bonds, btype, rb_c, mat_c, (types, coefficients), atom
      types)``, as the line-by-line reader gives it, or ``None`` for any file that is not plainly well formed.

    Raises:
      SampleFileError: a bad checksum field, metadata line or header line.
    """
    lines = _lines(text)
    if lines is None:
        return None
    crc, meta = head_meta(path, [lines.line(k) for k in range(min(6, lines.count))])
    counts, i = header(path, ((k + 1, lines.line(k)) for k in range(1, lines.count)))
    sections = _sections(lines, counts, i)
    atoms = None if sections is None else _atoms(lines, sections, atom_style)
    if atoms is not None and np.any((atoms[4] < 1) | (atoms[4] > counts.get("atom types", np.inf))):
        atoms = None  # a type outside the header's: the line-by-line reader names the line
    bonds = None if atoms is None else _bonds(lines, sections, atoms[0], counts)
    if bonds is None:
        return None
    _, dia, dens, pos, atom_types = atoms
    table = _coeffs(path, lines, sections)
    return (crc, text[text.index("\n") + 1:], meta, pos, dia, dens, *bonds, table, atom_types)
