"""The verdict: which method wins on E, as the toolkit measures it (docs/comparison.md, the verdict).

E is the median over the last 10 % of each run (never one sample), compared on
every one of three seeds with a 1.3x margin, so that each assertion is a
property rather than luck. The floor is the maximum-likelihood estimate on the
same log (``E / floor`` in every table).

What holds: the adaptive default sits at the floor, beats both configurations
of the high-gain observer of [4] and the paper's law as printed, matches the
EKF, and beats an EKF told 10x too little noise (it needs no noise model). Its
cost per step is measured by ``fmscal compare`` and ``fmscal bench``, not
asserted in a timed test.
"""

import numpy as np
import pandas as pd
import pytest

from fmscal.analysis._comparison import compare

SEEDS = 3
MARGIN = 1.3
OBSERVERS = ["adaptive", "adaptive-paper", "high-gain", "high-gain-ref4", "ekf", "least-squares"]
#: The EKF's documented setting for a sensor drifting at the drift scenario's rate (docs/comparison.md).
DRIFT_RATE_EKF = {"q_S": 1e-5, "adapt_q": False}

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def runs():
    """60 s runs: {(scenario, observer): [E per seed]} and {(scenario, observer): [E / floor per seed]}."""
    table = compare(["paper", "ekf-noise-low", "drift"], SEEDS, OBSERVERS, duration=60, progress=False)
    told = compare(["drift"], SEEDS, ["ekf"], duration=60, settings={"ekf": DRIFT_RATE_EKF}, progress=False)
    told["observer"] = "ekf told the drift rate"
    table = pd.concat([table, told])
    E, ratio = {}, {}
    for key, g in table.groupby(["scenario", "observer"]):
        g = g.sort_values("seed")
        E[key], ratio[key] = list(g["E"]), list(g["E_over_floor"])
    return E, ratio


def _beats(E, scenario, winner, loser):
    return all(w * MARGIN < lo for w, lo in zip(E[scenario, winner], E[scenario, loser]))


def test_nothing_diverges_but_the_papers_law_may(runs):
    E, _ = runs
    for (scenario, observer), values in E.items():
        if observer != "adaptive-paper":
            assert np.all(np.isfinite(values)), (scenario, observer)


def test_adaptive_default_is_at_the_floor(runs):
    _, ratio = runs
    assert all(0.7 < r < MARGIN for r in ratio["paper", "adaptive"])


def test_adaptive_default_beats_both_high_gain_configurations_of_ref_4(runs):
    E, _ = runs
    assert _beats(E, "paper", "adaptive", "high-gain")
    assert _beats(E, "paper", "adaptive", "high-gain-ref4")


def test_adaptive_default_matches_the_ekf(runs):
    E, _ = runs
    assert all(a < MARGIN * e and e < MARGIN * a for a, e in zip(E["paper", "adaptive"], E["paper", "ekf"]))


def test_adaptive_default_beats_the_papers_law_and_the_paper_misses_its_claim_by_100x(runs):
    E, _ = runs
    assert _beats(E, "paper", "adaptive", "adaptive-paper")
    assert np.nanmin(E["paper", "adaptive-paper"]) > 100 * 9.1106e-4


def test_adaptive_beats_an_ekf_told_10x_too_little_noise(runs):
    """The adaptive observer needs no noise model; the EKF's accuracy rests on it."""
    E, _ = runs
    assert _beats(E, "ekf-noise-low", "adaptive", "ekf")
    assert all(bad > MARGIN * good for bad, good in zip(E["ekf-noise-low", "ekf"], E["paper", "ekf"]))


def test_least_squares_leaves_accuracy_on_the_table_but_not_much(runs):
    _, ratio = runs
    assert all(1.0 < r < 2.0 for r in ratio["paper", "least-squares"])


def test_drifting_sensor_the_trackers_follow_and_least_squares_cannot(runs):
    E, _ = runs
    assert _beats(E, "drift", "adaptive", "high-gain")
    assert _beats(E, "drift", "adaptive", "least-squares")
    # told the rate, the EKF tracks best, though by less than the 1.3x margin: the adaptive default, told
    # nothing, is 1.08-1.32x behind it at 60 s (forgetting on evidence of a drift, t_forget = 0.05 s)
    assert all(told < a < 1.5 * told for told, a in zip(E["drift", "ekf told the drift rate"], E["drift", "adaptive"]))
    assert min(E["drift", "least-squares"]) > 0.1                          # it assumes a constant S
