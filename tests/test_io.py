"""Sample files (HDF5) and VTK export: exact round trip, atomic writes, clear errors."""

import os
import re

import h5py
import jax
import numpy as np
import pytest

from jaxbpm import io
from jaxbpm.errors import SampleError, SampleFileError
from jaxbpm.sample import Domain, Sample


def _chain(n=6, seed=0, **kw):
    """A small sample: a noisy chain of particles plus a few cross bonds."""
    rng = np.random.default_rng(seed)
    pos = np.arange(n)[:, None] * np.array([1.0, 0.0, 0.0]) + 0.1 * rng.standard_normal((n, 3))
    radii = 0.45 + 0.05 * rng.random(n)
    bonds = [[i, i + 1] for i in range(n - 1)] + [[0, 2], [3, 5]]
    nb = len(bonds)
    kw.setdefault("bond_radius", 0.1 + 0.1 * rng.random(nb))
    return Sample.from_arrays(pos, radii, bonds, **kw)


def _multi():
    return _chain(
        bond_material=np.array([0, 1, 2, 1, 0, 2, 1]),
        materials={"E": [1e9, 2.5e9, 7e10], "nu": [0.2, 0.25, 0.3], "tensile_strength": [1e6, np.inf, 3e7],
                   "shear_strength": [2e6, 5e6, np.inf]},
        particle_material={"density": 2650.0, "E": 7e10, "nu": 0.17, "friction": 0.3, "restitution": 0.8},
        bond_contact="replace",
        domain=Domain("cylinder", (-0.5, -1.0, -1.0), (5.5, 1.0, 1.0)))


def _without_header(path):
    """The file's HDF5 content copied into a file without jaxbpm's header (as older jaxbpm versions and other tools
    write it)."""
    plain = path.with_name("plain-" + path.name)
    with h5py.File(path, "r") as a, h5py.File(plain, "w") as b:
        for key, value in a.attrs.items():
            b.attrs[key] = value
        for name in a:
            a.copy(a[name], b, name=name)
    plain.replace(path)
    return path


def _assert_same(a: Sample, b: Sample):
    la, ta = jax.tree_util.tree_flatten_with_path(a)
    lb, tb = jax.tree_util.tree_flatten_with_path(b)
    assert ta == tb  # same structure and same static fields (bond_contact, domain)
    for (path, x), (_, y) in zip(la, lb):
        assert np.asarray(x).dtype == np.asarray(y).dtype, path
        assert np.array_equal(x, y), path
    assert a.bond_contact == b.bond_contact
    assert a.domain == b.domain


@pytest.mark.parametrize("make", [_chain, _multi], ids=["default", "multi-material"])
def test_round_trip_exact(tmp_path, make):
    sample = make()
    path = io.save_sample(tmp_path / "s.h5", sample)
    assert path == tmp_path / "s.h5"
    _assert_same(sample, io.load_sample(path))


def test_round_trip_without_bonds_and_domain_variants(tmp_path):
    no_bonds = Sample.from_arrays(np.eye(3), 0.2, np.zeros((0, 2), int), np.zeros(0))
    _assert_same(no_bonds, io.load_sample(io.save_sample(tmp_path / "a.h5", no_bonds)))
    boxed = _chain(domain=Domain("box", (0, 0, 0), (1, 2, 3)), bond_contact="replace")
    loaded = io.load_sample(io.save_sample(tmp_path / "b.h5", boxed))
    _assert_same(boxed, loaded)
    assert loaded.domain == Domain("box", (0.0, 0.0, 0.0), (1.0, 2.0, 3.0))
    assert _chain().domain is None and io.load_sample(io.save_sample(tmp_path / "c.h5", _chain())).domain is None


def test_file_layout(tmp_path):
    sample = _multi()
    path = io.save_sample(tmp_path / "s.h5", sample)
    with h5py.File(path, "r") as f:
        assert f.attrs["format"] == io.FORMAT and f.attrs["format_version"] == io.FORMAT_VERSION
        assert "jaxbpm_version" in f.attrs and "units" in f.attrs
        assert f.attrs["bond_contact"] == "replace" and f.attrs["domain_kind"] == "cylinder"
        assert f["positions"].attrs["units"] == "m" and f["materials/E"].attrs["units"] == "Pa"
        assert f["particle_material/density"].attrs["units"] == "kg/m^3"
        assert f["bonds"].dtype == np.int32
        assert np.array_equal(f["derived/mass"][()], sample.mass)
        assert np.array_equal(f["derived/bond_length"][()], sample.bond_length)
        assert np.array_equal(f["derived/coordination"][()], sample.coordination())
        for name in f:
            if isinstance(f[name], h5py.Dataset):
                assert "units" in f[name].attrs, name


def _listing(d):
    return sorted(os.listdir(d))


@pytest.mark.parametrize("existing", [False, True], ids=["new", "existing"])
def test_save_is_atomic(tmp_path, monkeypatch, existing):
    target = tmp_path / "s.h5"
    if existing:
        io.save_sample(target, _chain())
    before = target.read_bytes() if existing else None
    listing = _listing(tmp_path)

    def boom(f, sample):
        f.create_dataset("partial", data=np.zeros(10))
        raise RuntimeError("crash mid-write")

    monkeypatch.setattr(io, "_write_derived", boom)
    with pytest.raises(RuntimeError, match="crash mid-write"):
        io.save_sample(target, _multi())
    assert _listing(tmp_path) == listing  # no temp file left, no target created
    if existing:
        assert target.read_bytes() == before
        _assert_same(io.load_sample(target), _chain())


def test_save_atomic_when_rename_fails(tmp_path, monkeypatch):
    target = tmp_path / "s.h5"
    io.save_sample(target, _chain())
    before = target.read_bytes()

    def fail(src, dst):
        raise OSError("disk gone")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(OSError, match="disk gone"):
        io.save_sample(target, _multi())
    assert _listing(tmp_path) == ["s.h5"] and target.read_bytes() == before


def test_a_failed_save_names_its_target_and_stale_temporaries_go(tmp_path, monkeypatch):
    import errno
    import os
    import time

    target = tmp_path / "s.h5"
    with pytest.raises(IsADirectoryError, match=r"cannot write .*: it is a directory"):
        io.save_sample(tmp_path, _chain())

    def busy(src, dst):  # what the OS says when the rename fails names the hidden temporary file
        raise OSError(errno.EBUSY, "Device or resource busy", src)

    monkeypatch.setattr(os, "replace", busy)
    with pytest.raises(OSError, match=r"cannot write .*s\.h5: Device or resource busy") as err:
        io.save_sample(target, _chain())
    assert ".tmp" not in str(err.value) and _listing(tmp_path) == []
    monkeypatch.undo()
    # a killed save leaves its temporary file; the next save to that name removes it once it is stale
    stale, fresh = tmp_path / ".s.h5.killed.tmp", tmp_path / ".s.h5.running.tmp"
    stale.write_bytes(b"x" * 1000)
    fresh.write_bytes(b"y")
    old = time.time() - 2 * io.STALE_AFTER_S
    os.utime(stale, (old, old))
    io.save_sample(target, _chain())
    assert not stale.exists() and fresh.exists()  # (a younger one may be another process's save in progress)


def test_save_rejects_non_sample_and_missing_directory(tmp_path):
    with pytest.raises(TypeError, match="Sample"):
        io.save_sample(tmp_path / "s.h5", {"positions": np.zeros((1, 3))})
    with pytest.raises(FileNotFoundError, match="no such directory"):
        io.save_sample(tmp_path / "nope" / "s.h5", _chain())


def test_missing_file(tmp_path):
    with pytest.raises(SampleFileError, match="no such sample file") as info:
        io.load_sample(tmp_path / "missing.h5")
    assert "missing.h5" in str(info.value)


def test_corrupt_file(tmp_path):
    path = tmp_path / "junk.h5"
    path.write_bytes(np.random.default_rng(0).bytes(4096))
    with pytest.raises(SampleFileError, match="not a readable HDF5 file") as info:
        io.load_sample(path)
    assert "junk.h5" in str(info.value)


def test_truncated_file(tmp_path):
    path = io.save_sample(tmp_path / "s.h5", _multi())
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(SampleFileError, match=rf"s\.h5: the file holds {len(data) // 2} bytes, but {len(data)} were "
                                              r"written.*cut short"):
        io.load_sample(path)
    _without_header(io.save_sample(path, _multi()))  # a file without the header: HDF5 finds the cut
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(SampleFileError, match="s.h5"):
        io.load_sample(path)


def test_header_checks_the_whole_file(tmp_path):
    """The header's CRC-32 and length cover every byte after it; a file edited through h5py says how to read it."""
    path = io.save_sample(tmp_path / "s.h5", _multi())
    data = path.read_bytes()
    assert re.fullmatch(rb"jaxbpm-sample crc32=[0-9a-f]{8} bytes=%d" % (len(data) - 512), data[:512].split(b"\n")[0])
    damaged = bytearray(data)
    damaged[len(data) // 3] ^= 0x10
    path.write_bytes(bytes(damaged))
    with pytest.raises(SampleFileError, match=r"does not match the CRC-32 in its header \(crc32=[0-9a-f]{8}, the file "
                                              r"gives [0-9a-f]{8}\): the file is damaged"):
        io.load_sample(path)
    path.write_bytes(data.replace(b" bytes=", b" bytes=x", 1))
    with pytest.raises(SampleFileError, match=r"the file's header .* is damaged"):
        io.load_sample(path)
    path.write_bytes(data)
    with h5py.File(path, "a") as f:
        f["particle_material/friction"][()] = 0.4
    with pytest.raises(SampleFileError, match=r"load it with load_sample\(path, verify=False\) .* and save it again"):
        io.load_sample(path)
    edited = io.load_sample(path, verify=False)
    assert edited.particle_material.friction == 0.4
    _assert_same(edited, io.load_sample(io.save_sample(path, edited)))


def test_not_a_jaxbpm_file(tmp_path):
    path = tmp_path / "other.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("x", data=np.zeros(3))
    with pytest.raises(SampleFileError, match="not a jaxbpm sample file"):
        io.load_sample(path)
    with h5py.File(path, "a") as f:
        f.attrs["format"] = "something-else"
    with pytest.raises(SampleFileError, match="something-else"):
        io.load_sample(path)


def test_wrong_format_version(tmp_path):
    path = io.save_sample(tmp_path / "s.h5", _chain())
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = 99
    with pytest.raises(SampleFileError, match=r"format_version 99.*reads format_version 1"):
        io.load_sample(path, verify=False)


@pytest.mark.parametrize("field", ["positions", "bond_radius", "materials/E", "particle_material/friction",
                                   "materials"])
def test_missing_field(tmp_path, field):
    path = io.save_sample(tmp_path / "s.h5", _multi())
    with h5py.File(path, "a") as f:
        del f[field]
    with pytest.raises(SampleFileError, match=f"missing field '/{field}'"):
        io.load_sample(path, verify=False)


def test_missing_attribute(tmp_path):
    path = io.save_sample(tmp_path / "s.h5", _multi())
    with h5py.File(path, "a") as f:
        del f.attrs["domain_hi"]
    with pytest.raises(SampleFileError, match="domain_hi"):
        io.load_sample(path, verify=False)


def test_invalid_content_is_a_sample_error(tmp_path):
    path = io.save_sample(tmp_path / "s.h5", _chain())
    with h5py.File(path, "a") as f:
        f["bonds"][0] = [0, 100]  # bond to a missing particle
    with pytest.raises(SampleError, match=r"s\.h5: bonds reference missing particles"):
        io.load_sample(path, verify=False)


def test_public_api_documented():
    functions = {"save_sample", "load_sample", "export_vtk", "write_json", "atomic_write", "check_writable",
                 "save_local_map", "export_local_map_vtk", "plot_local_map"}
    assert set(io.__all__) == {"FORMAT", "FORMAT_VERSION"} | functions
    for name in functions:
        assert getattr(io, name).__doc__


@pytest.mark.parametrize("field", ["positions", "radii", "bonds", "materials/E"])
def test_a_flipped_byte_is_an_error_naming_the_field(tmp_path, field):
    import h5py

    target = io.save_sample(tmp_path / "s.h5", _multi())
    with h5py.File(target, "r") as f:
        ds = f[field]
        assert ds.fletcher32
        offset = ds.id.get_chunk_info(0).byte_offset
    raw = bytearray(target.read_bytes())
    raw[offset + 3] ^= 0x01  # one bit of the field's first chunk
    target.write_bytes(bytes(raw))
    with pytest.raises(SampleFileError, match="does not match the CRC-32 in its header"):
        io.load_sample(target)
    with pytest.raises(SampleFileError, match=rf"field '/{field}' is corrupt"):
        io.load_sample(target, verify=False)


@pytest.mark.parametrize("field, change, derived", [
    ("positions", lambda d: d.__setitem__((2, 0), d[2, 0] + 1e-3), "bond_length"),
    ("radii", lambda d: d.__setitem__(1, 0.9 * d[1]), "mass"),
    ("bonds", lambda d: d.__setitem__((0, 1), 3), "bond_length"),
    ("bond_radius", lambda d: d.__setitem__(0, 2 * d[0]), "bond_area"),
])
def test_inputs_changed_after_writing_are_an_error(tmp_path, field, change, derived):
    """A file without the header (an older one), edited through h5py (which rewrites the Fletcher-32 sums): the
    derived quantities stored beside the inputs still tell (and deleting /derived accepts an intended edit)."""
    path = _without_header(io.save_sample(tmp_path / "s.h5", _chain()))
    with h5py.File(path, "a") as f:
        data = f[field][()]
        change(data)
        f[field][...] = data
    with pytest.raises(SampleFileError, match=rf"/derived/{derived}\[\d+\] is .* in the file but .* from its "
                                              r"positions.*delete the /derived group"):
        io.load_sample(path)
    with h5py.File(path, "a") as f:
        del f["derived"]
    assert io.load_sample(path).n_bonds == _chain().n_bonds


@pytest.mark.parametrize("edit, changed", [
    (lambda f: f["particle_material/friction"].write_direct(np.asarray(0.31)),
     lambda s: s.particle_material.friction == 0.31),
    (lambda f: f.attrs.__setitem__("domain_lo", np.array([-0.5, -1.0, -1.25])), lambda s: s.domain.lo[2] == -1.25),
    (lambda f: f.attrs.__setitem__("bond_contact", "superimpose"), lambda s: s.bond_contact == "superimpose"),
], ids=["friction", "domain", "bond_contact"])
def test_scalars_and_attributes_changed_after_writing_are_an_error(tmp_path, edit, changed):
    """In a file without the header, what no Fletcher-32 sum covers (scalars, attributes) is covered by the inputs'
    CRC-32 in /derived; without it (an older file, or the attribute deleted to accept an intended edit) the file
    loads as it is."""
    path = _without_header(io.save_sample(tmp_path / "s.h5", _multi()))
    with h5py.File(path, "a") as f:
        edit(f)
    with pytest.raises(SampleFileError, match=r"does not match the file's checksum \(/derived attribute inputs_crc32"
                                              r".*delete the /derived group"):
        io.load_sample(path)
    with h5py.File(path, "a") as f:
        del f["derived"].attrs["inputs_crc32"]
    assert changed(io.load_sample(path))


def test_particle_types_round_trip(tmp_path):
    typed = _chain(types=[1, 4, 4, 2, 0, 7])
    loaded = io.load_sample(io.save_sample(tmp_path / "t.h5", typed))
    _assert_same(typed, loaded)
    assert loaded.types.dtype == np.int32 and loaded.types.tolist() == [1, 4, 4, 2, 0, 7]
    with h5py.File(tmp_path / "t.h5", "r") as f:
        assert f["types"].dtype == np.int32 and f["types"].attrs["units"] == "1"


def test_a_file_without_types_loads_with_type_1_and_verifies(tmp_path):
    # a file written before /types existed: its inputs' CRC-32 did not cover types, and still verifies
    path = _without_header(io.save_sample(tmp_path / "s.h5", _multi()))
    with h5py.File(path, "a") as f:
        del f["types"]
    loaded = io.load_sample(path)
    assert loaded.types.tolist() == [1] * 6
    _assert_same(_multi(), loaded)


def test_types_changed_after_writing_are_an_error(tmp_path):
    path = _without_header(io.save_sample(tmp_path / "s.h5", _chain(types=[1, 2, 2, 2, 1, 1])))
    with h5py.File(path, "a") as f:
        f["types"][0] = 3
    with pytest.raises(SampleFileError, match=r"inputs_crc32"):
        io.load_sample(path)
    assert io.load_sample(path, verify=False).types[0] == 3


def test_two_dimensional_round_trip(tmp_path):
    from jaxbpm.generate import lattice

    s = lattice("square", (4, 3), 1e-3, thickness=0.25, materials={"E": [1e9, 2e9]}, bond_material=np.arange(17) % 2)
    s = s.replace(domain=Domain("box", (-1e-3, -1e-3), (8e-3, 6e-3)))
    back = io.load_sample(io.save_sample(tmp_path / "flat.h5", s))
    _assert_same(s, back)
    assert back.dim == 2 and back.thickness == 0.25
    with h5py.File(tmp_path / "flat.h5", "r") as f:
        assert f["positions"].shape == (12, 2) and float(f.attrs["thickness"]) == 0.25
    plain = io.load_sample(_without_header(tmp_path / "flat.h5"))  # the inputs' CRC covers the thickness
    _assert_same(s, plain)
