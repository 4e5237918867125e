"""Calibrators: recovery of known bond moduli, gradients, seed-003 options, the surrogate, multi-fidelity, errors."""

import importlib
import json

import jax.numpy as jnp
import numpy as np
import optax
import pytest

import jaxbpm
from jaxbpm import calibrate as cal
from jaxbpm.calibrate import CalibrationError, Forward, Parameter, ParameterSpace, Problem, Target
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression

# one xdist worker for the module: the tests that calibrate `one` and `two` share their compiled solves and losses
pytestmark = pytest.mark.xdist_group("calibrate-module")

SCENE = UniaxialCompression(strain=0.002)
SOLVE = importlib.import_module("jaxbpm.solving")


@pytest.fixture(scope="module")
def one():
    return jaxbpm.generate.lattice("fcc", (3, 3, 4), 1e-3, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})


@pytest.fixture(scope="module")
def two(one):
    """Two components, moduli 1:4, mixed at random."""
    return jaxbpm.generate.mix_materials(one, [0.5, 0.5], seed=2, materials={"E": [1e9, 4e9], "nu": 0.25})


@pytest.fixture(scope="module")
def dsm_forward(one):
    return cal.forward_model(one, SCENE, "dsm")


def _modulus(sample, params):
    return jaxbpm.solve(sample, SCENE, "dsm", params=params).youngs_modulus


# ---------------------------------------------------------------------------------------------------- recovery
@pytest.mark.parametrize("which", ["one", "two"])
def test_adam_autodiff_recovers_known_bond_E(which, request):
    sample = request.getfixturevalue(which)
    p = default_params(sample)
    true = {**p, "bond_E": p["bond_E"] * 2.7}
    target = _modulus(sample, true)
    res = cal.calibrate(sample, SCENE, {"youngs_modulus": target}, method="adam", shortcut=False,
                        gradient="autodiff", tol=0.005, max_iterations=10)
    assert res.method == "adam" and res.converged and res.iterations <= 10
    np.testing.assert_allclose(res.params["bond_E"], true["bond_E"], rtol=5e-3)
    # the answer checked by an independent solve
    assert abs(_modulus(sample, res.params) / target - 1) < 5e-3
    if which == "two":
        np.testing.assert_allclose(res.params["bond_E"][1] / res.params["bond_E"][0], 4.0, rtol=1e-12)


def test_adam_without_estimates_converges(one):
    """Plain Adam (Eq. 4-8) from 20 % off, autodiff: within 2 % in <= 10 iterations (Adam's fixed step size limits
    the final precision; the initial estimates of Qu et al. 2020 remove that limit, see above)."""
    target = _modulus(one, {**default_params(one), "bond_E": jnp.array([1.2e9])})
    res = cal.calibrate(one, SCENE, {"youngs_modulus": target}, method="adam", shortcut=False, gradient="autodiff",
                        tol=0.02, max_iterations=10, first_estimate=False, second_estimate=False,
                        learning_rate=0.05)
    assert res.converged and res.iterations <= 10, res.table()
    assert all(r["kind"] in ("initial", "adam") for r in res.history.rows)
    assert abs(res.values["bond_E"] / 1.2e9 - 1) < 2e-2
    assert res.max_error < abs(res.history.rows[0]["errors"][0]) / 8


def test_closed_form_shortcut_is_used_and_says_so(two):
    p = default_params(two)
    target = _modulus(two, {**p, "bond_E": p["bond_E"] * 0.37})
    res = cal.calibrate(two, SCENE, {"youngs_modulus": target}, method="adam")
    assert res.method == "closed-form" and res.evaluations == 1
    assert any("linear" in n for n in res.notes) and any("shortcut" in n for n in res.notes)
    np.testing.assert_allclose(res.params["bond_E"], p["bond_E"] * 0.37, rtol=1e-6)


def test_closed_form_least_squares_on_two_scenes(two):
    """Two free components, two tests: the least squares on the linear responses recovers both."""
    scenes = {"z": SCENE, "x": UniaxialCompression(axis=0, strain=0.002)}
    true = {**default_params(two), "bond_E": jnp.array([1.3e9, 4.4e9])}
    targets = [Target("youngs_modulus", jaxbpm.solve(two, scenes[k], "dsm", params=true).youngs_modulus, scene=k)
               for k in scenes]
    start = [Parameter("bond_E", 0, initial=1.1e9), Parameter("bond_E", 1, initial=4.0e9)]
    res = cal.calibrate(two, scenes, targets, method="closed-form", parameters=start, verify=True)
    assert res.converged and res.info["verified"]
    np.testing.assert_allclose([res.values["bond_E[0]"], res.values["bond_E[1]"]], [1.3e9, 4.4e9], rtol=1e-3)


def test_fd_and_autodiff_gradients_agree(two):
    fwd = cal.forward_model(two, SCENE, "dsm")
    targets = [Target("youngs_modulus", 3e8), Target("stiffness", 5e6, weight=3.0)]
    space = ParameterSpace([Parameter("bond_E", 0), Parameter("bond_E", 1)], default_params(two))
    pb = Problem(fwd, targets, space)
    z = np.array([0.1, -0.2])
    l_ad, g_ad, _ = cal.loss_and_gradient(pb, z, "autodiff")
    l_c, g_c, _ = cal.loss_and_gradient(pb, z, "fd-central", step=1e-5)
    assert abs(l_ad - l_c) <= 1e-12 * l_ad
    assert np.linalg.norm(g_c - g_ad) <= 1e-4 * np.linalg.norm(g_ad), (g_c, g_ad)
    assert np.all(np.abs(g_ad) > 0)
    evals = pb.evaluations
    l_f, g_f, _ = cal.loss_and_gradient(pb, z, "fd-forward", step=1e-4)
    assert pb.evaluations == evals + 3  # the base point and two perturbed points, one batch
    assert np.linalg.norm(g_f - g_ad) <= 1e-3 * np.linalg.norm(g_ad), (g_f, g_ad)


# ---------------------------------------------------------------------------------------------------- Qu et al. 2020
def _analytic(c=3.0):
    """A cheap homogeneous model: E = c * bond_E, K = 2 c * bond_E[1] + 0.01 bond_E[0]."""
    def fn(params):
        e = params["bond_E"]
        return {"youngs_modulus": c * e[0], "stiffness": 2 * c * e[1] + 0.01 * e[0]}
    return Forward.from_function(fn, name="analytic")


def _analytic_problem(targets, n=1, **space_kw):
    base = {"bond_E": jnp.array([1.0, 1.0]), "bond_nu": jnp.array([0.3, 0.3])}
    params = [Parameter("bond_E", i, bounds=(1e-3, 1e3)) for i in range(n)]
    return Problem(_analytic(), targets, ParameterSpace(params, base, **space_kw))


def test_loss_scaled_step_follows_eq9():
    steps = {}
    for scaled in (False, True):
        pb = _analytic_problem([Target("youngs_modulus", 30.0)])
        res = cal.adam(pb, gradient="fd-forward", loss_scaled=scaled, max_iterations=2, first_estimate=False,
                       second_estimate=False, learning_rate=0.1)
        v = res.history.column("values")[:, 0]
        steps[scaled] = (np.log(v[1] / v[0]), res.history.rows[0]["loss"])
    # first Adam step: -lr * sign(g) (bias-corrected moments); Eq. 9 multiplies it by L
    np.testing.assert_allclose(steps[False][0], 0.1, rtol=1e-6)
    np.testing.assert_allclose(steps[True][0], 0.1 * steps[True][1], rtol=1e-6)
    assert steps[True][1] > 0.5  # far from the target (E = 3 vs 30): L = 0.81, the step is scaled accordingly


def test_initial_estimates_follow_eq14_eq15():
    pb = _analytic_problem([Target("youngs_modulus", 30.0)])
    res = cal.adam(pb, gradient="fd-forward", tol=1e-9, max_iterations=5)
    kinds = [r["kind"] for r in res.history.rows]
    assert kinds[:2] == ["estimate-1", "estimate-2"]
    assert abs(res.history.rows[0]["values"][0] - 30.0) < 1e-9  # Eq. 14: bond E := target E
    assert abs(res.history.rows[1]["values"][0] - 10.0) < 1e-9  # Eq. 15: 30 * 30 / 90
    assert res.converged and res.iterations == 2 and res.evaluations == 2
    plain = cal.adam(_analytic_problem([Target("youngs_modulus", 30.0)]), gradient="fd-forward", tol=1e-3,
                     max_iterations=5, first_estimate=False, second_estimate=False)
    assert not plain.converged and plain.evaluations > res.evaluations


def test_simplified_scheme_runs_fewer_sets():
    targets = [Target("youngs_modulus", 30.0), Target("stiffness", 12.0)]
    tie = {"bond_E[0]": "youngs_modulus", "bond_E[1]": "stiffness"}
    kw = dict(gradient="fd-forward", tie=tie, tol=1e-9, max_iterations=4, first_estimate=False,
              second_estimate=False)
    full = cal.adam(_analytic_problem(targets, n=2), **kw)
    pert = cal.adam(_analytic_problem(targets, n=2), simplified="perturbed", **kw)
    simp = cal.adam(_analytic_problem(targets, n=2), simplified=True, **kw)
    # 3 iterations with gradients + the last point: full 3 * 3 + 1 solves, one perturbed point 3 * 2 + 1; the
    # secant form (Qu et al.'s count) one point per iteration, plus a perturbed point at the first (no step yet)
    assert full.evaluations == 10 and pert.evaluations == 7 and simp.evaluations == 5
    assert simp.info["secant_gradients"] == 2 and pert.info["secant_gradients"] == 0
    # the weak coupling (0.01) leaves the path nearly unchanged
    np.testing.assert_allclose(pert.history.column("values"), full.history.column("values"), rtol=2e-2)
    np.testing.assert_allclose(simp.history.column("values"), full.history.column("values"), rtol=2e-2)
    assert simp.info["simplified"] == "secant" and pert.info["simplified"] == "perturbed"
    assert not full.info["simplified"]
    with pytest.raises(CalibrationError, match="simplified must be"):
        cal.adam(_analytic_problem(targets, n=2), simplified="fast", **kw)


def test_target_scaled_form():
    pb = _analytic_problem([Target("youngs_modulus", 30.0)], scaling="target", scales=[30.0])
    np.testing.assert_allclose(pb.space.to_z(np.array([30.0])), [1.0])
    res = cal.adam(pb, gradient="autodiff", tol=1e-6, max_iterations=4)
    assert res.converged and abs(res.values["bond_E[0]"] - 10.0) < 1e-5


def test_adam_default_optimizer_is_optax_adam():
    kw = dict(gradient="fd-forward", tol=1e-9, max_iterations=8, first_estimate=False, second_estimate=False)
    res = cal.adam(_analytic_problem([Target("youngs_modulus", 30.0)]), **kw)
    # the iterates of the hand-applied Adam step before optimizer= existed: exp(0.1 k) for the first steps
    ref = [1.0, 1.1051709119385378, 1.221540328442136, 1.3504150578882226, 1.4932737582894595, 1.6517910123846327,
           1.8278647301850988, 2.0236472535478476]
    np.testing.assert_allclose(res.history.column("values")[:, 0], ref, rtol=1e-13)
    np.testing.assert_allclose([r["loss"] for r in res.history.rows][:2], [0.81, 0.791179845058243], rtol=1e-13)
    assert res.info["optimizer"] == "adam" and res.info["learning_rate"] == 0.1
    same = cal.adam(_analytic_problem([Target("youngs_modulus", 30.0)]),
                    optimizer=optax.adam(0.1, b1=0.9, b2=0.99, eps=1e-8), **kw)
    np.testing.assert_array_equal(same.history.column("values"), res.history.column("values"))
    assert same.info["optimizer"] == "custom" and same.info["learning_rate"] is None


@pytest.mark.parametrize("name", ["sgd", "adamw"])
def test_adam_accepts_any_optax_optimizer(name):
    opt = optax.sgd(0.5) if name == "sgd" else optax.adamw(0.2, b2=0.99, weight_decay=1e-4)
    res = cal.adam(_analytic_problem([Target("youngs_modulus", 30.0)]), gradient="autodiff", optimizer=opt, tol=1e-3,
                   max_iterations=40, first_estimate=False, second_estimate=False)
    assert res.converged and abs(res.values["bond_E[0]"] / 10.0 - 1) < 1e-3  # E = 3 bond_E = 30
    # a different optimizer takes a different path from the default Adam's
    first = cal.adam(_analytic_problem([Target("youngs_modulus", 30.0)]), gradient="autodiff", max_iterations=2,
                     first_estimate=False, second_estimate=False)
    assert abs(res.history.rows[1]["values"][0] - first.history.rows[1]["values"][0]) > 1e-3
    for bad in ("sgd", optax.sgd, 0.1):
        with pytest.raises(CalibrationError, match="optimizer must be an optax.GradientTransformation"):
            cal.adam(_analytic_problem([Target("youngs_modulus", 30.0)]), optimizer=bad)


# ---------------------------------------------------------------------------------------------------- surrogate
AT = np.linspace(0.2, 1.0, 5)


def _curve_model():
    def fn(params):
        a, b = params["bond_E"][0], params["bond_E"][1]
        return {"curve": a * jnp.asarray(AT) + 3 * b * jnp.square(jnp.asarray(AT))}  # bond_nu: no effect
    return Forward.from_function(fn, name="curve")


def _curve_problem(a, b):
    base = {"bond_E": jnp.array([1.0, 1.0]), "bond_nu": jnp.array([0.3])}
    space = ParameterSpace([Parameter("bond_E", 0, bounds=(1.0, 3.0), initial=2.0),
                            Parameter("bond_E", 1, bounds=(0.5, 2.0), initial=1.0),
                            Parameter("bond_nu", 0, bounds=(0.1, 0.4), initial=0.3)], base)
    return Problem(_curve_model(), [Target("curve", a * AT + 3 * b * AT ** 2)], space)


def test_surrogate_recovers_parameters_and_reuses_runs(tmp_path):
    pb = _curve_problem(2.2, 1.1)
    res = cal.surrogate(pb, n_runs=200, n_trees=50, L_s=400, it_max=15, I_e=0.2, seed=1, verify=True)
    assert res.evaluations == 201 and res.info["n_runs"] == 200
    assert abs(res.values["bond_E[0]"] / 2.2 - 1) < 0.05 and abs(res.values["bond_E[1]"] / 1.1 - 1) < 0.10
    r2 = res.info["oob_r2"]
    assert r2.shape == (5,) and np.all(r2 > 0.5) and np.all(r2 <= 1)
    imp = res.info["mean_importance"]
    assert np.argmin(imp) == 2 and res.info["importance"].shape == (5, 3)
    lo, hi = res.band["bond_E[0]"]
    assert lo <= res.values["bond_E[0]"] <= hi and lo >= 1.0 + 0.05 * 2.0 - 1e-12
    # store the run set, calibrate a second specimen from it: no new runs
    path = res.info["runs"].save(tmp_path / "runs.h5")
    runs = cal.RunSet.load(path)
    np.testing.assert_array_equal(runs.Y, res.info["runs"].Y)
    pb2 = _curve_problem(1.6, 1.6)
    res2 = cal.surrogate(pb2, runs=runs, n_trees=50, L_s=400, it_max=15, I_e=0.2, seed=1)
    assert res2.evaluations == 0 and pb2.evaluations == 0
    assert abs(res2.values["bond_E[0]"] / 1.6 - 1) < 0.08 and abs(res2.values["bond_E[1]"] / 1.6 - 1) < 0.10


def test_surrogate_drops_unimportant_parameter_and_resamples():
    pb = _curve_problem(2.2, 1.1)
    res = cal.surrogate(pb, n_runs=60, n_trees=30, L_s=300, it_max=8, importance_threshold=0.2,
                        resample_runs=60, seed=0)
    assert res.info["dropped"] == ["bond_nu[0]"] and res.evaluations == 120
    assert res.values["bond_nu[0]"] == 0.3 and res.info["mean_importance"][2] == 0.0


@pytest.mark.parametrize("kind", ["RandomForestRegressor", "ExtraTreesRegressor"])
@pytest.mark.parametrize("outputs", [1, 2])
def test_forest_prediction_equals_scikit_learn(kind, outputs):
    """The surrogate's own loop over a forest's trees gives scikit-learn's ``predict`` to the last bit."""
    import sklearn.ensemble

    from jaxbpm.calibrate.surrogate import _predict_one

    rng = np.random.default_rng(3)
    X = rng.random((80, 3))
    y = np.stack([X @ [1.0, 2.0, 3.0] + 0.1 * rng.random(80), X[:, 0] ** 2], axis=1)[:, :outputs]
    forest = getattr(sklearn.ensemble, kind)(n_estimators=30, random_state=0).fit(X, y[:, 0] if outputs == 1 else y)
    Xp = rng.random((500, 3))
    ours, theirs = _predict_one(forest, Xp), forest.predict(Xp)
    assert ours.shape == theirs.shape
    np.testing.assert_array_equal(ours, theirs)


def test_surrogate_takes_any_scikit_learn_regressor():
    from sklearn.cluster import KMeans
    from sklearn.ensemble import ExtraTreesRegressor, RandomForestRegressor
    from sklearn.multioutput import MultiOutputRegressor
    from sklearn.neighbors import KNeighborsRegressor
    from sklearn.svm import SVR

    pb = _curve_problem(2.2, 1.1)
    kw = dict(L_s=200, it_max=6, seed=1)
    base = cal.surrogate(pb, n_runs=60, n_trees=20, **kw)
    models = base.info["models"]
    assert len(models) == 5 and all(type(m) is RandomForestRegressor for m in models)  # one forest per element
    assert [m.random_state for m in models] == [1, 2, 3, 4, 5]
    runs = base.info["runs"]
    et = ExtraTreesRegressor(n_estimators=30, bootstrap=True, oob_score=True)
    res = cal.surrogate(pb, runs=runs, regressor=et, n_jobs=1, **kw)
    (model,) = res.info["models"]
    assert type(model) is ExtraTreesRegressor and model.n_outputs_ == 5  # one multi-output model
    assert model.random_state == 1 and model.n_jobs == 1 and not hasattr(et, "estimators_")  # a fitted clone
    assert res.info["oob_r2"].shape == (5,) and np.all(res.info["oob_r2"] > 0.3)
    assert res.info["importance"].shape == (5, 3) and np.argmin(res.info["mean_importance"]) == 2
    assert abs(res.values["bond_E[0]"] / 2.2 - 1) < 0.1
    knn = cal.surrogate(pb, runs=runs, regressor=KNeighborsRegressor(3), **kw)
    assert type(knn.info["models"][0]) is KNeighborsRegressor and np.all(np.isnan(knn.info["oob_r2"]))
    with pytest.raises(CalibrationError, match="importance_threshold needs feature importances"):
        cal.surrogate(pb, runs=runs, regressor=KNeighborsRegressor(3), importance_threshold=0.1, **kw)
    svr = cal.surrogate(pb, runs=runs, regressor=SVR(C=10.0, epsilon=0.001), I_e=0.5, **kw)
    (wrapped,) = svr.info["models"]  # SVR fits one output: one clone per element
    assert type(wrapped) is MultiOutputRegressor and len(wrapped.estimators_) == 5
    for bad in (KMeans(2), RandomForestRegressor, "rf"):
        with pytest.raises(CalibrationError, match="regressor must be a scikit-learn regressor"):
            cal.surrogate(pb, runs=runs, regressor=bad, **kw)


# ---------------------------------------------------------------------------------------------------- multi-fidelity
def _biased(sample, factor):
    """A deliberately biased low-fidelity model: the DSM stiffness times ``factor``."""
    from jaxbpm import dsm

    f = dsm.stiffness_function(sample, SCENE)
    length, area = SCENE.geometry(sample)

    def pure(params):
        k = f(params) * factor
        return {"main": {"stiffness": k, "youngs_modulus": k * length / area}}

    def evaluate(params):
        return {"main": {k: np.asarray(v) for k, v in pure(params)["main"].items()}}

    return Forward(name=f"biased-{factor:g}", evaluate=evaluate, pure=pure, homogeneous=True)


def test_multifidelity_stops_early_and_escalates(one):
    target = 1.3 * _modulus(one, None)
    if "ste" in SOLVE.METHODS:
        low = cal.forward_model(one, SCENE, "ste")
        p = default_params(one)
        diff = abs(float(low.pure(p)["main"]["youngs_modulus"]) / _modulus(one, p) - 1)
    else:
        low, diff = _biased(one, 1.08), 0.08
    if diff < 2e-3:  # the cheap model is too close to the DSM here to show an escalation
        low, diff = _biased(one, 1.08), 0.08
    space = ParameterSpace(cal.default_parameters(one), default_params(one))
    # tolerance wider than the gap: the DSM check accepts the cheap answer (one DSM solve)
    early = cal.multifidelity(one, SCENE, {"youngs_modulus": target}, space, levels=(low, "dsm"), tol=2 * diff)
    assert [lv["action"] for lv in early.levels] == ["calibrated", "accepted"]
    assert early.levels[1]["evaluations"] == 1 and early.solver == "dsm"
    assert abs(early.errors["youngs_modulus"]) <= 2 * diff
    # tolerance narrower than the gap: DSM is calibrated from the cheap answer
    esc = cal.multifidelity(one, SCENE, {"youngs_modulus": target}, space, levels=(low, "dsm"), tol=diff / 4)
    assert [lv["action"] for lv in esc.levels] == ["calibrated", "escalated"]
    assert esc.converged and esc.levels[1]["evaluations"] >= 1
    assert abs(_modulus(one, esc.params) / target - 1) < diff / 4
    assert esc.evaluations == sum(lv["evaluations"] for lv in esc.levels)


def test_auto_is_the_default_and_checks(one):
    target = 0.8 * _modulus(one, None)
    res = cal.calibrate(one, SCENE, {"youngs_modulus": target}, tol=0.01, check="dsm")
    assert res.method == "multi-fidelity" and res.converged
    assert res.levels[0]["solver"] == ("ste" if "ste" in SOLVE.METHODS else "dsm")
    assert res.info["check"]["max_error"] < 0.01


# ---------------------------------------------------------------------------------------------------- history, CLI
def test_history_saved_and_plotted(tmp_path):
    pb = _analytic_problem([Target("youngs_modulus", 30.0)])
    res = cal.adam(pb, gradient="fd-central", tol=1e-3, max_iterations=6, first_estimate=False,
                   second_estimate=False, learning_rate=0.3)
    path = res.save(tmp_path / "history.h5")
    h = cal.load_history(path)
    assert len(h) == len(res.history) == 6
    np.testing.assert_allclose(h.column("loss"), res.history.column("loss"))
    assert list(h.column("evaluations")) == [3 * i for i in range(1, 6)] + [16]
    assert np.all(h.column("time") >= 0)
    res.plot(tmp_path / "history.png")
    assert (tmp_path / "history.png").stat().st_size > 1000


def test_cli_calibrate(one, tmp_path, capsys):
    from jaxbpm import cli
    from jaxbpm.io import save_sample

    path = save_sample(tmp_path / "s.h5", one)
    target = 1.5 * _modulus(one, None)
    assert cli.main(["calibrate", str(path), "--target-E", repr(target), "--method", "auto", "--tol", "0.01",
                     "--history", str(tmp_path / "h.h5")]) == 0
    out = capsys.readouterr().out
    assert "bond_E" in out and "converged" in out and (tmp_path / "h.h5").exists()
    cfg = tmp_path / "c.json"
    cfg.write_text(json.dumps({"targets": [{"observable": "youngs_modulus", "value": 0.7 * target}],
                               "tol": 0.01}))
    assert cli.main(["calibrate", str(path), "--config", str(cfg), "--quiet"]) == 0
    assert "converged (tol 1 %)" in capsys.readouterr().out
    assert cli.main(["calibrate", str(path)]) == 2
    assert "no target" in capsys.readouterr().err
    cfg.write_text("{not json")
    assert cli.main(["calibrate", str(path), "--config", str(cfg)]) == 2


# ---------------------------------------------------------------------------------------------------- errors
def test_clear_errors(one, dsm_forward):
    p = default_params(one)
    with pytest.raises(CalibrationError, match="unknown calibration method"):
        cal.calibrate(one, SCENE, {"youngs_modulus": 1e8}, method="newton")
    with pytest.raises(CalibrationError, match="unknown solver"):
        cal.calibrate(one, SCENE, {"youngs_modulus": 1e8}, method="adam", solver="fem")
    with pytest.raises(CalibrationError, match="must be > 0"):
        Target("youngs_modulus", -1.0)
    with pytest.raises(CalibrationError, match="finite"):
        Target("stiffness", float("nan"))
    with pytest.raises(CalibrationError, match="needs 'at'"):
        Target("stress", [1.0, 2.0])
    with pytest.raises(CalibrationError, match="weight"):
        Target("stiffness", 1.0, weight=0)
    with pytest.raises(CalibrationError, match="out of range"):
        ParameterSpace([Parameter("bond_E", 3)], p)
    with pytest.raises(CalibrationError, match="outside its bounds"):
        ParameterSpace([Parameter("bond_E", 0, bounds=(1.0, 2.0))], p)
    with pytest.raises(CalibrationError, match="no entry"):
        ParameterSpace([Parameter("friction")], p)
    with pytest.raises(CalibrationError, match="both set"):
        ParameterSpace([Parameter("bond_E"), Parameter("bond_E", 0)], p)
    space = ParameterSpace([Parameter("bond_E")], p)
    with pytest.raises(CalibrationError, match="does not report 'strength'"):
        Problem(dsm_forward, [Target("strength", 1e6)], space).outputs([[1e9]])
    pb = Problem(dsm_forward, [Target("youngs_modulus", 1e8)], space)
    with pytest.raises(CalibrationError, match="unknown gradient"):
        cal.adam(pb, gradient="fd-backward")
    with pytest.raises(CalibrationError, match="tol"):
        cal.adam(pb, tol=5.0)
    with pytest.raises(CalibrationError, match="I_e"):
        cal.surrogate(pb, I_e=0.0)
    dem = Problem(cal.forward_model(one, SCENE, "dem"), [Target("youngs_modulus", 1e8)], space)
    with pytest.raises(CalibrationError, match="autodiff"):
        cal.adam(dem, gradient="autodiff")
    with pytest.raises(CalibrationError, match="scene 'x'"):
        Problem(dsm_forward, [Target("stiffness", 1.0, scene="x")], space)
    two_free = ParameterSpace([Parameter("bond_E", 0)], {**p, "bond_E": jnp.array([1e9, 1e9])})
    with pytest.raises(CalibrationError, match="held fixed"):
        cal.closed_form(Problem(cal.forward_model(one, SCENE, "dsm"), [Target("stiffness", 1.0)], two_free))
    with pytest.raises(CalibrationError, match="simplified"):
        cal.adam(_analytic_problem([Target("youngs_modulus", 1.0), Target("stiffness", 1.0)], n=2),
                 simplified=True)


def test_base_params_reads_particle_and_cohesive_entries():
    s = jaxbpm.generate.lattice("sc", (2, 2, 2), 1e-3, particle_material={"E": 3e8, "friction": 0.3})
    law = {"c0": 2e4, "kc": 0.25, "c_max": 6e4}
    scene = UniaxialCompression(strain=0.01, contacts=True, contact_law="cohesive", cohesive=law)
    base = cal.base_params(s, ["contact_E", "friction", "cohesion_initial", "cohesion_max"], scene)
    assert float(base["contact_E"]) == 3e8 and float(base["friction"]) == 0.3
    assert float(base["cohesion_initial"]) == 2e4 and float(base["cohesion_max"]) == 6e4
    with pytest.raises(CalibrationError, match="cohesive contact law"):
        cal.base_params(s, ["cohesion_max"], UniaxialCompression(strain=0.01))
    with pytest.raises(CalibrationError, match="no parameter entry 'bond_colour'"):
        cal.base_params(s, ["bond_colour"])


def test_run_set_shows_a_progress_bar_only_when_asked(capsys):
    from jaxbpm.calibrate.runs import run_set

    s = jaxbpm.generate.lattice("sc", (3, 3, 4), 1e-3, materials={"E": 1e9, "nu": 0.25})
    problem = cal.Problem(cal.forward_model(s, UniaxialCompression(strain=0.002), solver="ste"),
                          [cal.Target("stiffness", 1.0)],
                          cal.ParameterSpace([cal.Parameter("bond_E", index=0)], cal.base_params(s)))
    quiet = run_set(problem, 6, chunk=4)
    assert capsys.readouterr().err == ""
    shown = run_set(problem, 6, chunk=4, progress=True)
    err = capsys.readouterr().err
    assert "run set" in err and "6/6" in err  # a bar of the runs, on stderr
    np.testing.assert_array_equal(shown.Y, quiet.Y)
