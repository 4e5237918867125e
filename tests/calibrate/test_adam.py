"""Adam (Qu et al. 2020): recovery of known bond moduli, gradients, the estimates, the simplified scheme, optax."""

import jax.numpy as jnp
import numpy as np
import optax
import pytest

from jaxbpm import calibrate as cal
from jaxbpm.calibrate import CalibrationError, Parameter, ParameterSpace, Problem, Target
from jaxbpm.physics.model import default_params
from tests.calibrate._cases import SCENE, _analytic_problem, _modulus

# one xdist worker for the calibration tests: those that calibrate `one` and `two` share their compiled solves
pytestmark = pytest.mark.xdist_group("calibrate-module")


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


def test_tied_gradient_keeps_its_sign_across_a_sign_change_of_the_error():
    """Between two points whose error has opposite signs (E = 3 bond_E against 30: bond_E 8 gives -20 %, 11 gives
    +10 %), the secant of the squared error points the wrong way; the chain rule with the errors' secant agrees in
    sign (and here, a linear model, in value) with the derivative at the point."""
    pb = _analytic_problem([Target("youngs_modulus", 30.0)])
    z_prev, z = pb.space.to_z(np.array([8.0])), pb.space.to_z(np.array([11.0]))
    e_prev, e = (np.asarray(pb.errors_of(pb.outputs(pb.space.from_z(p[None, :]))[0])) for p in (z_prev, z))
    assert e_prev[0] < 0 < e[0]
    g = cal.tied_gradient(pb, e, e_prev, z_prev - z, [0])
    _, g_exact, _ = cal.loss_and_gradient(pb, z, "fd-central", step=1e-6)
    squared_secant = (float(pb.loss_of(e)) - float(pb.loss_of(e_prev))) / (z - z_prev)[0]
    assert g[0] > 0 and g_exact[0] > 0 and squared_secant < 0
    # exact for a model linear in bond_E up to the log form's curvature: within the secant's span, 15 %
    assert abs(g[0] / g_exact[0] - 1) < 0.15
    # the perturbed form is the forward difference of the errors, within fd_step of the derivative
    _, g_pert, _ = cal.loss_and_gradient(pb, z, "simplified", step=1e-5, tie=[0])
    np.testing.assert_allclose(g_pert, g_exact, rtol=1e-4)


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


def test_adam_errors(one, dsm_forward):
    space = ParameterSpace([Parameter("bond_E")], default_params(one))
    pb = Problem(dsm_forward, [Target("youngs_modulus", 1e8)], space)
    with pytest.raises(CalibrationError, match="unknown gradient"):
        cal.adam(pb, gradient="fd-backward")
    with pytest.raises(CalibrationError, match="tol"):
        cal.adam(pb, tol=5.0)
    dem = Problem(cal.forward_model(one, SCENE, "dem"), [Target("youngs_modulus", 1e8)], space)
    with pytest.raises(CalibrationError, match="autodiff"):
        cal.adam(dem, gradient="autodiff")
    with pytest.raises(CalibrationError, match="simplified"):
        cal.adam(_analytic_problem([Target("youngs_modulus", 1.0), Target("stiffness", 1.0)], n=2),
                 simplified=True)
