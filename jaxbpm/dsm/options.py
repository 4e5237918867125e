"""The DSM's options, :class:`DSM` (``jaxbpm.DSM``): what ``jaxbpm.solve(..., method="dsm")`` and
:func:`jaxbpm.dsm.solve_scene` take."""

from __future__ import annotations

from jaxbpm._options import choice, flag, fraction, optional, option, positive, SolverOptions, whole

__all__ = ["DSM"]


def _stiffness_tol(name, v):
    if not (isinstance(v, str) and v == "auto"):
        optional(positive)(name, v)


class DSM(SolverOptions):
    """Options of the direct stiffness method (the static solve: linear, or Newton on the nonlinear laws).

    ``jaxbpm.solve(sample, scene, jaxbpm.DSM(dofs=3, stiffness_tol=1e-3))`` is the same solve as
    ``jaxbpm.solve(sample, scene, method="dsm", dofs=3, stiffness_tol=1e-3)``.

    Attributes:
      dofs: 3 or 6 per particle; ``None``: the model's choice (6 with bonds).
      nonlinear: Newton on the nonlinear laws; ``None``: True when the scene has contacts or walls.
      tol: the nonlinear solve's relative residual (``None``: 1e-3).
      linear_tol: the CG's relative residual.
      maxiter: CG iterations at most (``None``: 10 x the free DOFs).
      newton_maxiter: Newton iterations at most per load step.
      stiffness_tol: linear solves: CG also stops once the strain energy, hence K, has settled to this relative
        change; nonlinear: Newton stops when the reaction changes less than this, relative. ``"auto"``: 1e-6 for
        the linear bonds-only solve (K within about 1e-7 of the residual-converged answer, a third fewer CG
        iterations) and off elsewhere; ``None``: the residual tests alone.
      contact_skin: pairs whose gap at rest is below it [m] are contact candidates. ``None``: half the mean radius;
        with ``nonlinear=False`` four times the affine approach of two touching mean-sized particles at the
        linearisation state, doubled up to half a radius while a pair that touches there lies more than half the
        reach apart at rest, each try's time counted in.
      load_steps: nonlinear: equal load increments; K is their least-squares slope over the scene's fit range.
      throw: raise the :class:`~jaxbpm.errors.SolveError` of a failed status (``False``: return the result).
      operator: the tangent operator: ``"jacobians"`` (per-bond Jacobians), ``"jvp"`` or ``"auto"``.
      preconditioner: ``"two-level"`` (aggregation coarse space), ``"jacobi"`` or ``"auto"``.
      aggregate_size: the coarse space's aggregate size [m] (``None``: its default).
      slip: contacts slide at the Coulomb limit; False: no slip (Jarolin & Dosta's assumption, which overestimates
        K where contacts slide).
      contact_fraction: with ``nonlinear=False`` on a scene with contacts, the contacts are linearised (Hertz normal
        and secant Mindlin tangential stiffness, symmetric) at this fraction of the strain (``None``: the middle of
        the fit range), first of the affine field, then of the previous solution.
      contact_passes: the linearised contacts' passes; each starts from the previous one's displacements and all
        but the last stop once the strain energy has settled to 1 %.
      pad: the linear bonds-only solve runs on the sample padded to its size class (held padding particles, bonds
        without stiffness; the same answer to round-off), so that samples of a class share one compiled program;
        its setup is kept for the last few samples.
      geometric_correction: linear bonds-only solves: K corrected for the bonds' geometric nonlinearity from the
        linear displacement field (the exact bond law's work along it); ``stats["stiffness_linear"]`` keeps the
        linear K.
    """

    method = "dsm"

    dofs: int | None = option(None, choice(None, 3, 6))
    nonlinear: bool | None = option(None, optional(flag))
    tol: float | None = option(None, optional(positive))
    linear_tol: float = option(1e-6, positive)
    maxiter: int | None = option(None, optional(whole))
    newton_maxiter: int = option(30, whole)
    stiffness_tol: float | str | None = option("auto", _stiffness_tol)
    contact_skin: float | None = option(None, optional(positive))
    load_steps: int = option(4, whole)
    throw: bool = option(True, flag)
    operator: str = option("auto", choice("auto", "jacobians", "jvp"))
    preconditioner: str = option("auto", choice("auto", "two-level", "jacobi"))
    aggregate_size: float | None = option(None, optional(positive))
    slip: bool = option(True, flag)
    contact_fraction: float | None = option(None, optional(fraction))
    contact_passes: int = option(2, whole)
    pad: bool = option(True, flag)
    geometric_correction: bool = option(False, flag)
