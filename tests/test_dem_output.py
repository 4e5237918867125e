"""Long DEM runs: records appended to HDF5 as they arrive, Ctrl-C without losing what was computed, VTU snapshots
with broken bonds for ParaView, progress output."""

import meshio
import numpy as np
import pytest

import jaxbpm
from jaxbpm import SampleFileError, SceneError, SimulationInterrupted, dem
from jaxbpm.physics.model import default_params
from jaxbpm.records import read_records
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


def test_interrupt_keeps_what_was_computed(weak, tmp_path):
    h5 = tmp_path / "cut.h5"
    seen = []

    def stop_after_three(done, total, elapsed):
        # the record file is valid HDF5 between chunks and already holds every step done
        seen.append((done, read_records(h5)[0]["time"].shape[0]))
        if len(seen) == 3:
            raise KeyboardInterrupt

    with pytest.raises(SimulationInterrupted) as info:
        jaxbpm.solve(weak, SCENE, "dem", transits=10, chunk=20, record_to=h5, progress=stop_after_three)
    err = info.value
    assert isinstance(err, KeyboardInterrupt)
    assert seen == [(20, 20), (40, 40), (60, 60)]
    assert err.stats["interrupted"] and err.stats["steps"] == 60 and err.stats["steps_planned"] == 120
    assert len(err.records["time"]) == 60
    res = err.result
    assert res.interrupted and res.stats["interrupted"] and len(res.force) == 60
    rec, attrs = read_records(h5)
    assert attrs["status"] == "interrupted" and attrs["steps"] == 60 and attrs["steps_planned"] == 120
    np.testing.assert_array_equal(rec["time"], err.records["time"])
    np.testing.assert_array_equal(rec["force"], res.force)
    np.testing.assert_allclose(float(err.state.time), rec["time"][-1])


def test_interrupted_simulation_resumes_to_the_same_state(weak):
    model = SCENE.model(weak, breakage=True)
    params = default_params(weak)
    load = SCENE.loading(weak, 0.05)
    dt = 0.5 * dem.critical_time_step(model, params)
    full, full_rec, _ = dem.simulate(model, params, load, dt=dt, n_steps=300, chunk=50)
    calls = []

    def cut(done, total, elapsed):
        calls.append(done)
        if done == 100:
            raise KeyboardInterrupt

    with pytest.raises(SimulationInterrupted) as info:
        dem.simulate(model, params, load, dt=dt, n_steps=300, chunk=50, progress=cut)
    part = info.value
    rest, rest_rec, _ = dem.simulate(model, params, load, dt=dt, n_steps=200, chunk=50, state=part.state)
    np.testing.assert_allclose(rest.positions, full.positions, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(rest.broken, full.broken)
    np.testing.assert_allclose(np.concatenate([part.records["reaction"], rest_rec["reaction"]]),
                               full_rec["reaction"], rtol=1e-12, atol=1e-12)


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


def _interrupted_run(sample, scene, h5, after=3, **options):
    """A run stopped by a KeyboardInterrupt after ``after`` chunks (as Ctrl-C would stop it)."""
    calls = []

    def cut(done, total, elapsed):
        calls.append(done)
        if len(calls) == after:
            raise KeyboardInterrupt

    with pytest.raises(SimulationInterrupted) as info:
        jaxbpm.solve(sample, scene, "dem", record_to=h5, progress=cut, **options)
    return info.value


@pytest.mark.parametrize("contacts", [False, True], ids=["bonds", "contacts"])
def test_solve_resumes_an_interrupted_run_from_its_record(weak, tmp_path, contacts):
    scene = UniaxialCompression(strain=0.03, breakage=True, contacts=contacts)
    options = dict(transits=10, chunk=20)
    full = jaxbpm.solve(weak, scene, "dem", record_to=tmp_path / "full.h5", **options)
    cut = tmp_path / "cut.h5"
    stop = _interrupted_run(weak, scene, cut, **options)
    assert stop.stats["steps"] == 60 and read_records(cut)[1]["status"] == "interrupted"
    res = jaxbpm.solve(weak, scene, "dem", resume=cut, **options)
    assert res.status == "converged" and res.stats["steps"] == full.stats["steps"] == 120
    assert res.stats["resumed_at"] == 60
    np.testing.assert_allclose(res.stiffness, full.stiffness, rtol=1e-9, atol=0)
    a, _ = read_records(tmp_path / "full.h5")
    b, attrs = read_records(cut)  # appended to: one record of the whole run
    assert attrs["status"] == "complete" and attrs["steps"] == 120 and attrs["resumed"] == 1
    for key in a:
        np.testing.assert_allclose(b[key], a[key], rtol=1e-9, atol=1e-12 * np.max(np.abs(a[key])))
    np.testing.assert_array_equal(res.state.broken, full.state.broken)
    with pytest.raises(SampleFileError, match="complete.*nothing to resume"):
        jaxbpm.solve(weak, scene, "dem", resume=cut, **options)


def test_resume_refuses_another_run(weak, tmp_path):
    cut = tmp_path / "cut.h5"
    _interrupted_run(weak, SCENE, cut, after=2, transits=10, chunk=20)
    with pytest.raises(SampleFileError, match=r"not a record of this run.*damping \(file 0.7, this run 0.5\)"):
        jaxbpm.solve(weak, SCENE, "dem", resume=cut, transits=10, chunk=20, damping=0.5)
    with pytest.raises(SampleFileError, match="chunk"):
        jaxbpm.solve(weak, SCENE, "dem", resume=cut, transits=10, chunk=10)
    other = jaxbpm.generate.lattice("fcc", (2, 2, 2), 1.001 * R, materials={"E": 1e9, "nu": 0.25})
    with pytest.raises(SampleFileError, match="sample_digest|gauge_length"):
        jaxbpm.solve(other, SCENE, "dem", resume=cut, transits=10, chunk=20)
    with pytest.raises(SceneError, match="leave record_to out"):
        jaxbpm.solve(weak, SCENE, "dem", resume=cut, record_to=tmp_path / "x.h5", transits=10, chunk=20)
    assert read_records(cut)[1]["status"] == "interrupted"  # refused resumes leave the record as it was
    killed = tmp_path / "killed.h5"
    jaxbpm.solve(weak, SCENE, "dem", transits=10, chunk=20, record_to=killed)
    import h5py

    with h5py.File(killed, "a") as f:  # as a killed run leaves it: rows, no saved state
        f.attrs["status"] = "running"
    with pytest.raises(SampleFileError, match="without a saved state.*run it again"):
        jaxbpm.solve(weak, SCENE, "dem", resume=killed, transits=10, chunk=20)


def test_a_ctrl_c_swallowed_during_setup_still_stops_the_solve(weak, monkeypatch, tmp_path):
    """Python drops a KeyboardInterrupt raised inside a garbage-collection callback (JAX runs one during setups
    and compilations): the solve must stop all the same, not run to the end."""
    import gc
    import signal
    import sys

    fired, ignored = [], []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: ignored.append(u.exc_type))

    def interrupt_once(phase, info):
        if phase == "start" and not fired and jaxbpm._interrupt._state["active"]:  # (inside the solve)
            fired.append(True)
            signal.raise_signal(signal.SIGINT)

    gc.callbacks.append(interrupt_once)
    threshold = gc.get_threshold()
    gc.set_threshold(10)  # (a solve whose programs are compiled allocates too little to start a collection)
    # Python's own handler, as in an interactive session (a suite started with SIGINT ignored, e.g. under nohup,
    # would never see the signal)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            jaxbpm.solve(weak, SCENE, "dem", transits=10, chunk=20, record_to=tmp_path / "run.h5")
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the solve put it back
    finally:
        gc.callbacks.remove(interrupt_once)
        gc.set_threshold(*threshold)
        signal.signal(signal.SIGINT, previous)
    assert fired and ignored == [KeyboardInterrupt]  # it was swallowed where it arrived, and raised later
    assert read_records(tmp_path / "run.h5")[1]["status"] == "interrupted"  # the record says so


def test_guard_lets_errors_through_when_interrupts_are_ignored():
    # started with SIGINT ignored (`nohup`, `&` in a script): an error raised inside the guard is that error, not
    # "generator didn't stop after throw()" (a SceneError is a ValueError, which the guard's set-up once caught)
    import signal

    from jaxbpm import _interrupt

    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with pytest.raises(SceneError, match="bad scene"):
            with _interrupt.guard():
                raise SceneError("bad scene")
    finally:
        signal.signal(signal.SIGINT, old)
