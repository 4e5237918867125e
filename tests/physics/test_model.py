"""The model of a sample (jaxbpm.physics.model): rigid motion gives no internal force; a model holds what its
scene needs."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm.physics import rotation
from jaxbpm.physics.model import build_model, default_params

R = 1e-3


def pair(distance=2 * R, **kw):
    pos = np.array([[0.0, 0.0, 0.0], [distance, 0.0, 0.0]])
    return jaxbpm.Sample.from_arrays(pos, R, [[0, 1]], bond_radius_ratio=0.5,
                                     materials={"E": 1e9, "nu": 0.3}, **kw)


def _random_rotation(key):
    return rotation.from_rotation_vector(jax.random.normal(key, (3,)) * 1.3)


def test_rigid_motion_of_a_whole_sample_gives_no_internal_force():
    s = jaxbpm.generate.lattice("fcc", (2, 2, 2), R)
    model = build_model(s)
    params = default_params(s)
    q = _random_rotation(jax.random.PRNGKey(3))
    x = rotation.rotate(q[None, :], model.positions0) + jnp.array([[1e-2, -3e-3, 5e-3]])
    qs = jnp.broadcast_to(q, (s.n_particles, 4))
    f, m, _ = model.forces(x, qs, params)
    # the same rotation with one particle nudged by 1 um gives a clear force, so the check can fail
    f_ref, _, _ = model.forces(x.at[0, 0].add(1e-6), qs, params)
    scale = float(jnp.max(jnp.abs(f_ref)))
    assert scale > 0
    assert float(jnp.max(jnp.abs(f))) < 1e-8 * scale
    assert float(jnp.max(jnp.abs(m))) < 1e-8 * scale * R


def test_model_has_only_what_it_needs():
    s = pair()
    assert build_model(s).rotations is True
    assert build_model(s, rotations=False).rotations is False
    free = jaxbpm.Sample.from_arrays(np.array([[0, 0, 0], [3e-3, 0, 0.0]]), R, np.zeros((0, 2), int),
                                     bond_radius=np.zeros(0), particle_material={"friction": 0.0})
    m = build_model(free, contacts=True)
    assert m.contacts and not m.rotations and m.walls is None


def test_dimension_and_dofs_are_the_samples():
    # the spatial dimension is data (positions [n, dim]); DOF per particle: translations, plus rotations if any
    s = pair()
    assert build_model(s).dim == s.dim == 3
    assert build_model(s).dofs == 6 and build_model(s, rotations=False).dofs == 3


def test_float32_model_warns():
    s = pair()
    with jax.enable_x64(False):
        with pytest.warns(UserWarning, match="float32"):
            build_model(s)


def test_two_dimensional_model_bonds_only_and_padded():
    from jaxbpm.errors import SceneError
    from jaxbpm.generate import lattice

    s = lattice("square", (4, 3))
    with pytest.raises(SceneError, match="not available in 2D"):
        build_model(s, contacts=True)  # Hertz-Mindlin: the linear law only between discs
    m = build_model(s)
    assert (m.dim, m.dofs) == (2, 3) and build_model(s, rotations=False).dofs == 2
    padded = build_model(s, pad_to=(20, 30))
    u = 1e-6 * jnp.sin(jnp.arange(2 * s.n_particles, dtype=float)).reshape(-1, 2)
    params = default_params(s)
    f, mo, _ = m.forces(m.positions0 + u, jnp.zeros((m.n, 1)), params)
    fp, mp, _ = padded.forces(padded.positions0.at[:m.n].add(u), jnp.zeros((20, 1)), params)
    assert jnp.allclose(f, fp[:m.n], rtol=1e-12, atol=1e-9) and jnp.allclose(mo, mp[:m.n], rtol=1e-12, atol=1e-12)
    assert float(jnp.abs(fp[m.n:]).max()) == 0.0
