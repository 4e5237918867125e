"""The jaxbpm side of every bond-parameter translation (:mod:`jaxbpm.interop.conventions`): jaxbpm's bond
parameters (:class:`JaxbpmBond`), the parameters of given stiffnesses, a sample's bonds, and the checks and warnings
the translators share."""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any

import numpy as np

from jaxbpm._geometry import bond_section
from jaxbpm.errors import ConventionError
from jaxbpm.physics.bond import BondStiffness, stiffness

__all__ = ["REL", "InexactTranslationWarning", "JaxbpmBond", "from_stiffness", "sample_bonds", "as_float", "warn",
           "max_rel", "positive", "strength", "nu_from_ratio"]

REL = 1e-9  # relative tolerance below which two translated quantities count as equal (round-off)


class InexactTranslationWarning(UserWarning):
    """A translation between bond conventions is not exact; the message states the size of the difference."""


def as_float(x) -> np.ndarray:
    """``x`` as a float64 array."""
    return np.asarray(x, dtype=np.float64)


def warn(msg: str) -> None:
    """Warn with an :class:`InexactTranslationWarning`, attributed to the translator's caller."""
    warnings.warn(msg, InexactTranslationWarning, stacklevel=3)


def max_rel(a, b) -> float:
    """The largest relative difference of ``a`` from ``b`` (equal infinities: 0)."""
    a, b = np.broadcast_arrays(as_float(a), as_float(b))
    with np.errstate(invalid="ignore", divide="ignore"):
        both_inf = np.isinf(a) & np.isinf(b) & (np.sign(a) == np.sign(b))
        rel = np.where(both_inf, 0.0, np.abs(a - b) / np.maximum(np.abs(b), np.finfo(float).tiny))
    return float(np.max(rel)) if rel.size else 0.0


def positive(name: str, x) -> np.ndarray:
    """``x`` as float64, or a :class:`ConventionError` naming ``name`` when some value is not > 0."""
    arr = as_float(x)
    if np.any(~(arr > 0)) or np.any(np.isnan(arr)):
        raise ConventionError(f"{name} must be > 0, got {np.ravel(arr)[np.flatnonzero(~(np.ravel(arr) > 0))[:5]]}")
    return arr


def strength(name: str, x) -> np.ndarray:
    """A strength as float64 (``inf``: unbreakable), or a :class:`ConventionError` when some value is not > 0."""
    arr = as_float(x)
    if np.any(~(arr > 0)):
        raise ConventionError(f"{name} must be > 0 (inf = unbreakable), got {np.ravel(arr)[:5]}")
    return arr


def nu_from_ratio(kt_over_kn, what: str) -> np.ndarray:
    """nu from k_t / k_n = 1 / (2 (1 + nu)); raises when nu leaves jaxbpm's range (-1, 0.5)."""
    ratio = as_float(kt_over_kn)
    with np.errstate(divide="ignore"):
        nu = 1.0 / (2.0 * ratio) - 1.0
    bad = ~((nu > -1.0) & (nu < 0.5))
    if np.any(bad):
        r = float(np.ravel(np.broadcast_to(ratio, bad.shape))[np.flatnonzero(np.ravel(bad))[0]])
        raise ConventionError(
            f"{what}: shear/normal stiffness ratio k_t/k_n = {r:.6g} needs a Poisson ratio nu = "
            f"{1 / (2 * r) - 1 if r > 0 else float('inf'):.6g}; jaxbpm's law k_t/k_n = 1/(2(1+nu)) with nu in "
            f"(-1, 0.5) covers only k_t/k_n > 1/3")
    return nu


# ---------------------------------------------------------------------------------------------- jaxbpm
@dataclasses.dataclass(frozen=True)
class JaxbpmBond:
    """jaxbpm's bond parameters, per bond (arrays broadcast).

    E [Pa], nu [-], bond_radius r_b [m], tensile_strength and shear_strength [Pa] (``inf`` = unbreakable);
    thickness: ``None`` for a cylindrical bond between spheres, or the discs' thickness t [m] of a two-dimensional
    sample, whose bonds have the rectangular cross-section ``2 r_b x t`` (PFC2D's parallel bond).
    """

    E: Any
    nu: Any
    bond_radius: Any
    tensile_strength: Any = np.inf
    shear_strength: Any = np.inf
    thickness: float | None = None

    def __post_init__(self):
        for name in ("E", "nu", "bond_radius", "tensile_strength", "shear_strength"):
            object.__setattr__(self, name, as_float(getattr(self, name)))
        if self.thickness is not None:
            object.__setattr__(self, "thickness", float(positive("thickness", self.thickness)))
        positive("E", self.E)
        positive("bond_radius", self.bond_radius)
        strength("tensile_strength", self.tensile_strength)
        strength("shear_strength", self.shear_strength)
        if np.any(~((self.nu > -1) & (self.nu < 0.5))):
            raise ConventionError(f"nu must lie in (-1, 0.5), got {np.ravel(self.nu)[:5]}")

    @property
    def dim(self) -> int:
        """3 (cylindrical bonds between spheres) or 2 (rectangular bonds between discs, ``thickness`` given)."""
        return 3 if self.thickness is None else 2

    def section(self):
        """The bonds' cross-section ``(A, I, J)`` (:func:`jaxbpm._geometry.bond_section`)."""
        return bond_section(self.bond_radius, self.thickness)

    @property
    def area(self):
        """Bond cross-section A [m^2]: pi r_b^2, or 2 r_b t in 2D."""
        return bond_section(self.bond_radius, self.thickness).area

    @property
    def inertia(self):
        """Second moment of area I [m^4]: pi r_b^4 / 4, or (2 r_b)^3 t / 12 in 2D."""
        return bond_section(self.bond_radius, self.thickness).inertia

    @property
    def polar(self):
        """Polar moment J [m^4]: pi r_b^4 / 2, or the rectangle's 2 r_b t ((2 r_b)^2 + t^2) / 12 in 2D (read by no
        2D law: a disc has no twist)."""
        return bond_section(self.bond_radius, self.thickness).polar

    def stiffness(self, length) -> BondStiffness:
        """jaxbpm's four stiffnesses (Eq. 1-4).

        Args:
          length: initial bond length [m].

        Returns:
          ``(k_n, k_t, k_tw, k_b)``.
        """
        return BondStiffness(*(np.asarray(k) for k in stiffness(self.E, self.nu, self.area, self.inertia,
                                                                  self.polar, positive("length", length))))


def from_stiffness(kn, kt, ktw, kb, length, *, what: str = "stiffness",
                   thickness: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(E, nu, r_b) of jaxbpm's law from four bond stiffnesses and the initial length.

    k_b / k_n = I / A (r_b^2 / 4, or r_b^2 / 3 for a 2D bond's rectangle) gives r_b, k_t / k_n gives nu, then
    E = k_n L / A. In 3D jaxbpm's law ties the twisting stiffness to the others (k_tw = k_b / (1 + nu)); a ``ktw``
    that differs is warned about with the ratio. In 2D the twisting stiffness is not read (a disc has no twist).

    Args:
      kn, kt: normal and shear stiffness [N/m].
      ktw, kb: twisting and bending stiffness [N m/rad].
      length: initial bond length L [m].
      what: the source's name, for messages.
      thickness: ``None`` (3D) or the discs' thickness t [m] of a 2D sample.

    Returns:
      ``(E, nu, bond_radius)``, arrays of the inputs' shape.

    Raises:
      ConventionError: stiffnesses that no jaxbpm bond has (not positive, or nu out of range).
    """
    kn, kt, ktw, kb = (positive(n, v) for n, v in (("k_n", kn), ("k_t", kt), ("k_tw", ktw), ("k_b", kb)))
    length = positive("length", length)
    nu = nu_from_ratio(kt / kn, what)
    if thickness is not None:
        rb = np.sqrt(3.0 * kb / kn)
        return kn * length / (2.0 * rb * thickness), nu, rb
    rb = 2.0 * np.sqrt(kb / kn)
    E = kn * length / (np.pi * rb**2)
    ktw_law = kb / (1.0 + nu)
    off = max_rel(ktw_law, ktw)
    if off > REL:
        warn(f"{what}: the twisting stiffness cannot be represented exactly: jaxbpm's law gives k_tw = k_b/(1+nu) "
              f"from the other three, which differs from the given one by up to {100 * off:.3g} % (normal, shear "
              f"and bending stiffness are exact)")
    return E, nu, rb


def sample_bonds(sample) -> tuple[JaxbpmBond, np.ndarray, np.ndarray, np.ndarray]:
    """The per-bond parameters of a sample.

    Args:
      sample: a :class:`~jaxbpm.sample.Sample`.

    Returns:
      ``(JaxbpmBond, length, radius1, radius2)``, each ``[nb]``; the bond carries a 2D sample's thickness.
    """
    m = sample.materials
    bm = np.asarray(sample.bond_material)
    b = np.asarray(sample.bonds)
    rad = np.asarray(sample.radii)
    bond = JaxbpmBond(as_float(m.E)[bm], as_float(m.nu)[bm], as_float(sample.bond_radius), as_float(m.tensile_strength)[bm],
                      as_float(m.shear_strength)[bm], thickness=getattr(sample, "thickness", None))
    return bond, as_float(sample.bond_length), rad[b[:, 0]], rad[b[:, 1]]
