"""Execute the notebooks at their small size and store them with their outputs: ``python notebooks/execute.py``.

Each notebook runs top to bottom in a fresh Jupyter kernel (``nbclient`` + ``ipykernel``, from the ``test`` extra)
with ``JAXBPM_NOTEBOOK_SMALL=1`` (the size the test suite runs), figures drawn inline, in a temporary working
directory (the notebooks' files do not land in the repository), importing the jaxbpm of this repository. A cell that
raises stops the script with the notebook and cell named, and nothing is written. On success the notebook is written
back with its outputs and, in its metadata, ``jaxbpm``: the version that made the outputs and the SHA-256 of its code
cells' sources. ``tests/test_notebooks.py`` compares both with the current ones, so outputs left from an older
version or from edited code fail the suite until this script is run again.

Usage::

    python notebooks/execute.py                       # every notebook under notebooks/
    python notebooks/execute.py 05_lammps_sample      # some of them (file names, with or without .ipynb)
    python notebooks/execute.py --check               # execute, write nothing (what the suite does)
"""

from __future__ import annotations

import argparse
import hashlib
import os
import pathlib
import sys
import tempfile
import time

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent
METADATA_KEY = "jaxbpm"
INLINE = "module://matplotlib_inline.backend_inline"


def notebooks(names=()) -> list[pathlib.Path]:
    """The notebooks under ``notebooks/``: all of them, or those named (stems or file names)."""
    every = sorted(HERE.glob("*.ipynb"))
    if not names:
        return every
    wanted = {pathlib.Path(n).stem for n in names}
    missing = wanted - {p.stem for p in every}
    if missing:
        raise SystemExit(f"no notebook named {sorted(missing)} under {HERE}")
    return [p for p in every if p.stem in wanted]


def _source(cell) -> str:
    src = cell.get("source", "")
    return "".join(src) if isinstance(src, list) else src


def code_digest(nb) -> str:
    """SHA-256 of the notebook's code cells' sources, in order (markdown edits do not change it)."""
    h = hashlib.sha256()
    for cell in nb["cells"]:
        if cell["cell_type"] == "code":
            h.update(_source(cell).encode("utf-8") + b"\0")
    return h.hexdigest()


def jaxbpm_version() -> str:
    """``jaxbpm.__version__`` of this repository (read from its file: no import of jaxbpm or JAX)."""
    text = (ROOT / "jaxbpm" / "_version.py").read_text(encoding="utf-8")
    for line in text.splitlines():
        if line.startswith("__version__"):
            return line.split("=", 1)[1].strip().strip("\"'")
    raise RuntimeError("no __version__ in jaxbpm/_version.py")


def kernel_env(extra: dict | None = None) -> dict:
    """The kernel's environment: this one, plus the small size, inline figures and this repository's jaxbpm first on
    the path; ``extra`` on top (the suite adds its compilation cache and its strict JAX settings)."""
    env = dict(os.environ)
    env.update(JAXBPM_NOTEBOOK_SMALL="1", MPLBACKEND=INLINE, PYTHONHASHSEED="0")
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    env.update(extra or {})
    return env


def execute(path: pathlib.Path, *, env: dict | None = None, timeout: int = 900, km=None):
    """Run the notebook at ``path`` in a new kernel; returns the executed notebook (``nbformat.NotebookNode``).

    Args:
      path: the ``.ipynb`` file.
      env: the kernel's environment (default :func:`kernel_env`).
      timeout: seconds a cell may take.
      km: a started ``jupyter_client.KernelManager`` to run in instead of a new kernel (left running; its
        execution counts go on from the last notebook it ran).

    Returns:
      The notebook with its outputs and ``metadata["jaxbpm"]`` (``version``, ``code_sha256``, ``small``).

    Raises:
      nbclient.exceptions.CellExecutionError: a cell raised (the message holds the cell and the traceback).
    """
    import nbformat
    from nbclient import NotebookClient

    nb = nbformat.read(path, as_version=4)
    if km is not None:
        NotebookClient(nb, km=km, timeout=timeout, record_timing=False).execute()
    else:
        with tempfile.TemporaryDirectory(prefix=f"jaxbpm-{path.stem}-") as cwd:
            client = NotebookClient(nb, timeout=timeout, kernel_name="python3", record_timing=False,
                                    resources={"metadata": {"path": cwd}})
            client.execute(env=env or kernel_env())  # start_kernel's keywords: the kernel's environment
    nb.metadata[METADATA_KEY] = {"version": jaxbpm_version(), "code_sha256": code_digest(nb), "small": True}
    return nb


def _reset(km) -> None:
    """A fresh namespace in the kernel ``km`` (restarted if a notebook killed it)."""
    if not km.is_alive():  # a notebook that killed its kernel fails alone, not the ones after it
        km.restart_kernel(now=True)
    kc = km.client()
    kc.start_channels()
    try:
        kc.wait_for_ready(timeout=120)
        reply = kc.execute_interactive("%reset -f\nimport matplotlib.pyplot as plt\nplt.close('all')\ndel plt",
                                       timeout=120)
        if reply["content"]["status"] != "ok":
            raise RuntimeError(f"the kernel's namespace could not be reset: {reply['content']}")
    finally:
        kc.stop_channels()


def run_shared(paths, into: pathlib.Path, *, timeout: int = 600) -> None:
    """Run the notebooks ``paths`` one after another in one kernel, each in a fresh namespace (so they share its
    imports and compiled programs), and write each executed notebook to ``into / name``, or, where a cell raised,
    the cell and its traceback to ``into / (name + ".error")``. The stored notebooks are left as they are."""
    import nbformat
    from jupyter_client.manager import KernelManager
    from nbclient.exceptions import CellExecutionError

    km = KernelManager(kernel_name="python3")
    with tempfile.TemporaryDirectory(prefix="jaxbpm-notebooks-") as cwd:
        km.start_kernel(env=kernel_env(), cwd=cwd)
        try:
            for path in paths:
                _reset(km)
                try:
                    nbformat.write(execute(path, km=km, timeout=timeout), into / path.name)
                except CellExecutionError as err:
                    (into / (path.name + ".error")).write_text(str(err), encoding="utf-8")
        finally:
            km.shutdown_kernel(now=True)


def main(argv=None) -> int:
    """Execute the notebooks named on the command line (default all) and write them back with their outputs."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("names", nargs="*", help="notebooks to run (default: all under notebooks/)")
    parser.add_argument("--check", action="store_true", help="execute only, write nothing")
    parser.add_argument("--into", default=None, metavar="DIR",
                        help="run the notebooks (paths) in one kernel and write the executed ones (or NAME.error) "
                             "into DIR, leaving the stored ones alone (what the test suite runs)")
    args = parser.parse_args(argv)
    import nbformat

    if args.into is not None:
        run_shared([pathlib.Path(n) for n in args.names], pathlib.Path(args.into))
        return 0

    for path in notebooks(args.names):
        t = time.perf_counter()
        nb = execute(path)
        if not args.check:
            nbformat.write(nb, path)
        print(f"{path.name}: {'executed' if args.check else 'executed and stored'} in "
              f"{time.perf_counter() - t:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
