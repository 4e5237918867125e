"""Plane walls (jaxbpm.physics.wall) against the Hertz and linear closed forms."""

import jax.numpy as jnp
import numpy as np

from jaxbpm.physics import wall

R = 1e-3


def test_wall_hertz_and_linear():
    pos = jnp.array([[0.0, 0.0, 0.9e-3], [0.0, 0.0, 5e-3]])
    radii = jnp.array([R, R])
    points, normals = jnp.array([[0.0, 0.0, 0.0]]), jnp.array([[0.0, 0.0, 1.0]])
    f, reaction = wall.wall_forces(pos, radii, points, normals, "hertz", 1e9)
    expected = 4 / 3 * 1e9 * np.sqrt(R) * (0.1e-3) ** 1.5
    np.testing.assert_allclose(f[0], [0, 0, expected], rtol=1e-12)
    np.testing.assert_allclose(f[1], 0.0)
    np.testing.assert_allclose(reaction[0], [0, 0, -expected], rtol=1e-12)
    f, _ = wall.wall_forces(pos, radii, points, normals, "linear", 1e5)
    np.testing.assert_allclose(f[0, 2], 1e5 * 0.1e-3, rtol=1e-12)
