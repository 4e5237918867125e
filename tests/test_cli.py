"""The ``jaxbpm`` command, end to end in a temporary directory."""

import json
import os
import pathlib
import subprocess
import sys
import textwrap

import meshio
import numpy as np
import pytest

from jaxbpm import cli, generate, io
from jaxbpm.sample import Domain, Sample


def _run(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _tiny(**kw):
    return Sample.from_arrays(np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0]]), 0.5, [[0, 1], [1, 2]],
                              bond_radius_ratio=0.5, domain=Domain("box", (-0.5, -0.5, -0.5), (1.5, 1.5, 0.5)), **kw)


def test_generate_info_export_sc(tmp_path, capsys):
    out = tmp_path / "sc.h5"
    code, stdout, err = _run(capsys, "generate", "--shape", "sc", "--n", 27, "--seed", 3, "--out", out,
                             "--mean-radius", 2e-3, "--E", 5e9, "--nu", 0.2, "--quiet")
    assert code == 0, err
    assert "particles            27" in stdout and f"wrote {out}" in stdout and " s)" in stdout
    sample = io.load_sample(out)
    assert sample.n_particles == 27 and sample.n_bonds == 54
    assert np.allclose(sample.radii, 2e-3) and np.allclose(sample.bond_radius, 1e-3)
    assert np.array_equal(sample.materials.E, [5e9]) and np.array_equal(sample.materials.nu, [0.2])

    code, stdout, _ = _run(capsys, "info", out)
    assert code == 0 and str(sample.summary()) in stdout

    for suffix in (".vtu", ".vtk"):
        vtk = tmp_path / f"sc{suffix}"
        code, stdout, err = _run(capsys, "export-vtk", out, vtk)
        assert code == 0, err
        assert str(vtk) in stdout
        mesh = meshio.read(vtk)
        assert mesh.points.shape == (27, 3)
        assert {c.type: len(c.data) for c in mesh.cells} == {"vertex": 27, "line": 54}
        assert np.allclose(mesh.point_data["radius"], 2e-3)


def test_generate_forwards_only_applicable_options(tmp_path, capsys, monkeypatch):
    calls = []

    def fake_from_shape(shape, n, *, seed=0, progress=False, **kw):
        calls.append(dict(shape=shape, n=n, seed=seed, progress=progress, **kw))
        return _tiny()

    monkeypatch.setattr(generate, "from_shape", fake_from_shape, raising=False)
    code, _, err = _run(capsys, "generate", "--shape", "fcc", "--n", 50, "--out", tmp_path / "a.h5",
                        "--spread", 0.1, "--bond-radius-ratio", 0.3)
    assert code == 0 and "--spread ignored" in err
    assert calls[-1] == dict(shape="fcc", n=50, seed=0, progress=True, bond_radius_ratio=0.3,
                             materials={"E": 1e9, "nu": 0.25})
    code, _, _ = _run(capsys, "generate", "--shape", "sc", "--n", 8, "--out", tmp_path / "b.h5", "--mean-radius", 0.01,
                      "--quiet")
    assert code == 0 and calls[-1]["radius"] == 0.01 and calls[-1]["progress"] is False
    assert "mean_radius" not in calls[-1] and "packing_fraction" not in calls[-1]

    code, _, _ = _run(capsys, "generate", "--shape", "cylinder", "--n", 100, "--seed", 7, "--out", tmp_path / "c.h5",
                      "--mean-radius", 0.01, "--packing-fraction", 0.55, "--E", 2e9)
    assert code == 0
    assert calls[-1] == dict(shape="cylinder", n=100, seed=7, progress=True, mean_radius=0.01, radius_spread=0.05,
                             packing_fraction=0.55, bond_radius_ratio=0.5, materials={"E": 2e9, "nu": 0.25})
    assert "radius" not in calls[-1]
    assert io.load_sample(tmp_path / "c.h5").n_particles == 3


def test_generate_random_box(tmp_path, capsys):
    out = tmp_path / "box.h5"
    code, stdout, err = _run(capsys, "generate", "--shape", "box", "--n", 200, "--seed", 1, "--out", out,
                             "--packing-fraction", 0.5, "--quiet")
    assert code == 0, err
    sample = io.load_sample(out)
    assert sample.n_particles == 200 and sample.n_bonds > 0 and sample.domain is not None
    assert str(sample.summary()) in stdout


def _chain(n):
    """n particles in a bonded chain: a stand-in for a random packing where only the plumbing is under test."""
    pos = np.arange(n)[:, None] * np.array([2e-3, 0.0, 0.0])
    return Sample.from_arrays(pos, 1e-3, np.stack([np.arange(n - 1), np.arange(1, n)], axis=1),
                              bond_radius_ratio=0.5)


def test_demo(tmp_path, capsys, monkeypatch):
    # The random packing itself is covered by test_generate_random_box; a real 300-particle packing at the
    # generator's default packing fraction takes tens of seconds, so the demo's plumbing runs on a stand-in.
    calls = []

    def fake_from_shape(shape, n, *, seed=0, progress=False, **kw):
        calls.append(dict(shape=shape, n=n, seed=seed, progress=progress, **kw))
        return generate.lattice("sc", (3, 3, 6), 1e-3)  # small and exact: the solvers agree on it

    monkeypatch.setattr(generate, "from_shape", fake_from_shape, raising=False)
    out_dir = tmp_path / "demo"
    code, stdout, err = _run(capsys, "demo", "--out", out_dir, "--n", 300, "--seed", 2, "--quiet")
    assert code == 0, err
    assert calls == [dict(shape="box", n=300, seed=2, progress=False)]
    sample = io.load_sample(out_dir / "demo_sample.h5")
    assert sample.n_particles == 54 and str(sample.summary()) in stdout
    assert "demo_sample.h5" in stdout
    # the comparison table: DSM within 1 % of the DEM on this lattice; the STE (an estimate from local tensors,
    # here of a sample that is almost all surface) within 15 %
    report = json.loads((out_dir / "demo_results.json").read_text())
    methods = {row["method"]: row for row in report["results"]}
    assert set(methods) == {"dem", "dsm", "dsm stol 1e-3", "ste"}
    for name, row in methods.items():
        assert abs(row["difference_to_dem"]) < (0.15 if name == "ste" else 1e-2), row
    assert "vs DEM" in stdout
    # the table says which ratio is which and spells out the methods; the calibration's levels are explained
    assert "run ratio" in stdout and "wall ratio" in stdout and "the whole call (setup + compile + run)" in stdout
    for name in cli._DEMO_NAMES.values():
        assert name in stdout
    assert "(calibrated: " in stdout
    # the calibration reaches the target, checked by the DEM, and the chart is written
    cal = report["calibration"]
    assert cal["errors"]["youngs_modulus"] < 0.01 and cal["evaluations"] <= 8
    assert (out_dir / "demo_speed_accuracy.png").stat().st_size > 10_000


def test_demo_defaults(tmp_path, monkeypatch, capsys):
    calls = []
    monkeypatch.setattr(generate, "from_shape", lambda shape, n, **kw: calls.append((shape, n, kw)) or _chain(5),
                        raising=False)
    monkeypatch.chdir(tmp_path)
    assert cli.main(["demo", "--no-solve"]) == 0
    assert calls == [("box", 2000, {"seed": 0, "progress": True})]
    assert (tmp_path / "jaxbpm-demo" / "demo_sample.h5").is_file()
    result = cli.run_demo(tmp_path / "again", n=7, seed=1, quiet=True, solve=False)
    assert result["sample_path"] == tmp_path / "again" / "demo_sample.h5" and result["sample"].n_particles == 5


def test_a_second_demo_into_the_same_folder_says_so(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(generate, "from_shape", lambda shape, n, **kw: _chain(5), raising=False)
    out_dir = tmp_path / "demo"
    assert _run(capsys, "demo", "--no-solve", "--out", out_dir)[0] == 0
    (out_dir / "notes.txt").write_text("mine")
    first = (out_dir / "demo_sample.h5").read_bytes()
    code, _, err = _run(capsys, "demo", "--no-solve", "--out", out_dir, "--seed", 3)
    assert code == 2 and "earlier demo's files (demo_sample.h5)" in err and "--force" in err
    assert (out_dir / "demo_sample.h5").read_bytes() == first  # nothing was written
    code, out, _ = _run(capsys, "demo", "--no-solve", "--out", out_dir, "--force")
    assert code == 0 and "replacing the earlier demo's files" in out
    assert (out_dir / "notes.txt").read_text() == "mine"  # the folder's other files are left alone


@pytest.mark.parametrize("argv", [["--help"], ["generate", "--help"], ["info", "--help"], ["export-vtk", "--help"],
                                  ["demo", "--help"], ["--version"]])
def test_help_and_version(capsys, argv):
    with pytest.raises(SystemExit) as exc:
        cli.main(argv)
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert ("jaxbpm 0.1.0" in out) if argv == ["--version"] else ("usage: jaxbpm" in out and len(out) > 200)


@pytest.mark.parametrize("argv", [[], ["frobnicate"], ["generate", "--shape", "torus", "--n", "5", "--out", "x.h5"],
                                  ["generate", "--shape", "sc", "--n", "-3", "--out", "x.h5"], ["info"]])
def test_usage_errors_exit_2(capsys, argv):
    with pytest.raises(SystemExit) as exc:
        cli.main(argv)
    assert exc.value.code == 2
    assert "usage:" in capsys.readouterr().err


def test_errors_are_one_line_exit_2(tmp_path, capsys):
    code, out, err = _run(capsys, "info", tmp_path / "missing.h5")
    assert code == 2 and err.startswith("error: ") and "missing.h5" in err and "Traceback" not in err

    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5 at all" * 100)
    code, _, err = _run(capsys, "export-vtk", junk, tmp_path / "j.vtu")
    assert code == 2 and "error: " in err and "junk.h5" in err

    good = io.save_sample(tmp_path / "good.h5", _tiny())
    code, _, err = _run(capsys, "export-vtk", good, tmp_path / "out.txt")
    assert code == 2 and ".vtu" in err
    code, _, err = _run(capsys, "export-vtk", good, tmp_path / "no" / "dir" / "out.vtu")
    assert code == 2 and err.startswith("error: ") and "no such directory" in err
    code, _, err = _run(capsys, "generate", "--shape", "sc", "--n", 8, "--out", tmp_path / "nodir" / "x.h5", "--quiet")
    assert code == 2 and err.startswith("error: ")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["good.h5", "junk.h5"]


@pytest.mark.parametrize("command, option", [("calibrate", "--target-E"), ("convert", "--normalize"),
                                             ("params", "--radius1")])
def test_help_of_the_commands_loaded_on_use(capsys, command, option):
    with pytest.raises(SystemExit) as exc:
        cli.main(["--help"])
    out = capsys.readouterr().out
    assert exc.value.code == 0 and command in out and cli._LAZY_COMMANDS[command][:30] in out.replace("\n", " ")
    with pytest.raises(SystemExit) as exc:
        cli.main([command, "--help"])
    out = capsys.readouterr().out
    assert exc.value.code == 0 and f"usage: jaxbpm {command}" in out and option in out and "--cache-dir" in out


def test_help_and_version_import_no_jax():
    """``jaxbpm --help``, ``--version`` and ``COMMAND --help`` (of commands defined in jaxbpm.cli, and of ``convert``
    and ``params``, defined in jaxbpm.interop.cli, and ``calibrate``) answer without importing JAX; ``import jaxbpm`` imports none either
    and still lists every public name."""
    code = textwrap.dedent("""
        import contextlib, io, sys
        import jaxbpm, jaxbpm.cli
        assert set(jaxbpm.__all__) <= set(dir(jaxbpm)), set(jaxbpm.__all__) - set(dir(jaxbpm))
        jaxbpm.cli.build_parser().parse_args(["info", "x.h5", "--no-cache"])
        out = io.StringIO()
        for argv in (["--help"], ["--version"], ["generate", "--help"], ["demo", "--help"], ["info", "--help"],
                     ["export-vtk", "--help"], ["convert", "--help"], ["params", "--help"], ["calibrate", "--help"]):
            with contextlib.redirect_stdout(out):
                try:
                    jaxbpm.cli.main(argv)
                except SystemExit as exc:
                    assert exc.code == 0, argv
        assert "jax" not in sys.modules, [m for m in sys.modules if m.startswith("jaxbpm")]
        print(out.getvalue())
    """)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=_env())
    assert res.returncode == 0, res.stderr
    assert "usage: jaxbpm" in res.stdout and "jaxbpm 0.1.0" in res.stdout and "--packing-fraction" in res.stdout
    assert "usage: jaxbpm convert" in res.stdout and ".vtkhdf" in res.stdout and "--radius1" in res.stdout


def _env():
    env = dict(os.environ)
    env["JAX_PLATFORMS"] = "cpu"
    return env


def test_console_script_help():
    script = pathlib.Path(sys.executable).with_name("jaxbpm")
    cmd = [str(script)] if script.exists() else [sys.executable, "-m", "jaxbpm"]
    res = subprocess.run(cmd + ["--help"], capture_output=True, text=True, timeout=120, env=_env())
    assert res.returncode == 0 and "usage: jaxbpm" in res.stdout and "export-vtk" in res.stdout


def test_python_m_missing_file(tmp_path):
    res = subprocess.run([sys.executable, "-m", "jaxbpm", "info", "missing.h5"], capture_output=True, text=True,
                         timeout=120, cwd=tmp_path, env=_env())
    assert res.returncode == 2
    assert "error:" in res.stderr and "missing.h5" in res.stderr and "Traceback" not in res.stderr


def test_generate_checks_its_output_before_packing(tmp_path, capsys, monkeypatch):
    def must_not_run(*args, **kwargs):
        raise AssertionError("the packing ran before the output path was checked")

    monkeypatch.setattr(generate, "from_shape", must_not_run, raising=False)
    code, _, err = _run(capsys, "generate", "--shape", "box", "--n", 50, "--out", tmp_path / "missing" / "x.h5")
    assert code == 2 and "no such directory" in err and "missing" in err
    code, _, err = _run(capsys, "generate", "--shape", "box", "--n", 50, "--out", tmp_path)
    assert code == 2 and "it is a directory" in err and ".tmp" not in err
    code, _, err = _run(capsys, "generate", "--shape", "box", "--n", 50, "--out", tmp_path / "w.h5",
                        "--bond-radius-ratio", 1.5)
    assert code == 2 and "--bond-radius-ratio 1.5 > 1" in err and "wide_bonds=True" in err


def test_negative_and_out_of_range_numbers_get_the_options_own_message(tmp_path, capsys):
    """``--E -1e8`` reached argparse as an option ("expected one argument"); ``--spread 5`` made negative radii."""
    with pytest.raises(SystemExit) as exc:
        cli.main(["generate", "--shape", "box", "--n", "50", "--E", "-1e8", "--out", str(tmp_path / "x.h5")])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "--E: expected a finite number > 0, got -1e8" in err
    code, _, err = _run(capsys, "generate", "--shape", "box", "--n", 50, "--spread", 5, "--out", tmp_path / "x.h5")
    assert code == 2 and "radius_spread must be < 1" in err and "Traceback" not in err
    good = io.save_sample(tmp_path / "good.h5", _tiny())
    code, _, err = _run(capsys, "calibrate", good, "--target-E", "-1e8")
    assert code == 2 and err.startswith("error: ") and "must be > 0" in err and "np." not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["good.h5"]


def test_no_command_overwrites_an_input_or_a_sample(tmp_path, capsys, monkeypatch):
    """``generate --out`` over a sample needs ``--force``; ``export-vtk`` onto its own input is refused even with it;
    nothing is packed or written before the refusal."""
    def must_not_run(*args, **kwargs):
        raise AssertionError("the packing ran before the output path was checked")

    sample = tmp_path / "s.h5"
    io.save_sample(sample, _tiny())
    before = sample.read_bytes()
    monkeypatch.setattr(generate, "from_shape", must_not_run, raising=False)
    code, _, err = _run(capsys, "generate", "--shape", "box", "--n", 50, "--out", sample)
    assert code == 2 and f"--out {sample}" in err and "--force" in err and err.startswith("error:")
    for argv in (["export-vtk", sample, sample], ["export-vtk", sample, tmp_path / "." / "s.h5", "--force"]):
        code, _, err = _run(capsys, *argv)
        assert code == 2 and "input SAMPLE" in err and "not even with --force" in err
    assert sample.read_bytes() == before
    monkeypatch.setattr(generate, "from_shape", lambda shape, n, **kw: _chain(4), raising=False)
    code, _, err = _run(capsys, "generate", "--shape", "box", "--n", 4, "--out", sample, "--force", "--quiet")
    assert code == 0, err
    assert io.load_sample(sample).n_particles == 4


def test_demo_reuses_its_folder_but_not_a_file(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(generate, "from_shape", lambda shape, n, **kw: _chain(5), raising=False)
    afile = tmp_path / "notes.txt"
    afile.write_text("keep")
    code, _, err = _run(capsys, "demo", "--out", afile, "--no-solve", "--quiet")
    assert code == 2 and "--out" in err and "folder" in err and afile.read_text() == "keep"
    for force in ([], ["--force"]):  # the second run replaces the demo's own files (with --force)
        assert _run(capsys, "demo", "--out", tmp_path / "d", "--no-solve", "--quiet", *force)[0] == 0
    (tmp_path / "e" / "demo_sample.h5").mkdir(parents=True)
    code, _, err = _run(capsys, "demo", "--out", tmp_path / "e", "--no-solve", "--quiet", "--force")
    assert code == 2 and "directory" in err
