"""VTK export (jaxbpm._vtk, public as jaxbpm.io.export_vtk): readable back with meshio, user fields checked, atomic."""

import meshio
import numpy as np
import pytest

from jaxbpm import _vtk, io
from jaxbpm.errors import SampleError, SampleFileError
from jaxbpm.sample import Sample
from tests.test_io import _chain, _listing, _multi


@pytest.mark.parametrize("suffix", [".vtu", ".vtk"])
def test_export_vtk_readable(tmp_path, suffix):
    sample = _multi()
    n, nb = sample.n_particles, sample.n_bonds
    disp = np.arange(3 * n, dtype=np.float64).reshape(n, 3)
    force = np.linspace(-1.0, 1.0, nb)
    path = io.export_vtk(tmp_path / f"s{suffix}", sample, point_data={"displacement": disp, "flag": np.arange(n) > 2},
                         bond_data={"force": force})
    assert path.suffix == suffix and _listing(tmp_path) == [path.name]
    mesh = meshio.read(path)
    assert mesh.points.shape == (n, 3) and np.allclose(mesh.points, sample.positions)
    blocks = {c.type: c.data for c in mesh.cells}
    assert blocks["vertex"].shape == (n, 1) and blocks["line"].shape == (nb, 2)
    assert np.array_equal(blocks["line"], sample.bonds)
    assert np.allclose(mesh.point_data["radius"], sample.radii)
    assert np.allclose(mesh.point_data["mass"], sample.mass)
    assert np.array_equal(mesh.point_data["coordination"], sample.coordination())
    assert np.allclose(mesh.point_data["displacement"], disp)
    assert np.array_equal(np.ravel(mesh.point_data["flag"]), np.arange(n) > 2)
    line = [c.type for c in mesh.cells].index("line")
    vert = 1 - line
    assert np.allclose(mesh.cell_data["bond_radius"][line], sample.bond_radius)
    assert np.array_equal(mesh.cell_data["material"][line], sample.bond_material)
    assert np.allclose(mesh.cell_data["length"][line], sample.bond_length)
    assert np.allclose(mesh.cell_data["force"][line], force)
    assert np.isnan(mesh.cell_data["bond_radius"][vert]).all() and (mesh.cell_data["material"][vert] == -1).all()


def test_export_vtk_without_bonds(tmp_path):
    sample = Sample.from_arrays(np.eye(3), 0.2, np.zeros((0, 2), int), np.zeros(0))
    for suffix in (".vtu", ".vtk"):
        mesh = meshio.read(io.export_vtk(tmp_path / f"s{suffix}", sample))
        assert [c.type for c in mesh.cells] == ["vertex"] and mesh.points.shape == (3, 3)


@pytest.mark.parametrize("kw, match", [
    ({"point_data": {"temperature": np.zeros(3)}}, "point_data\\['temperature'\\].*\\[6\\]"),
    ({"point_data": {"u": np.zeros((6, 3, 3))}}, "point_data\\['u'\\]"),
    ({"point_data": {"radius": np.zeros(6)}}, "built-in"),
    ({"point_data": {"s": np.array(["a"] * 6)}}, "point_data\\['s'\\].*real numeric"),
    ({"bond_data": {"force": np.zeros(8)}}, "bond_data\\['force'\\].*\\[7\\]"),
])
def test_export_vtk_bad_user_data(tmp_path, kw, match):
    with pytest.raises(SampleError, match=match):
        io.export_vtk(tmp_path / "s.vtu", _multi(), **kw)
    assert _listing(tmp_path) == []


def test_export_vtk_bad_suffix(tmp_path):
    with pytest.raises(SampleFileError, match=r"\.vtu"):
        io.export_vtk(tmp_path / "s.txt", _chain())


def test_export_vtk_is_atomic(tmp_path, monkeypatch):
    target = tmp_path / "s.vtu"
    io.export_vtk(target, _chain())
    before = target.read_bytes()

    def boom(filename, mesh, file_format=None, **kw):
        with open(filename, "w") as fh:
            fh.write("<VTKFile half written")
        raise RuntimeError("crash mid-write")

    monkeypatch.setattr(meshio, "write", boom)
    with pytest.raises(RuntimeError, match="crash mid-write"):
        io.export_vtk(target, _multi())
    assert _listing(tmp_path) == ["s.vtu"] and target.read_bytes() == before


def test_io_exports_the_vtk_writer():
    assert io.export_vtk is _vtk.export_vtk


def test_export_vtk_writes_the_particle_types(tmp_path):
    sample = _chain(types=[5, 1, 1, 2, 2, 2])
    mesh = meshio.read(io.export_vtk(tmp_path / "t.vtu", sample))
    np.testing.assert_array_equal(mesh.point_data["type"], [5, 1, 1, 2, 2, 2])


@pytest.mark.parametrize("suffix", [".vtu", ".vtk"])
def test_export_vtk_writes_the_broken_bonds_by_mode(tmp_path, suffix):
    sample = _multi()
    n, nb = sample.n_particles, sample.n_bonds
    mode = np.array([0, 1, 2, 0, 2, 2, 1])
    mesh = meshio.read(io.export_vtk(tmp_path / f"s{suffix}", sample, break_mode=mode))
    line = [c.type for c in mesh.cells].index("line")
    np.testing.assert_array_equal(mesh.cell_data["break_mode"][line], mode)
    assert mesh.cell_data["broken"][line].sum() == np.count_nonzero(mode) == 5
    np.testing.assert_array_equal(mesh.cell_data["broken"][line], mode != 0)
    assert (mesh.cell_data["break_mode"][1 - line] == -1).all() and len(mesh.cell_data["broken"][1 - line]) == n
    for bad in (mode[:-1], np.r_[mode[:-1], 3]):
        with pytest.raises(SampleError, match="break_mode"):
            io.export_vtk(tmp_path / "bad.vtu", sample, break_mode=bad)
    assert nb == len(mode)


def test_export_vtk_two_dimensional_discs_at_z_zero(tmp_path):
    from jaxbpm.generate import lattice

    s = lattice("square", (3, 2), 1e-3)
    mesh = meshio.read(io.export_vtk(tmp_path / "discs.vtu", s))
    assert mesh.points.shape == (6, 3)
    assert np.array_equal(mesh.points[:, :2], s.positions) and np.all(mesh.points[:, 2] == 0.0)
    assert np.allclose(mesh.point_data["radius"], 1e-3)
