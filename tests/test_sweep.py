"""Sweeps: the same table on one process, on local cores and on a Dask cluster; the bench's short mode."""

import json

import pandas as pd
import pytest

from fmscal.analysis.cli import main
from fmscal.analysis._sweep import TIMING_COLUMNS, expand_settings, settings_label, sweep

GRID = {"high-gain": {"lam": [10.0, 20.0]}}


def _without_timing(table):
    return table.drop(columns=list(TIMING_COLUMNS)).reset_index(drop=True)


@pytest.fixture(scope="module")
def serial_table():
    return sweep(["paper", "drift"], seeds=[0, 3], noise_scales=[0.5, 1.0], observers=["adaptive", "high-gain"],
                 settings=GRID, duration=1.5, n_jobs=1, progress=False)


def test_the_table_covers_the_product(serial_table):
    # 2 scenarios x 2 noise levels x 2 seeds, each with adaptive and two high-gain variants
    assert len(serial_table) == 2 * 2 * 2 * 3
    assert set(serial_table["settings"]) == {"default", "lam=10", "lam=20"}
    assert set(serial_table["noise_scale"]) == {0.5, 1.0}
    assert list(serial_table["case"]) == sorted(serial_table["case"])
    # the noise scale reaches the data: the same seed at two noise levels gives different E
    e = serial_table.set_index(["scenario", "seed", "noise_scale", "observer", "settings"])["E"]
    assert e[("paper", 0, 0.5, "adaptive", "default")] != e[("paper", 0, 1.0, "adaptive", "default")]


@pytest.mark.slow
def test_local_cores_give_the_serial_table(serial_table):
    parallel = sweep(["paper", "drift"], seeds=[0, 3], noise_scales=[0.5, 1.0], observers=["adaptive", "high-gain"],
                     settings=GRID, duration=1.5, n_jobs=2, progress=False)
    pd.testing.assert_frame_equal(_without_timing(parallel), _without_timing(serial_table))


@pytest.mark.slow
def test_a_dask_cluster_gives_the_serial_table(serial_table):
    import dask.distributed as distributed      # the [distributed] extra; README installs it (a failure if missing)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, host="127.0.0.1", dashboard_address=None,
                                  processes=True) as cluster, distributed.Client(cluster) as client:
        table = sweep(["paper", "drift"], seeds=[0, 3], noise_scales=[0.5, 1.0],
                      observers=["adaptive", "high-gain"], settings=GRID, duration=1.5, scheduler=client,
                      progress=False)
    pd.testing.assert_frame_equal(_without_timing(table), _without_timing(serial_table))


def test_settings_expand_to_their_product():
    variants = expand_settings(["adaptive", "high-gain"], {"high-gain": {"lam": [10, 20], "gamma": [1, 2]}})
    assert variants[0] == ("adaptive", {})
    assert sorted(settings_label(v) for n, v in variants[1:]) == [
        "gamma=1, lam=10", "gamma=1, lam=20", "gamma=2, lam=10", "gamma=2, lam=20"]
    with pytest.raises(ValueError, match="not swept"):
        expand_settings(["adaptive"], {"ekf": {"q_S": [0.0]}})
    with pytest.raises(ValueError, match="unknown observer"):
        expand_settings(["kalman"])


def test_a_misspelt_setting_fails_before_any_work():
    with pytest.raises(ValueError, match="high-gain: .*lamda"):
        sweep(["paper"], 1, observers=["high-gain"], settings={"high-gain": {"lamda": [10]}}, duration=1,
              progress=False)


def test_the_sweep_command(tmp_path, capsys):
    out = tmp_path / "runs.csv"
    code = main(["sweep", "--seeds", "2", "--duration", "1", "--observer", "adaptive", "high-gain",
                 "--set", "high-gain:lam=10,20", "--noise-scale", "1", "2", "--jobs", "1", "--out", str(out),
                 "--json"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert len(summary) == 2 * 3 and all(row["seeds"] == 2 for row in summary)
    assert len(pd.read_csv(out)) == 2 * 2 * 3
    assert main(["sweep", "--set", "high-gain-lam=10"]) == 2
    assert "OBSERVER:PARAM" in capsys.readouterr().err
    assert main(["sweep", "--seeds", "0"]) == 2


@pytest.mark.slow
def test_the_bench_runs_in_its_short_mode(tmp_path, capsys):
    code = main(["bench", "--quick", "--out", str(tmp_path / "bench.md")])
    assert code == 0
    text = capsys.readouterr().out
    for row in ("`adaptive` step", "`high-gain` step", "`ekf` step", "`ekf` run as by default", "(`eiv=False`",
                "`max-likelihood` run (the floor)", "Function.buffer()", "simulator", "`fmscal reproduce`",
                "sweep:", "`max-likelihood` on a 2 s `spatial-arm` log", "`least-squares` on a 2 s `spatial-arm` log",
                "`adaptive` step on that `spatial-arm` log", "`ekf` step on that `spatial-arm` log",
                "`adaptive` whole run on that log"):
        assert row in text
    assert "not the full job" in text and "not the full log" in text      # the short mode claims no target
    assert (tmp_path / "bench.md").read_text() == text.rstrip("\n") + "\n"


def test_a_scheduler_that_is_neither_an_address_nor_a_client_is_refused():
    with pytest.raises(TypeError, match="tcp://HOST:PORT"):
        sweep(["paper"], 1, observers=["adaptive"], duration=1, scheduler=8786, progress=False)


def test_a_spatial_sweep_scales_the_noise_and_shows_the_planar_methods_as_not_applicable():
    from fmscal.analysis._comparison import summarise, summary_markdown
    table = sweep(["spatial-arm"], seeds=1, noise_scales=[1.0, 4.0], observers=["least-squares", "high-gain"],
                  duration=3.0, n_jobs=1, progress=False)
    assert len(table) == 4 and set(table["observer"]) == {"least-squares", "high-gain"}
    planar = table[table["observer"] == "high-gain"]
    assert not planar["applicable"].any() and planar["E"].isna().all() and not planar["diverged"].any()
    ls = table[table["observer"] == "least-squares"].set_index("noise_scale")
    assert ls["applicable"].all() and ls["E"].notna().all()
    assert ls.loc[4.0, "E"] > 1.5 * ls.loc[1.0, "E"]                  # four times the noise: a worse fit
    text = summary_markdown(summarise(table))
    assert "| not applicable |" in text and "HighGainObserver is defined for planar models" in text


def test_a_method_that_refuses_a_log_is_a_row_that_says_why_not_an_abort():
    """spatial-weak's torque and vertical force never move beyond their noise: least squares refuses the log in one
    line; the comparison goes on with the other methods and names the refusal under its table."""
    from fmscal.analysis._comparison import run_case, summarise, summary_markdown
    rows = run_case("spatial-weak", 0, ["least-squares", "adaptive"], duration=2.0)
    refused, ran = rows
    assert "does not move beyond its noise" in refused["refused"] and refused["applicable"]
    assert ran["refused"] == "" and ran["E"] > 0
    text = summary_markdown(summarise(pd.DataFrame(rows)))
    assert "| refused the log |" in text
    assert "Refused the log: least-squares on spatial-weak (1 of 1 seeds) (the reading tz, fz does not move" in text
    assert text.count("refused the log") == 1                       # the adaptive observer's row has figures


def test_a_late_pose_streams_run_still_reports_the_checkpoint_at_its_end():
    """real-rig's poses are 20 ms late: moved back, the log ends 20 ms short of 10 s, and E at 10 s is still
    reported (within analysis's CHECKPOINT_SLACK), as on a log with no latency."""
    import numpy as np
    from fmscal.analysis import compare
    row = compare(("real-rig",), seeds=1, observers=("least-squares",), duration=10.0, progress=False).iloc[0]
    assert 9.9 < row["duration"] < 10.0
    assert np.isfinite(row["E_10s"]) and 0 < row["E_10s"] < 1
    assert "E_30s" not in row.index
