"""The surrogate's default parameter ranges: centred on the closed-form (or initial) estimate, widened where the runs
do not reach a target; explicit bounds kept, with an error naming the outputs the runs reached."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import calibrate as cal
from jaxbpm.calibrate import CalibrationError, Forward, Parameter, ParameterSpace, Problem, Target
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression

# one xdist worker for the module: `box` and `E_now` (~20 s to make) are built once, and the calibrations on `box`
# share their compiled run sets
pytestmark = pytest.mark.xdist_group("surrogate-ranges-module")

SCENE = UniaxialCompression(strain=1e-3)


@pytest.fixture(scope="module")
def box():
    return jaxbpm.generate.box(300, seed=0, mean_radius=1e-3, packing_fraction=0.5,
                               materials={"E": 1e9, "nu": 0.25}).largest_cluster()


@pytest.fixture(scope="module")
def E_now(box):
    return {m: float(jaxbpm.solve(box, SCENE, m).youngs_modulus) for m in ("ste", "dsm")}


def _solved(sample, res, solver="ste", scene=SCENE):
    return float(jaxbpm.solve(sample, scene, solver, params=res.params).youngs_modulus)


def _no_closed_form(sample, solver="ste"):
    """The forward with its closed form switched off: the ranges start at the initial values and must widen."""
    return dataclasses.replace(cal.forward_model(sample, SCENE, solver), homogeneous=False, _compiled={})


@pytest.mark.parametrize("f", [1.37, 0.5, 3.0])
def test_default_call_succeeds_off_the_current_modulus(box, E_now, f):
    """The issue's call, default settings: the ranges centre on the closed-form estimate (one solve)."""
    target = f * E_now["ste"]
    res = cal.calibrate(box, SCENE, {"youngs_modulus": target}, method="surrogate", solver="ste")
    assert res.converged and res.info["n_runs"] == 100 and res.evaluations == 101, res.notes
    (start,) = res.info["ranges"]  # no widening needed
    assert start["from"] == "the closed-form estimate" and start["reach"][0]["inside"]
    np.testing.assert_allclose(start["centre"], [f * 1e9], rtol=1e-6)
    np.testing.assert_allclose([start["lower"][0], start["upper"][0]], [f * 1e9 / 2, f * 1e9 * 2], rtol=1e-6)
    assert any("closed-form estimate" in n and "log space" in n for n in res.notes)
    assert abs(_solved(box, res) / target - 1) <= res.tol  # checked by an independent solve


def test_default_call_succeeds_on_the_default_dsm_model(box, E_now):
    target = 1.37 * E_now["dsm"]
    res = cal.calibrate(box, SCENE, {"youngs_modulus": target}, method="surrogate", verify=True)
    assert res.solver == "dsm" and res.converged and res.info["n_runs"] == 100
    assert abs(_solved(box, res, "dsm") / target - 1) <= res.tol
    assert res.max_error <= res.tol and res.history.rows[-1]["kind"] == "verify"


@pytest.mark.parametrize("f,widened", [(1.37, []), (0.5, [("bond_E", "lower")]), (3.0, [("bond_E", "upper")])])
def test_ranges_widen_towards_a_target_the_runs_do_not_reach(box, E_now, f, widened):
    """Without a closed form the ranges start at the initial value (x/2 .. 2x) and widen by 4 on the target's side,
    adding runs there; each round is in the notes and in info["ranges"]."""
    target = f * E_now["ste"]
    res = cal.calibrate(box, SCENE, {"youngs_modulus": target}, method="surrogate", solver=_no_closed_form(box))
    assert res.converged, res.notes
    ranges = res.info["ranges"]
    assert ranges[0]["from"] == "the initial values" and ranges[0]["lower"] == [0.5e9] and ranges[0]["upper"] == [2e9]
    assert [r["widened"] for r in ranges[1:]] == ([widened] if widened else [])
    assert res.info["n_runs"] == 100 + 50 * len(widened) == res.evaluations
    rounds = [n for n in res.notes if n.startswith("widening round")]
    assert len(rounds) == len(widened)
    if widened:
        assert ranges[1]["lower"] == ([0.125e9] if f < 1 else [0.5e9])
        assert ranges[1]["upper"] == ([2e9] if f < 1 else [8e9])
        assert "youngs_modulus" in rounds[0] and "outside the runs'" in rounds[0] and "+50 runs" in rounds[0]
        assert ranges[1]["reach"][0]["inside"] and not ranges[0]["reach"][0]["inside"]
        assert np.sum(res.info["runs"].X[:, 0] > 2e9 if f > 1 else res.info["runs"].X[:, 0] < 0.5e9) == 50
    assert abs(_solved(box, res) / target - 1) <= res.tol


def test_two_default_parameters_on_two_scenes(box):
    """Two free moduli (two components), two tests, default ranges around the least-squares closed form."""
    two = jaxbpm.generate.mix_materials(box, [0.5, 0.5], seed=2, materials={"E": [1e9, 4e9], "nu": 0.25})
    scenes = {"z": SCENE, "x": UniaxialCompression(axis=0, strain=1e-3)}
    true = {**default_params(two), "bond_E": jnp.array([1.37e9, 12e9])}
    targets = [Target("youngs_modulus", jaxbpm.solve(two, scenes[k], "ste", params=true).youngs_modulus, scene=k)
               for k in scenes]
    res = cal.calibrate(two, scenes, targets, method="surrogate", solver="ste",
                        parameters=[Parameter("bond_E", 0), Parameter("bond_E", 1)], verify=True)
    assert res.converged and res.max_error <= res.tol, res.errors
    assert res.info["ranges"][0]["from"] == "the closed-form estimate"
    for t in targets:
        assert abs(_solved(two, res, scene=scenes[t.scene]) / t.value - 1) <= res.tol


def test_explicit_bounds_are_kept_and_the_error_names_the_reached_range(box, E_now):
    target = 3.0 * E_now["ste"]
    with pytest.raises(CalibrationError, match=r"no parameter combination is admissible .*youngs_modulus: the runs "
                                               r"reach \[[-+.e0-9]+, [-+.e0-9]+\], the target is [-+.e0-9]+ "
                                               r"\(outside\)"):
        cal.calibrate(box, SCENE, {"youngs_modulus": target}, method="surrogate", solver="ste",
                      parameters=[Parameter("bond_E", bounds=(0.5e9, 2e9))], n_runs=40, n_trees=50, L_s=300)
    space = ParameterSpace([Parameter("bond_E", bounds=(0.5e9, 4e9))], cal.base_params(box, ["bond_E"], SCENE))
    pb = Problem(cal.forward_model(box, SCENE, "ste"), [Target("youngs_modulus", target)], space)
    res = cal.surrogate(pb, n_runs=40, n_trees=50, L_s=300)  # explicit bounds: no estimate, no widening
    assert "ranges" not in res.info and res.evaluations == 40
    assert res.info["runs"].lower.tolist() == [0.5e9] and res.info["runs"].upper.tolist() == [4e9]


# ---------------------------------------------------------------------------------------------------- analytic
def _analytic_problem(t_E, t_K):
    """E = 3 bond_E[0], K = 2 bond_E[1] + 0.01 bond_E[0]: each target moves with its own parameter."""
    def fn(params):
        e = params["bond_E"]
        return {"youngs_modulus": 3 * e[0], "stiffness": 2 * e[1] + 0.01 * e[0]}

    base = {"bond_E": jnp.array([1.0, 1.0]), "bond_nu": jnp.array([0.3, 0.3])}
    space = ParameterSpace([Parameter("bond_E", 0), Parameter("bond_E", 1)], base)
    return Problem(Forward.from_function(fn, name="analytic"), [Target("youngs_modulus", t_E),
                                                                Target("stiffness", t_K)], space)


def test_widening_moves_only_the_parameter_and_side_that_reach_the_target():
    pb = _analytic_problem(3 * 10.0, 2 * 0.2 + 0.1)  # bond_E[0] = 10 (up, two rounds), bond_E[1] = 0.2 (down)
    res = cal.surrogate(pb, n_trees=100, L_s=400, it_max=15, verify=True)
    ranges = res.info["ranges"]
    assert ranges[1]["widened"] == [("bond_E[0]", "upper"), ("bond_E[1]", "lower")]
    assert ranges[2]["widened"] == [("bond_E[0]", "upper")]  # bond_E[1] reached in round 1
    assert ranges[-1]["lower"] == pytest.approx([0.5, 0.5 / 4]) and ranges[-1]["upper"] == pytest.approx([32.0, 2.0])
    assert sum(n.startswith("widening round") for n in res.notes) == len(ranges) - 1 == 2
    assert res.info["n_runs"] == 100 + 3 * 50 == res.evaluations - 1  # three slabs; one verify run
    # the answer lies in the sparser widened part of the runs (x10 from the start): within the forests' resolution
    assert abs(res.values["bond_E[0]"] / 10 - 1) < 0.1 and abs(res.values["bond_E[1]"] / 0.2 - 1) < 0.1


def test_widening_stops_at_the_default_bounds_and_says_so():
    pb = _analytic_problem(3 * 1e4, 2.01)  # bond_E[0] = 1e4: beyond the default bounds (0.01, 100)
    with pytest.raises(CalibrationError, match=r"youngs_modulus: the runs reach \[[.0-9]+, [.0-9]+\], the target "
                                               r"is 3e\+04 \(outside\).*3 widening round\(s\), at the parameters' "
                                               r"default bounds"):
        cal.surrogate(pb, n_runs=30, n_trees=20, L_s=200, it_max=5)
    with pytest.raises(CalibrationError, match=r"the target is 150 \(outside\).*after 0 widening round\(s\)"):
        cal.surrogate(_analytic_problem(3 * 50.0, 2.5), n_runs=30, n_trees=20, L_s=200, it_max=5, widen=0)
    with pytest.raises(CalibrationError, match="widen"):
        cal.surrogate(pb, widen=-1)


def test_widened_run_set_is_stored_and_resumed(tmp_path):
    path = tmp_path / "runs.h5"
    pb = _analytic_problem(3 * 5.0, 2.01)
    res = cal.surrogate(pb, n_runs=30, n_trees=20, L_s=200, it_max=8, runs_file=path)
    assert len(res.info["ranges"]) == 2 and res.info["n_runs"] == 45
    stored = cal.RunSet.load(path)
    np.testing.assert_array_equal(stored.X, res.info["runs"].X)
    assert stored.upper[0] == pytest.approx(8.0)
    pb2 = _analytic_problem(3 * 5.0, 2.01)
    res2 = cal.surrogate(pb2, n_runs=30, n_trees=20, L_s=200, it_max=8, runs_file=path)
    assert pb2.evaluations == 0  # every run, the widened ones included, read back from the file
    np.testing.assert_array_equal(res2.info["runs"].Y, res.info["runs"].Y)
    assert res2.values == res.values


def test_interrupted_widening_round_resumes_from_the_file(tmp_path):
    """A run that fails in a widening round leaves the runs before it in the file; called again, only the rest are
    solved (a plain NumPy model: one run at a time, each stored as it finishes)."""
    calls = []

    def fn(params, fail_at=None):
        calls.append(float(np.asarray(params["bond_E"])[0]))
        if len(calls) == fail_at:
            raise RuntimeError(f"run {fail_at} failed")
        return {"youngs_modulus": 3.0 * np.asarray(params["bond_E"])[0]}

    def problem(fail_at=None):
        space = ParameterSpace([Parameter("bond_E")], {"bond_E": np.asarray([1.0])})
        fwd = Forward.from_function(lambda p: fn(p, fail_at), name="plain", pure=False)
        return Problem(fwd, [Target("youngs_modulus", 15.0)], space)

    path, kw = tmp_path / "runs.h5", dict(n_runs=30, n_trees=30, L_s=200, it_max=8)
    with pytest.raises(RuntimeError, match="run 35 failed"):
        cal.surrogate(problem(fail_at=35), runs_file=path, **kw)  # in widening round 1 (runs 31-45)
    assert int(cal.RunSet.load(path, partial=True).done.sum()) == 34
    calls.clear()
    res = cal.surrogate(problem(), runs_file=path, **kw)
    assert len(calls) == 11 and res.info["n_runs"] == 45 and res.info["runs"].info["resumed"] == 34
    assert res.converged and abs(res.values["bond_E"] / 5 - 1) < res.tol
    np.testing.assert_array_equal(cal.RunSet.load(path).Y, res.info["runs"].Y)
