"""VTKHDF series for ParaView: the topology stored once, each step's points and data, errors."""

import shutil

import h5py
import numpy as np
import pytest

from jaxbpm.errors import SampleError, SampleFileError
from jaxbpm.interop import formats
from tests.interop.samples import _lattice


# ============================================================================================== VTKHDF series
def test_vtkhdf_series_stores_the_topology_once(tmp_path):
    sample = _lattice()
    n, nb = sample.n_particles, sample.n_bonds
    rng = np.random.default_rng(0)
    steps = []
    with formats.VTKHDFSeries(tmp_path / "run.vtkhdf", sample) as series:
        for k in range(3):
            intact = np.ones(nb, bool)
            intact[:k] = False
            pos = np.asarray(sample.positions) + 1e-4 * k * rng.standard_normal((n, 3))
            steps.append((0.5 * k, pos, intact, rng.standard_normal(nb)))
            assert series.write(0.5 * k, positions=pos, intact=intact, bond_data={"force": steps[-1][3]}) == k
    with h5py.File(tmp_path / "run.vtkhdf", "r") as f:
        root = f["VTKHDF"]
        assert list(root.attrs["Version"]) == [2, 1] and root.attrs["Type"] == b"UnstructuredGrid"
        # one topology: a vertex per particle, then a line per bond
        assert root["Connectivity"].shape == (n + 2 * nb,)
        np.testing.assert_array_equal(root["Connectivity"][n:].reshape(-1, 2), sample.bonds)
        np.testing.assert_array_equal(root["Types"][:], [1] * n + [3] * nb)
        assert root["Offsets"].shape == (n + nb + 1,) and root["Offsets"][-1] == n + 2 * nb
        assert list(root["NumberOfPoints"]) == [n] and list(root["NumberOfCells"]) == [n + nb]
        st = root["Steps"]
        assert st.attrs["NSteps"] == 3
        np.testing.assert_array_equal(st["Values"][:], [0.0, 0.5, 1.0])
        np.testing.assert_array_equal(st["PointOffsets"][:], [0, n, 2 * n])
        for name in ("CellOffsets", "ConnectivityIdOffsets", "PartOffsets"):
            np.testing.assert_array_equal(st[name][:], [0, 0, 0])
        np.testing.assert_array_equal(st["NumberOfParts"][:], [1, 1, 1])
        np.testing.assert_array_equal(st["PointDataOffsets/radius"][:], [0, 0, 0])  # stored once
        assert root["PointData/radius"].shape == (n,)
        for k, (_, pos, intact, force) in enumerate(steps):
            at = st["PointOffsets"][k]
            np.testing.assert_array_equal(root["Points"][at:at + n], pos)
            c = st["CellDataOffsets/intact"][k]
            np.testing.assert_array_equal(root["CellData/intact"][c + n:c + n + nb], intact)
            assert np.all(root["CellData/intact"][c:c + n] == -1)
            c = st["CellDataOffsets/force"][k]
            np.testing.assert_array_equal(root["CellData/force"][c + n:c + n + nb], force)
            d = st["PointDataOffsets/displacement"][k]
            np.testing.assert_allclose(root["PointData/displacement"][d:d + n], pos - np.asarray(sample.positions))


def test_vtkhdf_series_errors(tmp_path):
    sample = _lattice()
    (tmp_path / "old.vtkhdf").write_bytes(b"keep me")
    with pytest.raises(SampleFileError, match="exists"):
        formats.VTKHDFSeries(tmp_path / "old.vtkhdf", sample)
    assert (tmp_path / "old.vtkhdf").read_bytes() == b"keep me"
    with pytest.raises(SampleFileError, match=".vtkhdf"):
        formats.VTKHDFSeries(tmp_path / "run.vtu", sample)
    series = formats.VTKHDFSeries(tmp_path / "run.vtkhdf", sample)
    series.write(0.0, point_data={"v": np.zeros((sample.n_particles, 3))})
    with pytest.raises(SampleError, match="same arrays"):
        series.write(1.0)
    with pytest.raises(SampleError, match="shape"):
        series.write(1.0, positions=np.zeros((2, 3)), point_data={"v": np.zeros((sample.n_particles, 3))})
    # the file on disk holds the steps written so far (flushed after each): what a run that stops leaves
    shutil.copyfile(tmp_path / "run.vtkhdf", tmp_path / "stopped.vtkhdf")
    with h5py.File(tmp_path / "stopped.vtkhdf", "r") as f:
        assert f["VTKHDF/Steps"].attrs["NSteps"] == 1 and f["VTKHDF/Points"].shape == (sample.n_particles, 3)
    series.close()
    with pytest.raises(SampleFileError, match="closed"):
        series.write(2.0)


def test_vtkhdf_series_stores_the_particle_types_once(tmp_path):
    sample = _lattice()
    sample = sample.replace(types=np.arange(sample.n_particles) % 4 + 1)
    with formats.VTKHDFSeries(tmp_path / "t.vtkhdf", sample) as series:
        series.write(0.0)
        series.write(1.0)
    with h5py.File(tmp_path / "t.vtkhdf", "r") as f:
        np.testing.assert_array_equal(f["VTKHDF/PointData/type"][:], sample.types)
        np.testing.assert_array_equal(f["VTKHDF/Steps/PointDataOffsets/type"][:], [0, 0])
