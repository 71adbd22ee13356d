"""The examples in the public docstrings run, and say what they print.

Every class and function of the public surface (the names ``docs/_api.py`` puts on the API
pages) has its ``>>>`` examples run by :mod:`doctest` in the namespace of the module that
defines it; what a user reads on a page is what the code does. Every class and function that
``fmscal.observers`` exports carries at least one example (the issue's "each with an example
in its docstring").
"""

import doctest
import importlib
import inspect
import sys
from pathlib import Path

import pytest

import fmscal.observers

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "docs"))
import _api  # noqa: E402  (docs/_api.py)

FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


def _public_routines():
    """``{dotted path: object}`` of every public class and function, each object once."""
    out, seen = {}, set()
    for package in _api.PACKAGES:
        for module_name, names in _api.sections(package):
            module = importlib.import_module(module_name)
            for name in names:
                obj = getattr(module, name)
                if not _api.is_data(obj) and id(obj) not in seen:
                    seen.add(id(obj))
                    out[f"{module_name}.{name}"] = obj
    return out


ROUTINES = _public_routines()
WITH_EXAMPLES = {path: obj for path, obj in ROUTINES.items() if ">>>" in (inspect.getdoc(obj) or "")}


def test_the_surface_is_walked():
    assert len(ROUTINES) > 100 and len(WITH_EXAMPLES) >= 20


@pytest.mark.slow
@pytest.mark.parametrize("path", sorted(WITH_EXAMPLES))
def test_an_example_runs_as_written(path):
    obj = WITH_EXAMPLES[path]
    globs = dict(vars(inspect.getmodule(obj)))
    tests = doctest.DocTestFinder(recurse=False).find(obj, path, globs=globs)
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    report = []
    for test in tests:
        runner.run(test, out=report.append)
    assert runner.failures == 0, "".join(report)
    assert runner.tries > 0


@pytest.mark.parametrize("name", sorted(n for n in fmscal.observers.__all__
                                        if not _api.is_data(getattr(fmscal.observers, n))))
def test_every_name_observers_exports_has_an_example(name):
    assert ">>>" in (inspect.getdoc(getattr(fmscal.observers, name)) or ""), f"fmscal.observers.{name} has no example"


def test_a_wrong_example_fails(tmp_path):
    # The runner itself, both ways: a docstring that prints something else is a failure.
    def wrong():
        """>>> 1 + 1
        3
        """
    (test,) = doctest.DocTestFinder(recurse=False).find(wrong, "wrong", globs={})
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    runner.run(test, out=lambda s: None)
    assert runner.failures == 1
