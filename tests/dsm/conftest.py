"""The DSM tests' samples: a simple-cubic column and a 200-particle packing."""

import numpy as np
import pytest

import jaxbpm

R = 1e-3
# one xdist worker for the tests that solve `packing` (or a sample of its size class) with contacts: they share the
# compiled nonlinear solve with contacts, the DEM's run with contacts and the linear solves
SHARED = "dsm-packing-contacts"
KN = 1e9 * np.pi * (0.5 * R) ** 2 / (2 * R)


@pytest.fixture(scope="session")
def column():
    return jaxbpm.generate.lattice("sc", (3, 3, 6), R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})


@pytest.fixture(scope="session")
def packing():
    s = jaxbpm.generate.box(200, seed=3, mean_radius=R, packing_fraction=0.5)
    return s.largest_cluster()
