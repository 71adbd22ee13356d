"""Test-suite settings: short notebooks (marked ``slow``: each runs for tens of seconds), and no silent skips
on CI.

The notebooks run on short settings inside the test suite (they read
``FMSCAL_QUICK``). When the environment variable ``CI`` is set (CI runs
with ``CI=true``), a skipped test is a failure: every test there must run
(the pymunk physics check, the Dask sweep, the compiled paths), so a missing
package or compiler fails the build instead of passing it quietly.
"""

import os

import pytest

os.environ.setdefault("FMSCAL_QUICK", "1")
# The arithmetic pinned to what every x86-64-v3 processor runs (AVX2), before numpy loads (this file is read
# before any test module, and pytest-xdist's workers inherit the environment): OpenBLAS's Haswell kernel, and
# numpy's own AVX-512 loops off. The golden outputs (tests/test_golden.py, whose docstring says how they move
# with the kernel) are then one machine's to the last bits on any such processor, AVX-512 or not.
os.environ.setdefault("OPENBLAS_CORETYPE", "Haswell")
# numpy 2's dispatch targets above AVX2 (a name numpy does not dispatch is an ImportWarning on stderr)
os.environ.setdefault("NPY_DISABLE_CPU_FEATURES", "X86_V4 AVX512_ICL AVX512_SPR")


def _skips_fail():
    return os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if report.skipped and not hasattr(report, "wasxfail") and _skips_fail():
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        report.outcome = "failed"
        report.longrepr = f"skipped on CI (CI={os.environ['CI']}), where every test must run: {reason}"


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(items):
    """The notebooks are long scenarios: marked ``slow`` (before ``-m`` selects)."""
    for item in items:
        if item.path.suffix == ".ipynb":
            item.add_marker(pytest.mark.slow)
