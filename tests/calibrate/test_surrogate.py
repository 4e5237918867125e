"""The random-forest surrogate (Irazabal et al. 2023): recovery, re-used run sets, importance, any regressor."""

import jax.numpy as jnp
import numpy as np
import pytest

from jaxbpm import calibrate as cal
from jaxbpm.calibrate import CalibrationError, Forward, Parameter, ParameterSpace, Problem, Target
from jaxbpm.physics.model import default_params

# one xdist worker for the calibration tests: those that calibrate `one` and `two` share their compiled solves
pytestmark = pytest.mark.xdist_group("calibrate-module")


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


def test_surrogate_errors(one, dsm_forward):
    space = ParameterSpace([Parameter("bond_E")], default_params(one))
    pb = Problem(dsm_forward, [Target("youngs_modulus", 1e8)], space)
    with pytest.raises(CalibrationError, match="I_e"):
        cal.surrogate(pb, I_e=0.0)


def test_chunk_is_a_deprecated_name_of_batch_size():
    pb = _curve_problem(2.2, 1.1)
    kw = dict(n_runs=20, n_trees=30, L_s=100, it_max=3, I_e=0.5, seed=1)
    new = cal.surrogate(pb, batch_size=8, **kw)
    with pytest.warns(DeprecationWarning, match="batch_size="):
        old = cal.surrogate(pb, chunk=8, **kw)
    assert old.values == new.values
    np.testing.assert_array_equal(old.info["runs"].Y, new.info["runs"].Y)
    with pytest.raises(TypeError, match="batch_size= only"):
        cal.surrogate(pb, batch_size=8, chunk=8, **kw)
