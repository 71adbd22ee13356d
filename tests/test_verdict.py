"""The verdict: which observer wins on E, as the toolkit measures it (README, "Which observer to trust").

The user asked for a suite asserting that the paper's adaptive observer beats the
baselines on E. Measured, it does not: on the paper's own scenario the high-gain
reconstruction and the EKF (each with its documented tuning) reach a lower E,
the EKF as low as the offline least-squares fit. These tests assert the
measured order instead, on every one of three seeds with a 1.3x margin, so that
each is a property rather than luck; and they assert what the adaptive observer
does measurably better: it needs no noise model (an EKF told 10x too little
noise falls behind it) and it tracks a fast drift better than the high-gain
observer and than the EKF with its defaults (whose random walk is sized for a
slowly changing sensor; told the drift rate, the EKF tracks it best). Its
third advantage, cost per step, is measured by ``fmscal compare`` (the README
table) rather than asserted in a timed test.
"""

import pytest

from analysis.comparison import compare

SEEDS = 3
MARGIN = 1.3
OBSERVERS = ["adaptive", "adaptive-paper", "high-gain", "ekf", "least-squares"]
#: The EKF's documented setting for a sensor drifting at the drift scenario's rate (README).
DRIFT_RATE_EKF = {"q_S": 1e-5, "adapt_q": False}

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def E():
    """E at the end of 60 s runs: {(scenario, observer): [E per seed]}."""
    table = compare(["paper", "ekf-noise-low", "drift"], SEEDS, OBSERVERS, duration=60, progress=False)
    assert not table["diverged"].any()
    E = {key: list(g.sort_values("seed")["E"]) for key, g in table.groupby(["scenario", "observer"])}
    told = compare(["drift"], SEEDS, ["ekf"], duration=60, settings={"ekf": DRIFT_RATE_EKF}, progress=False)
    E["drift", "ekf told the drift rate"] = list(told.sort_values("seed")["E"])
    return E


def _beats(E, scenario, winner, loser):
    return all(w * MARGIN < lo for w, lo in zip(E[scenario, winner], E[scenario, loser]))


def test_paper_scenario_high_gain_reconstruction_beats_adaptive_on_E(E):
    assert _beats(E, "paper", "high-gain", "adaptive")


def test_paper_scenario_ekf_beats_adaptive_on_E(E):
    assert _beats(E, "paper", "ekf", "adaptive")


def test_paper_scenario_least_squares_beats_the_observers_and_the_ekf_matches_it(E):
    for observer in ("adaptive", "high-gain"):
        assert _beats(E, "paper", "least-squares", observer), observer
    assert all(ekf < MARGIN * ls for ekf, ls in zip(E["paper", "ekf"], E["paper", "least-squares"]))


def test_paper_scenario_adaptive_default_beats_the_literal_paper_configuration(E):
    assert _beats(E, "paper", "adaptive", "adaptive-paper")


def test_literal_paper_configuration_misses_the_claimed_E_by_more_than_100x(E):
    assert min(E["paper", "adaptive-paper"]) > 100 * 9.1106e-4


def test_adaptive_beats_an_ekf_told_10x_too_little_noise(E):
    """The adaptive observer needs no noise model; the EKF's accuracy rests on it."""
    assert _beats(E, "ekf-noise-low", "adaptive", "ekf")
    assert all(bad > MARGIN * good for bad, good in zip(E["ekf-noise-low", "ekf"], E["paper", "ekf"]))


def test_drifting_sensor_adaptive_tracks_better_than_high_gain_and_the_default_ekf(E):
    assert _beats(E, "drift", "adaptive", "high-gain")
    assert _beats(E, "drift", "adaptive", "ekf")


def test_drifting_sensor_ekf_told_the_rate_tracks_best_and_least_squares_cannot_track(E):
    assert _beats(E, "drift", "ekf told the drift rate", "adaptive")
    assert min(E["drift", "least-squares"]) > 0.1          # it assumes a constant S
    assert _beats(E, "drift", "ekf", "least-squares")     # the default EKF still follows
