"""The figure commands write their PNG files; the plots module leaves matplotlib's backend alone."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fmscal.analysis.cli import main
from fmscal.analysis._plots import plot_comparison, wandering_methods
from fmscal.plant import PAPER_PAYLOAD

PNG = b"\x89PNG\r\n\x1a\n"


def _is_png(path):
    data = Path(path).read_bytes()
    return data[:8] == PNG and len(data) > 10_000


@pytest.mark.slow
def test_importing_the_plots_leaves_the_backend_alone():
    code = ("import matplotlib; matplotlib.use('svg'); "
            "import fmscal.analysis._plots, fmscal.analysis.cli, fmscal.analysis._reproduce; "
            "print(matplotlib.get_backend())")          # (python-control imports pyplot; that alone switches nothing)
    env = {**os.environ, "MPLBACKEND": "svg"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "svg"


@pytest.mark.slow
def test_calibrate_plot(tmp_path, capsys):
    log = tmp_path / "rig.csv"
    assert main(["simulate", "--scenario", "real-rig", "--duration", "6", "--out", str(log)]) == 0
    p = PAPER_PAYLOAD
    for method in ("least-squares", "high-gain"):          # with and without S_std
        png = tmp_path / f"{method}.png"
        assert main(["calibrate", str(log), "--mass", str(p.mass), "--inertia", str(p.inertia), "--rho",
                     *map(str, p.rho), "--observer", method, "--truth", str(log.with_suffix(".truth.json")),
                     "--latency", "0.02", "--plot", str(png)]) == 0
        assert _is_png(png)
    capsys.readouterr()


@pytest.mark.slow
def test_compare_and_reproduce_write_their_figures(tmp_path, capsys):
    assert main(["compare", "--scenario", "paper", "--observer", "ekf", "adaptive-paper", "--duration", "3",
                 "--out", str(tmp_path / "cmp")]) == 0
    assert _is_png(tmp_path / "cmp" / "E_paper.png")
    assert main(["reproduce", "--quick", "0.02", "--out", str(tmp_path / "rep")]) == 0
    for name in ("fig2_paper.png", "fig3_noisy.png", "fig4_time-varying.png"):
        assert _is_png(tmp_path / "rep" / name)
    capsys.readouterr()


def test_a_wandering_method_is_clipped_and_named(tmp_path):
    t = np.linspace(0, 10, 500)
    good = {name: 0.5 * np.exp(-t) + 1e-3 * (1 + k) for k, name in enumerate(("ekf", "high-gain", "adaptive"))}
    E = {**good, "adaptive-paper": 2.0 + np.sin(t)}
    assert wandering_methods(E) == {"adaptive-paper"}
    assert wandering_methods(good) == set()
    assert wandering_methods({**good, "adaptive-paper": 5e-3 + 0 * t}) == set()    # a factor 5: not far
    runs = {name: (t, e, np.tile(np.eye(3), (len(t), 1, 1))) for name, e in E.items()}
    assert plot_comparison(runs, None, tmp_path / "c.png", "test") == {"adaptive-paper"}
    assert _is_png(tmp_path / "c.png")


def test_a_method_far_above_the_best_is_drawn_behind_the_others():
    from fmscal.analysis._plots import _behind, _style
    t = np.linspace(0, 10, 500)
    E = {"ekf": 1e-3 + 0 * t, "high-gain": 3e-3 + 0 * t, "high-gain-ref4": 3e-2 * (1.5 + np.sin(40 * t))}
    behind = _behind(E, clipped=set())
    assert behind == {"high-gain-ref4"}
    assert _style("high-gain-ref4", set(), behind)["zorder"] < _style("ekf", set(), behind)["zorder"]
    assert _style("high-gain-ref4", set(), behind)["lw"] < _style("ekf", set(), behind)["lw"]
    assert _behind(E, clipped={"high-gain-ref4"}) == set()       # clipped already: drawn faded, not twice
