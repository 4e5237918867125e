"""The parameter pytree (jaxbpm.physics.params): a sample's defaults, and the one check of every solver's params."""

import jax
import numpy as np
import pytest

import jaxbpm
from jaxbpm import SceneError
from jaxbpm.physics.params import check_params, default_params


def _two_materials():
    s = jaxbpm.generate.lattice("sc", (2, 2, 3))
    return jaxbpm.generate.mix_materials(s, [0.5, 0.5], seed=0, materials={"E": [1e9, 3e9], "nu": [0.2, 0.3]})


def test_defaults_are_the_sample_materials_once_moved():
    s = _two_materials()
    params = default_params(s)
    np.testing.assert_array_equal(params["bond_E"], s.materials.E)
    np.testing.assert_array_equal(params["bond_nu"], s.materials.nu)
    again = default_params(s)
    assert again is not params and again["bond_E"] is params["bond_E"]  # a new dict of the same device arrays


def test_check_params_moves_lists_and_names_what_is_wrong():
    s = _two_materials()
    out = check_params({"bond_E": [2e9, 4e9], "bond_nu": (0.25, 0.25)}, s)
    assert isinstance(out["bond_E"], jax.Array)
    np.testing.assert_array_equal(out["bond_E"], [2e9, 4e9])
    with pytest.raises(SceneError, match=r"must have shape \[2\]"):
        check_params({"bond_E": [2e9], "bond_nu": [0.2, 0.2]}, s)
    with pytest.raises(SceneError, match=r"bad entries \(material: value\) 1: 0.5"):
        check_params({"bond_E": [2e9, 2e9], "bond_nu": [0.2, 0.5]}, s)
    with pytest.raises(SceneError, match="did you mean 'friction'"):
        check_params({**default_params(s), "frictoin": 0.3}, s)
    with pytest.raises(SceneError, match="must be at least"):
        check_params({**default_params(s), "cohesion_initial": 2.0, "cohesion_max": 1.0}, s)
