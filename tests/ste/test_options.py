"""The STE's options (:mod:`jaxbpm.ste.options`): defaults, every option checked, the keyword shorthand."""

import numpy as np
import pytest

import jaxbpm
from jaxbpm.errors import OptionsError
from jaxbpm.scenes import UniaxialCompression
from jaxbpm.ste.options import ESTIMATOR_OPTIONS, STE

DEFAULTS = dict(dofs=3, first_neighbour=False, layered=False, contacts=None, contact_fraction=None,
                layer_thickness=None, surface_depth=None, volumes=None, precision="float64", pad=True, throw=True,
                clamp_layers=False)
BAD = dict(dofs=None, first_neighbour=1, layered="no", contacts=1.0, contact_fraction=0, layer_thickness=-1.0,
           surface_depth=-1.0, volumes=[1.0, -1.0], precision="float16", pad=None, throw=0, clamp_layers="yes")


def test_the_defaults():
    assert STE.defaults() == DEFAULTS and jaxbpm.STE is STE and STE.method == "ste"
    assert set(ESTIMATOR_OPTIONS) < set(STE.names())


@pytest.mark.parametrize("name", sorted(BAD))
def test_every_option_refuses_a_bad_value_naming_it(name):
    assert set(BAD) == set(STE.names())
    with pytest.raises(OptionsError, match=f"^{name} must"):
        STE(**{name: BAD[name]})


def test_every_option_is_documented_on_the_class():
    for name in STE.names():
        assert f"\n      {name}: " in STE.__doc__, name


def test_options_with_arrays_are_hashable_and_equal_options_compile_nothing():
    lattice = jaxbpm.generate.lattice("sc", (3, 3, 4), 1e-3, bond_radius_ratio=0.5,
                                      materials={"E": 1e9, "nu": 0.25})
    scene = UniaxialCompression(strain=0.002)
    volumes = np.full(lattice.n_particles, 8e-9)
    a = STE(volumes=volumes, surface_depth=0)
    assert a == STE(volumes=volumes.copy(), surface_depth=0) and hash(a) == hash(STE(volumes=volumes.copy(),
                                                                                     surface_depth=0))
    first = jaxbpm.solve(lattice, scene, a)
    keywords = jaxbpm.solve(lattice, scene, method="ste", volumes=volumes, surface_depth=0)
    assert first.stiffness == keywords.stiffness
    with jaxbpm.count_compilations() as c:
        again = jaxbpm.solve(lattice, scene, STE(volumes=volumes.copy(), surface_depth=0))
    assert c.count == 0 and again.stiffness == first.stiffness
    with pytest.raises(OptionsError, match="did you mean 'layered'"):
        jaxbpm.solve(lattice, scene, a, layerd=True)
