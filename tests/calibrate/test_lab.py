"""The staged laboratory calibration (jaxbpm.calibrate.lab): E, nu, UCS and BTS from wrong starting parameters."""

import json

import numpy as np
import pytest

import jaxbpm
from jaxbpm.calibrate import CalibrationError, lab
from jaxbpm.sample import BondMaterials

pytestmark = pytest.mark.xdist_group("lab")
TRUE = {"E": 1e9, "nu": 0.2, "tensile_strength": 4e6, "shear_strength": 8e6}
START = {"E": 3e8, "nu": 0.3, "tensile_strength": 1e7, "shear_strength": 1e7}


@pytest.fixture(scope="module")
def specimens():
    cyl = jaxbpm.generate.cylinder(250, seed=0, materials=TRUE).largest_cluster()
    disc = jaxbpm.generate.cylinder(300, seed=0, aspect=0.5, materials=TRUE).largest_cluster()
    elastic = jaxbpm.solve(cyl, jaxbpm.scenes.UniaxialCompression(strain=1e-3), "dsm")
    targets = {"E": elastic.youngs_modulus, "nu": elastic.poisson_ratio,
               "ucs": jaxbpm.solve(cyl, jaxbpm.scenes.UniaxialCompression.to_failure(strain=0.02), "dem",
                                   transits=30).stats["strength"],
               "bts": jaxbpm.solve(disc, jaxbpm.scenes.BrazilianDisc(), "dem", transits=30).stats["strength"]}
    start = BondMaterials.create(**START)
    return cyl.replace(materials=start), disc.replace(materials=start), targets


def test_lab_reaches_every_target_from_wrong_parameters(specimens, tmp_path):
    """Targets made by the DSM and the DEM with known bond parameters; the calibration starts 3x off in E, with the
    wrong bond nu and strengths: E and nu within 2 % (DEM check), UCS and BTS within 5 % (DEM), in few solves."""
    cyl, disc, targets = specimens
    res = lab({"ucs": cyl, "bts": disc}, targets)
    assert res.converged and not res.unreached, res.table()
    for key, (value, err) in res.achieved.items():
        assert abs(err) <= (0.02 if key in ("E", "nu") else 0.05), (key, value, err)
        np.testing.assert_allclose(value, targets[key] * (1 + err))
    assert res.stages["elastic"].evaluations <= 4
    assert res.solves["strength (DEM failure runs)"] <= 2 * 8  # at most 8 parameter sets of 2 runs
    # the answer is a set the strength stage ran: its runs give the curves and the check, none is run again
    assert res.solves["answer runs (DEM)"] == 0
    stage = res.stages["strength"]
    for key in ("ucs", "bts"):
        np.testing.assert_allclose(res.achieved[key][1], stage.errors[f"{key}.strength"], rtol=1e-12, atol=1e-15)
    # the bond strength that the tension test fixes comes back (the UCS is tension-limited here too)
    np.testing.assert_allclose(res.params["bond_tensile_strength"], TRUE["tensile_strength"], rtol=0.1)
    np.testing.assert_allclose(res.params["bond_E"], TRUE["E"], rtol=0.02)
    # translated for other codes, and a one-page report
    assert {"lammps", "pfc", "yade", "musen"} <= set(res.conventions)
    np.testing.assert_allclose(res.conventions["musen"]["tangential_strength"], res.params["bond_shear_strength"])
    md = res.report(tmp_path / "lab.md")
    assert (tmp_path / "lab.png").stat().st_size > 10_000 and "| ucs |" in md.read_text()


def test_any_subset_and_unreachable_targets(specimens):
    cyl, _, targets = specimens
    only_e = lab({"elastic": cyl}, {"E": targets["E"]}, check=None)
    assert only_e.converged and set(only_e.achieved) == {"E"} and "strength" not in only_e.stages
    # a Poisson ratio no bond nu reaches: said, and E calibrated all the same
    res = lab({"elastic": cyl}, {"E": targets["E"], "nu": 0.35}, check=None)
    assert "nu" in res.unreached and "out of this sample's reach" in res.unreached["nu"]
    assert abs(res.achieved["E"][1]) <= 0.02 and not res.converged


def test_lab_errors_and_the_command(specimens, tmp_path):
    cyl, _, targets = specimens
    with pytest.raises(CalibrationError, match="lab targets"):
        lab({"ucs": cyl}, {"young": 1e9})
    with pytest.raises(CalibrationError, match="no specimen for \\['bts'\\]"):
        lab({"ucs": cyl}, {"bts": 1e6})
    with pytest.raises(CalibrationError, match="'nu' must be in"):
        lab({"ucs": cyl}, {"nu": 0.7})
    with pytest.raises(CalibrationError, match="unknown bond failure rule 'lammps'.*'summed'"):
        lab({"ucs": cyl}, {"ucs": 1e6}, failure_rule="lammps")
    with pytest.raises(CalibrationError, match="different failure rules \\['separate', 'summed'\\]"):
        lab({"ucs": cyl, "bts": cyl}, {"ucs": 1e6, "bts": 1e5},
            scenes={"bts": jaxbpm.scenes.BrazilianDisc(failure_rule="summed")})
    jaxbpm.io.save_sample(tmp_path / "cyl.h5", cyl)
    (tmp_path / "lab.json").write_text(json.dumps({"lab": {"targets": {"E": targets["E"], "nu": targets["nu"]},
                                                           "options": {"check": None}, "report": "out.md"}}))
    from jaxbpm.cli import main

    assert main(["calibrate", str(tmp_path / "cyl.h5"), "--config", str(tmp_path / "lab.json"), "--quiet"]) == 0
    assert (tmp_path / "out.md").exists() and (tmp_path / "out.png").exists()


def test_elastic_model_is_the_old_name_of_elastic_solver():
    with pytest.warns(DeprecationWarning, match="elastic_solver="):
        with pytest.raises(CalibrationError, match="lab targets"):
            lab({}, {"young": 1e9}, elastic_model="dsm")


def test_strength_advice_says_out_of_reach_when_a_bound_stops_it(monkeypatch):
    """``lab`` advised "raise max_iterations" for a target no bond strength can reach; with the strength pinned at
    a bound of its range (``info["unreachable"]`` of the strength stage) it says the target is out of reach."""
    import importlib
    import types

    lab_module = importlib.import_module("jaxbpm.calibrate.lab")

    def stage(unreachable):
        return types.SimpleNamespace(
            converged=False, errors={"ucs.strength": -0.9, "bts.strength": 0.2}, iterations=6, evaluations=9,
            values={}, info={"unreachable": unreachable})

    monkeypatch.setattr(lab_module, "_curves", lambda *args, **kwargs: ({}, 0))
    for unreachable, expected in (
            ([{"target": "ucs.strength", "pinned": [("bond_shear_strength", "upper", 8e9)]}],
             {"ucs": "out of reach of the bond strength range (best -90.0%): bond_shear_strength at its upper bound "
                     "8e+09; more iterations will not reach it", "bts": "raise max_iterations"}),
            ([], {"ucs": "raise max_iterations", "bts": "raise max_iterations"})):
        monkeypatch.setattr(lab_module, "_strength_stage", lambda *args, _u=unreachable, **kwargs: stage(_u))
        unreached = {}
        lab_module._strengths({}, {}, {"ucs": 1.0, "bts": 1.0}, ["ucs", "bts"],
                              {"bond_tensile_strength": 1.0, "bond_shear_strength": 1.0}, {}, unreached, {}, {},
                              tol=0.05, max_iterations=6, fd_step=0.2, solve_options=None, executor=None,
                              progress=False)
        for key, text in expected.items():
            assert text in unreached[key], (key, unreached[key])
        assert ("raise max_iterations" in unreached["ucs"]) == (not unreachable)


def test_first_jacobian_takes_the_estimates_secant_and_perturbs_across_it():
    """On strengths linear in log space, the Jacobian from the two estimates' secant and ``n - 1`` perturbed sets
    is the exact one; with no other set far enough, every axis is perturbed (``n`` sets)."""
    from jaxbpm.calibrate.lab import _first_jacobian

    rng = np.random.default_rng(0)
    for n in (1, 2, 3):
        A, b = rng.normal(size=(2, n)), rng.normal(size=2)
        calls = []

        def run(points, kind, A=A, b=b):
            calls.append((kind, len(points)))
            return points @ A.T + b

        x1, x2 = rng.normal(size=n), rng.normal(size=n) + 2.0
        seen = [(x1, x1 @ A.T + b), (x2, x2 @ A.T + b)]
        J = _first_jacobian(run, x2, x2 @ A.T + b, seen, np.log1p(0.05))
        np.testing.assert_allclose(J, A, rtol=1e-9, atol=1e-12)
        assert sum(k for _, k in calls) == n - 1
        calls.clear()
        J = _first_jacobian(run, x2, x2 @ A.T + b, seen[1:], np.log1p(0.05))
        np.testing.assert_allclose(J, A, rtol=1e-9, atol=1e-12)
        assert calls == [("fd", n)]


def test_fitted_jacobian_is_the_plane_through_the_sets_seen():
    """Exact on strengths linear in log space (any sets that span the parameters); ``J`` kept where they do not.
    On a UCS that bends (it stops rising with tau_c once tension-limited), the plane through sets on either side of
    the target gives a step towards it from the best set, which lies on the flat part."""
    from jaxbpm.calibrate.lab import _fitted_jacobian

    rng = np.random.default_rng(1)
    A, b = rng.normal(size=(2, 2)), rng.normal(size=2)
    pts = rng.normal(size=(4, 2))
    np.testing.assert_allclose(_fitted_jacobian([(p, p @ A.T + b) for p in pts], None), A, rtol=1e-9, atol=1e-12)
    J0 = np.eye(2)
    line = [(np.array([t, 2 * t]), np.array([t, t])) for t in (0.0, 1.0, 2.0)]
    assert _fitted_jacobian(line, J0) is J0 and _fitted_jacobian(line[:2], J0) is J0

    def r(x):  # log strength / target: flexural ~ sigma_c; the UCS rises with tau_c below a knee, flat above it
        return np.array([x[0], 0.1 + np.minimum(x[1], 0.0)])

    # the best set (flat part, UCS +10 %), the perturbed set across, a step far down (UCS -60 %), one back up
    sets = [np.array(p) for p in ([0.0, 0.3], [0.1, 0.35], [0.02, -0.7], [0.01, 0.1])]
    J = _fitted_jacobian([(p, r(p)) for p in sets], J0)
    x = sets[0] + np.linalg.solve(J, -r(sets[0]))  # the Gauss-Newton step from the best set
    # a step of tau_c down towards the UCS target (at -0.1), not past the set below it (the flat part's own slope,
    # 0, gives no step at all)
    assert -0.7 < x[1] < sets[0][1] - 0.1 and abs(x[0]) < 0.05, (J, x)


def test_probe_step_reaches_past_a_flat_part():
    """A bond strength the strengths barely follow, with its tied target missed, is probed once by a factor 2 in
    the direction the target asks for; a followed one, a met target or a second time: no probe."""
    from jaxbpm.calibrate.lab import _probe_step

    J = np.array([[1.0, 0.01], [0.9, 0.02]])  # flexural and UCS against (log sigma_c, log tau_c)
    tied = [0, 1]  # sigma_c to the flexural strength, tau_c to the UCS
    probed = set()
    dx = _probe_step(J, np.log1p(np.array([-0.06, 0.10])), tied, probed, 0.05)
    np.testing.assert_allclose(dx, [0.0, -np.log(2.0)])  # the UCS 10 % high: tau_c halved
    assert probed == {1} and _probe_step(J, np.log1p(np.array([-0.06, 0.10])), tied, probed, 0.05) is None
    assert _probe_step(J, np.log1p(np.array([-0.06, 0.03])), tied, set(), 0.05) is None  # the UCS within tol
    dx = _probe_step(J, np.log1p(np.array([-0.06, -0.2])), tied, set(), 0.05)
    np.testing.assert_allclose(dx, [0.0, np.log(2.0)])  # the UCS low: tau_c doubled


def test_conventions_of_a_2d_sample():
    """A 2D sample's answer in other codes: LAMMPS (dimension 2) from the 2 r_b x t rectangle (A = 2 r_b t,
    I = (2 r_b)^3 t / 12), PFC2D's per-area values, and no numbers for the codes without a 2D form."""
    import importlib

    translations = importlib.import_module("jaxbpm.calibrate.lab")._translations
    sample = jaxbpm.generate.lattice("square", (4, 3)).replace(thickness=0.3)
    params = {"bond_E": 1e9, "bond_nu": 0.25, "bond_tensile_strength": 2e6, "bond_shear_strength": 3e6}
    out = translations(sample, params)
    r = float(np.mean(sample.radii))
    rb, t, L = 0.5 * r, 0.3, 2 * r
    A, I = 2 * rb * t, (2 * rb) ** 3 * t / 12
    np.testing.assert_allclose([out["lammps"][k] for k in ("Kr", "Kb", "Fcr", "Tcb")],
                               [1e9 * A / L, 1e9 * I / L, 2e6 * A, 2e6 * I / rb], rtol=1e-12)
    np.testing.assert_allclose([out["pfc"]["pb_kn"], out["pfc"]["pb_rmul"], out["pfc"]["kratio"]], [1e9 / L, 0.5, 2.5])
    assert out["jaxbpm"]["thickness"] == 0.3
    assert set(out["yade"]) == {"2D"} and "no two-dimensional" in out["musen"]["2D"]


def test_lab_on_discs_uses_the_plane_scenes():
    """2D specimens (a rectangle and a disc of discs): the default scenes load in the plane with linear contacts; E and
    nu within 2 %, UCS and BTS within 5 % by the same tests run with the true parameters, from a start 3x off."""
    rect = jaxbpm.generate.disc_packing(200, "rectangle", aspect=(1, 2), seed=0, materials=TRUE).largest_cluster()
    disc = jaxbpm.generate.disc_packing(200, "disc", seed=0, materials=TRUE).largest_cluster()
    scenes = {"ucs": jaxbpm.scenes.UniaxialCompression.to_failure(strain=0.02, axis=1, contact_law="linear"),
              "bts": jaxbpm.scenes.BrazilianDisc(contact_law="linear")}
    elastic = jaxbpm.solve(rect, jaxbpm.scenes.UniaxialCompression(strain=1e-3, axis=1), "dsm")
    targets = {"E": elastic.youngs_modulus, "nu": elastic.poisson_ratio,
               "ucs": jaxbpm.solve(rect, scenes["ucs"], "dem", transits=30).stats["strength"],
               "bts": jaxbpm.solve(disc, scenes["bts"], "dem", transits=30).stats["strength"]}
    start = BondMaterials.create(**START)
    res = lab({"ucs": rect.replace(materials=start), "bts": disc.replace(materials=start)}, targets)
    assert res.converged and not res.unreached, res.table()
    for key, (value, err) in res.achieved.items():
        assert abs(err) <= (0.02 if key in ("E", "nu") else 0.05), (key, value, err)
    np.testing.assert_allclose(res.params["bond_tensile_strength"], TRUE["tensile_strength"], rtol=0.1)
    assert res.solves["strength (DEM failure runs)"] <= 2 * 8
    with pytest.raises(CalibrationError, match="mix 2D and 3D"):
        lab({"ucs": rect, "bts": jaxbpm.generate.cylinder(100, seed=0)}, {"ucs": 1e6, "bts": 1e5})
