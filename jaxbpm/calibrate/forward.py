"""Forwards: the map from a parameter pytree to the observables of one or several scenes, which the calibrators run.

:class:`Forward` holds the map (``evaluate``, and a pure JAX ``pure`` where the solver offers one) and the recipe of
its runs as independent tasks for other processes (:mod:`jaxbpm.parallel`);
:func:`~jaxbpm.calibrate.objective.forward_model` builds one from a solver. A solve's result is read here (its status
checked, its observations taken).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Mapping

import jax
import numpy as np

from jaxbpm.calibrate.space import DEFAULT_SCENE, CalibrationError
from jaxbpm.status import Status

__all__ = ["Forward", "STRENGTH_OBSERVABLES"]


@dataclasses.dataclass
class Forward:
    """A forward: the map from a parameter pytree to the observables of its scenes, which the calibrators run.

    evaluate: one parameter pytree -> ``{scene: {observable: value}}`` (any solver; NumPy values).
    pure: optional JAX function with the same signature, traceable (``jit``/``grad``/``vmap``); it may report fewer
      observables (``pure_observables``; ``None`` = the same as ``evaluate``).
    scenes: the scene keys. homogeneous: its elastic observables are homogeneous of degree one in ``bond_E``
      (a bonds-only scene on a linear model: scaling every bond modulus scales K), so the closed form applies.
    """

    name: str
    evaluate: Callable[[dict], dict]
    pure: Callable[[dict], dict] | None = None
    scenes: tuple[str, ...] = (DEFAULT_SCENE,)
    pure_observables: tuple[str, ...] | None = None
    homogeneous: bool = False
    recipe: tuple | None = dataclasses.field(default=None, repr=False, compare=False)
    _compiled: dict = dataclasses.field(default_factory=dict, repr=False, compare=False)

    def tasks(self, params) -> list[tuple[str, Any]]:
        """The runs of one parameter set as independent :class:`jaxbpm.parallel.Task` s, one per scene.

        Args:
          params: the parameter pytree (its free entries; the sample's own complete it in the worker).

        Returns:
          ``[(scene key, Task)]``; empty when this forward cannot be sent to another process (built by hand from
          closures).
        """
        from jaxbpm.parallel import Task, worker_settings

        if self.recipe is None:
            return []
        values = {k: np.asarray(v) for k, v in params.items()}
        settings = worker_settings()
        if self.recipe[0] == "function":
            return [(DEFAULT_SCENE, Task(_function_task, (self.recipe[1], values), settings))]
        _, samples, scenes, solver, options = self.recipe
        return [(key, Task(_solve_task, (samples[key], sc, solver, values, options, key), settings))
                for key, sc in scenes.items()]

    @classmethod
    def from_function(cls, fn: Callable[[dict], Mapping[str, Any]], *, name: str = "function", pure: bool = True,
                      homogeneous: bool = False) -> "Forward":
        """Wrap a function of the parameters as a forward of one scene.

        Args:
          fn: ``fn(params) -> {observable: value}``.
          name: the forward's name (in results and histories).
          pure: ``fn`` is a JAX function (traced, ``vmap``-ped and differentiated); else it is called with NumPy values,
            one parameter set at a time.
          homogeneous: its elastic observables are homogeneous of degree one in ``bond_E`` (the closed form applies).

        Returns:
          A :class:`Forward`.

        Raises:
          CalibrationError: ``fn`` is not callable.
        """
        if not callable(fn):
            raise CalibrationError(f"a model function must be callable, got {fn!r}")

        def evaluate(params):
            out = fn(params)
            return {DEFAULT_SCENE: {k: np.asarray(v) for k, v in out.items()}}

        jitted = jax.jit(fn) if pure else None

        def pure_fn(params):
            return {DEFAULT_SCENE: dict(jitted(params))}

        return cls(name=name, evaluate=evaluate, pure=pure_fn if pure else None, homogeneous=homogeneous,
                   recipe=None if pure else ("function", fn))


STRENGTH_OBSERVABLES = ("strength", "peak_force", "broken_tensile", "broken_shear")
"""Scalars a failure run (DEM with bond breakage) reports in ``Result.stats``: the strength (UCS or flexural strength
[Pa]), the peak force [N] and the broken bond counts."""


def _checked(result, key, params):
    """``result`` if its solve converged; else a :class:`CalibrationError` naming the scene, the parameters and the
    status (a calibrator never fits to an answer its solver does not vouch for)."""
    if result.status == Status.CONVERGED:
        return result
    shown = {k: np.asarray(v).tolist() for k, v in params.items()}
    raise CalibrationError(f"the {result.method.upper()} solve of scene {key!r} at {shown} ended with status "
                           f"{result.status!r}: {result.stats.get('failure', 'no answer')}")


def _observations(result) -> dict:
    obs = {"stiffness": float(result.stiffness), "youngs_modulus": float(result.youngs_modulus),
           "strain": np.asarray(result.strain), "stress": np.asarray(result.stress),
           "force": np.asarray(result.force)}
    stats = result.stats if isinstance(result.stats, dict) else {}
    nu = getattr(result, "poisson_ratio", None)
    if nu is None:
        nu = stats.get("poisson_ratio", stats.get("nu_iso"))
    if nu is not None:
        obs["poisson_ratio"] = float(nu)
    for key in STRENGTH_OBSERVABLES:
        if stats.get(key) is not None and np.size(stats[key]) == 1:
            obs[key] = float(np.asarray(stats[key]).reshape(()))
    return obs


def _solve_one(sample, scene, solver, params, options, key, shown):
    """The observations of one solve (a module-level function: a worker process runs it as a task)."""
    from jaxbpm.solving import solve

    return _observations(_checked(solve(sample, scene, method=solver, params=params, **options), key, shown))


def _solve_task(sample, scene, solver, params, options, key):
    """:func:`_solve_one` for a task: the parameter set arrives as NumPy arrays and is completed with the sample's
    own entries."""
    from jaxbpm.physics.model import default_params

    return _solve_one(sample, scene, solver, {**default_params(sample), **params}, options, key, params)


def _function_task(fn, params):
    return {k: np.asarray(v) for k, v in fn(params).items()}
