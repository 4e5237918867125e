"""A chunk of DEM steps as one compiled program: ``lax.scan`` of :func:`jaxbpm.dem.stepper.step` (or a
``while_loop`` that stops before a host-built candidate list goes stale), with what the checks between chunks need
(overflow flags, finiteness, the particles' extent, counts)."""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp

from jaxbpm.dem.neighbors import HostList, near_build, near_springs, stale
from jaxbpm.dem.stepper import _drift, step

__all__ = []


@functools.partial(jax.jit, static_argnames=("n_steps", "near_slots"))
def _run_chunk(model, params, load, state, dt, damping, origin, n_steps, margin=None, near_slots=None, limit=None,
               forced=None):
    # ``params`` comes precomputed (stiffnesses and strengths, once per run, not per step): its structure is the
    # same whatever entries the caller's dict had, so the chunk compiles once per model. With Hertz contacts and a
    # ``margin``, the steps carry the pairs within reach (``near_slots`` of them at most; found at the chunk's
    # start, again when stale) and hand their springs back to the state at its end. With a candidate list built on
    # the host (:class:`jaxbpm.dem.neighbors.HostList`) the chunk runs at most ``limit`` steps and stops before the step
    # that would make the list stale; ``done`` says how many ran (the records after them are zeros); its first
    # ``forced`` steps run unchecked (a list built where the next step takes the particles).
    near_overflow, near_pairs, near_found = jnp.zeros((), bool), jnp.zeros((), jnp.int32), jnp.zeros((), jnp.int32)
    near = None
    if margin is not None and model.contacts and model.contact_law != "cohesive":
        def advance(carry):
            s, rec, near = step(model, params, load, carry[0], dt, damping, origin, near=carry[1], margin=margin)
            return (s, near), rec

        near = near_build(model, state.positions, state.nbrs, state.spring, margin, near_slots)
    else:
        def advance(carry):
            s, rec = step(model, params, load, carry[0], dt, damping, origin)
            return (s, None), rec

    rebuilds = jnp.zeros((), jnp.int32)
    if model.contacts and isinstance(state.nbrs, HostList):
        (state, near), records, done = _run_until_stale(model, load, advance, (state, near), dt, damping, n_steps,
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


def _run_until_stale(model, load, advance, carry, dt, damping, n_steps, limit, forced=None):
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
        return (k < limit) & ((k < forced) | ~stale(s.nbrs, _drift(model, load, s, dt, damping)[1]))

    def body(c):
        k, carry, records = c
        carry, rec = advance(carry)
        return k + 1, carry, jax.tree.map(lambda r, a: r.at[k].set(a), records, rec)

    done, carry, records = jax.lax.while_loop(going, body, (jnp.zeros((), jnp.int32), carry, records))
    return carry, records, done


@jax.jit
def _ahead(model, load, state, dt, damping):
    """The positions the next step's drift takes the particles to."""
    return _drift(model, load, state, dt, damping)[1]
