"""PFC's linear contact model (jaxbpm.physics.linear) against its closed forms: normal force k_n delta with PFC's
deformability stiffness, shear increments k_s ds, the Coulomb cap, the dashpots' restitution, its tangent against
finite differences of the DEM's force function, and its scene-level checks."""

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm.errors import SceneError
from jaxbpm.physics import contact, linear, rotation, tangent
from jaxbpm.physics.model import build_model, default_params

R1, R2 = 1e-3, 1.5e-3
EMOD, KRATIO, MU = 2e9, 1.21, 0.4


def _pair_sample(overlap, friction=MU):
    return jaxbpm.Sample.from_arrays(np.array([[0, 0, 0], [R1 + R2 - overlap, 0, 0]]), [R1, R2],
                                     np.zeros((0, 2), int), bond_radius=np.zeros(0),
                                     particle_material={"E": 1e9, "nu": 0.25, "friction": friction})


def test_normal_force_is_kn_times_overlap_with_pfc_deformability_stiffness():
    delta = 2e-6
    s = _pair_sample(delta)
    model = build_model(s, contacts=True, contact_law=linear.LinearLaw(emod=EMOD, kratio=KRATIO))
    assert model.contact_law == "linear" and model.rotations  # frictional contacts rotate the particles
    zeros = jnp.zeros((1, 3))
    f, m, parts = model.forces(model.positions0, rotation.identity(2, zeros.dtype), default_params(s),
                               contacts=(jnp.array([[0, 1]]), jnp.array([True]), zeros, zeros, zeros))
    kn = EMOD * math.pi * min(R1, R2) ** 2 / (R1 + R2)  # A = pi min(R)^2, L = R1 + R2
    np.testing.assert_allclose(-float(f[0, 0]), kn * delta, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(f[0] + f[1]), 0.0, atol=1e-20)
    np.testing.assert_allclose(float(parts["contacts"].normal[0]), kn * delta, rtol=1e-12)
    np.testing.assert_allclose(float(linear.normal_stiffness(R1, R2, EMOD)), kn, rtol=1e-15)
    # the stiffness is constant: twice the overlap, twice the force
    s2 = _pair_sample(2 * delta)
    f2, _, _ = build_model(s2, contacts=True, contact_law=linear.LinearLaw(emod=EMOD, kratio=KRATIO)).forces(
        jnp.asarray(s2.positions), None, default_params(s2),
        contacts=(jnp.array([[0, 1]]), jnp.array([True]), zeros, zeros, zeros))
    np.testing.assert_allclose(float(f2[0, 0]), 2 * float(f[0, 0]), rtol=1e-12)


def test_shear_force_grows_by_ks_ds_and_is_capped_by_coulomb():
    p = linear.linear_params(EMOD, KRATIO, MU)
    delta = 1e-6
    d = jnp.array([R1 + R2 - delta, 0.0, 0.0])
    zero = jnp.zeros(3)
    kn = EMOD * math.pi * R1**2 / (R1 + R2)
    ks = kn / KRATIO
    ds1, ds2 = jnp.array([0.0, 1e-8, 0.0]), jnp.array([0.0, 0.0, 2e-8])
    a = contact.hertz_mindlin(d, R1, R2, 1.0, 1.0, zero, ds1, zero, p)
    np.testing.assert_allclose(np.asarray(a.f_i), [-kn * delta, ks * 1e-8, 0.0], rtol=1e-12)  # i dragged along j
    # the next step's slip adds its own increment: F_s = k_s (ds1 + ds2)
    b = contact.hertz_mindlin(d, R1, R2, 1.0, 1.0, a.spring, ds2, zero, p)
    np.testing.assert_allclose(np.asarray(b.f_i[1:]), [ks * 1e-8, ks * 2e-8], rtol=1e-12)
    assert not bool(b.sliding)
    # a moment on each particle: the tangential force at the contact point, (r - delta / 2) from the centre
    np.testing.assert_allclose(float(jnp.linalg.norm(b.m_i)), (R1 - delta / 2) * ks * math.hypot(1e-8, 2e-8),
                               rtol=1e-12)
    np.testing.assert_allclose(float(jnp.linalg.norm(b.m_j)), (R2 - delta / 2) * ks * math.hypot(1e-8, 2e-8),
                               rtol=1e-12)
    # a large slip slides at mu F_n, and the spring is shortened to match the force
    big = jnp.array([0.0, 1e-5, 0.0])
    c = contact.hertz_mindlin(d, R1, R2, 1.0, 1.0, zero, big, zero, p)
    assert bool(c.sliding)
    np.testing.assert_allclose(float(c.f_i[1]), MU * kn * delta, rtol=1e-12)
    np.testing.assert_allclose(float(c.spring[1]), MU * kn * delta / ks, rtol=1e-12)
    # unloading from the limit is elastic again: a step back takes k_s off the capped force
    back = contact.hertz_mindlin(d, R1, R2, 1.0, 1.0, c.spring, -ds1, zero, p)
    np.testing.assert_allclose(float(back.f_i[1]), MU * kn * delta - ks * 1e-8, rtol=1e-12)
    # out of contact: nothing, and the spring is dropped
    apart = contact.hertz_mindlin(jnp.array([R1 + R2 + 1e-6, 0, 0]), R1, R2, 1.0, 1.0, c.spring, ds1, zero, p)
    assert not bool(apart.active) and float(jnp.abs(apart.f_i).max()) == 0.0 and float(apart.spring[1]) == 0.0


def test_two_dimensional_discs_use_the_unit_thickness_area():
    p = linear.linear_params(EMOD, KRATIO, MU)
    delta = 1e-6
    zero = (jnp.asarray(0.0),) * 2
    out = linear.law_components((jnp.asarray(R1 + R2 - delta), jnp.asarray(0.0)), R1, R2, 1.0, 1.0, zero,
                                (0.0, 1e-9), zero, p)
    kn = EMOD * 2 * R1 * 1.0 / (R1 + R2)  # A = 2 r t, t = 1 m
    np.testing.assert_allclose([float(c) for c in out.f_i], [-kn * delta, kn / KRATIO * 1e-9], rtol=1e-12)
    assert len(out.m_i) == 1  # one (out-of-plane) moment
    # i is dragged along +y at its contact point, (r - delta / 2) along +x: a moment about +z
    np.testing.assert_allclose(float(out.m_i[0]), (R1 - delta / 2) * kn / KRATIO * 1e-9, rtol=1e-12)


def test_dashpots_give_the_coefficient_of_restitution():
    e = 0.3
    p = linear.linear_params(EMOD, KRATIO, MU, restitution=e, damping=True)
    beta = float(p.beta)
    # a linear spring-dashpot with damping ratio beta rebounds with e = exp(-pi beta / sqrt(1 - beta^2))
    np.testing.assert_allclose(math.exp(-math.pi * beta / math.sqrt(1 - beta**2)), e, rtol=1e-12)
    d, zero, m1, m2 = jnp.array([R1 + R2 - 1e-6, 0.0, 0.0]), jnp.zeros(3), 2.0, 3.0
    v = jnp.array([-0.1, 0.0, 0.0])  # approaching
    out = contact.hertz_mindlin(d, R1, R2, m1, m2, zero, zero, v, p)
    kn = float(linear.normal_stiffness(R1, R2, EMOD))
    c_n = 2 * beta * math.sqrt(m1 * m2 / (m1 + m2) * kn)
    np.testing.assert_allclose(float(out.normal), kn * 1e-6 + c_n * 0.1, rtol=1e-12)


def test_tangent_matches_finite_differences_of_the_dem_force():
    """The 12 x 12 pair stiffness the DSM and STE take (tangent.contact_full, jvps of the law) against central
    differences of Model.forces (the DEM's force function) with the contact points' slip since rest."""
    delta = 3e-6
    s = _pair_sample(delta, friction=1e3)
    model = build_model(s, contacts=True, contact_law=linear.LinearLaw(emod=EMOD, kratio=KRATIO))
    params, x0 = default_params(s), model.positions0
    pairs, valid = jnp.array([[0, 1]]), jnp.array([True])
    d0 = x0[1] - x0[0]
    n = d0 / jnp.linalg.norm(d0)

    def forces(z):
        u, w = z[np.array([0, 1, 2, 6, 7, 8])].reshape(2, 3), z[np.array([3, 4, 5, 9, 10, 11])].reshape(2, 3)
        slip = u[1] - u[0] + jnp.cross(w[1], -R2 * n) - jnp.cross(w[0], R1 * n)
        zero = jnp.zeros((1, 3))
        q = rotation.from_rotation_vector(w)
        f, m, _ = model.forces(x0 + u, q, params, contacts=(pairs, valid, zero, slip[None], zero))
        return jnp.concatenate([f[0], m[0], f[1], m[1]])

    h, forces = 1e-10, jax.jit(forces)
    fd = np.stack([(forces(h * e) - forces(-h * e)) / (2 * h) for e in np.eye(12)], axis=1)
    k = np.asarray(tangent.contact_full(d0[None], jnp.array([[R1, R2]]), model.contact, 6)[0])
    np.testing.assert_allclose(k, -fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())
    # and at the contact's rest (zero overlap about to close): k_n along n, k_s across
    kn = float(linear.normal_stiffness(R1, R2, EMOD))
    touch = jnp.array([[R1 + R2 - 1e-15, 0.0, 0.0]])
    k0 = np.asarray(tangent.contact_full(touch, jnp.array([[R1, R2]]), model.contact, 3)[0])
    np.testing.assert_allclose(np.diag(k0)[:3], [kn, kn / KRATIO, kn / KRATIO], rtol=1e-9)


def test_gradients_with_respect_to_emod_and_kratio_match_finite_differences():
    delta = 2e-6
    d = jnp.array([R1 + R2 - delta, 0.0, 0.0])
    zero = jnp.zeros(3)

    def work(emod, kratio):
        p = linear.linear_params(emod, kratio, MU)
        out = contact.hertz_mindlin(d, R1, R2, 1.0, 1.0, zero, jnp.array([0.0, 1e-8, 3e-8]), zero, p)
        return jnp.sum(out.f_i * jnp.array([1.0, 2.0, -1.5]))

    g = jax.grad(work, argnums=(0, 1))(EMOD, KRATIO)
    for k, (x, step) in enumerate(((EMOD, 1e-4 * EMOD), (KRATIO, 1e-4 * KRATIO))):
        args = [EMOD, KRATIO]
        hi, lo = list(args), list(args)
        hi[k], lo[k] = x + step, x - step
        fd = (work(*hi) - work(*lo)) / (2 * step)
        np.testing.assert_allclose(float(g[k]), float(fd), rtol=1e-7)


def test_linear_law_defaults_and_bad_parameters():
    pm = _pair_sample(1e-6).particle_material
    p = linear.LinearLaw().params(pm)
    assert float(p.emod) == 1e9 and float(p.friction) == MU and p.beta is None
    np.testing.assert_allclose(float(p.kratio), (2 - 0.25) / (2 * (1 - 0.25)), rtol=1e-15)
    for bad in ({"emod": 0.0}, {"kratio": -1.0}, {"friction": -0.1}, {"restitution": 1.5}, {"emod": float("nan")}):
        with pytest.raises(SceneError, match="linear contact law"):
            linear.LinearLaw(**bad)
    with pytest.raises(SceneError, match="cohesive contact parameters"):
        build_model(_pair_sample(1e-6), contacts=True, contact_law="linear", cohesive={"c0": 1.0})
    with pytest.raises(SceneError, match="unknown contact law 'lineer'"):
        build_model(_pair_sample(1e-6), contacts=True, contact_law="lineer")


def test_bonded_pairs_overlapping_at_rest_are_warned_about():
    pos = np.array([[0, 0, 0], [R1 + R2 - 1e-6, 0, 0]])
    s = jaxbpm.Sample.from_arrays(pos, [R1, R2], [[0, 1]], bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})
    kn = EMOD * math.pi * R1**2 / (R1 + R2)
    with pytest.warns(UserWarning, match=f"1 of 1 bonded pairs overlap at rest .*up to {kn * 1e-6:.3g} N"):
        build_model(s, contacts=True, contact_law=linear.LinearLaw(emod=EMOD))
    touching = s.replace(positions=np.array([[0, 0, 0], [R1 + R2, 0, 0]]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        build_model(touching, contacts=True, contact_law="linear")
        build_model(s, contacts=True)  # Hertz-Mindlin: no warning


def test_discs_of_any_thickness_and_the_model_of_a_2d_sample():
    t, delta = 0.3, 1e-6
    zero = (jnp.asarray(0.0),) * 2
    out = linear.law_components((jnp.asarray(R1 + R2 - delta), jnp.asarray(0.0)), R1, R2, 1.0, 1.0, zero, zero,
                                zero, linear.linear_params(EMOD, KRATIO, MU, thickness=t))
    kn = EMOD * 2 * R1 * t / (R1 + R2)  # A = 2 r t
    np.testing.assert_allclose(float(out.f_i[0]), -kn * delta, rtol=1e-12)
    # a 2D sample's model carries its thickness into the law: the DEM's pair forces in [n, 2] and [n, 1]
    s = jaxbpm.Sample.from_arrays(np.array([[0.0, 0.0], [R1 + R2 - delta, 0.0]]), [R1, R2], np.zeros((0, 2), int),
                                  bond_radius=np.zeros(0), thickness=t,
                                  particle_material={"E": 1e9, "nu": 0.25, "friction": MU})
    model = build_model(s, contacts=True, contact_law=linear.LinearLaw(emod=EMOD, kratio=KRATIO))
    assert float(model.contact.thickness) == t and model.dofs == 3
    zeros = jnp.zeros((1, 2))
    f, m, _ = model.forces(model.positions0, jnp.zeros((2, 1)), default_params(s),
                           contacts=(jnp.array([[0, 1]]), jnp.array([True]), zeros, zeros, zeros))
    assert f.shape == (2, 2) and m.shape == (2, 1)
    np.testing.assert_allclose(np.asarray(f), [[-kn * delta, 0.0], [kn * delta, 0.0]], rtol=1e-12, atol=1e-20)
