"""The DEM scene driver: closed-form lattice modulus, failure as a result (unstable, interrupted), runs interrupted
and resumed from their record, a second solve of the same size compiling nothing new."""

import numpy as np
import pytest

import jaxbpm
from jaxbpm import SampleFileError, SceneError, SimulationInterrupted, dem
from jaxbpm.dem import chunk
from jaxbpm.dem.records import read_records
from jaxbpm.physics.model import build_model, default_params
from jaxbpm.scenes import UniaxialCompression

R = 1e-3


@pytest.mark.parametrize("cells", [(3, 3, 8), (2, 3, 5)])
def test_simple_cubic_column_modulus(cells):
    s = jaxbpm.generate.lattice("sc", cells, R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})
    res = jaxbpm.solve(s, jaxbpm.scenes.UniaxialCompression(strain=0.002))
    kn = 1e9 * np.pi * (0.5 * R) ** 2 / (2 * R)
    np.testing.assert_allclose(res.youngs_modulus, kn / (2 * R), rtol=1e-2)
    assert res.stats["steps"] > 0 and res.wall_time > 0 and np.isfinite(res.compile_time)
    assert res.force[-1] > 0  # compression positive


def test_time_step_above_critical_raises():
    s = jaxbpm.generate.lattice("sc", (2, 2, 4), R)
    dt = 3.0 * dem.critical_time_step(build_model(s), default_params(s))
    with pytest.raises(jaxbpm.InstabilityError, match=r"time step dt = .* critical time step estimate") as err:
        with pytest.warns(UserWarning, match=r"above the critical time step estimate"):
            jaxbpm.solve(s, jaxbpm.scenes.UniaxialCompression(strain=0.002), safety=1.0, dt=dt, damping=0.0)
    # the error carries the result of what ran before the blow-up; throw=False returns it
    assert err.value.result.status == "unstable" and not err.value.result.ok
    with pytest.warns(UserWarning, match=r"above the critical time step estimate"):
        res = jaxbpm.solve(s, jaxbpm.scenes.UniaxialCompression(strain=0.002), jaxbpm.DEM(dt=dt, damping=0.0),
                           throw=False)
    assert res.status == "unstable" and "unstable" in res.stats["failure"] and res.stats["unstable"]
    assert res.stats["steps"] < res.stats["steps_planned"]


def test_unstable_run_with_contacts_raises_instead_of_reallocating():
    # a blown-up chunk overflows the neighbour buffer too: the instability must be reported, not re-allocated for
    s = jaxbpm.generate.box(150, seed=0, mean_radius=R, packing_fraction=0.5,
                            particle_material={"E": 1e10, "nu": 0.25, "density": 2500.0, "friction": 0.5,
                                               "restitution": 0.5})
    scene = jaxbpm.scenes.UniaxialCompression(strain=0.01, contacts=True)
    crit = dem.critical_time_step(build_model(s, contacts=True), default_params(s))
    with pytest.raises(jaxbpm.InstabilityError, match=r"time step dt = .* critical time step estimate"):
        with pytest.warns(UserWarning, match=r"above the critical time step estimate .* \(3\.00x\)"):
            jaxbpm.solve(s, scene, dt=3.0 * crit, transits=10)


def test_second_solve_of_same_size_does_not_recompile():
    s = jaxbpm.generate.lattice("sc", (2, 2, 4), R)
    scene = jaxbpm.scenes.UniaxialCompression(strain=0.002)
    jaxbpm.solve(s, scene)
    before = chunk._run_chunk._cache_size()
    stiffer = s.replace(materials={"E": 3e9, "nu": 0.25})  # same shapes, other values
    res = jaxbpm.solve(stiffer, scene, dt=1e-7, loading_time=2e-4, chunk=100)
    jaxbpm.solve(stiffer, scene, dt=1e-7, loading_time=2e-4, chunk=100)
    assert chunk._run_chunk._cache_size() == before + 1  # one new chunk length, then reused
    assert res.stiffness > 0


@pytest.fixture(scope="module")
def weak():
    """A small FCC block whose bonds break under compression (bonds only: quick)."""
    return jaxbpm.generate.lattice("fcc", (2, 2, 2), R, materials={"E": 1e9, "nu": 0.25, "tensile_strength": 2e6,
                                                                   "shear_strength": 4e6})


SCENE = UniaxialCompression(strain=0.03, breakage=True)


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
