"""Every public name of the three packages is documented, and listed in the API reference.

A name is public when it is in the ``__all__`` of ``fmscal.plant``, ``fmscal.observers`` or
``fmscal.analysis``, or of one of their subpackages (whose name does not start with an
underscore; every module is private). The API reference is written at each build from those
``__all__`` by ``docs/_api.py`` (autosummary lists, from which Sphinx generates a page per class
or function; constants documented on the package's page); CI builds the site with ``-W``; this
test checks what the pages list without building them.
"""

import importlib
import inspect
import sys
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "docs"))
import _api  # noqa: E402  (docs/_api.py)

PACKAGES = _api.PACKAGES


def public_names(package):
    """``{dotted path: object}`` of every public name of ``package`` and of its public subpackages."""
    pkg = importlib.import_module(package)
    names = {f"{package}.{n}": getattr(pkg, n) for n in pkg.__all__}
    for sub in _api.subpackages(package):
        module = importlib.import_module(sub)
        for n in module.__all__:
            names[f"{sub}.{n}"] = getattr(module, n)
    return names


def listed_names(text):
    """``{dotted path: kind}`` a page lists: ``"page"`` in autosummary blocks, ``"data"`` by ``py:data``."""
    listed, current, in_block = {}, None, False
    for line in text.splitlines():
        match = re.match(r"\.\. currentmodule:: (\S+)", line)
        data = re.match(r"\.\. py:data:: (\S+)", line)
        if match:
            current, in_block = match.group(1), False
        elif data:
            listed[f"{current}.{data.group(1)}"] = "data"
            in_block = False
        elif line.startswith(".. autosummary::"):
            in_block = True
        elif in_block and line.startswith("   ") and line.strip() and not line.strip().startswith(":"):
            listed[f"{current}.{line.strip()}"] = "page"
        elif in_block and line.strip() and not line.startswith(" "):
            in_block = False
    return listed


def resolve(path):
    module, _, name = path.rpartition(".")
    return getattr(importlib.import_module(module), name)


data_doc = _api.data_doc


def docstring(path, obj):
    if inspect.isclass(obj) or inspect.isroutine(obj):
        doc = (obj.__doc__ or "").strip()
        # dataclasses and named tuples make up a docstring, the signature: that is none.
        return "" if doc.startswith(f"{obj.__name__}(") else doc
    return data_doc(path)


ALL_PUBLIC = {path: obj for pkg in PACKAGES for path, obj in public_names(pkg).items()}
PAGES = {pkg: _api.page(pkg) for pkg in PACKAGES}


def test_the_packages_have_public_names():
    # Guards the collection itself: a broken walk must not pass every check vacuously.
    assert 100 < len(ALL_PUBLIC) < 600
    assert "fmscal.observers.AdaptiveObserver" in ALL_PUBLIC
    assert "fmscal.analysis.cli.main" in ALL_PUBLIC
    assert not any("._" in path for path in ALL_PUBLIC)


@pytest.mark.parametrize("path", sorted(ALL_PUBLIC))
def test_public_name_has_a_docstring(path):
    assert docstring(path, ALL_PUBLIC[path]), f"{path} has no docstring (a '#:' comment for a constant)"


@pytest.mark.parametrize("package", PACKAGES)
def test_every_public_name_is_in_the_api_reference(package):
    listed = listed_names(PAGES[package])
    missing = []
    for path, obj in public_names(package).items():
        name = path.rpartition(".")[2]
        # Listed under this path, or under another public path to the same object and name
        # (a class defined in a subpackage and exported by its package is listed once).
        if path not in listed and not any(
                other.rpartition(".")[2] == name and other in ALL_PUBLIC and ALL_PUBLIC[other] is obj
                for other in listed):
            missing.append(path)
    assert not missing, f"public names missing from the {package} page: {missing}"


@pytest.mark.parametrize("package", PACKAGES)
def test_the_api_reference_lists_only_public_names_and_constants_get_no_page(package):
    listed = listed_names(PAGES[package])
    assert len(listed) > 15
    stale = [path for path in listed if path not in ALL_PUBLIC]
    assert not stale, f"the {package} page lists names that are not public: {stale}"
    paged_data = [path for path, kind in listed.items() if kind == "page" and _api.is_data(ALL_PUBLIC[path])]
    assert not paged_data, f"constants with a page of their own (in the sidebar): {paged_data}"
    assert any(kind == "data" for kind in listed.values()) or package == "fmscal.analysis"


def test_the_pages_are_written_from_the_packages(tmp_path):
    # What Sphinx reads is what this test checks: docs/conf.py writes these very pages.
    paths = _api.write_pages(tmp_path)
    assert [p.read_text() for p in paths] == [PAGES[pkg] for pkg in PACKAGES]
    assert "write_pages(HERE / \"api\")" in (ROOT / "docs" / "conf.py").read_text()


def test_data_docs_are_found_and_missing_ones_are_not():
    # The '#:' reader itself, both ways: a documented constant, a package re-export, a non-name.
    assert "Times" in data_doc("fmscal.analysis._comparison.CHECKPOINTS")
    assert data_doc("fmscal.plant.PAPER_S")
    assert data_doc("fmscal.analysis._comparison.no_such_constant") == ""
