"""The EKF's adjustable random-walk level, fed NIS samples directly."""

import numpy as np
import pytest

from fmscal.observers.kalman._noise_level import NIS_CLIP, NoiseLevel

DT = 1e-3


def _feed(level, nis):
    return np.array([level.update(e, DT) for e in nis])


def test_a_consistent_filter_keeps_the_base_level():
    rng = np.random.default_rng(0)
    q = _feed(NoiseLevel(1e-8, 1e-4), rng.chisquare(3, 100_000))
    assert np.mean(q > 1e-8) < 0.01


@pytest.mark.slow
def test_a_noise_model_within_the_tolerance_keeps_the_base_level():
    """Standard deviations told 20 % too small scale the NIS by 1/0.8^2 = 1.56; the 25 % tolerance takes it."""
    rng = np.random.default_rng(1)
    q = _feed(NoiseLevel(1e-8, 1e-4), rng.chisquare(3, 100_000) / 0.8 ** 2)
    assert np.all(q == 1e-8)
    q = _feed(NoiseLevel(1e-8, 1e-4, tolerance=0.0), rng.chisquare(3, 100_000) / 0.8 ** 2)
    assert q[-1] == 1e-4                        # without tolerance the same model raises it to the top


def test_inconsistent_innovations_raise_the_level_and_it_returns_after():
    rng = np.random.default_rng(2)
    level = NoiseLevel(1e-8, 1e-4)
    q_up = _feed(level, 5 * rng.chisquare(3, 5_000))              # 5 s of a lagging S
    assert q_up[-1] == 1e-4 and np.argmax(q_up == 1e-4) < 3_000     # top within 3 s
    q_down = _feed(level, rng.chisquare(3, 20_000))               # consistent again
    assert q_down[-1] == 1e-8
    assert np.argmax(q_down == 1e-8) < 15_000                      # 10^4 down at fall = 1/s: about 10 s


def test_a_single_outlier_does_not_raise_the_level():
    rng = np.random.default_rng(3)
    nis = rng.chisquare(3, 10_000)
    nis[5_000] = 1e6                                               # a 1000-sigma pose
    level = NoiseLevel(1e-8, 1e-4)
    assert np.all(_feed(level, nis) == 1e-8)
    assert level.eps_bar < NIS_CLIP


def test_the_average_accounts_for_the_time_between_poses():
    """At 50 Hz the bound widens with the fewer samples per window; consistent NIS keeps the base level."""
    rng = np.random.default_rng(4)
    level = NoiseLevel(1e-8, 1e-4)
    q = np.array([level.update(e, 0.02) for e in rng.chisquare(3, 5_000)])
    assert np.mean(q > 1e-8) < 0.01
    assert level.bound(np.exp(-0.02)) > level.bound(np.exp(-0.001))


def test_a_zero_base_level_stays_zero_on_a_consistent_filter():
    rng = np.random.default_rng(5)
    level = NoiseLevel(0.0, 1e-4)
    q = _feed(level, rng.chisquare(3, 100_000))
    assert np.mean(q > 0) < 0.01 and q[-1] == 0.0 and not level.raised


def test_a_zero_base_level_starts_at_q_start_and_drops_back_to_zero():
    """From a zero base the first alarm starts the level at q_start; once it decays below q_start it is 0 again."""
    rng = np.random.default_rng(6)
    level = NoiseLevel(0.0, 1e-4, q_start=1e-8)
    q_up = _feed(level, 5 * rng.chisquare(3, 5_000))
    first = np.argmax(q_up > 0)
    assert 1e-8 <= q_up[first] < 1.1e-8                            # started at q_start
    assert q_up[-1] == 1e-4 and level.raised
    q_down = _feed(level, rng.chisquare(3, 20_000))
    assert q_down[-1] == 0.0 and not level.raised
    assert np.all((q_down == 0.0) | (q_down >= 1e-8))              # never between 0 and q_start


@pytest.mark.parametrize("args, kwargs", [
    ((-1e-8, 1e-4), {}), ((0.0, 1e-4), {"q_start": 0.0}), ((0.0, 1e-9), {}), ((1e-6, 1e-7), {}),
])
def test_noise_level_refuses_bad_levels(args, kwargs):
    with pytest.raises(ValueError, match="NoiseLevel needs"):
        NoiseLevel(*args, **kwargs)
