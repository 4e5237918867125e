"""The checks of a sample's input arrays (jaxbpm._validate), one per input: what each accepts, returns and says."""

import numpy as np
import pytest

from jaxbpm import _validate as v
from jaxbpm.errors import SampleError


def test_listed_shows_at_most_ten():
    assert v.listed([3, 1]) == "[3, 1]"
    assert v.listed(np.arange(25)) == f"{list(range(10))} ... (25 in all)"


def test_arrays_and_finite():
    assert v.float_array("x", [1, 2]).dtype == np.float64
    with pytest.raises(SampleError, match=r"^x must be an array of numbers, got \[\[1\], \[1, 2\]\]"):
        v.array("x", [[1], [1, 2]])
    with pytest.raises(SampleError, match=r"^x must be a real numeric array, got dtype <U1$"):
        v.float_array("x", ["a"])
    with pytest.raises(SampleError, match=r"^x contains NaN values at indices \[1, 3\]$"):
        v.finite("x", np.array([[0.0, 1], [np.nan, 0], [0, 0], [0, np.nan]]))
    with pytest.raises(SampleError, match=r"^x contains inf values at indices \[0\]$"):
        v.finite("x", np.array(np.inf))


def test_positions_and_radii():
    pos = v.checked_positions([[0, 0, 0], [1, 0, 0]])
    assert pos.dtype == np.float64 and pos.shape == (2, 3)
    for bad, match in (([[0, 0, 0, 0]], r"shape \[n, 3\] \(spheres\) or \[n, 2\].*got \(1, 4\)"),
                       (np.zeros((0, 3)), "has no particles")):
        with pytest.raises(SampleError, match=match):
            v.checked_positions(bad)
    assert np.array_equal(v.checked_radii(0.5, 3), [0.5, 0.5, 0.5])
    with pytest.raises(SampleError, match=r"^radii must be > 0; non-positive radius at particles \[1\]$"):
        v.checked_radii([1.0, 0.0], 2)
    with pytest.raises(SampleError, match=r"bad radius 1e\+70 m at particles \[0\]$"):
        v.checked_radii([1e70], 1)


def test_bonds_sorted_and_checked():
    b = v.checked_bonds([[2, 1], [0, 3.0]], 4)
    assert b.dtype == np.int32 and np.array_equal(b, [[1, 2], [0, 3]])  # each pair sorted, their order kept
    assert v.checked_bonds([], 4).shape == (0, 2)
    cases = [([[0, 4]], r"missing particles \(valid indices are 0\.\.3\); bad bonds \[0\], e\.g\. bond 0 = \[0, 4\]"),
             ([[1, 1]], r"^self-bonds \(a particle bonded to itself\) at bonds \[0\]$"),
             ([[0, 1], [2, 3], [1, 0]], r"duplicate bonds .* at bonds \[2\]; e\.g\. bond 2 repeats bond 0 = \[0, 1\]"),
             ([[0, 1.5]], r"^bonds must hold integer particle indices, got dtype float64$")]
    for bonds, match in cases:
        with pytest.raises(SampleError, match=match):
            v.checked_bonds(bonds, 4)


def test_bond_lengths_and_radii():
    pos = np.array([[0.0, 0, 0], [1.0, 0, 0], [1.0, 2.0, 0]])
    rad = np.full(3, 0.5)
    b = np.array([[0, 1], [1, 2]], np.int32)
    assert np.array_equal(v.bond_lengths(pos, rad, b), [1.0, 2.0])
    with pytest.raises(SampleError, match=r"^zero-length bonds \(coincident particles\) at bonds \[0\]$"):
        v.bond_lengths(np.zeros((2, 3)), rad[:2], b[:1])
    with pytest.raises(SampleError, match=r"bonds \[0\] are more than 1000 times"):
        v.bond_lengths(np.array([[0.0, 0, 0], [2e3, 0, 0]]), rad[:2], b[:1])
    with pytest.raises(SampleError, match=r"positions lie too far from the origin"):
        v.bond_lengths(np.array([[1e9, 0, 0], [1e9 + 1e-3, 0, 0]]), np.full(2, 5e-4), b[:1])
    assert np.array_equal(v.checked_bond_radius(None, 0.5, np.array([0.5, 0.2, 0.4]), b), [0.1, 0.1])
    assert np.array_equal(v.checked_bond_radius(0.3, None, rad, b), [0.3, 0.3])
    with pytest.raises(SampleError, match=r"^give exactly one of bond_radius and bond_radius_ratio$"):
        v.checked_bond_radius(0.3, 0.5, rad, b)
    with pytest.raises(SampleError, match=r"^bond_radius_ratio must be finite and > 0, got True$"):
        v.checked_bond_radius(None, True, rad, b)


def test_bond_material_against_the_table():
    assert np.array_equal(v.checked_bond_material(None, 3, 1), [0, 0, 0])
    assert np.array_equal(v.checked_bond_material(1, 2, 2), [1, 1])
    with pytest.raises(SampleError, match=r"table has 2 components, 0\.\.1\) at bonds \[1\], e\.g\. index 2$"):
        v.checked_bond_material([0, 2], 2, 2)
    with pytest.raises(SampleError, match=r"^bond_material must hold integer component indices, got dtype float64$"):
        v.checked_bond_material([0.0, 1.0], 2, 2)
