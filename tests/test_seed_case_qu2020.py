"""The specimens of ``benchmarks/seed_case_qu2020.py --2d`` (Qu et al. 2020's SiC in 2D) at a hundredth of the paper's
sizes: counts, radii, bond gaps, proportions, the rollers of the bending test, and the PFC translation of Table 3."""

import importlib.util
import pathlib
import sys

import numpy as np
import pytest

BENCH = pathlib.Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture(scope="module")
def case():
    sys.path.insert(0, str(BENCH))
    try:
        spec = importlib.util.spec_from_file_location("seed_case_qu2020_2d", BENCH / "seed_case_qu2020_2d.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module  # the scene's dataclass resolves its annotations there
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.path.remove(str(BENCH))
        sys.modules.pop("seed_case_qu2020_2d", None)


def _gaps(positions, radii, pairs):
    d = np.linalg.norm(positions[pairs[:, 1]] - positions[pairs[:, 0]], axis=1)
    return d - radii[pairs[:, 0]] - radii[pairs[:, 1]]


def test_the_ucs_specimen_has_table_3s_discs_and_bonds(case):
    n = case.PAPER_COUNTS["ucs"] // 100
    s, scene = case.ucs_specimen(n, seed=3)
    x, r = np.asarray(s.positions), np.asarray(s.radii)
    assert s.dim == 2 and s.thickness == 1.0 and 0.98 * n <= s.n_particles <= n
    assert r.min() >= 4.5e-6 * (1 - 1e-12) and r.max() <= 6.75e-6 * (1 + 1e-12)
    gap = _gaps(x, r, np.asarray(s.bonds))
    assert gap.max() <= case.BOND_GAP * (1 + 1e-9) and gap.min() > -1e-3 * 5.625e-6  # bonded within the gap
    lo, hi = (x - r[:, None]).min(0), (x + r[:, None]).max(0)
    assert abs((hi[1] - lo[1]) / (hi[0] - lo[0]) - 2.0) < 0.1  # height 2 x width
    assert scene.axis == 1 and scene.breakage and scene.contacts
    # the bond radius is the smaller disc's (pb_rmul = 1)
    b = np.asarray(s.bonds)
    np.testing.assert_allclose(np.asarray(s.bond_radius), np.minimum(r[b[:, 0]], r[b[:, 1]]), rtol=1e-12)


def test_the_beam_rests_on_rollers_that_touch_it(case):
    n = case.PAPER_COUNTS["tpb"] // 100
    beam, scene = case.beam_specimen(n, seed=4)
    assert 0.98 * n <= beam.n_particles <= n and scene.rollers and scene.contacts
    s, bound = scene.stage(beam)  # what jaxbpm.solve runs: the beam with the scene's three rollers last
    nb = beam.n_particles
    x, r = np.asarray(s.positions), np.asarray(s.radii)
    assert s.n_particles == nb + 3 and np.all(r[nb:] == case.ROLLER * case.R_MEAN)
    lo, hi = (x[:nb] - r[:nb, None]).min(0), (x[:nb] + r[:nb, None]).max(0)
    length, height = hi - lo
    assert abs(length / height - 25.0 / 3.0) < 0.5  # ASTM C1161 configuration A's proportions
    assert scene.span == pytest.approx(0.8 * length, rel=1e-12)
    for k, below in zip(range(3), (True, True, False)):  # each roller touches the beam, overlapping none
        pairs = np.stack([np.full(nb, nb + k), np.arange(nb)], axis=1)
        gap = _gaps(x, r, pairs)
        assert abs(gap.min()) < 1e-9 * case.R_MEAN
        assert (x[nb + k, 1] < lo[1]) == below and (x[nb + k, 1] > hi[1]) == (not below)
    np.testing.assert_allclose(x[nb:nb + 2, 0], 0.5 * (lo[0] + hi[0]) + np.array([-0.5, 0.5]) * scene.span)
    # no bond joins a roller to the beam: they touch through the linear contacts alone
    assert s.n_bonds == beam.n_bonds and np.asarray(s.bonds).max() < nb
    # the scene measures the beam, not the rollers: sigma_f = 3 F S / (2 t h^2)
    assert bound.dimensions(s) == (pytest.approx(0.8 * length), 1.0, pytest.approx(height))
    assert bound.strength(2.0, s) == pytest.approx(3 * 2.0 * 0.8 * length / (2 * height**2))
    supports, punch = bound.layers(s)
    assert list(np.flatnonzero(supports)) == [nb, nb + 1] and list(np.flatnonzero(punch)) == [nb + 2]


def test_table_3_in_pfc_names(case):
    s, _ = case.ucs_specimen(200, seed=1)
    p = case.params_for(s, 1.26e9, 2.83e9)
    assert float(p["bond_nu"][0]) == pytest.approx(1.21 / 2 - 1)
    assert float(p["bond_E"][0]) == 211e9 and p["contact_emod"] == 211e9 and p["contact_kratio"] == 1.21
    assert float(p["bond_tensile_strength"][0]) == 1.26e9 and float(p["bond_shear_strength"][0]) == 2.83e9
    law = case.contact_law()
    assert (law.emod, law.kratio, law.friction) == (211e9, 1.21, 0.7)
