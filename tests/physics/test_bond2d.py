"""The 2D bond law (jaxbpm.physics.bond2d) against PFC2D's parallel bond in closed form: the pair stiffness, rigid
motions, momentum balance, the breakage loads of PFC's rule, and its derivatives against finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from jaxbpm.physics import bond, bond2d, tangent
from jaxbpm.physics.model import build_model, default_params
from jaxbpm.sample import Sample

E, NU, RB, T, L = 2e9, 0.2, 0.4e-3, 0.5, 2e-3
A, I = 2 * RB * T, (2 * RB) ** 3 * T / 12


def _k():
    return bond.stiffness(E, NU, A, I, 1.0, L)


def _pair_stiffness_closed_form(kn, kt, kb, h):
    """PFC2D's parallel bond between two discs along x, DOF (u_xi, u_yi, theta_i, u_xj, u_yj, theta_j): axial k_n;
    shear k_t on delta = u_yj - u_yi - h (theta_i + theta_j); moment on each disc h F_s -+ k_b (theta_j - theta_i)."""
    K = np.zeros((6, 6))
    K[np.ix_([0, 3], [0, 3])] = kn * np.array([[1, -1], [-1, 1]])
    s = np.array([0, -1, -h, 0, 1, -h])  # delta = s . u
    f_yi = kt * s  # the shear force on i (positive y) per DOF
    m = np.array([0, 0, -1, 0, 0, 1])  # theta_j - theta_i
    # rows: minus the force/moment on each DOF
    K[1] -= f_yi
    K[4] += f_yi
    K[2] -= h * f_yi + kb * m
    K[5] -= h * f_yi - kb * m
    return K


@pytest.mark.parametrize("angle", [0.0, 0.7, 2.5])
def test_pair_stiffness_is_pfc2d_parallel_bond(angle):
    k = _k()
    c, s = np.cos(angle), np.sin(angle)
    r0 = jnp.array([[L * c, L * s]])
    K = np.asarray(tangent.bond_full(r0, bond.BondStiffness(*(jnp.array([v]) for v in k)), rotations=True)[0])
    R = np.eye(6)
    R[np.ix_([0, 1], [0, 1])] = R[np.ix_([3, 4], [3, 4])] = [[c, -s], [s, c]]
    expected = R @ _pair_stiffness_closed_form(k.kn, k.kt, k.kb, L / 2) @ R.T
    scale = np.abs(expected).max()
    assert np.abs(K - expected).max() < 1e-12 * scale
    assert np.abs(K - K.T).max() < 1e-12 * scale
    # translations only: the 2 x 2 blocks of k_n along the axis and k_t across it
    K2 = np.asarray(tangent.bond_full(r0, bond.BondStiffness(*(jnp.array([v]) for v in k)), rotations=False)[0])
    assert np.abs(K2 - expected[np.ix_([0, 1, 3, 4], [0, 1, 3, 4])]).max() < 1e-12 * scale


def test_rigid_motion_gives_no_force_and_momentum_balances():
    k = _k()
    r0 = (L * 0.8, L * 0.6)
    turn = 0.9
    d = bond2d.rotate(turn, r0)
    f_i, m_i, m_j, *_ = bond2d.law_components(d, r0, turn, turn, k.kn, k.kt, k.kb)
    assert max(abs(float(v)) for v in f_i + m_i + m_j) < 1e-9 * k.kn * 1e-9
    # finite deformation: f_j = -f_i and the moments about disc i sum to zero
    d = (r0[0] + 3e-5, r0[1] - 2e-5)
    f_i, m_i, m_j, *_ = bond2d.law_components(d, r0, 0.01, -0.02, k.kn, k.kt, k.kb)
    torque = d[0] * -f_i[1] - d[1] * -f_i[0] + m_i[0] + m_j[0]
    assert abs(float(torque)) < 1e-12 * k.kn * 1e-5 * L


def test_derivatives_match_finite_differences():
    jax.config.update("jax_enable_x64", True)
    k = _k()
    r0 = jnp.array([L * 0.8, L * 0.6])

    def law(z, kn, kt, kb):
        f_i, m_i, m_j, normal, *_ = bond2d.law_components((r0[0] + z[0], r0[1] + z[1]), tuple(r0), z[2], z[3],
                                                          kn, kt, kb)
        return jnp.stack(f_i + m_i + m_j + (normal,))

    z = jnp.array([2e-5, -1e-5, 0.02, -0.01])
    check_grads(lambda z: law(z, k.kn, k.kt, k.kb), (z,), order=2, modes=("fwd", "rev"), eps=1e-7)
    check_grads(lambda e: law(z, e * k.kn, e * k.kt, e * k.kb), (jnp.array(1.0),), order=1, eps=1e-4)


def _two_discs(**materials):
    pos = np.array([[0.0, 0.0], [L, 0.0]])
    s = Sample.from_arrays(pos, L / 2, [[0, 1]], bond_radius=RB, thickness=T,
                           materials={"E": E, "nu": NU, **materials})
    return s, build_model(s, breakage=True)


def _load(model, s, u_j, theta_i=0.0, theta_j=0.0):
    x = model.positions0 + jnp.array([[0.0, 0.0], u_j])
    q = jnp.array([[theta_i], [theta_j]])
    return model.forces(x, q, default_params(s))[2]


def test_breakage_loads_are_pfc_rule():
    sigma_c, tau_c = 5e6, 8e6
    s, model = _two_discs(tensile_strength=sigma_c, shear_strength=tau_c)
    k = _k()
    # tension: F_n = sigma_c A
    stretch = sigma_c * A / k.kn
    assert bool(_load(model, s, [0.999 * stretch, 0.0])["intact"][0])
    parts = _load(model, s, [1.001 * stretch, 0.0])
    assert not bool(parts["intact"][0]) and int(parts["broken"][0]) == bond.TENSILE
    # bending alone: |M| R_b / I = sigma_c (a relative rotation of the two discs in opposite senses)
    theta = sigma_c * I / RB / k.kb / 2
    assert bool(_load(model, s, [0.0, 0.0], -0.999 * theta, 0.999 * theta)["intact"][0])
    assert int(_load(model, s, [0.0, 0.0], -1.001 * theta, 1.001 * theta)["broken"][0]) == bond.TENSILE
    # shear alone: |F_s| / A = tau_c (disc j moved across the bond, no rotation: no bending moment)
    slide = tau_c * A / k.kt
    parts = _load(model, s, [0.0, 1.001 * slide])
    assert int(parts["broken"][0]) == bond.SHEAR
    parts = _load(model, s, [0.0, 0.999 * slide])
    shear = float(jnp.linalg.norm(parts["bonds"].shear[0]))
    # (the axis turns by slide / L ~ 1e-2: the shear is k_t slide to second order in that angle)
    assert bool(parts["intact"][0]) and np.isclose(shear, 0.999 * slide * k.kt, rtol=1e-4)


def test_tension_and_bending_add_up():
    sigma_c = 5e6
    s, model = _two_discs(tensile_strength=sigma_c)
    k = _k()
    stretch = 0.5 * sigma_c * A / k.kn  # half the strength from tension ...
    theta = 0.5 * sigma_c * I / RB / k.kb / 2  # ... and half from bending
    assert bool(_load(model, s, [0.99 * stretch, 0.0], -0.99 * theta, 0.99 * theta)["intact"][0])
    assert not bool(_load(model, s, [1.01 * stretch, 0.0], -1.01 * theta, 1.01 * theta)["intact"][0])


def test_blocked_pass_is_the_one_pass():
    from jaxbpm.generate import lattice

    s = lattice("hex", (12, 10), 1e-3, materials={"E": 1e9, "tensile_strength": 3e5, "shear_strength": 3e5})
    model = build_model(s, breakage=True)
    key = jax.random.PRNGKey(0)
    x = model.positions0 + 2e-6 * jax.random.normal(key, model.positions0.shape)
    q = 1e-3 * jax.random.normal(jax.random.PRNGKey(1), (model.n, 1))
    k, st = model.stiffness(default_params(s)), model.strength(default_params(s))
    one = bond.bond_forces_breaking(x, q, model.bonds, model.r0, k, None, st)
    blocks = bond.bond_forces_breaking(x, q, model.bonds, model.r0, k, None, st, block=64)
    assert one[0].shape == (model.n, 2) and one[1].shape == (model.n, 1)
    for a, b in zip(one[:2], blocks[:2]):
        assert np.allclose(a, b, rtol=1e-12, atol=1e-12 * float(jnp.abs(a).max()))
    assert np.array_equal(one[3], blocks[3]) and 0 < int(jnp.sum(one[4] > 0)) < s.n_bonds


@pytest.mark.parametrize("block", [None, 64])
def test_bond_pass_sums_the_law_of_each_intact_bond(block):
    """The pass (one sine and cosine per disc, the broken bonds' rows masked once) gives, at large rotations and with
    some bonds broken, the sums of the per-bond law evaluated one bond at a time with its own sines and cosines."""
    from jaxbpm.generate import lattice

    s = lattice("hex", (12, 10), 1e-3, materials={"E": 1e9})
    model = build_model(s)
    x = model.positions0 + 2e-5 * jax.random.normal(jax.random.PRNGKey(0), model.positions0.shape)
    q = 0.8 * jax.random.normal(jax.random.PRNGKey(1), (model.n, 1))
    intact = jax.random.uniform(jax.random.PRNGKey(2), (s.n_bonds,)) > 0.3
    k = model.stiffness(default_params(s))
    force, moment, *_ = bond.bond_forces_breaking(x, q, model.bonds, model.r0, k, intact, None, block=block)
    want_f, want_m = np.zeros((model.n, 2)), np.zeros((model.n, 1))
    xs, qs, b, r0 = np.asarray(x), np.asarray(q), np.asarray(model.bonds), np.asarray(model.r0)
    for c in np.flatnonzero(np.asarray(intact)):
        i, j = b[c]
        f_i, m_i, m_j, *_ = bond2d.law_components(tuple(xs[j] - xs[i]), tuple(r0[c]), qs[i, 0], qs[j, 0],
                                                  k.kn[c], k.kt[c], k.kb[c])
        want_f[i] += np.asarray(f_i)
        want_f[j] -= np.asarray(f_i)
        want_m[i] += float(m_i[0])
        want_m[j] += float(m_j[0])
    assert 0.5 < float(jnp.mean(intact)) < 0.9
    np.testing.assert_allclose(force, want_f, rtol=1e-12, atol=1e-12 * np.abs(want_f).max())
    np.testing.assert_allclose(moment, want_m, rtol=1e-12, atol=1e-12 * np.abs(want_m).max())


def test_cos_sin_is_the_cosine_and_sine():
    jax.config.update("jax_enable_x64", True)
    rng = np.random.default_rng(0)
    quarters = np.arange(-400, 401) * np.pi / 4
    theta = np.concatenate([rng.uniform(-1e-6, 1e-6, 1000), rng.uniform(-4, 4, 20000), rng.uniform(-1e3, 1e3, 20000),
                            rng.uniform(-1e6, 1e6, 20000), quarters, quarters + 1e-9, quarters - 1e-13, [0.0]])
    c, s = (np.asarray(v) for v in bond2d.cos_sin(jnp.asarray(theta)))
    assert np.abs(c - np.cos(theta)).max() < 3e-16 and np.abs(s - np.sin(theta)).max() < 3e-16
    # near zero the sine keeps its relative precision; the unit circle to round-off
    small = np.abs(theta) < 1e-6
    assert np.all(np.abs(s[small] - np.sin(theta[small])) <= 2.3e-16 * np.abs(theta[small]))
    assert np.abs(c * c + s * s - 1).max() < 1e-15
    # derivatives (the DSM's tangents): d cos = -sin, d sin = cos
    dc, ds = jax.vmap(jax.grad(lambda t: bond2d.cos_sin(t)[0]))(jnp.asarray(theta[:2000])), jax.vmap(
        jax.grad(lambda t: bond2d.cos_sin(t)[1]))(jnp.asarray(theta[:2000]))
    assert np.abs(np.asarray(dc) + s[:2000]).max() < 1e-15 and np.abs(np.asarray(ds) - c[:2000]).max() < 1e-15
    # float32: jnp.cos and jnp.sin themselves
    c32, s32 = bond2d.cos_sin(jnp.asarray(theta[:5000], jnp.float32))
    assert c32.dtype == jnp.float32 and np.array_equal(c32, jnp.cos(jnp.asarray(theta[:5000], jnp.float32)))


def test_law_is_the_kinematics_of_the_module_docstring():
    """The law, as the pass and the one-bond API run it, against the docstring's formulas transcribed in NumPy
    (n = d / |d|, the half-vectors turned by NumPy's cos and sin), at large and small rotations and deformations."""
    jax.config.update("jax_enable_x64", True)
    rng = np.random.default_rng(3)
    m = 500
    phi = rng.uniform(-np.pi, np.pi, m)
    r0 = L * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    theta = np.concatenate([rng.normal(0, 1e-4, (m // 2, 2)), rng.uniform(-7, 7, (m - m // 2, 2))])
    common = rng.uniform(-3, 3, m)  # a rigid turn of the pair, plus a deformation of 1e-6 to 1e-2 of L
    c, s = np.cos(common), np.sin(common)
    d = np.stack([c * r0[:, 0] - s * r0[:, 1], s * r0[:, 0] + c * r0[:, 1]], axis=1)
    d += L * 10.0 ** rng.uniform(-6, -2, (m, 1)) * rng.normal(size=(m, 2))
    kn, kt, kb = (np.full(m, v) * rng.uniform(0.5, 2, m) for v in _k()[:2] + (_k().kb,))

    def turned(t, v):
        return np.stack([np.cos(t) * v[:, 0] - np.sin(t) * v[:, 1], np.sin(t) * v[:, 0] + np.cos(t) * v[:, 1]], 1)

    length = np.linalg.norm(d, axis=1)
    n = d / length[:, None]
    t = np.stack([-n[:, 1], n[:, 0]], axis=1)
    delta = d - turned(theta[:, 0], r0 / 2) - turned(theta[:, 1], r0 / 2)
    shear = (kt * np.sum(delta * t, axis=1))[:, None] * t
    normal = kn * (length - np.linalg.norm(r0, axis=1))
    bend = kb * (theta[:, 1] - theta[:, 0])
    lever = 0.5 * (d[:, 0] * shear[:, 1] - d[:, 1] * shear[:, 0])
    f_i = normal[:, None] * n + shear
    f, m_i, m_j, nrm, sh, _, bd = bond2d.law_components(tuple(jnp.asarray(d.T)), tuple(jnp.asarray(r0.T)),
                                                       jnp.asarray(theta[:, 0]), jnp.asarray(theta[:, 1]),
                                                       *(jnp.asarray(v) for v in (kn, kt, kb)))
    scale_f = kn * L * 1e-6 + np.abs(normal) + np.linalg.norm(shear, axis=1)  # forces, to round-off of their size
    np.testing.assert_array_less(np.abs(np.stack(f, 1) - f_i).max(axis=1), 1e-11 * scale_f)
    np.testing.assert_array_less(np.abs(np.stack(sh, 1) - shear).max(axis=1), 1e-11 * scale_f)
    np.testing.assert_array_less(np.abs(np.asarray(nrm) - normal), 1e-11 * scale_f)
    scale_m = L * scale_f + np.abs(bend)
    np.testing.assert_array_less(np.abs(np.asarray(m_i[0]) - (lever + bend)), 1e-11 * scale_m)
    np.testing.assert_array_less(np.abs(np.asarray(m_j[0]) - (lever - bend)), 1e-11 * scale_m)
    assert np.array_equal(np.asarray(bd[0]), bend)
