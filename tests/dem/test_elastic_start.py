"""The DSM-started DEM (``DEM(start="elastic")``): the first-break scale against closed forms and against a DEM run
from rest, the start state in balance under the DEM's own forces, the peak and the modulus against the run from rest,
the elastic segment of the records, the fallback to rest, the options, and a second solve compiling nothing."""

import dataclasses
import warnings

import numpy as np
import pytest

import jaxbpm
from jaxbpm.dem.elastic_start import break_scales, elastic_start, IMBALANCE
from jaxbpm.dem.plan import plan
from jaxbpm.elastic_field import dsm_field
from jaxbpm.errors import OptionsError
from jaxbpm.physics import bond as bond_mod
from jaxbpm.physics.model import build_model, default_params
from jaxbpm.scenes import UniaxialCompression

ROCK = {"E": 1e9, "nu": 0.2, "tensile_strength": 4e6, "shear_strength": 8e6}
SCENE = UniaxialCompression.to_failure(strain=0.02, contacts=False, stop_after_peak=None)  # whole curves compared
TRANSITS = 80


@pytest.fixture(scope="module")
def rock():
    return jaxbpm.generate.cylinder(300, seed=0, materials=ROCK).largest_cluster()


@pytest.fixture(scope="module")
def runs(rock):
    """The same failure run from rest and from the DSM's elastic state."""
    rest = jaxbpm.solve(rock, SCENE, "dem", transits=TRANSITS)
    elastic = jaxbpm.solve(rock, SCENE, "dem", transits=TRANSITS, start="elastic")
    return rest, elastic


def _forces(nb, seed):
    rng = np.random.default_rng(seed)
    return bond_mod.BondForces(f_i=None, m_i=None, m_j=None, normal=rng.normal(size=nb) * 10.0,
                               shear=rng.normal(size=(nb, 3)) * 5.0, twist=rng.normal(size=nb) * 1e-3,
                               bend=rng.normal(size=(nb, 3)) * 1e-3)


def _strength(nb, tan_phi=0.0):
    r = np.full(nb, 1e-3)
    area, inertia = np.pi * r**2, np.pi * r**4 / 4
    return bond_mod.BondStrength(tensile=np.full(nb, 4e6), cohesion=np.full(nb, 8e6), tan_phi=np.full(nb, tan_phi),
                                 radius=r, area=area, inertia=inertia, polar=2 * inertia)


def test_break_scales_are_the_closed_forms_of_the_failure_rules():
    f, s = _forces(200, 0), _strength(200)
    sigma = f.normal / s.area + np.linalg.norm(f.bend, axis=1) * s.radius / s.inertia
    tau = np.linalg.norm(f.shear, axis=1) / s.area + np.abs(f.twist) * s.radius / s.polar
    tensile = np.where(sigma > 0, s.tensile / np.where(sigma > 0, sigma, 1.0), np.inf)
    shear = s.cohesion / tau
    np.testing.assert_allclose(break_scales(f, s, "separate"), np.minimum(tensile, shear), rtol=1e-9)
    # summed: s sigma / sigma_c + s tau / tau_c = 1 (tan phi = 0), where the tensile part is positive
    summed = 1.0 / (sigma / s.tensile + tau / s.cohesion)
    got = np.asarray(break_scales(f, s, "summed"))
    np.testing.assert_allclose(got[sigma > 0], summed[sigma > 0], rtol=1e-9)
    # max: the first of the four single-mode limits
    u = np.stack([f.normal / s.area / s.tensile, (sigma - f.normal / s.area) / s.tensile,
                  np.linalg.norm(f.shear, axis=1) / s.area / s.cohesion,
                  (tau - np.linalg.norm(f.shear, axis=1) / s.area) / s.cohesion])
    np.testing.assert_allclose(break_scales(f, s, "max"), 1.0 / np.max(u, axis=0), rtol=1e-9)


def test_break_scales_follow_the_mohr_coulomb_shear_strength():
    # tau_c = c - s sigma_n tan(phi): s tau = c - s sigma_n tan(phi) -> s = c / (tau + sigma_n tan(phi))
    f = _forces(100, 1)
    f = f._replace(normal=-np.abs(f.normal) * 1e3, bend=0 * f.bend)  # compressed: never tensile
    s = _strength(100, tan_phi=0.5)
    tau = np.linalg.norm(f.shear, axis=1) / s.area + np.abs(f.twist) * s.radius / s.polar
    expected = s.cohesion / (tau + f.normal / s.area * s.tan_phi)
    np.testing.assert_allclose(break_scales(f, s, "separate"), np.where(expected > 0, expected, np.inf), rtol=1e-9)


def test_the_start_is_where_the_dsm_puts_it_and_in_balance(rock):
    params = default_params(rock)
    the_plan = plan(rock, SCENE, params, transits=TRANSITS)
    start = elastic_start(rock, SCENE, params, the_plan, dsm_field)
    info = start.stats["elastic_start"]
    assert start.steps_done % the_plan.chunk == 0 and start.steps_done > 0
    assert info["scale"] == pytest.approx(start.steps_done / the_plan.n_steps)
    assert info["scale"] <= 0.9 * info["first_break_scale"] + 1e-12
    n, state = rock.n_particles, start.state
    # the clamped particles where the loading puts them at that time; the others at the DSM's field
    load = the_plan.load
    clamped = np.asarray(load.clamped)[:n]
    x0 = np.asarray(rock.positions)
    t = start.steps_done * the_plan.dt
    np.testing.assert_allclose(np.asarray(state.positions)[:n][clamped],
                               (x0 + t * np.asarray(load.velocity)[:n])[clamped], rtol=0, atol=1e-15)
    assert float(state.time) == pytest.approx(t)
    dsm = jaxbpm.solve(rock, dataclasses.replace(SCENE, breakage=False), "dsm")
    u = info["scale"] * np.asarray(dsm.state)[:n, :3]
    np.testing.assert_allclose(np.asarray(state.positions)[:n] - x0, u, atol=1e-6 * np.abs(u).max())
    # the DEM's own forces there: the free particles' net force is small against the bonds' (DSM and DEM agree)
    force = np.asarray(state.force)[:n][~clamped]
    model = build_model(rock)
    per_bond = bond_mod.bond_forces(state.positions[:n], state.orientations[:n], model.bonds, model.r0,
                                    model.stiffness(params))[2]
    mean_bond = float(np.mean(np.linalg.norm(np.asarray(per_bond.f_i), axis=1)))
    assert np.sqrt(np.mean(np.sum(force**2, axis=1))) < 0.03 * mean_bond
    assert info["imbalance"] < 0.03
    # the velocities are the loading's quasi-static field: the DSM's field per unit displacement x the speed
    v = np.asarray(state.velocities)[:n][~clamped]
    np.testing.assert_allclose(v, (the_plan.speed / info["displacement"]) * u[~clamped],
                               atol=1e-6 * the_plan.speed)


def test_the_first_break_is_where_the_run_from_rest_breaks_its_first_bond(runs):
    rest, elastic = runs
    first = float(np.nanmin(np.asarray(rest.state.broken_time))) / rest.stats["loading_time"]
    assert elastic.stats["elastic_start"]["first_break_scale"] == pytest.approx(first, rel=0.03)


def test_the_modulus_agrees_with_the_run_from_rest(runs):
    rest, elastic = runs
    assert elastic.youngs_modulus == pytest.approx(rest.youngs_modulus, rel=0.01)
    # fewer DEM steps: those of the elastic segment are the DSM's
    assert elastic.stats["steps"] + elastic.stats["elastic_segment"] == rest.stats["steps"]


def test_the_peak_agrees_with_the_runs_from_rest_within_their_scatter(rock, runs):
    # a small sample's peak is an avalanche of a few bonds: a slightly other loading rate moves it by a few per cent.
    # Over four rates the mean peak of the elastic starts lies within the spread of the runs from rest
    rates = (70, 90, 100)
    rest = [runs[0].stats["strength"]] + [jaxbpm.solve(rock, SCENE, "dem", transits=t).stats["strength"]
                                           for t in rates]
    elastic = [runs[1].stats["strength"]] + [
        jaxbpm.solve(rock, SCENE, "dem", transits=t, start="elastic").stats["strength"] for t in rates]
    spread = np.ptp(rest) / np.mean(rest)
    assert spread < 0.06
    assert abs(np.mean(elastic) / np.mean(rest) - 1) <= spread


def test_the_records_start_with_the_dsm_elastic_segment(rock, runs):
    rest, elastic = runs
    k, info = elastic.stats["elastic_segment"], elastic.stats["elastic_start"]
    assert k == info["steps_skipped"] > 0
    disp, force = elastic.displacement, elastic.force
    seg = disp <= info["displacement"] * (1 + 1e-9)
    assert seg.sum() >= 2
    # the segment is the DSM's straight line from zero: one secant stiffness along it
    np.testing.assert_allclose(force[seg] / disp[seg], force[seg][-1] / disp[seg][-1], rtol=1e-3)
    # and the DSM's stiffness (the DEM's reaction at the DSM's state over its displacement)
    dsm = jaxbpm.solve(rock, dataclasses.replace(SCENE, breakage=False), "dsm")
    assert force[seg][-1] / disp[seg][-1] == pytest.approx(dsm.stiffness, rel=0.01)
    assert len(disp) == len(rest.displacement)
    np.testing.assert_allclose(disp, rest.displacement, rtol=1e-12)


def test_a_second_solve_compiles_nothing(rock, runs):
    with jaxbpm.count_compilations() as c:
        again = jaxbpm.solve(rock, SCENE, "dem", transits=TRANSITS, start="elastic")
    assert c.count == 0
    assert again.stats["strength"] == pytest.approx(runs[1].stats["strength"], rel=1e-12)


@pytest.mark.parametrize("scene, reason", [
    (UniaxialCompression.to_failure(strain=0.02, contacts=False, boundary="walls"), "walls"),
    (UniaxialCompression(strain=0.02, breakage=False), "no bond breaks"),
])
def test_where_the_dsm_cannot_give_the_state_it_starts_from_rest(rock, scene, reason):
    params = default_params(rock)
    the_plan = plan(rock, scene, params, transits=TRANSITS)
    with jaxbpm.count_compilations() as c, pytest.warns(UserWarning, match=f"starting from rest: .*{reason}"):
        start = elastic_start(rock, scene, params, the_plan, dsm_field)
    assert c.count == 0  # refused before anything is solved
    assert start.state is None and start.steps_done == 0 and not start.records
    assert reason in start.stats["elastic_start"]["fallback"]


def test_with_walls_the_run_says_it_started_from_rest():
    s = jaxbpm.generate.lattice("sc", (2, 2, 4), 1e-3, materials=ROCK)
    scene = UniaxialCompression.to_failure(strain=0.005, contacts=False, boundary="walls")
    with pytest.warns(UserWarning, match="starting from rest: the scene loads by walls"):
        res = jaxbpm.solve(s, scene, "dem", transits=5, start="elastic")
    assert "walls" in res.stats["elastic_start"]["fallback"] and res.stats["elastic_segment"] == 0


def test_with_contacts_the_start_uses_the_linearised_dsm(rock):
    scene = UniaxialCompression.to_failure(strain=0.02)
    params = default_params(rock)
    the_plan = plan(rock, scene, params, transits=TRANSITS)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no fallback
        start = elastic_start(rock, scene, params, the_plan, dsm_field)
    info = start.stats["elastic_start"]
    assert info["dsm"] == "linearised contacts"
    assert 0 < info["contact_share"] < 0.5 and info["imbalance"] < IMBALANCE
    # the bonded pairs' contact springs: the contact points' relative tangential motion, in the tangent plane
    spring = np.asarray(start.state.bond_spring)
    assert np.any(spring != 0)
    b = np.asarray(rock.bonds)
    d = np.asarray(start.state.positions)[b[:, 1]] - np.asarray(start.state.positions)[b[:, 0]]
    np.testing.assert_allclose(np.sum(spring * d, axis=1), 0.0, atol=1e-9 * np.abs(spring).max() * np.abs(d).max())


@pytest.mark.parametrize("kw, match", [({"start": "elastc"}, "start must be 'rest' or 'elastic'"),
                                       ({"start": None}, "start must be"),
                                       ({"start_safety": 0.0}, "start_safety"),
                                       ({"start_safety": 1.5}, "start_safety")])
def test_bad_start_options_are_refused(kw, match):
    with pytest.raises(OptionsError, match=match):
        jaxbpm.DEM(**kw)
    assert jaxbpm.DEM(start="elastic", start_safety=0.95).start == "elastic"


def test_a_batch_refuses_the_elastic_start(rock):
    params = default_params(rock)
    with jaxbpm.count_compilations() as c, pytest.raises(jaxbpm.SceneError, match="starts its members from rest"):
        jaxbpm.dem.solve_batch(rock, SCENE, [params, params], start="elastic")
    assert c.count == 0


def test_the_dem_alone_asks_for_the_static_solve(rock):
    with pytest.raises(OptionsError, match="start='elastic' needs the static solve"):
        jaxbpm.dem.solve_scene(rock, SCENE, None, jaxbpm.DEM(start="elastic"))
