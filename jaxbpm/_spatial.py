"""Spatial helpers on the host, below the data types and the solvers: the Morton permutation that numbers particles
along a space-filling curve, pair lists of nearby centres built by a k-d tree (in either of jax-md's sparse
layouts), the neighbour list that carries such a pair list into jitted code, and jax-md's neighbour-list modules
imported alone.

Everything here takes and returns NumPy arrays (or, for :class:`HostList`, the JAX arrays it carries) and depends on
no other part of jaxbpm.
"""

from __future__ import annotations

import importlib.util
import sys
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["morton_order", "pair_list", "HostList", "stale", "jax_md_neighbors"]


def morton_order(positions, bits: int = 10) -> np.ndarray:
    """The permutation that sorts points along a Morton (Z-order) curve over their bounding box.

    Particles close in space get close indices, so per-bond gathers and per-particle sums touch memory in runs.

    Args:
      positions: ``[n, 3]`` (or ``[n, 2]``) points (any real dtype; read as float64).
      bits: cells per axis are ``2**bits``.

    Returns:
      ``[n]`` int64 permutation (ties keep their order).
    """
    x = np.asarray(positions, dtype=np.float64)
    dim = x.shape[-1] if x.ndim == 2 and x.shape[-1] in (2, 3) else 3
    x = x.reshape(-1, dim)
    if len(x) == 0:
        return np.zeros(0, np.int64)
    lo, span = x.min(axis=0), np.ptp(x, axis=0)
    q = np.floor((x - lo) / np.where(span > 0, span, 1.0) * (2**bits - 1)).astype(np.uint64)
    code = np.zeros(len(x), np.uint64)
    for bit in range(bits):
        for axis in range(dim):
            code |= ((q[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(dim * bit + axis)
    return np.argsort(code, kind="stable")


def pair_list(x: np.ndarray, radius: float, capacity: int, multiplier: float, *,
              both_ways: bool = False) -> tuple[np.ndarray, int]:
    """Pairs of centres closer than ``radius`` (a k-d tree), padded to a fixed number of slots.

    Two layouts, those of jax-md's sparse neighbour lists:

    * ``both_ways=False`` (``OrderedSparse``): each pair once, ``idx[0] < idx[1]``, sorted by ``idx[0]`` then
      ``idx[1]``.
    * ``both_ways=True`` (``Sparse``): each pair in both directions, sorted by ``idx[1]`` then ``idx[0]`` (the order
      in which per-particle sums over ``idx[1]`` add).

    Unused slots hold ``n``. The slot count is kept while the pairs fit; otherwise (and when it is 0: never an
    empty list) it becomes ``int(count * multiplier) + 1``, so that a list built again later with a few more pairs
    keeps its size and the compiled program that takes it.

    Args:
      x: ``[n, 3]`` float64 centres.
      radius: the pair distance.
      capacity: the current slot count.
      multiplier: spare room when the slots are reallocated (e.g. 1.5).
      both_ways: the layout, see above.

    Returns:
      ``(idx, capacity)``: ``idx [2, capacity]`` int32 and the slot count.
    """
    from scipy.spatial import cKDTree

    n = x.shape[0]
    half = cKDTree(x).query_pairs(radius, output_type="ndarray").astype(np.int32)
    if both_ways:
        first = np.concatenate([half[:, 1], half[:, 0]])  # idx[0]
        second = np.concatenate([half[:, 0], half[:, 1]])  # idx[1]: the sort key
        order = np.argsort(second.astype(np.int64) * n + first, kind="stable")
        pairs = np.stack([first[order], second[order]])
    else:
        pairs = half[np.argsort(half[:, 0].astype(np.int64) * n + half[:, 1], kind="stable")].T
    count = pairs.shape[1]
    if count > capacity or capacity == 0:
        capacity = int(count * multiplier) + 1
    idx = np.full((2, capacity), n, np.int32)
    idx[:, :count] = pairs
    return idx, capacity


class HostList(NamedTuple):
    """A neighbour list built on the host by :func:`pair_list`, as jitted code takes it.

    Attributes:
      idx: ``[2, capacity]`` pairs in one of :func:`pair_list`'s layouts (padding ``n``).
      reference_position: ``[n, 3]`` the positions it was built at.
      threshold: the squared distance a particle may move from there before the list is stale (``(skin / 2)^2``).

    Inside jitted code the list never changes (``update`` is the identity, and ``did_buffer_overflow`` is false, as
    for a jax-md list whose buffer never overflows); the caller checks :func:`stale` and builds it again.
    """

    idx: jax.Array
    reference_position: jax.Array
    threshold: jax.Array

    @property
    def did_buffer_overflow(self):
        """Always false: the list's size is fixed when it is built."""
        return jnp.zeros((), bool)

    def update(self, positions):
        """The list itself (it is built again on the host, not inside jitted code).

        Args:
          positions: ``[n, 3]`` (unused).

        Returns:
          ``self``.
        """
        return self


def stale(nbrs: HostList, positions) -> jax.Array:
    """Whether a particle has moved more than the list's threshold allows.

    Args:
      nbrs: the list.
      positions: ``[n, 3]`` the particles now.

    Returns:
      A scalar boolean array: some particle's squared displacement from ``nbrs.reference_position`` exceeds
      ``nbrs.threshold``.
    """
    return jnp.max(jnp.sum((positions - nbrs.reference_position) ** 2, axis=1)) > nbrs.threshold


def jax_md_neighbors():
    """jax-md's ``partition`` and ``space`` modules, imported without the rest of jax-md.

    Unless jax-md is imported already, only these two modules and their own imports are loaded: the package's
    ``__init__`` imports all of jax-md (neural networks, rigid bodies, with computations at import), which takes
    seconds. A later ``import jax_md`` loads the rest as usual. jax-md is not strict-promotion safe: call its
    functions within standard promotion contexts.

    Returns:
      ``(partition, space)``.
    """
    if "jax_md" not in sys.modules:
        spec = importlib.util.find_spec("jax_md")
        if spec is not None and spec.submodule_search_locations:
            sys.modules["jax_md"] = importlib.util.module_from_spec(spec)  # the package, __init__ not run
            try:
                from jax_md import partition, space
                return partition, space
            except ImportError:
                pass
            finally:
                del sys.modules["jax_md"]
    from jax_md import partition, space
    return partition, space
