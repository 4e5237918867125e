"""The DEM's options, :class:`DEM` (``jaxbpm.DEM``): what ``jaxbpm.solve(..., method="dem")``,
:func:`jaxbpm.dem.solve_scene` and :func:`jaxbpm.dem.solve_batch` take."""

from __future__ import annotations

from jaxbpm._options import (choice, flag, optional, optional_path, option, positive, progress, shown,
                             SolverOptions, unit_interval, whole)
from jaxbpm.dem.neighbors import NeighborSettings
from jaxbpm.errors import OptionsError

__all__ = ["DEM"]


def _neighbors(name, v):
    if v is not None and not isinstance(v, NeighborSettings):
        raise OptionsError(f"{name} must be a jaxbpm.dem.NeighborSettings or None, got {shown(v)}")


class DEM(SolverOptions):
    """Options of the explicit DEM (a run in time, under the scene's loading, to its target strain).

    ``jaxbpm.solve(sample, scene, jaxbpm.DEM(transits=20))`` is the same solve as
    ``jaxbpm.solve(sample, scene, method="dem", transits=20)``.

    Attributes:
      dt: the time step [s]; ``None``: ``safety`` x the critical time step
        (:func:`~jaxbpm.dem.timestep.critical_time_step`). A ``dt`` above the critical one warns: bonds alone blow up
        (status ``"unstable"``), a run with contacts may finish with a wrong stiffness.
      safety: the default time step's fraction of the critical one, in (0, 1].
      damping: the local damping coefficient, in [0, 1): ``F_d = -damping |F| sign(v)`` per component, and the same
        for moments (0: undamped, energy-conserving dynamics).
      loading_time: the loading time [s]; ``None``: ``transits`` x the time an elastic wave needs to cross the
        sample along the scene's path (from the mean bond, or contact, stiffness and the mean mass).
      transits: wave transits per loading when ``loading_time`` is not given.
      chunk: steps per compiled chunk; ``None``: a power of two, 32 to 4096 steps, about 20 chunks a run (with
        ``snapshots``, at least one chunk per frame), so that samples with about the same number of steps share the
        compiled chunk. The run's steps are whole chunks; the loading speed is set so that they end at the target.
      progress: ``True`` prints a progress bar with the strain; a callable is called as
        ``progress(steps_done, steps_total, elapsed_s)`` after every chunk.
      neighbors: the contact candidate lists' :class:`~jaxbpm.dem.NeighborSettings` (``None``: a skin of half the
        smallest radius).
      max_records: the most points kept in the returned curve.
      record_to: an ``.h5`` path: every step's time, displacement, force, reactions, largest speed and broken-bond
        counts are appended chunk by chunk as they arrive (:mod:`jaxbpm.dem.records`); an existing file is replaced
        only when it is a record of the same run or with ``overwrite``.
      snapshots: ``K`` VTU frames evenly spaced in time, the first at rest (with ``vtu``): displacement, velocity,
        force and broken bonds (tensile, shear) per particle; per bond ``intact``, ``break_mode`` and
        ``broken_time``.
      vtu: the ParaView series ``dir/run.pvd`` the frames are written to as the run goes (with ``snapshots``).
      pad: a bonds-only scene (no contacts, no walls) runs on the sample padded to its size class
        (:func:`jaxbpm._compile.size_class`: extra particles clamped at rest, joined by bonds without stiffness that
        never break), so that another sample of that class reuses the compiled programs; curves, time step,
        records, frames and the returned state are the sample's own.
      throw: raise the status's :class:`~jaxbpm.errors.SolveError` (an ``InstabilityError`` for a run that blew up,
        carrying the result of what ran before); ``False``: return the result with its status.
      overwrite: replace an existing record file that is not a record of this run.
      resume: the ``.h5`` record of an interrupted run: continue it from its saved state and append to its record,
        giving the same records and stiffness as an uninterrupted run (to round-off). Give the same sample, scene and
        options: the record's time step, speed, damping, chunk and sample fingerprint must agree, else an error
        names what differs.
      start: where the run starts: ``"rest"``, or ``"elastic"``: at ``start_safety`` x the displacement at which the
        DSM's elastic state has its first bond at its strength (:mod:`jaxbpm.dem.elastic_start`), from the DSM's
        displacements and the loading's velocity field, its records beginning with the DSM's elastic segment
        (``stats["elastic_segment"]`` rows). Where the DSM cannot give that state (walls, the cohesive contact law,
        no breakage, contacts that carry most of the load or slide) the run starts from rest with a warning and
        ``stats["elastic_start"]["fallback"]`` saying why. A resumed run continues from its saved state.
      start_safety: ``start="elastic"``: the start's fraction of the first-break displacement, in (0, 1].

    A ``KeyboardInterrupt`` during the run (Ctrl-C, or raised by the ``progress`` callable) raises
    :class:`~jaxbpm.errors.SimulationInterrupted`, whose ``result`` is the result of the part that was run (status
    ``"interrupted"``; the record file is kept, status ``"interrupted"``, with the state after the last completed
    chunk saved in it). A Ctrl-C before the first chunk raises a plain ``KeyboardInterrupt`` (the record file, if
    any, says ``"interrupted"``). ``Result.setup_time`` is what comes before the first chunk (model, time step,
    loading, candidate list, padding, initial state), ``compile_time`` the tracing and compiling of the programs the
    solve builds (0 when the process had them) and ``run_time`` the rest (the chunks and the work between them).
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
    start: str = option("rest", choice("rest", "elastic"))
    start_safety: float = option(0.9, unit_interval())
