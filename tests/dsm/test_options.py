"""The DSM's options (:mod:`jaxbpm.dsm.options`): defaults, every option checked, the keyword shorthand."""

import numpy as np
import pytest

import jaxbpm
from jaxbpm.dsm.options import DSM
from jaxbpm.errors import OptionsError
from jaxbpm.scenes import UniaxialCompression

DEFAULTS = dict(dofs=None, nonlinear=None, tol=None, linear_tol=1e-6, maxiter=None, newton_maxiter=30,
                stiffness_tol="auto", contact_skin=None, load_steps=4, throw=True, operator="auto",
                preconditioner="auto", aggregate_size=None, slip=True, contact_fraction=None, contact_passes=2,
                pad=True, geometric_correction=False)
BAD = dict(dofs=4, nonlinear=1, tol=-1.0, linear_tol=None, maxiter=0, newton_maxiter=2.5, stiffness_tol="Auto",
           contact_skin=0.0, load_steps=0, throw="yes", operator="dense", preconditioner="ilu", aggregate_size=np.nan,
           slip=None, contact_fraction=1.5, contact_passes=None, pad=1, geometric_correction=None)


def test_the_defaults():
    assert DSM.defaults() == DEFAULTS and DSM().asdict() == DEFAULTS and jaxbpm.DSM is DSM
    assert DSM.method == "dsm"


@pytest.mark.parametrize("name", sorted(BAD))
def test_every_option_refuses_a_bad_value_naming_it(name):
    assert set(BAD) == set(DSM.names())
    with pytest.raises(OptionsError, match=f"^{name} must"):
        DSM(**{name: BAD[name]})


def test_every_option_is_documented_on_the_class():
    for name in DSM.names():
        assert f"\n      {name}: " in DSM.__doc__, name


def test_a_misspelt_option_suggests_the_right_one():
    with pytest.raises(OptionsError, match="did you mean 'stiffness_tol'"):
        DSM(stifness_tol=1e-3)
    box = jaxbpm.generate.lattice("sc", (2, 2, 3), 1e-3, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})
    with jaxbpm.count_compilations() as c, pytest.raises(OptionsError, match="did you mean 'linear_tol'"):
        jaxbpm.solve(box, UniaxialCompression(strain=0.002), method="dsm", linear_tl=1e-8)
    assert c.count == 0


def test_keywords_override_the_object_and_equal_options_compile_nothing():
    box = jaxbpm.generate.lattice("sc", (3, 3, 4), 1e-3, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})
    scene = UniaxialCompression(strain=0.002)
    a = jaxbpm.solve(box, scene, DSM(dofs=6, linear_tol=1e-4), linear_tol=1e-10, stiffness_tol=None)
    b = jaxbpm.solve(box, scene, method="dsm", dofs=6, linear_tol=1e-10, stiffness_tol=None)
    assert a.stiffness == b.stiffness and a.stats["residual"] <= 1e-10
    with jaxbpm.count_compilations() as c:
        again = jaxbpm.solve(box, scene, DSM(dofs=6, linear_tol=1e-10, stiffness_tol=None))
    assert c.count == 0 and again.stiffness == a.stiffness
