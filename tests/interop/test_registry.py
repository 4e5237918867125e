"""The tables the CLI's help shows (jaxbpm.interop._registry) agree with the readers and conventions they describe,
and load without JAX."""

import pathlib
import subprocess
import sys

import pytest

from jaxbpm.errors import SampleFileError
from jaxbpm.interop import _registry


def test_every_named_reader_is_one(tmp_path):
    from jaxbpm.interop import formats

    for name in _registry.READERS:
        with pytest.raises(SampleFileError) as err:
            formats.read_sample(tmp_path / "missing.txt", format=name)
        assert "unknown format" not in str(err.value), name
    with pytest.raises(SampleFileError, match=f"unknown format 'pfc'; known: {', '.join(_registry.READERS)}$"):
        formats.read_sample(tmp_path / "missing.txt", format="pfc")
    for suffix in _registry.FORMATS:
        assert formats._kind(pathlib.Path(f"s{suffix.upper()}"), "input") == suffix


def test_every_convention_translates_both_ways():
    from jaxbpm.interop import conventions

    assert set(_registry.CONVENTIONS) == {"jaxbpm", "pfc", "lammps", "yade", "musen"}
    for name, spec in _registry.CONVENTIONS.items():
        assert spec["doc"] and spec["params"]
        if name != "jaxbpm":
            assert callable(getattr(conventions, f"to_{name}")) and callable(getattr(conventions, f"from_{name}"))


def test_registry_loads_without_jax():
    code = ("import sys\nfrom jaxbpm.interop import _registry\n"
            "assert _registry.FORMATS and 'jax' not in sys.modules, sorted(sys.modules)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
