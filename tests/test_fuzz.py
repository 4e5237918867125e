"""Fuzz tests, seeded: damaged sample files (HDF5, LAMMPS data and dump, CSV) and invalid parameters and options.

Every case must give a named jaxbpm error (a :class:`~jaxbpm.errors.JaxbpmError`, whose message shows plain numbers,
not NumPy reprs) or a correct result: a sample equal to the one written, leaf for leaf. A generic exception
(``KeyError``, ``ValueError``, ...) or a different sample where the damage can be seen is a failure. Only random
damage to a text file without jaxbpm's checksum (a file from another program, or with the checksum deleted) may
change a value unseen: there a sample must merely come back valid. Each test counts its cases, asserts a minimum
(it cannot silently try nothing) and prints the tally.
"""

import collections
import math
import re
import string
import warnings

import h5py
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from tests.interop import test_dump
from jaxbpm import io
from jaxbpm.errors import JaxbpmError, SceneError
from jaxbpm.interop import formats
from jaxbpm.interop.conventions import InexactTranslationWarning
from jaxbpm import DEM, DSM, STE
from jaxbpm._options import options_class, resolve_options
from jaxbpm.physics.model import check_params
from jaxbpm.sample import Domain, Sample
from jaxbpm.scenes import UniaxialCompression

NUMPY_REPR = re.compile(r"\bnp\.\w+\(|\barray\(|\bnp\.(?:True|False)_")


def _sample() -> Sample:
    """Five particles, five bonds, two bond materials, a domain and a particle material that are not the defaults
    (a reader that lost any of them would give a different sample)."""
    rng = np.random.default_rng(0)
    pos = np.arange(5)[:, None] * np.array([1.0, 0.0, 0.0]) + 0.1 * rng.standard_normal((5, 3))
    return Sample.from_arrays(
        pos, 0.45 + 0.05 * rng.random(5), [[0, 1], [1, 2], [2, 3], [3, 4], [0, 2]], 0.1 + 0.1 * rng.random(5),
        bond_material=[0, 1, 1, 0, 1],
        materials={"E": [1e9, 2.5e9], "nu": [0.2, 0.3], "tensile_strength": [1e6, np.inf],
                   "shear_strength": [2e6, 5e6]},
        particle_material={"density": 2650.0, "E": 7e10, "nu": 0.17, "friction": 0.3, "restitution": 0.8},
        bond_contact="replace", domain=Domain("box", (-0.5, -1.0, -1.0), (5.5, 1.0, 1.0)))


SAMPLE = _sample()


def _same(a: Sample, b: Sample) -> bool:
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    return ta == tb and all(np.asarray(x).dtype == np.asarray(y).dtype and np.array_equal(x, y)
                            for x, y in zip(la, lb))


class Tally:
    """Outcomes of the cases of one test: named errors, correct results, undetectable changes and failures."""

    def __init__(self):
        self.counts = collections.Counter()
        self.failures = []

    @property
    def cases(self) -> int:
        return sum(self.counts.values()) + len(self.failures)

    def error(self, label: str, exc: JaxbpmError, names=()) -> None:
        text = str(exc)
        if NUMPY_REPR.search(text):
            self.failures.append(f"{label}: message shows a NumPy repr: {text}")
        elif names and not any(n in text for n in names):
            self.failures.append(f"{label}: message names none of {list(names)}: {text}")
        else:
            self.counts["named error"] += 1

    def read(self, label: str, read, expected=None, *, strict=True, names=()):
        """Run ``read()``: a named error, or a result equal to ``expected`` (``strict``) / a valid sample."""
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", InexactTranslationWarning)  # foreign files: stated translations
                got = read()
        except JaxbpmError as exc:
            self.error(label, exc, names)
            return None
        except Exception as exc:  # noqa: BLE001  (a generic exception is what this test looks for)
            self.failures.append(f"{label}: generic {type(exc).__name__}: {exc}")
            return None
        if expected is None or _same(got, expected):
            self.counts["correct result"] += 1
        elif strict:
            self.failures.append(f"{label}: silent change of the sample")
        else:
            assert isinstance(got, Sample)
            self.counts["changed value, no checksum to see it"] += 1
        return got

    def refused(self, label: str, call, names=(), error=SceneError):
        """``call()`` must raise ``error`` naming one of ``names``."""
        try:
            call()
        except error as exc:
            self.error(label, exc, names)
            return
        except Exception as exc:  # noqa: BLE001
            self.failures.append(f"{label}: generic {type(exc).__name__}: {exc}")
            return
        self.failures.append(f"{label}: accepted")

    def finish(self, name: str, minimum: int) -> None:
        print(f"\n{name}: {self.cases} cases: {dict(self.counts)}; failures: {len(self.failures)}")
        assert not self.failures, f"{len(self.failures)} of {self.cases} cases failed:\n" + "\n".join(
            self.failures[:40])
        assert self.cases >= minimum, f"{name}: only {self.cases} cases (expected at least {minimum})"


# ============================================================================================== text files
def _random_damage(data: bytes, rng, count: int):
    """``count`` randomly damaged copies: a flipped bit, a changed digit, an inserted, deleted or replaced byte."""
    digits = [i for i, c in enumerate(data) if chr(c).isdigit()]
    for _ in range(count):
        b = bytearray(data)
        kind = ("bit", "digit", "insert", "delete", "byte")[int(rng.integers(5))]
        i = int(rng.integers(len(b)))
        if kind == "bit":
            b[i] ^= 1 << int(rng.integers(8))
        elif kind == "digit":
            i = digits[int(rng.integers(len(digits)))]
            b[i] = ord(str((int(chr(b[i])) + int(rng.integers(1, 10))) % 10))
        elif kind == "insert":
            b.insert(i, ord(rng.choice(list(string.printable))))
        elif kind == "delete":
            del b[i]
        else:
            b[i] = int(rng.integers(256))
        yield f"{kind} at byte {i}", bytes(b)


def _line_damage(data: bytes, rng, keep=()):
    """Cuts at every line boundary and inside every line, each line dropped (but those in ``keep``) or doubled."""
    lines = data.splitlines(keepends=True)
    for k, line in enumerate(lines):
        yield f"cut before line {k + 1}", b"".join(lines[:k])
        if len(line) > 1:
            yield f"cut inside line {k + 1}", b"".join(lines[:k]) + line[:int(rng.integers(1, len(line)))]
        if k not in keep:
            yield f"line {k + 1} dropped", b"".join(lines[:k] + lines[k + 1:])
        yield f"line {k + 1} doubled", b"".join(lines[:k + 1] + lines[k:])


GARBAGE = [b"", b"-1", b"0", b"1 2", b"nan", b"inf", b"99999999999999999999", b"1e400", b"#", b"x y z",
           b"Atoms", b"Bonds", b"ITEM: ATOMS id", b"ITEM: ENTRIES a", b"\xff\xfe", b'"', b",,,,"]


def _lines_replaced(data: bytes, rng, count: int):
    """``count`` copies with one line, or one word of a line, replaced by something else."""
    lines = data.splitlines(keepends=True)
    for _ in range(count):
        k = int(rng.integers(len(lines)))
        new = GARBAGE[int(rng.integers(len(GARBAGE)))]
        words = lines[k].split()
        if words and rng.random() < 0.5:
            w = int(rng.integers(len(words)))
            new = b" ".join(words[:w] + [new] + words[w + 1:])
        yield f"line {k + 1} replaced by {new!r}", b"".join(lines[:k] + [new + b"\n"] + lines[k + 1:])


def _lammps_sections(data: bytes):
    """``(name, copy without that section)`` for each section of a LAMMPS data file, and without the header block."""
    lines = data.splitlines(keepends=True)
    names = ("Atoms", "Velocities", "Bond Coeffs", "Bonds")
    starts = [k for k, ln in enumerate(lines) if ln.split(b"#")[0].strip().decode() in names]
    for a, b in zip(starts, starts[1:] + [len(lines)]):
        yield lines[a].split(b"#")[0].strip().decode(), b"".join(lines[:a] + lines[b:])
    yield "header block", b"".join(lines[:3] + lines[starts[0]:])


def _without_checksum_lammps(data: bytes) -> bytes:
    title, rest = data.split(b"\n", 1)
    assert b" crc32=" in title
    return title.split(b" crc32=")[0] + b"\n" + rest


def test_fuzz_lammps_data(tmp_path):
    """LAMMPS data files as jaxbpm writes them (with the checksum), without the checksum (as from another program)
    and with a Velocities section added: cut, sections and lines dropped or doubled, random bytes damaged."""
    rng = np.random.default_rng(1)
    tally = Tally()
    written = formats.write_lammps_data(tmp_path / "w.data", SAMPLE).read_bytes()
    plain = _without_checksum_lammps(written)
    velocities = plain + b"\nVelocities\n\n" + b"".join(b"%d 0.0 0.0 0.0 0.0 0.0 0.0\n" % (i + 1) for i in range(5))
    target = tmp_path / "s.data"

    def read(data):
        target.write_bytes(data)
        return lambda: formats.read_lammps_data(target)

    for variant, data, checked in (("written", written, True), ("no checksum", plain, False),
                                   ("with Velocities", velocities, False)):
        tally.read(f"{variant}: intact", read(data), SAMPLE)
        # line 2 holds jaxbpm's metadata: without it (and without the checksum) the file is a foreign one, whose
        # parameters are translated from the coefficients by design
        keep = () if checked else (1,)
        for label, damaged in _line_damage(data, rng, keep):
            tally.read(f"{variant}: {label}", read(damaged), SAMPLE, names=(target.name,))
        for label, damaged in _lammps_sections(data):
            tally.read(f"{variant}: {label} dropped", read(damaged), SAMPLE, names=(target.name,))
        for label, damaged in [*_random_damage(data, rng, 150 if checked else 60),
                               *_lines_replaced(data, rng, 60 if checked else 40)]:
            tally.read(f"{variant}: {label}", read(damaged), SAMPLE, strict=checked, names=(target.name,))
    tally.finish("LAMMPS data", 850)


def test_fuzz_csv(tmp_path):
    """CSV particles and bonds files as jaxbpm writes them (with the checksums) and without the checksum line: each
    file cut, lines dropped or doubled, random bytes damaged; the bonds file missing, empty or a directory."""
    rng = np.random.default_rng(2)
    tally = Tally()
    p, b = formats.write_csv(tmp_path / "s.csv", SAMPLE)
    written = {p: p.read_bytes(), b: b.read_bytes()}
    plain_p = b"".join(ln for ln in written[p].splitlines(keepends=True) if not ln.startswith(b"# crc32="))
    assert plain_p != written[p]
    names = (p.name, b.name)

    def read(particles, bonds):
        p.write_bytes(particles)
        if b.is_dir():
            b.rmdir()
        if bonds is None:
            b.unlink(missing_ok=True)
        elif bonds == "dir":
            b.unlink(missing_ok=True)
            b.mkdir()
        else:
            b.write_bytes(bonds)
        return lambda: formats.read_csv(p)

    for variant, particles, checked in (("written", written[p], True), ("no checksum", plain_p, False)):
        bonds = written[b]
        tally.read(f"{variant}: intact", read(particles, bonds), SAMPLE)
        # line 1 of the particles file is jaxbpm's metadata: without it (and the checksum) the files are foreign
        for label, damaged in _line_damage(particles, rng, keep=() if checked else (0,)):
            tally.read(f"{variant}: particles {label}", read(damaged, bonds), SAMPLE, names=names)
        for label, damaged in _line_damage(bonds, rng):
            tally.read(f"{variant}: bonds {label}", read(particles, damaged), SAMPLE, names=names)
        for label, bonds_now in (("missing", None), ("empty", b""), ("a directory", "dir")):
            tally.read(f"{variant}: bonds file {label}", read(particles, bonds_now), SAMPLE, names=names)
        for label, damaged in [*_random_damage(particles, rng, 150 if checked else 60),
                               *_lines_replaced(particles, rng, 40 if checked else 30)]:
            tally.read(f"{variant}: particles {label}", read(damaged, bonds), SAMPLE, strict=checked, names=names)
        for label, damaged in [*_random_damage(bonds, rng, 150 if checked else 60),
                               *_lines_replaced(bonds, rng, 40 if checked else 30)]:
            tally.read(f"{variant}: bonds {label}", read(particles, damaged), SAMPLE, strict=checked, names=names)
    tally.finish("CSV", 650)


DUMP = test_dump.DUMP.encode()  # two frames: atoms and a local bond list


def test_fuzz_lammps_dump(tmp_path):
    """LAMMPS text dumps (written by LAMMPS: no checksum) cut, with lines dropped or doubled and bytes damaged: a
    named error or frames whose positions and bond lists can be read."""
    rng = np.random.default_rng(3)
    tally = Tally()
    target = tmp_path / "run.dump"

    def read(data):
        target.write_bytes(data)

        def frames():
            out = formats.read_lammps_dump(target)
            atoms = [f for f in out if f.kind == "atoms"]
            for f in out:
                if f.kind == "atoms":
                    f.ids, f.positions
                elif atoms:
                    f.bonds(atoms[0].ids)
                else:
                    f.bond_atoms
            return None

        return frames

    cases = [*_line_damage(DUMP, rng), *_random_damage(DUMP, rng, 150), *_lines_replaced(DUMP, rng, 150)]
    for label, damaged in cases:
        tally.read(label, read(damaged), None, names=(target.name, "timestep"))
    tally.finish("LAMMPS dump", 390)


# ============================================================================================== HDF5
def _h5_targets(path) -> list[tuple[str, int, int]]:
    """``(what, offset, length)`` of the bytes that hold the sample: every dataset's data, and the attributes' values
    (found by their bytes in the file, where those occur once)."""
    out = []
    raw = path.read_bytes()
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset) and obj.size:
                if obj.chunks is not None:
                    for k in range(obj.id.get_num_chunks()):
                        info = obj.id.get_chunk_info(k)
                        out.append((f"/{name} chunk {k}", info.byte_offset, info.size))
                elif obj.id.get_offset() is not None:
                    out.append((f"/{name}", obj.id.get_offset(), obj.id.get_storage_size()))
        f.visititems(visit)
        for g in (f, f["derived"]):
            for key, value in g.attrs.items():
                needle = value.encode() if isinstance(value, str) else np.asarray(value).tobytes()
                if key not in ("units", "description") and len(needle) >= 4 and raw.count(needle) == 1:
                    out.append((f"attribute {g.name}:{key}", raw.find(needle), len(needle)))
    return out


def _without_header(path, plain):
    """``path``'s HDF5 content copied into ``plain``, a file without jaxbpm's header (as older versions wrote)."""
    with h5py.File(path, "r") as a, h5py.File(plain, "w") as b:
        for key, value in a.attrs.items():
            b.attrs[key] = value
        for name in a:
            a.copy(a[name], b, name=name)
    return plain


def test_fuzz_hdf5(tmp_path):
    """Sample files as jaxbpm writes them (with the header holding the file's CRC-32): bits flipped at random offsets,
    in the header and inside the stored data and attributes, the file cut at random lengths, each dataset, group and
    attribute deleted; and files without the header (as older versions wrote them): bits flipped in the stored data
    and attributes, each object and attribute deleted. A named error or the same sample."""
    rng = np.random.default_rng(4)
    tally = Tally()
    files = {"header": io.save_sample(tmp_path / "w.h5", SAMPLE)}
    files["no header"] = _without_header(files["header"], tmp_path / "plain.h5")
    target = tmp_path / "s.h5"

    def read(data):
        target.write_bytes(data)
        return lambda: io.load_sample(target)

    for variant, path in files.items():
        raw = path.read_bytes()
        tally.read(f"{variant}: intact", read(raw), SAMPLE)
        targets = _h5_targets(path)
        assert {"/positions chunk 0", "/particle_material/friction", "attribute /:domain_lo",
                "attribute /derived:inputs_crc32"} <= {t[0] for t in targets}
        if variant == "header":
            targets.append(("the header line", 0, raw.index(b"\n")))
        for what, offset, length in targets:
            for _ in range(4):
                b = bytearray(raw)
                i = offset + int(rng.integers(length))
                b[i] ^= 1 << int(rng.integers(8))
                tally.read(f"{variant}: bit flipped in {what} (byte {i})", read(bytes(b)), SAMPLE, names=(target.name,))
        # HDF5's own reader may fail in any way on damage to its internal structures (even hang): only files with
        # the header, which is checked before HDF5 reads anything, take damage at random places
        if variant == "header":
            for _ in range(250):
                b = bytearray(raw)
                i = int(rng.integers(len(b)))
                b[i] ^= 1 << int(rng.integers(8))
                tally.read(f"{variant}: bit flipped at byte {i}", read(bytes(b)), SAMPLE, names=(target.name,))
            for n in sorted(rng.integers(0, len(raw), 30)):
                tally.read(f"{variant}: cut to {n} bytes", read(raw[:n]), SAMPLE, names=(target.name,))
        # deletions through h5py: every dataset and group, every attribute (root, groups and datasets)
        with h5py.File(path, "r") as f:
            objects = []
            f.visit(objects.append)
            attributes = [("/", k) for k in f.attrs] + [(name, k) for name in objects for k in f[name].attrs]
        deletions = [(f"/{name} deleted", lambda f, name=name: f.__delitem__(name)) for name in objects]
        deletions += [(f"attribute {name}:{key} deleted", lambda f, name=name, key=key: f[name].attrs.__delitem__(key))
                      for name, key in attributes]
        deletions.append(("the domain deleted", lambda f: [f.attrs.__delitem__(k) for k in ("domain_kind", "domain_lo",
                                                                                          "domain_hi")]))
        for label, delete in deletions:
            target.write_bytes(raw)
            with h5py.File(target, "a") as f:
                delete(f)
            tally.read(f"{variant}: {label}", lambda: io.load_sample(target), SAMPLE, names=(target.name,))
    tally.finish("HDF5", 500)


# ============================================================================================== parameters
PER_MATERIAL = {"bond_E": [0.0, -1e9, np.inf, -np.inf, np.nan], "bond_nu": [-1.0, 0.5, 0.7, -2.0, np.inf, np.nan],
                "bond_tensile_strength": [-1.0, -np.inf, np.nan], "bond_shear_strength": [-1e6, np.nan],
                "bond_friction_angle": [-0.1, math.pi / 2, 2.0, np.inf, np.nan]}
SCALARS = {"contact_E": [0.0, -1.0, np.inf, np.nan], "contact_nu": [0.5, -1.0, 0.9, np.nan],
           "friction": [-0.1, np.inf, np.nan], "restitution": [0.0, 1.5, -1.0, np.nan],
           "cohesion_initial": [-1.0, np.inf, np.nan], "cohesion_from_stress": [-0.5, np.nan],
           "cohesion_max": [-1.0, np.inf]}
VALID = {"bond_E": (1e8, 1e10), "bond_nu": (-0.9, 0.49), "bond_tensile_strength": (0.0, 1e7),
         "bond_shear_strength": (0.0, 1e7), "bond_friction_angle": (0.0, 1.5), "contact_E": (1e8, 1e10),
         "contact_nu": (-0.9, 0.49), "friction": (0.0, 1.0), "restitution": (0.01, 1.0), "cohesion_initial": (0.0, 0.0),
         "cohesion_from_stress": (0.0, 1.0), "cohesion_max": (0.0, 1e6)}
WRONG_TYPES = ["1e9", None, {"a": 1.0}, 1j, [1e9 + 1j, 1e9], [True, False], object(), [[1e9], [1e9, 2e9]], b"1"]


def _typo(name: str, rng) -> str:
    k = int(rng.integers(len(name)))
    kind = int(rng.integers(3))
    if kind == 0:
        return name[:k] + name[k + 1:]
    if kind == 1:
        return name[:k] + rng.choice(list(string.ascii_letters)) + name[k:]
    return name[:k] + name[k].swapcase() + name[k + 1:] if name[k].isalpha() else name + "_"


def _valid_params(rng, m: int, extra: int) -> dict:
    out = {"bond_E": rng.uniform(*VALID["bond_E"], m), "bond_nu": rng.uniform(*VALID["bond_nu"], m)}
    for key in rng.choice(sorted(set(VALID) - set(out)), extra, replace=False):
        lo, hi = VALID[key]
        out[key] = rng.uniform(lo, hi, m) if key in PER_MATERIAL else float(rng.uniform(lo, hi))
    if "cohesion_max" in out and "cohesion_initial" in out:
        out["cohesion_max"] = max(out["cohesion_max"], out["cohesion_initial"])
    form = int(rng.integers(3))
    return {k: (v.tolist() if form == 1 and isinstance(v, np.ndarray) else
                jnp.asarray(v) if form == 2 else v) for k, v in out.items()}


def _invalid_params(rng, m: int, none: bool = True) -> tuple[str, object, tuple]:
    """``(label, params, names the message must hold one of)``, params certainly invalid (``none``: ``None`` among
    them; :func:`jaxbpm.solve` reads ``params=None`` as the sample's own parameters)."""
    params = _valid_params(rng, m, int(rng.integers(0, 4)))
    mode = int(rng.integers(8))
    if mode == 0:  # a per-material entry out of range
        key = rng.choice(sorted(PER_MATERIAL))
        value = np.asarray(params.get(key, rng.uniform(*VALID[key], m)), dtype=float).copy()
        value[int(rng.integers(m))] = rng.choice(PER_MATERIAL[key])
        params[key] = value if rng.random() < 0.5 else value.tolist()
        return f"{key} = {value.tolist()}", params, (key,)
    if mode == 1:  # a per-material entry of the wrong length or kind
        key = rng.choice(sorted(PER_MATERIAL))
        value = [[[1.0] * m], 1.0, [1.0] * (m + 1), [1.0] * (m - 1), []][int(rng.integers(5))] if rng.random() < 0.6 \
            else WRONG_TYPES[int(rng.integers(len(WRONG_TYPES)))]
        params[key] = value
        return f"{key} = {value!r}", params, (key,)
    if mode == 2:  # a scalar out of range, or not a scalar
        key = rng.choice(sorted(SCALARS))
        value = rng.choice(SCALARS[key]) if rng.random() < 0.6 else \
            [[0.3], "0.3", None, [0.3, 0.3], True, 0.3j][int(rng.integers(6))]
        params[key] = value
        return f"{key} = {value!r}", params, (key,)
    if mode == 3:  # a required key missing
        key = rng.choice(["bond_E", "bond_nu"])
        del params[key]
        return f"no {key}", params, ("bond_E",)
    if mode == 4:  # an unknown key: a misspelt one or another
        key = _typo(str(rng.choice(sorted(VALID))), rng) if rng.random() < 0.7 else \
            [1, None, ("bond_E",), "E", "youngs_modulus", "bond_e"][int(rng.integers(6))]
        if key in VALID:
            key = "bond_E_"
        params[key] = 1.0
        return f"unknown key {key!r}", params, (repr(key),)
    if mode == 5:  # not a mapping
        value = [[1e9] * m, (1e9, 0.25), "bond_E", 1e9, np.array([1e9, 0.25]), None][
            int(rng.integers(6 if none else 5))]
        return f"params = {value!r}", value, ("bond_E",)
    if mode == 6:  # cohesion_max below cohesion_initial
        params["cohesion_initial"], params["cohesion_max"] = 2e6, float(rng.uniform(0, 1.9e6))
        return "cohesion_max < cohesion_initial", params, ("cohesion_max",)
    key = rng.choice(sorted(PER_MATERIAL))  # a NaN hidden in a device array
    value = np.asarray(params.get(key, rng.uniform(*VALID[key], m)), dtype=float).copy()
    value[-1] = np.nan
    params[key] = jnp.asarray(value)
    return f"{key} = device array with NaN", params, (key,)


def test_fuzz_params():
    """Random invalid ``params`` through :func:`check_params` (every solver's one path): a SceneError naming the
    key; random valid ones come back with their values."""
    rng = np.random.default_rng(5)
    tally = Tally()
    m = SAMPLE.n_materials
    for k in range(600):
        label, params, names = _invalid_params(rng, m)
        tally.refused(f"case {k}: {label}", lambda: check_params(params, SAMPLE), names)
    for k in range(100):
        params = _valid_params(rng, m, int(rng.integers(0, 6)))
        got = tally.read(f"valid case {k}", lambda: check_params(params, SAMPLE))
        assert got is not None and all(np.array_equal(np.asarray(got[key]), np.asarray(params[key], dtype=float))
                                       for key in params)
    tally.finish("params", 700)


# ============================================================================================== options
_POSITIVE = [0, 0.0, -1.0, np.nan, np.inf, -np.inf, "1e-3", True, [1e-3], 1j]
_WHOLE = [0, -1, 2.5, "10", True, np.nan, 10.0, [10]]
_FLAG = [1, 0, "yes", None, np.array(True), 1.0]
INVALID_OPTIONS = {
    "dem": {"dt": _POSITIVE, "safety": [0, -0.1, 1.5, np.nan, np.inf, "0.5", True, None],
            "damping": [1, 1.0, -0.1, np.nan, 2, "0.7", None, True], "loading_time": _POSITIVE,
            "transits": _POSITIVE + [None], "chunk": _WHOLE, "max_records": _WHOLE + [None],
            "snapshots": _WHOLE, "pad": _FLAG, "throw": _FLAG, "overwrite": _FLAG, "progress": ["yes", 1, 2.5],
            "neighbors": [0.5, "auto", {"skin": 1e-4}], "record_to": [1, 2.5, ["run.h5"]], "vtu": [1, True],
            "resume": [0, 1.0], "start": ["Elastic", "dsm", None, True, 1], "start_safety": [0, 1.5, -0.1, np.nan,
                                                                                           "0.9", True]},
    "dsm": {"dofs": [4, 3.0, "3", True, 0, -3, np.nan, np.array([3, 6])], "nonlinear": _FLAG[:-3] + [1.0],
            "tol": _POSITIVE, "linear_tol": _POSITIVE + [None], "maxiter": _WHOLE, "newton_maxiter": _WHOLE + [None],
            "stiffness_tol": ["Auto", "none", 0, -1.0, np.nan, True], "contact_skin": _POSITIVE,
            "load_steps": _WHOLE + [None], "throw": _FLAG, "operator": ["JVP", "", None, 1, ["jvp"]],
            "preconditioner": ["multigrid", None, 2], "aggregate_size": _POSITIVE, "slip": _FLAG,
            "contact_fraction": [0, -0.5, 1.5, np.nan, "0.5", True], "contact_passes": _WHOLE + [None],
            "pad": _FLAG, "geometric_correction": _FLAG},
    "ste": {"dofs": [None, 4, "6", 6.0, True], "first_neighbour": _FLAG, "layered": _FLAG,
            "contacts": _FLAG[:3] + [1.0], "contact_fraction": [0, 1.01, np.nan, "all"],
            "layer_thickness": _POSITIVE, "surface_depth": [-1.0, np.nan, np.inf, "1e-3", True, np.array([1.0, 2.0])],
            "volumes": [[1.0, -1.0], [np.nan], "abc", [[1.0], [1.0, 2.0]], [True, False], 1.0],
            "precision": ["float16", 64, None, "FLOAT64"], "pad": _FLAG, "throw": _FLAG,
            "boundary": ["layers", "walls", None, True, "Clamped", ["free"]]},
}
VALID_OPTIONS = {"dem": {"dt": 1e-7, "safety": 0.3, "damping": 0.0, "chunk": 50, "pad": False, "progress": None},
                 "dsm": {"dofs": 3, "tol": 1e-8, "stiffness_tol": "auto", "operator": "jvp", "contact_fraction": 1},
                 "ste": {"dofs": 6, "surface_depth": 0, "precision": "float32", "volumes": np.ones(4)}}
CLASSES = {"dem": DEM, "dsm": DSM, "ste": STE}


def test_fuzz_options():
    """Random invalid solver options, as option objects and as keywords (``resolve_options``), for each method: a
    SceneError naming the option; unknown names get a "did you mean"; valid ones are kept as given."""
    rng = np.random.default_rng(6)
    tally = Tally()
    for method, table in INVALID_OPTIONS.items():
        assert set(table) == set(options_class(method).names()), method  # every option is fuzzed
        cls = CLASSES[method]
        for k in range(150):
            name = str(rng.choice(sorted(table)))
            value = table[name][int(rng.integers(len(table[name])))]
            others = {n: v for n, v in VALID_OPTIONS[method].items() if n != name and rng.random() < 0.5}
            options = {**others, name: value}
            tally.refused(f"{method} {name}={value!r}", lambda: cls(**options), (name,))
            tally.refused(f"{method} {name}={value!r} (keywords)", lambda: resolve_options(method, options), (name,))
        for k in range(40):
            name = _typo(str(rng.choice(sorted(table))), rng)
            if name in table:
                continue
            tally.refused(f"{method} unknown option {name!r}", lambda: cls(**{name: 1}), (repr(name),))
            close = [n for n in table if n[:3] == name[:3] and abs(len(n) - len(name)) <= 1]
            if close and len(name) > 4:
                with pytest.raises(SceneError, match="did you mean"):
                    cls(**{name: 1})
        got = tally.read(f"{method} valid options", lambda: cls(**VALID_OPTIONS[method]))
        assert got is not None and all(getattr(got, k) is v for k, v in VALID_OPTIONS[method].items())
    for method in ("fem", "DEM", None, 3, ["dem"]):
        tally.refused(f"method {method!r}", lambda: resolve_options(method, {}), (repr(method),))
    tally.finish("options", 900)


@pytest.fixture(scope="module")
def lattice():
    return jaxbpm.generate.lattice("fcc", (2, 2, 2), 1e-3, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})


def test_fuzz_solve_refuses_before_compiling(lattice):
    """Through :func:`jaxbpm.solve`, for each method: random invalid params and options are a SceneError naming the
    problem, raised before any program is compiled."""
    rng = np.random.default_rng(7)
    tally = Tally()
    scene = UniaxialCompression(strain=0.002)
    cases = []  # (label, params, options, names), made before counting compilations (jnp arrays among them)
    for method in ("dem", "dsm", "ste"):
        for k in range(6):
            label, params, names = _invalid_params(rng, lattice.n_materials, none=False)
            cases.append((method, label, params, {}, names))
        table = INVALID_OPTIONS[method]
        for k in range(6):
            name = str(rng.choice(sorted(table)))
            value = table[name][int(rng.integers(len(table[name])))]
            cases.append((method, f"{name}={value!r}", None, {name: value}, (name,)))
        name = _typo(str(rng.choice(sorted(table))), rng)
        if name not in table:
            cases.append((method, f"unknown option {name!r}", None, {name: 1}, (repr(name),)))
    with jaxbpm.count_compilations() as compiled:
        for method, label, params, options, names in cases:
            tally.refused(f"{method} {label}", lambda: jaxbpm.solve(lattice, scene, method, params=params, **options),
                          names)
    assert compiled.count == 0
    tally.finish("solve", 36)


# ============================================================================================== scenes, radii, targets
def test_fuzz_scene_names_and_failure_scenes(lattice):
    """Scenes by name and failure scenes for the static solvers: an unknown name (typos, random words) is a
    SceneError listing the names, for every method; a failure scene (breakage on) asked of the DSM or STE is refused
    at once, saying which method gives the strength; nothing is compiled."""
    from jaxbpm.scenes import ThreePointBending, scene_from_name
    from jaxbpm.scenes.names import SCENE_NAMES

    rng = np.random.default_rng(11)
    tally = Tally()
    cases = []
    for k in range(24):
        base = str(rng.choice(sorted(SCENE_NAMES)))
        name = _typo(base, rng) if k % 2 else "".join(rng.choice(list(string.ascii_letters + " _-"), 1 + k % 7))
        if name.strip().lower() in SCENE_NAMES:
            continue
        cases.append((f"name {name!r}", name, str(rng.choice(["dem", "dsm", "ste", "auto"])), ("unknown scene name",)))
    for k in range(8):
        name = str(rng.choice(["ucs", "UCS", " ucs", "bts", "Brazilian"]))
        cases.append((f"name {name!r}", name, str(rng.choice(["dsm", "ste"])), ("elastic range only", "needs method")))
    for k in range(12):
        strain = float(10 ** rng.uniform(-4, -0.5))
        scene = [UniaxialCompression(strain=strain, breakage=True, contacts=bool(rng.integers(2))),
                 UniaxialCompression.to_failure(strain=strain), ThreePointBending(breakage=True)][k % 3]
        method = str(rng.choice(["dsm", "ste"]))
        cases.append((f"{type(scene).__name__} strain {strain:.3g}", scene, method, ("elastic range only",
                                                                                      "needs method")))
    with jaxbpm.count_compilations() as compiled:
        for label, scene, method, names in cases:
            tally.refused(f"{method} {label}", lambda: jaxbpm.solve(lattice, scene, method), names)
    assert compiled.count == 0
    for name in SCENE_NAMES:  # and every known name, in any case, is its scene
        assert scene_from_name(f" {name.upper()} ") == scene_from_name(name)
    tally.finish("scene names and failure scenes", 36)


def test_fuzz_bond_radii():
    """Random bond radius ratios and per-bond radii on random radii: refused naming the bonds (or the ratio) and
    ``wide_bonds``, or accepted with no bond wider than its smaller particle; ``wide_bonds=True`` accepts them."""
    rng = np.random.default_rng(12)
    tally = Tally()
    pos = np.arange(6)[:, None] * np.array([1.0, 0.0, 0.0])
    bonds = [[0, 1], [1, 2], [2, 3], [3, 4], [4, 5]]
    for k in range(60):
        radii = 0.5 * rng.uniform(0.5, 1.0, 6)
        smaller = np.minimum(radii[:-1], radii[1:])
        if k % 2:
            ratio = float(10 ** rng.uniform(-2, 2))
            kw, wide = {"bond_radius_ratio": ratio}, ratio > 1 + 1e-9
        else:
            rb = smaller * 10 ** rng.uniform(-1, 0.2, 5)
            kw, wide = {"bond_radius": rb}, bool(np.any(rb > smaller * (1 + 1e-9)))
        label = f"case {k}: {'ratio' if k % 2 else 'radii'}"
        if wide:
            tally.refused(label, lambda: Sample.from_arrays(pos, radii, bonds, **kw), ("wide_bonds",),
                          error=jaxbpm.SampleError)
            got = Sample.from_arrays(pos, radii, bonds, wide_bonds=True, **kw)
            assert np.any(got.bond_radius > smaller), label
        else:
            got = tally.read(label, lambda: Sample.from_arrays(pos, radii, bonds, **kw))
            assert got is not None and np.all(got.bond_radius <= smaller * (1 + 1e-9)), label
    tally.finish("bond radii", 60)


def test_fuzz_lammps_atom_types(tmp_path):
    """Atom types and the header's ``atom types`` count changed at random in a file without the checksum: a type
    outside 1..count is an error naming its line, as LAMMPS refuses it; any other file reads with those types."""
    rng = np.random.default_rng(13)
    tally = Tally()
    lines = _without_checksum_lammps(formats.write_lammps_data(tmp_path / "w.data", SAMPLE).read_bytes()) \
        .decode().splitlines()
    header = next(k for k, ln in enumerate(lines) if ln.endswith("atom types"))
    first = next(k for k, ln in enumerate(lines) if ln.startswith("Atoms")) + 2
    target = tmp_path / "t.data"
    for k in range(40):
        count = int(rng.integers(1, 4))
        types = rng.integers(1, count + 1, SAMPLE.n_particles)
        if k % 2:  # one or two atoms of a type the header does not count
            types[rng.choice(SAMPLE.n_particles, 1 + k % 3 // 2, replace=False)] = rng.choice([-1, 0, count + 1, 9])
        edited = list(lines)
        edited[header] = f"{count} atom types"
        for i, t in enumerate(types):
            words = edited[first + i].split("#")[0].split()
            words[2] = str(int(t))  # bpm/sphere: id mol type diameter density x y z
            edited[first + i] = " ".join(words)
        target.write_text("\n".join(edited) + "\n")
        bad = np.flatnonzero((types < 1) | (types > count))
        if bad.size:
            tally.refused(f"case {k}: types {types.tolist()} under {count}", lambda: formats.read_lammps_data(target),
                          (f"t.data:{first + bad[0] + 1}: atom {bad[0] + 1} has type {types[bad[0]]}",),
                          error=jaxbpm.SampleFileError)
        else:
            got = tally.read(f"case {k}", lambda: formats.read_lammps_data(target))
            assert got is not None and np.array_equal(got.types, types)
    tally.finish("LAMMPS atom types", 40)


def test_fuzz_calibration_targets():
    """Random targets over 24 decades on a model of known range (E = 3 bond_E, bond_E in [1e-3, 1e3]): each result is
    converged within tol, or a target out of the range is reported with the parameter at the bound on its side."""
    from jaxbpm import calibrate as cal
    from jaxbpm.calibrate import Target
    from tests.calibrate._cases import _analytic_problem

    rng = np.random.default_rng(14)
    outcomes = collections.Counter()
    for k in range(12):
        target = float(10 ** rng.uniform(-12, 12))
        res = cal.adam(_analytic_problem([Target("youngs_modulus", target)]), gradient="fd-forward", tol=0.01,
                       max_iterations=5)
        reachable = 3e-3 <= target <= 3e3
        if res.converged:
            assert reachable and abs(res.errors["youngs_modulus"]) <= 0.01, (target, res.errors)
            outcomes["converged"] += 1
            continue
        assert not reachable, (target, res.table())
        (entry,) = res.info["unreachable"]
        side = "upper" if target > 3e3 else "lower"
        assert [p[1] for p in entry["pinned"]] == [side] and entry["value"] == target, entry
        assert entry["message"] in res.notes and "out of reach" in res.table()
        outcomes[f"out of reach ({side})"] += 1
    assert outcomes["converged"] and len(outcomes) == 3, outcomes


def test_fuzz_cli_outputs_never_replace_an_input(tmp_path, monkeypatch, capsys):
    """Every command that writes a file, with its output naming its input however spelled (relative, ``./``,
    ``sub/..``, absolute, a symbolic link, a hard link), with and without ``--force``: refused (exit 2, ``error:``
    naming the input) before any work, the input unchanged; an existing sample that is no input: refused without
    ``--force``."""
    import os
    import pathlib

    import jaxbpm.calibrate
    from jaxbpm import cli, generate

    def must_not_run(*args, **kwargs):
        raise AssertionError("work started before the outputs were checked")

    monkeypatch.setattr(generate, "from_shape", must_not_run, raising=False)
    monkeypatch.setattr(jaxbpm.calibrate, "calibrate", must_not_run)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sub").mkdir()
    io.save_sample(tmp_path / "s.h5", SAMPLE)
    io.save_sample(tmp_path / "other.h5", SAMPLE)
    os.symlink(tmp_path / "s.h5", tmp_path / "link.h5")
    os.link(tmp_path / "s.h5", tmp_path / "hard.h5")
    before = (tmp_path / "s.h5").read_bytes()
    spellings = ["s.h5", "./s.h5", "sub/../s.h5", str(tmp_path / "s.h5"), "link.h5", "hard.h5"]
    commands = {"export-vtk": lambda out: ["export-vtk", "s.h5", out],
                "calibrate": lambda out: ["calibrate", "s.h5", "--target-E", "1e9", "--history", out],
                "convert": lambda out: ["convert", "s.h5", out]}
    tally = Tally()
    for name, argv in commands.items():
        for out in spellings:
            for force in ([], ["--force"]):
                code = cli.main(argv(out) + force)
                err = capsys.readouterr().err
                if code == 2 and err.startswith("error:") and "is the command's input" in err \
                        and str(pathlib.Path(out)) in err:
                    tally.counts["named error"] += 1
                else:
                    tally.failures.append(f"{name} -> {out} {force}: exit {code}, {err.strip()!r}")
        code = cli.main(argv("other.h5"))  # a sample, no input: --force needed
        err = capsys.readouterr().err
        if code == 2 and "--force" in err and "other.h5" in err:
            tally.counts["named error"] += 1
        else:
            tally.failures.append(f"{name} -> other.h5: exit {code}, {err.strip()!r}")
    for out in spellings + ["other.h5"]:
        code = cli.main(["generate", "--shape", "box", "--n", "9", "--out", out])
        err = capsys.readouterr().err
        if code == 2 and "--force" in err:
            tally.counts["named error"] += 1
        else:
            tally.failures.append(f"generate -> {out}: exit {code}, {err.strip()!r}")
    assert (tmp_path / "s.h5").read_bytes() == before
    tally.finish("CLI outputs", 46)
