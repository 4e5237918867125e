"""The uniaxial compression scene: geometry, boundary conditions, walls in series, and bad input."""

import numpy as np
import pytest

import jaxbpm
from jaxbpm import SceneError
from jaxbpm.scenes import UniaxialCompression

R = 1e-3


@pytest.fixture(scope="module")
def column():
    return jaxbpm.generate.lattice("sc", (2, 2, 6), R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})


def test_layers_and_geometry(column):
    scene = UniaxialCompression()
    fixed, driven = scene.layers(column)
    z = np.asarray(column.positions)[:, 2]
    np.testing.assert_array_equal(fixed, z == z.min())
    np.testing.assert_array_equal(driven, z == z.max())
    length, area = scene.geometry(column)
    np.testing.assert_allclose(length, 5 * 2 * R)
    np.testing.assert_allclose(area, (4 * R) ** 2)
    length, area = UniaxialCompression(gauge_length=1.0, area=2.0).geometry(column)
    assert (length, area) == (1.0, 2.0)


def test_linear_walls_act_as_springs_in_series(column):
    """Two linear walls of stiffness k_w per particle in series with the column: 1/K = 1/K_col + 2/(4 k_w)."""
    kn = 1e9 * np.pi * (0.5 * R) ** 2 / (2 * R)
    k_w = 2.0 * kn
    scene = UniaxialCompression(strain=0.002, boundary="walls", wall_law="linear", wall_stiffness=k_w)
    res = jaxbpm.solve(column, scene)
    k_col = 4 * kn / 5  # four chains of five bonds in series
    expected = 1.0 / (1.0 / k_col + 2.0 / (4 * k_w))
    np.testing.assert_allclose(res.stiffness, expected, rtol=1e-2)
    np.testing.assert_allclose(res.gauge_length, 12 * R)  # wall gap


def test_explicit_masks_reproduce_layers(column):
    fixed, driven = UniaxialCompression().layers(column)
    a = jaxbpm.solve(column, UniaxialCompression(strain=0.002))
    b = jaxbpm.solve(column, UniaxialCompression(strain=0.002, fixed=fixed, driven=driven))
    np.testing.assert_allclose(a.stiffness, b.stiffness, rtol=1e-12)


def test_compression_along_x_matches_z():
    s = jaxbpm.generate.lattice("sc", (6, 2, 2), R, bond_radius_ratio=0.5)
    t = jaxbpm.generate.lattice("sc", (2, 2, 6), R, bond_radius_ratio=0.5)
    ref = jaxbpm.solve(t, UniaxialCompression(axis=2, strain=0.002))
    same = dict(dt=ref.stats["dt"], loading_time=ref.stats["loading_time"])  # identical protocol
    ez = jaxbpm.solve(t, UniaxialCompression(axis=2, strain=0.002), **same).youngs_modulus
    ex = jaxbpm.solve(s, UniaxialCompression(axis=0, strain=0.002), **same).youngs_modulus
    np.testing.assert_allclose(ex, ez, rtol=1e-9)


@pytest.mark.parametrize("kw, message", [
    (dict(axis=3), "axis must be the whole number 0, 1 or 2"),
    (dict(axis=2.0), r"axis must be the whole number 0, 1 or 2, got 2\.0"),
    (dict(axis=True), "axis must be the whole number 0, 1 or 2, got True"),
    (dict(strain=0.0), "strain must lie in"),
    (dict(boundary="plates"), "boundary must be"),
    (dict(fixed=np.ones(3, bool)), "give both fixed and driven"),
    (dict(fit_range=(0.5, 0.2)), "fit_range"),
])
def test_bad_scene_arguments(kw, message):
    with pytest.raises(SceneError, match=message):
        UniaxialCompression(**kw)


def test_bad_masks(column):
    n = column.n_particles
    with pytest.raises(SceneError, match=r"fixed mask must have shape"):
        UniaxialCompression(fixed=np.ones(3, bool), driven=np.ones(3, bool)).layers(column)
    both = np.zeros(n, bool)
    both[0] = True
    with pytest.raises(SceneError, match="both fixed and driven"):
        UniaxialCompression(fixed=both, driven=both).layers(column)
    with pytest.raises(SceneError, match="at least one particle"):
        UniaxialCompression(fixed=np.zeros(n, bool), driven=both).layers(column)


def test_bad_time_step(column):
    with pytest.raises(SceneError, match="dt must be a positive"):
        jaxbpm.solve(column, UniaxialCompression(), dt=-1.0)
    with pytest.raises(ValueError, match="unknown method"):
        jaxbpm.solve(column, UniaxialCompression(), method="fem")
