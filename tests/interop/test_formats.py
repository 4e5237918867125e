"""The format dispatch of jaxbpm.interop.formats (reading, writing and converting by suffix), and the old module
names gone."""

import h5py
import numpy as np
import pytest

from jaxbpm.interop import formats
from tests.interop.samples import _lattice


def test_convert_dump_to_vtkhdf(tmp_path):
    sample = _lattice()
    n = sample.n_particles
    pos = np.asarray(sample.positions)
    lines = []
    for step in (0, 10):
        lines += ["ITEM: TIMESTEP", str(step), "ITEM: NUMBER OF ATOMS", str(n), "ITEM: BOX BOUNDS pp pp pp",
                  "-1 1", "-1 1", "-1 1", "ITEM: ATOMS id x y z"]
        lines += [f"{i + 1} {x + 1e-5 * step!r} {y!r} {z!r}" for i, (x, y, z) in enumerate(pos.tolist())]
    (tmp_path / "run.dump").write_text("\n".join(lines) + "\n")
    written = formats.convert(tmp_path / "run.dump", tmp_path / "run.vtkhdf", sample=sample)
    assert written == [tmp_path / "run.vtkhdf"]
    with h5py.File(written[0], "r") as f:
        assert list(f["VTKHDF/Steps/Values"]) == [0.0, 10.0]
        np.testing.assert_allclose(f["VTKHDF/Points"][n:, 0], pos[:, 0] + 1e-4)


def test_convert_2d_dump_to_vtkhdf(tmp_path):
    """A LAMMPS dimension 2 run's dump (z = 0) converts with a 2D reference sample; atoms at several z are refused."""
    import jaxbpm
    from jaxbpm.errors import SampleFileError

    sample = jaxbpm.generate.lattice("square", (3, 4))
    n, pos = sample.n_particles, np.asarray(sample.positions)

    def dump(z):
        lines = ["ITEM: TIMESTEP", "5", "ITEM: NUMBER OF ATOMS", str(n), "ITEM: BOX BOUNDS ff ff pp", "-1 1", "-1 1",
                 "-0.5 0.5", "ITEM: ATOMS id x y z"]
        lines += [f"{i + 1} {x + 1e-5!r} {y!r} {z[i]!r}" for i, (x, y) in enumerate(pos.tolist())]
        (tmp_path / "run.dump").write_text("\n".join(lines) + "\n")

    dump([0.0] * n)
    written = formats.convert(tmp_path / "run.dump", tmp_path / "run.vtkhdf", sample=sample)
    with h5py.File(written[0], "r") as f:
        np.testing.assert_allclose(f["VTKHDF/Points"][:, :2], pos + [1e-5, 0.0])
        assert not np.any(f["VTKHDF/Points"][:, 2])
    dump([0.0] * (n - 1) + [1e-6])
    with pytest.raises(SampleFileError, match="different z"):
        formats.convert(tmp_path / "run.dump", tmp_path / "run2.vtkhdf", sample=sample)




def test_old_module_names_are_gone():
    # the format and convention modules live in jaxbpm.interop only (no jaxbpm.formats, jaxbpm.conventions)
    import pathlib

    import jaxbpm

    for old in ("formats", "conventions"):
        assert not (pathlib.Path(jaxbpm.__file__).parent / f"{old}.py").exists()
        assert old not in jaxbpm._LAZY and old not in dir(jaxbpm)
        with pytest.raises(AttributeError):
            getattr(jaxbpm, old)
