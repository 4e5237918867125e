"""The jaxbpm side of the translations (jaxbpm.interop._translation): the bond's sections and stiffnesses (closed
forms), parameters back from stiffnesses, checks."""

import numpy as np
import pytest

from jaxbpm.errors import ConventionError
from jaxbpm.interop import _translation as tr


def test_sections_and_stiffness_closed_forms():
    bond = tr.JaxbpmBond(E=2e9, nu=0.25, bond_radius=[1e-3, 2e-3])
    r = np.array([1e-3, 2e-3])
    np.testing.assert_allclose(bond.area, np.pi * r**2, rtol=1e-15)
    np.testing.assert_allclose(bond.inertia, np.pi * r**4 / 4, rtol=1e-15)
    np.testing.assert_allclose(bond.polar, np.pi * r**4 / 2, rtol=1e-15)
    k = bond.stiffness(3e-3)
    np.testing.assert_allclose(k.kn, 2e9 * np.pi * r**2 / 3e-3, rtol=1e-14)
    np.testing.assert_allclose(k.kt, 2e9 * np.pi * r**2 / (2 * 3e-3 * 1.25), rtol=1e-14)
    np.testing.assert_allclose(k.kb, 2e9 * np.pi * r**4 / 4 / 3e-3, rtol=1e-14)
    E, nu, rb = tr.from_stiffness(*k, 3e-3)
    np.testing.assert_allclose(E, 2e9, rtol=1e-12)
    np.testing.assert_allclose(nu, 0.25, rtol=1e-12)
    np.testing.assert_allclose(rb, r, rtol=1e-12)


def test_checks_and_warnings():
    with pytest.raises(ConventionError, match="nu must lie in"):
        tr.JaxbpmBond(1e9, 0.5, 1e-3)
    with pytest.raises(ConventionError, match="bond_radius must be > 0"):
        tr.JaxbpmBond(1e9, 0.2, 0.0)
    with pytest.raises(ConventionError, match=r"k_t/k_n > 1/3"):
        tr.nu_from_ratio(0.3, "test")
    np.testing.assert_allclose(tr.nu_from_ratio(1 / 2.5, "test"), 0.25, rtol=1e-14)
    assert tr.max_rel([1.0, np.inf], [1.0, np.inf]) == 0.0 and np.isclose(tr.max_rel(1.1, 1.0), 0.1)
    with pytest.warns(tr.InexactTranslationWarning, match="differs"):
        tr.warn("the twisting stiffness differs")
