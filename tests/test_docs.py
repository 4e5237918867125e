"""The documentation: the README stays a newcomer's page, every ``python`` code block of the README and of the docs
runs as written (page by page, one fresh namespace per page, in a temporary directory), ``py`` fragments parse,
every public symbol has a docstring, and the site builds with ``mkdocs build --strict`` (no broken link, no
docstring the API pages cannot render). The built site (one build, shared by the tests that read it) has a page per
notebook with the figures it stores, every image a page shows, and no relative link of its HTML pages pointing
nowhere; the solver and workflow pages open with a figure."""

import ast
import importlib
import importlib.util
import inspect
import os
import re
import subprocess
import sys
import urllib.parse
from html.parser import HTMLParser
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


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The site, built once with ``mkdocs build --strict`` (the tests that read it share an xdist worker)."""
    out = tmp_path_factory.mktemp("site") / "site"
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(out)],
                         cwd=ROOT, capture_output=True, text=True, env=env, timeout=600)
    assert run.returncode == 0, run.stdout + run.stderr
    return out


@pytest.mark.xdist_group("docs-site")
def test_site_builds_strictly(site):
    assert (site / "api" / "core" / "index.html").is_file()
    assert (site / "index.html").is_file()


class _Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.links = []

    def handle_starttag(self, tag, attrs):
        self.links += [v for k, v in attrs if k in ("href", "src") and v]


def broken_links(site: Path) -> list[str]:
    """``page: link`` for every relative ``href``/``src`` of the site's HTML pages whose target is not in the site."""
    broken = []
    for page in sorted(site.rglob("*.html")):
        parser = _Links()
        parser.feed(page.read_text(encoding="utf-8"))
        for link in parser.links:
            target = urllib.parse.urlsplit(link)
            if target.scheme or target.netloc or not target.path:  # another site, data:, mailto:, a #fragment
                continue
            path = urllib.parse.unquote(target.path)
            resolved = (site / path.lstrip("/")) if path.startswith("/") else (page.parent / path)
            if not (resolved.is_file() or (resolved / "index.html").is_file()):
                broken.append(f"{page.relative_to(site)}: {link}")
    return broken


@pytest.mark.xdist_group("docs-site")
def test_site_has_no_broken_internal_link(site, tmp_path):
    assert not broken_links(site), broken_links(site)[:20]
    # the check finds one
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "index.html").write_text('<a href="../b/">b</a><img src="../img/x.png"><a href="#top">t</a>'
                                               '<a href="https://example.org/x">x</a>', encoding="utf-8")
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "index.html").write_text("", encoding="utf-8")
    assert broken_links(tmp_path) == ["a/index.html: ../img/x.png"]


_IMAGE = re.compile(r"!\[[^\]]*\]\(([^)\s]+)\)|<img [^>]*src=\"([^\"]+)\"")


def _images(path: Path) -> list[str]:
    text = path.read_text(encoding="utf-8")
    return [a or b for a, b in _IMAGE.findall(text) if not (a or b).startswith(("http:", "https:", "data:"))]


@pytest.mark.xdist_group("docs-site")
def test_every_image_of_the_docs_is_in_the_site(site):
    docs = ROOT / "docs"
    shown = 0
    for page in sorted(docs.rglob("*.md")):
        for image in _images(page):
            source = (page.parent / image).resolve()
            assert source.is_file(), f"{page.relative_to(ROOT)} shows {image}, which does not exist"
            assert (site / source.relative_to(docs)).is_file(), f"{image} of {page.name} is not in the site"
            shown += 1
    assert shown >= 20, shown  # the benchmarks page and the eight pages that open with a figure


NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


@pytest.mark.xdist_group("docs-site")
def test_every_notebook_is_a_page_with_its_figures(site):
    """Each stored notebook is a page under Notebooks, with every figure it stores (inline PNGs)."""
    import json

    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    assert len(NOTEBOOKS) >= 5
    for path in NOTEBOOKS:
        assert f"notebooks/{path.name}" in nav, f"{path.name} is not in the nav of mkdocs.yml"
        page = site / "notebooks" / path.stem / "index.html"
        assert page.is_file(), f"no page for {path.name}"
        html = page.read_text(encoding="utf-8")
        stored = sum("image/png" in out.get("data", {}) for cell in json.loads(path.read_text(encoding="utf-8"))["cells"]
                     for out in cell.get("outputs", []))
        assert stored and html.count("data:image/png;base64,") >= stored, (path.name, stored)


# the solver and workflow pages open with a figure: an image before any other paragraph
FIGURE_FIRST = ["index.md", "getting-started.md", "dem.md", "dsm.md", "ste.md", "methods.md", "strength.md",
                "calibration.md"]


def opening(path: Path) -> str:
    """The first block of a page after its title (paragraphs are separated by blank lines)."""
    body = path.read_text(encoding="utf-8").split("\n", 1)[1].strip()
    return body.split("\n\n", 1)[0]


@pytest.mark.parametrize("name", FIGURE_FIRST)
def test_pages_open_with_a_figure(name):
    first = opening(ROOT / "docs" / name)
    assert _images(ROOT / "docs" / name) and first.lstrip().startswith(("![", "<img", "<figure")), first[:200]


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
