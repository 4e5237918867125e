"""The geometry of spheres and discs, checked against the textbook formulas (and PFC2D's unit thickness)."""

import numpy as np
import pytest

from jaxbpm import _geometry
from jaxbpm.errors import SampleError, SceneError
from jaxbpm.generate import lattice


def test_disc_mass_and_inertia_are_those_of_a_thin_cylinder():
    r, rho, t = np.array([1e-3, 2e-3]), 2500.0, 0.1
    mass, inertia = _geometry.particle_mass(r, rho, t)
    # a thin cylinder of radius r, height t: volume pi r^2 t, moment of inertia about its axis m r^2 / 2
    assert np.allclose(mass, rho * np.pi * r**2 * t, rtol=1e-15)
    assert np.allclose(inertia, 0.5 * mass * r**2, rtol=1e-15)
    mass3, inertia3 = _geometry.particle_mass(r, rho, None)
    assert np.allclose(mass3, rho * 4 / 3 * np.pi * r**3) and np.allclose(inertia3, 0.4 * mass3 * r**2)


def test_rectangular_bond_section_by_integration():
    rb, t = np.array([0.3e-3]), 2e-3
    sec = _geometry.bond_section(rb, t)
    # integrate y^2 over the rectangle |y| <= rb, |z| <= t / 2 (midpoint rule, exact to 1e-8 here)
    m = 20000
    y = (np.arange(m) + 0.5) / m * 2 * rb[0] - rb[0]
    dy = 2 * rb[0] / m
    assert np.isclose(sec.area[0], 2 * rb[0] * t, rtol=1e-15)
    assert np.isclose(sec.inertia[0], np.sum(y**2) * dy * t, rtol=1e-8)
    z = (np.arange(m) + 0.5) / m * t - t / 2
    polar = np.sum(y**2) * dy * t + np.sum(z**2) * (t / m) * 2 * rb[0]
    assert np.isclose(sec.polar[0], polar, rtol=1e-8)


def test_thickness_checks():
    assert _geometry.checked_thickness(None, 2) == _geometry.DEFAULT_THICKNESS == 1.0
    assert _geometry.checked_thickness(0.5, 2) == 0.5
    assert _geometry.checked_thickness(None, 3) is None
    with pytest.raises(SampleError, match="takes none"):
        _geometry.checked_thickness(1.0, 3)
    for bad in (0.0, -1.0, np.inf, "1", True):
        with pytest.raises(SampleError, match="thickness"):
            _geometry.checked_thickness(bad, 2)


def test_solid_measure():
    r = np.array([1.0, 2.0])
    assert np.isclose(_geometry.solid_measure(r, 2), 5 * np.pi)
    assert np.isclose(_geometry.solid_measure(r, 3), 4 / 3 * np.pi * 9)


def test_check_three_d_names_what_is_missing():
    _geometry.check_three_d(lattice("sc", (2, 2, 2)), "the DEM")
    with pytest.raises(SceneError, match=r"the DEM in 2D is not yet available"):
        _geometry.check_three_d(lattice("square", (2, 2)), "the DEM")
