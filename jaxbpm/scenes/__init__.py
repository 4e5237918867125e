"""Scenes: a lab test = boundary conditions + loading + observables, applied to a sample."""

from jaxbpm.scenes.uniaxial import (
    BrazilianDisc, ThreePointBending, UniaxialCompression, _build_model, _check_failure_rule, _is_axis, _loading,
    lateral_stats, sample_breaks)

__all__ = ["UniaxialCompression", "ThreePointBending", "BrazilianDisc", "sample_breaks", "lateral_stats"]
