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

import dataclasses
import warnings
from typing import Any

import numpy as np

from jaxbpm.errors import ConventionError
from jaxbpm.interop._registry import CONVENTIONS  # (kept JAX-free for the CLI's help)
from jaxbpm.physics.bond import BondStiffness, check_failure_rule, stiffness

__all__ = [
    "InexactTranslationWarning", "JaxbpmBond", "PFCParallelBond", "LammpsBpmRotational", "YadeCohFrict",
    "MusenSolidBond", "to_pfc", "from_pfc", "to_lammps", "from_lammps", "to_yade", "from_yade", "to_musen",
    "from_musen", "from_stiffness", "sample_bonds", "failure_index", "CONVENTIONS", "convert",
]

_REL = 1e-9  # relative tolerance below which two translated quantities count as equal (round-off)


class InexactTranslationWarning(UserWarning):
    """A translation between bond conventions is not exact; the message states the size of the difference."""


def _f(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


def _warn(msg: str) -> None:
    warnings.warn(msg, InexactTranslationWarning, stacklevel=3)


def _max_rel(a, b) -> float:
    a, b = np.broadcast_arrays(_f(a), _f(b))
    with np.errstate(invalid="ignore", divide="ignore"):
        both_inf = np.isinf(a) & np.isinf(b) & (np.sign(a) == np.sign(b))
        rel = np.where(both_inf, 0.0, np.abs(a - b) / np.maximum(np.abs(b), np.finfo(float).tiny))
    return float(np.max(rel)) if rel.size else 0.0


def _positive(name: str, x) -> np.ndarray:
    arr = _f(x)
    if np.any(~(arr > 0)) or np.any(np.isnan(arr)):
        raise ConventionError(f"{name} must be > 0, got {np.ravel(arr)[np.flatnonzero(~(np.ravel(arr) > 0))[:5]]}")
    return arr


def _strength(name: str, x) -> np.ndarray:
    arr = _f(x)
    if np.any(~(arr > 0)):
        raise ConventionError(f"{name} must be > 0 (inf = unbreakable), got {np.ravel(arr)[:5]}")
    return arr


def _nu_from_ratio(kt_over_kn, what: str) -> np.ndarray:
    """nu from k_t / k_n = 1 / (2 (1 + nu)); raises when nu leaves jaxbpm's range (-1, 0.5)."""
    ratio = _f(kt_over_kn)
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
            object.__setattr__(self, name, _f(getattr(self, name)))
        _positive("E", self.E)
        _positive("bond_radius", self.bond_radius)
        _strength("tensile_strength", self.tensile_strength)
        _strength("shear_strength", self.shear_strength)
        if np.any(~((self.nu > -1) & (self.nu < 0.5))):
            raise ConventionError(f"nu must lie in (-1, 0.5), got {np.ravel(self.nu)[:5]}")

    @property
    def area(self):
        return np.pi * self.bond_radius**2

    @property
    def inertia(self):
        return np.pi * self.bond_radius**4 / 4.0

    @property
    def polar(self):
        return np.pi * self.bond_radius**4 / 2.0

    def stiffness(self, length) -> BondStiffness:
        """jaxbpm's four stiffnesses (Eq. 1-4) for initial length ``length`` [m]."""
        return BondStiffness(*(np.asarray(k) for k in stiffness(self.E, self.nu, self.area, self.inertia,
                                                                  self.polar, _positive("length", length))))


def from_stiffness(kn, kt, ktw, kb, length, *, what: str = "stiffness") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(E, nu, r_b) of jaxbpm's law from four bond stiffnesses and the initial length.

    k_b / k_n = r_b^2 / 4 gives r_b, k_t / k_n gives nu, then E = k_n L / A. jaxbpm's law ties the twisting
    stiffness to the others (k_tw = k_b / (1 + nu)); a ``ktw`` that differs is warned about with the ratio.
    """
    kn, kt, ktw, kb = (_positive(n, v) for n, v in (("k_n", kn), ("k_t", kt), ("k_tw", ktw), ("k_b", kb)))
    length = _positive("length", length)
    nu = _nu_from_ratio(kt / kn, what)
    rb = 2.0 * np.sqrt(kb / kn)
    E = kn * length / (np.pi * rb**2)
    ktw_law = kb / (1.0 + nu)
    off = _max_rel(ktw_law, ktw)
    if off > _REL:
        _warn(f"{what}: the twisting stiffness cannot be represented exactly: jaxbpm's law gives k_tw = k_b/(1+nu) "
              f"from the other three, which differs from the given one by up to {100 * off:.3g} % (normal, shear "
              f"and bending stiffness are exact)")
    return E, nu, rb


def sample_bonds(sample) -> tuple[JaxbpmBond, np.ndarray, np.ndarray, np.ndarray]:
    """Per-bond parameters of a :class:`~jaxbpm.sample.Sample`: ``(JaxbpmBond, length, radius1, radius2)``."""
    m = sample.materials
    bm = np.asarray(sample.bond_material)
    b = np.asarray(sample.bonds)
    rad = np.asarray(sample.radii)
    bond = JaxbpmBond(_f(m.E)[bm], _f(m.nu)[bm], _f(sample.bond_radius), _f(m.tensile_strength)[bm],
                      _f(m.shear_strength)[bm])
    return bond, _f(sample.bond_length), rad[b[:, 0]], rad[b[:, 1]]


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

    def stiffness(self, radius1, radius2) -> BondStiffness:
        """PFC's own stiffnesses: k_n = pb_kn A, k_s = pb_ks A, k_tw = pb_ks J, k_b = pb_kn I."""
        rb = _f(self.pb_rmul) * np.minimum(_f(radius1), _f(radius2))
        area, inertia, polar = np.pi * rb**2, np.pi * rb**4 / 4.0, np.pi * rb**4 / 2.0
        kn, ks = _f(self.pb_kn), _f(self.pb_ks)
        return BondStiffness(kn * area, ks * area, ks * polar, kn * inertia)


def to_pfc(bond: JaxbpmBond, length, radius1, radius2) -> PFCParallelBond:
    """jaxbpm -> PFC linear parallel bond (exact, with pb_fa = 0 and pb_mcf = 1)."""
    length, r1, r2 = _positive("length", length), _positive("radius1", radius1), _positive("radius2", radius2)
    pb_kn = bond.E / length
    kratio = 2.0 * (1.0 + bond.nu)
    return PFCParallelBond(pb_kn=pb_kn, pb_ks=pb_kn / kratio, pb_rmul=bond.bond_radius / np.minimum(r1, r2),
                           pb_ten=bond.tensile_strength, pb_coh=bond.shear_strength, pb_fa=np.zeros_like(pb_kn),
                           pb_mcf=np.ones_like(pb_kn), emod=pb_kn * (r1 + r2), kratio=kratio)


def from_pfc(radius1, radius2, length, *, pb_rmul=1.0, pb_kn=None, pb_ks=None, emod=None, kratio=None,
             pb_ten=np.inf, pb_coh=np.inf, pb_fa=0.0, pb_mcf=1.0) -> JaxbpmBond:
    """PFC linear parallel bond -> jaxbpm. Give ``pb_kn``/``pb_ks`` or ``emod``/``kratio`` (deformability method,
    L_pfc = R1 + R2). pb_fa != 0 or pb_mcf != 1 are not part of the translated bond (warned, with the size of the
    difference); the DEM models them through its params ``bond_friction_angle`` and ``bond_moment_factor``."""
    r1, r2, length = _positive("radius1", radius1), _positive("radius2", radius2), _positive("length", length)
    if emod is not None or kratio is not None:
        if emod is None or kratio is None or pb_kn is not None or pb_ks is not None:
            raise ConventionError("PFC: give either pb_kn and pb_ks, or emod and kratio (deformability method)")
        pb_kn = _positive("emod", emod) / (r1 + r2)
        pb_ks = pb_kn / _positive("kratio", kratio)
    elif pb_kn is None or pb_ks is None:
        raise ConventionError("PFC: give either pb_kn and pb_ks, or emod and kratio (deformability method)")
    pb_kn, pb_ks = _positive("pb_kn", pb_kn), _positive("pb_ks", pb_ks)
    nu = _nu_from_ratio(pb_ks / pb_kn, "PFC (kratio = pb_kn/pb_ks must be < 3)")
    rb = _positive("pb_rmul", pb_rmul) * np.minimum(r1, r2)
    fa, mcf, coh = _f(pb_fa), _f(pb_mcf), _strength("pb_coh", pb_coh)
    if np.any(fa != 0) and np.any(np.isfinite(coh)):
        tan = float(np.max(np.abs(np.tan(np.radians(fa)))))
        _warn(f"PFC pb_fa = {float(np.max(np.abs(fa))):.6g} deg is not part of the translated bond: its shear "
              f"strength does not depend on the normal stress. Pure tension and pure shear are exact; shear under a "
              f"normal stress sigma_n differs by -sigma_n tan(pb_fa) / pb_coh = -{tan:.4g} sigma_n / pb_coh (a "
              f"tensile stress of half pb_coh: {-50 * tan:.3g} %). The DEM models it: params "
              f"bond_friction_angle = radians(pb_fa)")
    if np.any(mcf != 1):
        beta = float(np.min(mcf))
        _warn(f"PFC pb_mcf = {beta:.6g} is not part of the translated bond, which counts the full moments (pb_mcf = "
              f"1). Pure tension and pure shear are exact; pure bending and pure twist break at {beta:.4g} x PFC's "
              f"moment ({100 * (beta - 1):.3g} %). The DEM models it: params bond_moment_factor = pb_mcf")
    return JaxbpmBond(pb_kn * length, nu, rb, _strength("pb_ten", pb_ten), coh)


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
        """LAMMPS's stiffnesses: Kr, Ks (divided by the reference length r0 with ``normalize yes``), Kt, Kb."""
        scale = 1.0 / _f(length) if self.normalize else 1.0
        return BondStiffness(_f(self.Kr) * scale, _f(self.Ks) * scale, _f(self.Kt), _f(self.Kb))

    def coefficients(self) -> np.ndarray:
        """``[nb, 8]`` rows Kr Ks Kt Kb Fcr Fcs Tct Tcb (the order of ``bond_coeff``, before the dampings)."""
        cols = np.broadcast_arrays(*(_f(getattr(self, k)) for k in ("Kr", "Ks", "Kt", "Kb", "Fcr", "Fcs", "Tct",
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
    """jaxbpm -> LAMMPS ``bpm/rotational`` (stiffness exact; strengths exact when they were calibrated under
    ``failure_rule="summed"``, LAMMPS's rule; under another rule the difference is warned about when a strength is
    finite)."""
    k = bond.stiffness(length)
    length = _f(length)
    scale = length if normalize else 1.0
    sig, tau, rb = bond.tensile_strength, bond.shear_strength, bond.bond_radius
    finite = np.any(np.isfinite(sig)) or np.any(np.isfinite(tau))
    if finite and check_failure_rule(failure_rule, ConventionError) != "summed":
        _warn(_SUMMED_RULE)
    return LammpsBpmRotational(Kr=k.kn * scale, Ks=k.kt * scale, Kt=k.ktw, Kb=k.kb, Fcr=sig * bond.area,
                               Fcs=tau * bond.area, Tct=tau * bond.polar / rb, Tcb=sig * bond.inertia / rb,
                               normalize=normalize)


def from_lammps(p: LammpsBpmRotational, length, *, breaking: bool = True,
                failure_rule: str = "separate") -> JaxbpmBond:
    """LAMMPS ``bpm/rotational`` -> jaxbpm. ``breaking=False`` (LAMMPS's ``break no``) ignores the thresholds.

    Warned: a Kt that jaxbpm's law cannot match (see :func:`from_stiffness`), thresholds whose bending/twisting
    limits disagree with the tensile/shear ones, and the summed failure rule unless ``failure_rule="summed"`` (the
    rule the jaxbpm scenes will break these bonds by).
    """
    k = p.stiffness(length)
    E, nu, rb = from_stiffness(k.kn, k.kt, k.ktw, k.kb, length, what="LAMMPS bpm/rotational")
    if not breaking:
        return JaxbpmBond(E, nu, rb)
    area, inertia, polar = np.pi * rb**2, np.pi * rb**4 / 4.0, np.pi * rb**4 / 2.0
    sig = _positive("Fcr", p.Fcr) / area
    tau = _positive("Fcs", p.Fcs) / area
    for name, limit, law in (("Tcb", p.Tcb, sig * inertia / rb), ("Tct", p.Tct, tau * polar / rb)):
        off = _max_rel(law, _positive(name, limit))
        if off > _REL:
            _warn(f"LAMMPS {name} cannot be represented exactly: jaxbpm's strengths fix it at "
                  f"{'sigma_t I / r_b = Fcr r_b / 4' if name == 'Tcb' else 'tau_c J / r_b = Fcs r_b / 2'}, which "
                  f"differs from the given one by up to {100 * off:.3g} % (pure "
                  f"{'bending' if name == 'Tcb' else 'twist'} breaks at that moment in jaxbpm)")
    if check_failure_rule(failure_rule, ConventionError) != "summed":
        _warn(_SUMMED_RULE)
    return JaxbpmBond(E, nu, rb, sig, tau)


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
        computes it: kn, ks, kr, ktw [N/m, N m/rad] and normalAdhesion, shearAdhesion [N], rollingAdhesion,
        twistingAdhesion [N m]."""
        r1, r2 = _f(radius1), _f(radius2)
        E, v = _f(self.young), _f(self.poisson)
        kn = 2.0 * E * r1 * E * r2 / (E * r1 + E * r2)  # harmonic mean of E_a R_a and E_b R_b
        ks = 2.0 * E * r1 * v * E * r2 * v / (E * r1 * v + E * r2 * v)
        rmin = np.minimum(r1, r2)
        roll = self.normalCohesion if self.rollingCohesion is None else self.rollingCohesion
        twist = self.shearCohesion if self.twistingCohesion is None else self.twistingCohesion
        return {"kn": kn, "ks": ks, "kr": r1 * r2 * ks * _f(self.alphaKr), "ktw": r1 * r2 * ks * _f(self.alphaKtw),
                "normalAdhesion": _f(self.normalCohesion) * rmin**2, "shearAdhesion": _f(self.shearCohesion) * rmin**2,
                "rollingAdhesion": 0.25 * _f(roll) * rmin**3, "twistingAdhesion": 0.5 * _f(twist) * rmin**3}

    def stiffness(self, radius1, radius2) -> BondStiffness:
        """Yade's stiffnesses (k_n, k_s, k_tw, k_r as k_b) from its own formulas."""
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
    """jaxbpm -> Yade CohFrictMat values for each bond (stiffness exact per bond; Yade's materials belong to
    particles, so one material reproduces all bonds only where the per-bond values agree)."""
    k = bond.stiffness(length)
    r1, r2 = _positive("radius1", radius1), _positive("radius2", radius2)
    young = k.kn * (r1 + r2) / (2.0 * r1 * r2)
    poisson = k.kt / k.kn
    rmin, rb = np.minimum(r1, r2), bond.bond_radius
    sig, tau = bond.tensile_strength, bond.shear_strength
    finite = np.any(np.isfinite(sig)) or np.any(np.isfinite(tau))
    if finite and check_failure_rule(failure_rule, ConventionError) != "max":
        _warn(_MAX_RULE)
    return YadeCohFrict(young=young, poisson=poisson, alphaKr=k.kb / (r1 * r2 * k.kt),
                        alphaKtw=k.ktw / (r1 * r2 * k.kt), normalCohesion=sig * bond.area / rmin**2,
                        shearCohesion=tau * bond.area / rmin**2,
                        rollingCohesion=4.0 * sig * bond.inertia / rb / rmin**3,
                        twistingCohesion=2.0 * tau * bond.polar / rb / rmin**3)


def from_yade(p: YadeCohFrict, radius1, radius2, length, *, failure_rule: str = "separate") -> JaxbpmBond:
    """Yade CohFrictMat (one material for both particles) -> jaxbpm, per bond (the separate-checks rule is warned
    about unless ``failure_rule="max"``, the rule the jaxbpm scenes will break these bonds by)."""
    ph = p.phys(_positive("radius1", radius1), _positive("radius2", radius2))
    E, nu, rb = from_stiffness(ph["kn"], ph["ks"], ph["ktw"], ph["kr"], length, what="Yade CohFrictMat")
    area, inertia, polar = np.pi * rb**2, np.pi * rb**4 / 4.0, np.pi * rb**4 / 2.0
    sig = _strength("normalCohesion", ph["normalAdhesion"]) / area
    tau = _strength("shearCohesion", ph["shearAdhesion"]) / area
    for name, limit, law in (("rollingCohesion", ph["rollingAdhesion"], sig * inertia / rb),
                             ("twistingCohesion", ph["twistingAdhesion"], tau * polar / rb)):
        off = _max_rel(law, limit)
        if off > _REL:
            _warn(f"Yade {name} cannot be represented exactly: jaxbpm's strengths fix the "
                  f"{'bending' if name.startswith('rolling') else 'twisting'} failure moment, which differs from "
                  f"Yade's by up to {100 * off:.3g} %")
    finite = np.any(np.isfinite(sig)) or np.any(np.isfinite(tau))
    if finite and check_failure_rule(failure_rule, ConventionError) != "max":
        _warn(_MAX_RULE)
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
        return _f(self.young_modulus) / (2.0 * (1.0 + _f(self.poisson_ratio)))

    def stiffness(self, initial_length) -> BondStiffness:
        """MUSEN's stiffnesses: E A / L, G A / L, 2 I G / L (normal moment), E I / L (tangential moment), with
        A = pi d^2 / 4 (CrossCut) and I = pi d^4 / 64 (AxialMoment)."""
        d, L = _f(self.diameter), _f(initial_length)
        cross_cut, axial_moment = np.pi * d**2 / 4.0, np.pi * d**4 / 64.0
        E, G = _f(self.young_modulus), self.shear_modulus
        return BondStiffness(E * cross_cut / L, G * cross_cut / L, 2.0 * axial_moment * G / L, E * axial_moment / L)


def to_musen(bond: JaxbpmBond) -> MusenSolidBond:
    """jaxbpm -> MUSEN elastic solid bond (exact; MUSEN's breakage criterion 1 is jaxbpm's rule)."""
    return MusenSolidBond(2.0 * bond.bond_radius, bond.E, bond.nu, bond.tensile_strength, bond.shear_strength)


def from_musen(p: MusenSolidBond, *, criterion: int = 1) -> JaxbpmBond:
    """MUSEN elastic solid bond -> jaxbpm. ``criterion`` is MUSEN's CONSIDER_BREAKAGE (1: standard, jaxbpm's rule;
    2: separate checks, warned; 0: no breakage)."""
    if criterion not in (0, 1, 2):
        raise ConventionError(f"MUSEN CONSIDER_BREAKAGE must be 0, 1 or 2, got {criterion!r}")
    if criterion == 0:
        return JaxbpmBond(p.young_modulus, p.poisson_ratio, _f(p.diameter) / 2.0)
    if criterion == 2:
        _warn("MUSEN criterion 2 checks tension, bending (in tension only), shear and twist separately; jaxbpm adds "
              "tension and bending, and shear and twist (MUSEN's criterion 1). Pure tension, shear, bending and "
              "twist break at the same load (0 %); tension plus bending at equal utilisation breaks at twice the load "
              "with criterion 2 (+100 %), in general at max(a+b, c+d)/max(a, b, c, d) of jaxbpm's failure load")
    return JaxbpmBond(p.young_modulus, p.poisson_ratio, _f(p.diameter) / 2.0, p.normal_strength,
                      p.tangential_strength)


# ---------------------------------------------------------------------------------------------- failure rules
def failure_index(rule: str, normal, shear, twist, bend, bond: JaxbpmBond):
    """Failure index of a bond under forces (normal ``F_n`` > 0 in tension, ``|F_t|``, ``|M_tw|``, ``|M_b|``) by
    ``rule`` ("jaxbpm", "lammps", "yade"), all with thresholds translated from ``bond``'s strengths; >= 1 breaks.

    Used to state and test the differences between the rules (see the module docstring).
    """
    rb = bond.bond_radius
    u_n = _f(normal) / (bond.tensile_strength * bond.area)
    u_b = np.abs(_f(bend)) / (bond.tensile_strength * bond.inertia / rb)
    u_s = np.abs(_f(shear)) / (bond.shear_strength * bond.area)
    u_t = np.abs(_f(twist)) / (bond.shear_strength * bond.polar / rb)
    if rule == "jaxbpm":
        return np.maximum(u_n + u_b, u_s + u_t)
    if rule == "lammps":
        return np.maximum(u_n + u_b + u_s + u_t, 0.0)
    if rule == "yade":
        return np.maximum.reduce([u_n, u_b, u_s, u_t])
    raise ConventionError(f"unknown failure rule {rule!r}; expected 'jaxbpm', 'lammps' or 'yade'")


def _to_jaxbpm(name: str, values: dict[str, Any], length, r1, r2) -> JaxbpmBond:
    if name == "jaxbpm":
        return JaxbpmBond(**values)
    if name == "pfc":
        return from_pfc(r1, r2, length, **values)
    if name == "lammps":
        coeffs = {k: v for k, v in values.items() if k != "normalize"}
        return from_lammps(LammpsBpmRotational(**coeffs, normalize=bool(values.get("normalize", 0.0))), length)
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
            normalize: bool = False):
    """Translate one bond's parameters ``values`` (names of ``CONVENTIONS[source]``) into ``target``'s dataclass,
    for particles of radii ``radius1``, ``radius2`` and initial centre distance ``length`` (default R1 + R2).

    ``normalize`` applies to a LAMMPS target. Unknown or missing parameter names raise :class:`ConventionError`.
    """
    for name in (source, target):
        if name not in CONVENTIONS:
            raise ConventionError(f"unknown convention {name!r}; expected one of {sorted(CONVENTIONS)}")
    spec = CONVENTIONS[source]["params"]
    unknown = sorted(set(values) - set(spec))
    if unknown:
        raise ConventionError(f"{source}: unknown parameters {unknown}; known: {list(spec)}")
    r1, r2 = _positive("radius1", radius1), _positive("radius2", radius2)
    length = r1 + r2 if length is None else _positive("length", length)
    given = {k: v for k, v in values.items() if v is not None}
    if source == "jaxbpm":
        ratio = given.pop("bond_radius_ratio", None)
        if ("bond_radius" in given) == (ratio is not None):
            raise ConventionError("jaxbpm: give exactly one of bond_radius and bond_radius_ratio")
        if ratio is not None:
            given["bond_radius"] = _f(ratio) * np.minimum(r1, r2)
    either = {"pfc": {"pb_kn", "pb_ks", "emod", "kratio"}, "jaxbpm": {"bond_radius", "bond_radius_ratio"},
              "yade": {"rollingCohesion", "twistingCohesion"}}.get(source, set())
    missing = [k for k, d in spec.items() if d is None and k not in given and k not in either]
    if missing:
        raise ConventionError(f"{source}: missing parameters {missing} ({CONVENTIONS[source]['doc']})")
    bond = _to_jaxbpm(source, given, length, r1, r2)
    return _from_jaxbpm(target, bond, length, r1, r2, normalize=normalize)
