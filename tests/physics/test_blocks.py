"""Sums and folds over blocks of pairs (jaxbpm.physics.blocks) against one plain sum."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxbpm.physics import blocks


def test_block_length_divides_or_pads():
    b = blocks.BLOCK
    assert blocks.block_length(7 * b) == b
    assert blocks.block_length(3 * b // 2) == b // 2  # a power-of-two divisor down to an eighth
    assert blocks.block_length(7 * b + 1) == b  # none divides: the last block is padded
    assert blocks.block_length(24, block=16) == 8 and blocks.block_length(17, block=16) == 16


@pytest.mark.parametrize("n", [5, 24, 37])  # one block; three of 8; three of 16, padded
def test_sum_over_blocks_is_the_plain_sum_and_its_gradient(n):
    rng = np.random.default_rng(n)
    x = jnp.asarray(rng.normal(size=n))
    w = jnp.asarray(rng.normal(size=(n, 3)))

    def blocked(x):
        return blocks.sum_blocks(lambda idx, keep: _term(x, w, idx, keep), n, block=16)

    def _term(x, w, idx, keep):
        if idx is None:
            return jnp.sum(jnp.sin(x)[:, None] * w, axis=0)
        return jnp.sum(jnp.where(keep[:, None], jnp.sin(x[idx])[:, None] * w[idx], 0.0), axis=0)

    plain = np.sum(np.sin(np.asarray(x))[:, None] * np.asarray(w), axis=0)
    np.testing.assert_allclose(blocked(x), plain, rtol=1e-13)
    grad = jax.grad(lambda x: jnp.sum(blocked(x)))(x)
    np.testing.assert_allclose(grad, np.cos(np.asarray(x)) * np.asarray(w).sum(axis=1), rtol=1e-13)


def test_fold_visits_every_index_once():
    n = 37  # blocks of 16, the last padded

    def step(carry, idx, keep):
        return carry.at[idx].add(jnp.where(keep, 1, 0))

    counts = blocks.fold_blocks(step, jnp.zeros(n, jnp.int32), n, block=16)
    np.testing.assert_array_equal(counts, np.ones(n, int))
    # a count that fits one block is one call with every index at once
    assert blocks.fold_blocks(lambda c, idx, keep: (c, idx, keep), 0, 5, block=16) == (0, None, None)
