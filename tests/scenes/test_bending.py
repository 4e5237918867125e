"""The three-point bending scene: flexural strength, beam geometry and bad input."""

import dataclasses

import numpy as np
import pytest

import jaxbpm
from jaxbpm import SceneError
from jaxbpm.scenes import ThreePointBending

# one worker for the whole module under pytest-xdist (loadgroup): its specimen (a module fixture) is built once
pytestmark = pytest.mark.xdist_group("bending")


def _with_strengths(sample, tensile, shear):
    m = dataclasses.replace(sample.materials, tensile_strength=np.array([tensile]), shear_strength=np.array([shear]))
    return sample.replace(materials=m)


@pytest.fixture(scope="module")
def beam():
    materials = {"E": 1e9, "nu": 0.25, "tensile_strength": 5e6, "shear_strength": 1e7}
    return jaxbpm.generate.beam(300, seed=1, packing_fraction=0.52, materials=materials).largest_cluster()


def test_flexural_strength_grows_with_the_tensile_strength(beam):
    scene = ThreePointBending(strain=0.1)
    low = jaxbpm.solve(_with_strengths(beam, 2e6, 1e7), scene, "dem", transits=30)
    high = jaxbpm.solve(_with_strengths(beam, 6e6, 1e7), scene, "dem", transits=30)
    ratio = high.stats["strength"] / low.stats["strength"]
    assert 1.8 < ratio < 3.6, ratio  # nearly proportional (Qu et al. 2020 observes a near-linear relation)
    assert low.stats["past_peak"] and low.stats["broken_tensile"] > low.stats["broken_shear"]
    span, b, h = scene.dimensions(beam)
    np.testing.assert_allclose(low.stats["strength"], 3 * low.stats["peak_force"] * span / (2 * b * h**2))


def test_bending_scene_errors_are_named(beam):
    with pytest.raises(SceneError, match="span"):
        ThreePointBending(span=1.0).dimensions(beam)
    with pytest.raises(SceneError, match="axis"):
        ThreePointBending(axis=0, span_axis=0)
    with pytest.raises(SceneError, match="punch"):
        ThreePointBending(punch_width=1e-9).layers(beam)
