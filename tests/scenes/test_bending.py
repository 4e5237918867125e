"""The three-point bending scene: flexural strength, beam geometry and bad input."""

import dataclasses

import meshio
import numpy as np
import pytest

import jaxbpm
from jaxbpm import SceneError
from jaxbpm.generate import disc_packing, lattice
from jaxbpm.scenes import ThreePointBending

# one worker for the whole module under pytest-xdist (loadgroup): its specimen (a module fixture) is built once
pytestmark = pytest.mark.xdist_group("bending")


def _with_strengths(sample, tensile, shear):
    m = dataclasses.replace(sample.materials, tensile_strength=np.array([tensile]), shear_strength=np.array([shear]))
    return sample.replace(materials=m)


@pytest.fixture(scope="module")
def beam():
    materials = {"E": 1e9, "nu": 0.25, "tensile_strength": 5e6, "shear_strength": 1e7}
    return jaxbpm.generate.beam(300, seed=1, packing_fraction=0.52, materials=materials).largest_cluster()


def test_flexural_strength_grows_with_the_tensile_strength(beam):
    scene = ThreePointBending(strain=0.1)
    low = jaxbpm.solve(_with_strengths(beam, 2e6, 1e7), scene, "dem", transits=30)
    high = jaxbpm.solve(_with_strengths(beam, 6e6, 1e7), scene, "dem", transits=30)
    ratio = high.stats["strength"] / low.stats["strength"]
    assert 1.8 < ratio < 3.6, ratio  # nearly proportional (Qu et al. 2020 observes a near-linear relation)
    assert low.stats["past_peak"] and low.stats["broken_tensile"] > low.stats["broken_shear"]
    span, b, h = scene.dimensions(beam)
    np.testing.assert_allclose(low.stats["strength"], 3 * low.stats["peak_force"] * span / (2 * b * h**2))


def test_bending_scene_errors_are_named(beam):
    with pytest.raises(SceneError, match="span"):
        ThreePointBending(span=1.0).dimensions(beam)
    with pytest.raises(SceneError, match="axis"):
        ThreePointBending(axis=0, span_axis=0)
    with pytest.raises(SceneError, match="punch"):
        ThreePointBending(punch_width=1e-9).layers(beam)


def _old_default_finds(s, scene):
    """Whether one mean diameter (the earlier default width) finds a bottom particle under each support and a top one
    under the punch."""
    pos, rad = np.asarray(s.positions), np.asarray(s.radii)
    r = rad.mean()
    z, x = pos[:, scene.axis], pos[:, scene.span_axis]
    lo, hi = (pos - rad[:, None]).min(0)[scene.span_axis], (pos + rad[:, None]).max(0)[scene.span_axis]
    mid, span = 0.5 * (lo + hi), scene.dimensions(s)[0]
    bottom, top = z <= z.min() + r, z >= z.max() - r
    return [bool((layer & (np.abs(x - c) <= r)).any())
            for layer, c in ((bottom, mid - span / 2), (bottom, mid + span / 2), (top, mid))]


def test_default_supports_take_the_nearest_particles_of_a_sparse_layer():
    s = disc_packing(120, "beam", seed=0).largest_cluster()
    scene = ThreePointBending(axis=1, span_axis=0)
    assert _old_default_finds(s, scene) == [False, True, False]  # one diameter finds nothing at two of the points
    supports, punch = scene.layers(s)
    pos, rad = np.asarray(s.positions), np.asarray(s.radii)
    r, y, x = rad.mean(), pos[:, 1], pos[:, 0]
    lo, hi = (pos - rad[:, None]).min(0)[0], (pos + rad[:, None]).max(0)[0]
    mid, span = 0.5 * (lo + hi), scene.dimensions(s)[0]
    bottom, top = y <= y.min() + r, y >= y.max() - r
    for mask, layer, c in ((supports & (x < mid), bottom, mid - span / 2), (punch, top, mid)):
        dist = np.where(layer, np.abs(x - c), np.inf)
        assert mask.any() and np.all(layer[mask])
        np.testing.assert_array_equal(mask, dist <= dist.min() + r)  # the nearest, and those within r of it
    right = supports & (x > mid)
    np.testing.assert_array_equal(right, bottom & (np.abs(x - (mid + span / 2)) <= r))  # found: kept as it was
    with pytest.raises(SceneError, match=r"support_width=.* finds no particle.*nearest lies"):
        ThreePointBending(axis=1, span_axis=0, support_width=2 * r).layers(s)


def _linear(**kw):
    return ThreePointBending(axis=1, span_axis=0, contact_law="linear", rollers=True, **kw)


def test_rollers_touch_the_beam_and_gain_no_bonds():
    s = disc_packing(300, "beam", seed=1, materials={"E": 1e9}).largest_cluster()
    scene = _linear(roller_radius=4e-3)
    staged, bound = scene.stage(s)
    n = s.n_particles
    assert staged.n_particles == n + 3 and bound.beam_particles == n and staged.n_bonds == s.n_bonds
    assert np.asarray(staged.bonds).max() < n  # no bond reaches a roller
    np.testing.assert_array_equal(np.asarray(staged.bonds), np.asarray(s.bonds))
    np.testing.assert_array_equal(np.asarray(staged.types)[n:], [2, 2, 2])  # the sample's types are 1
    assert bound.dimensions(staged) == pytest.approx(scene.dimensions(s), rel=1e-12)
    pos, rad = np.asarray(staged.positions), np.asarray(staged.radii)
    span, _, h = scene.dimensions(s)
    mid = 0.5 * ((pos[:n, 0] - rad[:n]).min() + (pos[:n, 0] + rad[:n]).max())
    np.testing.assert_allclose(pos[n:, 0], [mid - span / 2, mid + span / 2, mid], rtol=1e-12)
    for k in range(n, n + 3):
        gap = np.linalg.norm(pos[:n] - pos[k], axis=1) - rad[:n] - rad[k]
        assert abs(gap.min()) < 1e-12 and gap.min() > -1e-12 * 4e-3  # touching, overlapping none
    supports, punch = bound.layers(staged)
    assert list(np.flatnonzero(supports)) == [n, n + 1] and list(np.flatnonzero(punch)) == [n + 2]
    assert scene.stage(s)[0] is staged and bound.stage(staged) == (staged, bound)  # cached; staged once
    with pytest.raises(SceneError, match="stage"):
        scene.layers(s)


def test_rollers_in_3d_are_rows_of_spheres_across_the_width(beam):
    scene = ThreePointBending(rollers=True, roller_radius=float(np.mean(beam.radii)) * 1.5)
    staged, bound = scene.stage(beam)
    n, added = beam.n_particles, staged.n_particles - beam.n_particles
    span, b, h = scene.dimensions(beam)
    per_row = max(1, round(b / (2 * scene.roller_radius)))
    assert added == 3 * per_row and per_row > 1
    pos, rad = np.asarray(staged.positions), np.asarray(staged.radii)
    for k in range(n, n + added):
        gap = np.linalg.norm(pos[:n] - pos[k], axis=1) - rad[:n] - rad[k]
        assert abs(gap.min()) < 1e-12
    supports, punch = bound.layers(staged)
    assert supports.sum() == 2 * per_row and punch.sum() == per_row


def test_bad_roller_input_is_named():
    with pytest.raises(SceneError, match="contacts"):
        ThreePointBending(rollers=True, contacts=False)
    for radius in (0.0, -1e-3, float("nan")):
        with pytest.raises(SceneError, match="roller_radius"):
            ThreePointBending(rollers=True, roller_radius=radius)
    with pytest.raises(SceneError, match="rollers=True"):
        ThreePointBending(roller_radius=1e-3)
    with pytest.raises(SceneError, match="supports"):
        ThreePointBending(rollers=True, supports=[0], punch=[1])


def test_a_beam_on_rollers_bends_below_the_simply_supported_bound_and_its_rollers_carry_the_load(tmp_path):
    from jaxbpm.dem import read_records

    E, t, R, ny = 1e9, 0.1, 1e-3, 4
    s = lattice("square", (25, ny), R, thickness=t, materials={"E": E}).replace(bond_contact="replace")
    scene = ThreePointBending(axis=1, span_axis=0, contact_law="linear", breakage=False, strain=0.005,
                              fit_range=(0.3, 1.0), rollers=True)
    r = jaxbpm.solve(s, scene, "dem", transits=200, record_to=tmp_path / "run.h5", snapshots=1,
                     vtu=tmp_path / "run.pvd")
    assert r.stats["added_particles"] == 3
    frame = meshio.read(sorted(tmp_path.glob("run*.vtu"))[-1])  # the rollers are the frames' last points, type 2
    assert len(frame.points) == s.n_particles + 3 and list(frame.point_data["type"][-4:]) == [1, 2, 2, 2]
    assert np.asarray(r.state.positions).shape == (s.n_particles + 3, 2)  # the rollers are the last rows
    assert np.asarray(r.state.broken).shape == (s.n_bonds,)  # and they have no bond
    # the lattice's bending stiffness: each row's bonds (E A) at its distance y from the middle, plus the rows' own
    # bending (E I of a bond); here each roller lies right under (over) a disc and touches it alone, a simple support:
    # Euler-Bernoulli is the stiffest the beam can be, shear (S/h = 5: about 20 %), the rollers' contacts (about 7 %)
    # and the beam's indentation under them add compliance, while clamped rows (which hold the ends' rotation) give
    # 1.35 x Euler-Bernoulli on this beam
    span = scene.dimensions(s)[0]
    area, inertia = float(np.asarray(s.bond_area)[0]), float(np.asarray(s.bond_I)[0])
    EI = E * (area * sum(((k - (ny - 1) / 2) * 2 * R) ** 2 for k in range(ny)) + ny * inertia)
    ratio = r.stiffness / (48 * EI / span**3)
    assert 0.7 < ratio < 1.0, ratio
    rec, attrs = read_records(tmp_path / "run.h5")
    assert attrs["added_particles"] == 3 and attrs["particles"] == s.n_particles + 3
    reaction = np.asarray(rec["reaction"])[:, :, 1]  # (supports, punch) along y
    late = slice(len(reaction) // 2, None)
    load = np.mean(0.5 * (reaction[late, 0] - reaction[late, 1]))
    assert load > 0 and abs(np.mean(reaction[late, 0] + reaction[late, 1])) < 0.05 * load  # supports hold the punch


def test_groups_of_discs_resting_on_the_beam_need_no_bond_where_contacts_are_on():
    from jaxbpm.errors import GroupError

    s = disc_packing(200, "beam", seed=3).largest_cluster()
    staged, _ = _linear().stage(s)  # three discs touching the beam, no bond to it
    n = s.n_particles
    own = dict(axis=1, span_axis=0, supports=[n, n + 1], punch=[n + 2])
    supports, punch = ThreePointBending(contact_law="linear", **own).layers(staged)
    assert list(np.flatnonzero(supports)) == [n, n + 1] and list(np.flatnonzero(punch)) == [n + 2]
    with pytest.raises(GroupError, match="no bond path"):
        ThreePointBending(contacts=False, **own).layers(staged)


def test_rollers_are_the_dems_alone():
    s = lattice("square", (12, 3), 1e-3, materials={"E": 1e9})
    scene = _linear(breakage=False)
    assert scene.methods == ("dem",) and ThreePointBending.methods == ("dem", "dsm")
    with pytest.raises(SceneError, match="method='dem'"):
        jaxbpm.solve(s, scene, "dsm")
