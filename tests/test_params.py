"""One validation path for every solver's ``params``: the same named errors from the DEM, the DSM and the STE, before
anything is compiled, and the README's list form accepted."""

import numpy as np
import pytest

import jaxbpm
from jaxbpm import SceneError
from jaxbpm.scenes import UniaxialCompression

SCENE = UniaxialCompression(strain=0.002)


@pytest.fixture(scope="module")
def lattice():
    return jaxbpm.generate.lattice("fcc", (2, 2, 3), 1e-3, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})


BAD = [
    ({"bond_E": [0.0], "bond_nu": [0.25]}, r"bond_E.*> 0.*0: 0"),
    ({"bond_E": [-1e9], "bond_nu": [0.25]}, r"bond_E.*> 0.*0: -1e\+09"),
    ({"bond_E": [float("nan")], "bond_nu": [0.25]}, r"bond_E.*finite.*0: nan"),
    ({"bond_E": [1e9], "bond_nu": [0.7]}, r"bond_nu.*\(-1, 0\.5\).*0: 0\.7"),
    ({"bond_E": [1e9], "bond_nu": [-1.0]}, r"bond_nu.*\(-1, 0\.5\)"),
    ({"bond_E": [1e9, 2e9], "bond_nu": [0.25]}, r"bond_E.*shape \[1\].*\(2,\)"),
    ({"bond_E": 1e9, "bond_nu": [0.25]}, r"bond_E.*shape \[1\].*\(\)"),
    ({"bond_E": [], "bond_nu": [0.25]}, r"bond_E.*shape \[1\]"),
    ({"bond_E": ["abc"], "bond_nu": [0.25]}, r"bond_E.*numbers"),
    ({"bond_E": [1e9]}, r"'bond_E' and 'bond_nu'.*\['bond_E'\]"),
    ([1e9, 0.25], r"'bond_E' and 'bond_nu'.*list"),
    ({"bond_E": [1e9], "bond_nu": [0.25], "bond_tensile_strength": [-1.0]}, r"bond_tensile_strength.*>= 0"),
    ({"bond_E": [1e9], "bond_nu": [0.25], "bond_shear_strength": [float("nan")]}, r"bond_shear_strength.*>= 0"),
    ({"bond_E": [1e9], "bond_nu": [0.25], "bond_e": [1e9]}, r"unknown key 'bond_e'; did you mean 'bond_E'"),
    ({"bond_E": [1e9], "bond_nu": [0.25], "bond_friction_angle": [2.0]}, r"bond_friction_angle.*\[0, pi/2\).*0: 2"),
    ({"bond_E": [1e9], "bond_nu": [0.25], "friction": -0.1}, r"'friction'.*scalar, finite and >= 0; got -0\.1"),
    ({"bond_E": [1e9], "bond_nu": [0.25], "cohesion_initial": 2e6, "cohesion_max": 1e6},
     r"cohesion_max.*at least.*cohesion_initial"),
    ({"bond_E": [1e9 + 1j], "bond_nu": [0.25]}, r"bond_E.*real numbers"),
    ({"bond_E": [True], "bond_nu": [0.25]}, r"bond_E.*real numbers"),
]


@pytest.mark.parametrize("method", ["dem", "dsm", "ste"])
def test_bad_params_are_named_by_every_method(lattice, method):
    with jaxbpm.count_compilations() as c:
        for params, match in BAD:
            with pytest.raises(SceneError, match=match):
                jaxbpm.solve(lattice, SCENE, method, params=params)
    assert c.count == 0  # refused before anything is built


def test_the_list_form_gives_the_array_answer(lattice):
    arrays = jaxbpm.solve(lattice, SCENE, "dsm", params={"bond_E": np.array([2e9]), "bond_nu": np.array([0.3])})
    lists = jaxbpm.solve(lattice, SCENE, "dsm", params={"bond_E": [2e9], "bond_nu": [0.3]})
    assert lists.stiffness == arrays.stiffness
    ste = jaxbpm.solve(lattice, SCENE, "ste", params={"bond_E": (2e9,), "bond_nu": (0.3,)})
    assert np.isfinite(ste.stiffness) and ste.status == "converged"


@pytest.mark.parametrize("options, match", [
    (dict(damping=-1.0), r"damping must lie in \[0, 1\), got -1"),
    (dict(damping=5), r"damping must lie in \[0, 1\), got 5"),
    (dict(chunk=0), r"chunk must be a whole number >= 1, got 0"),
    (dict(transits=0), r"transits must be a positive number, got 0"),
    (dict(dampnig=0.5), r"unknown.*'dampnig'.*did you mean.*'damping'"),
])
def test_bad_dem_options_are_named_before_anything_runs(lattice, options, match):
    """A negative damping gave a negative stiffness, chunk=0 a ZeroDivisionError and a misspelt option a TypeError
    naming private functions: each is now refused up front, naming the option."""
    with jaxbpm.count_compilations() as c, pytest.raises(SceneError, match=match):
        jaxbpm.solve(lattice, SCENE, "dem", **options)
    assert c.count == 0
