"""Pure functions of the parameters: the stiffness of a scene (``jit``, ``grad``, ``vmap``) and several load cases on
one operator.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm._compile import strong, traced
from jaxbpm.dsm.boundary import _check_held, free_mask
from jaxbpm.dsm.krylov import cg, tangent_operator
from jaxbpm.dsm.linear import (
    _energy_test, _linear_setup, _linear_setups, _linear_stiffness_tol, linear_jit, linear_program)
from jaxbpm.dsm.preconditioner import _coarse_for, bond_geometry, build_preconditioner
from jaxbpm.errors import SceneError


def stiffness_function(sample, scene, *, dofs=None, tol=1e-6, maxiter=None, operator="auto", stiffness_tol="auto",
                       preconditioner="auto", aggregate_size=None, n_materials=None, pad=True, nonlinear_tol=None,
                       newton_maxiter=30, load_steps=4, contact_skin=None, slip=True):
    """A pure function ``params -> K`` [N/m] of the DSM on ``scene``: the linear solve (clamped layers, bonds
    only), or with contacts or walls the nonlinear one (:func:`jaxbpm.dsm.newton.newton_outputs`: Newton over
    ``load_steps`` load steps to ``nonlinear_tol``, default 1e-3, K the least-squares slope over the scene's fit
    range, as :func:`jaxbpm.solve` reports it). ``params`` may then also hold ``contact_E`` and ``contact_nu``.

    It can be ``jit``-ed, differentiated (``jax.grad``: implicit differentiation through the CG solve) and
    ``vmap``-ped over parameter sets, e.g. ``jax.vmap(f)({"bond_E": E_batch, "bond_nu": nu_batch})``.
    n_materials: the length of ``params["bond_E"]`` (default: the sample's material count); pad: pad the sample to
    its size class (same values to round-off; samples of one class then share compilations). A call with concrete
    parameters runs the program :func:`solve_scene` compiles (none is compiled when the process solved a sample of
    that class with these options before); a traced call (``jit``, ``grad``, ``vmap``) traces the solve. The
    nonlinear solve's gradient is implicit (the implicit function theorem at each load step's equilibrium), so it
    holds to the tolerance the equilibrium is solved to: pass a tight ``nonlinear_tol`` (e.g. 1e-10) for gradients.
    """
    rotations = None if dofs is None else {3: False, 6: True}[int(dofs)]
    if scene.uses_walls or scene.contacts:
        return _nonlinear_stiffness_function(sample, scene, rotations, tol=1e-3 if nonlinear_tol is None else
                                             nonlinear_tol, linear_tol=tol, maxiter=maxiter,
                                             newton_maxiter=newton_maxiter, load_steps=load_steps,
                                             contact_skin=contact_skin, slip=slip, preconditioner=preconditioner,
                                             aggregate_size=aggregate_size)
    stiffness_tol = _linear_stiffness_tol(stiffness_tol)
    m = sample.n_materials if n_materials is None else int(n_materials)
    key = (scene, rotations, operator, preconditioner, aggregate_size, m, bool(pad))
    setup = _linear_setups.get(sample, key, lambda: _linear_setup(sample, scene, rotations, operator, preconditioner,
                                                                   aggregate_size, m, pad))

    def stiffness(params):
        if not traced(params):
            out = linear_program(setup.model, strong(params), setup.free, setup.u_p, tol, _energy_test(stiffness_tol),
                                  setup.coarse, setup.geometry, setup.guess, maxiter=maxiter, operator=operator)[0]
            return out[0][1] / setup.delta
        return linear_jit(setup.model, params, setup.free, setup.u_p, tol, maxiter, operator, stiffness_tol,
                           setup.coarse, geometry=setup.geometry, guess=setup.guess)[1] / setup.delta

    return stiffness


def load_cases(sample, scene, directions, params=None, *, dofs=None, tol=1e-8, preconditioner="auto",
               aggregate_size=None):
    """Reactions of several load cases on the same operator: the driven layer moved by ``strain * l`` along each
    unit vector in ``directions [L, 3]`` (e.g. the three axes: compression and two shears), all solved at once with
    ``vmap``.

    Args:
      sample: the bonded sample.
      scene: a bonds-only scene with clamped layers.
      directions: ``[L, 3]`` the load cases' unit vectors.
      params: the bond parameters (``None``: the sample's own).
      dofs: 3 or 6 per particle (``None``: the model's choice).
      tol: the CG's relative residual.
      preconditioner: ``"auto"``, ``"two-level"`` or ``"jacobi"``.
      aggregate_size: the coarse space's aggregate size [m] (``None``: its default).

    Returns:
      ``[L, 3]`` the reaction forces per unit displacement [N/m] (row: load case).
    """
    from jaxbpm.physics.model import default_params

    rotations = None if dofs is None else {3: False, 6: True}[int(dofs)]
    model = scene.model(sample, rotations=rotations, contacts=False)
    params = default_params(sample) if params is None else params
    free_np, fixed, driven = free_mask(model, scene, sample)
    _check_held(sample, model, free_np, fixed | driven)
    length, _ = scene.geometry(sample)
    delta = scene.strain * length
    dirs = np.asarray(directions, float).reshape(-1, 3)
    u_p = np.zeros((len(dirs),) + free_np.shape)
    u_p[:, driven, :3] = delta * dirs[:, None, :]
    free = jnp.asarray(free_np)
    coarse = _coarse_for(model, free_np, preconditioner, aggregate_size)
    geometry = bond_geometry(model, coarse, n_materials=sample.n_materials)

    out = _load_case_reactions(model, params, free, coarse, geometry, jnp.asarray(driven),
                               jnp.asarray(u_p, model.positions0.dtype), tol)
    return np.asarray(out) / delta


@jax.jit
def _load_case_reactions(model, params, free, coarse, geometry, driven, u_p, tol):
    """Reaction on the driven layer ``[L, 3]`` of each load case ``u_p [L, n, nd]`` (one operator, vmapped CG)."""
    full, jac = tangent_operator(model, params, geometry=geometry)
    precond = build_preconditioner(model, params, free, jac, coarse, geometry)

    def one(up):
        gen = -cg(full, precond, free, up, tol, None)[4]
        # force the machine applies to the driven layer = minus the internal force on it
        return -jnp.sum(jnp.where(driven[:, None], gen[:, :3], 0.0), axis=0)

    return jax.vmap(one)(u_p)


def _nonlinear_stiffness_function(sample, scene, rotations, *, tol, linear_tol, maxiter, newton_maxiter, load_steps,
                                  contact_skin, slip, preconditioner, aggregate_size):
    from jaxbpm.dsm.boundary import contact_candidates
    from jaxbpm.dsm.newton import newton_outputs, newton_problem, newton_program
    from jaxbpm.dsm.scene import boundary_inputs, wall_touching

    model, free_np, fixed, driven, u_p, walls, (_, _, delta) = boundary_inputs(sample, scene, rotations)
    pairs = None
    if scene.contacts:
        skin = 0.5 * float(np.mean(sample.radii)) if contact_skin is None else float(contact_skin)
        pairs = contact_candidates(sample, model, skin)
    _check_held(sample, model, free_np, fixed | driven, pairs, wall_touching(sample, scene, delta))
    dtype = model.positions0.dtype
    prob = newton_problem(model, jnp.asarray(free_np), jnp.asarray(u_p, dtype), pairs, walls, scene, maxiter,
                          newton_maxiter, driven, delta, preconditioner, aggregate_size, slip)
    fractions = tuple(float(f) for f in np.arange(1, load_steps + 1) / load_steps)
    disp = np.asarray(fractions) * delta
    sel = np.flatnonzero(scene.fit_mask(disp, delta))
    if len(sel) < 2 and load_steps > 1:
        raise SceneError("too few load steps in the scene's fit_range to fit a stiffness; raise load_steps")
    tols = (jnp.asarray(tol, dtype), jnp.asarray(linear_tol, dtype))

    def slope(reactions):
        if load_steps == 1:
            return reactions[-1] / delta
        x, y = jnp.asarray(disp[sel], dtype), reactions[sel]
        xc = x - jnp.mean(x)
        return jnp.sum(xc * (y - jnp.mean(y))) / jnp.sum(xc * xc)

    def stiffness(params):
        if not traced(params):
            out = newton_program(prob, strong(params), *tols, fractions=fractions, stiffness_tol=None)[0]
        else:
            out = newton_outputs(prob, params, *tols, fractions=fractions)
        return slope(out[1])

    return stiffness

