"""The LAMMPS data file's layout as jaxbpm reads it (jaxbpm.interop._lammps_layout): header counts, comments,
coefficient rows and tables."""

import numpy as np
import pytest

from jaxbpm.errors import SampleFileError
from jaxbpm.interop import _lammps_layout as layout
from jaxbpm.interop import _meta
from tests.interop.samples import _sample


def test_split_and_header():
    assert layout.split("1 2 3 # 0.5 1") == (["1", "2", "3"], " 0.5 1") and layout.split("  ") == ([], "")
    text = ["title", "", "4 atoms", "3 bonds  # c", "2 bond types", "0 10 xlo xhi", "", "Atoms # sphere", ""]
    counts, start = layout.header("f", ((k + 1, s) for k, s in enumerate(text) if k >= 1))
    assert counts == {"atoms": 4, "bonds": 3, "bond types": 2} and text[start] == "Atoms # sphere"
    with pytest.raises(SampleFileError, match=r"^f:3: cannot read header line 'four atoms'"):
        layout.header("f", [(2, ""), (3, "four atoms")])
    with pytest.raises(SampleFileError, match=r"^f:2: the count of 'atoms' must be a whole number"):
        layout.header("f", [(2, "4.5 atoms"), (3, "Atoms")])
    with pytest.raises(SampleFileError, match=r"^f: no Atoms section"):
        layout.header("f", [(2, "4 atoms")])
    with pytest.raises(SampleFileError, match=r"^f: header lacks the 'atoms' count"):
        layout.header("f", [(2, "4 bonds"), (3, "Bonds")])
    assert set(layout.SECTIONS) >= {"Atoms", "Bonds", "Bond Coeffs"} and layout.ATOM_COLUMNS["sphere"] == 7


def test_coefficient_rows_and_tables():
    t, row = layout.coeff_row(["3"] + [str(v) for v in range(1, 9)], "f:9")
    assert t == 3 and np.array_equal(row, [1, 2, 3, 4, 5, 6, 7, 8, 0, 0, 0, 0])  # no dampings: zeros
    with pytest.raises(SampleFileError, match=r"^f:9: bpm/rotational coefficients need a type and 12 values"):
        layout.coeff_row(["3", "1", "2"], "f:9")
    with pytest.raises(SampleFileError, match=r"^f:9: bond coefficients must be numbers, the stiffnesses"):
        layout.coeff_row(["3", "inf"] + ["1"] * 7, "f:9")
    layout.coeffs_head("f", 4, " bpm/rotational ")
    with pytest.raises(SampleFileError, match=r"^f:4: Bond Coeffs are for 'harmonic'"):
        layout.coeffs_head("f", 4, "harmonic")
    rows = {2: np.full(12, 2.0), 1: np.full(12, 1.0)}
    keys, vals = layout.table_arrays(rows)
    assert np.array_equal(keys, [1, 2]) and np.array_equal(vals[:, 0], [1.0, 2.0])
    keys, vals = layout.last_wins(np.array([5, 1, 5]), np.array([[0.0], [1.0], [2.0]]))
    assert np.array_equal(keys, [1, 5]) and np.array_equal(vals, [[1.0], [2.0]])  # as a dict filled in order


def test_head_meta_reads_the_checksum_and_the_metadata_line():
    line = _meta.meta_line(_meta.meta_of(_sample(), normalize=False))
    crc, meta = layout.head_meta("f", ["title crc32=89abcdef", line, ""])
    assert crc == "89abcdef" and meta == _meta.parse_meta(line, "f:2") and meta["bond_contact"] == "superimpose"
    assert layout.head_meta("f", ["LAMMPS data file", "", "4 atoms"]) == (None, None)


def test_planar_positions():
    """dim from jaxbpm's header (thickness too), else 3; dim=2 drops z when every z is equal; bad dims named."""
    from jaxbpm.interop._lammps_layout import planar_positions

    pos = np.array([[0.0, 1.0, 0.0], [2.0, 3.0, 0.0]])
    kw = {}
    np.testing.assert_array_equal(planar_positions("f", pos, {"dim": 2, "thickness": 0.5}, None, kw), pos[:, :2])
    assert kw == {"thickness": 0.5}
    kw = {"thickness": 0.1}
    assert planar_positions("f", pos, {"dim": 2, "thickness": 0.5}, None, kw).shape == (2, 2) and kw["thickness"] == 0.1
    kw = {}
    assert planar_positions("f", pos, None, None, kw).shape == (2, 3) and kw == {}
    assert planar_positions("f", pos, None, 2, kw).shape == (2, 2) and kw == {"thickness": 1.0}
    with pytest.raises(SampleFileError, match="dim must be 2"):
        planar_positions("f", pos, None, 4, {})
    with pytest.raises(SampleFileError, match="atom 2"):
        planar_positions("f", pos + [[0, 0, 0], [0, 0, 1e-9]], None, 2, {})
