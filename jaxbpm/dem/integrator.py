"""The DEM run: :func:`integrate` advances a model under a loading in compiled chunks of steps
(:mod:`jaxbpm.dem.chunk`) and returns its :class:`Outcome`; :func:`simulate` is the same run that raises on failure.

Between chunks, outside jit, the run checks the chunk: instability first (a blown-up chunk also overflows the
candidate list), then the pairs within reach (more than their slots: the chunk runs again with more), the candidate
list (its buffer overflowed or the particles left its box: it is allocated again and the chunk runs again, so no
contact is ever dropped), and a list built on the host that would go stale (built again where the next step takes the
particles, and the chunk goes on from there). Accepted chunks hand their records to ``on_chunk`` and progress. With a
stop after the peak (:mod:`jaxbpm.dem.peak`) the chunks track the force's peak on the device; a chunk in which the
run stopped ends there, and the run ends with it.

Contacts: on the CPU the candidate list is built on the host by a k-d tree between chunks; on accelerators it is
jax-md's cell list, built again inside the step (:func:`jaxbpm.dem.neighbors.neighbors_owner`).
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm import _interrupt
from jaxbpm._compile import compile_clock
from jaxbpm.dem.chunk import _ahead, _run_chunk
from jaxbpm.dem.forces import initial_cohesion
from jaxbpm.dem.neighbors import (_remap_history, HostList, near_count, near_size, neighbors_owner,
                                  NeighborSettings)
from jaxbpm.dem.peak import PeakStop, tracker
from jaxbpm.dem.state import DEMState
from jaxbpm.dem.stepper import _precompute, _start, _with_bond_springs
from jaxbpm.errors import InstabilityError, SimulationInterrupted
from jaxbpm.physics.loading import Loading
from jaxbpm.physics.model import Model
from jaxbpm.status import Status

__all__ = ["Outcome", "integrate", "simulate", "progress_printer", "NEAR_MARGIN"]

#: the pairs within reach (see :func:`jaxbpm.dem.stepper.step`): within this fraction of the candidate list's skin of
#: touching (0.05 r_min with the default skin, found again every ~0.025 r_min of motion); ``None``: every step tests
#: and packs the whole candidate list
NEAR_MARGIN = 0.1


class Outcome(NamedTuple):
    """What a DEM run ends with, whether it ran to the end or not.

    Attributes:
        state: the state after the last completed chunk.
        records: per-step arrays of the completed chunks (``reaction [steps, W+2, 3]``, ``vmax [steps]``,
            ``time [steps]``; with breakage ``broken [steps, 2]``, the cumulative tensile and shear counts); empty
            when no chunk completed.
        stats: the run's statistics (see :func:`integrate`); with ``failure`` (the message) when unstable.
        status: :class:`~jaxbpm.status.Status` ``CONVERGED`` (every step ran, or the run stopped after the peak:
            ``stats["stop_reason"]`` says which), ``UNSTABLE`` (the run blew up, or the
            candidate list was allocated again and again for one chunk) or ``INTERRUPTED`` (a ``KeyboardInterrupt``:
            Ctrl-C, or raised by a callback; a chunk in flight is dropped).
    """

    state: DEMState
    records: dict
    stats: dict
    status: Status


def integrate(model: Model, params, load: Loading, *, dt: float, n_steps: int, damping: float = 0.0,
              chunk: int = 1000, neighbors: NeighborSettings | None = None, progress: bool | Callable = False,
              dt_crit: float | None = None, state: DEMState | None = None,
              on_chunk: Callable[[int, DEMState, dict], Any] | None = None, stop: PeakStop | None = None,
              peak: float | None = None) -> Outcome:
    """Run ``n_steps`` DEM steps (rounded up to whole chunks) and return the outcome, failed or not.

    Args:
        model: the run's model.
        params: the bond and contact parameters.
        load: the loading.
        dt: the time step [s].
        n_steps: steps to run.
        damping: the local damping coefficient (0: undamped).
        chunk: steps per compiled program.
        neighbors: the candidate list's settings (default: a skin of half the smallest radius).
        progress: ``True`` prints progress (:func:`progress_printer`); a callable is called as
            ``progress(steps_done, steps_total, elapsed_s)`` after every chunk.
        dt_crit: the critical time step, named in the failure messages.
        state: the state to start from (default: the model at rest, :func:`jaxbpm.dem.stepper.init_state`).
        on_chunk: called as ``on_chunk(steps_done, state, chunk_records)`` after every chunk (records of that chunk
            only, NumPy arrays), e.g. to write them to a file as they arrive.
        stop: the stop after the peak (:func:`jaxbpm.dem.peak.peak_stop`): the run ends after the step where the
            force has fallen to its fraction of the peak; the progress then gets ``steps_total = steps_done``.
        peak: the force's peak before ``state`` [N] (a resumed run's), for ``stop``.

    Returns:
        The :class:`Outcome`. Its stats: ``wall_time`` = ``setup_time`` (candidate list, initial state) +
        ``compile_time`` (tracing, compiling or reading from the persistent cache the programs the run builds, see
        :func:`jaxbpm._compile.compile_clock`; 0 when this process had them all) + ``run_time`` (the rest: the
        chunks, the checks between them, records and callbacks); ``kernel_time`` (the chunks alone), ``steps``,
        ``steps_per_second`` (the median chunk), ``reallocations`` of the candidate list; with contacts the list's
        capacity (``contact_capacity``), the most pairs within reach (``contacts_within_reach``) and their slots
        (``contact_slots``), where the list is built (``contact_list``: ``"host"`` or ``"jax-md"``), how often it
        was built again (``contact_rebuilds``) and how often the pairs within reach were found
        (``contacts_refound``), chunks run again included. A run that did not finish has ``steps_planned`` and
        ``unstable`` or ``interrupted`` set; ``stop_reason`` says why the run ended (``"after_peak"``,
        ``"full_strain"``, ``"unstable"`` or ``"interrupted"``), and a run stopped after the peak has
        ``steps_planned``.

    Raises:
        KeyboardInterrupt: an interruption during the set-up, before the first chunk.
    """
    with compile_clock() as compiling:
        run = _Run(model, params, load, dt, damping, chunk, n_steps, neighbors, state, compiling, stop, peak)
        return run.loop(_progress_fn(progress), on_chunk, dt_crit)


def simulate(model: Model, params, load: Loading, *, dt: float, n_steps: int, damping: float = 0.0,
             chunk: int = 1000, neighbors: NeighborSettings | None = None, progress: bool | Callable = False,
             dt_crit: float | None = None, state: DEMState | None = None,
             on_chunk: Callable[[int, DEMState, dict], Any] | None = None, stop: PeakStop | None = None,
             peak: float | None = None):
    """:func:`integrate`, raising where the run did not finish.

    Args:
        model, params, load, dt, n_steps, damping, chunk, neighbors, progress, dt_crit, state, on_chunk, stop, peak:
            as for :func:`integrate`.

    Returns:
        ``(final_state, records, stats)`` (see :class:`Outcome`).

    Raises:
        InstabilityError: the run blew up (NaN, or a particle moving over a quarter of the smallest radius in one
            step), naming the time step and the critical one; it carries ``state``, ``records`` and ``stats`` of the
            chunks before.
        SimulationInterrupted: a ``KeyboardInterrupt`` (Ctrl-C, or raised by a callback), carrying the state,
            records and stats of the chunks completed so far.
    """
    out = integrate(model, params, load, dt=dt, n_steps=n_steps, damping=damping, chunk=chunk, neighbors=neighbors,
                    progress=progress, dt_crit=dt_crit, state=state, on_chunk=on_chunk, stop=stop, peak=peak)
    if out.status == Status.UNSTABLE:
        err = InstabilityError(out.stats["failure"])
        err.state, err.records, err.stats = out.state, out.records, out.stats
        raise err
    if out.status == Status.INTERRUPTED:
        raise SimulationInterrupted(out.state, out.records, out.stats)
    return out.state, out.records, out.stats


class _Chunk(NamedTuple):
    """A chunk as it came back: the state after it, its records (host arrays, the steps run), its kernel time, the
    overflow flags (candidate list, pairs within reach), whether the positions are finite, the particles' extent,
    the steps run, the most pairs within reach, the peak tracker after it and whether the run stopped in it."""

    state: DEMState
    records: dict
    elapsed: float
    overflow: bool
    near_overflow: bool
    finite: bool
    extent: tuple
    ran: int
    within: int
    track: Any
    stopped: bool


class _Run:
    """The host side of a run: its set-up and the loop over chunks with the checks between them."""

    def __init__(self, model, params, load, dt, damping, chunk, n_steps, neighbors, state, compiling, stop, peak):
        self.t0 = time.perf_counter()
        self.model, self.load, self.dt, self.damping, self.compiling = model, load, dt, damping, compiling
        self.clock = {"t0": self.t0, "compiling": compiling, "kernel": []}
        self.r_min = float(np.min(np.asarray(model.radii)))
        self.owner, self.margin, self.near_slots = None, None, None
        self.origin = jax.device_put(np.zeros(model.dim, model.positions0.dtype))
        nbrs = None
        if model.contacts:
            nbrs, state = self._contacts(neighbors, state)
        if state is None:
            state, self.pre = _start(model, params, load, nbrs)
        else:
            self.pre = _precompute(model, params)
        jax.block_until_ready((state, self.pre))
        _interrupt.check()  # (a Ctrl-C the setup's garbage collection swallowed stops here: nothing has run yet)
        self.clock["setup_compile"] = compiling.seconds
        self.chunk = max(1, min(chunk, n_steps))
        self.n_chunks = -(-n_steps // self.chunk)  # every chunk has the same length: it compiles once
        self.state = self.done = state  # done: the state after the last completed chunk
        self.records, self.reallocs, self.stalled = [], 0, 0
        # the stop after the peak: the tracker after the last completed chunk (or part of one), and whether it fired
        self.stop, self.stopped, self.steps_run = stop, False, 0
        self.track = None if stop is None else tracker(-np.inf if peak is None else peak, model.positions0.dtype)
        # a candidate list built on the host: a chunk stops before the list goes stale, the list is built again and
        # the chunk goes on from there (``left`` steps; the records and kernel time of its parts so far in ``parts``)
        self.host = model.contacts and isinstance(state.nbrs, HostList)
        self.left, self.parts, self.forced = self.chunk, [], 0

    def _contacts(self, neighbors, state):
        """The candidate list's owner, the list at the start, the pairs within reach's margin and slots, and a
        given start ``state`` moved onto the new list."""
        model, dtype = self.model, self.model.positions0.dtype
        settings = neighbors or NeighborSettings(skin=0.5 * self.r_min)
        self.owner = neighbors_owner(model, settings, model.positions0)
        at = model.positions0 if state is None else state.positions
        if state is not None and state.nbrs is None:
            # a start of its own (the DSM's elastic state): the list keeps the slots of a run from rest where its
            # pairs fit there, and with them that run's compiled chunk
            self.owner.allocate(model.positions0)
        nbrs = self.owner.allocate(at)
        if NEAR_MARGIN is not None and model.contact_law != "cohesive":
            margin = NEAR_MARGIN * settings.skin
            within = near_count(model, at, nbrs, margin)
            # the bonded pairs' contacts run on the bond list; the slots hold the others, which a breaking sample
            # makes more of as it goes: room for 1/32 of the bonds from the start, so that few chunks run again
            self.margin = jnp.asarray(margin, dtype)
            self.near_slots = near_size(max(within, model.bonds.shape[0] // 32), nbrs.idx.shape[1])
            self.clock["contact_slots"], self.clock["near_count"] = self.near_slots, within
        self.origin = jnp.asarray(self.owner.origin, dtype)
        if state is not None:
            state = _onto_list(model, state, nbrs)
        return nbrs, state

    def loop(self, report, on_chunk, dt_crit) -> Outcome:
        """Run the chunks until all are done, the run fails or is interrupted; returns the outcome."""
        crit = f"{dt_crit:.4g} s" if dt_crit is not None else "unknown"  # for the error messages
        self.clock["loop"] = time.perf_counter()
        failure = None
        try:
            while len(self.records) < self.n_chunks and failure is None and not self.stopped:
                _interrupt.check()
                failure = self._advance(crit, on_chunk, report)
        except KeyboardInterrupt:
            _interrupt.clear()
            return self._outcome(Status.INTERRUPTED)
        return self._outcome(Status.CONVERGED if failure is None else Status.UNSTABLE, failure)

    def _advance(self, crit, on_chunk, report) -> str | None:
        """Run the next chunk (or the rest of it) and act on the checks; returns the failure message, if any."""
        c = self._run()
        # instability first: a blown-up chunk also overflows the candidate list, and allocating it again for that
        # would only run it again (and again)
        vmax = float(np.max(c.records["vmax"])) if c.records["vmax"].size else 0.0
        if not np.isfinite(vmax) or not c.finite or vmax * self.dt > 0.25 * self.r_min:
            return (f"DEM run became unstable within steps {self._steps(0)}..{self._steps(1)} (non-finite or runaway "
                    f"motion, max speed {vmax:.3g} m/s): time step dt = {self.dt:.4g} s, critical time step estimate "
                    f"= {crit}. Use a smaller time step (or a smaller safety factor).")
        if c.near_overflow and not c.overflow:
            self._more_slots(c.within)
        elif self.model.contacts and (c.overflow or not self.owner.inside(*c.extent)):
            return self._reallocate(c, vmax, crit)
        elif self.host and c.ran < self.left and not c.stopped:
            self._rebuild_ahead(c)
        else:
            self._accept(c, on_chunk, report)
        return None

    def _steps(self, k: int) -> int:
        return (len(self.records) + k) * self.chunk

    def _run(self) -> _Chunk:
        """The next chunk, run from the current state, and what the checks need of it."""
        tc, compiled, host = time.perf_counter(), self.compiling.seconds, self.host
        new, rec, overflow, finite, pmin, pmax, counts, track = _run_chunk(
            self.model, self.pre, self.load, self.state, self.dt, self.damping, self.origin, self.chunk,
            self.margin, self.near_slots, jnp.asarray(self.left, jnp.int32) if host else None,
            jnp.asarray(self.forced, jnp.int32) if host else None, self.stop, self.track)
        jax.block_until_ready(new.positions)
        elapsed = time.perf_counter() - tc - (self.compiling.seconds - compiled)  # (less a new program's compile)
        rec, (ran, within, refound, rebuilt) = jax.device_get(rec), (int(c) for c in np.asarray(counts))
        self.clock["rebuilds"] = self.clock.get("rebuilds", 0) + rebuilt
        if self.near_slots is not None:
            self.clock["near_count"] = max(self.clock["near_count"], within)
            self.clock["near_found"] = self.clock.get("near_found", 0) + refound
        rec = {k: r[:ran] for k, r in rec.items()}  # (steps after a stop, or after the host's list went stale)
        if host and ran == 0:
            new = self.state  # the first step would go stale: the list is built again
        overflow, near_overflow = (bool(o) for o in np.asarray(overflow))
        stopped = track is not None and bool(track.stopped)
        return _Chunk(new, rec, elapsed, overflow, near_overflow, bool(finite), (pmin, pmax), ran, within, track,
                      stopped)

    def _more_slots(self, within: int) -> None:
        """More pairs within reach than slots: the chunk runs again with more (a new size compiles it again)."""
        capacity = self.state.nbrs.idx.shape[1]
        self.near_slots = self.clock["contact_slots"] = min(max(near_size(within, capacity), 2 * self.near_slots),
                                                            capacity)

    def _reallocate(self, c: _Chunk, vmax: float, crit: str) -> str | None:
        """The candidate list overflowed or the particles left its box: allocate it again from the chunk's start and
        run the chunk again (a new buffer size compiles it again). Returns the failure message of a run that
        stalls (the same chunk five times)."""
        self.reallocs += 1
        self.stalled += 1
        if self.stalled > 4:
            return (f"DEM run stalled within steps {self._steps(0)}..{self._steps(1)}: the neighbour list was "
                    f"re-allocated {self.stalled} times for the same chunk (particles moving too far, too fast: max "
                    f"speed {vmax:.3g} m/s) with time step dt = {self.dt:.4g} s, critical time step estimate = "
                    f"{crit}. Use a smaller time step (or a smaller safety factor).")
        extra = int(np.ceil(0.5 * self.state.nbrs.idx.shape[1] / self.model.n)) if c.overflow else 0
        self.state = self.done = _with_new_list(self.model, self.owner, self.state, extra_per_particle=extra,
                                                reach=c.extent)
        self.origin = jnp.asarray(self.owner.origin, self.model.positions0.dtype)
        self._fit_slots()
        return None

    def _rebuild_ahead(self, c: _Chunk) -> None:
        """The host's list would go stale in the next step: build it again where that step takes the particles (as
        jax-md's list is built again inside the step) and go on with that step unchecked: a particle moving more
        than half the skin in every step (a skin set small) costs a rebuild a step, not the run."""
        self.parts.append((c.records, c.elapsed))
        self.left -= c.ran
        self.track = c.track
        self.state = _with_new_list(self.model, self.owner, c.state,
                                    at=_ahead(self.model, self.load, c.state, self.dt, self.damping))
        self.clock["rebuilds"] = self.clock.get("rebuilds", 0) + 1
        self._fit_slots()
        self.forced = 1

    def _fit_slots(self) -> None:
        if self.near_slots is not None:
            self.near_slots = self.clock["contact_slots"] = min(self.near_slots, self.state.nbrs.idx.shape[1])

    def _accept(self, c: _Chunk, on_chunk, report) -> None:
        """A completed chunk (its parts joined): its records kept, handed to ``on_chunk`` and the progress."""
        rec, elapsed = c.records, c.elapsed
        if self.parts:
            self.parts.append((rec, elapsed))
            rec = {k: np.concatenate([p[0][k] for p in self.parts]) for k in rec}
            elapsed = sum(p[1] for p in self.parts)
        self.left, self.parts, self.forced = self.chunk, [], 0
        self.clock["kernel"].append(elapsed)
        self.stalled = 0
        self.state = self.done = c.state
        self.track, self.stopped = c.track, c.stopped
        self.records.append(rec)
        self.steps_run += len(rec["time"])
        if on_chunk is not None:
            on_chunk(self.steps_run, self.state, rec)
        total = self.steps_run if self.stopped else self.n_chunks * self.chunk
        report(self.steps_run, total, time.perf_counter() - self.t0)

    def _outcome(self, status: Status, failure: str | None = None) -> Outcome:
        state = self.done if status != Status.CONVERGED else self.state
        out, stats = _collect(self.model, state, self.records, self.chunk, self.reallocs, self.clock)
        planned = self.n_chunks * self.chunk
        if status == Status.UNSTABLE:
            stats.update(unstable=True, steps_planned=planned, failure=failure, stop_reason="unstable")
        elif status == Status.INTERRUPTED:
            stats.update(interrupted=True, steps_planned=planned, stop_reason="interrupted")
        elif self.stopped:
            stats.update(steps_planned=planned, stop_reason="after_peak")
        else:
            stats["stop_reason"] = "full_strain"
        return Outcome(state, out, stats, status)


def _onto_list(model: Model, state: DEMState, nbrs) -> DEMState:
    """A given start ``state`` on the new candidate list ``nbrs``: its per-contact history carried over from its own
    list's pairs (a resumed run), or empty (a state without one)."""
    if state.nbrs is not None:
        spring, cohesion = _remap_history(state.nbrs.idx.T, nbrs.idx.T, model.n, state.spring, state.cohesion)
        state = dataclasses.replace(state, nbrs=nbrs, spring=spring, cohesion=cohesion)
    else:
        state = dataclasses.replace(state, nbrs=nbrs,
                                    spring=jnp.zeros((nbrs.idx.shape[1], model.dim), model.positions0.dtype))
        if model.contact_law == "cohesive":
            state = dataclasses.replace(state, cohesion=initial_cohesion(model, state))
    return _with_bond_springs(model, state)


def _with_new_list(model, nb_owner, state, at=None, **allocate):
    """``state`` with a candidate list built again at its positions (or ``at``; ``allocate``: the owner's
    ``allocate`` options) and its per-contact history (springs, cohesion) carried over to the new list's layout."""
    nbrs = nb_owner.allocate(state.positions if at is None else at, **allocate)
    spring, cohesion = _remap_history(state.nbrs.idx.T, nbrs.idx.T, model.n, state.spring, state.cohesion)
    return dataclasses.replace(state, nbrs=nbrs, spring=spring, cohesion=cohesion)


def _collect(model, state, records, chunk, reallocs, clock):
    """The records of the completed chunks, concatenated, and the run's statistics (see :func:`integrate`)."""
    kernel = clock["kernel"]
    per_chunk = float(np.median(kernel)) if kernel else float("nan")
    out = {k: np.concatenate([r[k] for r in records]) for k in records[0]} if records else {}
    wall, compile_time = time.perf_counter() - clock["t0"], clock["compiling"].seconds
    setup = clock["loop"] - clock["t0"] - clock["setup_compile"]
    stats = {"setup_time": setup, "compile_time": compile_time, "run_time": wall - setup - compile_time,
             "wall_time": wall, "kernel_time": float(np.sum(kernel)),
             "steps": int(sum(len(r["time"]) for r in records)),
             "steps_per_second": chunk / per_chunk, "reallocations": reallocs,
             "contact_capacity": int(state.nbrs.idx.shape[1]) if model.contacts else 0,
             "contact_slots": clock.get("contact_slots", 0), "contacts_within_reach": clock.get("near_count", 0),
             "contact_rebuilds": clock.get("rebuilds", 0), "contacts_refound": clock.get("near_found", 0),
             "contact_list": ("host" if isinstance(state.nbrs, HostList) else "jax-md") if model.contacts else None}
    return out, stats


def progress_printer(strain_per_step: float | None = None):
    """A progress callback for :func:`integrate`: a bar of DEM steps on stderr (:mod:`jaxbpm.progress`).

    Args:
        strain_per_step: the simulated strain of one step, shown beside the bar when given.

    Returns:
        A callable ``report(steps_done, steps_total, elapsed_s)``.
    """
    from jaxbpm.progress import bar

    shown = []

    def report(done, total, elapsed):
        if not shown:
            shown.append(bar("DEM steps", total=total))
        b = shown[0]
        b.update(done - b.n)
        if strain_per_step is not None:
            b.set_postfix_str(f"strain {100 * strain_per_step * done:.4f} %", refresh=False)
        if done >= total:
            b.close()

    return report


def _progress_fn(progress):
    if callable(progress):
        return progress
    return progress_printer() if progress else (lambda *a: None)
