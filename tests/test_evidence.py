"""Issue 24, item 2: "converged" needs evidence: information in every direction of S, an estimate that moved."""

import json

import numpy as np
import pytest

from fmscal import plant
from fmscal.analysis._ablation import ablation, ablation_markdown
from fmscal.analysis.cli import main
from fmscal.analysis._comparison import compare, summarise, summary_markdown
from fmscal.analysis._sweep import sweep
from fmscal.observers import AdaptiveObserver, HighGainObserver
from fmscal.observers.core._convergence import informed, moved
from fmscal.observers.diagnostics._evidence import log_uncertainty


@pytest.fixture(scope="module")
def paper():
    sc = plant.get_scenario("paper").with_(duration=30.0)
    log, truth, _ = sc.generate(0)
    return sc.payload, log, truth


@pytest.mark.parametrize("make, samples", [(HighGainObserver, 100), (HighGainObserver, 500),
                                           (AdaptiveObserver, 12)])
def test_a_short_run_has_not_converged(paper, make, samples):
    """Each said converged=True before (E 2.7-6.8): the estimate stood still, or settled on too little data."""
    payload, log, truth = paper
    result = make(payload).run(log.head(samples), truth.S0)
    assert not result.diverged and not result.converged


@pytest.mark.parametrize("make", [HighGainObserver, AdaptiveObserver])
def test_the_same_observers_converge_on_the_whole_log(paper, make):
    payload, log, truth = paper
    assert make(payload).run(log, truth.S0).converged


def test_evidence_grows_with_the_log(paper):
    payload, log, _ = paper
    assert log_uncertainty(log.head(500), payload) == np.inf            # too short for a fit
    short, whole = log_uncertainty(log.head(3000), payload), log_uncertainty(log, payload)
    assert 0 < whole < short                                            # more data, less uncertainty
    assert 1e-4 < whole < 0.05                                          # pinned down, but not exactly


def test_moved_and_informed_are_two_sided():
    still = np.repeat(np.eye(3)[None], 50, axis=0)
    assert not moved(still)
    travelled = still.copy()
    travelled[10:] = 2 * np.eye(3)
    assert moved(travelled)
    nudged = still.copy()
    nudged[10:, 0, 1] = 0.02                      # 2 % of |S|: within the tolerance
    assert not moved(nudged)
    S = np.diag([1.0, 2.0, 3.0])
    assert informed(S, np.full((3, 3), 0.01)) and not informed(S, np.full((3, 3), 0.1))
    assert not informed(S, np.full((3, 3), np.nan))


def test_compare_half_a_second_says_nothing_converged_and_gives_no_floor_ratio():
    table = compare(["paper"], 1, ["adaptive", "high-gain", "ekf", "max-likelihood"], duration=0.5, progress=False)
    assert not table["converged"].any()
    assert table["E_over_floor"].isna().all() and table["floor_E"].isna().all()
    markdown = summary_markdown(summarise(table))
    assert "| - [-] |" in markdown and "0/1" in markdown


def test_sweep_of_50_ms_says_nothing_converged():
    table = sweep(["paper"], 1, observers=["adaptive", "high-gain", "ekf"], duration=0.05, n_jobs=1,
                  progress=False)
    assert len(table) == 3 and not table["converged"].any() and table["E_over_floor"].isna().all()


def test_ablation_of_10_ms_gives_no_ratio(capsys):
    table = ablation(["paper"], 1, duration=0.01)
    assert table["ratio"].isna().all()
    rows = [line for line in ablation_markdown(table).splitlines() if line.startswith("| paper")]
    assert len(rows) == 4 and all(" n/a | n/a |" in row for row in rows)
    assert main(["ablation", "--scenario", "paper", "--seeds", "1", "--duration", "0.01", "--json"]) == 0
    assert all(r["ratio"] is None for r in json.loads(capsys.readouterr().out))
