"""Explicit DEM: velocity-Verlet time integration of the Model's forces, with rotations and local damping.

The stepper is a pair of pure functions on a pytree state (:func:`init_state`, :func:`step`), run in compiled
chunks of steps by :func:`integrate` (or :func:`simulate`, which raises on failure). Between chunks, outside jit, the
run checks the contact candidate list for overflow (allocating it again and running the chunk again, so no contact
is ever dropped), checks for instability, and reports progress. Compile once: the set-up of a run is host work plus
two compiled programs (the time step's power iteration, and the initial state with the per-run constants); a
bonds-only model padded to a size class runs the chunk compiled for any sample of that class.

The package, one module per part:

* :mod:`~jaxbpm.dem.state` -- :class:`DEMState`, energies, padding, checkpoint arrays;
* :mod:`~jaxbpm.dem.forces` -- the forces of a step, with the contact law on the pairs that need it;
* :mod:`~jaxbpm.dem.stepper` -- :func:`init_state` and :func:`step` (velocity Verlet, local damping);
* :mod:`~jaxbpm.dem.chunk` -- a chunk of steps as one compiled program;
* :mod:`~jaxbpm.dem.neighbors` -- the contact candidate lists (jax-md's cell list, or a k-d tree on the host);
* :mod:`~jaxbpm.dem.timestep` -- :func:`critical_time_step`;
* :mod:`~jaxbpm.dem.integrator` -- :func:`integrate` and its :class:`Outcome`, :func:`simulate`;
* :mod:`~jaxbpm.dem.plan` -- the :class:`Plan` of a scene run (model, time step, steps, chunk, loading, start);
* :mod:`~jaxbpm.dem.writers` -- the record file and the VTU frames a run writes as it goes;
* :mod:`~jaxbpm.dem.records` -- the record file format (:class:`RecordFile`, :func:`read_records`);
* :mod:`~jaxbpm.dem.curve` -- the loading curve, stiffness, peak and statistics of a run;
* :mod:`~jaxbpm.dem.scene` -- :func:`solve_scene`, what ``jaxbpm.solve(..., method="dem")`` runs;
* :mod:`~jaxbpm.dem.batched` -- :func:`solve_batch`, B parameter sets in one program.
"""

from jaxbpm.dem.batched import solve_batch
from jaxbpm.dem.integrator import integrate, Outcome, progress_printer, simulate
from jaxbpm.dem.neighbors import NeighborSettings
from jaxbpm.dem.plan import Plan
from jaxbpm.dem.records import read_records, RecordFile
from jaxbpm.dem.scene import solve_scene
from jaxbpm.dem.state import DEMState, kinetic_energy, pad_loading, potential_energy, unpad_state
from jaxbpm.dem.stepper import init_state, step
from jaxbpm.dem.timestep import critical_time_step
from jaxbpm.physics.loading import Loading

__all__ = ["DEMState", "Loading", "critical_time_step", "init_state", "step", "simulate", "integrate", "Outcome",
           "kinetic_energy", "potential_energy", "NeighborSettings", "progress_printer", "pad_loading", "unpad_state",
           "solve_scene", "solve_batch", "Plan", "RecordFile", "read_records"]
