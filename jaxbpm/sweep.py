"""Parameter sweeps spread over every available device.

A sweep evaluates one pure function on a batch of parameter sets -- the runs of a surrogate's training set, the
perturbed runs of finite-difference gradients, uncertainty runs. :func:`sweep` splits the batch along its leading
axis over all devices with ``jax.sharding`` (each device ``vmap`` s its share); with one device it is plain ``vmap``.
The same call runs on a laptop CPU and on a multi-GPU node::

    f = jaxbpm.dsm.stiffness_function(sample, scene)            # params -> K
    batch = {"bond_E": E_values[:, None], "bond_nu": nu_values[:, None]}   # [B, n_materials] leaves
    K = jaxbpm.sweep.sweep(f, batch)                            # [B]

A batch that does not divide evenly is padded with copies of its last set (their results are dropped).
``batch_size`` bounds memory: the batch is evaluated ``batch_size`` sets per device at a time.
"""

from __future__ import annotations

import functools
from typing import Any, Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from jaxbpm._renamed import batch_size_keyword

__all__ = ["sweep", "batch_size"]


def batch_size(batch) -> int:
    """Size of the leading axis shared by every leaf of ``batch``.

    Args:
      batch: a pytree of arrays with a leading batch axis.

    Returns:
      The batch size.

    Raises:
      ValueError: no arrays, a scalar leaf, or leaves of different leading sizes.
    """
    sizes = {int(np.shape(leaf)[0]) if np.ndim(leaf) else -1 for leaf in jax.tree_util.tree_leaves(batch)}
    if not sizes:
        raise ValueError("sweep: the batch has no arrays")
    if -1 in sizes or len(sizes) != 1:
        raise ValueError("sweep: every leaf of the batch needs the same leading (batch) axis; got sizes "
                         f"{sorted(sizes)} (-1: a scalar leaf)")
    return sizes.pop()


_leading_size = batch_size  # sweep's keyword batch_size hides the function of that name


def sweep(fn: Callable, batch, *, devices: Sequence[Any] | None = None, batch_size: int | None = None,
          chunk: int | None = None):
    """``jax.vmap(fn)(batch)``, with the batch axis sharded over ``devices``.

    Args:
      fn: a pure JAX function of one parameter set (a pytree).
      batch: the same pytree with a leading batch axis on every leaf.
      devices: the devices to shard over (default: all of the default backend).
      batch_size: at most this many sets per device in one evaluation (default: the whole share).
      chunk: deprecated name of ``batch_size`` (a :class:`DeprecationWarning`); removed in the next release.

    Returns:
      The stacked outputs (leading axis = batch size), as NumPy-compatible JAX arrays on the default device.

    Raises:
      ValueError: a bad batch (see :func:`batch_size`), no devices, or a bad ``batch_size``.
      TypeError: both ``batch_size`` and ``chunk``.
    """
    batch_size = batch_size_keyword(batch_size, chunk)
    size = _leading_size(batch)
    devices = list(jax.devices() if devices is None else devices)
    if not devices:
        raise ValueError("sweep: no devices")
    if batch_size is not None and not (isinstance(batch_size, (int, np.integer)) and batch_size >= 1):
        raise ValueError(f"sweep: batch_size must be a positive whole number, got {batch_size!r}")
    nd = len(devices)
    per_round = nd * (batch_size if batch_size is not None else -(-size // nd))
    runner = _runner(fn, tuple(devices))
    outs = []
    for start in range(0, size, per_round):
        part = jax.tree_util.tree_map(lambda a: jnp.asarray(a)[start:start + per_round], batch)
        n = min(per_round, size - start)
        padded = -(-n // nd) * nd
        if padded > n:  # repeat the last set so that every device gets the same share
            part = jax.tree_util.tree_map(
                lambda a: jnp.concatenate([a, jnp.repeat(a[-1:], padded - n, axis=0)]), part)
        res = runner(part)
        outs.append(jax.tree_util.tree_map(lambda a: a[:n], res))
    if len(outs) == 1:
        return outs[0]
    return jax.tree_util.tree_map(lambda *a: jnp.concatenate(a), *outs)


@functools.lru_cache(maxsize=16)
def _runner(fn, devices):
    mapped = jax.jit(jax.vmap(fn))
    if len(devices) == 1:
        return mapped
    mesh = Mesh(np.asarray(devices), ("batch",))
    sharded = NamedSharding(mesh, PartitionSpec("batch"))

    def run(part):
        part = jax.device_put(part, sharded)  # each device holds its share; jit follows the input sharding
        return mapped(part)

    return run
