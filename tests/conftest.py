"""Strict numerics for every test: float64, strict dtype promotion, no silent rank broadcasting.

The test session has a persistent compilation cache of its own, a temporary directory shared by the pytest-xdist
workers (the first process of the session makes it and passes it on through ``JAXBPM_TEST_XLA_CACHE``; it is
removed when that process exits): a program one worker compiled is read by the other instead of compiled again.
It is also ``JAXBPM_CACHE_DIR``, so ``jaxbpm`` commands run by the tests, in process or as subprocesses, never touch
the user's cache. Tests that change JAX's cache settings get them put back afterwards. XLA's CPU runtime runs on one
thread per process (the xdist workers share the cores).
"""

import atexit
import os
import shutil
import tempfile

_CACHE_DIR = os.environ.get("JAXBPM_TEST_XLA_CACHE")
if not _CACHE_DIR:  # the session's first process (the xdist controller, or the only process): it owns the directory
    os.environ["JAXBPM_TEST_XLA_CACHE"] = _CACHE_DIR = tempfile.mkdtemp(prefix="jaxbpm-test-xla-")
    atexit.register(shutil.rmtree, _CACHE_DIR, ignore_errors=True)
os.environ["JAXBPM_CACHE_DIR"] = _CACHE_DIR
os.environ.setdefault("MPLBACKEND", "Agg")
# each xdist worker keeps to one thread of XLA's CPU runtime: the workers already fill the cores
if "xla_cpu_multi_thread_eigen" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_cpu_multi_thread_eigen=false").strip()
# the suite is bound by compilation (many small programs, each run once or twice on small samples): LLVM's backend
# optimisation off makes it about a third faster (a DSM test 120 s -> 78 s, a DEM test 49 s -> 35 s). Only code
# generation changes -- the same HLO, the same floating-point semantics; speed is measured in the benchmarks, not here
if "xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ["XLA_FLAGS"] + " --xla_backend_optimization_level=0").strip()
# and XLA's older loop emitters for fusions instead of the MLIR fusion emitters: a fifth to a half less compile time
# per program (a DEM chunk with contacts 10.1 s -> 6.1 s, an STE estimate 1.6 s -> 0.7 s), again codegen only
# (jaxlib 0.11 removed those emitters and stops at an unknown flag: there the new emitters compile)
def _jaxlib_before(major, minor):
    from importlib.metadata import version

    return tuple(int(p) for p in version("jaxlib").split(".")[:2]) < (major, minor)


if "xla_cpu_use_fusion_emitters" not in os.environ.get("XLA_FLAGS", "") and _jaxlib_before(0, 11):
    os.environ["XLA_FLAGS"] = (os.environ["XLA_FLAGS"] + " --xla_cpu_use_fusion_emitters=false").strip()

import jax  # noqa: E402
import jax_md  # noqa: E402,F401  (jax-md's import-time code does not pass strict promotion: import it first)
import pytest  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
jax.config.update("jax_numpy_rank_promotion", "raise")

from jaxbpm import _cache  # noqa: E402
from jaxbpm._compile import memory_mappings, release_executables  # noqa: E402

_cache.enable_compilation_cache(_CACHE_DIR)

_CACHE_OPTIONS = ("jax_compilation_cache_dir", "jax_persistent_cache_min_compile_time_secs",
                  "jax_persistent_cache_min_entry_size_bytes", "jax_enable_compilation_cache")


@pytest.fixture(autouse=True)
def jax_cache_config():
    """Put JAX's compilation cache settings back after the test (``jaxbpm.cli.main`` and
    ``jaxbpm.enable_compilation_cache`` change them for the whole process)."""
    saved = {name: jax.config.values[name] for name in _CACHE_OPTIONS if name in jax.config.values}
    yield saved
    changed = {name: value for name, value in saved.items() if jax.config.values[name] != value}
    for name, value in changed.items():
        jax.config.update(name, value)
    if changed:
        from jaxbpm._cache import _reset_jax_cache

        _reset_jax_cache()


# A test process keeps every program it compiled (jaxbpm's programs and JAX's caches hold them), and each executable
# keeps a dozen or more memory mappings: a worker that ran a few hundred tests reached Linux's limit of 65,530
# mappings per process (vm.max_map_count), and the compilation that went over it failed inside XLA and took the
# worker down. After a test that leaves the process above this many mappings, the executables are dropped (a later
# test compiles again, or reads the session's persistent cache); between modules, or anywhere above the hard limit.
_MAPPINGS_SOFT, _MAPPINGS_HARD = 25_000, 45_000


def pytest_runtest_teardown(item, nextitem):
    count = memory_mappings()
    new_module = nextitem is None or nextitem.module is not item.module
    if count > _MAPPINGS_HARD or (count > _MAPPINGS_SOFT and new_module):
        import gc

        release_executables()
        gc.collect()
        if os.environ.get("JAXBPM_TEST_MAPPINGS_LOG"):
            with open(os.environ["JAXBPM_TEST_MAPPINGS_LOG"], "a") as f:
                f.write(f"{os.getpid()} {item.nodeid} {count} -> {memory_mappings()}\n")
