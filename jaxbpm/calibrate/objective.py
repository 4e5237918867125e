"""What a calibration aims at and what it changes: targets, the parameter space, the forward, the objective.

* :class:`Target`: one measured quantity of a scene (stiffness, Young's modulus, Poisson ratio, the points of a
  stress-strain curve, or any observable a forward returns), its weight and how its error is normalised.
* :class:`Parameter` / :class:`ParameterSpace`: the free entries of the parameter pytree
  (``{"bond_E": [n_materials], "bond_nu": [n_materials]}``) with bounds, mapped to an optimisation variable ``z`` in
  log form (``z = log(p / p_ref)``) or target-scaled form (``z = p / scale``, Qu et al. 2020 Eq. 10-11;
  :mod:`~jaxbpm.calibrate.space`). :func:`base_params` gives the pytree of a sample.
* :class:`Forward` (a *forward*: parameters -> observables, :mod:`~jaxbpm.calibrate.forward`): :func:`forward_model`
  builds one from any solver of :func:`jaxbpm.solve` (``"ste"``, ``"dsm"``, ``"dem"``) on one or several scenes;
  :meth:`Forward.from_function` from a plain function. Where the solver module offers a pure
  ``stiffness_function(sample, scene)`` (``params -> K``), elastic targets use it: batches of parameter sets go
  through ``jax.vmap`` and gradients through ``jax.grad``.
* :class:`Problem`: targets + parameters + a forward, with the objective (Qu et al. 2020, Eq. 3;
  :mod:`~jaxbpm.calibrate.problem`).

This module builds forwards from solvers and re-exports the other pieces, so that one import gives them all.
"""

from __future__ import annotations

import importlib
from typing import Mapping

import jax.numpy as jnp
import numpy as np

from jaxbpm._options import options_class
from jaxbpm.calibrate.forward import STRENGTH_OBSERVABLES, Forward, _solve_one
from jaxbpm.calibrate.problem import Problem
from jaxbpm.calibrate.space import (as_targets, CalibrationError, DEFAULT_SCENE, ELASTIC_OBSERVABLES, Parameter,
                                    ParameterSpace, Target)
from jaxbpm.scenes import Scene

__all__ = ["CalibrationError", "Target", "Parameter", "ParameterSpace", "Forward", "forward_model", "Problem",
           "ELASTIC_OBSERVABLES", "STRENGTH_OBSERVABLES", "as_targets", "base_params"]


def base_params(sample, keys=(), scene=None) -> dict:
    """The parameter pytree of ``sample`` (``bond_E``, ``bond_nu``) plus the entries ``keys`` asks for.

    Args:
      sample: a :class:`~jaxbpm.Sample`.
      keys: extra entries: ``"bond_tensile_strength"``, ``"bond_shear_strength"`` (from the sample's bond material
        table); ``"contact_E"``, ``"contact_nu"``, ``"friction"``, ``"restitution"`` (from its particle material,
        scalars); ``"contact_emod"``, ``"contact_kratio"`` (from the linear contact law of ``scene``, or its defaults
        for the particle material); ``"cohesion_initial"``, ``"cohesion_from_stress"``, ``"cohesion_max"`` (from the
        cohesive law of ``scene``).
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
    linear = {"contact_emod": "emod", "contact_kratio": "kratio"}
    known = sorted(out) + sorted(table) + sorted(particle) + sorted(linear) + sorted(cohesive)
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
        elif key in linear:
            out[key] = _linear_entry(sample, scene, linear[key])
        elif key in cohesive:
            scenes = list(scene.values()) if isinstance(scene, Mapping) else [scene]
            laws = [sc.cohesive_law for sc in scenes if sc.cohesive_law is not None]
            if not laws:
                raise CalibrationError(f"{key!r} is a parameter of the cohesive contact law, but no scene has "
                                       "contact_law='cohesive'")
            out[key] = jnp.asarray(np.float64(getattr(laws[0], cohesive[key])))
        else:
            raise CalibrationError(f"no parameter entry {key!r} (entries: {known})")
    return out


def _linear_entry(sample, scene, field: str):
    """A scalar of the linear contact law of the first scene that has one (or of its defaults)."""
    from jaxbpm.physics.linear import LinearLaw

    scenes = list(scene.values()) if isinstance(scene, Mapping) else [scene]
    laws = [law for law in (getattr(sc, "linear_law", None) for sc in scenes) if law is not None]
    p = (laws[0] if laws else LinearLaw()).params(sample.particle_material)
    return jnp.asarray(np.float64(getattr(p, field)))


def _linear_scene(scene) -> bool:
    return not (scene.contacts or scene.uses_walls)


_FORWARDS: dict = {}  # recent forwards: repeated calibrations of one sample share their compiled functions
_FORWARDS_MAX = 8


def forward_model(sample, scenes, solver: str = "dsm", *, model: str | None = None, **solve_options) -> Forward:
    """The :class:`Forward` of ``jaxbpm.solve(sample, scene, method=solver, params=..., **solve_options)``.

    sample: a :class:`~jaxbpm.Sample`, or ``{key: sample}`` with one sample per scene key (e.g. a cylinder for
    ``"ucs"`` and a beam for ``"tpb"``). scenes: a scene or a mapping ``{key: scene}``. Each solve gets the sample's
    own parameters (``bond_E``, ``bond_nu``) overridden by the entries of the parameter pytree it is given. When
    ``jaxbpm.<solver>`` has a ``stiffness_function`` and every scene is linear (bonds only, clamped layers), elastic
    targets use that pure function (batched and differentiable) with the solver's default options (``jaxbpm.DSM()``,
    ``jaxbpm.STE()``). ``solve_options`` go to ``jaxbpm.solve`` only.
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
        if not isinstance(sc, Scene):
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
            fns[key] = (factory(sample_map[key], sc, options_class(solver)()), length / area)

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
