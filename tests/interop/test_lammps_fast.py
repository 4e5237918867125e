"""The one-go reader of LAMMPS data files (jaxbpm.interop._lammps_fast): what the line-by-line reader gives, and
nothing (``None``) for files that are not plainly regular."""

import warnings

import jax
import numpy as np

from jaxbpm.interop import _lammps_fast, formats, lammps
from jaxbpm.interop.conventions import InexactTranslationWarning
from tests.interop.samples import _multi, _sample


def test_lammps_data_fast_and_line_by_line_reading_agree(tmp_path):
    """Files read in one go per section give what reading them line by line gives; files that are not plainly
    regular (leading blanks, comments, blank lines inside a section) are read line by line."""
    written = formats.write_lammps_data(tmp_path / "s.data", _multi()).read_text()
    lines = written.splitlines()
    plain = "\n".join(ln.split("#")[0].rstrip() if not ln.startswith(("Atoms", "Bond Coeffs")) else ln
                      for ln in lines[1:] if not ln.startswith("# jaxbpm")) + "\n"
    sphere = "\n".join(" ".join(ln.split()[:1] + ln.split()[2:]) if ln[:1].isdigit() and len(ln.split()) == 8
                       else ln.replace("Atoms # bpm/sphere", "Atoms # sphere") for ln in plain.splitlines()) + "\n"
    base = "LAMMPS data file\n" + written.split("\n", 1)[1]  # (without the checksum, which edits break)
    velocities = base + "\nVelocities\n\n" + "".join(f"{i + 1} 0 0 0 0 0 0\n" for i in range(6))
    images = "\n".join(ln + " 0 -1 0" if ln[:1].isdigit() and len(ln.split()) == 8 else ln
                       for ln in plain.splitlines()) + "\n"
    fast = {"written": written, "plain": plain, "sphere": sphere, "velocities": velocities, "images": images,
            "comment before rows": plain.replace("Atoms # bpm/sphere\n\n1 1 1", "Atoms\n\n# c\n1 1 1")}
    slow = {"leading blanks": base.replace("\n1 ", "\n 1 "), "blank line in Bonds": base.replace(
        "\n2 ", "\n\n2 ", 1), "comment in Atoms": plain.replace("\n3 1 1 ", "\n# c\n3 1 1 ", 1)}
    for label, text in [*fast.items(), *slow.items()]:
        path = tmp_path / f"{label}.data"
        path.write_text(text)
        got = _lammps_fast.parse_fast(path, text, None)
        assert (got is None) == (label in slow), label
        want = lammps._parse_lines(path, text, None)
        if got is not None:
            for x, y in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(want)):
                if isinstance(x, np.ndarray):
                    assert x.dtype == y.dtype and np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), label
                else:
                    assert x == y, label
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", InexactTranslationWarning)
            formats.read_lammps_data(path, particle_material=_multi().particle_material)




def test_irregular_files_are_left_to_the_line_by_line_reader(tmp_path):
    text = formats.write_lammps_data(tmp_path / "s.data", _sample()).read_text()
    path = tmp_path / "s.data"
    assert _lammps_fast.parse_fast(path, text, None) is not None
    for irregular in (text[:-1], text.replace("\n", "\r\n"), text.replace("\n", "\n\x01", 1),
                      text.replace("Atoms # bpm/sphere", "Atoms # ellipsoid")):
        assert _lammps_fast.parse_fast(path, irregular, None) is None
