"""Generators: exact lattices, random packings (density, overlaps, walls, determinism), bonds and materials.

Every check compares against an independent computation (integer closed forms, O(n^2) distance loops) rather than
stored snapshots. Random packings are kept to a few hundred particles so the file runs in seconds.
"""

import logging

import jax
import numpy as np
import pytest

from jaxbpm import generate as g
from jaxbpm.errors import SampleError
from jaxbpm.sample import BondMaterials

R = 1e-3  # mean radius used throughout [m]
TOL = 1e-3  # default overlap tolerance, relative to R


# ------------------------------------------------------------------------------------------- independent helpers
def brute_gaps(pos, rad):
    """All pairs i < j and their surface gaps, by an O(n^2) loop over rows."""
    i, j = np.triu_indices(len(pos), k=1)
    return i, j, np.linalg.norm(pos[j] - pos[i], axis=1) - rad[i] - rad[j]


def brute_bonds(pos, rad, gap):
    i, j, gaps = brute_gaps(pos, rad)
    keep = gaps < gap
    return np.stack([i[keep], j[keep]], axis=1)


def check_bond_array(b, n):
    """int32, [nb, 2], i < j, in range, unique, lexicographically sorted."""
    assert b.dtype == np.int32 and b.ndim == 2 and b.shape[1] == 2
    assert np.all(b[:, 0] < b[:, 1])
    assert b.min(initial=0) >= 0 and b.max(initial=0) < n
    assert len(np.unique(b, axis=0)) == len(b)
    assert np.array_equal(b, b[np.lexsort((b[:, 1], b[:, 0]))])


def fcc_sites(cells):
    """Closed form: even-parity points of an odd (2c+1)^3 grid."""
    nx, ny, nz = cells
    return ((2 * nx + 1) * (2 * ny + 1) * (2 * nz + 1) + 1) // 2


# ------------------------------------------------------------------------------------------------------ lattices
@pytest.mark.parametrize("cells", [(1, 1, 1), (2, 3, 4), (5, 1, 2), (4, 4, 4)])
def test_sc_counts_and_geometry(cells):
    nx, ny, nz = cells
    s = g.lattice("sc", cells, radius=R)
    assert s.n_particles == nx * ny * nz
    assert s.n_bonds == (nx - 1) * ny * nz + nx * (ny - 1) * nz + nx * ny * (nz - 1)
    check_bond_array(np.asarray(s.bonds), s.n_particles)
    np.testing.assert_allclose(s.bond_length, 2 * R, rtol=1e-12)
    # the bonds are exactly the touching pairs
    pos, rad = np.asarray(s.positions), np.asarray(s.radii)
    assert np.array_equal(np.asarray(s.bonds), brute_bonds(pos, rad, 1e-9 * R))
    i, j, gaps = brute_gaps(pos, rad)
    assert gaps.min(initial=np.inf) > -1e-12 * R  # nothing overlaps
    ijk = np.rint(pos / (2 * R)).astype(int)
    interior = np.all((ijk > 0) & (ijk < np.array(cells) - 1), axis=1)
    assert np.all(s.coordination()[interior] == 6)
    assert s.domain.kind == "box"
    np.testing.assert_allclose(s.domain.lo, -R)
    np.testing.assert_allclose(s.domain.hi, 2 * R * (np.array(cells) - 1) + R)


@pytest.mark.parametrize("cells", [(1, 1, 1), (2, 1, 3), (3, 3, 3)])
def test_fcc_counts_and_geometry(cells):
    s = g.lattice("fcc", cells, radius=R)
    pos, rad = np.asarray(s.positions), np.asarray(s.radii)
    assert s.n_particles == fcc_sites(cells)
    # brute force: all pairs at distance 2r, and nothing closer
    i, j, gaps = brute_gaps(pos, rad)
    assert gaps.min() > -1e-9 * R
    touching = np.stack([i, j], axis=1)[np.abs(gaps) < 1e-9 * R]
    assert np.array_equal(np.asarray(s.bonds), touching)
    check_bond_array(np.asarray(s.bonds), s.n_particles)
    np.testing.assert_allclose(s.bond_length, 2 * R, rtol=1e-12)
    ijk = np.rint(pos / (np.sqrt(2.0) * R)).astype(int)
    interior = np.all((ijk > 0) & (ijk < 2 * np.array(cells)), axis=1)
    assert np.all(s.coordination()[interior] == 12)
    assert s.coordination().max() <= 12
    assert interior.any() or cells == (1, 1, 1)
    np.testing.assert_allclose(s.domain.hi, 2 * np.sqrt(2) * R * np.array(cells) + R)


def test_fcc_site_closed_form_matches_enumeration():
    for cells in [(1, 1, 1), (1, 2, 3), (4, 2, 2)]:
        dims = [2 * c + 1 for c in cells]
        count = sum(1 for a in range(dims[0]) for b in range(dims[1]) for c in range(dims[2]) if (a + b + c) % 2 == 0)
        assert count == fcc_sites(cells) == g.lattice("fcc", cells).n_particles


def test_lattice_forwards_sample_options():
    s = g.lattice("sc", (2, 2, 2), radius=2e-3, bond_radius_ratio=0.3, density=1000.0,
                  materials={"E": [5e9], "nu": 0.2}, bond_contact="replace")
    np.testing.assert_allclose(s.bond_radius, 0.3 * 2e-3)
    np.testing.assert_allclose(s.mass, 1000.0 * 4 / 3 * np.pi * (2e-3) ** 3)
    assert s.materials.E[0] == 5e9 and s.bond_contact == "replace"
    s = g.lattice("sc", (2, 2, 2), bond_radius=1e-4)  # an explicit bond radius overrides the ratio
    np.testing.assert_allclose(s.bond_radius, 1e-4)


@pytest.mark.parametrize("args, match", [
    (("bcc", (2, 2, 2)), "kind"),
    (("sc", (0, 2, 2)), "cells"),
    (("sc", (2, 2)), "cells"),
    (("sc", (2, 2, 2.5)), "cells"),
    (("fcc", (2, 2, 2), -1.0), "radius"),
])
def test_lattice_errors(args, match):
    with pytest.raises(SampleError, match=match):
        g.lattice(*args)


def test_lattice_rejects_generated_fields():
    with pytest.raises(SampleError, match="set by the generator"):
        g.lattice("sc", (2, 2, 2), domain=None)


# -------------------------------------------------------------------------------------------------------- bonds
def test_bond_pairs_matches_brute_force():
    rng = np.random.default_rng(1)
    pos = rng.uniform(0, 20 * R, (300, 3))
    rad = R * rng.uniform(0.8, 1.2, 300)
    for gap in [0.0, 0.1 * R, 2 * R]:
        b = g.bond_pairs(pos, rad, gap)
        check_bond_array(b, 300)
        assert np.array_equal(b, brute_bonds(pos, rad, gap))
    assert g.bond_pairs(pos[:1], rad[:1], R).shape == (0, 2)
    assert g.bond_pairs(pos, rad, -10 * R).shape == (0, 2)
    with pytest.raises(SampleError, match="positions"):
        g.bond_pairs(pos[:, :1], rad, R)


# ---------------------------------------------------------------------------------------------- random packings
def check_packing(s, phi_min=0.0):
    pos, rad = np.asarray(s.positions), np.asarray(s.radii)
    assert pos.dtype == np.float64
    phi, basis = s.packing_fraction()
    assert phi >= phi_min and "domain" in basis
    _, _, gaps = brute_gaps(pos, rad)
    assert -gaps.min() < TOL * R  # largest pair overlap
    lo, hi = np.asarray(s.domain.lo), np.asarray(s.domain.hi)
    np.testing.assert_array_equal(lo, 0.0)
    assert np.all(pos[:, 2] - rad > -TOL * R) and np.all(pos[:, 2] + rad < hi[2] + TOL * R)
    if s.domain.kind == "cylinder":
        big = hi[0] / 2
        assert hi[0] == hi[1]
        assert np.all(np.hypot(pos[:, 0] - big, pos[:, 1] - big) + rad < big + TOL * R)
    else:
        assert np.all(pos - rad[:, None] > -TOL * R) and np.all(pos + rad[:, None] < hi + TOL * R)
    b = np.asarray(s.bonds)
    check_bond_array(b, s.n_particles)
    assert np.array_equal(b, brute_bonds(pos, rad, 0.05 * R))
    assert s.coordination().mean() > 3.0


@pytest.fixture(scope="module")
def box400():
    return g.random_packing(400, packing_fraction=0.56, seed=0)


def test_box_packing_is_dense_overlap_free_and_bonded(box400):
    s = box400
    assert s.n_particles == 400
    check_packing(s, phi_min=0.55)
    rad = np.asarray(s.radii)
    assert rad.min() >= 0.95 * R and rad.max() <= 1.05 * R and abs(rad.mean() - R) < 0.01 * R
    size = np.subtract(s.domain.hi, s.domain.lo)
    np.testing.assert_allclose(size / size[0], 1.0)  # default aspect: a cube
    np.testing.assert_allclose(s.bond_radius, 0.5 * np.minimum(rad[s.bonds[:, 0]], rad[s.bonds[:, 1]]))


def test_packing_is_deterministic_and_reports_progress(box400, capsys, caplog):
    with jax.log_compiles(), caplog.at_level(logging.WARNING):
        again = g.random_packing(400, packing_fraction=0.56, seed=0, progress=True)
    assert not [r for r in caplog.records if "ompil" in r.getMessage()], "the second call recompiled"
    for name in ("positions", "radii", "bonds"):
        assert np.array_equal(getattr(again, name), getattr(box400, name))
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert lines and all(line.startswith("random_packing: packing fraction 0.56: ") for line in lines)
    assert _messages(lines)[-1].startswith("random_packing: packing fraction 0.56: packed after ")
    assert "\r" not in err  # stderr is no terminal here: progress as lines (a bar is tested in tests/test_progress.py)

    calls = []
    other = g.random_packing(400, packing_fraction=0.56, seed=1, progress=lambda *a: calls.append(a))
    assert not np.array_equal(other.positions, box400.positions)
    steps = [c[0] for c in calls]
    assert steps == sorted(steps) and calls[-1][1] < TOL
    assert all(isinstance(c[0], int) and isinstance(c[1], float) and c[2] >= 0 for c in calls)


def _messages(lines):
    """The lines that stay (packed, given up), without the progress bar's redraws."""
    return [line for line in lines if "packed after" in line or "given up after" in line]


def attempts(calls):
    """Split progress calls ``(step, overlap, elapsed)`` into the attempts (the step count restarts at each)."""
    out = []
    for c in calls:
        if not out or c[0] <= out[-1][-1][0]:
            out.append([])
        out[-1].append(c)
    return out


@pytest.fixture(scope="module")
def auto400():
    records = []
    handler = logging.Handler()
    handler.emit = lambda record: records.append(record.getMessage())
    logger = logging.getLogger("jax")
    logger.addHandler(handler)
    calls = []
    try:
        with jax.log_compiles():
            s = g.box(400, seed=0, progress=lambda *a: calls.append(a))
    finally:
        logger.removeHandler(handler)
    return s, calls, records


def test_auto_fraction_is_as_dense_as_before_and_quick(auto400):
    # Once, 400 spheres tried 0.60 (8500 steps to jam) and 0.58 (9500), then packed 0.56 (1774 steps); later 0.60
    # and 0.58 were short trials (400 steps each): now the expected jamming fraction (0.561) skips them and the
    # first attempt packs 0.56
    s, calls, records = auto400
    check_packing(s, phi_min=0.56 - 1e-9)
    phi = s.packing_fraction()[0]
    radii = np.asarray(s.radii) / R
    fractions = g._auto_fractions("box", None, float(np.sum(4.0 / 3.0 * np.pi * radii**3)), float(radii.max()))
    assert fractions[0] == 0.56 and phi == pytest.approx(fractions[0], rel=1e-12)
    runs = attempts(calls)
    assert len(runs) == 1
    assert runs[-1][-1][1] < TOL and sum(run[-1][0] for run in runs) < 4000
    # one compiled FIRE chunk for all the fractions tried
    assert sum(m.startswith("Compiling jit(run)") for m in records) <= 1  # (0: an earlier test compiled it)
    # most bonded neighbours touch, as after an explicit packing_fraction
    b, pos, rad = np.asarray(s.bonds), np.asarray(s.positions), np.asarray(s.radii)
    gaps = np.linalg.norm(pos[b[:, 1]] - pos[b[:, 0]], axis=1) - rad[b[:, 0]] - rad[b[:, 1]]
    assert np.mean(gaps < 2 * TOL * R) > 0.7


def test_auto_fraction_is_deterministic(auto400, capsys):
    again = g.box(400, seed=0, progress=True)
    for name in ("positions", "radii", "bonds"):
        assert np.array_equal(getattr(again, name), getattr(auto400[0], name))
    lines = _messages(capsys.readouterr().err.splitlines())
    given_up = [line for line in lines if "given up after" in line]
    assert len(given_up) == len(attempts(auto400[1])) - 1 and len(lines) == len(given_up) + 1
    assert lines[-1].startswith(f"random_packing: packing fraction {again.packing_fraction()[0]:g}: packed after")


def test_explicit_jamming_fraction_still_raises():
    with pytest.raises(SampleError, match=r"^random packing did not converge: the spheres jammed \(no progress in "
                                          r"the last 5000 steps\); reached largest overlap .* at packing fraction "
                                          r"0\.62\. Try a lower packing_fraction"):
        g.random_packing(60, packing_fraction=0.62, seed=3)


@pytest.mark.parametrize("shape, n, phi, aspect", [
    ("cylinder", 300, 0.55, None),
    ("beam", 300, 0.52, None),
    ("box", 200, 0.5, (2.0, 1.0, 1.5)),
])
def test_each_shape(shape, n, phi, aspect):
    kw = {} if aspect is None else {"aspect": aspect}
    s = getattr(g, shape)(n, packing_fraction=phi, seed=2, **kw)
    assert s.n_particles == n
    check_packing(s, phi_min=phi - 1e-9)
    size = np.asarray(s.domain.hi)
    if shape == "cylinder":
        assert s.domain.kind == "cylinder"
        np.testing.assert_allclose(size[2] / size[0], 2.0)  # height / diameter
    else:
        want = np.array((4.0, 1.0, 1.0) if aspect is None else aspect)
        np.testing.assert_allclose(size / size[0], want / want[0])
    np.testing.assert_allclose(s.packing_fraction()[0], phi, rtol=1e-12)


def test_packing_in_float32():
    with jax.enable_x64(False):
        s = g.random_packing(150, packing_fraction=0.5, seed=4, density=3000.0)
    assert s.positions.dtype == np.float64
    check_packing(s, phi_min=0.5 - 1e-9)
    np.testing.assert_allclose(s.particle_material.density, 3000.0)


def test_not_converged_raises():
    with pytest.raises(SampleError, match="did not converge.*packing_fraction"):
        g.random_packing(150, packing_fraction=0.5, seed=4, max_steps=1)


@pytest.mark.parametrize("kw, match", [
    ({"shape": "sphere"}, "shape"),
    ({"n": 0}, "n must"),
    ({"n": 2.5}, "n must"),
    ({"packing_fraction": 0.8}, "packing_fraction"),
    ({"packing_fraction": -0.1}, "packing_fraction"),
    ({"radius_spread": -0.1}, "radius_spread"),
    ({"mean_radius": 0.0}, "mean_radius"),
    ({"aspect": (1.0, 2.0)}, "aspect"),
    ({"shape": "cylinder", "aspect": -1.0}, "aspect"),
    ({"shape": "beam", "aspect": (200.0, 1.0, 1.0), "n": 20}, "too thin"),
    ({"progress": "yes"}, "progress"),
    ({"seed": -1}, "seed"),
    ({"domain": None}, "set by the generator"),
])
def test_random_packing_errors(kw, match):
    kw = {"n": 50, **kw}
    with pytest.raises(SampleError, match=match):
        g.random_packing(kw.pop("n"), **kw)


# ---------------------------------------------------------------------------------------------------- from_shape
@pytest.mark.parametrize("shape", ["sc", "fcc"])
@pytest.mark.parametrize("n", [1, 30, 100, 1000, 5000])
def test_from_shape_lattice_closest_count(shape, n):
    s = g.from_shape(shape, n)
    count = (lambda c: c**3) if shape == "sc" else (lambda c: fcc_sites((c, c, c)))
    best = min(abs(count(c) - n) for c in range(2, 40))
    assert abs(s.n_particles - n) == best
    assert s.n_particles >= count(2)


def test_from_shape_random_and_errors():
    s = g.from_shape("Box", 150, seed=4, packing_fraction=0.5)
    assert s.n_particles == 150
    with pytest.raises(SampleError, match="box, cylinder, beam, sc, fcc"):
        g.from_shape("sphere", 100)
    with pytest.raises(SampleError, match="n must"):
        g.from_shape("sc", 0)
    s = g.from_shape("fcc", 60, mean_radius=2e-3, density=1000.0)  # mean_radius is the lattice radius
    np.testing.assert_allclose(s.radii, 2e-3)
    np.testing.assert_allclose(s.bond_length, 4e-3)


# ----------------------------------------------------------------------------------------------------- materials
@pytest.fixture(scope="module")
def sc5():
    return g.lattice("sc", (5, 5, 5))  # 300 bonds


@pytest.mark.parametrize("fractions, counts", [
    ([0.3, 0.7], [90, 210]),
    ([0.25, 0.25, 0.5], [75, 75, 150]),
    ([1.0 / 3, 1.0 / 3, 1.0 / 3], [100, 100, 100]),
    ([0.0, 1.0], [0, 300]),
    ([0.001, 0.999], [0, 300]),  # round(0.3) = 0, the rest to the last
    ([0.0015, 0.9985], [0, 300]),  # round(0.45) = 0
])
def test_mix_materials_exact_counts(sc5, fractions, counts):
    mats = {"E": [1e9 * (k + 1) for k in range(len(fractions))]}
    s = g.mix_materials(sc5, fractions, materials=mats, seed=3)
    assert np.array_equal(np.bincount(s.bond_material, minlength=len(fractions)), counts)
    assert s.n_materials == len(fractions)
    np.testing.assert_array_equal(s.bonds, sc5.bonds)


def test_mix_materials_randomness_and_table(sc5):
    mats = BondMaterials.create(E=[1e9, 2e9], nu=[0.2, 0.3])
    a = g.mix_materials(sc5, [0.5, 0.5], materials=mats, seed=0)
    b = g.mix_materials(sc5, [0.5, 0.5], materials=mats, seed=0)
    c = g.mix_materials(sc5, [0.5, 0.5], materials=mats, seed=1)
    assert np.array_equal(a.bond_material, b.bond_material)
    assert not np.array_equal(a.bond_material, c.bond_material)
    np.testing.assert_array_equal(a.materials.nu, [0.2, 0.3])
    # a sample that already has two components keeps its table
    d = g.mix_materials(a, [0.2, 0.8])
    np.testing.assert_array_equal(d.materials.E, [1e9, 2e9])
    assert np.array_equal(np.bincount(d.bond_material), [60, 240])


@pytest.mark.parametrize("fractions, kw, match", [
    ([0.3, 0.6], {"materials": {"E": [1e9, 2e9]}}, "sum to 1"),
    ([-0.2, 1.2], {"materials": {"E": [1e9, 2e9]}}, ">= 0"),
    ([], {}, "non-empty"),
    ([[0.5, 0.5]], {}, "1-D"),
    ("ab", {}, "numbers"),
    ([0.5, 0.5], {}, "1 components but 2 fractions"),
    ([0.5, 0.5], {"materials": {"E": [1e9, 2e9, 3e9]}}, "3 components but 2 fractions"),
    ([0.5, 0.5], {"materials": {"nu": [0.2, 0.3]}}, "missing 'E'"),
    ([0.5, 0.5], {"materials": {"E": [1e9, 2e9], "G": 1.0}}, "unknown fields"),
    ([0.5, 0.5], {"materials": [1e9, 2e9]}, "mapping"),
    ([1.0], {"seed": -2}, "seed"),
])
def test_mix_materials_errors(sc5, fractions, kw, match):
    with pytest.raises(SampleError, match=match):
        g.mix_materials(sc5, fractions, **kw)


def test_mix_materials_accepts_rounding_noise(sc5):
    s = g.mix_materials(sc5, [0.1] * 10, materials={"E": [1e9] * 10})
    assert np.array_equal(np.bincount(s.bond_material), [30] * 10)


def test_materials_by_region(sc5):
    pos, b = np.asarray(sc5.positions), np.asarray(sc5.bonds)
    x_mid = 4 * R  # the middle plane of the 5-particle lattice (x = 0 .. 8 mm)
    s = g.materials_by_region(sc5, lambda mid: (mid[:, 0] > x_mid).astype(np.int64),
                              materials={"E": [1e9, 3e9]})
    want = np.array([int(pos[i, 0] + pos[j, 0] > 2 * x_mid) for i, j in b])
    np.testing.assert_array_equal(s.bond_material, want)
    assert s.bond_material.dtype == np.int32
    s_bool = g.materials_by_region(sc5, lambda mid: mid[:, 0] > x_mid, materials={"E": [1e9, 3e9]})
    np.testing.assert_array_equal(s_bool.bond_material, want)
    with pytest.raises(SampleError, match="integer component indices"):
        g.materials_by_region(sc5, lambda mid: mid[:, 0])
    with pytest.raises(SampleError, match=r"\[300\]"):
        g.materials_by_region(sc5, lambda mid: np.zeros(3, dtype=int))
    with pytest.raises(SampleError, match="unknown material index"):
        g.materials_by_region(sc5, lambda mid: np.ones(len(mid), dtype=int))  # the table has one component
    with pytest.raises(SampleError, match="callable"):
        g.materials_by_region(sc5, 3)


def test_small_samples_pack_with_the_default_fraction():
    # Boxes of fewer than about 300 spheres jam at 0.55 (the walls loosen them): the automatic mode continues below
    # it, from the expected jamming fraction, instead of raising (60 spheres, seed 0, once jammed at 0.55).
    fractions = g._auto_fractions("box", None, 60 * 4.0 / 3.0 * np.pi, 1.05)
    assert fractions[0] < 0.55 and fractions[-1] < 0.5
    assert np.all(np.diff(fractions) < 0)
    big = g._auto_fractions("box", None, 3000 * 4.0 / 3.0 * np.pi, 1.05)
    assert big == tuple(g.AUTO_PACKING_FRACTIONS)  # large samples try what they always tried
    s = g.box(60, seed=0)
    phi = s.packing_fraction()[0]
    assert phi < 0.55 and min(abs(phi - f) for f in fractions) < 1e-9
    check_packing(s, phi_min=0.4)
