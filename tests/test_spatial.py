"""Host spatial helpers (jaxbpm._spatial): the Morton permutation, k-d-tree pair lists in both of jax-md's sparse
layouts against all O(n^2) distances, the host list's staleness, and jax-md's neighbour lists imported alone."""

import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import pytest

from jaxbpm import _spatial


def _interleaved(q, bits):
    """Morton codes by the definition: bit b of axis a goes to bit 3 b + a (a plain Python loop)."""
    out = []
    for row in q:
        code = 0
        for b in range(bits):
            for a in range(3):
                code |= ((int(row[a]) >> b) & 1) << (3 * b + a)
        out.append(code)
    return np.array(out)


def test_morton_order_is_the_z_order_permutation():
    rng = np.random.default_rng(0)
    q = rng.integers(0, 16, (500, 3))
    x = q * 0.25 - 3.0  # a 16^3 grid, points sharing cells (ties keep their order)
    x[:3] = [[-3.0, -3.0, -3.0], [0.75, 0.75, 0.75], [0.75, 0.75, 0.75]]  # the grid's corners are in the sample
    q[:3] = [[0, 0, 0], [15, 15, 15], [15, 15, 15]]
    order = _spatial.morton_order(x, bits=4)
    assert order.dtype == np.int64 and np.array_equal(np.sort(order), np.arange(500))  # a permutation
    assert np.array_equal(order, np.argsort(_interleaved(q, 4), kind="stable"))
    assert np.array_equal(_spatial.morton_order(np.zeros((0, 3))), np.zeros(0, np.int64))
    assert np.array_equal(_spatial.morton_order(np.ones((4, 3))), np.arange(4))  # no extent: the given order


def test_morton_order_keeps_neighbours_close():
    rng = np.random.default_rng(1)
    x = rng.uniform(0.0, 1.0, (4000, 3))
    order = _spatial.morton_order(x)
    rank = np.empty(4000, np.int64)
    rank[order] = np.arange(4000)
    i, j = _spatial.pair_list(x, 0.06, 0, 1.0)[0]
    keep = i < 4000
    assert np.median(np.abs(rank[i[keep]] - rank[j[keep]])) < 0.05 * 4000  # random numbering: ~0.33 * 4000


def _brute(x, radius):
    d = np.linalg.norm(x[:, None] - x[None], axis=2)
    return {(int(i), int(j)) for i, j in zip(*np.nonzero(d < radius)) if i < j}


@pytest.mark.parametrize("both_ways", [False, True])
def test_pair_list_against_all_distances(both_ways):
    rng = np.random.default_rng(2)
    n = 300
    x = rng.uniform(0.0, 8.0, (n, 3))
    want = _brute(x, 1.5)
    idx, slots = _spatial.pair_list(x, 1.5, 0, 1.5, both_ways=both_ways)
    count = int((idx[0] < n).sum())
    assert idx.dtype == np.int32 and idx.shape == (2, slots) and slots == int(count * 1.5) + 1
    assert np.all(idx[:, count:] == n) and np.all(idx[:, :count] < n)
    pairs = [(int(i), int(j)) for i, j in idx[:, :count].T]
    if both_ways:  # each pair both ways, sorted by idx[1] then idx[0]
        assert count == 2 * len(want) and {(min(p), max(p)) for p in pairs} == want and len(set(pairs)) == count
        assert pairs == sorted(pairs, key=lambda p: (p[1], p[0]))
    else:  # each pair once, i < j, sorted by i then j
        assert count == len(want) and set(pairs) == want and pairs == sorted(pairs)
    assert _spatial.pair_list(x, 1.5, slots, 1.5, both_ways=both_ways)[1] == slots  # kept while the pairs fit
    assert _spatial.pair_list(x, 1.5, count, 2.0, both_ways=both_ways)[1] == count  # exactly full: kept
    assert _spatial.pair_list(x, 1.5, count - 1, 2.0, both_ways=both_ways)[1] == 2 * count + 1


def test_pair_list_is_never_empty():
    idx, slots = _spatial.pair_list(np.array([[0.0, 0, 0], [5.0, 0, 0]]), 1.0, 0, 1.5)
    assert slots == 1 and np.array_equal(idx, [[2], [2]])


def test_host_list_is_stale_once_a_particle_moved_half_the_skin():
    x = jnp.zeros((3, 3))
    nbrs = _spatial.HostList(jnp.zeros((2, 4), jnp.int32), x, jnp.asarray(0.25 ** 2))
    assert nbrs.update(x + 1.0) is nbrs and not bool(nbrs.did_buffer_overflow)
    assert not bool(_spatial.stale(nbrs, x.at[1, 0].set(0.25)))  # exactly the threshold: still fresh
    assert bool(_spatial.stale(nbrs, x.at[1, 0].set(0.2501)))


def test_jax_md_neighbors_load_only_the_neighbour_lists():
    # jax-md's package __init__ imports all of it (seconds); the packing and the DEM need two modules, and a later
    # full import must still work, with the same module objects
    code = ("import sys\n"
            "from jaxbpm import _spatial\n"
            "partition, space = _spatial.jax_md_neighbors()\n"
            "assert 'jax_md' not in sys.modules and 'jax_md.energy' not in sys.modules\n"
            "import jax_md\n"
            "assert jax_md.partition is partition and jax_md.space is space and jax_md.energy.soft_sphere\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
