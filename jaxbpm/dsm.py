"""Direct stiffness method (DSM): the static equilibrium of the Model's forces, solved without a matrix.

Unknowns are the displacements (and, with 6 DOF per particle, the rotation vectors) of the free particles; the
clamped ones are prescribed by the scene. The residual is the Model's force function itself, so DSM and DEM differ
only by the approximations the method names: no inertia, small motion (linear DSM) and fixed contact candidates.

* **Linear** (bonds only): ``K_ff u_f = -K_fp u_p`` with ``K v`` a Jacobian-vector product of the forces at rest
  (``jax.jvp``; never an assembled matrix), solved by ``jax.scipy.sparse.linalg.cg`` with a block-Jacobi
  preconditioner (each particle's 6x6 (or 3x3) self-stiffness, from per-bond Jacobians of the same bond law).
  ``cg`` is a ``lax.custom_linear_solve``: derivatives with respect to the bond parameters come from implicit
  differentiation, not from unrolling the iterations; ``vmap`` over parameter sets works.
* **Nonlinear** (Hertz contacts, walls): Newton-Krylov, started from the linear bond solution; each Newton step
  solves the tangent system (jvp at the current state) with GMRES, then a backtracking line search on the residual
  norm. Contact candidates are the pairs within reach at rest (fixed in advance); tangential contacts do not slip and
  carry the whole relative tangential displacement (seed 000, 3.1.2); walls are ideal frictionless moving walls.

Convergence is measured by the residual norm relative to the norm of the reaction forces. A solve that misses its
tolerance is reported (``converged=False`` in the stats and a warning), or raises :class:`ConvergenceError` with
``throw=True``. A sample whose free part is not held (a cluster that touches no clamped particle and no wall) raises
:class:`SceneError` naming the particles.
"""

from __future__ import annotations

import dataclasses
import functools
import time
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm.errors import ConvergenceError, SceneError
from jaxbpm.physics import bond as bond_mod
from jaxbpm.physics import rotation
from jaxbpm.physics.model import Model

__all__ = ["bond_jacobians", "block_diagonal", "linear_solve", "solve_scene"]


# ---------------------------------------------------------------------------------------------------- operators
def _configuration(model: Model, u):
    """Positions and orientations for a DOF array ``u [n, 3 or 6]``."""
    x = model.positions0 + u[:, :3]
    q = rotation.from_rotation_vector(u[:, 3:]) if model.rotations else None
    return x, q


def _internal_forces(model: Model, params, u, contacts=None, walls=None):
    """Generalised forces ``[n, 3 or 6]`` (forces, then moments) at the DOF state ``u``."""
    x, q = _configuration(model, u)
    con = None
    if contacts is not None:
        pairs, valid = contacts
        i, j = pairs[:, 0], pairs[:, 1]
        d = x[j] - x[i]
        nrm = d / jnp.linalg.norm(d, axis=1, keepdims=True)
        dxi = u[j, :3] - u[i, :3]
        if model.rotations:
            dxi = dxi + jnp.cross(u[j, 3:], -model.radii[j, None] * nrm) - jnp.cross(u[i, 3:],
                                                                                    model.radii[i, None] * nrm)
        zeros = jnp.zeros_like(dxi)
        con = (pairs, valid, zeros, dxi, zeros)
    wp, wn = (None, None) if walls is None else walls
    f, m, parts = model.forces(x, q, params, contacts=con, wall_points=wp, wall_normals=wn)
    gen = jnp.concatenate([f, m], axis=1) if model.rotations else f
    return gen, parts


def bond_jacobians(model: Model, params) -> jnp.ndarray:
    """Per-bond tangent stiffness ``[nb, 12, 12]`` (or ``[nb, 6, 6]`` without rotations) at rest, in the global
    frame, DOF order (u_i, theta_i, u_j, theta_j): ``jax.jacfwd`` of the same bond law, minus sign (stiffness)."""
    k = model.stiffness(params)
    nd = 6 if model.rotations else 3

    def one(r0, kn, kt, ktw, kb):
        def f(z):
            ui, uj = z[:3], z[nd:nd + 3]
            if model.rotations:
                qi, qj = rotation.from_rotation_vector(z[3:6]), rotation.from_rotation_vector(z[9:12])
            else:
                qi = qj = jnp.array([1.0, 0.0, 0.0, 0.0], r0.dtype)
            out = bond_mod.bond_law(r0 + uj - ui, r0, qi, qj, kn, kt, ktw, kb)
            parts = [out.f_i, out.m_i, -out.f_i, out.m_j] if model.rotations else [out.f_i, -out.f_i]
            return jnp.concatenate(parts)

        return -jax.jacfwd(f)(jnp.zeros(2 * nd, r0.dtype))

    return jax.vmap(one)(model.r0, k.kn, k.kt, k.ktw, k.kb)


def block_diagonal(model: Model, params) -> jnp.ndarray:
    """Each particle's self-stiffness block ``[n, nd, nd]`` summed over its bonds."""
    jac = bond_jacobians(model, params)
    nd = jac.shape[1] // 2
    n = model.n
    blocks = jax.ops.segment_sum(jac[:, :nd, :nd], model.bonds[:, 0], n)
    return blocks + jax.ops.segment_sum(jac[:, nd:, nd:], model.bonds[:, 1], n)


def _preconditioner(model: Model, params, free):
    """Block-Jacobi: inverse of each particle's self-stiffness on its free DOFs (identity on the rest)."""
    blocks = jax.lax.stop_gradient(block_diagonal(model, params))
    nd = blocks.shape[1]
    eye = jnp.eye(nd, dtype=blocks.dtype)
    mask = free[:, :, None] & free[:, None, :]
    blocks = jnp.where(mask, blocks, eye[None])
    # particles without bonds (contacts only): a scalar guess from the mean bond diagonal keeps the block regular
    scale = jnp.mean(jnp.abs(jnp.diagonal(blocks, axis1=1, axis2=2)), axis=0)
    empty = jnp.all(jnp.abs(jnp.where(mask, blocks, 0.0)) == 0, axis=(1, 2))
    blocks = jnp.where(empty[:, None, None], jnp.diag(scale)[None], blocks)
    inv = jnp.linalg.inv(blocks)

    def apply(v):
        return jnp.where(free, jnp.einsum("nij,nj->ni", inv, v), v)

    return apply


# ---------------------------------------------------------------------------------------------------- linear solve
def linear_solve(model: Model, params, free, u_prescribed, *, tol=1e-6, maxiter=None, walls=None):
    """Solve the linearised equilibrium for one load case.

    free: ``[n, nd]`` bool, u_prescribed: ``[n, nd]`` (zero on free DOFs). Returns ``(u, info)`` with the full
    displacement field and ``info = {"residual": relative residual, "iterations": ...}``.
    Differentiable with respect to ``params``; ``vmap``-able over ``params`` or ``u_prescribed``.
    """
    u0 = jnp.zeros_like(u_prescribed)

    def f(u):
        return _internal_forces(model, params, u, walls=walls)[0]

    def matvec(v):
        # identity on the prescribed DOFs keeps the operator regular, so that the adjoint (transpose) solve of
        # reverse-mode differentiation stays consistent whatever cotangent reaches those DOFs
        return jnp.where(free, -jax.jvp(f, (u0,), (jnp.where(free, v, 0.0),))[1], v)

    rhs = jnp.where(free, jax.jvp(f, (u0,), (u_prescribed,))[1], 0.0)
    precond = _preconditioner(model, params, free)
    v, _ = jax.scipy.sparse.linalg.cg(matvec, rhs, tol=tol, maxiter=maxiter, M=precond)
    u = u_prescribed + v
    res = jnp.linalg.norm(matvec(v) - rhs) / jnp.maximum(jnp.linalg.norm(rhs), jnp.finfo(rhs.dtype).tiny)
    return u, {"residual": res}


# ---------------------------------------------------------------------------------------------------- scenes
def _free_mask(model: Model, scene, sample):
    nd = 6 if model.rotations else 3
    n = model.n
    free = np.ones((n, nd), bool)
    if scene.uses_walls:
        # frictionless walls hold the sample along the axis only: pin the lateral rigid-body motions with the least
        # constraints possible (two lateral DOFs of one bottom particle, one of another), which carry no load
        ax = scene.axis
        pos = np.asarray(sample.positions)
        lat = [k for k in range(3) if k != ax]
        bottom = np.flatnonzero(pos[:, ax] - np.asarray(sample.radii) <= (pos[:, ax] - np.asarray(sample.radii)).min()
                                + 1e-9 + float(np.mean(sample.radii)))
        c = pos[bottom].mean(axis=0)
        p0 = bottom[np.argmin(np.linalg.norm(pos[bottom] - c, axis=1))]
        p1 = bottom[np.argmax(np.linalg.norm(pos[bottom] - pos[p0], axis=1))]
        free[p0, lat] = False
        arm = pos[p1] - pos[p0]
        free[p1, lat[int(np.argmin(np.abs(arm[lat])))]] = False
        return free, np.zeros(n, bool), np.zeros(n, bool)
    fixed, driven = scene.layers(sample)
    free[fixed | driven] = False
    return free, fixed, driven


def _check_held(sample, model, free, clamped, contact_pairs=None, wall_touching=None):
    """Raise SceneError if a cluster of bonded (or touching) particles is held by nothing."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = model.n
    b = np.asarray(sample.bonds)
    if contact_pairs is not None and len(contact_pairs):
        b = np.concatenate([b, contact_pairs])
    graph = coo_matrix((np.ones(len(b)), (b[:, 0], b[:, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    held = clamped | (~free).any(axis=1)
    if wall_touching is not None:
        held = held | wall_touching
    ok = np.zeros(labels.max() + 1, bool)
    ok[labels[held]] = True
    loose = np.flatnonzero(~ok[labels])
    if loose.size:
        raise SceneError(
            f"the system is singular: {loose.size} particles belong to clusters held by no clamped particle or wall "
            f"(floating), e.g. particles {loose[:10].tolist()}; remove them or clamp part of each cluster")


def _contact_candidates(sample, model, skin):
    from scipy.spatial import cKDTree

    pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
    tree = cKDTree(pos)
    pairs = np.array(sorted(tree.query_pairs(2 * rad.max() + skin)), dtype=np.int64).reshape(-1, 2)
    if len(pairs):
        gap = np.linalg.norm(pos[pairs[:, 1]] - pos[pairs[:, 0]], axis=1) - rad[pairs[:, 0]] - rad[pairs[:, 1]]
        pairs = pairs[gap < skin]
    if sample.bond_contact == "replace" and len(pairs):
        bonded = np.asarray(model.bonded(jnp.asarray(pairs, jnp.int32)))
        pairs = pairs[~bonded]
    return pairs.astype(np.int32)


def solve_scene(sample, scene, params, *, dofs=None, nonlinear=None, tol=None, linear_tol=1e-6, maxiter=None,
                newton_maxiter=30, stiffness_tol=None, contact_skin=None, load_steps=4, throw=False):
    """Solve a :class:`~jaxbpm.scenes.UniaxialCompression` statically. See :func:`jaxbpm.solve`."""
    from jaxbpm.physics.model import default_params
    from jaxbpm.result import Result

    t0 = time.perf_counter()
    rotations = None if dofs is None else {3: False, 6: True}.get(int(dofs))
    if dofs is not None and rotations is None:
        raise SceneError(f"dofs must be 3 or 6 per particle, got {dofs!r}")
    model = scene.model(sample, rotations=rotations, contacts=False)
    if nonlinear is None:
        nonlinear = bool(scene.contacts or scene.uses_walls)
    if scene.uses_walls and not nonlinear:
        raise SceneError("a scene with walls needs the nonlinear DSM (walls are contacts); use nonlinear=True")
    params = default_params(sample) if params is None else params
    length, area = scene.geometry(sample)
    delta = scene.strain * length
    free_np, fixed, driven = _free_mask(model, scene, sample)
    clamped = fixed | driven
    nd = free_np.shape[1]
    ax = scene.axis
    u_p = np.zeros((model.n, nd))
    u_p[driven, ax] = -delta
    walls = None
    if scene.uses_walls:
        load = scene.loading(sample, speed=1.0)
        walls = (load.wall_points0 + load.wall_velocity * delta, load.wall_normals)  # top wall moved by delta
    pairs = None
    if scene.contacts:
        skin = contact_skin if contact_skin is not None else 0.5 * float(np.mean(sample.radii))
        pairs = _contact_candidates(sample, model, skin)
    touching = None
    if scene.uses_walls:
        pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
        reach = float(np.mean(rad)) * 0.5 + delta
        touching = ((pos[:, ax] - rad) <= (pos[:, ax] - rad).min() + reach) | (
            (pos[:, ax] + rad) >= (pos[:, ax] + rad).max() - reach)
    _check_held(sample, model, free_np, clamped, pairs, touching)
    free = jnp.asarray(free_np)
    u_p = jnp.asarray(u_p, model.positions0.dtype)

    stats = {"dofs": nd, "nonlinear": nonlinear, "free_dofs": int(free_np.sum())}
    tc = time.perf_counter()
    if not nonlinear:
        # the jit cache serves repeated solves of one sample size (calibration loops); on a cache miss the first
        # call includes compilation, and a second call gives the run time
        cached = _linear_jit._cache_size()
        u, force_total, res = jax.block_until_ready(_linear_jit(model, params, free, u_p, linear_tol, maxiter))
        first = time.perf_counter() - tc
        if _linear_jit._cache_size() > cached:
            tr = time.perf_counter()
            u, force_total, res = jax.block_until_ready(_linear_jit(model, params, free, u_p, linear_tol, maxiter))
            run_time = time.perf_counter() - tr
            compile_time = max(first - run_time, 0.0)
        else:
            run_time, compile_time = first, 0.0
        res = float(res)
        converged = res <= linear_tol * 1.01
        stats.update(residual=res, residual_history=[res], converged=converged, iterations=None)
        reaction = float(force_total)
    else:
        tol = 1e-3 if tol is None else tol
        u, disps, forces, info, compile_time, run_time = _newton(
            model, params, free, u_p, pairs, walls, scene, tol, linear_tol, maxiter, newton_maxiter, stiffness_tol,
            driven, delta, load_steps)
        converged = info["converged"]
        stats.update(info)
    if not converged:
        msg = (f"DSM did not converge: relative residual {stats['residual']:.3g} above tolerance "
               f"{(tol if nonlinear else linear_tol):.3g}")
        if throw:
            raise ConvergenceError(msg)
        warnings.warn(msg, stacklevel=3)
    if nonlinear:
        # the same measure as the DEM: least-squares slope of the load steps within the scene's fit range
        stiffness = scene.fit_stiffness(disps, forces, delta) if load_steps > 1 else float(forces[-1] / delta)
        disps, forces = np.concatenate([[0.0], disps]), np.concatenate([[0.0], forces])
    else:
        stiffness = reaction / delta
        disps, forces = np.array([0.0, delta]), np.array([0.0, reaction])
    stats.update(bond_forces=_bond_forces_at(dataclasses.replace(model, walls=None), params, u))
    return Result(method="dsm", stiffness=stiffness, youngs_modulus=stiffness * length / area, gauge_length=length,
                  area=area, displacement=disps, force=forces,
                  wall_time=time.perf_counter() - t0, compile_time=compile_time, run_time=run_time, stats=stats,
                  state=u)


@jax.jit
def _bond_forces_at(model, params, u):
    """Per-bond forces (:class:`BondForces`) at the DOF state ``u``."""
    return _internal_forces(model, params, u)[1]["bonds"]


@functools.partial(jax.jit, static_argnames=("maxiter",))
def _linear_jit(model, params, free, u_p, tol, maxiter):
    u, info = linear_solve(model, params, free, u_p, tol=tol, maxiter=maxiter)
    # reaction from the linearised forces (exactly what the linear model predicts)
    f = lambda w: _internal_forces(model, params, w)[0]  # noqa: E731
    gen = jax.jvp(f, (jnp.zeros_like(u),), (u,))[1]
    clamped = ~jnp.any(free, axis=1)
    moving = clamped & jnp.any(u_p != 0, axis=1)
    resting = clamped & ~moving
    ax = jnp.argmax(jnp.any(u_p != 0, axis=0))
    comp = jnp.take(gen, ax, axis=1)
    reaction = 0.5 * (jnp.sum(jnp.where(moving, comp, 0.0)) - jnp.sum(jnp.where(resting, comp, 0.0)))
    return u, reaction, info["residual"]


def _newton(model, params, free, u_p, pairs, walls, scene, tol, linear_tol, maxiter, newton_maxiter, stiffness_tol,
            driven, delta, load_steps):
    """Newton-Krylov with backtracking line search, over ``load_steps`` equal load increments.

    Returns displacement field, per-step displacements and reactions, info, compile and run time.
    """
    model_c = dataclasses.replace(model, contacts=pairs is not None and len(pairs) > 0)
    if model_c.contacts:
        # no slip (seed 000): the Coulomb limit is lifted for the static solve
        model_c = dataclasses.replace(model_c, contact=model_c.contact._replace(
            friction=jnp.asarray(jnp.inf, model.positions0.dtype)))
        con = (jnp.asarray(pairs), jnp.ones(len(pairs), bool))
    else:
        con = None
    ax = scene.axis
    uses_walls = walls is not None
    clamped = ~np.asarray(free).any(axis=1)
    moving = jnp.asarray(driven) if not uses_walls else None
    resting = jnp.asarray(clamped & ~np.asarray(driven)) if not uses_walls else None
    normals = walls[1] if uses_walls else None
    wall_base = walls[0] if uses_walls else None

    def residual(u, wall_points):
        gen, parts = _internal_forces(model_c, params, u, con, (wall_points, normals) if uses_walls else None)
        return jnp.where(free, gen, 0.0), gen, parts

    def reaction_of(gen, parts):
        if uses_walls:
            r = parts["walls"]
            return 0.5 * (r[1, ax] - r[0, ax])
        comp = gen[:, ax]
        return 0.5 * (jnp.sum(jnp.where(moving, comp, 0.0)) - jnp.sum(jnp.where(resting, comp, 0.0)))

    @jax.jit
    def evaluate(u, wall_points):
        r, gen, parts = residual(u, wall_points)
        # the residual is measured against the external forces: reactions of clamped DOFs and of the walls
        scale = jnp.linalg.norm(jnp.where(free, 0.0, gen))
        if uses_walls:
            scale = scale + jnp.linalg.norm(parts["walls"])
        scale = scale + jnp.finfo(gen.dtype).tiny
        return jnp.linalg.norm(r), scale, reaction_of(gen, parts)

    @jax.jit
    def newton_step(u, wall_points, krylov_tol):
        r = residual(u, wall_points)[0]

        def matvec(v):
            return jnp.where(free, -jax.jvp(lambda w: residual(w, wall_points)[0], (u,),
                                            (jnp.where(free, v, 0.0),))[1], v)

        # right preconditioning (A M y = r, du = M y): jax's gmres measures a left-preconditioned residual against
        # the unpreconditioned right-hand side, which stops it at once when M carries units (1 / stiffness)
        y, _ = jax.scipy.sparse.linalg.gmres(lambda y: matvec(precond(y)), r, tol=krylov_tol, restart=40,
                                             maxiter=maxiter or 10, solve_method="batched")
        return jnp.where(free, precond(y), 0.0)

    precond = _preconditioner(model, params, free)
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
        # a little (seed 000 starts Newton from the pure bond solution; without overlap the walls add no stiffness
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
        bonds_only = dataclasses.replace(model, walls=None)
        u, _ = jax.jit(lambda p: linear_solve(bonds_only, p, jnp.asarray(free_lin), jnp.asarray(guess, u_p.dtype),
                                              tol=linear_tol))(params)
    else:
        u, _ = jax.jit(lambda p: linear_solve(model, p, free, frac0 * u_p, tol=linear_tol))(params)
    jax.block_until_ready(evaluate(u, walls_at(frac0)))
    jax.block_until_ready(newton_step(u, walls_at(frac0), 1e-3))
    compile_time = time.perf_counter() - tc
    tr = time.perf_counter()
    history, step_reactions, converged_all, iterations = [], [], True, 0
    prev = None
    for frac in fractions:
        wp = walls_at(frac)
        if prev is not None:
            u = u * (frac / prev)  # proportional extrapolation; prescribed DOFs land exactly on frac * u_p
        prev = frac
        norm, scale, react = evaluate(u, wp)
        history.append(float(norm / scale))
        reactions = [float(react)]
        converged = False
        for _ in range(newton_maxiter):
            rel = float(norm / scale)
            if rel <= tol or (stiffness_tol is not None and len(reactions) > 1 and
                              abs(reactions[-1] - reactions[-2]) <= stiffness_tol * abs(reactions[-1])):
                converged = True
                break
            du = newton_step(u, wp, min(0.1, max(rel * 0.1, 1e-8)))
            alpha = 1.0
            for _ in range(12):
                trial = u + alpha * du
                t_norm, t_scale, t_react = evaluate(trial, wp)
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
    run_time = time.perf_counter() - tr
    info = {"residual": float(norm / scale), "residual_history": history, "iterations": iterations,
            "converged": bool(converged_all), "contacts": int(0 if pairs is None else len(pairs)),
            "load_steps": int(load_steps)}
    return u, fractions * delta, np.asarray(step_reactions), info, compile_time, run_time


# ---------------------------------------------------------------------------------------------------- pure functions
def stiffness_function(sample, scene, *, dofs=None, tol=1e-8, maxiter=None):
    """A pure function ``params -> K`` [N/m] of the linear DSM on ``scene`` (clamped layers, bonds only).

    It can be ``jit``-ed, differentiated (``jax.grad``: implicit differentiation through the CG solve) and
    ``vmap``-ped over parameter sets, e.g. ``jax.vmap(f)({"bond_E": E_batch, "bond_nu": nu_batch})``.
    """
    if scene.uses_walls or scene.contacts:
        raise SceneError("stiffness_function covers the linear DSM (clamped layers, bonds only)")
    rotations = None if dofs is None else {3: False, 6: True}[int(dofs)]
    model = scene.model(sample, rotations=rotations, contacts=False)
    free_np, fixed, driven = _free_mask(model, scene, sample)
    _check_held(sample, model, free_np, fixed | driven)
    length, _ = scene.geometry(sample)
    delta = scene.strain * length
    u_p = np.zeros(free_np.shape)
    u_p[driven, scene.axis] = -delta
    free, u_p = jnp.asarray(free_np), jnp.asarray(u_p, model.positions0.dtype)

    def stiffness(params):
        return _linear_jit(model, params, free, u_p, tol, maxiter)[1] / delta

    return stiffness


def load_cases(sample, scene, directions, params=None, *, dofs=None, tol=1e-8):
    """Reactions of several load cases on the same operator: the driven layer moved by ``strain * l`` along each
    unit vector in ``directions [L, 3]`` (e.g. the three axes: compression and two shears), all solved at once with
    ``vmap``. Returns the ``[L, 3]`` matrix of reaction forces per unit displacement [N/m] (row: load case)."""
    from jaxbpm.physics.model import default_params

    rotations = None if dofs is None else {3: False, 6: True}[int(dofs)]
    model = scene.model(sample, rotations=rotations, contacts=False)
    params = default_params(sample) if params is None else params
    free_np, fixed, driven = _free_mask(model, scene, sample)
    _check_held(sample, model, free_np, fixed | driven)
    length, _ = scene.geometry(sample)
    delta = scene.strain * length
    dirs = np.asarray(directions, float).reshape(-1, 3)
    u_p = np.zeros((len(dirs),) + free_np.shape)
    u_p[:, driven, :3] = delta * dirs[:, None, :]
    free = jnp.asarray(free_np)

    @jax.jit
    def reactions(u_p):
        def one(up):
            u, _ = linear_solve(model, params, free, up, tol=tol)
            f = lambda w: _internal_forces(model, params, w)[0]  # noqa: E731
            gen = jax.jvp(f, (jnp.zeros_like(u),), (u,))[1]
            # force the machine applies to the driven layer = minus the internal force on it
            return -jnp.sum(jnp.where(jnp.asarray(driven)[:, None], gen[:, :3], 0.0), axis=0)

        return jax.vmap(one)(u_p)

    return np.asarray(reactions(jnp.asarray(u_p, model.positions0.dtype))) / delta
