"""The static failure solver (sequentially linear analysis) against closed forms, the linear DSM's bond forces and the
DEM's failure rule."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm._compile import compile_clock
from jaxbpm.dsm.failure import critical_scales, failure_solve, StaticFailure
from jaxbpm.errors import OptionsError, SceneError
from jaxbpm.physics import bond as bond_mod
from jaxbpm.physics.model import build_model, default_params
from jaxbpm.scenes import UniaxialCompression

E, SIGMA_C, TAU_C = 1e9, 4e6, 8e6


@pytest.fixture(scope="module")
def rock():
    materials = {"E": E, "nu": 0.2, "tensile_strength": SIGMA_C, "shear_strength": TAU_C}
    return jaxbpm.generate.cylinder(150, seed=3, materials=materials).largest_cluster()


def test_first_event_is_where_the_linear_dsms_most_utilised_bond_reaches_its_strength(rock):
    scene = UniaxialCompression(strain=1e-6)
    dsm = jaxbpm.solve(rock, scene, "dsm", linear_tol=1e-11, stiffness_tol=None)
    bf = dsm.stats["bond_forces"]  # the bond law's forces at the DSM's solution (its own computation)
    s = build_model(rock, breakage=True).strength(default_params(rock))
    sigma, tau, _ = bond_mod.bond_stresses(bf.normal, bf.shear, bf.twist, bf.bend, s)
    utilisation = float(jnp.max(jnp.maximum(sigma / s.tensile, tau / s.cohesion)))
    res = failure_solve(rock, scene, options=StaticFailure(tol=1e-11, max_events=1))
    np.testing.assert_allclose(res.force[0], dsm.force[-1] / utilisation, rtol=1e-5)
    np.testing.assert_allclose(res.displacement[0], dsm.displacement[-1] / utilisation, rtol=1e-5)
    np.testing.assert_allclose(res.stiffness, dsm.stiffness, rtol=1e-6)
    worst = int(jnp.argmax(jnp.maximum(sigma / s.tensile, tau / s.cohesion)))
    assert res.critical_bond[0] == worst and res.broken[0] == 1 and res.events == 1


def _random_loads(nb, seed):
    rng = np.random.default_rng(seed)
    normal = rng.normal(0.0, 50.0, nb)
    shear = tuple(rng.normal(0.0, 30.0, nb) for _ in range(3))
    twist = rng.normal(0.0, 2e-3, nb)
    bend = tuple(rng.normal(0.0, 5e-3, nb) for _ in range(3))
    rb = np.full(nb, 2.5e-4)
    strength = bond_mod.BondStrength(
        tensile=jnp.asarray(rng.uniform(2e6, 6e6, nb)), cohesion=jnp.asarray(rng.uniform(4e6, 9e6, nb)),
        tan_phi=jnp.asarray(rng.uniform(0.0, 0.8, nb)), radius=jnp.asarray(rb), area=jnp.asarray(np.pi * rb**2),
        inertia=jnp.asarray(np.pi * rb**4 / 4), polar=jnp.asarray(np.pi * rb**4 / 2), moment_factor=0.7)
    return normal, shear, twist, bend, strength


@pytest.mark.parametrize("rule", ["separate", "summed", "max"])
def test_critical_scale_is_where_the_dems_failure_rule_breaks_the_bond(rule):
    normal, shear, twist, bend, strength = _random_loads(400, seed=1)
    scales = np.asarray(critical_scales(normal, shear, twist, bend, strength, rule))
    finite = np.isfinite(scales)
    assert finite.sum() > 300 and np.all(scales[finite] > 0)

    def breaks(factor):
        f = np.where(finite, scales, 1.0) * factor
        mode = bond_mod.bond_failure(f * normal, tuple(f * c for c in shear), f * twist, tuple(f * c for c in bend),
                                     strength, rule)[0]
        return np.asarray(mode) > 0

    assert not breaks(1 - 1e-7)[finite].any()  # intact just below the scale, broken just above
    assert breaks(1 + 1e-7)[finite].all()
    # where no scale breaks the bond, a thousand times the others' scales does not either
    big = np.nanmax(scales[finite]) * 1e3
    mode = bond_mod.bond_failure(big * normal, tuple(big * c for c in shear), big * twist,
                                 tuple(big * c for c in bend), strength, rule)[0]
    assert not np.asarray(mode)[~finite].any()


def _chain(radii):
    """Spheres in a row along x, each bonded to the next (bond radius half the smaller sphere's)."""
    radii = np.asarray(radii, float)
    x = np.concatenate([[0.0], np.cumsum(radii[:-1] + radii[1:])])
    pos = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    bonds = [[k, k + 1] for k in range(len(radii) - 1)]
    return jaxbpm.Sample.from_arrays(pos, radii, bonds, bond_radius_ratio=0.5,
                                     materials={"E": E, "nu": 0.25, "tensile_strength": SIGMA_C,
                                                "shear_strength": TAU_C})


def test_a_series_chain_breaks_its_weakest_bond_and_the_load_drops_to_zero():
    radii = [1.0e-3, 0.9e-3, 1.1e-3, 0.7e-3, 1.0e-3, 1.2e-3]
    chain = _chain(radii)
    n = len(radii)
    # the first sphere driven (moved against x, away from the others), the last one held: the chain is pulled
    driven, fixed = np.zeros(n, bool), np.zeros(n, bool)
    driven[0], fixed[-1] = True, True
    # (the driven end lies below the held one: the gauge length and area are given)
    scene = UniaxialCompression(axis=0, fixed=fixed, driven=driven, strain=1e-4, gauge_length=0.01, area=1e-6)
    res = failure_solve(chain, scene, options=StaticFailure(tol=1e-12, preconditioner="jacobi"))
    r = np.asarray(radii)
    rb = 0.5 * np.minimum(r[:-1], r[1:])
    area, length = np.pi * rb**2, r[:-1] + r[1:]
    weakest = int(np.argmin(area))
    peak = SIGMA_C * area[weakest]  # one force through the chain: the smallest section reaches sigma_c first
    np.testing.assert_allclose(res.peak_force, peak, rtol=1e-8)
    np.testing.assert_allclose(res.peak_displacement, peak * np.sum(length / (E * area)), rtol=1e-8)
    assert res.critical_bond.tolist() == [weakest] and res.broken.tolist() == [1]
    assert res.status == "split" and res.events == 1  # no bond carries load afterwards


def test_removing_bonds_compiles_nothing_new(rock):
    scene = UniaxialCompression(strain=1e-3)
    options = StaticFailure(max_events=9, chunk=4, stop_fraction=0.01)
    params = {**default_params(rock), "bond_tensile_strength": jnp.array([SIGMA_C])}
    first = failure_solve(rock, scene, params, options)
    assert first.events == 9 and first.stats["calls"] == 3 and first.broken.sum() >= 9
    weaker = {**params, "bond_tensile_strength": jnp.array([0.5 * SIGMA_C])}
    with compile_clock() as clock:
        again = failure_solve(rock, scene, weaker, options)
    assert clock.count == 0 and again.compile_time == 0
    assert again.events == 9 and again.peak_force < first.peak_force
    # half the tensile strength, fewer bonds reach shear: the first event, a tensile one, halves exactly
    if again.critical_bond[0] == first.critical_bond[0]:
        np.testing.assert_allclose(again.force[0], 0.5 * first.force[0], rtol=1e-6)


def test_bonds_within_group_tol_break_in_one_event():
    # two equal chains side by side between the same clamped ends, each with a thinner middle bond: those two
    # reach their strength together
    a = _chain([1e-3] * 4)
    pos = np.concatenate([np.asarray(a.positions), np.asarray(a.positions) + [0, 0, 4e-3]])
    bonds = [[0, 1], [1, 2], [2, 3], [4, 5], [5, 6], [6, 7]]
    twin = jaxbpm.Sample.from_arrays(pos, 1e-3, bonds, bond_radius=[5e-4, 4e-4, 5e-4] * 2, materials=dict(
        E=E, nu=0.25, tensile_strength=SIGMA_C, shear_strength=TAU_C))
    driven, fixed = np.zeros(8, bool), np.zeros(8, bool)
    driven[[0, 4]], fixed[[3, 7]] = True, True
    scene = UniaxialCompression(axis=0, fixed=fixed, driven=driven, strain=1e-4, gauge_length=0.01, area=1e-6)
    res = failure_solve(twin, scene, options=StaticFailure(group_tol=1e-6, tol=1e-12, preconditioner="jacobi"))
    assert res.broken[0] == 2 and res.events == 1 and res.status == "split"  # one bond in each chain
    np.testing.assert_allclose(res.peak_force, 2 * SIGMA_C * np.pi * 4e-4**2, rtol=1e-8)


def test_bad_input_is_a_named_error(rock):
    with pytest.raises(SceneError, match="walls"):
        failure_solve(rock, UniaxialCompression(boundary="walls"))
    unbreakable = rock.replace(materials=dataclasses.replace(
        rock.materials, tensile_strength=np.array([np.inf]), shear_strength=np.array([np.inf])))
    with pytest.raises(SceneError, match="never break"):
        failure_solve(unbreakable, UniaxialCompression())
    with pytest.raises(OptionsError, match="StaticFailure"):
        failure_solve(rock, UniaxialCompression(), options=jaxbpm.DSM())
    with pytest.raises(OptionsError, match="stop_fraction"):
        StaticFailure(stop_fraction=0.0)
    with pytest.raises(OptionsError, match="group_tol"):
        StaticFailure(group_tol=1.5)
    with pytest.raises(OptionsError, match="max_evnts"):
        StaticFailure(max_evnts=3)
    with pytest.raises(ValueError, match="failure rule"):
        critical_scales(0.0, (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), None, "lammps")
