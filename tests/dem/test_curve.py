"""What a DEM run's records give, on records made by hand: the stiffness of a straight curve, the peak and the
broken bonds there, a curve cut short, the statistics of a plan."""

import types

import numpy as np
import pytest

import jaxbpm
from jaxbpm import SceneError
from jaxbpm.dem.curve import curve, fit_line, peak_stats, plan_stats
from jaxbpm.scenes import UniaxialCompression

R = 1e-3
SCENE = UniaxialCompression(strain=0.002)  # clamped layers: reactions [steps, 2, 3], axis z


def _records(force, dt=1e-6):
    steps = len(force)
    reaction = np.zeros((steps, 2, 3))
    reaction[:, 0, 2], reaction[:, 1, 2] = force, -force  # the moving end pushes, the resting end holds
    broken = np.stack([np.arange(steps) // 3, np.arange(steps) // 5], axis=1).astype(np.int32)
    return {"time": dt * np.arange(1, steps + 1), "reaction": reaction, "vmax": np.zeros(steps), "broken": broken}


def test_a_straight_curve_gives_its_slope():
    speed, k = 2.0, 3.5e6
    rec = _records(k * 2.0 * 1e-6 * np.arange(1, 101))
    target = speed * rec["time"][-1]
    disp, force, stiffness, keep = curve(SCENE, rec, speed, target, max_records=10)
    np.testing.assert_allclose(disp, speed * rec["time"])
    np.testing.assert_allclose(stiffness, k, rtol=1e-9)
    assert len(keep) == 10 and keep[0] == 0 and keep[-1] == 99
    assert len(curve(SCENE, rec, speed, target, max_records=1000)[3]) == 100


def test_the_fit_line_is_the_least_squares_line_of_the_fit_range():
    speed, k, f0 = 2.0, 3.5e6, 7.0  # a straight curve with an offset, bent beyond the fit range
    disp = speed * 1e-6 * np.arange(1, 101)
    lo, hi = SCENE.fit_range
    target = 0.6 * disp[-1]
    force = k * disp + f0 + np.where(disp > hi * target, -1e9 * (disp - hi * target) ** 2, 0.0)
    length, area = 0.01, 2e-5
    line = fit_line(SCENE, disp, force, target, length, area)
    inside = disp[(disp >= lo * target * (1 - 1e-9)) & (disp <= hi * target * (1 + 1e-9))]
    assert len(inside) > 10 and inside[-1] < disp[-1]
    np.testing.assert_allclose(line["fit_strain"], [inside[0] / length, inside[-1] / length], rtol=1e-12)
    np.testing.assert_allclose(line["fit_stress"], [(k * inside[0] + f0) / area, (k * inside[-1] + f0) / area],
                               rtol=1e-9)
    assert fit_line(SCENE, disp[:1], force[:1], disp[-1], length, area) == {}


def test_a_curve_cut_short():
    rec = _records(np.ones(1))
    with pytest.raises(SceneError, match="too few records"):
        curve(SCENE, rec, 1.0, 1.0, 100)
    disp, force, stiffness, keep = curve(SCENE, rec, 1.0, 1.0, 100, strict=False)
    assert np.isnan(stiffness) and len(disp) == 1
    disp, force, stiffness, keep = curve(SCENE, {}, 1.0, 1.0, 100, strict=False)
    assert len(disp) == len(force) == len(keep) == 0 and peak_stats(SCENE, None, {}, disp, force, keep, True) == {}


def test_the_peak_and_the_broken_bonds_there():
    s = jaxbpm.generate.lattice("sc", (2, 2, 4), R)
    force = np.r_[np.linspace(0, 10, 30), np.linspace(9, 2, 10)]
    rec = _records(force)
    disp, force, _, keep = curve(SCENE, rec, 1.0, 1.0, 8, strict=False)
    stats = peak_stats(SCENE, s, rec, disp, force, keep, breakage=True)
    assert stats["peak_force"] == 10.0 and stats["displacement_at_peak"] == disp[29]
    np.testing.assert_allclose(stats["strength"], 10.0 / SCENE.geometry(s)[1])
    assert (stats["broken_tensile"], stats["broken_shear"]) == (39 // 3, 39 // 5)
    assert stats["broken_at_peak"] == 29 // 3 + 29 // 5 and stats["past_peak"]
    np.testing.assert_array_equal(stats["broken_curve"], rec["broken"][keep])
    assert "broken_tensile" not in peak_stats(SCENE, s, rec, disp, force, keep, breakage=False)
    rising = _records(np.linspace(0, 10, 30))
    d, f, _, k = curve(SCENE, rising, 1.0, 1.0, 8, strict=False)
    assert not peak_stats(SCENE, s, rising, d, f, k, breakage=True)["past_peak"]


def test_plan_stats():
    model = types.SimpleNamespace(rotations=True, contacts=False, contact_law="hertz", failure_rule="potyondy")
    the_plan = types.SimpleNamespace(model=model, size=None, dt=1e-7, n_steps=100, speed=0.5, damping=0.7,
                                     breakage=False)
    stats = plan_stats(the_plan, 2e-7, interrupted=False)
    assert stats["loading_time"] == 100 * 1e-7 and stats["dt_crit"] == 2e-7 and stats["padded_to"] is None
    assert stats["rotations"] and not stats["interrupted"] and stats["failure_rule"] == "potyondy"
