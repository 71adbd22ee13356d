"""Sphinx configuration of the fmscal documentation.

Build: ``pip install -e ".[docs]"`` then ``sphinx-build -W -b html docs docs/_build/html``.
The tutorials are the repository's notebooks, copied here and executed at build time on the
short settings the test suite uses (``FMSCAL_QUICK=1``).
"""

import importlib
import os
import pkgutil
import shutil
from pathlib import Path

HERE = Path(__file__).resolve().parent

# The notebooks live in notebooks/ beside the packages; Sphinx reads sources under docs/ only,
# so each build copies them (docs/tutorials/notebooks/ is ignored by git).
_NB_SOURCE = HERE.parent / "notebooks"
_NB_TARGET = HERE / "tutorials" / "notebooks"
shutil.rmtree(_NB_TARGET, ignore_errors=True)
_NB_TARGET.mkdir(parents=True)
for _nb in sorted(_NB_SOURCE.glob("*.ipynb")):
    shutil.copy2(_nb, _NB_TARGET / _nb.name)

# Short settings for the notebooks, as in the test suite (conftest.py); the kernel inherits it.
os.environ.setdefault("FMSCAL_QUICK", "1")

project = "fmscal"
author = "the fmscal authors"
copyright = "the fmscal authors; MIT licence"

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "myst_nb",
    "sphinx_copybutton",
]

source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
exclude_patterns = ["_build", "**.ipynb_checkpoints", "Thumbs.db", ".DS_Store"]
templates_path = ["_templates"]

# API reference: one page per public name, generated from the numpydoc docstrings.


def _long_values(packages=("fmscal.plant", "fmscal.observers", "fmscal.analysis"), limit=120):
    """Public constants whose value is too long to print on their page (a dict of scenarios)."""
    names = set()
    for package in packages:
        pkg = importlib.import_module(package)
        modules = [pkg] + [importlib.import_module(f"{package}.{m.name}")
                           for m in pkgutil.iter_modules(pkg.__path__) if not m.name.startswith("_")]
        for module in modules:
            for name in getattr(module, "__all__", ()):
                value = getattr(module, name)
                if not callable(value) and len(repr(value)) > limit:
                    names.add(f"{module.__name__}.{name}")
    return names


autosummary_context = {"long_values": _long_values()}
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"member-order": "bysource"}
autodoc_typehints = "none"
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

# Tutorials: executed at build time (cached between builds); an error in a cell fails the build.
nb_execution_mode = "cache"
nb_execution_timeout = 600
nb_execution_raise_on_error = True
nb_execution_in_temp = True
nb_execution_show_tb = True
myst_enable_extensions = ["dollarmath"]
myst_heading_anchors = 3

html_theme = "pydata_sphinx_theme"
html_title = "fmscal"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
}
html_static_path = []


def _resolve_short_names(app, env, node, contnode):
    """Docstrings name objects by their repository path (``plant.Log``): resolve them as ``fmscal.plant.Log``."""
    target = node.get("reftarget", "")
    if node.get("refdomain") != "py" or not target.startswith(("plant.", "observers.", "analysis.")):
        return None
    domain = env.get_domain("py")
    node["reftarget"] = f"fmscal.{target}"
    try:
        return domain.resolve_xref(env, node["refdoc"], app.builder, node["reftype"], node["reftarget"],
                                   node, contnode)
    finally:
        node["reftarget"] = target


def setup(app):
    app.connect("missing-reference", _resolve_short_names)
