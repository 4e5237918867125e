"""The DEM on two-dimensional samples (discs, one rotation each): against the DSM on lattices and a random disc
packing, and the breakage load of a two-disc bond against PFC's rule in closed form."""

import numpy as np
import pytest

import jaxbpm
from jaxbpm.generate import disc_packing, lattice
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
