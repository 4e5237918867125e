"""Boundary groups: each kind gives the particles of the equivalent boolean mask (and the same DSM stiffness, checked
against the closed form of a simple cubic column), the named errors, the cache and the scenes' setup keys."""

import re

import numpy as np
import pytest

import jaxbpm
from jaxbpm import SceneError
from jaxbpm._compile import content_key, count_compilations
from jaxbpm.errors import GroupError
from jaxbpm.scenes import BrazilianDisc, Ids, Layer, Region, ThreePointBending, Type, UniaxialCompression
from jaxbpm.scenes.groups import clamped_groups, select, touching_pairs

R = 1e-3
pytestmark = pytest.mark.xdist_group("groups")


@pytest.fixture(scope="module")
def column():
    """A simple cubic column 3 x 3 x 8, z from 0 to 14 R; types: 1 in the bottom plane, 2 in the top one, 3 between."""
    s = jaxbpm.generate.lattice("sc", (3, 3, 8), R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})
    z = np.asarray(s.positions)[:, 2]
    return s.replace(types=np.where(z == z.min(), 1, np.where(z == z.max(), 2, 3)))


def _z(s, k=2):
    return np.asarray(s.positions)[:, k]


def test_each_kind_selects_the_particles_of_its_mask(column):
    pos = np.asarray(column.positions)
    x, y, z = pos.T
    lo, hi = z.min(), z.max()
    cases = [
        (Region.slab(2, None, lo + 0.5 * R), z <= lo + 0.5 * R),
        (Region.slab(0, x.min() + R, None), x >= x.min() + R),
        (Region.box([None, y.min(), 3 * R], [x.min() + 0.1 * R, None, 9 * R]),
         (x <= x.min() + 0.1 * R) & (y >= y.min()) & (z >= 3 * R) & (z <= 9 * R)),
        (Region.cylinder(2, [x.mean(), y.mean()], 1.01 * 2 * R, 2 * R, 8 * R),
         ((x - x.mean()) ** 2 + (y - y.mean()) ** 2 <= (2.02 * R) ** 2) & (z >= 2 * R) & (z <= 8 * R)),
        (Region.sphere(pos[10], 2.5 * R), np.linalg.norm(pos - pos[10], axis=1) <= 2.5 * R),
        (Type(2), z == hi),
        (Type(1, 2), (z == hi) | (z == lo)),
        (Ids([4, 0, 7]), np.isin(np.arange(len(z)), [0, 4, 7])),
        ([4, 0, 7], np.isin(np.arange(len(z)), [0, 4, 7])),
        (np.array([4, 0, 7]), np.isin(np.arange(len(z)), [0, 4, 7])),
        (Layer(end="low"), z <= lo + R),  # the default thickness: one mean radius
        (Layer(2.5 * R, "high"), z >= hi - 2.5 * R),
        (Layer(0.0, "high", axis=0), x == x.max()),
        (Type(1) | Type(2), (z == lo) | (z == hi)),
        (Region.slab(2, None, 5 * R) & Region.slab(0, None, x.min()), (z <= 5 * R) & (x == x.min())),
        (Layer(end="low") - Ids(range(3)), (z <= lo + R) & (np.arange(len(z)) >= 3)),
        (~Type(3), (z == lo) | (z == hi)),
    ]
    for spec, want in cases:
        assert want.any() and not want.all(), spec
        np.testing.assert_array_equal(select(spec, column), want, err_msg=repr(spec))


def test_layer_takes_the_scene_thickness_and_axis(column):
    z = _z(column)
    np.testing.assert_array_equal(select(Layer(end="high"), column, layer_thickness=2.5 * R), z >= z.max() - 2.5 * R)
    x = _z(column, 0)
    np.testing.assert_array_equal(select(Layer(), column, axis=0), x <= x.min() + R)


def test_default_layers_written_as_groups_give_the_same_masks(column):
    default = UniaxialCompression(layer_thickness=2.5 * R).layers(column)
    for fixed, driven in [(Layer(end="low"), Layer(end="high")),
                          (Region.slab(2, None, 2.5 * R), Region.slab(2, 14 * R - 2.5 * R, None)),
                          (Layer(2.5 * R), Layer(2.5 * R, "high"))]:
        got = UniaxialCompression(layer_thickness=2.5 * R, fixed=fixed, driven=driven).layers(column)
        np.testing.assert_array_equal(got[0], default[0])
        np.testing.assert_array_equal(got[1], default[1])


@pytest.mark.parametrize("fixed, driven", [
    (Type(1), Type(2)),
    (Region.slab(2, None, 0.5 * R), Region.box([None] * 3, [None, None, None]) - Region.slab(2, None, 13.5 * R)),
    (Layer(end="low"), Layer(end="high")),
    ("mask", "mask"),
    ("ids", "ids"),
])
def test_every_kind_gives_the_closed_form_dsm_stiffness(column, fixed, driven):
    # 9 chains of 7 bonds in series, ends clamped: K = 9 k_n / 7, k_n = E A / L
    z = _z(column)
    if fixed == "mask":
        fixed, driven = z == z.min(), z == z.max()
    elif fixed == "ids":
        fixed, driven = np.flatnonzero(z == z.min()).tolist(), np.flatnonzero(z == z.max()).tolist()
    res = jaxbpm.solve(column, UniaxialCompression(strain=1e-3, fixed=fixed, driven=driven), method="dsm")
    kn = 1e9 * np.pi * (0.5 * R) ** 2 / (2 * R)
    np.testing.assert_allclose(res.stiffness, 9 * kn / 7, rtol=1e-9)


def test_scenes_with_groups_hash_and_key_the_setup_by_content(column):
    a = UniaxialCompression(fixed=Type(1), driven=Region.slab(2, 13 * R, None))
    b = UniaxialCompression(fixed=Type(1), driven=Region.slab(2, 13 * R, None))
    assert hash(a) == hash(b) and a == b and a != UniaxialCompression(fixed=Type(1), driven=Type(2))
    listed = UniaxialCompression(fixed=[0, 1, 2], driven=[70, 71])
    assert content_key(listed) == content_key(UniaxialCompression(fixed=[0, 1, 2], driven=[70, 71]))
    setups = jaxbpm.dsm.linear._linear_setups
    first = jaxbpm.solve(column, a, method="dsm")
    built = setups.builds
    again = jaxbpm.solve(column, b, method="dsm")
    assert setups.builds == built and again.stiffness == first.stiffness


def test_the_resolved_masks_are_cached_and_not_shared(column):
    first = clamped_groups(column, Type(1), Type(2))
    first[0][:] = True  # the caller's copy: the cache keeps its own
    again = clamped_groups(column, Type(1), Type(2))
    np.testing.assert_array_equal(again[0], _z(column) == _z(column).min())


def test_other_types_same_geometry_solve_alike(column):
    # types are read by no solver: another labelling gives the same stiffness, but keys a sample of its own
    relabelled = column.replace(types=np.asarray(column.types) + 10)
    assert content_key(relabelled) != content_key(column)
    scene = UniaxialCompression(strain=1e-3)
    for method, kw in (("dsm", {}), ("ste", {}), ("dem", {"transits": 5, "throw": False})):
        first = jaxbpm.solve(column, scene, method=method, **kw).stiffness
        with count_compilations() as n:  # the programs compiled for the first labelling serve the second
            assert jaxbpm.solve(relabelled, scene, method=method, **kw).stiffness == first
        assert n[0] == 0, method


def _raises(match, fixed, driven, sample, **kw):
    with pytest.raises(GroupError, match=match) as info:
        UniaxialCompression(fixed=fixed, driven=driven, **kw).layers(sample)
    assert isinstance(info.value, SceneError)
    return info.value


def test_named_errors(column):
    n = column.n_particles
    err = _raises(r"fixed mask must have shape \[72\] \(one entry per particle\), got \(5,\)", np.ones(5, bool),
                  Type(2), column)
    assert err.group == "fixed"
    err = _raises(r"driven: particle indices \[72, 99\] are out of range: the sample has 72 particles, 0..71",
                  Type(1), [3, 72, 99], column)
    assert err.particles == (72, 99) and err.group == "driven"
    _raises(r"fixed: Type\(5\): the sample has no particle of type \[5\]; its types are \[1, 2, 3\]", Type(5),
            Type(2), column)
    _raises(r"driven: Region.box\(.*\) selects no particle \(the particle centres span \[0.0, 0.0, 0.0\] .. "
            r"\[0.004, 0.004, 0.014\]\); a group must hold at least one particle", Type(1),
            Region.slab(2, 1.0, 2.0), column)
    _raises("fixed: the mask selects no particle", np.zeros(n, bool), Type(2), column)
    _raises("driven: Ids\\(\\[\\]\\) selects no particle", Type(1), [], column)
    top = np.flatnonzero(_z(column) == _z(column).max())
    err = _raises(re.escape(f"9 particles are in both fixed and driven: {top.tolist()}; give disjoint groups"),
                  Type(1, 2), Type(2), column)
    assert err.particles == tuple(top)
    _raises("look like a mask written in whole numbers", (_z(column) == 0).astype(int), Type(2), column)


def test_disconnected_groups_name_their_particles(column):
    z = _z(column)
    b = np.asarray(column.bonds)
    bottom = np.flatnonzero(z == z.min())
    in_plane = (z[b[:, 0]] == z.min()) & (z[b[:, 1]] == z.min())
    upward = (z[b].min(axis=1) == z.min()) & (z[b].max(axis=1) > z.min())

    def without(cut):
        return column.replace(bonds=b[~cut], bond_radius=np.asarray(column.bond_radius)[~cut])

    # the bottom plane's bonds cut, and every bond up from it but one particle's: the other 8 hang free
    loose = without(in_plane | (upward & ~np.isin(b, bottom[:1]).any(axis=1)))
    err = _raises(re.escape(f"fixed particles {bottom[1:].tolist()} have no bond path to driven"), Type(1), Type(2),
                  loose)
    assert err.particles == tuple(bottom[1:])
    # no bond up from the bottom plane at all: nothing carries the load
    _raises("no bond path joins driven and fixed: the sample carries no load between them", Type(1), Type(2),
            without(upward))


@pytest.mark.parametrize("value, match", [
    (3, r"one particle: Ids\(\[k\]\); a type: Type\(k\)"),
    ("top", "a group is a boolean mask"),
    ([0.5, 1.5], "Ids takes a list of whole particle indices"),
])
def test_a_group_of_no_known_form_fails_at_the_scene(value, match):
    with pytest.raises(GroupError, match=match):
        UniaxialCompression(fixed=value, driven=[1])


def test_bad_specs():
    for make, match in [(lambda: Region.box([0, 0], [1, 1, 1]), "3 lower and 3 upper"),
                        (lambda: Region.box([0, 0, 2], [1, 1, 1]), "lo <= hi"),
                        (lambda: Region.slab(3, 0, 1), "axis must be 0, 1 or 2"),
                        (lambda: Region.cylinder(2, [0, 0], -1.0), "radius > 0"),
                        (lambda: Region.sphere([0, 0], 1.0), "centre of 3"),
                        (lambda: Layer(end="top"), "'low' or 'high'"),
                        (lambda: Layer(-1.0), "length >= 0"),
                        (lambda: Type(), "one or more whole numbers"),
                        (lambda: Type(1.5), "one or more whole numbers")]:
        with pytest.raises(GroupError, match=match):
            make()


def test_bending_groups_reproduce_its_supports_and_punch():
    beam = jaxbpm.generate.lattice("sc", (12, 2, 3), R, bond_radius_ratio=0.5)
    default = ThreePointBending(fit_range=(0.2, 1.0))
    supports, punch = default.layers(beam)
    given = ThreePointBending(fit_range=(0.2, 1.0), supports=np.flatnonzero(supports).tolist(), punch=punch)
    for a, b in zip(given.layers(beam), (supports, punch)):
        np.testing.assert_array_equal(a, b)
    k0 = jaxbpm.solve(beam, default, method="dsm").stiffness
    assert jaxbpm.solve(beam, given, method="dsm").stiffness == pytest.approx(k0, rel=1e-12)
    with pytest.raises(SceneError, match="give both supports and punch"):
        ThreePointBending(supports=supports)
    with pytest.raises(GroupError, match="particles are in both supports and punch"):
        ThreePointBending(supports=supports | punch, punch=punch).layers(beam)


def test_brazilian_groups_reproduce_its_strips():
    disc = jaxbpm.generate.cylinder(300, aspect=0.5, seed=0)
    strips = BrazilianDisc()
    fixed, driven = strips.layers(disc)
    given = BrazilianDisc(fixed=fixed, driven=np.flatnonzero(driven))
    assert not given.uses_walls and given.boundary == "layers"
    for a, b in zip(given.layers(disc), (fixed, driven)):
        np.testing.assert_array_equal(a, b)
    la, lb = strips.loading(disc, 0.1), given.loading(disc, 0.1)
    np.testing.assert_array_equal(la.clamped, lb.clamped)
    np.testing.assert_array_equal(la.velocity, lb.velocity)
    assert BrazilianDisc(platens="walls", fixed=fixed, driven=driven).uses_walls is False
    with pytest.raises(SceneError, match="give both fixed and driven"):
        BrazilianDisc(fixed=fixed)


def test_touching_pairs_and_a_contact_path_between_groups():
    # three unbonded discs in a row: 0 and 1 touch, 2 lies a hundredth of a radius away from 1
    x = np.array([[0.0, 0.0], [2 * R, 0.0], [4.01 * R, 0.0]])
    s = jaxbpm.Sample.from_arrays(x, R, np.zeros((0, 2), int), bond_radius=R)
    pairs = touching_pairs(s, np.array([True, True, True]))
    assert sorted(map(tuple, pairs.tolist())) == [(0, 1), (1, 0)]
    assert len(touching_pairs(s, np.array([False, True, False]), tol=0.02 * R)) == 2  # (1, 0) and (1, 2)
    a, b = clamped_groups(s, [0], [1], contacts=True)
    assert a.tolist() == [True, False, False] and b.tolist() == [False, True, False]
    with pytest.raises(GroupError, match="no bond path"):
        clamped_groups(s, [0], [1])
    with pytest.raises(GroupError, match="no path of bonds or contacts"):
        clamped_groups(s, [0], [2], contacts=True)
