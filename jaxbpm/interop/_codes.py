"""Other DEM codes' bond models and their exact translations to and from jaxbpm's (PFC's linear parallel bond,
LAMMPS's ``bpm/rotational``, Yade's CohFrictMat, MUSEN's elastic solid bond); public through
:mod:`jaxbpm.interop.conventions`, whose docstring states every translation and where it cannot be exact."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from jaxbpm._geometry import bond_section
from jaxbpm.errors import ConventionError
from jaxbpm.interop._translation import (REL, JaxbpmBond, as_float, from_stiffness, max_rel, nu_from_ratio,
                                         positive, strength, warn)
from jaxbpm.physics.bond import BondStiffness, check_failure_rule

__all__ = ["PFCParallelBond", "LammpsBpmRotational", "YadeCohFrict", "MusenSolidBond", "to_pfc", "from_pfc",
           "to_lammps", "from_lammps", "to_yade", "from_yade", "to_musen", "from_musen", "NO_2D", "three_d_only"]


NO_2D = {"yade": "Yade's CohFrictPhys joins spheres (3D only): it has no two-dimensional (disc) form",
         "musen": "MUSEN's solid bond is a cylinder between spheres (3D only): it has no two-dimensional (disc) form"}
"""Why a convention has no translation of a 2D sample's bonds, by convention name."""


def three_d_only(bond: JaxbpmBond, code: str) -> None:
    """Raise a :class:`~jaxbpm.errors.ConventionError` for a 2D bond where ``code`` has no 2D form.

    Args:
      bond: the jaxbpm parameters.
      code: ``"Yade"`` or ``"MUSEN"``.

    Raises:
      ConventionError: ``bond.thickness`` is given (a 2D sample's bond).
    """
    if bond.thickness is not None:
        raise ConventionError(f"{NO_2D[code.lower()]}; translate 2D bonds to PFC (PFC2D) or LAMMPS (dimension 2)")


# ---------------------------------------------------------------------------------------------- PFC
@dataclasses.dataclass(frozen=True)
class PFCParallelBond:
    """PFC linear parallel bond (``linearpbond``) properties, per contact.

    pb_kn, pb_ks: bond normal and shear stiffness per area [Pa/m]; pb_rmul: radius multiplier (bond radius =
    pb_rmul min(R1, R2)); pb_ten: tensile strength [Pa]; pb_coh: cohesion [Pa]; pb_fa: friction angle [deg];
    pb_mcf: moment contribution factor [-]. emod [Pa] and kratio [-] are the deformability-method inputs that give
    pb_kn = emod / (R1 + R2) and pb_ks = pb_kn / kratio (informative; pb_kn, pb_ks are what PFC uses).
    """

    pb_kn: Any
    pb_ks: Any
    pb_rmul: Any
    pb_ten: Any = np.inf
    pb_coh: Any = np.inf
    pb_fa: Any = 0.0
    pb_mcf: Any = 1.0
    emod: Any = None
    kratio: Any = None

    def stiffness(self, radius1, radius2, thickness: float | None = None) -> BondStiffness:
        """PFC's own stiffnesses: k_n = pb_kn A, k_s = pb_ks A, k_tw = pb_ks J, k_b = pb_kn I.

        Args:
          radius1, radius2: the particles' radii [m] (the bond radius is pb_rmul min(R1, R2)).
          thickness: ``None`` (PFC3D: A = pi r_b^2, I = pi r_b^4 / 4), or the discs' thickness t (PFC2D: A = 2 r_b t,
            I = (2 r_b)^3 t / 12; PFC2D's t is 1 m).

        Returns:
          ``(k_n, k_t, k_tw, k_b)``.
        """
        rb = as_float(self.pb_rmul) * np.minimum(as_float(radius1), as_float(radius2))
        area, inertia, polar = bond_section(rb, thickness)
        kn, ks = as_float(self.pb_kn), as_float(self.pb_ks)
        return BondStiffness(kn * area, ks * area, ks * polar, kn * inertia)


def to_pfc(bond: JaxbpmBond, length, radius1, radius2) -> PFCParallelBond:
    """Translate jaxbpm bonds into PFC linear parallel bonds (exact, with pb_fa = 0 and pb_mcf = 1).

    Args:
      bond: the jaxbpm parameters.
      length: initial bond length [m].
      radius1, radius2: the particles' radii [m].

    Returns:
      The PFC parameters.
    """
    length, r1, r2 = positive("length", length), positive("radius1", radius1), positive("radius2", radius2)
    pb_kn = bond.E / length
    kratio = 2.0 * (1.0 + bond.nu)
    return PFCParallelBond(pb_kn=pb_kn, pb_ks=pb_kn / kratio, pb_rmul=bond.bond_radius / np.minimum(r1, r2),
                           pb_ten=bond.tensile_strength, pb_coh=bond.shear_strength, pb_fa=np.zeros_like(pb_kn),
                           pb_mcf=np.ones_like(pb_kn), emod=pb_kn * (r1 + r2), kratio=kratio)


def from_pfc(radius1, radius2, length, *, pb_rmul=1.0, pb_kn=None, pb_ks=None, emod=None, kratio=None,
             pb_ten=np.inf, pb_coh=np.inf, pb_fa=0.0, pb_mcf=1.0, thickness: float | None = None) -> JaxbpmBond:
    """Translate PFC linear parallel bonds into jaxbpm bonds.

    pb_fa != 0 or pb_mcf != 1 are not part of the translated bond (warned, with the size of the difference); the
    DEM models them through its params ``bond_friction_angle`` and ``bond_moment_factor``.

    Args:
      radius1, radius2: the particles' radii [m].
      length: initial bond length [m].
      pb_rmul: bond radius multiplier.
      pb_kn, pb_ks: normal and shear stiffness per area [Pa/m]; or give ``emod``, ``kratio``.
      emod, kratio: the deformability method's modulus [Pa] and kn/ks ratio (L_pfc = R1 + R2).
      pb_ten, pb_coh: tensile strength and cohesion [Pa].
      pb_fa: friction angle [deg].
      pb_mcf: moment contribution factor.
      thickness: ``None`` (PFC3D), or the discs' thickness t [m] of a 2D (PFC2D) bond; the per-area values are the
        same in both.

    Returns:
      The jaxbpm parameters.

    Raises:
      ConventionError: missing or contradictory parameters, or values with no jaxbpm counterpart.
    """
    r1, r2, length = positive("radius1", radius1), positive("radius2", radius2), positive("length", length)
    if emod is not None or kratio is not None:
        if emod is None or kratio is None or pb_kn is not None or pb_ks is not None:
            raise ConventionError("PFC: give either pb_kn and pb_ks, or emod and kratio (deformability method)")
        pb_kn = positive("emod", emod) / (r1 + r2)
        pb_ks = pb_kn / positive("kratio", kratio)
    elif pb_kn is None or pb_ks is None:
        raise ConventionError("PFC: give either pb_kn and pb_ks, or emod and kratio (deformability method)")
    pb_kn, pb_ks = positive("pb_kn", pb_kn), positive("pb_ks", pb_ks)
    nu = nu_from_ratio(pb_ks / pb_kn, "PFC (kratio = pb_kn/pb_ks must be < 3)")
    rb = positive("pb_rmul", pb_rmul) * np.minimum(r1, r2)
    fa, mcf, coh = as_float(pb_fa), as_float(pb_mcf), strength("pb_coh", pb_coh)
    if np.any(fa != 0) and np.any(np.isfinite(coh)):
        tan = float(np.max(np.abs(np.tan(np.radians(fa)))))
        warn(f"PFC pb_fa = {float(np.max(np.abs(fa))):.6g} deg is not part of the translated bond: its shear "
              f"strength does not depend on the normal stress. Pure tension and pure shear are exact; shear under a "
              f"normal stress sigma_n differs by -sigma_n tan(pb_fa) / pb_coh = -{tan:.4g} sigma_n / pb_coh (a "
              f"tensile stress of half pb_coh: {-50 * tan:.3g} %). The DEM models it: params "
              f"bond_friction_angle = radians(pb_fa)")
    if np.any(mcf != 1):
        beta = float(np.min(mcf))
        warn(f"PFC pb_mcf = {beta:.6g} is not part of the translated bond, which counts the full moments (pb_mcf = "
              f"1). Pure tension and pure shear are exact; pure bending and pure twist break at {beta:.4g} x PFC's "
              f"moment ({100 * (beta - 1):.3g} %). The DEM models it: params bond_moment_factor = pb_mcf")
    return JaxbpmBond(pb_kn * length, nu, rb, strength("pb_ten", pb_ten), coh, thickness=thickness)


# ---------------------------------------------------------------------------------------------- LAMMPS
@dataclasses.dataclass(frozen=True)
class LammpsBpmRotational:
    """LAMMPS ``bond_style bpm/rotational`` coefficients, per bond (type).

    Kr, Ks [N/m] (``normalize yes``: [N]), Kt, Kb [N m/rad]; failure thresholds Fcr, Fcs [N], Tct, Tcb [N m].
    """

    Kr: Any
    Ks: Any
    Kt: Any
    Kb: Any
    Fcr: Any = np.inf
    Fcs: Any = np.inf
    Tct: Any = np.inf
    Tcb: Any = np.inf
    normalize: bool = False

    def stiffness(self, length) -> BondStiffness:
        """LAMMPS's stiffnesses: Kr, Ks (divided by the reference length r0 with ``normalize yes``), Kt, Kb.

        Args:
          length: the reference length r0 [m].

        Returns:
          ``(k_n, k_t, k_tw, k_b)``.
        """
        scale = 1.0 / as_float(length) if self.normalize else 1.0
        return BondStiffness(as_float(self.Kr) * scale, as_float(self.Ks) * scale, as_float(self.Kt), as_float(self.Kb))

    def coefficients(self) -> np.ndarray:
        """The coefficients in the order of ``bond_coeff``, before the dampings.

        Returns:
          ``[nb, 8]`` rows Kr Ks Kt Kb Fcr Fcs Tct Tcb.
        """
        cols = np.broadcast_arrays(*(as_float(getattr(self, k)) for k in ("Kr", "Ks", "Kt", "Kb", "Fcr", "Fcs", "Tct",
                                                                     "Tcb")))
        return np.stack([np.atleast_1d(c) for c in cols], axis=1)


_SUMMED_RULE = ("LAMMPS bpm/rotational breaks a bond when Fr/Fcr + Fs/Fcs + Tb/Tcb + Tt/Tct >= 1 (one summed "
                "rule); jaxbpm checks tension (F_n/A + M_b r_b/I) and shear (F_t/A + M_tw r_b/J) separately. The "
                "thresholds are set so that pure tension, pure shear, pure bending and pure twist break at the same "
                "load in both (0 % difference); under mixed loading LAMMPS breaks earlier: at equal tensile and shear "
                "utilisation at half the load (-50 %), in general at max(a+b, c+d)/(a+b+c+d) of jaxbpm's failure "
                "load (0.5 to 1), and compression (Fr < 0) lets LAMMPS bonds carry more shear. jaxbpm's scenes break "
                "bonds by LAMMPS's rule with failure_rule='summed': strengths calibrated so hold in LAMMPS as they "
                "are (pass failure_rule='summed' here to say so)")


def to_lammps(bond: JaxbpmBond, length, *, normalize: bool = False,
              failure_rule: str = "separate") -> LammpsBpmRotational:
    """Translate jaxbpm bonds into LAMMPS ``bpm/rotational`` coefficients.

    Stiffness exact; strengths exact when they were calibrated under ``failure_rule="summed"``, LAMMPS's rule;
    under another rule the difference is warned about when a strength is finite. A 2D bond (``bond.thickness``)
    gives the rectangle's A and I (``dimension 2``); its Kt and Tct, from the rectangle's J, are never loaded in a
    2D LAMMPS run (a disc has no twist).

    Args:
      bond: the jaxbpm parameters.
      length: initial bond length [m].
      normalize: coefficients for ``normalize yes``.
      failure_rule: the rule the strengths were calibrated under.

    Returns:
      The LAMMPS coefficients.
    """
    k = bond.stiffness(length)
    length = as_float(length)
    scale = length if normalize else 1.0
    sig, tau, rb = bond.tensile_strength, bond.shear_strength, bond.bond_radius
    finite = np.any(np.isfinite(sig)) or np.any(np.isfinite(tau))
    if finite and check_failure_rule(failure_rule, ConventionError) != "summed":
        warn(_SUMMED_RULE)
    return LammpsBpmRotational(Kr=k.kn * scale, Ks=k.kt * scale, Kt=k.ktw, Kb=k.kb, Fcr=sig * bond.area,
                               Fcs=tau * bond.area, Tct=tau * bond.polar / rb, Tcb=sig * bond.inertia / rb,
                               normalize=normalize)


def from_lammps(p: LammpsBpmRotational, length, *, breaking: bool = True, failure_rule: str = "separate",
                thickness: float | None = None) -> JaxbpmBond:
    """LAMMPS ``bpm/rotational`` -> jaxbpm. ``breaking=False`` (LAMMPS's ``break no``) ignores the thresholds.

    Warned: a Kt that jaxbpm's law cannot match (see :func:`from_stiffness`), thresholds whose bending/twisting
    limits disagree with the tensile/shear ones, and the summed failure rule unless ``failure_rule="summed"`` (the
    rule the jaxbpm scenes will break these bonds by).

    Args:
      p: the LAMMPS coefficients.
      length: initial bond length [m].
      breaking: ``False`` (LAMMPS's ``break no``) ignores the thresholds.
      failure_rule: the rule the jaxbpm scenes will break these bonds by.
      thickness: ``None`` (spheres), or the discs' thickness t [m] of a 2D sample (``dimension 2``): the bonds
        are ``2 r_b x t`` rectangles, Kt and Tct (twist, which a disc does not have) are not read.

    Returns:
      The jaxbpm parameters.

    Raises:
      ConventionError: coefficients with no jaxbpm counterpart.
    """
    k = p.stiffness(length)
    E, nu, rb = from_stiffness(k.kn, k.kt, k.ktw, k.kb, length, what="LAMMPS bpm/rotational", thickness=thickness)
    if not breaking:
        return JaxbpmBond(E, nu, rb, thickness=thickness)
    area, inertia, polar = JaxbpmBond(E, nu, rb, thickness=thickness).section()
    sig = positive("Fcr", p.Fcr) / area
    tau = positive("Fcs", p.Fcs) / area
    moments = (("Tcb", p.Tcb, sig * inertia / rb),) + ((("Tct", p.Tct, tau * polar / rb),) if thickness is None else ())
    for name, limit, law in moments:
        off = max_rel(law, positive(name, limit))
        if off > REL:
            bend = "Fcr r_b / 4" if thickness is None else "Fcr r_b / 3"
            warn(f"LAMMPS {name} cannot be represented exactly: jaxbpm's strengths fix it at "
                  f"{'sigma_t I / r_b = ' + bend if name == 'Tcb' else 'tau_c J / r_b = Fcs r_b / 2'}, which "
                  f"differs from the given one by up to {100 * off:.3g} % (pure "
                  f"{'bending' if name == 'Tcb' else 'twist'} breaks at that moment in jaxbpm)")
    if check_failure_rule(failure_rule, ConventionError) != "summed":
        warn(_SUMMED_RULE)
    return JaxbpmBond(E, nu, rb, sig, tau, thickness=thickness)


# ---------------------------------------------------------------------------------------------- Yade
@dataclasses.dataclass(frozen=True)
class YadeCohFrict:
    """Yade ``CohFrictMat`` values (both particles of the bond made of this material), per bond.

    young [Pa]; poisson = k_s / k_n [-] (Yade's meaning, not a Poisson ratio); alphaKr, alphaKtw [-];
    normalCohesion, shearCohesion [Pa] (multiplied by min(R1, R2)^2, without pi, to give the adhesion forces);
    rollingCohesion, twistingCohesion [Pa] (moments 0.25 and 0.5 x cohesion x min(R1, R2)^3).
    The interaction values (``CohFrictPhys``) follow from :meth:`phys`.
    """

    young: Any
    poisson: Any
    alphaKr: Any
    alphaKtw: Any
    normalCohesion: Any = np.inf
    shearCohesion: Any = np.inf
    rollingCohesion: Any = None
    twistingCohesion: Any = None

    def phys(self, radius1, radius2) -> dict[str, np.ndarray]:
        """``CohFrictPhys`` of a bond between spheres of radii R1, R2, as ``Ip2_CohFrictMat_CohFrictMat_CohFrictPhys``
        computes it.

        Args:
          radius1, radius2: the spheres' radii [m].

        Returns:
          ``{kn, ks, kr, ktw}`` [N/m, N m/rad] and ``{normalAdhesion, shearAdhesion}`` [N], ``{rollingAdhesion,
          twistingAdhesion}`` [N m].
        """
        r1, r2 = as_float(radius1), as_float(radius2)
        E, v = as_float(self.young), as_float(self.poisson)
        kn = 2.0 * E * r1 * E * r2 / (E * r1 + E * r2)  # harmonic mean of E_a R_a and E_b R_b
        ks = 2.0 * E * r1 * v * E * r2 * v / (E * r1 * v + E * r2 * v)
        rmin = np.minimum(r1, r2)
        roll = self.normalCohesion if self.rollingCohesion is None else self.rollingCohesion
        twist = self.shearCohesion if self.twistingCohesion is None else self.twistingCohesion
        return {"kn": kn, "ks": ks, "kr": r1 * r2 * ks * as_float(self.alphaKr), "ktw": r1 * r2 * ks * as_float(self.alphaKtw),
                "normalAdhesion": as_float(self.normalCohesion) * rmin**2, "shearAdhesion": as_float(self.shearCohesion) * rmin**2,
                "rollingAdhesion": 0.25 * as_float(roll) * rmin**3, "twistingAdhesion": 0.5 * as_float(twist) * rmin**3}

    def stiffness(self, radius1, radius2) -> BondStiffness:
        """Yade's stiffnesses from its own formulas.

        Args:
          radius1, radius2: the spheres' radii [m].

        Returns:
          ``(k_n, k_s, k_tw, k_r as k_b)``.
        """
        ph = self.phys(radius1, radius2)
        return BondStiffness(ph["kn"], ph["ks"], ph["ktw"], ph["kr"])


_MAX_RULE = ("Yade checks tension, shear, bending and twist separately (max(u_n, u_b, u_s, u_t) >= 1); jaxbpm adds "
             "tension and bending, and shear and twist (F_n/A + M_b r_b/I, F_t/A + M_tw r_b/J). Pure tension, shear, "
             "bending and twist break at the same load (0 %); tension plus bending at equal utilisation breaks at "
             "twice the load in Yade (+100 %), in general at max(a+b, c+d)/max(a, b, c, d) of jaxbpm's failure load "
             "(1 to 2). Yade's shear limit also grows by F_n tan(frictionAngle) unless frictionAngle = 0 or "
             "cohesionDisablesFriction. jaxbpm's scenes break bonds by Yade's rule with failure_rule='max' (pass "
             "failure_rule='max' here to say the strengths were calibrated so)")


def to_yade(bond: JaxbpmBond, length, radius1, radius2, *, failure_rule: str = "separate") -> YadeCohFrict:
    """Translate jaxbpm bonds into Yade CohFrictMat values, one set per bond.

    Stiffness exact per bond; Yade's materials belong to particles, so one material reproduces all bonds only where
    the per-bond values agree.

    Args:
      bond: the jaxbpm parameters.
      length: initial bond length [m].
      radius1, radius2: the particles' radii [m].
      failure_rule: the rule the strengths were calibrated under.

    Returns:
      The Yade values.

    Raises:
      ConventionError: a 2D bond (``bond.thickness`` given): Yade's CohFrictPhys joins spheres, it has no disc form.
    """
    three_d_only(bond, "Yade")
    k = bond.stiffness(length)
    r1, r2 = positive("radius1", radius1), positive("radius2", radius2)
    young = k.kn * (r1 + r2) / (2.0 * r1 * r2)
    poisson = k.kt / k.kn
    rmin, rb = np.minimum(r1, r2), bond.bond_radius
    sig, tau = bond.tensile_strength, bond.shear_strength
    finite = np.any(np.isfinite(sig)) or np.any(np.isfinite(tau))
    if finite and check_failure_rule(failure_rule, ConventionError) != "max":
        warn(_MAX_RULE)
    return YadeCohFrict(young=young, poisson=poisson, alphaKr=k.kb / (r1 * r2 * k.kt),
                        alphaKtw=k.ktw / (r1 * r2 * k.kt), normalCohesion=sig * bond.area / rmin**2,
                        shearCohesion=tau * bond.area / rmin**2,
                        rollingCohesion=4.0 * sig * bond.inertia / rb / rmin**3,
                        twistingCohesion=2.0 * tau * bond.polar / rb / rmin**3)


def from_yade(p: YadeCohFrict, radius1, radius2, length, *, failure_rule: str = "separate") -> JaxbpmBond:
    """Translate a Yade CohFrictMat (one material for both particles) into jaxbpm bonds.

    The separate-checks rule is warned about unless ``failure_rule="max"``, the rule the jaxbpm scenes will break
    these bonds by.

    Args:
      p: the Yade material.
      radius1, radius2: the particles' radii [m].
      length: initial bond length [m].
      failure_rule: the rule the jaxbpm scenes will break these bonds by.

    Returns:
      The jaxbpm parameters, per bond.

    Raises:
      ConventionError: values with no jaxbpm counterpart.
    """
    ph = p.phys(positive("radius1", radius1), positive("radius2", radius2))
    E, nu, rb = from_stiffness(ph["kn"], ph["ks"], ph["ktw"], ph["kr"], length, what="Yade CohFrictMat")
    area, inertia, polar = np.pi * rb**2, np.pi * rb**4 / 4.0, np.pi * rb**4 / 2.0
    sig = strength("normalCohesion", ph["normalAdhesion"]) / area
    tau = strength("shearCohesion", ph["shearAdhesion"]) / area
    for name, limit, law in (("rollingCohesion", ph["rollingAdhesion"], sig * inertia / rb),
                             ("twistingCohesion", ph["twistingAdhesion"], tau * polar / rb)):
        off = max_rel(law, limit)
        if off > REL:
            warn(f"Yade {name} cannot be represented exactly: jaxbpm's strengths fix the "
                  f"{'bending' if name.startswith('rolling') else 'twisting'} failure moment, which differs from "
                  f"Yade's by up to {100 * off:.3g} %")
    finite = np.any(np.isfinite(sig)) or np.any(np.isfinite(tau))
    if finite and check_failure_rule(failure_rule, ConventionError) != "max":
        warn(_MAX_RULE)
    return JaxbpmBond(E, nu, rb, sig, tau)


# ---------------------------------------------------------------------------------------------- MUSEN
@dataclasses.dataclass(frozen=True)
class MusenSolidBond:
    """MUSEN elastic solid bond (``CModelSBElastic``), per bond: diameter [m], young_modulus [Pa] (its normal
    stiffness), poisson_ratio [-] (tangential stiffness = shear modulus E / (2 (1 + nu))), normal_strength and
    tangential_strength [Pa]."""

    diameter: Any
    young_modulus: Any
    poisson_ratio: Any
    normal_strength: Any = np.inf
    tangential_strength: Any = np.inf

    @property
    def shear_modulus(self):
        """G = E / (2 (1 + nu)) [Pa]."""
        return as_float(self.young_modulus) / (2.0 * (1.0 + as_float(self.poisson_ratio)))

    def stiffness(self, initial_length) -> BondStiffness:
        """MUSEN's stiffnesses: E A / L, G A / L, 2 I G / L (normal moment), E I / L (tangential moment), with
        A = pi d^2 / 4 (CrossCut) and I = pi d^4 / 64 (AxialMoment).

        Args:
          initial_length: initial bond length L [m].

        Returns:
          ``(k_n, k_t, k_tw, k_b)``.
        """
        d, L = as_float(self.diameter), as_float(initial_length)
        cross_cut, axial_moment = np.pi * d**2 / 4.0, np.pi * d**4 / 64.0
        E, G = as_float(self.young_modulus), self.shear_modulus
        return BondStiffness(E * cross_cut / L, G * cross_cut / L, 2.0 * axial_moment * G / L, E * axial_moment / L)


def to_musen(bond: JaxbpmBond) -> MusenSolidBond:
    """Translate jaxbpm bonds into MUSEN elastic solid bonds (exact; MUSEN's breakage criterion 1 is jaxbpm's rule).

    Args:
      bond: the jaxbpm parameters.

    Returns:
      The MUSEN parameters.

    Raises:
      ConventionError: a 2D bond (``bond.thickness`` given): MUSEN's solid bond is a cylinder between spheres.
    """
    three_d_only(bond, "MUSEN")
    return MusenSolidBond(2.0 * bond.bond_radius, bond.E, bond.nu, bond.tensile_strength, bond.shear_strength)


def from_musen(p: MusenSolidBond, *, criterion: int = 1) -> JaxbpmBond:
    """Translate MUSEN elastic solid bonds into jaxbpm bonds.

    Args:
      p: the MUSEN parameters.
      criterion: MUSEN's CONSIDER_BREAKAGE (1: standard, jaxbpm's rule; 2: separate checks, warned; 0: no
        breakage).

    Returns:
      The jaxbpm parameters.

    Raises:
      ConventionError: an unknown criterion or values with no jaxbpm counterpart.
    """
    if criterion not in (0, 1, 2):
        raise ConventionError(f"MUSEN CONSIDER_BREAKAGE must be 0, 1 or 2, got {criterion!r}")
    if criterion == 0:
        return JaxbpmBond(p.young_modulus, p.poisson_ratio, as_float(p.diameter) / 2.0)
    if criterion == 2:
        warn("MUSEN criterion 2 checks tension, bending (in tension only), shear and twist separately; jaxbpm adds "
              "tension and bending, and shear and twist (MUSEN's criterion 1). Pure tension, shear, bending and "
              "twist break at the same load (0 %); tension plus bending at equal utilisation breaks at twice the load "
              "with criterion 2 (+100 %), in general at max(a+b, c+d)/max(a, b, c, d) of jaxbpm's failure load")
    return JaxbpmBond(p.young_modulus, p.poisson_ratio, as_float(p.diameter) / 2.0, p.normal_strength,
                      p.tangential_strength)
