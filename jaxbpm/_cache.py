"""JAX's persistent compilation cache: compiled programs kept on disk, so a new process loads them instead of
compiling them again.

Opt-in for library users (one call, :func:`enable_compilation_cache`); the ``jaxbpm`` command turns it on by default.
Nothing here runs at import.
"""

from __future__ import annotations

import os
import pathlib
import sys

__all__ = ["enable_compilation_cache", "compilation_cache_dir", "default_cache_dir"]

ENV_VAR = "JAXBPM_CACHE_DIR"
# The JAX options this module sets: the directory, and "cache every program, however small or quick to compile"
# (JAX's defaults skip programs that compile in under 1 s, which is most of a jaxbpm run on small samples).
_DIR_OPTION = "jax_compilation_cache_dir"
_MIN_TIME_OPTION = "jax_persistent_cache_min_compile_time_secs"
_MIN_SIZE_OPTION = "jax_persistent_cache_min_entry_size_bytes"
_ENABLE_OPTION = "jax_enable_compilation_cache"
_ENTRY_SUFFIX = "-cache"  # JAX's file cache writes one '<key>-cache' file per compiled program


def default_cache_dir() -> pathlib.Path:
    """The directory :func:`enable_compilation_cache` uses when it is given none.

    ``$JAXBPM_CACHE_DIR`` if set (and not empty), else the user's cache directory + ``jaxbpm/xla``:
    ``$XDG_CACHE_HOME/jaxbpm/xla`` or ``~/.cache/jaxbpm/xla`` on Linux and other Unix systems,
    ``~/Library/Caches/jaxbpm/xla`` on macOS, ``%LOCALAPPDATA%\\jaxbpm\\xla`` on Windows. Only computes the path:
    creates nothing and changes no setting.

    Returns:
      An absolute path (``~`` expanded).
    """
    env = os.environ.get(ENV_VAR)
    if env:
        return _absolute(env)
    if sys.platform == "win32":
        base = os.environ.get("LOCALAPPDATA") or os.path.join("~", "AppData", "Local")
    elif sys.platform == "darwin":
        base = os.path.join("~", "Library", "Caches")
    else:
        xdg = os.environ.get("XDG_CACHE_HOME", "")
        # the XDG specification: a relative XDG_CACHE_HOME is invalid and ignored
        base = xdg if xdg and os.path.isabs(os.path.expanduser(xdg)) else os.path.join("~", ".cache")
    return _absolute(base) / "jaxbpm" / "xla"


def enable_compilation_cache(path: str | os.PathLike | None = None) -> pathlib.Path:
    """Turn on JAX's persistent compilation cache in ``path``, so compiled programs carry across processes.

    The first run of a scene compiles its programs (seconds to tens of seconds for DEM and DSM); with the cache on,
    later processes on the same machine, JAX version and settings load them from disk instead. Every program is
    cached, however small or quick to compile.

    This changes JAX's global configuration for the whole process (that is why the library never calls it; the
    ``jaxbpm`` command does, unless given ``--no-cache``):

    - ``jax_compilation_cache_dir`` = ``path``;
    - ``jax_persistent_cache_min_compile_time_secs`` = 0 (JAX's default, 1 s, skips most small programs);
    - ``jax_persistent_cache_min_entry_size_bytes`` = 0 (no size threshold);
    - ``jax_enable_compilation_cache`` = True.

    If JAX already set up its cache in this process (another directory, or the cache found off at an earlier
    compilation), it is reset so that ``path`` takes effect for the next compilation. Programs already compiled
    in this process stay in memory and are not written to ``path``. Call it again with another path to switch.

    The cache is trusted: anyone who can write to ``path`` can make this process run code, so do not point it at a
    directory others can write to. The directory grows with every new program; delete it to clear it.

    Args:
      path: directory of the cache, created (with its parents) if missing. Default: :func:`default_cache_dir`,
        i.e. ``$JAXBPM_CACHE_DIR`` or the user's cache directory (``~/.cache/jaxbpm/xla`` on Linux).

    Returns:
      The cache directory, absolute.

    Raises:
      NotADirectoryError: ``path`` (or one of its parents) is a file; the message names it.
      PermissionError: ``path`` cannot be created or written to; the message names it.
      OSError: ``path`` cannot be created for another reason; the message names it.
    """
    import jax

    path = default_cache_dir() if path is None else _absolute(path)
    _make_dir(path)
    changed = compilation_cache_dir() != path
    jax.config.update(_DIR_OPTION, str(path))
    for name, value in ((_MIN_TIME_OPTION, 0.0), (_MIN_SIZE_OPTION, 0), (_ENABLE_OPTION, True)):
        if name in jax.config.values:  # all present in jax 0.4.x-0.10; skip any a later JAX drops
            jax.config.update(name, value)
    if changed or not _cache_active():
        _reset_jax_cache()
    return path


def compilation_cache_dir() -> pathlib.Path | None:
    """The directory of JAX's persistent compilation cache in this process, or None when the cache is off.

    Reads JAX's configuration (``jax_compilation_cache_dir``, ``jax_enable_compilation_cache``), so it also reports
    a directory set through JAX itself, e.g. with ``JAX_COMPILATION_CACHE_DIR``.

    Returns:
      The absolute directory, or ``None``.
    """
    import jax

    directory = jax.config.values.get(_DIR_OPTION)
    if not directory or not jax.config.values.get(_ENABLE_OPTION, True):
        return None
    return pathlib.Path(directory)


def _absolute(path: str | os.PathLike) -> pathlib.Path:
    return pathlib.Path(os.path.abspath(os.path.expanduser(os.fspath(path))))


def _make_dir(path: pathlib.Path) -> None:
    """Create ``path`` if missing and check it is a writable directory; errors name the path."""
    what = f"the compilation cache directory {path}"
    if path.exists() and not path.is_dir():
        raise NotADirectoryError(f"cannot use {what}: it is a file, not a directory")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise NotADirectoryError(f"cannot create {what}: one of its parents is a file") from None
    except OSError as exc:
        raise type(exc)(f"cannot create {what}: {exc.strerror or exc}") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise PermissionError(f"cannot use {what}: it is not writable")


def _cache_active() -> bool:
    """Whether JAX's cache object is built and in use (False also when JAX has not looked at it yet)."""
    try:
        from jax._src import compilation_cache as cc

        return bool(cc._cache is not None and cc._cache_used)
    except (ImportError, AttributeError):
        return False


def _reset_jax_cache() -> None:
    """Make JAX build its cache again from the current configuration at the next compilation.

    JAX builds its cache object once, and decides once per process (at the first compilation) whether the cache is
    used; both are reset here. Private JAX API, hence guarded: without it a new directory takes effect only in a
    new process.
    """
    try:
        from jax._src import compilation_cache as cc

        cc.reset_cache()
    except (ImportError, AttributeError):
        pass


def usage(path: str | os.PathLike) -> tuple[int, int]:
    """What a compilation cache directory holds.

    Args:
      path: the directory.

    Returns:
      ``(number of cached programs, total bytes of all files)`` under ``path``; ``(0, 0)`` if it does not exist.
    """
    entries = size = 0
    for root, _dirs, files in os.walk(path):
        for name in files:
            try:
                size += os.stat(os.path.join(root, name)).st_size
            except OSError:  # removed meanwhile, by JAX's eviction or another process
                continue
            entries += name.endswith(_ENTRY_SUFFIX)
    return entries, size


