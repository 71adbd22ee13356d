"""The fmscal command line: simulate, check-gains, reproduce, and bad input."""

import json
import subprocess
import sys

import numpy as np

import plant
from analysis.cli import main


def test_simulate_writes_a_log_that_matches_the_plant(tmp_path):
    out = tmp_path / "paper.csv"
    assert main(["simulate", "--scenario", "paper", "--noise-free", "--duration", "2", "--out", str(out)]) == 0
    log = plant.read_log(out)
    truth = plant.read_truth(tmp_path / "paper.truth.json")
    x = plant.integrate(truth.payload, plant.PaperWrench(), log.t)
    np.testing.assert_allclose(log.pose, x[:, [0, 2, 4]], atol=1e-12)
    np.testing.assert_allclose(truth.S_at(0), plant.PAPER_S)
    assert json.loads((tmp_path / "paper.truth.json").read_text())["scenario"] == "paper"


def test_bad_arguments_give_one_line_and_exit_2(tmp_path, capsys):
    assert main(["simulate", "--duration", "-1", "--out", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--duration must be positive" in err[0]


def test_check_gains_says_assumption_2_fails_for_the_paper(capsys):
    assert main(["check-gains", "--config", "paper"]) == 0
    text = capsys.readouterr().out
    assert "-23.96" in text and "does NOT hold" in text


def test_console_script_runs_and_reports_errors_without_traceback(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "analysis.cli", "simulate", "--out", str(tmp_path / "x.txt"),
                           "--duration", "0.1"], capture_output=True, text=True)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and "--out must end in .csv" in proc.stderr


def test_reproduce_writes_figures_and_summary(tmp_path):
    assert main(["reproduce", "--out", str(tmp_path), "--quick", "0.05"]) == 0
    for name in ("fig2_paper.png", "fig3_noisy.png", "fig4_time-varying.png", "summary.md"):
        assert (tmp_path / name).stat().st_size > 0
    summary = (tmp_path / "summary.md").read_text()
    assert "0.0009111" in summary and "adaptive-paper" in summary and "| ekf |" in summary
