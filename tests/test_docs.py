"""Every public name of the three packages is documented, and listed in the API reference.

A name is public when it is in the ``__all__`` of ``fmscal.plant``, ``fmscal.observers`` or
``fmscal.analysis``, or of one of their modules whose name does not start with an underscore.
The API reference is ``docs/api/{plant,observers,analysis}.rst``: autosummary lists under
``.. currentmodule::`` directives, from which Sphinx generates a page per name (CI builds the
site with ``-W``; this test does not build it).
"""

import ast
import importlib
import inspect
import pkgutil
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("fmscal.plant", "fmscal.observers", "fmscal.analysis")
API_PAGES = {pkg: ROOT / "docs" / "api" / f"{pkg.split('.')[1]}.rst" for pkg in PACKAGES}


def public_names(package):
    """``{dotted path: object}`` of every public name of ``package``."""
    pkg = importlib.import_module(package)
    names = {f"{package}.{n}": getattr(pkg, n) for n in pkg.__all__}
    for info in pkgutil.iter_modules(pkg.__path__):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{package}.{info.name}")
        for n in getattr(module, "__all__", ()):
            names[f"{module.__name__}.{n}"] = getattr(module, n)
    return names


def listed_names(page):
    """Dotted paths an API page lists in its autosummary blocks, with their line numbers."""
    listed, current, in_block = {}, None, False
    for number, line in enumerate(page.read_text().splitlines(), start=1):
        match = re.match(r"\.\. currentmodule:: (\S+)", line)
        if match:
            current, in_block = match.group(1), False
        elif line.startswith(".. autosummary::"):
            in_block = True
        elif in_block and line.startswith("   ") and line.strip() and not line.strip().startswith(":"):
            listed[f"{current}.{line.strip()}"] = number
        elif in_block and line.strip() and not line.startswith(" "):
            in_block = False
    return listed


def resolve(path):
    module, _, name = path.rpartition(".")
    return getattr(importlib.import_module(module), name)


def attribute_doc(module_name, name):
    """The ``#:`` comment or the string after a module-level assignment of ``name`` (Sphinx's rule)."""
    module = importlib.import_module(module_name)
    source = Path(module.__file__).read_text()
    lines = source.splitlines()
    body = ast.parse(source).body
    for i, node in enumerate(body):
        targets = node.targets if isinstance(node, ast.Assign) else (
            [node.target] if isinstance(node, ast.AnnAssign) else [])
        if not any(isinstance(t, ast.Name) and t.id == name for t in targets):
            continue
        comment = []
        k = node.lineno - 2
        while k >= 0 and lines[k].lstrip().startswith("#:"):
            comment.insert(0, lines[k].lstrip()[2:].strip())
            k -= 1
        inline = lines[node.lineno - 1].partition("#:")[2].strip()
        after = body[i + 1] if i + 1 < len(body) else None
        string = (after.value.value if isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant)
                  and isinstance(after.value.value, str) else "")
        return " ".join(comment) or inline or string.strip()
    return None


def data_doc(path):
    """The documentation of a constant, found where it is defined (its module, or a submodule)."""
    module, _, name = path.rpartition(".")
    doc = attribute_doc(module, name)
    if doc is None:  # imported into a package's __init__: look where it is assigned
        package = importlib.import_module(module)
        for info in pkgutil.iter_modules(getattr(package, "__path__", ())):
            doc = attribute_doc(f"{module}.{info.name}", name)
            if doc is not None:
                break
    return doc or ""


def docstring(path, obj):
    if inspect.isclass(obj) or inspect.isroutine(obj):
        doc = (obj.__doc__ or "").strip()
        # dataclasses and named tuples make up a docstring, the signature: that is none.
        return "" if doc.startswith(f"{obj.__name__}(") else doc
    return data_doc(path)


ALL_PUBLIC = {path: obj for pkg in PACKAGES for path, obj in public_names(pkg).items()}


def test_the_packages_have_public_names():
    # Guards the collection itself: a broken walk must not pass every check vacuously.
    assert 150 < len(ALL_PUBLIC) < 1000
    assert "fmscal.observers.AdaptiveObserver" in ALL_PUBLIC
    assert "fmscal.analysis._comparison.compare" in ALL_PUBLIC


@pytest.mark.parametrize("path", sorted(ALL_PUBLIC))
def test_public_name_has_a_docstring(path):
    assert docstring(path, ALL_PUBLIC[path]), f"{path} has no docstring (a '#:' comment for a constant)"


@pytest.mark.parametrize("package", PACKAGES)
def test_every_public_name_is_in_the_api_reference(package):
    listed = listed_names(API_PAGES[package])
    missing = []
    for path, obj in public_names(package).items():
        name = path.rpartition(".")[2]
        # Listed under this path, or under another public path to the same object and name
        # (a class defined in a module and imported into its package is listed once).
        if path not in listed and not any(
                other.rpartition(".")[2] == name and other in ALL_PUBLIC and ALL_PUBLIC[other] is obj
                for other in listed):
            missing.append(path)
    assert not missing, f"public names missing from {API_PAGES[package].relative_to(ROOT)}: {missing}"


@pytest.mark.parametrize("package", PACKAGES)
def test_the_api_reference_lists_only_public_names(package):
    listed = listed_names(API_PAGES[package])
    assert len(listed) > 20
    stale = [f"{path} (line {line})" for path, line in listed.items() if path not in ALL_PUBLIC]
    assert not stale, f"{API_PAGES[package].relative_to(ROOT)} lists names that are not public: {stale}"


def test_data_docs_are_found_and_missing_ones_are_not():
    # The '#:' reader itself, both ways: a documented constant, a package re-export, a non-name.
    assert "Times" in data_doc("fmscal.analysis._comparison.CHECKPOINTS")
    assert data_doc("fmscal.plant.PAPER_S")
    assert data_doc("fmscal.analysis._comparison.no_such_constant") == ""
