"""Preconditioned CG (:mod:`jaxbpm.dsm.krylov`)."""

import jax.numpy as jnp
import numpy as np

from jaxbpm import dsm
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression


def test_cg_starts_from_a_guess(packing):
    scene = UniaxialCompression(strain=0.002)
    model = scene.model(packing, contacts=False)
    free_np, fixed, driven = dsm.free_mask(model, scene, packing)
    delta = scene.strain * scene.geometry(packing)[0]
    u_p = np.zeros(free_np.shape)
    u_p[driven, scene.axis] = -delta
    free, u_p = jnp.asarray(free_np), jnp.asarray(u_p)
    full, jac = dsm.tangent_operator(model, default_params(packing))
    precond = dsm.build_preconditioner(model, default_params(packing), free, jac)
    cold = dsm.cg(full, precond, free, u_p, 1e-10, None)
    affine = dsm.cg(full, precond, free, u_p, 1e-10, None, x0=dsm.affine_field(packing, model, scene.axis, delta))
    # the same solution from a start closer to it (the guess's prescribed DOFs are not used)
    assert affine[1] <= 1e-10 and int(affine[2]) < int(cold[2]), (int(affine[2]), int(cold[2]))
    scale = np.abs(np.asarray(cold[0])).max(axis=0)  # displacements and rotations apart
    assert np.abs(np.asarray(affine[0] - cold[0]) / scale).max() < 1e-6
    np.testing.assert_allclose(affine[3], cold[3], rtol=1e-12)  # the energy, tracked from the guess's own
    # started at the solution, nothing is left to do
    assert int(dsm.cg(full, precond, free, u_p, 1e-8, None, x0=cold[0])[2]) == 0
