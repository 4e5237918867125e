"""The documentation: the README stays a newcomer's page, every ``python`` code block of the README and of the docs
runs as written (page by page, one fresh namespace per page, in a temporary directory), ``py`` fragments parse,
every public symbol has a docstring, and the site builds with ``mkdocs build --strict`` (no broken link, no
docstring the API pages cannot render)."""

import ast
import importlib
import importlib.util
import inspect
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))
_BLOCK = re.compile(r"^```(\w+)[^\n]*\n(.*?)^```", re.S | re.M)


def blocks(path: Path, language: str) -> list[str]:
    return [code for lang, code in _BLOCK.findall(path.read_text(encoding="utf-8")) if lang == language]


def _runnable_pages():
    seen, pages = set(), []
    for path in PAGES:
        code = [b for b in blocks(path, "python") if b not in seen]  # a block shown twice runs once
        seen.update(code)
        if code:
            pages.append(pytest.param(path, code, id=path.name))
    return pages


def test_readme_is_a_newcomers_page():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.encode()) <= 10_000, f"README.md is {len(text.encode())} bytes; move details to docs/"
    for section in ("## Quick start", "## A short example", "## Time to answer"):
        assert section in text
    assert "docs/" in text and "mkdocs" in text
    example = blocks(ROOT / "README.md", "python")
    assert len(example) == 1 and len(example[0].strip().splitlines()) <= 20


@pytest.mark.parametrize("path, code", _runnable_pages())
def test_code_blocks_run(path, code, tmp_path, monkeypatch):
    """Each page's ``python`` blocks, in order, in one namespace (as a reader would paste them)."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    namespace = {"__name__": f"docs_{path.stem}"}
    for k, block in enumerate(code):
        try:
            exec(compile(block, f"{path.name}[python block {k + 1}]", "exec"), namespace)
        except Exception as err:  # noqa: BLE001 -- name the page and block, keep the cause
            raise AssertionError(f"{path.name}, python block {k + 1} failed: {err!r}\n{block}") from err
    import matplotlib.pyplot as plt

    plt.close("all")


@pytest.mark.parametrize("path", PAGES, ids=[p.name for p in PAGES])
def test_fragments_parse(path):
    for block in blocks(path, "py"):
        ast.parse(block)


def _documented_modules():
    text = "\n".join(p.read_text(encoding="utf-8") for p in sorted((ROOT / "docs" / "api").glob("*.md")))
    return sorted({m.group(1) for m in re.finditer(r"^::: ([\w.]+)", text, re.M)})


def test_every_public_symbol_has_a_docstring():
    missing = []
    for target in _documented_modules():
        try:
            obj = importlib.import_module(target)
        except ImportError:
            mod, _, name = target.rpartition(".")
            obj = getattr(importlib.import_module(mod), name)
        if not inspect.ismodule(obj):
            if not inspect.getdoc(obj):
                missing.append(target)
            continue
        if not (obj.__doc__ or "").strip():
            missing.append(target)
        for name in getattr(obj, "__all__", []):
            member = getattr(obj, name)
            if inspect.ismodule(member) or not (callable(member) or inspect.isclass(member)):
                continue
            if not (member.__doc__ or "").strip():
                missing.append(f"{target}.{name}")
    assert not missing, f"public symbols without a docstring: {missing}"


def test_site_builds_strictly(tmp_path):
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(tmp_path / "site")],
                         cwd=ROOT, capture_output=True, text=True, env=env, timeout=600)
    assert run.returncode == 0, run.stdout + run.stderr
    assert (tmp_path / "site" / "api" / "core" / "index.html").is_file()


def test_benchmark_figures_are_traceable():
    """Every results file that docs/benchmarks.md names is committed, and every image it shows exists."""
    text = (ROOT / "docs" / "benchmarks.md").read_text(encoding="utf-8")
    named = set(re.findall(r"`(?:results/)?((?:gpu/)?[\w.]+\.json)`", text))
    committed = set(subprocess.run(["git", "ls-files", "results"], cwd=ROOT, capture_output=True, text=True,
                                   check=True).stdout.split())
    missing = sorted(n for n in named if f"results/{n}" not in committed and not (ROOT / "results" / n).is_file())
    assert named and not missing, f"docs/benchmarks.md names results files that do not exist: {missing}"
    images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert images and all((ROOT / "docs" / im).is_file() for im in images), images


def test_charts_are_drawn_from_the_results_there_are(tmp_path):
    """benchmarks/charts.py draws a chart per results file set that exists, and skips those that do not."""
    spec = importlib.util.spec_from_file_location("charts", ROOT / "benchmarks" / "charts.py")
    charts = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(charts)
    results = tmp_path / "results"
    (results / "gpu").mkdir(parents=True)
    for name in ("vs_lammps.json", "dem_throughput_3k_100k_1core.json", "gpu/dem_throughput_float64.json"):
        (results / name).write_bytes((ROOT / "results" / name).read_bytes())
    written = charts.main(["--results", str(results), "--out", str(tmp_path / "img")])
    assert sorted(p.name for p in written) == ["dem_throughput.png", "vs_lammps.png"]  # no scaling file: skipped
    assert all(p.stat().st_size > 10_000 for p in written)
    points = charts.throughput_points(results)
    assert points["CPU, one core, float64, bonds only"] == [(3000, pytest.approx(2.4275e7, rel=1e-4)),
                                                           (100000, pytest.approx(1.1689e7, rel=1e-4))]
    assert [p[0] for p in charts.lammps_pairs(results)] == ["3k box, compression,\nbonds only"]
