"""LAMMPS text dumps: ``ITEM: ATOMS`` frames and ``ITEM: ENTRIES`` frames of ``dump local``."""

from __future__ import annotations

import dataclasses
import pathlib

import numpy as np

from jaxbpm.errors import SampleFileError
from jaxbpm.interop._meta import read_text


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
        """The atom IDs of an atoms frame, sorted: ``[n]`` int64."""
        return np.sort(self.columns["id"].astype(np.int64))

    @property
    def positions(self) -> np.ndarray:
        """The atom positions ``[n, 3]`` [m] in the order of :attr:`ids` (scaled coordinates unscaled by the box)."""
        order = np.argsort(self.columns["id"], kind="stable")
        for names, scaled in ((("x", "y", "z"), False), (("xu", "yu", "zu"), False), (("xs", "ys", "zs"), True)):
            if all(c in self.columns for c in names):
                pos = np.stack([self.columns[c] for c in names], axis=1)[order]
                return self.box[:, 0] + pos * (self.box[:, 1] - self.box[:, 0]) if scaled else pos
        raise SampleFileError(f"dump frame at timestep {self.timestep} has no position columns (x y z, xu yu zu or "
                              f"xs ys zs); columns: {list(self.columns)}")

    @property
    def types(self) -> np.ndarray:
        """The atom types of an atoms frame (its ``type`` column) in the order of :attr:`ids`: ``[n]`` int64, as
        ``Sample.types`` takes them (``Sample.from_arrays(frame.positions, ..., types=frame.types)``)."""
        if "type" not in self.columns:
            raise SampleFileError(f"dump frame at timestep {self.timestep} has no 'type' column; columns: "
                                  f"{list(self.columns)}")
        t = self.columns["type"]
        if not np.all(np.isfinite(t) & (t == np.round(t))):
            raise SampleFileError(f"dump frame at timestep {self.timestep}: the 'type' column holds values that are "
                                  f"not whole numbers")
        return t[np.argsort(self.columns["id"], kind="stable")].astype(np.int64)

    @property
    def bond_atoms(self) -> np.ndarray:
        """The two atom IDs of each entry of a local (bond) frame: ``[nb, 2]`` int64."""
        names = list(self.columns)
        a = next((c for c in names if "batom1" in c), names[0])
        b = next((c for c in names if "batom2" in c), names[1])
        return np.stack([self.columns[a], self.columns[b]], axis=1).astype(np.int64)

    def bonds(self, ids) -> np.ndarray:
        """:attr:`bond_atoms` as 0-based particle indices.

        Args:
          ids: ``[n]`` the particles' atom IDs (e.g. ``frame.ids`` of an atoms frame, or particle index + 1 for a
            file written by :func:`~jaxbpm.interop.lammps.write_lammps_data`).

        Returns:
          ``[nb, 2]`` int64 indices into ``ids``.
        """
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
    """Read all frames of a LAMMPS text dump (``dump atom/custom`` or ``dump local``).

    Args:
      path: the dump file.

    Returns:
      The frames, in file order.

    Raises:
      SampleFileError: a missing or malformed file (the line is named).
    """
    path = pathlib.Path(path)
    lines = read_text(path).splitlines()
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
            words = lines[i + 5 + c].split()[:2]
            try:
                box[c] = [float(w) for w in words]
                if len(words) != 2 or not np.isfinite(box[c]).all():
                    raise ValueError
            except ValueError:
                raise SampleFileError(f"{path}:{i + 6 + c}: box bounds must be two finite numbers (lo hi), got "
                                      f"{lines[i + 5 + c].strip()!r}") from None
        names = expect(i + 8, "ITEM: ATOMS" if kind == "atoms" else "ITEM: ENTRIES").split()
        if not names:
            raise SampleFileError(f"{path}:{i + 9}: the ITEM line names no columns")
        if kind == "local" and len(names) < 2:
            raise SampleFileError(f"{path}:{i + 9}: an ENTRIES frame needs two columns of bond atom IDs, got "
                                  f"{' '.join(names)!r}")
        if count < 0:
            raise SampleFileError(f"{path}:{i + 4}: the number of {'atoms' if kind == 'atoms' else 'entries'} is "
                                  f"{count} (< 0)")
        if count > len(lines) - (i + 9):  # (before any memory is taken for the rows)
            raise SampleFileError(f"{path}:{len(lines)}: the frame at timestep {step} ends after "
                                  f"{len(lines) - (i + 9)} of {count} rows")
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
        id_cols = ["id"] if kind == "atoms" else [next((c for c in names if key in c), names[k])
                                                  for k, key in enumerate(("batom1", "batom2"))]
        for name in id_cols:  # atom IDs: whole numbers (a NaN would become an arbitrary integer)
            bad = np.flatnonzero(~np.isfinite(cols[name]) | (cols[name] != np.round(cols[name]))
                                 | (np.abs(cols[name]) >= 2.0**62))
            if bad.size:
                raise SampleFileError(f"{path}:{i + 10 + int(bad[0])}: column {name!r} holds atom IDs, which must be "
                                      f"whole numbers; got {lines[i + 9 + int(bad[0])].strip()!r}")
        frames.append(DumpFrame(step, box, kind, cols))
        i += 9 + count
    if not frames:
        raise SampleFileError(f"{path}: no frames (not a LAMMPS text dump?)")
    return frames
