"""Other codes' bond models (jaxbpm.interop._codes): their known factors against jaxbpm's law (closed forms)."""

import numpy as np
import pytest

from jaxbpm.interop import _codes
from jaxbpm.interop._translation import InexactTranslationWarning, JaxbpmBond


def test_known_factors():
    # Yade: equal touching spheres with r_b = R: young = pi/2 E, poisson = k_s/k_n = 1/(2(1+nu)), no pi in adhesion
    bond = JaxbpmBond(1e9, 0.25, 1e-3, tensile_strength=5e6)
    with pytest.warns(InexactTranslationWarning, match="separately"):
        y = _codes.to_yade(bond, 2e-3, 1e-3, 1e-3)
    assert np.isclose(y.young, np.pi / 2 * 1e9, rtol=1e-14) and np.isclose(y.poisson, 0.4, rtol=1e-14)
    assert np.isclose(y.normalCohesion, np.pi * 5e6, rtol=1e-14)
    # PFC deformability method: emod = E for touching particles, kratio = 2 (1 + nu)
    p = _codes.to_pfc(bond, 2e-3, 1e-3, 1e-3)
    assert np.isclose(p.emod, 1e9, rtol=1e-14) and np.isclose(p.kratio, 2.5) and p.pb_rmul == 1.0
    assert np.isclose(_codes.from_pfc(1e-3, 1e-3, 2e-3, emod=1e9, kratio=2.5).E, 1e9, rtol=1e-14)
    # LAMMPS normalize yes: Kr = E A
    lmp = _codes.to_lammps(JaxbpmBond(1e9, 0.25, 1e-3), 2e-3, normalize=True)
    assert np.isclose(lmp.Kr, 1e9 * np.pi * 1e-6, rtol=1e-14)


def test_each_code_round_trips_and_reports_the_stiffness_it_was_given():
    bond = JaxbpmBond(2.7e9, 0.21, 0.62e-3, tensile_strength=4e6, shear_strength=7e6)
    r1, r2, length = 1.0e-3, 1.3e-3, 2.45e-3
    want = bond.stiffness(length)
    lmp = _codes.to_lammps(bond, length, failure_rule="summed")
    musen = _codes.to_musen(bond)
    for back, k in ((_codes.from_lammps(lmp, length, failure_rule="summed"), lmp.stiffness(length)),
                    (_codes.from_musen(musen), musen.stiffness(length))):
        for name in ("E", "nu", "bond_radius", "tensile_strength", "shear_strength"):
            np.testing.assert_allclose(getattr(back, name), getattr(bond, name), rtol=1e-12)
        np.testing.assert_allclose(np.asarray(k), np.asarray(want), rtol=1e-12)


def test_2d_bonds_rectangular_section_and_codes_without_2d():
    """A 2D bond (thickness t) is the 2 r_b x t rectangle: LAMMPS's Kr, Kb, Fcr, Tcb from A = 2 r_b t and
    I = (2 r_b)^3 t / 12, inverted exactly with the thickness; PFC's per-area values equal the 3D ones; Yade and
    MUSEN, which have no disc form, refuse it."""
    rb, t, L = 0.5e-3, 0.3, 2e-3
    bond = JaxbpmBond(1e9, 0.25, rb, tensile_strength=2e6, shear_strength=3e6, thickness=t)
    A, I = 2 * rb * t, (2 * rb) ** 3 * t / 12
    with pytest.warns(InexactTranslationWarning):
        p = _codes.to_lammps(bond, L)
    np.testing.assert_allclose([p.Kr, p.Kb, p.Fcr, p.Tcb], [1e9 * A / L, 1e9 * I / L, 2e6 * A, 2e6 * I / rb],
                               rtol=1e-14)
    with pytest.warns(InexactTranslationWarning):
        back = _codes.from_lammps(p, L, thickness=t)
    for name in ("E", "nu", "bond_radius", "tensile_strength", "shear_strength"):
        np.testing.assert_allclose(getattr(back, name), getattr(bond, name), rtol=1e-12)
    assert back.thickness == t
    three = JaxbpmBond(1e9, 0.25, rb, tensile_strength=2e6, shear_strength=3e6)
    pfc2, pfc3 = _codes.to_pfc(bond, L, 1e-3, 1e-3), _codes.to_pfc(three, L, 1e-3, 1e-3)
    assert pfc2 == pfc3
    with pytest.raises(_codes.ConventionError, match="Yade.*no two-dimensional"):
        _codes.to_yade(bond, L, 1e-3, 1e-3)
    with pytest.raises(_codes.ConventionError, match="MUSEN.*no two-dimensional"):
        _codes.to_musen(bond)
