"""Bond parameter conventions (PFC, LAMMPS, Yade, MUSEN): exact translations to and from jaxbpm's bond law, stated
differences of the failure rules, and what has no counterpart."""

import dataclasses
import warnings

import jax.numpy as jnp
import numpy as np
import pytest

from jaxbpm.interop import conventions
from jaxbpm.interop.conventions import InexactTranslationWarning, JaxbpmBond
from jaxbpm.errors import ConventionError
from jaxbpm.physics.bond import bond_law


# one bond of unequal particles that neither touch (L != R1 + R2) nor have r_b = min(R): nothing cancels by accident
R1, R2, L = 1.0e-3, 1.3e-3, 2.45e-3
BOND = JaxbpmBond(E=2.7e9, nu=0.21, bond_radius=0.62e-3, tensile_strength=4e6, shear_strength=7e6)



# ============================================================================================== conventions
def _measured_stiffness(bond: JaxbpmBond, length: float) -> np.ndarray:
    """k_n, k_t, k_tw, k_b from the forces of jaxbpm's bond law under small prescribed motions (central
    differences: the O(eps^2) error is below round-off at eps = 1e-6)."""
    k = bond.stiffness(length)
    kn, kt, ktw, kb = (jnp.asarray(float(v)) for v in k)
    n = np.array([2.0, -1.0, 0.5])
    n /= np.linalg.norm(n)
    t = np.cross(n, [0.0, 0.0, 1.0])
    t /= np.linalg.norm(t)
    r0 = length * n
    ident = jnp.array([1.0, 0.0, 0.0, 0.0])

    def quat(axis, angle):
        return jnp.asarray(np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis]))

    def forces(dx, q_j):
        return bond_law(jnp.asarray(r0 + dx), jnp.asarray(r0), ident, q_j, kn, kt, ktw, kb)

    eps = 1e-6
    out = []
    for probe in ("stretch", "shear", "twist", "bend"):
        vals = []
        for s in (+1.0, -1.0):
            if probe == "stretch":
                f = forces(s * eps * length * n, ident)
                vals.append(float(jnp.dot(f.f_i, n)))
            elif probe == "shear":
                f = forces(s * eps * length * t, ident)
                vals.append(float(jnp.dot(f.shear, t)))
            elif probe == "twist":
                vals.append(float(forces(np.zeros(3), quat(n, s * eps)).twist))
            else:
                vals.append(float(jnp.dot(forces(np.zeros(3), quat(t, s * eps)).bend, t)))
        scale = eps * length if probe in ("stretch", "shear") else eps
        out.append((vals[0] - vals[1]) / (2 * scale))
    return np.array(out)


def _their_stiffness(name: str, params) -> np.ndarray:
    """The other code's own stiffness formula applied to the translated parameters."""
    k = params.stiffness(R1, R2) if name in ("pfc", "yade") else params.stiffness(L)
    return np.array([float(v) for v in k])


TRANSLATE = {
    "pfc": lambda b: conventions.to_pfc(b, L, R1, R2),
    "lammps": lambda b: conventions.to_lammps(b, L),
    "lammps-normalize": lambda b: conventions.to_lammps(b, L, normalize=True),
    "yade": lambda b: conventions.to_yade(b, L, R1, R2),
    "musen": conventions.to_musen,
}
BACK = {
    "pfc": lambda p: conventions.from_pfc(R1, R2, L, pb_rmul=p.pb_rmul, pb_kn=p.pb_kn, pb_ks=p.pb_ks, pb_ten=p.pb_ten,
                                          pb_coh=p.pb_coh, pb_fa=p.pb_fa, pb_mcf=p.pb_mcf),
    "lammps": lambda p: conventions.from_lammps(p, L),
    "lammps-normalize": lambda p: conventions.from_lammps(p, L),
    "yade": lambda p: conventions.from_yade(p, R1, R2, L),
    "musen": conventions.from_musen,
}


@pytest.mark.parametrize("name", list(TRANSLATE))
def test_translated_convention_has_jaxbpm_stiffness(name):
    measured = _measured_stiffness(BOND, L)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", InexactTranslationWarning)  # strength rules; stiffness is exact
        params = TRANSLATE[name](BOND)
        theirs = _their_stiffness(name.split("-")[0], params)
        back = BACK[name](params)
    np.testing.assert_allclose(theirs, measured, rtol=1e-9)  # normal, shear, twisting, bending
    for f in dataclasses.fields(JaxbpmBond):  # and the translation is invertible
        if f.name == "thickness":
            assert back.thickness is None and BOND.thickness is None
            continue
        np.testing.assert_allclose(getattr(back, f.name), getattr(BOND, f.name), rtol=1e-12)


def test_failure_rules_stated_differences():
    b = BOND
    sig_force, tau_force = b.tensile_strength * b.area, b.shear_strength * b.area
    bend_limit = b.tensile_strength * b.inertia / b.bond_radius
    # translated thresholds make single-mode failure loads identical
    with pytest.warns(InexactTranslationWarning, match="half the load"):
        lmp = conventions.to_lammps(b, L)
    assert np.isclose(lmp.Fcr, sig_force) and np.isclose(lmp.Tcb, bend_limit)
    for rule in ("jaxbpm", "lammps", "yade"):
        assert np.isclose(conventions.failure_index(rule, sig_force, 0, 0, 0, b), 1.0)  # pure tension
        assert np.isclose(conventions.failure_index(rule, 0, tau_force, 0, 0, b), 1.0)  # pure shear
        assert np.isclose(conventions.failure_index(rule, 0, 0, 0, bend_limit, b), 1.0)  # pure bending
    # mixed: tension + shear at half their limits: LAMMPS breaks (index 1), jaxbpm at half (breaks at 2x the load)
    mixed = (0.5 * sig_force, 0.5 * tau_force, 0, 0)
    assert np.isclose(conventions.failure_index("lammps", *mixed, b), 1.0)
    assert np.isclose(conventions.failure_index("jaxbpm", *mixed, b), 0.5)
    # tension + bending at half: jaxbpm breaks, Yade (separate checks) only at twice the load
    tb = (0.5 * sig_force, 0, 0, 0.5 * bend_limit)
    assert np.isclose(conventions.failure_index("jaxbpm", *tb, b), 1.0)
    assert np.isclose(conventions.failure_index("yade", *tb, b), 0.5)


def test_the_dem_breaks_bonds_by_each_codes_rule():
    """jaxbpm's failure rules (the DEM's, in JAX) against the codes' rules as written here (NumPy), on random loads
    of a translated bond: the same bonds break, and a translation to the code whose rule was used warns of nothing."""
    import warnings

    import jax.numpy as jnp

    from jaxbpm.physics import bond as bond_mod

    b = BOND
    rng = np.random.default_rng(0)
    n = 4000
    limits = np.array([b.tensile_strength * b.area, b.shear_strength * b.area,
                       b.shear_strength * b.polar / b.bond_radius, b.tensile_strength * b.inertia / b.bond_radius])
    u = rng.uniform(0, 1.1, (n, 4)) * np.array([rng.choice([-1, 1], n), np.ones(n), np.ones(n), np.ones(n)]).T
    normal, shear, twist, bend = (u * limits).T
    strength = bond_mod.BondStrength(*(jnp.full(n, v) for v in (b.tensile_strength, b.shear_strength, 0.0,
                                                                 b.bond_radius, b.area, b.inertia, b.polar)))
    zero = jnp.zeros(n)
    for rule, code in (("separate", "jaxbpm"), ("summed", "lammps"), ("max", "yade")):
        mode = np.asarray(bond_mod.bond_failure(jnp.asarray(normal), (jnp.asarray(shear), zero, zero),
                                                jnp.asarray(twist), (zero, jnp.asarray(bend), zero), strength,
                                                rule)[0])
        index = conventions.failure_index(code, normal, shear, twist, bend, b)
        clear = np.abs(index - 1.0) > 1e-9
        np.testing.assert_array_equal(mode[clear] > 0, index[clear] >= 1.0, err_msg=rule)
        assert 0.05 < np.mean(mode > 0) < 0.95, rule  # the loads straddle the limit
    with warnings.catch_warnings():
        warnings.simplefilter("error", InexactTranslationWarning)
        conventions.to_lammps(b, L, failure_rule="summed")
        conventions.to_yade(b, L, R1, R2, failure_rule="max")
    with pytest.warns(InexactTranslationWarning, match="failure_rule='summed'"):
        conventions.to_lammps(b, L)
    with pytest.raises(ConventionError, match="unknown bond failure rule"):
        conventions.to_lammps(b, L, failure_rule="lammps")


def test_unrepresentable_parameters():
    with pytest.raises(ConventionError, match=r"k_t/k_n = 0\.3 .*nu = 0\.666667"):
        conventions.from_yade(conventions.YadeCohFrict(1e9, 0.3, 2.0, 2.0), R1, R2, L)
    with pytest.raises(ConventionError, match="k_t/k_n > 1/3"):
        conventions.from_pfc(R1, R2, L, emod=1e9, kratio=3.5)
    with pytest.warns(InexactTranslationWarning, match=r"twisting stiffness .* up to 20 %"):
        k = BOND.stiffness(L)
        conventions.from_lammps(conventions.LammpsBpmRotational(k.kn, k.kt, 1.25 * k.ktw, k.kb), L, breaking=False)
    with pytest.warns(InexactTranslationWarning, match="pb_fa"):
        conventions.from_pfc(R1, R2, L, emod=1e9, kratio=2.5, pb_coh=5e6, pb_fa=30.0)
    with pytest.warns(InexactTranslationWarning, match="pb_mcf = 0.5"):
        conventions.from_pfc(R1, R2, L, emod=1e9, kratio=2.5, pb_mcf=0.5)
    with pytest.raises(ConventionError, match="unknown parameters"):
        conventions.convert("pfc", "jaxbpm", {"pb_emod": 1.0}, radius1=R1, radius2=R2)


def test_convert_2d_bonds_pfc2d_to_lammps_and_back():
    """A PFC2D bond (thickness t) converted to LAMMPS: LAMMPS's stiffnesses equal PFC2D's own (pb_kn A, pb_ks A,
    pb_kn I with A = 2 r_b t, I = (2 r_b)^3 t / 12) and the strengths' single-mode loads (Fcr = pb_ten A,
    Tcb = pb_ten I / r_b); back to PFC exactly; Yade and MUSEN refuse 2D bonds."""
    t = 0.4
    pfc = {"pb_kn": 2.7e9 / L, "pb_ks": 2.7e9 / L / 2.42, "pb_rmul": 0.62e-3 / R1, "pb_ten": 4e6, "pb_coh": 7e6}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", InexactTranslationWarning)  # LAMMPS's summed rule
        lmp = conventions.convert("pfc", "lammps", pfc, radius1=R1, radius2=R2, length=L, thickness=t)
        back = conventions.convert("lammps", "pfc", dataclasses.asdict(lmp), radius1=R1, radius2=R2, length=L,
                                   thickness=t)
    theirs = conventions.PFCParallelBond(**pfc).stiffness(R1, R2, thickness=t)
    rb = 0.62e-3
    A, I = 2 * rb * t, (2 * rb) ** 3 * t / 12
    np.testing.assert_allclose([lmp.Kr, lmp.Ks, lmp.Kb], [theirs.kn, theirs.kt, theirs.kb], rtol=1e-12)
    np.testing.assert_allclose([lmp.Kr, lmp.Kb, lmp.Fcr, lmp.Tcb], [2.7e9 / L * A, 2.7e9 / L * I, 4e6 * A,
                                                                   4e6 * I / rb], rtol=1e-12)
    for k, v in pfc.items():
        np.testing.assert_allclose(getattr(back, k), v, rtol=1e-12)
    for target in ("yade", "musen"):
        with pytest.raises(ConventionError, match="no two-dimensional"):
            conventions.convert("pfc", target, pfc, radius1=R1, radius2=R2, length=L, thickness=t)
