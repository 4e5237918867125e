"""The stress-dependent cohesive contact law of Irazabal et al. (Eq. 2-17, Fig. 7): history, closed forms, restitution,
Coulomb limit, neighbour-list rebuilds, and a cohesive granular sample under uniaxial compression."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import SceneError, dem
from jaxbpm.physics import cohesive as co
from jaxbpm.physics.model import build_model, default_params
from jaxbpm.scenes import UniaxialCompression

R = 1.5e-3
PM = {"density": 3280.0, "E": 5e6, "nu": 0.3, "friction": 0.4, "restitution": 0.5}
LAW = co.CohesiveLaw(c0=2e4, kc=0.5, c_max=6e4)
M = 3280.0 * 4.0 / 3.0 * np.pi * R**3


def _params(law=LAW):
    return law.params(jaxbpm.ParticleMaterial.create(**PM), jnp.float64)


def _kn(delta, r_i=R, r_j=R, E=PM["E"]):
    rsum = r_i + r_j
    area = np.pi * (rsum / 2) ** 2 * rsum / (rsum - delta)
    return 0.5 * E * area / (rsum - delta), area


@jax.jit
def _static(delta, spring, dxi, history, p):
    """One evaluation of the law for two spheres at rest along x with overlap ``delta``."""
    d = jnp.stack([2 * R - delta, 0.0, 0.0])
    zero = jnp.zeros(3)
    return co.cohesive_contact(d, R, R, M, M, spring, dxi, zero, history, p)


def test_history_follows_fig7():
    """Initial contact at c_0; grows with k_c max sigma; capped at c_max; kept when unloading; lost when the
    particles part; a contact formed later starts at zero (not c_0) and grows from k_c sigma."""
    p = _params()
    deltas = [1e-5, 5e-5, 1e-4, 1.2e-4, 2e-4, 3e-4, 1e-4, 5e-5, -1e-5, 2e-5, 6e-5, 2e-5]
    history = jnp.asarray(-LAW.c0)  # an initial contact (present when the run starts)
    got_c, got_f, want_c, want_f = [], [], [], []
    c_prev = LAW.c0
    for delta in deltas:
        out = _static(jnp.asarray(delta), jnp.zeros(3), jnp.zeros(3), history, p)
        history = out.cohesion
        got_c.append(float(history))
        got_f.append(float(out.normal))
        if delta > 0:
            k, area = _kn(delta)
            want_f.append(k * delta - c_prev * area)  # Eq. 3 with the cohesion of the previous steps (Eq. 14)
            c_prev = min(LAW.c_max, max(c_prev, LAW.kc * k * delta / area))
        else:
            want_f.append(0.0)
            c_prev = 0.0
        want_c.append(c_prev)
    np.testing.assert_allclose(got_c, want_c, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(got_f, want_f, rtol=1e-12, atol=1e-15)
    c = np.array(got_c)
    assert c[0] == LAW.c0                               # k_c sigma < c_0: stays at c_0
    assert LAW.c0 < c[1] < c[2] < c[3] < LAW.c_max       # grows with the largest stress
    assert c[4] == c[5] == LAW.c_max                     # capped
    assert c[6] == c[7] == LAW.c_max                     # unloading keeps it
    assert c[8] == 0                                     # the particles parted
    k, area = _kn(2e-5)
    np.testing.assert_allclose(c[9], LAW.kc * k * 2e-5 / area)  # a new contact starts at 0, not c_0 ...
    assert c[9] < LAW.c0 and got_f[9] == pytest.approx(k * 2e-5)  # ... with no cohesive pull in its first step
    assert c[11] == c[10] > c[9]                         # and keeps its own history


def test_new_contact_and_pending_initial_contact():
    p = _params()
    new = _static(jnp.asarray(1e-5), jnp.zeros(3), jnp.zeros(3), jnp.asarray(0.0), p)
    k, area = _kn(1e-5)
    np.testing.assert_allclose(float(new.normal), k * 1e-5)  # no cohesion in a new contact's first step
    np.testing.assert_allclose(float(new.cohesion), LAW.kc * k * 1e-5 / area)
    # an initial contact that does not touch yet keeps its c_0 (encoded -c_0) until it does
    apart = _static(jnp.asarray(-1e-5), jnp.zeros(3), jnp.zeros(3), jnp.asarray(-LAW.c0), p)
    assert float(apart.cohesion) == -LAW.c0 and float(apart.normal) == 0.0 and not bool(apart.active)


def test_normal_force_closed_form_with_damping_unequal_spheres():
    p = _params(co.CohesiveLaw(c0=1e4, kc=0.2, c_max=3e4))
    r_i, r_j, m_i, m_j = 1.2e-3, 1.8e-3, 2e-5, 7e-5
    delta, v_n = 4e-5, -0.02  # approaching at 2 cm/s
    n = np.array([1.0, 2.0, 2.0]) / 3.0
    d = n * (r_i + r_j - delta)
    out = co.cohesive_contact(jnp.asarray(d), r_i, r_j, m_i, m_j, jnp.zeros(3), jnp.zeros(3), jnp.asarray(v_n * n),
                              jnp.asarray(-1e4), p)
    lnc = np.log(PM["restitution"])
    gamma = -lnc / np.sqrt(np.pi**2 + lnc**2)  # Eq. 7
    rsum = r_i + r_j
    area = np.pi * (rsum / 2) ** 2 * rsum / (rsum - delta)  # Eq. 11
    kn = PM["E"] / 2 * area / (rsum - delta)  # Eq. 4, E^ = E E / (E + E)
    dn = 2 * gamma * np.sqrt(m_i * m_j / (m_i + m_j) * kn)  # Eq. 5, 6
    fn = kn * delta + dn * (-v_n) - 1e4 * area  # Eq. 3, 12
    np.testing.assert_allclose(float(out.normal), fn, rtol=1e-12)
    np.testing.assert_allclose(out.f_i, -fn * n, rtol=1e-12)  # along the line of centres, on i away from j
    np.testing.assert_allclose(float(out.stress), (kn * delta + dn * (-v_n)) / area, rtol=1e-12)  # Eq. 13
    # the stiffness grows with the indentation (A / l)
    assert float(co.normal_stiffness(R, R, 2e-4, 5e6)) > float(co.normal_stiffness(R, R, 1e-5, 5e6))


def test_coulomb_limit_and_tangential_stiffness():
    p = _params()
    delta = 1e-4
    k, area = _kn(delta)
    kappa = 2 * (1 - PM["nu"]) / (2 - PM["nu"])  # Eq. 16
    small = _static(jnp.asarray(delta), jnp.zeros(3), jnp.array([0.0, 1e-7, 0.0]), jnp.asarray(-LAW.c0), p)
    np.testing.assert_allclose(small.spring, [0.0, -kappa * k * 1e-7, 0.0], rtol=1e-12)
    assert not bool(small.sliding)
    big = _static(jnp.asarray(delta), jnp.zeros(3), jnp.array([0.0, 1e-4, 1e-4]), jnp.asarray(-LAW.c0), p)
    assert bool(big.sliding)
    limit = PM["friction"] * k * delta  # mu times the contact pressure (the cohesive pull not subtracted)
    ft = -np.asarray(big.f_i)[1:]
    np.testing.assert_allclose(np.linalg.norm(ft), limit, rtol=1e-12)
    np.testing.assert_allclose(ft / np.linalg.norm(ft), [-np.sqrt(0.5), -np.sqrt(0.5)], rtol=1e-12)
    np.testing.assert_allclose(big.spring, np.r_[0.0, ft], rtol=1e-12)  # the stored force sits on the limit
    # a contact without pressure transmits no friction
    none = _static(jnp.asarray(1e-9), jnp.zeros(3), jnp.array([0.0, 1e-4, 0.0]), jnp.asarray(-LAW.c0), p)
    assert abs(float(none.f_i[1])) <= PM["friction"] * _kn(1e-9)[0] * 1e-9 * (1 + 1e-12)


def test_damping_gives_the_coefficient_of_restitution():
    """Two free spheres colliding head-on separate at COR times their approach speed (Eq. 5, 7)."""
    cor, v0 = 0.5, 0.005
    pos = np.array([[0.0, 0.0, 0.0], [2 * R + 2e-6, 0.0, 0.0]])
    s = jaxbpm.Sample.from_arrays(pos, R, np.zeros((0, 2), int), bond_radius=np.zeros(0),
                                  particle_material={**PM, "restitution": cor})
    model = build_model(s, contacts=True, contact_law="cohesive")  # no cohesion: c0 = kc = c_max = 0
    assert not model.rotations  # Irazabal et al. 2023: particles do not rotate
    params = default_params(s)
    empty = jnp.zeros((0, 3))
    load = dem.Loading(clamped=jnp.zeros(2, bool), velocity=jnp.zeros((2, 3)), wall_points0=empty,
                       wall_normals=empty, wall_velocity=empty)
    owner = dem.neighbors._Neighbors(model, dem.NeighborSettings(skin=0.5 * R), model.positions0)
    state = dem.init_state(model, params, load, nbrs=owner.allocate(model.positions0))
    state = dataclasses.replace(state, velocities=jnp.array([[v0, 0, 0], [-v0, 0, 0]]))
    k, _ = _kn(0.0)
    t_c = np.pi / np.sqrt(k / (M / 2))
    dt = t_c / 400
    final, rec, _ = dem.simulate(model, params, load, dt=dt, n_steps=1200, chunk=1200, state=state)
    v = np.asarray(final.velocities)[:, 0]
    assert v[1] - v[0] > 0  # they parted
    np.testing.assert_allclose((v[1] - v[0]) / (2 * v0), cor, rtol=5e-3)
    np.testing.assert_allclose(v[0] + v[1], 0.0, atol=1e-12)  # momentum


def test_history_is_carried_through_neighbour_rebuilds():
    old = jnp.array([[0, 1], [2, 3], [1, 4], [5, 5]])  # the last row is padding (index n)
    n = 5
    spring = jnp.arange(12.0).reshape(4, 3)
    cohesion = jnp.array([1e4, -2e4, 3e4, 7.0])
    new = jnp.array([[1, 4], [0, 1], [0, 2], [5, 5]])
    s, c = dem.neighbors._remap_history(old, new, n, spring, cohesion)
    np.testing.assert_array_equal(c, [3e4, 1e4, 0.0, 0.0])  # kept by pair, zero for a pair new to the list
    np.testing.assert_array_equal(s, [[6, 7, 8], [0, 1, 2], [0, 0, 0], [0, 0, 0]])


def test_parameters_are_checked():
    with pytest.raises(SceneError, match="c_max"):
        co.CohesiveLaw(c0=3e4, kc=0.1, c_max=1e4)
    with pytest.raises(SceneError, match="restitution"):
        co.CohesiveLaw(restitution=0.0)
    with pytest.raises(SceneError, match="kc"):
        co.CohesiveLaw(kc=-0.1)
    with pytest.raises(SceneError, match="unknown parameters"):
        UniaxialCompression(contacts=True, contact_law="cohesive", cohesive={"c_0": 1.0})
    with pytest.raises(SceneError, match="contact law"):
        UniaxialCompression(contacts=True, contact_law="jkr")
    with pytest.raises(SceneError, match="contacts=True"):
        UniaxialCompression(contact_law="cohesive")
    with pytest.raises(SceneError, match="contact_law='cohesive'"):
        build_model(jaxbpm.generate.lattice("sc", (2, 2, 2), R), contacts=True, cohesive=LAW)


def _granular(seed=0):
    """An FCC packing of cohesive grains (no bonds), radii shrunk at random by up to 3 %."""
    lat = jaxbpm.generate.lattice("fcc", (2, 2, 3), R)
    rng = np.random.default_rng(seed)
    radii = np.asarray(lat.radii) * (1 - 0.03 * rng.uniform(size=lat.n_particles))
    return jaxbpm.Sample.from_arrays(lat.positions, radii, np.zeros((0, 2), int), bond_radius=np.zeros(0),
                                     particle_material=PM, domain=lat.domain)


def test_cohesive_sample_stress_strain_curve():
    """A cohesive granular sample under uniaxial compression gives the stress-strain curve Irazabal et al. calibrates
    against (17 points up to 11.33 % strain); cohesion raises it, and the DSM refuses the history-dependent law."""
    s = _granular()
    strains = np.linspace(0.0, 0.1133, 17)
    curves = {}
    for name, law in {"cohesive": {"c0": 2e4, "kc": 0.5, "c_max": 1e5, "initial_gap": 0.1 * R},
                      "cohesionless": {}}.items():
        scene = UniaxialCompression(strain=0.1133, contacts=True, contact_law="cohesive", cohesive=law,
                                    fit_range=(0.02, 0.1))
        res = jaxbpm.solve(s, scene, "dem", transits=12)
        assert res.stats["contact_law"] == "cohesive" and not res.stats["rotations"]
        curves[name] = res.stress_at(strains)
    c, f = curves["cohesive"], curves["cohesionless"]
    assert np.all(np.isfinite(c)) and c.shape == (17,)
    assert c[-1] > 0 and np.max(c[8:]) > 2 * max(np.max(f[8:]), 1.0)  # cohesion holds the grains together
    with pytest.raises(SceneError, match="method='dem'"):
        jaxbpm.solve(s, UniaxialCompression(contacts=True, contact_law="cohesive"), "dsm")
