"""The geometry a sample's dimension gives its particles and bonds (the steps of
:meth:`Sample.from_arrays <jaxbpm.sample.Sample.from_arrays>` that differ between 3D and 2D).

* 3D: spheres (mass ``rho 4/3 pi R^3``, moment of inertia ``2/5 m R^2``) joined by cylindrical bonds of radius
  ``r_b`` (``A = pi r_b^2``, ``I = pi r_b^4 / 4``, ``J = pi r_b^4 / 2``).
* 2D: discs of thickness ``t`` (PFC2D's unit thickness by default, ``t = 1 m``; mass ``rho pi R^2 t``, moment of
  inertia ``m R^2 / 2`` about the disc's axis) joined by bonds of rectangular cross-section ``2 r_b x t``
  (``A = 2 r_b t``, ``I = (2 r_b)^3 t / 12`` for bending in the plane; ``J = 2 r_b t ((2 r_b)^2 + t^2) / 12``, the
  rectangle's polar moment, which no 2D force law reads: a disc has no twist).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from jaxbpm._text import shown
from jaxbpm.errors import SampleError

__all__ = ["DEFAULT_THICKNESS", "checked_thickness", "particle_mass", "Section", "bond_section", "solid_measure",
           "SOLVERS_2D", "check_three_d"]

DEFAULT_THICKNESS = 1.0
"""The thickness of a two-dimensional sample's discs when none is given [m] (PFC2D's unit thickness)."""


def checked_thickness(thickness, dim: int) -> float | None:
    """The discs' thickness of a sample of dimension ``dim``, checked.

    Args:
      thickness: ``None`` (2D: :data:`DEFAULT_THICKNESS`) or a finite number > 0 [m]; 3D samples take none.
      dim: the sample's dimension, 2 or 3.

    Returns:
      The thickness as a float in 2D, ``None`` in 3D.

    Raises:
      SampleError: a thickness given for a 3D sample, or one that is not a finite number > 0.
    """
    if dim == 3:
        if thickness is not None:
            raise SampleError(f"thickness is the discs' thickness of a two-dimensional sample (positions [n, 2]); a "
                              f"sample of spheres (positions [n, 3]) takes none, got {shown(thickness)}")
        return None
    if thickness is None:
        return DEFAULT_THICKNESS
    try:
        if isinstance(thickness, (str, bytes, bool)):
            raise TypeError
        t = float(thickness)
    except (TypeError, ValueError, OverflowError):
        t = float("nan")
    if not (np.isfinite(t) and t > 0):
        raise SampleError(f"thickness must be a finite number > 0 [m], got {shown(thickness)}")
    return t


def particle_mass(radii: np.ndarray, density: float, thickness: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Mass and moment of inertia of each particle.

    Args:
      radii: ``[n]`` radii [m].
      density: the particle material's density [kg/m^3].
      thickness: ``None`` (spheres) or the discs' thickness [m].

    Returns:
      ``(mass [n] kg, inertia [n] kg m^2)``: a sphere's ``4/3 pi rho R^3`` and ``2/5 m R^2``, or a disc's
      ``rho pi R^2 t`` and ``m R^2 / 2``.
    """
    if thickness is None:
        mass = density * 4.0 / 3.0 * np.pi * radii**3
        return mass, 0.4 * mass * radii**2
    mass = density * np.pi * radii**2 * thickness
    return mass, 0.5 * mass * radii**2


class Section(NamedTuple):
    """A bond's cross-section: area ``A`` [m^2], second moment of area ``I`` [m^4] and polar moment ``J`` [m^4]."""

    area: np.ndarray
    inertia: np.ndarray
    polar: np.ndarray


def bond_section(bond_radius: np.ndarray, thickness: float | None) -> Section:
    """The cross-section of each bond.

    Args:
      bond_radius: ``[nb]`` bond radii r_b [m].
      thickness: ``None`` (3D: a circle of radius r_b) or the discs' thickness t [m] (2D: a ``2 r_b x t``
        rectangle).

    Returns:
      The bonds' :class:`Section`, each ``[nb]``.
    """
    rb = bond_radius
    if thickness is None:
        return Section(np.pi * rb**2, np.pi * rb**4 / 4.0, np.pi * rb**4 / 2.0)
    width = 2.0 * rb
    return Section(width * thickness, width**3 * thickness / 12.0,
                   width * thickness * (width**2 + thickness**2) / 12.0)


def solid_measure(radii: np.ndarray, dim: int) -> float:
    """The particles' total volume (3D, m^3) or area (2D, m^2), the numerator of a packing fraction.

    Args:
      radii: ``[n]`` radii [m].
      dim: the sample's dimension, 2 or 3.

    Returns:
      ``sum 4/3 pi R^3`` or ``sum pi R^2``.
    """
    if dim == 2:
        return float(np.sum(np.pi * radii**2))
    return float(np.sum(4.0 / 3.0 * np.pi * radii**3))


#: what solves a two-dimensional sample so far (see :func:`check_three_d`)
SOLVERS_2D: tuple[str, ...] = ("dsm", "ste", "dem")


def check_three_d(sample, what: str) -> None:
    """Raise a :class:`~jaxbpm.errors.SceneError` where ``what`` would be given a two-dimensional sample it does not
    model (a wrong answer, not an error, would follow).

    Args:
      sample: the sample (anything with a ``dim``).
      what: the part of jaxbpm that needs three dimensions, for the message (``"the DEM"``).

    Raises:
      SceneError: ``sample`` is two-dimensional.
    """
    from jaxbpm.errors import SceneError

    if getattr(sample, "dim", 3) == 2:
        names = " and ".join(f"the {m.upper()}" for m in SOLVERS_2D)
        done = (f"2D samples are solved by {names} (bonds between clamped layers; the DEM also with linear contacts, "
                "contact_law='linear') so far; " if SOLVERS_2D else
                "2D samples (discs) can be built, stored and exported, and their bond law evaluated "
                "(jaxbpm.physics.model.build_model), but no solver takes them yet: ")
        raise SceneError(f"{done}{what} in 2D is not yet available (the sample's positions are [n, 2])")
