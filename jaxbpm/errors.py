"""Exceptions raised by jaxbpm. Every error names the problem and, where it can, the offending items."""

__all__ = [
    "JaxbpmError",
    "SampleError",
    "SampleFileError",
    "InstabilityError",
    "ConvergenceError",
    "NotFiniteError",
    "NotQuasiStaticError",
    "SolveError",
    "SceneError",
    "GroupError",
    "OptionsError",
    "SimulationInterrupted",
]


class JaxbpmError(Exception):
    """Base class of every jaxbpm error."""


class SampleError(JaxbpmError, ValueError):
    """A bonded sample is malformed (bad shapes, NaN, bonds to missing particles, ...)."""


class SampleFileError(JaxbpmError, OSError):
    """A sample file is missing, corrupt, of the wrong format version or lacks a field."""


class SceneError(JaxbpmError, ValueError):
    """A scene (boundary conditions, loading) does not fit the sample or is ill-posed."""


class GroupError(SceneError):
    """A boundary group (the particles a scene clamps or moves) selects nothing, overlaps another, is cut off from it
    by the bonds, or does not fit the sample. A :class:`SceneError`. ``group``: the group's name (``"fixed"``,
    ``"driven"``, ...); ``particles``: the indices of the particles at fault (empty where none are).
    """

    def __init__(self, message: str, group: str = "", particles=()):
        super().__init__(message)
        self.group = group
        self.particles = tuple(int(i) for i in particles)


class OptionsError(SceneError):
    """A solver option is unknown (the message names the closest ones) or out of its range (the message names the
    option). A :class:`SceneError`, so that ``except SceneError`` catches it."""


class SolveError(JaxbpmError, RuntimeError):
    """A solve did not produce a trustworthy answer (``Result.status`` other than ``"converged"``; raised by
    ``throw=True``, the default). ``result``: the :class:`~jaxbpm.result.Result` of what was computed (its
    ``status`` says which failure), or ``None`` where the failure left nothing to report."""

    result = None

    def __init__(self, *args, result=None):
        super().__init__(*args)
        self.result = result


class InstabilityError(SolveError):
    """An explicit time integration blew up (NaN or runaway kinetic energy): status ``"unstable"``."""


class ConvergenceError(SolveError):
    """An iterative solve did not reach its tolerance within its iteration budget: status ``"max_iterations"``."""


class NotFiniteError(SolveError):
    """A solve returned a stiffness that is NaN or infinite: status ``"not_finite"``."""


class NotQuasiStaticError(SolveError):
    """A DEM run was loaded too fast for a static answer (its ends out of balance, its curve not a line): status
    ``"not_quasi_static"``."""


class ConventionError(JaxbpmError, ValueError):
    """Bond parameters of another code's convention have no counterpart in jaxbpm's bond law (or are malformed)."""


class SimulationInterrupted(KeyboardInterrupt):
    """A DEM run was interrupted (Ctrl-C, or a ``KeyboardInterrupt`` raised by a progress or chunk callback).

    It is a ``KeyboardInterrupt`` (an uncaught one still stops a script), carrying what was computed: ``state`` (the
    DEM state after the last completed chunk), ``records`` (the per-step records of the completed chunks) and
    ``stats`` (with ``interrupted=True``, ``steps`` done and ``steps_planned``). :func:`jaxbpm.solve` adds
    ``result``, a :class:`~jaxbpm.result.Result` of the part that was run (``result.interrupted`` is True).
    """

    def __init__(self, state, records, stats, result=None):
        super().__init__(f"DEM run interrupted after {stats.get('steps', 0)} of {stats.get('steps_planned', '?')} "
                         "steps; the exception carries the state and records so far")
        self.state, self.records, self.stats, self.result = state, records, stats, result
