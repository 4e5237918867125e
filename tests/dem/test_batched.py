"""Batched DEM runs (``jaxbpm.dem.batched.solve_batch``): every member's result is its single run's, with the batch's
time step, loading time and chunk; a second batch of the same size compiles nothing; a member that blows up fails
alone; scenes with contacts are refused."""


import jax
import numpy as np
import pytest

import jaxbpm
from jaxbpm.dem.batched import solve_batch
from jaxbpm.errors import InstabilityError, SceneError
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import ThreePointBending, UniaxialCompression

from tests.dem._events import compilations

R = 1e-3
ELASTIC = UniaxialCompression(strain=0.002)
FAILURE = UniaxialCompression.to_failure(strain=0.01, contacts=False)
UNBREAKABLE = UniaxialCompression(strain=0.002, breakage=False)


@pytest.fixture(scope="module")
def rock():
    return jaxbpm.generate.box(300, seed=0, mean_radius=R, materials={"E": 1e9, "nu": 0.25, "tensile_strength": 5e6,
                                                                      "shear_strength": 1e7})


def _single(sample, scene, params, batched):
    """The single run of a member, with the batch's time step, loading time and chunk."""
    b = batched.stats["batch"]
    return jaxbpm.solve(sample, scene, method="dem", params=params, dt=b["dt"], loading_time=b["loading_time"],
                        chunk=b["chunk"])


# Compiled as in a user's process the batched and the single runs are bit-identical; the suite compiles with LLVM's
# optimisation off and XLA's older loop emitters (conftest), where the two programs' floating-point operations are
# not ordered alike, and the local damping's sign(v) turns the round-off into differences of up to ~1e-3 of the
# force (the same elastic run gives K = 1872439 and 1872140 N/m under the two code generators). A member given
# another member's parameters is off by 20-30 %.
RTOL = 2e-3


def _assert_same(single, batched, peak_rtol=RTOL):
    """``peak_rtol``: bonds breaking amplify the differences further (0.6 % of the peak measured; a member with
    another member's strengths is 10-30 % off), so failure runs compare the force up to the first break."""
    for value in ("stiffness", "youngs_modulus"):
        np.testing.assert_allclose(getattr(batched, value), getattr(single, value), rtol=RTOL)
    for key in ("dt", "dt_crit", "loading_time", "speed", "steps"):
        np.testing.assert_allclose(batched.stats[key], single.stats[key], rtol=1e-9)
    for key in ("peak_force", "strength"):
        np.testing.assert_allclose(batched.stats[key], single.stats[key], rtol=peak_rtol)
    np.testing.assert_allclose(batched.displacement, single.displacement, rtol=1e-9)
    intact = len(single.force)
    if "broken_curve" in single.stats:
        broke = np.flatnonzero(np.sum(single.stats["broken_curve"], axis=1) > 0)
        intact = broke[0] if broke.size else intact
    np.testing.assert_allclose(batched.force[:intact], single.force[:intact], rtol=0,
                               atol=RTOL * np.max(np.abs(single.force)))
    assert batched.status == single.status == "converged"


def test_elastic_members_equal_their_single_runs(rock):
    p0 = default_params(rock)
    members = [dict(p0, bond_E=np.array([e]), bond_nu=np.array([nu])) for e, nu in ((1e9, 0.25), (1.3e9, 0.2),
                                                                                     (0.8e9, 0.3))]
    out = solve_batch(rock, ELASTIC, members, transits=10)
    assert len(out) == 3 and [r.stats["batch"]["index"] for r in out] == [0, 1, 2]
    # the shared time step is the smallest member's; the loading time the softest member's transits
    assert out[0].stats["dt"] == pytest.approx(0.5 * min(r.stats["dt_crit"] for r in out), rel=1e-12)
    assert out[1].stats["dt_crit"] < out[0].stats["dt_crit"] < out[2].stats["dt_crit"]
    for p, r in zip(members, out):
        _assert_same(_single(rock, ELASTIC, p, r), r)
    assert out[1].stiffness > out[0].stiffness > out[2].stiffness


def test_breaking_members_equal_their_single_runs(rock):
    """A dict of arrays with a leading batch axis: strengths perturbed as a finite-difference calibration does."""
    batch = {"bond_E": np.array([[1e9], [1e9], [1.3e9]]), "bond_nu": np.full((3, 1), 0.25),
             "bond_tensile_strength": np.array([[5e6], [5.5e6], [4e6]]),
             "bond_shear_strength": np.full((3, 1), 1e7)}
    out = solve_batch(rock, FAILURE, batch, transits=10)
    for b, r in enumerate(out):
        p = {k: v[b] for k, v in batch.items()}
        single = _single(rock, FAILURE, p, r)
        _assert_same(single, r, peak_rtol=0.03)
        for key in ("broken_tensile", "broken_shear"):
            assert abs(r.stats[key] - single.stats[key]) <= 0.1 * max(single.stats[key], 10), key
    assert sum(r.stats["broken_tensile"] for r in out) > 0


def test_second_batch_of_the_same_size_compiles_nothing(rock):
    p0 = default_params(rock)
    members = [dict(p0, bond_E=np.array([e])) for e in (1e9, 1.1e9)]
    first = solve_batch(rock, ELASTIC, members, transits=10)
    with compilations() as seen:
        again = solve_batch(rock, ELASTIC, [dict(p0, bond_E=np.array([e])) for e in (1e9, 1.1e9)], transits=10)
    assert seen == []
    assert all(r.compile_time == 0.0 for r in again)
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a.force, b.force)
    np.testing.assert_allclose(sum(r.wall_time for r in again), again[0].stats["batch"]["wall_time"], rtol=1e-9)
    for r in again:  # each member's times are its share of the batch's, adding up like a single run's
        assert r.wall_time == r.stats["wall_time"] and r.run_time == r.stats["run_time"]
        assert r.setup_time == r.stats["setup_time"] > 0 and r.run_time > 0
        np.testing.assert_allclose(r.setup_time + r.compile_time + r.run_time, r.wall_time, rtol=1e-12)


def test_a_member_that_blows_up_fails_alone(rock):
    p0 = default_params(rock)  # (bonds that cannot break: a breaking one would only shed its stiff bonds)
    soft, stiff = dict(p0), dict(p0, bond_E=np.array([1e11]))
    dt = 0.5 * solve_batch(rock, UNBREAKABLE, [soft], transits=2, chunk=8)[0].stats["dt_crit"]
    with pytest.warns(UserWarning, match="member 1"):
        out = solve_batch(rock, UNBREAKABLE, [soft, stiff], dt=dt, transits=10, chunk=8, damping=0.0, throw=False)
    assert [r.status for r in out] == ["converged", "unstable"]
    assert "unstable" in out[1].stats["failure"] and out[1].stats["steps"] < out[0].stats["steps"]
    # the failing member's result is its single run's
    with pytest.warns(UserWarning, match="above the critical"):
        single = jaxbpm.solve(rock, UNBREAKABLE, params=stiff, dt=dt, chunk=8, damping=0.0, throw=False,
                              loading_time=out[1].stats["batch"]["loading_time"])
    assert single.status == "unstable" and single.stats["steps"] == out[1].stats["steps"]
    np.testing.assert_array_equal(single.force, out[1].force)
    assert np.isfinite(out[0].stiffness) and np.all(np.isfinite(np.asarray(out[1].state.positions)))
    with pytest.warns(UserWarning), pytest.raises(InstabilityError) as err:
        solve_batch(rock, UNBREAKABLE, [soft, stiff], dt=dt, transits=10, chunk=8, damping=0.0)
    assert err.value.result.status == "unstable" and [r.status for r in err.value.results] == ["converged",
                                                                                               "unstable"]


def test_scenes_with_contacts_and_other_methods_are_refused(rock):
    p0 = default_params(rock)
    for scene in (UniaxialCompression.to_failure(), ThreePointBending(), UniaxialCompression(contacts=True)):
        with pytest.raises(SceneError, match="contacts=True.*one by one"):
            solve_batch(rock, scene, [p0])
    with pytest.raises(SceneError, match="DEM only"):
        solve_batch(rock, ELASTIC, [p0], method="dsm")
    with pytest.raises(SceneError, match="record_to"):
        solve_batch(rock, ELASTIC, [p0], record_to="run.h5")
    with pytest.raises(SceneError, match="leading batch axis"):
        solve_batch(rock, ELASTIC, {"bond_E": np.ones((2, 1)), "bond_nu": np.full((3, 1), 0.25)})
    with pytest.raises(SceneError, match="bond_E"):
        solve_batch(rock, ELASTIC, [{"bond_E": [-1.0], "bond_nu": [0.25]}])
    assert jaxbpm.solve_batch is solve_batch


def test_vectorized_batch_agrees_to_the_dems_round_off_sensitivity(rock):
    """``vectorize=True`` (jax.vmap): XLA's CPU code rounds by an ulp differently, which the local damping
    amplifies; the stiffness still agrees closely."""
    p0 = default_params(rock)
    members = [dict(p0, bond_E=np.array([e])) for e in (1e9, 1.2e9)]
    exact = solve_batch(rock, ELASTIC, members, transits=10)
    vec = solve_batch(rock, ELASTIC, members, transits=10, vectorize=True)
    for a, b in zip(exact, vec):
        assert b.stats["batch"]["vectorize"] and not a.stats["batch"]["vectorize"]
        np.testing.assert_allclose(b.stiffness, a.stiffness, rtol=1e-3)
        np.testing.assert_allclose(b.force, a.force, rtol=0, atol=1e-2 * np.max(np.abs(a.force)))
