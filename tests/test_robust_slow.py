"""Glitches and misfit over seeds (issue 37): the statistics behind tests/test_robust.py's single cases."""

import copy

import numpy as np
import pytest

from fmscal.analysis import calibrate
from fmscal.observers.core import find_glitches, reading_noise
from fmscal.observers.diagnostics import misfit
from fmscal.plant import SPATIAL_SCENARIOS, PlanarModel, SpatialModel, get_scenario

from test_robust import EXACT, turned

pytestmark = pytest.mark.slow
ARM = SPATIAL_SCENARIOS["spatial-arm"]
MOCAP = SPATIAL_SCENARIOS["spatial-mocap"]


def test_spikes_of_5_to_50_noise_sigmas_leave_the_floor_as_on_the_clean_log():
    """Spikes of 5 to 50 times the reading's noise on 0.1 to 1 % of the samples (one channel each, either sign):
    E within 1.2x of the clean log's, nothing 5 sigma off, every spike of 10 sigma or more rejected."""
    scenario = ARM.with_(duration=10.0)
    ratios = []
    for seed in range(6):
        log, truth, _ = scenario.generate(seed)
        S = truth.S_at(log.t[-1])
        clean = calibrate(log, scenario.payload, latency=0.0, truth=truth, payload_std=EXACT)
        rng = np.random.default_rng(seed)
        share, size = [0.001, 0.003, 0.01][seed % 3], [5.0, 20.0, 50.0][seed // 2 % 3]
        rows = rng.choice(np.arange(len(log)), int(share * len(log)), replace=False)
        channels = rng.integers(0, 6, len(rows))
        bad = copy.copy(log)
        bad.w_hat = log.w_hat.copy()
        bad.w_hat[rows, channels] += rng.choice([-1.0, 1.0], len(rows)) * size * reading_noise(log.w_hat)[channels]
        cal = calibrate(bad, scenario.payload, latency=0.0, truth=truth, payload_std=EXACT)
        ratios.append(cal.E / clean.E)
        assert cal.E < 1.2 * clean.E, (seed, share, size, cal.E, clean.E)
        assert np.abs((cal.S_hat - S) / cal.S_std).max() < 5 or not cal.converged
        if size >= 10:
            assert set(rows) <= set(cal.glitches["indices"])
    assert 0.8 < np.mean(ratios) < 1.1


def test_a_clean_log_rejects_nothing():
    """The threshold (G2) on clean simulated logs of planar scenarios (one whose S steps among them) and of the
    spatial ones: nothing rejected (a clean 60 s log of six channels at 1 kHz among them)."""
    count = 0
    for name in ("paper", "noisy", "real-rig", "vision-50hz", "random-S", "time-varying"):
        for seed in range(2):
            log, _, _ = get_scenario(name).generate(seed)
            count += find_glitches(log.t, log.w_hat)[0].count
    for scenario in (ARM, MOCAP):
        for seed in range(2):
            log, _, _ = scenario.generate(seed)
            count += find_glitches(log.t, log.w_hat)[0].count
    assert count == 0


@pytest.mark.parametrize("scenario", [ARM, MOCAP], ids=["arm", "mocap"])
def test_the_misfit_check_passes_clean_logs(scenario):
    """At least 95 % of clean 10 s logs fit (M1, M2); none is a gross misfit."""
    short = scenario.with_(duration=10.0)
    model = SpatialModel(short.payload)
    found = [misfit(log.shift_poses(short.latency), model)
             for log in (short.generate(100 + seed)[0] for seed in range(20))]
    assert sum(f.fits for f in found) >= 19
    assert not any(f.gross for f in found)
    ratio = np.array([f.ratio for f in found])
    assert 0.9 < ratio.mean() < 1.1 and ratio.max() < 1.3


def test_the_misfit_check_passes_mujoco_logs():
    """Logs MuJoCo integrated (another engine's dynamics): they fit."""
    pytest.importorskip("mujoco")
    from mujoco_log import mujoco_log
    short = ARM.with_(duration=10.0)
    model = SpatialModel(short.payload)
    found = [misfit(mujoco_log(short, seed)[0], model) for seed in range(4)]
    assert all(f.fits for f in found) and max(f.ratio.max() for f in found) < 1.1


def test_a_frame_turned_10_degrees_is_caught():
    """The payload in the sensor's axes, the poses of a frame turned 10 degrees: a gross misfit on at least 7 of
    8 logs of 10 s, and on 60 s logs."""
    model = SpatialModel(ARM.payload)
    short = ARM.with_(duration=10.0)
    assert sum(misfit(turned(short.generate(seed)[0], 10.0), model).gross for seed in range(8)) >= 7
    assert all(misfit(turned(ARM.generate(seed)[0], 10.0), model).gross for seed in range(2))


def test_forty_spikes_on_a_planar_real_rig_log():
    """Issue 37: 40 spikes on a planar real-rig log (20 noise standard deviations on fx): the floor as on the
    clean log, all 40 rejected; and the misfit measure, shared, finds the planar model fitting it."""
    scenario = get_scenario("real-rig")
    log, truth, _ = scenario.generate(0)
    clean = calibrate(log, scenario.payload, truth=truth, payload_std=EXACT)
    rows = np.random.default_rng(4).choice(np.arange(len(log)), 40, replace=False)
    bad = copy.copy(log)
    bad.w_hat = log.w_hat.copy()
    bad.w_hat[rows, 1] += 20 * reading_noise(log.w_hat)[1]
    cal = calibrate(bad, scenario.payload, truth=truth, payload_std=EXACT)
    assert sorted(cal.glitches["indices"]) == sorted(rows.tolist())
    assert cal.E < 1.2 * clean.E and cal.converged
    assert np.abs((cal.S_hat - truth.S_at(log.t[-1])) / cal.S_std).max() < 5
    assert misfit(log.shift_poses(cal.latency), PlanarModel(scenario.payload)).fits
