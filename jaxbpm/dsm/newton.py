"""The nonlinear DSM as one pure program: Newton-Krylov over load steps from the linear bond solution (contacts,
walls), with a backtracking line search; load steps in ``lax.scan``, Newton in ``lax.while_loop`` with a fixed
iteration budget, the contact candidates as data. Each load step's equilibrium carries its own reverse-mode rule,
so the program is differentiable by the implicit function theorem at the converged states (the iterations
themselves are never differentiated) and ``vmap``-able over parameter sets.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm._compile import Program
from jaxbpm.dsm.linear import _linear_fn
from jaxbpm.dsm.operator import (
    _contact_product, contact_jacobians, internal_forces, reduced_jacobians, stiffness_product)
from jaxbpm.dsm.preconditioner import _coarse_for, build_preconditioner, Preconditioner
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


@dataclasses.dataclass(frozen=True)
class NewtonProblem:
    """Everything the nonlinear solve needs besides the parameters (a pytree; built on the host by :func:`_newton`).

    model: the model with its contacts (and walls); bond_model: the same without walls (the start's linear solve);
    free ``[n, nd]``; pairs ``[C, 2]`` contact candidates (or ``None``); normals ``[W, 3]`` and wall_base ``[W, 3]``
    (the walls at full load; or ``None``); u_p ``[n, nd]``: the prescribed DOFs at full load; moving, resting
    ``[n]``: driven and fixed clamped particles; start_free, start_guess: the start's linear solve with the walls'
    touching particles held (walls), or ``None``; coarse: the bonds' coarse space (or ``None``); delta: the
    displacement at full load [m]. Static: axis,
    gmres_maxiter, newton_maxiter, slip."""

    model: Model
    bond_model: Model
    free: Any
    pairs: Any
    normals: Any
    wall_base: Any
    u_p: Any
    moving: Any
    resting: Any
    start_free: Any
    start_guess: Any
    coarse: Any
    delta: Any
    axis: int = 2
    gmres_maxiter: int = 10
    newton_maxiter: int = 30
    slip: bool = True


jax.tree_util.register_dataclass(
    NewtonProblem, data_fields=["model", "bond_model", "free", "pairs", "normals", "wall_base", "u_p", "moving",
                                "resting", "start_free", "start_guess", "coarse", "delta"],
    meta_fields=["axis", "gmres_maxiter", "newton_maxiter", "slip"])


_LINE_SEARCH = 12   # backtracking halvings per Newton step
_TANGENT_TOL = 1e-10  # GMRES tolerance of the implicit derivative's linear solves


def _system(prob: NewtonProblem, params) -> _NewtonSystem:
    """The Newton system at ``params``: the contacts' Hertz-Mindlin (or linear-law) parameters from ``params``
    (:meth:`~jaxbpm.physics.model.Model.hertz_params`) where given, no Coulomb limit without slip, the bonds'
    preconditioner."""
    model = prob.model
    if model.contacts:
        contact = model.hertz_params(params)
        if not prob.slip:  # no slip (Jarolin & Dosta 2020): the Coulomb limit is lifted for the static solve
            contact = contact._replace(friction=jnp.asarray(jnp.inf, model.positions0.dtype))
        model = dataclasses.replace(model, contact=contact)
    # the preconditioner from the bonds (contacts only add stiffness); never differentiated
    precond = jax.lax.stop_gradient(build_preconditioner(prob.bond_model, params, prob.free, None, prob.coarse))
    return _NewtonSystem(model=model, params=params, free=prob.free, pairs=prob.pairs if model.contacts else None,
                         normals=prob.normals, moving=prob.moving, resting=prob.resting, precond=precond,
                         axis=prob.axis, maxiter=prob.gmres_maxiter)


def _walls_at(prob: NewtonProblem, frac, dtype):
    """The walls at load fraction ``frac``: the top wall (index 1) moved back by ``(1 - frac) delta`` from its
    place at full load."""
    if prob.normals is None:
        return jnp.zeros((0, 3), dtype)
    return prob.wall_base.at[1, prob.axis].add((1.0 - frac) * prob.delta)


def _iterate(sys: _NewtonSystem, u, wp, tol, stiffness_tol, maxiter: int):
    """Newton with backtracking from ``u`` (``lax.while_loop``, at most ``maxiter`` steps); returns ``u`` and the
    float diagnostics ``(converged, steps, relative residual, residual history [maxiter + 1])``."""
    norm, scale, react = _newton_evaluate(sys, u, wp)
    dtype = norm.dtype
    history = jnp.full(maxiter + 1, jnp.nan, dtype).at[0].set(norm / scale)

    def cond(state):
        k, _, _, _, _, done, _ = state
        return (~done) & (k < maxiter)

    def body(state):
        k, u, norm, scale, react, _, history = state
        rel = norm / scale
        du = _newton_step(sys, u, wp, jnp.clip(0.1 * rel, 1e-8, 0.1))

        def try_cond(t):
            j, _, ok, *_ = t
            return (j < _LINE_SEARCH) & ~ok

        def try_body(t):
            j, alpha, _, *_ = t
            trial = u + alpha * du
            t_norm, t_scale, t_react = _newton_evaluate(sys, trial, wp)
            ok = jnp.isfinite(t_norm) & (t_norm < (1.0 - 1e-4 * alpha) * norm)
            return j + 1, jnp.where(ok, alpha, 0.5 * alpha), ok, trial, t_norm, t_scale, t_react

        init = (0, jnp.asarray(1.0, dtype), jnp.asarray(False), u, norm, scale, react)
        _, _, _, u_new, n_new, s_new, r_new = jax.lax.while_loop(try_cond, try_body, init)
        rel_new = n_new / s_new
        done = rel_new <= tol
        if stiffness_tol is not None:
            done = done | (jnp.abs(r_new - react) <= stiffness_tol * jnp.abs(r_new))
        return k + 1, u_new, n_new, s_new, r_new, done, history.at[k + 1].set(rel_new)

    state = (0, u, norm, scale, react, norm / scale <= tol, history)
    k, u, norm, scale, _, done, history = jax.lax.while_loop(cond, body, state)
    rel = norm / scale
    converged = done | (rel <= tol)
    return u, (converged.astype(dtype), jnp.asarray(k, dtype), rel, history)


def _equations(sys: _NewtonSystem, wp, target, u):
    """``F(u)``, zero at equilibrium: minus the internal forces on the free DOFs, ``u - target`` on the prescribed
    ones (so that ``dF/du`` is the stiffness on the free DOFs and the identity on the rest)."""
    return jnp.where(sys.free, -_newton_residual(sys, u, wp)[1], u - target)


def _gmres(sys: _NewtonSystem, operator, rhs):
    """``operator^-1 rhs`` by right-preconditioned GMRES to ``_TANGENT_TOL``."""
    shape = rhs.shape
    z, _ = jax.scipy.sparse.linalg.gmres(lambda z: operator(sys.precond(z.reshape(shape))).reshape(-1),
                                         rhs.reshape(-1), tol=_TANGENT_TOL, restart=40,
                                         maxiter=max(sys.maxiter, 50), solve_method="batched")
    return sys.precond(z.reshape(shape))


@functools.partial(jax.custom_vjp, nondiff_argnums=(6, 7))
def _equilibrium(sys: _NewtonSystem, wp, target, guess, tol, stiffness_tol, maxiter: int, use_stiffness_tol: bool):
    """The equilibrium ``u*`` of one load step, Newton from ``guess`` (:func:`_iterate`), and its diagnostics.

    Differentiated by the implicit function theorem: ``F(x, u*(x)) = 0`` gives ``x_bar = -(dF/dx)^T lambda`` with
    ``(dF/du)^T lambda = u_bar`` at ``u*`` (one adjoint GMRES solve per load step; the Newton iterations are never
    differentiated, and the guess gets no derivative)."""
    return _iterate(sys, guess, wp, tol, stiffness_tol if use_stiffness_tol else None, maxiter)


def _equilibrium_fwd(sys, wp, target, guess, tol, stiffness_tol, maxiter, use_stiffness_tol):
    u, diag = _equilibrium(sys, wp, target, guess, tol, stiffness_tol, maxiter, use_stiffness_tol)
    return (u, diag), (sys, wp, target, u, guess, tol, stiffness_tol)


def _equilibrium_bwd(maxiter, use_stiffness_tol, res, cotangents):
    sys, wp, target, u, guess, tol, stiffness_tol = res
    u_bar = cotangents[0]
    _, vjp_u = jax.vjp(lambda v: _equations(sys, wp, target, v), u)
    lam = _gmres(sys, lambda v: vjp_u(v)[0], u_bar)
    _, vjp_x = jax.vjp(lambda s, w, t: _equations(s, w, t, u), sys, wp, target)
    sys_bar, wp_bar, target_bar = vjp_x(-lam)
    return (sys_bar, wp_bar, target_bar, jnp.zeros_like(guess), jnp.zeros_like(tol), jnp.zeros_like(stiffness_tol))


_equilibrium.defvjp(_equilibrium_fwd, _equilibrium_bwd)


def newton_outputs(prob: NewtonProblem, params, tol, linear_tol, fractions=(1.0,), stiffness_tol=None):
    """The nonlinear solve as a pure function of the parameters, load step by load step.

    Differentiable with respect to ``params`` (and the problem's arrays) through each load step's equilibrium
    (:func:`_equilibrium`, reverse mode).

    Args:
      prob: the :class:`NewtonProblem` (:func:`newton_problem`).
      params: the parameters.
      tol: the Newton tolerance on the residual.
      linear_tol: the tolerance of the linear solve that gives the start.
      fractions: ``[L]`` the load fractions, increasing (a static tuple).
      stiffness_tol: the inner solves' stiffness tolerance (static; ``None``: the residual test alone).

    Returns:
      ``(u, reactions, diagnostics)``: ``[n, nd]`` the DOFs at the last fraction, ``[L]`` the reactions [N], and
      ``(converged [L], steps [L], residual [L], history [L, newton_maxiter + 1])`` (floats).
    """
    sys = _system(prob, params)
    dtype = prob.model.positions0.dtype
    frac0 = fractions[0]
    if prob.normals is not None:
        start = _linear_fn(prob.bond_model, params, prob.start_free, prob.start_guess * frac0, linear_tol, None)
    else:
        start = _linear_fn(prob.bond_model, params, prob.free, frac0 * prob.u_p, linear_tol, None, "auto", None,
                           prob.coarse)
    u0 = jax.lax.stop_gradient(start[0])

    stol = jnp.asarray(0.0 if stiffness_tol is None else stiffness_tol, dtype)

    def load_step(carry, frac):
        u, prev = carry
        u = u * (frac / prev)  # proportional extrapolation; prescribed DOFs land exactly on frac * u_p
        wp = _walls_at(prob, frac, dtype)
        u, diag = _equilibrium(sys, wp, frac * prob.u_p, u, jnp.asarray(tol, dtype), stol, prob.newton_maxiter,
                               stiffness_tol is not None)
        react = _newton_evaluate(sys, u, wp)[2]
        return (u, frac), (react, diag)

    fr = jnp.asarray(fractions, dtype)
    (u, _), (reactions, diag) = jax.lax.scan(load_step, (u0, fr[0]), fr)
    return u, reactions, diag


newton_program = Program(newton_outputs, static_argnames=("fractions", "stiffness_tol"))


def _newton(model, params, free, u_p, pairs, walls, scene, tol, linear_tol, maxiter, newton_maxiter, stiffness_tol,
            driven, delta, load_steps, preconditioner="auto", aggregate_size=None, slip=True):
    """Newton-Krylov with backtracking line search, over ``load_steps`` equal load increments
    (:func:`newton_outputs`, one compiled program).

    Returns displacement field, per-step displacements and reactions, info, compile and run time.
    """
    prob = newton_problem(model, free, u_p, pairs, walls, scene, maxiter, newton_maxiter, driven, delta,
                          preconditioner, aggregate_size, slip)
    fractions = tuple(float(f) for f in np.arange(1, load_steps + 1) / load_steps)
    out, compile_time, run_time = newton_program(prob, params, jnp.asarray(tol, u_p.dtype),
                                                 jnp.asarray(linear_tol, u_p.dtype), fractions=fractions,
                                                 stiffness_tol=None if stiffness_tol is None else float(stiffness_tol))
    u, reactions, (converged, steps, residual, history) = out
    history = np.asarray(history)
    info = {"residual": float(residual[-1]), "residual_history": [float(h) for h in history.ravel() if np.isfinite(h)],
            "iterations": int(np.sum(np.asarray(steps))), "converged": bool(np.all(np.asarray(converged) > 0)),
            "contacts": int(0 if pairs is None else len(pairs)), "slip": bool(slip), "load_steps": int(load_steps),
            "step_converged": [bool(c > 0) for c in np.asarray(converged)]}
    return u, np.asarray(fractions) * delta, np.asarray(reactions), info, compile_time, run_time


def newton_problem(model, free, u_p, pairs, walls, scene, maxiter, newton_maxiter, driven, delta,
                   preconditioner="auto", aggregate_size=None, slip=True) -> NewtonProblem:
    """The :class:`NewtonProblem` of a scene.

    The host-side setup: contact candidates in, the start's held particles with walls, the bonds' coarse space.

    Args:
      model: the model.
      free: ``[n, nd]`` boolean mask of the free DOFs.
      u_p: ``[n, nd]`` the prescribed DOFs at full load [m].
      pairs: ``[C, 2]`` the contact candidates (``None`` or empty: no contacts).
      walls: ``(points, normals)`` of the walls (``None``: no walls).
      scene: the scene (its ``axis``).
      maxiter: GMRES iterations per Newton step (``None`` or 0: 10).
      newton_maxiter: the Newton steps per load step, at most.
      driven: ``[n]`` boolean mask of the driven particles.
      delta: the load's travel [m].
      preconditioner: ``"auto"``, ``"two-level"`` or ``"jacobi"`` (no coarse space with walls).
      aggregate_size: the coarse aggregates' size (``None``: the default).
      slip: Coulomb sliding of the contacts on.

    Returns:
      The :class:`NewtonProblem`.

    Raises:
      ValueError: an unknown ``preconditioner``, or an ``aggregate_size`` below 1.
    """
    model_c = dataclasses.replace(model, contacts=pairs is not None and len(pairs) > 0)
    # with slip, the tangential spring of a contact is its whole relative tangential displacement since rest, capped by
    # Coulomb (|F_t| <= mu F_n): path-independent, so one residual function of u, and equal to the DEM's incremental
    # law under monotonic loading that does not turn the contacts' sliding direction
    ax = scene.axis
    uses_walls = walls is not None
    free_np = np.asarray(free)
    clamped = ~free_np.any(axis=1)
    # the two-level preconditioner from the bonds; not with walls alone holding the sample along the axis, where the
    # bonds' coarse matrix is singular
    coarse = None if uses_walls else _coarse_for(model, free_np, preconditioner, aggregate_size)
    start_free = start_guess = wall_base = normals = None
    if uses_walls:
        # start from the bond system with the wall-touching particles moved axially so that each wall overlaps them
        # a little (Jarolin & Dosta 2020 start Newton from the pure bond solution; without overlap the walls add no
        # stiffness and the first Newton system would be singular); the guess is at full load, scaled by the first
        # load fraction in the program
        z, rad = np.asarray(model.positions0[:, ax]), np.asarray(model.radii)
        lo, hi = (z - rad).min(), (z + rad).max()
        reach = 0.25 * float(rad.mean())
        beta = 0.1
        bottom, top = (z - rad) <= lo + reach, (z + rad) >= hi - reach
        guess = np.zeros(u_p.shape)
        guess[bottom, ax] = -0.5 * beta * delta
        guess[top, ax] = -(1.0 - 0.5 * beta) * delta
        free_lin = free_np.copy()
        free_lin[bottom | top, ax] = False
        start_free, start_guess = jnp.asarray(free_lin), jnp.asarray(guess, u_p.dtype)
        wall_base, normals = walls[0], walls[1]
    dtype = u_p.dtype
    prob = NewtonProblem(model=model_c, bond_model=dataclasses.replace(model, walls=None), free=jnp.asarray(free),
                         pairs=jnp.asarray(pairs) if model_c.contacts else None, normals=normals,
                         wall_base=wall_base, u_p=jnp.asarray(u_p, dtype), moving=jnp.asarray(driven),
                         resting=jnp.asarray(clamped & ~np.asarray(driven)), start_free=start_free,
                         start_guess=start_guess, coarse=coarse, delta=jnp.asarray(delta, dtype), axis=int(ax),
                         gmres_maxiter=int(maxiter or 10),
                         newton_maxiter=int(newton_maxiter), slip=bool(slip))
    return prob
