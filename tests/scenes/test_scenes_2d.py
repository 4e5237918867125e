"""The Brazilian disc and three-point bending of two-dimensional samples: the width is the discs' thickness, the
DEM's bending stiffness agrees with the DSM's, and the strengths follow their formulas with the 2D dimensions."""

import numpy as np
import pytest

import jaxbpm
from jaxbpm import SceneError
from jaxbpm.generate import disc_packing, lattice
from jaxbpm.scenes import BrazilianDisc, ThreePointBending

STRONG = {"E": 1e9, "tensile_strength": 2e6, "shear_strength": 4e6}


def test_brazilian_disc_in_2d_splits_in_tension():
    s = disc_packing(250, "disc", seed=2, thickness=0.2, materials=STRONG).largest_cluster()
    scene = BrazilianDisc(contacts=False)
    d, t = scene.dimensions(s)
    assert np.isclose(d, s.domain.hi[0] - s.domain.lo[0]) and t == 0.2
    r = jaxbpm.solve(s, scene, "dem")
    assert np.isclose(r.stats["strength"], 2 * r.stats["peak_force"] / (np.pi * d * t), rtol=1e-12)
    assert r.stats["broken_tensile"] > r.stats["broken_shear"] and r.stats["stop_reason"] == "after_peak"
    assert 0.02 * 2e6 < r.stats["strength"] < 2e6  # the disc splits below the bonds' own strength
    with pytest.raises(SceneError, match="x-y plane"):
        BrazilianDisc(axis=2, disc_axis=0, contacts=False).dimensions(s)


def test_three_point_bending_in_2d_dem_agrees_with_dsm():
    s = lattice("square", (25, 5), 1e-3, thickness=0.1, materials={"E": 1e9})
    scene = ThreePointBending(axis=1, span_axis=0, contacts=False, breakage=False, strain=0.01)
    span, b, h = scene.dimensions(s)
    assert b == 0.1 and np.isclose(h, 10e-3) and np.isclose(span, 0.8 * 50e-3)
    dsm = jaxbpm.solve(s, scene, "dsm")
    dem = jaxbpm.solve(s, scene, "dem", transits=250)
    assert abs(dem.stiffness / dsm.stiffness - 1) < 0.015
    with pytest.raises(SceneError, match="x-y plane"):
        ThreePointBending(contacts=False).dimensions(s)


def test_three_point_bending_strength_formula_in_2d():
    s = lattice("square", (25, 5), 1e-3, materials=STRONG)
    scene = ThreePointBending(axis=1, span_axis=0, contacts=False)
    r = jaxbpm.solve(s, scene, "dem", throw=False)
    span, b, h = scene.dimensions(s)
    assert np.isclose(r.stats["strength"], 3 * r.stats["peak_force"] * span / (2 * b * h**2), rtol=1e-12)
    assert r.stats["broken_tensile"] > 0
