"""VTU time series for ParaView, read back with meshio."""

import xml.etree.ElementTree as ET

import meshio
import numpy as np

from jaxbpm.interop import formats
from tests.interop.samples import _sample


# ============================================================================================== VTU series
def test_vtu_series_read_back(tmp_path):
    sample = _sample()
    n, nb = sample.n_particles, sample.n_bonds
    rng = np.random.default_rng(1)
    frames = []
    for step in range(3):
        intact = np.ones(nb, bool)
        intact[:step] = False
        frames.append({"time": 0.1 * step, "displacement": 1e-3 * step * rng.standard_normal((n, 3)),
                       "intact": intact, "point_data": {"velocity": rng.standard_normal((n, 3)),
                                                        "stiffness": rng.random(n)},
                       "bond_data": {"force": rng.standard_normal(nb), "break_mode": np.arange(nb) % 3}})
    pvd = formats.write_vtu_series(tmp_path / "run.pvd", sample, frames)
    files = [d.get("file") for d in ET.parse(pvd).getroot().iter("DataSet")]
    times = [float(d.get("timestep")) for d in ET.parse(pvd).getroot().iter("DataSet")]
    assert times == [0.0, 0.1, 0.2] and len(files) == 3
    for frame, name in zip(frames, files):
        mesh = meshio.read(tmp_path / name)
        np.testing.assert_allclose(mesh.points, np.asarray(sample.positions) + frame["displacement"])
        np.testing.assert_array_equal(mesh.cells_dict["line"], sample.bonds)
        np.testing.assert_allclose(mesh.point_data["velocity"], frame["point_data"]["velocity"])
        broken = np.bincount(np.asarray(sample.bonds)[~frame["intact"]].ravel(), minlength=n)
        np.testing.assert_array_equal(mesh.point_data["broken_bonds"], broken)
        intact = [c for c in mesh.cell_data["intact"] if len(c) == nb][0]
        np.testing.assert_array_equal(intact, frame["intact"])
        np.testing.assert_array_equal(mesh.cell_data["broken"][1], ~frame["intact"])  # (ParaView thresholds it)
        force = [c for c in mesh.cell_data["force"] if len(c) == nb][0]
        np.testing.assert_allclose(force, frame["bond_data"]["force"])
    assert not list(tmp_path.glob(".*.tmp"))  # atomic writes leave no temporary files


def test_vtu_series_carries_the_particle_types(tmp_path):
    sample = _sample().replace(types=[1, 3, 3, 2, 1, 9])
    formats.write_vtu_series(tmp_path / "run.pvd", sample, [{"time": 0.0}])
    mesh = meshio.read(next(tmp_path.glob("*.vtu")))
    np.testing.assert_array_equal(mesh.point_data["type"], [1, 3, 3, 2, 1, 9])
