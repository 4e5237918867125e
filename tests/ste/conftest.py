"""The STE tests' samples: a simple-cubic lattice, a 1000-particle packing and its STE solve (one each for the
session: the first solve of the packing is the one that compiles)."""

import pytest

import jaxbpm
from jaxbpm.scenes import UniaxialCompression

R = 1e-3
D = 2 * R  # bond length of the lattices


@pytest.fixture(scope="session")
def lattice():
    return jaxbpm.generate.lattice("sc", (5, 5, 5), R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})


@pytest.fixture(scope="session")
def packing():
    s = jaxbpm.generate.box(1000, seed=3, mean_radius=R, packing_fraction=0.58, materials={"E": 1e9, "nu": 0.25})
    return s.largest_cluster()


@pytest.fixture(scope="session")
def plain(packing):
    return jaxbpm.solve(packing, UniaxialCompression(strain=0.002), method="ste")
