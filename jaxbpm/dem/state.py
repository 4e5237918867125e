"""The DEM's state: :class:`DEMState`, a pytree of the particles' motion, the bonds' state and the contacts' history,
with what is computed from it (energies), its padding to a size class, and its arrays as a record file's checkpoint
holds them."""

from __future__ import annotations

import dataclasses
import types
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm.physics.loading import Loading
from jaxbpm.physics.model import Model

__all__ = ["DEMState", "pad_loading", "unpad_state", "kinetic_energy", "potential_energy", "state_arrays",
           "restore_state"]


@dataclasses.dataclass(frozen=True)
class DEMState:
    """Integrator state (a pytree).

    A two-dimensional sample's state has ``[n, 2]`` positions, velocities and forces, ``[n, 1]`` angles, spins and
    moments, and ``[C, 2]`` / ``[nb, 2]`` springs.

    Attributes:
        positions: ``[n, 3]`` particle centres [m].
        velocities: ``[n, 3]`` [m/s].
        orientations: ``[n, 4]`` unit quaternions.
        omegas: ``[n, 3]`` angular velocities [rad/s].
        force: ``[n, 3]`` forces of the last force evaluation [N].
        moment: ``[n, 3]`` moments of the last force evaluation [N m].
        intact: ``[nb]`` bool, the bonds that hold.
        spring: ``[C, 3]`` tangential contact springs, in the candidate list's layout (with the cohesive contact law
            the elastic tangential force [N]).
        nbrs: the contact candidate list (``None`` without contacts).
        time: simulated time [s].
        broken: ``[nb]`` int8, how each bond broke: 0 intact, 1 tensile, 2 shear.
        broken_time: ``[nb]`` when each bond broke [s], NaN while intact.
        cohesion: ``[C]`` per-contact cohesion history [Pa] with the cohesive contact law
            (:mod:`jaxbpm.physics.cohesive`), ``None`` otherwise.
        bond_spring: ``[nb, 3]`` with Hertz or linear contacts, the tangential springs of the bonded pairs' contacts
            (``spring`` then holds those of the other pairs).
    """

    positions: Any
    velocities: Any
    orientations: Any
    omegas: Any
    force: Any
    moment: Any
    intact: Any
    spring: Any
    nbrs: Any
    time: Any
    broken: Any = None
    broken_time: Any = None
    cohesion: Any = None
    bond_spring: Any = None


jax.tree_util.register_dataclass(DEMState, data_fields=["positions", "velocities", "orientations", "omegas", "force",
                                                        "moment", "intact", "spring", "nbrs", "time", "broken",
                                                        "broken_time", "cohesion", "bond_spring"],
                                 meta_fields=[])


def pad_loading(load: Loading, n: int) -> Loading:
    """The loading of a model padded to ``n`` particles: the extra ones clamped at rest (host work, no program).

    Args:
        load: the sample's loading.
        n: the padded number of particles (at least the sample's).

    Returns:
        The padded loading.

    Raises:
        ValueError: ``n`` is below the loading's number of particles.
    """
    clamped, velocity = np.asarray(load.clamped), np.asarray(load.velocity)
    extra = n - clamped.shape[0]
    if extra < 0:
        raise ValueError(f"cannot pad a loading of {clamped.shape[0]} particles to {n}")
    return dataclasses.replace(
        load, clamped=jax.device_put(np.concatenate([clamped, np.ones(extra, bool)])),
        velocity=jax.device_put(np.concatenate([velocity, np.zeros((extra, velocity.shape[1]), velocity.dtype)])))


def unpad_state(state: DEMState, n: int, n_bonds: int) -> DEMState:
    """The state of the first ``n`` particles and ``n_bonds`` bonds of a padded run (sliced on the host: no program
    is compiled for the sample's own sizes).

    Args:
        state: the state of the padded run.
        n: the sample's number of particles.
        n_bonds: the sample's number of bonds.

    Returns:
        The sample's part of ``state`` (its other fields, the contacts' and the time, as they are).
    """
    def cut(x, size):
        return None if x is None else jax.device_put(np.asarray(x)[:size])

    return dataclasses.replace(
        state, positions=cut(state.positions, n), velocities=cut(state.velocities, n),
        orientations=cut(state.orientations, n), omegas=cut(state.omegas, n), force=cut(state.force, n),
        moment=cut(state.moment, n), intact=cut(state.intact, n_bonds), broken=cut(state.broken, n_bonds),
        broken_time=cut(state.broken_time, n_bonds))


def kinetic_energy(model: Model, state: DEMState):
    """Translational plus rotational kinetic energy [J].

    Args:
        model: the run's model (masses, inertias).
        state: the state.

    Returns:
        A scalar array.
    """
    ke = 0.5 * jnp.sum(model.mass[:, None] * state.velocities**2)
    if model.rotations:
        ke = ke + 0.5 * jnp.sum(model.inertia[:, None] * state.omegas**2)
    return ke


def potential_energy(model: Model, params, state: DEMState):
    """Elastic energy stored in the bonds [J] (contacts and walls not included).

    Args:
        model: the run's model.
        params: the bond parameters (as :func:`jaxbpm.physics.model.default_params` gives them).
        state: the state.

    Returns:
        A scalar array.
    """
    from jaxbpm.physics.bond import bond_energy

    return bond_energy(state.positions, state.orientations if model.rotations else None, model.bonds, model.r0,
                       model.stiffness(params), state.intact)


def _state_fields() -> list[str]:
    """The array fields of a DEM state (all but the candidate list, which a resumed run builds again)."""
    return [f.name for f in dataclasses.fields(DEMState) if f.name != "nbrs"]


def state_arrays(state: DEMState) -> dict:
    """The arrays of a DEM state, as a record file's checkpoint holds them.

    Args:
        state: the state.

    Returns:
        ``{field: array}`` of the fields that are set, and ``nbrs_idx`` (the candidate list's pairs ``[2, C]``) with
        contacts.
    """
    out = {k: np.asarray(getattr(state, k)) for k in _state_fields() if getattr(state, k) is not None}
    if state.nbrs is not None:
        out["nbrs_idx"] = np.asarray(state.nbrs.idx)
    return out


def restore_state(arrays) -> DEMState:
    """The DEM state of a checkpoint (:func:`state_arrays`).

    Args:
        arrays: ``{field: array}`` as :func:`state_arrays` gives them.

    Returns:
        The state; its candidate list holds the saved pairs only (``nbrs.idx``): the run builds the list again and
        carries the contact history over from them.
    """
    from jaxbpm._compile import put

    fields = {k: put(arrays[k]) if k in arrays else None for k in _state_fields()}
    nbrs = types.SimpleNamespace(idx=put(arrays["nbrs_idx"])) if "nbrs_idx" in arrays else None
    return DEMState(nbrs=nbrs, **fields)
