"""Scenes: a lab test = boundary conditions + loading + observables, applied to a sample.

A scene tells the solvers what to clamp or press, how far, and how to read the force-displacement curve:
:class:`Scene` (in :mod:`jaxbpm.scenes.base`) is the protocol every solver relies on; any class with its members is a
scene. The scenes of the package:

* :class:`UniaxialCompression` (:mod:`~jaxbpm.scenes.uniaxial`): squeezed along one axis between clamped layers or
  plane walls; stiffness, Young's modulus E = K l / A, Poisson ratio, compressive strength. Every solver.
* :class:`ThreePointBending` (:mod:`~jaxbpm.scenes.bending`): a beam on two supports under a punch; beam modulus and
  flexural strength. DEM and DSM.
* :class:`BrazilianDisc` (:mod:`~jaxbpm.scenes.brazilian`): a disc squeezed across a diameter; Brazilian tensile
  strength. DEM only.

A scene may also be given by name (:mod:`~jaxbpm.scenes.names`: ``"uniaxial"``, ``"ucs"``, ``"bts"``, ``"tpb"``).
Each scene's clamped groups take a mask, particle indices, a type, a region or a layer (:mod:`~jaxbpm.scenes.groups`:
:class:`Ids`, :class:`Type`, :class:`Region`, :class:`Layer`).
"""

from jaxbpm.scenes.base import (
    METHODS, AxialScene, BaseScene, Scene, _build_model, _check_failure_rule, _is_axis, _loading, force_weights,
    lateral_stats, sample_breaks)
from jaxbpm.scenes.bending import ThreePointBending
from jaxbpm.scenes.groups import Group, Ids, Layer, Region, Type
from jaxbpm.scenes.brazilian import BrazilianDisc
from jaxbpm.scenes.uniaxial import UniaxialCompression
from jaxbpm.scenes.names import SCENE_NAMES, scene_from_name

__all__ = ["UniaxialCompression", "ThreePointBending", "BrazilianDisc", "Scene", "BaseScene", "AxialScene", "METHODS",
           "sample_breaks", "lateral_stats", "force_weights", "Group", "Ids", "Type", "Region", "Layer",
           "SCENE_NAMES", "scene_from_name"]
