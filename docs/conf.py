"""Sphinx configuration of the fmscal documentation.

Build: ``pip install -e ".[docs]"`` then ``sphinx-build -W -b html docs docs/_build/html``.
The tutorials are the repository's notebooks, copied here and executed at build time on the
short settings the test suite uses (``FMSCAL_QUICK=1``).
"""

import os
import re
import shutil
import sys
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

# API reference: docs/api/{plant,observers,analysis}.rst written from the packages' __all__ (docs/_api.py),
# then one page per public class or function, generated from its numpydoc docstring.
sys.path.insert(0, str(HERE))
from _api import write_pages  # noqa: E402

write_pages(HERE / "api")
# A summary is the docstring's first sentence: not cut at "eq." or "Fig." (docs/_api.py, SUMMARY_ABBREVIATIONS).
import sphinx.ext.autosummary as _autosummary  # noqa: E402
from _api import SUMMARY_ABBREVIATIONS  # noqa: E402

_autosummary.WELL_KNOWN_ABBREVIATIONS = tuple(dict.fromkeys((*_autosummary.WELL_KNOWN_ABBREVIATIONS,
                                                             *SUMMARY_ABBREVIATIONS)))
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


#: A Markdown link to a notebook where the repository holds it (``../../notebooks/NAME.ipynb``: it reads on GitHub).
_NOTEBOOK_LINK = re.compile(r"\]\(((?:\.\./)+notebooks/[\w.-]+\.ipynb)\)")


def _notebook_links(app, docname, source):
    """A page's links to the repository's notebooks (``notebooks/NAME.ipynb``, as on GitHub) made links to their
    copies here (``tutorials/notebooks/NAME.ipynb``, the executed pages): one link that works in both."""
    page = (HERE / docname).parent

    def local(match):
        target = (page / match.group(1)).resolve()
        if target.parent != _NB_SOURCE.resolve():
            return match.group(0)
        return "](" + os.path.relpath(_NB_TARGET / target.name, page) + ")"

    source[0] = _NOTEBOOK_LINK.sub(local, source[0])


def setup(app):
    app.connect("missing-reference", _resolve_short_names)
    app.connect("source-read", _notebook_links)
