"""DEM solver against closed forms: bond oscillation periods, energy conservation, lattice modulus, Hertz impact."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import dem
from jaxbpm.physics import bond
from jaxbpm.physics.model import build_model, default_params

R = 1e-3


def _free_loading(n, dtype=jnp.float64):
    empty = jnp.zeros((0, 3), dtype)
    return dem.Loading(clamped=jnp.zeros(n, bool), velocity=jnp.zeros((n, 3), dtype), wall_points0=empty,
                       wall_normals=empty, wall_velocity=empty)


@functools.partial(jax.jit, static_argnames=("n_steps",))
def _trajectory(model, params, load, state, dt, n_steps, origin=None):
    origin = jnp.zeros(3) if origin is None else origin

    def body(s, _):
        s, _ = dem.step(model, params, load, s, dt, 0.0, origin)
        return s, s

    return jax.lax.scan(body, state, None, length=n_steps)[1]


def _period(signal, dt):
    """Mean period from upward zero crossings (linear interpolation)."""
    s = np.asarray(signal)
    s = s - s.mean()
    up = np.flatnonzero((s[:-1] < 0) & (s[1:] >= 0))
    t = (up + (-s[up]) / (s[up + 1] - s[up])) * dt
    assert len(t) >= 3, "too few oscillations recorded"
    return float(np.mean(np.diff(t)))


@pytest.fixture(scope="module")
def pair():
    pos = np.array([[0.0, 0.0, 0.0], [2 * R, 0.0, 0.0]])
    s = jaxbpm.Sample.from_arrays(pos, R, [[0, 1]], bond_radius_ratio=0.6, materials={"E": 1e9, "nu": 0.3})
    model = build_model(s)
    params = default_params(s)
    return s, model, params, model.stiffness(params)


def _mode(pair, v_i, v_j, w_i, w_j):
    s, model, params, k = pair
    load = _free_loading(2)
    state = dem.init_state(model, params, load)
    state = dataclasses.replace(state, velocities=jnp.array([v_i, v_j]), omegas=jnp.array([w_i, w_j]))
    return model, params, load, state, k


def _bond_signals(model, params, traj):
    f = jax.vmap(lambda x, q: bond.bond_forces(x, q, model.bonds, model.r0, model.stiffness(params))[2])
    return f(traj.positions, traj.orientations)


@pytest.mark.parametrize("mode", ["axial", "shear", "bending", "twisting"])
def test_two_particle_oscillation_periods(pair, mode):
    s, model, params, k = pair
    m, inertia, L = float(s.mass[0]), float(s.inertia[0]), 2 * R
    kn, kt, ktw, kb = (float(v[0]) for v in k)
    v, w = 1e-4, 1e-4 / R
    zero = [0.0, 0.0, 0.0]
    if mode == "axial":
        omega2 = 2 * kn / m
        setup = ([-v, 0, 0], [v, 0, 0], zero, zero)
    elif mode == "shear":  # translation against rotation, orthogonal to the rigid rotation of the pair
        omega2 = kt * (2 / m + L**2 / (2 * inertia))
        wz = -m * L * v / (2 * inertia)
        setup = ([0, -v, 0], [0, v, 0], [0, 0, wz], [0, 0, wz])
    elif mode == "bending":
        omega2 = 2 * kb / inertia
        setup = (zero, zero, [0, 0, w], [0, 0, -w])
    else:
        omega2 = 2 * ktw / inertia
        setup = (zero, zero, [w, 0, 0], [-w, 0, 0])
    period = 2 * np.pi / np.sqrt(omega2)
    model, params, load, state, _ = _mode(pair, *(jnp.array(a, jnp.float64) for a in setup))
    dt = period / 400
    traj = _trajectory(model, params, load, state, dt, 2000)
    bf = _bond_signals(model, params, traj)
    signal = {"axial": bf.normal[:, 0], "shear": bf.shear[:, 0, 1], "bending": bf.bend[:, 0, 2],
              "twisting": bf.twist[:, 0]}[mode]
    assert float(jnp.max(jnp.abs(signal))) > 0
    np.testing.assert_allclose(_period(signal, dt), period, rtol=1e-2)


def test_energy_conserved_without_damping():
    s = jaxbpm.generate.lattice("fcc", (1, 1, 2), R, bond_radius_ratio=0.5)
    model = build_model(s)
    params = default_params(s)
    load = _free_loading(s.n_particles)
    state = dem.init_state(model, params, load)
    key1, key2 = jax.random.split(jax.random.PRNGKey(0))
    vel = 1e-3 * jax.random.normal(key1, (s.n_particles, 3))
    vel = vel - jnp.mean(vel, axis=0, keepdims=True)
    state = dataclasses.replace(state, velocities=vel, omegas=1.0 * jax.random.normal(key2, (s.n_particles, 3)))
    dt = 0.1 * dem.critical_time_step(model, params)
    traj = _trajectory(model, params, load, state, dt, 10_000)
    # (one compiled program for the energies of the whole trajectory, not a vmap run op by op)
    kin, pot = jax.jit(jax.vmap(lambda st: (dem.kinetic_energy(model, st), dem.potential_energy(model, params, st))))(
        traj)
    energy = np.asarray(kin + pot)
    e0 = float(dem.kinetic_energy(model, state))
    drift = abs(energy[-500:].mean() - energy[:500].mean()) / e0
    assert np.all(np.isfinite(energy))
    assert drift < 1e-4, drift
    # the energy really moves between kinetic and potential, so the check has teeth
    assert float(jnp.max(pot)) > 0.1 * e0


@pytest.mark.parametrize("cells", [(3, 3, 8), (2, 3, 5)])
def test_simple_cubic_column_modulus(cells):
    s = jaxbpm.generate.lattice("sc", cells, R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})
    res = jaxbpm.solve(s, jaxbpm.scenes.UniaxialCompression(strain=0.002))
    kn = 1e9 * np.pi * (0.5 * R) ** 2 / (2 * R)
    np.testing.assert_allclose(res.youngs_modulus, kn / (2 * R), rtol=1e-2)
    assert res.stats["steps"] > 0 and res.wall_time > 0 and np.isfinite(res.compile_time)
    assert res.force[-1] > 0  # compression positive


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
    owner = dem._Neighbors(model, dem.NeighborSettings(skin=0.5 * R), model.positions0)
    state = dem.init_state(model, params, load, nbrs=owner.allocate(model.positions0))
    dt, v0, chunk = 1e-6, 100.0, 100  # 0.1 R a step, 10 R a chunk: past the box's padding (~5 R) in one chunk
    state = dataclasses.replace(state, velocities=jnp.array([[0.0, 0.0, 0.0], [v0, 0.0, 0.0], [0.0, 0.0, 0.0]]))
    final, _, stats = dem.simulate(model, params, load, dt=dt, n_steps=3 * chunk, chunk=chunk, state=state)
    assert 1 <= stats["reallocations"] <= 3  # at most once per chunk
    np.testing.assert_allclose(np.asarray(final.positions), pos + np.array([[0, 0, 0], [v0 * 3 * chunk * dt, 0, 0],
                                                                            [0, 0, 0]]), rtol=0, atol=1e-12)


def _host_lists(monkeypatch):
    """The DEM's candidate list built on the host (a k-d tree between chunks) at every size (the CPU's default)."""
    from jaxbpm import neighbors

    monkeypatch.setattr(neighbors, "HOST_LIST_MIN", 0)


def _jax_md_lists(monkeypatch):
    """The DEM's candidate list by jax-md's cell list inside the step (the accelerators' list) on the CPU too."""
    from jaxbpm import neighbors

    monkeypatch.setattr(neighbors, "HOST_LIST_MIN", 1 << 62)


def test_host_candidate_list_holds_every_pair_within_its_radius():
    from jaxbpm.neighbors import ordered_pairs

    x = np.random.default_rng(0).uniform(0.0, 1.0, (300, 3))
    idx, capacity = ordered_pairs(x, 0.2, 0, 1.5)
    i, j = np.nonzero(np.triu(np.linalg.norm(x[:, None] - x[None], axis=2) < 0.2, 1))  # by i, then j
    assert i.size > 1000
    np.testing.assert_array_equal(idx[:, :i.size], np.stack([i, j]))
    assert capacity == int(1.5 * i.size) + 1 and np.all(idx[:, i.size:] == 300)
    idx2, capacity2 = ordered_pairs(x, 0.201, capacity, 1.5)  # a few more pairs: the same size (no recompilation)
    assert capacity2 == capacity and np.sum(idx2[0] < 300) > i.size


def test_host_candidate_list_runs_as_jax_md_list_through_breakage(monkeypatch):
    """To failure with contacts (bonds replace them): the list built on the host between chunks, with each chunk
    stopped before it goes stale, gives jax-md's run (its list rebuilt inside the step), to round-off."""
    s = jaxbpm.generate.cylinder(250, seed=0, materials={"E": 1e9, "nu": 0.25, "tensile_strength": 5e6,
                                                         "shear_strength": 5e6},
                                 particle_material={"E": 1e9, "nu": 0.25, "density": 2500.0, "friction": 0.5,
                                                    "restitution": 0.5}).largest_cluster()
    scene = jaxbpm.scenes.UniaxialCompression.to_failure(strain=0.02)
    _jax_md_lists(monkeypatch)
    cell = jaxbpm.solve(s, scene, "dem", transits=30, damping=0.0)
    _host_lists(monkeypatch)
    host = jaxbpm.solve(s, scene, "dem", transits=30, damping=0.0)
    assert (cell.stats["contact_list"], host.stats["contact_list"]) == ("jax-md", "host")
    # the host builds its list again between the steps where jax-md builds its own inside them: as often
    assert host.stats["contact_rebuilds"] > 5
    assert abs(cell.stats["contact_rebuilds"] - host.stats["contact_rebuilds"]) <= 1, (cell.stats, host.stats)
    assert host.stats["contacts_refound"] >= host.stats["contact_rebuilds"]  # (a new list: found again)
    curve = np.sum(cell.stats["broken_curve"], axis=1)
    first = int(np.argmax(curve > 0))
    assert 0 < first and curve[-1] > 20
    scale = np.max(np.abs(cell.force))
    np.testing.assert_allclose(host.force[:first], cell.force[:first], rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(host.force, cell.force, rtol=0, atol=1e-8 * scale)
    assert abs(host.stats["strength"] / cell.stats["strength"] - 1) < 1e-8


def _head_on(monkeypatch, gap, v0, skin=0.5 * R, lists="host"):
    """Two spheres ``gap`` apart closing at ``2 v0``, the list built on the host (or by jax-md)."""
    (_host_lists if lists == "host" else _jax_md_lists)(monkeypatch)
    pos = np.array([[0.0, 0.0, 0.0], [2 * R + gap, 0.0, 0.0]])
    s = jaxbpm.Sample.from_arrays(pos, R, np.zeros((0, 2), int), bond_radius=np.zeros(0),
                                  particle_material={"E": 1e8, "nu": 0.3, "friction": 0.0})
    model = build_model(s, contacts=True)
    params, load = default_params(s), _free_loading(2)
    owner = dem.neighbors_owner(model, dem.NeighborSettings(skin=skin), model.positions0)
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


def test_hertz_impact_contact_time():
    """Two spheres colliding head-on: Hertz contact duration 2.87 (m*^2 / (R*^2 E*^4 v))^(1/5)."""
    E, nu, v0 = 1e8, 0.3, 0.05
    pos = np.array([[0.0, 0.0, 0.0], [2.2 * R, 0.0, 0.0]])
    s = jaxbpm.Sample.from_arrays(pos, R, np.zeros((0, 2), int), bond_radius=np.zeros(0),
                                  particle_material={"E": E, "nu": nu, "friction": 0.0})
    model = build_model(s, contacts=True)
    params = default_params(s)
    load = _free_loading(2)
    e_star, r_star = E / (2 * (1 - nu**2)), R / 2
    m_star = float(s.mass[0]) / 2
    v_rel = 2 * v0
    t_c = 2.868 * (m_star**2 / (r_star * e_star**2 * v_rel)) ** 0.2
    dt = t_c / 400
    owner = dem._Neighbors(model, dem.NeighborSettings(skin=0.5 * R), model.positions0)
    state = dem.init_state(model, params, load, nbrs=owner.allocate(model.positions0))
    state = dataclasses.replace(state, velocities=jnp.array([[v0, 0, 0], [-v0, 0, 0]]))
    n_steps = int(2 * (0.2 * R / v_rel) / dt) + 800
    traj = _trajectory(model, params, load, state, dt, n_steps, jnp.asarray(owner.origin))
    gap = np.linalg.norm(np.asarray(traj.positions[:, 1] - traj.positions[:, 0]), axis=1) - 2 * R
    assert gap[-1] > 0.1 * R  # they met and parted again
    np.testing.assert_allclose(np.sum(gap < 0) * dt, t_c, rtol=1e-2)
    # no damping: they separate at the speed they came with
    np.testing.assert_allclose(traj.velocities[-1, :, 0], [-v0, v0], rtol=1e-3)
    # the same run through simulate() (chunks, neighbour-list checks) ends in the same place
    final, _, _ = dem.simulate(model, params, load, dt=dt, n_steps=n_steps, chunk=n_steps, state=state)
    np.testing.assert_allclose(final.positions, traj.positions[-1], rtol=1e-10, atol=1e-12)


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
        with pytest.warns(UserWarning, match=r"above the critical time step estimate .* \(2\.00x\)"):
            jaxbpm.solve(s, scene, dt=2.0 * crit, transits=10)


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
def contact_box():
    """Soft bonds among stiff particles: contacts carry most of the stiffness."""
    return jaxbpm.generate.box(300, seed=0, materials={"E": 1e8, "nu": 0.25},
                               particle_material={"E": 1e10, "nu": 0.25, "density": 2500.0, "friction": 0.5,
                                                  "restitution": 0.5}).largest_cluster()


def _with_near(monkeypatch, margin, size=None):
    monkeypatch.setattr(dem, "NEAR_MARGIN", margin)
    if size is not None:
        monkeypatch.setattr(dem, "near_size", size)


def test_pairs_within_reach_match_packing_every_step(contact_box, monkeypatch):
    """The contact law on the pairs within reach (found again as particles move) gives the run of the per-step
    packing of the whole candidate list, to round-off: the two programs differ from step 28 on by 1e-18 of the force
    (summation order), which the sliding contacts amplify to 3e-12 by step 400 and ~1e-4 by the end, as they amplify
    a change of 1e-15 in one coordinate (K then moves by 8e-5)."""
    scene = jaxbpm.scenes.UniaxialCompression(strain=0.005, contacts=True)
    near = jaxbpm.solve(contact_box, scene, "dem", transits=20)
    _with_near(monkeypatch, None)
    every = jaxbpm.solve(contact_box, scene, "dem", transits=20)
    scale = np.max(np.abs(every.force))
    assert len(near.force) == len(every.force) > 1000
    np.testing.assert_allclose(near.force[:400], every.force[:400], rtol=0, atol=1e-9 * scale)
    assert abs(near.stiffness / every.stiffness - 1) < 5e-4


@pytest.mark.parametrize("bond_contact", ["superimpose", "replace"])
def test_pairs_within_reach_through_breakage(bond_contact, monkeypatch):
    """To failure: the bonded pairs' contacts run on the bond list (where bonds replace contacts, a broken bond's
    only; where they superimpose, every bond's), the other pairs within reach on their slots. Either way the run is
    the per-step packing of the whole candidate list's, to
    round-off before the breaks and within the chaos of breakage after them. Without local damping: its
    ``-alpha |F| sign(v)`` jumps where a velocity component changes sign, so it turns a last-bit difference in the
    order the two programs sum forces into a jump (1e-13 to 1e-9 of the force within three records on one XLA
    thread, 1e-4 before the first break); undamped, the two agree to 2e-13 there."""
    s = jaxbpm.generate.cylinder(250, seed=0, bond_contact=bond_contact,
                                 materials={"E": 1e9, "nu": 0.25, "tensile_strength": 5e6, "shear_strength": 5e6},
                                 particle_material={"E": 1e9, "nu": 0.25, "density": 2500.0, "friction": 0.5,
                                                    "restitution": 0.5}).largest_cluster()
    assert s.bond_contact == bond_contact
    scene = jaxbpm.scenes.UniaxialCompression.to_failure(strain=0.02)
    near = jaxbpm.solve(s, scene, "dem", transits=30, damping=0.0)
    _with_near(monkeypatch, None)
    every = jaxbpm.solve(s, scene, "dem", transits=30, damping=0.0)
    curve = np.sum(every.stats["broken_curve"], axis=1)
    first = int(np.argmax(curve > 0))
    assert 0 < first and curve[-1] > 20  # bonds break, and not from the start
    scale = np.max(np.abs(every.force))
    np.testing.assert_allclose(near.force[:first], every.force[:first], rtol=0, atol=1e-10 * scale)
    assert abs(near.stats["strength"] / every.stats["strength"] - 1) < 0.02


def test_pairs_within_reach_overflow_runs_the_chunk_again(contact_box, monkeypatch):
    """Too few slots for the pairs within reach: the chunk runs again with more, and nothing is lost. By default the
    slots are sized to the pairs within reach that are not bonded pairs at the start (a quarter more; room for a
    32nd of the bonds at least), not to the candidate list. Half the bonds of the box removed, so that many
    touching pairs are not bonded."""
    half = contact_box.replace(bonds=contact_box.bonds[::2], bond_radius=contact_box.bond_radius[::2],
                               bond_material=contact_box.bond_material[::2])
    scene = jaxbpm.scenes.UniaxialCompression(strain=0.005, contacts=True)
    roomy = jaxbpm.solve(half, scene, "dem", transits=20)
    within, slots = roomy.stats["contacts_within_reach"], roomy.stats["contact_slots"]
    assert 100 < within <= slots <= dem.near_size(max(within, half.n_bonds // 32), roomy.stats["contact_capacity"])
    assert slots < 1.5 * within + 64
    _with_near(monkeypatch, dem.NEAR_MARGIN, lambda count, capacity: max(count // 4, 1))
    tight = jaxbpm.solve(half, scene, "dem", transits=20)
    assert tight.stats["contact_slots"] >= tight.stats["contacts_within_reach"] == within  # the slots grew
    np.testing.assert_allclose(tight.force[:400], roomy.force[:400], rtol=0, atol=1e-9 * np.max(np.abs(roomy.force)))
    assert abs(tight.stiffness / roomy.stiffness - 1) < 5e-4


def test_second_solve_of_same_size_does_not_recompile():
    s = jaxbpm.generate.lattice("sc", (2, 2, 4), R)
    scene = jaxbpm.scenes.UniaxialCompression(strain=0.002)
    jaxbpm.solve(s, scene)
    before = dem._run_chunk._cache_size()
    stiffer = s.replace(materials={"E": 3e9, "nu": 0.25})  # same shapes, other values
    res = jaxbpm.solve(stiffer, scene, dt=1e-7, loading_time=2e-4, chunk=100)
    jaxbpm.solve(stiffer, scene, dt=1e-7, loading_time=2e-4, chunk=100)
    assert dem._run_chunk._cache_size() == before + 1  # one new chunk length, then reused
    assert res.stiffness > 0


def test_bonded_pairs_replace_or_superimpose_contacts():
    """Two bonded spheres pressed together: with "replace" only the bond acts, with "superimpose" Hertz adds."""
    pos = np.array([[0.0, 0.0, 0.0], [1.98 * R, 0.0, 0.0]])
    kw = dict(bond_radius_ratio=0.5, particle_material={"E": 1e9, "friction": 0.0})
    model_r = build_model(jaxbpm.Sample.from_arrays(pos, R, [[0, 1]], bond_contact="replace", **kw), contacts=True)
    model_s = build_model(jaxbpm.Sample.from_arrays(pos, R, [[0, 1]], bond_contact="superimpose", **kw),
                          contacts=True)
    params = default_params(jaxbpm.Sample.from_arrays(pos, R, [[0, 1]], **kw))
    pairs = jnp.array([[0, 1]])
    x = model_r.positions0.at[1, 0].add(-0.01 * R)  # squeeze the bond too
    out = {}
    for name, model in (("replace", model_r), ("superimpose", model_s)):
        valid = jnp.array([True]) if name == "superimpose" else ~model.bonded(pairs)
        zeros = jnp.zeros((1, 3))
        f, _, _ = model.forces(x, None, params, contacts=(pairs, valid, zeros, zeros, zeros))
        out[name] = float(f[1, 0])
    k = model_r.stiffness(params)
    np.testing.assert_allclose(out["replace"], float(k.kn[0]) * 0.01 * R, rtol=1e-9)  # bond only
    delta = 2 * R - (1.98 * R - 0.01 * R)
    hertz = 4 / 3 * (1e9 / (2 * (1 - 0.25**2))) * np.sqrt(R / 2) * delta**1.5
    np.testing.assert_allclose(out["superimpose"], out["replace"] + hertz, rtol=1e-9)


def test_bond_pass_in_blocks_through_breakage(monkeypatch):
    """Large samples pass over their bonds in blocks (``Model.bond_block``): forced here on a small cylinder with
    contacts (the bonded pairs' Hertz law runs in the same blocks), blocks of 64 bonds that do not divide the bond
    count, the run is the one-pass run's to round-off before the first break and as strong after it."""
    from jaxbpm.physics import model as model_mod

    s = jaxbpm.generate.cylinder(250, seed=0,
                                 materials={"E": 1e9, "nu": 0.25, "tensile_strength": 5e6, "shear_strength": 5e6},
                                 particle_material={"E": 1e9, "nu": 0.25, "density": 2500.0, "friction": 0.5,
                                                    "restitution": 0.5}).largest_cluster()
    scene = jaxbpm.scenes.UniaxialCompression.to_failure(strain=0.02)
    assert build_model(s).bond_block is None
    one = jaxbpm.solve(s, scene, "dem", transits=30, damping=0.0)
    monkeypatch.setattr(model_mod, "BLOCKED_FROM", 0)
    monkeypatch.setattr(model_mod, "BOND_BLOCK", 64)
    assert build_model(s).bond_block == 64 and s.n_bonds % 64 != 0
    blocks = jaxbpm.solve(s, scene, "dem", transits=30, damping=0.0)
    curve = np.sum(one.stats["broken_curve"], axis=1)
    first = int(np.argmax(curve > 0))
    assert 0 < first and curve[-1] > 20
    scale = np.max(np.abs(one.force))
    np.testing.assert_allclose(blocks.force[:first], one.force[:first], rtol=0, atol=1e-10 * scale)
    assert abs(blocks.stats["strength"] / one.stats["strength"] - 1) < 0.02
