"""The one entry point (:mod:`jaxbpm.solving`): the solver from a name or an options object, checks made once, before
anything is built."""

import numpy as np
import pytest

import jaxbpm
from jaxbpm import auto, solving
from jaxbpm.errors import OptionsError, SceneError
from jaxbpm.physics import model as physics_model
from jaxbpm.scenes import UniaxialCompression

SCENE = UniaxialCompression(strain=0.002)


@pytest.fixture(scope="module")
def lattice():
    return jaxbpm.generate.lattice("sc", (3, 3, 4), 1e-3, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})


def test_a_name_and_an_object_are_the_same_solve(lattice):
    for name, cls in (("dsm", jaxbpm.DSM), ("ste", jaxbpm.STE)):
        by_name = jaxbpm.solve(lattice, SCENE, method=name, dofs=3)
        by_object = jaxbpm.solve(lattice, SCENE, cls(dofs=3))
        assert by_name.method == name and by_name.stiffness == by_object.stiffness


@pytest.mark.parametrize("method", ["dsm", "ste", "auto"])
def test_the_parameters_are_checked_once_per_solve(lattice, method, monkeypatch):
    calls = []
    check = physics_model.check_params

    def counted(params, sample):
        calls.append(1)
        return check(params, sample)

    for module in (solving, auto, physics_model):
        monkeypatch.setattr(module, "check_params", counted)
    res = jaxbpm.solve(lattice, SCENE, method, params={"bond_E": [2e9], "bond_nu": [0.3]})
    assert len(calls) == 1 and res.status == "converged"


def test_refusals_come_before_anything_is_built(lattice):
    with jaxbpm.count_compilations() as c:
        with pytest.raises(OptionsError, match="unknown method 'fem'"):
            jaxbpm.solve(lattice, SCENE, "fem")
        with pytest.raises(OptionsError, match="did you mean 'tol'"):
            jaxbpm.solve(lattice, SCENE, "dsm", tl=1e-3)
        with pytest.raises(TypeError, match="jaxbpm.Sample"):
            jaxbpm.solve("sample.h5", SCENE, "ste")
        with pytest.raises(SceneError, match="method='auto' takes only"):
            jaxbpm.solve(lattice, SCENE, "auto", dofs=3)
        with pytest.raises(SceneError, match="bond_E"):
            jaxbpm.solve(lattice, SCENE, "dsm", params={"bond_E": [-1.0], "bond_nu": [0.3]})
        cohesive = UniaxialCompression(strain=0.002, contacts=True, contact_law="cohesive")
        with pytest.raises(SceneError, match="cohesive contact law"):
            jaxbpm.solve(lattice, cohesive, "ste")
    assert c.count == 0


def test_a_scene_states_the_solvers_that_model_it(lattice):
    disc = jaxbpm.scenes.BrazilianDisc()
    assert disc.methods == ("dem",)
    with jaxbpm.count_compilations() as c:
        for method in ("dsm", "ste"):
            with pytest.raises(SceneError, match=f"BrazilianDisc needs method='dem'.*the {method.upper()} does not"):
                jaxbpm.solve(lattice, disc, method)
    assert c.count == 0


def test_methods_lists_every_solver():
    assert solving.METHODS == ("dem", "dsm", "ste")
    assert np.all([jaxbpm.solve.__doc__.count(c) for c in ("jaxbpm.DEM", "jaxbpm.DSM", "jaxbpm.STE")])


def test_a_scene_by_name(lattice):
    """``solve(S, "ucs", "dsm")`` raised ``AttributeError: 'str' object has no attribute 'contacts'``."""
    by_name = jaxbpm.solve(lattice, "uniaxial", "dsm")
    assert by_name.stiffness == jaxbpm.solve(lattice, UniaxialCompression(), "dsm").stiffness
    with pytest.raises(SceneError, match="unknown scene name 'ucss'.*'ucs'"):
        jaxbpm.solve(lattice, "ucss", "dsm")
    with pytest.raises(SceneError, match="unknown scene name"):
        jaxbpm.solve(lattice, "nope", "auto")
    with pytest.raises(SceneError, match="needs method='dem'"):  # the Brazilian test: the DEM only
        jaxbpm.solve(lattice, "bts", "ste")


@pytest.mark.parametrize("method", ["dsm", "ste"])
def test_a_static_solver_refuses_a_failure_scene_at_once(lattice, method, monkeypatch):
    """``solve(S, UniaxialCompression.to_failure(), "dsm")`` ran 40 s, then said "too few records in fit_range"."""
    from jaxbpm import dsm, ste

    def must_not_run(*args, **kwargs):
        raise AssertionError("the solver ran")

    monkeypatch.setattr(dsm, "solve_scene", must_not_run)
    monkeypatch.setattr(ste, "solve_scene", must_not_run)
    for scene in ("ucs", UniaxialCompression.to_failure(), UniaxialCompression(strain=0.002, breakage=True)):
        with pytest.raises(SceneError, match=rf"the {method.upper()} gives the elastic range only.*method='dem' "
                                             "gives the strength"):
            jaxbpm.solve(lattice, scene, method)


@pytest.mark.parametrize("scene,method", [(jaxbpm.scenes.UniaxialCompression.to_failure(axis=1), "dem"),
                                          (jaxbpm.scenes.UniaxialCompression(axis=1, boundary="walls"), "dsm")])
def test_a_two_dimensional_sample_is_refused_where_no_solver_models_it(scene, method):
    flat = jaxbpm.generate.lattice("square", (4, 4))
    with pytest.raises(SceneError, match="not (yet )?available"):
        jaxbpm.solve(flat, scene, method)
    with pytest.raises(SceneError, match="start='elastic'"):
        jaxbpm.solve(flat, jaxbpm.scenes.UniaxialCompression(axis=1), "dem", start="elastic")
