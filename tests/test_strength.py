"""Bond breakage (tensile, shear, Mohr-Coulomb) and compression to failure."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import SceneError, dem
from jaxbpm.physics import bond as bond_mod
from jaxbpm.physics.model import build_model, default_params
from jaxbpm.scenes import ThreePointBending, UniaxialCompression

# one worker for the whole module under pytest-xdist (loadgroup): its specimens (module fixtures) are built once
pytestmark = pytest.mark.xdist_group("strength-module")

R = 1e-3
A = np.pi * (0.5 * R) ** 2
KN = 1e9 * A / (2 * R)
KT = KN / (2 * 1.25)


def _pair(tensile, shear):
    return jaxbpm.Sample.from_arrays([[0, 0, 0], [2 * R, 0, 0]], R, [[0, 1]], bond_radius_ratio=0.5,
                                     materials={"E": 1e9, "nu": 0.25, "tensile_strength": tensile,
                                                "shear_strength": shear})


def _pull(sample, direction, u_break, params=None, failure_rule="separate"):
    """Move particle 1 along ``direction`` at constant speed (2000 steps to the expected break), particle 0 fixed."""
    model = build_model(sample, breakage=True, failure_rule=failure_rule)
    v = 1e-3
    z = jnp.zeros((0, 3))
    load = dem.Loading(clamped=jnp.array([True, True]), velocity=jnp.array([[0.0, 0, 0], np.multiply(direction, v)]),
                       wall_points0=z, wall_normals=z, wall_velocity=z)
    dt = u_break / v / 2000
    state, rec, _ = dem.simulate(model, params or default_params(sample), load, dt=dt, n_steps=3000, chunk=500)
    return state, rec, dt * v  # displacement per step


def test_a_pulled_bond_breaks_at_its_tensile_strength():
    sigma_c = 5e6
    state, rec, du = _pull(_pair(sigma_c, np.inf), [1, 0, 0], sigma_c * A / KN)
    assert int(state.broken[0]) == bond_mod.TENSILE and not bool(state.intact[0])
    peak = np.abs(rec["reaction"][:, 0, 0]).max()
    np.testing.assert_allclose(peak, sigma_c * A, rtol=1e-3)  # within one step of the exact load
    np.testing.assert_allclose(float(state.broken_time[0]) * 1e-3, sigma_c * A / KN, rtol=1e-3)
    # after the break the bond carries nothing
    assert np.abs(rec["reaction"][-1]).max() == 0
    np.testing.assert_array_equal(rec["broken"][-1], [1, 0])


def test_a_sheared_bond_breaks_at_its_shear_strength():
    tau_c = 3e6
    state, rec, _ = _pull(_pair(np.inf, tau_c), [0, 1, 0], tau_c * A / KT)
    assert int(state.broken[0]) == bond_mod.SHEAR
    np.testing.assert_allclose(np.abs(rec["reaction"][:, 0, 1]).max(), tau_c * A, rtol=1e-3)
    np.testing.assert_array_equal(rec["broken"][-1], [0, 1])


def test_bending_and_twisting_count_at_the_rim():
    s = bond_mod.BondStrength(tensile=jnp.array(1e6), cohesion=jnp.array(1e6), tan_phi=jnp.array(0.0),
                              radius=jnp.array(0.5 * R), area=jnp.array(A),
                              inertia=jnp.array(np.pi * (0.5 * R) ** 4 / 4), polar=jnp.array(np.pi * (0.5 * R) ** 4 / 2))
    zero = (0.0, 0.0, 0.0)
    # a bending moment M gives sigma = M r / I at the rim; a twisting moment T gives tau = T r / J
    m = 0.9 * 1e6 * float(s.inertia) / float(s.radius)
    sigma, tau, _ = bond_mod.bond_stresses(0.0, zero, 0.0, (m, 0.0, 0.0), s)
    np.testing.assert_allclose([float(sigma), float(tau)], [0.9e6, 0.0], atol=1e-6)
    mode, *_ = bond_mod.bond_failure(0.1 * 1e6 * A * 1.01, zero, 0.0, (m, 0.0, 0.0), s)  # 0.9 + 0.101 > 1
    assert int(mode) == bond_mod.TENSILE
    t = 1e6 * float(s.polar) / float(s.radius)
    assert int(bond_mod.bond_failure(0.0, zero, 0.99 * t, zero, s)[0]) == 0
    assert int(bond_mod.bond_failure(0.0, zero, 1.01 * t, zero, s)[0]) == bond_mod.SHEAR


def test_mohr_coulomb_shear_strength_moves_with_normal_stress():
    c, phi = 3e6, np.deg2rad(30.0)
    s = bond_mod.BondStrength(tensile=jnp.array(np.inf), cohesion=jnp.array(c), tan_phi=jnp.array(np.tan(phi)),
                              radius=jnp.array(0.5 * R), area=jnp.array(A),
                              inertia=jnp.array(np.pi * (0.5 * R) ** 4 / 4), polar=jnp.array(np.pi * (0.5 * R) ** 4 / 2))
    for sigma_n in (-4e6, 0.0, 2e6):  # compression raises the shear strength, tension lowers it
        tau_c = c - sigma_n * np.tan(phi)
        below = bond_mod.bond_failure(sigma_n * A, (0.999 * tau_c * A, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), s)
        above = bond_mod.bond_failure(sigma_n * A, (1.001 * tau_c * A, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), s)
        assert int(below[0]) == 0 and int(above[0]) == bond_mod.SHEAR, sigma_n
        np.testing.assert_allclose(float(above[3]), tau_c)
    # the same through the DEM: a bond pre-stretched in tension breaks in shear at c - sigma_n tan(phi)
    sample = _pair(np.inf, c)
    params = {**default_params(sample), "bond_friction_angle": jnp.array([phi])}
    state, rec, _ = _pull(sample, [0.2, 1.0, 0.0], c * A / KT, params)
    assert int(state.broken[0]) == bond_mod.SHEAR
    k = int(np.argmax(rec["broken"][:, 1] > 0))
    fn, ft = rec["reaction"][k - 1, 0, 0], rec["reaction"][k - 1, 0, 1]  # forces on the moving particle
    # just before the break: |F_t| / A close to c - (F_n / A) tan(phi), F_n > 0 in tension (pulls back: -x)
    np.testing.assert_allclose(abs(ft) / A, c - (-fn / A) * np.tan(phi), rtol=5e-3)


def _section_strength(tensile, cohesion, tan_phi=0.0):
    rb = 0.5 * R
    return bond_mod.BondStrength(tensile=jnp.array(tensile), cohesion=jnp.array(cohesion), tan_phi=jnp.array(tan_phi),
                                 radius=jnp.array(rb), area=jnp.array(A), inertia=jnp.array(np.pi * rb**4 / 4),
                                 polar=jnp.array(np.pi * rb**4 / 2))


@pytest.mark.parametrize("u_n, u_b, u_s, u_t, separate, summed, most", [
    # utilisations (a load over its single-mode limit) -> the break mode under each rule (0 intact, 1 tensile, 2 shear)
    (0.6, 0.0, 0.5, 0.0, 0, 1, 0),     # tension and shear: only LAMMPS's sum reaches 1
    (0.0, 0.3, 0.0, 0.8, 0, 2, 0),     # bending and twist: summed, the larger part (shear) names the mode
    (0.55, 0.55, 0.0, 0.0, 1, 1, 0),   # tension and bending: added by "separate" and "summed", not by "max"
    (0.0, 0.0, 0.6, 0.6, 2, 2, 0),     # shear and twist: the same on the shear side
    (-0.5, 0.0, 1.2, 0.0, 2, 0, 2),    # a compressed bond carries more shear under the sum (u_n signed)
    (1.01, 0.0, 0.0, 0.0, 1, 1, 1),    # single-mode limits agree
    (0.0, 0.0, 0.0, 0.99, 0, 0, 0),
])
def test_failure_rules_combine_the_utilisations_as_their_codes_do(u_n, u_b, u_s, u_t, separate, summed, most):
    sigma_c, c = 4e6, 7e6
    s = _section_strength(sigma_c, c)
    rb, inertia, polar = float(s.radius), float(s.inertia), float(s.polar)
    normal = u_n * sigma_c * A
    shear = (0.0, u_s * c * A, 0.0)
    twist = u_t * c * polar / rb
    bend = (0.0, 0.0, u_b * sigma_c * inertia / rb)
    got = [int(bond_mod.bond_failure(normal, shear, twist, bend, s, rule)[0]) for rule in ("separate", "summed", "max")]
    assert got == [separate, summed, most]


def test_an_unknown_failure_rule_is_an_error_naming_the_rules():
    with pytest.raises(ValueError, match="'separate'.*'summed'.*'max'"):
        bond_mod.bond_failure(0.0, (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), _section_strength(1e6, 1e6), "lammps")
    with pytest.raises(ValueError, match="unknown bond failure rule 'lammps'"):
        build_model(_pair(1e6, 1e6), breakage=True, failure_rule="lammps")
    with pytest.raises(SceneError, match="failure_rule: unknown bond failure rule"):
        UniaxialCompression.to_failure(failure_rule="lammps")
    with pytest.raises(SceneError, match="failure_rule"):
        ThreePointBending(failure_rule="Summed")


def test_a_bond_pulled_in_tension_and_shear_breaks_where_its_rule_says():
    # pulled at 45 degrees: F_n = k_n u / sqrt(2), F_t = k_t u / sqrt(2) (no rotation: both particles clamped), with
    # tau_c chosen so that both utilisations grow alike: the separate checks break at u_1, LAMMPS's sum at u_1 / 2
    sigma_c = 5e6
    tau_c = sigma_c * KT / KN
    u_1 = np.sqrt(2.0) * sigma_c * A / KN
    at = {}
    for rule, expected in (("separate", u_1), ("max", u_1), ("summed", 0.5 * u_1)):
        state, rec, du = _pull(_pair(sigma_c, tau_c), [np.sqrt(0.5), np.sqrt(0.5), 0.0], u_1, failure_rule=rule)
        assert not bool(state.intact[0]), rule
        at[rule] = (int(np.argmax(rec["broken"].sum(axis=1) > 0)) + 1) * du  # the step that broke it
        np.testing.assert_allclose(at[rule], expected, rtol=5e-3, err_msg=rule)  # (the bond turns: 0.2 % early)
    assert at["max"] == at["separate"]
    np.testing.assert_allclose(at["summed"] / at["separate"], 0.5, rtol=4e-3)


@pytest.fixture(scope="module")
def rock():
    return jaxbpm.generate.cylinder(250, seed=0, materials={"E": 1e9, "nu": 0.25, "tensile_strength": 5e6,
                                                            "shear_strength": 5e6}).largest_cluster()


def _with_strengths(sample, tensile, shear):
    m = dataclasses.replace(sample.materials, tensile_strength=np.array([tensile]), shear_strength=np.array([shear]))
    return sample.replace(materials=m)


def test_compression_to_failure_peaks_and_drops(rock):
    res = jaxbpm.solve(rock, UniaxialCompression.to_failure(strain=0.02), "dem", transits=30)
    f = res.force
    peak = int(np.argmax(f))
    assert res.stats["breakage"] and res.stats["past_peak"]
    assert 0.1 * len(f) < peak < 0.9 * len(f)
    assert f[-1] < 0.8 * f[peak]  # a post-peak drop
    curve = res.stats["broken_curve"].sum(axis=1)
    assert np.all(np.diff(curve) >= 0) and curve[-1] > 5 * max(curve[peak // 2], 1)  # bonds break, mostly late
    np.testing.assert_allclose(res.stats["strength"], f[peak] / res.area)
    assert res.youngs_modulus > 0
    # the elastic modulus of the failure run agrees with an elastic run of the same model (contacts, no breakage);
    # the failure run strains ten times faster over the same 30 transits, which stiffens it by 4-5 % on such samples
    elastic = jaxbpm.solve(rock, UniaxialCompression(strain=0.002, contacts=True, breakage=False), "dem",
                           transits=30)
    assert abs(res.youngs_modulus / elastic.youngs_modulus - 1) < 0.06, (res.youngs_modulus, elastic.youngs_modulus)


def test_ucs_grows_with_the_shear_strength(rock):
    scene = UniaxialCompression.to_failure(strain=0.02)
    weak = jaxbpm.solve(_with_strengths(rock, 8e6, 2e6), scene, "dem", transits=30)
    strong = jaxbpm.solve(_with_strengths(rock, 8e6, 6e6), scene, "dem", transits=30)
    assert strong.stats["strength"] > 1.3 * weak.stats["strength"]
    assert weak.stats["broken_shear"] > weak.stats["broken_tensile"]


def test_elastic_solvers_do_not_break_bonds(rock):
    # a strength of 1 Pa would break every bond in a DEM step; the static solvers model the elastic range
    weak = _with_strengths(rock, 1.0, 1.0)
    a = jaxbpm.solve(weak, UniaxialCompression(strain=0.002), "dsm")
    b = jaxbpm.solve(rock, UniaxialCompression(strain=0.002), "dsm")
    np.testing.assert_allclose(a.stiffness, b.stiffness, rtol=1e-12)


def test_the_summed_rule_breaks_a_specimen_earlier_and_is_reported(rock):
    # LAMMPS's rule adds the shear utilisation to the tensile one: bonds break earlier under mixed loads, so the UCS
    # is lower (LAMMPS against jaxbpm's separate checks: 1.23-1.30x at 300-8000 particles, benchmarks/vs_lammps.py)
    runs = {rule: jaxbpm.solve(rock, UniaxialCompression.to_failure(strain=0.02, failure_rule=rule), "dem",
                               transits=30) for rule in ("separate", "summed")}
    assert [r.stats["failure_rule"] for r in runs.values()] == ["separate", "summed"]
    ratio = runs["separate"].stats["strength"] / runs["summed"].stats["strength"]
    assert 1.1 < ratio < 1.6, ratio
    # the elastic part is the same
    np.testing.assert_allclose(runs["summed"].stiffness, runs["separate"].stiffness, rtol=1e-6)


def test_the_moment_factor_scales_the_moments_in_the_rim_stresses():
    # PFC's pb_mcf: sigma = F_n / A + beta |M_b| r_b / I; pure bending breaks at 1 / beta times the moment
    s = _section_strength(1e6, 1e6)._replace(moment_factor=jnp.array(0.5))
    limit = 1e6 * float(s.inertia) / float(s.radius)
    zero = (0.0, 0.0, 0.0)
    for rule in ("separate", "summed", "max"):
        assert int(bond_mod.bond_failure(0.0, zero, 0.0, (1.99 * limit, 0.0, 0.0), s, rule)[0]) == 0, rule
        assert int(bond_mod.bond_failure(0.0, zero, 0.0, (2.01 * limit, 0.0, 0.0), s, rule)[0]) == bond_mod.TENSILE
    twist_limit = 1e6 * float(s.polar) / float(s.radius)
    assert int(bond_mod.bond_failure(0.0, zero, 1.99 * twist_limit, zero, s)[0]) == 0
    assert int(bond_mod.bond_failure(0.0, zero, 2.01 * twist_limit, zero, s)[0]) == bond_mod.SHEAR
    # forces are not scaled
    assert int(bond_mod.bond_failure(1.01e6 * A, zero, 0.0, zero, s)[0]) == bond_mod.TENSILE
    # through the params, checked
    sample = _pair(1e6, 1e6)
    model = build_model(sample, breakage=True)
    strength = model.strength({**default_params(sample), "bond_moment_factor": jnp.array([0.25])})
    np.testing.assert_allclose(np.asarray(strength.moment_factor), [0.25])
    from jaxbpm.physics.model import check_params

    with pytest.raises(SceneError, match="bond_moment_factor"):
        check_params({**default_params(sample), "bond_moment_factor": [1.5]}, sample)
