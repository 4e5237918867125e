"""Scenes given by name (:mod:`jaxbpm.scenes.names`)."""

import pytest

from jaxbpm.errors import SceneError
from jaxbpm.scenes import BrazilianDisc, ThreePointBending, UniaxialCompression, scene_from_name
from jaxbpm.scenes.names import SCENE_NAMES


def test_each_name_gives_its_scene_with_the_defaults():
    expected = {"uniaxial": UniaxialCompression(), "ucs": UniaxialCompression.to_failure(),
                "bts": BrazilianDisc(), "brazilian": BrazilianDisc(), "tpb": ThreePointBending(),
                "bending": ThreePointBending(), "flexural": ThreePointBending()}
    assert set(expected) == set(SCENE_NAMES)
    for name, scene in expected.items():
        for spelled in (name, name.upper(), f" {name} "):
            got = scene_from_name(spelled)
            assert type(got) is type(scene) and got == scene, spelled
    ucs = scene_from_name("ucs")
    assert ucs.breakage is True and ucs.contacts and scene_from_name("uniaxial").breakage is not True


@pytest.mark.parametrize("name", ["UCS2", "compression", "", "dem"])
def test_an_unknown_name_lists_the_known_ones(name):
    with pytest.raises(SceneError, match=r"unknown scene name .*'ucs'.*'bts'.*'tpb'"):
        scene_from_name(name)
