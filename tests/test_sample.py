"""Sample construction, derived quantities and every validation error."""

import jax
import numpy as np
import pytest

from jaxbpm import BondMaterials, Domain, Sample, SampleError

R = 1e-3


def chain(n=4, **kw):
    pos = np.zeros((n, 3))
    pos[:, 0] = 2 * R * np.arange(n)
    bonds = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    kw.setdefault("bond_radius", 0.5 * R)
    return Sample.from_arrays(pos, R, bonds, **kw)


def test_derived_quantities():
    rb = 0.4e-3
    s = chain(3, bond_radius=rb, density=2000.0)
    np.testing.assert_allclose(s.bond_length, 2 * R)
    np.testing.assert_allclose(s.bond_area, np.pi * rb**2)
    np.testing.assert_allclose(s.bond_I, np.pi * rb**4 / 4)
    np.testing.assert_allclose(s.bond_J, np.pi * rb**4 / 2)
    m = 2000.0 * 4 / 3 * np.pi * R**3
    np.testing.assert_allclose(s.mass, m)
    np.testing.assert_allclose(s.inertia, 0.4 * m * R**2)
    assert s.positions.dtype == np.float64 and s.bonds.dtype == np.int32
    assert s.dim == 3 and s.positions.shape == (s.n_particles, s.dim)


def test_bond_radius_ratio_uses_smaller_particle():
    pos = np.array([[0, 0, 0], [3e-3, 0, 0]])
    s = Sample.from_arrays(pos, [1e-3, 2e-3], [[1, 0]], bond_radius_ratio=0.5)
    np.testing.assert_allclose(s.bond_radius, [0.5e-3])
    np.testing.assert_array_equal(s.bonds, [[0, 1]])  # stored with i < j


def test_is_a_pytree_and_jittable():
    s = chain(3)
    leaves, tree = jax.tree_util.tree_flatten(s)
    assert len(leaves) == 11 + 4 + 5 + 1  # the arrays, the two material tables, the particle types
    s2 = jax.tree_util.tree_unflatten(tree, leaves)
    assert s2.bond_contact == s.bond_contact
    total = jax.jit(lambda smp: smp.mass.sum() + smp.materials.E.sum())(s)
    np.testing.assert_allclose(total, s.mass.sum() + 1e9)


def test_materials_table_and_replace():
    s = chain(4, materials={"E": [1e9, 2e9], "nu": 0.3}, bond_material=[0, 1, 1])
    assert s.n_materials == 2
    np.testing.assert_allclose(s.materials.nu, [0.3, 0.3])
    assert np.all(np.isinf(s.materials.tensile_strength))
    s2 = s.replace(materials=BondMaterials.create(E=[5e9, 6e9], nu=[0.2, 0.1]))
    np.testing.assert_allclose(s2.materials.E, [5e9, 6e9])
    np.testing.assert_array_equal(s2.bond_material, s.bond_material)


def test_summary_reports_clusters_and_unbonded():
    pos = np.array([[0, 0, 0], [2e-3, 0, 0], [10e-3, 0, 0], [12e-3, 0, 0], [20e-3, 0, 0]], float)
    s = Sample.from_arrays(pos, R, [[0, 1], [2, 3]], bond_radius=0.5e-3,
                           domain=Domain("box", (-1e-3, -1e-3, -1e-3), (21e-3, 1e-3, 1e-3)))
    summ = s.summary()
    assert summ.n_clusters == 3 and summ.largest_cluster == 2 and summ.n_unbonded == 1
    assert summ.coordination_min == 0 and summ.coordination_max == 1
    np.testing.assert_allclose(summ.coordination_mean, 4 / 5)
    np.testing.assert_allclose(summ.packing_fraction, 5 * 4 / 3 * np.pi * R**3 / (22e-3 * 2e-3 * 2e-3))
    text = str(summ)
    assert "clusters" in text and "packing fraction" in text


GOOD = dict(positions=np.array([[0, 0, 0], [2e-3, 0, 0], [4e-3, 0, 0]], float), radii=R,
            bonds=np.array([[0, 1], [1, 2]]), bond_radius=0.5e-3)


@pytest.mark.parametrize("change, message", [
    (dict(positions=np.zeros((3, 4))), r"positions must have shape \[n, 3\]"),
    (dict(positions=np.array([[0, 0, 0], [np.nan, 0, 0], [4e-3, 0, 0]])), r"positions contains NaN .*\[1\]"),
    (dict(positions=np.array([[0, 0, 0], [np.inf, 0, 0], [4e-3, 0, 0]])), r"positions contains inf"),
    (dict(positions=np.array([["a", "b", "c"]] * 3)), r"positions must be a real numeric array"),
    (dict(radii=[1e-3, -1e-3, 1e-3]), r"non-positive radius at particles \[1\]"),
    (dict(radii=[1e-3, 1e-3]), r"radii must have shape \[3\]"),
    (dict(bonds=np.array([0, 1, 2])), r"bonds must have shape \[nb, 2\]"),
    (dict(bonds=np.array([[0, 1], [1, 3]])), r"bonds reference missing particles .* bad bonds \[1\]"),
    (dict(bonds=np.array([[0, 1], [-1, 2]])), r"bonds reference missing particles"),
    (dict(bonds=np.array([[0.5, 1.0], [1, 2]])), r"integer particle indices"),
    (dict(bonds=np.array([[0, 1], [2, 2]])), r"self-bonds .* \[1\]"),
    (dict(bonds=np.array([[0, 1], [1, 2], [1, 0]])), r"duplicate bonds .* \[2\].*repeats bond 0"),
    (dict(positions=np.array([[0, 0, 0], [0, 0, 0], [4e-3, 0, 0]], float)), r"zero-length bonds .* \[0\]"),
    (dict(bond_radius=[0.5e-3, 0.0]), r"bond_radius must be > 0; non-positive at bonds \[1\]"),
    (dict(bond_radius=[0.5e-3, np.nan]), r"bond_radius contains NaN"),
    (dict(bond_radius=None), r"exactly one of bond_radius and bond_radius_ratio"),
    (dict(bond_material=[0, 1]), r"unknown material index .* bonds \[1\]"),
    (dict(bond_material=[0, 0, 0]), r"bond_material must have shape \[2\]"),
    (dict(materials={"E": [-1.0]}), r"E must be finite and > 0"),
    (dict(materials={"E": [1e9], "nu": 0.7}), r"nu must lie in"),
    (dict(materials={"E": "abc"}), r"materials: E must be numbers, got 'abc'"),
    (dict(materials={"E": [1e9], "nu": "x"}), r"materials: nu must be numbers"),
    (dict(materials={"nu": 0.2}), r"missing field 'E'"),
    (dict(materials={"E": 1e9, "G": 1.0}), r"unknown fields \['G'\]"),
    (dict(density=-5.0), r"density=.* out of range"),
    (dict(bond_contact="sum"), r"bond_contact must be one of"),
    (dict(domain=Domain("sphere", (0, 0, 0), (1, 1, 1))), r"domain kind must be one of \('box', 'cylinder'\)"),
    (dict(domain=Domain("box", (0, 0, 0), (1, 0, 1))), r"domain hi must exceed lo"),
    (dict(domain=Domain("box", (0, 0, np.nan), (1, 1, 1))), r"domain lo and hi must be 3 finite numbers"),
    (dict(domain=Domain("box", (0, 0), (1, 1))), r"domain lo and hi must be 3 finite numbers"),
    (dict(domain=(0, 1)), r"domain must be a Domain"),
    (dict(particle_material={"density": "heavy"}), r"particle_material: density must be a real number, got 'heavy'"),
    (dict(particle_material={"nu": np.float64(0.7)}), r"particle_material: nu=0\.7 is out of range"),
    (dict(bonds=[[0, 1], [1]]), r"bonds must be an array of numbers"),
    (dict(bond_radius=None, bond_radius_ratio="half"), r"bond_radius_ratio must be finite and > 0, got 'half'"),
    (dict(materials={"E": [1e9 + 1j]}), r"materials: E must be numbers"),
    (dict(radii=1e300), r"radii must lie where mass and inertia are finite"),
    (dict(radii=[1e-3, 1e-300, 1e-3]), r"mass and inertia are finite and > 0 .* particles \[1\]"),
    (dict(positions=np.array([[0, 0, 0], [2e-3, 0, 0], [4e-3, 0, 0]]) + 1e12), r"too far from the origin.*recentre"),
    (dict(positions=np.array([[0, 0, 0], [2e-3, 0, 0], [1e306, 0, 0]])), r"bonds must join neighbours.*\[1\]"),
    (dict(types=[1, 2]), r"types must have shape \[3\] \(one per particle\), got \(2,\)"),
    (dict(types=[1, -2, 3]), r"types must lie in 0\.\.2147483647; not at particles \[1\]"),
    (dict(types=[1, 2.5, 3]), r"types must be whole numbers; not at particles \[1\]"),
    (dict(types=[True, False, True]), r"types must hold whole numbers .* got dtype bool"),
    (dict(types=[1, 2**40, 1]), r"types must lie in 0\.\.2147483647; not at particles \[1\]"),
    (dict(types=["a", "b", "c"]), r"types must hold whole numbers"),
])
def test_validation_errors(change, message):
    with pytest.raises(SampleError, match=message):
        Sample.from_arrays(**{**GOOD, **change})


def test_unconnected_particles_are_allowed():
    s = Sample.from_arrays(GOOD["positions"], R, np.zeros((0, 2), int), bond_radius=np.zeros(0))
    assert s.n_bonds == 0 and s.summary().n_unbonded == 3


def test_renumbered_keeps_the_sample_and_generators_number_along_a_curve():
    """Renumbering moves particles in memory only: positions, bonds (as pairs of points), bond data, masses and the
    DSM stiffness are those of the original; random packings come numbered along the Morton curve (bonds join
    particles close in index)."""
    import jaxbpm

    s = jaxbpm.generate.box(300, seed=4, mean_radius=R, packing_fraction=0.5,
                            materials={"E": 1e9, "nu": 0.3}, density=2500.0)
    b = np.asarray(s.bonds)
    assert np.median(np.abs(b[:, 1] - b[:, 0])) < s.n_particles / 20  # ~9 on this sample; ~100 in random order
    rng = np.random.default_rng(0)
    order = rng.permutation(s.n_particles)
    t = s.renumbered(order)
    np.testing.assert_array_equal(t.positions, np.asarray(s.positions)[order])
    np.testing.assert_array_equal(t.mass, np.asarray(s.mass)[order])
    tb = np.asarray(t.bonds)
    assert np.all(tb[:, 0] < tb[:, 1]) and np.all(np.diff(tb[:, 0]) >= 0)

    def pairs(x):  # bonds as sorted pairs of end points, with their radii
        p = np.asarray(x.positions)[np.asarray(x.bonds)]
        key = np.concatenate([np.sort(p.reshape(-1, 6), axis=1), np.asarray(x.bond_radius)[:, None]], axis=1)
        return key[np.lexsort(key.T[::-1])]

    np.testing.assert_array_equal(pairs(t), pairs(s))
    back = t.renumbered()  # along the curve again: the generator's own order
    np.testing.assert_array_equal(back.positions, s.positions)
    np.testing.assert_array_equal(back.bonds, s.bonds)
    scene = jaxbpm.scenes.UniaxialCompression(strain=1e-3)
    k0, k1 = (jaxbpm.solve(x, scene, method="dsm").stiffness for x in (s, t))
    np.testing.assert_allclose(k1, k0, rtol=1e-9)
    with pytest.raises(SampleError, match="permutation"):
        s.renumbered(np.zeros(s.n_particles, int))


def test_particle_types_follow_their_particles():
    """Types default to 1 (LAMMPS's first atom type), are int32, and go with their particles through replace,
    subset, largest_cluster and renumbered; the pytree and the summary carry them."""
    s = chain(5)
    assert s.types.dtype == np.int32 and s.types.tolist() == [1] * 5
    t = s.replace(types=np.array([3.0, 1.0, 4.0, 1.0, 5.0]))  # whole floats (a text file's column) accepted
    assert t.types.dtype == np.int32 and t.types.tolist() == [3, 1, 4, 1, 5]
    assert t.replace(radii=1.1 * R).types.tolist() == [3, 1, 4, 1, 5]
    assert chain(5, types=7).types.tolist() == [7] * 5
    assert t.subset(np.array([True, False, True, True, False])).types.tolist() == [3, 4, 1]
    order = np.array([4, 2, 0, 1, 3])
    r = t.renumbered(order)
    assert r.types.tolist() == [5, 4, 3, 1, 1]
    np.testing.assert_array_equal(np.asarray(r.positions), np.asarray(t.positions)[order])
    cut = t.replace(bonds=[[0, 1], [1, 2], [3, 4]], bond_radius=0.5 * R)
    assert cut.largest_cluster().types.tolist() == [3, 1, 4]
    leaves, tree = jax.tree_util.tree_flatten(t)
    assert any(leaf is t.types for leaf in leaves)
    assert jax.tree_util.tree_unflatten(tree, leaves).types.tolist() == [3, 1, 4, 1, 5]
    assert t.summary().types == ((1, 2), (3, 1), (4, 1), (5, 1))
    assert "particle types       1: 2, 3: 1, 4: 1, 5: 1" in str(t.summary())


def test_bonds_wider_than_their_particles_need_wide_bonds():
    """``bond_radius_ratio=50.0`` was accepted (bonds 50 times wider than the particles)."""
    from jaxbpm.errors import SampleError

    pos = np.array([[0.0, 0, 0], [1.5, 0, 0], [3.0, 0, 0]])
    radii = np.array([1.0, 0.5, 1.0])
    bonds = [[0, 1], [1, 2]]
    with pytest.raises(SampleError, match=r"bond_radius_ratio 50.0 > 1.*wide_bonds=True"):
        Sample.from_arrays(pos, radii, bonds, bond_radius_ratio=50.0)
    # bond radius per bond: against the smaller particle (0.5 here), the bond named
    with pytest.raises(SampleError, match=r"above the smaller particle's radius at bonds \[1\].*ratio 1.2"):
        Sample.from_arrays(pos, radii, bonds, [0.5, 0.6])
    assert np.allclose(Sample.from_arrays(pos, radii, bonds, bond_radius_ratio=1.0).bond_radius, 0.5)
    wide = Sample.from_arrays(pos, radii, bonds, bond_radius_ratio=2.0, wide_bonds=True)
    assert np.allclose(wide.bond_radius, 1.0) and np.allclose(wide.bond_area, np.pi)
    # the sample's own bonds stay accepted through subsets, renumbering and unrelated changes
    assert wide.subset([True, True, False]).n_bonds == 1 and wide.renumbered([2, 1, 0]).n_bonds == 2
    assert wide.replace(density=1000.0).n_bonds == 2
    with pytest.raises(SampleError, match="wide_bonds=True"):  # new radii: checked again
        wide.replace(radii=0.4)
    assert wide.replace(radii=0.4, wide_bonds=True).n_bonds == 2


def test_a_saved_sample_with_wide_bonds_loads(tmp_path):
    from jaxbpm import io

    pos = np.array([[0.0, 0, 0], [1.5, 0, 0]])
    wide = Sample.from_arrays(pos, 1.0, [[0, 1]], bond_radius_ratio=3.0, wide_bonds=True)
    back = io.load_sample(io.save_sample(tmp_path / "w.h5", wide))
    assert np.array_equal(back.bond_radius, wide.bond_radius)


# ---------------------------------------------------------------------------------------------- two dimensions
def test_two_dimensional_sample_from_arrays():
    pos = np.array([[0.0, 0.0], [2e-3, 0.0], [2e-3, 2e-3]])
    s = Sample.from_arrays(pos, 1e-3, [[0, 1], [1, 2]], bond_radius=0.5e-3, density=2000.0, thickness=0.01)
    assert s.dim == 2 and s.thickness == 0.01
    assert np.allclose(s.mass, 2000.0 * np.pi * 1e-6 * 0.01) and np.allclose(s.inertia, 0.5 * s.mass * 1e-6)
    assert np.allclose(s.bond_area, 1e-3 * 0.01) and np.allclose(s.bond_I, (1e-3) ** 3 * 0.01 / 12)
    assert np.allclose(s.bond_length, 2e-3)
    assert Sample.from_arrays(pos, 1e-3, [[0, 1]], bond_radius=0.5e-3).thickness == 1.0  # PFC2D's unit thickness
    # the thickness survives every rebuild
    assert s.replace(radii=0.9e-3).thickness == 0.01
    assert s.subset(np.array([True, True, False])).thickness == 0.01
    assert s.renumbered().thickness == 0.01 and s.renumbered().dim == 2
    assert "dim=2" in repr(s)


def test_two_dimensional_validation():
    pos = np.array([[0.0, 0.0], [2e-3, 0.0]])
    with pytest.raises(SampleError, match=r"\[n, 2\]"):
        Sample.from_arrays(np.zeros((2, 4)), 1e-3, [[0, 1]], bond_radius=1e-4)
    with pytest.raises(SampleError, match="takes none"):
        Sample.from_arrays(np.zeros((2, 3)) + [[0, 0, 0], [1, 0, 0]], 1.0, [[0, 1]], bond_radius=0.1, thickness=1.0)
    with pytest.raises(SampleError, match="thickness"):
        Sample.from_arrays(pos, 1e-3, [[0, 1]], bond_radius=1e-4, thickness=-1.0)
    with pytest.raises(SampleError, match="2 finite numbers"):
        Sample.from_arrays(pos, 1e-3, [[0, 1]], bond_radius=1e-4, domain=Domain("box", (0, 0, 0), (1, 1, 1)))
    with pytest.raises(SampleError, match="zero-length"):
        Sample.from_arrays(np.zeros((2, 2)), 1e-3, [[0, 1]], bond_radius=1e-4)


def test_two_dimensional_packing_fraction_is_an_area_fraction():
    pos = np.array([[0.0, 0.0], [2.0, 0.0]])
    s = Sample.from_arrays(pos, 1.0, [[0, 1]], bond_radius=0.5)
    assert np.isclose(s.packing_fraction()[0], 2 * np.pi / 8.0)  # two unit discs in a 4 x 2 box
    assert "discs" in s.packing_fraction()[1]
    disc = s.replace(domain=Domain("cylinder", (-1.0, -2.0), (3.0, 2.0)))
    assert np.isclose(disc.packing_fraction()[0], 2 * np.pi / (np.pi * 4.0))
