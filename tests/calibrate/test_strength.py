"""Strength calibration (Qu et al. 2020): original vs simplified scheme, the initial estimates, the history table."""

import numpy as np
import pytest

import jaxbpm
from jaxbpm import calibrate as cal
from jaxbpm.calibrate import CalibrationError, Forward

TRUE = (4e6, 8e6)  # sigma_c, tau_c


def _stand_in(a=0.30, b=0.05, c=0.40, d=0.02, offset=0.0, log=None):
    """Strengths affine in (sigma_c, tau_c) with cross-coupling: UCS = a tau + b sigma, f = c sigma + d tau + offset.
    Each call is one parameter set (a UCS and a bending 'run'); ``log`` collects the sets."""
    def evaluate(params):
        s = float(np.asarray(params["bond_tensile_strength"]).reshape(-1)[0])
        t = float(np.asarray(params["bond_shear_strength"]).reshape(-1)[0])
        if log is not None:
            log.append((s, t))
        return {"ucs": {"strength": a * t + b * s}, "tpb": {"strength": c * s + d * t + offset}}

    return Forward(name="stand-in", evaluate=evaluate, scenes=("ucs", "tpb"))


def _targets(**kw):
    out = _stand_in(**kw).evaluate({"bond_tensile_strength": TRUE[0], "bond_shear_strength": TRUE[1]})
    return out["ucs"]["strength"], out["tpb"]["strength"]


def _run(scheme, forward_kw=None, **kw):
    forward_kw = forward_kw or {}
    log = []
    ucs, f = _targets(**forward_kw)
    res = cal.calibrate_strength(None, None, ucs=ucs, flexural=f, scheme=scheme,
                                 solver=_stand_in(log=log, **forward_kw), **kw)
    return res, log


def test_estimates_follow_eq14_and_eq15():
    ucs, f = _targets()
    res, log = _run("original", tol=1e-9, max_iterations=2)
    rows = cal.strength_table(res)
    assert [r["kind"] for r in rows] == ["estimate-1", "estimate-2"]
    # Eq. 14: sigma_c := flexural target, tau_c := UCS target
    np.testing.assert_allclose([rows[0]["sigma_c"], rows[0]["tau_c"]], [f, ucs], rtol=1e-12)
    # Eq. 15: each scaled by its tied target over the model value there (sigma_c - flexural, tau_c - UCS)
    m_ucs, m_f = 0.30 * ucs + 0.05 * f, 0.40 * f + 0.02 * ucs
    np.testing.assert_allclose([rows[1]["sigma_c"], rows[1]["tau_c"]], [f * f / m_f, ucs * ucs / m_ucs], rtol=1e-12)
    np.testing.assert_allclose([rows[0]["ucs"], rows[0]["flexural"]], [m_ucs, m_f], rtol=1e-12)
    np.testing.assert_allclose(rows[0]["ucs_error"], m_ucs / ucs - 1, rtol=1e-12)
    assert [r["models"] for r in rows] == [1, 2] and [r["runs"] for r in rows] == [2, 4] and len(log) == 2
    # without cross-coupling the strengths are proportional: the second estimate is the answer
    exact, log = _run("simplified", forward_kw={"b": 0.0, "d": 0.0}, tol=1e-9, max_iterations=5)
    assert exact.converged and exact.iterations == 2 and exact.info["parameter_sets"] == 2
    np.testing.assert_allclose([exact.values["bond_tensile_strength"], exact.values["bond_shear_strength"]], TRUE,
                               rtol=1e-9)


def test_original_and_simplified_model_counts():
    kw = dict(tol=1e-9, max_iterations=6, learning_rate=0.05, fd_step=0.05)
    full, flog = _run("original", **kw)
    simp, slog = _run("simplified", **kw)
    assert not full.converged and not simp.converged and full.iterations == simp.iterations == 6
    # original: 2 estimates + per Adam iteration the point and 2 perturbed sets: 6 + 2 * 4 = 14 sets
    assert full.info["parameter_sets"] == len(flog) == 14 and full.evaluations == 28
    # simplified: one set per point; the secant between successive points is the gradient (Eq. 16-19)
    assert simp.info["parameter_sets"] == len(slog) == 6 and simp.evaluations == 12
    assert simp.info["secant_gradients"] == 4 and "secant" in " ".join(simp.notes)
    # the perturbed sets of the original scheme move one parameter each, by fd_step times the target (Eq. 13)
    ucs, f = _targets()
    p0 = np.array(flog[1])  # the second estimate; its perturbed sets follow it
    np.testing.assert_allclose(np.array(flog[2]) - p0, [0.05 * f, 0.0], rtol=1e-9, atol=1e-3)
    np.testing.assert_allclose(np.array(flog[3]) - p0, [0.0, 0.05 * ucs], rtol=1e-9, atol=1e-3)
    # the answer is the best point seen: here the second estimate (weak coupling), within 3 %
    for res in (full, simp):
        est2 = max(abs(e) for e in res.history.rows[1]["errors"])
        assert res.max_error <= est2 < 0.03, cal.format_strength_table(cal.strength_table(res))


def test_cross_coupling_costs_the_simplified_scheme_accuracy():
    """The simplified gradient uses each parameter's own test only (Eq. 16-19); with a strong coupling of the flexural
    strength to tau_c (outside the range Qu et al. allows it for) it is off, the original scheme's gradient is not."""
    strong = {"b": 0.05, "d": 0.5}
    kw = dict(tol=0.01, max_iterations=8, learning_rate=0.05, fd_step=0.05)
    full, flog = _run("original", forward_kw=strong, **kw)
    simp, slog = _run("simplified", forward_kw=strong, **kw)
    # one set per point, plus one perturbed set where Adam's step was too short for a secant
    fallback = simp.iterations - 2 - simp.info["secant_gradients"]
    assert 0 <= fallback <= 2 and simp.info["parameter_sets"] == len(slog) == simp.iterations + fallback
    assert full.info["parameter_sets"] == len(flog) == 3 * full.iterations - 4
    f_full = [abs(r["flexural_error"]) for r in cal.strength_table(full)]
    f_simp = [abs(r["flexural_error"]) for r in cal.strength_table(simp)]
    # the full gradient lowers sigma_c against the flexural excess caused by tau_c: the error falls every iteration
    assert all(b < a for a, b in zip(f_full[1:], f_full[2:])) and f_full[-1] < 0.5 * f_full[1]
    # the simplified gradient's sign is right (sigma_c falls against the flexural excess from the first step on) but
    # it ignores tau_c's share of the flexural change: tau_c rises for the UCS and holds the flexural strength up
    sig = [r["values"][0] for r in simp.history.rows]
    assert all(b < a for a, b in zip(sig[1:], sig[2:]))
    assert f_simp[-1] < f_simp[1] and f_simp[-1] > 0.5 * f_simp[1] and f_simp[-1] > 2 * f_full[-1]
    # a note warns when the answer lies outside the ratio Qu et al. 2020 allows for the simplified scheme
    ucs, f = 2e6, 3e6
    res = cal.calibrate_strength(None, None, ucs=ucs, flexural=f, scheme="simplified",
                                 solver=_stand_in(a=0.3, b=0.0, c=0.3, d=0.0), tol=1e-6, max_iterations=3)
    assert res.values["bond_tensile_strength"] / res.values["bond_shear_strength"] > 0.8
    assert any("0.8" in n for n in res.notes)


def test_history_table_and_errors():
    res, _ = _run("original", tol=0.05, max_iterations=8, learning_rate=0.05, fd_step=0.05)
    rows = cal.strength_table(res)
    text = cal.format_strength_table(rows)
    assert text.count("\n") == len(rows) and "sigma_c" in text and "UCS" in text
    assert [r["iteration"] for r in rows] == list(range(len(rows)))
    assert all(a["models"] < b["models"] for a, b in zip(rows, rows[1:]))
    with pytest.raises(CalibrationError, match="scheme"):
        cal.calibrate_strength(None, None, ucs=1e6, flexural=1e6, scheme="fast", solver=_stand_in())
    with pytest.raises(CalibrationError, match="ucs"):
        cal.calibrate_strength(None, None, ucs=-1.0, flexural=1e6, solver=_stand_in())
    with pytest.raises(CalibrationError, match="scenes"):
        cal.calibrate_strength(None, None, ucs=1e6, flexural=1e6,
                               solver=Forward(name="x", evaluate=lambda p: {}, scenes=("main",)))
    with pytest.raises(CalibrationError, match="initial"):
        cal.calibrate_strength(None, None, ucs=1e6, flexural=1e6, solver=_stand_in(), initial={"bond_E": 1.0})
    with pytest.raises(CalibrationError, match="calibrate_strength"):
        cal.strength_table(cal.adam(_identity_problem(), max_iterations=1))


def _identity_problem():
    from jaxbpm.calibrate import Parameter, ParameterSpace, Problem, Target

    fwd = Forward.from_function(lambda p: {"youngs_modulus": p["bond_E"][0]})
    space = ParameterSpace([Parameter("bond_E", 0, bounds=(0.1, 10.0), initial=1.0)],
                           {"bond_E": np.array([1.0]), "bond_nu": np.array([0.3])})
    return Problem(fwd, [Target("youngs_modulus", 2.0)], space)


# same specimens and run length as notebook 04 at its small size: on one worker (pytest-xdist's loadgroup), the
# notebook's compiled failure runs serve this test too (0.6 s instead of 36 s)
@pytest.mark.xdist_group("strength-150")
def test_one_dem_iteration_reads_strengths_from_the_failure_runs():
    """Real DEM: tiny specimens; the first estimate's runs report both strengths, one set = a UCS and a bending run."""
    mats = {"E": 1e9, "nu": 0.25, "tensile_strength": 4e6, "shear_strength": 8e6}
    cyl = jaxbpm.generate.cylinder(150, seed=0, packing_fraction=0.5, materials=mats).largest_cluster()
    beam = jaxbpm.generate.beam(150, seed=1, packing_fraction=0.5, materials=mats).largest_cluster()
    res = cal.calibrate_strength(cyl, beam, ucs=1e6, flexural=1.5e6, tol=1e-6, max_iterations=1,
                                 solve_options={"transits": 15})
    row = cal.strength_table(res)[0]
    assert res.evaluations == 2 and row["models"] == 1 and res.solver == "dem"
    assert row["sigma_c"] == 1.5e6 and row["tau_c"] == 1e6  # Eq. 14
    assert 0 < row["ucs"] < 1e6 and 0 < row["flexural"] < 1.5e6  # bonds at the macroscopic strengths: weaker
    # the same numbers as a direct solve
    from jaxbpm.physics.model import default_params
    from jaxbpm.scenes import ThreePointBending

    p = {**default_params(beam), "bond_tensile_strength": np.array([1.5e6]), "bond_shear_strength": np.array([1e6])}
    direct = jaxbpm.solve(beam, ThreePointBending(strain=0.1), "dem", params=p, transits=15)
    np.testing.assert_allclose(row["flexural"], direct.stats["strength"], rtol=1e-9)


def test_model_keyword_still_works_with_a_deprecation_warning():
    """``model=`` is the old name of ``solver=``: it warns, naming ``solver=``, and gives the same answer."""
    ucs, f = _targets()
    new = cal.calibrate_strength(None, None, ucs=ucs, flexural=f, solver=_stand_in(), max_iterations=4)
    with pytest.warns(DeprecationWarning, match="solver="):
        old = cal.calibrate_strength(None, None, ucs=ucs, flexural=f, model=_stand_in(), max_iterations=4)
    assert old.values == new.values and old.errors == new.errors and old.solver == new.solver == "stand-in"
