"""The fmscal command line: simulate, check-gains, reproduce, and bad input."""

import json
import subprocess
import sys

import numpy as np
import pytest

from fmscal import plant
from fmscal.analysis.cli import main


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
    proc = subprocess.run([sys.executable, "-m", "fmscal.analysis.cli", "simulate", "--out", str(tmp_path / "x.txt"),
                           "--duration", "0.1"], capture_output=True, text=True)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and "--out must end in .csv" in proc.stderr


@pytest.mark.slow
def test_reproduce_writes_figures_and_summary(tmp_path):
    assert main(["reproduce", "--out", str(tmp_path), "--quick", "0.05"]) == 0
    for name in ("fig2_paper.png", "fig3_noisy.png", "fig4_time-varying.png", "summary.md"):
        assert (tmp_path / name).stat().st_size > 0
    summary = (tmp_path / "summary.md").read_text()
    assert "0.0009111" in summary and "0.0367" in summary and "| adaptive-paper |" in summary
    for name in ("| ekf (after [3]) |", "| high-gain (reconstruction of [4]) |", "| high-gain-ref4 (reconstruction"):
        assert name in summary


@pytest.mark.slow
def test_reproduce_gives_the_same_rows_on_one_process_and_on_two(tmp_path):
    """The scenario and method pairs run on worker processes; the table does not depend on how many."""
    from fmscal.analysis._reproduce import reproduce
    rows = [reproduce(tmp_path / str(n), duration_scale=0.02, progress=False, n_jobs=n) for n in (1, 2)]
    strip = lambda table: [{k: v for k, v in r.items() if k != "wall_time"} for r in table]     # noqa: E731
    assert strip(rows[0]) == strip(rows[1])
    for name in ("fig2_paper.png", "fig3_noisy.png", "fig4_time-varying.png"):
        assert (tmp_path / "1" / name).read_bytes() == (tmp_path / "2" / name).read_bytes()


def test_compare_json_is_strict_and_has_a_row_per_observer_and_seed(capsys):
    assert main(["compare", "--scenario", "paper", "--seeds", "2", "--duration", "3", "--json",
                 "--observer", "adaptive", "adaptive-paper", "high-gain", "ekf"]) == 0
    rows = json.loads(capsys.readouterr().out, parse_constant=lambda c: pytest.fail(f"non-strict JSON {c}"))
    assert sorted((r["observer"], r["seed"]) for r in rows) == sorted(
        (o, s) for o in ("adaptive", "adaptive-paper", "high-gain", "ekf") for s in (0, 1))
    for r in rows:
        assert r["scenario"] == "paper" and isinstance(r["E"], float)
        assert r["convergence_time"] is None or r["convergence_time"] >= 0
    assert any(r["convergence_time"] is None for r in rows)      # adaptive-paper: not within 3 s


@pytest.mark.slow
def test_compare_writes_plots_and_summary(tmp_path, capsys):
    assert main(["compare", "--scenario", "paper", "drift", "--duration", "2", "--out", str(tmp_path),
                 "--observer", "adaptive", "high-gain"]) == 0
    assert (tmp_path / "E_paper.png").stat().st_size > 0 and (tmp_path / "E_drift.png").stat().st_size > 0
    text = (tmp_path / "summary.md").read_text()
    assert text == capsys.readouterr().out.strip() + "\n"
    assert "| drift | high-gain (reconstruction of [4]) |" in text


@pytest.mark.parametrize("argv, message", [
    (["compare", "--scenario", "nowhere"], "unknown scenario 'nowhere'"),
    (["compare", "--observer", "kalman"], "unknown observer 'kalman'"),
    (["compare", "--seeds", "0"], "--seeds must be at least 1"),
    (["compare", "--duration", "nan"], "--duration must be positive"),
    (["check-gains", "--config", "adaptive", "--lam", "10"], "--lam applies to the high-gain"),
])
def test_compare_and_check_gains_refuse_bad_arguments(argv, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_ablation_quick_gives_one_row_per_change(capsys):
    assert main(["ablation", "--quick", "--scenario", "paper", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["step"] for r in rows] == [0, 1, 2, 3]
    assert all(r["ratio"] > 0.5 for r in rows)                    # nothing beats the floor by far
    assert rows[0]["ratio"] > 10 * rows[-1]["ratio"]              # the paper's law is far from it


def test_version_is_the_installed_distributions(capsys):
    from importlib.metadata import version
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"fmscal {version('fmscal')}"


def test_simulate_help_lists_every_scenario_on_its_own_line(capsys):
    assert main(["simulate", "--help"]) == 0
    lines = capsys.readouterr().out.splitlines()
    for name, sc in {**plant.SCENARIOS, **plant.SPATIAL_SCENARIOS}.items():
        (line,) = [k for k in lines if k.split()[:1] == [name]]
        assert sc.description.split()[0] in line


@pytest.mark.slow
def test_reproduce_replaces_its_own_folder_but_not_one_the_user_named(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    for _ in range(2):                  # README's quick start, run twice
        assert main(["reproduce", "--quick", "0.01", "--jobs", "1"]) == 0
    assert (tmp_path / "reproduce" / "summary.md").stat().st_size > 0
    assert main(["reproduce", "--quick", "0.01", "--jobs", "1", "--out", "reproduce"]) == 2
    assert "add --overwrite" in capsys.readouterr().err


def test_reproduce_says_why_the_floor_does_not_converge_where_S_changes():
    from fmscal.analysis._reproduce import summary_markdown
    row = {"E_100": 1e-3, "E_end": 1e-3, "E_median_last_10s": 1e-3, "convergence_time": 1.0, "diverged": False,
           "converged": True, "wall_time": 0.1, "S_hat_100": np.eye(3).tolist(), "S_changes": []}
    rows = [{**row, "scenario": sc, "observer": obs} for sc in ("paper", "time-varying")
            for obs in ("adaptive", "max-likelihood")]
    rows[-1].update(E_end=1.18, converged=False, S_changes=[100.0, 200.0])
    text = summary_markdown(rows, 0, 1.0)
    assert "does not converge on time-varying" in text and "at 100 and 200 s" in text and "1.18" in text
    assert "on paper" not in text


@pytest.mark.slow
@pytest.mark.parametrize("unbuffered", ["", "1"])
def test_output_cut_short_by_its_reader_ends_quietly(tmp_path, monkeypatch, unbuffered):
    """``fmscal ... | head``: the reader gone before the command writes; status 141 (128 + SIGPIPE), nothing on
    stderr (no traceback, no "Exception ignored" at the interpreter's exit), whether the write fails at once
    (PYTHONUNBUFFERED) or at the last flush."""
    monkeypatch.setenv("PYTHONUNBUFFERED", unbuffered)
    args = ["simulate", "--scenario", "paper", "--duration", "1", "--out", str(tmp_path / "log.csv")]
    proc = subprocess.Popen([sys.executable, "-m", "fmscal.analysis.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.close()                                   # before the interpreter has even imported fmscal
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 141, err
    assert err == ""


def test_a_command_runs_its_blas_on_one_thread_unless_told(monkeypatch):
    """The command line's linear algebra on one thread (OpenBLAS's further threads spin between the fits' small
    calls: CPU for no time gained, benchmarks/blas_threads.py); a thread count the environment sets is kept."""
    from threadpoolctl import threadpool_info

    from fmscal.plant.numerics import THREAD_VARIABLES, one_blas_thread

    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    blas = [i for i in threadpool_info() if i["user_api"] == "blas"]
    assert blas, "numpy's BLAS not seen by threadpoolctl"
    with one_blas_thread():
        assert {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"} == {1}
    assert [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"] == [i["num_threads"] for i in blas]
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")
    with one_blas_thread():
        assert [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"] == \
            [i["num_threads"] for i in blas]
