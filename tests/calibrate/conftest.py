"""Samples shared by the calibration tests (one per test session: their forwards and compiled solves are shared)."""

import pytest

import jaxbpm
from jaxbpm import calibrate as cal
from tests.calibrate._cases import SCENE


@pytest.fixture(scope="package")
def one():
    return jaxbpm.generate.lattice("fcc", (3, 3, 4), 1e-3, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})


@pytest.fixture(scope="package")
def two(one):
    """Two components, moduli 1:4, mixed at random."""
    return jaxbpm.generate.mix_materials(one, [0.5, 0.5], seed=2, materials={"E": [1e9, 4e9], "nu": 0.25})


@pytest.fixture(scope="package")
def dsm_forward(one):
    return cal.forward_model(one, SCENE, "dsm")

