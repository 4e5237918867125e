"""A static failure solver: the linear DSM with bonds removed one event at a time (sequentially linear analysis).

Lattice fracture models find the peak load of a brittle lattice without dynamics (Rots et al. 2008, sequentially
linear analysis; Schlangen & Garboczi 1997). :func:`failure_solve` does it on the bonded sample of a scene with
clamped layers (uniaxial compression between layers, three-point bending, the Brazilian disc's loading strips):

1. solve the linear DSM for the scene's prescribed displacement ``delta`` (the unit load);
2. every intact bond's forces and moments scale with the load, so the scale ``s`` at which it reaches its strength
   under the scene's failure rule follows in closed form (:func:`critical_scales`: a ratio for ``"separate"`` and
   ``"max"``, the smallest admissible root of a quadratic for ``"summed"`` with a Mohr-Coulomb friction angle);
3. the event: the smallest scale ``s_min``; the load there is ``s_min F_unit`` at the displacement ``s_min delta``;
   the critical bond is removed (with it every intact bond within ``group_tol`` of the same scale);
4. solve again from the previous solution (warm-started CG), and repeat.

The peak force is the largest event load. Under displacement control the sample stays at the largest event
displacement reached so far (an event below it snaps back: it breaks at once); the run stops once the load that the
damaged sample carries there has fallen to ``stop_fraction`` of the peak (a single event's load drops and recovers
again and again, so it is no stop), when no intact bond carries load (the sample split apart), or after ``max_events``.

Broken bonds that close become contacts (``contacts=True``): a broken bond whose ends approach in the current
solution carries a linear normal spring (the bond's normal stiffness times ``contact_stiffness``, compression only,
no friction); the set of closed bonds is found by repeating the solve until it no longer changes (at most
``contact_passes`` solves per event). Contacts between particles that were never bonded are not modelled, nor the
Hertz contacts the DEM adds to bonded pairs that overlap.

The bonds' state is data (a per-bond array), not structure: the stiffness operator is the packed per-bond Jacobians
of :mod:`~jaxbpm.dsm.operator` weighted by it, the block-Jacobi part of the preconditioner is rebuilt from it at
every solve and the coarse factor at the start of every ``chunk`` events, which run in one compiled program (a
``lax.while_loop``): removing bonds compiles nothing. A tiny spring to ground (``regularisation`` times each DOF's
mean self-stiffness) keeps fragments that come loose from making the system singular.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm._compile import Program, put, strong
from jaxbpm._options import choice, flag, fraction, option, optional, positive, SolverOptions, unit_interval, whole
from jaxbpm.dsm.krylov import cg
from jaxbpm.dsm.linear import _setup_for
from jaxbpm.dsm.operator import (
    _apply_packed, _pair_dofs, _scatter_pairs, block_diagonal, packed_jacobians, reduced_jacobians)
from jaxbpm.dsm.preconditioner import CholeskyBlocks, coarse_matrix, Preconditioner
from jaxbpm.errors import OptionsError, SceneError
from jaxbpm.physics import bond as bond_mod

__all__ = ["StaticFailure", "FailureResult", "failure_solve", "critical_scales", "unit_bond_loads"]

INTACT, CLOSED, OPEN = 0, 1, 2  # a bond's state: intact; broken and closed (a contact spring); broken and open

#: the sample has split apart once its reaction to the unit load falls below this fraction of the intact sample's
SPLIT = 1e-4


class StaticFailure(SolverOptions):
    """Options of the static failure solver (:func:`failure_solve`).

    Attributes:
      max_events: events at most.
      stop_fraction: stop once the load at the largest displacement reached has fallen to this fraction of the peak
        (PFC's usual 0.7-0.8).
      group_tol: bonds whose critical scale lies within this relative tolerance of the event's break in the same
        event (0: one bond per event, ties aside).
      tol: the CG's relative residual at each solve.
      maxiter: CG iterations at most per solve (``None``: 10 x the DOFs).
      contacts: broken bonds that close become linear normal springs (compression only); False: removed for good.
      contact_stiffness: the closed bonds' normal stiffness over the bond's own.
      contact_passes: solves per event at most while the set of closed bonds changes.
      chunk: events per compiled call (the host checks the stop between calls; the program stops within one).
      dofs: 3 or 6 per particle (``None``: the model's choice).
      preconditioner: ``"two-level"``, ``"jacobi"`` or ``"auto"`` (as :class:`~jaxbpm.dsm.options.DSM`).
      aggregate_size: the coarse space's aggregate size (``None``: its default).
      regularisation: the spring to ground on every free DOF, over that DOF's mean self-stiffness.
    """

    method = "static_failure"

    max_events: int = option(4000, whole)
    stop_fraction: float = option(0.7, fraction)
    group_tol: float = option(0.0, unit_interval(lo_open=False, hi_closed=False))
    tol: float = option(1e-6, positive)
    maxiter: int | None = option(None, optional(whole))
    contacts: bool = option(True, flag)
    contact_stiffness: float = option(1.0, positive)
    contact_passes: int = option(4, whole)
    chunk: int = option(64, whole)
    dofs: int | None = option(None, choice(None, 3, 6))
    preconditioner: str = option("auto", choice("auto", "two-level", "jacobi"))
    aggregate_size: float | None = option(None, optional(positive))
    regularisation: float = option(1e-9, positive)


@dataclasses.dataclass(frozen=True)
class FailureResult:
    """What :func:`failure_solve` gives.

    Attributes:
      peak_force: the largest event load [N].
      strength: the scene's strength of that load [Pa] (``scene.strength``).
      peak_displacement: the displacement at the peak [m].
      peak_event: the event of the peak (0-based).
      displacement: ``[events]`` the displacement of each event [m] (the envelope of the load-displacement curve).
      force: ``[events]`` each event's load [N].
      broken: ``[events]`` the bonds broken in each event.
      critical_bond: ``[events]`` the bond (the sample's index) that set each event's load.
      cg_iterations: ``[events]`` the CG iterations of each event's solves.
      closed: ``[events]`` the broken bonds closed (contact springs) at each event's solve.
      events: the events run.
      stiffness: the intact sample's stiffness ``F_unit / delta`` [N/m].
      status: why it stopped: ``"past_peak"`` (the load at the largest displacement reached fell to
        ``stop_fraction`` of the peak), ``"split"`` (no intact bond carries load), ``"max_events"``.
      wall_time: seconds in all.
      setup_time: seconds of setup (the linear DSM's setup, the Jacobians, the ground springs).
      compile_time: seconds compiling.
      kernel_time: seconds running the event programs and the coarse factors.
      stats: further figures: ``"bonds"``, ``"rule"``, ``"calls"`` (compiled calls), ``"compilations"`` (of the
        events program in this process), ``"group_tol"``, ``"contacts"``, ``"max_residual"``,
        ``"unsettled_contacts"`` (events whose closed set still changed after ``contact_passes`` solves),
        ``"bonds_broken"``, ``"bonds_broken_to_peak"``, ``"cg_iterations"``.
    """

    peak_force: float
    strength: float
    peak_displacement: float
    peak_event: int
    displacement: np.ndarray
    force: np.ndarray
    broken: np.ndarray
    critical_bond: np.ndarray
    cg_iterations: np.ndarray
    closed: np.ndarray
    events: int
    stiffness: float
    status: str
    wall_time: float
    setup_time: float
    compile_time: float
    kernel_time: float
    stats: dict = dataclasses.field(default_factory=dict)


def unit_bond_loads(model, jp, u):
    """Each bond's linearised forces and moments for the DOF state ``u`` (at rest, from the packed Jacobians).

    Args:
      model: the model.
      jp: ``[np, nb]`` the packed Jacobians (:func:`~jaxbpm.dsm.operator.packed_jacobians`).
      u: ``[n, nd]`` the DOFs.

    Returns:
      ``(normal [nb], shear (x, y, z), twist [nb], bend (x, y, z))`` in the conventions of
      :class:`~jaxbpm.physics.bond.BondForces` (tension > 0).
    """
    y = _apply_packed(jp, _pair_dofs(model, model.bonds, u))
    length = jnp.linalg.norm(model.r0, axis=1)
    n = tuple(model.r0[:, c] / jnp.where(length > 0, length, 1.0) for c in range(3))
    f = tuple(y[c] for c in range(3))
    normal = sum(f[c] * n[c] for c in range(3))
    shear = tuple(f[c] - normal * n[c] for c in range(3))
    if not model.rotations:
        zero = jnp.zeros_like(normal)
        return normal, shear, zero, (zero, zero, zero)
    m = tuple(0.5 * (y[3 + c] - y[6 + c]) for c in range(3))  # m_i - m_j = 2 (twist n + bend)
    twist = sum(m[c] * n[c] for c in range(3))
    return normal, shear, twist, tuple(m[c] - twist * n[c] for c in range(3))


def _positive_inverse(x):
    """``1 / x`` where ``x > 0``, else inf."""
    return jnp.where(x > 0, 1.0 / jnp.where(x > 0, x, 1.0), jnp.inf)


def critical_scales(normal, shear, twist, bend, strength: bond_mod.BondStrength, rule: str = "separate"):
    """The load scale at which each bond reaches its strength, for forces that grow in proportion to the load.

    With ``tau_c = c - sigma_n tan(phi)`` and every stress ``s`` times its value at the unit load, the scale is
    ``min(sigma_c / sigma, c / (tau + sigma_n tan(phi)))`` under ``"separate"``; under ``"max"`` the same per single
    load (normal, bending, shear, twist); under ``"summed"`` the smallest root ``s > 0`` of ``s sigma / sigma_c +
    s tau / (c - s sigma_n tan(phi)) = 1`` (a quadratic) with ``tau_c > 0``. Under ``"summed"`` and ``"max"`` a bond
    also breaks where its shear strength reaches zero (``s = c / (sigma_n tan(phi))``), as
    :func:`~jaxbpm.physics.bond.bond_failure` says.

    Args:
      normal, shear, twist, bend: the bonds' forces and moments at the unit load (:func:`unit_bond_loads`).
      strength: the bonds' :class:`~jaxbpm.physics.bond.BondStrength`.
      rule: the failure rule (:data:`~jaxbpm.physics.bond.FAILURE_RULES`).

    Returns:
      ``[nb]`` the scales (inf: the bond never breaks under this load).

    Raises:
      ValueError: ``rule`` names no failure rule.
    """
    bond_mod.check_failure_rule(rule)
    s = strength
    sigma, tau, sigma_n = bond_mod.bond_stresses(normal, shear, twist, bend, s)
    c = s.cohesion
    finite_c = jnp.isfinite(c)
    over_c = lambda x: jnp.where(finite_c, x / jnp.where(finite_c, c, 1.0), 0.0)  # noqa: E731
    p = over_c(sigma_n * s.tan_phi)  # the loss of shear strength per unit scale, over c
    a = jnp.where(jnp.isfinite(s.tensile), sigma / jnp.where(jnp.isfinite(s.tensile), s.tensile, 1.0), 0.0)
    if rule == "separate":
        return jnp.minimum(_positive_inverse(a), _positive_inverse(over_c(tau) + p))
    gone = _positive_inverse(p)
    if rule == "max":
        tau_s = bond_mod._norm(shear) / s.area
        a_n = jnp.where(jnp.isfinite(s.tensile), sigma_n / jnp.where(jnp.isfinite(s.tensile), s.tensile, 1.0), 0.0)
        scales = (_positive_inverse(a_n), _positive_inverse(a - a_n), _positive_inverse(over_c(tau_s) + p),
                  _positive_inverse(over_c(tau - tau_s) + p), gone)
        return jnp.min(jnp.stack(scales), axis=0)
    # "summed": a s + q s / (1 - p s) = 1, 1 - p s > 0  <=>  -a p s^2 + (a + q + p) s - 1 = 0
    q = over_c(tau)
    qa, qb = -a * p, a + q + p
    disc = qb * qb + 4.0 * qa
    root = jnp.sqrt(jnp.maximum(disc, 0.0))
    big = -0.5 * (qb + jnp.where(qb >= 0, root, -root))  # the stable pair of roots: big / qa and -1 / big
    r1 = jnp.where(qa != 0, big / jnp.where(qa != 0, qa, 1.0), jnp.inf)
    r2 = jnp.where(big != 0, -1.0 / jnp.where(big != 0, big, 1.0), jnp.inf)
    linear = jnp.abs(qa) <= 1e-12 * jnp.maximum(qb * qb, 1e-300)
    ok = lambda r: (r > 0) & jnp.isfinite(r) & (1.0 - p * r > 0) & (disc >= 0)  # noqa: E731
    quadratic = jnp.minimum(jnp.where(ok(r1), r1, jnp.inf), jnp.where(ok(r2), r2, jnp.inf))
    return jnp.minimum(jnp.where(linear, _positive_inverse(qb), quadratic), gone)


class _Context(NamedTuple):
    """What every event of one solve reads (a pytree of arrays): the padded model, its bonds' strengths, the packed
    (``jp``) and reduced (``jr``) Jacobians of the intact bonds, those of the closed bonds' normal springs (``jn``,
    ``jn_r``), the ground springs ``[n, nd]``, the free DOFs, the prescribed displacements of the unit load and the
    coarse space (or ``None``)."""

    model: Any
    strength: Any
    jp: Any
    jr: Any
    jn: Any
    jn_r: Any
    ground: Any
    free: Any
    u_p: Any
    coarse: Any


def _prepare(model, params, free, u_p, coarse, regularisation, contact_stiffness):
    """The :class:`_Context` of a solve (one setup program)."""
    jr = reduced_jacobians(model, params)
    kn = model.stiffness(params).kn * contact_stiffness
    length = jnp.linalg.norm(model.r0, axis=1)
    n = model.r0 / jnp.where(length > 0, length, 1.0)[:, None]
    # the spring's d f_i / d (u_j - u_i) = k_n n n^T, in the reduced form [c, o, nb] (input c, output o)
    jn_r = jnp.zeros_like(jr).at[:3, :3].set(kn[None, None] * n.T[:, None, :] * n.T[None, :, :])
    blocks = block_diagonal(model, None, jr)
    scale = jnp.mean(jnp.abs(jnp.diagonal(blocks, axis1=1, axis2=2)), axis=0)  # [nd]
    ground = jnp.where(free, regularisation * scale[None], 0.0)
    strength = dataclasses.replace(model, breakage=True).strength(params)
    return _Context(model=model, strength=strength, jp=packed_jacobians(jr), jr=jr, jn=packed_jacobians(jn_r),
                    jn_r=jn_r, ground=ground, free=free, u_p=u_p, coarse=coarse)


prepare_program = Program(_prepare)


def _solve_state(ctx: _Context, factor, state, x0, tol, maxiter, contacts):
    """The linear solve of the unit load with the bonds in ``state``: ``(u, F_unit, residual, iterations)``. The
    block-Jacobi part of the preconditioner is built from the intact bonds and closed springs; the coarse
    ``factor`` (:class:`~jaxbpm.dsm.preconditioner.CholeskyBlocks`, or ``None``) is the caller's."""
    model = ctx.model
    intact = (state == INTACT).astype(ctx.jp.dtype)
    closed = (state == CLOSED).astype(ctx.jp.dtype)
    jp = ctx.jp * intact[None]
    if contacts:
        jp = jp + ctx.jn * closed[None]

    def full(v):
        z = _pair_dofs(model, model.bonds, v)
        return _scatter_pairs(model, model.bonds[:, 0], model.bonds[:, 1], _apply_packed(jp, z)) + ctx.ground * v

    blocks = block_diagonal(model, None, ctx.jr * intact[None, None])
    if contacts:
        blocks = blocks + block_diagonal(model, None, ctx.jn_r * closed[None, None])
    # a particle held by closed springs alone has a singular block: the shift (a thousand ground springs) keeps the
    # preconditioner regular without touching the operator
    nd = blocks.shape[1]
    eye = jnp.eye(nd, dtype=blocks.dtype)
    blocks = blocks + (1e3 * ctx.ground)[:, :, None] * eye[None]
    inv = jnp.linalg.inv(jnp.where(ctx.free[:, :, None] & ctx.free[:, None, :], blocks, eye[None]))
    precond = Preconditioner(inv=inv, free=ctx.free, factor=factor, coarse=ctx.coarse)
    u, res, iterations, _, ku = cg(full, precond, ctx.free, ctx.u_p, tol, maxiter, None, x0=x0)
    delta = jnp.max(jnp.abs(ctx.u_p))
    return u, jnp.vdot(u, ku) / delta, res, iterations


def _contact_solve(ctx: _Context, factor, state, x0, tol, maxiter, passes, contacts):
    """Solve, close the broken bonds whose ends approach and open those that separate (``contacts``), and solve
    again until the set no longer changes (at most ``passes`` solves): ``(state, u, F_unit, residual, iterations,
    changed)``, ``u`` the last solve's (of the state before its update: ``changed`` where they differ)."""
    bonds = ctx.model.bonds
    length = jnp.linalg.norm(ctx.model.r0, axis=1)
    n = ctx.model.r0 / jnp.where(length > 0, length, 1.0)[:, None]

    def body(c):
        st, u, _, _, its, k, _ = c
        u, f_unit, res, it = _solve_state(ctx, factor, st, u, tol, maxiter, contacts)
        opening = jnp.sum((u[bonds[:, 1], :3] - u[bonds[:, 0], :3]) * n, axis=1)
        closing = (opening < 0) if contacts else jnp.zeros_like(opening, bool)
        new = jnp.where(st == INTACT, INTACT, jnp.where(closing, CLOSED, OPEN)).astype(st.dtype)
        return new, u, f_unit, res, its + it, k + 1, jnp.any(new != st)

    def more(c):
        return c[6] & (c[5] < passes)

    zero = jnp.zeros((), x0.dtype)
    init = (state, x0, zero, zero, jnp.zeros((), jnp.int32), jnp.zeros((), jnp.int32), jnp.array(True))
    st, u, f_unit, res, its, _, changed = jax.lax.while_loop(more, body, init)
    return st, u, f_unit, res, its, changed


def _events(ctx: _Context, factor, carry, limit, stop_fraction, group_tol, tol, maxiter, passes, contacts, chunk):
    """Up to ``limit`` (at most ``chunk``) events from ``carry = (state [nb], u [n, nd], peak, f0, reach)`` (``f0``:
    the intact sample's unit reaction, 0 before the first event; ``reach``: the largest event scale so far), stopping
    within the call as :func:`failure_solve` says: ``(carry, records, count, stop)``, ``records`` ``[8, chunk]``
    (scale, load, broken, iterations, closed, residual, unsettled, critical bond) of which the first ``count`` columns
    are set, ``stop`` the reason (0 none, 1 past the peak, 2 split)."""
    dtype = ctx.jp.dtype
    rule = ctx.model.failure_rule

    def body(c):
        state, u, peak, f0, reach, k, stop, rec = c
        state, u, f_unit, res, its, unsettled = _contact_solve(ctx, factor, state, u, tol, maxiter, passes,
                                                                   contacts)
        normal, shear, twist, bend = unit_bond_loads(ctx.model, ctx.jp, u)
        scales = jnp.where(state == INTACT, critical_scales(normal, shear, twist, bend, ctx.strength, rule), jnp.inf)
        s_min = jnp.min(scales)
        f0 = jnp.where(f0 > 0, f0, f_unit)
        split = ~jnp.isfinite(s_min) | ~(f_unit > SPLIT * f0)
        load = jnp.where(split, 0.0, s_min * f_unit)
        remove = (state == INTACT) & (scales <= s_min * (1.0 + group_tol)) & ~split
        # a bond that breaks in compression starts as a closed contact (the next solve checks it)
        fresh = jnp.where((normal < 0) & contacts, CLOSED, OPEN).astype(state.dtype)
        state = jnp.where(remove, fresh, state)
        # under displacement control the sample is at the largest displacement reached so far: past the peak once the
        # load of this state there has fallen to stop_fraction of the peak
        held = f_unit * reach
        reach = jnp.where(split, reach, jnp.maximum(reach, s_min))
        stop = jnp.where(split, 2, jnp.where((held < stop_fraction * peak) & (peak > 0), 1, 0)).astype(jnp.int32)
        peak = jnp.maximum(peak, load)
        row = (jnp.where(split, jnp.inf, s_min), load, jnp.sum(remove).astype(dtype), its.astype(dtype),
               jnp.sum(state == CLOSED).astype(dtype), res, unsettled.astype(dtype), jnp.argmin(scales).astype(dtype))
        rec = rec.at[:, k].set(jnp.stack([jnp.asarray(v, dtype) for v in row]))
        return state, u, peak, f0, reach, k + 1, stop, rec

    def more(c):
        return (c[5] < limit) & (c[6] == 0)

    zero = jnp.zeros((), jnp.int32)
    state, u, peak, f0, reach, k, stop, rec = jax.lax.while_loop(
        more, body, tuple(carry) + (zero, zero, jnp.zeros((8, chunk), dtype)))
    return (state, u, peak, f0, reach), rec, k, stop


events_program = Program(_events, static_argnames=("maxiter", "passes", "contacts", "chunk"))


def _coarse_matrix(ctx: _Context, state, contacts):
    """The Galerkin coarse matrix of the intact bonds (and, with ``contacts``, the closed springs) in ``state``."""
    dtype = ctx.jr.dtype
    a = coarse_matrix(ctx.model, ctx.jr * (state == INTACT).astype(dtype)[None, None], ctx.coarse)
    if contacts:
        a = a + coarse_matrix(ctx.model, ctx.jn_r * (state == CLOSED).astype(dtype)[None, None], ctx.coarse)
    return a


coarse_program = Program(_coarse_matrix, static_argnames=("contacts",))


def _coarse_factor(ctx: _Context, state, contacts):
    """``(factor, compile_time, run_time)``: the coarse factor (:class:`~jaxbpm.dsm.preconditioner.CholeskyBlocks`)
    of the bonds in ``state``, factorised on the host (XLA's CPU Cholesky is far slower at these sizes), or
    ``None`` without a coarse space."""
    import scipy.linalg

    if ctx.coarse is None:
        return None, 0.0, 0.0
    a, compile_time, run_time = coarse_program(ctx, state, contacts=contacts)
    t0 = time.perf_counter()
    a = np.asarray(a)
    a = 0.5 * (a + a.T)
    diag = np.diagonal(a)
    for shift in (1e-10, 1e-6, 1e-3):  # 1e-10: as the DSM's own; more where a fragment leaves a mode without stiffness
        try:
            low = np.linalg.cholesky(a + np.diag(np.where(diag > 0, shift * diag.max(), 1.0)))
            break
        except np.linalg.LinAlgError:
            continue
    else:
        return None, compile_time, run_time + time.perf_counter() - t0
    m, size = a.shape[0], CholeskyBlocks.size
    edges = list(range(0, m, size)) + [m]
    inv_diag = [scipy.linalg.solve_triangular(low[i:j, i:j], np.eye(j - i), lower=True)
                for i, j in zip(edges[:-1], edges[1:])]
    rows = [low[i:j, :i] for i, j in zip(edges[:-1], edges[1:])]
    cols_t = [low[j:, i:j].T.copy() for i, j in zip(edges[:-1], edges[1:])]
    dtype = ctx.jp.dtype
    factor = CholeskyBlocks(inv_diag=[put(x, dtype) for x in inv_diag], rows=[put(x, dtype) for x in rows],
                            cols_t=[put(x, dtype) for x in cols_t])
    return factor, compile_time, run_time + time.perf_counter() - t0


def _check_inputs(sample, scene, options):
    """The checks of :func:`failure_solve` (before any setup)."""
    if options is not None and not isinstance(options, StaticFailure):
        raise OptionsError(f"options must be a StaticFailure, got {type(options).__name__}")
    if getattr(scene, "uses_walls", False):
        raise SceneError("the static failure solver needs a scene with clamped layers (loading strips, supports), "
                         "not walls: use boundary='layers' (platens='strips')")
    if not callable(getattr(scene, "layers", None)):
        raise SceneError(f"the static failure solver needs a scene with clamped layers; {type(scene).__name__} "
                         "has no layers()")
    if getattr(sample, "n_bonds", 0) == 0:
        raise SceneError("the sample has no bonds: nothing to break")


def failure_solve(sample, scene, params=None, options: StaticFailure | None = None) -> FailureResult:
    """The peak load of ``scene`` on ``sample`` by sequentially linear analysis (see the module docstring).

    Args:
      sample: the bonded sample.
      scene: a scene with clamped layers (:class:`~jaxbpm.scenes.UniaxialCompression` with ``boundary="layers"``,
        :class:`~jaxbpm.scenes.ThreePointBending`, :class:`~jaxbpm.scenes.BrazilianDisc` with loading strips); its
        ``failure_rule`` is the bonds'; its ``strain`` only sets the unit load.
      params: the parameters (``None``: the sample's own), with the bonds' strengths
        (``"bond_tensile_strength"``, ``"bond_shear_strength"``, ``"bond_friction_angle"``,
        ``"bond_moment_factor"``, or the material table's).
      options: the :class:`StaticFailure` options (``None``: the defaults).

    Returns:
      The :class:`FailureResult`.

    Raises:
      SceneError: a scene with walls or without layers, a sample without bonds, bonds that cannot break (no finite
        strength) or that the scene does not load, or a free cluster that nothing holds.
      OptionsError: options that are not :class:`StaticFailure`.
    """
    from jaxbpm._compile import compile_clock
    from jaxbpm.physics.model import default_params

    t0 = time.perf_counter()
    _check_inputs(sample, scene, options)
    options = StaticFailure() if options is None else options
    params = strong(default_params(sample) if params is None else params)
    rotations = None if options.dofs is None else options.dofs == 6
    # (the setup without the bond geometry, which only the DSM's own operator reads)
    setup, setup_compile = _setup_for(sample, scene, params, rotations, "jvp", options.preconditioner,
                                      options.aggregate_size, True)
    with compile_clock() as clock:
        ctx, prep_compile, _ = prepare_program(setup.model, params, setup.free, setup.u_p, setup.coarse,
                                               options.regularisation, options.contact_stiffness)
    s = ctx.strength
    solid = np.asarray(setup.model.bond_area)[:setup.nb] > 0
    if not (np.isfinite(np.asarray(s.tensile)[:setup.nb][solid]).any()
            or np.isfinite(np.asarray(s.cohesion)[:setup.nb][solid]).any()):
        raise SceneError("the bonds never break (no finite tensile or shear strength in the sample's materials or "
                         "the params)")
    compile_time = setup_compile + max(clock.seconds, prep_compile)
    setup_time = time.perf_counter() - t0 - compile_time
    zero = jnp.zeros((), setup.guess.dtype)
    carry = (jnp.zeros(setup.model.bonds.shape[0], jnp.int8), setup.guess, zero, zero, zero)
    records, kernel, calls, status = [], 0.0, 0, "max_events"
    while sum(r.shape[1] for r in records) < options.max_events:
        limit = min(options.chunk, options.max_events - sum(r.shape[1] for r in records))
        factor, f_compile, f_time = _coarse_factor(ctx, carry[0], options.contacts)
        compile_time, kernel = compile_time + f_compile, kernel + f_time
        (carry, rec, count, stop), c_time, r_time = events_program(
            ctx, factor, carry, limit, options.stop_fraction, options.group_tol, options.tol, maxiter=options.maxiter,
            passes=options.contact_passes, contacts=options.contacts, chunk=options.chunk)
        compile_time, kernel, calls = compile_time + c_time, kernel + r_time, calls + 1
        records.append(np.asarray(rec)[:, :int(count)])
        if int(stop):
            status = {1: "past_peak", 2: "split"}[int(stop)]
            break
    rec = np.concatenate(records, axis=1)
    return _result(sample, scene, setup, rec, status, t0, setup_time, compile_time, kernel,
                   {"calls": calls, "compilations": events_program.compilations, "rule": setup.model.failure_rule,
                    "bonds": setup.nb, "group_tol": options.group_tol, "contacts": options.contacts})


def _result(sample, scene, setup, rec, status, t0, setup_time, compile_time, kernel, stats) -> FailureResult:
    """The :class:`FailureResult` of the event records ``rec [8, events]``."""
    if status == "split" and rec.shape[1] and rec[1, -1] == 0:  # the last solve found nothing loaded: no event
        rec = rec[:, :-1]
    scale, load, broken, iterations, closed, residual, unsettled, critical = rec
    if len(load) == 0:
        raise SceneError("no bond of the sample carries load under this scene (nothing to break)")
    k = int(np.argmax(load))
    delta = setup.delta
    stats = {**stats, "max_residual": float(np.max(residual)) if len(residual) else 0.0,
             "unsettled_contacts": int(np.sum(unsettled)), "bonds_broken": int(np.sum(broken)),
             "bonds_broken_to_peak": int(np.sum(broken[:k + 1])), "cg_iterations": int(np.sum(iterations))}
    f_unit = load[0] / scale[0]
    return FailureResult(
        peak_force=float(load[k]), strength=float(scene.strength(float(load[k]), sample)),
        peak_displacement=float(scale[k] * delta), peak_event=k, displacement=scale * delta, force=load,
        broken=broken.astype(int), critical_bond=critical.astype(int), cg_iterations=iterations.astype(int),
        closed=closed.astype(int), events=len(load), stiffness=float(f_unit / delta), status=status,
        wall_time=time.perf_counter() - t0, setup_time=setup_time, compile_time=compile_time, kernel_time=kernel,
        stats=stats)
