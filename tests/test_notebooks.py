"""The example notebooks under ``notebooks/`` are stored executed, by the current jaxbpm, and run as notebooks.

Stored: every code cell has run, in order, with no error output; every figure a cell shows is stored (an
``image/png`` output); ``metadata["jaxbpm"]`` names the jaxbpm version and the SHA-256 of the code cells that made
the outputs, and both must be the current ones (``python notebooks/execute.py`` stores them again).

Run: the notebooks are executed in one Jupyter kernel (``nbclient`` + ``ipykernel``), each in a fresh namespace
(``%reset -f``), by ``notebooks/execute.py --into`` in a process of its own (the test process never loads Jupyter's
client, its threads and ZMQ), at their small size (``JAXBPM_NOTEBOOK_SMALL=1``), in a temporary directory, with the
suite's strict JAX settings and a compilation cache of their own; a cell that raises fails the test with the cell
and its traceback. ``python notebooks/execute.py`` runs each in a kernel of its own and stores it. Each notebook
asserts a physical outcome of its own (e.g. the DSM within 5 % of the DEM, a calibrated modulus confirmed by a DEM
run), so a failing check fails the test. The figures drawn now must be those stored.
"""

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOK_DIR = ROOT / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))

_spec = importlib.util.spec_from_file_location("notebooks_execute", NOTEBOOK_DIR / "execute.py")
execute = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(execute)


def _source(cell) -> str:
    src = cell.get("source", "")
    return "".join(src) if isinstance(src, list) else src


def _code(nb) -> list:
    return [c for c in nb["cells"] if c["cell_type"] == "code"]


def _cells_with_figures(nb) -> list[int]:
    return [k for k, cell in enumerate(_code(nb))
            if any("image/png" in out.get("data", {}) for out in cell.get("outputs", []))]


def stored_problems(nb) -> list[str]:
    """What is wrong with a notebook as stored: not run, run out of order, an error, a figure missing, outputs of
    another version or of other code. Empty when it is as ``notebooks/execute.py`` writes it."""
    problems = []
    code = _code(nb)
    counts = [c.get("execution_count") for c in code]
    if counts != list(range(1, len(code) + 1)):
        problems.append(f"code cells not run top to bottom in one kernel (execution counts {counts})")
    for k, cell in enumerate(code):
        outs = cell.get("outputs", [])
        if any(o.get("output_type") == "error" for o in outs):
            problems.append(f"code cell {k + 1} stored with an error")
        if "plt.show()" in _source(cell) and not any("image/png" in o.get("data", {}) for o in outs):
            problems.append(f"code cell {k + 1} shows a figure but none is stored")
    if not any(c.get("outputs") for c in code):
        problems.append("no outputs stored")
    meta = nb.get("metadata", {}).get(execute.METADATA_KEY)
    if not meta:
        problems.append("no metadata['jaxbpm']: not stored by notebooks/execute.py")
    else:
        if meta.get("version") != execute.jaxbpm_version():
            problems.append(f"outputs from jaxbpm {meta.get('version')}, this is {execute.jaxbpm_version()}")
        if meta.get("code_sha256") != execute.code_digest(nb):
            problems.append("the code cells changed since the outputs were stored")
        if meta.get("small") is not True:
            problems.append("not executed at the small size")
    return problems


def _notebook(path: Path) -> dict:
    return json.loads(path.read_text(encoding="utf-8"))


def test_the_five_notebooks_are_stored_executed():
    names = [p.name for p in NOTEBOOKS]
    assert names[:5] == ["01_quick_start.ipynb", "02_elastic_calibration.ipynb", "03_surrogate_stress_strain.ipynb",
                         "04_strength_calibration.ipynb", "05_lammps_sample.ipynb"], names
    hint = "; store the outputs again with `python notebooks/execute.py NAME`"
    for path in NOTEBOOKS:
        nb = _notebook(path)
        assert nb["nbformat"] == 4, path.name
        code = _code(nb)
        assert code and any(c["cell_type"] == "markdown" for c in nb["cells"]), path.name
        first = _source(code[0])
        assert 'jax.config.update("jax_enable_x64", True)' in first and "JAXBPM_NOTEBOOK_SMALL" in first, path.name
        assert any("assert " in _source(c) for c in code), f"{path.name} checks no outcome"
        assert not stored_problems(nb), f"{path.name}: {stored_problems(nb)}{hint}"


def test_the_version_stored_is_jaxbpms():
    import jaxbpm

    assert execute.jaxbpm_version() == jaxbpm.__version__


def test_stored_problems_are_found():
    """The check above fails a notebook saved without outputs, with an error, or from another version or code."""
    nb = _notebook(NOTEBOOK_DIR / "01_quick_start.ipynb")
    assert stored_problems(nb) == []
    bare = json.loads(json.dumps(nb))
    for cell in _code(bare):
        cell["outputs"], cell["execution_count"] = [], None
    found = " ".join(stored_problems(bare))
    assert "not run top to bottom" in found and "no outputs stored" in found and "none is stored" in found
    old = json.loads(json.dumps(nb))
    old["metadata"]["jaxbpm"]["version"] = "0.0.1"
    assert any("jaxbpm 0.0.1" in p for p in stored_problems(old))
    edited = json.loads(json.dumps(nb))
    _code(edited)[-1]["source"] += "\nassert True\n"
    assert stored_problems(edited) == ["the code cells changed since the outputs were stored"]
    broken = json.loads(json.dumps(nb))
    _code(broken)[0]["outputs"].append({"output_type": "error", "ename": "E", "evalue": "", "traceback": []})
    assert stored_problems(broken) == ["code cell 1 stored with an error"]


def _runner_env(cache) -> dict:
    """The runner's environment: the suite's strict JAX settings and XLA flags, a compilation cache of its own."""
    env = dict(os.environ)
    env.update(JAX_NUMPY_DTYPE_PROMOTION="strict", JAX_NUMPY_RANK_PROMOTION="raise", JAXBPM_CACHE_DIR=str(cache),
               JAX_COMPILATION_CACHE_DIR=str(cache), JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0")
    env.pop("JAXBPM_TEST_XLA_CACHE", None)
    return env


def run_notebooks(paths, into: Path, cache: Path) -> None:
    """``notebooks/execute.py --into``: the notebooks run in one kernel, started by a process of its own (the test
    process never loads Jupyter's client, its threads and ZMQ); the executed ones land in ``into``."""
    into.mkdir(parents=True, exist_ok=True)
    r = subprocess.run([sys.executable, str(NOTEBOOK_DIR / "execute.py"), "--into", str(into), *map(str, paths)],
                       env=_runner_env(cache), capture_output=True, text=True, timeout=1800)
    assert r.returncode == 0, r.stderr[-3000:]


@pytest.fixture(scope="module")
def executed(tmp_path_factory):
    """The five notebooks executed now, in one kernel: ``{name: notebook or the error text}``."""
    import nbformat

    into, cache = tmp_path_factory.mktemp("executed"), tmp_path_factory.mktemp("xla")
    run_notebooks(NOTEBOOKS, into, cache)
    out = {}
    for path in NOTEBOOKS:
        error = into / (path.name + ".error")
        out[path.name] = error.read_text(encoding="utf-8") if error.exists() else nbformat.read(into / path.name, 4)
    return out


@pytest.mark.xdist_group("notebooks")  # one worker runs the fixture, once
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs_in_a_kernel(path, executed):
    nb = executed[path.name]
    if isinstance(nb, str):
        pytest.fail(f"{path.name}: a cell failed\n{nb}", pytrace=False)
    problems = [p for p in stored_problems(nb) if "execution counts" not in p]  # the kernel's counts go on
    assert not problems, (path.name, problems)
    assert _cells_with_figures(nb) == _cells_with_figures(_notebook(path)), "the figures drawn are not those stored"


def test_a_cell_that_raises_fails(tmp_path):
    """A cell that raises is reported with its error; the next notebook in the kernel starts from an empty
    namespace."""
    import nbformat

    first, second = tmp_path / "a_failing.ipynb", tmp_path / "b_reset.ipynb"
    nbformat.write(nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("x = 1"),
                                                   nbformat.v4.new_code_cell("assert x == 2, 'x is not 2'")]), first)
    nbformat.write(nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("print(x)")]), second)
    run_notebooks([first, second], tmp_path / "out", tmp_path / "xla")
    assert "x is not 2" in (tmp_path / "out" / "a_failing.ipynb.error").read_text()
    assert "NameError" in (tmp_path / "out" / "b_reset.ipynb.error").read_text()
