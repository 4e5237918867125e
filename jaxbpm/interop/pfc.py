"""PFC's parameter names, both ways: a dict of the properties of PFC's linear parallel-bond model (``linearpbond``:
the linear contact model of :mod:`jaxbpm.physics.linear` plus a parallel bond) to jaxbpm's ``params``
(:mod:`jaxbpm.physics.params`) and back.

=============  ==========================  ===============================================================
PFC            jaxbpm                      translation
=============  ==========================  ===============================================================
``emod``       ``contact_emod``            the same [Pa] (``contact_law="linear"``: k_n = emod A / L)
``kratio``     ``contact_kratio``          the same (k_n / k_s of the contacts)
``fric``       ``friction``                the same
``pb_emod``    ``bond_E``                  the same [Pa] (exact where a bond's length L is R1 + R2)
``pb_kratio``  ``bond_nu``                 ``nu = pb_kratio / 2 - 1`` (k_n / k_s = 2 (1 + nu)); pb_kratio < 3
``pb_ten``     ``bond_tensile_strength``   the same [Pa]
``pb_coh``     ``bond_shear_strength``     the same [Pa] (the cohesion c)
``pb_fa``      ``bond_friction_angle``     degrees -> radians (shear strength c - sigma tan(phi))
``pb_mcf``     ``bond_moment_factor``      the same
``pb_rmul``    the sample's bond radii     r_b = pb_rmul min(R1, R2): a property of the sample, checked
=============  ==========================  ===============================================================

PFC's bond strengths are those of its parallel bond, whose tensile and shear stresses are checked apart: jaxbpm's
``failure_rule="separate"`` (:data:`jaxbpm.physics.bond.FAILURE_RULES`). Under ``"summed"`` or ``"max"`` the same
numbers break bonds at other loads, so the translation refuses them (:class:`PFCNameError` names the rule).

PFC's deformability method takes L = R1 + R2 for both the contacts and the bonds; jaxbpm's bond stiffness is
``E A / L`` with L the bond's initial length (the centre distance when it was made), so ``pb_emod = bond_E`` is
exact for bonded particles that touch, and a bond gap g changes the bond's k_n by ``(R1 + R2) / (R1 + R2 + g)``
(with ``sample=``, an :class:`~jaxbpm.interop.conventions.InexactTranslationWarning` states the largest). The per-bond
translations of :mod:`jaxbpm.interop.conventions` (``from_pfc``, ``to_pfc`` there) are exact bond by bond.

Two-dimensional samples (PFC2D) take the same names and values: PFC's properties are moduli, ratios and stresses,
and PFC2D's parallel bond is jaxbpm's 2D bond, the ``2 r_b x t`` rectangle (``A = 2 r_b t``, ``I = (2 r_b)^3 t /
12``), so ``pb_emod A / (R1 + R2)`` is the bond's k_n in both. PFC2D's thickness is 1 m; jaxbpm's is the sample's
(``Sample.thickness``, default 1 m): forces scale with it, stresses and moduli do not. ``pb_rmul`` is checked
against a 2D sample's bond radii as in 3D. The linear contacts' ``emod`` enters with PFC2D's contact area per
unit thickness, ``2 min(R1, R2)`` (:func:`jaxbpm.physics.linear.contact_area`), i.e. for ``t = 1 m``.

Examples:
    >>> from jaxbpm.interop.pfc import from_pfc, to_pfc
    >>> params = from_pfc({"emod": 211e9, "kratio": 1.21, "pb_emod": 211e9, "pb_kratio": 2.5, "pb_ten": 5e9,
    ...                    "pb_coh": 7.8e8, "pb_fa": 0.0, "fric": 0.7})
    >>> float(params["bond_nu"][0]), float(params["contact_kratio"])
    (0.25, 1.21)
    >>> to_pfc(params)["pb_kratio"]
    2.5
    >>> from_pfc({"pb_emd": 1e9})  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    jaxbpm.interop.pfc.PFCNameError: unknown PFC parameter 'pb_emd'; did you mean 'pb_emod' ...
"""

from __future__ import annotations

import difflib
import math
from typing import Any

import numpy as np

from jaxbpm.errors import ConventionError
from jaxbpm.interop._translation import REL, max_rel, warn

__all__ = ["PFC_NAMES", "PFCNameError", "from_pfc", "to_pfc"]

#: PFC's name -> jaxbpm's params key (``pb_rmul`` -> ``None``: the sample's bond radii)
PFC_NAMES = {"emod": "contact_emod", "kratio": "contact_kratio", "fric": "friction", "pb_emod": "bond_E",
             "pb_kratio": "bond_nu", "pb_ten": "bond_tensile_strength", "pb_coh": "bond_shear_strength",
             "pb_fa": "bond_friction_angle", "pb_mcf": "bond_moment_factor", "pb_rmul": None}
_JAXBPM_NAMES = {v: k for k, v in PFC_NAMES.items() if v is not None}
_PER_MATERIAL = {"pb_emod", "pb_kratio", "pb_ten", "pb_coh", "pb_fa", "pb_mcf"}
_STRENGTHS = {"pb_ten", "pb_coh", "pb_fa", "pb_mcf"}


class PFCNameError(ConventionError):
    """A name with no counterpart on the other side (an unknown PFC parameter, a jaxbpm params key PFC's
    linear parallel-bond model does not have), or PFC's strengths under a failure rule that is not PFC's."""


def _unknown(name, known, side: str, why: str = "") -> PFCNameError:
    close = difflib.get_close_matches(name, known, n=2, cutoff=0.6) if isinstance(name, str) else []
    hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
    return PFCNameError(f"{side} {name!r}{why}{hint} (known: {', '.join(sorted(known))})")


def _check_rule(names, failure_rule: str):
    strengths = sorted(set(names) & _STRENGTHS)
    if strengths and failure_rule != "separate":
        raise PFCNameError(f"PFC's {', '.join(strengths)} are the strengths of its parallel bond, whose tension and "
                           f"shear are checked apart (failure_rule='separate'); under failure_rule={failure_rule!r} "
                           "they break bonds at other loads. Use failure_rule='separate', or translate per bond with "
                           "jaxbpm.interop.conventions")


def _value(name: str, v, ok, what: str) -> np.ndarray:
    try:
        arr = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConventionError(f"PFC {name} must be a number or a list of numbers (one per bond material), got "
                              f"{v!r}") from None
    if arr.ndim > 1 or not np.all(ok(arr)):
        raise ConventionError(f"PFC {name} must be {what}, got {v!r}")
    return arr


_CHECKS = {  # PFC name -> (check, what it must be, to jaxbpm, from jaxbpm)
    "emod": (lambda v: np.isfinite(v) & (v > 0), "finite and > 0 [Pa]", None, None),
    "kratio": (lambda v: np.isfinite(v) & (v > 0), "finite and > 0", None, None),
    "fric": (lambda v: np.isfinite(v) & (v >= 0), "finite and >= 0", None, None),
    "pb_emod": (lambda v: np.isfinite(v) & (v > 0), "finite and > 0 [Pa]", None, None),
    "pb_kratio": (lambda v: np.isfinite(v) & (v > 0) & (v < 3), "in (0, 3): k_n / k_s = 2 (1 + nu) with jaxbpm's "
                  "nu in (-1, 0.5)", lambda v: v / 2.0 - 1.0, lambda nu: 2.0 * (1.0 + nu)),
    "pb_ten": (lambda v: v >= 0, ">= 0 [Pa] (inf: never breaks)", None, None),
    "pb_coh": (lambda v: v >= 0, ">= 0 [Pa] (inf: never breaks)", None, None),
    "pb_fa": (lambda v: np.isfinite(v) & (v >= 0) & (v < 90), "in [0, 90) [deg]", np.radians, np.degrees),
    "pb_mcf": (lambda v: np.isfinite(v) & (v >= 0) & (v <= 1), "in [0, 1]", None, None),
}


def from_pfc(values, *, sample=None, failure_rule: str = "separate") -> dict:
    """jaxbpm's ``params`` from PFC's linear parallel-bond properties.

    Args:
        values: ``{PFC name: value}`` (the names of :data:`PFC_NAMES`); a bond property is a number (every bond
            material) or a list of one per bond material.
        sample: the sample the parameters are for, or ``None``. With a sample the result is complete (its
            :func:`~jaxbpm.physics.params.default_params` under the translated entries, checked by
            :func:`~jaxbpm.physics.params.check_params`), ``pb_rmul`` is checked against its bond radii, and bond
            lengths other than R1 + R2 are warned about.
        failure_rule: the failure rule of the scene the parameters are for (PFC's strengths need ``"separate"``).

    Returns:
        The params dict (without a sample: the translated entries alone; per-material entries as NumPy arrays,
        contact scalars as floats).

    Raises:
        PFCNameError: an unknown name (the message suggests the closest), or strengths under another rule.
        ConventionError: a value out of its range (``pb_kratio >= 3``: no jaxbpm Poisson's ratio), ``pb_rmul``
            without a sample or unlike the sample's bond radii.
    """
    for name in values:
        if name not in PFC_NAMES:
            raise _unknown(name, PFC_NAMES, "unknown PFC parameter")
    _check_rule(values, failure_rule)
    n_mat = None if sample is None else sample.n_materials
    out: dict[str, Any] = {}
    for name, v in values.items():
        if name == "pb_rmul":
            _check_rmul(v, sample)
            continue
        ok, what, forward, _ = _CHECKS[name]
        arr = _value(name, v, ok, what)
        arr = arr if forward is None else forward(arr)
        if name in _PER_MATERIAL:
            if arr.ndim == 0:
                arr = np.full(1 if n_mat is None else n_mat, float(arr))
            elif n_mat is not None and arr.shape != (n_mat,):
                raise ConventionError(f"PFC {name}: {arr.size} values for {n_mat} bond materials")
            out[PFC_NAMES[name]] = arr
        elif arr.ndim:
            raise ConventionError(f"PFC {name} is one number for all contacts, got {v!r}")
        else:
            out[PFC_NAMES[name]] = float(arr)
    if sample is None:
        return out
    if "pb_emod" in values:
        _warn_lengths(sample)
    from jaxbpm.physics.params import check_params, default_params

    return check_params({**default_params(sample), **out}, sample)


def to_pfc(params, *, sample=None, failure_rule: str = "separate") -> dict:
    """PFC's linear parallel-bond properties from jaxbpm's ``params``.

    Args:
        params: a params dict (:mod:`jaxbpm.physics.params`) with keys of :data:`PFC_NAMES`' values.
        sample: with a sample, ``pb_rmul`` too (its bond radius over the smaller particle's radius, which must be
            one number for all bonds).
        failure_rule: the failure rule the strengths were calibrated under (PFC's need ``"separate"``).

    Returns:
        ``{PFC name: value}``: floats, or lists of one per bond material where there are several.

    Raises:
        PFCNameError: a params key PFC's model has no name for (e.g. Hertz-Mindlin's ``contact_E``), or strengths
            under another rule.
        ConventionError: bond radii that are not one multiple of the smaller radius.
    """
    for key in params:
        if key not in _JAXBPM_NAMES:
            raise _unknown(key, _JAXBPM_NAMES, "jaxbpm params key",
                           ": PFC's linear parallel-bond model has no name for it")
    _check_rule([_JAXBPM_NAMES[k] for k in params], failure_rule)
    out: dict[str, Any] = {}
    for key, v in params.items():
        name = _JAXBPM_NAMES[key]
        back = _CHECKS[name][3]
        arr = np.asarray(v, dtype=np.float64)
        arr = arr if back is None else back(arr)
        out[name] = arr.item() if arr.size == 1 else [float(x) for x in arr.ravel()]
    if sample is not None and sample.n_bonds:
        out["pb_rmul"] = _rmul(sample)
    return out


def _rmul(sample) -> float:
    """The sample's one bond radius multiplier."""
    b, rad = np.asarray(sample.bonds), np.asarray(sample.radii, np.float64)
    ratio = np.asarray(sample.bond_radius, np.float64) / np.minimum(rad[b[:, 0]], rad[b[:, 1]])
    if max_rel(ratio, np.full_like(ratio, ratio[0])) > REL:
        raise ConventionError(f"PFC pb_rmul is one number; this sample's bond radii are {ratio.min():.6g} to "
                              f"{ratio.max():.6g} x the smaller particle's radius")
    return float(ratio[0])


def _check_rmul(v, sample):
    rmul = float(_value("pb_rmul", v, lambda x: np.isfinite(x) & (x > 0), "finite and > 0"))
    if sample is None:
        raise ConventionError("PFC pb_rmul sets the sample's bond radii (r_b = pb_rmul min(R1, R2)), not a "
                              "parameter: build the sample with bond_radius_ratio=pb_rmul, and pass sample= to check "
                              "it")
    if sample.n_bonds and not math.isclose(_rmul(sample), rmul, rel_tol=REL):
        raise ConventionError(f"PFC pb_rmul = {rmul:.6g}, but this sample's bonds have {_rmul(sample):.6g}: use "
                              f"sample.replace(bond_radius_ratio={rmul:.6g})")


def _warn_lengths(sample):
    """Warn when bond lengths differ from R1 + R2 (PFC's L of ``pb_emod``)."""
    if not sample.n_bonds:
        return
    b, rad = np.asarray(sample.bonds), np.asarray(sample.radii, np.float64)
    off = max_rel(rad[b[:, 0]] + rad[b[:, 1]], np.asarray(sample.bond_length, np.float64))
    if off > REL:
        warn(f"PFC pb_emod: PFC's bond stiffness is pb_emod A / (R1 + R2), jaxbpm's bond_E A / L with L the bond's "
             f"initial length; this sample's bonds (gaps between the particles) differ from R1 + R2 by up to "
             f"{100 * off:.3g} %, and so do their normal and shear stiffnesses")
