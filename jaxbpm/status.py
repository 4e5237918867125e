"""What a solve ended with: :class:`Status`, the same for every solver.

Each member carries the ``message`` that says what it means and the ``error`` that ``throw=True`` raises for it
(``None`` where nothing is raised from the status: a converged solve, or an interruption, which the DEM raises itself
as :class:`~jaxbpm.errors.SimulationInterrupted`).

>>> from jaxbpm.status import Status
>>> Status.CONVERGED == "converged", Status.CONVERGED.ok, Status("max_iterations").error.__name__
(True, True, 'ConvergenceError')
"""

from __future__ import annotations

import enum

from jaxbpm.errors import ConvergenceError, InstabilityError, NotFiniteError, NotQuasiStaticError

__all__ = ["Status"]


class Status(str, enum.Enum):
    """How a solve ended (``Result.status``). A ``str`` enum: ``Status.CONVERGED == "converged"``.

    Attributes:
      message: what the status means.
      error: the :class:`~jaxbpm.errors.SolveError` subclass ``throw=True`` raises for it, or ``None``.
      ok: whether the answer is what the solver promises (``CONVERGED``).
    """

    CONVERGED = "converged", "the answer is what the method promises", None
    MAX_ITERATIONS = ("max_iterations", "an iterative solve stopped at its iteration budget above its tolerance",
                      ConvergenceError)
    UNSTABLE = "unstable", "the DEM's time integration blew up", InstabilityError
    INTERRUPTED = "interrupted", "a DEM run stopped early by Ctrl-C or a callback", None
    NOT_FINITE = "not_finite", "the stiffness came out NaN or infinite", NotFiniteError
    NOT_QUASI_STATIC = ("not_quasi_static", "a DEM run loaded too fast for a static answer (see its stats' imbalance)",
                        NotQuasiStaticError)

    def __new__(cls, value: str, message: str, error):
        member = str.__new__(cls, value)
        member._value_ = value
        member.message = message
        member.error = error
        return member

    @property
    def ok(self) -> bool:
        """Whether the solve converged."""
        return self is Status.CONVERGED

    def __str__(self) -> str:
        return self.value

    def __format__(self, spec) -> str:
        return format(self.value, spec)

    def __repr__(self) -> str:
        return repr(self.value)
