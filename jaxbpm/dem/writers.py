"""What a DEM scene run writes as it goes: its record file (:mod:`jaxbpm.dem.records`, rows appended chunk by chunk;
a resumed run appends to its own) and its VTU frames (a ParaView series, evenly spaced in time)."""

from __future__ import annotations

import dataclasses
import hashlib
import pathlib
from typing import Any, Callable

import numpy as np

from jaxbpm.errors import SceneError

__all__ = ["Writers", "check_frames", "writers"]


@dataclasses.dataclass
class Writers:
    """The writers of one run.

    Attributes:
        recorder: the record file (:class:`~jaxbpm.dem.records.RecordFile`), or ``None``.
        prior: a resumed run's records written before (empty otherwise).
        saved: a resumed run's saved state (:func:`jaxbpm.dem.state.state_arrays`), or ``None``.
        series: the VTU series (:class:`~jaxbpm.interop.formats.VTUSeries`), or ``None``.
        calls: the callbacks, each ``call(steps_done, state, chunk_records)``.
        path: the record file's path as given, or ``None``.
    """

    recorder: Any = None
    prior: dict = dataclasses.field(default_factory=dict)
    saved: dict | None = None
    series: Any = None
    calls: list = dataclasses.field(default_factory=list)
    path: Any = None

    @property
    def steps_done(self) -> int:
        """The steps the record file holds already (a resumed run's; 0 otherwise)."""
        return 0 if self.recorder is None else self.recorder.steps

    @property
    def on_chunk(self) -> Callable | None:
        """The callback the run calls after every chunk, or ``None`` without writers."""
        if not self.calls:
            return None

        def on_chunk(done, state, rec):
            for call in self.calls:
                call(done, state, rec)

        return on_chunk


def check_frames(snapshots, vtu) -> None:
    """Check the frame options before anything runs.

    Args:
        snapshots: the number of VTU frames, or ``None``.
        vtu: the series' ``.pvd`` path, or ``None``.

    Raises:
        SceneError: one of the two is given without the other, or ``snapshots`` is not a whole number >= 1.
    """
    if (snapshots is None) != (vtu is None):
        raise SceneError("snapshots=K and vtu='dir/run.pvd' go together: give both or neither")
    if snapshots is not None and not (isinstance(snapshots, (int, np.integer)) and snapshots >= 1):
        raise SceneError(f"snapshots must be a whole number >= 1 of VTU frames, got {snapshots!r}")


def writers(sample, scene, plan, *, record_to=None, snapshots=None, vtu=None, overwrite=False,
            resume=None) -> Writers:
    """Open the writers of a run.

    Args:
        sample: the sample.
        scene: the scene (the force of its reactions).
        plan: the run's :class:`~jaxbpm.dem.plan.Plan`.
        record_to: the record file's path (``.h5``), or ``None``.
        snapshots: the number of VTU frames, or ``None``.
        vtu: the VTU series' path (``dir/run.pvd``), or ``None``.
        overwrite: replace an existing record file that is not a record of this run.
        resume: the record file of an interrupted run to continue (and append to).

    Returns:
        The :class:`Writers`; the first VTU frame (the sample at rest) is written.

    Raises:
        SceneError: ``resume`` with another ``record_to`` or with frames; too few chunks for the frames.
        SampleFileError: the record file cannot be written, or resumed.
    """
    out = Writers()
    if resume is not None:
        if record_to is not None and pathlib.Path(record_to) != pathlib.Path(resume):
            raise SceneError(f"resume={str(resume)!r} appends to its own record file: leave record_to out")
        if snapshots is not None:
            raise SceneError("resume does not continue a VTU series: leave snapshots and vtu out")
        record_to = resume
    if record_to is not None:
        out.path = record_to
        out.recorder, out.prior, out.saved = _record_file(sample, plan, record_to, overwrite, resume)
        out.calls.append(_rows(scene, plan, out.recorder))
    if snapshots is not None:
        out.series, call = _frames(sample, plan, vtu, snapshots)
        out.calls.append(call)
    return out


def _record_file(sample, plan, path, overwrite, resume):
    """A new record file (or the resumed one), its rows so far and its saved state."""
    from jaxbpm.dem.records import RecordFile

    size = plan.size
    attrs = dict(plan.attrs, particles=sample.n_particles, bonds=sample.n_bonds, sample_digest=_digest(sample),
                 padded_particles=-1 if size is None else size.particles,
                 padded_bonds=-1 if size is None else size.bonds)
    if resume is None:
        return RecordFile(path, attrs, steps_planned=plan.n_steps, overwrite=overwrite), {}, None
    return RecordFile.resume(resume, {**attrs, "steps_planned": plan.n_steps})


def _rows(scene, plan, recorder):
    """The callback appending a chunk's records to the record file."""
    def write_records(done, state, rec):
        rows = {"time": rec["time"], "displacement": plan.speed * rec["time"],
                "force": scene.compressive_force(rec["reaction"]), "reaction": rec["reaction"], "vmax": rec["vmax"]}
        if "broken" in rec:
            rows["broken"] = rec["broken"]
        recorder.append(rows)

    return write_records


def _frames(sample, plan, vtu, snapshots):
    """The VTU series (its first frame, the sample at rest, written) and the callback writing the others:
    ``snapshots`` frames evenly spaced in time, the last the end of the run (one frame: the end only)."""
    from jaxbpm.interop.formats import VTUSeries

    n_chunks, chunk = plan.n_chunks, plan.chunk
    if snapshots - 1 > n_chunks:
        raise SceneError(f"snapshots={snapshots} needs at least {snapshots - 1} chunks, the run has {n_chunks} of "
                         f"{chunk} steps; give a smaller chunk")
    series = VTUSeries(vtu, sample)
    if snapshots == 1:
        frames = {n_chunks}
    else:
        frames = set(np.round(np.linspace(0, n_chunks, snapshots)).astype(int)[1:].tolist())
        write_frame(series, None, sample, 0.0)

    def frame(done, state, rec):
        if done // chunk in frames:
            write_frame(series, state, sample, float(state.time))

    return series, frame


def write_frame(series, state, sample, t: float) -> None:
    """Write one VTU frame.

    Args:
        series: the VTU series.
        state: the DEM state (of the sample, or of its padded model: the sample's particles and bonds come first),
            or ``None`` for the sample at rest.
        sample: the sample.
        t: the frame's time [s].

    The frame holds positions, velocity and force per particle, broken bonds per particle by mode
    (``broken_tensile``, ``broken_shear``), and per bond ``intact``, ``broken``, ``break_mode`` (0 intact,
    1 tensile, 2 shear) and ``broken_time`` (NaN while intact).
    """
    n, nb = sample.n_particles, sample.n_bonds
    if state is None:  # at rest
        pos, vel, frc = np.asarray(sample.positions), np.zeros((n, 3)), np.zeros((n, 3))
        mode, when = np.zeros(nb, np.int32), np.full(nb, np.nan)
    else:
        pos, vel, frc = (np.asarray(a, np.float64)[:n] for a in (state.positions, state.velocities, state.force))
        mode = np.asarray(state.broken, np.int32)[:nb]
        when = np.asarray(state.broken_time, np.float64)[:nb]
    b = np.asarray(sample.bonds)
    point = {"velocity": vel, "force": frc,
             "broken_tensile": np.bincount(b[mode == 1].ravel(), minlength=n).astype(np.int32),
             "broken_shear": np.bincount(b[mode == 2].ravel(), minlength=n).astype(np.int32)}
    series.write(t, positions=pos, intact=mode == 0, point_data=point,
                 bond_data={"break_mode": mode, "broken_time": when})


def _digest(sample) -> str:
    """A short fingerprint of the sample's geometry (a resumed run must be of the same sample)."""
    h = hashlib.sha1()
    for a in (sample.positions, sample.radii, sample.bonds, sample.bond_radius):
        h.update(np.ascontiguousarray(np.asarray(a)).tobytes())
    return h.hexdigest()[:16]
