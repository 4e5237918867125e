"""The DEM on two-dimensional samples (discs, one rotation each): against the DSM on lattices and a random disc
packing, and the breakage load of a two-disc bond against PFC's rule in closed form."""

import numpy as np
import pytest

import jaxbpm
from jaxbpm.errors import SceneError
from jaxbpm.generate import disc_packing, lattice
from jaxbpm.physics.linear import LinearLaw
from jaxbpm.physics.model import build_model, default_params
from jaxbpm.sample import Sample
from jaxbpm.scenes import UniaxialCompression


@pytest.mark.parametrize("make", [lambda: lattice("square", (6, 9)), lambda: lattice("hex", (8, 9)),
                                  lambda: disc_packing(200, aspect=(1, 1.5), seed=1).largest_cluster()],
                         ids=["square", "hex", "packing"])
def test_dem_agrees_with_the_dsm(make):
    s = make()
    scene = UniaxialCompression(axis=1, strain=1e-4)
    dem = jaxbpm.solve(s, scene, "dem")
    dsm = jaxbpm.solve(s, scene, "dsm")
    assert dem.state.orientations.shape == (s.n_particles, 1)
    assert abs(dem.stiffness / dsm.stiffness - 1) < 0.01
    if "poisson_ratio" in dsm.stats and dsm.stats["poisson_ratio"] > 0.05:
        assert abs(dem.stats["poisson_ratio"] / dsm.stats["poisson_ratio"] - 1) < 0.02


def test_two_disc_bond_breaks_at_the_analytic_load():
    L, a, tau = 2e-3, np.pi / 4, 1e6  # bond at 45 degrees to the load, both discs clamped (no rotation)
    s = Sample.from_arrays([[0.0, 0.0], [L * np.cos(a), L * np.sin(a)]], 1e-3, [[0, 1]], bond_radius=0.5e-3,
                           materials={"E": 1e9, "nu": 0.25, "tensile_strength": 1e9, "shear_strength": tau})
    k = build_model(s).stiffness(default_params(s))
    kn, kt, area = float(k.kn[0]), float(k.kt[0]), float(s.bond_area[0])
    # the driven disc moves by delta against y: shear delta cos(a) across the bond, no bending (rotations held):
    # PFC's shear rule |F_s| / A = tau_c gives delta_c, and the load along y is (k_n sin^2 a + k_t cos^2 a) delta
    delta_c = tau * area / (kt * np.cos(a))
    scene = UniaxialCompression(axis=1, strain=3 * delta_c / (L * np.sin(a)), breakage=True, stop_after_peak=None)
    r = jaxbpm.solve(s, scene, "dem", chunk=8)
    last = int(np.flatnonzero(r.force > 0).max())  # the last record with the bond intact
    assert r.displacement[last] <= delta_c * (1 + 1e-9) <= r.displacement[last + 1] * (1 + 1e-3)
    slope = kn * np.sin(a) ** 2 + kt * np.cos(a) ** 2
    assert abs(r.force[last] / (slope * r.displacement[last]) - 1) < 0.01
    assert r.stats["broken_shear"] == 1 and r.stats["broken_tensile"] == 0


def test_a_2d_run_writes_its_vtu_series_at_z_zero(tmp_path):
    import meshio

    s = lattice("square", (4, 6))
    r = jaxbpm.solve(s, UniaxialCompression(axis=1, strain=1e-4), "dem", snapshots=2, vtu=tmp_path / "run.pvd")
    last = meshio.read(sorted(tmp_path.glob("*.vtu"))[-1])
    assert last.points.shape == (s.n_particles, 3) and np.all(last.points[:, 2] == 0.0)
    # the last frame is the final state: its displacement is the run's
    moved = np.asarray(r.state.positions) - np.asarray(s.positions)
    assert np.allclose(last.point_data["displacement"][:, :2], moved, rtol=0, atol=1e-15)


R_DISC = 1e-3


def _stack_of_discs(thickness):
    """Three discs in a column along y, touching, no bonds: the ends are the clamped layers, the middle one free."""
    return Sample.from_arrays(np.array([[0.0, 0.0], [0.0, 2 * R_DISC], [0.0, 4 * R_DISC]]), R_DISC,
                              np.zeros((0, 2), int), bond_radius=np.zeros(0), thickness=thickness,
                              particle_material={"E": 1e9, "nu": 0.25, "friction": 0.5, "density": 2500.0})


def test_discs_pressed_together_carry_the_linear_law_force():
    """Linear contacts between discs of thickness t: k_n = E* (2 r t) / (2 r) = E* t; the free middle disc between
    the clamped ones settles between two springs in series, so the load is k_n / 2 times the shortening."""
    emod, t = 2e9, 0.2
    law = LinearLaw(emod=emod, kratio=1.21)
    scene = UniaxialCompression(axis=1, strain=0.005, contacts=True, contact_law=law)
    r = jaxbpm.solve(_stack_of_discs(t), scene, "dem")
    kn = emod * t
    late = r.displacement > 0.5 * r.displacement[-1]
    np.testing.assert_allclose(r.force[late], 0.5 * kn * r.displacement[late], rtol=0.01)
    np.testing.assert_allclose(r.stiffness, 0.5 * kn, rtol=0.01)
    x = np.asarray(r.state.positions)
    np.testing.assert_allclose(x[1, 0], 0.0, atol=1e-12)  # no sideways force on a column
    np.testing.assert_allclose(x[1, 1], 0.5 * (x[0, 1] + x[2, 1]), rtol=1e-3)


def _max_overlap(sample, positions):
    """The largest overlap of any two discs, over the smaller radius."""
    from scipy.spatial import cKDTree

    x, rad = np.asarray(positions), np.asarray(sample.radii)
    p = cKDTree(x).query_pairs(2 * rad.max(), output_type="ndarray")
    gap = np.linalg.norm(x[p[:, 1]] - x[p[:, 0]], axis=1) - rad[p[:, 0]] - rad[p[:, 1]]
    return float(np.max(-gap / np.minimum(rad[p[:, 0]], rad[p[:, 1]])))


@pytest.mark.filterwarnings("ignore:linear contacts:UserWarning")  # the generated packing's bonded pairs overlap
def test_a_disc_packing_to_failure_with_linear_contacts():
    """Compression past the peak: bonds break, the broken discs push on each other by the linear law (at the end no
    two discs overlap by more than a few percent of a radius, about the strain); without contacts they pass through
    each other."""
    s = disc_packing(300, aspect=(1, 2), seed=1).largest_cluster()
    params = default_params(s) | {"bond_tensile_strength": np.array([3e6]), "bond_shear_strength": np.array([6e6])}
    r = jaxbpm.solve(s, UniaxialCompression.to_failure(axis=1, contact_law="linear"), "dem", params=params)
    peak = int(np.argmax(r.force))
    assert r.stats["stop_reason"] == "after_peak" and 0 < peak < len(r.force) - 1
    assert r.force[-1] < 0.9 * r.force[peak] and r.displacement[-1] < 0.02 * r.gauge_length
    assert r.stats["broken_tensile"] + r.stats["broken_shear"] > 0.1 * s.n_bonds
    assert _max_overlap(s, r.state.positions) < 0.05
    bare = jaxbpm.solve(s, UniaxialCompression.to_failure(axis=1, contacts=False), "dem", params=params)
    assert _max_overlap(s, bare.state.positions) > 0.5


def test_only_linear_contacts_and_only_the_dem_in_2d():
    s = _stack_of_discs(1.0)
    with pytest.raises(SceneError, match="linear contacts"):
        build_model(s, contacts=True)  # Hertz-Mindlin between discs: refused
    with pytest.raises(SceneError, match="linear contacts"):
        build_model(s, contacts=True, contact_law="cohesive", cohesive={"c0": 1.0, "c_max": 1.0})
    with pytest.raises(SceneError, match="walls"):
        build_model(s, contacts=True, contact_law="linear", walls="hertz")
    scene = UniaxialCompression(axis=1, strain=1e-3, contacts=True, contact_law="linear")
    with pytest.raises(SceneError, match="the DSM with contacts.*not yet available"):
        jaxbpm.solve(s, scene, "dsm")
    with pytest.raises(SceneError, match="the STE with contacts.*not yet available"):
        jaxbpm.solve(disc_packing(60, seed=2), scene, "ste")
    model = build_model(s, contacts=True, contact_law="linear")
    assert model.contacts and model.contact_law == "linear" and model.dofs == 3
