"""The XDMF companion of a sample file: what ParaView opens is the sample file's own data."""

import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

import jaxbpm
from jaxbpm import io
from jaxbpm.errors import SampleError
from jaxbpm.interop.xdmf import write_xdmf


def test_xdmf_companion_reads_back_as_the_sample(tmp_path):
    s = jaxbpm.generate.lattice("fcc", (2, 2, 2), 1e-3, materials={"E": [1e9, 2e9], "nu": 0.25})
    s = jaxbpm.generate.mix_materials(s, [0.5, 0.5], seed=0)
    h5 = io.save_sample(tmp_path / "s.h5", s)
    xdmf = write_xdmf(h5)
    assert xdmf == tmp_path / "s.xdmf"
    text = xdmf.read_text()
    assert "s.h5:/positions" in text and str(tmp_path) not in text  # by name: the pair can move together
    ET.fromstring(text)  # well-formed XML
    mesh = meshio.read(xdmf)  # an independent XDMF reader, through HDF5 (the sample file's header block skipped)
    np.testing.assert_array_equal(mesh.points, np.asarray(s.positions))
    np.testing.assert_array_equal(mesh.cells_dict["line"], np.asarray(s.bonds))
    np.testing.assert_array_equal(mesh.point_data["radius"], np.asarray(s.radii))
    np.testing.assert_array_equal(mesh.point_data["coordination"], np.asarray(s.coordination()))
    np.testing.assert_array_equal(mesh.cell_data["bond_radius"][0], np.asarray(s.bond_radius))
    np.testing.assert_array_equal(mesh.cell_data["material"][0], np.asarray(s.bond_material))
    np.testing.assert_allclose(mesh.cell_data["length"][0], np.asarray(s.bond_length), rtol=1e-15)
    assert io.load_sample(h5).n_bonds == s.n_bonds  # the sample file is untouched


def test_xdmf_needs_bonds_and_a_valid_sample(tmp_path):
    bare = jaxbpm.Sample.from_arrays(np.array([[0.0, 0, 0], [3e-3, 0, 0]]), 1e-3, np.zeros((0, 2), int),
                                     bond_radius_ratio=0.5)
    with pytest.raises(SampleError, match="no bonds.*export_vtk"):
        write_xdmf(io.save_sample(tmp_path / "bare.h5", bare))
    (tmp_path / "junk.h5").write_bytes(b"not a sample")
    with pytest.raises(jaxbpm.SampleFileError):
        write_xdmf(tmp_path / "junk.h5")
    assert not list(tmp_path.glob("*.xdmf"))


def test_xdmf_shows_the_particle_types(tmp_path):
    s = jaxbpm.generate.lattice("sc", (2, 2, 3), 1e-3)
    s = s.replace(types=np.arange(s.n_particles) % 2 + 1)
    mesh = meshio.read(write_xdmf(io.save_sample(tmp_path / "s.h5", s)))
    np.testing.assert_array_equal(mesh.point_data["type"], s.types)


def test_xdmf_of_a_2d_sample(tmp_path):
    """A disc sample's companion has an XY geometry that an independent reader opens as the discs' centres."""
    s = jaxbpm.generate.lattice("square", (3, 4)).replace(thickness=0.5)
    xdmf = write_xdmf(io.save_sample(tmp_path / "d.h5", s))
    assert 'GeometryType="XY"' in xdmf.read_text()
    mesh = meshio.read(xdmf)
    np.testing.assert_array_equal(mesh.points[:, :2], np.asarray(s.positions))
    np.testing.assert_array_equal(mesh.cells_dict["line"], np.asarray(s.bonds))
