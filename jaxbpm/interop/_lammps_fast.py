"""The fast path of :func:`jaxbpm.interop.lammps.read_lammps_data`: every numeric section of a plainly well-formed
data file parsed in one go (``np.loadtxt`` with a type per column, checks vectorised). Anything irregular or
wrong returns ``None`` and the file is read line by line, whose errors name the line."""

from __future__ import annotations

import bisect
import io

import numpy as np

from jaxbpm.interop._meta import _N_COEFFS
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


def parse_fast(path, text: str, atom_style):
    """What :func:`jaxbpm.interop.lammps._parse_lines` gives, each numeric section parsed in one go; ``None`` for any file that is not
    plainly well formed (every check of :func:`jaxbpm.interop.lammps._parse_lines` passes), which is then read line by line (and its
    error names the line). Only the checksum, metadata and header errors, which come first, are raised here."""
    if not text.endswith("\n") or any(c in text for c in _BREAKS):
        return None
    data = text.encode("utf-8", "surrogatepass")
    buf = np.frombuffer(data, np.uint8)
    nl = np.flatnonzero(buf == 10)
    if np.count_nonzero(buf < 32) != len(nl) + text.count("\t"):  # other control characters
        return None
    nlines = len(nl)
    starts = np.empty(nlines, np.int64)
    starts[0], starts[1:] = 0, nl[:-1] + 1
    # lines that start like a number are numeric rows (not blank, not a section name); the others are few
    special = np.flatnonzero(~_DATA_START[buf[starts]]).tolist()
    if len(special) > 10_000:
        return None
    special_set = set(special)

    def line(k: int) -> str:
        return data[starts[k]:nl[k]].decode("utf-8", "surrogatepass")

    def block(rows: tuple[int, int]) -> bytes:
        return data[starts[rows[0]]:nl[rows[1] - 1] + 1]

    crc, meta = head_meta(path, [line(k) for k in range(min(6, nlines))])
    counts, i = header(path, ((k + 1, line(k)) for k in range(1, nlines)))
    sections: dict[str, tuple[int, str, tuple[int, int]]] = {}
    while i < nlines:
        if i not in special_set:
            return None
        words, comment = split(line(i))
        if not words:
            i += 1
            continue
        name = " ".join(words)
        if name not in SECTIONS:
            return None
        want, j = counts.get(SECTIONS[name], 0), i + 1
        if want:
            while j < nlines and j in special_set:  # blank lines before the rows
                if split(line(j))[0]:
                    return None
                j += 1
            nxt = bisect.bisect_left(special, j)
            if j + want > nlines or (nxt < len(special) and special[nxt] < j + want):
                return None
        sections[name] = (i + 1, comment, (j, j + want))
        i = j + want
    if any(counts.get(key, 0) > 0 and name not in sections for name, key in (("Atoms", "atoms"), ("Bonds", "bonds"))):
        return None
    # atoms
    if "Atoms" not in sections:
        return None
    _, comment, rows = sections["Atoms"]
    style = atom_style or (comment.strip() or None)
    n = rows[1] - rows[0]
    if (style is not None and style not in ATOM_COLUMNS) or n == 0:
        return None
    text_rows = block(rows)
    ncols = len(line(rows[0]).split())
    ncol = ATOM_COLUMNS.get(style or {7: "sphere", 10: "sphere", 8: "bpm/sphere", 11: "bpm/sphere"}.get(ncols))
    if b"#" in text_rows or ncol is None or ncols not in (ncol, ncol + 3):
        return None
    off = ncol - 7
    got = _table(text_rows, [(f"c{k}", "f8" if 2 + off <= k <= 6 + off else "i8") for k in range(ncols)])
    if got is None or len(got) != n:
        return None
    ids, dia, dens = got["c0"], got[f"c{2 + off}"], got[f"c{3 + off}"]
    pos = np.stack([got[f"c{k + 4 + off}"] for k in range(3)], axis=1)
    if not (np.all((dia > 0) & np.isfinite(dia)) and np.all(np.isfinite(pos))):
        return None
    order = np.argsort(ids, kind="stable")
    ids, dia, dens, pos = ids[order], dia[order], dens[order], pos[order]
    if np.any(np.diff(ids) == 0) or np.any(dens != dens[0]):
        return None
    # bonds: "id type atom1 atom2", each with jaxbpm's comment "# bond_radius material" or none without
    _, _, rows = sections.get("Bonds", (0, "", (0, 0)))
    nb = rows[1] - rows[0]
    text_rows = block(rows) if nb else b""
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
    if got is None or len(got) != nb:
        return None
    t = got_t = got["t"]
    bonds = np.zeros((nb, 2), np.int64)
    for c, a in enumerate((got["a1"], got["a2"])):
        k = np.minimum(np.searchsorted(ids, a), n - 1)
        if np.any(ids[k] != a):
            return None
        bonds[:, c] = k
    if np.any(got["a1"] == got["a2"]) or np.any((t < 1) | (t > counts.get("bond types", 0))):
        return None
    if hashes and nb:
        rb_c, mat_c = np.ascontiguousarray(got["rb"]), np.ascontiguousarray(got["m"])
    else:
        rb_c, mat_c = np.full(nb, np.nan), np.full(nb, -1)
    # coefficients
    table = table_arrays({})
    if "Bond Coeffs" in sections:
        no, comment, rows = sections["Bond Coeffs"]
        coeffs_head(path, no, comment)
        text_rows = block(rows) if rows[1] > rows[0] else b""
        width = len(line(rows[0]).split()) if text_rows else 13
        got = None if b"#" in text_rows or width not in (9, 13) else \
            _table(text_rows, [("t", "i8")] + [(f"c{k}", "f8") for k in range(width - 1)]) if text_rows else \
            np.zeros(0, [("t", "i8")] + [(f"c{k}", "f8") for k in range(12)])
        if got is not None and len(got) == rows[1] - rows[0]:
            vals = np.zeros((len(got), _N_COEFFS))
            for k in range(width - 1):
                vals[:, k] = got[f"c{k}"]
            if not (np.any(np.isnan(vals)) or not np.all(np.isfinite(vals[:, :4]))):
                table = last_wins(got["t"], vals)
                got = True
        if got is not True:  # the rows line by line: the error names the line
            tab = {}
            for k in range(*rows):
                key, row = coeff_row(split(line(k))[0], f"{path}:{k + 1}")
                tab[key] = row
            table = table_arrays(tab)
    return (crc, text[text.index("\n") + 1:], meta, pos, dia, dens, bonds, np.asarray(got_t, np.int64), rb_c, mat_c, table)
