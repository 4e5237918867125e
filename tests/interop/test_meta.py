"""The metadata line, checksums and number format shared by the LAMMPS and CSV files (jaxbpm.interop._meta)."""

import zlib

import numpy as np
import pytest

from jaxbpm.errors import SampleError, SampleFileError
from jaxbpm.interop import _meta
from jaxbpm.sample import Domain
from tests.interop.samples import _multi


def test_exact_text_round_trips_every_float():
    values = np.random.default_rng(0).standard_normal(200) * 10.0 ** np.arange(-100, 100)
    assert all(float(_meta.exact_text(v)) == v for v in values)
    assert _meta.exact_text(np.float32(0.1)) == repr(float(np.float32(0.1)))


def test_meta_line_round_trip():
    sample = _multi()
    line = _meta.meta_line(_meta.meta_of(sample, normalize=True))
    assert line.startswith(_meta.META) and "\n" not in line
    meta = _meta.parse_meta(line, "f:1")
    assert meta["normalize"] is True and meta["bond_contact"] == "replace"
    assert meta["materials"]["E"] == [1e9, 2.5e9, 7e10]
    assert _meta.domain_of(meta) == Domain("cylinder", (-0.5, -1.0, -1.0), (5.5, 1.0, 1.0))
    assert _meta.domain_of(None) is None and _meta.parse_meta("# another comment", "f:1") is None
    with pytest.raises(SampleFileError, match=r"^f:2: unreadable jaxbpm header comment"):
        _meta.parse_meta(_meta.META + "{broken", "f:2")
    with pytest.raises(SampleFileError, match=r"^f:3: the '# jaxbpm' header comment is not a jaxbpm exchange header"):
        _meta.parse_meta(_meta.META + '{"format": "other"}', "f:3")


def test_checksums_against_zlib():
    text = "line one\nline two é\n"
    assert _meta.crc32(text) == f"{zlib.crc32(text.encode()):08x}"
    assert _meta.without_line("a\nb\r\nc", 1) == "a\nc" and _meta.without_line("a\nb", 0) == "b"
    assert _meta.checksums("title crc32=0123abcd", "f:1", ("crc32",)) == {"crc32": "0123abcd"}
    with pytest.raises(SampleFileError, match=r"^f:1: malformed checksum crc32 in 'title crc32=0123abc'"):
        _meta.checksums("title crc32=0123abc", "f:1", ("crc32",))
    _meta.verify(text, "crc32", _meta.crc32(text), "f", "line 1", "delete it")
    with pytest.raises(SampleFileError, match=r"^f: the content does not match its CRC-32 checksum .* To accept an "
                                              r"intended edit, delete it \(the file is then read as it is\)"):
        _meta.verify(text + "x", "crc32", _meta.crc32(text), "f", "line 1", "delete it")


def test_names_file_prefixes_errors_once():
    @_meta.names_file
    def read(path, message):
        raise SampleError(message)

    with pytest.raises(SampleError, match=r"^a\.txt: bad$"):
        read("a.txt", "bad")
    with pytest.raises(SampleError, match=r"^a\.txt:3: bad$"):
        read("a.txt", "a.txt:3: bad")


def test_read_text_names_what_is_wrong(tmp_path):
    (tmp_path / "t.txt").write_text("x\n")
    assert _meta.read_text(tmp_path / "t.txt") == "x\n"
    with pytest.raises(SampleFileError, match=r"missing\.txt: no such file"):
        _meta.read_text(tmp_path / "missing.txt")
    with pytest.raises(SampleFileError, match=r": is a directory, not a file"):
        _meta.read_text(tmp_path)
    (tmp_path / "b.bin").write_bytes(b"\xff\xfe\x00\x81")
    with pytest.raises(SampleFileError, match=r"b\.bin: not a text file"):
        _meta.read_text(tmp_path / "b.bin")


def test_meta_of_a_2d_sample():
    """A 2D sample's header holds dim 2, its thickness and a 2-component domain; a damaged one is named."""
    import json

    import jaxbpm

    sample = jaxbpm.generate.lattice("square", (3, 2)).replace(thickness=0.7)
    meta = _meta.parse_meta(_meta.meta_line(_meta.meta_of(sample)), "f:1")
    assert meta["dim"] == 2 and meta["thickness"] == 0.7 and len(meta["domain"]["lo"]) == 2
    assert "dim" not in _meta.meta_of(_multi())
    for bad, field in (({"thickness": None}, "thickness"), ({"dim": 4}, "dim"), ({"dim": 3}, "domain")):
        damaged = {**meta, **bad}
        with pytest.raises(SampleFileError, match=repr(field)):
            _meta.parse_meta(_meta.META + json.dumps(damaged), "f:1")
