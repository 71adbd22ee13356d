"""The maximum-likelihood reference estimate of S: known answers, honest uncertainties, inputs."""

import numpy as np
import pytest

from fmscal import plant
from fmscal.analysis import calibration_error
from fmscal.observers import LeastSquares
from fmscal.observers.batch._max_likelihood import MaximumLikelihoodFit, fit_max_likelihood
from fmscal.observers.kalman import POSE_SD_FLOOR, V0_SD
from fmscal.plant.numerics._errors import FmscalError


def _case(name="paper", seed=0, duration=10.0, **changes):
    sc = plant.get_scenario(name).with_(duration=duration, **changes)
    log, truth, _ = sc.generate(seed)
    return sc, log.shift_poses(truth.latency), truth


def _batch_gls(log, payload, noise, S_noise, offset):
    """The same model written densely: all poses at once, generalized least squares.

    ``x_k = Phi^k x_0 + sum_j<k Phi^(k-1-j) (U_j s + w_j)`` with ``x_0`` the
    first pose and zero velocities (prior ``V0_SD``), ``w_j`` white with
    ``Cov = [h^2, h][h^2, h]^T (x) G_j S Sigma S^T G_j^T``, poses with white
    noise. Returns the information ``J = D^T V^-1 D`` about ``s`` (row order
    ``[S | c]``), the right side ``r = D^T V^-1 y``, and the errors-in-variables
    term ``B = E[D_n^T V^-1 D_n]`` (``D_n`` the part of the design the
    reading's noise makes).
    """
    n = 4 if offset else 3
    m, N, h = 3 * n, len(log), log.dt
    theta = np.interp(log.t, log.t[log.has_pose], log.pose[log.has_pose, 0])
    w_aug = np.column_stack([log.w_hat, np.ones(N)]) if offset else log.w_hat
    G = np.array([plant.input_matrix(theta[k], payload) for k in range(N)])
    reg = np.array([np.kron(G[k], w_aug[k][None, :]) for k in range(N)])
    W = S_noise @ np.diag(np.square(noise.wrench_sd)) @ S_noise.T
    pose_var = np.maximum(noise.pose_sd, POSE_SD_FLOOR) ** 2
    # random inputs: e0 (6: initial state error), then per step j the noise w_j (6); their covariance
    n_rand = 6 + 6 * (N - 1)
    cov_rand = np.zeros((n_rand, n_rand))
    cov_rand[:6, :6] = np.diag([pose_var[0], V0_SD ** 2, pose_var[1], V0_SD ** 2, pose_var[2], V0_SD ** 2])
    g = np.array([h * h, h])
    U = np.zeros((N - 1, 6, m))
    for j in range(N - 1):
        cov_rand[6 + 6 * j:12 + 6 * j, 6 + 6 * j:12 + 6 * j] = np.kron(G[j] @ W @ G[j].T, np.outer(g, g))
        U[j, 0::2] = h * h * (2 * reg[j] + reg[j + 1]) / 6
        U[j, 1::2] = h * (reg[j] + reg[j + 1]) / 2
    rows = [k for k in range(1, N) if log.has_pose[k]]
    T = np.zeros((3 * len(rows), n_rand))           # pose of channel c at k from the random inputs
    y = np.zeros(3 * len(rows))
    for i, k in enumerate(rows):
        for c in range(3):
            T[3 * i + c, 2 * c] = 1.0
            T[3 * i + c, 2 * c + 1] = k * h
            j = np.arange(k)
            T[3 * i + c, 6 + 6 * j + 2 * c] = 1.0
            T[3 * i + c, 6 + 6 * j + 2 * c + 1] = (k - 1 - j) * h
            y[3 * i + c] = log.pose[k, c] - log.pose[0, c]
    T_steps = T[:, 6:]                              # a step's input (6) enters the poses as its noise does
    D = T_steps @ U.reshape(-1, m)
    V = T @ cov_rand @ T.T + np.kron(np.eye(len(rows)), np.diag(pose_var))
    Vi = np.linalg.inv(V)
    J, r = D.T @ Vi @ D, D.T @ Vi @ y
    # a unit of reading noise on component l at sample k moves column (i, l) of the design by
    # T_steps (dU_(k-1) + dU_k): the end of step k-1 and the start of step k
    beta = np.zeros((3, 3))
    for k in range(N):
        a = np.zeros((len(y), 3))
        for i in range(3):
            if k >= 1:
                a[:, i] += T_steps[:, 6 * (k - 1):6 * k] @ np.kron(G[k][:, i], [h * h / 6, h / 2])
            if k <= N - 2:
                a[:, i] += T_steps[:, 6 * k:6 * (k + 1)] @ np.kron(G[k][:, i], [h * h / 3, h / 2])
        beta += a.T @ Vi @ a
    B = np.zeros((m, m))
    for l in range(3):
        idx = [n * i + l for i in range(3)]
        B[np.ix_(idx, idx)] = noise.wrench_sd[l] ** 2 * beta
    return J, r, B


@pytest.mark.parametrize("offset, pose_rate", [(False, None), (True, None), (False, 100.0)])
def test_the_filter_is_the_batch_least_squares_of_the_same_model(offset, pose_rate):
    """Information, right side and errors-in-variables term against the dense batch form."""
    sc = plant.get_scenario("random-S").with_(duration=0.3, dt=2e-3, pose_rate=pose_rate,
                                              offset=(0.3, 2.0, -1.5) if offset else None)
    log, truth, _ = sc.generate(3)
    S_noise = truth.S_at(0.0)
    fit = fit_max_likelihood(log, sc.payload, truth.noise, offset=offset, passes=1, S0=S_noise)
    J, r, B = _batch_gls(log, sc.payload, truth.noise, S_noise, offset)
    scale = np.sqrt(np.outer(np.diag(J), np.diag(J)))
    np.testing.assert_allclose(fit.information / scale, J / scale, atol=1e-8)
    np.testing.assert_allclose(fit.eiv_bias / scale, B / scale, atol=1e-8)
    assert np.max(np.abs(B / scale)) > 1e-9                 # the test can see B
    S_batch = np.linalg.solve(J - B, r).reshape(fit.S_aug.shape)
    Jc_inv = np.linalg.inv(J - B)
    cov = Jc_inv @ J @ Jc_inv
    std = np.sqrt(np.diag(cov)).reshape(fit.S_aug.shape)
    assert np.max(np.abs(fit.S_aug - S_batch) / std) < 1e-4          # a short log: ill-conditioned
    np.testing.assert_allclose(np.sqrt(np.diag(fit.cov_aug)).reshape(std.shape), std, rtol=1e-5)


def test_noise_free_log_gives_the_true_S():
    sc = plant.get_scenario("random-S").with_(duration=5.0)
    log, truth, _ = sc.generate(1, noise_free=True)
    fit = fit_max_likelihood(log, sc.payload, plant.NoiseSpec((0.0, 0.0, 0.0), 1e-6, 1e-6))
    assert calibration_error(fit.S_hat, truth.S_at(0.0)) < 1e-6
    assert calibration_error(fit.S_history[-1], truth.S_at(0.0)) < 1e-6
    np.testing.assert_allclose(fit.x_history[:, [0, 2, 4]], log.pose, atol=1e-6)
    assert np.all(fit.eiv_bias == 0)


def _agree(fits, late, tol_std):
    """The numpy and the compiled fit: the same numbers to 1e-9 (relative to each entry's scale).

    The estimate is compared in units of its uncertainty, to ``tol_std``: the solve amplifies
    the rounding of the information by its condition number, enormous on a short log.
    """
    d = np.sqrt(np.diag(fits[0].information))
    np.testing.assert_allclose(fits[0].information / np.outer(d, d), fits[1].information / np.outer(d, d),
                               atol=1e-9)
    np.testing.assert_allclose(fits[0].eiv_bias / np.outer(d, d), fits[1].eiv_bias / np.outer(d, d),
                               atol=1e-12)
    std = np.sqrt(np.diag(fits[0].cov_aug)).reshape(fits[0].S_aug.shape)
    assert np.max(np.abs(fits[0].S_aug - fits[1].S_aug) / std) < tol_std
    np.testing.assert_allclose(np.sqrt(np.diag(fits[1].cov_aug)).reshape(std.shape), std, rtol=1e-9)
    # the history: its first samples are unidentified (rank-deficient information)
    assert np.max(np.abs(fits[0].S_history[late] - fits[1].S_history[late]) / std[None]) < tol_std
    np.testing.assert_allclose(fits[0].x_history[late], fits[1].x_history[late], atol=1e-9)


def test_numpy_and_compiled_paths_agree():
    # one pass: on so short a log the estimate is ill-conditioned, and a second pass would take
    # its noise model from it, amplifying rounding
    sc, log, truth = _case("paper", 2, duration=0.8, dt=2e-3, offset=(0.3, 2.0, -1.5))
    fits = [fit_max_likelihood(log, sc.payload, offset=True, passes=1, S0=truth.S0, compiled=c)
            for c in (False, True)]
    _agree(fits, slice(len(log) // 2, None), tol_std=1e-5)        # 0.8 s with an offset: ill-conditioned


@pytest.mark.slow
def test_numpy_and_compiled_paths_agree_on_a_multi_rate_rig():
    sc, log, truth = _case("real-rig", 2, duration=2.0)
    fits = [fit_max_likelihood(log, sc.payload, offset=True, S0=truth.S0, compiled=c) for c in (False, True)]
    _agree(fits, slice(int(0.9 * len(log)), None), tol_std=1e-8)


def _z_scores(name, seeds, duration, offset=False):
    z, zb = [], []
    for seed in seeds:
        sc, log, truth = _case(name, seed, duration)
        fit = fit_max_likelihood(log, sc.payload, offset=offset, S0=truth.S0)
        z.append(((fit.S_hat - truth.S_at(0.0)) / fit.S_std).ravel())
        if offset:
            zb.append((fit.b - truth.offset) / fit.b_std)
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
    assert np.all(np.abs(fit.b - truth.offset) < 5 * fit.b_std)
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
    with pytest.raises(FmscalError, match="fit_max_likelihood needs a model .* got dict"):
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
