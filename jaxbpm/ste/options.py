"""The STE's options, :class:`STE` (``jaxbpm.STE``): what ``jaxbpm.solve(..., method="ste")`` and
:func:`jaxbpm.ste.solve_scene` take."""

from __future__ import annotations

import numbers

import numpy as np

from jaxbpm._options import choice, flag, fraction, optional, option, positive, shown, SolverOptions
from jaxbpm.errors import OptionsError

__all__ = ["STE", "ESTIMATOR_OPTIONS"]


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
      surface_depth: particles closer than this to the sample's boundary [m] are left out of the averages
        (``None``: one mean particle diameter; 0 keeps every non-singular particle).
      volumes: ``[n]`` particle volumes V^n [m^3] (``None``: particle volume / global solid fraction).
      precision: ``"float64"``, or ``"float32"``: faster, ~1e-7 relative change (calibrate with float64).
      pad: the estimator is padded to the sample's size class and kept for the last few samples, so that samples
        of similar size share one compiled program (the same result to round-off).
      throw: raise :class:`~jaxbpm.errors.NotFiniteError` when the stiffness is not finite (``False``: return the
        result with ``status="not_finite"``).
      clamp_layers: the particles the scene clamps follow the affine field instead of relaxing (see
        :func:`jaxbpm.ste.estimator`).
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
    clamp_layers: bool = option(False, flag)


#: the options that shape the estimator (:func:`jaxbpm.ste.estimator`), as against the solve's own
ESTIMATOR_OPTIONS = ("dofs", "first_neighbour", "contacts", "contact_fraction", "layer_thickness", "surface_depth",
                     "volumes", "precision", "clamp_layers")
