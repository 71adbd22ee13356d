"""The maximum-likelihood reference estimate of S: known answers, honest uncertainties, inputs."""

import numpy as np
import pytest

import plant
from analysis import calibration_error
from observers import LeastSquares
from observers.max_likelihood import POSE_SD_FLOOR, V0_SD, MaximumLikelihoodFit, fit_max_likelihood
from plant.errors import FmscalError


def _case(name="paper", seed=0, duration=10.0, **changes):
    sc = plant.get_scenario(name).with_(duration=duration, **changes)
    log, truth, _ = sc.generate(seed)
    return sc, log.shift_poses(truth.extra.get("latency") or 0.0), truth


def _batch_gls(log, payload, noise, S_noise, offset):
    """The same model written densely: all poses at once, generalized least squares.

    ``x_k = Phi^k x_0 + sum_j<k Phi^(k-1-j) (U_j s + w_j)`` with ``x_0`` the
    first pose and zero velocities (prior ``V0_SD``), ``w_j`` white with
    ``Cov = [h^2, h][h^2, h]^T (x) G_j S Sigma S^T G_j^T``, poses with white
    noise; ``s`` (row order ``[S | c]``) by GLS with no prior.
    """
    n = 4 if offset else 3
    m, N, h = 3 * n, len(log), log.dt
    theta = np.interp(log.t, log.t[log.has_pose], log.pose[log.has_pose, 0])
    w_aug = np.column_stack([log.w_hat, np.ones(N)]) if offset else log.w_hat
    reg = np.array([np.kron(plant.input_matrix(theta[k], payload), w_aug[k][None, :]) for k in range(N)])
    W = S_noise @ np.diag(np.square(noise.wrench_sd)) @ S_noise.T
    pose_var = np.maximum(noise.pose_sd, POSE_SD_FLOOR) ** 2
    # random inputs: e0 (6: initial state error), then per step j the noise w_j (6); their covariance
    n_rand = 6 + 6 * (N - 1)
    cov_rand = np.zeros((n_rand, n_rand))
    cov_rand[:6, :6] = np.diag([pose_var[0], V0_SD ** 2, pose_var[1], V0_SD ** 2, pose_var[2], V0_SD ** 2])
    g = np.array([h * h, h])
    U = np.zeros((N - 1, 6, m))
    for j in range(N - 1):
        A = plant.input_matrix(theta[j], payload) @ W @ plant.input_matrix(theta[j], payload).T
        cov_rand[6 + 6 * j:12 + 6 * j, 6 + 6 * j:12 + 6 * j] = np.kron(A, np.outer(g, g))
        U[j, 0::2] = h * h * (2 * reg[j] + reg[j + 1]) / 6
        U[j, 1::2] = h * (reg[j] + reg[j + 1]) / 2
    rows = [k for k in range(1, N) if log.has_pose[k]]
    T = np.zeros((3 * len(rows), n_rand))           # pose of channel c at k from the random inputs
    D = np.zeros((3 * len(rows), m))                # and from s
    y = np.zeros(3 * len(rows))
    for i, k in enumerate(rows):
        for c in range(3):
            T[3 * i + c, 2 * c] = 1.0
            T[3 * i + c, 2 * c + 1] = k * h
            j = np.arange(k)
            T[3 * i + c, 6 + 6 * j + 2 * c] = 1.0
            T[3 * i + c, 6 + 6 * j + 2 * c + 1] = (k - 1 - j) * h
            D[3 * i + c] = U[j, 2 * c].sum(0) + ((k - 1 - j)[:, None] * h * U[j, 2 * c + 1]).sum(0)
            y[3 * i + c] = log.pose[k, c] - log.pose[0, c]
    V = T @ cov_rand @ T.T + np.kron(np.eye(len(rows)), np.diag(pose_var))
    Vi_D = np.linalg.solve(V, D)
    info = D.T @ Vi_D
    s = np.linalg.solve(info, Vi_D.T @ y)
    return s.reshape(3, n), np.linalg.inv(info)


@pytest.mark.parametrize("offset, pose_rate", [(False, None), (True, None), (False, 100.0)])
def test_the_filter_is_the_batch_generalized_least_squares_of_the_same_model(offset, pose_rate):
    sc = plant.get_scenario("paper").with_(duration=0.6, dt=2e-3, pose_rate=pose_rate,
                                           offset=(0.3, 2.0, -1.5) if offset else None)
    log, truth, _ = sc.generate(3)
    S_noise = truth.S_at(0.0)
    fit = fit_max_likelihood(log, sc.payload, truth.noise, offset=offset, passes=1, S0=S_noise)
    S_gls, cov_gls = _batch_gls(log, sc.payload, truth.noise, S_noise, offset)
    np.testing.assert_allclose(fit.S_aug, S_gls, rtol=0, atol=1e-7 * np.max(np.abs(S_gls)))
    np.testing.assert_allclose(fit.cov_aug, cov_gls, rtol=1e-6, atol=1e-9 * np.max(np.abs(cov_gls)))


def test_noise_free_log_gives_the_true_S():
    sc = plant.get_scenario("random-S").with_(duration=5.0)
    log, truth, _ = sc.generate(1, noise_free=True)
    fit = fit_max_likelihood(log, sc.payload, plant.NoiseSpec((1e-3, 1e-3, 1e-3), 1e-6, 1e-6))
    assert calibration_error(fit.S_hat, truth.S_at(0.0)) < 1e-6
    assert calibration_error(fit.S_history[-1], truth.S_at(0.0)) < 1e-6
    np.testing.assert_allclose(fit.x_history[:, [0, 2, 4]], log.pose, atol=1e-6)


def test_numpy_and_compiled_paths_agree():
    sc, log, truth = _case("real-rig", 2, duration=1.0)
    fits = [fit_max_likelihood(log, sc.payload, offset=True, S0=truth.S0, compiled=c) for c in (False, True)]
    np.testing.assert_allclose(fits[0].S_aug, fits[1].S_aug, atol=1e-9)
    np.testing.assert_allclose(fits[0].cov_aug, fits[1].cov_aug, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(fits[0].x_history, fits[1].x_history, atol=1e-9)
    late = slice(len(log) // 2, None)            # early on the history is regularised: rounding grows
    np.testing.assert_allclose(fits[0].S_history[late], fits[1].S_history[late], atol=1e-9)


def _z_scores(name, seeds, duration, offset=False):
    z, zb = [], []
    for seed in seeds:
        sc, log, truth = _case(name, seed, duration)
        fit = fit_max_likelihood(log, sc.payload, offset=offset, S0=truth.S0)
        z.append(((fit.S_hat - truth.S_at(0.0)) / fit.S_std).ravel())
        if offset:
            zb.append((fit.b - np.array(truth.extra["offset"])) / fit.b_std)
    return np.concatenate(z), (np.concatenate(zb) if offset else None)


def test_S_std_is_honest_over_seeds():
    """The z-scores of every entry over 24 seeds (216 values): mean near 0, standard deviation near 1."""
    z, _ = _z_scores("paper", range(24), 10.0)
    assert abs(np.mean(z)) < 0.25
    assert 0.8 <= np.std(z) <= 1.25


@pytest.mark.slow
def test_S_std_and_b_std_are_honest_on_a_multi_rate_rig_with_offset():
    z, zb = _z_scores("real-rig", range(20), 20.0, offset=True)
    assert 0.8 <= np.std(z) <= 1.25
    assert 0.8 <= np.std(zb) <= 1.25
    assert abs(np.mean(z)) < 0.3


@pytest.mark.slow
def test_S_std_is_honest_with_large_noise_and_a_random_S():
    z, _ = _z_scores("noisy", range(20), 10.0)
    assert 0.8 <= np.std(z) <= 1.25


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_not_worse_than_least_squares(seed):
    sc, log, truth = _case("paper", seed, 20.0)
    S = truth.S_at(0.0)
    E_ml = calibration_error(fit_max_likelihood(log, sc.payload, S0=truth.S0).S_hat, S)
    E_ls = calibration_error(LeastSquares(sc.payload).run(log).S_hat, S)
    assert E_ml < 1.1 * E_ls


def test_multi_rate_log_with_dropped_frames_and_latency():
    sc, log, truth = _case("real-rig", 0, 20.0)
    assert not log.has_pose.all()
    fit = fit_max_likelihood(log, sc.payload, offset=True, S0=truth.S0)
    assert isinstance(fit, MaximumLikelihoodFit) and fit.noise_estimated and fit.passes == 2
    assert fit.S_history.shape == (len(log), 3, 4) and fit.x_history.shape == (len(log), 6)
    assert calibration_error(fit.S_hat, truth.S_at(0.0)) < 0.02
    assert np.all(np.abs(fit.b - np.array(truth.extra["offset"])) < 5 * fit.b_std)
    assert np.all(np.isfinite(fit.S_history)) and np.all(np.isfinite(fit.x_history))


def test_told_noise_is_used_and_reported():
    sc, log, truth = _case("paper", 0, 2.0)
    fit = fit_max_likelihood(log, sc.payload, truth.noise, passes=1)
    assert fit.noise == truth.noise and not fit.noise_estimated and fit.passes == 1
    assert fit.b is None and fit.b_std is None


def test_bad_inputs_raise_with_the_value_named():
    sc, log, truth = _case("paper", 0, 1.0)
    with pytest.raises(TypeError, match="log must be a plant.Log; got ndarray"):
        fit_max_likelihood(np.zeros((10, 7)), sc.payload)
    with pytest.raises(TypeError, match="payload must be a plant.Payload; got dict"):
        fit_max_likelihood(log, {"mass": 2.5})
    with pytest.raises(TypeError, match="noise must be a plant.NoiseSpec or None; got tuple"):
        fit_max_likelihood(log, sc.payload, noise=(0.1, 0.1, 0.1))
    with pytest.raises(FmscalError, match="passes must be a positive integer; got 0"):
        fit_max_likelihood(log, sc.payload, passes=0)
    with pytest.raises(FmscalError, match="S0 has the wrong shape"):
        fit_max_likelihood(log, sc.payload, S0=np.eye(2))


def test_a_log_that_does_not_excite_S_raises():
    t = np.arange(200) * 1e-3
    log = plant.Log(t, np.zeros((200, 3)), np.tile([0.0, 1.0, 0.0], (200, 1)), name="still")
    with pytest.raises(FmscalError, match="still: the log does not excite all nine entries of S"):
        fit_max_likelihood(log, plant.PAPER_PAYLOAD, plant.NoiseSpec((0.01,) * 3, 1e-3, 1e-4))
