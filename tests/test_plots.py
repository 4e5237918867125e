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

from jaxbpm import cli, io
from jaxbpm.calibrate.history import History, plot_history


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


_TABLE = [{"method": m, "difference_to_dem": d, "run_time": r, "wall_time": w, "speedup_run": 2.0 / r}
          for m, d, r, w in (("dem", 0.0, 2.0, 3.5), ("dsm", 1e-4, 0.05, 0.9), ("dsm stol 1e-3", 2e-3, 0.04, 0.8),
                             ("ste", 0.08, 0.01, 0.6))]
_SAMPLE = types.SimpleNamespace(n_particles=54, n_bonds=117)


def _plot_all(tmp):
    """Call every plot function of jaxbpm once; returns {name: (returned object, file)}."""
    return {
        "plot_history": (plot_history(_history(), tmp / "history.svg"), tmp / "history.svg"),
        "plot_local_map": (io.plot_local_map(tmp / "map.png", _local_map()), tmp / "map.png"),
        "demo chart": (cli._demo_chart(tmp / "chart.png", _TABLE, _SAMPLE), tmp / "chart.png"),
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
    assert out["demo chart"][0] == tmp_path / "chart.png"
    for name, (_, path) in out.items():
        assert path.stat().st_size > 5000, name
    assert (tmp_path / "history.svg").read_text().lstrip().startswith("<?xml")  # the format follows the suffix
    assert not list(tmp_path.glob(".*.tmp"))  # atomic: no temporary file left behind


def test_demo_chart_has_a_legend_and_wall_times(tmp_path, monkeypatch):
    saved = []
    monkeypatch.setattr(Figure, "savefig", lambda self, *a, **kw: saved.append(self) or open(a[0], "wb").close())
    cli._demo_chart(tmp_path / "chart.png", _TABLE, _SAMPLE)
    (fig,) = saved
    (ax,) = fig.axes
    (legend,) = fig.legends
    labels = [t.get_text() for t in legend.get_texts()]
    for row in _TABLE:
        assert any(row["method"] in t and "wall" in t and f"{row['wall_time']:.3g}" in t for t in labels), labels
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

