"""The plain spatial reference: smoothed inverse dynamics and least squares for [S | c] (issue 22)."""

import numpy as np
import pytest

from fmscal.analysis._metrics import block_errors
from fmscal.observers.batch._inverse_dynamics import fit_inverse_dynamics
from fmscal.plant import FmscalError
from fmscal.plant.scenarios._spatial import SPATIAL_SCENARIOS


@pytest.fixture(scope="module")
def arm_logs():
    return [SPATIAL_SCENARIOS["spatial-arm"].with_(duration=30.0).generate(seed) for seed in range(3)]


def test_with_the_noise_compensated_the_arm_is_calibrated_with_honest_uncertainties(arm_logs):
    for log, truth, _ in arm_logs:
        S = truth.S_at(0.0)
        fit = fit_inverse_dynamics(log, truth.payload)
        E, E_torque, E_force = block_errors(fit.S_hat, S)
        assert E_torque < 0.02 and E_force < 0.02 and E < 0.2
        z = (fit.S_hat - S) / fit.S_std
        assert 0.5 < np.sqrt(np.mean(z ** 2)) < 1.6
        assert np.abs((fit.b - truth.offset) / fit.b_std).max() < 4
        assert fit.converged and not fit.undetermined


def test_plain_least_squares_is_biased_where_the_torque_carries_little_of_its_own(arm_logs):
    """Errors in variables: the reading's noise shrinks S along the weakly excited directions."""
    for log, truth, _ in arm_logs:
        S = truth.S_at(0.0)
        plain = fit_inverse_dynamics(log, truth.payload, eiv=False)
        compensated = fit_inverse_dynamics(log, truth.payload)
        assert block_errors(plain.S_hat, S)[1] > 5 * block_errors(compensated.S_hat, S)[1]
        assert np.sqrt(np.mean(((plain.S_hat - S) / plain.S_std) ** 2)) > 3        # and overconfident


def test_static_poses_leave_directions_undetermined_and_say_what_to_record():
    log, truth, _ = SPATIAL_SCENARIOS["spatial-static"].generate(0)
    fit = fit_inverse_dynamics(log, truth.payload)
    assert 2 <= len(fit.undetermined) <= 3 and not fit.converged
    assert any("angular acceleration" in w for w in fit.warnings)
    for d in fit.undetermined:
        assert np.linalg.norm(d) == pytest.approx(1.0)


def test_a_dead_channel_is_one_error_not_a_singular_matrix(arm_logs):
    log, truth, _ = arm_logs[0]
    from fmscal.plant.io._log import Log
    w_hat = log.w_hat.copy()
    w_hat[:, 0] = 0.25                                   # tx stuck
    with pytest.raises(FmscalError, match="the reading tx does not move"):
        fit_inverse_dynamics(Log(log.t, log.pose, w_hat, "stuck"), truth.payload)


@pytest.mark.parametrize("kwargs, message", [({"block": 0}, "block"), ({"gravity": [0, -9.81]}, "gravity"),
                                             ({"window": -1}, "window")])
def test_settings_are_checked(arm_logs, kwargs, message):
    log, truth, _ = arm_logs[0]
    with pytest.raises(FmscalError, match=message):
        fit_inverse_dynamics(log, truth.payload, **kwargs)


def test_block_errors_split_units():
    S = np.eye(6)
    S_hat = np.eye(6)
    S_hat[0, 3] = 0.01                                  # a force reading's share of a torque, m
    E, E_torque, E_force = block_errors(S_hat, S)
    assert E == pytest.approx(0.01) and E_torque == 0 and E_force == 0


@pytest.mark.parametrize("scenario, latency", [("spatial-mocap", 0.02), ("spatial-arm", 0.012)])
def test_the_pose_streams_latency_is_found_in_3d(scenario, latency):
    """Shifted back by the right delay the spatial log fits Newton-Euler best: the search finds the delay of a
    tracker that lags the sensor to one sample (seeded; a search that ignored the shift would return 0)."""
    from fmscal.observers.batch._latency import estimate_latency
    from fmscal.plant.physics._model import SpatialModel
    log, truth, _ = SPATIAL_SCENARIOS[scenario].with_(duration=20.0, latency=latency).generate(1)
    found = estimate_latency(log, SpatialModel(truth.payload), max_latency=0.05)
    assert abs(found.latency - latency) <= min(log.dt, 4 * found.std) and found.determined
    assert found.costs[0.0] > 1.5 * min(found.costs.values())    # the zero shift is clearly worse


def test_the_latency_search_refuses_a_log_of_another_case(arm_logs):
    from fmscal.observers.batch._latency import estimate_latency
    from fmscal.plant import PAPER_PAYLOAD
    with pytest.raises(FmscalError, match="set up for planar logs .* got a spatial log"):
        estimate_latency(arm_logs[0][0], PAPER_PAYLOAD)


@pytest.mark.parametrize("n", [201, 202, 2001, 60001])
def test_the_fast_smoothing_is_scipys_savgol_filter(n):
    """The poses' smoothing (overlap-add inside, the end polynomials at the ends) equals ``savgol_filter`` with
    ``mode="interp"`` to rounding, values and both derivatives, on signals of a pose's size (a quaternion's
    component, a position in m, a noise) from a log one window long to 60 s at 1 kHz: measured 2e-15 (values),
    1e-14 (velocities), 3e-14 (accelerations) of the largest; a wrong end or a shifted interior would be off by
    the signal's own size."""
    from scipy.signal import savgol_filter

    from fmscal.plant.physics._differentiate import ORDER, _savgol
    rng = np.random.default_rng(3)
    t = np.arange(n) * 1e-3
    values = np.column_stack([np.sin(7 * t + 1), 1.5 + np.sin(0.3 * t), 1e-3 * rng.normal(size=n)])
    for derivative in (0, 1, 2):
        expected = savgol_filter(values, 201, ORDER, deriv=derivative, delta=1e-3, axis=0, mode="interp")
        got = _savgol(values, 201, derivative, 1e-3)
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
