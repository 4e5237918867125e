"""Two-dimensional samples: lattices of discs and random disc packings."""

import numpy as np
import pytest

from jaxbpm import discs, generate
from jaxbpm.errors import SampleError

R = 1e-3


def _brute(pos, rad, gap):
    n = len(pos)
    out = [(i, j) for i in range(n) for j in range(i + 1, n)
           if np.linalg.norm(pos[j] - pos[i]) - rad[i] - rad[j] < gap]
    return np.array(out, dtype=np.int32).reshape(-1, 2)


def test_square_lattice_counts_and_geometry():
    nx, ny = 5, 3
    s = generate.lattice("square", (nx, ny), R, thickness=0.2, density=2000.0)
    assert s.dim == 2 and s.positions.shape == (nx * ny, 2) and s.thickness == 0.2
    assert s.n_bonds == (nx - 1) * ny + nx * (ny - 1)  # nearest neighbours of a grid
    assert np.allclose(s.bond_length, 2 * R, rtol=1e-14)
    assert np.array_equal(s.bonds, _brute(s.positions, s.radii, 1e-9 * R))  # every touching pair, no other
    assert np.allclose(s.mass, 2000.0 * np.pi * R**2 * 0.2)
    assert np.isclose(s.packing_fraction()[0], np.pi / 4)  # a disc in its square cell
    assert s.domain.lo == (-R, -R) and np.allclose(s.domain.hi, (2 * R * (nx - 1) + R, 2 * R * (ny - 1) + R))


def test_hex_lattice_bonds_touching_neighbours():
    s = discs.lattice2d("hex", (6, 5), R)
    assert np.array_equal(s.bonds, _brute(s.positions, s.radii, 1e-9 * R))
    assert np.allclose(s.bond_length, 2 * R, rtol=1e-12)
    assert s.coordination().max() == 6


@pytest.mark.parametrize("cells", [(2, 2, 2), (0, 3), (2.5, 3), "ab"])
def test_lattice_2d_rejects_bad_cells(cells):
    with pytest.raises(SampleError, match="cells"):
        generate.lattice("square", cells)


@pytest.mark.parametrize("shape", discs.DISC_SHAPES)
def test_disc_packing_has_no_overlap_and_bonds_its_contacts(shape):
    s = generate.disc_packing(150, shape, mean_radius=R, seed=3)
    pos, rad = np.asarray(s.positions), np.asarray(s.radii)
    assert s.dim == 2 and s.n_particles == 150
    d = np.linalg.norm(pos[:, None] - pos[None], axis=-1) + np.eye(150) * 1e9
    assert (rad[:, None] + rad[None] - d).max() < 1.01e-3 * R  # overlap_tol
    lo, hi = np.asarray(s.domain.lo), np.asarray(s.domain.hi)
    if shape == "disc":
        c, big = 0.5 * (lo + hi), 0.5 * (hi - lo)[0]
        assert np.max(np.linalg.norm(pos - c, axis=1) + rad - big) < 1.01e-3 * R
    else:
        assert np.all(pos - rad[:, None] >= lo - 1e-12) and np.all(pos + rad[:, None] <= hi + 1e-12)
    assert np.array_equal(s.bonds, _brute(pos, rad, 0.05 * R))
    phi = s.packing_fraction()[0]
    area = np.prod(hi - lo) * (np.pi / 4 if shape == "disc" else 1)
    assert 0.75 < phi < 0.82 and np.isclose(phi, np.sum(np.pi * rad**2) / area)
    assert s.coordination().mean() > 3.0  # a dense packing, not a gas


def test_disc_packing_is_deterministic_and_checks_arguments():
    a, b = (generate.rectangle(40, seed=1) for _ in range(2))
    assert np.array_equal(a.positions, b.positions)
    with pytest.raises(SampleError, match="packing_fraction"):
        generate.rectangle(40, packing_fraction=0.9)
    with pytest.raises(SampleError, match="aspect"):
        generate.rectangle(40, aspect=(1, 1, 1))
    with pytest.raises(SampleError, match="shape"):
        discs.disc_packing(40, "sphere")
    with pytest.raises(SampleError, match="sweeps"):
        generate.rectangle(200, packing_fraction=0.85, max_sweeps=5)


def test_contact_pairs_in_the_plane():
    rng = np.random.default_rng(0)
    pos, rad = rng.uniform(0, 20 * R, (200, 2)), R * rng.uniform(0.8, 1.2, 200)
    assert np.array_equal(discs.contact_pairs(pos, rad, 0.1 * R), _brute(pos, rad, 0.1 * R))
    with pytest.raises(SampleError, match="positions"):
        discs.contact_pairs(pos[:, :1], rad, R)
