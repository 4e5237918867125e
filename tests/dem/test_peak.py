"""The stop after the peak (``jaxbpm.dem.peak``): a run stops at the first step where, armed (a bond broken, past the
fit range), the force is at or below the fraction of its running peak -- checked on the host against the full run's
records -- with the full run's peak, stiffness and curve up to there; ``None`` runs the full strain; another fraction
compiles nothing; batch members stop on their own; the candidate lists built on the host and by jax-md stop alike."""

import dataclasses
import types

import jax
import numpy as np
import pytest

import jaxbpm
from jaxbpm.dem import neighbors
from jaxbpm.dem.batched import solve_batch
from jaxbpm.dem.peak import peak_stop, tracker
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression

from tests.dem._events import compilations

STRENGTHS = {"E": 1e9, "nu": 0.25, "tensile_strength": 5e6, "shear_strength": 1e7}
SCENE = UniaxialCompression.to_failure(strain=0.02, contacts=False)
ALL = 10**8  # max_records: every record, so that curves compare step by step


@pytest.fixture(scope="module")
def rock():
    return jaxbpm.generate.cylinder(250, seed=0, materials=STRENGTHS)


@pytest.fixture(scope="module")
def runs(rock):
    """The full run and the runs stopped at 0.7 of the peak."""
    full = jaxbpm.solve(rock, dataclasses.replace(SCENE, stop_after_peak=None), "dem", transits=30, max_records=ALL)
    stopped = jaxbpm.solve(rock, SCENE, "dem", transits=30, max_records=ALL)
    return full, stopped


def _stop_index(res, fraction, scene):
    """The record where the run should stop, from a run's records on the host: the first one armed (a bond broken,
    the displacement past the fit range) whose force is at or below ``fraction`` x the running peak; ``None``: none."""
    force = np.asarray(res.force)
    target = scene.strain * res.gauge_length
    armed = (np.asarray(res.displacement) >= scene.fit_range[1] * target * (1 - 1e-12))
    armed &= np.asarray(res.stats["broken_curve"]).sum(axis=1) > 0
    fell = armed & (force <= fraction * np.maximum.accumulate(force))
    return int(np.argmax(fell)) if fell.any() else None


def test_the_stop_fires_where_the_force_fell_and_keeps_the_peak(runs):
    full, stopped = runs
    assert stopped.status == full.status == "converged"
    assert (stopped.stats["stop_reason"], full.stats["stop_reason"]) == ("after_peak", "full_strain")
    at = _stop_index(full, 0.7, SCENE)
    assert at is not None and len(stopped.force) == at + 1 < len(full.force)
    assert stopped.stats["steps"] == at + 1 and stopped.stats["steps_planned"] == full.stats["steps"]
    # the same program up to the stop: the same curve, peak, strain at the peak and stiffness to the last bit
    np.testing.assert_array_equal(stopped.force, full.force[:at + 1])
    for key in ("peak_force", "strength", "strain_at_peak", "displacement_at_peak", "broken_at_peak"):
        assert stopped.stats[key] == full.stats[key], key
    assert stopped.stiffness == full.stiffness
    assert stopped.stats["strain_at_peak"] == pytest.approx(full.stats["displacement_at_peak"] / full.gauge_length)
    assert stopped.force[-1] <= 0.7 * stopped.stats["peak_force"] < stopped.force[-2]
    assert stopped.stats["past_peak"]


def test_none_runs_the_full_strain(runs):
    full, _ = runs
    np.testing.assert_allclose(full.displacement[-1], SCENE.strain * full.gauge_length, rtol=1e-9)
    assert full.force[-1] < 0.7 * full.stats["peak_force"]  # (it went on well past where 0.7 would stop)
    assert "steps_planned" not in full.stats


def test_another_fraction_compiles_nothing(rock, runs):
    full, _ = runs
    with compilations() as seen:
        later = jaxbpm.solve(rock, dataclasses.replace(SCENE, stop_after_peak=0.9), "dem", transits=30,
                             max_records=ALL)
    assert seen == [] and later.compile_time == 0.0
    at = _stop_index(full, 0.9, SCENE)
    assert len(later.force) == at + 1 and later.stats["peak_force"] == full.stats["peak_force"]


def test_a_model_whose_bonds_do_not_break_is_never_stopped(rock):
    scene = UniaxialCompression(strain=0.002, breakage=False)
    model = scene.model(rock, breakage=False)
    plan = types.SimpleNamespace(target=1e-5, speed=1e-2)
    stop = peak_stop(scene, model, scene.loading(rock, 1e-2), plan)
    assert float(stop.fraction) == -np.inf and np.all(np.asarray(stop.weights) == 0)
    stop = peak_stop(UniaxialCompression.to_failure(), scene.model(rock, breakage=True), scene.loading(rock, 1e-2),
                     plan)
    assert float(stop.fraction) == 0.7 and float(stop.arm_time) == pytest.approx(0.25 * 1e-5 / 1e-2)
    np.testing.assert_array_equal(np.asarray(stop.weights), [[0, 0, 0.5], [0, 0, -0.5]])
    assert not bool(tracker().stopped) and float(tracker().peak) == -np.inf


def test_batch_members_stop_on_their_own(rock):
    """Weaker members stop earlier, the strongest runs the full strain; each member's records end where its own
    criterion says, and its peak is its single run's (to the suite's round-off between the two programs, see
    tests/dem/test_batched.py)."""
    scene = UniaxialCompression.to_failure(strain=0.03, contacts=False)
    p0 = default_params(rock)
    members = [dict(p0, bond_tensile_strength=np.array([t]), bond_shear_strength=np.array([2 * t]))
               for t in (5e6, 3e6, 2e7)]
    for vectorize in (False, True):
        out = solve_batch(rock, scene, members, vectorize=vectorize, transits=30, max_records=ALL)
        reasons = [r.stats["stop_reason"] for r in out]
        assert reasons == ["after_peak", "after_peak", "full_strain"], (vectorize, reasons)
        assert out[1].stats["steps"] < out[0].stats["steps"] < out[2].stats["steps"]
        assert "steps_planned" not in out[2].stats and out[0].stats["steps_planned"] == out[2].stats["steps"]
        for r in out[:2]:
            assert len(r.force) == _stop_index(r, 0.7, scene) + 1 == r.stats["steps"]
    b = out[0].stats["batch"]
    for p, r in zip(members, out):
        single = jaxbpm.solve(rock, scene, "dem", params=p, dt=b["dt"], loading_time=b["loading_time"],
                              chunk=b["chunk"])
        assert single.stats["stop_reason"] == r.stats["stop_reason"]
        np.testing.assert_allclose(r.stats["peak_force"], single.stats["peak_force"], rtol=1e-2)
        np.testing.assert_allclose(r.stats["steps"], single.stats["steps"], rtol=0.05)


@pytest.mark.parametrize("lists", ["host", "jax-md"])
def test_runs_with_contacts_stop_on_either_candidate_list(lists, monkeypatch):
    monkeypatch.setattr(neighbors, "HOST_LIST_MIN", 0 if lists == "host" else 1 << 62)
    sample = jaxbpm.generate.cylinder(120, seed=1, materials=STRENGTHS)
    scene = UniaxialCompression.to_failure(strain=0.03)
    full = jaxbpm.solve(sample, dataclasses.replace(scene, stop_after_peak=None), "dem", transits=20,
                        max_records=ALL)
    stopped = jaxbpm.solve(sample, scene, "dem", transits=20, max_records=ALL)
    assert stopped.stats["contact_list"] == lists
    at = _stop_index(full, 0.7, scene)
    assert at is not None and stopped.stats["stop_reason"] == "after_peak" and len(stopped.force) == at + 1
    np.testing.assert_array_equal(stopped.force, full.force[:at + 1])
    assert stopped.stats["peak_force"] == full.stats["peak_force"] and stopped.stiffness == full.stiffness
    assert jax.numpy.all(jax.numpy.isfinite(stopped.state.positions))


def test_a_run_resumed_after_its_peak_stops_where_the_whole_run_does(rock, runs, tmp_path):
    """The peak before an interruption is carried into the resumed run (else it would track the falling force from
    where it resumed and stop later)."""
    full, stopped = runs
    chunk = 32
    peak, end = int(np.argmax(full.force)), len(stopped.force) - 1
    after = ((peak + end) // 2) // chunk  # chunks run before the interruption: past the peak, before the stop
    assert peak < after * chunk - 1 < end

    calls = []

    def cut(done, total, elapsed):
        calls.append(done)
        if len(calls) == after:
            raise KeyboardInterrupt

    options = dict(transits=30, chunk=chunk, max_records=ALL)
    whole = jaxbpm.solve(rock, SCENE, "dem", **options)
    with pytest.raises(jaxbpm.SimulationInterrupted):
        jaxbpm.solve(rock, SCENE, "dem", record_to=tmp_path / "cut.h5", progress=cut, **options)
    resumed = jaxbpm.solve(rock, SCENE, "dem", resume=tmp_path / "cut.h5", **options)
    assert whole.stats["stop_reason"] == resumed.stats["stop_reason"] == "after_peak"
    assert resumed.stats["steps"] == whole.stats["steps"] == len(whole.force) == _stop_index(whole, 0.7, SCENE) + 1
    np.testing.assert_allclose(resumed.stats["peak_force"], whole.stats["peak_force"], rtol=1e-9)
