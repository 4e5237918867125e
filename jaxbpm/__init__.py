"""jaxbpm: calibrate bonded-particle models fast, with one physics solved three ways (DEM, DSM, STE) in JAX.

jaxbpm never changes JAX's global settings at import. Stiffness solves want float64: call
``jax.config.update("jax_enable_x64", True)`` before creating arrays (the ``jaxbpm`` command does this).
"""

from jaxbpm import errors, generate, io, scenes
from jaxbpm.errors import (ConvergenceError, InstabilityError, JaxbpmError, SampleError, SampleFileError,
                           SceneError, SimulationInterrupted)
from jaxbpm.result import Result
from jaxbpm.sample import BondMaterials, Domain, ParticleMaterial, Sample, SampleSummary
from jaxbpm.solve import solve

__version__ = "0.1.0"

__all__ = [
    "Sample", "BondMaterials", "ParticleMaterial", "Domain", "SampleSummary",
    "generate", "io", "errors", "scenes", "solve", "Result",
    "JaxbpmError", "SampleError", "SampleFileError", "SceneError", "InstabilityError", "ConvergenceError",
    "SimulationInterrupted",
]
