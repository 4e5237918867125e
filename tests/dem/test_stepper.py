"""The DEM stepper against closed forms: bond oscillation periods, energy conservation, Hertz impact."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import dem
from jaxbpm.dem.neighbors import _Neighbors
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
    owner = _Neighbors(model, dem.NeighborSettings(skin=0.5 * R), model.positions0)
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
