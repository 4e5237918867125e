"""LIGGGHTS data and dump files and Yade text files (jaxbpm.interop.othercodes)."""

import textwrap

import numpy as np
import pytest

from jaxbpm import generate
from jaxbpm.errors import SampleFileError
from jaxbpm.interop import formats
from jaxbpm.sample import Sample


# ============================================================================================== LIGGGHTS
LIGGGHTS_DATA = """\
LIGGGHTS data file from restart file: timestep = 0, procs = 1

4 atoms
1 atom types
3 bonds
1 bond types

-0.01 0.01 xlo xhi
-0.01 0.01 ylo yhi
-0.01 0.01 zlo zhi

Atoms # granular

1 1 0.002 2500 0 0 0 0 0 0
3 1 0.002 2500 0.004 0 0 0 0 0
2 1 0.002 2500 0.002 0 0 0 0 0
4 1 0.0025 2500 0.004 0.00225 0 0 0 0

Velocities

1 0 0 0 0 0 0
2 0 0 0 0 0 0
3 0 0 0 0 0 0
4 0 0 0 0 0 0

Bonds

1 1 1 2
2 1 2 3
3 1 3 4
"""


def test_read_liggghts_data(tmp_path):
    path = tmp_path / "in.data"
    path.write_text(LIGGGHTS_DATA)
    s = formats.read_liggghts_data(path, bond_radius_ratio=0.5)
    np.testing.assert_array_equal(s.radii, [0.001, 0.001, 0.001, 0.00125])
    np.testing.assert_array_equal(np.asarray(s.positions)[:, 0], [0, 0.002, 0.004, 0.004])  # ordered by ID
    np.testing.assert_array_equal(s.bonds, [[0, 1], [1, 2], [2, 3]])
    assert float(s.particle_material.density) == 2500.0
    assert s.n_bonds == 3 and np.allclose(s.bond_radius, 0.5e-3)
    same = formats.read_sample(path, format="liggghts", bond_radius_ratio=0.5)
    np.testing.assert_array_equal(same.positions, s.positions)
    # particles only
    no_bonds = LIGGGHTS_DATA.replace("3 bonds\n1 bond types\n", "").split("\nBonds")[0]
    path.write_text(no_bonds)
    assert formats.read_liggghts_data(path).n_bonds == 0
    # bonds without a bond radius: the error says what to give
    path.write_text(LIGGGHTS_DATA)
    with pytest.raises(SampleFileError, match="bond_radius_ratio"):
        formats.read_liggghts_data(path)
    path.write_text(LIGGGHTS_DATA.replace("3 1 0.002 2500 0.004 0 0", "3 1 0.002 2500 0.004 zero 0"))
    with pytest.raises(SampleFileError, match=r"in.data:15"):
        formats.read_liggghts_data(path, bond_radius_ratio=0.5)


def test_read_liggghts_dump(tmp_path):
    path = tmp_path / "dump.liggghts"
    path.write_text(textwrap.dedent("""\
        ITEM: TIMESTEP
        1000
        ITEM: NUMBER OF ATOMS
        2
        ITEM: BOX BOUNDS ff ff ff
        -0.01 0.01
        -0.01 0.01
        -0.01 0.01
        ITEM: ATOMS id type x y z ix iy iz vx vy vz fx fy fz omegax omegay omegaz radius
        2 1 0.002 0 0 0 0 0 0.1 0 0 0 0 0 0 0 0 0.001
        1 1 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0.001
        """))
    (frame,) = formats.read_liggghts_dump(path)
    assert frame.timestep == 1000 and frame.kind == "atoms"
    np.testing.assert_array_equal(frame.positions, [[0, 0, 0], [0.002, 0, 0]])
    np.testing.assert_array_equal(frame.columns["radius"], [0.001, 0.001])


# ============================================================================================== Yade
def test_yade_text_round_trip(tmp_path):
    sample = generate.lattice("fcc", (2, 2, 1), 1e-3)
    rng = np.random.default_rng(3)
    sample = Sample.from_arrays(np.asarray(sample.positions) + 1e-6 * rng.standard_normal((sample.n_particles, 3)),
                                np.asarray(sample.radii) * (1 + 0.01 * rng.random(sample.n_particles)),
                                np.zeros((0, 2), int), np.zeros(0))
    path = formats.write_yade_text(tmp_path / "spheres.txt", sample, comment="from jaxbpm")
    lines = path.read_text().splitlines()
    assert lines[0] == "#format x_y_z_r" and lines[1] == "# from jaxbpm" and len(lines[2].split("\t")) == 4
    back = formats.read_yade_text(path)
    np.testing.assert_array_equal(back.positions, sample.positions)
    np.testing.assert_array_equal(back.radii, sample.radii)
    assert back.n_bonds > 0  # bonded at contacts
    assert formats.read_yade_text(path, bond_gap=None).n_bonds == 0
    np.testing.assert_array_equal(formats.read_sample(path, format="yade").bonds, back.bonds)


def test_yade_text_formats_and_errors(tmp_path):
    path = tmp_path / "y.txt"
    path.write_text("#format x_y_z_r_matId\n# a comment\n0\t0\t0\t1e-3\t2\n2e-3\t0\t0\t1e-3\t2\n")
    s = formats.read_yade_text(path)
    assert s.n_particles == 2 and s.n_bonds == 1
    path.write_text("#format x_y_z_r_attrs\n# x y z r speed\n0 0 0 1e-3 0.5\n2e-3 0 0 1e-3 0.1\n")
    assert formats.read_yade_text(path).n_particles == 2
    path.write_text("0 0 0 1e-3\n2e-3 0 0 1e-3\n")  # no #format line: x_y_z_r, as in Yade
    assert formats.read_yade_text(path).n_particles == 2
    for text, message in (("#format x_y_z_r\n0 0 0 1e-3 7\n", r"y.txt:2: 5 values, expected 4"),
                          ("#format x_y_z_r\n0 0 0 -1\n", r"y.txt:2: .*radius > 0"),
                          ("#format x_y_z_r\n0 0 zero 1\n", r"y.txt:2: x y z r must be numbers"),
                          ("#format x_y_z_r_color\n0 0 0 1\n", r"y.txt:1: .*'x_y_z_r_color'"),
                          ("#format x_y_z_r\n", "no spheres")):
        path.write_text(text)
        with pytest.raises(SampleFileError, match=message):
            formats.read_yade_text(path)
    with pytest.raises(SampleFileError, match="unknown format"):
        formats.read_sample(path, format="pfc")


def test_yade_mat_ids_are_the_particle_types(tmp_path):
    s = generate.lattice("sc", (3, 2, 2), 1e-3)
    typed = s.replace(types=np.arange(s.n_particles) % 3)
    path = formats.write_yade_text(tmp_path / "t.txt", typed)
    assert path.read_text().startswith("#format x_y_z_r_matId\n")
    back = formats.read_yade_text(path, bond_gap=None)
    np.testing.assert_array_equal(back.types, typed.types)
    np.testing.assert_array_equal(back.positions, typed.positions)
    plain = formats.write_yade_text(tmp_path / "p.txt", s)  # every type 1: the plain layout, as before
    assert plain.read_text().startswith("#format x_y_z_r\n")
    assert formats.read_yade_text(plain, bond_gap=None).types.tolist() == [1] * s.n_particles
    bad = path.read_text().replace("\t2\n", "\ttwo\n", 1)
    (tmp_path / "b.txt").write_text(bad)
    with pytest.raises(SampleFileError, match="matId must be a whole number"):
        formats.read_yade_text(tmp_path / "b.txt")


def test_liggghts_atom_types_are_the_particle_types(tmp_path):
    text = LIGGGHTS_DATA.replace("1 atom types", "3 atom types").replace("3 1 0.002 2500", "3 3 0.002 2500")
    (tmp_path / "l.data").write_text(text.replace("4 1 0.0025", "4 2 0.0025"))
    s = formats.read_liggghts_data(tmp_path / "l.data", bond_radius_ratio=0.5)
    assert s.types.tolist() == [1, 1, 3, 2]  # atoms 1..4 (the file lists 1, 3, 2, 4)


def test_yade_text_refuses_2d_samples(tmp_path):
    from jaxbpm.errors import SampleError

    with pytest.raises(SampleError, match="Yade models spheres"):
        formats.write_yade_text(tmp_path / "d.txt", generate.lattice("square", (3, 3)))
    assert not (tmp_path / "d.txt").exists()
