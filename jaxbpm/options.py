"""The DEM's options, :class:`DEM` (``jaxbpm.DEM``), until the DEM is a package of its own (``jaxbpm.dem.options``).

The base, the value checks and the registry of the solvers' options classes are in :mod:`jaxbpm._options`; the
DSM's and the STE's options in :mod:`jaxbpm.dsm.options` and :mod:`jaxbpm.ste.options`.
"""

from __future__ import annotations

from jaxbpm._options import (
    flag, optional, optional_path, option, positive, progress, shown, SolverOptions, unit_interval, whole)
from jaxbpm.errors import OptionsError

__all__ = ["DEM"]


def _neighbors(name, v):
    from jaxbpm.neighbors import NeighborSettings

    if v is not None and not isinstance(v, NeighborSettings):
        raise OptionsError(f"{name} must be a jaxbpm.dem.NeighborSettings or None, got {shown(v)}")


class DEM(SolverOptions):
    """Explicit DEM options (what ``jaxbpm.solve(..., method="dem")`` takes).

    A ``KeyboardInterrupt`` during the run (Ctrl-C, or raised by the ``progress`` callable) raises
    :class:`~jaxbpm.errors.SimulationInterrupted`, whose ``result`` is the :class:`~jaxbpm.result.Result` of the part
    that was run (``interrupted=True``, status ``"interrupted"``; the record file is kept, and the state after the
    last completed chunk is saved in it). A Ctrl-C before the first chunk raises a plain ``KeyboardInterrupt`` (the
    record file, if any, says ``"interrupted"``). ``Result.setup_time`` is what comes before the first chunk (model,
    time step, loading, neighbour list, padding, initial state), ``compile_time`` the tracing and compiling of the
    programs the solve builds (0 when the process had them) and ``run_time`` the rest (the chunks and the work
    between them).

    Attributes:
      dt: time step [s] (default ``safety`` x the critical time step).
      safety: the fraction of the critical time step the default ``dt`` is.
      damping: local damping coefficient alpha, in [0, 1).
      loading_time: loading time [s] (default ``transits`` x the time a wave needs to cross the sample along the
        axis, estimated from the mean bond).
      transits: wave transits per loading when ``loading_time`` is not given.
      chunk: steps per compiled chunk (default a power of two, 32 to 4096 steps, 20-40 chunks a run where that
        range allows, so that samples with about the same number of steps share the compiled chunk).
      progress: print progress, or a callable ``progress(steps_done, steps_total, elapsed_s)``.
      neighbors: a :class:`~jaxbpm.dem.NeighborSettings` (contact candidate lists).
      max_records: points kept in the returned curve.
      record_to: an ``.h5`` path: every step's time, displacement, force, reactions and broken-bond counts are
        appended chunk by chunk as they arrive (see :mod:`jaxbpm.records`); an existing file is replaced only when
        it is a record of the same run or with ``overwrite=True``.
      snapshots: ``K`` VTU frames evenly spaced in time, the first at rest (with ``vtu``).
      vtu: the ParaView series ``"dir/run.pvd"`` the frames are written to as the run goes: displacement, velocity,
        force and broken bonds (tensile, shear) per particle; per bond ``intact``, ``break_mode`` and
        ``broken_time`` (with ``snapshots``).
      pad: a bonds-only scene (no contacts, no walls) runs on the sample padded to its size class
        (:func:`jaxbpm._compile.size_class`: extra particles clamped at rest, joined by bonds without stiffness that
        never break), so that another sample of that class reuses the compiled programs; curves, time step,
        records, frames and the returned state are the sample's own.
      throw: raise the :class:`~jaxbpm.errors.SolveError` of a failed status (``False``: return the result).
      overwrite: replace an existing record file of another run.
      resume: the ``.h5`` record of an interrupted run: continue that run from its saved state and append to its
        record, giving the same records and stiffness as an uninterrupted run (to round-off; give the same sample,
        scene and options: the record's time step, speed, damping, chunk and sample fingerprint must agree, else an
        error names what differs).
    """

    method = "dem"

    dt: float | None = option(None, optional(positive))
    safety: float = option(0.5, unit_interval())
    damping: float = option(0.7, unit_interval(False, False))
    loading_time: float | None = option(None, optional(positive))
    transits: float = option(40.0, positive)
    chunk: int | None = option(None, optional(whole))
    progress: object = option(False, progress)
    neighbors: object = option(None, _neighbors)
    max_records: int = option(2000, whole)
    record_to: object = option(None, optional_path)
    snapshots: int | None = option(None, optional(whole))
    vtu: object = option(None, optional_path)
    pad: bool = option(True, flag)
    throw: bool = option(True, flag)
    overwrite: bool = option(False, flag)
    resume: object = option(None, optional_path)
