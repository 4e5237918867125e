"""The package's layering, read from its source: solvers never import one another; physics, the sample and the
scenes never import a solver (scenes depend on physics, solvers on physics, sample and scenes, never the reverse).
Every import counts, those inside functions too."""

import ast
import pathlib

import jaxbpm

ROOT = pathlib.Path(jaxbpm.__file__).parent
SOLVERS = ("dem", "dsm", "ste")


def _module_name(path: pathlib.Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: pathlib.Path) -> set[str]:
    """The jaxbpm modules ``path`` imports (``from jaxbpm import dsm`` counts as ``jaxbpm.dsm``)."""
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1] + ([base] if base else []))
            out.add(base)
            out.update(f"{base}.{a.name}" for a in node.names)
    return {m for m in out if m == "jaxbpm" or m.startswith("jaxbpm.")}


def _solver(module: str):
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in SOLVERS else None


def _graph():
    return {_module_name(p): _imports(p) for p in ROOT.rglob("*.py")}


def test_the_walk_sees_the_package():
    graph = _graph()
    assert {"jaxbpm.dem", "jaxbpm.dsm", "jaxbpm.dsm.scene", "jaxbpm.ste", "jaxbpm.scenes", "jaxbpm.sample",
            "jaxbpm.physics.model"} <= set(graph)
    assert "jaxbpm.dsm.linear" in graph["jaxbpm.dsm.scene"]  # imports inside the package are seen
    assert "jaxbpm.dsm" in graph["jaxbpm.solving"]  # and those inside functions (solve imports its solvers lazily)


def test_no_solver_imports_another():
    bad = [(m, t) for m, targets in _graph().items() for t in targets
           if _solver(m) and _solver(t) and _solver(t) != _solver(m)]
    assert not bad, bad


def test_physics_sample_and_scenes_import_no_solver():
    lower = lambda m: m.startswith(("jaxbpm.physics", "jaxbpm.scenes")) or m == "jaxbpm.sample"  # noqa: E731
    bad = [(m, t) for m, targets in _graph().items() if lower(m) for t in targets if _solver(t)]
    assert not bad, bad
