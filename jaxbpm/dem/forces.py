"""The forces of a DEM step: the Model's forces at a state, with the contact law on the pairs that need it.

Contacts: the candidate list (:mod:`jaxbpm.dem.neighbors`) gives the candidate pairs. The bonded pairs have their
contact law evaluated on the bond list, in one pass with the bond law, their rows scattered to the particles after the
bonds' (superimposed on every bonded pair, or on broken bonds only where bonds replace contacts; springs by bond:
``DEMState.bond_spring``).
The other pairs within reach (surfaces closer than a margin, :class:`jaxbpm.dem.neighbors._Near`) are found again when
a particle has moved half that margin, and each step runs the contact law on those only. Without pairs within reach
(the cohesive law), each step packs the touching candidates into a third of the list when they fit there.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from jaxbpm.dem.neighbors import (_contact_pairs, _Near, _remap_springs, near_apart, near_build, near_springs,
                                  near_stale, pack)
from jaxbpm.dem.state import DEMState
from jaxbpm.physics import contact as contact_mod
from jaxbpm.physics.loading import Loading
from jaxbpm.physics.model import Model

__all__ = ["initial_cohesion"]


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
    touching = valid & (model.radii[i] + model.radii[j] - _length(d) > 0)

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
    bonded = (state.bond_spring, lambda i, j, d, r_i, r_j: _motion(model, state, i, j, d, dt, r_i, r_j), on)
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
    """The contact law on the bonded pairs (on the bond list, in the bond law's pass) and on the other pairs
    within reach (:class:`jaxbpm.dem.neighbors._Near`), found again when stale (the candidate list was rebuilt, a
    particle moved more than ``margin / 2``). Returns the step's forces, moments, wall reactions, intact
    mask and break modes, the pairs within reach (their ``overflow`` set when they did not fit their slots: the chunk
    is then run again with more) and the bonded pairs' new springs."""
    capacity = new.nbrs.idx.shape[1]

    def refresh():
        spring = near_springs(near, capacity)
        spring = jax.lax.cond(rebuilt, lambda: _remap_springs(state.nbrs.idx.T, spring, new.nbrs.idx.T, model.n),
                              lambda: spring)
        # the candidates that are not bonded pairs: the same as before unless the candidate list was built again
        apart = jax.lax.cond(rebuilt, lambda: near_apart(model, new.nbrs), lambda: near.apart)
        found = near_build(model, new.positions, new.nbrs, spring, margin, near.slot.shape[0], apart)
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
    """Cohesion history at the start of a run.

    Args:
        model: a model with the cohesive contact law.
        state: the state, with its candidate list.

    Returns:
        ``[C]``: ``-c_0`` (an initial contact, see :mod:`jaxbpm.physics.cohesive`) for the candidate pairs that
        overlap or whose surface gap is at most the law's ``initial_gap``, 0 for the others.
    """
    pairs, valid = _contact_pairs(model, state.nbrs, state.intact)
    i, j, d = contact_mod.pair_vectors(state.positions, pairs, valid)
    gap = _length(d) - model.radii[i] - model.radii[j]
    c = model.cohesive
    return jnp.where(valid & (gap <= c.initial_gap), -c.c0, 0.0)


def _contact_motion(model: Model, state: DEMState, pairs, valid, dt):
    """Relative displacement in this step and relative velocity of the contact points of the pairs, as ``(x, y, z)``
    (2D: ``(x, y)``) tuples of ``[C]`` arrays: ``v_rel = v_j - v_i - (r_j w_j + r_i w_i) x n``, ``dxi = dt v_rel``."""
    i, j, d = contact_mod.pair_vectors(state.positions, pairs, valid)  # padding has d = (1, 1, 1)
    return _motion(model, state, i, j, d, dt)


def _length(d):
    """``|d|`` of component tuples (two or three)."""
    return jnp.sqrt(sum(c * c for c in d))


def _motion(model: Model, state: DEMState, i, j, d, dt, r_i=None, r_j=None):
    """:func:`_contact_motion` of the pairs ``i, j`` whose vectors are ``d`` (``|d| > 0``) and radii ``r_i, r_j``
    (``None``: gathered here); discs (two components, one rotation each): ``v_rel = v_j - v_i - (r_j w_j + r_i w_i)
    (-n_y, n_x)``."""
    dist = _length(d)
    v_t, w_t = state.velocities.T, state.omegas.T
    r_i, r_j = (model.radii[i], model.radii[j]) if r_i is None else (r_i, r_j)
    s = tuple(r_j * w_t[k][j] + r_i * w_t[k][i] for k in range(w_t.shape[0]))
    if len(d) == 2:
        spin = (-s[0] * d[1], s[0] * d[0])
    else:
        spin = (s[1] * d[2] - s[2] * d[1], s[2] * d[0] - s[0] * d[2], s[0] * d[1] - s[1] * d[0])
    # one division per component, so that XLA computes each component once (see jaxbpm.physics.contact.law_components)
    v_rel = tuple(((v_t[k][j] - v_t[k][i]) * dist - spin[k]) / dist for k in range(len(d)))
    return tuple(dt * c for c in v_rel), v_rel  # the contact law takes component tuples as well as [C, 3] rows
