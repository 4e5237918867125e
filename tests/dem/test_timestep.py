"""The critical time step against the highest natural frequency of the linearised model, found independently (the
dense stiffness matrix of the Model's forces, its generalised eigenvalues by NumPy)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import InstabilityError
from jaxbpm.dem.timestep import critical_time_step
from jaxbpm.physics import rotation
from jaxbpm.physics.model import build_model, default_params

R = 1e-3


def _omega2_max(s):
    """omega_max^2 of ``M^-1 K``, K the Jacobian of the forces and moments against the translations and rotation
    vectors at rest (a dense matrix: small samples only)."""
    model, params = build_model(s), default_params(s)
    n = s.n_particles
    x0 = model.positions0

    def generalised_forces(z):
        u, w = z[:3 * n].reshape(n, 3), z[3 * n:].reshape(n, 3)
        q = rotation.integrate(rotation.identity(n, x0.dtype), w)
        f, m, _ = model.forces(x0 + u, q, params)
        return jnp.concatenate([f.ravel(), m.ravel()])

    k = -np.asarray(jax.jacfwd(generalised_forces)(jnp.zeros(6 * n)))
    mass = np.concatenate([np.repeat(np.asarray(s.mass), 3), np.repeat(np.asarray(s.inertia), 3)])
    scaled = k / np.sqrt(mass)[:, None] / np.sqrt(mass)[None, :]
    return float(np.max(np.linalg.eigvalsh(0.5 * (scaled + scaled.T))))


@pytest.mark.parametrize("sample", ["pair", "column"])
def test_critical_time_step_is_two_over_the_highest_frequency(sample):
    if sample == "pair":
        s = jaxbpm.Sample.from_arrays(np.array([[0.0, 0, 0], [2 * R, 0, 0]]), R, [[0, 1]], bond_radius_ratio=0.6,
                                      materials={"E": 1e9, "nu": 0.3})
    else:
        s = jaxbpm.generate.lattice("sc", (1, 2, 3), R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})
    dt = critical_time_step(build_model(s), default_params(s), iterations=400)
    # (the estimate keeps a 2 % margin on omega_max^2)
    np.testing.assert_allclose(dt, 2.0 / np.sqrt(1.02 * _omega2_max(s)), rtol=1e-6)


def test_a_model_without_stiffness_has_no_time_step():
    s = jaxbpm.Sample.from_arrays(np.array([[0.0, 0, 0], [3 * R, 0, 0]]), R, np.zeros((0, 2), int),
                                  bond_radius=np.zeros(0))
    with pytest.raises(InstabilityError, match="no stiffness"):
        critical_time_step(build_model(s), default_params(s))
