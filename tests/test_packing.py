"""The packing engine (jaxbpm.packing): its host neighbour list, the automatic fraction's give-up rule, the jamming
estimate and the progress lines. The packings themselves are checked in test_generate.py, through random_packing."""

import jax.numpy as jnp
import numpy as np
import pytest

from jaxbpm import generate as g
from jaxbpm import packing as pk
from tests.test_generate import R, TOL, _messages, check_packing


@pytest.fixture(scope="module")
def box400():
    return g.random_packing(400, packing_fraction=0.56, seed=0)


def test_host_list_holds_every_pair_within_reach_both_ways():
    # the host packer's list: every pair closer than cutoff + skin, in both directions, grouped by idx[1] (jax-md's
    # Sparse layout, which _forces sums over), padded with n; checked against all O(n^2) distances
    rng = np.random.default_rng(5)
    x = rng.uniform(0.0, 10.0, (250, 3))
    allocate, _, _ = pk._host_packer((16.0, 16.0, 16.0), 2.1, False)
    nbrs = allocate(jnp.asarray(x))
    idx = np.asarray(nbrs.idx)
    count = int((idx[1] < 250).sum())
    d = np.linalg.norm(x[:, None] - x[None], axis=2)
    want = {(int(i), int(j)) for i, j in zip(*np.nonzero(d < 2.1 + pk._SKIN)) if i != j}
    assert {(int(i), int(j)) for j, i in idx[:, :count].T} == want and count == len(want)
    assert np.all(idx[:, count:] == 250) and np.all(np.diff(idx[1, :count]) >= 0)
    assert float(nbrs.threshold) == (0.5 * pk._SKIN) ** 2 and np.array_equal(nbrs.reference_position, x)
    assert idx.shape[1] >= count and allocate(jnp.asarray(x)).idx.shape == idx.shape  # the slots are kept while the pairs fit


def test_host_neighbour_list_packs_as_the_cell_list_does(box400, monkeypatch):
    # large samples build their neighbour list on the host (k-d tree) between jitted chunks instead of with jax-md's
    # cell list inside the step: the same packing (to 1e-3 R: the force sums add in another order, and FIRE's path
    # amplifies those 1e-16 differences to ~1e-4 R)
    monkeypatch.setattr(pk, "_HOST_LIST_MIN", 0)
    assert pk._packer_for(400) is pk._host_packer
    s = g.random_packing(400, packing_fraction=0.56, seed=0)
    check_packing(s, phi_min=0.55)
    np.testing.assert_allclose(s.positions, box400.positions, rtol=0, atol=1e-3 * R)
    assert np.array_equal(s.bonds, box400.bonds)
    c = g.random_packing(300, shape="cylinder", packing_fraction=0.5, seed=1)
    check_packing(c)
    monkeypatch.setattr(pk, "_HOST_LIST_MIN", 10**9)
    np.testing.assert_allclose(c.positions, g.random_packing(300, shape="cylinder", packing_fraction=0.5,
                                                             seed=1).positions, rtol=0, atol=1e-3 * R)


def geometric(rate, start=0.05, chunk=100, n=60):
    steps = np.arange(1, n + 1) * chunk
    return steps, start * np.exp(-rate * steps)


def first_give_up(steps, overlaps, trial, target=TOL):
    for k in range(1, len(steps) + 1):
        if overlaps[k - 1] < target:
            return None
        if pk._give_up(steps[:k], overlaps[:k], target=target, trial=trial):
            return int(steps[k - 1])
    return None


def test_give_up_predicate_on_synthetic_histories():
    assert (pk._TRIAL_FROM, pk._STALL_STEPS, pk._STALL_DROP) == (400, 3000, 0.1)
    # packs at step ln(50) / 0.005 = 782: kept, on trial or not, also with noise on top (the lowest value so far
    # is what counts)
    steps, fast = geometric(0.005)
    assert first_give_up(steps, fast, trial=1500) is None and first_give_up(steps, fast, trial=None) is None
    assert first_give_up(steps, fast * (1.0 + 0.3 * (np.arange(len(fast)) % 2)), trial=1500) is None
    # packs at step 1400: kept to the end of a 1500-step trial
    steps, late = geometric(np.log(50.0) / 1400.0)
    assert first_give_up(steps, late, trial=1500) is None
    # packs at step 3900: a trial is given up at step 400, where the extrapolation starts; an attempt at a
    # fraction expected to pack is kept
    steps, slow = geometric(0.001)
    assert first_give_up(steps, slow, trial=1500) == 400
    assert first_give_up(steps, slow, trial=None) is None
    # jammed: falls from 0.06 to a plateau at 0.03 at step 1000
    steps = np.arange(1, 101) * 100
    jammed = np.maximum(0.06 - 3e-5 * steps, 0.03)
    assert first_give_up(steps, jammed, trial=1500) == 400
    assert not pk._give_up(steps[:3], jammed[:3], target=TOL, trial=1500)  # too early to tell
    assert 1000 + 0.5 * pk._STALL_STEPS < first_give_up(steps, jammed, trial=None) <= 1000 + pk._STALL_STEPS
    # a trial's budget is a hard limit; slow progress (15 % per 3000 steps) is not a stall
    assert pk._give_up([100, 1500], [0.02, 0.0011], target=TOL, trial=1500)
    assert not pk._give_up([100, 1400], [0.02, 0.0011], target=TOL, trial=1500)
    steps = np.arange(1, 200) * 100
    assert first_give_up(steps, 0.02 * 0.85 ** (steps / 3000.0), trial=None) is None


def test_jamming_fraction_estimate_grows_with_the_domain():
    # boxes at 0.6 from fresh insertions: 2000 and 2500 spheres jam, 3000 pack (in 10 000 steps): the estimate
    # must put 0.6 between them, so that 3000 spheres keep 0.6 and 2000 do not wait for it
    def estimate(n, shape="box"):
        return pk.jamming_fraction(g._walls(shape, None, n * 4.0 / 3.0 * np.pi / 0.6, 1.05))

    assert estimate(2000) < estimate(2500) < 0.6 < estimate(3000) < estimate(10_000) < pk._PHI_BULK
    assert estimate(2000, "cylinder") < 0.6 and estimate(2000, "beam") < estimate(2000)


def test_progress_bar_and_final_line(capsys):
    report = pk._reporter(True, 0.6)
    for k in range(100):  # 10 s of chunks every 0.1 s
        report(100 * (k + 1), 0.01, 0.1 * (k + 1), False)
    report(10_100, 1e-4, 10.05, True)
    err = capsys.readouterr().err
    assert _messages(err.splitlines()) == ["random_packing: packing fraction 0.6: packed after 10100 FIRE steps "
                                           "(10.05 s)"]
    assert "random_packing: packing fraction 0.6: " in err and "FIRE step" in err  # the bar, cleared at the end
    calls = []
    pk._reporter(lambda *a: calls.append(a), 0.6)(5, 0.1, 0.2, False)
    assert calls == [(5, 0.1, 0.2)]
