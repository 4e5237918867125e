"""Sums over pairs (bonds, contacts) in blocks: the setup and estimate programs of large samples fold over blocks of
pairs instead of materialising per-pair temporaries for all of them at once, and reuse a block's temporaries from
block to block.

A block is a count of pairs, and only that: the DEM's ``chunk`` (steps per compiled program) is another idea.

Examples:
    >>> import jax.numpy as jnp
    >>> from jaxbpm.physics import blocks
    >>> blocks.block_length(7 * blocks.BLOCK) == blocks.BLOCK  # a whole number of blocks
    True
    >>> blocks.block_length(100, block=32)  # 100 = 4 x 25: the largest power-of-two divisor of 32 down to 32 / 8
    4
    >>> blocks.block_length(99, block=32)  # no divisor: the last block is padded
    32
    >>> x = jnp.arange(10.0)
    >>> float(blocks.sum_blocks(lambda idx, w: jnp.sum(jnp.where(w, x[idx], 0.0)), 10, block=4))
    45.0
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["BLOCK", "block_length", "fold_blocks", "sum_blocks"]

BLOCK = 1 << 16
"""Pairs per block: samples with more pairs are folded over blocks of this many (or a power-of-two divisor of
their count down to an eighth of it, :func:`block_length`)."""


def block_length(n: int, block: int | None = None) -> int:
    """The block length for ``n`` items, chosen so that no padding is needed where it can be.

    Args:
        n: the number of items (pairs).
        block: the largest block length (default :data:`BLOCK`).

    Returns:
        ``block``, or the largest power of two down to an eighth of it that divides ``n`` (the padded counts of a
        size class); ``block`` itself when none does.
    """
    block = BLOCK if block is None else int(block)
    for c in (block >> k for k in range(4)):
        if c and n % c == 0:
            return c
    return block


def fold_blocks(step, init, n: int, block: int | None = None):
    """Fold ``carry = step(carry, idx, weight)`` over blocks of the indices ``0 .. n-1``.

    A ``fori_loop`` with static bounds: reverse-mode differentiable and ``vmap``-able.

    Args:
        step: ``step(carry, idx, weight) -> carry``; ``idx: [m]`` the block's indices (the last block's padding
            repeats ``n - 1``), ``weight: [m]`` True on them and False on the padding, which ``step`` must make add
            nothing. Called once as ``step(init, None, None)`` (all items at once) when ``n`` fits one block.
        init: the initial carry (a pytree).
        n: the number of items.
        block: the block length (:func:`block_length` of it is used; default :data:`BLOCK`).

    Returns:
        The final carry.
    """
    block = block_length(n, block)
    if n <= block:
        return step(init, None, None)
    ks = jnp.arange(block)

    def body(c, carry):
        k = c * block + ks
        return step(carry, jnp.minimum(k, n - 1), k < n)

    return jax.lax.fori_loop(0, -(-n // block), body, init)


def sum_blocks(fn, n: int, block: int | None = None):
    """The sum over the blocks of :func:`fold_blocks` of ``fn(idx, w)``.

    Args:
        fn: ``fn(idx, w) -> pytree`` for one block (``idx: [m]``, ``w: [m]``), or ``fn(None, None)`` for all items
            at once when ``n`` fits one block; it must give zero for padding (``w`` False).
        n: the number of items.
        block: the block length (default :data:`BLOCK`).

    Returns:
        The pytree of sums, shaped as one block's ``fn``.
    """
    if n <= block_length(n, block):
        return fn(None, None)
    shape = jax.eval_shape(lambda: fn(jnp.zeros(block_length(n, block), jnp.int32),
                                      jnp.ones(block_length(n, block), bool)))
    init = jax.tree_util.tree_map(lambda t: jnp.zeros(t.shape, t.dtype), shape)
    return fold_blocks(lambda acc, idx, w: jax.tree_util.tree_map(jnp.add, acc, fn(idx, w)), init, n, block)
