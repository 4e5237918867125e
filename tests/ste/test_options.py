"""The STE's options (:mod:`jaxbpm.ste.options`): defaults, every option checked, the keyword shorthand."""

import warnings

import numpy as np
import pytest

import jaxbpm
from jaxbpm.errors import OptionsError
from jaxbpm.scenes import UniaxialCompression
from jaxbpm.ste.options import ESTIMATOR_OPTIONS, STE

DEFAULTS = dict(dofs=3, first_neighbour=False, layered=False, contacts=None, contact_fraction=None,
                layer_thickness=None, surface_depth=None, volumes=None, precision="float64", pad=True, throw=True,
                boundary="clamped")
BAD = dict(dofs=None, first_neighbour=1, layered="no", contacts=1.0, contact_fraction=0, layer_thickness=-1.0,
           surface_depth=-1.0, volumes=[1.0, -1.0], precision="float16", pad=None, throw=0, boundary="walls")


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


def test_clamp_layers_is_a_deprecated_alias_of_boundary():
    # the old spelling maps onto the new option: an equal object (one setup, one compiled program), a warning that
    # names the caller; not an option of its own
    for old, new in ((True, "clamped"), (False, "free")):
        with pytest.warns(DeprecationWarning, match=f"clamp_layers= is deprecated.*boundary='{new}'") as caught:
            a = STE(clamp_layers=old)
        assert caught[0].filename == __file__
        assert a == STE(boundary=new) and hash(a) == hash(STE(boundary=new)) and a.boundary == new
        with pytest.warns(DeprecationWarning):
            assert STE(boundary="free").replace(clamp_layers=old).boundary == new  # where given, it decides
        with pytest.warns(DeprecationWarning):
            assert jaxbpm.solving.resolve_options("ste", {"clamp_layers": old}) == STE(boundary=new)
    assert "clamp_layers" not in STE.names() and repr(STE(boundary="free")) == "STE(boundary='free')"
    with pytest.raises(OptionsError, match="^clamp_layers must be True or False"):
        STE(clamp_layers=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        STE(boundary="free")  # the new name warns nothing
    with pytest.raises(OptionsError, match="the scene's own boundary, layers or walls, is set on the scene"):
        STE(boundary="layers")
