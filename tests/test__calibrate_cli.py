"""The ``jaxbpm calibrate`` command: a calibration end to end, the config and the options that override it."""

import json

import numpy as np
import pytest

import jaxbpm
from jaxbpm import cli, io
from jaxbpm.io import save_sample
from jaxbpm.sample import Domain, Sample
from jaxbpm.scenes import UniaxialCompression

pytestmark = pytest.mark.xdist_group("calibrate-module")


@pytest.fixture(scope="module")
def one():
    return jaxbpm.generate.lattice("fcc", (3, 3, 4), 1e-3, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})


def _modulus(sample, params):
    return jaxbpm.solve(sample, UniaxialCompression(strain=0.002), "dsm", params=params).youngs_modulus


def _run(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _tiny():
    return Sample.from_arrays(np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0]]), 0.5, [[0, 1], [1, 2]],
                              bond_radius_ratio=0.5, domain=Domain("box", (-0.5, -0.5, -0.5), (1.5, 1.5, 0.5)))


def test_cli_calibrate(one, tmp_path, capsys):
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


def test_calibrate_options_override_the_config(tmp_path, capsys, monkeypatch):
    """defaults < --config < options given on the command line."""
    import jaxbpm.calibrate
    from jaxbpm.errors import JaxbpmError

    calls = []

    def fake_calibrate(sample, scene, targets, **kw):
        calls.append({k: kw[k] for k in ("method", "solver", "tol")})
        raise JaxbpmError("stop after the options")

    monkeypatch.setattr(jaxbpm.calibrate, "calibrate", fake_calibrate)
    sample = io.save_sample(tmp_path / "s.h5", _tiny())
    config = tmp_path / "config.json"
    config.write_text(json.dumps({"method": "adam", "solver": "ste", "tol": 0.02}))
    for argv, expected in (
            ([], {"method": "auto", "solver": "dsm", "tol": None}),  # the defaults (tol: calibrate's, for the targets)
            (["--config", config], {"method": "adam", "solver": "ste", "tol": 0.02}),  # the config over them
            (["--config", config, "--solver", "dem", "--tol", 0.1], {"method": "adam", "solver": "dem", "tol": 0.1}),
            (["--method", "surrogate", "--config", config], {"method": "surrogate", "solver": "ste", "tol": 0.02}),
            (["--solver", "dsm", "--config", config], {"method": "adam", "solver": "dsm", "tol": 0.02})):  # = default
        code, _, err = _run(capsys, "calibrate", sample, "--target-E", 1e9, *argv)
        assert code == 2 and "stop after the options" in err
        assert calls[-1] == expected, argv


def test_old_solver_option_and_config_key_still_read(tmp_path, capsys, monkeypatch):
    """``--model`` and the config key ``"model"`` are the old names of ``--solver`` and ``"solver"``: still read,
    with a warning that names the new one."""
    import jaxbpm.calibrate
    from jaxbpm.errors import JaxbpmError

    calls = []

    def fake_calibrate(sample, scene, targets, **kw):
        calls.append(kw["solver"])
        raise JaxbpmError("stop after the options")

    monkeypatch.setattr(jaxbpm.calibrate, "calibrate", fake_calibrate)
    sample = io.save_sample(tmp_path / "s.h5", _tiny())
    code, _, err = _run(capsys, "calibrate", sample, "--target-E", 1e9, "--model", "ste")
    assert code == 2 and calls[-1] == "ste" and "--model is deprecated" in err and "--solver" in err
    config = tmp_path / "config.json"
    config.write_text(json.dumps({"model": "dem"}))
    code, _, err = _run(capsys, "calibrate", sample, "--target-E", 1e9, "--config", config)
    assert code == 2 and calls[-1] == "dem" and '"model" is deprecated' in err and '"solver"' in err
    config.write_text(json.dumps({"model": "dem", "solver": "ste"}))
    code, _, err = _run(capsys, "calibrate", sample, "--target-E", 1e9, "--config", config)
    assert code == 2 and 'give "solver" only' in err


def test_history_never_replaces_the_input_sample(tmp_path, capsys, monkeypatch):
    """``--history s.h5`` onto the calibrated sample: refused before any calibration, even with ``--force``; an
    existing record needs ``--force``; the runs file of a config may not be the sample either."""
    import jaxbpm.calibrate

    def must_not_run(*args, **kwargs):
        raise AssertionError("the calibration ran before the outputs were checked")

    monkeypatch.setattr(jaxbpm.calibrate, "calibrate", must_not_run)
    sample = tmp_path / "s.h5"
    save_sample(sample, _tiny())
    before = sample.read_bytes()
    for extra in ([], ["--force"]):
        code, _, err = _run(capsys, "calibrate", sample, "--target-E", 1.5e8, "--history", sample, *extra)
        assert code == 2 and f"--history {sample}" in err and "input SAMPLE" in err
    old = tmp_path / "old.h5"
    save_sample(old, _tiny())
    code, _, err = _run(capsys, "calibrate", sample, "--target-E", 1.5e8, "--history", old)
    assert code == 2 and "--force" in err
    cfg = tmp_path / "c.json"
    cfg.write_text(json.dumps({"options": {"runs_file": str(sample)}}))
    code, _, err = _run(capsys, "calibrate", sample, "--target-E", 1.5e8, "--config", cfg)
    assert code == 2 and "runs_file" in err and "input SAMPLE" in err
    lab_cfg = tmp_path / "lab.json"
    lab_cfg.write_text(json.dumps({"lab": {"targets": {"E": 1e9}, "samples": {"ucs": "s.h5"}, "report": "s.h5"}}))
    code, _, err = _run(capsys, "calibrate", old, "--config", lab_cfg, "--force")
    assert code == 2 and 'lab "report"' in err and "input" in err
    assert sample.read_bytes() == before


def test_an_unreachable_target_is_said_on_the_command_line(one, tmp_path, capsys):
    path = tmp_path / "s.h5"
    save_sample(path, one)
    code, out, _ = _run(capsys, "calibrate", path, "--target-E", 1e15, "--method", "closed-form", "--quiet")
    assert code == 1
    assert "target youngs_modulus = 1e+15 is out of reach of the parameter range: bond_E" in out
    assert "at its upper bound" in out and "closest value reached" in out
