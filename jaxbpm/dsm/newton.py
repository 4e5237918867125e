"""The nonlinear DSM: Newton-Krylov over load steps from the linear bond solution (contacts, walls), with a
backtracking line search.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm._compile import compile_clock
from jaxbpm.dsm.linear import linear_jit
from jaxbpm.dsm.operator import (
    _contact_product, contact_jacobians, internal_forces, reduced_jacobians, stiffness_product)
from jaxbpm.dsm.preconditioner import _build_preconditioner_jit, _coarse_for, Preconditioner
from jaxbpm.physics import wall as wall_mod
from jaxbpm.physics.model import Model


@dataclasses.dataclass(frozen=True)
class _NewtonSystem:
    """Everything a Newton step needs, as one pytree (the jitted steps below compile once per shape)."""

    model: Model
    params: Any
    free: Any
    pairs: Any           # [C, 2] contact candidates (or None)
    normals: Any         # [W, 3] wall normals (or None)
    moving: Any          # [n] driven clamped particles (layers)
    resting: Any         # [n] fixed clamped particles (layers)
    precond: Preconditioner
    axis: int
    maxiter: int


jax.tree_util.register_dataclass(_NewtonSystem, data_fields=["model", "params", "free", "pairs", "normals", "moving",
                                                             "resting", "precond"],
                                 meta_fields=["axis", "maxiter"])


def _newton_residual(sys: _NewtonSystem, u, wall_points):
    con = None if sys.pairs is None else (sys.pairs, jnp.ones(sys.pairs.shape[0], bool))
    walls = None if sys.normals is None else (wall_points, sys.normals)
    gen, parts = internal_forces(sys.model, sys.params, u, con, walls)
    return jnp.where(sys.free, gen, 0.0), gen, parts


@jax.jit
def _newton_evaluate(sys: _NewtonSystem, u, wall_points):
    """Residual norm, its scale (the external forces: reactions of clamped DOFs and of the walls) and the reaction."""
    r, gen, parts = _newton_residual(sys, u, wall_points)
    scale = jnp.linalg.norm(jnp.where(sys.free, 0.0, gen))
    if sys.normals is not None:
        scale = scale + jnp.linalg.norm(parts["walls"])
        reaction = 0.5 * (parts["walls"][1, sys.axis] - parts["walls"][0, sys.axis])
    else:
        comp = gen[:, sys.axis]
        reaction = 0.5 * (jnp.sum(jnp.where(sys.moving, comp, 0.0)) - jnp.sum(jnp.where(sys.resting, comp, 0.0)))
    scale = scale + jnp.finfo(gen.dtype).tiny
    return jnp.linalg.norm(r), scale, reaction


@jax.jit
def _newton_step(sys: _NewtonSystem, u, wall_points, krylov_tol):
    """The Newton correction: GMRES on the tangent at ``u`` (element by element for bonds and contacts, a jvp for
    walls), right-preconditioned."""
    r = _newton_residual(sys, u, wall_points)[0]
    free = sys.free
    # the tangent at u, element by element: bonds and contacts from their Jacobians at u (batched jvps of the same
    # laws, once per step; XLA on CPU runs a jvp of a pair law inside the Krylov loop several times slower), walls
    # by a jvp
    jac = reduced_jacobians(sys.model, sys.params, u)
    jc = None if sys.pairs is None else contact_jacobians(sys.model, sys.pairs, u)

    def matvec(v):
        vf = jnp.where(free, v, 0.0)
        kv = stiffness_product(sys.model, jac, vf)
        if jc is not None:
            kv = kv + _contact_product(sys.model, sys.pairs, jc, vf)
        if sys.normals is not None:  # walls push on translations only
            m = sys.model
            fw = jax.jvp(lambda x: wall_mod.wall_forces(x, m.radii, wall_points, sys.normals, m.walls,
                                                        m.wall_stiffness)[0],
                         (m.positions0 + u[:, :3],), (vf[:, :3],))[1]
            kv = kv.at[:, :3].add(-fw)
        return jnp.where(free, kv, v)

    # right preconditioning (A M y = r, du = M y): jax's gmres measures a left-preconditioned residual against the
    # unpreconditioned right-hand side, which stops it at once when M carries units (1 / stiffness)
    # on a flat vector: with [n, nd] vectors jax's gmres keeps its Krylov basis as [n, nd, restart + 1] and XLA on
    # CPU transposed the whole basis for the Gram-Schmidt products at every iteration
    shape = r.shape
    y, _ = jax.scipy.sparse.linalg.gmres(lambda y: matvec(sys.precond(y.reshape(shape))).reshape(-1), r.reshape(-1),
                                         tol=krylov_tol, restart=40, maxiter=sys.maxiter, solve_method="batched")
    return jnp.where(free, sys.precond(y.reshape(shape)), 0.0)


def _newton(model, params, free, u_p, pairs, walls, scene, tol, linear_tol, maxiter, newton_maxiter, stiffness_tol,
            driven, delta, load_steps, preconditioner="auto", aggregate_size=None, slip=True):
    """Newton-Krylov with backtracking line search, over ``load_steps`` equal load increments.

    Returns displacement field, per-step displacements and reactions, info, compile and run time.
    """
    model_c = dataclasses.replace(model, contacts=pairs is not None and len(pairs) > 0)
    if model_c.contacts and not slip:
        # no slip (Jarolin & Dosta 2020): the Coulomb limit is lifted for the static solve
        model_c = dataclasses.replace(model_c, contact=model_c.contact._replace(
            friction=jnp.asarray(jnp.inf, model.positions0.dtype)))
    # with slip, the tangential spring of a contact is its whole relative tangential displacement since rest, capped by
    # Coulomb (|F_t| <= mu F_n): path-independent, so one residual function of u, and equal to the DEM's incremental
    # law under monotonic loading that does not turn the contacts' sliding direction
    ax = scene.axis
    uses_walls = walls is not None
    clamped = ~np.asarray(free).any(axis=1)
    wall_base = walls[0] if uses_walls else None
    # the two-level preconditioner from the bonds (contacts only add stiffness); not with walls alone holding the
    # sample along the axis, where the bonds' coarse matrix is singular
    coarse = None if uses_walls else _coarse_for(model, np.asarray(free), preconditioner, aggregate_size)
    precond = _build_preconditioner_jit(model, params, free, None, coarse)
    sys = _NewtonSystem(model=model_c, params=params, free=free,
                        pairs=jnp.asarray(pairs) if model_c.contacts else None,
                        normals=walls[1] if uses_walls else None,
                        moving=jnp.asarray(driven), resting=jnp.asarray(clamped & ~np.asarray(driven)),
                        precond=precond, axis=int(ax), maxiter=int(maxiter or 10))
    fractions = np.arange(1, load_steps + 1) / load_steps

    def walls_at(frac):
        # the top wall (index 1) moves by frac * delta against the axis; wall_base holds it at the full delta
        if not uses_walls:
            return jnp.zeros((0, 3), u_p.dtype)
        shift = jnp.zeros_like(wall_base).at[1, ax].set((1.0 - frac) * delta)
        return wall_base + shift

    tc = time.perf_counter()
    frac0 = fractions[0]
    if uses_walls:
        # start from the bond system with the wall-touching particles moved axially so that each wall overlaps them
        # a little (Jarolin & Dosta 2020 starts Newton from the pure bond solution; without overlap the walls add no
        # stiffness
        # and the first Newton system would be singular)
        z, rad = np.asarray(model.positions0[:, ax]), np.asarray(model.radii)
        lo, hi = (z - rad).min(), (z + rad).max()
        reach = 0.25 * float(rad.mean())
        beta = 0.1
        bottom, top = (z - rad) <= lo + reach, (z + rad) >= hi - reach
        guess = np.zeros(u_p.shape)
        guess[bottom, ax] = -0.5 * beta * frac0 * delta
        guess[top, ax] = -(1.0 - 0.5 * beta) * frac0 * delta
        free_lin = np.asarray(free).copy()
        free_lin[bottom | top, ax] = False
        start_args = (dataclasses.replace(model, walls=None), params, jnp.asarray(free_lin),
                      jnp.asarray(guess, u_p.dtype), linear_tol, None)
    else:
        start_args = (model, params, free, frac0 * u_p, linear_tol, None, "auto", None, coarse)
    # the programs compile when first called (the clock takes their compilation out of the run time): nothing is run
    # twice to time it
    with compile_clock() as compiling:
        u, history, step_reactions, converged_all, iterations, norm, scale = _newton_run(
            sys, start_args, fractions, walls_at, tol, newton_maxiter, stiffness_tol)
    compile_time = compiling.seconds
    run_time = time.perf_counter() - tc - compile_time
    info = {"residual": float(norm / scale), "residual_history": history, "iterations": iterations,
            "converged": bool(converged_all), "contacts": int(0 if pairs is None else len(pairs)), "slip": bool(slip),
            "load_steps": int(load_steps)}
    return u, fractions * delta, np.asarray(step_reactions), info, compile_time, run_time


def _newton_run(sys, start_args, fractions, walls_at, tol, newton_maxiter, stiffness_tol):
    """The load steps of :func:`_newton` from the bond solution ``linear_jit(*start_args)``."""
    u = linear_jit(*start_args)[0]
    history, step_reactions, converged_all, iterations = [], [], True, 0
    prev = None
    for frac in fractions:
        wp = walls_at(frac)
        if prev is not None:
            u = u * (frac / prev)  # proportional extrapolation; prescribed DOFs land exactly on frac * u_p
        prev = frac
        norm, scale, react = _newton_evaluate(sys, u, wp)
        history.append(float(norm / scale))
        reactions = [float(react)]
        converged = False
        for _ in range(newton_maxiter):
            rel = float(norm / scale)
            if rel <= tol or (stiffness_tol is not None and len(reactions) > 1 and
                              abs(reactions[-1] - reactions[-2]) <= stiffness_tol * abs(reactions[-1])):
                converged = True
                break
            du = _newton_step(sys, u, wp, min(0.1, max(rel * 0.1, 1e-8)))
            alpha = 1.0
            for _ in range(12):
                trial = u + alpha * du
                t_norm, t_scale, t_react = _newton_evaluate(sys, trial, wp)
                if np.isfinite(float(t_norm)) and float(t_norm) < (1 - 1e-4 * alpha) * float(norm):
                    break
                alpha *= 0.5
            u, norm, scale, react = trial, t_norm, t_scale, t_react
            history.append(float(norm / scale))
            reactions.append(float(react))
            iterations += 1
        else:
            converged = float(norm / scale) <= tol
        converged_all &= converged
        step_reactions.append(float(react))
    jax.block_until_ready(u)
    return u, history, step_reactions, converged_all, iterations, norm, scale
