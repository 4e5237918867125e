"""The Brazilian disc scene: a bonded disc split between two loading strips, BTS = 2 F / (pi D t)."""

import dataclasses

import meshio
import numpy as np
import pytest

import jaxbpm
from jaxbpm import SceneError
from jaxbpm.dem.records import read_records
from jaxbpm.scenes import BrazilianDisc

# one worker for the whole module under pytest-xdist: the disc and its failure run (module fixtures) are built once
pytestmark = pytest.mark.xdist_group("brazilian-module")

MATS = {"E": 1e9, "nu": 0.25, "tensile_strength": 5e6, "shear_strength": 1e7}
SCENE = BrazilianDisc(strain=0.02)
TRANSITS = 30


@pytest.fixture(scope="module")
def disc():
    """A 400-sphere disc, t / D = 0.5 (ISRM), about ten spheres across."""
    return jaxbpm.generate.cylinder(400, seed=0, aspect=0.5, materials=MATS).largest_cluster()


@pytest.fixture(scope="module")
def split(disc, tmp_path_factory):
    """The disc loaded past its peak, with every step's record and three VTU frames."""
    out = tmp_path_factory.mktemp("bts")
    res = jaxbpm.solve(disc, SCENE, "dem", transits=TRANSITS, record_to=out / "run.h5", snapshots=3,
                       vtu=out / "run.pvd")
    return res, out


def _with_strengths(sample, tensile, shear):
    m = dataclasses.replace(sample.materials, tensile_strength=np.array([tensile]), shear_strength=np.array([shear]))
    return sample.replace(materials=m)


def test_the_disc_splits_in_tension_at_its_bts(disc, split):
    res, _ = split
    st = res.stats
    assert res.status == "converged" and st["past_peak"]
    d, t = SCENE.dimensions(disc)
    np.testing.assert_allclose([d, t], [disc.domain.hi[0], disc.domain.hi[2]])  # the cylinder domain, D = 2 t
    np.testing.assert_allclose(st["strength"], 2 * st["peak_force"] / (np.pi * d * t), rtol=1e-12)
    np.testing.assert_allclose(res.area, d * t) and np.testing.assert_allclose(res.gauge_length, d)
    # elastic-brittle: a linear rise, then the split: the force falls, and the run stops at 0.7 of the peak
    f = res.force
    peak = int(np.argmax(f))
    assert 0.2 * len(f) < peak < 0.95 * len(f) and f[-1] <= SCENE.stop_after_peak * f[peak] < f[-2]
    assert st["stop_reason"] == "after_peak" and st["steps"] < st["steps_planned"]
    # it fails in tension, along the loaded diameter (x; the strips' centre line y = D / 2)
    assert st["broken_tensile"] > 50 and st["broken_tensile"] > 10 * st["broken_shear"]
    assert res.stiffness > 0 and np.isnan(res.youngs_modulus)
    # the BTS of a bonded packing lies well below its bonds' tensile strength (5 MPa): about a tenth here
    assert 0.02 < st["strength"] / MATS["tensile_strength"] < 0.3, st["strength"]


def test_the_bts_is_proportional_to_the_bond_strengths(disc, split):
    # elastic-brittle bonds at fixed stiffness: twice the strengths, loaded at the same rate relative to the
    # failure (twice the platen travel in as many steps), break at twice the load
    base = split[0].stats["strength"]
    strong = jaxbpm.solve(_with_strengths(disc, 2 * MATS["tensile_strength"], 2 * MATS["shear_strength"]),
                          BrazilianDisc(strain=2 * SCENE.strain), "dem", transits=TRANSITS)
    assert strong.stats["past_peak"]
    ratio = strong.stats["strength"] / base
    assert abs(ratio - 2) < 0.1, ratio


def test_records_and_the_breakage_map(disc, split):
    res, out = split
    rec, attrs = read_records(out / "run.h5")
    assert attrs["status"] == "complete" and attrs["scene"] == "BrazilianDisc"
    np.testing.assert_array_equal(rec["force"], SCENE.compressive_force(rec["reaction"]))
    np.testing.assert_array_equal(rec["broken"][-1], [res.stats["broken_tensile"], res.stats["broken_shear"]])
    assert attrs["strength"] == res.stats["strength"]
    # the map of the last frame: broken bonds per particle and each bond's break mode; the crack runs along
    # the loaded diameter (bond midpoints within D / 5 of it) and crosses the disc from strip to strip
    files = sorted(out.glob("run_*.vtu"))
    assert len(files) >= 2  # at rest, ..., where the run stopped after the peak (frames planned later: none)
    last = meshio.read(files[-1])
    mode = last.cell_data["break_mode"][1]
    np.testing.assert_array_equal(mode, np.asarray(res.state.broken))
    b, pos = np.asarray(disc.bonds), np.asarray(disc.positions)
    mid = 0.5 * (pos[b[:, 0]] + pos[b[:, 1]])
    d = SCENE.dimensions(disc)[0]
    broken = mid[mode > 0]
    assert np.mean(np.abs(broken[:, 1] - 0.5 * d) < 0.2 * d) > 0.9
    assert np.histogram(broken[:, 0] / d, bins=5, range=(0, 1))[0].min() > 0  # across the whole diameter
    assert last.point_data["broken_tensile"].sum() == 2 * np.sum(mode == 1)


def test_a_calibration_target_reads_the_bts(disc, split):
    from jaxbpm.calibrate import forward_model
    from jaxbpm.physics.model import default_params

    fwd = forward_model(disc, {"bts": SCENE}, "dem", transits=TRANSITS)
    params = {**default_params(disc), "bond_tensile_strength": np.array([MATS["tensile_strength"]]),
              "bond_shear_strength": np.array([MATS["shear_strength"]])}
    got = fwd.evaluate(params)["bts"]
    np.testing.assert_allclose(got["strength"], split[0].stats["strength"], rtol=1e-9)
    np.testing.assert_allclose(got["peak_force"], split[0].stats["peak_force"], rtol=1e-9)


def test_flat_platens_run(disc):
    # plane walls touching the rim (the option; crushing at the rim point contacts makes their peak ill-defined on
    # discs this coarse): they load the disc and break bonds
    res = jaxbpm.solve(disc, BrazilianDisc(platens="walls", strain=0.01), "dem", transits=10)
    assert res.status == "converged" and res.force.max() > 0 and res.stiffness > 0
    assert res.stats["broken_tensile"] + res.stats["broken_shear"] >= 0


def test_brazilian_errors_are_named(disc):
    with pytest.raises(SceneError, match="disc_axis"):
        BrazilianDisc(axis=2, disc_axis=2)
    with pytest.raises(SceneError, match="strain"):
        BrazilianDisc(strain=0.7)
    with pytest.raises(SceneError, match="platens"):
        BrazilianDisc(platens="jaws")
    with pytest.raises(SceneError, match="thickness"):
        BrazilianDisc(thickness=-1.0)
    with pytest.raises(SceneError, match="wall_stiffness"):
        BrazilianDisc(platens="walls", wall_law="linear")
    with pytest.raises(SceneError, match="disc_axis=2"):
        BrazilianDisc(axis=2, disc_axis=0).dimensions(disc)
    with pytest.raises(SceneError, match="strip_width"):
        BrazilianDisc(strip_width=1e-9).layers(disc)
    with pytest.raises(SceneError, match="method='dem'"):
        jaxbpm.solve(disc, SCENE, "dsm")
    with pytest.raises(SceneError, match="needs method='dem': the STE"):
        jaxbpm.solve(disc, SCENE, "ste")
