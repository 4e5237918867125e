"""The DEM's options (:mod:`jaxbpm.dem.options`): defaults, every option checked, the keyword shorthand."""

import numpy as np
import pytest

import jaxbpm
from jaxbpm.dem import NeighborSettings
from jaxbpm.dem.options import DEM
from jaxbpm.errors import OptionsError
from jaxbpm.scenes import UniaxialCompression

DEFAULTS = dict(dt=None, safety=0.5, damping=0.7, loading_time=None, transits=40.0, chunk=None, progress=False,
                neighbors=None, max_records=2000, record_to=None, snapshots=None, vtu=None, pad=True, throw=True,
                overwrite=False, resume=None, start="rest", start_safety=0.9)
BAD = dict(dt=-1e-7, safety=0.0, damping=1.0, loading_time=np.inf, transits=0, chunk=0, progress="yes",
           neighbors=0.5, max_records=2.5, record_to=3, snapshots=0, vtu=1.0, pad=1, throw=None, overwrite="no",
           resume=7, start="elastc", start_safety=0.0)


def test_the_defaults():
    assert DEM.defaults() == DEFAULTS and DEM().asdict() == DEFAULTS and jaxbpm.DEM is DEM
    assert DEM.method == "dem"
    assert DEM(damping=0.0, neighbors=NeighborSettings(skin=1e-4)).damping == 0.0  # undamped is allowed


@pytest.mark.parametrize("name", sorted(BAD))
def test_every_option_refuses_a_bad_value_naming_it(name):
    assert set(BAD) == set(DEM.names())
    with pytest.raises(OptionsError, match=f"^{name} must"):
        DEM(**{name: BAD[name]})


def test_every_option_is_documented_on_the_class():
    for name in DEM.names():
        assert f"\n      {name}: " in DEM.__doc__, name


def test_a_misspelt_option_suggests_the_right_one():
    with pytest.raises(OptionsError, match="did you mean 'damping'"):
        DEM(dampng=0.5)
    box = jaxbpm.generate.lattice("sc", (2, 2, 3), 1e-3, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})
    with jaxbpm.count_compilations() as c, pytest.raises(OptionsError, match="did you mean 'transits'"):
        jaxbpm.solve(box, UniaxialCompression(strain=0.002), method="dem", transit=5)
    assert c.count == 0


def test_keywords_override_the_object():
    box = jaxbpm.generate.lattice("sc", (2, 2, 3), 1e-3, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})
    scene = UniaxialCompression(strain=0.002)
    a = jaxbpm.solve(box, scene, DEM(transits=40, damping=0.5), transits=5)
    b = jaxbpm.solve(box, scene, method="dem", transits=5, damping=0.5)
    assert a.stiffness == b.stiffness and a.stats["damping"] == 0.5 and a.stats["steps"] == b.stats["steps"]
