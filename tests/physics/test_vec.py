"""The component-tuple functions of the force laws (jaxbpm.physics.vec) against NumPy."""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm.physics import vec


class Out(NamedTuple):
    f: object
    m: object
    normal: object


def _tuple(a):
    return tuple(jnp.asarray(a[:, k]) for k in range(3))


def test_dot_and_cross_are_numpys():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(6, 3)), rng.normal(size=(6, 3))
    np.testing.assert_allclose(vec.dot(_tuple(a), _tuple(b)), np.einsum("ij,ij->i", a, b), rtol=1e-14)
    np.testing.assert_allclose(np.stack(vec.cross(_tuple(a), _tuple(b)), axis=1), np.cross(a, b), rtol=1e-13)


def test_safe_sqrt_has_a_finite_derivative_at_zero():
    x = jnp.array([0.0, 0.25, 4.0])
    np.testing.assert_allclose(vec.safe_sqrt(x), [0.0, 0.5, 2.0])
    grad = jax.vmap(jax.grad(vec.safe_sqrt))(x)
    np.testing.assert_allclose(grad, [0.0, 1.0, 0.25])
    assert float(jax.grad(jnp.sqrt)(0.0)) == np.inf  # what the plain square root gives


def test_stack_makes_arrays_of_component_tuples():
    rng = np.random.default_rng(1)
    f, m = rng.normal(size=(4, 3)), rng.normal(size=(4, 3))
    out = vec.stack(Out(_tuple(f), _tuple(m), jnp.ones(4)))
    assert isinstance(out, Out) and out.f.shape == (4, 3)
    np.testing.assert_array_equal(out.f, f)
    np.testing.assert_array_equal(out.m, m)
    np.testing.assert_array_equal(out.normal, np.ones(4))
    assert float(vec.once(jnp.array(6.0), jnp.array(2.0))) == 3.0
