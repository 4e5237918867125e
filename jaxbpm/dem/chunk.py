"""A chunk of DEM steps as one compiled program: a ``while_loop`` of :func:`jaxbpm.dem.stepper.step` that ends after
its steps, before a host-built candidate list goes stale, or after the step where the run stopped past its peak
(:mod:`jaxbpm.dem.peak`), with what the checks between chunks need (overflow flags, finiteness, the particles'
extent, counts)."""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp

from jaxbpm.dem.neighbors import HostList, near_build, near_springs, stale
from jaxbpm.dem.peak import _track
from jaxbpm.dem.stepper import _drift, step

__all__ = []


@functools.partial(jax.jit, static_argnames=("n_steps", "near_slots"))
def _run_chunk(model, params, load, state, dt, damping, origin, n_steps, margin=None, near_slots=None, limit=None,
               forced=None, stop=None, track=None):
    # ``params`` comes precomputed (stiffnesses and strengths, once per run, not per step): its structure is the
    # same whatever entries the caller's dict had, so the chunk compiles once per model. With Hertz contacts and a
    # ``margin``, the steps carry the pairs within reach (``near_slots`` of them at most; found at the chunk's
    # start, again when stale) and hand their springs back to the state at its end. With a candidate list built on
    # the host (:class:`jaxbpm.dem.neighbors.HostList`) the chunk runs at most ``limit`` steps and stops before the step
    # that would make the list stale; its first ``forced`` steps run unchecked (a list built where the next step takes
    # the particles). With a stop after the peak (``stop``, :class:`jaxbpm.dem.peak.PeakStop`, and its tracker
    # ``track``) the chunk ends after the step where the run stopped (at once when it had stopped before). ``done``
    # says how many steps ran (the records after them are zeros).
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

    host = model.contacts and isinstance(state.nbrs, HostList)
    going = None
    if host:
        forced = 0 if forced is None else forced
        going = lambda k, s: (k < forced) | ~stale(s.nbrs, _drift(model, load, s, dt, damping)[1])  # noqa: E731
    (state, near), records, done, rebuilds, track = _steps(advance, (state, near), n_steps, limit if host else None,
                                                           going, stop, track, counted=model.contacts and not host)
    if near is not None:
        state = dataclasses.replace(state, spring=near_springs(near, state.spring.shape[0]))
        near_overflow, near_pairs, near_found = near.overflow, near.count, near.found
    overflow = jnp.stack([jnp.asarray(state.nbrs.did_buffer_overflow if model.contacts else False).astype(bool),
                          near_overflow.astype(bool)])
    finite = jnp.all(jnp.isfinite(state.positions))
    # steps run; pairs within reach: most, refound; candidate list built again inside the steps (jax-md's)
    counts = jnp.stack([done, near_pairs, near_found, rebuilds]).astype(jnp.int32)
    extent = jnp.min(state.positions, axis=0), jnp.max(state.positions, axis=0)
    return state, records, overflow, finite, *extent, counts, track


def _steps(advance, carry, n_steps, limit, going, stop, track, counted):
    """``advance`` (``carry -> (carry, record)``, ``carry[0]`` the state) at most ``min(n_steps, limit)`` times, before
    each step asking ``going(k, state)`` (when given) and whether the tracker ``track`` has stopped (when ``stop`` is
    given). Returns the carry, the records ``[n_steps, ...]`` (zeros after the last step run), the number of steps
    run, how often jax-md's list was built again inside them (``counted``; else 0) and the tracker."""
    template = jax.eval_shape(lambda c: advance(c)[1], carry)
    records = jax.tree.map(lambda a: jnp.zeros((n_steps,) + a.shape, a.dtype), template)
    limit = n_steps if limit is None else jnp.minimum(limit, n_steps)
    tracking = stop is not None

    def more(c):
        k, (s, _), _, _, t = c
        ok = k < limit
        if going is not None:
            ok = ok & going(k, s)
        return ok & ~t.stopped if tracking else ok

    def body(c):
        k, old, records, rebuilds, t = c
        new, rec = advance(old)
        if counted:  # jax-md's list is built again inside a step when a particle has moved half the skin
            moved = jnp.any(new[0].nbrs.reference_position != old[0].nbrs.reference_position)
            rebuilds = rebuilds + moved.astype(jnp.int32)
        if tracking:
            t = _track(t, rec, stop)
        return k + 1, new, jax.tree.map(lambda r, a: r.at[k].set(a), records, rec), rebuilds, t

    zero = jnp.zeros((), jnp.int32)
    done, carry, records, rebuilds, track = jax.lax.while_loop(more, body, (zero, carry, records, zero, track))
    return carry, records, done, rebuilds, track


@jax.jit
def _ahead(model, load, state, dt, damping):
    """The positions the next step's drift takes the particles to."""
    return _drift(model, load, state, dt, damping)[1]
