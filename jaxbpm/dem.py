"""Explicit DEM: velocity-Verlet time integration of the Model's forces, with rotations.

The integrator is a pair of pure functions on a pytree state (:func:`init_state`, :func:`step`), run in jitted
``lax.scan`` chunks by :func:`simulate`. Between chunks, outside jit, jaxbpm checks the neighbour list for overflow
(re-allocating and re-running the chunk, so no contact is ever dropped), checks for instability, and prints progress.

Integration (per step, time step dt)::

    v   += dt/2 (F + F_d) / m ,   w += dt/2 (M + M_d) / I        (half kick)
    x   += dt v ,                 q  = exp(dt w) q                (drift; clamped particles follow their motion)
    F, M = forces(x, q)                                           (one force evaluation per step)
    v   += dt/2 (F + F_d) / m ,   w += dt/2 (M + M_d) / I        (half kick)

Contacts: a neighbour list gives the candidate pairs (rebuilt when a particle has moved half its skin): on the CPU
a k-d tree on the host, rebuilt between chunks (a chunk stops before the step that would make it stale and goes on
after the rebuild); on accelerators jax-md's cell list, rebuilt inside the step (its rebuild fills a dense candidate
array that took a 1M-particle run on the CPU past 22 GiB). Inside the list, the pairs
within reach (surfaces closer than ``NEAR_MARGIN`` x skin) that are not bonded pairs are found again when a particle
has moved half that margin, and each step runs the contact law on those only (on an 8k dense box 1.6x faster per
step than testing and packing every candidate each step). The bonded pairs have their contact law evaluated on the
bond list, in one pass with the bond law and one scatter to the particles (superimposed on every bonded pair, or on
broken bonds only where bonds replace contacts; springs by bond: ``DEMState.bond_spring``).

Damping ``F_d`` is local non-viscous damping as in PFC and MUSEN: ``F_d = -alpha |F| sign(v)`` per component
(and the same for moments). It removes kinetic energy where a particle accelerates, without slowing a uniform
motion, which is what quasi-static loading needs; ``alpha = 0`` gives undamped, energy-conserving dynamics.

Time step: :func:`critical_time_step` finds the highest natural frequency of the bonded network by power iteration on
``M^-1/2 K M^-1/2`` (K from the Jacobians of the same bond law at rest), adds contact and wall stiffness at a
reference overlap, and returns ``dt_crit = 2 / omega_max``; the default step is ``safety * dt_crit``.

Compile once: the set-up of a run is host work plus two jitted programs (the power iteration, and the initial state
with the per-run constants); only scenes with contacts import jax-md (for its neighbour lists). A bonds-only model
padded to a size class (``build_model(..., pad_to=...)``, :func:`pad_loading`, :func:`unpad_state`) runs the chunk
compiled for any sample of that class.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm import _interrupt
from jaxbpm._compile import compile_clock, setup_jit
from jaxbpm.errors import InstabilityError, SimulationInterrupted
from jaxbpm.physics import contact as contact_mod
from jaxbpm.physics import rotation
from jaxbpm.physics.loading import Loading
from jaxbpm.physics.model import Model
from jaxbpm.neighbors import (_contact_pairs, _jax_md_context, _Near, _Neighbors, _remap_history, _remap_springs,
                              HostList, near_build, near_count, near_size, near_springs, near_stale, neighbors_owner,
                              NeighborSettings, pack, stale)

__all__ = ["DEMState", "Loading", "critical_time_step", "init_state", "step", "simulate", "kinetic_energy",
           "potential_energy", "NeighborSettings", "progress_printer", "pad_loading", "unpad_state"]


@dataclasses.dataclass(frozen=True)
class DEMState:
    """Integrator state (a pytree): positions/velocities ``[n, 3]``, orientations ``[n, 4]``, angular velocities
    ``[n, 3]``, current forces and moments ``[n, 3]``, bond ``intact`` mask ``[nb]``, how and when each bond broke
    (``broken`` ``[nb]`` int8: 0 intact, 1 tensile, 2 shear; ``broken_time`` ``[nb]`` [s], NaN while intact),
    contact ``spring`` ``[C, 3]`` and the jax-md neighbour list (``None`` without contacts), simulated ``time``;
    with the cohesive contact law the per-contact cohesion history ``cohesion`` ``[C]`` [Pa] (see
    :mod:`jaxbpm.physics.cohesive`; ``None`` otherwise) and ``spring`` holds the elastic tangential force [N]. With
    Hertz contacts, the contacts of bonded pairs keep their springs by bond, ``bond_spring`` ``[nb, 3]`` (``spring``
    then holds those of the other pairs)."""

    positions: Any
    velocities: Any
    orientations: Any
    omegas: Any
    force: Any
    moment: Any
    intact: Any
    spring: Any
    nbrs: Any
    time: Any
    broken: Any = None
    broken_time: Any = None
    cohesion: Any = None
    bond_spring: Any = None


jax.tree_util.register_dataclass(DEMState, data_fields=["positions", "velocities", "orientations", "omegas", "force",
                                                        "moment", "intact", "spring", "nbrs", "time", "broken",
                                                        "broken_time", "cohesion", "bond_spring"],
                                 meta_fields=[])


def _walls(load: Loading, t):
    return load.wall_points0 + t * load.wall_velocity, load.wall_normals


def _evaluate(model: Model, params, state: DEMState, load: Loading, dxi, v_rel, pairs_valid=None):
    contacts = None
    if model.contacts:
        pairs, valid = _contact_pairs(model, state.nbrs, state.intact) if pairs_valid is None else pairs_valid
        contacts = (pairs, valid, state.spring, dxi, v_rel)
        if model.contact_law == "cohesive":
            contacts = contacts + (state.cohesion,)
    return _forces(model, params, state, load, contacts)


def _forces(model: Model, params, state: DEMState, load: Loading, contacts, bond_contacts=None):
    """:meth:`Model.forces` at ``state``, with the walls where ``load`` has them at its time (the bonds in blocks of
    ``model.bond_block``)."""
    points, normals = _walls(load, state.time)
    return model.forces(state.positions, state.orientations, params, state.intact, contacts,
                        points if model.walls else None, normals if model.walls else None, bond_contacts,
                        model.bond_block)


def _contact_step(model: Model, params, load: Loading, state: DEMState, spring, dt, cohesion=None):
    """Forces and moments, wall reactions, the new tangential springs ``[C, 3]``, the new intact mask and break
    modes and (cohesive law) the new cohesion history ``[C]`` of a DEM step with contacts.

    Most candidate pairs of the neighbour list are padding or not touching, and the contact law costs the same for
    every pair it is given: when the touching pairs fit in half the buffer, only those are handed to the law (packed
    into a list of that size), otherwise all candidates are.
    """
    pairs, valid = _contact_pairs(model, state.nbrs, state.intact)
    capacity = pairs.shape[0]
    size = max(capacity // 3, 1)
    i, j, d = contact_mod.pair_vectors(state.positions, pairs, valid)
    # the contact law's own test (so that no pair it would find in contact is left out)
    touching = valid & (model.radii[i] + model.radii[j] - jnp.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) > 0)

    if model.contact_law == "cohesive":
        return _cohesive_step(model, params, load, state, spring, cohesion, dt, pairs, valid, touching, size)

    def evaluate(pairs, valid, spring):
        return _contact_forces(model, params, load, state, pairs, valid, spring, dt)

    def packed():
        take, _ = pack(touching, size)  # the touching slots, then `capacity` (none)
        force, moment, walls, packed_spring, intact, broken = evaluate(
            pairs.at[take].get(mode="fill", fill_value=model.n), take < capacity,
            spring.at[take].get(mode="fill", fill_value=0.0))
        return (force, moment, walls, jnp.zeros_like(spring).at[take].set(packed_spring, mode="drop"), intact,
                broken)

    return jax.lax.cond(jnp.sum(touching.astype(jnp.int32)) <= size, packed, lambda: evaluate(pairs, valid, spring))


def _contact_forces(model: Model, params, load: Loading, state: DEMState, pairs, valid, spring, dt):
    """Forces and moments, wall reactions, the pairs' new springs, the new intact mask and break modes, with the
    contact law on ``pairs`` only."""
    dxi, v_rel = _contact_motion(model, state, pairs, valid, dt)
    force, moment, parts = _evaluate(model, params, dataclasses.replace(state, spring=spring), load, dxi, v_rel,
                                     (pairs, valid))
    return force, moment, parts["walls"], parts["contacts"].spring, parts["intact"], parts["broken"]


def _near_forces(model: Model, params, load: Loading, state: DEMState, pairs, valid, spring, dt):
    """:func:`_contact_forces` with the bonded pairs' contacts on the bond list (with the bond law: one pass, one
    scatter; superimposed: every bonded pair, where bonds replace contacts: the broken ones) and the other pairs'
    on ``pairs`` (skipped in a step where none is within reach). Returns the same and the bonded pairs' new
    springs."""
    on = jnp.ones_like(state.intact) if model.bond_contact != "replace" else ~state.intact
    bonded = (state.bond_spring, lambda i, j, d: _motion(model, state, i, j, d, dt), on)
    force, moment, parts = _forces(model, params, state, load, None, bonded)

    def others():
        dxi, v_rel = _contact_motion(model, state, pairs, valid, dt)
        fc, mc, cf = contact_mod.pair_forces(state.positions, pairs, valid, model.radii, model.mass, spring, dxi,
                                             v_rel, model.hertz_params(params))
        return fc, mc, cf.spring

    fc, mc, spring = jax.lax.cond(jnp.any(valid), others,
                                  lambda: (jnp.zeros_like(force), jnp.zeros_like(moment), jnp.zeros_like(spring)))
    return (force + fc, moment + mc, parts["walls"], spring, parts["intact"], parts["broken"],
            parts["bond_contacts"])


def _near_step(model: Model, params, load: Loading, state: DEMState, new: DEMState, near: _Near, rebuilt, dt,
               margin):
    """The contact law on the bonded pairs (on the bond list, with the bond law: one pass, one scatter) and on the
    other pairs within reach (:class:`jaxbpm.neighbors._Near`), found again when stale (the candidate list was
    rebuilt, a particle moved more than ``margin / 2``). Returns the step's forces, moments, wall reactions, intact
    mask and break modes, the pairs within reach (their ``overflow`` set when they did not fit their slots: the chunk
    is then run again with more) and the bonded pairs' new springs."""
    capacity = new.nbrs.idx.shape[1]

    def refresh():
        spring = near_springs(near, capacity)
        spring = jax.lax.cond(rebuilt, lambda: _remap_springs(state.nbrs.idx.T, spring, new.nbrs.idx.T, model.n),
                              lambda: spring)
        found = near_build(model, new.positions, new.nbrs, spring, margin, near.slot.shape[0])
        return found._replace(overflow=found.overflow | near.overflow, count=jnp.maximum(found.count, near.count),
                              found=near.found + 1)

    near = jax.lax.cond(rebuilt | near_stale(near, new.positions, margin), refresh, lambda: near)
    force, moment, walls, spring, intact, broken, bond_spring = _near_forces(
        model, params, load, new, near.pairs, near.slot < capacity, near.spring, dt)
    return force, moment, walls, intact, broken, near._replace(spring=spring), bond_spring


def _cohesive_step(model: Model, params, load, state, spring, cohesion, dt, pairs, valid, touching, size):
    """:func:`_contact_step` for the cohesive law: the same packing of touching pairs, with the cohesion history
    packed alongside the springs (pairs left out are not in contact: their history is reset, see
    :func:`jaxbpm.physics.cohesive.update_cohesion`)."""
    capacity = pairs.shape[0]

    def evaluate(pairs, valid, spring, cohesion):
        dxi, v_rel = _contact_motion(model, state, pairs, valid, dt)
        force, moment, parts = _evaluate(model, params, dataclasses.replace(state, spring=spring, cohesion=cohesion),
                                         load, dxi, v_rel, (pairs, valid))
        cf = parts["contacts"]
        return force, moment, parts["walls"], cf.spring, parts["intact"], parts["broken"], cf.cohesion

    def packed():
        take, _ = pack(touching, size)
        force, moment, walls, packed_spring, intact, broken, packed_cohesion = evaluate(
            pairs.at[take].get(mode="fill", fill_value=model.n), take < capacity,
            spring.at[take].get(mode="fill", fill_value=0.0), cohesion.at[take].get(mode="fill", fill_value=0.0))
        rest = jnp.where(cohesion < 0, cohesion, 0.0)  # out of contact: pending initial contacts stay, others reset
        return (force, moment, walls, jnp.zeros_like(spring).at[take].set(packed_spring, mode="drop"), intact,
                broken, rest.at[take].set(packed_cohesion, mode="drop"))

    return jax.lax.cond(jnp.sum(touching.astype(jnp.int32)) <= size, packed,
                        lambda: evaluate(pairs, valid, spring, cohesion))


def initial_cohesion(model: Model, state: DEMState):
    """Cohesion history at the start of a run: ``-c_0`` (an initial contact, see
    :mod:`jaxbpm.physics.cohesive`) for the candidate pairs that overlap or whose surface gap is at most the law's
    ``initial_gap``, 0 for the others."""
    pairs, valid = _contact_pairs(model, state.nbrs, state.intact)
    i, j, d = contact_mod.pair_vectors(state.positions, pairs, valid)
    gap = jnp.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) - model.radii[i] - model.radii[j]
    c = model.cohesive
    return jnp.where(valid & (gap <= c.initial_gap), -c.c0, 0.0)


def _contact_motion(model: Model, state: DEMState, pairs, valid, dt):
    """Relative displacement in this step and relative velocity of the contact points of the pairs, as ``(x, y, z)``
    tuples of ``[C]`` arrays: ``v_rel = v_j - v_i - (r_j w_j + r_i w_i) x n``, ``dxi = dt v_rel``."""
    i, j, d = contact_mod.pair_vectors(state.positions, pairs, valid)  # padding has d = (1, 1, 1)
    return _motion(model, state, i, j, d, dt)


def _motion(model: Model, state: DEMState, i, j, d, dt):
    """:func:`_contact_motion` of the pairs ``i, j`` whose vectors are ``d`` (``|d| > 0``)."""
    dist = jnp.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    v_t, w_t, r_i, r_j = state.velocities.T, state.omegas.T, model.radii[i], model.radii[j]
    s = tuple(r_j * w_t[k][j] + r_i * w_t[k][i] for k in range(3))
    spin = (s[1] * d[2] - s[2] * d[1], s[2] * d[0] - s[0] * d[2], s[0] * d[1] - s[1] * d[0])
    # one division per component, so that XLA computes each component once (see jaxbpm.physics.contact.law_components)
    v_rel = tuple(((v_t[k][j] - v_t[k][i]) * dist - spin[k]) / dist for k in range(3))
    return tuple(dt * c for c in v_rel), v_rel  # the contact law takes component tuples as well as [C, 3] rows


def init_state(model: Model, params, load: Loading, nbrs=None) -> DEMState:
    """Reference configuration at rest (velocities of clamped particles as prescribed), with the forces there
    (one jitted program)."""
    return _start(model, params, load, nbrs)[0]


@setup_jit
def _start(model: Model, params, load: Loading, nbrs):
    """The initial state (see :func:`init_state`) and the per-run constants (:meth:`Model.precompute`)."""
    return _initial_state(model, params, load, nbrs), model.precompute(params)


def _initial_state(model: Model, params, load: Loading, nbrs) -> DEMState:
    n, dtype = model.n, model.positions0.dtype
    capacity = nbrs.idx.shape[1] if nbrs is not None else 0
    state = DEMState(
        positions=model.positions0,
        velocities=jnp.where(load.clamped[:, None], load.velocity, 0.0),
        orientations=rotation.identity(n, dtype),
        omegas=jnp.zeros((n, 3), dtype),
        force=jnp.zeros((n, 3), dtype),
        moment=jnp.zeros((n, 3), dtype),
        intact=jnp.ones(model.bonds.shape[0], bool),
        spring=jnp.zeros((capacity, 3), dtype),
        nbrs=nbrs,
        time=jnp.zeros((), dtype),
        broken=jnp.zeros(model.bonds.shape[0], jnp.int8),
        broken_time=jnp.full(model.bonds.shape[0], jnp.nan, dtype),
    )
    if model.contacts and model.contact_law == "cohesive":
        state = dataclasses.replace(state, cohesion=initial_cohesion(model, state))
    state = _with_bond_springs(model, state)
    zeros = jnp.zeros((capacity, 3), dtype)
    force, moment, _ = _evaluate(model, params, state, load, zeros, zeros)
    return dataclasses.replace(state, force=force, moment=moment)


def _with_bond_springs(model: Model, state: DEMState) -> DEMState:
    """``state`` with empty springs for the contacts of the bonded pairs (Hertz contacts; see :func:`_near_forces`)
    where it has none."""
    if not model.contacts or model.contact_law == "cohesive" or state.bond_spring is not None:
        return state
    return dataclasses.replace(state, bond_spring=jnp.zeros((model.bonds.shape[0], 3), state.positions.dtype))


#: the pairs within reach (see :func:`step`): within this fraction of the neighbour list's skin of touching
#: (0.05 r_min by default, found again every ~0.025 r_min of motion). Bonded pairs are not among them, so a wider
#: margin costs few slots: an 8k cylinder to failure had at most 895 such pairs (690 at 0.02 r_min) and found them
#: 284 times in 5120 steps (631 times), 24.3 s against 26.0 s; ``None``: every step tests and packs the whole
#: candidate list
NEAR_MARGIN = 0.1


def _damped(f, v, alpha):
    return f - alpha * jnp.abs(f) * jnp.sign(v)


def _drift(model: Model, load: Loading, state: DEMState, dt, alpha):
    """The first half kick and the drift of :func:`step`: the half-step velocities, the new positions and time."""
    clamped = load.clamped[:, None]
    v = state.velocities + 0.5 * dt * _damped(state.force, state.velocities, alpha) * (1.0 / model.mass[:, None])
    v = jnp.where(clamped, load.velocity, v)
    t = state.time + dt
    x = jnp.where(clamped, model.positions0 + t * load.velocity, state.positions + dt * v)
    return v, x, t


def step(model: Model, params, load: Loading, state: DEMState, dt, alpha, origin, near: _Near | None = None,
         margin=None):
    """One velocity-Verlet step. Returns ``(new_state, record)``; record holds the reaction forces ``[W+2, 3]``
    (walls, then the sums of internal forces on the clamped particles moving and at rest) and the largest speed.

    With Hertz contacts, ``near`` (the pairs within ``margin`` of touching, :func:`jaxbpm.neighbors.near_build`)
    makes the step run the contact law on those pairs only; it then returns ``(new_state, record, near)``. Without,
    every step tests and packs the whole candidate list."""
    clamped = load.clamped[:, None]
    inv_m, inv_i = 1.0 / model.mass[:, None], 1.0 / model.inertia[:, None]
    v, x, t = _drift(model, load, state, dt, alpha)
    if model.rotations:
        w = state.omegas + 0.5 * dt * _damped(state.moment, state.omegas, alpha) * inv_i
        w = jnp.where(clamped, 0.0, w)
        q = rotation.integrate(state.orientations, dt * w)
    else:
        w, q = state.omegas, state.orientations

    new = DEMState(positions=x, velocities=v, orientations=q, omegas=w, force=state.force, moment=state.moment,
                   intact=state.intact, spring=state.spring, nbrs=state.nbrs, time=t, broken=state.broken,
                   broken_time=state.broken_time, cohesion=state.cohesion, bond_spring=state.bond_spring)
    if model.contacts:
        # the pairs gather x, v and w about 20 times each: an exact division by a run-time one makes XLA compute them
        # once, not again inside every gather
        one = dt / dt
        x, v, w = x / one, v / one, w / one
        if isinstance(state.nbrs, HostList):  # built between chunks; the chunk stops before it goes stale
            nbrs, rebuilt = state.nbrs, jnp.zeros((), bool)
        else:
            with _jax_md_context():
                nbrs = state.nbrs.update(x - origin[None, :])
            rebuilt = jnp.any(nbrs.reference_position != state.nbrs.reference_position)
        new = dataclasses.replace(new, positions=x, velocities=v, omegas=w, nbrs=nbrs)
        if model.contact_law == "cohesive":
            spring, cohesion = jax.lax.cond(
                rebuilt, lambda: _remap_history(state.nbrs.idx.T, nbrs.idx.T, model.n, state.spring, state.cohesion),
                lambda: (state.spring, state.cohesion))
            force, moment, walls, spring, intact, broken, cohesion = _contact_step(model, params, load, new, spring,
                                                                                   dt, cohesion)
            new = dataclasses.replace(new, cohesion=cohesion)
        elif near is not None:
            force, moment, walls, intact, broken, near, bond_spring = _near_step(model, params, load, state, new, near,
                                                                                 rebuilt, dt, margin)
            new = dataclasses.replace(new, bond_spring=bond_spring)
            spring = state.spring  # (the pairs within reach carry the springs; the chunk hands them back at its end)
        else:
            spring = jax.lax.cond(rebuilt,
                                  lambda: _remap_springs(state.nbrs.idx.T, state.spring, nbrs.idx.T, model.n),
                                  lambda: state.spring)
            force, moment, walls, spring, intact, broken = _contact_step(model, params, load, new, spring, dt)
    else:
        force, moment, parts = _evaluate(model, params, new, load, None, None)
        walls, spring, intact, broken = parts["walls"], state.spring, parts["intact"], parts["broken"]
    v = v + 0.5 * dt * _damped(force, v, alpha) * inv_m
    v = jnp.where(clamped, load.velocity, v)
    if model.rotations:
        w = w + 0.5 * dt * _damped(moment, w, alpha) * inv_i
        w = jnp.where(clamped, 0.0, w)
    moving = clamped & jnp.any(load.velocity != 0, axis=1, keepdims=True)
    resting = clamped & ~moving
    reactions = [jnp.sum(jnp.where(moving, force, 0.0), axis=0), jnp.sum(jnp.where(resting, force, 0.0), axis=0)]
    if model.walls:
        reactions = [*walls, *reactions]
    record = {"reaction": jnp.stack(reactions), "vmax": jnp.max(jnp.abs(v)), "time": t}
    new = dataclasses.replace(new, velocities=v, omegas=w, force=force, moment=moment, spring=spring)
    if broken is not None:
        # bonds that broke in this step: their mode and time; the counts so far (tensile, shear) are recorded
        mode = jnp.where(state.broken > 0, state.broken, broken)
        new = dataclasses.replace(new, intact=intact, broken=mode,
                                  broken_time=jnp.where((broken > 0) & (state.broken == 0), t, state.broken_time))
        record["broken"] = jnp.stack([jnp.sum(mode == 1), jnp.sum(mode == 2)]).astype(jnp.int32)
    return (new, record) if near is None else (new, record, near)


@setup_jit
def _precompute(model, params):
    return model.precompute(params)


@functools.partial(jax.jit, static_argnames=("n_steps", "near_slots"))
def _run_chunk(model, params, load, state, dt, alpha, origin, n_steps, margin=None, near_slots=None, limit=None,
               forced=None):
    # ``params`` comes precomputed (stiffnesses and strengths, once per run, not per step): its structure is the
    # same whatever entries the caller's dict had, so the chunk compiles once per model. With Hertz contacts and a
    # ``margin``, the steps carry the pairs within reach (``near_slots`` of them at most; found at the chunk's
    # start, again when stale) and hand their springs back to the state at its end. With a candidate list built on
    # the host (:class:`jaxbpm.neighbors.HostList`) the chunk runs at most ``limit`` steps and stops before the step
    # that would make the list stale; ``done`` says how many ran (the records after them are zeros); its first
    # ``forced`` steps run unchecked (a list built where the next step takes the particles).
    near_overflow, near_pairs, near_found = jnp.zeros((), bool), jnp.zeros((), jnp.int32), jnp.zeros((), jnp.int32)
    near = None
    if margin is not None and model.contacts and model.contact_law != "cohesive":
        def advance(carry):
            s, rec, near = step(model, params, load, carry[0], dt, alpha, origin, near=carry[1], margin=margin)
            return (s, near), rec

        near = near_build(model, state.positions, state.nbrs, state.spring, margin, near_slots)
    else:
        def advance(carry):
            s, rec = step(model, params, load, carry[0], dt, alpha, origin)
            return (s, None), rec

    rebuilds = jnp.zeros((), jnp.int32)
    if model.contacts and isinstance(state.nbrs, HostList):
        (state, near), records, done = _run_until_stale(model, load, advance, (state, near), dt, alpha, n_steps,
                                                        limit, forced)
    elif model.contacts:
        # jax-md's list is built again inside a step when a particle has moved half the skin: count those steps
        def counted(c, _):
            carry, k = advance(c[0]), c[1]
            moved = jnp.any(carry[0][0].nbrs.reference_position != c[0][0].nbrs.reference_position)
            return (carry[0], k + moved.astype(jnp.int32)), carry[1]

        ((state, near), rebuilds), records = jax.lax.scan(counted, ((state, near), rebuilds), None, length=n_steps)
        done = jnp.asarray(n_steps, jnp.int32)
    else:
        (state, near), records = jax.lax.scan(lambda c, _: advance(c), (state, near), None, length=n_steps)
        done = jnp.asarray(n_steps, jnp.int32)
    if near is not None:
        state = dataclasses.replace(state, spring=near_springs(near, state.spring.shape[0]))
        near_overflow, near_pairs, near_found = near.overflow, near.count, near.found
    overflow = jnp.stack([jnp.asarray(state.nbrs.did_buffer_overflow if model.contacts else False).astype(bool),
                          near_overflow.astype(bool)])
    finite = jnp.all(jnp.isfinite(state.positions))
    # steps run; pairs within reach: most, refound; candidate list built again inside the steps (jax-md's)
    counts = jnp.stack([done, near_pairs, near_found, rebuilds]).astype(jnp.int32)
    return state, records, overflow, finite, jnp.min(state.positions, axis=0), jnp.max(state.positions, axis=0), counts


def _run_until_stale(model, load, advance, carry, dt, alpha, n_steps, limit, forced=None):
    """``advance`` (``carry -> (carry, record)``, ``carry[0]`` the state) at most ``min(n_steps, limit)`` times,
    stopping before the step whose drift would take a particle past the host list's threshold (not checked for the
    first ``forced`` steps). Returns the carry, the records ``[n_steps, ...]`` (zeros after the last step run) and
    the number of steps run."""
    template = jax.eval_shape(lambda c: advance(c)[1], carry)
    records = jax.tree.map(lambda a: jnp.zeros((n_steps,) + a.shape, a.dtype), template)
    limit = n_steps if limit is None else jnp.minimum(limit, n_steps)
    forced = 0 if forced is None else forced

    def going(c):
        k, (s, _), _ = c
        return (k < limit) & ((k < forced) | ~stale(s.nbrs, _drift(model, load, s, dt, alpha)[1]))

    def body(c):
        k, carry, records = c
        carry, rec = advance(carry)
        return k + 1, carry, jax.tree.map(lambda r, a: r.at[k].set(a), records, rec)

    done, carry, records = jax.lax.while_loop(going, body, (jnp.zeros((), jnp.int32), carry, records))
    return carry, records, done


@jax.jit
def _ahead(model, load, state, dt, alpha):
    """The positions the next step's drift takes the particles to."""
    return _drift(model, load, state, dt, alpha)[1]


def pad_loading(load: Loading, n: int) -> Loading:
    """``load`` for a model padded to ``n`` particles: the extra ones clamped at rest (host work, no program)."""
    clamped, velocity = np.asarray(load.clamped), np.asarray(load.velocity)
    extra = n - clamped.shape[0]
    if extra < 0:
        raise ValueError(f"cannot pad a loading of {clamped.shape[0]} particles to {n}")
    return dataclasses.replace(
        load, clamped=jax.device_put(np.concatenate([clamped, np.ones(extra, bool)])),
        velocity=jax.device_put(np.concatenate([velocity, np.zeros((extra, 3), velocity.dtype)])))


def unpad_state(state: DEMState, n: int, n_bonds: int) -> DEMState:
    """The state of the first ``n`` particles and ``n_bonds`` bonds of a padded run (sliced on the host: no
    program is compiled for the sample's own sizes)."""
    def cut(x, size):
        return None if x is None else jax.device_put(np.asarray(x)[:size])

    return dataclasses.replace(
        state, positions=cut(state.positions, n), velocities=cut(state.velocities, n),
        orientations=cut(state.orientations, n), omegas=cut(state.omegas, n), force=cut(state.force, n),
        moment=cut(state.moment, n), intact=cut(state.intact, n_bonds), broken=cut(state.broken, n_bonds),
        broken_time=cut(state.broken_time, n_bonds))


def kinetic_energy(model: Model, state: DEMState):
    """Translational plus rotational kinetic energy [J]."""
    ke = 0.5 * jnp.sum(model.mass[:, None] * state.velocities**2)
    if model.rotations:
        ke = ke + 0.5 * jnp.sum(model.inertia[:, None] * state.omegas**2)
    return ke


def potential_energy(model: Model, params, state: DEMState):
    """Elastic energy stored in the bonds [J] (contacts and walls not included)."""
    from jaxbpm.physics.bond import bond_energy

    return bond_energy(state.positions, state.orientations if model.rotations else None, model.bonds, model.r0,
                       model.stiffness(params), state.intact)


def critical_time_step(model: Model, params, *, contact_overlap: float = 0.01, iterations: int = 60) -> float:
    """Critical time step 2 / omega_max of the linearised model at rest [s].

    omega_max^2 of the bonds is found by power iteration on ``M^-1/2 K M^-1/2`` (K v from the Jacobians of the bond
    law at rest, translations and rotations, 81 numbers per bond; one jitted program), from a pseudo-random start
    whose row for particle i depends on i alone, with a Rayleigh quotient summed exactly on the host: particles that
    no bond with stiffness joins (e.g. the padding of a size class) leave the estimate unchanged to the last bit.
    Contacts and walls add ``z k_c / m`` with the Hertz (or cohesive-law) stiffness at an overlap of
    ``contact_overlap`` times the smallest radius (z = 12 neighbours, 1 wall).
    """
    omega2 = 0.0
    if model.bonds.shape[0]:
        v0 = jax.device_put(_start_vector(model.n, model.positions0.dtype))
        v, kv = _bond_omega2(model, params, v0, iterations=iterations)
        v, kv = np.asarray(v, np.float64).ravel(), np.asarray(kv, np.float64).ravel()
        # the Rayleigh quotient, exactly rounded sums: the same whatever zeros (padding) the vectors hold; it
        # approaches omega_max^2 from below: a 2 % margin
        omega2 = 1.02 * math.fsum(v * kv) / math.fsum(v * v) if np.all(np.isfinite(v)) else 0.0  # (no stiffness)
    r_min = float(np.min(np.asarray(model.radii)))
    m_min = float(np.min(np.asarray(model.mass)))
    delta = contact_overlap * r_min
    if model.contacts and model.contact_law == "cohesive":
        # linear spring-dashpot: k_N at the reference overlap; the dashpot lowers the stable step of an explicit
        # scheme by sqrt(1 + gamma^2) - gamma
        from jaxbpm.physics import cohesive as cohesive_mod

        c = model.cohesive
        k_c = float(cohesive_mod.normal_stiffness(r_min, r_min, delta, float(c.E)))
        gamma = float(cohesive_mod.restitution_damping(float(c.restitution)))
        omega2 += 12 * k_c / m_min / (np.sqrt(1.0 + gamma**2) - gamma) ** 2
    elif model.contacts:
        k_c = 2.0 * float(model.contact.E_star) * np.sqrt(0.5 * r_min * delta)
        omega2 += 12 * k_c / m_min
    if model.walls == "hertz":
        omega2 += 2.0 * float(model.wall_stiffness) * np.sqrt(r_min * delta) / m_min
    elif model.walls == "linear":
        omega2 += float(model.wall_stiffness) / m_min
    if omega2 <= 0:
        raise InstabilityError("cannot estimate a time step: the model has no stiffness (no bonds, contacts or walls)")
    return 2.0 / np.sqrt(omega2)


def _start_vector(n: int, dtype) -> np.ndarray:
    """``[n, 6]`` pseudo-random numbers in [-1, 1) made on the host, entry (i, k) a hash (splitmix64) of 6 i + k alone:
    the start of the power iteration, the same for a particle whatever the number of particles after it."""
    z = np.arange(6 * n, dtype=np.uint64) + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return ((z >> np.uint64(11)).astype(np.float64) * 2.0**-52 - 1.0).reshape(n, 6).astype(dtype)


@setup_jit(static_argnames=("iterations",))
def _bond_omega2(model: Model, params, v0, iterations):
    """The last iterate ``v`` of the power iteration on ``M^-1/2 K M^-1/2`` and ``M^-1/2 K M^-1/2 v``, ``[n, 6]``."""
    from jaxbpm.physics.bond import bond_law

    n, dtype = model.n, model.positions0.dtype
    k = model.stiffness(params)

    def jacobian(r0, kn, kt, ktw, kb):
        # one bond at rest: (f_i, m_i, m_j) against (d = x_j - x_i, the rotation vectors of i and j); a rotation
        # vector w turns the identity by the quaternion (1, w / 2) to first order
        def law(z):
            one = jnp.ones(1, dtype)
            q_i, q_j = jnp.concatenate([one, 0.5 * z[3:6]]), jnp.concatenate([one, 0.5 * z[6:]])
            out = bond_law(r0 + z[:3], r0, q_i, q_j, kn, kt, ktw, kb)
            return jnp.concatenate([out.f_i, out.m_i, out.m_j])

        return jax.jacfwd(law)(jnp.zeros(9, dtype))

    # the Jacobians once ([nb, 9, 9]: the same bond law, linearised), then each iteration is a gather, a small
    # product and a scatter (a Jacobian-vector product of the whole force function costs ten DEM steps on CPU)
    jac = jax.vmap(jacobian)(model.r0, k.kn, k.kt, k.ktw, k.kb)
    if not model.rotations:
        jac = jac[:, :3, :3]
    i, j = model.bonds[:, 0], model.bonds[:, 1]
    scale = jnp.concatenate([jnp.broadcast_to(model.mass[:, None], (n, 3)),
                             jnp.broadcast_to(model.inertia[:, None], (n, 3))], axis=1) ** -0.5

    def apply(v):
        u = scale * v
        u_i, u_j = u[i], u[j]
        if model.rotations:
            z = jnp.concatenate([u_j[:, :3] - u_i[:, :3], u_i[:, 3:], u_j[:, 3:]], axis=1)
            out = jnp.einsum("bkl,bl->bk", jac, z)
            rows = jnp.concatenate([out[:, :6], jnp.concatenate([-out[:, :3], out[:, 6:]], axis=1)])
        else:
            f = jnp.einsum("bkl,bl->bk", jac, u_j[:, :3] - u_i[:, :3])
            rows = jnp.concatenate([jnp.concatenate([f, jnp.zeros_like(f)], axis=1),
                                    jnp.concatenate([-f, jnp.zeros_like(f)], axis=1)])
        return -scale * jax.ops.segment_sum(rows, jnp.concatenate([i, j]), n)

    # particles without bond stiffness (loose ones, padding) start at rest: K is zero there, and leaving them out of
    # the start makes every iterate, normalised by its largest entry (a maximum, in any order), the same to the bit
    # with or without padding
    per_bond = k.kn + k.kt + k.ktw + k.kb
    stiff = jax.ops.segment_sum(jnp.concatenate([per_bond, per_bond]), jnp.concatenate([i, j]), n) > 0
    v0 = jnp.where(stiff[:, None], v0, 0.0)
    if not model.rotations:
        v0 = v0.at[:, 3:].set(0.0)

    def body(v, _):
        w = apply(v)
        return w / jnp.max(jnp.abs(w)), None

    v, _ = jax.lax.scan(body, v0 / jnp.max(jnp.abs(v0)), None, length=iterations)
    return v, apply(v)


def simulate(model: Model, params, load: Loading, *, dt: float, n_steps: int, alpha: float = 0.0,
             chunk: int = 1000, neighbors: NeighborSettings | None = None, progress: bool | Callable = False,
             dt_crit: float | None = None, state: DEMState | None = None,
             on_chunk: Callable[[int, DEMState, dict], Any] | None = None):
    """Run ``n_steps`` DEM steps (rounded up to whole chunks). Returns ``(final_state, records, stats)``.

    records: dict of per-step arrays (``reaction [steps, W+2, 3]``, ``vmax [steps]``, ``time [steps]``; with
    breakage ``broken [steps, 2]``, the cumulative tensile and shear counts).
    stats: ``wall_time`` = ``setup_time`` (neighbour list, initial state) + ``compile_time`` (tracing, compiling or
    reading from the persistent cache the programs the run builds, see :func:`jaxbpm._compile.compile_clock`; 0 when
    this process had them all) + ``run_time``
    (the rest: the chunks, the checks between them, records and callbacks); ``kernel_time`` (the chunks alone),
    steps, steps per second (the median chunk), number of neighbour-list re-allocations; with contacts the
    candidate list's capacity (``contact_capacity``), the most pairs within reach (``contacts_within_reach``) and
    their slots (``contact_slots``: sized to them at the start, grown and the chunk run again when they overflow),
    where the list is built (``contact_list``: ``"host"`` or ``"jax-md"``), how often it was built again
    (``contact_rebuilds``: by the host between steps, or by jax-md inside them; chunks run again included) and how often the pairs within reach were found (``contacts_refound``: passes
    over the candidate list, at each chunk's start and when stale; chunks run again included).
    progress: ``True`` prints progress (:func:`progress_printer`); a callable is called as
    ``progress(steps_done, steps_total, elapsed_s)`` after every chunk.
    on_chunk: called as ``on_chunk(steps_done, state, chunk_records)`` after every chunk (records of that chunk
    only, NumPy arrays), e.g. to write them to a file as they arrive.
    Raises :class:`InstabilityError` on NaN or a runaway (a particle moving over a quarter of the smallest radius in
    one step), naming the time step and the critical one. A ``KeyboardInterrupt`` (Ctrl-C, or raised by a callback)
    raises :class:`~jaxbpm.errors.SimulationInterrupted` carrying the state, records and stats of the chunks
    completed so far (a chunk in flight is dropped).
    """
    with compile_clock() as compiling:
        return _simulate(model, params, load, dt, n_steps, alpha, chunk, neighbors, progress, dt_crit, state,
                         on_chunk, compiling)


def _simulate(model, params, load, dt, n_steps, alpha, chunk, neighbors, progress, dt_crit, state, on_chunk,
              compiling):
    t0 = time.perf_counter()
    dtype = model.positions0.dtype
    r_min = float(np.min(np.asarray(model.radii)))
    nb_owner, origin, margin, near_slots = None, jax.device_put(np.zeros(3, dtype)), None, None
    clock = {"t0": t0, "compiling": compiling, "kernel": []}
    if model.contacts:
        settings = neighbors or NeighborSettings(skin=0.5 * r_min)
        nb_owner = neighbors_owner(model, settings, model.positions0)
        nbrs = nb_owner.allocate(model.positions0 if state is None else state.positions)
        if NEAR_MARGIN is not None and model.contact_law != "cohesive":
            margin = NEAR_MARGIN * settings.skin
            within = near_count(model, model.positions0 if state is None else state.positions, nbrs, margin)
            # the bonded pairs' contacts run on the bond list; the slots hold the others, which a breaking sample
            # makes more of as it goes (an 8k cylinder to failure: 2.7 % of its bond count): room for 1/32 of the
            # bonds from the start, so that few chunks run again (and compile again) with more
            margin = jnp.asarray(margin, dtype)
            near_slots = near_size(max(within, model.bonds.shape[0] // 32), nbrs.idx.shape[1])
            clock["contact_slots"], clock["near_count"] = near_slots, within
        origin = jnp.asarray(nb_owner.origin, dtype)
        if state is not None and state.nbrs is not None:
            spring, cohesion = _remap_history(state.nbrs.idx.T, nbrs.idx.T, model.n, state.spring, state.cohesion)
            state = dataclasses.replace(state, nbrs=nbrs, spring=spring, cohesion=cohesion)
        elif state is not None:
            state = dataclasses.replace(state, nbrs=nbrs, spring=jnp.zeros((nbrs.idx.shape[1], 3), dtype))
            if model.contact_law == "cohesive":
                state = dataclasses.replace(state, cohesion=initial_cohesion(model, state))
        if state is not None:
            state = _with_bond_springs(model, state)
    else:
        nbrs = None
    if state is None:
        state, pre = _start(model, params, load, nbrs)
    else:
        pre = _precompute(model, params)
    jax.block_until_ready((state, pre))
    _interrupt.check()  # (a Ctrl-C the setup's garbage collection swallowed stops here: nothing has run yet)
    clock["setup_compile"] = compiling.seconds
    chunk = max(1, min(chunk, n_steps))
    n_chunks = -(-n_steps // chunk)  # every chunk has the same length, so the chunk function compiles once
    records, reallocs, stalled = [], 0, 0
    crit = f"{dt_crit:.4g} s" if dt_crit is not None else "unknown"  # for the error messages
    report = _progress_fn(progress)
    done = state  # the state after the last completed chunk
    # a candidate list built on the host: a chunk stops before the list goes stale, the list is built again and the
    # chunk goes on from there (``left`` steps; the records and kernel time of its parts so far in ``parts``)
    host = model.contacts and isinstance(state.nbrs, HostList)
    left, parts, forced = chunk, [], 0
    clock["loop"] = time.perf_counter()
    try:
        while len(records) < n_chunks:
            _interrupt.check()
            tc, compiled = time.perf_counter(), compiling.seconds
            new, rec, overflow, finite, pmin, pmax, counts = _run_chunk(
                model, pre, load, state, dt, alpha, origin, chunk, margin, near_slots,
                jnp.asarray(left, jnp.int32) if host else None, jnp.asarray(forced, jnp.int32) if host else None)
            jax.block_until_ready(new.positions)
            elapsed = time.perf_counter() - tc - (compiling.seconds - compiled)  # (less a new program's compilation)
            rec, (ran, within, refound, rebuilt) = jax.device_get(rec), (int(c) for c in np.asarray(counts))
            clock["rebuilds"] = clock.get("rebuilds", 0) + rebuilt
            if near_slots is not None:
                clock["near_count"] = max(clock["near_count"], within)
                clock["near_found"] = clock.get("near_found", 0) + refound
            if host:
                rec = {k: r[:ran] for k, r in rec.items()}
                if ran == 0:
                    new = state  # the first step would go stale: the list is built again below
            # instability first: a blown-up chunk also overflows the neighbour buffer, and re-allocating for it
            # would only run it again (and again)
            vmax = float(np.max(rec["vmax"])) if rec["vmax"].size else 0.0
            if not np.isfinite(vmax) or not bool(finite) or vmax * dt > 0.25 * r_min:
                raise InstabilityError(
                    f"DEM run became unstable within steps {len(records) * chunk}..{(len(records) + 1) * chunk} "
                    f"(non-finite or runaway motion, max speed {vmax:.3g} m/s): time step dt = {dt:.4g} s, critical "
                    f"time step estimate = {crit}. Use a smaller time step (or a smaller safety factor).")
            overflow, near_overflow = (bool(o) for o in np.asarray(overflow))
            if near_overflow and not overflow:
                # more pairs within reach than slots: the chunk again with more (a new size compiles it again)
                near_slots = clock["contact_slots"] = min(max(near_size(within, state.nbrs.idx.shape[1]),
                                                              2 * near_slots),
                                                          state.nbrs.idx.shape[1])
                continue
            if model.contacts and (overflow or not nb_owner.inside(pmin, pmax)):
                # re-allocate from the chunk's start and run it again: no contact is ever dropped
                reallocs += 1
                stalled += 1
                if stalled > 4:
                    raise InstabilityError(
                        f"DEM run stalled within steps {len(records) * chunk}..{(len(records) + 1) * chunk}: the "
                        f"neighbour list was re-allocated {stalled} times for the same chunk (particles moving too "
                        f"far, too fast: max speed {vmax:.3g} m/s) with time step dt = {dt:.4g} s, critical time "
                        f"step estimate = {crit}. Use a smaller time step (or a smaller safety factor).")
                extra = int(np.ceil(0.5 * state.nbrs.idx.shape[1] / model.n)) if overflow else 0
                state = done = _with_new_list(model, nb_owner, state, extra_per_particle=extra, reach=(pmin, pmax))
                origin = jnp.asarray(nb_owner.origin, dtype)
                if near_slots is not None:
                    near_slots = clock["contact_slots"] = min(near_slots, state.nbrs.idx.shape[1])
                continue  # (a new buffer size compiles the chunk again)
            if host and ran < left:
                # the list would go stale in the next step: build it again where that step takes the particles (as
                # jax-md's list is built again inside the step) and go on with that step unchecked: a particle moving
                # more than half the skin in every step (a skin set small) costs a rebuild a step, not the run
                parts.append((rec, elapsed))
                left -= ran
                state = _with_new_list(model, nb_owner, new, at=_ahead(model, load, new, dt, alpha))
                clock["rebuilds"] = clock.get("rebuilds", 0) + 1
                if near_slots is not None:
                    near_slots = clock["contact_slots"] = min(near_slots, state.nbrs.idx.shape[1])
                forced = 1
                continue
            if parts:
                parts.append((rec, elapsed))
                rec = {k: np.concatenate([p[0][k] for p in parts]) for k in rec}
                elapsed = sum(p[1] for p in parts)
            left, parts, forced = chunk, [], 0
            clock["kernel"].append(elapsed)
            stalled = 0
            state = done = new
            records.append(rec)
            if on_chunk is not None:
                on_chunk(len(records) * chunk, state, rec)
            report(len(records) * chunk, n_chunks * chunk, time.perf_counter() - t0)
    except InstabilityError as err:
        # what was computed before the blow-up travels with the error (jaxbpm.solve makes a Result of it)
        out, stats = _collect(model, done, records, chunk, reallocs, clock)
        stats.update(unstable=True, steps_planned=n_chunks * chunk)
        err.state, err.records, err.stats = done, out, stats
        raise
    except KeyboardInterrupt as err:
        _interrupt.clear()
        out, stats = _collect(model, done, records, chunk, reallocs, clock)
        stats.update(interrupted=True, steps_planned=n_chunks * chunk)
        raise SimulationInterrupted(done, out, stats) from err
    out, stats = _collect(model, state, records, chunk, reallocs, clock)
    return state, out, stats


def _with_new_list(model, nb_owner, state, at=None, **allocate):
    """``state`` with a candidate list built again at its positions (or ``at``; ``allocate``: the owner's
    ``allocate`` options) and its per-contact history (springs, cohesion) carried over to the new list's layout."""
    nbrs = nb_owner.allocate(state.positions if at is None else at, **allocate)
    spring, cohesion = _remap_history(state.nbrs.idx.T, nbrs.idx.T, model.n, state.spring, state.cohesion)
    return dataclasses.replace(state, nbrs=nbrs, spring=spring, cohesion=cohesion)


def _collect(model, state, records, chunk, reallocs, clock):
    """The records of the completed chunks, concatenated, and the run's statistics (see :func:`simulate`)."""
    kernel = clock["kernel"]
    per_chunk = float(np.median(kernel)) if kernel else float("nan")
    out = {k: np.concatenate([r[k] for r in records]) for k in records[0]} if records else {}
    wall, compile_time = time.perf_counter() - clock["t0"], clock["compiling"].seconds
    setup = clock["loop"] - clock["t0"] - clock["setup_compile"]
    stats = {"setup_time": setup, "compile_time": compile_time, "run_time": wall - setup - compile_time,
             "wall_time": wall, "kernel_time": float(np.sum(kernel)), "steps": len(records) * chunk,
             "steps_per_second": chunk / per_chunk, "reallocations": reallocs,
             "contact_capacity": int(state.nbrs.idx.shape[1]) if model.contacts else 0,
             "contact_slots": clock.get("contact_slots", 0), "contacts_within_reach": clock.get("near_count", 0),
             "contact_rebuilds": clock.get("rebuilds", 0), "contacts_refound": clock.get("near_found", 0),
             "contact_list": ("host" if isinstance(state.nbrs, HostList) else "jax-md") if model.contacts else None}
    return out, stats


def progress_printer(strain_per_step: float | None = None):
    """A progress callback for :func:`simulate`: a bar of DEM steps on stderr (:mod:`jaxbpm.progress`) with the
    simulated strain, when the strain per step is given."""
    from jaxbpm.progress import bar

    shown = []

    def report(done, total, elapsed):
        if not shown:
            shown.append(bar("DEM steps", total=total))
        b = shown[0]
        b.update(done - b.n)
        if strain_per_step is not None:
            b.set_postfix_str(f"strain {100 * strain_per_step * done:.4f} %", refresh=False)
        if done >= total:
            b.close()

    return report


def _progress_fn(progress):
    if callable(progress):
        return progress
    return progress_printer() if progress else (lambda *a: None)
