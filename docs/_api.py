"""The API reference's pages, written from the packages' ``__all__`` at every build.

A name is public when it is in the ``__all__`` of ``fmscal.plant``, ``fmscal.observers`` or
``fmscal.analysis``, or of one of their subpackages (a folder whose name does not start with an
underscore; its modules are private). Each package gets one page, ``docs/api/<package>.rst``:
the package's docstring, its own names, then one section per subpackage with the names the
package itself does not export. Classes and functions are listed in autosummary blocks, so each
gets a page of its own in the sidebar, summary first; constants (data) are documented on the
package page by their ``#:`` comment and get no page. The pages are generated, never edited: a
name added to an ``__all__`` is documented by the next build (``docs/conf.py`` calls
:func:`write_pages`), and ``tests/test_docs.py`` checks what they list.

An autosummary list shows each name's summary, the first sentence of its docstring: autosummary
ends it at the first period followed by a space, unless the text up to it ends with one of its
known abbreviations. The docstrings cite equations (``E of eq. (16)``, ``Eqs. (6)-(8)``) and the
paper's figures: :data:`SUMMARY_ABBREVIATIONS` adds those, so that a summary is not cut at
``eq.`` (``docs/conf.py`` sets autosummary's list to it).
"""

import ast
import importlib
import inspect
import pkgutil
from pathlib import Path

PACKAGES = ("fmscal.plant", "fmscal.observers", "fmscal.analysis")
TITLES = {
    "fmscal.plant": "the physics, the sensor and the files",
    "fmscal.observers": "the contract and the methods",
    "fmscal.analysis": "workflows, metrics, plots and the command line",
}
#: Constants whose value is too long to print on a page (a dict of scenarios, a registry).
LONG_VALUE = 120
#: Where a summary's first sentence does not end: autosummary's own abbreviations
#: (``sphinx.ext.autosummary.WELL_KNOWN_ABBREVIATIONS``), then the docstrings' citations of equations and figures.
SUMMARY_ABBREVIATIONS = ("et al.", "e.g.", "i.e.", "vs.",
                         " eq.", "(eq.", "Eq.", " eqs.", "(eqs.", "Eqs.", " Fig.", "(Fig.", " Figs.", "(Figs.")


def subpackages(package):
    """The public subpackages of ``package`` (dotted names), in alphabetical order."""
    pkg = importlib.import_module(package)
    return [f"{package}.{info.name}" for info in pkgutil.iter_modules(pkg.__path__)
            if info.ispkg and not info.name.startswith("_")]


def is_data(obj):
    """A constant: documented on its package's page, with no page (and no sidebar entry) of its own."""
    return not (inspect.isclass(obj) or inspect.isroutine(obj))


def sections(package):
    """``[(module, [names])]``: the package's own names, then each subpackage's that the package does not export."""
    pkg = importlib.import_module(package)
    seen = {id(getattr(pkg, n)) for n in pkg.__all__ if not is_data(getattr(pkg, n))}
    out = [(package, list(pkg.__all__))]
    for sub in subpackages(package):
        module = importlib.import_module(sub)
        names = [n for n in module.__all__ if is_data(getattr(module, n)) or id(getattr(module, n)) not in seen]
        seen |= {id(getattr(module, n)) for n in names if not is_data(getattr(module, n))}
        out.append((sub, names))
    return out


def attribute_doc(module_name, name):
    """The ``#:`` comment or the string after a module-level assignment of ``name``; None if not assigned there."""
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
    """The documentation of a constant, found where it is assigned (its module, or a private module below it)."""
    module, _, name = path.rpartition(".")
    doc = attribute_doc(module, name)
    if doc is None:  # imported into a package's __init__: look where it is assigned
        package = importlib.import_module(module)
        for info in pkgutil.walk_packages(getattr(package, "__path__", ()), prefix=f"{module}."):
            doc = attribute_doc(info.name, name)
            if doc is not None:
                break
    return doc or ""


def page(package):
    """The reStructuredText of ``package``'s page."""
    title = f"{package}: {TITLES[package]}"
    lines = [title, "=" * len(title), "", f".. automodule:: {package}", ""]
    for module_name, names in sections(package):
        module = importlib.import_module(module_name)
        if module_name != package:
            heading = f"``{module_name}``"
            lines += [heading, "-" * len(heading), "", f".. automodule:: {module_name}", ""]
        routines = [n for n in names if not is_data(getattr(module, n))]
        data = [n for n in names if is_data(getattr(module, n))]
        lines += [f".. currentmodule:: {module_name}", ""]
        if routines:
            lines += [".. autosummary::", "   :toctree: generated/", "", *(f"   {n}" for n in routines), ""]
        for n in data:            # its '#:' comment, not the docstring of its type (an ndarray's, a dict's)
            lines += [f".. py:data:: {n}"]
            value = repr(getattr(module, n))
            if len(value) <= LONG_VALUE and "\n" not in value:
                lines += [f"   :value: {value}"]
            lines += ["", f"   {data_doc(f'{module_name}.{n}')}", ""]
    return "\n".join(lines)


def write_pages(folder):
    """Write ``<folder>/<package>.rst`` for each package; returns the paths written."""
    folder = Path(folder)
    paths = []
    for package in PACKAGES:
        path = folder / f"{package.split('.')[1]}.rst"
        text = page(package)
        if not path.exists() or path.read_text() != text:      # unchanged pages keep their time: no rebuild
            path.write_text(text)
        paths.append(path)
    return paths
