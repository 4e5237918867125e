"""The DEM started from the DSM's elastic state: what ``DEM(start="elastic")`` runs before the chunks.

Until the first bond breaks, a bonded sample under quasi-static loading is linear (with Hertz-Mindlin contacts:
linearised about the start), so every bond's forces and moments scale with the prescribed displacement. The DSM
solves the scene once at its target displacement; the scale ``s*`` (a fraction of the target) at which the first bond
reaches its strength under the scene's failure rule follows per bond by a 1-D root solve on the rule itself
(:func:`break_scales`), refined once with the exact bond law at ``s*``. The DEM then starts at ``safety x s*``
(rounded down to whole chunks) from the DSM's displacements and rotations at that scale, with the loading's
quasi-static velocity field (the DSM field per unit prescribed displacement times the loading speed), the clamped
particles where the loading puts them at that time, the tangential springs of the bonded pairs' contacts from the
relative motion of their contact points (no slip) and the forces of that state. The run's records start with the
DSM's elastic segment: one row per skipped step, the reactions of the start state scaled linearly from zero.

Where the DSM cannot give the state the run starts from rest and says why (``stats["elastic_start"]["fallback"]``,
and a warning): walls (their gaps close as the load goes), the cohesive contact law, no breakage, a DSM solve that
did not converge, contacts that carry most of the load, a start state out of balance (contacts that slide), a first
break within the first chunk.
"""

from __future__ import annotations

import dataclasses
import functools
import time
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm._compile import capacity
from jaxbpm.dem.state import DEMState
from jaxbpm.physics import bond as bond_mod, rotation

__all__ = ["ElasticStart", "elastic_start", "first_break_scale", "break_scales", "with_segment", "SAFETY",
           "IMBALANCE", "CONTACT_SHARE"]

#: the start's default fraction of the first-break scale (``DEM(start_safety=...)``)
SAFETY = 0.9
#: the largest force imbalance of the start state (the rms force on the free particles over the mean bond force):
#: above it the DSM's state is not the DEM's (contacts that slide, or that the linearisation misses)
IMBALANCE = 0.25
#: the states along the DSM's field whose reactions the elastic segment interpolates
SEGMENT_POINTS = 16
#: the largest share of the reaction the contacts may carry at the start (the DSM linearises them)
CONTACT_SHARE = 0.5


class ElasticStart(NamedTuple):
    """Where a DEM run starts.

    Attributes:
        state: the start state (of the plan's model, padded where it is), or ``None``: from rest.
        steps_done: the steps of the loading the start stands for (whole chunks; 0 from rest).
        records: the elastic segment, one row per skipped step (``time``, ``reaction``, ``vmax``, ``broken``, as
            the DEM records them); empty from rest.
        stats: ``{"elastic_start": {...}}``: the scale of the start and of the first break, the DSM's kind and time,
            the start's force imbalance and contacts; or the ``fallback`` reason.
    """

    state: DEMState | None
    steps_done: int
    records: dict
    stats: dict


def elastic_start(sample, scene, params, the_plan, static, *, safety: float = SAFETY) -> ElasticStart:
    """The DSM-started state of a DEM run, or a start from rest where the DSM cannot give it.

    Args:
        sample: the sample.
        scene: the scene.
        params: the parameters (checked).
        the_plan: the run's :class:`~jaxbpm.dem.plan.Plan` (model, time step, loading, steps, chunk).
        static: the static solve, ``static(sample, scene, params, safety)`` returning ``(u, s_first, info)``: the
            displacements (and rotation vectors) ``[n, 3 or 6]`` at the target displacement, the first-break scale
            (:func:`first_break_scale`) and a dict of what the solve was; or a string, the reason it cannot give the
            state (:func:`jaxbpm.elastic_field.dsm_field`, the DSM's, is what :func:`jaxbpm.solve` passes).
        safety: the start's fraction of the first-break scale, in (0, 1].

    Returns:
        The :class:`ElasticStart` (``state`` ``None`` with a warning naming the reason where the run starts from
        rest).
    """
    t0 = time.perf_counter()
    reason = _unsupported(sample, scene, the_plan)
    if reason is not None:
        return _rest(reason)
    field = static(sample, scene, params, safety)
    if isinstance(field, str):
        return _rest(field)
    u, first, info = field
    model = the_plan.model
    steps_done = int(np.floor(safety * min(first, 1.0) * the_plan.n_steps / the_plan.chunk)) * the_plan.chunk
    if steps_done <= 0:
        return _rest(f"the first bond breaks at {100 * first:.3g} % of the target displacement, within the first "
                     f"chunk ({the_plan.chunk} steps)")
    scale = steps_done / the_plan.n_steps
    state, check = _start_state(sample, model, params, the_plan, u, scale, steps_done)
    if check["broken"]:
        return _rest(f"{check['broken']} bonds break at the start state (the DSM's first-break scale does not hold "
                     "for the exact laws)")
    if check["contact_share"] > CONTACT_SHARE:
        return _rest(f"contacts carry {100 * check['contact_share']:.0f} % of the reaction at the start: the "
                     "linearised DSM does not give that state")
    if check["imbalance"] > IMBALANCE:
        return _rest(f"the DEM's forces at the DSM's state are out of balance by {100 * check['imbalance']:.0f} % "
                     f"of the mean bond force ({check['sliding']} of {check['active']} contacts slide there; the "
                     "DSM's do not)")
    records = _segment(the_plan, check["along"], steps_done, check["vmax"])
    info.update(scale=scale, first_break_scale=first, safety=float(safety), steps_skipped=steps_done,
                displacement=scale * the_plan.target, strain=scale * scene.strain,
                imbalance=check["imbalance"], contact_share=check["contact_share"],
                contacts_sliding=check["sliding"], contacts_active=check["active"], time=time.perf_counter() - t0)
    return ElasticStart(state, steps_done, records, {"elastic_start": info, "elastic_segment": steps_done})


def _rest(reason: str) -> ElasticStart:
    warnings.warn(f"start='elastic': starting from rest: {reason}", stacklevel=4)
    return ElasticStart(None, 0, {}, {"elastic_start": {"fallback": reason}, "elastic_segment": 0})


def _unsupported(sample, scene, the_plan) -> str | None:
    """Why the DSM cannot give the start of this run, or ``None``."""
    if scene.uses_walls:
        return "the scene loads by walls, whose gaps to the sample close as the load goes (the DSM holds clamped " \
               "particles only)"
    if scene.cohesive_law is not None:
        return "the cohesive contact law has no DSM"
    if not the_plan.breakage or sample.n_bonds == 0:
        return "no bond breaks in this run"
    return None


def first_break_scale(model, params, u) -> float:
    """The fraction of the displacement field ``u`` at which the first bond reaches its strength.

    Args:
        model: the model of the sample's bonds (its failure rule).
        params: the parameters.
        u: ``[n, 3 or 6]`` the DSM's displacements (and rotation vectors) at the target displacement.

    Returns:
        The scale ``s*`` (``inf`` when no bond breaks): forces scale linearly with it from the field's, evaluated
        again with the exact bond law at the first estimate.
    """
    strength = model.strength(params)
    k = model.stiffness(params)
    scale = 1.0
    for _ in range(2):
        per_bond = _bond_forces(model, k, jnp.asarray(scale * u, model.positions0.dtype))
        s = float(jnp.min(break_scales(per_bond, strength, model.failure_rule)))
        if not np.isfinite(s):
            return float("inf")
        scale = scale * s
    return scale


def _bond_forces(model, k, u):
    x = model.positions0 + u[:, :3]
    q = rotation.from_rotation_vector(u[:, 3:6]) if model.rotations else None
    return bond_mod.bond_forces(x, q, model.bonds, model.r0, k)[2]


@functools.partial(jax.jit, static_argnames=("rule",))
def break_scales(forces, strength, rule: str):
    """The scale of each bond's forces at which it breaks under ``rule``, by bisection on the rule itself.

    Args:
        forces: the bonds' :class:`~jaxbpm.physics.bond.BondForces` (``[nb, ...]``) at scale 1.
        strength: the bonds' :class:`~jaxbpm.physics.bond.BondStrength`.
        rule: the failure rule (:data:`jaxbpm.physics.bond.FAILURE_RULES`).

    Returns:
        ``[nb]`` the scales (``inf`` where a bond holds up to 1e6 times its forces): within 1e-12 relative.
    """
    def breaks(s):
        mode, *_ = bond_mod.bond_failure(s * forces.normal, s[:, None] * forces.shear, s * forces.twist,
                                         s[:, None] * forces.bend, strength, rule)
        return mode > 0

    nb = forces.normal.shape[0]
    dtype = forces.normal.dtype
    hi = jnp.full(nb, 1e6, dtype)
    lo = jnp.zeros(nb, dtype)

    def bisect(_, bounds):
        lo, hi = bounds
        mid = jnp.sqrt(jnp.maximum(lo, 1e-12) * hi)  # geometric: scales over many decades
        out = breaks(mid)
        return jnp.where(out, lo, mid), jnp.where(out, mid, hi)

    lo, hi = jax.lax.fori_loop(0, 80, bisect, (lo, hi))
    return jnp.where(breaks(hi), hi, jnp.inf)


def _start_state(sample, model, params, the_plan, u, scale, steps_done):
    """The DEM state at ``scale`` of the DSM's field ``u`` (time ``steps_done`` steps in), the reactions of the DEM's
    forces along the field up to it (:data:`SEGMENT_POINTS` states) and what the checks need of the start: bonds
    broken there, the contacts' share of the reaction and sliding, the force imbalance of the free particles and the
    largest speed."""
    n, dtype = model.n, np.dtype(model.positions0.dtype)
    load, t = the_plan.load, steps_done * the_plan.dt
    per_unit = np.zeros((n, 6))
    per_unit[:u.shape[0], :u.shape[1]] = u / the_plan.target  # the field per unit prescribed displacement
    clamped, velocity = np.asarray(load.clamped), np.asarray(load.velocity, np.float64)
    x, theta, bond_spring = _configuration(model, load, per_unit, scale * the_plan.target, t)
    v = np.where(clamped[:, None], velocity, the_plan.speed * per_unit[:, :3])
    w = np.where(clamped[:, None], 0.0, the_plan.speed * per_unit[:, 3:]) if model.rotations else np.zeros((n, 3))
    q = rotation.from_rotation_vector(jnp.asarray(theta, dtype))
    nb = model.bonds.shape[0]
    pairs = jnp.asarray(_touching_pairs(sample, model, x) if model.contacts else np.zeros((0, 2)), np.int32)
    put = lambda a, t=dtype: jnp.asarray(a, t)  # noqa: E731
    force, moment, bonds_only, bond_scale, broken, sliding, active = _forces_at(
        model, params, put(x), q, None if bond_spring is None else put(bond_spring), pairs)
    state = DEMState(positions=put(x), velocities=put(v), orientations=q, omegas=put(w), force=force,
                     moment=moment, intact=jnp.ones(nb, bool), spring=jnp.zeros((0, 3), dtype), nbrs=None,
                     time=jnp.asarray(t, dtype), broken=jnp.zeros(nb, jnp.int8),
                     broken_time=jnp.full(nb, jnp.nan, dtype),
                     bond_spring=None if bond_spring is None else put(bond_spring))
    check = _checks(load, np.asarray(force), np.asarray(bonds_only), float(bond_scale), int(broken), int(sliding),
                    int(active))
    check["vmax"] = float(np.max(np.abs(v)))
    # the reactions along the field (the pairs that touch at the start: the others touch nowhere before it)
    along = [np.zeros_like(check["reaction"])]
    for k in range(1, SEGMENT_POINTS):
        frac = k / SEGMENT_POINTS
        xk, theta_k, spring_k = _configuration(model, load, per_unit, frac * scale * the_plan.target, frac * t)
        fk = _forces_at(model, params, put(xk), rotation.from_rotation_vector(jnp.asarray(theta_k, dtype)),
                        None if spring_k is None else put(spring_k), pairs)[0]
        along.append(_reaction_rows(load, np.asarray(fk)))
    check["along"] = np.stack(along + [check["reaction"]])
    return state, check


def _configuration(model, load, per_unit, displacement, t):
    """Positions ``[n, 3]``, rotation vectors ``[n, 3]`` and the bonded pairs' contact springs (``None`` without
    contacts) at ``displacement`` [m] of the field ``per_unit`` (per unit prescribed displacement), the clamped
    particles where the loading puts them at time ``t``."""
    clamped, velocity = np.asarray(load.clamped), np.asarray(load.velocity, np.float64)
    x0 = np.asarray(model.positions0, np.float64)
    x = np.where(clamped[:, None], x0 + t * velocity, x0 + displacement * per_unit[:, :3])
    theta = np.where(clamped[:, None], 0.0, displacement * per_unit[:, 3:]) if model.rotations else 0 * x
    return x, theta, _bond_springs(model, x, theta) if model.contacts else None


def _reaction_rows(load, force):
    """``[2, 3]`` the sums of the forces on the clamped particles that move and on those at rest."""
    clamped, velocity = np.asarray(load.clamped), np.asarray(load.velocity)
    moving = clamped & np.any(velocity != 0, axis=1)
    return np.stack([force[moving].sum(axis=0), force[clamped & ~moving].sum(axis=0)])


def _checks(load, force, bonds_only, bond_scale, broken, sliding, active) -> dict:
    """The start state's reaction rows, bonds broken, the contacts' share of the reaction, the contacts sliding
    (count and share of the active ones) and the imbalance: the rms force on the free particles over the mean bond
    force."""
    clamped = np.asarray(load.clamped)
    reaction, from_bonds = _reaction_rows(load, force), _reaction_rows(load, bonds_only)
    total = np.linalg.norm(reaction)
    share = float(np.linalg.norm(reaction - from_bonds) / total) if total > 0 else 0.0
    free = ~clamped
    rms = float(np.sqrt(np.mean(np.sum(force[free] ** 2, axis=1)))) if free.any() else 0.0
    return {"reaction": reaction, "broken": broken, "contact_share": share, "sliding": sliding, "active": active,
            "imbalance": rms / bond_scale if bond_scale > 0 else 0.0}


def _bond_springs(model, x, theta):
    """``[nb, 3]`` the tangential springs of the bonded pairs' contacts at positions ``x`` and rotations ``theta``:
    the relative displacement of their contact points since rest, in the tangent plane (no slip), where they
    overlap."""
    b = np.asarray(model.bonds)
    i, j = b[:, 0], b[:, 1]
    r = np.asarray(model.radii, np.float64)
    x0 = np.asarray(model.positions0, np.float64)
    d = x[j] - x[i]
    dist = np.linalg.norm(d, axis=1, keepdims=True)
    normal = d / np.where(dist > 0, dist, 1.0)
    spin = r[j, None] * theta[j] + r[i, None] * theta[i]
    xi = (x[j] - x0[j]) - (x[i] - x0[i]) - np.cross(spin, normal)
    xi = xi - np.sum(xi * normal, axis=1, keepdims=True) * normal
    overlap = r[i] + r[j] - dist[:, 0] > 0
    return np.where(overlap[:, None], xi, 0.0)


def _touching_pairs(sample, model, x):
    """``[C, 2]`` the pairs not bonded that overlap at positions ``x`` (their springs start empty, as in the
    DEM), padded with pairs ``(n, n)``."""
    from scipy.spatial import cKDTree

    n = sample.n_particles
    pos, r = x[:n], np.asarray(model.radii, np.float64)[:n]
    pairs = np.array(sorted(cKDTree(pos).query_pairs(2 * r.max())), dtype=np.int64).reshape(-1, 2)
    if len(pairs):
        pairs = pairs[np.linalg.norm(pos[pairs[:, 1]] - pos[pairs[:, 0]], axis=1) < r[pairs[:, 0]] + r[pairs[:, 1]]]
    if len(pairs):
        pairs = pairs[~np.asarray(model.bonded(jnp.asarray(pairs, np.int32)))]
    # padded (pairs of particle n, never valid) to a size of the capacity ladder: one program for starts nearby
    padded = np.full((capacity(len(pairs)), 2), model.n, np.int64)
    padded[:len(pairs)] = pairs
    return padded.astype(np.int32)


@jax.jit
def _forces_at(model, params, x, q, bond_spring, pairs):
    """The DEM's forces and moments at a state at rest in time (bonds, the bonded pairs' contacts with the given
    springs, the other touching ``pairs`` with empty ones), the bonds' part alone, the bonds broken there, the
    bonded pairs' new springs, and the contacts sliding and active."""
    contacts = bonded = None
    sliding = active = jnp.zeros((), jnp.int32)
    on = None
    if model.contacts:
        def still(i, j, d, *radii):
            zero = (jnp.zeros_like(d[0]),) * 3
            return zero, zero

        on = jnp.full(model.bonds.shape[0], model.bond_contact != "replace")
        bonded = (bond_spring, still, on)
        zero = jnp.zeros((pairs.shape[0], 3), x.dtype)
        contacts = (pairs, pairs[:, 0] < model.n, zero, zero, zero)
    force, moment, parts = model.forces(x, q, params, None, contacts, None, None, bonded)
    bonds_only, _, per_bond = bond_mod.bond_forces(x, q if model.rotations else None, model.bonds, model.r0,
                                                   model.stiffness(params))
    solid = model.bond_area > 0
    bond_scale = jnp.sum(jnp.where(solid, jnp.linalg.norm(per_bond.f_i, axis=1), 0.0)) / jnp.maximum(
        jnp.sum(solid), 1).astype(x.dtype)
    broken = jnp.sum(parts["broken"] > 0) if parts["broken"] is not None else jnp.zeros((), jnp.int32)
    new_springs = parts["bond_contacts"]
    if model.contacts:
        old, new = jnp.linalg.norm(bond_spring, axis=1), jnp.linalg.norm(new_springs, axis=1)
        cf = parts["contacts"]
        sliding = jnp.sum(on & (new < old * (1 - 1e-9))) + jnp.sum(cf.sliding)
        active = jnp.sum(on & (old > 0)) + jnp.sum(cf.active)
    return force, moment, bonds_only, bond_scale, broken, sliding, active


def _segment(the_plan, along, steps_done, vmax) -> dict:
    """The elastic segment's records: one row per skipped step, the reactions interpolated between those of the
    DEM's forces along the DSM's field (``along``: ``[K + 1, 2, 3]`` at ``0, 1/K, ..., 1`` of the start)."""
    k = np.arange(1, steps_done + 1)
    at = np.linspace(0.0, 1.0, along.shape[0])
    flat = along.reshape(along.shape[0], -1)
    rows = np.stack([np.interp(k / steps_done, at, flat[:, c]) for c in range(flat.shape[1])], axis=1)
    rows = {"time": k * the_plan.dt, "reaction": rows.reshape((steps_done,) + along.shape[1:]),
            "vmax": np.full(steps_done, vmax)}
    if the_plan.breakage:
        rows["broken"] = np.zeros((steps_done, 2), np.int32)
    return rows


def with_segment(records: dict, segment: dict) -> dict:
    """A run's records with the elastic segment first.

    Args:
        records: the DEM's per-step records (empty: no chunk completed).
        segment: the elastic segment (:attr:`ElasticStart.records`).

    Returns:
        The joined records; a record the segment lacks gets zeros of its kind there.
    """
    if not segment:
        return records
    if not records:
        return dict(segment)
    k = len(segment["time"])
    out = {}
    for key, rec in records.items():
        rec = np.asarray(rec)
        head = segment.get(key)
        head = np.zeros((k,) + rec.shape[1:], rec.dtype) if head is None else np.asarray(head, rec.dtype)
        out[key] = np.concatenate([head, rec])
    return out
