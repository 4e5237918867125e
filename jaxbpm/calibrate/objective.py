"""What a calibration aims at and what it changes: targets, the parameter space, the forward, the objective.

* :class:`Target`: one measured quantity of a scene (stiffness, Young's modulus, Poisson ratio, the points of a
  stress-strain curve, or any observable a custom model returns), its weight and how its error is normalised.
* :class:`Parameter` / :class:`ParameterSpace`: the free entries of the parameter pytree
  (``{"bond_E": [n_materials], "bond_nu": [n_materials]}``) with bounds, mapped to an optimisation variable ``z`` in
  log form (``z = log(p / p_ref)``) or target-scaled form (``z = p / scale``, Qu et al. 2020 Eq. 10-11).
* :class:`Forward` (a *forward*: parameters -> observables): any solver of :func:`jaxbpm.solve` (``"ste"``, ``"dsm"``,
  ``"dem"``) on one or several scenes, or a plain function. Where the solver module offers a pure
  ``stiffness_function(sample, scene)`` (``params -> K``), elastic targets use it: batches of parameter sets go
  through ``jax.vmap`` and gradients through ``jax.grad``.
* :class:`Problem`: targets + parameters + a forward. Weights are normalised to sum 1 and the objective is
  ``L = sum_k w_k mean((y_k - t_k)^2 / s_k^2)`` (Qu et al. 2020, Eq. 3), ``s_k`` the target's scale (``|t|`` for a
  scalar,
  ``max |t|`` for a vector unless given). It counts every solve (one parameter set on one scene).
"""

from __future__ import annotations

import dataclasses
import importlib
import time
from typing import Any, Callable, Mapping

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm.calibrate.space import (as_targets, CalibrationError, DEFAULT_SCENE, ELASTIC_OBSERVABLES, Parameter,
                                    ParameterSpace, Target)

__all__ = ["CalibrationError", "Target", "Parameter", "ParameterSpace", "Forward", "forward_model", "Problem",
           "ELASTIC_OBSERVABLES", "STRENGTH_OBSERVABLES", "as_targets", "base_params"]

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
    if result.status == "converged":
        return result
    shown = {k: np.asarray(v).tolist() for k, v in params.items()}
    raise CalibrationError(f"the {result.method.upper()} solve of scene {key!r} at {shown} ended with status "
                           f"{result.status!r}: {result.stats.get('failure', 'no answer')}")


def _observations(result) -> dict:
    obs = {"stiffness": float(result.stiffness), "youngs_modulus": float(result.youngs_modulus),
           "strain": np.asarray(result.strain), "stress": np.asarray(result.stress)}
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


def base_params(sample, keys=(), scene=None) -> dict:
    """The parameter pytree of ``sample`` (``bond_E``, ``bond_nu``) plus the entries ``keys`` asks for.

    Args:
      sample: a :class:`~jaxbpm.Sample`.
      keys: extra entries: ``"bond_tensile_strength"``, ``"bond_shear_strength"`` (from the sample's bond material
        table); ``"contact_E"``, ``"contact_nu"``, ``"friction"``, ``"restitution"`` (from its particle material,
        scalars); ``"cohesion_initial"``, ``"cohesion_from_stress"``, ``"cohesion_max"`` (from the cohesive law of
        ``scene``).
      scene: a scene, or a mapping of scenes (the first with ``contact_law="cohesive"`` gives the cohesive entries).

    Returns:
      ``{entry: jax array}``.

    Raises:
      CalibrationError: an unknown entry, a strength the material table lacks, or a cohesive entry without a cohesive
        scene.
    """
    from jaxbpm.physics.model import default_params

    out = dict(default_params(sample))
    table = {"bond_tensile_strength": "tensile_strength", "bond_shear_strength": "shear_strength"}
    particle = {"contact_E": "E", "contact_nu": "nu", "friction": "friction", "restitution": "restitution"}
    cohesive = {"cohesion_initial": "c0", "cohesion_from_stress": "kc", "cohesion_max": "c_max"}
    known = sorted(out) + sorted(table) + sorted(particle) + sorted(cohesive)
    for key in keys:
        if key in out:
            continue
        if key in table:
            value = getattr(sample.materials, table[key], None)
            if value is None:
                raise CalibrationError(f"the sample's material table has no {table[key]!r} for {key!r}")
            out[key] = jnp.asarray(np.asarray(value, dtype=np.float64).reshape(-1))
        elif key in particle:
            out[key] = jnp.asarray(np.float64(getattr(sample.particle_material, particle[key])))
        elif key in cohesive:
            scenes = list(scene.values()) if isinstance(scene, Mapping) else [scene]
            laws = [sc.cohesive_law for sc in scenes if getattr(sc, "cohesive_law", None) is not None]
            if not laws:
                raise CalibrationError(f"{key!r} is a parameter of the cohesive contact law, but no scene has "
                                       "contact_law='cohesive'")
            out[key] = jnp.asarray(np.float64(getattr(laws[0], cohesive[key])))
        else:
            raise CalibrationError(f"no parameter entry {key!r} (entries: {known})")
    return out


def _linear_scene(scene) -> bool:
    return not (getattr(scene, "contacts", False) or getattr(scene, "uses_walls", False))


_FORWARDS: dict = {}  # recent forwards: repeated calibrations of one sample share their compiled functions
_FORWARDS_MAX = 8


def forward_model(sample, scenes, solver: str = "dsm", *, model: str | None = None, **solve_options) -> Forward:
    """The :class:`Forward` of ``jaxbpm.solve(sample, scene, method=solver, params=..., **solve_options)``.

    sample: a :class:`~jaxbpm.Sample`, or ``{key: sample}`` with one sample per scene key (e.g. a cylinder for
    ``"ucs"`` and a beam for ``"tpb"``). scenes: a scene or a mapping ``{key: scene}``. Each solve gets the sample's
    own parameters (``bond_E``, ``bond_nu``) overridden by the entries of the parameter pytree it is given. When
    ``jaxbpm.<solver>`` has a ``stiffness_function`` and every scene is linear (bonds only, clamped layers), elastic
    targets use that pure function (batched and differentiable). ``solve_options`` go to ``jaxbpm.solve`` only.
    Forwards are cached: the same samples, scenes, solver and options give the same object (and its compiled
    functions).

    Args:
      sample: a :class:`~jaxbpm.Sample`, or ``{key: sample}`` with one sample per scene key.
      scenes: a scene or ``{key: scene}``.
      solver: the solver, one of ``jaxbpm.solving.METHODS`` (``"dsm"``, ``"ste"``, ``"dem"``).
      model: deprecated name of ``solver`` (a :class:`DeprecationWarning`); removed in the next release.
      **solve_options: options of ``jaxbpm.solve``.

    Returns:
      A :class:`Forward` named after the solver.

    Raises:
      CalibrationError: an unknown solver, no scene, an object that is not a scene or a sample, or samples that do
        not match the scene keys.
    """
    from jaxbpm import solving as solve_mod
    from jaxbpm.calibrate._common import renamed_keyword
    from jaxbpm.sample import Sample

    solver = renamed_keyword(solver, model, new="solver", old="model")
    if not isinstance(solver, str) or solver not in solve_mod.METHODS:
        raise CalibrationError(f"unknown solver {solver!r}; choose one of {solve_mod.METHODS}")
    scene_map = dict(scenes) if isinstance(scenes, Mapping) else {DEFAULT_SCENE: scenes}
    if not scene_map:
        raise CalibrationError("no scene given")
    for key, sc in scene_map.items():
        if not hasattr(sc, "geometry") or not hasattr(sc, "model"):
            raise CalibrationError(f"scene {key!r} is not a jaxbpm scene (got {type(sc).__name__})")
    if isinstance(sample, Mapping):
        if set(sample) != set(scene_map):
            raise CalibrationError(f"one sample per scene: samples for {sorted(sample)}, scenes {sorted(scene_map)}")
        sample_map = {k: sample[k] for k in scene_map}
    else:
        sample_map = {k: sample for k in scene_map}
    for key, s in sample_map.items():
        if not isinstance(s, Sample):
            raise CalibrationError(f"sample{'' if len(sample_map) == 1 else f' {key!r}'} must be a jaxbpm.Sample, "
                                   f"got {type(s).__name__}")
    try:
        cache_key = (tuple((k, id(s)) for k, s in sample_map.items()), solver,
                     tuple((k, repr(sc)) for k, sc in scene_map.items()), repr(sorted(solve_options.items())))
    except TypeError:
        cache_key = None
    hit = _FORWARDS.get(cache_key)
    if hit is not None and all(ref() is sample_map[k] for k, ref in hit[0].items()):
        return hit[1]
    fwd = _forward_model(sample_map, scene_map, solver, solve_options)
    if cache_key is not None:
        import weakref

        while len(_FORWARDS) >= _FORWARDS_MAX:
            _FORWARDS.pop(next(iter(_FORWARDS)))
        try:
            _FORWARDS[cache_key] = ({k: weakref.ref(s) for k, s in sample_map.items()}, fwd)
        except TypeError:
            pass
    return fwd


def _forward_model(sample_map, scene_map, solver, solve_options) -> Forward:
    from jaxbpm.physics.model import default_params

    own = {k: default_params(s) for k, s in sample_map.items()}

    options = {"throw": False, **solve_options}  # the calibrator reads the status itself

    def evaluate(params):
        return {key: _solve_one(sample_map[key], sc, solver, {**own[key], **params}, options, key, params)
                for key, sc in scene_map.items()}

    linear = all(_linear_scene(sc) for sc in scene_map.values())
    factory = None
    if linear and solver != "dem":
        try:
            factory = getattr(importlib.import_module(f"jaxbpm.{solver}"), "stiffness_function", None)
        except ImportError:
            factory = None
    fns = {}
    if factory is not None:
        for key, sc in scene_map.items():
            length, area = sc.geometry(sample_map[key])
            fns[key] = (factory(sample_map[key], sc), length / area)

    def pure(params):
        out = {}
        for key, (f, l_over_a) in fns.items():
            k = f({**own[key], **params})
            out[key] = {"stiffness": k, "youngs_modulus": k * l_over_a}
        return out

    return Forward(name=solver, evaluate=evaluate, pure=pure if fns else None, scenes=tuple(scene_map),
                   pure_observables=ELASTIC_OBSERVABLES if fns else None,
                   homogeneous=linear and all(s.n_bonds > 0 for s in sample_map.values()),
                   recipe=("solve", sample_map, scene_map, solver, options))


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


# ---------------------------------------------------------------------------------------------------- problem
class Problem:
    """Targets, parameters and a model: evaluates the relative errors and the weighted objective (Qu et al. 2020, Eq. 3)
    and counts the solves (``evaluations``: one parameter set on one scene).

    executor: a :class:`concurrent.futures.Executor` (e.g. Dask's ``Client(...).get_executor()``) on which the runs of
    a model that is not batched (DEM, a plain function with ``pure=False``) are spread: a run set, the perturbed
    runs of a finite-difference gradient (:mod:`jaxbpm.parallel`). retries: how often a run whose worker died is
    submitted again.
    """

    def __init__(self, forward: Forward, targets, space: ParameterSpace, *, executor=None, retries: int = 2):
        from jaxbpm.parallel import check_executor, check_retries

        self.executor, self.retries = check_executor(executor), check_retries(retries)
        if not isinstance(forward, Forward):
            raise CalibrationError(f"forward must be a Forward, got {type(forward).__name__}")
        if not isinstance(space, ParameterSpace):
            raise CalibrationError(f"space must be a ParameterSpace, got {type(space).__name__}")
        self.forward, self.targets, self.space = forward, as_targets(targets), space
        names = [t.name for t in self.targets]
        if len(set(names)) != len(names):
            raise CalibrationError(f"target names must be unique, got {names}")
        for t in self.targets:
            if t.scene not in forward.scenes:
                raise CalibrationError(f"target {t.name!r}: the model has no scene {t.scene!r} "
                                       f"(scenes: {list(forward.scenes)})")
        w = np.asarray([t.weight for t in self.targets], dtype=np.float64)
        self.weights = w / w.sum()
        sizes = [t.size for t in self.targets]
        self.slices = [slice(a, a + s) for a, s in zip(np.cumsum([0] + sizes[:-1]), sizes)]
        self.use_pure = forward.pure is not None and (
            forward.pure_observables is None or all(t.observable in forward.pure_observables
                                                    for t in self.targets))
        self.evaluations = 0
        self.solve_time = 0.0
        self._last = None  # (values, outputs) of the last single point: a repeated point costs no new solve
        self._sweep_fn = None  # the one-set model function that sharded batches run (see outputs)

    # -------------------------------------------------------------- pieces
    @property
    def n_scenes(self) -> int:
        return len({t.scene for t in self.targets}) if self.use_pure else len(self.forward.scenes)

    @property
    def target_names(self) -> list[str]:
        return [t.name for t in self.targets]

    @property
    def differentiable(self) -> bool:
        return self.use_pure

    def closed_form_applies(self) -> tuple[bool, str]:
        """Whether the closed form applies (bonds-only elasticity, K homogeneous in the bond moduli).

        Returns:
          ``(applies, why)``: why it applies, or why not.
        """
        if not self.forward.homogeneous:
            return False, f"the {self.forward.name} model is not linear in the bond moduli (contacts or walls)"
        if not all(t.elastic for t in self.targets):
            return False, "a target is not an elastic stiffness or Young's modulus"
        if not all(p.key == "bond_E" for p in self.space.parameters):
            return False, "a free parameter is not a bond Young's modulus"
        covered = sum(int(np.size(self.space.base["bond_E"])) if p.index is None else 1
                      for p in self.space.parameters)
        if covered != int(np.size(self.space.base["bond_E"])):
            return False, "some bond moduli are held fixed (K is then not proportional to the free ones)"
        return True, "stiffness is linear in a common factor on the bond moduli (bonds-only elasticity)"

    def _vector(self):
        """The model's target elements ``(values, base) -> [m]`` as a plain function. Called with concrete values (one
        parameter set), the solvers' stiffness functions run the programs ``solve`` compiles, so a calibration after
        a solve of the same sample compiles no solver again."""
        targets, space, pure = self.targets, self.space, self.forward.pure

        def vector(values, base):
            obs = pure(space.to_params(values, base))
            return jnp.concatenate([jnp.reshape(t.extract(obs), (-1,)) for t in targets])

        return vector

    def _compiled(self, what):
        """Jitted pure functions, cached on the model per parameter and target structure: problems that differ only
        in values (targets, initial values, bases) share one compilation."""
        targets, space = self.targets, self.space
        key = (what, space.structure, tuple((t.observable, t.scene, t.at, t.size) for t in targets))
        cache = self.forward._compiled
        if key not in cache:
            vector = self._vector()

            if what == "vector":
                fn = vector
            elif what == "batch":
                fn = jax.vmap(vector, in_axes=(0, None))
            elif what == "jacobian":
                def fn(values, base):
                    return vector(values, base), jax.jacfwd(vector)(values, base)
            else:  # value_and_grad of the loss in z
                def loss_z(z, base, initial, scales, tvals, tscale, wel):
                    y = vector(space.from_z(z, initial, scales), base)
                    return jnp.sum(wel * jnp.square((y - tvals) / tscale)), y

                fn = jax.value_and_grad(loss_z, has_aux=True)
            cache[key] = jax.jit(fn)
        return cache[key]

    def _element_arrays(self):
        tvals = np.concatenate([np.reshape(t.value, -1) for t in self.targets])
        tscale = np.concatenate([np.full(t.size, t.scale) for t in self.targets])
        wel = np.concatenate([np.full(t.size, w / t.size) for t, w in zip(self.targets, self.weights)])
        return tvals, tscale, wel

    # -------------------------------------------------------------- evaluation
    def outputs(self, values_batch, *, chunk: int | None = None, progress: bool = False,
                on_row: Callable[[int, np.ndarray], None] | None = None) -> np.ndarray:
        """The forward's values of all target elements for a batch of parameter sets (``vmap`` when pure).

        A forward that is not batched (DEM, a plain function with ``pure=False``) solves the sets one after another, or,
        with an ``executor`` (:class:`Problem`), as separate tasks, one per set and scene (see :mod:`jaxbpm.parallel`).

        Args:
          values_batch: parameter values ``[B, n]``.
          chunk: for a pure forward, solve at most this many sets in one ``vmap`` (bounds the memory of large batches:
            each vmapped solve holds its own operator and workspace); the last chunk is padded so that every chunk
            shares one compilation. ``None``: all at once.
          progress: a bar of the sets solved (:mod:`jaxbpm.progress`) where they are solved in parts (chunks, or one at
            a time).
          on_row: called ``(index, row)`` as each set of a forward that is not batched finishes (in completion order),
            e.g. to store it.

        Returns:
          ``[B, m]``.

        Raises:
          CalibrationError: a bad ``chunk``, a target the forward does not report, a solve that did not converge.
        """
        vb = np.atleast_2d(np.asarray(values_batch, dtype=np.float64))
        if chunk is not None and (isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)) or chunk < 1):
            raise CalibrationError(f"chunk must be a whole number >= 1, got {chunk!r}")
        if len(vb) == 1 and self._last is not None and np.array_equal(self._last[0], vb[0]):
            return self._last[1][None].copy()
        t0 = time.perf_counter()
        if self.use_pure:
            base = self.space.base
            if len(vb) > 1 and jax.device_count() > 1:
                # several devices (GPUs, or host devices): the batch is sharded over all of them
                from jaxbpm.sweep import sweep

                if self._sweep_fn is None:
                    vector, space_base = self._compiled("vector"), base
                    self._sweep_fn = lambda v: vector(v, space_base)  # one function: sweep compiles it once
                y = np.asarray(sweep(self._sweep_fn, jnp.asarray(vb), chunk=chunk))
            elif chunk is not None and len(vb) > chunk > 1:
                fn, parts, shown = self._compiled("batch"), [], _bar(progress, len(vb))
                for a in range(0, len(vb), chunk):
                    part = vb[a:a + chunk]
                    pad = np.concatenate([part, np.repeat(part[-1:], chunk - len(part), axis=0)])
                    parts.append(np.asarray(fn(jnp.asarray(pad), base))[:len(part)])
                    shown.update(len(part))
                shown.close()
                y = np.concatenate(parts)
            elif chunk == 1 and len(vb) > 1:
                fn, shown, rows = self._compiled("vector"), _bar(progress, len(vb)), []
                for v in vb:
                    rows.append(np.asarray(fn(jnp.asarray(v), base)))
                    shown.update(1)
                shown.close()
                y = np.stack(rows)
            elif len(vb) > 1:
                # small batches are padded to a power of two (repeating the last set): the batch sizes of n-point
                # finite differences (n + 1, 2n) then share compilations
                size = 1 << (len(vb) - 1).bit_length() if len(vb) <= 8 else len(vb)
                pad = np.concatenate([vb, np.repeat(vb[-1:], size - len(vb), axis=0)])
                y = np.asarray(self._compiled("batch")(jnp.asarray(pad), base))[:len(vb)]
            else:  # one set: not jitted here (the solvers run their own compiled programs)
                y = np.asarray(self._vector()(jnp.asarray(vb[0]), base))[None]
        else:
            shown = _bar(progress and len(vb) > 1, len(vb))
            if self.executor is not None:
                y = self._spread(vb, shown, on_row)
            else:
                rows = []
                for i, v in enumerate(vb):
                    rows.append(self._row(self.forward.evaluate(self.space.to_params(jnp.asarray(v)))))
                    if on_row is not None:
                        on_row(i, rows[-1])
                    shown.update(1)
                y = np.stack(rows)
            shown.close()
        self.evaluations += len(vb) * self.n_scenes
        self.solve_time += time.perf_counter() - t0
        if len(vb) == 1:
            self._last = (vb[0].copy(), y[0].copy())
        return y

    def _row(self, obs) -> np.ndarray:
        return np.concatenate([np.reshape(np.asarray(t.extract(obs)), (-1,)) for t in self.targets])

    def _spread(self, vb, shown, on_row) -> np.ndarray:
        """The runs of ``vb`` as tasks on ``self.executor`` (one per parameter set and scene), rows in order."""
        from jaxbpm.parallel import run_tasks

        owner, tasks, scenes = [], [], []
        for i, v in enumerate(vb):
            made = self.forward.tasks(self.space.to_params(jnp.asarray(v)))
            if not made:
                raise CalibrationError(f"the {self.forward.name} model cannot be sent to other processes (it is not "
                                       "a solver model nor a plain function): run it without an executor")
            for key, task in made:
                owner.append(i), tasks.append(task), scenes.append(key)
        parts: dict = {}
        rows: list = [None] * len(vb)

        def arrived(k, value):
            i = owner[k]
            got = parts.setdefault(i, {})
            got[scenes[k]] = value
            if len(got) == owner.count(i):
                rows[i] = self._row(got)
                if on_row is not None:
                    on_row(i, rows[i])
                shown.update(1)

        run_tasks(self.executor, tasks, on_result=arrived, retries=self.retries)
        return np.stack(rows)

    def jacobian(self, values) -> tuple[np.ndarray, np.ndarray]:
        """Outputs and their Jacobian by forward-mode autodiff (pure forwards only).

        Args:
          values: parameter values ``[n]``.

        Returns:
          ``(outputs [m], jacobian [m, n])``.
        """
        t0 = time.perf_counter()
        y, j = self._compiled("jacobian")(jnp.asarray(values, dtype=jnp.float64), self.space.base)
        self.evaluations += self.n_scenes
        self.solve_time += time.perf_counter() - t0
        return np.asarray(y), np.asarray(j)

    def value_and_grad(self, z) -> tuple[float, np.ndarray, np.ndarray]:
        """Loss, its gradient with respect to ``z`` (reverse-mode autodiff) and the outputs (pure forwards only).

        Args:
          z: the point ``[n]`` in the optimisation variable.

        Returns:
          ``(loss, gradient [n], outputs [m])``.

        Raises:
          CalibrationError: the forward has no pure function for these targets.
        """
        if not self.use_pure:
            raise CalibrationError(f"autodiff gradients need a pure model; the {self.forward.name} model with "
                                   f"targets {self.target_names} has none (use gradient='fd-forward')")
        t0 = time.perf_counter()
        sp = self.space
        (loss, y), g = self._compiled("value_and_grad")(jnp.asarray(z, dtype=jnp.float64), sp.base,
                                                        jnp.asarray(sp.initial), jnp.asarray(sp.scales),
                                                        *map(jnp.asarray, self._element_arrays()))
        self.evaluations += self.n_scenes
        self.solve_time += time.perf_counter() - t0
        return float(loss), np.asarray(g), np.asarray(y)

    # -------------------------------------------------------------- objective
    def errors_of(self, y):
        """Relative errors of all target elements.

        Args:
          y: outputs ``[m]`` (NumPy or JAX).

        Returns:
          ``[m]``: ``(y - t) / s`` per element.
        """
        xp = jnp if isinstance(y, jax.Array) else np
        return xp.concatenate([t.relative_error(y[s]) for t, s in zip(self.targets, self.slices)])

    def target_losses(self, e):
        """Each target's weighted term of the objective.

        Args:
          e: relative errors ``[m]``.

        Returns:
          ``[k]``: ``w_k mean(e_k^2)`` per target.
        """
        xp = jnp if isinstance(e, jax.Array) else np
        return xp.stack([w * xp.mean(xp.square(e[s])) for w, s in zip(self.weights, self.slices)])

    def loss_of(self, e):
        """The objective (Qu et al. 2020, Eq. 3).

        Args:
          e: relative errors ``[m]``.

        Returns:
          ``L = sum_k w_k mean(e_k^2)``.
        """
        xp = jnp if isinstance(e, jax.Array) else np
        return xp.sum(self.target_losses(e))

    def max_errors(self, e) -> np.ndarray:
        """Each target's largest relative error magnitude.

        Args:
          e: relative errors ``[m]``.

        Returns:
          ``[k]``.
        """
        e = np.asarray(e)
        return np.array([np.max(np.abs(e[s])) for s in self.slices])

    def signed_errors(self, e) -> dict[str, Any]:
        """The errors by target name.

        Args:
          e: relative errors ``[m]``.

        Returns:
          ``{target name: error}``: a float for a scalar target, an array for a vector target.
        """
        e = np.asarray(e)
        return {t.name: (float(e[s][0]) if t.size == 1 else e[s].copy()) for t, s in zip(self.targets, self.slices)}

    def per_target(self, e) -> np.ndarray:
        """One error per target: signed for a scalar target, the largest magnitude for a vector target.

        Args:
          e: relative errors ``[m]``.

        Returns:
          ``[k]``.
        """
        e = np.asarray(e)
        return np.array([float(e[s][0]) if t.size == 1 else float(np.max(np.abs(e[s])))
                         for t, s in zip(self.targets, self.slices)])



def _bar(progress, total):
    """A bar of parameter sets solved (:mod:`jaxbpm.progress`), showing nothing unless ``progress``."""
    from jaxbpm.progress import bar

    return bar("run set", total=total, unit="run", disable=not progress)
