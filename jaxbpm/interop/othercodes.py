"""Files of two more DEM codes: LIGGGHTS data files and dumps, and Yade's ``export.textExt`` sphere lists.

LIGGGHTS (a LAMMPS derivative) writes LAMMPS data files with ``atom_style granular`` (``Atoms`` lines ``id type
diameter density x y z``, optionally + 3 image flags: the columns of LAMMPS' ``sphere`` style) and LAMMPS text dumps
(``dump custom``). :func:`read_liggghts_data` reads the particles and, when the file has one, its ``Bonds``
section; LIGGGHTS' bond styles have no ``bpm/rotational`` coefficients, so bonded files need
``bond_radius_ratio=`` (and optionally ``materials=``). The atom types become ``Sample.types``.
:func:`read_liggghts_dump` reads dumps as :func:`jaxbpm.interop.dump.read_lammps_dump` does.

Yade's ``yade.export.textExt(filename, format=...)`` writes ``#format NAME`` on the first line, optional ``#``
comment lines, then one sphere a line, tab-separated: ``x y z r`` (``x_y_z_r``), ``x y z r matId``
(``x_y_z_r_matId``) or ``x y z r`` and more columns (``x_y_z_r_attrs``); ``yade.ymport.textExt`` reads them back.
:func:`read_yade_text` reads particles (a ``matId`` as the particle's type, ``Sample.types``) and bonds every pair
closer than a surface gap, as :func:`jaxbpm.generate.random_packing` does; :func:`write_yade_text` writes
``x_y_z_r`` with exact decimals (``x_y_z_r_matId`` with the particle types, where some type is not 1).

These files have no suffix of their own (``.data``, ``.txt``), so :func:`jaxbpm.interop.formats.read_sample` does
not choose them by suffix: call these functions, or pass ``format="liggghts"`` / ``format="yade"`` to
:func:`~jaxbpm.interop.formats.read_sample` and :func:`~jaxbpm.interop.formats.convert`.
"""

from __future__ import annotations

import pathlib

import numpy as np

from jaxbpm._atomic import atomic_write
from jaxbpm.errors import SampleError, SampleFileError
from jaxbpm.interop._meta import exact_text, names_file, read_text
from jaxbpm.interop.dump import DumpFrame, read_lammps_dump
from jaxbpm.interop.lammps import read_lammps_data
from jaxbpm.sample import Sample

__all__ = ["read_liggghts_data", "read_liggghts_dump", "read_yade_text", "write_yade_text", "YADE_FORMATS"]

YADE_FORMATS = {"x_y_z_r": 4, "x_y_z_r_matId": 5, "x_y_z_r_attrs": None}  # name -> values a line (None: >= 4)


def read_liggghts_data(path, *, bond_radius_ratio: float | None = None, materials=None, **sample_kw) -> Sample:
    """Read a LIGGGHTS data file (``atom_style granular``) into a :class:`Sample`.

    Args:
      path: the data file.
      bond_radius_ratio: bond radius over the smaller particle's radius, for the bonds of a ``Bonds`` section
        (``id type atom1 atom2``), if there is one.
      materials: the bond material table (default one component, see :meth:`Sample.from_arrays`).
      **sample_kw: more :meth:`Sample.from_arrays` keywords.

    Returns:
      The sample, particles ordered by atom ID.

    Raises:
      SampleFileError: a missing or malformed file (the line is named).
    """
    kw = dict(sample_kw)
    if bond_radius_ratio is not None:
        kw.update(bond_radius_ratio=bond_radius_ratio, materials=materials)
    elif materials is not None:
        kw["materials"] = materials
    return read_lammps_data(path, atom_style="sphere", **kw)


def read_liggghts_dump(path) -> list[DumpFrame]:
    """Read all frames of a LIGGGHTS text dump (``dump custom``, e.g. ``id type x y z vx vy vz radius``).

    Args:
      path: the dump, a LAMMPS text dump (:func:`jaxbpm.interop.dump.read_lammps_dump`).

    Returns:
      The frames, in file order.

    Raises:
      SampleFileError: a missing or malformed file (the line is named).
    """
    return read_lammps_dump(path)


@names_file
def read_yade_text(path, *, bond_gap: float | None = 0.05, bond_radius_ratio: float = 0.5, **sample_kw) -> Sample:
    """Read spheres written by Yade's ``export.textExt`` (formats ``x_y_z_r``, ``x_y_z_r_matId``,
    ``x_y_z_r_attrs``; a file without a ``#format`` line is ``x_y_z_r``, as in Yade) into a :class:`Sample`.

    Args:
      path: the text file.
      bond_gap: bond every pair whose surface gap is below ``bond_gap`` times the mean radius (as
        :func:`jaxbpm.generate.random_packing` does); ``None``: no bonds.
      bond_radius_ratio: bond radius over the smaller particle's radius.
      **sample_kw: more :meth:`Sample.from_arrays` keywords (``materials``, ``particle_material``, ...).

    Returns:
      The sample, particles in file order; in ``x_y_z_r_matId`` each particle's ``matId`` is its type
      (``Sample.types``).
    """
    from jaxbpm.generate import bond_pairs

    path = pathlib.Path(path)
    pos, rad, mat_ids = _yade_rows(path)
    sample_kw.setdefault("types", mat_ids)
    bonds = np.zeros((0, 2), np.int64)
    if bond_gap is not None:
        if not (np.isfinite(bond_gap) and bond_gap >= 0):
            raise SampleFileError(f"{path}: bond_gap must be finite and >= 0 (or None), got {bond_gap!r}")
        bonds = bond_pairs(pos, rad, float(bond_gap) * float(rad.mean()))
    return Sample.from_arrays(pos, rad, bonds, bond_radius_ratio=bond_radius_ratio, **sample_kw)


def _yade_rows(path: pathlib.Path) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Centres ``[n, 3]``, radii ``[n]`` and material ids ``[n]`` (``None`` but in ``x_y_z_r_matId``) of a textExt
    file; errors name the line."""
    fmt, rows, mats = "x_y_z_r", [], []
    for no, line in enumerate(read_text(path).splitlines(), start=1):
        words = line.split()
        if not words:
            continue
        if words[0] == "#format":
            fmt = words[1] if len(words) > 1 else ""
            if fmt not in YADE_FORMATS:
                raise SampleFileError(f"{path}:{no}: Yade text format {fmt!r} is not read by jaxbpm (known: "
                                      f"{', '.join(YADE_FORMATS)})")
            continue
        if words[0].startswith("#"):
            continue
        want = YADE_FORMATS[fmt]
        if (len(words) != want) if want else (len(words) < 4):
            raise SampleFileError(f"{path}:{no}: {len(words)} values, expected {want or 'at least 4'} ({fmt}: "
                                  f"x y z r{' matId' if fmt.endswith('matId') else ''}...)")
        try:
            row = [float(w) for w in words[:4]]
        except ValueError:
            raise SampleFileError(f"{path}:{no}: x y z r must be numbers, got {line.strip()!r}") from None
        if not (np.all(np.isfinite(row)) and row[3] > 0):
            raise SampleFileError(f"{path}:{no}: a sphere needs a finite centre and radius > 0, got "
                                  f"{line.strip()!r}")
        if fmt == "x_y_z_r_matId":
            try:
                mats.append(int(words[4]))
            except ValueError:
                raise SampleFileError(f"{path}:{no}: matId must be a whole number, got {words[4]!r}") from None
        rows.append(row)
    if not rows:
        raise SampleFileError(f"{path}: no spheres (not a Yade textExt file?)")
    arr = np.array(rows, np.float64)
    return arr[:, :3], arr[:, 3], (np.array(mats, np.int64) if len(mats) == len(rows) else None)


def write_yade_text(path, sample: Sample, *, comment: str | None = None,
                    mat_ids: bool | None = None) -> pathlib.Path:
    """Write the particles of ``sample`` in Yade's ``export.textExt`` ``x_y_z_r`` layout (or ``x_y_z_r_matId``, each
    particle's type as its material id), atomically.

    Tab-separated, exact decimals; load it in Yade with ``ymport.textExt(path, format='x_y_z_r')`` (or
    ``'x_y_z_r_matId'``). Bonds are not written (Yade makes its cohesive bonds from contacts).

    Args:
      path: the text file.
      sample: the sample.
      comment: a comment line written after the ``#format`` line.
      mat_ids: write ``x_y_z_r_matId`` with ``Sample.types`` (``None``: where some type is not 1).

    Returns:
      ``path`` as a :class:`pathlib.Path`.

    Raises:
      SampleError: a two-dimensional sample (Yade has no discs).
    """
    if not isinstance(sample, Sample):
        raise TypeError(f"write_yade_text expects a jaxbpm Sample, got {type(sample).__name__}")
    if comment is not None and (comment.splitlines() != [comment]):
        raise SampleFileError(f"{path}: comment must be one line of text, got {comment!r}")
    if sample.dim == 2:
        raise SampleError("write_yade_text: Yade models spheres (3D only); a 2D sample (discs, positions [n, 2]) has "
                          "no Yade form: write it for LAMMPS (dimension 2, write_lammps_data) or as CSV")
    pos, rad = np.asarray(sample.positions, np.float64), np.asarray(sample.radii, np.float64)
    types = np.ones(len(rad), np.int64) if sample.types is None else np.asarray(sample.types, np.int64)
    with_ids = bool(np.any(types != 1)) if mat_ids is None else bool(mat_ids)
    head = f"#format x_y_z_r{'_matId' if with_ids else ''}\n" + (f"# {comment}\n" if comment else "")
    ends = [f"\t{t}\n" for t in types.tolist()] if with_ids else ["\n"] * len(rad)
    body = "".join(f"{exact_text(x)}\t{exact_text(y)}\t{exact_text(z)}\t{exact_text(r)}{e}"
                   for (x, y, z), r, e in zip(pos.tolist(), rad.tolist(), ends))
    return atomic_write(path, lambda tmp: pathlib.Path(tmp).write_text(head + body, encoding="utf-8"))
