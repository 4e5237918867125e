"""The persistent compilation cache: ``jaxbpm.enable_compilation_cache`` and the command's cache options.

Every test here runs under the ``jax_cache_config`` fixture of conftest.py, which puts JAX's cache settings back
afterwards, so the rest of the suite runs with the session's cache (conftest.py).
"""

import os
import pathlib
import sys
import uuid

import jax
import jax.numpy as jnp
import pytest

import jaxbpm
from jaxbpm import _cache, cli


def _entries(path):
    return sorted(p.name for p in pathlib.Path(path).iterdir() if p.name.endswith("-cache"))


def _compile_new_program():
    """jit-compile and run a program no earlier test compiled (a constant of its own), so it is not in memory."""
    c = float(uuid.uuid4().int % 10**6) + 0.5
    out = jax.jit(lambda x: jnp.sin(x) * c + x)(jnp.arange(4.0))
    out.block_until_ready()
    return out


def test_enable_writes_entries_and_switches_directory(tmp_path, jax_cache_config):
    first = tmp_path / "first" / "nested"
    # earlier tests compiled with the cache off: JAX took note of that, and enabling must undo it
    assert jaxbpm.enable_compilation_cache(first) == first
    assert first.is_dir() and _entries(first) == []
    assert jaxbpm.compilation_cache_dir() == first
    assert jax.config.jax_compilation_cache_dir == str(first)
    assert jax.config.jax_persistent_cache_min_compile_time_secs == 0
    assert jax.config.jax_persistent_cache_min_entry_size_bytes == 0
    _compile_new_program()
    assert len(_entries(first)) >= 1

    # another directory takes effect in the same process
    second = tmp_path / "second"
    assert jaxbpm.enable_compilation_cache(str(second)) == second
    n_first = len(_entries(first))
    _compile_new_program()
    assert len(_entries(second)) >= 1 and len(_entries(first)) == n_first
    entries, size = _cache.usage(second)
    assert entries == len(_entries(second)) and size >= sum(p.stat().st_size for p in second.iterdir()) > 0


def test_fixture_put_the_session_cache_back():
    # the test above (and the in-process commands of test_cli) leave the session's cache as it was
    assert jax.config.jax_compilation_cache_dir == os.environ["JAXBPM_TEST_XLA_CACHE"]
    assert jaxbpm.compilation_cache_dir() == pathlib.Path(os.environ["JAXBPM_TEST_XLA_CACHE"])


def test_default_dir(monkeypatch, tmp_path):
    monkeypatch.setenv("JAXBPM_CACHE_DIR", str(tmp_path / "mine"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert jaxbpm.default_cache_dir() == tmp_path / "mine"
    monkeypatch.setenv("JAXBPM_CACHE_DIR", "")  # empty = not set
    monkeypatch.setattr(sys, "platform", "linux")
    assert jaxbpm.default_cache_dir() == tmp_path / "xdg" / "jaxbpm" / "xla"
    monkeypatch.delenv("JAXBPM_CACHE_DIR")
    assert jaxbpm.default_cache_dir() == tmp_path / "xdg" / "jaxbpm" / "xla"
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/ignored")
    assert jaxbpm.default_cache_dir() == tmp_path / "home" / ".cache" / "jaxbpm" / "xla"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert jaxbpm.default_cache_dir() == tmp_path / "home" / ".cache" / "jaxbpm" / "xla"
    monkeypatch.setattr(sys, "platform", "darwin")
    assert jaxbpm.default_cache_dir() == tmp_path / "home" / "Library" / "Caches" / "jaxbpm" / "xla"
    assert not (tmp_path / "home").exists()  # only computes the path


def test_enable_uses_default_dir(monkeypatch, tmp_path, jax_cache_config):
    monkeypatch.setenv("JAXBPM_CACHE_DIR", str(tmp_path / "env"))
    assert jaxbpm.enable_compilation_cache() == tmp_path / "env" and (tmp_path / "env").is_dir()
    assert jaxbpm.compilation_cache_dir() == tmp_path / "env"


def test_file_in_the_way(tmp_path, jax_cache_config):
    blocker = tmp_path / "blocker"
    blocker.write_text("not a directory")
    with pytest.raises(NotADirectoryError, match="blocker.*is a file"):
        jaxbpm.enable_compilation_cache(blocker)
    with pytest.raises(OSError, match=r"blocker.xla.*parents is a file"):
        jaxbpm.enable_compilation_cache(blocker / "xla")
    assert jax.config.jax_compilation_cache_dir == jax_cache_config["jax_compilation_cache_dir"]  # unchanged


def test_cli_info_cache(tmp_path, capsys, jax_cache_config):
    target = tmp_path / "cli-cache"
    assert cli.main(["info", "--cache", "--cache-dir", str(target)]) == 0
    out = capsys.readouterr().out
    assert f"cache directory      {target}\n" in out and "compilation cache    on" in out
    assert "cached programs      0" in out and target.is_dir()
    assert jaxbpm.compilation_cache_dir() == target

    _compile_new_program()  # the cache is now on in this process: the program lands in it
    assert cli.main(["--cache-dir", str(target), "info", "--cache"]) == 0
    out = capsys.readouterr().out
    assert f"cached programs      {len(_entries(target))}" in out and len(_entries(target)) >= 1


def test_cli_no_cache(tmp_path, capsys, jax_cache_config):
    before = jax.config.jax_compilation_cache_dir
    assert cli.main(["--no-cache", "info", "--cache"]) == 0
    out = capsys.readouterr().out
    assert jax.config.jax_compilation_cache_dir == before
    if before is None:  # (not set through JAX_COMPILATION_CACHE_DIR)
        assert "compilation cache    off (--no-cache)" in out
        assert f"cache directory      {jaxbpm.default_cache_dir()}\n" in out
    assert cli.main(["info", "--cache", "--no-cache"]) == 0  # after the command too
    assert jax.config.jax_compilation_cache_dir == before


def test_cli_cache_errors(tmp_path, capsys, monkeypatch, jax_cache_config):
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    # an explicit --cache-dir that cannot be used: one-line error, exit 2
    assert cli.main(["info", "--cache", "--cache-dir", str(blocker)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and str(blocker) in err and err.count("\n") == 1
    # the default directory that cannot be used: a warning, and the command runs without the cache (the session's
    # cache turned off first, as in a new process)
    jax.config.update("jax_enable_compilation_cache", False)
    monkeypatch.setenv("JAXBPM_CACHE_DIR", str(blocker))
    assert cli.main(["info", "--cache"]) == 0
    out, err = capsys.readouterr()
    assert err.startswith("warning: ") and str(blocker) in err and "compilation cache    off" in out
    with pytest.raises(SystemExit) as exc:
        cli.main(["--no-cache", "--cache-dir", str(tmp_path), "info", "--cache"])
    assert exc.value.code == 2 and "exclude each other" in capsys.readouterr().err
