"""The shared tangent (jaxbpm.physics.tangent): closed forms, finite differences of the force laws, and the DSM and
the STE reading the same numbers."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxbpm import generate
from jaxbpm.physics import bond as bond_mod, contact as contact_mod, rotation, tangent


def _bonds(nb=5, seed=0):
    rng = np.random.default_rng(seed)
    r0 = rng.normal(size=(nb, 3))
    r0 *= (rng.uniform(1e-3, 3e-3, nb) / np.linalg.norm(r0, axis=1))[:, None]
    k = bond_mod.BondStiffness(*(jnp.asarray(rng.uniform(0.5, 2.0, nb) * s) for s in (1e6, 4e5, 1e-2, 2e-2)))
    return jnp.asarray(r0), k


def test_unit_jacobians_are_the_closed_form():
    """d f_i / d d at rest: k_n n n^T (normal) + k_t (I - n n^T) (shear); twist and bending need rotations."""
    r0, _ = _bonds()
    unit = np.asarray(tangent.bond_unit(r0)).reshape(4, -1, 3, 3)
    n = np.asarray(r0) / np.linalg.norm(r0, axis=1, keepdims=True)
    nn = n[:, :, None] * n[:, None, :]
    np.testing.assert_allclose(unit[0], nn, atol=1e-12)
    np.testing.assert_allclose(unit[1], np.eye(3) - nn, atol=1e-12)
    assert np.all(unit[2:] == 0.0)


@pytest.mark.parametrize("rotations", [False, True])
def test_full_tangent_matches_finite_differences_of_the_bond_law(rotations):
    r0, k = _bonds(nb=3, seed=1)
    nd = 6 if rotations else 3
    full = np.asarray(tangent.bond_full(r0, k, rotations))
    assert full.shape == (3, 2 * nd, 2 * nd)

    def forces(z, b):  # generalised forces (f_i, m_i, f_j, m_j) of bond b at DOFs z
        r = r0[b]
        ui, uj = z[:3], z[nd:nd + 3]
        if rotations:
            qi, qj = rotation.from_rotation_vector(z[3:6]), rotation.from_rotation_vector(z[9:12])
        else:
            qi = qj = jnp.array([1.0, 0.0, 0.0, 0.0])
        out = bond_mod.bond_law(r + uj - ui, r, qi, qj, k.kn[b], k.kt[b], k.ktw[b], k.kb[b])
        parts = [out.f_i, out.m_i, -out.f_i, out.m_j] if rotations else [out.f_i, -out.f_i]
        return jnp.concatenate(parts)

    h = 1e-7
    for b in range(3):
        fd = np.stack([(np.asarray(forces(h * e, b)) - np.asarray(forces(-h * e, b))) / (2 * h)
                       for e in jnp.eye(2 * nd)], axis=1)
        scale = np.max(np.abs(fd))
        np.testing.assert_allclose(full[b], -fd, atol=1e-6 * scale)


def test_full_tangent_is_symmetric_and_moves_rigidly():
    """Stiffness of a conservative law at rest: symmetric, and a rigid translation gives no force."""
    r0, k = _bonds(nb=4, seed=2)
    full = np.asarray(tangent.bond_full(r0, k, rotations=True))
    np.testing.assert_allclose(full, full.transpose(0, 2, 1), atol=1e-9 * np.max(np.abs(full)))
    shift = np.concatenate([[1.0, -2.0, 0.5], np.zeros(3)] * 2)
    np.testing.assert_allclose(full @ shift, 0.0, atol=1e-9 * np.max(np.abs(full)))


def test_contact_tangent_is_hertz_mindlin():
    """Normal stiffness 2 E* sqrt(R* delta) (Hertz); the whole block against finite differences of the law."""
    E, nu = 1e9, 0.25
    p = contact_mod.contact_params(E, nu, 0.5, 0.5)
    radii = jnp.array([[1e-3, 2e-3], [1.5e-3, 1.5e-3]])
    delta = jnp.array([2e-6, 5e-6])
    n = jnp.array([[0.0, 0.0, 1.0], [0.6, 0.8, 0.0]])
    d0 = n * (radii.sum(axis=1) - delta)[:, None]
    full = np.asarray(tangent.contact_full(d0, radii, p, dofs=3))
    rs = np.asarray(radii[:, 0] * radii[:, 1] / radii.sum(axis=1))
    kn = 2.0 * float(p.E_star) * np.sqrt(rs * np.asarray(delta))
    block = full[:, :3, 3:]  # force on i per displacement of j, sign flipped
    np.testing.assert_allclose(np.einsum("ca,cab,cb->c", n, block, n), -kn, rtol=1e-10)
    zero = jnp.zeros(3)
    h = 1e-10
    for c in range(2):
        def f_i(uj):
            ri, rj = radii[c, 0], radii[c, 1]
            return np.asarray(contact_mod.hertz_mindlin(d0[c] + uj, ri, rj, 1.0, 1.0, zero, uj, zero, p).f_i)
        fd = np.stack([(f_i(h * e) - f_i(-h * e)) / (2 * h) for e in jnp.eye(3)], axis=1)
        np.testing.assert_allclose(block[c], -fd, atol=1e-6 * np.max(np.abs(fd)))


def test_dsm_and_ste_read_the_same_tangent():
    """The DSM's reduced Jacobians and the STE's K^nm of every bond are the same numbers."""
    from jaxbpm import ste
    from jaxbpm.dsm import operator
    from jaxbpm.physics.model import build_model, default_params

    s = generate.box(300, seed=3, packing_fraction=0.5).largest_cluster()
    p = default_params(s)
    model = build_model(s, rotations=False)
    jr = np.asarray(jax.jit(operator.reduced_jacobians)(model, p))  # [in, out, nb]
    est = ste.estimator(s, pad=False)
    K = np.asarray(jax.jit(ste.tensor.coupling)(est, p))[:est.n_bonds]  # d f_i / d d, [nb, out, in]
    np.testing.assert_allclose(K, jr.transpose(2, 1, 0), rtol=1e-12, atol=1e-12 * np.max(np.abs(K)))
