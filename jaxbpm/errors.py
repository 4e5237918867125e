"""Exceptions raised by jaxbpm. Every error names the problem and, where it can, the offending items."""

__all__ = [
    "JaxbpmError",
    "SampleError",
    "SampleFileError",
    "InstabilityError",
    "ConvergenceError",
    "SceneError",
]


class JaxbpmError(Exception):
    """Base class of every jaxbpm error."""


class SampleError(JaxbpmError, ValueError):
    """A bonded sample is malformed (bad shapes, NaN, bonds to missing particles, ...)."""


class SampleFileError(JaxbpmError, OSError):
    """A sample file is missing, corrupt, of the wrong format version or lacks a field."""


class SceneError(JaxbpmError, ValueError):
    """A scene (boundary conditions, loading) does not fit the sample or is ill-posed."""


class InstabilityError(JaxbpmError, RuntimeError):
    """An explicit time integration blew up (NaN or runaway kinetic energy)."""


class ConvergenceError(JaxbpmError, RuntimeError):
    """An iterative solve did not reach its tolerance."""


class ConventionError(JaxbpmError, ValueError):
    """Bond parameters of another code's convention have no counterpart in jaxbpm's bond law (or are malformed)."""
