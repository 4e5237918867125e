"""The DEM's contact candidates: jax-md neighbour lists owned on the host (box, origin, re-allocation) or, on the
CPU, lists built on the host by a k-d tree (:class:`HostList`); the candidate pairs they give (bonded pairs masked
where bonds replace contacts) and the per-contact state carried across a rebuild. jax-md is imported
only when a scene has contacts and uses its lists.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm._spatial import HostList, pair_list, stale  # noqa: F401  (HostList, stale: this module's API)
from jaxbpm.physics.model import Model

__all__ = ["NeighborSettings"]


@dataclasses.dataclass(frozen=True)
class NeighborSettings:
    """Settings of the contact candidate lists.

    Attributes:
      skin: [m] the list radius is 2 r_max + 2 skin (jax-md's cutoff ``2 r_max + skin`` plus its threshold
        ``skin``); the list is built again when a particle has moved more than skin / 2.
      capacity_multiplier: spare room in the pair buffer.
      box_margin: relative padding of jax-md's cell-list box around the sample.
    """

    skin: float
    capacity_multiplier: float = 1.5
    box_margin: float = 0.25


def _jax_md_context():
    """jax-md is not written for JAX's strict promotion modes: run it under the standard ones, locally."""
    stack = contextlib.ExitStack()
    stack.enter_context(jax.numpy_dtype_promotion("standard"))
    stack.enter_context(jax.numpy_rank_promotion("allow"))
    return stack


@functools.lru_cache(maxsize=32)
def _neighbor_fns(box: tuple, cutoff: float, skin: float, capacity_multiplier: float):
    from jaxbpm._spatial import jax_md_neighbors

    # only jax-md's neighbour lists: its package __init__ (rigid bodies, computed at import) costs seconds
    partition, space = jax_md_neighbors()

    displacement, _ = space.free()
    return partition.neighbor_list(displacement, jnp.asarray(box), r_cutoff=cutoff, dr_threshold=skin,
                                   capacity_multiplier=capacity_multiplier, format=partition.OrderedSparse)


class _Neighbors:
    """Host-side owner of the neighbour-list functions (box, origin), re-allocating when needed."""

    def __init__(self, model: Model, settings: NeighborSettings, positions):
        self.model, self.settings = model, settings
        pos = np.asarray(positions)
        self._setup(pos.min(axis=0), pos.max(axis=0))

    def _setup(self, pos_min, pos_max):
        """The cell-list box around the centres' extent ``pos_min``..``pos_max`` (with the settings' margin)."""
        r_max = float(np.max(np.asarray(self.model.radii)))
        lo, hi = pos_min - r_max, pos_max + r_max
        pad = self.settings.box_margin * (hi - lo) + 4 * r_max
        self.origin = lo - pad
        box = tuple(float(v) for v in (hi - lo + 2 * pad))
        cutoff = 2 * r_max + self.settings.skin
        self.key = (box, cutoff, self.settings.skin, self.settings.capacity_multiplier)
        self.fns = _neighbor_fns(*self.key)
        self.lo, self.hi = self.origin + 0.05 * pad, self.origin + np.asarray(box) - 0.05 * pad

    def inside(self, pos_min, pos_max) -> bool:
        return bool(np.all(np.asarray(pos_min) > self.lo) and np.all(np.asarray(pos_max) < self.hi))

    def allocate(self, positions, extra_per_particle: int = 0, reach=None):
        """A fresh list; ``extra_per_particle`` adds room for that many more pairs per particle. ``reach``
        (``(pos_min, pos_max)``) is where the particles went in a chunk that left the box: the box covers it too, so
        that the chunk, run again from ``positions``, stays inside (a fragment flying off after a failure)."""
        pos = np.asarray(positions)
        lo, hi = pos.min(axis=0), pos.max(axis=0)
        if reach is not None:
            lo, hi = np.minimum(lo, np.asarray(reach[0])), np.maximum(hi, np.asarray(reach[1]))
        if not self.inside(lo, hi):
            self._setup(lo, hi)
        with _jax_md_context():
            shifted = jnp.asarray(positions) - jnp.asarray(self.origin)[None, :]
            nbrs = self.fns.allocate(shifted, extra_capacity=extra_per_particle)
            if nbrs.idx.shape[1] == 0:  # never empty (as the host's list): room for the first pairs to come
                nbrs = self.fns.allocate(shifted, extra_capacity=max(1, extra_per_particle))
        if getattr(nbrs, "cell_list_fn", None) is not None:
            # jax-md makes new cell-list functions (static pytree metadata) at every allocation, which would compile
            # the DEM chunk again for every run; those of one box, cell size and multiplier are interchangeable
            nbrs = nbrs.set(cell_list_fn=_CELL_LIST_FNS.setdefault(self.key, nbrs.cell_list_fn))
        return nbrs


_CELL_LIST_FNS: dict = {}  # cell-list functions by neighbour-list settings (see _Neighbors.allocate)

#: from this many particles on the CPU the DEM's candidate list is built on the host (a k-d tree, between steps)
#: instead of by jax-md's cell list inside the step (which fills a dense ``[n, 27 x cell capacity]`` candidate array
#: at every build); 0: the host list is the CPU's list from the first particle. Accelerators keep jax-md's (no host
#: round trip)
HOST_LIST_MIN = 0


class _HostNeighbors:
    """:class:`_Neighbors` for :class:`HostList`: no box (the k-d tree has none; ``inside`` is always true, the
    origin zero), the same list radius as jax-md's (``2 r_max + 2 skin``: cutoff plus threshold), a capacity that
    only grows."""

    def __init__(self, model: Model, settings: NeighborSettings, positions):
        self.model, self.settings = model, settings
        r_max = float(np.max(np.asarray(model.radii)))
        self.radius = 2 * r_max + 2 * settings.skin
        self.capacity = 0
        self.origin = np.zeros(model.dim)

    def inside(self, pos_min, pos_max) -> bool:
        return True

    def allocate(self, positions, extra_per_particle: int = 0, reach=None):
        x = np.asarray(positions, dtype=np.float64)
        idx, self.capacity = pair_list(x, self.radius, self.capacity + extra_per_particle * x.shape[0],
                                           self.settings.capacity_multiplier)
        dtype = jnp.asarray(positions).dtype
        return HostList(jax.device_put(idx), jnp.asarray(positions),
                        jnp.asarray((0.5 * self.settings.skin) ** 2, dtype))


def neighbors_owner(model: Model, settings: NeighborSettings, positions):
    """The owner of a run's candidate list, which builds it (``allocate``) and says whether particles left its box.

    Args:
      model: the run's model (radii).
      settings: the list's settings.
      positions: ``[n, 3]`` the particles' positions at the start.

    Returns:
      On the CPU (from :data:`HOST_LIST_MIN` particles) an owner of lists built on the host (:class:`HostList`),
      else of jax-md's cell lists, built again inside the step.
    """
    if model.n >= HOST_LIST_MIN and jax.default_backend() == "cpu":
        return _HostNeighbors(model, settings, positions)
    return _Neighbors(model, settings, positions)


def _contact_pairs(model: Model, nbrs, intact=None):
    pairs = nbrs.idx.T
    valid = pairs[:, 0] < model.n
    if model.bond_contact == "replace":
        # bonded pairs have no contact while their bond holds; a broken bond falls back to the contact law
        valid = valid & ~model.bonded(jnp.where(valid[:, None], pairs, 0), intact)
    return pairs, valid


def _remap_springs(old_pairs, old_spring, new_pairs, n):
    """Carry tangential springs across a neighbour-list rebuild by matching pair keys."""
    take, found = _remap_index(old_pairs, new_pairs, n)
    return jnp.where(found[:, None], old_spring[take], 0.0)


@functools.partial(jax.jit, static_argnames=("n",))
def _remap_history(old_pairs, new_pairs, n, spring, cohesion):
    """Carry the per-contact state (springs and, with the cohesive law, the cohesion history) across a rebuild; a
    pair new to the list starts with an empty spring and zero cohesion (a new contact). One compiled program (the
    run calls it between chunks at every rebuild of a host-built list: op by op, it compiled some twenty programs
    in the first run and dispatched them one by one after)."""
    take, found = _remap_index(old_pairs, new_pairs, n)
    spring = jnp.where(found[:, None], spring[take], 0.0)
    return spring, (None if cohesion is None else jnp.where(found, cohesion[take], 0.0))


def _remap_index(old_pairs, new_pairs, n):
    """For each new pair: the index of the same pair in the old list, and whether it was there."""
    key_t = jnp.int64 if jax.config.jax_enable_x64 else jnp.int32
    big = jnp.asarray(jnp.iinfo(key_t).max, key_t)
    old_key = jnp.where(old_pairs[:, 0] < n, old_pairs[:, 0].astype(key_t) * n + old_pairs[:, 1].astype(key_t), big)
    order = jnp.argsort(old_key)
    sorted_key = old_key[order]
    new_key = new_pairs[:, 0].astype(key_t) * n + new_pairs[:, 1].astype(key_t)
    pos = jnp.clip(jnp.searchsorted(sorted_key, new_key), 0, sorted_key.shape[0] - 1)
    found = (sorted_key[pos] == new_key) & (new_pairs[:, 0] < n)
    return order[pos], found


class _Near(NamedTuple):
    """The pairs within reach: the candidates that are not bonded pairs (those have their contact evaluated on the
    bond list, see :func:`jaxbpm.dem.stepper.step`) whose surfaces are closer than ``margin`` when the list was
    built. While no particle has moved more than ``margin / 2`` since then, no other such candidate can touch, so
    each step's contact law runs on these pairs only, without testing and packing the whole candidate list (a
    second, tighter Verlet list inside the candidate list).

    ``pairs [S, 2]`` (padding: ``n``), ``slot [S]`` (their index in the candidate list; padding: its capacity),
    ``spring [S, 3]`` (their tangential springs), ``ref [n, 3]`` (positions when built), ``overflow`` (more pairs
    within reach than ``S``: the run needs more slots), ``count`` (the most pairs within reach found so far),
    ``found`` (how often they were found: passes over the candidate list), ``apart [C]`` (the candidates that are
    not padding and not bonded pairs: the same until the candidate list is built again, so that finding the pairs
    again does not search the bonds)."""

    pairs: jnp.ndarray
    slot: jnp.ndarray
    spring: jnp.ndarray
    ref: jnp.ndarray
    overflow: jnp.ndarray
    count: jnp.ndarray
    found: jnp.ndarray
    apart: jnp.ndarray


def near_size(count: int, capacity: int) -> int:
    """Slots for ``count`` pairs within reach (the contact law runs on every slot).

    Args:
      count: the pairs within reach.
      capacity: the candidate list's capacity.

    Returns:
      A quarter more than ``count`` (and 64), rounded up to one of 8 to 16 sizes an octave (runs on one sample, or
      samples of similar size, share the compiled chunk), at most ``capacity``.
    """
    want = int(1.25 * count) + 64
    grain = 1 << max(want.bit_length() - 4, 0)
    return max(min(-(-want // grain) * grain, capacity), 1)


def near_count(model: Model, positions, nbrs, margin: float) -> int:
    """How many candidate pairs that are not bonded pairs are within ``margin`` of touching (on the host).

    Args:
      model: the run's model (radii, bonds).
      positions: ``[n, 3]`` positions.
      nbrs: the candidate list.
      margin: [m] the reach.

    Returns:
      The count, which :func:`near_size` sizes the slots for at the start of a run.
    """
    x, idx = np.asarray(positions), np.asarray(nbrs.idx)
    pairs = idx[:, idx[0] < model.n].T
    if pairs.size and model.bond_keys.shape[0]:
        keys = np.asarray(model.bond_keys)
        key = pairs[:, 0].astype(keys.dtype) * model.n + pairs[:, 1].astype(keys.dtype)
        pos = np.clip(np.searchsorted(keys, key), 0, keys.shape[0] - 1)
        pairs = pairs[keys[pos] != key]
    r = np.asarray(model.radii)
    gap = np.linalg.norm(x[pairs[:, 1]] - x[pairs[:, 0]], axis=1) - r[pairs[:, 0]] - r[pairs[:, 1]]
    return int(np.count_nonzero(gap < margin))


def pack(mask, size: int):
    """The indices of the ``True`` entries of a mask, packed into ``size`` slots.

    Args:
      mask: ``[C]`` bool.
      size: the slots.

    Returns:
      ``(take [size], count)``: the indices in order (``C`` in an empty slot) and how many entries are ``True``
      (more than ``size``: they did not all fit).
    """
    capacity = mask.shape[0]
    slot = jax.lax.associative_scan(jnp.add, mask.astype(jnp.int32)) - 1
    take = jnp.full(size, capacity, jnp.int32).at[jnp.where(mask, slot, size)].set(
        jnp.arange(capacity, dtype=jnp.int32), mode="drop")
    return take, slot[-1] + 1


def near_build(model: Model, positions, nbrs, spring, margin, size: int, apart=None) -> _Near:
    """Find the pairs within reach.

    Args:
      model: the run's model.
      positions: ``[n, 3]`` positions.
      nbrs: the candidate list.
      spring: ``[C, 3]`` the springs in the candidate list's layout.
      margin: [m] the reach.
      size: the slots.
      apart: ``[C]`` bool, the candidates that are neither padding nor bonded pairs (``_Near.apart`` of the same
        candidate list), or ``None``: found here (a search of the bonds for every candidate).

    Returns:
      The candidate pairs that are not bonded pairs within ``margin`` of touching, with their springs
      (:class:`_Near`; ``overflow`` set when they did not fit).
    """
    from jaxbpm.physics.contact import pair_vectors

    pairs = nbrs.idx.T
    valid = near_apart(model, nbrs) if apart is None else apart
    i, j, d = pair_vectors(positions, pairs, valid)
    close = valid & (model.radii[i] + model.radii[j] + margin - jnp.sqrt(sum(c * c for c in d)) > 0)
    take, count = pack(close, size)
    return _Near(pairs=pairs.at[take].get(mode="fill", fill_value=model.n), slot=take,
                 spring=spring.at[take].get(mode="fill", fill_value=0.0), ref=positions, overflow=count > size,
                 count=count, found=jnp.ones((), jnp.int32), apart=valid)


def near_apart(model: Model, nbrs):
    """The candidates that are neither padding nor bonded pairs.

    Args:
      model: the run's model (its bonds).
      nbrs: the candidate list.

    Returns:
      ``[C]`` bool.
    """
    pairs = nbrs.idx.T
    valid = pairs[:, 0] < model.n
    return valid & ~model.bonded(jnp.where(valid[:, None], pairs, 0))


def near_springs(near: _Near, capacity: int):
    """The springs of the pairs within reach in the candidate list's layout.

    Args:
      near: the pairs within reach.
      capacity: the candidate list's capacity.

    Returns:
      ``[capacity, 3]`` (2D: ``[capacity, 2]``; every candidate not within reach is apart: no spring).
    """
    return jnp.zeros((capacity, near.spring.shape[1]), near.spring.dtype).at[near.slot].set(near.spring, mode="drop")


def near_stale(near: _Near, positions, margin):
    """Whether the pairs within reach must be found again.

    Args:
      near: the pairs within reach.
      positions: ``[n, 3]`` positions.
      margin: [m] their reach.

    Returns:
      A boolean scalar array: a particle moved more than ``margin / 2`` since they were found.
    """
    return jnp.max(jnp.sum((positions - near.ref) ** 2, axis=1)) > 0.25 * margin * margin