"""The plan of a DEM scene run, made before it starts: the model (padded to a size class where it can be), the time
step, the loading time and speed, the number of steps and the steps per compiled chunk, the loading, and the state
the run starts from. One run (:func:`jaxbpm.dem.scene.solve_scene`) and a batch of runs
(:func:`jaxbpm.dem.batched.solve_batch`) are planned by the same :func:`plan`.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np

from jaxbpm._compile import SetupCache, size_class
from jaxbpm.dem.integrator import progress_printer
from jaxbpm.dem.state import DEMState, pad_loading
from jaxbpm.dem.timestep import critical_time_step
from jaxbpm.errors import SceneError
from jaxbpm.physics.loading import Loading
from jaxbpm.physics.model import Model
from jaxbpm.scenes import sample_breaks

__all__ = ["Plan", "plan", "default_chunk", "transit_time"]


@dataclasses.dataclass(frozen=True, eq=False)
class Plan:
    """What a DEM scene run is, before it runs.

    Attributes:
        model: the scene's model of the sample (padded to ``size`` when set).
        size: the size class the model is padded to (:func:`jaxbpm._compile.size_class`), or ``None``.
        breakage: whether bonds break.
        dt: the time step [s].
        dt_crit: the critical time step of each parameter set [s] (one for a single run, one per member of a batch).
        damping: the local damping coefficient.
        gauge_length: the scene's gauge length [m].
        area: the scene's cross-section [m^2].
        target: the displacement at the end of the loading [m].
        loading_time: the loading time asked for (given, or ``transits`` x the transit time) [s].
        n_steps: the steps of the whole run (whole chunks).
        chunk: steps per compiled chunk.
        speed: the loading speed, from the steps run: the run ends exactly at ``target`` [m/s].
        load: the loading at that speed (padded with the model).
        attrs: the run's scalar attributes (what a record file of it stores; ``added_particles`` where the scene
            added particles to the sample, its rollers: the sample's last ones).
        start: the state the run starts from (``None``: the model at rest).
        steps_done: the steps of the run before ``start`` (0 from rest; a resumed run's steps so far).
        transit_time: the time an elastic wave needs to cross the sample along the scene's path [s] (the slowest
            member's; the run's loading time over it is its ``transits``).
    """

    model: Model
    size: Any
    breakage: bool
    dt: float
    dt_crit: tuple
    damping: float
    gauge_length: float
    area: float
    target: float
    loading_time: float
    n_steps: int
    chunk: int
    speed: float
    load: Loading
    attrs: dict
    start: DEMState | None = None
    steps_done: int = 0
    transit_time: float = float("nan")

    @property
    def n_chunks(self) -> int:
        """Chunks of the whole run."""
        return self.n_steps // self.chunk

    @property
    def steps_left(self) -> int:
        """Steps to run from ``start``."""
        return self.n_steps - self.steps_done

    def starting_from(self, state: DEMState | None, steps_done: int = 0) -> "Plan":
        """The same run, started from ``state`` (after ``steps_done`` of its steps).

        Args:
            state: the state to start from (``None``: the model at rest); a state of the padded model when the plan
                pads.
            steps_done: the steps of the run that led to ``state``.

        Returns:
            The new plan.
        """
        return dataclasses.replace(self, start=state, steps_done=int(steps_done))

    def progress(self, progress):
        """The progress callback of the run.

        Args:
            progress: ``True`` for a bar with the strain; anything else (``False``, ``None``, a callable) is kept.

        Returns:
            The callback (a :func:`progress_printer` for ``True``), else ``progress`` itself.
        """
        if progress is True:
            return progress_printer(strain_per_step=self.speed * self.dt / self.gauge_length)
        return progress


def plan(sample, scene, params, *, dt=None, safety=0.5, damping=0.7, loading_time=None, transits=40.0, chunk=None,
         snapshots=None, pad=True, state: DEMState | None = None) -> Plan:
    """Plan a DEM run of ``scene`` on ``sample``.

    Args:
        sample: the sample.
        scene: the scene.
        params: the parameters (a dict, already checked), or a list of them: the members of a batch, which share the
            plan (the time step of the smallest critical one, the loading time of the slowest transit).
        dt: the time step [s] (default ``safety`` x the critical one).
        safety: the time step's fraction of the critical one.
        damping: the local damping coefficient.
        loading_time: the loading time [s] (default ``transits`` x the time a wave needs to cross the sample along
            the scene's path).
        transits: see ``loading_time``.
        chunk: steps per compiled chunk (default :func:`default_chunk`).
        snapshots: VTU frames the run writes (the default chunk gives each its own chunk).
        pad: pad a bonds-only model without walls to its size class (:func:`jaxbpm._compile.size_class`).
        state: the state to start from (``None``: the model at rest; see :meth:`Plan.starting_from`).

    Returns:
        The :class:`Plan`.

    Raises:
        SceneError: ``safety`` or ``dt`` out of range, or contacts or walls asked of a two-dimensional sample.
    """
    members = list(params) if not isinstance(params, Mapping) else [params]
    breaks = sample_breaks(sample, scene.breakage)
    # bonds only (no contacts, no walls): the model is padded to the sample's size class, so that the next sample of
    # that class reuses the compiled programs (the extra particles and bonds never act: see build_model's pad_to)
    size = None
    if pad and not scene.contacts and not scene.uses_walls:
        size = size_class(sample.n_particles, sample.n_bonds)
    model = _scene_setup(sample, scene, breaks, size)
    dt_crit = tuple(critical_time_step(model, p) for p in members)
    dt = float(_time_step(dt, safety, dt_crit, batch=not isinstance(params, Mapping)))
    length, area = scene.geometry(sample)
    target = scene.strain * length
    # a wave crossing the sample along its longest loaded path (the gauge length; a beam's span)
    path = scene.transit_length(sample)
    crossing = max(transit_time(sample, model, p, path) for p in members)
    if loading_time is None:
        loading_time = transits * crossing
    n_steps = int(np.ceil(loading_time / dt))
    if chunk is None:
        chunk = default_chunk(n_steps, snapshots)
    n_steps = -(-n_steps // chunk) * chunk
    speed = target / (n_steps * dt)  # the speed from the steps actually run (whole chunks): the run ends at target
    load = scene.loading(sample, speed)
    if size is not None:
        load = pad_loading(load, size.particles)
    attrs = dict(method="dem", scene=type(scene).__name__, dt=dt, dt_crit=float(min(dt_crit)), speed=float(speed),
                 gauge_length=length, area=area, target_displacement=target, damping=float(damping), chunk=chunk,
                 contact_law=model.contact_law, breakage=breaks, failure_rule=model.failure_rule)
    beam = getattr(scene, "beam_particles", None)  # a scene that added particles (rollers) to the sample
    if beam is not None:
        attrs["added_particles"] = sample.n_particles - int(beam)
    return Plan(model=model, size=size, breakage=breaks, dt=dt, dt_crit=dt_crit, damping=damping,
                gauge_length=length, area=area, target=target, loading_time=float(loading_time), n_steps=n_steps,
                chunk=chunk, speed=speed, load=load, attrs=attrs, start=state, transit_time=float(crossing))


_models = SetupCache()


def _scene_setup(sample, scene, breaks: bool, size) -> Model:
    """The scene's model of ``sample`` (padded to ``size``), kept for the next run of the same sample and scene: the
    same sample loaded again and a scene holding the same masks find it (:class:`~jaxbpm._compile.SetupCache`, keyed
    by content). It depends on no parameter: the time step and the loading speed are planned per run."""
    overrides = {} if size is None else {"pad_to": size}
    return _models.get(sample, ("dem-model", scene, breaks, size),
                       lambda: scene.model(sample, breakage=breaks, **overrides))


def _time_step(dt, safety, dt_crit: tuple, batch: bool) -> float:
    """The time step: ``safety`` x the smallest critical one, or ``dt`` checked (a warning above the critical one)."""
    crit = min(dt_crit)
    if dt is None:
        if not (0 < safety <= 1):
            raise SceneError(f"safety must lie in (0, 1], got {safety!r}")
        return safety * crit
    if not (dt > 0 and np.isfinite(dt)):
        raise SceneError(f"dt must be a positive time step in seconds, got {dt!r}")
    if dt > crit and batch:
        worst = int(np.argmin(dt_crit))
        warnings.warn(f"time step dt = {dt:.4g} s is above the critical time step estimate {dt_crit[worst]:.4g} s "
                      f"of member {worst} ({dt / dt_crit[worst]:.2f}x): that member may blow up; keep dt <= 0.5 x "
                      "the smallest estimate (the default)", stacklevel=5)
    elif dt > crit:
        # bonds alone blow up soon after (status "unstable"); with Hertz contacts, whose stiffness grows with the
        # overlap, a run somewhat above the estimate can finish with a wrong stiffness and no error
        warnings.warn(f"time step dt = {dt:.4g} s is above the critical time step estimate {crit:.4g} s "
                      f"({dt / crit:.2f}x): the run may blow up or, with contacts, finish with a wrong stiffness; "
                      "keep dt <= 0.5 x the estimate (the default)", stacklevel=5)
    return dt


def default_chunk(n_steps: int, snapshots=None) -> int:
    """The default chunk, so that samples with about the same number of steps share the compiled chunk.

    Args:
        n_steps: the run's steps.
        snapshots: VTU frames the run writes, or ``None``.

    Returns:
        A power of two, 32 to 4096 steps, about 20 chunks a run (a run of fewer than 32 steps is one chunk of its
        steps: the loading time asked for is the one run); with ``snapshots`` at least one chunk per frame after the
        first.
    """
    if n_steps < 32:
        return max(int(n_steps), 1)
    chunk = 1 << int(np.log2(np.clip(n_steps // 20, 32, 4096)))
    if snapshots is not None and snapshots > 1:
        chunk = max(1, min(chunk, n_steps // (snapshots - 1)))
    return chunk


def transit_time(sample, model: Model, params, length: float) -> float:
    """The time an elastic wave needs to cross ``length``, from the sample's mean bond (or contact) stiffness and
    particle mass (NumPy on the host: the model may be padded).

    Args:
        sample: the sample.
        model: its model (the contact law of a sample without bonds).
        params: the parameters (``bond_E``, ``bond_nu``).
        length: the path [m].

    Returns:
        The transit time [s].
    """
    from jaxbpm.physics.bond import stiffness as bond_stiffness

    m = float(np.mean(sample.mass))
    if sample.n_bonds:
        mat = np.asarray(sample.bond_material)
        E, nu = (np.asarray(params[key], np.float64)[mat] for key in ("bond_E", "bond_nu"))
        k = bond_stiffness(E, nu, sample.bond_area, sample.bond_I, sample.bond_J, sample.bond_length)
        kn, spacing = float(np.mean(k.kn)), float(np.mean(sample.bond_length))
    else:
        r = float(np.mean(sample.radii))
        if model.contact_law == "cohesive":
            from jaxbpm.physics.cohesive import normal_stiffness

            kn = float(normal_stiffness(r, r, 0.01 * r, float(model.cohesive.E)))
        elif model.contact_law == "linear":
            from jaxbpm.physics.linear import normal_stiffness as linear_stiffness

            p = model.hertz_params(params)
            kn = float(linear_stiffness(r, r, float(p.emod), model.dim, float(p.thickness)))
        else:
            kn = 2.0 * float(model.contact.E_star) * np.sqrt(0.5 * r * 0.01 * r)
        spacing = 2.0 * r
    return length / spacing * np.sqrt(m / kn)
