"""The distribution installs one import name, ``fmscal`` (issue 21).

The wheel is built from this checkout (no build isolation: the test
environment's setuptools) and installed into an empty folder; the folder's
top-level names are what a user's ``site-packages`` would gain.
"""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_the_wheel_installs_only_fmscal(tmp_path):
    wheels, target = tmp_path / "wheels", tmp_path / "site"
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "--no-input"]
    subprocess.run([*pip, "wheel", "--quiet", "--no-deps", "--no-build-isolation", "-w", str(wheels), str(ROOT)],
                   check=True, capture_output=True, cwd=tmp_path)
    (wheel,) = wheels.glob("fmscal-*.whl")
    subprocess.run([*pip, "install", "--quiet", "--no-deps", "--target", str(target), str(wheel)],
                   check=True, capture_output=True, cwd=tmp_path)
    top = {p.name for p in target.iterdir() if not p.name.endswith(".dist-info") and p.name != "bin"}
    assert top == {"fmscal"}, f"top-level names installed: {sorted(top)}"
    assert {p.name for p in (target / "fmscal").iterdir()} >= {"plant", "observers", "analysis"}
    # the installed copy imports by the one name, and the old names are gone
    code = ("import sys; sys.path.insert(0, sys.argv[1]); import fmscal.plant, fmscal.observers, fmscal.analysis;"
            "import importlib.util as u; print(fmscal.plant.__file__.startswith(sys.argv[1]),"
            " [n for n in ('plant', 'observers', 'analysis') if u.find_spec(n) is not None])")
    out = subprocess.run([sys.executable, "-c", code, str(target)], capture_output=True, text=True, check=True,
                         cwd=tmp_path)
    assert out.stdout.split() == ["True", "[]"], out.stdout
