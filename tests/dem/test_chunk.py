"""Compile once, answer fast (DEM): no jax-md for bonds-only runs, samples padded to size classes share the compiled
programs without changing any result, a repeated solve compiles nothing, and wall = setup + compile + run."""

import subprocess
import sys

import jax
import meshio
import numpy as np
import pytest

import jaxbpm
from jaxbpm.dem import chunk
from jaxbpm.scenes import UniaxialCompression

from tests.dem._events import compilations

R = 1e-3
ELASTIC = UniaxialCompression(strain=0.002)


def _lattice(cells, **materials):
    return jaxbpm.generate.lattice("sc", cells, R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25,
                                                                                       **materials})


def _check_times(res):
    assert res.setup_time > 0 and res.compile_time >= 0 and res.run_time > 0
    np.testing.assert_allclose(res.setup_time + res.compile_time + res.run_time, res.wall_time, rtol=1e-9)


def test_bonds_only_dem_does_not_import_jax_md():
    # nor does the DEM with contacts on the CPU (its candidate list is built on the host); with jax-md's list (the
    # accelerators') it loads only jax-md's neighbour lists: the package __init__ (rigid bodies, energies) computes
    # at import, which compiled about 3 s of small programs in a first call
    code = ("import jax, sys; jax.config.update('jax_enable_x64', True); import jaxbpm, jaxbpm.dem; "
            "print('jax_md' in sys.modules); "
            "s = jaxbpm.generate.lattice('sc', (2, 2, 3), 1e-3); "
            "r = jaxbpm.solve(s, jaxbpm.scenes.UniaxialCompression(strain=0.002), method='dem', transits=5); "
            "print(r.stiffness > 0, 'jax_md' in sys.modules); "
            "scene = jaxbpm.scenes.UniaxialCompression(strain=0.002, contacts=True); "
            "c = jaxbpm.solve(s, scene, method='dem', transits=2, throw=False); "
            "print(c.stiffness > 0, c.stats['contact_list'], any(m.startswith('jax_md') for m in sys.modules)); "
            "jaxbpm.dem.neighbors.HOST_LIST_MIN = 1 << 62; "
            "c = jaxbpm.solve(s, scene, method='dem', transits=2, throw=False); "
            "print(c.stiffness > 0, c.stats['contact_list'], 'jax_md.partition' in sys.modules, "
            "any(m in sys.modules for m in ('jax_md', 'jax_md.rigid_body', 'jax_md.energy')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "True", "False", "True", "host", "False", "True", "jax-md", "True",
                                  "False"]


def test_padding_changes_nothing(tmp_path):
    """A breaking sample run padded to its size class and as it is: the same time step, curve, broken bonds, state
    and VTU frames."""
    s = jaxbpm.generate.lattice("fcc", (2, 2, 2), R, materials={"E": 1e9, "nu": 0.25, "tensile_strength": 2e6,
                                                                 "shear_strength": 4e6})
    scene = UniaxialCompression(strain=0.03, breakage=True)
    padded = jaxbpm.solve(s, scene, transits=10, snapshots=2, vtu=tmp_path / "run.pvd")
    plain = jaxbpm.solve(s, scene, transits=10, pad=False)
    n_cap, nb_cap = padded.stats["padded_to"]
    assert n_cap >= s.n_particles + 2 and nb_cap > s.n_bonds and plain.stats["padded_to"] is None

    np.testing.assert_allclose(padded.stats["dt"], plain.stats["dt"], rtol=1e-12)
    assert padded.stats["steps"] == plain.stats["steps"]
    np.testing.assert_allclose(padded.stiffness, plain.stiffness, rtol=1e-12)
    np.testing.assert_allclose(padded.displacement, plain.displacement, rtol=1e-12)
    np.testing.assert_allclose(padded.force, plain.force, rtol=1e-12, atol=1e-12 * np.max(np.abs(plain.force)))
    assert 0 < padded.stats["broken_tensile"] + padded.stats["broken_shear"] < s.n_bonds
    for key in ("broken_tensile", "broken_shear", "broken_at_peak"):
        assert padded.stats[key] == plain.stats[key]
    np.testing.assert_array_equal(padded.stats["broken_curve"], plain.stats["broken_curve"])

    a, b = padded.state, plain.state
    for name in ("positions", "velocities", "orientations", "omegas", "force", "moment"):
        assert getattr(a, name).shape == getattr(b, name).shape == (s.n_particles, 4 if name == "orientations" else 3)
        scale = np.max(np.abs(getattr(b, name)))
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=1e-12, atol=1e-12 * scale)
    for name in ("intact", "broken"):
        assert getattr(a, name).shape == (s.n_bonds,)
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    np.testing.assert_allclose(a.broken_time, b.broken_time, rtol=1e-12)  # (NaN where intact, in both)

    last = meshio.read(sorted(tmp_path.glob("run_*.vtu"))[-1])
    assert last.points.shape == (s.n_particles, 3) and len(last.cells_dict["line"]) == s.n_bonds
    np.testing.assert_allclose(last.points, np.asarray(a.positions))
    np.testing.assert_array_equal(last.cell_data["break_mode"][1], np.asarray(a.broken))


@pytest.fixture(scope="module")
def first():
    """A solve of a 128-particle lattice (size class 160 particles, 401 bonds); it may have compiled."""
    size = chunk._run_chunk._cache_size()
    res = jaxbpm.solve(_lattice((4, 4, 8)), ELASTIC)
    return res, chunk._run_chunk._cache_size() > size


def test_first_solve_times_add_up(first):
    res, compiled = first
    _check_times(res)
    assert (res.compile_time > 0) == compiled  # a new chunk program is timed, a cached one is not
    assert res.stats["kernel_time"] <= res.run_time


def test_second_solve_of_the_same_sample_compiles_nothing(first):
    res, _ = first
    with compilations() as seen:
        again = jaxbpm.solve(_lattice((4, 4, 8)), ELASTIC)
    assert seen == []
    assert again.compile_time == 0.0
    _check_times(again)
    np.testing.assert_allclose(again.force, res.force, rtol=1e-14)


def test_another_sample_of_the_same_size_class_compiles_nothing(first):
    res, _ = first
    other = _lattice((4, 5, 7), E=2e9)  # 140 particles, 337 bonds: another sample of the class
    size = chunk._run_chunk._cache_size()
    with compilations() as seen:
        out = jaxbpm.solve(other, ELASTIC)
    assert seen == []
    assert chunk._run_chunk._cache_size() == size and out.compile_time == 0.0
    assert out.stats["padded_to"] == res.stats["padded_to"]
    assert out.state.positions.shape == (other.n_particles, 3)
    # 2x the bond modulus, same lattice: twice the Young's modulus (to the DEM's own accuracy)
    np.testing.assert_allclose(out.youngs_modulus, 2 * res.youngs_modulus, rtol=2e-2)
    _check_times(out)
