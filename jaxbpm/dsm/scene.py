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
from jaxbpm.dsm.boundary import (
    _check_contact_skin, _check_held, affine_field, contact_candidates, free_mask, LINEAR_REACH)
from jaxbpm.dsm.linear import (
    _bond_forces_at, _energy_test, _linear_stiffness_tol, _report_convergence, _solve_linear, contacts_program,
    pad_candidates, with_geometric_correction)
from jaxbpm.dsm.newton import _newton
from jaxbpm.dsm.preconditioner import _coarse_for, bond_geometry
from jaxbpm.errors import SceneError
from jaxbpm.scenes import lateral_stats


def boundary_inputs(sample, scene, rotations=None):
    """What a static solve of ``scene`` needs of the boundary: ``(model, free [n, nd], fixed [n], driven [n],
    u_p [n, nd], walls, (length, area, delta))`` -- the bonds' model, the free DOFs and the clamped layers, the
    prescribed DOFs at full load (the driven layer moved by ``delta = strain * length`` against the axis), the
    walls at full load ``(points [W, 3], normals [W, 3])`` or ``None``, and the gauge length, area and
    displacement."""
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
    """``[n]``: the particles within half a mean radius (plus the load's travel ``delta``) of either wall, which the
    walls hold; ``None`` without walls."""
    if not scene.uses_walls:
        return None
    ax = scene.axis
    pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
    reach = float(np.mean(rad)) * 0.5 + delta
    return ((pos[:, ax] - rad) <= (pos[:, ax] - rad).min() + reach) | (
        (pos[:, ax] + rad) >= (pos[:, ax] + rad).max() - reach)


def solve_scene(sample, scene, params, *, dofs=None, nonlinear=None, tol=None, linear_tol=1e-6, maxiter=None,
                newton_maxiter=30, stiffness_tol="auto", contact_skin=None, load_steps=4, throw=True,
                operator="auto", preconditioner="auto", aggregate_size=None, slip=True, contact_fraction=None,
                contact_passes=2, pad=True, geometric_correction=False, _auto_skin=None):
    """Solve a :class:`~jaxbpm.scenes.UniaxialCompression` statically. See :func:`jaxbpm.solve`.

    pad: the linear bonds-only solve pads the sample to its size class (:func:`jaxbpm._compile.size_class`: held
    padding particles joined by bonds of zero stiffness), so that samples of similar size share one compiled
    program; the result is the same to round-off. Its setup (model, coarse space, bond geometry) is kept for the
    last few samples solved (:class:`jaxbpm._compile.SetupCache`): solving one sample again costs the solve alone.
    geometric_correction: the linear bonds-only solve's stiffness corrected for the bonds' geometric nonlinearity
    (:func:`jaxbpm.dsm.linear.geometric_stiffness`: the exact bond law's work along the linear displacement field,
    second-order accurate; a few force evaluations after the solve).
    """
    arguments = dict(locals())  # for a second try with a wider contact reach
    from jaxbpm.physics.model import default_params
    from jaxbpm.result import Result, settle

    t0 = time.perf_counter()
    if params is not None:  # (one compiled program whatever the parameters' array form)
        params = strong(params)
    rotations = None if dofs is None else {3: False, 6: True}.get(int(dofs))
    if dofs is not None and rotations is None:
        raise SceneError(f"dofs must be 3 or 6 per particle, got {dofs!r}")
    if nonlinear is None:
        nonlinear = bool(scene.contacts or scene.uses_walls)
    if geometric_correction and (nonlinear or scene.contacts or scene.uses_walls):
        raise SceneError("geometric_correction corrects the linear DSM on bonds alone between clamped layers "
                         "(nonlinear=False, no contacts, no walls); the nonlinear DSM solves the geometric "
                         "nonlinearity itself")
    if not nonlinear and not scene.contacts and not scene.uses_walls:
        stiffness_tol = _linear_stiffness_tol(stiffness_tol)
        setup_options = dict(rotations=rotations, operator=operator, preconditioner=preconditioner,
                             aggregate_size=aggregate_size, pad=pad)
        result = _solve_linear(sample, scene, params, linear_tol=linear_tol, maxiter=maxiter,
                               stiffness_tol=stiffness_tol, throw=throw, t0=t0, **setup_options)
        if geometric_correction:
            result = with_geometric_correction(result, sample, scene, params, **setup_options)
        return result
    if isinstance(stiffness_tol, str) and stiffness_tol == "auto":  # the default of the linear bonds-only solve
        stiffness_tol = None
    if scene.uses_walls and not nonlinear:
        raise SceneError("a scene with walls needs the nonlinear DSM (walls are contacts); use nonlinear=True")
    params = default_params(sample) if params is None else params
    model, free_np, fixed, driven, u_p, walls, (length, area, delta) = boundary_inputs(sample, scene, rotations)
    clamped = fixed | driven
    nd = free_np.shape[1]
    ax = scene.axis
    frac = None
    if scene.contacts and not nonlinear:
        # the linear solve takes the contact candidates as springs linearised at `contact_fraction` of the target
        # strain (the middle of the fit range by default): first at the affine displacement field, then
        # (`contact_passes` - 1 times) at the previous solution, which puts the overlaps where the sample's
        # non-affine motion puts them
        if operator not in ("auto", "jacobians"):
            raise SceneError("linearised contacts need operator='jacobians' (or 'auto')")
        frac = float(np.mean(scene.fit_range)) if contact_fraction is None else float(contact_fraction)
        if not (0 < frac <= 1):
            raise SceneError(f"contact_fraction must lie in (0, 1], got {contact_fraction!r}")
        if int(contact_passes) < 1:
            raise SceneError(f"contact_passes must be at least 1, got {contact_passes!r}")
    pairs = lin = None
    if scene.contacts:
        skin = contact_skin if _auto_skin is None else _auto_skin
        widest_skin = 0.5 * float(np.mean(sample.radii))  # the default reach, and the most the linear path widens to
        if skin is None:
            # the linearised contacts only see the state at `contact_fraction` of the strain: four times the affine
            # approach of two touching mean-sized particles there (0.1 mean radii at 2 % strain); it doubles while a
            # touching pair comes near it (below)
            skin = widest_skin if frac is None else min(
                widest_skin, LINEAR_REACH * frac * scene.strain * 2.0 * float(np.mean(sample.radii)))
        pairs = contact_candidates(sample, model, skin)
        if frac is not None:
            lin = [put(pairs, np.int32), affine_field(sample, model, ax, delta),
                   jnp.asarray(frac, model.positions0.dtype), None]
    _check_held(sample, model, free_np, clamped, pairs, wall_touching(sample, scene, delta))
    free = jnp.asarray(free_np)
    u_p = jnp.asarray(u_p, model.positions0.dtype)

    stats = {"dofs": nd, "nonlinear": nonlinear, "free_dofs": int(free_np.sum())}
    tc = time.perf_counter()
    if not nonlinear:
        springs = model if lin is None else dataclasses.replace(model, bonds=jnp.concatenate([model.bonds, lin[0]]))
        if lin is not None:
            stats.update(contact_candidates=int(lin[0].shape[0]), contact_fraction=frac,
                         contact_passes=int(contact_passes))
        coarse = _coarse_for(springs, free_np, preconditioner, aggregate_size)
        if lin is not None and coarse is not None:
            # one coarse space (its aggregates do not depend on the springs): the bonds' part of the coarse matrix
            # comes from the bond geometry, the contacts' part is assembled from the pairs that couple its modes
            nb, cb = model.bonds.shape[0], np.asarray(coarse.bonds)
            lin[3] = dataclasses.replace(coarse, bonds=put(cb[cb >= nb] - nb, np.int32))
            coarse = dataclasses.replace(coarse, bonds=put(cb[cb < nb], np.int32))
        lin = None if lin is None else tuple(pad_candidates(lin, sample, ax))
        geometry = None
        if operator in ("auto", "jacobians"):
            # parameter-independent, once per sample: the bond Jacobians and the preconditioner's parts per unit
            # modulus (BondGeometry); its own compilation on a new size is part of this time
            geometry = jax.block_until_ready(bond_geometry(
                model, coarse, n_materials=int(jnp.shape(params["bond_E"])[0])))
        stats["setup_time"] = time.perf_counter() - tc
        # CG starts from the affine field of the prescribed strain (the linearised contacts' first pass too)
        guess = None if lin is not None else affine_field(sample, model, ax, delta)
        (u, force_total, force_boundary, res, iterations), compile_time, run_time = contacts_program(
            model, params, free, u_p, linear_tol, _energy_test(stiffness_tol), coarse, lin, geometry, guess,
            maxiter=maxiter, operator=operator, contact_passes=int(contact_passes))
        res, iterations = float(res), int(iterations)
        limit = 10 * int(free_np.size) if maxiter is None else int(maxiter)
        # converged: the residual test, or (with stiffness_tol) the energy test before the iteration limit
        converged = res <= linear_tol * 1.01 or (stiffness_tol is not None and iterations < limit)
        stats.update(residual=res, residual_history=[res], converged=converged, iterations=iterations,
                     operator=operator, stiffness_tol=stiffness_tol,
                     preconditioner="jacobi" if coarse is None else "two-level",
                     aggregates=0 if coarse is None else coarse.count,
                     stiffness_boundary=float(force_boundary) / delta)
        reaction = float(force_total)
        if lin is not None and _check_contact_skin(sample, pairs, frac * np.asarray(u)[:, :3], skin, stats):
            if contact_skin is None and skin < widest_skin:
                # the default reach was too short for this sample's motion: again with twice the reach, the time
                # spent on this try counted in
                spent = time.perf_counter() - t0  # this try
                again = solve_scene(**{**arguments, "_auto_skin": min(widest_skin, 2.0 * skin)})
                retries = again.stats.get("contact_skin_retries", 0) + 1
                return dataclasses.replace(
                    again, wall_time=again.wall_time + spent, run_time=again.run_time + run_time,
                    compile_time=again.compile_time + compile_time,
                    setup_time=again.setup_time + max(spent - run_time - compile_time, 0.0),
                    stats={**again.stats, "contact_skin_retries": retries})
            warnings.warn(f"linearised contacts: a pair {stats['contact_gap_max']:.3g} m apart at rest touches at "
                          f"the linearisation state, near the candidate reach (contact_skin {skin:.3g} m): pairs "
                          f"beyond it may touch too; pass a larger contact_skin", stacklevel=3)
    else:
        tol = 1e-3 if tol is None else tol
        u, disps, forces, info, compile_time, run_time = _newton(
            model, params, free, u_p, pairs, walls, scene, tol, linear_tol, maxiter, newton_maxiter, stiffness_tol,
            driven, delta, load_steps, preconditioner, aggregate_size, slip)
        converged = info["converged"]
        stats.update(info)
    _report_convergence(stats, converged, stats["residual"], tol if nonlinear else linear_tol)
    if nonlinear:
        # the same measure as the DEM: least-squares slope of the load steps within the scene's fit range
        stiffness = scene.fit_stiffness(disps, forces, delta) if load_steps > 1 else float(forces[-1] / delta)
        disps, forces = np.concatenate([[0.0], disps]), np.concatenate([[0.0], forces])
    else:
        stiffness = reaction / delta
        disps, forces = np.array([0.0, delta]), np.array([0.0, reaction])
    stats.update(bond_forces=_bond_forces_at(dataclasses.replace(model, walls=None), params, u))
    stats.update(lateral_stats(scene, sample, u))
    wall = time.perf_counter() - t0
    # everything but the solver's compilation and run (model, candidates, geometry, Newton's host loop) is setup
    return settle(Result(method="dsm", stiffness=stiffness, youngs_modulus=stiffness * length / area,
                         gauge_length=length, area=area, displacement=disps, force=forces, wall_time=wall,
                         setup_time=max(wall - compile_time - run_time, 0.0), compile_time=compile_time,
                         run_time=run_time, stats=stats, state=u), throw)
