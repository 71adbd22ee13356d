"""The spatial scenarios: what they claim to hold (noise, rates, latency, motion), and their files."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fmscal.plant import read_log, read_truth
from fmscal.plant.physics._rigid_body import sensor_wrench
from fmscal.plant.scenarios._spatial import SPATIAL_SCENARIOS


@pytest.fixture(scope="module")
def arm():
    return SPATIAL_SCENARIOS["spatial-arm"].with_(duration=20.0).generate(3)


def _angles(q):
    return Rotation.from_quat(np.roll(q, -1, axis=1)).as_euler("zyx")


def test_the_reading_is_S_inverse_of_the_wrench_the_motion_needs_plus_offset_and_noise(arm):
    log, truth, x = arm
    S, b = truth.S_at(0.0), truth.offset
    # the wrench at a few samples, from the true state by finite differences of the true velocities
    k = np.arange(100, len(log) - 100, 997)
    dt = log.dt
    v, omega = x[:, 7:10], x[:, 10:13]
    w = np.array([sensor_wrench(x[i, 3:7], omega[i], (omega[i + 1] - omega[i - 1]) / (2 * dt),
                                (v[i + 1] - v[i - 1]) / (2 * dt), truth.payload) for i in k])
    residual = log.w_hat[k] - (w @ np.linalg.inv(S).T + b)
    sd = np.array(truth.noise.wrench_sd)
    z = residual / sd
    assert 0.7 < np.std(z) < 1.3 and abs(np.mean(z)) < 0.3           # white noise of the stated size, no bias


def test_the_noise_has_the_stated_size(arm):
    log, truth, x = arm
    n = log.w_hat.shape[0]
    # second differences of white noise have variance 6 sd^2; the smooth signal adds little at 1 kHz
    d2 = np.diff(log.w_hat, 2, axis=0)
    ratio = np.std(d2, axis=0) / (np.sqrt(6) * np.array(truth.noise.wrench_sd))
    assert np.all((0.95 < ratio) & (ratio < 1.1)), ratio
    turn = (Rotation.from_quat(np.roll(x[:, 3:7], -1, axis=1)).inv()
            * Rotation.from_quat(np.roll(log.pose[:, :4], -1, axis=1))).as_rotvec()
    assert 0.95 < np.std(turn) / truth.noise.angle_sd < 1.05
    assert 0.95 < np.std(log.pose[:, 4:] - x[:, :3]) / truth.noise.position_sd < 1.05
    assert n == 20001


def test_arm_turns_through_large_angles_and_weak_does_not(arm):
    spread = np.degrees(np.ptp(_angles(arm[2][:, 3:7]), axis=0))
    assert np.all(spread > 45), spread
    _, _, x = SPATIAL_SCENARIOS["spatial-weak"].with_(duration=20.0).generate(0)
    assert np.degrees(np.ptp(_angles(x[:, 3:7]), axis=0)).max() < 10


def test_mocap_has_its_rate_drops_and_latency():
    sc = SPATIAL_SCENARIOS["spatial-mocap"].with_(duration=20.0)
    log, truth, x = sc.generate(1, noise_free=True)
    rate = log.pose_rate()
    assert 190 < rate < 199                             # 200 Hz less 2 % dropped
    k = np.flatnonzero(log.has_pose)[10:-10]
    lag = int(round(0.005 / log.dt))
    np.testing.assert_allclose(log.pose[k, 4:], x[k - lag, :3], atol=1e-12)      # the pose of t - latency
    assert truth.latency == 0.005


def test_static_holds_its_attitudes():
    _, _, x = SPATIAL_SCENARIOS["spatial-static"].generate(0)
    still = np.linalg.norm(x[:, 10:13], axis=1) < 1e-9
    assert 0.3 < still.mean() < 0.45                    # 3 s held of every 8 s
    assert np.abs(x[:, 10:13]).max() < 1.0


def test_a_spatial_log_and_its_truth_round_trip(tmp_path, arm):
    log, truth, _ = arm
    log.write(tmp_path / "arm.csv")
    truth.write(tmp_path / "arm.truth.json")
    again, back = read_log(tmp_path / "arm.csv"), read_truth(tmp_path / "arm.truth.json")
    assert again.kind == "spatial"
    np.testing.assert_array_equal(again.w_hat, log.w_hat)
    np.testing.assert_array_equal(back.S_at(0.0), truth.S_at(0.0))
    np.testing.assert_array_equal(back.offset, truth.offset)
    assert back.payload == truth.payload and back.noise == truth.noise


def test_spatial_drift_moves_each_gain_by_its_stated_share_and_nothing_else():
    scenario = SPATIAL_SCENARIOS["spatial-drift"].with_(duration=10.0)
    log, truth, x = scenario.generate(2)
    S0, S_end = truth.S_at(0.0), truth.S_at(log.t[-1])
    gains = np.diag(np.linalg.solve(S0, S_end))                   # S(t) = S0 (I + drift diag(d) t / T)
    np.testing.assert_allclose(np.abs(gains - 1), 0.05 * 9 / 10, rtol=1e-12)      # the last 1 s step: 9/10
    assert len(set(np.sign(gains - 1))) == 2                      # signs drawn per channel (this seed: both)
    np.testing.assert_allclose(np.linalg.solve(S0, S_end), np.diag(gains), atol=1e-12)
    # a scenario without drift keeps its draws: spatial-arm's log is spatial-drift's motion, S0 and noise
    arm, arm_truth, arm_x = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=10.0).generate(2)
    np.testing.assert_array_equal(arm_x, x)
    np.testing.assert_array_equal(arm_truth.S_at(0.0), S0)
