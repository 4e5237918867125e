"""The package's layering and size, read from its source.

Solvers never import one another; physics, the sample and the scenes never import a solver (scenes depend on
physics, solvers on physics, sample and scenes, never the reverse). No import circle among jaxbpm's modules, no
module taking another package's ``_private`` names, no module over 600 lines, no function over 100 lines (its
docstring not counted). Every import counts, those inside functions too. The tests mirror the package: every module
has a test file of its own.

Each check is a function of a module graph or a source tree, tested on a small synthetic package as well, so that a
check is known to catch what it looks for.
"""

import ast
import pathlib

import pytest

import jaxbpm

ROOT = pathlib.Path(jaxbpm.__file__).parent
TESTS = pathlib.Path(__file__).parent
SOLVERS = ("dem", "dsm", "ste")
MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 100


def module_name(path: pathlib.Path, root: pathlib.Path = ROOT) -> str:
    """The dotted name of the module at ``path`` in the package whose directory is ``root``."""
    parts = path.relative_to(root.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _package_of(name: str, path: pathlib.Path) -> str:
    return name if path.name == "__init__.py" else name.rpartition(".")[0]


def _from_base(node: ast.ImportFrom, package: str) -> str:
    base = node.module or ""
    if node.level:
        parts = package.split(".")
        base = ".".join(parts[: len(parts) - node.level + 1] + ([base] if base else []))
    return base


def modules(root: pathlib.Path = ROOT) -> dict[str, pathlib.Path]:
    """Every module of the package at ``root``, by dotted name."""
    return {module_name(p, root): p for p in sorted(root.rglob("*.py"))}


def imports(path: pathlib.Path, root: pathlib.Path = ROOT, known: set[str] | None = None) -> set[str]:
    """The package's modules that ``path`` imports, anywhere in it (inside functions too).

    ``from P import name`` is the module ``P.name`` where that is a module (one of ``known``, default every module
    under ``root``), else ``P``: taking a submodule from a package does not wait for the package's ``__init__``.
    """
    top = root.name
    known = set(modules(root)) if known is None else known
    name = module_name(path, root)
    package = _package_of(name, path)
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = _from_base(node, package)
            out.update(f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names)
    return {m for m in out if m == top or m.startswith(top + ".")}


def graph(root: pathlib.Path = ROOT) -> dict[str, set[str]]:
    """The import graph of the package at ``root``: module -> the package's modules it imports."""
    mods = modules(root)
    return {m: imports(p, root, set(mods)) - {m} for m, p in mods.items()}


def import_circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import circles of ``graph``: its strongly connected components of more than one module (Tarjan's), each
    sorted, and every module importing itself."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in graph:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1 or v in graph.get(v, ()):
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def private_imports(root: pathlib.Path = ROOT) -> list[tuple[str, str]]:
    """``(importer, module._name)`` for every ``from P.m import _name`` (or ``from P import _name``) where the importer
    is not inside package ``P``. Top-level modules are in the root package; private modules (``import P._m``) and
    dunders are fine."""
    top = root.name
    bad = []
    for name, path in modules(root).items():
        package = _package_of(name, path)
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ImportFrom):
                continue
            base = _from_base(node, package)
            if not (base == top or base.startswith(top + ".")):
                continue
            for alias in node.names:
                private = alias.name.startswith("_") and not alias.name.endswith("__")
                if not private:
                    continue
                # the package owning the name: for `from P.m import _x` (m a module) it is P; for `from P import _x`
                # (``_x`` a private module of P, or a name in P/__init__) it is P
                owner = base if (root.parent / base.replace(".", "/") / "__init__.py").is_file() else \
                    base.rpartition(".")[0]
                if (root.parent / owner.replace(".", "/") / f"{alias.name}.py").is_file() and base == owner:
                    continue  # `from P import _m`: a private module, its names public
                if not (package == owner or package.startswith(owner + ".")):
                    bad.append((name, f"{base}.{alias.name}"))
    return sorted(bad)


def long_modules(root: pathlib.Path = ROOT, limit: int = MAX_MODULE_LINES) -> list[tuple[str, int]]:
    """``(module, lines)`` for every module of more than ``limit`` lines."""
    out = []
    for name, path in modules(root).items():
        n = len(path.read_text().splitlines())
        if n > limit:
            out.append((name, n))
    return out


def _docstring_lines(fn: ast.AST) -> int:
    body = getattr(fn, "body", [])
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
            and isinstance(body[0].value.value, str):
        return body[0].end_lineno - body[0].lineno + 1
    return 0


def long_functions(root: pathlib.Path = ROOT, limit: int = MAX_FUNCTION_LINES) -> list[tuple[str, int]]:
    """``(module:qualified.name, lines)`` for every function (methods and nested functions too) longer than ``limit``
    lines from its ``def`` (decorators not counted) to its last line, its docstring not counted."""
    out = []
    for name, path in modules(root).items():
        tree = ast.parse(path.read_text())

        def walk(node, prefix):
            for child in ast.iter_child_nodes(node):
                if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    qual = f"{prefix}{child.name}"
                    n = child.end_lineno - child.lineno + 1 - _docstring_lines(child)
                    if n > limit:
                        out.append((f"{name}:{qual}", n))
                    walk(child, qual + ".")
                elif isinstance(child, ast.ClassDef):
                    walk(child, f"{prefix}{child.name}.")
                else:
                    walk(child, prefix)

        walk(tree, "")
    return out


def own_test_files(path: pathlib.Path, root: pathlib.Path = ROOT, tests: pathlib.Path = TESTS) -> list[pathlib.Path]:
    """The test files that may test the module at ``path``: ``a/b.py`` -> ``tests/a/test_b.py``; a private ``a/_b.py``
    -> ``tests/a/test_b.py`` or ``tests/a/test__b.py``, only the latter where a public ``a/b.py`` takes the name."""
    folder = tests / path.parent.relative_to(root)
    stem = path.stem
    if not stem.startswith("_"):
        return [folder / f"test_{stem}.py"]
    if path.with_name(f"{stem[1:]}.py").is_file():
        return [folder / f"test_{stem}.py"]
    return [folder / f"test_{stem[1:]}.py", folder / f"test_{stem}.py"]


def untested_modules(root: pathlib.Path = ROOT, tests: pathlib.Path = TESTS) -> list[str]:
    """Every module of the package at ``root`` with no test file of its own under ``tests`` (:func:`own_test_files`);
    ``__init__``, ``__main__`` and ``_version`` need none."""
    return [name for name, path in modules(root).items()
            if path.name not in ("__init__.py", "__main__.py", "_version.py")
            and not any(f.is_file() for f in own_test_files(path, root, tests))]


def _solver(module: str):
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in SOLVERS else None


# --- the package -----------------------------------------------------------------------------------------------------

def test_the_walk_sees_the_package():
    g = graph()
    assert {"jaxbpm.dem", "jaxbpm.dsm", "jaxbpm.dsm.scene", "jaxbpm.ste", "jaxbpm.scenes", "jaxbpm.sample",
            "jaxbpm.physics.model"} <= set(g)
    assert "jaxbpm.dsm.linear" in g["jaxbpm.dsm.scene"]  # imports inside the package are seen
    assert "jaxbpm.dsm" in g["jaxbpm.solving"]  # and those inside functions (solve imports its solvers lazily)


def test_no_solver_imports_another():
    bad = [(m, t) for m, targets in graph().items() for t in targets
           if _solver(m) and _solver(t) and _solver(t) != _solver(m)]
    assert not bad, bad


def test_physics_sample_and_scenes_import_no_solver():
    lower = lambda m: m.startswith(("jaxbpm.physics", "jaxbpm.scenes")) or m == "jaxbpm.sample"  # noqa: E731
    bad = [(m, t) for m, targets in graph().items() if lower(m) for t in targets if _solver(t)]
    assert not bad, bad


def test_no_import_circle():
    circles = import_circles(graph())
    assert not circles, f"import circles among jaxbpm's modules: {circles}"


def test_no_private_name_across_packages():
    bad = private_imports()
    assert not bad, f"modules taking another package's private names (importer, name): {bad}"


def test_no_module_over_600_lines():
    bad = long_modules()
    assert not bad, f"modules over {MAX_MODULE_LINES} lines: {bad}"


def test_no_function_over_100_lines():
    bad = long_functions()
    assert not bad, f"functions over {MAX_FUNCTION_LINES} lines, docstrings not counted: {bad}"


def test_every_module_has_its_test_file():
    bad = untested_modules()
    assert not bad, f"modules without a test file of their own (jaxbpm/a/b.py: tests/a/test_b.py): {bad}"


# --- the checks on a synthetic package -------------------------------------------------------------------------------

def _package(tmp_path, files: dict[str, str]) -> pathlib.Path:
    root = tmp_path / "toy"
    for rel, text in {"__init__.py": "", **files}.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root


CLEAN = {
    "a/__init__.py": "",
    "a/low.py": "def _helper():\n    return 1\n\n\ndef public():\n    return _helper()\n",
    "a/high.py": "from toy.a.low import _helper, public\n",  # private name within its own package
    "_compile.py": "def put(x):\n    return x\n",
    "b/__init__.py": "from toy import _compile\n",  # a private module with public names
    "b/user.py": "from toy._compile import put\nfrom toy.a import low\n\n\n"
                 "def f():\n    from toy.a.high import public\n    return public, put, low\n",
    "c.py": "from toy.a.low import __doc__ as doc\nfrom . import b\n",  # a dunder; a relative import
}


def test_checks_pass_on_a_clean_package(tmp_path):
    root = _package(tmp_path, CLEAN)
    g = graph(root)
    assert g["toy.b.user"] == {"toy._compile", "toy.a.low", "toy.a.high"}  # inside functions too
    assert g["toy.c"] == {"toy.a.low", "toy.b"}
    assert import_circles(g) == []
    assert private_imports(root) == []
    assert long_modules(root) == []
    assert long_functions(root) == []


def test_an_import_circle_is_caught(tmp_path):
    root = _package(tmp_path, {**CLEAN,
                               "a/low.py": CLEAN["a/low.py"] + "\n\ndef g():\n    from toy.b import user\n",
                               "d/__init__.py": "", "d/x.py": "from toy.d import y\n", "d/y.py": "import toy.d.x\n"})
    assert import_circles(graph(root)) == [["toy.a.high", "toy.a.low", "toy.b.user"], ["toy.d.x", "toy.d.y"]]
    # `from P import name` is the module P.name where that is a module, else P
    root = _package(tmp_path / "2", {"m.py": "from toy.n import thing\n", "n/__init__.py": "thing = 1\n",
                                     "n/other.py": "import toy.m\n",
                                     "p/__init__.py": "from toy.p.low import x\n",
                                     "p/low.py": "from toy.p import _sib\nx = 1\n",
                                     "p/_sib.py": ""})
    assert graph(root)["toy.p.low"] == {"toy.p._sib"}
    assert import_circles(graph(root)) == []
    (root / "m.py").write_text("from toy.n import other, thing\n")
    (root / "p" / "_sib.py").write_text("def f():\n    from toy.p import x\n")
    assert import_circles(graph(root)) == [["toy.m", "toy.n.other"], ["toy.p", "toy.p._sib", "toy.p.low"]]


def test_a_private_import_across_packages_is_caught(tmp_path):
    root = _package(tmp_path, {**CLEAN, "b/sneak.py": "from toy.a.low import _helper\n",
                               "top.py": "def f():\n    from toy.a.high import _helper as h\n    return h\n",
                               "a/inner/__init__.py": "", "a/inner/ok.py": "from toy.a.low import _helper\n"})
    assert private_imports(root) == [("toy.b.sneak", "toy.a.low._helper"), ("toy.top", "toy.a.high._helper")]


def test_a_long_module_is_caught(tmp_path):
    root = _package(tmp_path, {**CLEAN, "big.py": "x = 1\n" * 601, "edge.py": "x = 1\n" * 600})
    assert long_modules(root) == [("toy.big", 601)]


def test_a_long_function_is_caught(tmp_path):
    body = "    x = 1\n" * 99
    doc = '    """' + "A docstring.\n" * 30 + '    """\n'
    nested = "def outer():\n    def inner():\n" + "        x = 1\n" * 100 + "    return inner\n"
    method = "class C:\n    @staticmethod\n    def m():\n" + "        x = 1\n" * 99 + "        return 1\n"
    root = _package(tmp_path, {**CLEAN, "f.py": f"def ok():\n{doc}{body}\n\ndef long():\n{body}    x = 2\n",
                               "g.py": f"{method}\n\n{nested}"})
    assert long_functions(root) == [("toy.f:long", 101), ("toy.g:C.m", 101), ("toy.g:outer", 103),
                                    ("toy.g:outer.inner", 101)]


def test_a_module_without_its_test_file_is_caught(tmp_path):
    root = _package(tmp_path, {**CLEAN, "__main__.py": "", "_version.py": "", "b/_hidden.py": "", "b/name.py": "",
                               "b/_name.py": ""})
    tests = tmp_path / "tests"
    for rel in ("a/test_low.py", "a/test_high.py", "test_compile.py", "b/test_user.py", "test_c.py",
                "b/test_name.py", "b/test__name.py"):
        (tests / rel).parent.mkdir(parents=True, exist_ok=True)
        (tests / rel).write_text("")
    assert untested_modules(root, tests) == ["toy.b._hidden"]
    (tests / "b" / "test__hidden.py").write_text("")  # either name for a private module without a public twin
    assert untested_modules(root, tests) == []
    (tests / "b" / "test__name.py").unlink()  # `test_name.py` is public `name.py`'s, not `_name.py`'s
    (tests / "test_c.py").rename(tests / "a" / "test_c.py")  # a test file in another folder is not the module's
    assert untested_modules(root, tests) == ["toy.b._name", "toy.c"]
