"""The DEM stepper: a pair of pure functions on a :class:`~jaxbpm.dem.state.DEMState`, :func:`init_state` and
:func:`step` (velocity Verlet with rotations and local damping).

Per step, time step dt::

    v   += dt/2 (F + F_d) / m ,   w += dt/2 (M + M_d) / I        (half kick)
    x   += dt v ,                 q  = exp(dt w) q                (drift; clamped particles follow their motion;
                                                               a disc's angle: theta += dt w)
    F, M = forces(x, q)                                           (one force evaluation per step)
    v   += dt/2 (F + F_d) / m ,   w += dt/2 (M + M_d) / I        (half kick)

Damping ``F_d`` is local non-viscous damping as in PFC and MUSEN: ``F_d = -damping |F| sign(v)`` per component (and
the same for moments), with ``v`` the velocity the undamped half kick gives (``v + dt F / 2m``, Yade's form), so that
a particle starting from rest does not take the sign of a round-off. It removes kinetic energy where a particle accelerates, without slowing a uniform motion, which
is what quasi-static loading needs; ``damping = 0`` gives undamped, energy-conserving dynamics.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from jaxbpm._compile import setup_jit
from jaxbpm.dem.forces import _contact_step, _evaluate, _near_step, initial_cohesion
from jaxbpm.dem.neighbors import _jax_md_context, _Near, _remap_history, _remap_springs, HostList
from jaxbpm.dem.state import DEMState
from jaxbpm.physics import rotation
from jaxbpm.physics.loading import Loading
from jaxbpm.physics.model import Model

__all__ = ["init_state", "step"]


def init_state(model: Model, params, load: Loading, nbrs=None) -> DEMState:
    """The reference configuration at rest, with the forces there (one jitted program).

    Args:
        model: the run's model.
        params: the bond and contact parameters.
        load: the loading (clamped particles start with their prescribed velocities).
        nbrs: the contact candidate list (a model with contacts), else ``None``.

    Returns:
        The initial state.
    """
    return _start(model, params, load, nbrs)[0]


@setup_jit
def _start(model: Model, params, load: Loading, nbrs):
    """The initial state (see :func:`init_state`) and the per-run constants (:meth:`Model.precompute`)."""
    return _initial_state(model, params, load, nbrs), model.precompute(params)


def _initial_state(model: Model, params, load: Loading, nbrs) -> DEMState:
    n, dtype = model.n, model.positions0.dtype
    capacity = nbrs.idx.shape[1] if nbrs is not None else 0
    flat = model.dim == 2  # discs: an angle and a spin about z each
    state = DEMState(
        positions=model.positions0,
        velocities=jnp.where(load.clamped[:, None], load.velocity, 0.0),
        orientations=jnp.zeros((n, 1), dtype) if flat else rotation.identity(n, dtype),
        omegas=jnp.zeros((n, 1 if flat else 3), dtype),
        force=jnp.zeros((n, model.dim), dtype),
        moment=jnp.zeros((n, 1 if flat else 3), dtype),
        intact=jnp.ones(model.bonds.shape[0], bool),
        spring=jnp.zeros((capacity, model.dim), dtype),
        nbrs=nbrs,
        time=jnp.zeros((), dtype),
        broken=jnp.zeros(model.bonds.shape[0], jnp.int8),
        broken_time=jnp.full(model.bonds.shape[0], jnp.nan, dtype),
    )
    if model.contacts and model.contact_law == "cohesive":
        state = dataclasses.replace(state, cohesion=initial_cohesion(model, state))
    state = _with_bond_springs(model, state)
    zeros = jnp.zeros((capacity, model.dim), dtype)
    force, moment, _ = _evaluate(model, params, state, load, zeros, zeros)
    return dataclasses.replace(state, force=force, moment=moment)


def _with_bond_springs(model: Model, state: DEMState) -> DEMState:
    """``state`` with empty springs for the contacts of the bonded pairs (Hertz contacts; see :func:`_near_forces`)
    where it has none."""
    if not model.contacts or model.contact_law == "cohesive" or state.bond_spring is not None:
        return state
    springs = jnp.zeros((model.bonds.shape[0], model.dim), state.positions.dtype)
    return dataclasses.replace(state, bond_spring=springs)




def _damped(f, v, damping, kick):
    """``f + F_d``, ``F_d = -damping |f| sign(v + kick f)``: the sign of the velocity the undamped half kick
    (``kick = dt / 2m``) would give, as Yade's integrator takes it. A particle at rest, or moving at a speed of the
    order of round-off, is damped by the force that starts it, whatever the last bit of its velocity: the run does not
    depend on round-off (a translated or reordered sample gives the same answer)."""
    return f - damping * jnp.abs(f) * jnp.sign(v + kick * f)


def _drift(model: Model, load: Loading, state: DEMState, dt, damping):
    """The first half kick and the drift of :func:`step`: the half-step velocities, the new positions and time."""
    clamped = load.clamped[:, None]
    kick = 0.5 * dt / model.mass[:, None]
    v = state.velocities + kick * _damped(state.force, state.velocities, damping, kick)
    v = jnp.where(clamped, load.velocity, v)
    t = state.time + dt
    x = jnp.where(clamped, model.positions0 + t * load.velocity, state.positions + dt * v)
    return v, x, t


def step(model: Model, params, load: Loading, state: DEMState, dt, damping, origin, near: _Near | None = None,
         margin=None):
    """One velocity-Verlet step.

    Args:
        model: the run's model.
        params: the per-run constants (:meth:`~jaxbpm.physics.model.Model.precompute`) or the parameters.
        load: the loading.
        state: the state before the step.
        dt: the time step [s].
        damping: the local damping coefficient (0: undamped).
        origin: ``[3]`` the origin of jax-md's cell-list box (zeros for a list built on the host).
        near: with Hertz contacts, the pairs within ``margin`` of touching (:func:`jaxbpm.dem.neighbors.near_build`):
            the step runs the contact law on those pairs only. Without, every step tests and packs the whole
            candidate list.
        margin: the reach of ``near`` [m].

    Returns:
        ``(new_state, record)``, or ``(new_state, record, near)`` when ``near`` is given. ``record`` holds the
        reaction forces ``reaction [W+2, 3]`` (walls, then the sums of internal forces on the clamped particles
        moving and at rest), the largest speed ``vmax``, the ``time`` and, with breakage, ``broken [2]`` (the
        tensile and shear counts so far).
    """
    clamped = load.clamped[:, None]
    inv_m, inv_i = 1.0 / model.mass[:, None], 1.0 / model.inertia[:, None]
    v, x, t = _drift(model, load, state, dt, damping)
    if model.rotations:
        w = state.omegas + 0.5 * dt * inv_i * _damped(state.moment, state.omegas, damping, 0.5 * dt * inv_i)
        w = jnp.where(clamped, 0.0, w)
        q = state.orientations + dt * w if model.dim == 2 else rotation.integrate(state.orientations, dt * w)
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
    v = v + 0.5 * dt * inv_m * _damped(force, v, damping, 0.5 * dt * inv_m)
    v = jnp.where(clamped, load.velocity, v)
    if model.rotations:
        w = w + 0.5 * dt * inv_i * _damped(moment, w, damping, 0.5 * dt * inv_i)
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
