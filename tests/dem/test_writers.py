"""What a DEM run writes as it goes: records appended to HDF5, VTU snapshots with broken bonds for ParaView,
progress output; the output options checked before anything runs; a record never replacing another file."""

import meshio
import numpy as np
import pytest

import jaxbpm
from jaxbpm import SampleFileError, SceneError
from jaxbpm.dem.records import read_records
from jaxbpm.scenes import UniaxialCompression

R = 1e-3


@pytest.fixture(scope="module")
def weak():
    """A small FCC block whose bonds break under compression (bonds only: quick)."""
    return jaxbpm.generate.lattice("fcc", (2, 2, 2), R, materials={"E": 1e9, "nu": 0.25, "tensile_strength": 2e6,
                                                                   "shear_strength": 4e6})


SCENE = UniaxialCompression(strain=0.03, breakage=True)


def test_records_snapshots_and_progress(weak, tmp_path, capsys):
    h5, pvd = tmp_path / "run.h5", tmp_path / "run.pvd"
    res = jaxbpm.solve(weak, SCENE, "dem", transits=10, record_to=h5, snapshots=4, vtu=pvd, progress=True)
    assert "DEM step" in capsys.readouterr().err  # progress still printed
    rec, attrs = read_records(h5)
    assert attrs["status"] == "complete" and attrs["steps"] == res.stats["steps"] == attrs["steps_planned"]
    assert len(rec["time"]) == res.stats["steps"]
    np.testing.assert_allclose(rec["displacement"], res.stats["speed"] * rec["time"])
    np.testing.assert_array_equal(rec["force"], SCENE.compressive_force(rec["reaction"]))
    assert np.all(np.isin(res.force, rec["force"]))  # the returned curve is a subset of every step's record
    np.testing.assert_array_equal(rec["broken"][-1], [res.stats["broken_tensile"], res.stats["broken_shear"]])
    assert rec["broken"][-1].sum() > 0 and attrs["peak_force"] == res.stats["peak_force"]

    # four frames, the first at rest, the last the final state, bonds with their break mode
    assert res.stats["vtu_frames"] == 4
    files = sorted(tmp_path.glob("run_*.vtu"))
    assert len(files) == 4 and pvd.read_text().count("<DataSet") == 4
    first, last = meshio.read(files[0]), meshio.read(files[-1])
    np.testing.assert_array_equal(first.point_data["displacement"], 0.0)
    assert np.all(first.cell_data["intact"][1] == 1)
    state = res.state
    mode = np.asarray(state.broken)
    np.testing.assert_array_equal(last.cell_data["intact"][1], (mode == 0).astype(np.int32))
    np.testing.assert_array_equal(last.cell_data["break_mode"][1], mode)
    np.testing.assert_allclose(last.points, np.asarray(state.positions))
    np.testing.assert_allclose(last.point_data["velocity"], np.asarray(state.velocities))
    b = np.asarray(weak.bonds)
    assert last.point_data["broken_tensile"].sum() == 2 * np.sum(mode == 1)
    assert last.point_data["broken_shear"].sum() == 2 * np.sum(mode == 2)
    np.testing.assert_array_equal(last.point_data["broken_bonds"], np.bincount(b[mode > 0].ravel(),
                                                                                minlength=weak.n_particles))
    broken_t = last.cell_data["broken_time"][1]
    assert np.all(np.isnan(broken_t[mode == 0])) and np.all(broken_t[mode > 0] > 0)


def test_output_options_are_checked(weak, tmp_path):
    with pytest.raises(SceneError, match="snapshots"):
        jaxbpm.solve(weak, SCENE, "dem", snapshots=3)
    with pytest.raises(SceneError, match="snapshots"):
        jaxbpm.solve(weak, SCENE, "dem", snapshots=0, vtu=tmp_path / "a.pvd")
    with pytest.raises(SampleFileError, match=".h5"):
        jaxbpm.solve(weak, SCENE, "dem", record_to=tmp_path / "run.txt")
    with pytest.raises(SampleFileError, match="no such record file"):
        read_records(tmp_path / "missing.h5")


def test_a_record_never_replaces_another_file(weak, tmp_path):
    h5 = tmp_path / "sample.h5"
    jaxbpm.io.save_sample(h5, weak)
    before = h5.read_bytes()
    with pytest.raises(SampleFileError, match=r"sample\.h5 exists and is not a record of this run.*overwrite=True"):
        jaxbpm.solve(weak, SCENE, "dem", transits=5, record_to=h5)
    assert h5.read_bytes() == before and jaxbpm.io.load_sample(h5).n_particles == weak.n_particles
    # running the same run again replaces its own record; another run does not; overwrite=True does
    run = tmp_path / "run.h5"
    first = jaxbpm.solve(weak, SCENE, "dem", transits=5, record_to=run)
    again = jaxbpm.solve(weak, SCENE, "dem", transits=5, record_to=run)
    assert again.stiffness == first.stiffness and read_records(run)[1]["status"] == "complete"
    with pytest.raises(SampleFileError, match="not a record of this run"):
        jaxbpm.solve(weak, SCENE, "dem", transits=5, damping=0.5, record_to=run)
    jaxbpm.solve(weak, SCENE, "dem", transits=5, record_to=h5, overwrite=True)
    assert read_records(h5)[1]["format"] == "jaxbpm-records"
