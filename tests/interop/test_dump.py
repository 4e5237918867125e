"""LAMMPS text dumps: atom frames (scaled coordinates, ids out of order) and local bond lists; errors name the line."""

import textwrap

import numpy as np
import pytest

from jaxbpm.interop import formats
from jaxbpm.errors import SampleFileError


# ============================================================================================== LAMMPS dump
DUMP = textwrap.dedent("""\
    ITEM: TIMESTEP
    100
    ITEM: NUMBER OF ATOMS
    3
    ITEM: BOX BOUNDS ff ff ff
    0.0 10.0
    0.0 10.0
    0.0 5.0
    ITEM: ATOMS id type xs ys zs vx
    3 1 0.3 0.0 0.2 1.5
    1 1 0.1 0.5 0.0 0.5
    2 1 0.2 1.0 1.0 1.0
    ITEM: TIMESTEP
    100
    ITEM: NUMBER OF ENTRIES
    2
    ITEM: BOX BOUNDS ff ff ff
    0.0 10.0
    0.0 10.0
    0.0 5.0
    ITEM: ENTRIES c_b[1] c_b[2] c_b[3]
    1 2 1
    3 2 1
    """)
"""Two frames of a LAMMPS text dump: atoms (scaled coordinates, ids out of order) and a local bond list."""


def test_lammps_dump_atoms_and_local(tmp_path):
    (tmp_path / "run.dump").write_text(DUMP)
    atoms, local = formats.read_lammps_dump(tmp_path / "run.dump")
    assert atoms.kind == "atoms" and atoms.timestep == 100 and local.kind == "local"
    np.testing.assert_array_equal(atoms.ids, [1, 2, 3])
    np.testing.assert_allclose(atoms.positions, [[1.0, 5.0, 0.0], [2.0, 10.0, 5.0], [3.0, 0.0, 1.0]])
    np.testing.assert_array_equal(local.bonds(atoms.ids), [[0, 1], [2, 1]])
    (tmp_path / "cut.dump").write_text(DUMP.replace("2 1 0.2 1.0 1.0 1.0", "2 1 0.2 1.0 one 1.0"))
    with pytest.raises(SampleFileError, match=r"cut\.dump:12: a value is not a number"):
        formats.read_lammps_dump(tmp_path / "cut.dump")


def test_dump_frame_types_follow_the_ids(tmp_path):
    (tmp_path / "run.dump").write_text(DUMP.replace("3 1 0.3", "3 4 0.3").replace("2 1 0.2", "2 2 0.2"))
    atoms, local = formats.read_lammps_dump(tmp_path / "run.dump")
    np.testing.assert_array_equal(atoms.types, [1, 2, 4])  # ids 1, 2, 3
    with pytest.raises(SampleFileError, match="has no 'type' column"):
        local.types
