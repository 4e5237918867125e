"""Quaternion rotations (jaxbpm.physics.rotation) against the exponential map."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxbpm.physics import rotation


@pytest.mark.parametrize("largest", [1e-7, 1e-3, 0.03, 0.5])
def test_quaternion_update_is_the_exponential_map(largest):
    """``integrate`` turns by ``exp(theta)``: its series branch (every turn below 0.032 rad, as in explicit steps)
    and its trigonometric branch agree with the closed form to round-off, at every angle up to the threshold."""
    key = jax.random.PRNGKey(3)
    q = rotation.from_rotation_vector(jax.random.normal(key, (64, 3)))
    scales = jnp.logspace(-9, np.log10(largest), 64)
    theta = jax.random.normal(jax.random.PRNGKey(4), (64, 3))
    theta = theta / jnp.linalg.norm(theta, axis=1, keepdims=True) * scales[:, None]
    a = jnp.linalg.norm(theta, axis=1)
    exact = jnp.concatenate([jnp.cos(a / 2)[:, None], (jnp.sin(a / 2) / a)[:, None] * theta], axis=1)
    expected = jax.vmap(rotation.multiply)(exact, q)
    np.testing.assert_allclose(rotation.integrate(q, theta), expected, rtol=0, atol=4e-16)
    # the same turns beside one large one take the trigonometric branch: the same quaternions to round-off
    mixed = rotation.integrate(jnp.concatenate([q, q[:1]]), jnp.concatenate([theta, jnp.array([[1.0, 0.0, 0.0]])]))
    np.testing.assert_allclose(mixed[:64], expected, rtol=0, atol=4e-16)
