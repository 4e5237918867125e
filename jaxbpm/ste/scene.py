"""The STE on a :class:`~jaxbpm.scenes.UniaxialCompression` scene: the scene's geometry, layered springs in series,
walls in series, the pure stiffness function and :func:`solve_scene` (what ``jaxbpm.solve(..., method="ste")``
runs).
"""

from __future__ import annotations

import time
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm._compile import compile_clock, Program, put, SetupCache, traced
from jaxbpm.errors import SceneError
from jaxbpm.physics.model import default_params
from jaxbpm.result import settle, timed_result
from jaxbpm.sample import Sample
from jaxbpm.ste.estimator import clamped_form, Estimator, estimator
from jaxbpm.ste.options import ESTIMATOR_OPTIONS, STE
from jaxbpm.ste.tensor import body_tensor, isotropic_fit, local_tensors, moduli

__all__ = ["layer_stiffness", "wall_series", "SceneGeometry", "scene_geometry", "scene_stiffness",
           "stiffness_function", "solve_scene", "solve_program"]


def layer_stiffness(est: Estimator, params, gauge_length, area):
    """Stiffness [N/m] of the layered springs-in-series model along ``est.axis`` (Jarolin & Dosta 2020, Case 3).

    Layer k: modulus ``E_k`` from the V-weighted mean tensor of its included particles (the body tensor where a
    layer has none), cross-section ``A_k = V_k / h`` from the volume its particles represent; compliance of the
    stack ``sum_k h / (E_k A_k)`` over the sample's extent, scaled to the gauge length. ``area`` is used only to
    keep the units when a layer holds no particle at all (it then counts with ``area``).

    Args:
      est: the estimator.
      params: the bond parameters.
      gauge_length: l [m].
      area: A [m^2].

    Returns:
      K [N/m].
    """
    ax = est.axis
    c = local_tensors(est, params)
    w = jnp.where(est.include, est.volume, 0.0)
    cw = jnp.where(est.include[:, None, None], c, 0.0) * w[:, None, None]
    num = jax.ops.segment_sum(cw, est.layer, est.n_layers)
    wsum = jax.ops.segment_sum(w, est.layer, est.n_layers)
    vol = jax.ops.segment_sum(est.volume, est.layer, est.n_layers)
    body = body_tensor(est, params)
    c_layer = jnp.where(wsum[:, None, None] > 0, num / jnp.where(wsum > 0, wsum, 1.0)[:, None, None], body)
    e_layer = moduli(c_layer)["E"][:, ax]
    extent = jnp.sum(vol) / area  # the sample's extent along the axis, as the volume sees it
    count = jnp.asarray(est.n_layers if est.layer_count is None else est.layer_count, jnp.int32)
    h = extent / count.astype(vol.dtype)
    a_layer = jnp.where(vol > 0, vol / h, area)
    real = jnp.arange(est.n_layers, dtype=jnp.int32) < count  # layers beyond the count are padding
    compliance = jnp.sum(jnp.where(real, h / (e_layer * a_layer), 0.0)) * gauge_length / extent
    return 1.0 / compliance


class SceneGeometry(NamedTuple):
    """What the STE needs of a scene besides the estimator (a pytree; built on the host by
    :func:`scene_geometry`): gauge ``length`` [m], ``area`` [m^2], the compressive displacement ``load`` [m] at which
    the walls are linearised (``s`` x the target displacement, ``s`` the middle of the fit range), the
    ``wall_stiffness`` (E* [Pa] of a particle on a rigid wall, or k [N/m] for linear walls) and the masks ``[n]`` of
    the particles that touch the bottom and the top wall."""

    length: Any
    area: Any
    load: Any
    wall_stiffness: Any
    touch_bottom: Any
    touch_top: Any


def scene_geometry(est: Estimator, sample: Sample, scene, fraction: float | None = None):
    """What the STE needs of ``scene`` besides the estimator (NumPy work on the host).

    Args:
      est: the estimator (the masks get its ``est.n`` rows; padding rows touch nothing).
      sample: the bonded sample.
      scene: the scene.
      fraction: where the walls are linearised, a fraction of the target displacement (``None``: the middle of
        the fit range).

    Returns:
      ``(SceneGeometry, wall_law)``; ``wall_law`` is ``None`` without walls.

    Raises:
      SceneError: a wall law the STE does not know, or linear walls without a stiffness.
    """
    length, area = scene.geometry(sample)
    dtype = est.model.positions0.dtype
    n, law, ws = est.n, None, 0.0
    touch = [np.zeros(n, bool), np.zeros(n, bool)]
    s = float(np.mean(scene.fit_range)) if fraction is None else float(fraction)
    delta = scene.strain * length
    if scene.uses_walls:
        law = scene.wall_law
        pm = sample.particle_material
        if law == "hertz":
            ws = float(pm.E) / (1.0 - float(pm.nu) ** 2) if scene.wall_stiffness is None else scene.wall_stiffness
        elif law == "linear":
            if scene.wall_stiffness is None:
                raise SceneError("wall_law='linear' needs wall_stiffness [N/m]")
            ws = scene.wall_stiffness
        else:
            raise SceneError(f"unknown wall law {law!r}; use 'hertz' or 'linear'")
        ax = scene.axis
        pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
        m = len(rad)
        lo_gap = (pos[:, ax] - rad) - (pos[:, ax] - rad).min()
        hi_gap = (pos[:, ax] + rad).max() - (pos[:, ax] + rad)
        touch[0][:m], touch[1][:m] = lo_gap <= 0.5 * delta, hi_gap <= 0.5 * delta
    geo = SceneGeometry(length=put(length, dtype), area=put(area, dtype), load=put(s * delta, dtype),
                        wall_stiffness=put(ws, dtype), touch_bottom=put(touch[0]), touch_top=put(touch[1]))
    return geo, law


def _wall_series(k_body, radii, geo: SceneGeometry, law: str):
    dtype = jnp.result_type(k_body)
    ws = geo.wall_stiffness.astype(dtype)
    radii = radii.astype(dtype)

    def wall_k(force, touch):
        count = jnp.sum(touch.astype(dtype))
        if law == "linear":
            return ws * count + 0.0 * force
        share = force / count
        overlap = (3.0 * share / (4.0 * ws * jnp.sqrt(radii))) ** (2.0 / 3.0)
        return jnp.sum(jnp.where(touch, 2.0 * ws * jnp.sqrt(radii * overlap), 0.0))

    k = k_body
    kw = (k_body, k_body)
    load = geo.load.astype(dtype)
    for _ in range(40):  # k_wall ~ F^(1/3): a contraction, converges to round-off in a few dozen steps
        force = k * load
        kw = (wall_k(force, geo.touch_bottom), wall_k(force, geo.touch_top))
        k = 1.0 / (1.0 / k_body + 1.0 / kw[0] + 1.0 / kw[1])
    counts = [jnp.sum(t.astype(jnp.int32)) for t in (geo.touch_bottom, geo.touch_top)]
    return k, {"k_bottom": kw[0], "k_top": kw[1], "n_bottom": counts[0], "n_top": counts[1]}


def wall_series(k_body, est: Estimator, scene, sample: Sample, fraction: float | None = None):
    """The body and the two walls as springs in series (Jarolin & Dosta 2020, 3.2.3):
    ``1/K = 1/K_body + 1/k_bottom + 1/k_top``.

    A wall's stiffness is the sum of the tangent stiffnesses of the particles touching it, each carrying an equal
    share of the force ``F = K * s * delta`` the sample carries at the middle ``s`` of the scene's fit range
    (``delta`` = target displacement); ``K`` and ``F`` are solved for together (fixed point).

    Args:
      k_body: the body's stiffness [N/m].
      est: the estimator.
      scene: the scene (with walls).
      sample: the bonded sample.
      fraction: as in :func:`scene_geometry`.

    Returns:
      ``(K, {"k_bottom", "k_top", "n_bottom", "n_top"})``.
    """
    geo, law = scene_geometry(est, sample, scene, fraction)
    return _wall_series(k_body, est.model.radii, geo, law)


def _scene_stiffness(est: Estimator, params, geo: SceneGeometry, layered: bool, walls: str | None):
    c6 = body_tensor(est, params)
    e_axis = moduli(c6)["E"][est.axis]
    length, area = geo.length.astype(c6.dtype), geo.area.astype(c6.dtype)
    k_body = layer_stiffness(est, params, length, area) if layered else e_axis * area / length
    parts = {"K_body": k_body, "E_axis": e_axis, "tensor": c6}
    k = k_body
    if walls is not None:
        k, wall_parts = _wall_series(k_body, est.model.radii, geo, walls)
        parts.update(wall_parts)
    return k, parts


def scene_stiffness(est: Estimator, params, sample: Sample, scene, *, layered: bool = False):
    """Stiffness K [N/m] of ``scene`` from the STE: ``E_axis A / l`` (or the layered model), walls in series.

    Args:
      est: the estimator built for the scene (``est.axis`` is the load axis).
      params: the bond parameters.
      sample: the bonded sample.
      scene: the scene.
      layered: the layered springs-in-series model.

    Returns:
      ``(K, parts)`` with ``parts = {"K_body", "E_axis", "tensor", ...}`` (jnp values).
    """
    geo, law = scene_geometry(est, sample, scene)
    return _scene_stiffness(est, params, geo, layered, law)


def _check_scene(scene):
    from jaxbpm.scenes import Scene

    if not isinstance(scene, Scene) or "ste" not in scene.methods:
        raise SceneError(f"the STE knows the UniaxialCompression scene, got {type(scene).__name__}")


def _estimator_for(sample, scene, options: STE):
    """``(est, geometry, wall_law)`` of ``sample`` and ``scene``: the setup :func:`solve_scene` and
    :func:`stiffness_function` share, kept for the last few samples."""
    # what the estimator does not depend on gives one key; walls clamp nothing: both forms are the free one there
    boundary = options.boundary if clamped_form(scene, options.boundary) else "free"
    key = (scene, options.replace(layered=False, throw=True, boundary=boundary))
    return _setups.get(sample, key, lambda: _setup(sample, scene, options))


def stiffness_function(sample: Sample, scene, options: STE | None = None, **overrides):
    """A pure function ``params -> K`` [N/m] of ``scene`` estimated by the STE (``jit``/``grad``/``vmap``-able,
    e.g. ``jax.vmap(f)({"bond_E": E_batch, "bond_nu": nu_batch})``).

    The estimator is the one :func:`solve_scene` keeps for the sample (padded to its size class unless
    ``pad=False``), and a call with concrete parameters runs the program :func:`solve_scene` compiled (no
    compilation when the process solved a sample of that class before).

    Args:
      sample: the bonded sample.
      scene: a :class:`~jaxbpm.scenes.UniaxialCompression`.
      options: the :class:`~jaxbpm.ste.options.STE` options (``None``: the defaults).
      **overrides: options overriding those of ``options`` (``layered=True``, ...).

    Returns:
      ``stiffness(params) -> K``.
    """
    options = STE() if options is None else options
    if overrides:
        options = options.replace(**overrides)
    _check_scene(scene)
    est, geo, law = _estimator_for(sample, scene, options)
    layered = bool(options.layered)

    def stiffness(params):
        if not traced(params):
            return solve_program(est, params, geo, layered=layered, walls=law)[0][0]
        return _scene_stiffness(est, params, geo, layered, law)[0]

    return stiffness


def _outputs(est: Estimator, params, geo: SceneGeometry, layered: bool, walls: str | None):
    """Everything :func:`solve_scene` reports, from one program: K, its parts, the moduli and the isotropic fit."""
    k, parts = _scene_stiffness(est, params, geo, layered, walls)
    m = moduli(parts["tensor"])
    e_iso, nu_iso = isotropic_fit(parts["tensor"])
    return k, parts, m["E"], m["nu"], e_iso, nu_iso


solve_program = Program(_outputs, static_argnames=("layered", "walls"), prime=2)  # ms-long: see Program
_setups = SetupCache()


def _setup(sample, scene, options: STE):
    est = estimator(sample, scene, pad=options.pad, **{k: getattr(options, k) for k in ESTIMATOR_OPTIONS})
    return (est,) + scene_geometry(est, sample, scene)


def solve_scene(sample: Sample, scene, params=None, options: STE | None = None):
    """Estimate the stiffness of ``scene`` with the STE (what ``jaxbpm.solve(..., method="ste")`` runs).

    Args:
      sample: the bonded sample.
      scene: a :class:`~jaxbpm.scenes.UniaxialCompression`.
      params: parameters checked by :func:`jaxbpm.physics.model.check_params` (``None``: the sample's own).
      options: the :class:`~jaxbpm.ste.options.STE` options (``None``: the defaults).

    Returns:
      The :class:`~jaxbpm.result.Result`. Its ``stats``: ``tensor`` (Voigt 6x6 [Pa], nested lists), ``E_x``,
      ``E_y``, ``E_z`` [Pa], ``nu`` (3x3), ``E_iso``, ``nu_iso`` (isotropic fit), ``K_body`` (before walls),
      ``skipped`` (singular particles), ``surface`` (surface particles left out of the averages), ``clamped``
      (particles of the scene's fixed and driven sets, which follow the affine field and are left out of the
      averages), ``boundary`` (the form that ran: ``"clamped"``, or ``"free"`` where asked for or where the scene
      has walls), ``particles``, ``bonds``,
      ``contacts``, ``dofs``, ``first_neighbour``, ``layered``; walls: ``k_bottom``, ``k_top`` [N/m],
      ``n_bottom``, ``n_top``; ``size_class`` (the padded particle, bond and contact capacities).

    Raises:
      NotFiniteError: with ``options.throw``, a stiffness that is not finite.
    """
    options = STE() if options is None else options
    t0 = time.perf_counter()
    _check_scene(scene)
    params = default_params(sample) if params is None else params
    with compile_clock() as setup_compile:  # programs the setup compiles count as compilation
        est, geo, law = _estimator_for(sample, scene, options)
    setup_time = time.perf_counter() - t0 - setup_compile.seconds
    out, compile_time, run_time = solve_program(est, params, geo, layered=bool(options.layered), walls=law)
    compile_time += setup_compile.seconds
    k, parts, e, nu, e_iso, nu_iso = jax.tree_util.tree_map(np.asarray, out)
    length, area = float(geo.length), float(geo.area)
    delta = scene.strain * length
    stats = _stats(est, scene, parts, e, nu, e_iso, nu_iso, options.layered, setup_time)
    stats["boundary"] = "clamped" if clamped_form(scene, options.boundary) else "free"
    k = float(k)
    # what is neither setup nor compilation (moving the outputs to the host) counts as run time
    return settle(timed_result("ste", t0, stiffness=k, gauge_length=length, area=area,
                               displacement=np.array([0.0, delta]), force=np.array([0.0, k * delta]),
                               compile_time=compile_time, setup_time=setup_time, stats=stats), options.throw)


def _stats(est: Estimator, scene, parts, e, nu, e_iso, nu_iso, layered, setup_time) -> dict:
    """The result's ``stats`` from the program's outputs (host arrays)."""
    stats = {"tensor": parts["tensor"].tolist(), "E_x": float(e[0]), "E_y": float(e[1]),
             "E_z": float(e[2]) if len(e) > 2 else None,
             "nu": nu.tolist(), "E_iso": float(e_iso), "nu_iso": float(nu_iso), "K_body": float(parts["K_body"]),
             "E_axis": float(parts["E_axis"]), "skipped": est.skipped, "surface": est.surface, "clamped": est.clamped,
             "particles": est.particles, "bonds": est.bonds, "contacts": est.contacts, "dofs": est.dofs,
             "first_neighbour": est.first_neighbour, "layered": bool(layered), "precision": str(est.d.dtype),
             "size_class": [est.n, est.n_bonds, est.n_contacts], "setup_time": setup_time}
    lateral = [k for k in range(len(e)) if k != scene.axis]
    # the uniaxial test's Poisson ratio: lateral strain per axial strain under stress along the load axis
    stats["poisson_ratio"] = float(np.mean([nu[scene.axis, k] for k in lateral]))
    for name in ("k_bottom", "k_top", "n_bottom", "n_top"):
        if name in parts:
            stats[name] = float(parts[name]) if name.startswith("k") else int(parts[name])
    return stats
