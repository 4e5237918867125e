"""The base of the options classes (:mod:`jaxbpm._options`): checks at construction, names with a "did you mean",
hashing and equality with arrays and callables, pickling, the repr, the registry."""

import pickle

import numpy as np
import pytest

import jaxbpm
from jaxbpm._options import (
    choice, flag, fraction, optional, optional_path, option, options_class, positive, progress, resolve_options,
    SolverOptions, unit_interval, whole)
from jaxbpm.errors import OptionsError, SceneError


class Toy(SolverOptions):
    """Options of a solver that does not exist."""

    method = "toy"

    tol: float = option(1e-3, positive, doc="tolerance")
    steps: int | None = option(None, optional(whole))
    kind: str = option("a", choice("a", "b"))
    loud: bool = option(False, flag)
    share: float = option(0.5, fraction)
    volumes: object = option(None)
    callback: object = option(None, progress)


def test_fields_are_the_options_with_their_defaults():
    assert Toy.names() == ("callback", "kind", "loud", "share", "steps", "tol", "volumes")
    assert Toy.defaults() == {"tol": 1e-3, "steps": None, "kind": "a", "loud": False, "share": 0.5, "volumes": None,
                              "callback": None}
    t = Toy(tol=1e-6)
    assert t.tol == 1e-6 and t.steps is None and t.asdict()["tol"] == 1e-6 and t.changed() == {"tol": 1e-6}
    with pytest.raises(AttributeError):
        t.tol = 1.0  # frozen
    with pytest.raises(TypeError):
        Toy(1e-6)  # keywords only


@pytest.mark.parametrize("name, value, match", [
    ("tol", 0.0, "tol must be a positive number, got 0.0"), ("tol", True, "tol must be a positive number"),
    ("tol", float("nan"), "tol must be a positive"), ("steps", 0, r"steps must be a whole number >= 1, got 0"),
    ("steps", 2.0, "steps must be a whole number"), ("kind", "c", "kind must be 'a' or 'b', got 'c'"),
    ("loud", 1, "loud must be True or False, got 1"), ("share", 1.5, r"share must lie in \(0, 1\], got 1.5"),
    ("callback", "yes", "callback must be True, False"),
])
def test_a_bad_value_is_refused_naming_the_option(name, value, match):
    with pytest.raises(OptionsError, match=match):
        Toy(**{name: value})
    with pytest.raises(SceneError):  # what callers caught before
        Toy(**{name: value})


def test_the_checks_alone():
    unit_interval(False, False)("damping", 0.0)
    with pytest.raises(OptionsError, match=r"damping must lie in \[0, 1\), got 1"):
        unit_interval(False, False)("damping", 1)
    optional_path("record_to", "run.h5")
    with pytest.raises(OptionsError, match="record_to must be a file path"):
        optional_path("record_to", 3)
    with pytest.raises(OptionsError, match="dofs must be one of None, 3, 6, got 4"):
        choice(None, 3, 6)("dofs", 4)
    choice(None, 3, 6)("dofs", np.int64(3))


def test_a_misspelt_option_suggests_the_right_one():
    with pytest.raises(OptionsError, match=r"unknown TOY option 'tl'; did you mean 'tol'\? \(options: callback, "):
        Toy(tl=1e-3)
    with pytest.raises(OptionsError, match="did you mean 'steps'"):
        Toy(tol=1e-3).replace(stepz=3)
    with pytest.raises(OptionsError, match=r"unknown TOY option 'zzz' \(options"):
        Toy(zzz=1)


def test_equal_options_hash_equal_with_arrays_and_callables():
    def report(*args):
        return None

    a = Toy(volumes=np.ones(3), callback=report)
    b = Toy(volumes=np.ones(3), callback=report)
    assert a == b and hash(a) == hash(b) and len({a, b}) == 1
    assert a != Toy(volumes=np.ones(4), callback=report) and a != Toy(volumes=np.ones(3))
    assert Toy(tol=1e-3) == Toy() and hash(Toy(tol=1e-3)) == hash(Toy())  # a default given is the default
    assert a.replace(tol=1e-6) != a and a.replace(tol=1e-6).volumes is a.volumes


def test_pickle_and_repr():
    t = Toy(tol=1e-6, kind="b", volumes=np.arange(2.0))
    assert pickle.loads(pickle.dumps(t)) == t
    assert repr(Toy()) == "Toy()"
    assert repr(Toy(tol=1e-6, kind="b")) == "Toy(tol=1e-06, kind='b')"


def test_the_registry_knows_every_solver():
    assert options_class("dsm") is jaxbpm.DSM and options_class("ste") is jaxbpm.STE
    assert options_class("dem") is jaxbpm.DEM
    assert all(issubclass(options_class(m), SolverOptions) and options_class(m).method == m
               for m in ("dem", "dsm", "ste"))
    with pytest.raises(OptionsError, match="unknown method 'fem'"):
        options_class("fem")


def test_keywords_build_or_override_an_options_object():
    assert resolve_options("dsm", {"tol": 1e-6}) == jaxbpm.DSM(tol=1e-6)
    base = jaxbpm.DSM(dofs=3, tol=1e-4)
    assert resolve_options(base, {}) is base
    assert resolve_options(base, {"tol": 1e-6}) == jaxbpm.DSM(dofs=3, tol=1e-6)
    with pytest.raises(OptionsError, match="did you mean 'tol'"):
        resolve_options(base, {"tl": 1e-6})
    with pytest.raises(OptionsError, match="unknown method 3"):
        resolve_options(3, {})


def test_the_module_walkthrough_runs():
    import doctest

    from jaxbpm import _options

    assert doctest.testmod(_options).failed == 0
