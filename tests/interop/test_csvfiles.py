"""CSV files (particles and bonds): exact round trips, foreign files, checksums, errors naming the line."""

import re

import numpy as np
import pytest

from jaxbpm.interop import formats
from jaxbpm.errors import SampleFileError
from tests.interop.samples import _assert_same, _multi, _sample


# ============================================================================================== CSV
@pytest.mark.parametrize("make", [_sample, _multi], ids=["default", "multi-material"])
def test_csv_round_trip_exact(tmp_path, make):
    sample = make()
    p, b = formats.write_csv(tmp_path / "s.csv", sample)
    assert b == tmp_path / "s_bonds.csv"
    _assert_same(sample, formats.read_csv(p))


def test_csv_copied_pair_reads_its_own_bonds(tmp_path):
    import shutil

    sample = _sample()
    p, b = formats.write_csv(tmp_path / "a.csv", sample)
    shutil.copy(p, tmp_path / "b.csv")
    rows = b.read_text().splitlines()
    first = rows[1].split(",")
    first[2] = repr(0.5 * float(first[2]))  # the copy's first bond is thinner
    (tmp_path / "b_bonds.csv").write_text("\n".join([rows[0], ",".join(first)] + rows[2:]) + "\n")
    # an edited file no longer matches the checksum; deleting the checksum line accepts the edit
    with pytest.raises(SampleFileError, match=r"b_bonds\.csv: the content does not match its CRC-32 checksum "
                                              r"\(bonds_crc32=.*To accept an intended edit, delete line \d+ "
                                              r"\('# crc32=.*'\) of b\.csv"):
        formats.read_csv(tmp_path / "b.csv")
    lines = (tmp_path / "b.csv").read_text().splitlines()
    (tmp_path / "b.csv").write_text("\n".join(ln for ln in lines if not ln.startswith("# crc32=")) + "\n")
    got = formats.read_csv(tmp_path / "b.csv")  # b_bonds.csv, not a_bonds.csv (the name in the metadata)
    np.testing.assert_allclose(got.bond_radius[0], 0.5 * sample.bond_radius[0], rtol=1e-15)
    (tmp_path / "b_bonds.csv").unlink()  # without a file of its own name, the one the metadata names
    np.testing.assert_allclose(formats.read_csv(tmp_path / "b.csv").bond_radius[0], sample.bond_radius[0])
    # a bonds file cut at a row boundary, or down to its header, no longer reads as fewer bonds
    (tmp_path / "b_bonds.csv").write_text("\n".join(rows[:-1]) + "\n")
    with pytest.raises(SampleFileError, match=rf"{sample.n_bonds - 1} bonds read, but b\.csv's metadata declares "
                                              rf"{sample.n_bonds}"):
        formats.read_csv(tmp_path / "b.csv")
    (tmp_path / "b_bonds.csv").write_text(rows[0] + "\n")
    with pytest.raises(SampleFileError, match="0 bonds read"):
        formats.read_csv(tmp_path / "b.csv")


def test_csv_foreign_and_errors(tmp_path):
    (tmp_path / "p.csv").write_text("id,x,y,z,diameter\n10,0,0,0,1.0\n11,1,0,0,1.0\n12,2,0,0,1.0\n")
    (tmp_path / "p_bonds.csv").write_text("id1,id2,bond_diameter,E,nu\n10,11,0.5,1e9,0.2\n11,12,0.4,2e9,0.2\n")
    s = formats.read_csv(tmp_path / "p.csv")
    np.testing.assert_array_equal(s.bonds, [[0, 1], [1, 2]])
    np.testing.assert_array_equal(s.bond_radius, [0.25, 0.2])
    np.testing.assert_array_equal(s.materials.E, [1e9, 2e9])
    (tmp_path / "p_bonds.csv").write_text("id1,id2,bond_diameter\n10,11,0.5\n11,13,0.4\n")
    with pytest.raises(SampleFileError, match=r"p_bonds\.csv:3: bond refers to particle id 13"):
        formats.read_csv(tmp_path / "p.csv")
    (tmp_path / "p.csv").write_text("id,x,y,z,radius\n0,0,0,0,0.5\n1,1,zero,0,0.5\n")
    with pytest.raises(SampleFileError, match=r"p\.csv:3: column 'y' must hold numbers"):
        formats.read_csv(tmp_path / "p.csv")



def test_csv_checksums(tmp_path):
    sample = _multi()
    p, b = formats.write_csv(tmp_path / "s.csv", sample)
    last = p.read_text().splitlines()[-1]
    assert re.fullmatch(r"# crc32=[0-9a-f]{8} bonds_crc32=[0-9a-f]{8}", last)
    text = p.read_text()
    p.write_text(text.replace("2650.0", "2651.0"))  # the particle density, in the metadata line
    with pytest.raises(SampleFileError, match=r"s\.csv: the content does not match its CRC-32 checksum \(crc32="):
        formats.read_csv(p)
    p.write_text(text)
    rows = b.read_text().splitlines()
    b.write_text("\n".join([rows[0], rows[2], rows[1]] + rows[3:]) + "\n")  # two bonds swapped
    with pytest.raises(SampleFileError, match=r"s_bonds\.csv: the content does not match its CRC-32 checksum "
                                              r"\(bonds_crc32=.* on line \d+ of s\.csv"):
        formats.read_csv(p)
    p.write_text("".join(ln for ln in text.splitlines(keepends=True) if not ln.startswith("# crc32=")))
    swapped = formats.read_csv(p)  # without the checksum line, the edit is accepted
    np.testing.assert_array_equal(swapped.bonds[[1, 0]], sample.bonds[:2])
    b.write_text("\n".join(rows) + "\n")
    _assert_same(sample, formats.read_csv(p))


def test_csv_carries_the_particle_types(tmp_path):
    typed = _multi().replace(types=[2, 2, 5, 1, 0, 3])
    p, _ = formats.write_csv(tmp_path / "s.csv", typed)
    assert "id,x,y,z,radius,type" in p.read_text()
    _assert_same(typed, formats.read_csv(p))
    # a foreign file: types from a 'group' column, or type 1 without one
    (tmp_path / "f.csv").write_text("id,x,y,z,radius,group\n0,0,0,0,0.5,4\n1,1,0,0,0.5,2\n")
    assert formats.read_csv(tmp_path / "f.csv").types.tolist() == [4, 2]
    (tmp_path / "g.csv").write_text("id,x,y,z,radius\n0,0,0,0,0.5\n1,1,0,0,0.5\n")
    assert formats.read_csv(tmp_path / "g.csv").types.tolist() == [1, 1]
    (tmp_path / "h.csv").write_text("id,x,y,z,radius,type\n0,0,0,0,0.5,a\n")
    with pytest.raises(SampleFileError, match=r"h\.csv:2: column 'type' must hold whole numbers"):
        formats.read_csv(tmp_path / "h.csv")


def test_csv_2d_round_trip_and_foreign_file(tmp_path):
    """A disc sample writes x,y (no z) and reads back exactly, thickness included; a foreign x,y file (no header
    comment) reads as discs of the thickness given."""
    import jaxbpm

    sample = jaxbpm.generate.disc_packing(40, seed=2, thickness=0.3, materials={"E": 2e9, "tensile_strength": 1e6})
    p, b = formats.write_csv(tmp_path / "d.csv", sample)
    assert p.read_text().splitlines()[1] == "id,x,y,radius,type"
    back = formats.read_csv(p)
    assert back.dim == 2 and back.thickness == 0.3
    _assert_same(sample, back)
    lines = [ln for ln in p.read_text().splitlines() if not ln.startswith("#")]
    (tmp_path / "f.csv").write_text("\n".join(lines) + "\n")
    (tmp_path / "f_bonds.csv").write_text(b.read_text())
    foreign = formats.read_csv(tmp_path / "f.csv", thickness=0.3)
    assert foreign.dim == 2 and foreign.thickness == 0.3
    np.testing.assert_array_equal(foreign.positions, sample.positions)
    np.testing.assert_array_equal(foreign.bond_area, sample.bond_area)
