"""The packing engine of :func:`jaxbpm.generate.random_packing`: force-biased overlap removal with FIRE (Bitzek et
al. 2006, with the FIRE 2.0 corrections of Guenole et al. 2020) on a jax-md neighbour list, in chunks of jitted
steps, with the automatic packing fraction's trials, the jamming test and the progress lines.

Everything here is in mean-radius units with the domain's lower corner at the origin; jax-md runs under local
``jax.numpy_dtype_promotion("standard")`` and ``jax.numpy_rank_promotion("allow")`` contexts.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm._spatial import HostList, jax_md_neighbors, morton_order, pair_list, stale
from jaxbpm.errors import SampleError

__all__ = ["Walls", "pack", "pack_auto", "jamming_fraction"]



class Walls(NamedTuple):
    """The domain in units of the mean radius: lower corner at the origin, ``size`` its bounding box, ``cylinder``
    whether it is a z-axis cylinder inscribed in the box (else the box itself)."""

    cylinder: bool
    size: tuple[float, float, float]



# FIRE (Bitzek et al. 2006, with the FIRE 2.0 corrections of Guenole et al. 2020), in mean-radius units with unit
# mass and unit contact stiffness: a particle with z contacts oscillates at ~sqrt(z), so dt_max = 0.5 is stable
# (FIRE halves dt on any uphill step anyway). Displacements are capped per step to keep the first steps, out of a
# random and heavily overlapping start, tame.
_DT_START, _DT_MAX, _DT_MIN = 0.05, 0.5, 1e-3
_N_DELAY, _F_INC, _F_DEC, _ALPHA0, _F_ALPHA = 5, 1.1, 0.5, 0.1, 0.99
_MAX_MOVE = 0.03  # largest displacement per step [mean radii]: fewer neighbour-list rebuilds, as many steps
_SKIN = 0.5  # neighbour-list skin [mean radii]: the list is rebuilt when a particle moved SKIN / 2
_MARGIN = 3.0  # space around the domain in the cell-list box [mean radii]
_CAPACITY = 1.3  # neighbour-list capacity multiplier
_CHUNK = 500  # FIRE steps per jitted chunk
_JAM_CHUNKS, _JAM_PROGRESS = 10, 1e-3  # jammed: the largest overlap fell by < 0.1 % over the last 10 chunks
# Automatic packing fraction (random_packing, packing_fraction=None; the numbers are documented there).
_PHI_BULK, _WALL_LOSS = 0.645, 0.2  # expected jamming fraction: _PHI_BULK - _WALL_LOSS * wall area / volume
_AUTO_CHUNK = 100  # FIRE steps per chunk: the attempts are judged after each
_TRIAL_STEPS, _TRIAL_FROM = 1500, 400  # a fraction above the expected one: step budget, extrapolated from step 400
_STALL_STEPS, _STALL_DROP = 3000, 0.1  # stalled: the lowest largest overlap fell < 10 % over the last 3000 steps


class _Fire(NamedTuple):
    x: jax.Array  # [n, 3] centres, cell-list frame (domain corner at MARGIN)
    v: jax.Array  # [n, 3]
    f: jax.Array  # [n, 3] force at x
    max_overlap: jax.Array  # largest overlap (pairs and walls) at x
    dt: jax.Array
    alpha: jax.Array
    n_pos: jax.Array
    step: jax.Array


def _forces(x, idx, radii, walls, cylinder: bool):
    """Overlap forces ``[n, 3]`` and the largest overlap, pairs from a sparse (both-way) neighbour list."""
    n = x.shape[0]
    i, j = idx[1], idx[0]  # jax-md's sparse lists are grouped by idx[1], padded with n at the end
    valid = i < n
    d = x[i] - x[j.clip(0, n - 1)]
    dist = jnp.sqrt(jnp.sum(d * d, axis=1))
    overlap = jnp.where(valid, radii[i.clip(0, n - 1)] + radii[j.clip(0, n - 1)] - dist, 0.0)
    overlap = jnp.maximum(overlap, 0.0)
    scale = overlap / jnp.maximum(dist, 1e-12)
    f = jax.ops.segment_sum(d * scale[:, None], jnp.where(valid, i, n), num_segments=n,
                            indices_are_sorted=True)
    lo, hi = walls[0], walls[1]
    r = radii[:, None]
    pen_lo = jnp.maximum(r - (x - lo[None, :]), 0.0)
    pen_hi = jnp.maximum(x + r - hi[None, :], 0.0)
    if cylinder:  # side wall: a circle through the middle of the x, y extent
        centre = 0.5 * (lo[:2] + hi[:2])
        big = 0.5 * (hi[0] - lo[0])
        d_xy = x[:, :2] - centre[None, :]
        rho = jnp.sqrt(jnp.sum(d_xy * d_xy, axis=1))
        pen_r = jnp.maximum(rho + radii - big, 0.0)
        f_xy = -d_xy * (pen_r / jnp.maximum(rho, 1e-12))[:, None]
        f = f + jnp.concatenate([f_xy, (pen_lo - pen_hi)[:, 2:]], axis=1)
        wall_max = jnp.maximum(jnp.max(pen_r), jnp.max(jnp.maximum(pen_lo, pen_hi)[:, 2]))
    else:
        f = f + pen_lo - pen_hi
        wall_max = jnp.max(jnp.maximum(pen_lo, pen_hi))
    return f, jnp.maximum(jnp.max(overlap), wall_max)


def _fire_step(state: _Fire, nbrs, radii, walls, cell_box, cylinder: bool):
    """One FIRE step; returns the new state and the updated neighbour list."""
    x, v, f, _, dt, alpha, n_pos, step = state
    power = jnp.sum(f * v)
    uphill = power < 0.0
    n_pos = jnp.where(uphill, 0, n_pos + 1)
    grow = (~uphill) & (n_pos > _N_DELAY)
    dt = jnp.where(uphill, jnp.maximum(dt * _F_DEC, _DT_MIN), jnp.where(grow, jnp.minimum(dt * _F_INC, _DT_MAX), dt))
    alpha = jnp.where(uphill, _ALPHA0, jnp.where(grow, alpha * _F_ALPHA, alpha))
    x = jnp.where(uphill, x - 0.5 * dt * v, x)
    v = jnp.where(uphill, jnp.zeros_like(v), v) + dt * f
    v_norm = jnp.sqrt(jnp.sum(v * v))
    f_norm = jnp.sqrt(jnp.sum(f * f))
    v = (1.0 - alpha) * v + alpha * v_norm / jnp.maximum(f_norm, 1e-30) * f
    move = dt * v
    length = jnp.sqrt(jnp.sum(move * move, axis=1, keepdims=True))
    move = move * jnp.minimum(1.0, _MAX_MOVE / jnp.maximum(length, 1e-30))
    x = jnp.clip(x + move, 0.5, cell_box[None, :] - 0.5)  # keep inside the cell list (never active in practice)
    nbrs = nbrs.update(x)
    f, max_overlap = _forces(x, nbrs.idx, radii, walls, cylinder)
    return _Fire(x, v, f, max_overlap, dt, alpha, n_pos, step + 1), nbrs


def _fire_start(x, nbrs, radii, walls, cylinder: bool) -> _Fire:
    """The FIRE state at rest at ``x``: its forces from the neighbour list ``nbrs``."""
    f, max_overlap = _forces(x, nbrs.idx, radii, walls, cylinder)
    zero = jnp.zeros((), x.dtype)
    return _Fire(x, jnp.zeros_like(x), f, max_overlap, zero + _DT_START, zero + _ALPHA0,
                 jnp.zeros((), jnp.int32), jnp.zeros((), jnp.int32))


@functools.lru_cache(maxsize=8)
def _packer(cell_box: tuple[float, float, float], cutoff: float, cylinder: bool):
    """Neighbour-list functions and the jitted FIRE pieces for one cell-list box (cached: no recompilation)."""
    partition, space = jax_md_neighbors()
    box_arr = np.asarray(cell_box, dtype=np.float64)
    displacement, _ = space.free()
    neighbor_fn = partition.neighbor_list(displacement, box_arr, cutoff, dr_threshold=_SKIN,
                                          capacity_multiplier=_CAPACITY, format=partition.Sparse)
    cell_list_fn = partition.cell_list(box_arr, cutoff + _SKIN, _CAPACITY)

    def allocate(x):
        nbrs = neighbor_fn.allocate(x)
        if nbrs.cell_list_fn is not None:  # a fresh closure per allocation would force a recompilation
            nbrs = dataclasses.replace(nbrs, cell_list_fn=cell_list_fn)
        return nbrs

    init = jax.jit(functools.partial(_fire_start, cylinder=cylinder))

    @jax.jit
    def run(state, nbrs, radii, walls, tol, stop):
        cell = jnp.asarray(box_arr, dtype=state.x.dtype)

        def cond(carry):
            s, nb = carry
            return (s.step < stop) & (s.max_overlap >= tol) & (nb.did_buffer_overflow == 0)

        def body(carry):
            return _fire_step(*carry, radii, walls, cell, cylinder)

        state, nbrs = jax.lax.while_loop(cond, body, (state, nbrs))
        return state, nbrs, nbrs.did_buffer_overflow

    return allocate, init, run


# from this many spheres on the CPU the neighbour list is built on the host (a k-d tree) instead of by jax-md's cell
# list inside the step: the cell list's rebuild fills a dense [n, 27 x cell capacity, 3] candidate array, fresh from
# the system at every rebuild, which costs more than many steps at this size
_HOST_LIST_MIN = 20_000


@functools.lru_cache(maxsize=8)
def _host_packer(cell_box: tuple[float, float, float], cutoff: float, cylinder: bool):
    """:func:`_packer`'s three functions with the neighbour list built on the host (:func:`jaxbpm._spatial.pair_list`,
    both ways): the jitted chunk stops at the step after which a sphere has moved more than half the skin
    (:func:`jaxbpm._spatial.stale`), and the caller rebuilds the list there and recomputes the forces, as on a jax-md
    overflow. The slot count only grows (one compiled chunk)."""
    box = np.asarray(cell_box, dtype=np.float64)
    slots = [0]

    def allocate(x):
        idx, slots[0] = pair_list(np.asarray(x, dtype=np.float64), cutoff + _SKIN, slots[0], _CAPACITY,
                                  both_ways=True)
        return HostList(jnp.asarray(idx), x, jnp.asarray((0.5 * _SKIN) ** 2, x.dtype))

    init = jax.jit(functools.partial(_fire_start, cylinder=cylinder))

    @jax.jit
    def run(state, nbrs, radii, walls, tol, stop):
        cell = jnp.asarray(box, dtype=state.x.dtype)

        def cond(carry):
            s, _, moved = carry
            return (s.step < stop) & (s.max_overlap >= tol) & ~moved

        def body(carry):
            s, nb, _ = carry
            s, nb = _fire_step(s, nb, radii, walls, cell, cylinder)
            return s, nb, stale(nb, s.x)

        return jax.lax.while_loop(cond, body, (state, nbrs, jnp.zeros((), bool)))

    return allocate, init, run


def _packer_for(n: int):
    """:func:`_host_packer` for large samples on the CPU, :func:`_packer` (jax-md's cell list in the step) else."""
    return _host_packer if n >= _HOST_LIST_MIN and jax.default_backend() == "cpu" else _packer


class _Attempt(NamedTuple):
    """One FIRE run at one packing fraction."""

    x: np.ndarray  # [n, 3] float64 centres, mean-radius units, domain corner at the origin
    nbrs: Any  # the neighbour list at the end (the next attempt reuses its capacity: no recompilation)
    steps: list[int]  # step count after each chunk
    overlaps: list[float]  # largest overlap / mean radius after each chunk
    packed: bool


def pack(x0, radii, walls: Walls, cutoff: float, tol: float, max_steps: int, progress, phi: float) -> np.ndarray:
    """Remove the overlaps of spheres at one packing fraction.

    Args:
      x0: ``[n, 3]`` start centres (mean-radius units, domain corner at the origin).
      radii: ``[n]`` radii (mean-radius units).
      walls: the domain.
      cutoff: the neighbour-list cutoff (twice the largest radius).
      tol: the largest overlap accepted (mean radii).
      max_steps: the FIRE step budget.
      progress: see :func:`jaxbpm.generate.random_packing`.
      phi: the packing fraction, for messages.

    Returns:
      ``[n, 3]`` float64 centres.

    Raises:
      SampleError: the spheres jammed or ``max_steps`` ran out.
    """
    cell_box = _cell_box(walls)
    with jax.numpy_dtype_promotion("standard"), jax.numpy_rank_promotion("allow"):
        packer = _packer_for(len(x0))(cell_box, float(cutoff), walls.cylinder)
        report = _reporter(progress, phi)
        run = _relax(packer, x0, radii, walls, _target(tol, cell_box), max_steps, _CHUNK, _jammed, report)
        report.close()
    if not run.packed:
        raise SampleError(_not_converged(run, max_steps, tol, phi))
    return run.x


def pack_auto(start: Callable[[Walls], np.ndarray], radii, walls: list[Walls], fractions: tuple[float, ...],
               cutoff: float, tol: float, max_steps: int, progress) -> tuple[np.ndarray, int]:
    """The densest of several packing fractions at which the spheres pack (the automatic mode of
    :func:`jaxbpm.generate.random_packing`).

    Args:
      start: the start centres ``[n, 3]`` in a domain.
      radii: ``[n]`` radii (mean-radius units).
      walls: the domain of each fraction.
      fractions: the fractions to try, densest first.
      cutoff: the neighbour-list cutoff (twice the largest radius).
      tol: the largest overlap accepted (mean radii).
      max_steps: the FIRE step budget per fraction.
      progress: see :func:`jaxbpm.generate.random_packing`.

    Returns:
      ``(centres [n, 3] float64, index of the fraction kept)``.

    Raises:
      SampleError: the last fraction did not pack either.
    """
    cell_box = _cell_box(walls[-1])  # the largest domain: one cell list, one compiled program for all fractions
    nbrs = None
    with jax.numpy_dtype_promotion("standard"), jax.numpy_rank_promotion("allow"):
        packer = _packer_for(len(radii))(cell_box, float(cutoff), walls[0].cylinder)
        target = _target(tol, cell_box)
        for k, (phi, wall) in enumerate(zip(fractions, walls)):
            last = k == len(fractions) - 1
            trial = None if phi <= jamming_fraction(wall) else _TRIAL_STEPS
            give_up = _jammed if last else functools.partial(_give_up, target=target, trial=trial)
            t0 = time.perf_counter()
            report = _reporter(progress, phi)
            run = _relax(packer, start(wall), radii, wall, target, max_steps, _CHUNK if last else _AUTO_CHUNK,
                         give_up, report, nbrs, at_rest=True)
            report.close()
            if run.packed:
                return run.x, k
            if last:
                raise SampleError(_not_converged(run, max_steps, tol, phi))
            why = ("max_steps ran out" if run.steps[-1] >= max_steps
                   else "would not pack within a trial" if trial else "stalled")
            _say(progress, f"packing fraction {phi:g}: given up after {run.steps[-1]} FIRE steps ({why}; largest "
                           f"overlap {run.overlaps[-1]:.2e} x mean radius, {time.perf_counter() - t0:.2f} s); "
                           f"trying {fractions[k + 1]:g}")
            nbrs = run.nbrs
    raise AssertionError("unreachable")


def _relax(packer, x0, radii, walls: Walls, target: float, max_steps: int, chunk: int,
           give_up: Callable[[list[int], list[float]], bool], report, nbrs=None, at_rest: bool = False) -> _Attempt:
    """FIRE from ``x0`` (mean-radius units, domain corner at the origin) in chunks of ``chunk`` steps until the
    largest overlap is below ``target``, ``give_up(steps, overlaps)`` says so, or ``max_steps`` run out. ``nbrs``:
    a neighbour list (of earlier positions) to update rather than allocate: its capacity is kept, so the compiled
    chunk is reused; the attempt's first step then only updates the list and computes the forces. ``at_rest``: start
    so without ``nbrs`` too (the automatic mode's attempts: each runs the same steps whether or not others came
    before it; near jamming, one step's offset decides whether a fraction packs)."""
    allocate, init, run = packer
    dtype = jnp.result_type(float)
    t0 = time.perf_counter()
    size = np.asarray(walls.size)
    # the spheres relaxed in the order of a space-filling curve through their start: the pair gathers and force
    # sums touch memory in runs; the result comes back in their order
    order = morton_order(x0)
    x = jnp.asarray(np.asarray(x0)[order] + _MARGIN, dtype=dtype)
    r = jnp.asarray(np.asarray(radii)[order], dtype=dtype)
    w = jnp.asarray(np.stack([np.full(3, _MARGIN), size + _MARGIN]), dtype=dtype)
    tol_j = jnp.asarray(target, dtype=dtype)
    fresh = nbrs is None
    if fresh:
        nbrs = allocate(x)
    if fresh and not at_rest:
        state = init(x, nbrs, r, w)
    else:  # at rest, without force: the first step moves nothing, it updates the list and computes the forces
        scalar = functools.partial(np.asarray, dtype=x.dtype)
        zeros, count = np.zeros(x.shape, x.dtype), np.zeros((), np.int32)
        state = jax.tree.map(jnp.asarray, _Fire(x, zeros, zeros, scalar(np.inf), scalar(_DT_START),
                                                scalar(_ALPHA0), count, count))
    steps, overlaps = [], []
    while True:
        stop = min(int(state.step) + chunk, max_steps)
        while True:
            state, nbrs, rebuild = run(state, nbrs, r, w, tol_j, jnp.asarray(stop, dtype=jnp.int32))
            if not bool(rebuild):
                break
            # the last step used a truncated (jax-md) or stale (host) list: rebuild, recompute the forces, and go
            # on with the chunk
            nbrs = allocate(state.x)
            fresh = init(state.x, nbrs, r, w)
            state = state._replace(f=fresh.f, max_overlap=fresh.max_overlap)
            if int(state.step) >= stop or not float(state.max_overlap) >= target:
                break
            report(int(state.step), float(state.max_overlap), time.perf_counter() - t0, False)  # (display only)
        step, worst = int(state.step), float(state.max_overlap)
        steps.append(step)
        overlaps.append(worst)
        packed = worst < target
        report(step, worst, time.perf_counter() - t0, packed)
        if packed or step >= max_steps or give_up(steps, overlaps):
            break
    x = np.empty(x.shape, np.float64)
    x[order] = np.asarray(state.x, dtype=np.float64) - _MARGIN
    return _Attempt(x, nbrs, steps, overlaps, packed)


def _cell_box(walls: Walls) -> tuple[float, float, float]:
    """The cell-list box around a domain (integers: the compiled program is reused across seeds)."""
    return tuple(float(v) for v in np.ceil(np.asarray(walls.size) + 2.0 * _MARGIN))


def _target(tol: float, cell_box) -> float:
    """Stop a little below ``tol``, so that rounding (float32: ~eps * box size) cannot lift the result above it."""
    return max(tol - 16.0 * float(jnp.finfo(jnp.result_type(float)).eps) * max(cell_box), 0.5 * tol)


def _jammed(steps: list[int], overlaps: list[float]) -> bool:
    """Whether the spheres jammed: the largest overlap fell by < 0.1 % over the last 10 chunks (the rule of an
    explicit fraction and of the automatic mode's last one)."""
    return len(overlaps) > _JAM_CHUNKS and overlaps[-1] > (1.0 - _JAM_PROGRESS) * overlaps[-1 - _JAM_CHUNKS]


def _give_up(steps, overlaps, *, target: float, trial: int | None) -> bool:
    """Whether an attempt of the automatic mode should be given up, from its history.

    Args:
      steps: ``[k]`` step count after each chunk (increasing).
      overlaps: ``[k]`` largest overlap after each chunk.
      target: the overlap to reach.
      trial: the step budget of a fraction above the expected jamming fraction; ``None``: none.

    Returns:
      True when the attempt stalled: the lowest largest overlap so far fell by less than ``_STALL_DROP`` over the
      last ``_STALL_STEPS`` steps. With a ``trial`` budget also when it is spent, or when, from step
      ``_TRIAL_FROM`` on, the geometric decay of the lowest overlap so far over the second half of the history,
      extrapolated, reaches ``target`` only after ``trial`` steps (or never: no decay).
    """
    steps = np.asarray(steps, dtype=np.int64)
    best = np.minimum.accumulate(np.asarray(overlaps, dtype=np.float64))
    now = int(steps[-1])
    then = np.searchsorted(steps, now - _STALL_STEPS, side="right") - 1  # the last chunk _STALL_STEPS ago
    if then >= 0 and best[-1] > (1.0 - _STALL_DROP) * best[then]:
        return True
    if trial is None:
        return False
    if now >= trial:
        return True
    half = np.searchsorted(steps, now // 2, side="right") - 1  # the last chunk at or before half the steps
    if now < _TRIAL_FROM or half < 0 or best[-1] <= target:
        return False
    rate = np.log(best[half] / best[-1]) / (now - steps[half])  # per step
    return bool(rate <= 0.0 or now + np.log(best[-1] / target) / rate > trial)


def jamming_fraction(walls: Walls) -> float:
    """The empirical packing fraction near which fresh insertions in a domain jam.

    ``_PHI_BULK - _WALL_LOSS * S / V`` (wall area over volume, mean-radius units; fitted to boxes of 400 to 4000
    spheres with 5 % radius spread).

    Args:
      walls: the domain.

    Returns:
      The expected jamming fraction.
    """
    a, b, c = walls.size
    if walls.cylinder:
        radius = 0.5 * a
        area, volume = 2.0 * np.pi * radius * (radius + c), np.pi * radius**2 * c
    else:
        area, volume = 2.0 * (a * b + b * c + c * a), a * b * c
    return _PHI_BULK - _WALL_LOSS * area / volume


def _not_converged(run: _Attempt, max_steps: int, tol: float, phi: float) -> str:
    why = (f"the spheres jammed (no progress in the last {_JAM_CHUNKS * _CHUNK} steps)"
           if _jammed(run.steps, run.overlaps) else f"max_steps={max_steps} FIRE steps were not enough")
    return (f"random packing did not converge: {why}; reached largest overlap {run.overlaps[-1]:.3g} x mean radius "
            f"(tolerance {tol:g}) at packing fraction {phi:g}. Try a lower packing_fraction (small samples "
            f"jam earlier: the spheres pack loosely along the walls)")


def _reporter(progress, phi: float) -> Callable[[int, float, float, bool], None]:
    """Progress of one attempt: a callable gets every chunk (and every rebuild of a host neighbour list, for display
    only); ``True`` shows a bar of FIRE steps with the largest overlap (:mod:`jaxbpm.progress`), and a last line
    when the attempt packed. ``close()`` ends its display."""
    if callable(progress) or not progress:
        def report(step, worst, elapsed, packed):
            if callable(progress):
                progress(step, worst, elapsed)

        report.close = lambda: None  # (every reporter is closed after its attempt)
        return report
    from jaxbpm.progress import bar

    shown = bar(f"random_packing: packing fraction {phi:g}", unit=" FIRE step", leave=False)

    def report(step, worst, elapsed, packed):
        shown.update(step - shown.n)
        shown.set_postfix_str(f"max overlap / mean radius {worst:.3e}", refresh=False)
        if packed:
            shown.close()
            _say(True, f"packing fraction {phi:g}: packed after {step} FIRE steps ({elapsed:.2f} s)")

    report.close = shown.close
    return report


def _say(progress, message: str) -> None:
    if progress is True:
        from jaxbpm.progress import say

        say(f"random_packing: {message}")
