"""jaxbpm: calibrate bonded-particle models fast, with one physics solved three ways (DEM, DSM, STE) in JAX.

jaxbpm never changes JAX's global settings at import. Stiffness solves want float64: call
``jax.config.update("jax_enable_x64", True)`` before creating arrays (the ``jaxbpm`` command does this).
"""

from jaxbpm import errors, generate, io, scenes
from jaxbpm._cache import compilation_cache_dir, default_cache_dir, enable_compilation_cache
from jaxbpm.options import DEM, DSM, STE
from jaxbpm.errors import (ConvergenceError, InstabilityError, JaxbpmError, NotFiniteError, SampleError,
                           SampleFileError, SceneError, SimulationInterrupted, SolveError)
from jaxbpm.result import Result
from jaxbpm.sample import BondMaterials, Domain, ParticleMaterial, Sample, SampleSummary
from jaxbpm.solving import solve

from jaxbpm._version import __version__

__all__ = [
    "Sample", "BondMaterials", "ParticleMaterial", "Domain", "SampleSummary",
    "generate", "io", "errors", "scenes", "solve", "Result",
    "JaxbpmError", "SampleError", "SampleFileError", "SceneError", "SolveError", "InstabilityError", "ConvergenceError",
    "NotFiniteError",
    "SimulationInterrupted",
    "enable_compilation_cache", "compilation_cache_dir", "default_cache_dir",
    "DEM", "DSM", "STE", "count_compilations",
]

# submodules loaded on first use (``jaxbpm.dsm``, ``jaxbpm.calibrate``, ...): ``import jaxbpm`` stays cheap
_LAZY = ("dem", "dsm", "ste", "sweep", "calibrate", "interop", "records", "options", "physics", "sample", "result",
         "formats", "conventions")  # (the last two: old names of jaxbpm.interop's modules, deprecated)


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return importlib.import_module(f"jaxbpm.{name}")
    if name == "count_compilations":
        from jaxbpm._compile import count_compilations

        return count_compilations
    raise AttributeError(f"module 'jaxbpm' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY) | {"count_compilations"})
