"""The DSM on a :class:`~jaxbpm.scenes.UniaxialCompression` scene (:func:`solve_scene`, what ``jaxbpm.solve(...,
method="dsm")`` runs): it picks the linear or the nonlinear solve and reports a :class:`~jaxbpm.result.Result`.
"""

from __future__ import annotations

import dataclasses
import time
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm._compile import put, strong
from jaxbpm._geometry import check_three_d
from jaxbpm.dsm.boundary import (
    _check_contact_skin, _check_held, affine_field, contact_candidates, free_mask, LINEAR_REACH)
from jaxbpm.dsm.linear import (
    _bond_forces_at, _energy_test, _linear_stiffness_tol, _report_convergence, _solve_linear, contacts_program,
    pad_candidates, with_geometric_correction)
from jaxbpm.dsm.newton import _newton
from jaxbpm.dsm.options import DSM
from jaxbpm.dsm.preconditioner import _coarse_for, bond_geometry
from jaxbpm.errors import SceneError
from jaxbpm.physics.model import default_params
from jaxbpm.result import settle, timed_result
from jaxbpm.scenes import lateral_stats


def boundary_inputs(sample, scene, rotations=None):
    """What a static solve of ``scene`` needs of the boundary.

    Args:
      sample: the bonded sample.
      scene: the scene.
      rotations: rotational DOFs (``None``: the model's choice).

    Returns:
      ``(model, free [n, nd], fixed [n], driven [n], u_p [n, nd], walls, (length, area, delta))``: the bonds'
      model, the free DOFs and the clamped layers, the prescribed DOFs at full load (the driven layer moved by
      ``delta = strain * length`` against the axis), the walls at full load ``(points [W, 3], normals [W, 3])`` or
      ``None``, and the gauge length, area and displacement.
    """
    model = scene.model(sample, rotations=rotations, contacts=False)
    length, area = scene.geometry(sample)
    delta = scene.strain * length
    free_np, fixed, driven = free_mask(model, scene, sample)
    u_p = np.zeros(free_np.shape)
    u_p[driven, scene.axis] = -delta
    walls = None
    if scene.uses_walls:
        load = scene.loading(sample, speed=1.0)
        walls = (load.wall_points0 + load.wall_velocity * delta, load.wall_normals)  # top wall moved by delta
    return model, free_np, fixed, driven, u_p, walls, (length, area, delta)


def wall_touching(sample, scene, delta):
    """The particles the walls hold.

    Args:
      sample: the bonded sample.
      scene: the scene.
      delta: the load's travel [m].

    Returns:
      ``[n]`` the particles within half a mean radius (plus ``delta``) of either wall; ``None`` without walls.
    """
    if not scene.uses_walls:
        return None
    ax = scene.axis
    pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
    reach = float(np.mean(rad)) * 0.5 + delta
    return ((pos[:, ax] - rad) <= (pos[:, ax] - rad).min() + reach) | (
        (pos[:, ax] + rad) >= (pos[:, ax] + rad).max() - reach)


def solve_scene(sample, scene, params=None, options: DSM | None = None):
    """Solve ``scene`` (a :class:`~jaxbpm.scenes.UniaxialCompression`) statically with the DSM.

    The linear bonds-only solve between clamped layers (:func:`jaxbpm.dsm.linear._solve_linear`: setup kept per
    sample, one compiled program per size class); linearised contacts (``nonlinear=False`` on a scene with
    contacts: one compiled program over the contact passes, the contact reach widened and the solve repeated while a
    touching pair lies near it); or Newton over load steps (:func:`jaxbpm.dsm.newton._newton`).

    Args:
      sample: the bonded sample.
      scene: the scene.
      params: parameters checked by :func:`jaxbpm.physics.model.check_params` (``None``: the sample's own).
      options: the :class:`~jaxbpm.dsm.options.DSM` options (``None``: the defaults).

    Returns:
      The :class:`~jaxbpm.result.Result` (``state``: the displacements ``[n, dofs]``).

    Raises:
      SceneError: options that do not fit the scene, or a sample whose free part is not held.
      ConvergenceError: with ``options.throw``, a solve that missed its tolerance.
    """
    options = DSM() if options is None else options
    t0 = time.perf_counter()
    if params is not None:  # (one compiled program whatever the parameters' array form)
        params = strong(params)
    if sample.dim == 2:
        return _plane(sample, scene, params, options, t0)
    rotations, nonlinear = _modes(scene, options)
    if not nonlinear and not scene.contacts and not scene.uses_walls:
        return _bonds_linear(sample, scene, params, options, rotations, t0)
    stiffness_tol = options.stiffness_tol
    if isinstance(stiffness_tol, str) and stiffness_tol == "auto":  # the default of the linear bonds-only solve
        stiffness_tol = None
    if scene.uses_walls and not nonlinear:
        raise SceneError("a scene with walls needs the nonlinear DSM (walls are contacts); use nonlinear=True")
    params = default_params(sample) if params is None else params
    if nonlinear:
        return _solve_try(sample, scene, params, options, rotations, stiffness_tol, None, t0)[0]
    return _linearised_contacts(sample, scene, params, options, rotations, stiffness_tol, t0)


def _plane(sample, scene, params, options: DSM, t0):
    """The DSM of a two-dimensional sample: the linear bonds-only solve between clamped layers, 3 DOF per disc
    (u_x, u_y, theta), block-Jacobi preconditioned (the coarse space of aggregates' rigid modes is 3D)."""
    if scene.contacts or scene.uses_walls or options.nonlinear or options.geometric_correction:
        check_three_d(sample, "the DSM with contacts, walls, nonlinear=True or geometric_correction")
    if options.dofs is not None:
        raise SceneError("dofs counts the DOF of a sphere (3 or 6); a disc of a 2D sample has 3 (u_x, u_y, theta): "
                         "leave dofs=None")
    return _bonds_linear(sample, scene, params, options, None, t0)


def _modes(scene, options: DSM):
    """``(rotations, nonlinear)`` of a solve: rotations from ``dofs`` (``None``: the model's choice), ``nonlinear``
    by default on a scene with contacts or walls; ``geometric_correction`` checked against them."""
    rotations = None if options.dofs is None else {3: False, 6: True}.get(int(options.dofs))
    if options.dofs is not None and rotations is None:
        raise SceneError(f"dofs must be 3 or 6 per particle, got {options.dofs!r}")
    nonlinear = bool(scene.contacts or scene.uses_walls) if options.nonlinear is None else options.nonlinear
    if options.geometric_correction and (nonlinear or scene.contacts or scene.uses_walls):
        raise SceneError("geometric_correction corrects the linear DSM on bonds alone between clamped layers "
                         "(nonlinear=False, no contacts, no walls); the nonlinear DSM solves the geometric "
                         "nonlinearity itself")
    return rotations, nonlinear


def _bonds_linear(sample, scene, params, options: DSM, rotations, t0):
    """The linear bonds-only solve (and its geometric correction where asked)."""
    setup_options = dict(rotations=rotations, operator=options.operator, preconditioner=options.preconditioner,
                         aggregate_size=options.aggregate_size, pad=options.pad)
    result = _solve_linear(sample, scene, params, linear_tol=options.linear_tol, maxiter=options.maxiter,
                           stiffness_tol=_linear_stiffness_tol(options.stiffness_tol), throw=options.throw, t0=t0,
                           **setup_options)
    if options.geometric_correction:
        result = with_geometric_correction(result, sample, scene, params, **setup_options)
    return result


def _linearised_contacts(sample, scene, params, options: DSM, rotations, stiffness_tol, t0):
    """The linear solve with linearised contacts. With the default reach, a touching pair near it doubles the reach
    (up to half a mean radius) and solves again; the earlier tries' times count in the result."""
    skin, spent = None, []
    while True:
        result, wider = _solve_try(sample, scene, params, options, rotations, stiffness_tol, skin, t0)
        if wider is None:
            break
        spent.append((time.perf_counter() - t0,) + wider[1:])  # this try: wall, run and compile time
        skin, t0 = wider[0], time.perf_counter()
    for wall, run_time, compile_time in reversed(spent):
        result = dataclasses.replace(
            result, wall_time=result.wall_time + wall, run_time=result.run_time + run_time,
            compile_time=result.compile_time + compile_time,
            setup_time=result.setup_time + max(wall - run_time - compile_time, 0.0),
            stats={**result.stats, "contact_skin_retries": result.stats.get("contact_skin_retries", 0) + 1})
    return result


def _contact_fraction(scene, options: DSM, nonlinear):
    """The strain fraction at which the linear solve linearises the contacts (``None``: nonlinear or no
    contacts)."""
    if not scene.contacts or nonlinear:
        return None
    # the linear solve takes the contact candidates as springs linearised at `contact_fraction` of the target
    # strain (the middle of the fit range by default): first at the affine displacement field, then
    # (`contact_passes` - 1 times) at the previous solution, which puts the overlaps where the sample's non-affine
    # motion puts them
    if options.operator not in ("auto", "jacobians"):
        raise SceneError("linearised contacts need operator='jacobians' (or 'auto')")
    frac = float(np.mean(scene.fit_range)) if options.contact_fraction is None else float(options.contact_fraction)
    if not (0 < frac <= 1):
        raise SceneError(f"contact_fraction must lie in (0, 1], got {options.contact_fraction!r}")
    return frac


def _contact_skin(sample, scene, options: DSM, frac, skin):
    """``(skin, widest)``: the contact reach of this try [m] and the most the linear path widens it to."""
    widest = 0.5 * float(np.mean(sample.radii))  # the default reach, and the most the linear path widens to
    skin = options.contact_skin if skin is None else skin
    if skin is None:
        # the linearised contacts only see the state at `contact_fraction` of the strain: four times the affine
        # approach of two touching mean-sized particles there (0.1 mean radii at 2 % strain); it doubles while a
        # touching pair comes near it
        skin = widest if frac is None else min(
            widest, LINEAR_REACH * frac * scene.strain * 2.0 * float(np.mean(sample.radii)))
    return skin, widest


def _solve_try(sample, scene, params, options: DSM, rotations, stiffness_tol, skin, t0):
    """One solve with linearised contacts or Newton's: ``(result, None)``, or ``(None, (wider skin, run_time,
    compile_time))`` where the default reach was too short for this sample's motion."""
    nonlinear = _modes(scene, options)[1]
    model, free_np, fixed, driven, u_p, walls, (length, area, delta) = boundary_inputs(sample, scene, rotations)
    frac = _contact_fraction(scene, options, nonlinear)
    pairs = lin = None
    if scene.contacts:
        skin, widest = _contact_skin(sample, scene, options, frac, skin)
        pairs = contact_candidates(sample, model, skin)
        if frac is not None:
            lin = [put(pairs, np.int32), affine_field(sample, model, scene.axis, delta),
                   jnp.asarray(frac, model.positions0.dtype), None]
    _check_held(sample, model, free_np, fixed | driven, pairs, wall_touching(sample, scene, delta))
    free = jnp.asarray(free_np)
    u_p = jnp.asarray(u_p, model.positions0.dtype)
    stats = {"dofs": free_np.shape[1], "nonlinear": nonlinear, "free_dofs": int(free_np.sum())}
    if nonlinear:
        u, disps, forces, info, compile_time, run_time = _newton(
            model, params, free, u_p, pairs, walls, scene, 1e-3 if options.tol is None else options.tol,
            options.linear_tol, options.maxiter, options.newton_maxiter, stiffness_tol, driven, delta,
            options.load_steps, options.preconditioner, options.aggregate_size, options.slip)
        stats.update(info)
        _report_convergence(stats, info["converged"], stats["residual"],
                            1e-3 if options.tol is None else options.tol)
        # the same measure as the DEM: least-squares slope of the load steps within the scene's fit range
        stiffness = scene.fit_stiffness(disps, forces, delta) if options.load_steps > 1 else float(forces[-1] / delta)
        disps, forces = np.concatenate([[0.0], disps]), np.concatenate([[0.0], forces])
    else:
        u, reaction, compile_time, run_time = _linear_run(sample, scene, model, params, free, free_np, u_p, lin,
                                                          options, stiffness_tol, frac, delta, stats)
        if lin is not None and _check_contact_skin(sample, pairs, frac * np.asarray(u)[:, :3], skin, stats):
            if options.contact_skin is None and skin < widest:
                return None, (min(widest, 2.0 * skin), run_time, compile_time)
            warnings.warn(f"linearised contacts: a pair {stats['contact_gap_max']:.3g} m apart at rest touches at "
                          f"the linearisation state, near the candidate reach (contact_skin {skin:.3g} m): pairs "
                          f"beyond it may touch too; pass a larger contact_skin", stacklevel=6)
        _report_convergence(stats, stats["converged"], stats["residual"], options.linear_tol)
        stiffness = reaction / delta
        disps, forces = np.array([0.0, delta]), np.array([0.0, reaction])
    stats.update(bond_forces=_bond_forces_at(dataclasses.replace(model, walls=None), params, u))
    stats.update(lateral_stats(scene, sample, u))
    # everything but the solver's compilation and run (model, candidates, geometry, Newton's host loop) is setup
    return settle(timed_result("dsm", t0, stiffness=stiffness, gauge_length=length, area=area, displacement=disps,
                               force=forces, compile_time=compile_time, run_time=run_time, stats=stats, state=u),
                  options.throw), None


def _linear_run(sample, scene, model, params, free, free_np, u_p, lin, options: DSM, stiffness_tol, frac, delta,
                stats):
    """The linear solve's setup (springs, coarse space, bond geometry) and run: ``(u, reaction, compile_time,
    run_time)``; ``stats`` gets the setup time, the convergence and the solver's details."""
    tc = time.perf_counter()
    springs = model if lin is None else dataclasses.replace(model, bonds=jnp.concatenate([model.bonds, lin[0]]))
    if lin is not None:
        stats.update(contact_candidates=int(lin[0].shape[0]), contact_fraction=frac,
                     contact_passes=int(options.contact_passes))
    coarse = _coarse_for(springs, free_np, options.preconditioner, options.aggregate_size)
    if lin is not None and coarse is not None:
        # one coarse space (its aggregates do not depend on the springs): the bonds' part of the coarse matrix
        # comes from the bond geometry, the contacts' part is assembled from the pairs that couple its modes
        nb, cb = model.bonds.shape[0], np.asarray(coarse.bonds)
        lin[3] = dataclasses.replace(coarse, bonds=put(cb[cb >= nb] - nb, np.int32))
        coarse = dataclasses.replace(coarse, bonds=put(cb[cb < nb], np.int32))
    lin = None if lin is None else tuple(pad_candidates(lin, sample, scene.axis))
    geometry = None
    if options.operator in ("auto", "jacobians"):
        # parameter-independent, once per sample: the bond Jacobians and the preconditioner's parts per unit
        # modulus (BondGeometry); its own compilation on a new size is part of this time
        geometry = jax.block_until_ready(bond_geometry(
            model, coarse, n_materials=int(jnp.shape(params["bond_E"])[0])))
    stats["setup_time"] = time.perf_counter() - tc
    # CG starts from the affine field of the prescribed strain (the linearised contacts' first pass too)
    guess = None if lin is not None else affine_field(sample, model, scene.axis, delta)
    (u, force_total, force_boundary, res, iterations), compile_time, run_time = contacts_program(
        model, params, free, u_p, options.linear_tol, _energy_test(stiffness_tol), coarse, lin, geometry, guess,
        maxiter=options.maxiter, operator=options.operator, contact_passes=int(options.contact_passes))
    res, iterations = float(res), int(iterations)
    limit = 10 * int(free_np.size) if options.maxiter is None else int(options.maxiter)
    # converged: the residual test, or (with stiffness_tol) the energy test before the iteration limit
    converged = res <= options.linear_tol * 1.01 or (stiffness_tol is not None and iterations < limit)
    stats.update(residual=res, residual_history=[res], converged=converged, iterations=iterations,
                 operator=options.operator, stiffness_tol=stiffness_tol,
                 preconditioner="jacobi" if coarse is None else "two-level",
                 aggregates=0 if coarse is None else coarse.count, stiffness_boundary=float(force_boundary) / delta)
    return u, float(force_total), compile_time, run_time
