"""The example notebooks under ``notebooks/`` are stored executed, by the current jaxbpm, and run as notebooks.

Stored: every code cell has run, in order, with no error output; every figure a cell shows is stored (an
``image/png`` output); ``metadata["jaxbpm"]`` names the jaxbpm version and the SHA-256 of the code cells that made
the outputs, and both must be the current ones (``python notebooks/execute.py`` stores them again).

Run: each notebook is executed in a Jupyter kernel (``nbclient`` + ``ipykernel``, through
``notebooks/execute.py``) at its small size (``JAXBPM_NOTEBOOK_SMALL=1``), in a temporary directory, with the
suite's persistent compilation cache and strict JAX settings; a cell that raises fails the test with the cell and
its traceback. The notebooks a test process runs share one kernel, each in a fresh namespace (``%reset -f``), so
they share imports and compiled programs as they did when run as scripts in the test process;
``python notebooks/execute.py`` runs each in a kernel of its own. Each notebook asserts a physical outcome of its own (e.g. the DSM within 5 % of the DEM, a calibrated
modulus confirmed by a DEM run), so a failing check fails the test. The figures drawn now must be those stored.
"""

import importlib.util
import json
import os
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


def _param(path):
    # notebook 04's DEM failure runs are the strength-calibration DEM test's programs: on one worker, one after the
    # other, the second reads them from the suite's compilation cache
    marks = [pytest.mark.xdist_group("strength-150")] if path.stem == "04_strength_calibration" else []
    return pytest.param(path, id=path.stem, marks=marks)


def _kernel_env() -> dict:
    cache = os.environ["JAXBPM_TEST_XLA_CACHE"]  # conftest's: the suite's own compilation cache
    return execute.kernel_env({
        "JAX_COMPILATION_CACHE_DIR": cache, "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0",
        "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "0", "JAX_NUMPY_DTYPE_PROMOTION": "strict",
        "JAX_NUMPY_RANK_PROMOTION": "raise", "XLA_FLAGS": os.environ.get("XLA_FLAGS", "")})


@pytest.fixture(scope="module")
def kernel(tmp_path_factory):
    """One kernel for the notebooks a test process runs (each in a fresh namespace: ``%reset -f`` before it), so
    they share its imports and compiled programs as one Python process would; started in a temporary directory."""
    from jupyter_client.manager import KernelManager

    km = KernelManager(kernel_name="python3")
    km.start_kernel(env=_kernel_env(), cwd=str(tmp_path_factory.mktemp("kernel")))
    yield km
    km.shutdown_kernel(now=True)


def _reset(km):
    if not km.is_alive():  # a notebook that killed its kernel fails alone, not the ones after it
        km.restart_kernel(now=True)
    kc = km.client()
    kc.start_channels()
    try:
        kc.wait_for_ready(timeout=120)
        reply = kc.execute_interactive("%reset -f\nimport matplotlib.pyplot as plt\nplt.close('all')\ndel plt",
                                       timeout=120)
        assert reply["content"]["status"] == "ok", reply["content"]
    finally:
        kc.stop_channels()


@pytest.mark.parametrize("path", [_param(p) for p in NOTEBOOKS])
def test_notebook_runs_in_a_kernel(path, kernel):
    from nbclient.exceptions import CellExecutionError

    _reset(kernel)
    try:
        nb = execute.execute(path, km=kernel, timeout=600)
    except CellExecutionError as err:
        pytest.fail(f"{path.name}: a cell failed\n{err}", pytrace=False)
    problems = [p for p in stored_problems(nb) if "execution counts" not in p]  # the kernel's counts go on
    assert not problems, (path.name, problems)
    assert _cells_with_figures(nb) == _cells_with_figures(_notebook(path)), "the figures drawn are not those stored"


def test_a_cell_that_raises_fails(kernel, tmp_path):
    import nbformat
    from nbclient.exceptions import CellExecutionError

    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("x = 1"),
                                         nbformat.v4.new_code_cell("assert x == 2, 'x is not 2'")])
    path = tmp_path / "failing.ipynb"
    nbformat.write(nb, path)
    _reset(kernel)
    with pytest.raises(CellExecutionError, match="x is not 2"):
        execute.execute(path, km=kernel, timeout=60)
    _reset(kernel)  # the namespace a notebook leaves is gone before the next
    with pytest.raises(CellExecutionError, match="NameError"):
        nbformat.write(nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("print(x)")]), path)
        execute.execute(path, km=kernel, timeout=60)
