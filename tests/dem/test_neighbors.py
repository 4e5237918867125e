"""The DEM's contact candidate lists: the host's k-d tree list against brute force, run as jax-md's list through
breakage, the contact history carried across a rebuild."""

import jax.numpy as jnp
import numpy as np

import jaxbpm
from jaxbpm.dem import neighbors
from jaxbpm.dem.neighbors import pair_list



def _host_lists(monkeypatch):
    """The DEM's candidate list built on the host (a k-d tree between chunks) at every size (the CPU's default)."""
    monkeypatch.setattr(neighbors, "HOST_LIST_MIN", 0)


def _jax_md_lists(monkeypatch):
    """The DEM's candidate list by jax-md's cell list inside the step (the accelerators' list) on the CPU too."""
    monkeypatch.setattr(neighbors, "HOST_LIST_MIN", 1 << 62)


def test_host_candidate_list_holds_every_pair_within_its_radius():
    x = np.random.default_rng(0).uniform(0.0, 1.0, (300, 3))
    idx, capacity = pair_list(x, 0.2, 0, 1.5)
    i, j = np.nonzero(np.triu(np.linalg.norm(x[:, None] - x[None], axis=2) < 0.2, 1))  # by i, then j
    assert i.size > 1000
    np.testing.assert_array_equal(idx[:, :i.size], np.stack([i, j]))
    assert capacity == int(1.5 * i.size) + 1 and np.all(idx[:, i.size:] == 300)
    idx2, capacity2 = pair_list(x, 0.201, capacity, 1.5)  # a few more pairs: the same size (no recompilation)
    assert capacity2 == capacity and np.sum(idx2[0] < 300) > i.size


def test_host_candidate_list_runs_as_jax_md_list_through_breakage(monkeypatch):
    """To failure with contacts (bonds replace them): the list built on the host between chunks, with each chunk
    stopped before it goes stale, gives jax-md's run (its list rebuilt inside the step), to round-off."""
    s = jaxbpm.generate.cylinder(250, seed=0, materials={"E": 1e9, "nu": 0.25, "tensile_strength": 5e6,
                                                         "shear_strength": 5e6},
                                 particle_material={"E": 1e9, "nu": 0.25, "density": 2500.0, "friction": 0.5,
                                                    "restitution": 0.5}).largest_cluster()
    scene = jaxbpm.scenes.UniaxialCompression.to_failure(strain=0.02, stop_after_peak=None)  # the whole run
    _jax_md_lists(monkeypatch)
    cell = jaxbpm.solve(s, scene, "dem", transits=30, damping=0.0)
    _host_lists(monkeypatch)
    host = jaxbpm.solve(s, scene, "dem", transits=30, damping=0.0)
    assert (cell.stats["contact_list"], host.stats["contact_list"]) == ("jax-md", "host")
    # the host builds its list again between the steps where jax-md builds its own inside them: as often
    assert host.stats["contact_rebuilds"] > 5
    assert abs(cell.stats["contact_rebuilds"] - host.stats["contact_rebuilds"]) <= 1, (cell.stats, host.stats)
    assert host.stats["contacts_refound"] >= host.stats["contact_rebuilds"]  # (a new list: found again)
    curve = np.sum(cell.stats["broken_curve"], axis=1)
    first = int(np.argmax(curve > 0))
    assert 0 < first and curve[-1] > 20
    scale = np.max(np.abs(cell.force))
    np.testing.assert_allclose(host.force[:first], cell.force[:first], rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(host.force, cell.force, rtol=0, atol=1e-8 * scale)
    assert abs(host.stats["strength"] / cell.stats["strength"] - 1) < 1e-8


def test_host_list_of_a_model_against_brute_force_pairs():
    """The host's list of a contact model holds each pair of centres closer than 2 r_max + 2 skin once, ordered, and
    is stale exactly when a particle has moved more than half the skin."""
    s = jaxbpm.generate.box(120, seed=3, mean_radius=1e-3, radius_spread=0.2)
    model = jaxbpm.scenes.UniaxialCompression(contacts=True).model(s)
    skin = 0.3e-3
    owner = neighbors._HostNeighbors(model, neighbors.NeighborSettings(skin=skin), model.positions0)
    nbrs = owner.allocate(model.positions0)
    x = np.asarray(model.positions0)
    reach = 2 * float(np.max(s.radii)) + 2 * skin
    i, j = np.nonzero(np.triu(np.linalg.norm(x[:, None] - x[None], axis=2) < reach, 1))
    idx = np.asarray(nbrs.idx)
    found = idx[:, idx[0] < model.n]
    assert i.size > 100 and idx.shape[1] >= i.size
    np.testing.assert_array_equal(found, np.stack([i, j]))
    assert np.all(idx[:, i.size:] == model.n)  # padding after the pairs
    moved = jnp.asarray(x).at[7, 0].add(0.49 * skin)
    assert not bool(neighbors.stale(nbrs, moved))
    assert bool(neighbors.stale(nbrs, moved.at[7, 0].add(0.02 * skin)))


def test_contact_history_follows_its_pairs_across_a_rebuild():
    n = 6
    old = jnp.array([[0, 1], [0, 4], [2, 3], [n, n]])
    new = jnp.array([[2, 3], [1, 5], [0, 1], [n, n], [n, n]])
    spring = jnp.arange(12.0).reshape(4, 3)
    cohesion = jnp.array([10.0, 20.0, 30.0, 40.0])
    s, c = neighbors._remap_history(old, new, n, spring, cohesion)
    np.testing.assert_array_equal(s, [[6, 7, 8], [0, 0, 0], [0, 1, 2], [0, 0, 0], [0, 0, 0]])
    np.testing.assert_array_equal(c, [30.0, 0.0, 10.0, 0.0, 0.0])  # a pair new to the list: a new contact


def test_pack_takes_the_true_entries_in_order():
    mask = jnp.array([False, True, True, False, True, False, True])
    take, count = neighbors.pack(mask, 3)
    assert int(count) == 4  # they did not all fit
    np.testing.assert_array_equal(take, [1, 2, 4])
    take, count = neighbors.pack(mask, 6)
    np.testing.assert_array_equal(take, [1, 2, 4, 6, 7, 7])  # empty slots: the capacity
