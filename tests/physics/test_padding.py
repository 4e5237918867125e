"""Padding a model to a size class (jaxbpm.physics.padding) changes no force on the real particles."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm.physics import rotation
from jaxbpm.physics.model import build_model, default_params
from jaxbpm.physics.padding import pad_model, pad_rows


def test_pad_rows():
    out = pad_rows(np.arange(6).reshape(3, 2), 5, fill=-1)
    np.testing.assert_array_equal(out, [[0, 1], [2, 3], [4, 5], [-1, -1], [-1, -1]])
    with pytest.raises(ValueError, match="cannot pad 3 rows to 2"):
        pad_rows(np.zeros(3), 2)


def test_padded_model_gives_the_same_forces_on_the_real_particles():
    sample = jaxbpm.generate.lattice("fcc", (2, 2, 2))
    model, params = build_model(sample), default_params(sample)
    n, nb = model.n, int(model.bonds.shape[0])
    padded = pad_model(model, n + 5, nb + 7)
    assert padded.n == n + 5 and padded.bonds.shape[0] == nb + 7
    key = jax.random.PRNGKey(0)
    x = model.positions0 + 1e-5 * jax.random.normal(key, model.positions0.shape)
    q = jax.vmap(lambda k: rotation.from_rotation_vector(1e-3 * jax.random.normal(k, (3,))))(jax.random.split(key, n))
    f, m, _ = model.forces(x, q, params)
    x_p = jnp.concatenate([x, padded.positions0[n:]])
    q_p = jnp.concatenate([q, rotation.identity(5, x.dtype)])
    f_p, m_p, _ = padded.forces(x_p, q_p, params)
    assert float(jnp.max(jnp.abs(f))) > 0
    np.testing.assert_allclose(f_p[:n], f, rtol=0, atol=1e-12 * float(jnp.max(jnp.abs(f))))
    np.testing.assert_allclose(m_p[:n], m, rtol=0, atol=1e-12 * float(jnp.max(jnp.abs(m))))
    np.testing.assert_array_equal(f_p[n:], 0.0)  # the padding bonds have no stiffness


def test_a_size_class_too_small_is_refused():
    model = build_model(jaxbpm.generate.lattice("sc", (2, 2, 2)))
    with pytest.raises(ValueError, match="too small"):
        pad_model(model, model.n + 1, int(model.bonds.shape[0]))
