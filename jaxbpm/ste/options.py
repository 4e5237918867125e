"""The STE's options, :class:`STE` (``jaxbpm.STE``): what ``jaxbpm.solve(..., method="ste")`` and
:func:`jaxbpm.ste.solve_scene` take."""

from __future__ import annotations

import numbers
import os
import sys
import warnings

import numpy as np

from jaxbpm._options import choice, flag, fraction, optional, option, positive, shown, SolverOptions
from jaxbpm.errors import OptionsError

__all__ = ["STE", "ESTIMATOR_OPTIONS", "BOUNDARIES", "boundary_keyword"]

#: the STE's boundary forms: ``"clamped"`` (the scene's clamped particles follow the affine field and bound the
#: sample along the load; the default) and ``"free"`` (every surface free, the paper's form)
BOUNDARIES = ("clamped", "free")
_PACKAGE = os.path.dirname(os.path.dirname(os.path.abspath(__file__))) + os.sep


def _boundary(name, v):
    if not (isinstance(v, str) and v in BOUNDARIES):
        raise OptionsError(f"{name} must be 'clamped' or 'free', got {shown(v)} (the scene's own boundary, layers or "
                           "walls, is set on the scene)")


def boundary_keyword(boundary, clamp_layers):
    """The STE's boundary form, given as ``boundary=`` or its deprecated spelling ``clamp_layers=``.

    Args:
      boundary: the value given as ``boundary`` (``"clamped"`` or ``"free"``).
      clamp_layers: the value given as ``clamp_layers`` (``None``: not given; ``True``: ``"clamped"``, ``False``:
        ``"free"``). Where given it decides (a :class:`DeprecationWarning` names ``boundary=``).

    Returns:
      ``"clamped"`` or ``"free"``.

    Raises:
      OptionsError: a value that is neither.
    """
    _boundary("boundary", boundary)
    if clamp_layers is None:
        return boundary
    flag("clamp_layers", clamp_layers)
    new = "clamped" if clamp_layers else "free"
    # the warning names the first caller outside jaxbpm (solve(..., clamp_layers=...) passes through several frames)
    level, frame = 1, sys._getframe(0)
    while frame is not None and frame.f_code.co_filename.startswith(_PACKAGE):
        frame, level = frame.f_back, level + 1
    warnings.warn(f"clamp_layers= is deprecated and will be removed in the next release; use boundary={new!r} "
                  f"(clamp_layers={clamp_layers} is boundary={new!r})", DeprecationWarning, stacklevel=level)
    return new


def _surface_depth(name, v):
    if v is None or (isinstance(v, numbers.Real) and not isinstance(v, bool) and v == 0):
        return
    positive(name, v)


def _volumes(name, v):
    if v is None:
        return
    try:
        arr = np.asarray(v)
        ok = arr.dtype != bool and (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer))
        ok = ok and arr.ndim == 1 and bool(np.all(np.isfinite(arr) & (arr > 0)))
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise OptionsError(f"{name} must be [n] finite positive particle volumes [m^3], got {shown(v)}")


class STE(SolverOptions):
    """Options of the stiffness tensor estimation (no displacement computed; see :mod:`jaxbpm.ste`).

    Attributes:
      dofs: 3 (the paper's translations-only form) or 6 per particle.
      first_neighbour: the first-neighbour-only form (Eq. 33-35) instead of Eq. 32.
      layered: layered springs in series along the load (porous or shaped bodies).
      contacts: linearise contacts (``None``: the scene's ``contacts``).
      contact_fraction: the fraction of the target strain at which Hertz contacts are linearised (``None``: the
        middle of the scene's fit range).
      layer_thickness: the layered model's layer thickness [m] (``None``: two mean particle diameters).
      surface_depth: particles closer than this to the sample's free surface [m] are left out of the averages
        (``None``: one mean particle diameter; 0 keeps every non-singular particle that is not clamped). The free
        surface: the faces parallel to the load with ``boundary="clamped"``, every face with ``"free"``.
      volumes: ``[n]`` particle volumes V^n [m^3] (``None``: particle volume / global solid fraction).
      precision: ``"float64"``, or ``"float32"``: faster, ~1e-7 relative change (calibrate with float64).
      pad: the estimator is padded to the sample's size class and kept for the last few samples, so that samples
        of similar size share one compiled program (the same result to round-off).
      throw: raise :class:`~jaxbpm.errors.NotFiniteError` when the stiffness is not finite (``False``: return the
        result with ``status="not_finite"``).
      boundary: ``"clamped"`` (default): the particles the scene clamps (boundary ``"layers"`` or
        ``fixed``/``driven`` masks) follow the affine field, as their prescribed displacements do in the DEM and
        the DSM, and bound the sample along the load: they are left out of the averages, and ``surface_depth``
        counts from the free faces only (those parallel to the load). ``"free"``: the paper's form, every
        particle relaxes and ``surface_depth`` counts from every face. A scene with walls clamps no particle: it
        always gets the free form (``stats["boundary"]`` says which form ran). See :func:`jaxbpm.ste.estimator`.
        ``clamp_layers=True`` / ``False``, its deprecated spelling, is ``"clamped"`` / ``"free"`` (and decides where
        both are given).
    """

    method = "ste"

    dofs: int = option(3, choice(3, 6))
    first_neighbour: bool = option(False, flag)
    layered: bool = option(False, flag)
    contacts: bool | None = option(None, optional(flag))
    contact_fraction: float | None = option(None, optional(fraction))
    layer_thickness: float | None = option(None, optional(positive))
    surface_depth: float | None = option(None, _surface_depth)
    volumes: object = option(None, _volumes)
    precision: str = option("float64", choice("float64", "float32"))
    pad: bool = option(True, flag)
    throw: bool = option(True, flag)
    boundary: str = option("clamped", _boundary)

    @classmethod
    def _renamed(cls, options: dict) -> dict:
        """``clamp_layers=`` (deprecated) as ``boundary=``."""
        if "clamp_layers" not in options:
            return options
        options = dict(options)
        options["boundary"] = boundary_keyword(options.get("boundary", "clamped"), options.pop("clamp_layers"))
        return options


#: the options that shape the estimator (:func:`jaxbpm.ste.estimator`), as against the solve's own
ESTIMATOR_OPTIONS = ("dofs", "first_neighbour", "contacts", "contact_fraction", "layer_thickness", "surface_depth",
                     "volumes", "precision", "boundary")
