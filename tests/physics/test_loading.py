"""Boundary conditions (jaxbpm.physics.loading): a frozen pytree that jit carries through, as scenes build it."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm.physics.loading import Loading
from jaxbpm.scenes import UniaxialCompression


def _loading(n=4, walls=2):
    return Loading(clamped=jnp.arange(n) % 2 == 0, velocity=jnp.ones((n, 3)), wall_points0=jnp.zeros((walls, 3)),
                   wall_normals=jnp.tile(jnp.array([0.0, 0.0, 1.0]), (walls, 1)), wall_velocity=jnp.zeros((walls, 3)))


def test_loading_is_a_frozen_pytree():
    load = _loading()
    leaves, tree = jax.tree_util.tree_flatten(load)
    assert len(leaves) == 5
    assert jax.tree_util.tree_unflatten(tree, leaves) == load
    moved = jax.jit(lambda lo, t: lo.wall_points0 + t * lo.wall_velocity)(load, 2.0)
    np.testing.assert_array_equal(moved, np.zeros((2, 3)))
    with pytest.raises(dataclasses.FrozenInstanceError):
        load.clamped = None


def test_a_scene_builds_the_loading_of_a_sample():
    sample = jaxbpm.generate.lattice("sc", (2, 2, 3))
    load = UniaxialCompression(strain=0.001).loading(sample, 0.5)
    assert isinstance(load, Loading)
    clamped, velocity = np.asarray(load.clamped), np.asarray(load.velocity)
    assert clamped.shape == (sample.n_particles,) and velocity.shape == (sample.n_particles, 3)
    assert clamped.any() and not clamped.all()
    # the driven particles move at -speed along the axis, the others not at all
    moving = np.linalg.norm(velocity, axis=1) > 0
    assert moving.any() and (clamped | ~moving).all()
    np.testing.assert_allclose(velocity[moving], np.tile([0.0, 0.0, -0.5], (int(moving.sum()), 1)))
