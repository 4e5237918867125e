"""What a solve returns: the observables of a scene, what they cost, and how the solver got there."""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np

from jaxbpm.status import Status

__all__ = ["Result", "STATUSES", "Status", "Timings", "timed_result", "settle"]

STATUSES = tuple(s.value for s in Status)
"""The values ``Result.status`` can take (:class:`~jaxbpm.status.Status` says what each means)."""


@dataclasses.dataclass
class Result:
    """Outcome of :func:`jaxbpm.solve` on a scene, the same for every solver.

    With ``throw=True`` (the default of every solver) a status other than ``"converged"`` raises its
    ``Status.error`` (which carries this result); ``throw=False`` returns the result and leaves the status to the
    caller.

    Attributes:
      method: the solver (``"dem"``, ``"dsm"``, ``"ste"``).
      stiffness: K = dF/d(displacement) over the linear range [N/m].
      youngs_modulus: E = K l / A [Pa].
      gauge_length: l [m].
      area: A [m^2].
      displacement: ``[m]`` the loading curve's displacements [m] (compression positive); ``strain`` is the same
        over l.
      force: ``[m]`` its forces [N]; ``stress`` is the same over A.
      wall_time: what the call took [s], ``setup_time + compile_time + run_time``.
      compile_time: tracing and compiling the solver's programs [s] (0 when this process, or the persistent
        compilation cache, had them).
      run_time: the solver's kernel, run once [s].
      stats: solver details (steps, time step, critical time step, iterations, ...); ``stats["failure"]`` says
        what went wrong. A DEM run also has ``peak_force``, ``strength``, ``strain_at_peak`` and ``stop_reason``
        (``"after_peak"``: stopped once the force fell past its peak, see the scenes' ``stop_after_peak``;
        ``"full_strain"``, ``"unstable"``, ``"interrupted"``).
      state: the solver's final state (for restarts and inspection).
      interrupted: the run was stopped early (see :class:`~jaxbpm.errors.SimulationInterrupted`); the curve and
        stats cover the part that was run (stiffness NaN when the fit range was not reached).
      setup_time: building the model, estimator, geometry, preconditioner or neighbour list, on the host [s].
      status: a :class:`~jaxbpm.status.Status` (a ``str``: ``result.status == "converged"``); ``ok`` is
        ``status == "converged"``.
    """

    method: str
    stiffness: float
    youngs_modulus: float
    gauge_length: float
    area: float
    displacement: np.ndarray
    force: np.ndarray
    wall_time: float
    compile_time: float
    run_time: float
    stats: dict = dataclasses.field(default_factory=dict)
    state: Any = None
    interrupted: bool = False
    setup_time: float = 0.0
    status: Status = Status.CONVERGED

    def __post_init__(self):
        self.status = Status(self.status)

    @property
    def poisson_ratio(self) -> float | None:
        """Poisson's ratio of the scene, ``-lateral / axial`` strain in the middle third of the sample (DEM: an
        elastic run's loaded state; DSM: the static solution; see
        :meth:`~jaxbpm.scenes.UniaxialCompression.lateral_strain`), or the STE's from its tensor (lateral strains
        per axial strain along the load axis); ``None`` where the solve measures none (failure runs, bending)."""
        value = self.stats.get("poisson_ratio") if isinstance(self.stats, dict) else None
        return None if value is None else float(value)

    @property
    def ok(self) -> bool:
        """Whether the solve converged (``status == "converged"``)."""
        return Status(self.status).ok

    @property
    def strain(self) -> np.ndarray:
        """``[m]`` the loading curve's strains, displacement / gauge length."""
        return self.displacement / self.gauge_length

    @property
    def stress(self) -> np.ndarray:
        """``[m]`` the loading curve's stresses [Pa], force / area."""
        return self.force / self.area

    def stress_at(self, strains) -> np.ndarray:
        """The stress [Pa] at the given strains, interpolated linearly on the loading curve (a stress-strain vector
        target, e.g. Irazabal et al.'s 17 equispaced strains).

        Args:
          strains: ``[k]`` strains within the loading curve.

        Returns:
          ``[k]`` the stresses [Pa].

        Raises:
          ValueError: a strain beyond the curve.
        """
        strains = np.asarray(strains, np.float64)
        e = self.strain
        if len(e) == 0 or np.any(strains < min(e[0], 0.0) - 1e-12) or np.any(strains > e[-1] * (1 + 1e-9)):
            raise ValueError(f"stress_at: strains must lie within the loading curve [0, {e[-1] if len(e) else 0:.4g}]")
        return np.interp(strains, np.r_[0.0, e] if e[0] > 0 else e, np.r_[self.stress[0], self.stress]
                         if e[0] > 0 else self.stress)

    def plot(self, ax=None, *, label: str | None = None):
        """The loading curve, stress [MPa] against strain (:func:`jaxbpm.plots.stress_strain`): a DEM run's curve
        with the line of its modulus, its peak and its broken bonds; a DSM's or STE's line of slope E. Drawn on one
        ``ax``, results compare: ``ax = dem.plot(); dsm.plot(ax=ax)``.

        Args:
          ax: the Matplotlib ``Axes`` to draw on (``None``: a new figure's).
          label: the name in the legend (default: the method).

        Returns:
          The ``Axes``.
        """
        from jaxbpm.plots import stress_strain

        return stress_strain(self, ax, label=label)

    def plot_cracks(self, sample, ax=None, **section):
        """The bonds this DEM run broke, by mode (tension, shear), in a section through ``sample``
        (:func:`jaxbpm.plots.crack_pattern`).

        Args:
          sample: the sample the run was of.
          ax: the Matplotlib ``Axes`` to draw on (``None``: a new figure's).
          **section: ``positions``, ``normal``, ``origin``, ``thickness`` of :func:`jaxbpm.plots.crack_pattern`.

        Returns:
          The ``Axes``.

        Raises:
          ValueError: a result without break modes (a DSM or STE solve, which breaks no bond).
        """
        from jaxbpm.plots import crack_pattern

        modes = getattr(self.state, "broken", None)
        if modes is None:
            raise ValueError(f"plot_cracks: a {self.method.upper()} result has no broken bonds (only the DEM breaks "
                             "bonds: solve with method='dem' on a scene with breakage)")
        return crack_pattern(sample, np.asarray(modes), ax, **section)

    def summary(self) -> str:
        """The result as lines of text: method, stiffness, modulus, times and the scalar stats."""
        lines = [
            f"method            {self.method}",
            f"stiffness K       {self.stiffness:.6g} N/m",
            f"Young's modulus   {self.youngs_modulus:.6g} Pa  (l = {self.gauge_length:.4g} m, A = {self.area:.4g} m^2)",
            f"wall time         {self.wall_time:.3f} s  (setup {self.setup_time:.3f} s, "
            f"compile {self.compile_time:.3f} s, run {self.run_time:.3f} s)",
        ]
        for k, v in self.stats.items():
            if isinstance(v, (int, float, np.integer, np.floating, str, bool)):
                lines.append(f"{k:<18}{v:.6g}" if isinstance(v, (float, np.floating)) else f"{k:<18}{v}")
        return "\n".join(lines)

    def __repr__(self) -> str:
        status = "" if self.status == "converged" else f", status={self.status!r}"
        return (f"Result(method={self.method!r}, stiffness={self.stiffness:.6g}, "
                f"youngs_modulus={self.youngs_modulus:.6g}, wall_time={self.wall_time:.3g}{status})")


@dataclasses.dataclass(frozen=True)
class Timings:
    """What a solve cost [s]: ``wall_time = setup_time + compile_time + run_time`` (see :class:`Result`).

    Attributes:
      wall_time: the whole call.
      setup_time: the host's work before and around the solver's programs.
      compile_time: tracing and compiling.
      run_time: the solver's programs.
    """

    wall_time: float
    setup_time: float
    compile_time: float
    run_time: float

    @classmethod
    def since(cls, t0: float, compile_time: float, *, setup_time: float | None = None,
              run_time: float | None = None) -> Timings:
        """The timings of a solve that started at ``t0`` (``time.perf_counter()``), made to add up.

        The wall time is ``now - t0``. Give the solver's ``setup_time`` (then ``run_time = wall - setup - compile``)
        or its ``run_time`` (then ``setup_time = max(wall - compile - run, 0)``: all that is neither compiling nor
        running counts as setup), not both.

        Args:
          t0: when the solve started [s, ``time.perf_counter()``].
          compile_time: seconds spent tracing and compiling.
          setup_time: seconds spent on the host before the solve (or ``None``, see above).
          run_time: seconds spent in the solver's programs (or ``None``, see above).

        Returns:
          The :class:`Timings`.

        Raises:
          ValueError: both or neither of ``setup_time`` and ``run_time``.
        """
        if (setup_time is None) == (run_time is None):
            raise ValueError("timed_result: give setup_time or run_time, not both (the other is what is left)")
        wall = time.perf_counter() - t0
        if run_time is None:
            run_time = wall - setup_time - compile_time
        else:
            setup_time = max(wall - compile_time - run_time, 0.0)
        return cls(wall_time=wall, setup_time=setup_time, compile_time=compile_time, run_time=run_time)

    def share(self, n: int) -> Timings:
        """One of ``n`` equal shares (a member of a batch of ``n`` runs that one program ran together).

        Args:
          n: the number of shares.

        Returns:
          Each time divided by ``n``.
        """
        return Timings(wall_time=self.wall_time / n, setup_time=self.setup_time / n,
                       compile_time=self.compile_time / n, run_time=self.run_time / n)


def timed_result(method: str, t0: float | None = None, *, stiffness: float, gauge_length: float, area: float,
                 displacement, force, compile_time: float | None = None, setup_time: float | None = None,
                 run_time: float | None = None, timings: Timings | None = None, youngs_modulus: float | None = None,
                 stats: dict | None = None, state: Any = None, interrupted: bool = False,
                 status: Status | str = Status.CONVERGED) -> Result:
    """A :class:`Result` with its timings: those of a solve that started at ``t0`` (:meth:`Timings.since` with
    ``compile_time`` and ``setup_time`` or ``run_time``), or the given ``timings``.

    Args:
      method: the solver's name (``"dem"``, ``"dsm"``, ``"ste"``).
      t0: when the solve started [s, ``time.perf_counter()``]; ``None`` with ``timings``.
      stiffness: K [N/m].
      gauge_length: l [m].
      area: A [m^2].
      displacement: ``[m]`` the loading curve's displacements [m].
      force: ``[m]`` its forces [N].
      compile_time: seconds spent tracing and compiling (with ``t0``).
      setup_time: seconds spent on the host before the solve (with ``t0``; or ``None``, see :meth:`Timings.since`).
      run_time: seconds spent in the solver's programs (with ``t0``; or ``None``, see :meth:`Timings.since`).
      timings: the :class:`Timings` measured already (in place of ``t0`` and the times).
      youngs_modulus: E [Pa]; default ``K l / A``.
      stats: the solver's details.
      state: the solver's final state.
      interrupted: the run was stopped early.
      status: the :class:`~jaxbpm.status.Status` (``settle`` refines it from ``stats``).

    Returns:
      The :class:`Result`.

    Raises:
      ValueError: both or neither of ``t0`` and ``timings``, times given with ``timings``, or both or neither of
        ``setup_time`` and ``run_time`` with ``t0``.
    """
    if timings is None:
        if t0 is None or compile_time is None:
            raise ValueError("timed_result: give t0 and compile_time, or the timings")
        timings = Timings.since(t0, compile_time, setup_time=setup_time, run_time=run_time)
    elif not (t0 is None and compile_time is None and setup_time is None and run_time is None):
        raise ValueError("timed_result: give t0 and the times, or the timings, not both")
    if youngs_modulus is None:
        youngs_modulus = stiffness * gauge_length / area
    return Result(method=method, stiffness=stiffness, youngs_modulus=youngs_modulus, gauge_length=gauge_length,
                  area=area, displacement=displacement, force=force, wall_time=timings.wall_time,
                  setup_time=timings.setup_time, compile_time=timings.compile_time, run_time=timings.run_time,
                  stats={} if stats is None else stats, state=state, interrupted=interrupted, status=status)


def settle(result: Result, throw: bool) -> Result:
    """Give ``result`` its :class:`~jaxbpm.status.Status` from what the solver reported (an interruption,
    ``stats["converged"]``, a stiffness that is not finite) and, with ``throw``, raise the status's ``error``
    carrying it (an interruption is raised by the DEM itself, as a ``KeyboardInterrupt``).

    Args:
      result: the solver's result.
      throw: raise the :class:`~jaxbpm.errors.SolveError` of a failed status.

    Returns:
      ``result``, its status set.

    Raises:
      SolveError: with ``throw``, the status's ``error`` (``ConvergenceError``, ``InstabilityError``,
        ``NotFiniteError``), carrying ``result``.
    """
    try:
        status = Status(result.status)
    except ValueError:
        raise ValueError(f"unknown status {result.status!r}; one of {STATUSES}") from None
    if status is Status.CONVERGED:
        if result.interrupted:
            status = Status.INTERRUPTED
        elif result.stats.get("converged") is False:
            status = Status.MAX_ITERATIONS
        elif not np.isfinite(result.stiffness):
            status = Status.NOT_FINITE
            result.stats.setdefault("failure", f"the {result.method.upper()} stiffness is {result.stiffness} "
                                               "(check the parameters: bond E > 0, -1 < bond nu < 0.5)")
    result.status = status
    if throw and status.error is not None:
        message = result.stats.get("failure") or f"{result.method.upper()} solve ended with status {status!r}"
        raise status.error(f"{message} (status {status!r}; pass throw=False to get the result with its status)",
                           result=result)
    return result
