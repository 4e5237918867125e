"""Hertz-Mindlin contacts (jaxbpm.physics.contact) against closed forms."""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm.physics import contact
from jaxbpm.physics.model import build_model, default_params

R = 1e-3


@pytest.mark.parametrize("delta_rel", [1e-4, 1e-3, 1e-2, 5e-2])
def test_hertz_normal_force_closed_form(delta_rel):
    r1, r2 = 1e-3, 2e-3
    delta = delta_rel * r1
    E, nu = 5e9, 0.3
    s = jaxbpm.Sample.from_arrays(np.array([[0, 0, 0], [r1 + r2 - delta, 0, 0]]), [r1, r2], np.zeros((0, 2), int),
                                  bond_radius=np.zeros(0), particle_material={"E": E, "nu": nu, "friction": 0.0})
    model = build_model(s, contacts=True)
    zeros = jnp.zeros((1, 3))
    pairs = (jnp.array([[0, 1]]), jnp.array([True]), zeros, zeros, zeros)
    f, _, parts = model.forces(model.positions0, None, default_params(s), contacts=pairs)
    e_star = E / (2 * (1 - nu**2))
    r_star = r1 * r2 / (r1 + r2)
    expected = 4 / 3 * e_star * np.sqrt(r_star) * delta**1.5
    np.testing.assert_allclose(-f[0, 0], expected, rtol=1e-10)
    np.testing.assert_allclose(f[1, 0], expected, rtol=1e-10)
    np.testing.assert_allclose(parts["contacts"].normal[0], expected, rtol=1e-10)


def test_mindlin_tangential_spring_and_coulomb_limit():
    p = contact.contact_params(1e9, 0.25, 0.5, 0.5)
    d = jnp.array([1.99e-3, 0.0, 0.0])
    zero = jnp.zeros(3)
    small = jnp.array([0.0, 1e-9, 0.0])
    out = contact.hertz_mindlin(d, R, R, 1.0, 1.0, zero, small, zero, p)
    delta, r_star = 2 * R - 1.99e-3, R / 2
    kt = 8 * p.G_star * np.sqrt(r_star * delta)
    np.testing.assert_allclose(out.f_i[1], kt * 1e-9, rtol=1e-10)  # i is dragged along with j
    assert not bool(out.sliding)
    big = jnp.array([0.0, 1e-4, 0.0])
    out = contact.hertz_mindlin(d, R, R, 1.0, 1.0, zero, big, zero, p)
    np.testing.assert_allclose(jnp.linalg.norm(out.f_i[1:]), 0.5 * out.normal, rtol=1e-10)
    assert bool(out.sliding)


def test_sliding_spring_without_damping_terms_equals_the_damped_law_at_zero_damping():
    # the undamped law scales the spring with the force when a contact slides; the damped one computes -F_t / k_t:
    # at zero damping both give the same forces and springs, and a sliding spring carries exactly mu F_n
    rng = np.random.default_rng(3)
    c = 64
    d = np.array([2 * R, 0.0, 0.0]) + rng.normal(0.0, 2e-5, (c, 3))
    spring = rng.normal(0.0, 3e-6, (c, 3))
    spring[:8] = 0.0  # new contacts
    dxi, v_rel = rng.normal(0.0, 1e-6, (c, 3)), rng.normal(0.0, 1e-2, (c, 3))
    plain = contact.contact_params(1e9, 0.25, 0.4, 0.5)
    damped = contact.contact_params(1e9, 0.25, 0.4, 0.5, damping=jnp.asarray(False))
    assert plain.beta is None and float(damped.beta) == 0.0
    args = [tuple(jnp.asarray(a.T)) for a in (d, spring, dxi, v_rel)]
    a = contact.law_components(args[0], R, R, 1.0, 1.0, *args[1:], plain)
    b = contact.law_components(args[0], R, R, 1.0, 1.0, *args[1:], damped)
    a_f, b_f, a_s, b_s = (np.stack(v) for v in (a.f_i, b.f_i, a.spring, b.spring))
    np.testing.assert_allclose(a_f, b_f, rtol=0, atol=1e-13 * np.abs(b_f).max())
    np.testing.assert_allclose(a_s, b_s, rtol=0, atol=1e-13 * np.abs(b_s).max())
    sliding, active = np.asarray(a.sliding), np.asarray(a.active)
    assert sliding.sum() > 5 and (active & ~sliding).sum() > 5 and (~active).sum() > 5
    delta = 2 * R - np.linalg.norm(d, axis=1)
    kt = 8 * float(plain.G_star) * np.sqrt(R / 2 * np.maximum(delta, 0.0))
    np.testing.assert_allclose((kt * np.linalg.norm(a_s, axis=0))[sliding], 0.4 * np.asarray(a.normal)[sliding],
                               rtol=1e-12)
    assert np.all(a_s[:, ~active] == 0.0)
