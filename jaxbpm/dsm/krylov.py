"""Krylov solvers: preconditioned CG inside ``lax.custom_linear_solve`` (implicit derivatives) with an optional energy
stop, and the linear solve of a model with prescribed displacements.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxbpm.dsm.operator import (
    _geometric_operator, _packed_operator, _uses_geometry, BondGeometry, internal_forces, reduced_jacobians,
    stiffness_product)
from jaxbpm.dsm.preconditioner import build_preconditioner, CoarseSpace
from jaxbpm.errors import SceneError
from jaxbpm.physics.model import Model


def tangent_operator(model: Model, params, *, operator="auto", walls=None, geometry: BondGeometry | None = None):
    """The stiffness operator at rest, ``v -> K v`` on all DOFs (``[n, nd]`` in and out), and the reduced per-bond
    Jacobians it uses (:func:`reduced_jacobians`; ``None`` for ``"jvp"``).

    operator: ``"jacobians"`` (per-bond Jacobians of the bond law at rest, applied element by element:
    :func:`stiffness_product`; bonds only), ``"jvp"`` (a Jacobian-vector product of the whole force function at
    every application; any interaction) or ``"auto"`` (``"jacobians"`` unless the model has walls or contacts). Both
    give the same operator to round-off: the Jacobians are forward-mode derivatives of the same bond law. The
    element-by-element product is several times cheaper per application; it streams the packed symmetric form
    (:func:`packed_jacobians`: 45 numbers per bond with 6 DOF per particle, 6 with 3) at every application, and the
    reduced Jacobians (81 or 9 numbers per bond) are returned for the preconditioner. With ``geometry``
    (:func:`bond_geometry`, computed once per sample) and ``params`` as ``{"bond_E", "bond_nu"}``, the Jacobians are
    built from it instead of differentiating the bond law again (same numbers to round-off).

    Args:
      model: the model.
      params: the parameters.
      operator: ``"jacobians"``, ``"jvp"`` or ``"auto"`` (above).
      walls: the walls at the linearisation state, or ``None``.
      geometry: the sample's :class:`BondGeometry`, or ``None``.

    Returns:
      ``(apply, reduced)``: ``apply(v) -> K v`` and the reduced per-bond Jacobians (``None`` for ``"jvp"``).
    """
    if operator == "auto":
        operator = "jvp" if (walls is not None or model.walls is not None or model.contacts) else "jacobians"
    if operator == "jacobians":
        if walls is not None or model.walls is not None or model.contacts:
            raise SceneError("the 'jacobians' operator covers bonds only; use operator='jvp' with walls or contacts")
        if _uses_geometry(geometry, params):
            return _geometric_operator(model, params, geometry)
        jac = reduced_jacobians(model, params)
        if model.dim == 2:  # discs: the reduced 4 x 4 (or 2 x 2) form, applied as it is
            return (lambda v: stiffness_product(model, jac, v)), jac
        return _packed_operator(model, jac), jac
    if operator != "jvp":
        raise ValueError(f"operator must be 'auto', 'jacobians' or 'jvp', got {operator!r}")
    u0 = jnp.zeros((model.n, model.dofs), model.positions0.dtype)

    def f(u):
        return internal_forces(model, params, u, walls=walls)[0]

    return (lambda v: -jax.jvp(f, (u0,), (v,))[1]), None


def linear_solve(model: Model, params, free, u_prescribed, *, tol=1e-6, maxiter=None, walls=None,
                 operator="auto", stiffness_tol=None, coarse: CoarseSpace | None = None,
                 geometry: BondGeometry | None = None):
    """Solve the linearised equilibrium for one load case.

    Differentiable with respect to ``params``; ``vmap``-able over ``params`` or ``u_prescribed``.

    Args:
      model: the model.
      params: the parameters.
      free: ``[n, nd]`` bool, the DOFs solved for.
      u_prescribed: ``[n, nd]`` the prescribed displacements (zero on free DOFs).
      tol: the CG's relative residual.
      maxiter: CG iterations at most (``None``: 10 x the DOFs).
      walls: the walls at the linearisation state, or ``None``.
      operator: see :func:`tangent_operator`.
      stiffness_tol: also stop once the strain energy has settled to this relative change (see :func:`cg`).
      coarse: a :class:`CoarseSpace` for the two-level preconditioner (``None``: block-Jacobi alone).
      geometry: a :class:`BondGeometry` (:func:`bond_geometry`) to build the bond Jacobians from.

    Returns:
      ``(u, info)``: the full displacement field ``[n, nd]`` and ``{"residual": relative residual, "iterations":
      CG iterations}``.
    """
    full, jac = tangent_operator(model, params, operator=operator, walls=walls, geometry=geometry)
    precond = build_preconditioner(model, params, free, jac, coarse, geometry)
    u, res, iterations, _, _ = cg(full, precond, free, u_prescribed, tol, maxiter, stiffness_tol)
    return u, {"residual": res, "iterations": iterations}


def cg(full, precond, free, u_prescribed, tol, maxiter, stiffness_tol=None, delay=5, x0=None):
    """Preconditioned CG on the free DOFs for the prescribed displacements ``u_prescribed``.

    Stops when the relative residual ``|K_ff v - b| / |b|`` reaches ``tol`` or, with ``stiffness_tol``, when the
    strain energy -- hence the stiffness -- has settled: CG lowers the energy of its iterate monotonically, by
    ``alpha_k gamma_k / 2`` in step ``k``, and the sum of the last ``delay`` decreases estimates the error still left
    (the Hestenes-Stiefel estimate; it over-estimates the true error in practice). The energy converges
    quadratically while the residual converges linearly, so this stops several times sooner for the same stiffness.

    Wrapped in ``lax.custom_linear_solve``: derivatives come from implicit differentiation (an adjoint solve stopped
    by the residual), not from unrolling the iterations. The program holds three applications of ``full`` (one for
    the prescribed displacements and the guess together, one in the iteration, one for the solution) and one of
    ``precond`` (in the iteration, which preconditions the residual before it steps): each copy is compiled
    separately, and they are most of the compile time.

    Args:
      full: ``v -> K v`` on all DOFs (:func:`tangent_operator`).
      precond: the preconditioner, ``r -> M^-1 r`` (``[n, nd]`` in and out).
      free: ``[n, nd]`` bool, the DOFs solved for.
      u_prescribed: ``[n, nd]`` the prescribed displacements.
      tol: the relative residual to reach.
      maxiter: iterations at most.
      stiffness_tol: stop once the strain energy has settled to this relative change (``None``: the residual
        alone).
      delay: the iterations the energy estimate sums over.
      x0: a first guess of the displacements (``[n, nd]``, its free DOFs are used; ``None``: zero there).

    Returns:
      ``(u, residual, iterations, energy, ku)`` with ``ku = K u`` on all DOFs (the linearised internal forces are
      ``-ku``).
    """
    def matvec(v):
        # identity on the prescribed DOFs keeps the operator regular, so that the adjoint (transpose) solve of
        # reverse-mode differentiation stays consistent whatever cotangent reaches those DOFs
        return jnp.where(free, full(jnp.where(free, v, 0.0)), v)

    if x0 is None:
        k_p, k_0 = full(u_prescribed), None
    else:  # K u_p and K x0 in one application
        x0_free = jnp.where(free, jax.lax.stop_gradient(x0), 0.0)
        k_p, k_0 = jax.vmap(full)(jnp.stack([u_prescribed, x0_free]))
        k_0 = jnp.where(free, jax.lax.stop_gradient(k_0), 0.0)  # K_ff x0 (the guess is not differentiated)
    rhs = jnp.where(free, -k_p, 0.0)
    energy0 = 0.5 * jnp.vdot(u_prescribed, k_p)
    limit = 10 * rhs.size if maxiter is None else maxiter

    def run(mv, b, energy_test, guess=True):
        atol2 = jnp.square(tol) * jnp.vdot(b, b)
        # the energy and the guess belong to the system K v = rhs; custom_linear_solve also calls this solve for the
        # tangents of forward-mode derivatives (K v' = b'), which get the residual test from zero
        primal = jnp.all(b == rhs) if (energy_test or (guess and x0 is not None)) else False
        x_0, r_0, e_0 = jnp.zeros_like(b), b, energy0
        if guess and x0 is not None:
            # the energy of the guess: E(x) = E(0) - x.b + x.K x / 2 = E(0) - x.(b + r) / 2 with r = b - K x
            x_0 = jnp.where(primal, x0_free, 0.0)
            r_0 = b - jnp.where(primal, k_0, 0.0)
            e_0 = energy0 - 0.5 * jnp.vdot(x_0, b + r_0)
        window = jnp.zeros(delay, b.dtype)

        def done(c):
            _, r, _, _, k, energy, win = c
            small = jnp.vdot(r, r) <= atol2
            if energy_test:
                small |= primal & (k >= delay) & (jnp.sum(win) <= stiffness_tol * energy)
            return small | (k >= limit)

        def body(c):
            # preconditioned CG with the preconditioning at the top of the step: z = M r, then the new direction
            # (the first step has g = inf and p = 0, so p = z), the step along it
            x, r, g, p, k, energy, win = c
            z = precond(r)
            g2 = jnp.vdot(r, z)
            p = z + (g2 / g) * p
            ap = mv(p)
            alpha = g2 / jnp.vdot(p, ap)
            drop = 0.5 * alpha * g2
            return x + alpha * p, r - alpha * ap, g2, p, k + 1, energy - drop, win.at[k % delay].set(drop)

        init = (x_0, r_0, jnp.asarray(jnp.inf, b.dtype), jnp.zeros_like(b), 0, e_0, window)
        x, _, _, _, k, energy, _ = jax.lax.while_loop(lambda c: ~done(c), body, init)
        return x, (k, energy)

    v, (iterations, energy) = jax.lax.custom_linear_solve(
        matvec, rhs, lambda mv, b: run(mv, b, stiffness_tol is not None),
        transpose_solve=lambda mv, b: run(mv, b, False, False), symmetric=True, has_aux=True)
    k_v = full(jnp.where(free, v, 0.0))  # v is zero on the prescribed DOFs
    res = jnp.linalg.norm(jnp.where(free, k_v, v) - rhs) / jnp.maximum(jnp.linalg.norm(rhs),
                                                                        jnp.finfo(rhs.dtype).tiny)
    return u_prescribed + v, res, iterations, energy, k_p + k_v
