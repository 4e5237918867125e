"""What a solve returns: the observables of a scene, what they cost, and how the solver got there."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

__all__ = ["Result"]


@dataclasses.dataclass
class Result:
    """Outcome of :func:`jaxbpm.solve` on a scene.

    stiffness: K = dF/d(displacement) over the linear range [N/m]. youngs_modulus: E = K l / A [Pa].
    displacement, force: the loading curve [m], [N] (compression positive); strain, stress: the same over l and A.
    gauge_length l [m], area A [m^2]. wall_time [s]: what the call took, ``setup_time + compile_time + run_time``:
    setup_time (building the model, estimator, geometry, preconditioner or neighbour list, on the host), compile_time
    (tracing and compiling the solver's programs; 0 when this process, or the persistent compilation cache, had them)
    and run_time (the solver's kernel, run once). stats: solver details (steps, time step, critical time step,
    iterations, ...). state: the solver's final state (for restarts and inspection).
    interrupted: the run was stopped early (see :class:`~jaxbpm.errors.SimulationInterrupted`); the curve and
    stats cover the part that was run (stiffness NaN when the fit range was not reached).
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

    @property
    def strain(self) -> np.ndarray:
        return self.displacement / self.gauge_length

    @property
    def stress(self) -> np.ndarray:
        return self.force / self.area

    def stress_at(self, strains) -> np.ndarray:
        """The stress [Pa] at the given strains, interpolated linearly on the loading curve (a stress-strain vector
        target, e.g. Irazabal et al.'s 17 equispaced strains). Strains beyond the curve are an error."""
        strains = np.asarray(strains, np.float64)
        e = self.strain
        if len(e) == 0 or np.any(strains < min(e[0], 0.0) - 1e-12) or np.any(strains > e[-1] * (1 + 1e-9)):
            raise ValueError(f"stress_at: strains must lie within the loading curve [0, {e[-1] if len(e) else 0:.4g}]")
        return np.interp(strains, np.r_[0.0, e] if e[0] > 0 else e, np.r_[self.stress[0], self.stress]
                         if e[0] > 0 else self.stress)

    def summary(self) -> str:
        lines = [
            f"method            {self.method}",
            f"stiffness K       {self.stiffness:.6g} N/m",
            f"Young's modulus   {self.youngs_modulus:.6g} Pa  (l = {self.gauge_length:.4g} m, A = {self.area:.4g} m^2)",
            f"wall time         {self.wall_time:.3f} s  (setup {self.setup_time:.3f} s, compile {self.compile_time:.3f} s, "
            f"run {self.run_time:.3f} s)",
        ]
        for k, v in self.stats.items():
            if isinstance(v, (int, float, np.integer, np.floating, str, bool)):
                lines.append(f"{k:<18}{v:.6g}" if isinstance(v, (float, np.floating)) else f"{k:<18}{v}")
        return "\n".join(lines)

    def __repr__(self) -> str:
        return (f"Result(method={self.method!r}, stiffness={self.stiffness:.6g}, "
                f"youngs_modulus={self.youngs_modulus:.6g}, wall_time={self.wall_time:.3g})")
