"""PFC's parameter names both ways (jaxbpm.interop.pfc): the round trip, the translated values against PFC's own
stiffness formulas, and the named errors."""

import math
import warnings

import numpy as np
import pytest

import jaxbpm
from jaxbpm.errors import ConventionError
from jaxbpm.interop._translation import InexactTranslationWarning
from jaxbpm.interop.pfc import PFC_NAMES, PFCNameError, from_pfc, to_pfc
from jaxbpm.physics.bond import stiffness
from jaxbpm.physics.linear import normal_stiffness

R = 1e-3
QU = {"emod": 211e9, "kratio": 1.21, "fric": 0.7, "pb_emod": 211e9, "pb_kratio": 1.21, "pb_ten": 5e9,
      "pb_coh": 7.8e8, "pb_fa": 30.0, "pb_mcf": 0.8}  # Qu et al. 2020, Table 3 (pb_fa, pb_mcf added)


def _sample(ratio=0.5, gap=0.0):
    pos = np.array([[0, 0, 0], [2 * R + gap, 0, 0], [4 * R + 2 * gap, 0, 0]])
    return jaxbpm.Sample.from_arrays(pos, R, [[0, 1], [1, 2]], bond_radius_ratio=ratio,
                                     materials={"E": 1e9, "nu": 0.25})


def test_round_trip_both_ways():
    params = from_pfc(QU)
    back = to_pfc(params)
    assert set(back) == set(QU)
    for name, v in QU.items():
        np.testing.assert_allclose(back[name], v, rtol=1e-14, err_msg=name)
    again = from_pfc(back)
    for key, v in params.items():
        np.testing.assert_allclose(np.asarray(again[key]), np.asarray(v), rtol=1e-14, err_msg=key)
    # several bond materials: a list each way
    two = from_pfc({"pb_emod": [1e9, 2e9], "pb_kratio": 2.6})
    assert to_pfc(two) == {"pb_emod": [1e9, 2e9], "pb_kratio": pytest.approx(2.6, rel=1e-14)}


def test_translated_values_give_pfc_stiffnesses_and_strength_rule():
    s = _sample(ratio=0.6)
    params = from_pfc({**QU, "pb_rmul": 0.6}, sample=s)
    assert set(params) == {PFC_NAMES[k] for k in QU}  # bond_E and bond_nu among them: a complete params dict
    # the bond: PFC's k_n = pb_emod A / (R1 + R2), k_s = k_n / pb_kratio, k_b = pb_emod I / L, k_tw = k_s J / A
    rb = 0.6 * R
    area, inertia, polar = math.pi * rb**2, math.pi * rb**4 / 4, math.pi * rb**4 / 2
    k = stiffness(float(params["bond_E"][0]), float(params["bond_nu"][0]), area, inertia, polar, 2 * R)
    kn_pfc = QU["pb_emod"] * area / (2 * R)
    np.testing.assert_allclose([float(k.kn), float(k.kt), float(k.kb), float(k.ktw)],
                               [kn_pfc, kn_pfc / QU["pb_kratio"], QU["pb_emod"] * inertia / (2 * R),
                                kn_pfc / QU["pb_kratio"] * polar / area], rtol=1e-12)
    # the contact: PFC's k_n = emod pi min(R)^2 / (R1 + R2)
    np.testing.assert_allclose(float(normal_stiffness(R, R, params["contact_emod"])),
                               QU["emod"] * math.pi * R**2 / (2 * R), rtol=1e-15)
    np.testing.assert_allclose(float(params["bond_friction_angle"][0]), math.radians(30.0), rtol=1e-15)
    # the sample's own bond radii give pb_rmul back
    assert math.isclose(to_pfc(params, sample=s)["pb_rmul"], 0.6, rel_tol=1e-12)
    # PFC's strengths belong to its separate tension and shear checks
    for rule in ("summed", "max"):
        with pytest.raises(PFCNameError, match=f"failure_rule={rule!r}"):
            from_pfc(QU, failure_rule=rule)
        with pytest.raises(PFCNameError, match="pb_ten"):
            to_pfc(params, failure_rule=rule)
    assert "bond_E" in from_pfc({"pb_emod": 1e9, "emod": 1e9}, failure_rule="summed")  # no strengths: fine


def test_unknown_names_and_values_without_counterpart_are_named():
    with pytest.raises(PFCNameError, match="unknown PFC parameter 'pb_kration'; did you mean 'pb_kratio'"):
        from_pfc({"pb_kration": 2.0})
    with pytest.raises(PFCNameError, match="'contact_E'.*no name"):
        to_pfc({"contact_E": 1e9})
    with pytest.raises(ConventionError, match="pb_kratio must be in \\(0, 3\\)"):
        from_pfc({"pb_kratio": 3.2})  # nu = 0.6: no jaxbpm bond
    with pytest.raises(ConventionError, match="pb_fa must be in \\[0, 90\\)"):
        from_pfc({"pb_fa": 95.0})
    with pytest.raises(ConventionError, match="pb_rmul sets the sample's bond radii"):
        from_pfc({"pb_rmul": 1.0})
    with pytest.raises(ConventionError, match="bond_radius_ratio=1"):
        from_pfc({"pb_rmul": 1.0}, sample=_sample(ratio=0.5))
    with pytest.raises(ConventionError, match="3 values for 1 bond materials"):
        from_pfc({"pb_emod": [1e9, 2e9, 3e9]}, sample=_sample())
    with pytest.raises(ConventionError, match="one number for all contacts"):
        from_pfc({"emod": [1e9, 2e9]})


def test_bond_gaps_are_warned_with_their_size():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        from_pfc({"pb_emod": 1e9}, sample=_sample())  # touching: exact, no warning
    with pytest.warns(InexactTranslationWarning, match="up to 2.44 %"):
        from_pfc({"pb_emod": 1e9}, sample=_sample(gap=0.05 * R))  # L = 2.05 R against R1 + R2 = 2 R


def test_2d_sample_pb_rmul_and_pfc2d_stiffness():
    """With a 2D disc sample (thickness t): pb_rmul is checked against its bond radii and returned; PFC2D's bond
    stiffness pb_emod A / (R1 + R2) with A = 2 r_b t equals the sample's bond_E A / L for touching discs."""
    sample = jaxbpm.generate.lattice("square", (4, 3)).replace(thickness=0.4)
    params = from_pfc({"pb_emod": 2e9, "pb_kratio": 2.5, "pb_rmul": 0.5, "pb_ten": 1e6, "pb_coh": 2e6},
                      sample=sample)
    assert to_pfc({k: params[k] for k in ("bond_E", "bond_nu")}, sample=sample) == {
        "pb_emod": 2e9, "pb_kratio": 2.5, "pb_rmul": 0.5}
    with pytest.raises(ConventionError, match="pb_rmul = 0.7"):
        from_pfc({"pb_rmul": 0.7}, sample=sample)
    b, rad = np.asarray(sample.bonds), np.asarray(sample.radii)
    rb = 0.5 * np.minimum(rad[b[:, 0]], rad[b[:, 1]])
    pfc_kn = 2e9 * (2 * rb * 0.4) / (rad[b[:, 0]] + rad[b[:, 1]])
    kn = np.asarray(params["bond_E"])[np.asarray(sample.bond_material)] * np.asarray(sample.bond_area) / np.asarray(
        sample.bond_length)
    np.testing.assert_allclose(kn, pfc_kn, rtol=1e-12)
