"""The forces of a DEM step: the contact law on the pairs within reach (found again as particles move) against the
per-step packing of the whole candidate list, bonded pairs' contacts replaced or superimposed, the bond pass in
blocks."""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm.dem import integrator, neighbors
from jaxbpm.physics.model import build_model, default_params

R = 1e-3


@pytest.fixture(scope="module")
def contact_box():
    """Soft bonds among stiff particles: contacts carry most of the stiffness."""
    return jaxbpm.generate.box(300, seed=0, materials={"E": 1e8, "nu": 0.25},
                               particle_material={"E": 1e10, "nu": 0.25, "density": 2500.0, "friction": 0.5,
                                                  "restitution": 0.5}).largest_cluster()


def _with_near(monkeypatch, margin, size=None):
    monkeypatch.setattr(integrator, "NEAR_MARGIN", margin)
    if size is not None:
        monkeypatch.setattr(integrator, "near_size", size)


def test_pairs_within_reach_match_packing_every_step(contact_box, monkeypatch):
    """The contact law on the pairs within reach (found again as particles move) gives the run of the per-step
    packing of the whole candidate list, to round-off: the two programs differ from step 28 on by 1e-18 of the force
    (summation order), which the sliding contacts amplify to 3e-12 by step 400 and ~1e-4 by the end, as they amplify
    a change of 1e-15 in one coordinate (K then moves by 8e-5)."""
    scene = jaxbpm.scenes.UniaxialCompression(strain=0.005, contacts=True)
    near = jaxbpm.solve(contact_box, scene, "dem", transits=20)
    _with_near(monkeypatch, None)
    every = jaxbpm.solve(contact_box, scene, "dem", transits=20)
    scale = np.max(np.abs(every.force))
    assert len(near.force) == len(every.force) > 1000
    np.testing.assert_allclose(near.force[:400], every.force[:400], rtol=0, atol=1e-9 * scale)
    assert abs(near.stiffness / every.stiffness - 1) < 5e-4


@pytest.mark.parametrize("bond_contact", ["superimpose", "replace"])
def test_pairs_within_reach_through_breakage(bond_contact, monkeypatch):
    """To failure: the bonded pairs' contacts run on the bond list (where bonds replace contacts, a broken bond's
    only; where they superimpose, every bond's), the other pairs within reach on their slots. Either way the run is
    the per-step packing of the whole candidate list's, to
    round-off before the breaks and within the chaos of breakage after them. Without local damping: its
    ``-alpha |F| sign(v)`` jumps where a velocity component changes sign, so it turns a last-bit difference in the
    order the two programs sum forces into a jump (1e-13 to 1e-9 of the force within three records on one XLA
    thread, 1e-4 before the first break); undamped, the two agree to 2e-13 there."""
    s = jaxbpm.generate.cylinder(250, seed=0, bond_contact=bond_contact,
                                 materials={"E": 1e9, "nu": 0.25, "tensile_strength": 5e6, "shear_strength": 5e6},
                                 particle_material={"E": 1e9, "nu": 0.25, "density": 2500.0, "friction": 0.5,
                                                    "restitution": 0.5}).largest_cluster()
    assert s.bond_contact == bond_contact
    scene = jaxbpm.scenes.UniaxialCompression.to_failure(strain=0.02)
    near = jaxbpm.solve(s, scene, "dem", transits=30, damping=0.0)
    _with_near(monkeypatch, None)
    every = jaxbpm.solve(s, scene, "dem", transits=30, damping=0.0)
    curve = np.sum(every.stats["broken_curve"], axis=1)
    first = int(np.argmax(curve > 0))
    assert 0 < first and curve[-1] > 20  # bonds break, and not from the start
    scale = np.max(np.abs(every.force))
    np.testing.assert_allclose(near.force[:first], every.force[:first], rtol=0, atol=1e-10 * scale)
    assert abs(near.stats["strength"] / every.stats["strength"] - 1) < 0.02


def test_pairs_within_reach_overflow_runs_the_chunk_again(contact_box, monkeypatch):
    """Too few slots for the pairs within reach: the chunk runs again with more, and nothing is lost. By default the
    slots are sized to the pairs within reach that are not bonded pairs at the start (a quarter more; room for a
    32nd of the bonds at least), not to the candidate list. Half the bonds of the box removed, so that many
    touching pairs are not bonded."""
    half = contact_box.replace(bonds=contact_box.bonds[::2], bond_radius=contact_box.bond_radius[::2],
                               bond_material=contact_box.bond_material[::2])
    scene = jaxbpm.scenes.UniaxialCompression(strain=0.005, contacts=True)
    roomy = jaxbpm.solve(half, scene, "dem", transits=20)
    within, slots = roomy.stats["contacts_within_reach"], roomy.stats["contact_slots"]
    capacity = roomy.stats["contact_capacity"]
    assert 100 < within <= slots <= neighbors.near_size(max(within, half.n_bonds // 32), capacity)
    assert slots < 1.5 * within + 64
    _with_near(monkeypatch, integrator.NEAR_MARGIN, lambda count, capacity: max(count // 4, 1))
    tight = jaxbpm.solve(half, scene, "dem", transits=20)
    assert tight.stats["contact_slots"] >= tight.stats["contacts_within_reach"] == within  # the slots grew
    np.testing.assert_allclose(tight.force[:400], roomy.force[:400], rtol=0, atol=1e-9 * np.max(np.abs(roomy.force)))
    assert abs(tight.stiffness / roomy.stiffness - 1) < 5e-4


def test_bonded_pairs_replace_or_superimpose_contacts():
    """Two bonded spheres pressed together: with "replace" only the bond acts, with "superimpose" Hertz adds."""
    pos = np.array([[0.0, 0.0, 0.0], [1.98 * R, 0.0, 0.0]])
    kw = dict(bond_radius_ratio=0.5, particle_material={"E": 1e9, "friction": 0.0})
    model_r = build_model(jaxbpm.Sample.from_arrays(pos, R, [[0, 1]], bond_contact="replace", **kw), contacts=True)
    model_s = build_model(jaxbpm.Sample.from_arrays(pos, R, [[0, 1]], bond_contact="superimpose", **kw),
                          contacts=True)
    params = default_params(jaxbpm.Sample.from_arrays(pos, R, [[0, 1]], **kw))
    pairs = jnp.array([[0, 1]])
    x = model_r.positions0.at[1, 0].add(-0.01 * R)  # squeeze the bond too
    out = {}
    for name, model in (("replace", model_r), ("superimpose", model_s)):
        valid = jnp.array([True]) if name == "superimpose" else ~model.bonded(pairs)
        zeros = jnp.zeros((1, 3))
        f, _, _ = model.forces(x, None, params, contacts=(pairs, valid, zeros, zeros, zeros))
        out[name] = float(f[1, 0])
    k = model_r.stiffness(params)
    np.testing.assert_allclose(out["replace"], float(k.kn[0]) * 0.01 * R, rtol=1e-9)  # bond only
    delta = 2 * R - (1.98 * R - 0.01 * R)
    hertz = 4 / 3 * (1e9 / (2 * (1 - 0.25**2))) * np.sqrt(R / 2) * delta**1.5
    np.testing.assert_allclose(out["superimpose"], out["replace"] + hertz, rtol=1e-9)


def test_bond_pass_in_blocks_through_breakage(monkeypatch):
    """Large samples pass over their bonds in blocks (``Model.bond_block``): forced here on a small cylinder with
    contacts (the bonded pairs' Hertz law runs in the same blocks), blocks of 64 bonds that do not divide the bond
    count, the run is the one-pass run's to round-off before the first break and as strong after it."""
    from jaxbpm.physics import model as model_mod

    s = jaxbpm.generate.cylinder(250, seed=0,
                                 materials={"E": 1e9, "nu": 0.25, "tensile_strength": 5e6, "shear_strength": 5e6},
                                 particle_material={"E": 1e9, "nu": 0.25, "density": 2500.0, "friction": 0.5,
                                                    "restitution": 0.5}).largest_cluster()
    scene = jaxbpm.scenes.UniaxialCompression.to_failure(strain=0.02)
    assert build_model(s).bond_block is None
    one = jaxbpm.solve(s, scene, "dem", transits=30, damping=0.0)
    monkeypatch.setattr(model_mod, "BLOCKED_FROM", 0)
    monkeypatch.setattr(model_mod, "BOND_BLOCK", 64)
    assert build_model(s).bond_block == 64 and s.n_bonds % 64 != 0
    blocks = jaxbpm.solve(s, scene, "dem", transits=30, damping=0.0)
    curve = np.sum(one.stats["broken_curve"], axis=1)
    first = int(np.argmax(curve > 0))
    assert 0 < first and curve[-1] > 20
    scale = np.max(np.abs(one.force))
    np.testing.assert_allclose(blocks.force[:first], one.force[:first], rtol=0, atol=1e-10 * scale)
    assert abs(blocks.stats["strength"] / one.stats["strength"] - 1) < 0.02


def test_disc_contact_motion_is_the_3d_motion_about_z():
    """Discs turn about z: the contact points' relative velocity ``v_j - v_i - (r_j w_j + r_i w_i) (-n_y, n_x)`` is
    the 3D formula's with the spins along z; discs rolling on each other (equal and opposite contact-point speeds)
    have none."""
    from types import SimpleNamespace

    from jaxbpm.dem.forces import _motion

    rng = np.random.default_rng(3)
    n, dt = 6, 1e-6
    x, v, w = rng.normal(size=(n, 2)), rng.normal(size=(n, 2)), rng.normal(size=(n, 1))
    radii = jnp.asarray(rng.uniform(0.5, 1.0, n))
    i, j = jnp.array([0, 1, 2, 3, 4]), jnp.array([1, 2, 3, 4, 5])
    d2 = tuple(jnp.asarray(x[j] - x[i]).T)
    dxi2, v2 = _motion(SimpleNamespace(radii=radii), SimpleNamespace(velocities=jnp.asarray(v), omegas=jnp.asarray(w)),
                       i, j, d2, dt)
    pad = np.zeros((n, 1))
    three = SimpleNamespace(velocities=jnp.asarray(np.hstack([v, pad])), omegas=jnp.asarray(np.hstack([pad, pad, w])))
    _, v3 = _motion(SimpleNamespace(radii=radii), three, i, j, d2 + (jnp.zeros(5),), dt)
    assert len(v2) == 2
    np.testing.assert_allclose(np.stack(v2), np.stack(v3[:2]), rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(np.asarray(v3[2]), 0.0, atol=1e-15)
    np.testing.assert_allclose(np.stack(dxi2), dt * np.stack(v2), rtol=1e-15)
    # two discs side by side along x, turning as gears (r_i w_i = -r_j w_j): no slip; turning alike: 2 r w along -y
    pair = SimpleNamespace(radii=jnp.array([1.0, 2.0]))
    d = (jnp.array([3.0]), jnp.array([0.0]))
    zero_v = jnp.zeros((2, 2))
    _, gears = _motion(pair, SimpleNamespace(velocities=zero_v, omegas=jnp.array([[2.0], [-1.0]])),
                       jnp.array([0]), jnp.array([1]), d, dt)
    _, alike = _motion(pair, SimpleNamespace(velocities=zero_v, omegas=jnp.array([[1.0], [1.0]])),
                       jnp.array([0]), jnp.array([1]), d, dt)
    np.testing.assert_allclose(np.ravel(gears), 0.0, atol=1e-15)
    np.testing.assert_allclose(np.ravel(alike), [0.0, -3.0], atol=1e-15)


@pytest.mark.filterwarnings("ignore:linear contacts:UserWarning")  # the generated packing's bonded pairs overlap
def test_disc_bond_pass_in_blocks_with_linear_contacts(monkeypatch):
    """The blocked bond pass in 2D, the bonded pairs' linear contacts in the same blocks: the one-pass run's forces
    to round-off before the first break, its strength after."""
    from jaxbpm.physics import model as model_mod

    s = jaxbpm.generate.disc_packing(250, aspect=(1, 2), seed=4).largest_cluster()
    params = default_params(s) | {"bond_tensile_strength": np.array([3e6]), "bond_shear_strength": np.array([6e6])}
    scene = jaxbpm.scenes.UniaxialCompression.to_failure(axis=1, contact_law="linear")
    one = jaxbpm.solve(s, scene, "dem", params=params)
    monkeypatch.setattr(model_mod, "BLOCKED_FROM", 0)
    monkeypatch.setattr(model_mod, "BOND_BLOCK", 64)
    assert build_model(s).bond_block == 64 and s.n_bonds % 64 != 0
    blocks = jaxbpm.solve(s, scene, "dem", params=params)
    curve = np.sum(one.stats["broken_curve"], axis=1)
    first = int(np.argmax(curve > 0))
    assert 0 < first and curve[-1] > 20
    scale = np.max(np.abs(one.force))
    np.testing.assert_allclose(blocks.force[:first], one.force[:first], rtol=0, atol=1e-10 * scale)
    assert abs(blocks.stats["strength"] / one.stats["strength"] - 1) < 0.02
