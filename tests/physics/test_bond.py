"""The bond law (jaxbpm.physics.bond) against closed forms and invariants, and its pass over blocks of bonds
against the one pass."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm.physics import bond, rotation
from jaxbpm.physics.model import build_model, default_params


def test_stiffness_formulas():
    E, nu, rb, L = 2e9, 0.2, 0.4e-3, 2e-3
    A, I, J = np.pi * rb**2, np.pi * rb**4 / 4, np.pi * rb**4 / 2
    k = bond.stiffness(E, nu, A, I, J, L)
    np.testing.assert_allclose(k.kn, E * A / L)
    np.testing.assert_allclose(k.kt, E * A / (2 * L * (1 + nu)))
    np.testing.assert_allclose(k.ktw, E * J / (2 * L * (1 + nu)))
    np.testing.assert_allclose(k.kb, E * I / L)


def _random_rotation(key):
    return rotation.from_rotation_vector(jax.random.normal(key, (3,)) * 1.3)


def test_rigid_motion_of_a_pair_gives_zero_force():
    r0 = jnp.array([2e-3, 0.5e-3, -0.3e-3])
    q = _random_rotation(jax.random.PRNGKey(1))
    d = rotation.rotate(q, r0)
    out = bond.bond_law(d, r0, q, q, 1e5, 4e4, 1e-3, 2e-3)
    scale = 1e5 * 1e-3  # force of a 1 um stretch
    for name in ("f_i", "m_i", "m_j"):
        assert float(jnp.max(jnp.abs(getattr(out, name)))) < 1e-9 * scale, name


def test_bond_law_conserves_momentum_and_matches_linear_law():
    r0 = jnp.array([2e-3, 0.0, 0.0])
    k = (1e5, 4e4, 1e-3, 2e-3)
    u = jnp.array([1e-7, 2e-7, -1e-7])  # small relative displacement of j
    th_i, th_j = jnp.array([1e-5, 0.0, 2e-5]), jnp.array([0.0, -3e-5, 1e-5])
    qi, qj = rotation.from_rotation_vector(th_i), rotation.from_rotation_vector(th_j)
    out = bond.bond_law(r0 + u, r0, qi, qj, *k)
    # angular momentum balance about particle i: r x f_j + m_i + m_j = 0
    total = jnp.cross(r0 + u, -out.f_i) + out.m_i + out.m_j
    assert float(jnp.max(jnp.abs(total))) < 1e-12
    # linear law (Jarolin & Dosta 2020, Eq. 1-4) on the bond frame x = axis
    kn, kt, ktw, kb = k
    delta_t = jnp.array([0.0, u[1], u[2]]) - jnp.cross(th_i + th_j, 0.5 * r0)
    expected_f = jnp.array([kn * u[0], 0.0, 0.0]) + kt * jnp.array([0.0, delta_t[1], delta_t[2]])
    np.testing.assert_allclose(out.f_i, expected_f, rtol=2e-3, atol=1e-9 * kn * 1e-7)
    phi = th_j - th_i
    expected_moment = jnp.array([ktw * phi[0], kb * phi[1], kb * phi[2]])
    np.testing.assert_allclose(0.5 * (out.m_i - out.m_j), expected_moment, rtol=1e-3)
    np.testing.assert_allclose(0.5 * (out.m_i + out.m_j), jnp.cross(0.5 * r0, expected_f), rtol=2e-3, atol=1e-4 * 6.8e-6)


@pytest.mark.parametrize("rule", ["separate", "summed"])
def test_bond_pass_in_blocks_is_the_one_pass(rule):
    """:func:`bond.bond_forces_breaking` over blocks of 50 bonds (the last block overlapping the one before) gives
    the one pass's forces, moments, intact mask, break modes and the ``extra`` law's per-bond values."""
    s = jaxbpm.generate.box(200, seed=1, materials={"E": 1e9, "nu": 0.25, "tensile_strength": 1e6,
                                                    "shear_strength": 1e6})
    m = build_model(s, breakage=True)
    params = default_params(s)
    nb = m.bonds.shape[0]
    assert nb % 50 != 0 and nb >= 100
    key = jax.random.PRNGKey(3)
    x = m.positions0 + 0.01 * float(np.mean(s.radii)) * jax.random.normal(key, m.positions0.shape)
    q = jax.vmap(lambda k: rotation.from_rotation_vector(0.01 * jax.random.normal(k, (3,))))(
        jax.random.split(key, m.n))
    intact = jnp.arange(nb) % 7 != 0
    # strengths at the median stresses of this state: about half the bonds break
    bf = bond.bond_forces(x, q, m.bonds, m.r0, m.stiffness(params))[2]
    sigma, tau, _ = bond.bond_stresses(bf.normal, bf.shear, bf.twist, bf.bend, m.strength(params))
    strength = m.strength(params)._replace(tensile=jnp.full(nb, jnp.median(sigma)),
                                           cohesion=jnp.full(nb, 1.5 * jnp.median(tau)))
    weight = jnp.linspace(1.0, 2.0, nb)

    def extra(i, j, d, take):
        w = take(weight)
        f = tuple(w * c for c in d)
        return f, tuple(0.5 * c for c in f), tuple(-c for c in f), (w * d[0] + (i - j).astype(w.dtype),)

    def run(block):
        return bond.bond_forces_breaking(x, q, m.bonds, m.r0, m.stiffness(params), intact, strength, rule, extra,
                                         block)

    f1, m1, bf, in1, mode1, aux1 = run(None)
    f2, m2, none, in2, mode2, aux2 = run(50)
    assert bf is not None and none is None
    assert 0.2 * nb < int(jnp.sum(mode1 > 0)) < 0.8 * nb  # bonds break in this evaluation
    np.testing.assert_allclose(f2, f1, rtol=0, atol=1e-12 * float(jnp.max(jnp.abs(f1))))
    np.testing.assert_allclose(m2, m1, rtol=0, atol=1e-12 * float(jnp.max(jnp.abs(m1))))
    np.testing.assert_array_equal(in2, in1)
    np.testing.assert_array_equal(mode2, mode1)
    np.testing.assert_array_equal(aux2[0], aux1[0])


@pytest.mark.parametrize("block", [None, 50])
def test_extra_law_is_added_on_every_bond_whatever_its_state(block):
    """The ``extra`` law's forces and moments (scattered apart from the bond law's) are the bond pass's without
    ``extra`` plus their own sums per particle, on intact and broken bonds alike (summed in NumPy here)."""
    s = jaxbpm.generate.box(200, seed=2, materials={"E": 1e9, "nu": 0.25, "tensile_strength": 1e6,
                                                    "shear_strength": 1e6})
    m = build_model(s, breakage=True)
    params = default_params(s)
    nb, n = m.bonds.shape[0], m.n
    key = jax.random.PRNGKey(5)
    x = m.positions0 + 0.01 * float(np.mean(s.radii)) * jax.random.normal(key, m.positions0.shape)
    q = jax.vmap(lambda k: rotation.from_rotation_vector(0.01 * jax.random.normal(k, (3,))))(
        jax.random.split(key, n))
    intact = jnp.arange(nb) % 5 != 0
    weight = jnp.linspace(1.0, 3.0, nb)

    def extra(i, j, d, take):
        w = take(weight)
        f = tuple(w * c for c in d)
        return f, tuple(0.25 * c for c in f), tuple(-0.5 * c for c in f[::-1]), ()

    def run(law):
        return bond.bond_forces_breaking(x, q, m.bonds, m.r0, m.stiffness(params), intact, m.strength(params),
                                         "separate", law, block)

    f0, m0, *_ = run(None)
    f1, m1, _, in1, mode1, _ = run(extra)
    b = np.asarray(m.bonds)
    d = np.asarray(x)[b[:, 1]] - np.asarray(x)[b[:, 0]]
    fe = np.asarray(weight)[:, None] * d
    force, moment = np.array(f0), np.array(m0)
    np.add.at(force, b[:, 0], fe)
    np.add.at(force, b[:, 1], -fe)
    np.add.at(moment, b[:, 0], 0.25 * fe)
    np.add.at(moment, b[:, 1], -0.5 * fe[:, ::-1])
    np.testing.assert_allclose(f1, force, rtol=0, atol=1e-12 * np.abs(force).max())
    np.testing.assert_allclose(m1, moment, rtol=0, atol=1e-12 * np.abs(moment).max())
    assert np.abs(f1 - f0).max() > 1e-3 * np.abs(f0).max()  # the extra forces are not negligible
    assert int(jnp.sum(~in1)) >= nb // 5  # broken bonds among them
