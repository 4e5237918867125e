"""jaxbpm: calibrate bonded-particle models fast, with one physics solved three ways (DEM, DSM, STE) in JAX.

jaxbpm never changes JAX's global settings at import. Stiffness solves want float64: call
``jax.config.update("jax_enable_x64", True)`` before creating arrays (the ``jaxbpm`` command does this).

``import jaxbpm`` does not import JAX: the names below that need it (samples, solvers, scenes, ...) and the
submodules load on first use, so ``jaxbpm --help`` answers at once.

A walkthrough: a small face-centred cubic lattice of bonded spheres, compressed by 0.1 % along z, solved by the
stiffness tensor estimate (STE, no solve: seconds to compile, milliseconds to run) and by the direct stiffness
method (DSM, a static solve of the same bond law). The estimate is close to the solve, not equal to it.

Examples:
    >>> import jax
    >>> jax.config.update("jax_enable_x64", True)
    >>> import jaxbpm
    >>> sample = jaxbpm.generate.lattice("fcc", (2, 2, 2), materials={"E": 1e9, "nu": 0.25})
    >>> sample.n_particles, sample.n_bonds
    (63, 240)
    >>> scene = jaxbpm.scenes.UniaxialCompression(strain=0.001)
    >>> ste = jaxbpm.solve(sample, scene, method="ste")
    >>> dsm = jaxbpm.solve(sample, scene, method="dsm")
    >>> print(f"E: STE {ste.youngs_modulus / 1e6:.0f} MPa, DSM {dsm.youngs_modulus / 1e6:.0f} MPa")
    E: STE 286 MPa, DSM 254 MPa
    >>> 1.0 < ste.stiffness / dsm.stiffness < 1.2  # the 3-DOF estimate, clamped ends, against the 6-DOF solve
    True
"""

from jaxbpm import errors
from jaxbpm._cache import compilation_cache_dir, default_cache_dir, enable_compilation_cache
from jaxbpm.errors import (ConvergenceError, InstabilityError, JaxbpmError, NotFiniteError, NotQuasiStaticError,
                           OptionsError, SampleError, SampleFileError, SceneError, SimulationInterrupted, SolveError)

from jaxbpm._version import __version__

__all__ = [
    "Sample", "BondMaterials", "ParticleMaterial", "Domain", "SampleSummary",
    "generate", "io", "errors", "scenes", "solve", "Result",
    "JaxbpmError", "SampleError", "SampleFileError", "SceneError", "SolveError", "InstabilityError", "ConvergenceError",
    "NotFiniteError",
    "NotQuasiStaticError",
    "SimulationInterrupted",
    "enable_compilation_cache", "compilation_cache_dir", "default_cache_dir",
    "DEM", "DSM", "STE", "SolverOptions", "Status", "OptionsError", "count_compilations",
]

# submodules loaded on first use (``jaxbpm.dsm``, ``jaxbpm.calibrate``, ...): ``import jaxbpm`` stays cheap
_LAZY = ("generate", "io", "scenes", "dem", "dsm", "ste", "sweep", "calibrate", "interop",
         "physics", "sample", "result", "status", "plots")
# names loaded on first use: name -> the module that defines it
_LAZY_NAMES = {
    "Sample": "jaxbpm.sample", "BondMaterials": "jaxbpm.sample", "ParticleMaterial": "jaxbpm.sample",
    "Domain": "jaxbpm.sample", "SampleSummary": "jaxbpm.sample", "solve": "jaxbpm.solving",
    "Result": "jaxbpm.result", "DEM": "jaxbpm.dem.options", "DSM": "jaxbpm.dsm.options", "STE": "jaxbpm.ste.options",
    "Status": "jaxbpm.status", "SolverOptions": "jaxbpm._options",
    "count_compilations": "jaxbpm._compile", "solve_batch": "jaxbpm.dem.batched",
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
