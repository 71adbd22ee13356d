"""The library's imports keep to its layout (issue "One library for both cases", item 4).

import-linter checks the layers (``lint-imports``, pyproject.toml ``[tool.importlinter]``). This file
checks what it cannot express, on the source of ``plant/``, ``observers/`` and ``analysis/`` (an AST
scan, so nothing is imported to check it):

(a) no module imports a private module (a dotted part starting with ``_``) of another subpackage:
    across subpackages, names come from the subpackage (``from fmscal.plant.physics import SpatialModel``);
    inside one, its private modules are imported relatively (``from ._model import SpatialModel``);
(b) no name starting with ``_`` is imported from another subpackage;
(c) no fmscal module is imported inside a function: a function-level import hid an import cycle, and the
    layers have none (optional and heavy third-party libraries stay function-level, where they are used).

"Another subpackage": a private module ``P._m`` (and a private name in it) belongs to the package ``P``
and may be imported by any module in ``P`` or in a package inside ``P`` (``analysis.cli`` uses
``analysis._comparison``), as Python's own convention has it.

Also: no import cycle among the modules (import-linter's layers see only the subpackages, not a cycle
between two modules of one), at most 10 public modules (no dotted part starting with ``_``, packages'
``__init__`` not counted), at most 40 names in ``fmscal.observers.__all__``, and importing the packages
loads no optional dependency.
"""

import ast
import subprocess
import sys
import textwrap
from pathlib import Path

import grimp
import pytest

import fmscal.observers

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = {"plant": "fmscal.plant", "observers": "fmscal.observers", "analysis": "fmscal.analysis"}

# Files excused from the rules, each with why: none.
ALLOWED = {}

MAX_PUBLIC_MODULES = 10
MAX_OBSERVERS_ALL = 40


def module_name(path, root):
    """The dotted name of a source file under ``root`` (``plant/io/_log.py`` -> ``fmscal.plant.io._log``)."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    parts[0] = PACKAGES[parts[0]]
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def owner(dotted):
    """The package a module or name belongs to: everything before its first private part (``fmscal`` kept)."""
    parts = dotted.split(".")
    for k, part in enumerate(parts[1:], start=1):
        if part.startswith("_"):
            return ".".join(parts[:k]), True
    return dotted, False


def within(package, other):
    return package == other or package.startswith(other + ".")


def _absolute(node, package):
    """The module an ``ImportFrom`` names, made absolute from the importing file's package."""
    if not node.level:
        return node.module or ""
    base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def violations(root):
    """Every import in ``root``'s ``plant/``, ``observers/`` and ``analysis/`` breaking (a), (b) or (c).

    Returns
    -------
    list of (str, int, str, str)
        ``(file relative to root, line, rule, message)``, rule one of ``"a"``, ``"b"``, ``"c"``.
    """
    found = []
    for top in PACKAGES:
        for path in sorted((root / top).rglob("*.py")):
            rel = path.relative_to(root).as_posix()
            name = module_name(path, root)
            package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
            tree = ast.parse(path.read_text(), filename=rel)
            functions = [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
            nested = {id(i) for f in functions for i in ast.walk(f) if isinstance(i, (ast.Import, ast.ImportFrom))}
            for node in ast.walk(tree):
                if isinstance(node, ast.Import):
                    targets = [(a.name, None) for a in node.names]
                elif isinstance(node, ast.ImportFrom):
                    module = _absolute(node, package)
                    targets = [(module, a.name) for a in node.names]
                else:
                    continue
                for module, imported in targets:
                    if not module.startswith("fmscal"):
                        continue
                    if id(node) in nested:
                        found.append((rel, node.lineno, "c", f"function-level import of {module}"))
                    home, private = owner(module)        # the package the module (and its names) belong to
                    if private and not within(package, home):
                        found.append((rel, node.lineno, "a", f"private module {module} of {home}"))
                    elif imported and imported.startswith("_") and not within(package, home):
                        found.append((rel, node.lineno, "b", f"private name {imported} from {module}"))
    return found


def test_no_private_import_across_subpackages_and_no_function_level_import():
    found = [v for v in violations(ROOT) if v[0] not in ALLOWED]
    assert found == [], "\n".join(f"{f}:{line}: ({rule}) {msg}" for f, line, rule, msg in found)


def test_the_allowlist_names_existing_files():
    assert all((ROOT / f).is_file() for f in ALLOWED)


@pytest.fixture
def planted(tmp_path):
    """A copy of the layout's shape with one module breaking each rule, and one keeping them."""
    def write(rel, text):
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text))
    for pkg in ("plant", "plant/io", "observers", "observers/kalman", "analysis", "analysis/cli"):
        write(f"{pkg}/__init__.py", "")
    write("observers/kalman/_bad.py", """\
        from fmscal.observers.core._base import Observer
        from fmscal.plant.io import _as_path
        from fmscal.plant.physics._rigid_body import _inertia_matrix


        def late():
            from fmscal.plant import Log
            return Log
    """)
    write("observers/kalman/_good.py", """\
        import numpy as np
        from fmscal.observers.core import Observer, matrix as mx
        from ._filter import _private_helper
        from . import _ekf as ekf


        def lazy():
            import pinocchio
            return pinocchio, np, Observer, mx, _private_helper, ekf
    """)
    write("analysis/cli/_good.py", """\
        from .._comparison import compare, _refusal
        from fmscal.analysis._metrics import calibration_error
    """)
    return tmp_path


def test_the_scan_catches_a_planted_violation_of_each_rule(planted):
    found = violations(planted)
    assert {(f, rule) for f, _, rule, _ in found} == {("observers/kalman/_bad.py", r) for r in "abc"}
    messages = [msg for *_, msg in found]
    assert "private module fmscal.observers.core._base of fmscal.observers.core" in messages
    assert "private name _as_path from fmscal.plant.io" in messages
    assert "private module fmscal.plant.physics._rigid_body of fmscal.plant.physics" in messages
    assert "function-level import of fmscal.plant" in messages


def public_modules(root):
    """Modules whose dotted name has no part starting with ``_`` (packages' ``__init__`` not counted)."""
    names = (module_name(p, root) for top in PACKAGES for p in (root / top).rglob("*.py")
             if p.name != "__init__.py")
    return sorted(n for n in names if not any(part.startswith("_") for part in n.split(".")))


def test_few_public_modules():
    modules = public_modules(ROOT)
    assert len(modules) <= MAX_PUBLIC_MODULES, modules


def test_the_count_of_public_modules_sees_one(tmp_path):
    (tmp_path / "plant" / "io").mkdir(parents=True)
    for rel in ("plant/__init__.py", "plant/io/__init__.py", "plant/io/_log.py", "plant/io/reader.py"):
        (tmp_path / rel).write_text("")
    assert public_modules(tmp_path) == ["fmscal.plant.io.reader"]


def test_observers_exports_few_names():
    assert len(fmscal.observers.__all__) <= MAX_OBSERVERS_ALL, fmscal.observers.__all__


OPTIONAL = ("pinocchio", "mujoco", "rosbags", "rclpy")


def test_importing_the_packages_loads_no_optional_dependency():
    """In a fresh interpreter: the optional libraries load only when a function that needs them runs."""
    code = ("import sys, fmscal.plant, fmscal.observers, fmscal.analysis, fmscal.analysis.cli; "
            f"print(sorted(m for m in sys.modules if m.split('.')[0] in {OPTIONAL!r}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_the_optional_check_sees_a_loaded_one():
    """The same check, after importing one of them (pinocchio is in the test extra): it is seen."""
    code = ("import sys, pinocchio, fmscal.plant; "
            f"print(sorted(m for m in sys.modules if m.split('.')[0] in {OPTIONAL!r} and '.' not in m))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "['pinocchio']"


def cycles(imports):
    """The import cycles of a graph: its strongly connected components of more than one module (Tarjan).

    Parameters
    ----------
    imports : dict of str to iterable of str
        Each module's directly imported modules.

    Returns
    -------
    list of list of str
    """
    index, low, stack, on_stack, found = {}, {}, [], set(), []
    for root in imports:
        if root in index:
            continue
        work = [(root, iter(imports.get(root, ())))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(imports.get(w, ()))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                component = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    component.append(w)
                    if w == v:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_no_import_cycle():
    """Every import grimp sees (a function's too, so the five allowlisted files' as well)."""
    graph = grimp.build_graph(*PACKAGES.values())
    found = cycles({m: graph.find_modules_directly_imported_by(m) for m in graph.modules})
    assert found == []


def test_the_cycle_check_finds_a_cycle():
    assert cycles({"a": ["b"], "b": ["c"], "c": ["a"], "d": ["a"]}) == [["a", "b", "c"]]
    assert cycles({"a": ["b"], "b": []}) == []
