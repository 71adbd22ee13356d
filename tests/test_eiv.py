"""The errors-in-variables compensation the EKF reports through (observers.kalman._eiv)."""

import numpy as np
import pytest

from fmscal import plant
from fmscal.observers import AugmentedEKF
from fmscal.observers.kalman._eiv import _compensation, _compiled, compensation_matrix
from fmscal.observers.kalman._filter import filter_layout, initial_state
from fmscal.observers.batch._max_likelihood import fit_max_likelihood


@pytest.mark.slow
@pytest.mark.parametrize("n", [3, 4])
def test_compiled_compensation_matches_the_readable_step(n):
    """The compiled call and the same step in numpy agree to rounding, state and output, without and with the
    offset column (which has no noise: its rows of ``T`` stay those of the identity)."""
    model = plant.PlanarModel(plant.PAPER_PAYLOAD)
    rng = np.random.default_rng(3)
    z = initial_state(model, np.array([0.1, 0.2, -0.3]), np.array([1e-6, 1e-8, 1e-8]), n)
    q = np.array([1e-3, 1e-6, 1e-8, 1e-8, 4e-4, 2.5e-3, 2.5e-3])      # h, R (3), var_w (3)
    s = np.hstack([np.eye(3), rng.normal(size=(3, n - 3))]).ravel() + 0.1 * rng.normal(size=3 * n)
    fun = _compiled(model, n)
    for k in range(200):
        q0, q1 = [0.1 + 1e-3 * k, 0.2, -0.3], [0.1 + 1e-3 * (k + 1), 0.2, -0.3]    # the configuration at both ends
        u = np.concatenate([[k % 2], q0, q1, rng.normal(scale=0.1, size=3), rng.normal(size=6)])
        z_np, s_np = _compensation(model, z, u, q, s, n)
        z_c, s_c = (np.asarray(v) for v in fun(z, u, q, s))
        np.testing.assert_allclose(z_c.ravel(), np.ravel(z_np), rtol=1e-9, atol=1e-12)
        # the compensation solves with J, still rank-deficient over the first samples: rounding amplified
        np.testing.assert_allclose(s_c.ravel(), np.ravel(s_np), rtol=1e-7, atol=1e-10)
        T = compensation_matrix(model, np.ravel(z_np), q[4:7], s, n)    # the same compensation as a matrix
        np.testing.assert_allclose(T @ s, np.ravel(s_np), rtol=1e-7, atol=1e-10)
        z = np.ravel(z_np)
    assert z.size == filter_layout(model, n).size
    assert np.linalg.norm(T - np.eye(3 * n)) > 1e-6                    # the step did compensate something
    if n == 4:
        np.testing.assert_array_equal(T[:, 3::4], np.eye(12)[:, 3::4])  # nothing multiplies the offset entries


@pytest.fixture(scope="module")
def noisy_20s():
    sc = plant.get_scenario("noisy").with_(duration=20.0)
    log, truth, _ = sc.generate(1)
    return sc, log, truth


def test_the_ekf_compensation_is_the_floors_bias(noisy_20s):
    """At the end of a log the EKF's correction ``(T - I) s`` is the floor's ``J^-1 B s`` (the same moments, with
    the EKF's angles and its S in the noise): within 10 %, and not negligible on this scenario (1.4 % of ``|s|``,
    so that a compensation left off fails the test)."""
    sc, log, truth = noisy_20s
    ekf = AugmentedEKF(sc.payload, noise=truth.noise)
    ekf.run(log, truth.S0)
    fit = fit_max_likelihood(log, sc.payload, truth.noise)
    S = truth.S_at(0.0).ravel()
    floor_correction = np.linalg.solve(fit.information, fit.eiv_bias @ S)
    assert np.linalg.norm(floor_correction) > 5e-3 * np.linalg.norm(S)
    ekf_correction = (ekf.eiv.T - np.eye(9)) @ S
    assert np.linalg.norm(ekf_correction - floor_correction) < 0.1 * np.linalg.norm(floor_correction)


def test_the_ekf_reports_the_compensated_filter(noisy_20s):
    """``S_hat = T s`` and ``P_S = T P T^T`` from the filter's own ``s`` and ``P``; ``eiv=False`` reports them as is."""
    sc, log, truth = noisy_20s
    log = log.head(5000)
    ekf = AugmentedEKF(sc.payload, noise=truth.noise)
    result = ekf.run(log, truth.S0)
    # the nominal s (filterpy's x is the error state, zero between steps) and its block of P
    s, P, T = ekf.run_data.state.xs[6:], ekf.run_data.state.kf.P[6:, 6:], ekf.eiv.T
    assert not ekf.run_data.state.kf.x.any()
    np.testing.assert_allclose(result.S_hat.ravel(), T @ s, rtol=1e-12)
    np.testing.assert_allclose(result.S_std.ravel(), np.sqrt(np.diag(T @ P @ T.T)), rtol=1e-12)
    plain = AugmentedEKF(sc.payload, noise=truth.noise, eiv=False)
    result_plain = plain.run(log, truth.S0)
    np.testing.assert_allclose(result_plain.S_hat.ravel(), s, rtol=1e-12)      # the same filter underneath
    assert plain.eiv is None

