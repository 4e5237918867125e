"""jaxbpm's plot functions use no global matplotlib state: no pyplot, no ``matplotlib.use``, no figure left open;
they write their file atomically and return a :class:`matplotlib.figure.Figure` (or the path)."""

import os
import pathlib
import subprocess
import sys
import textwrap
import types

import matplotlib
import numpy as np
import pytest
from matplotlib.figure import Figure

from jaxbpm import cli, io, plots
from jaxbpm.calibrate.history import CalibrationResult, History, plot_history
from jaxbpm.result import Result
from jaxbpm.sample import Sample


def _history():
    h = History(parameter_names=["bond_E", "bond_nu"], target_names=["youngs_modulus"])
    for k in range(4):
        h.append(kind="adam", level="dsm", values=[1e9 * (1 + 0.1 * k), 0.25], loss=10.0 ** -k,
                 errors=[0.1 * 2.0 ** -k], evaluations=k + 1, time=0.1 * k)
    return h


def _local_map():
    rng = np.random.default_rng(0)
    return types.SimpleNamespace(positions=rng.uniform(0, 1e-2, (60, 3)), deviation=rng.normal(0, 0.05, (60, 3)),
                                 radius=2e-3)


def _result(method, E, wall, run, **stats):
    """A result made by hand (no solve): a straight curve of slope E to strain 1e-3, gauge 1 m, area 1 m^2."""
    strain = np.linspace(0.0, 1e-3, 11 if method == "dem" else 2)
    return Result(method=method, stiffness=E, youngs_modulus=E, gauge_length=1.0, area=1.0, displacement=strain,
                  force=E * strain, wall_time=wall, compile_time=0.0, run_time=run, stats=stats)


_RESULTS = {"dem": _result("dem", 1.00e8, 3.5, 2.0), "dsm": _result("dsm", 1.0001e8, 0.9, 0.05),
            "dsm stol 1e-3": _result("dsm", 1.002e8, 0.8, 0.04), "ste": _result("ste", 1.08e8, 0.6, 0.01)}
_SAMPLE = types.SimpleNamespace(n_particles=54, n_bonds=117)


def _line_sample():
    """A chain of five particles along z, bonded neighbour to neighbour, in the plane y = 0 but the fourth at
    y = 2 mm: the midpoints of bonds 0 and 1 at y = 0, of bonds 2 and 3 at y = 1 mm."""
    pos = [[0, 0, 0], [0, 0, 2e-3], [0, 0, 4e-3], [0, 2e-3, 6e-3], [0, 0, 8e-3]]
    return Sample.from_arrays(pos, 1e-3, [[0, 1], [1, 2], [2, 3], [3, 4]], bond_radius_ratio=0.5)


def _plot_all(tmp):
    """Call every plot function of jaxbpm once; returns {name: (returned object, file)}."""
    return {
        "plot_history": (plot_history(_history(), tmp / "history.svg"), tmp / "history.svg"),
        "plot_local_map": (io.plot_local_map(tmp / "map.png", _local_map()), tmp / "map.png"),
        "demo chart": (cli._demo_chart(tmp / "chart.png", _RESULTS, _SAMPLE), tmp / "chart.png"),
        "stress_strain": (plots.save(_RESULTS["dsm"].plot(_RESULTS["dem"].plot()), tmp / "curve.png"),
                          tmp / "curve.png"),
        "crack_pattern": (plots.save(plots.crack_pattern(_line_sample(), [0, 1, 2, 0]), tmp / "cracks.png"),
                          tmp / "cracks.png"),
        "speed_accuracy": (plots.save(plots.speed_accuracy(_RESULTS, _RESULTS["dem"]), tmp / "speed.png"),
                           tmp / "speed.png"),
        "calibration": (plots.save(_history().plot()[0], tmp / "calibration.png"), tmp / "calibration.png"),
    }


def test_plots_touch_no_global_state(tmp_path, monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("a jaxbpm plot function called matplotlib.use")

    backend = matplotlib.get_backend()
    pyplot = sys.modules.get("matplotlib.pyplot")
    open_before = pyplot.get_fignums() if pyplot is not None else []
    monkeypatch.setattr(matplotlib, "use", refuse)
    out = _plot_all(tmp_path)
    assert matplotlib.get_backend() == backend
    if pyplot is not None:
        assert pyplot.get_fignums() == open_before
    assert isinstance(out["plot_history"][0], Figure)
    assert out["plot_local_map"][0] == tmp_path / "map.png"
    for name in ("demo chart", "stress_strain", "crack_pattern", "speed_accuracy", "calibration"):
        assert out[name][0] == out[name][1], name
    for name, (_, path) in out.items():
        assert path.stat().st_size > 5000, name
    assert (tmp_path / "history.svg").read_text().lstrip().startswith("<?xml")  # the format follows the suffix
    assert not list(tmp_path.glob(".*.tmp"))  # atomic: no temporary file left behind


def test_demo_chart_names_its_ratios_and_abbreviations(tmp_path, monkeypatch):
    saved = []
    monkeypatch.setattr(Figure, "savefig", lambda self, *a, **kw: saved.append(self) or open(a[0], "wb").close())
    cli._demo_chart(tmp_path / "chart.png", _RESULTS, _SAMPLE)
    (fig,) = saved
    (ax,) = [a for a in fig.axes if a.get_legend() is not None]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    dem = _RESULTS["dem"]
    for label, res in _RESULTS.items():
        if label == "dem":  # the reference: a line at its wall time, not a point on a floor
            assert any("reference" in t and f"{dem.wall_time:.3g} s" in t for t in labels), labels
            continue
        (text,) = [t.replace("\n", " ") for t in labels if t.startswith(f"{label}: ")]
        assert cli._DEMO_NAMES[label] in text, text
        assert f"{dem.wall_time / res.wall_time:.3g}x faster than DEM in wall time" in text, text
        assert f"{dem.run_time / res.run_time:.3g}x faster than DEM in run time" in text, text
    assert any("Pareto front" in t for t in labels)
    for abbreviation in ("DEM", "DSM", "STE"):
        assert any(f"{abbreviation}, " in t and "method" in t or "estimate" in t for t in labels), abbreviation
    assert not any("floor" in t for t in labels + [ax.get_ylabel()])
    assert "wall time" in ax.get_xlabel() and "run time" in ax.get_xlabel()
    assert fig.get_layout_engine() is not None  # labels laid out without overlap


def test_plot_keeps_the_old_file_when_saving_fails(tmp_path, monkeypatch):
    target = tmp_path / "map.png"
    target.write_bytes(b"old")

    def broken(self, *args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(Figure, "savefig", broken)
    with pytest.raises(RuntimeError):
        io.plot_local_map(target, _local_map())
    assert target.read_bytes() == b"old" and not list(tmp_path.glob(".*.tmp"))


def test_plots_import_no_pyplot_and_keep_the_backend(tmp_path):
    """In a fresh interpreter with the ``svg`` backend: after every plot function the backend is still ``svg`` and
    ``matplotlib.pyplot`` was never imported."""
    code = textwrap.dedent(f"""
        import pathlib, sys
        import matplotlib
        matplotlib.use("svg")
        sys.path.insert(0, {str(pathlib.Path(__file__).parent)!r})
        import test_plots
        test_plots._plot_all(pathlib.Path({str(tmp_path)!r}))
        assert matplotlib.get_backend() == "svg", matplotlib.get_backend()
        assert "matplotlib.pyplot" not in sys.modules
        print("ok")
    """)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                         env={**os.environ, "JAX_PLATFORMS": "cpu"})
    assert res.returncode == 0 and res.stdout.strip() == "ok", res.stdout + res.stderr



# ------------------------------------------------------------------------------------------------ results' plots
@pytest.fixture(scope="module")
def failure(tmp_path_factory):
    """A UCS run to failure of a 250-particle cylinder (10 transits: not quasi-static, hence throw=False), its
    record file read back, and the sample."""
    import jaxbpm
    from jaxbpm.dem.records import read_records
    from jaxbpm.scenes import UniaxialCompression

    rock = jaxbpm.generate.cylinder(250, seed=0, materials={"E": 1e9, "nu": 0.25, "tensile_strength": 5e6,
                                                            "shear_strength": 5e6}).largest_cluster()
    path = tmp_path_factory.mktemp("failure") / "run.h5"
    res = jaxbpm.solve(rock, UniaxialCompression.to_failure(strain=0.02), "dem", transits=10, throw=False,
                       record_to=path)
    records, _ = read_records(path)
    return res, records, rock


def test_a_dem_curve_draws_its_records_peak_modulus_and_broken_bonds(failure):
    res, rec, _ = failure
    ax = res.plot()
    got = plots.drawn(ax)
    strain, stress = rec["displacement"] / res.gauge_length, rec["force"] / res.area / 1e6
    np.testing.assert_allclose(got["curve DEM"], np.stack([strain, stress], axis=1), rtol=1e-12)
    peak = int(np.argmax(rec["force"]))  # the peak of the records, and of the result's stats
    np.testing.assert_allclose(got["peak DEM"], [[strain[peak], stress[peak]]], rtol=1e-12)
    np.testing.assert_allclose(got["peak DEM"][0, 1], res.stats["strength"] / 1e6, rtol=1e-12)
    # the modulus line: slope E, the least-squares line of the records in its strain range
    (e0, s0), (e1, s1) = got["modulus DEM"]
    np.testing.assert_allclose((s1 - s0) * 1e6 / (e1 - e0), res.youngs_modulus, rtol=1e-9)
    sel = (strain >= e0) & (strain <= e1)
    slope, intercept = np.polyfit(strain[sel], stress[sel], 1)
    np.testing.assert_allclose([s0, s1], [slope * e0 + intercept, slope * e1 + intercept], rtol=1e-9)
    # the broken bonds, on the twin axis: the records' count, ending at the state's
    broken = got["broken DEM"]
    np.testing.assert_array_equal(broken[:, 1], rec["broken"].sum(axis=1))
    total = int(np.sum(np.asarray(res.state.broken) != 0))
    assert broken[-1, 1] == total == res.stats["broken_tensile"] + res.stats["broken_shear"] > 0
    assert "MPa" in ax.get_ylabel() and "strain" in ax.get_xlabel()


def test_dsm_and_ste_draw_beside_the_dem(failure):
    res = failure[0]
    ax = res.plot()
    for r in (_RESULTS["dsm"], _RESULTS["ste"]):
        assert r.plot(ax=ax) is ax
    got = plots.drawn(ax)
    for name in ("DSM", "STE"):
        (e0, s0), (e1, s1) = got[f"modulus {name}"]
        r = _RESULTS[name.lower()]
        assert e0 == s0 == 0 and e1 == r.strain[-1]
        np.testing.assert_allclose(s1 * 1e6 / e1, r.youngs_modulus, rtol=1e-12)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    for method, spelt in plots.METHOD_NAMES.items():  # each named in full once
        assert sum(t.startswith(f"{spelt}:") for t in labels) == 1, (spelt, labels)
    assert any("broken bonds" in t for t in labels)  # the twin axis's line is in the one legend


def test_plots_on_shared_axes_keep_to_their_own():
    fig = Figure(layout="constrained")
    left, right = fig.subplots(1, 2, sharex=True)
    broken = dict(broken_tensile=3, broken_shear=1, broken_curve=np.tile([[3, 1]], (11, 1)), peak_force=1e5,
                  displacement_at_peak=1e-3)
    _result("dem", 1e8, 1.0, 0.5, **broken).plot(left, label="one")
    _result("dem", 2e8, 1.0, 0.5, **broken).plot(right, label="two")
    _RESULTS["dsm"].plot(ax=left)
    assert sorted(plots.drawn(left)) == ["broken one", "curve one", "end DSM", "modulus DSM", "peak one"]
    assert sorted(plots.drawn(right)) == ["broken two", "curve two", "peak two"]
    assert not any("two" in t.get_text() for t in left.get_legend().get_texts())
    np.testing.assert_array_equal(plots.drawn(left)["broken one"][:, 1], 4)


def test_the_crack_pattern_draws_each_broken_bond_by_mode(failure):
    res, _, rock = failure
    mode = np.asarray(res.state.broken)
    got = plots.drawn(res.plot_cracks(rock, thickness=np.inf))  # every bond, projected
    assert len(got["bonds tension"]) == int(np.sum(mode == 1)) == res.stats["broken_tensile"]
    assert len(got["bonds shear"]) == int(np.sum(mode == 2)) == res.stats["broken_shear"]
    assert len(got["bonds intact"]) == int(np.sum(mode == 0))
    x = np.asarray(rock.positions)
    np.testing.assert_array_equal(got["bonds shear"], x[np.asarray(rock.bonds)[mode == 2]][:, :, [0, 2]])
    with pytest.raises(ValueError, match="no broken bonds"):
        _RESULTS["dsm"].plot_cracks(rock)


def test_the_section_keeps_the_bonds_whose_midpoints_are_in_the_slab():
    sample = _line_sample()
    got = plots.drawn(plots.crack_pattern(sample, [1, 2, 1, 0], normal=1, origin=0.0, thickness=1e-3))
    x = np.asarray(sample.positions)
    np.testing.assert_array_equal(got["bonds tension"], x[[[0, 1]]][:, :, [0, 2]])  # bond 2 is off the slab
    np.testing.assert_array_equal(got["bonds shear"], x[[[1, 2]]][:, :, [0, 2]])
    assert len(got["bonds intact"]) == 0
    around = plots.drawn(plots.crack_pattern(sample, [1, 2, 1, 0], normal=1, origin=1e-3, thickness=1e-3))
    assert [len(around[f"bonds {m}"]) for m in ("intact", "tension", "shear")] == [1, 1, 0]
    with pytest.raises(ValueError, match="3 break modes for a sample of 4 bonds"):
        plots.crack_pattern(sample, [0, 1, 2])
    with pytest.raises(ValueError, match="break modes are 0"):
        plots.crack_pattern(sample, [0, 1, 3, 0])
    with pytest.raises(ValueError, match="positions must be"):
        plots.crack_pattern(sample, [0, 1, 2, 0], positions=np.zeros((5, 2)))
    with pytest.raises(ValueError, match="thickness"):
        plots.crack_pattern(sample, [0, 1, 2, 0], thickness=0.0)
    with pytest.raises(ValueError, match="normal"):
        plots.crack_pattern(sample, [0, 1, 2, 0], normal=3)
    deformed = np.asarray(sample.positions) + [1e-3, 0.0, 0.0]  # drawn where given
    got = plots.drawn(plots.crack_pattern(sample, [1, 0, 0, 0], positions=deformed, origin=0.0, thickness=1e-3))
    np.testing.assert_array_equal(got["bonds tension"], deformed[[[0, 1]]][:, :, [0, 2]])


# ------------------------------------------------------------------------------------------------ speed vs accuracy
def test_the_pareto_front_is_the_non_dominated_points():
    times = [1.0, 2.0, 0.5, 3.0, 2.0, 0.5, 4.0]
    errors = [0.1, 0.05, 0.2, 0.05, 0.2, 0.3, 0.01]
    dominated = {i for i in range(7) for j in range(7)
                 if times[j] <= times[i] and errors[j] <= errors[i] and (times[j], errors[j]) != (times[i], errors[i])}
    assert sorted(plots.pareto_front(times, errors)) == sorted(set(range(7)) - dominated) == [0, 1, 2, 6]
    assert plots.pareto_front(times, errors) == [2, 0, 1, 6]  # fastest first
    assert plots.pareto_front([1.0, 2.0], [0.1, 0.0995], tie=0.01) == [0]  # within 1 %: no better
    with pytest.raises(ValueError):
        plots.pareto_front([1.0], [0.1, 0.2])


def test_speed_accuracy_marks_the_front_of_any_results():
    E = 1e8
    spec = {"a": (1.0, 0.10), "b": (2.0, 0.05), "c": (0.5, 0.20), "d": (3.0, 0.05), "e": (2.0, 0.20),
            "f": (4.0, 0.01)}
    results = {k: _result("dsm", E * (1 + err), t, t / 2) for k, (t, err) in spec.items()}
    ax = plots.speed_accuracy(results, reference=E)
    got = plots.drawn(ax)
    # d is beaten by b (as accurate, faster), e by b and a: the front is c, a, b, f by time
    np.testing.assert_allclose(got["pareto front"], [spec[k] for k in "cabf"], rtol=1e-9)
    for k, (t, err) in spec.items():
        np.testing.assert_allclose(got[f"point {k}"], [[t, err]], rtol=1e-9)
    assert ax.get_xscale() == ax.get_yscale() == "log" and "reference" not in got
    # a reference result is a line at its wall time, not a point
    got = plots.drawn(plots.speed_accuracy(_RESULTS, _RESULTS["dem"], run_time=True))
    assert "point dem" not in got and got["reference"][0, 0] == _RESULTS["dem"].wall_time
    np.testing.assert_allclose(got["run ste"], [[0.01, 0.08]], rtol=1e-9)
    with pytest.raises(ValueError, match="positive"):
        plots.speed_accuracy(results, reference=0.0)
    listed = plots.drawn(plots.speed_accuracy([_RESULTS["dsm"], _RESULTS["dsm stol 1e-3"], _RESULTS["ste"]], 1e8))
    dsm, ste = plots.METHOD_NAMES["dsm"], plots.METHOD_NAMES["ste"]
    assert {f"point {dsm}", f"point {dsm} #2", f"point {ste}"} <= set(listed)  # a list: labelled by method
    import jaxbpm

    assert jaxbpm.plots is plots  # (loaded on first use, as the other submodules)


# ------------------------------------------------------------------------------------------------ calibration
def test_the_calibration_plot_draws_targets_parameters_and_times():
    h = _history()
    h.append(kind="check", level="dem", values=[1.3e9, 0.25], loss=1e-4, errors=[-0.002], evaluations=5, time=2.0)
    axes = h.plot()
    assert len(axes) == 4 and len({a.figure for a in axes}) == 1
    got = {}
    for a in axes:
        got.update(plots.drawn(a))
    it = np.arange(1, 6)
    np.testing.assert_allclose(got["error youngs_modulus"], np.stack([it, 100 * np.abs(h.column("errors")[:, 0])], 1))
    np.testing.assert_allclose(got["parameter bond_E"][:, 1], h.column("values")[:, 0] / 1e9)
    np.testing.assert_allclose(got["time dsm"], [[1, 0.0], [2, 0.1], [3, 0.2], [4, 0.3]])
    np.testing.assert_allclose(got["time dem"], [[5, 2.0]])
    np.testing.assert_allclose(got["loss"][:, 1], h.column("loss"))
    fig = plot_history(h)  # the old call: a Figure
    assert isinstance(fig, Figure) and len(fig.axes) == 4
    res = CalibrationResult(values={"bond_E": 1.3e9}, params={}, errors={"youngs_modulus": -0.002}, converged=True,
                            method="adam", solver="dsm", evaluations=5, iterations=5, wall_time=2.6, tol=0.01,
                            history=h)
    assert isinstance(res.plot(), Figure)
    own = Figure().subplots(2, 2)
    assert list(res.plot(axes=own)) == list(own.ravel()) and plots.drawn(own[1, 1])["time dem"].shape == (1, 2)
    with pytest.raises(ValueError, match="four axes"):
        h.plot(axes[:2])
