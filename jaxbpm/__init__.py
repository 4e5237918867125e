"""jaxbpm: calibrate bonded-particle models fast, with one physics solved three ways (DEM, DSM, STE) in JAX.

jaxbpm never changes JAX's global settings at import. Stiffness solves want float64: call
``jax.config.update("jax_enable_x64", True)`` before creating arrays (the ``jaxbpm`` command does this).

``import jaxbpm`` does not import JAX: the names below that need it (samples, solvers, scenes, ...) and the
submodules load on first use, so ``jaxbpm --help`` answers at once.
"""

from jaxbpm import errors
from jaxbpm._cache import compilation_cache_dir, default_cache_dir, enable_compilation_cache
from jaxbpm.errors import (ConvergenceError, InstabilityError, JaxbpmError, NotFiniteError, OptionsError, SampleError,
                           SampleFileError, SceneError, SimulationInterrupted, SolveError)

from jaxbpm._version import __version__

__all__ = [
    "Sample", "BondMaterials", "ParticleMaterial", "Domain", "SampleSummary",
    "generate", "io", "errors", "scenes", "solve", "Result",
    "JaxbpmError", "SampleError", "SampleFileError", "SceneError", "SolveError", "InstabilityError", "ConvergenceError",
    "NotFiniteError",
    "SimulationInterrupted",
    "enable_compilation_cache", "compilation_cache_dir", "default_cache_dir",
    "DEM", "DSM", "STE", "SolverOptions", "Status", "OptionsError", "count_compilations",
]

# submodules loaded on first use (``jaxbpm.dsm``, ``jaxbpm.calibrate``, ...): ``import jaxbpm`` stays cheap
_LAZY = ("generate", "io", "scenes", "dem", "dsm", "ste", "sweep", "calibrate", "interop", "records", "options",
         "physics", "sample", "result", "status",
         "formats", "conventions")  # (the last two: old names of jaxbpm.interop's modules, deprecated)
# names loaded on first use: name -> the module that defines it
_LAZY_NAMES = {
    "Sample": "jaxbpm.sample", "BondMaterials": "jaxbpm.sample", "ParticleMaterial": "jaxbpm.sample",
    "Domain": "jaxbpm.sample", "SampleSummary": "jaxbpm.sample", "solve": "jaxbpm.solving",
    "Result": "jaxbpm.result", "DEM": "jaxbpm.options", "DSM": "jaxbpm.dsm.options", "STE": "jaxbpm.ste.options",
    "Status": "jaxbpm.status", "SolverOptions": "jaxbpm._options",
    "count_compilations": "jaxbpm._compile", "solve_batch": "jaxbpm.batched",
}


def __getattr__(name):
    import importlib

    if name in _LAZY:
        return importlib.import_module(f"jaxbpm.{name}")
    if name in _LAZY_NAMES:
        value = getattr(importlib.import_module(_LAZY_NAMES[name]), name)
        globals()[name] = value  # later look-ups skip this function
        return value
    raise AttributeError(f"module 'jaxbpm' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY) | set(_LAZY_NAMES))
