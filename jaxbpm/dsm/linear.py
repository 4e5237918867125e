"""The linear DSM on a scene: the bonds-only solve (padded to a size class, one compiled program) and the linear solve
with linearised contacts.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm._compile import capacity, compile_clock, Program, put, SetupCache, size_class
from jaxbpm.dsm.boundary import _check_held, affine_field, free_mask
from jaxbpm.dsm.krylov import cg, tangent_operator
from jaxbpm.dsm.operator import _linearised_contact_jacobians, _packed_operator, internal_forces
from jaxbpm.dsm.preconditioner import _coarse_for, bond_geometry, build_preconditioner, CoarseSpace
from jaxbpm.physics.padding import pad_model, pad_rows
from jaxbpm.result import settle, timed_result


class _LinearSetup(NamedTuple):
    """What a linear bonds-only solve of one sample needs besides the parameters (built once per sample and options,
    possibly padded to a size class): the Model, the free-DOF mask and prescribed displacements ``[n, nd]``, the
    coarse space, the bond geometry and the first guess (the affine field); the real particle and bond counts, the
    free DOF count and the target displacement."""

    model: Any
    free: Any
    u_p: Any
    coarse: Any
    geometry: Any
    guess: Any
    n: int
    nb: int
    free_dofs: int
    delta: float


def _linear_setup(sample, scene, rotations, operator, preconditioner, aggregate_size, n_materials, pad):
    model = scene.model(sample, rotations=rotations, contacts=False)
    free_np, fixed, driven = free_mask(model, scene, sample)
    _check_held(sample, model, free_np, fixed | driven)
    nd = free_np.shape[1]
    length, _ = scene.geometry(sample)
    delta = scene.strain * length
    u_p = np.zeros((model.n, nd))
    u_p[driven, scene.axis] = -delta
    guess = np.asarray(affine_field(sample, model, scene.axis, delta))
    n, nb = model.n, int(model.bonds.shape[0])
    free_dofs = int(free_np.sum())
    flat = model.dim == 2  # discs: block-Jacobi on the reduced Jacobians (the coarse space and geometry are 3D)
    coarse = None if flat else _coarse_for(model, free_np, preconditioner, aggregate_size)
    if pad:
        n_cap, nb_cap, _ = size_class(n, nb)
        model = pad_model(model, n_cap, nb_cap)
        free_np, u_p, guess = pad_rows(free_np, n_cap, False), pad_rows(u_p, n_cap), pad_rows(guess, n_cap)
        coarse = None if coarse is None else _pad_coarse(coarse, n_cap, nb, nb_cap, aggregate_size)
    geometry = None
    if operator in ("auto", "jacobians") and not flat:
        geometry = bond_geometry(model, coarse, n_materials=n_materials)
    dtype = model.positions0.dtype
    return _LinearSetup(model=model, free=put(free_np), u_p=put(u_p, dtype), coarse=coarse,
                        geometry=geometry, guess=put(guess, dtype), n=n, nb=nb, free_dofs=free_dofs,
                        delta=delta)


def _pad_coarse(coarse: CoarseSpace, n_cap: int, nb: int, nb_cap: int, aggregate_size=None) -> CoarseSpace:
    """The coarse space of a model padded to ``n_cap`` particles and ``nb_cap`` bonds (bonds from ``nb`` on are
    padding). The padding particles form no mode (zero basis rows, in the last aggregate); the aggregate count
    rounds up to a capacity that depends on the size class alone (the aggregates of the default size
    that ``n_cap`` particles make, or more when the sample has more), empty aggregates getting a unit coarse
    diagonal; the coupling bonds are padded with the padding bond ``nb`` up to ``nb_cap`` (they are only read when
    the preconditioner's parts are built, once per sample)."""
    per = max(100.0, n_cap / 250.0) if aggregate_size is None else float(aggregate_size)
    count = capacity(max(coarse.count, math.ceil(n_cap / per)), minimum=4)
    labels = pad_rows(coarse.labels, n_cap, count - 1)
    basis = pad_rows(coarse.basis, n_cap, 0.0)
    bonds = pad_rows(coarse.bonds, nb_cap, nb)
    return CoarseSpace(labels=put(labels, np.int32),
                       basis=put(basis, coarse.basis.dtype),
                       bonds=put(bonds, np.int32), count=count)


def _linear_outputs(model, params, free, u_p, tol, stiffness_tol, coarse, geometry, guess, maxiter, operator):
    """One linear solve (:func:`_linear_fn`) and the bond forces at its solution."""
    out = _linear_fn(model, params, free, u_p, tol, maxiter, operator, stiffness_tol, coarse, geometry=geometry,
                     guess=guess)
    return out, internal_forces(model, params, out[0])[1]["bonds"]


linear_program = Program(_linear_outputs, static_argnames=("maxiter", "operator"))
_linear_setups = SetupCache()


def _setup_for(sample, scene, params, rotations, operator, preconditioner, aggregate_size, pad):
    """The sample's :class:`_LinearSetup` for these options (kept in ``_linear_setups``) and the seconds its own
    programs took to compile (0 when it was kept)."""
    n_materials = int(jnp.shape(params["bond_E"])[0])
    key = (scene, rotations, operator, preconditioner, aggregate_size, n_materials, bool(pad))
    with compile_clock() as setup_compile:  # programs the setup compiles count as compilation
        setup = _linear_setups.get(sample, key, lambda: _linear_setup(
            sample, scene, rotations, operator, preconditioner, aggregate_size, n_materials, pad))
    return setup, setup_compile.seconds


def _solve_linear(sample, scene, params, *, rotations, linear_tol, maxiter, stiffness_tol, throw, operator,
                  preconditioner, aggregate_size, pad, t0):
    """The linear DSM on a bonds-only scene with clamped layers (see :func:`solve_scene`): setup (kept per sample),
    one compiled program (per size class), one run."""
    from jaxbpm.physics.model import default_params
    from jaxbpm.scenes import lateral_stats

    params = default_params(sample) if params is None else params
    setup, setup_compile = _setup_for(sample, scene, params, rotations, operator, preconditioner, aggregate_size, pad)
    setup_time = time.perf_counter() - t0 - setup_compile
    ((u, force_total, force_boundary, res, iterations), bond_forces), compile_time, _ = linear_program(
        setup.model, params, setup.free, setup.u_p, linear_tol, _energy_test(stiffness_tol), setup.coarse,
        setup.geometry, setup.guess, maxiter=maxiter, operator=operator)
    compile_time += setup_compile
    n, nb, delta = setup.n, setup.nb, setup.delta
    res, iterations, reaction = float(res), int(iterations), float(force_total)
    u = np.asarray(u)[:n]
    limit = 10 * int(setup.free.size) if maxiter is None else int(maxiter)
    # converged: the residual test, or (with stiffness_tol) the energy test before the iteration limit
    converged = res <= linear_tol * 1.01 or (stiffness_tol is not None and iterations < limit)
    coarse = setup.coarse
    stats = {"dofs": int(setup.free.shape[1]), "nonlinear": False, "free_dofs": setup.free_dofs,
             "setup_time": setup_time, "residual": res, "residual_history": [res], "converged": converged,
             "iterations": iterations, "operator": operator, "stiffness_tol": stiffness_tol,
             "preconditioner": "jacobi" if coarse is None else "two-level",
             "aggregates": 0 if coarse is None else coarse.count,
             "stiffness_boundary": float(force_boundary) / delta,
             "size_class": [setup.model.n, int(setup.model.bonds.shape[0])],
             "bond_forces": jax.tree_util.tree_map(lambda a: np.asarray(a)[:nb], bond_forces)}
    _report_convergence(stats, converged, res, linear_tol)
    stats.update(lateral_stats(scene, sample, u))
    length, area = scene.geometry(sample)
    stiffness = reaction / delta
    # what is neither setup nor compilation (the run, moving its outputs to the host) is the run time
    return settle(timed_result("dsm", t0, stiffness=stiffness, gauge_length=length, area=area,
                               displacement=np.array([0.0, delta]), force=np.array([0.0, reaction]),
                               compile_time=compile_time, setup_time=setup_time, stats=stats, state=u), throw)


def _path_work(model, params, u, fractions):
    """``[L]``: the work rate ``f_int(s u) . u`` of the exact bond law's internal forces (all DOFs, moments with
    rotations) along the straight path ``s u`` at each load fraction ``s`` of ``fractions``, one fraction at a time
    (``lax.map``: one fraction's bond intermediates in memory)."""
    def work(s):
        return -jnp.sum(internal_forces(model, params, s * u)[0] * u)

    return jax.lax.map(work, jnp.asarray(fractions, u.dtype))


path_work_program = Program(_path_work, static_argnames=("fractions",))

#: load fractions of the geometric correction (within the scene's fit range): the nonlinear DSM's load steps
CORRECTION_POINTS = 4


def geometric_stiffness(sample, scene, params, u, *, rotations=None, operator="auto", preconditioner="auto",
                        aggregate_size=None, pad=True):
    """The stiffness of the bonds-only scene with the bonds' geometric nonlinearity, to second order, from the
    linear solution.

    The displacement field of the linear solve is kinematically admissible and off the nonlinear equilibrium by
    a first-order amount; the potential energy along the scaled field ``s u`` is then off by a second-order amount,
    and so is its derivative, the work rate ``f_int(s u) . u``: divided by the prescribed displacement it is the
    reaction at load fraction ``s`` (``f_int``: the exact, nonlinear bond law). ``K`` is the scene's least-squares
    slope of those reactions over its fit range (``CORRECTION_POINTS`` fractions), the measure the DEM and the
    nonlinear DSM use. The model and its compiled program are the linear solve's (the same setup and size
    class).

    Args:
      sample: the bonded sample.
      scene: the scene.
      params: the parameters (``None``: the sample's own).
      u: ``[n, nd]`` the linear solution's DOFs (displacements [m], then rotations [rad]).
      rotations: rotational DOFs (``None``: the model's choice), as in the linear solve.
      operator: the linear solve's operator option.
      preconditioner: the linear solve's preconditioner option.
      aggregate_size: the linear solve's coarse aggregate size.
      pad: pad the model to its size class, as the linear solve does.

    Returns:
      ``(K, forces, fractions, compile_time, run_time)``: the stiffness [N/m], ``[L]`` the reactions [N] at
      ``[L]`` the load fractions, and the seconds spent compiling and running.

    Raises:
      SceneError: a scene that does not fit the sample (the linear solve's own checks).
      ValueError: an unknown ``preconditioner``, or an ``aggregate_size`` below 1.
    """
    from jaxbpm.physics.model import default_params

    params = default_params(sample) if params is None else params
    setup, setup_compile = _setup_for(sample, scene, params, rotations, operator, preconditioner, aggregate_size, pad)
    u = np.asarray(u, dtype=np.asarray(setup.u_p).dtype)
    full = np.zeros(setup.u_p.shape, u.dtype)
    full[:u.shape[0]] = u
    lo, hi = scene.fit_range
    fractions = tuple(float(f) for f in np.linspace(max(lo, hi / CORRECTION_POINTS), hi, CORRECTION_POINTS))
    work, compile_time, run_time = path_work_program(setup.model, params, jnp.asarray(full), fractions=fractions)
    forces = np.asarray(work) / setup.delta
    stiffness = scene.fit_stiffness(np.asarray(fractions) * setup.delta, forces, setup.delta)
    return stiffness, forces, np.asarray(fractions), compile_time + setup_compile, run_time


def with_geometric_correction(result, sample, scene, params, **setup_options):
    """The result of the linear bonds-only DSM with its stiffness corrected for the bonds' geometric nonlinearity.

    The correction is :func:`geometric_stiffness`'s; the correction's compile and run count in the result's times.

    Args:
      result: the :class:`~jaxbpm.result.Result` of the linear solve (its ``state``: the DOFs ``[n, nd]``).
      sample: the bonded sample.
      scene: the scene.
      params: the parameters (``None``: the sample's own).
      **setup_options: the linear solve's setup options (:func:`geometric_stiffness`'s keywords).

    Returns:
      The corrected result: its stiffness and modulus, the force-displacement points along the path,
      ``stats["stiffness_linear"]`` (the linear solve's K), ``stats["geometric_correction"]`` (``K / K_linear -
      1``) and ``stats["correction_fractions"]``.

    Raises:
      SceneError: a scene that does not fit the sample (the linear solve's own checks).
      ValueError: an unknown ``preconditioner``, or an ``aggregate_size`` below 1.
    """
    t0 = time.perf_counter()
    k, forces, fractions, compile_time, run_time = geometric_stiffness(sample, scene, params, result.state,
                                                                       **setup_options)
    spent = time.perf_counter() - t0
    delta = float(result.displacement[-1])
    stats = {**result.stats, "stiffness_linear": float(result.stiffness),
             "geometric_correction": float(k / result.stiffness - 1.0),
             "correction_fractions": [float(f) for f in fractions]}
    return dataclasses.replace(
        result, stiffness=float(k), youngs_modulus=float(k) * result.gauge_length / result.area,
        displacement=np.concatenate([[0.0], fractions * delta]), force=np.concatenate([[0.0], forces]),
        wall_time=result.wall_time + spent, compile_time=result.compile_time + compile_time,
        run_time=result.run_time + run_time, setup_time=result.setup_time + max(spent - compile_time - run_time, 0.0),
        stats=stats)


def _report_convergence(stats, converged, residual, tol):
    """What a solve that missed its tolerance says (``stats["failure"]``; :func:`jaxbpm.result.settle` gives the
    result its status and raises with ``throw=True``)."""
    if not converged:
        stats["failure"] = f"DSM did not converge: relative residual {residual:.3g} above tolerance {tol:.3g}"


@jax.jit
def _bond_forces_at(model, params, u):
    """Per-bond forces (:class:`BondForces`) at the DOF state ``u``."""
    return internal_forces(model, params, u)[1]["bonds"]


def _linear_fn(model, params, free, u_p, tol, maxiter, operator="auto", stiffness_tol=None, coarse=None,
               contacts=None, contact_passes=2, geometry=None, guess=None):
    """Linear solve of one load case; returns ``(u, reaction, boundary reaction, residual, iterations)``.

    reaction = ``u . K u / delta`` (twice the strain energy over the prescribed displacement ``delta``): at
    equilibrium it equals the force on the driven layer, and it is variational -- the CG iterate minimises the
    energy, so its error is quadratic in the error of ``u`` and a loose tolerance still gives an accurate stiffness.
    boundary reaction = mean of the axial forces on the driven and (minus) the resting clamped layer, the measure
    the DEM uses; the two agree to the solver's tolerance.
    contacts: ``(pairs [C, 2], u_lin [n, nd], fraction, pair_coarse)``: contact candidates linearised at the state
    ``fraction * u_lin`` (:func:`_linearised_contact_jacobians`; a pair that does not touch there adds nothing),
    added to the bonds as further springs (operator and preconditioner alike; ``pair_coarse``: ``coarse`` with
    ``bonds`` indexing the pairs that couple its modes). ``contact_passes`` solves: each later one re-linearises the
    contacts at ``fraction`` times the previous solution and starts from it; every pass but the last only places
    the contacts, and stops once the strain energy has settled to ``_PLACING_TOL`` (or at the final tolerances, if
    looser). Iterations are summed over the passes.
    geometry: :class:`BondGeometry` of the bonds (or ``None``: the Jacobians by differentiating the bond law).
    """
    if contacts is None:
        full, jac = tangent_operator(model, params, operator=operator, geometry=geometry)
        precond = build_preconditioner(model, params, free, jac, coarse, geometry)
        return _linear_once(free, u_p, tol, maxiter, stiffness_tol, full, precond, guess)
    pairs, u_lin, fraction, pair_coarse = contacts
    pair_model = dataclasses.replace(model, bonds=pairs.astype(model.bonds.dtype))
    bond_op, jb = tangent_operator(model, params, operator="jacobians", geometry=geometry)
    total, x0 = 0, u_lin
    placing_tol = _PLACING_TOL if stiffness_tol is None else jnp.maximum(_PLACING_TOL, stiffness_tol)
    for k in range(contact_passes):
        last = k == contact_passes - 1
        jc = _linearised_contact_jacobians(model, pairs, fraction * u_lin)
        contact_op = _packed_operator(pair_model, jc)
        if k == 0:  # the first pass's preconditioner serves the later ones (the contacts move little)
            precond = build_preconditioner(model, params, free, jb, coarse, geometry, (pair_model, jc, pair_coarse))
        out = _linear_once(free, u_p, tol, maxiter, stiffness_tol if last else placing_tol,
                           lambda v, c=contact_op: bond_op(v) + c(v), precond, x0)
        u_lin = x0 = jax.lax.stop_gradient(out[0])
        total = total + out[4]
    return out[:4] + (total,)


linear_jit = jax.jit(_linear_fn, static_argnames=("maxiter", "operator", "contact_passes"))


def _contacts_outputs(model, params, free, u_p, tol, stiffness_tol, coarse, contacts, geometry, guess, maxiter,
                      operator, contact_passes):
    return _linear_fn(model, params, free, u_p, tol, maxiter, operator, stiffness_tol, coarse, contacts,
                      contact_passes, geometry, guess)


def pad_candidates(lin, sample, axis):
    """The linearised contacts' candidates (and their coarse couplings) padded to a :func:`capacity`.

    Samples and reaches with about as many candidates then share the compiled solve: the padding pairs join the two
    particles farthest apart along ``axis``, which never touch (no stiffness). Left as they are when those two are
    not far enough apart.

    Args:
      lin: ``(pairs [C, 2], field, fraction, coarse)`` the linearised contacts: the candidates, ``[n, nd]`` the
        affine field they are linearised along, the load fraction, and the
        :class:`~jaxbpm.dsm.preconditioner.CoarseSpace` whose ``bonds`` index the candidates that couple its modes
        (or ``None``).
      sample: the sample.
      axis: the load axis (0, 1 or 2).

    Returns:
      ``lin`` with ``pairs`` (and the coarse space's ``bonds``) padded, as a list; ``lin`` itself when not padded.
    """
    pairs = np.asarray(lin[0])
    pos, rad = np.asarray(sample.positions)[:, axis], np.asarray(sample.radii)
    i, j = int(np.argmin(pos)), int(np.argmax(pos))
    if len(pairs) == 0 or pos[j] - pos[i] <= 4.0 * (rad[i] + rad[j]):
        return lin
    c = len(pairs)
    cap = capacity(c + 1)
    lin = list(lin)
    lin[0] = put(np.concatenate([pairs, np.tile(np.array([[i, j]], pairs.dtype), (cap - c, 1))]), np.int32)
    if lin[3] is not None:
        cb = np.asarray(lin[3].bonds)
        # the couplings (a subset of the candidates) padded to the candidates' capacity: their own count would give
        # candidate lists of one size class several programs
        lin[3] = dataclasses.replace(lin[3], bonds=put(pad_rows(cb, cap, c), np.int32))
    return lin


LINEAR_STIFFNESS_TOL = 1e-6
"""The linear bonds-only solve's default ``stiffness_tol``: CG stops once the strain energy (the stiffness) has
settled to 1e-6 by the Hestenes-Stiefel estimate, which over-estimates the error: K is then within about 1e-7 of the
fully converged answer, in fewer CG iterations than the 1e-6 residual test needs. ``stiffness_tol=None`` stops on the
residual alone."""


def _linear_stiffness_tol(stiffness_tol):
    """``stiffness_tol`` of a linear bonds-only solve: ``"auto"`` is :data:`LINEAR_STIFFNESS_TOL`."""
    return LINEAR_STIFFNESS_TOL if isinstance(stiffness_tol, str) and stiffness_tol == "auto" else stiffness_tol


def _energy_test(stiffness_tol):
    """``stiffness_tol`` as the programs take it: always a number (-1 turns the energy test off: the energy drops are
    never negative), so that solves with and without it share their compiled program."""
    return -1.0 if stiffness_tol is None else float(stiffness_tol)


# the linear solve with linearised contacts, compiled once per shape (its static options last)
contacts_program = Program(_contacts_outputs, static_argnames=("maxiter", "operator", "contact_passes"))

# how far the passes that only place the linearised contacts converge (relative change of the strain energy)
_PLACING_TOL = 1e-2


def _linear_once(free, u_p, tol, maxiter, stiffness_tol, full, precond, x0=None):
    u, res, iterations, _, ku = cg(full, precond, free, u_p, tol, maxiter, stiffness_tol, x0=x0)
    gen = -ku  # linearised internal forces
    delta = jnp.max(jnp.abs(u_p))
    energy_reaction = -jnp.vdot(u, gen) / delta
    clamped = ~jnp.any(free, axis=1)
    moving = clamped & jnp.any(u_p != 0, axis=1)
    resting = clamped & ~moving
    ax = jnp.argmax(jnp.any(u_p != 0, axis=0))
    comp = jnp.take(gen, ax, axis=1)
    reaction = 0.5 * (jnp.sum(jnp.where(moving, comp, 0.0)) - jnp.sum(jnp.where(resting, comp, 0.0)))
    return u, energy_reaction, reaction, res, iterations
