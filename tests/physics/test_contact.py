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
