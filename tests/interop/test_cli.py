"""The ``jaxbpm convert`` and ``jaxbpm params`` commands."""

import meshio
import numpy as np

from jaxbpm import cli, io
from tests.interop.samples import _assert_same, _multi


# ============================================================================================== CLI
def test_cli_convert_and_params(tmp_path, capsys):
    sample = _multi()
    io.save_sample(tmp_path / "s.h5", sample)
    for src, dst in (("s.h5", "s.data"), ("s.data", "s.csv"), ("s.csv", "t.h5"), ("t.h5", "t.vtu")):
        assert cli.main(["convert", str(tmp_path / src), str(tmp_path / dst)]) == 0
    out = capsys.readouterr().out
    assert "wrote" in out and "s_bonds.csv" in out
    _assert_same(sample, io.load_sample(tmp_path / "t.h5"))
    assert meshio.read(tmp_path / "t.vtu").points.shape == (sample.n_particles, 3)

    assert cli.main(["params", "--from", "pfc", "--to", "jaxbpm", "emod=1e9", "kratio=2.5", "pb_rmul=0.5",
                     "--radius1", "1e-3", "--json"]) == 0
    import json

    res = json.loads(capsys.readouterr().out)
    assert np.isclose(res["parameters"]["E"], 1e9) and np.isclose(res["parameters"]["nu"], 0.25)
    assert np.isclose(res["parameters"]["bond_radius"], 0.5e-3)
    assert cli.main(["params", "--from", "jaxbpm", "--to", "lammps", "E=1e9", "nu=0.25", "bond_radius_ratio=0.5",
                     "tensile_strength=5e6", "--radius1", "1e-3"]) == 0
    out, err = capsys.readouterr()
    assert "Kr" in out and "warning:" in err and "summed" in err
    assert cli.main(["params", "--from", "yade", "--to", "jaxbpm", "young=1e9", "poisson=0.3", "alphaKr=2",
                     "alphaKtw=2", "--radius1", "1e-3"]) == 2
    assert "error:" in capsys.readouterr().err
    pos = np.asarray(sample.positions)
    rows = "\n".join(f"{i + 1} 1 {pos[i, 0] + 1e-3} {pos[i, 1]} {pos[i, 2]}" for i in range(sample.n_particles))
    (tmp_path / "run.dump").write_text(f"ITEM: TIMESTEP\n5\nITEM: NUMBER OF ATOMS\n{sample.n_particles}\n"
                                       f"ITEM: BOX BOUNDS ff ff ff\n-9 9\n-9 9\n-9 9\nITEM: ATOMS id type x y z\n"
                                       f"{rows}\n")
    assert cli.main(["convert", str(tmp_path / "run.dump"), str(tmp_path / "run.pvd"), "--sample",
                     str(tmp_path / "s.h5")]) == 0
    capsys.readouterr()
    step = meshio.read(tmp_path / "run_000000.vtu")
    np.testing.assert_allclose(step.point_data["displacement"][:, 0], 1e-3, rtol=1e-9)
    (tmp_path / "bad.data").write_text("title\n\n2 atoms\n\nAtoms\n\n1 1 1 1.0 1.0 0 0 0\n")
    assert cli.main(["convert", str(tmp_path / "bad.data"), str(tmp_path / "x.h5")]) == 2
    assert "bad.data:7: section Atoms ended after 1 of 2 lines" in capsys.readouterr().err


def test_cli_convert_never_overwrites_its_input(tmp_path, capsys):
    sample = _multi()
    src = tmp_path / "s.h5"
    io.save_sample(src, sample)
    before = src.read_bytes()
    for argv in (["convert", src, src, "--force"], ["convert", src, tmp_path / "x" / ".." / "s.h5"],
                 ["convert", tmp_path / "run.dump", tmp_path / "run.pvd", "--sample", tmp_path / "run.pvd"]):
        (tmp_path / "x").mkdir(exist_ok=True)
        assert cli.main([str(a) for a in argv]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error:") and "is the command's input" in err and "not even with --force" in err
    assert cli.main(["convert", str(src), str(tmp_path / "t.csv")]) == 0
    # a CSV sample is two files: writing t.csv replaces t_bonds.csv, an input here
    assert cli.main(["convert", str(tmp_path / "t.csv"), str(tmp_path / "t_bonds.csv"), "--force"]) == 2
    assert "its bonds file" in capsys.readouterr().err
    assert cli.main(["convert", str(tmp_path / "t.csv"), str(src)]) == 2  # an existing sample: --force
    assert "--force" in capsys.readouterr().err and src.read_bytes() == before
    assert cli.main(["convert", str(tmp_path / "t.csv"), str(src), "--force"]) == 0
    _assert_same(sample, io.load_sample(src))


def test_cli_2d_sample_and_params(tmp_path, capsys):
    """A 2D sample through HDF5 -> LAMMPS data -> CSV -> HDF5 stays the same discs; ``params --thickness`` gives
    the 2D bond's LAMMPS Kr = E 2 r_b t / L and refuses Yade."""
    import jaxbpm

    sample = jaxbpm.generate.lattice("square", (4, 3)).replace(thickness=0.2)
    io.save_sample(tmp_path / "s.h5", sample)
    for src, dst in (("s.h5", "s.data"), ("s.data", "s.csv"), ("s.csv", "t.h5")):
        assert cli.main(["convert", str(tmp_path / src), str(tmp_path / dst)]) == 0
    _assert_same(sample, io.load_sample(tmp_path / "t.h5"))
    capsys.readouterr()
    assert cli.main(["params", "--from", "jaxbpm", "--to", "lammps", "E=1e9", "nu=0.25", "bond_radius_ratio=0.5",
                     "--radius1", "1e-3", "--thickness", "0.2", "--json"]) == 0
    import json

    res = json.loads(capsys.readouterr().out)
    assert np.isclose(res["parameters"]["Kr"], 1e9 * 2 * 0.5e-3 * 0.2 / 2e-3, rtol=1e-14)
    assert np.isclose(res["stiffness"]["k_n"], res["parameters"]["Kr"], rtol=1e-14)
    assert cli.main(["params", "--from", "jaxbpm", "--to", "yade", "E=1e9", "nu=0.25", "bond_radius_ratio=0.5",
                     "--radius1", "1e-3", "--thickness", "0.2"]) == 2
    assert "no two-dimensional" in capsys.readouterr().err
