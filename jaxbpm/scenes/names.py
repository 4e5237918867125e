"""Scenes given by name: ``jaxbpm.solve(sample, "ucs", "dem")``.

=====================  ========================================================================
name                   scene
=====================  ========================================================================
``"uniaxial"``         ``UniaxialCompression()``: the elastic range (every solver)
``"ucs"``              ``UniaxialCompression.to_failure()``: past the peak, the compressive strength (DEM)
``"bts"``, ``"brazilian"``  ``BrazilianDisc()``: the Brazilian tensile strength (DEM)
``"tpb"``, ``"bending"``, ``"flexural"``  ``ThreePointBending()``: beam modulus, flexural strength (DEM, DSM)
=====================  ========================================================================

Names are read case-insensitively; any other name is a :class:`~jaxbpm.errors.SceneError` listing these.
"""

from __future__ import annotations

from jaxbpm.errors import SceneError
from jaxbpm.scenes.bending import ThreePointBending
from jaxbpm.scenes.brazilian import BrazilianDisc
from jaxbpm.scenes.uniaxial import UniaxialCompression

__all__ = ["SCENE_NAMES", "scene_from_name"]

SCENE_NAMES = {"uniaxial": UniaxialCompression, "ucs": UniaxialCompression.to_failure, "bts": BrazilianDisc,
               "brazilian": BrazilianDisc, "tpb": ThreePointBending, "bending": ThreePointBending,
               "flexural": ThreePointBending}


def scene_from_name(name: str):
    """The scene a name stands for, with its defaults (see the table of :mod:`jaxbpm.scenes.names`).

    Args:
      name: one of :data:`SCENE_NAMES` (any case).

    Returns:
      A new scene.

    Raises:
      SceneError: an unknown name (the message lists the known ones).
    """
    make = SCENE_NAMES.get(str(name).strip().lower())
    if make is None:
        known = ", ".join(repr(k) for k in SCENE_NAMES)
        raise SceneError(f"unknown scene name {name!r}: give one of {known} or a scene object "
                         "(jaxbpm.scenes.UniaxialCompression, ThreePointBending, BrazilianDisc)")
    return make()
