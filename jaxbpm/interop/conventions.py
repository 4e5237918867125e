"""Bond parameter conventions of other DEM codes, translated exactly to and from jaxbpm's bond law.

jaxbpm's bond (Jarolin & Dosta 2020, Eq. 1-4) is a cylinder of radius r_b and initial length L (the centre distance of
the two
particles when the bond was made) of an isotropic material (E, nu)::

    A = pi r_b^2,  I = pi r_b^4 / 4,  J = pi r_b^4 / 2
    k_n = E A / L,  k_t = E A / (2 L (1 + nu)),  k_tw = E J / (2 L (1 + nu)),  k_b = E I / L

Its strengths are stresses at the rim of the bond, checked separately for tension and shear (the convention of
MUSEN's elastic bond with its standard criterion, and of PFC's parallel bond with ``pb_mcf = 1`` and ``pb_fa = 0``)::

    sigma = F_n / A + |M_b| r_b / I  >= tensile_strength      (F_n > 0 in tension)
    tau   = |F_t| / A + |M_tw| r_b / J >= shear_strength

Every translator works per bond on NumPy arrays (scalars broadcast) and is exact where the other convention can hold
jaxbpm's law; where it cannot, it says so with an :class:`InexactTranslationWarning` that states the size of the
difference, or raises :class:`~jaxbpm.errors.ConventionError` when the parameters have no jaxbpm counterpart at all.

Stiffness (all four are exact both ways unless noted):

============  ===========================================================================================
convention    translation (per bond; R1, R2 particle radii, L the initial centre distance)
============  ===========================================================================================
PFC           linear parallel bond: k_n = pb_kn A, k_s = pb_ks A, k_tw = pb_ks J, k_b = pb_kn I, with
              r_b = pb_rmul min(R1, R2). pb_kn = E / L, pb_ks = pb_kn / kratio, kratio = 2 (1 + nu).
              Deformability method: pb_kn = emod / (R1 + R2), so emod = E (R1 + R2) / L (= E only for
              touching particles). kratio >= 3 (nu >= 0.5) has no jaxbpm counterpart.
LAMMPS        ``bond_style bpm/rotational``: Kr = k_n, Ks = k_t, Kt = k_tw, Kb = k_b (``normalize no``);
              with ``normalize yes`` LAMMPS divides Kr and Ks by L, so Kr = E A, Ks = E A / (2 (1 + nu)).
              Four stiffnesses for three jaxbpm parameters: Kt must equal 2 Ks Kb / Kr, else the twisting
              stiffness differs (warned, with the ratio).
Yade          CohFrictMat / CohFrictPhys: k_n = 2 E1 R1 E2 R2 / (E1 R1 + E2 R2) (= E_y 2 R1 R2 / (R1 + R2)
              for one material), k_s = poisson k_n (Yade's ``poisson`` is k_s / k_n, not a Poisson ratio),
              k_r = alphaKr R1 R2 k_s, k_tw = alphaKtw R1 R2 k_s. Hence young = E pi r_b^2 (R1 + R2) /
              (2 R1 R2 L) (pi/2 x E for equal touching spheres and r_b = R), poisson = 1 / (2 (1 + nu)),
              alphaKr = 2 (1 + nu) r_b^2 / (4 R1 R2), alphaKtw = r_b^2 / (2 R1 R2). A Yade poisson <= 1/3
              needs nu >= 0.5 and has no jaxbpm counterpart.
MUSEN         elastic solid bond: the same law (Jarolin & Dosta's model is MUSEN's): Young modulus E, shear modulus
              G = E / (2 (1 + nu)), diameter 2 r_b, initial length L; normal/tangential strength.
============  ===========================================================================================

Strength, and where it cannot be exact (u_* are utilisations: force or moment over its single-mode limit)::

    jaxbpm "separate", MUSEN (criterion 1), PFC (pb_mcf 1, pb_fa 0):   max(u_n + u_b, u_s + u_t) >= 1
    jaxbpm "summed", LAMMPS bpm/rotational:                            u_n + u_b + u_s + u_t >= 1   (u_n signed)
    jaxbpm "max", Yade CohFrictPhys, MUSEN (criterion 2):              max(u_n, u_b, u_s, u_t) >= 1

jaxbpm's scenes break bonds by any of the three (``failure_rule=``, default ``"separate"``): calibrate strengths
under the rule of the code they are for, and the translation below is exact for them as well.

The thresholds are translated so that every single-mode load (pure tension, pure shear, pure bending, pure twist)
breaks at the same force or moment in both codes: Fcr = sigma_t A, Tcb = sigma_t I / r_b, Fcs = tau_c A,
Tct = tau_c J / r_b (LAMMPS); normalAdhesion = sigma_t A, rollingAdhesion = sigma_t I / r_b, shearAdhesion = tau_c A,
twistingAdhesion = tau_c J / r_b (Yade, whose adhesions are cohesion x min(R1, R2)^2 or ^3 without pi). Mixed
loading then differs:

* LAMMPS vs jaxbpm: pure tension 0 %, pure shear 0 %; tension plus shear at equal utilisation: LAMMPS breaks at
  half the load (-50 %); in general LAMMPS's failure load is max(a + b, c + d) / (a + b + c + d) of jaxbpm's
  (between 0.5 and 1; a, b, c, d the utilisations per unit load). Compression (Fr < 0) lowers LAMMPS's sum, so a
  compressed bond resists more shear in LAMMPS; jaxbpm's shear strength does not depend on the normal force.
* Yade vs jaxbpm: pure tension, pure shear 0 %; tension plus bending at equal utilisation: Yade breaks at twice the
  load (+100 %); in general max(a + b, c + d) / max(a, b, c, d) (between 1 and 2). Yade's shear limit also adds
  F_n tan(frictionAngle) (set frictionAngle 0 or cohesionDisablesFriction to match).
* PFC: exact for pb_mcf = 1 and pb_fa = 0. pb_mcf = beta < 1 scales the moment terms: pure bending and pure twist
  break at 1/beta times jaxbpm's moment. pb_fa = phi != 0 makes the shear strength c - sigma_n tan(phi): pure
  shear 0 %, shear under a normal stress sigma_n differs by -sigma_n tan(phi) / c. Both are params of jaxbpm's DEM
  (``bond_moment_factor`` = pb_mcf, ``bond_friction_angle`` = phi in radians), not fields of :class:`JaxbpmBond`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from jaxbpm.errors import ConventionError
from jaxbpm.interop._codes import (NO_2D, LammpsBpmRotational, MusenSolidBond, PFCParallelBond, YadeCohFrict,
                                   from_lammps, from_musen, from_pfc, from_yade, to_lammps, to_musen, to_pfc, to_yade)
from jaxbpm.interop._registry import CONVENTIONS  # (kept JAX-free for the CLI's help)
from jaxbpm.interop._translation import (InexactTranslationWarning, JaxbpmBond, as_float, from_stiffness, positive,
                                         sample_bonds)

__all__ = [
    "InexactTranslationWarning", "JaxbpmBond", "PFCParallelBond", "LammpsBpmRotational", "YadeCohFrict",
    "MusenSolidBond", "to_pfc", "from_pfc", "to_lammps", "from_lammps", "to_yade", "from_yade", "to_musen",
    "from_musen", "from_stiffness", "sample_bonds", "failure_index", "CONVENTIONS", "convert",
]


# ---------------------------------------------------------------------------------------------- failure rules
def failure_index(rule: str, normal, shear, twist, bend, bond: JaxbpmBond):
    """Failure index of a bond under forces (normal ``F_n`` > 0 in tension, ``|F_t|``, ``|M_tw|``, ``|M_b|``) by
    ``rule`` ("jaxbpm", "lammps", "yade"), all with thresholds translated from ``bond``'s strengths; >= 1 breaks.

    Used to state and test the differences between the rules (see the module docstring).

    Args:
      rule: ``"jaxbpm"``, ``"lammps"`` or ``"yade"``.
      normal: normal force F_n [N], > 0 in tension.
      shear, twist, bend: ``|F_t|`` [N], ``|M_tw|``, ``|M_b|`` [N m].
      bond: the jaxbpm parameters the thresholds are translated from.

    Returns:
      The failure index (arrays of the inputs' shape); >= 1 breaks.
    """
    rb = bond.bond_radius
    u_n = as_float(normal) / (bond.tensile_strength * bond.area)
    u_b = np.abs(as_float(bend)) / (bond.tensile_strength * bond.inertia / rb)
    u_s = np.abs(as_float(shear)) / (bond.shear_strength * bond.area)
    u_t = np.abs(as_float(twist)) / (bond.shear_strength * bond.polar / rb)
    if rule == "jaxbpm":
        return np.maximum(u_n + u_b, u_s + u_t)
    if rule == "lammps":
        return np.maximum(u_n + u_b + u_s + u_t, 0.0)
    if rule == "yade":
        return np.maximum.reduce([u_n, u_b, u_s, u_t])
    raise ConventionError(f"unknown failure rule {rule!r}; expected 'jaxbpm', 'lammps' or 'yade'")


def _to_jaxbpm(name: str, values: dict[str, Any], length, r1, r2, thickness=None) -> JaxbpmBond:
    if name == "jaxbpm":
        return JaxbpmBond(**values, thickness=thickness)
    if name == "pfc":
        return from_pfc(r1, r2, length, **values, thickness=thickness)
    if name == "lammps":
        coeffs = {k: v for k, v in values.items() if k != "normalize"}
        return from_lammps(LammpsBpmRotational(**coeffs, normalize=bool(values.get("normalize", 0.0))), length,
                           thickness=thickness)
    if thickness is not None and name in NO_2D:
        raise ConventionError(f"{NO_2D[name]}; translate 2D bonds to PFC (PFC2D) or LAMMPS (dimension 2)")
    if name == "yade":
        return from_yade(YadeCohFrict(**values), r1, r2, length)
    if name == "musen":
        return from_musen(MusenSolidBond(**values))
    raise ConventionError(f"unknown convention {name!r}; expected one of {sorted(CONVENTIONS)}")


def _from_jaxbpm(name: str, bond: JaxbpmBond, length, r1, r2, normalize: bool = False):
    if name == "jaxbpm":
        return bond
    if name == "pfc":
        return to_pfc(bond, length, r1, r2)
    if name == "lammps":
        return to_lammps(bond, length, normalize=normalize)
    if name == "yade":
        return to_yade(bond, length, r1, r2)
    if name == "musen":
        return to_musen(bond)
    raise ConventionError(f"unknown convention {name!r}; expected one of {sorted(CONVENTIONS)}")


def convert(source: str, target: str, values: dict[str, Any], *, radius1, radius2, length=None,
            normalize: bool = False, thickness: float | None = None):
    """Translate one bond's parameters ``values`` (names of ``CONVENTIONS[source]``) into ``target``'s dataclass,
    for particles of radii ``radius1``, ``radius2`` and initial centre distance ``length`` (default R1 + R2).

    Args:
      source: a key of ``CONVENTIONS`` (``"jaxbpm"``, ``"pfc"``, ``"lammps"``, ``"yade"``, ``"musen"``).
      target: likewise.
      values: the parameters, by the names of ``CONVENTIONS[source]``.
      radius1, radius2: the particles' radii [m].
      length: initial centre distance [m]; default R1 + R2.
      normalize: for a LAMMPS target, coefficients for ``normalize yes``.
      thickness: ``None`` (spheres), or the discs' thickness t [m] of a 2D bond (a ``2 r_b x t`` rectangle; Yade
        and MUSEN, which have no disc form, raise).

    Returns:
      ``target``'s parameter dataclass.

    Raises:
      ConventionError: unknown or missing parameter names, or values with no counterpart.
    """
    for name in (source, target):
        if name not in CONVENTIONS:
            raise ConventionError(f"unknown convention {name!r}; expected one of {sorted(CONVENTIONS)}")
    spec = CONVENTIONS[source]["params"]
    unknown = sorted(set(values) - set(spec))
    if unknown:
        raise ConventionError(f"{source}: unknown parameters {unknown}; known: {list(spec)}")
    r1, r2 = positive("radius1", radius1), positive("radius2", radius2)
    length = r1 + r2 if length is None else positive("length", length)
    given = {k: v for k, v in values.items() if v is not None}
    if source == "jaxbpm":
        ratio = given.pop("bond_radius_ratio", None)
        if ("bond_radius" in given) == (ratio is not None):
            raise ConventionError("jaxbpm: give exactly one of bond_radius and bond_radius_ratio")
        if ratio is not None:
            given["bond_radius"] = as_float(ratio) * np.minimum(r1, r2)
    either = {"pfc": {"pb_kn", "pb_ks", "emod", "kratio"}, "jaxbpm": {"bond_radius", "bond_radius_ratio"},
              "yade": {"rollingCohesion", "twistingCohesion"}}.get(source, set())
    missing = [k for k, d in spec.items() if d is None and k not in given and k not in either]
    if missing:
        raise ConventionError(f"{source}: missing parameters {missing} ({CONVENTIONS[source]['doc']})")
    bond = _to_jaxbpm(source, given, length, r1, r2, thickness)
    return _from_jaxbpm(target, bond, length, r1, r2, normalize=normalize)
