"""The DEM run between its chunks: the candidate list allocated again when it overflows or the particles leave its
box, built again on the host before it goes stale, an interrupted run continued from its state, failure returned as
an outcome."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import SimulationInterrupted, dem
from jaxbpm.dem import integrator, neighbors
from jaxbpm.physics.model import build_model, default_params
from jaxbpm.scenes import UniaxialCompression

R = 1e-3


def _free_loading(n, dtype=jnp.float64):
    empty = jnp.zeros((0, 3), dtype)
    return dem.Loading(clamped=jnp.zeros(n, bool), velocity=jnp.zeros((n, 3), dtype), wall_points0=empty,
                       wall_normals=empty, wall_velocity=empty)


def _host_lists(monkeypatch):
    """The DEM's candidate list built on the host (a k-d tree between chunks) at every size (the CPU's default)."""
    monkeypatch.setattr(neighbors, "HOST_LIST_MIN", 0)


def _jax_md_lists(monkeypatch):
    """The DEM's candidate list by jax-md's cell list inside the step (the accelerators' list) on the CPU too."""
    monkeypatch.setattr(neighbors, "HOST_LIST_MIN", 1 << 62)


def test_fragment_flying_out_of_the_neighbour_box_within_a_chunk(monkeypatch):
    """A particle that leaves the contact search box within one chunk (a fragment after a failure): the box is
    re-made around where the chunk took it and the chunk runs again, once; the flight is free (x0 + v t). The box
    was re-made around the chunk's start only, so the chunk left it again and again and the run stopped ("stalled")."""
    pos = np.array([[0.0, 0.0, 0.0], [2.5 * R, 0.0, 0.0], [0.0, 2.5 * R, 0.0]])
    s = jaxbpm.Sample.from_arrays(pos, R, np.zeros((0, 2), int), bond_radius=np.zeros(0),
                                  particle_material={"E": 1e8, "nu": 0.3, "friction": 0.0})
    model = build_model(s, contacts=True)
    params, load = default_params(s), _free_loading(3)
    _jax_md_lists(monkeypatch)  # (the host's list has no box)
    owner = neighbors._Neighbors(model, dem.NeighborSettings(skin=0.5 * R), model.positions0)
    state = dem.init_state(model, params, load, nbrs=owner.allocate(model.positions0))
    dt, v0, chunk = 1e-6, 100.0, 100  # 0.1 R a step, 10 R a chunk: past the box's padding (~5 R) in one chunk
    state = dataclasses.replace(state, velocities=jnp.array([[0.0, 0.0, 0.0], [v0, 0.0, 0.0], [0.0, 0.0, 0.0]]))
    final, _, stats = dem.simulate(model, params, load, dt=dt, n_steps=3 * chunk, chunk=chunk, state=state)
    assert 1 <= stats["reallocations"] <= 3  # at most once per chunk
    np.testing.assert_allclose(np.asarray(final.positions), pos + np.array([[0, 0, 0], [v0 * 3 * chunk * dt, 0, 0],
                                                                            [0, 0, 0]]), rtol=0, atol=1e-12)


def _head_on(monkeypatch, gap, v0, skin=0.5 * R, lists="host"):
    """Two spheres ``gap`` apart closing at ``2 v0``, the list built on the host (or by jax-md)."""
    (_host_lists if lists == "host" else _jax_md_lists)(monkeypatch)
    pos = np.array([[0.0, 0.0, 0.0], [2 * R + gap, 0.0, 0.0]])
    s = jaxbpm.Sample.from_arrays(pos, R, np.zeros((0, 2), int), bond_radius=np.zeros(0),
                                  particle_material={"E": 1e8, "nu": 0.3, "friction": 0.0})
    model = build_model(s, contacts=True)
    params, load = default_params(s), _free_loading(2)
    owner = neighbors.neighbors_owner(model, dem.NeighborSettings(skin=skin), model.positions0)
    state = dem.init_state(model, params, load, nbrs=owner.allocate(model.positions0))
    return model, params, load, dataclasses.replace(state, velocities=jnp.array([[v0, 0, 0], [-v0, 0, 0]]))


def test_host_candidate_list_finds_a_contact_made_within_a_chunk(monkeypatch):
    """Two spheres 10 R apart (beyond the list's 3 R) meet within one chunk: the chunk stops where the list would go
    stale, the list is built again and the spheres bounce (without the stop they would pass through each other)."""
    model, params, load, state = _head_on(monkeypatch, 10 * R, 1.0)
    final, rec, stats = dem.simulate(model, params, load, dt=2e-6, n_steps=6000, chunk=3000, state=state)
    assert stats["contact_list"] == "host" and stats["contact_rebuilds"] >= 10
    assert rec["vmax"].shape == (6000,)
    v, x = np.asarray(final.velocities), np.asarray(final.positions)
    assert v[0, 0] < -0.5 and v[1, 0] > 0.5  # they bounced (elastic: back near 1 m/s)
    assert x[1, 0] - x[0, 0] > 2 * R  # and parted, the right way round


def test_host_candidate_list_steps_past_half_the_skin_as_jax_md_does(monkeypatch):
    """A skin set small, so that the spheres move more than half of it in every step (0.02 R a step, skin 0.02 R):
    the host builds its list again where each step takes the particles, as jax-md builds its own inside the step, and
    the two runs are the same (the collision included). Before, the host's run stopped ("stalled")."""
    skin, runs = 0.02 * R, {}
    for lists in ("host", "jax-md"):
        model, params, load, state = _head_on(monkeypatch, 0.2 * R, 10.0, skin=skin, lists=lists)
        runs[lists] = dem.simulate(model, params, load, dt=2e-6, n_steps=120, chunk=60, state=state,
                                   neighbors=dem.NeighborSettings(skin=skin))
    (host, _, stats), (cell, _, stats_cell) = runs["host"], runs["jax-md"]
    assert (stats["contact_list"], stats_cell["contact_list"]) == ("host", "jax-md")
    assert stats["contact_rebuilds"] >= 100 and stats_cell["contact_rebuilds"] >= 100  # about one a step
    v = np.asarray(host.velocities)
    assert v[0, 0] < -5.0 and v[1, 0] > 5.0  # they met and bounced
    np.testing.assert_allclose(np.asarray(host.positions), np.asarray(cell.positions), rtol=0, atol=1e-12 * R)
    np.testing.assert_allclose(v, np.asarray(cell.velocities), rtol=0, atol=1e-9)


@pytest.mark.parametrize("lists", ["jax-md", "host"])
def test_neighbor_overflow_is_reallocated_and_matches_big_buffer(lists, monkeypatch):
    # jax-md's buffer overflows inside a chunk (which runs again); the host's list is sized when built
    (_jax_md_lists if lists == "jax-md" else _host_lists)(monkeypatch)
    s = jaxbpm.generate.box(80, seed=1, mean_radius=R, packing_fraction=0.45)
    scene = jaxbpm.scenes.UniaxialCompression(strain=0.05, contacts=True)
    tight = jaxbpm.solve(s, scene, neighbors=dem.NeighborSettings(skin=0.1 * R, capacity_multiplier=1.0),
                         transits=10)
    roomy = jaxbpm.solve(s, scene, neighbors=dem.NeighborSettings(skin=0.1 * R, capacity_multiplier=4.0),
                         transits=10)
    assert tight.stats["contact_list"] == lists
    assert tight.stats["reallocations"] >= (1 if lists == "jax-md" else 0)
    assert roomy.stats["reallocations"] == 0
    np.testing.assert_allclose(tight.force, roomy.force, rtol=1e-9, atol=1e-12 * np.max(np.abs(roomy.force)))


@pytest.fixture(scope="module")
def weak():
    """A small FCC block whose bonds break under compression (bonds only: quick)."""
    return jaxbpm.generate.lattice("fcc", (2, 2, 2), R, materials={"E": 1e9, "nu": 0.25, "tensile_strength": 2e6,
                                                                   "shear_strength": 4e6})


SCENE = UniaxialCompression(strain=0.03, breakage=True)


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


def test_a_blow_up_is_an_outcome_and_simulate_raises_it():
    """Three times the critical time step: :func:`integrate` returns the chunks before the blow-up with status
    "unstable" and the message; :func:`simulate` raises that message with the same state and records."""
    s = jaxbpm.generate.lattice("sc", (2, 2, 4), R)
    scene = UniaxialCompression(strain=0.002)
    model, params, load = scene.model(s), default_params(s), scene.loading(s, 0.05)
    crit = dem.critical_time_step(model, params)
    out = integrator.integrate(model, params, load, dt=3 * crit, n_steps=400, chunk=20, dt_crit=crit)
    assert isinstance(out, integrator.Outcome) and out.status == "unstable"
    assert out.stats["unstable"] and out.stats["steps"] < out.stats["steps_planned"] == 400
    assert len(out.records.get("time", [])) == out.stats["steps"]
    assert "time step dt = " in out.stats["failure"] and f"{crit:.4g} s" in out.stats["failure"]
    assert np.all(np.isfinite(np.asarray(out.state.positions)))  # the state before the blow-up
    with pytest.raises(jaxbpm.InstabilityError) as err:
        dem.simulate(model, params, load, dt=3 * crit, n_steps=400, chunk=20, dt_crit=crit)
    assert str(err.value) == out.stats["failure"] and err.value.stats["steps"] == out.stats["steps"]
    done = integrator.integrate(model, params, load, dt=0.5 * crit, n_steps=40, chunk=20)
    assert done.status == "converged" and done.stats["steps"] == 40 and "failure" not in done.stats
