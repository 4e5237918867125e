"""The critical time step against the highest natural frequency of the linearised model, found independently (the
dense stiffness matrix of the Model's forces, its generalised eigenvalues by NumPy)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import InstabilityError
from jaxbpm.dem.timestep import critical_time_step
from jaxbpm.physics import linear, rotation
from jaxbpm.physics.model import build_model, default_params

R = 1e-3


def _omega2_max(s):
    """omega_max^2 of ``M^-1 K``, K the Jacobian of the forces and moments against the translations and rotation
    vectors at rest (a dense matrix: small samples only)."""
    model, params = build_model(s), default_params(s)
    n = s.n_particles
    x0 = model.positions0

    def generalised_forces(z):
        u, w = z[:3 * n].reshape(n, 3), z[3 * n:].reshape(n, 3)
        q = rotation.integrate(rotation.identity(n, x0.dtype), w)
        f, m, _ = model.forces(x0 + u, q, params)
        return jnp.concatenate([f.ravel(), m.ravel()])

    k = -np.asarray(jax.jacfwd(generalised_forces)(jnp.zeros(6 * n)))
    mass = np.concatenate([np.repeat(np.asarray(s.mass), 3), np.repeat(np.asarray(s.inertia), 3)])
    scaled = k / np.sqrt(mass)[:, None] / np.sqrt(mass)[None, :]
    return float(np.max(np.linalg.eigvalsh(0.5 * (scaled + scaled.T))))


@pytest.mark.parametrize("sample", ["pair", "column"])
def test_critical_time_step_is_two_over_the_highest_frequency(sample):
    if sample == "pair":
        s = jaxbpm.Sample.from_arrays(np.array([[0.0, 0, 0], [2 * R, 0, 0]]), R, [[0, 1]], bond_radius_ratio=0.6,
                                      materials={"E": 1e9, "nu": 0.3})
    else:
        s = jaxbpm.generate.lattice("sc", (1, 2, 3), R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})
    dt = critical_time_step(build_model(s), default_params(s), iterations=400)
    # (the estimate keeps a 2 % margin on omega_max^2)
    np.testing.assert_allclose(dt, 2.0 / np.sqrt(1.02 * _omega2_max(s)), rtol=1e-6)


def test_a_model_without_stiffness_has_no_time_step():
    s = jaxbpm.Sample.from_arrays(np.array([[0.0, 0, 0], [3 * R, 0, 0]]), R, np.zeros((0, 2), int),
                                  bond_radius=np.zeros(0))
    with pytest.raises(InstabilityError, match="no stiffness"):
        critical_time_step(build_model(s), default_params(s))


def _linear_cluster(damping=False):
    """Eight spheres on the corners of a cube, overlapping their neighbours by 1 % of R, held together by soft bonds
    along the edges (the contacts, 400 times stiffer, set the time step), linear contacts."""
    pos = 2 * R * 0.99 * np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    edges = [[a, b] for a in range(8) for b in range(a + 1, 8) if np.sum(np.abs(pos[a] - pos[b]) > 0) == 1]
    s = jaxbpm.Sample.from_arrays(pos, R, edges, bond_radius_ratio=0.5, materials={"E": 1e7, "nu": 0.25},
                                  particle_material={"E": 1e9, "nu": 0.25, "friction": 1e3, "restitution": 0.5})
    law = linear.LinearLaw(emod=1e9, kratio=1.21)
    return s, build_model(s, contacts=True, contact_law=law, contact_damping=damping)


def _linear_omega2_max(s, model):
    """omega_max^2 of the cluster's linear contacts (dense M^-1 K, the contact points' slip from the translations
    and rotations, no sliding)."""
    n, x0, params = s.n_particles, model.positions0, default_params(s)
    pairs = jnp.array([[a, b] for a in range(n) for b in range(a + 1, n)])
    valid = jnp.ones(pairs.shape[0], bool)

    def generalised_forces(z):
        u, w = z[:3 * n].reshape(n, 3), z[3 * n:].reshape(n, 3)
        d = x0[pairs[:, 1]] - x0[pairs[:, 0]]
        nrm = d / jnp.linalg.norm(d, axis=1, keepdims=True)
        r = model.radii[pairs]
        slip = (u[pairs[:, 1]] - u[pairs[:, 0]] + jnp.cross(w[pairs[:, 1]], -r[:, 1:] * nrm)
                - jnp.cross(w[pairs[:, 0]], r[:, :1] * nrm))
        zero = jnp.zeros_like(slip)
        f, m, _ = model.forces(x0 + u, rotation.from_rotation_vector(w), params,
                               contacts=(pairs, valid, zero, slip, zero))
        return jnp.concatenate([f.ravel(), m.ravel()])

    k = -np.asarray(jax.jacfwd(generalised_forces)(jnp.zeros(6 * n)))
    mass = np.concatenate([np.repeat(np.asarray(s.mass), 3), np.repeat(np.asarray(s.inertia), 3)])
    scaled = k / np.sqrt(mass)[:, None] / np.sqrt(mass)[None, :]
    return float(np.max(np.linalg.eigvalsh(0.5 * (scaled + scaled.T))))


def _free_run(model, s, dt, n_steps):
    n = s.n_particles
    empty = jnp.zeros((0, 3))
    load = jaxbpm.dem.Loading(clamped=jnp.zeros(n, bool), velocity=jnp.zeros((n, 3)), wall_points0=empty,
                              wall_normals=empty, wall_velocity=empty)
    final, _, _ = jaxbpm.dem.simulate(model, default_params(s), load, dt=dt, n_steps=n_steps, chunk=n_steps)
    return final


@pytest.mark.filterwarnings("ignore:linear contacts:UserWarning")  # the cluster overlaps at rest on purpose
def test_linear_contacts_time_step_is_safe_and_the_run_stable():
    s, model = _linear_cluster()
    exact = 2.0 / np.sqrt(_linear_omega2_max(s, model))
    dt = critical_time_step(model, default_params(s))
    assert 0.2 * exact < dt < exact, (dt, exact)  # on the safe side, not far from it
    # the run (released from the overlapping start, the contacts pushing, the bonds pulling) stays bounded at the
    # estimate: by the start's strain energy, 1/2 k_n (0.02 R)^2 per contact; well past the exact limit it diverges
    # (just past it, the growing motion parts the contacts, which pull no particle back)
    final = _free_run(model, s, dt, 4000)
    kn = float(linear.normal_stiffness(R, R, 1e9))
    v = np.asarray(final.velocities)
    assert np.all(np.isfinite(v))
    assert 0.5 * float(np.sum(np.asarray(s.mass)[:, None] * v**2)) < 12 * 0.5 * kn * (0.02 * R) ** 2
    with pytest.raises(InstabilityError):
        _free_run(model, s, 3.0 * exact, 4000)
    # the dashpots lower the contacts' part (an explicit scheme's limit shrinks by sqrt(1 + beta^2) - beta; the soft
    # bonds' part stays)
    _, damped = _linear_cluster(damping=True)
    beta = float(damped.contact.beta)
    assert dt * (np.sqrt(1 + beta**2) - beta) < critical_time_step(damped, default_params(s)) < 0.9 * dt


def _disc_cluster():
    """Four discs on the corners of a square, overlapping their neighbours by 1 % of R, held by soft bonds along the
    edges, linear contacts (the 2D twin of :func:`_linear_cluster`)."""
    pos = 2 * R * 0.99 * np.array([[0, 0], [1, 0], [0, 1], [1, 1]], float)
    s = jaxbpm.Sample.from_arrays(pos, R, [[0, 1], [0, 2], [1, 3], [2, 3]], bond_radius_ratio=0.5, thickness=0.1,
                                  materials={"E": 1e7, "nu": 0.25},
                                  particle_material={"E": 1e9, "nu": 0.25, "friction": 1e3, "restitution": 0.5})
    return s, build_model(s, contacts=True, contact_law=linear.LinearLaw(emod=1e9, kratio=1.21))


def _disc_omega2_max(s, model):
    """omega_max^2 of the disc cluster (dense M^-1 K over x, y and the angle of each disc; the contact points' slip
    ``u_j - u_i - (r_j w_j + r_i w_i) (-n_y, n_x)``, no sliding)."""
    n, x0, params = s.n_particles, model.positions0, default_params(s)
    pairs = jnp.array([[a, b] for a in range(n) for b in range(a + 1, n)])
    valid = jnp.ones(pairs.shape[0], bool)

    def generalised_forces(z):
        u, w = z[:2 * n].reshape(n, 2), z[2 * n:].reshape(n, 1)
        d = x0[pairs[:, 1]] - x0[pairs[:, 0]]
        nrm = d / jnp.linalg.norm(d, axis=1, keepdims=True)
        r = model.radii[pairs]
        turn = r[:, 1:] * w[pairs[:, 1]] + r[:, :1] * w[pairs[:, 0]]
        slip = u[pairs[:, 1]] - u[pairs[:, 0]] - turn * jnp.stack([-nrm[:, 1], nrm[:, 0]], axis=1)
        zero = jnp.zeros_like(slip)
        f, m, _ = model.forces(x0 + u, w, params, contacts=(pairs, valid, zero, slip, zero))
        return jnp.concatenate([f.ravel(), m.ravel()])

    k = -np.asarray(jax.jacfwd(generalised_forces)(jnp.zeros(3 * n)))
    mass = np.concatenate([np.repeat(np.asarray(s.mass), 2), np.asarray(s.inertia)])
    scaled = k / np.sqrt(mass)[:, None] / np.sqrt(mass)[None, :]
    return float(np.max(np.linalg.eigvalsh(0.5 * (scaled + scaled.T))))


@pytest.mark.filterwarnings("ignore:linear contacts:UserWarning")  # the cluster overlaps at rest on purpose
def test_linear_contacts_between_discs_time_step_is_safe_and_the_run_stable():
    s, model = _disc_cluster()
    exact = 2.0 / np.sqrt(_disc_omega2_max(s, model))
    dt = critical_time_step(model, default_params(s))
    assert 0.2 * exact < dt < exact, (dt, exact)
    n = s.n_particles
    empty = jnp.zeros((0, 2))
    load = jaxbpm.dem.Loading(clamped=jnp.zeros(n, bool), velocity=jnp.zeros((n, 2)), wall_points0=empty,
                              wall_normals=empty, wall_velocity=empty)

    def run(step):
        return jaxbpm.dem.simulate(model, default_params(s), load, dt=step, n_steps=4000, chunk=4000)[0]

    def kinetic(step):
        v = np.asarray(run(step).velocities)
        assert np.all(np.isfinite(v))
        return 0.5 * float(np.sum(np.asarray(s.mass)[:, None] * v**2))

    # bounded at the estimate by the start's strain energy, 1/2 k_n (0.02 R)^2 per contact (k_n = E* t between equal
    # discs); past the exact limit the motion grows beyond it (until the contacts part: the soft bonds hold the discs)
    bound = 4 * 0.5 * (1e9 * 0.1) * (0.02 * R) ** 2
    assert kinetic(dt) < bound < kinetic(3.0 * exact)


@pytest.mark.filterwarnings("ignore:linear contacts:UserWarning")  # the cluster overlaps at rest on purpose
def test_linear_contacts_in_a_dense_hexagonal_disc_cluster():
    """The densest packing of equal discs (6 touching neighbours each, overlapping by 1 % of R, soft bonds): the
    estimate, ``12 max(k_n, 3 k_s) / m`` for the contacts, is safe and the run at it bounded; well past the exact
    limit the run diverges. The exact limit here is ``omega^2 = 7.5 max(k_n, 3 k_s) / m`` (the infinite lattice's is
    8, by Bloch waves; the rotation mode of all discs at once, ``24 k_s / m``): six neighbours in place of twelve would
    put the estimate above it."""
    lattice = jaxbpm.generate.lattice("hex", (5, 5), R)
    s = jaxbpm.Sample.from_arrays(0.99 * np.asarray(lattice.positions), R, np.asarray(lattice.bonds),
                                  bond_radius_ratio=0.5, thickness=0.1, materials={"E": 1e7, "nu": 0.25},
                                  particle_material={"E": 1e9, "nu": 0.25, "friction": 1e3, "restitution": 0.5})
    kratio = 1.21
    model = build_model(s, contacts=True, contact_law=linear.LinearLaw(emod=1e9, kratio=kratio))
    omega2 = _disc_omega2_max(s, model)
    exact = 2.0 / np.sqrt(omega2)
    dt = critical_time_step(model, default_params(s))
    assert 0.75 * exact < dt < exact, (dt, exact)
    kn, m = 1e9 * 0.1, float(np.min(np.asarray(s.mass)))  # k_n = E* t between equal discs
    assert 7 < omega2 * m / max(kn, 3 * kn / kratio) < 8
    n = s.n_particles
    empty = jnp.zeros((0, 2))
    load = jaxbpm.dem.Loading(clamped=jnp.zeros(n, bool), velocity=jnp.zeros((n, 2)), wall_points0=empty,
                              wall_normals=empty, wall_velocity=empty)
    contacts = lattice.n_bonds  # the touching pairs are the lattice's bonds
    bound = contacts * 0.5 * kn * (0.02 * R) ** 2  # the start's strain energy

    def kinetic(step):
        try:
            final = jaxbpm.dem.simulate(model, default_params(s), load, dt=step, n_steps=4000, chunk=4000)[0]
        except InstabilityError:
            return np.inf
        v = np.asarray(final.velocities)
        return 0.5 * float(np.sum(np.asarray(s.mass)[:, None] * v**2)) if np.all(np.isfinite(v)) else np.inf

    assert kinetic(dt) < bound < kinetic(2.5 * exact)
