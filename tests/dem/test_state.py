"""The DEM state: kinetic energy in closed form, a loading padded with particles clamped at rest, a padded state cut
back to the sample, and the checkpoint arrays that give the state back."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm.dem.state import (DEMState, kinetic_energy, pad_loading, restore_state, state_arrays, unpad_state)
from jaxbpm.dem.stepper import init_state
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression

R = 1e-3


@pytest.fixture(scope="module")
def column():
    s = jaxbpm.generate.lattice("sc", (1, 1, 4), R, bond_radius_ratio=0.5)
    scene = UniaxialCompression(strain=0.002)
    return s, scene, scene.model(s), scene.loading(s, 0.1)


def test_kinetic_energy_in_closed_form(column):
    s, _, model, load = column
    state = init_state(model, default_params(s), load)
    v, w = np.arange(12.0).reshape(4, 3), np.ones((4, 3))
    state = dataclasses.replace(state, velocities=jnp.asarray(v), omegas=jnp.asarray(w))
    expected = 0.5 * np.sum(np.asarray(s.mass)[:, None] * v**2)
    if model.rotations:
        expected += 0.5 * np.sum(np.asarray(s.inertia)[:, None] * w**2)
    np.testing.assert_allclose(float(kinetic_energy(model, state)), expected, rtol=1e-14)


def test_padding_the_loading_and_cutting_the_state_back(column):
    s, _, model, load = column
    padded = pad_loading(load, 7)
    np.testing.assert_array_equal(padded.clamped, np.r_[np.asarray(load.clamped), [True] * 3])
    np.testing.assert_array_equal(padded.velocity[:4], load.velocity)
    np.testing.assert_array_equal(padded.velocity[4:], 0.0)
    with pytest.raises(ValueError, match="cannot pad"):
        pad_loading(load, 3)
    state = init_state(model, default_params(s), load)
    big = dataclasses.replace(state, positions=jnp.concatenate([state.positions, jnp.ones((3, 3))]),
                              intact=jnp.concatenate([state.intact, jnp.zeros(2, bool)]))
    cut = unpad_state(big, s.n_particles, s.n_bonds)
    np.testing.assert_array_equal(cut.positions, state.positions)
    np.testing.assert_array_equal(cut.intact, state.intact)


def test_checkpoint_arrays_give_the_state_back(column):
    s, _, model, load = column
    state = init_state(model, default_params(s), load)
    arrays = state_arrays(state)
    assert "nbrs_idx" not in arrays and "cohesion" not in arrays  # (no contacts: no list, no history)
    back = restore_state(arrays)
    assert isinstance(back, DEMState) and back.nbrs is None and back.cohesion is None
    for f in dataclasses.fields(DEMState):
        a, b = getattr(state, f.name), getattr(back, f.name)
        if a is None:
            assert b is None
        else:
            np.testing.assert_array_equal(np.asarray(b), np.asarray(a))
