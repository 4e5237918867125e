"""The DEM's options, :class:`DEM` (``jaxbpm.DEM``), until the DEM is a package of its own (``jaxbpm.dem.options``).

The base, the value checks and the registry of the solvers' options classes are in :mod:`jaxbpm._options`; the
DSM's and the STE's options in :mod:`jaxbpm.dsm.options` and :mod:`jaxbpm.ste.options`.
"""

from __future__ import annotations

from jaxbpm._options import (
    flag, optional, optional_path, option, positive, progress, SolverOptions, unit_interval, whole)
from jaxbpm.errors import OptionsError

__all__ = ["DEM"]


def _neighbors(name, v):
    from jaxbpm.neighbors import NeighborSettings

    if v is not None and not isinstance(v, NeighborSettings):
        from jaxbpm._options import shown

        raise OptionsError(f"{name} must be a jaxbpm.dem.NeighborSettings or None, got {shown(v)}")


class DEM(SolverOptions):
    """Explicit DEM options (what ``jaxbpm.solve(..., method="dem")`` takes); see :func:`jaxbpm.solve`.

    Attributes:
      dt: time step [s] (default ``safety`` x the critical time step).
      safety: fraction of the critical time step used as the default ``dt``.
      damping: local damping coefficient alpha, in [0, 1).
      loading_time: loading time [s] (default ``transits`` x the time a wave needs to cross the sample).
      transits: wave transits per loading when ``loading_time`` is not given.
      chunk: steps per compiled chunk (default: a power of two, 32 to 4096).
      progress: print progress, or a callable ``progress(steps_done, steps_total, elapsed_s)``.
      neighbors: a :class:`~jaxbpm.dem.NeighborSettings` (contact candidate lists).
      max_records: points kept in the returned curve.
      record_to: an ``.h5`` path the per-step records are appended to.
      snapshots: VTU frames evenly spaced in time (with ``vtu``).
      vtu: the ParaView series path ``dir/run.pvd`` (with ``snapshots``).
      pad: bonds-only scenes run padded to their size class.
      throw: raise a :class:`~jaxbpm.errors.SolveError` when the run does not converge.
      overwrite: replace an existing record file of another run.
      resume: the ``.h5`` record of an interrupted run to continue.
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
