"""Sums over pairs (bonds, contacts) in chunks: the setup and estimate programs of large samples fold over chunks of
pairs instead of materialising per-pair temporaries for all of them at once. Memory taken fresh from the system
costs more than the arithmetic at a million particles (the DSM's bond geometry: 82 s for the whole sample against
6 s in chunks), and a chunk's temporaries are reused from chunk to chunk.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["CHUNK", "chunk_length", "fold_chunks", "sum_chunks"]

CHUNK = 1 << 16
"""Pairs per chunk: samples with more pairs are folded over chunks of this many (or a power-of-two divisor of
their count down to an eighth of it, :func:`chunk_length`)."""


def chunk_length(n: int, chunk: int | None = None) -> int:
    """The chunk length for ``n`` items: ``chunk`` (default :data:`CHUNK`), or the largest power of two down to an
    eighth of it that divides ``n`` (the padded counts of a size class), so that no padding is needed."""
    chunk = CHUNK if chunk is None else int(chunk)
    for c in (chunk >> k for k in range(4)):
        if c and n % c == 0:
            return c
    return chunk


def fold_chunks(step, init, n: int, chunk: int | None = None):
    """``carry = step(carry, idx, weight)`` over chunks of the indices ``0 .. n-1`` from ``init``: ``idx`` the chunk's
    indices (the last chunk's padding repeats ``n - 1``), ``weight`` True on them and False on the padding, which
    ``step`` must make add nothing. ``step(init, None, None)`` (all items at once) when ``n`` fits one chunk. A
    ``fori_loop`` with static bounds: reverse-mode differentiable and ``vmap``-able."""
    chunk = chunk_length(n, chunk)
    if n <= chunk:
        return step(init, None, None)
    ks = jnp.arange(chunk)

    def body(c, carry):
        k = c * chunk + ks
        return step(carry, jnp.minimum(k, n - 1), k < n)

    return jax.lax.fori_loop(0, -(-n // chunk), body, init)


def sum_chunks(fn, n: int, chunk: int | None = None):
    """``sum_c fn(idx_c, w_c)`` over the chunks of :func:`fold_chunks` (``fn(None, None)`` when ``n`` fits one
    chunk); ``fn`` must give zero for padding (``w`` False)."""
    if n <= chunk_length(n, chunk):
        return fn(None, None)
    shape = jax.eval_shape(lambda: fn(jnp.zeros(chunk_length(n, chunk), jnp.int32),
                                      jnp.ones(chunk_length(n, chunk), bool)))
    init = jax.tree_util.tree_map(lambda t: jnp.zeros(t.shape, t.dtype), shape)
    return fold_chunks(lambda acc, idx, w: jax.tree_util.tree_map(jnp.add, acc, fn(idx, w)), init, n, chunk)
