"""The augmented-state EKF: casadi Jacobians, accuracy, covariance health."""

import numpy as np
import pytest

import plant
from analysis import calibration_error, error_history
from observers import AugmentedEKF


def test_casadi_jacobians_match_finite_differences_of_the_plant():
    ekf = AugmentedEKF(plant.PAPER_PAYLOAD)
    rng = np.random.default_rng(0)
    xs, w0, w1, dt = rng.normal(size=15), rng.normal(size=3), rng.normal(size=3), 1e-2
    f, F, J0, J1 = ekf.transition(xs, w0, w1, dt)
    S = xs[6:].reshape(3, 3)
    np.testing.assert_allclose(f[:6], plant.rk4_step(xs[:6], S @ w0, S @ (w0 + w1) / 2, S @ w1, dt,
                                                     plant.PAPER_PAYLOAD), rtol=1e-12)
    h = 1e-6
    for j in range(15):
        e = np.zeros(15)
        e[j] = h
        column = (ekf.transition(xs + e, w0, w1, dt)[0] - ekf.transition(xs - e, w0, w1, dt)[0]) / (2 * h)
        np.testing.assert_allclose(F[:, j], column, atol=1e-7)
    for J, which in ((J0, 0), (J1, 1)):
        for j in range(3):
            e = np.zeros(3)
            e[j] = h
            args_p = (w0 + e, w1) if which == 0 else (w0, w1 + e)
            args_m = (w0 - e, w1) if which == 0 else (w0, w1 - e)
            column = (ekf.transition(xs, *args_p, dt)[0] - ekf.transition(xs, *args_m, dt)[0]) / (2 * h)
            np.testing.assert_allclose(J[:, j], column, atol=1e-7)


@pytest.fixture(scope="module")
def paper_30s():
    return plant.get_scenario("paper").with_(duration=30.0).generate(0)


def test_ekf_reaches_E_below_1e_2_within_30_s(paper_30s):
    log, truth, _ = paper_30s
    result = AugmentedEKF(plant.PAPER_PAYLOAD, noise=truth.noise).run(log, truth.S0)
    assert not result.diverged
    E = error_history(result.S_hat_history, truth.S_at(0.0))
    assert np.min(E[len(E) // 2:]) < 1e-2 and E[-1] < 2e-2
    assert result.S_std is not None and np.all(result.S_std > 0) and np.all(result.S_std < 0.05)


def test_covariance_stays_symmetric_positive_definite(paper_30s):
    log, truth, _ = paper_30s
    ekf = AugmentedEKF(plant.PAPER_PAYLOAD, noise=truth.noise)
    ekf.reset(truth.S0)
    for k in range(10000):
        ekf.step(log.dt, log.pose[k], log.w_hat[k])
        if k % 250 == 0:
            P = ekf._kf.P
            np.testing.assert_allclose(P, P.T, atol=1e-12 * np.max(np.abs(P)))
            assert np.min(np.linalg.eigvalsh((P + P.T) / 2)) > 0


def test_noise_is_estimated_from_the_log_when_not_given(paper_30s):
    log, truth, _ = paper_30s
    result = AugmentedEKF(plant.PAPER_PAYLOAD).run(log.head(5000), truth.S0)
    est = result.info["noise"]
    np.testing.assert_allclose(est["wrench_sd"], truth.noise.wrench_sd, rtol=0.1)
    assert est["angle_sd"] == pytest.approx(truth.noise.angle_sd, rel=0.1)
    assert est["position_sd"] == pytest.approx(truth.noise.position_sd, rel=0.1)


@pytest.mark.slow
def test_ekf_tracks_the_table_1_steps():
    log, truth, _ = plant.get_scenario("time-varying").generate(0)
    result = AugmentedEKF(plant.PAPER_PAYLOAD, noise=truth.noise).run(log, truth.S0)
    E = error_history(result.S_hat_history, truth.S_at(result.t))
    for end in (99.0, 199.0, 299.0):
        assert E[int(round(end / log.dt))] < 0.05


def test_ekf_on_another_payload_and_S():
    payload = plant.Payload(6.0, 0.3, [-0.15, 0.4])
    log, truth, _ = plant.get_scenario("random-S").with_(payload=payload, duration=30).generate(2)
    result = AugmentedEKF(payload, noise=truth.noise).run(log, truth.S0)
    assert not result.diverged
    assert calibration_error(result.S_hat, truth.S_at(0.0)) < 0.05


@pytest.mark.parametrize("call, match", [
    (lambda e: e.step(0.001, [0, 0, 0], [1, np.nan, 3]), "w_hat must be 3 finite"),
    (lambda e: e.step(0.001, [0, 0], [1, 2, 3]), "pose must be 3 finite numbers"),
    (lambda e: e.step(0.001, None, [1, 2, 3]), "first sample after reset"),
    (lambda e: (e.step(0.001, [0, 0, 0], [1, 2, 3]), e.step(0.0, [0, 0, 0], [1, 2, 3])), "dt must be positive"),
    (lambda e: e.reset(np.full((3, 3), np.nan)), "S0 must be finite"),
])
def test_ekf_refuses_bad_samples_like_every_observer(call, match):
    with pytest.raises(ValueError, match=match):
        call(AugmentedEKF(plant.PAPER_PAYLOAD))


def test_ekf_without_random_walk_is_near_least_squares_on_the_same_data():
    """Issue 4: the EKF near the accuracy of a least-squares fit (q_S = 0: constant S, as LS assumes)."""
    from observers import LeastSquares
    log, truth, _ = plant.get_scenario("paper").with_(duration=60).generate(0)
    E_ls = calibration_error(LeastSquares(plant.PAPER_PAYLOAD).run(log).S_hat, plant.PAPER_S)
    E_ekf = calibration_error(AugmentedEKF(plant.PAPER_PAYLOAD, noise=truth.noise, q_S=0.0)
                              .run(log, truth.S0).S_hat, plant.PAPER_S)
    assert E_ekf < 1.5 * E_ls
