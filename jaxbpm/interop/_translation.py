"""The jaxbpm side of every bond-parameter translation (:mod:`jaxbpm.interop.conventions`): jaxbpm's bond
parameters (:class:`JaxbpmBond`), the parameters of given stiffnesses, a sample's bonds, and the checks and warnings
the translators share."""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any

import numpy as np

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

    E [Pa], nu [-], bond_radius r_b [m], tensile_strength and shear_strength [Pa] (``inf`` = unbreakable).
    """

    E: Any
    nu: Any
    bond_radius: Any
    tensile_strength: Any = np.inf
    shear_strength: Any = np.inf

    def __post_init__(self):
        for name in ("E", "nu", "bond_radius", "tensile_strength", "shear_strength"):
            object.__setattr__(self, name, as_float(getattr(self, name)))
        positive("E", self.E)
        positive("bond_radius", self.bond_radius)
        strength("tensile_strength", self.tensile_strength)
        strength("shear_strength", self.shear_strength)
        if np.any(~((self.nu > -1) & (self.nu < 0.5))):
            raise ConventionError(f"nu must lie in (-1, 0.5), got {np.ravel(self.nu)[:5]}")

    @property
    def area(self):
        """Bond cross-section A = pi r_b^2 [m^2]."""
        return np.pi * self.bond_radius**2

    @property
    def inertia(self):
        """Second moment of area I = pi r_b^4 / 4 [m^4]."""
        return np.pi * self.bond_radius**4 / 4.0

    @property
    def polar(self):
        """Polar moment J = pi r_b^4 / 2 [m^4]."""
        return np.pi * self.bond_radius**4 / 2.0

    def stiffness(self, length) -> BondStiffness:
        """jaxbpm's four stiffnesses (Eq. 1-4).

        Args:
          length: initial bond length [m].

        Returns:
          ``(k_n, k_t, k_tw, k_b)``.
        """
        return BondStiffness(*(np.asarray(k) for k in stiffness(self.E, self.nu, self.area, self.inertia,
                                                                  self.polar, positive("length", length))))


def from_stiffness(kn, kt, ktw, kb, length, *, what: str = "stiffness") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(E, nu, r_b) of jaxbpm's law from four bond stiffnesses and the initial length.

    k_b / k_n = r_b^2 / 4 gives r_b, k_t / k_n gives nu, then E = k_n L / A. jaxbpm's law ties the twisting
    stiffness to the others (k_tw = k_b / (1 + nu)); a ``ktw`` that differs is warned about with the ratio.

    Args:
      kn, kt: normal and shear stiffness [N/m].
      ktw, kb: twisting and bending stiffness [N m/rad].
      length: initial bond length L [m].
      what: the source's name, for messages.

    Returns:
      ``(E, nu, bond_radius)``, arrays of the inputs' shape.

    Raises:
      ConventionError: stiffnesses that no jaxbpm bond has (not positive, or nu out of range).
    """
    kn, kt, ktw, kb = (positive(n, v) for n, v in (("k_n", kn), ("k_t", kt), ("k_tw", ktw), ("k_b", kb)))
    length = positive("length", length)
    nu = nu_from_ratio(kt / kn, what)
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
      ``(JaxbpmBond, length, radius1, radius2)``, each ``[nb]``.
    """
    m = sample.materials
    bm = np.asarray(sample.bond_material)
    b = np.asarray(sample.bonds)
    rad = np.asarray(sample.radii)
    bond = JaxbpmBond(as_float(m.E)[bm], as_float(m.nu)[bm], as_float(sample.bond_radius), as_float(m.tensile_strength)[bm],
                      as_float(m.shear_strength)[bm])
    return bond, as_float(sample.bond_length), rad[b[:, 0]], rad[b[:, 1]]
