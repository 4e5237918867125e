"""Pure functions of the parameters: the stiffness of a scene (``jit``, ``grad``, ``vmap``) and several load cases on
one operator.
"""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm._compile import strong, traced
from jaxbpm.dsm.boundary import _check_held, free_mask
from jaxbpm.dsm.krylov import cg, tangent_operator
from jaxbpm.dsm.linear import (
    _energy_test, _linear_setup, _linear_setups, _linear_stiffness_tol, linear_jit, linear_program)
from jaxbpm.dsm.options import DSM
from jaxbpm.dsm.preconditioner import _coarse_for, bond_geometry, build_preconditioner
from jaxbpm.errors import OptionsError, SceneError


#: the keywords ``stiffness_function`` took before it took the DSM's options -> the :class:`DSM` field each sets
_OLD_KEYWORDS = {"dofs": "dofs", "tol": "linear_tol", "maxiter": "maxiter", "operator": "operator",
                 "stiffness_tol": "stiffness_tol", "preconditioner": "preconditioner",
                 "aggregate_size": "aggregate_size", "pad": "pad", "nonlinear_tol": "tol",
                 "newton_maxiter": "newton_maxiter", "load_steps": "load_steps", "contact_skin": "contact_skin",
                 "slip": "slip"}


def _options_from(options: DSM | None, old: dict) -> DSM:
    """``options`` (``None``: the defaults) with the deprecated keywords ``old`` mapped onto its fields, each with a
    :class:`DeprecationWarning` naming the field."""
    options = DSM() if options is None else options
    if not isinstance(options, DSM):
        raise OptionsError(f"stiffness_function takes jaxbpm.DSM options, got {type(options).__name__}")
    unknown = sorted(set(old) - set(_OLD_KEYWORDS))
    if unknown:
        raise TypeError(f"stiffness_function() got an unexpected keyword argument {unknown[0]!r}")
    for name in old:
        field = _OLD_KEYWORDS[name]
        warnings.warn(f"stiffness_function({name}=...) is deprecated and will be removed in the next release; pass "
                      f"the options object: stiffness_function(sample, scene, jaxbpm.DSM({field}=...))",
                      DeprecationWarning, stacklevel=3)
    return options.replace(**{_OLD_KEYWORDS[k]: v for k, v in old.items()}) if old else options


def stiffness_function(sample, scene, options: DSM | None = None, *, n_materials: int | None = None, **deprecated):
    """A pure function ``params -> K`` [N/m] of the DSM on ``scene``: the linear solve (clamped layers, bonds
    only), or with contacts or walls the nonlinear one (:func:`jaxbpm.dsm.newton.newton_outputs`: Newton over
    ``options.load_steps`` load steps to ``options.tol``, K the least-squares slope over the scene's fit range, as
    :func:`jaxbpm.solve` reports it). ``params`` may then also hold ``contact_E`` and ``contact_nu`` (Hertz-Mindlin),
    or ``contact_emod``, ``contact_kratio`` and ``friction`` (the linear law).

    It can be ``jit``-ed, differentiated (``jax.grad``: implicit differentiation through the CG solve) and
    ``vmap``-ped over parameter sets, e.g. ``jax.vmap(f)({"bond_E": E_batch, "bond_nu": nu_batch})``. A call with
    concrete parameters runs the program :func:`solve_scene` compiles (none is compiled when the process solved a
    sample of that class with these options before); a traced call (``jit``, ``grad``, ``vmap``) traces the solve.
    The nonlinear solve's gradient is implicit (the implicit function theorem at each load step's equilibrium), so
    it holds to the tolerance the equilibrium is solved to: pass a tight ``tol`` (e.g. ``DSM(tol=1e-10)``) for
    gradients.

    The options read: ``dofs``, ``linear_tol``, ``maxiter``, ``operator``, ``stiffness_tol`` (linear solve),
    ``preconditioner``, ``aggregate_size``, ``pad`` (linear solve: pad the sample to its size class, same values to
    round-off, so that samples of one class share compilations); nonlinear: ``tol``, ``newton_maxiter``,
    ``load_steps``, ``contact_skin``, ``slip``. ``throw`` does not apply (no status); ``nonlinear`` must match the
    scene (or be ``None``), and ``geometric_correction`` and the linearised contacts are :func:`solve_scene`'s.

    Args:
      sample: the bonded sample.
      scene: the scene (e.g. a :class:`~jaxbpm.scenes.UniaxialCompression`).
      options: the :class:`~jaxbpm.dsm.options.DSM` options (``None``: the defaults).
      n_materials: the length of ``params["bond_E"]`` (``None``: the sample's material count).
      **deprecated: the former keywords, each mapped onto a field of ``options`` with a
        :class:`DeprecationWarning`: ``tol`` is ``linear_tol``, ``nonlinear_tol`` is ``tol``, the others
        (``dofs``, ``maxiter``, ``operator``, ``stiffness_tol``, ``preconditioner``, ``aggregate_size``, ``pad``,
        ``newton_maxiter``, ``load_steps``, ``contact_skin``, ``slip``) keep their names.

    Returns:
      ``stiffness(params) -> K``.

    Raises:
      OptionsError: ``options`` is not a :class:`DSM`, or asks for what the function does not compute
        (``geometric_correction``, ``nonlinear`` other than the scene's).
      TypeError: an unknown keyword.
    """
    options = _options_from(options, deprecated)
    nonlinear = bool(scene.uses_walls or scene.contacts)
    if options.geometric_correction or options.nonlinear not in (None, nonlinear):
        raise OptionsError("stiffness_function computes the scene's own solve (linear for bonds only with clamped "
                           "layers, else nonlinear) without geometric_correction; use jaxbpm.dsm.solve_scene")
    rotations = None if options.dofs is None else {3: False, 6: True}[int(options.dofs)]
    if nonlinear:
        return _nonlinear_stiffness_function(sample, scene, rotations, options)
    tol, maxiter, operator = options.linear_tol, options.maxiter, options.operator
    stiffness_tol = _linear_stiffness_tol(options.stiffness_tol)
    m = sample.n_materials if n_materials is None else int(n_materials)
    key = (scene, rotations, operator, options.preconditioner, options.aggregate_size, m, bool(options.pad))
    setup = _linear_setups.get(sample, key, lambda: _linear_setup(sample, scene, rotations, operator,
                                                                   options.preconditioner, options.aggregate_size, m,
                                                                   options.pad))

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


def _nonlinear_stiffness_function(sample, scene, rotations, options: DSM):
    """``params -> K`` of the nonlinear solve (contacts or walls) with ``options`` (see :func:`stiffness_function`)."""
    from jaxbpm.dsm.boundary import contact_candidates
    from jaxbpm.dsm.newton import newton_outputs, newton_problem, newton_program
    from jaxbpm.dsm.scene import boundary_inputs, wall_touching

    load_steps, skin = options.load_steps, options.contact_skin
    model, free_np, fixed, driven, u_p, walls, (_, _, delta) = boundary_inputs(sample, scene, rotations)
    pairs = None
    if scene.contacts:
        skin = 0.5 * float(np.mean(sample.radii)) if skin is None else float(skin)
        pairs = contact_candidates(sample, model, skin)
    _check_held(sample, model, free_np, fixed | driven, pairs, wall_touching(sample, scene, delta))
    dtype = model.positions0.dtype
    prob = newton_problem(model, jnp.asarray(free_np), jnp.asarray(u_p, dtype), pairs, walls, scene,
                          options.maxiter, options.newton_maxiter, driven, delta, options.preconditioner,
                          options.aggregate_size, options.slip)
    fractions = tuple(float(f) for f in np.arange(1, load_steps + 1) / load_steps)
    disp = np.asarray(fractions) * delta
    sel = np.flatnonzero(scene.fit_mask(disp, delta))
    if len(sel) < 2 and load_steps > 1:
        raise SceneError("too few load steps in the scene's fit_range to fit a stiffness; raise load_steps")
    tol = 1e-3 if options.tol is None else options.tol
    tols = (jnp.asarray(tol, dtype), jnp.asarray(options.linear_tol, dtype))

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

