"""The augmented-state EKF: casadi Jacobians, accuracy, covariance health."""

import numpy as np
import pytest

from fmscal import plant
from fmscal.analysis import calibration_error, error_history
from fmscal.observers import AugmentedEKF


def test_the_nominal_step_is_the_plants_motion():
    """The error-state filter's nominal step (the discretisation every method shares, with Heun's predictor) on
    the planar model: the motion of eq. (1) under ``w = S w_hat``, against :func:`plant.rk4_step` within a
    bound that falls with the step's square (3e-6 at 10 ms, 3e-8 at 1 ms on these numbers); ``s`` unchanged."""
    ekf = AugmentedEKF(plant.PAPER_PAYLOAD)
    assert type(ekf) is AugmentedEKF and ekf.dim_x == 15 and ekf.noise_at == "estimate"
    assert AugmentedEKF(plant.PAPER_PAYLOAD, offset=True).dim_x == 18
    rng = np.random.default_rng(0)
    xs, w0, w1 = rng.normal(size=15), rng.normal(size=3), rng.normal(size=3)
    S = xs[6:].reshape(3, 3)
    gap = {}
    for dt in (1e-2, 1e-3):
        f = ekf.transition(xs, w0, w1, dt)[0]
        rk4 = plant.rk4_step(xs[:6], S @ w0, S @ (w0 + w1) / 2, S @ w1, dt, plant.PAPER_PAYLOAD)
        gap[dt] = np.max(np.abs(f[:6] - rk4))
        assert np.max(np.abs(rk4 - xs[:6])) > 1e3 * gap[dt]                  # the step moved; the gap is small
        np.testing.assert_array_equal(f[6:], xs[6:])
    assert gap[1e-3] < 1e-7 and 30 < gap[1e-2] / gap[1e-3] < 300          # second order in the step


def test_the_error_state_jacobians_match_finite_differences_of_the_planar_step():
    """``F``, ``J0``, ``J1`` (casadi's) against central differences of the nominal step in the error state
    ``[dtheta, dX, dY, dtheta', dX', dY', ds]``: on the planar model the attitude's error is the angle's
    difference."""
    ekf = AugmentedEKF(plant.PAPER_PAYLOAD)
    model = ekf.model
    rng = np.random.default_rng(0)
    x, s = rng.normal(size=6), (np.eye(3) + 0.3 * rng.normal(size=(3, 3))).ravel()
    xs, w0, w1, dt = np.r_[x, s], rng.normal(size=3), rng.normal(size=3), 1e-2
    xs_next, F, J0, J1 = ekf.transition(xs, w0, w1, dt)
    assert F.shape == (15, 15) and J0.shape == J1.shape == (15, 3)

    def error_after(xs_start, w0, w1):
        moved = ekf.transition(xs_start, w0, w1, dt)[0]
        return np.r_[model.state_difference(xs_next[:6], moved[:6]), moved[6:] - xs_next[6:]]

    h = 1e-6
    for j in range(15):
        e = np.zeros(15)
        e[j] = h
        plus = np.r_[model.state_integrate(x, e[:6]), s + e[6:]]
        minus = np.r_[model.state_integrate(x, -e[:6]), s - e[6:]]
        np.testing.assert_allclose(F[:, j], (error_after(plus, w0, w1) - error_after(minus, w0, w1)) / (2 * h),
                                   atol=1e-7)
    for J, end in ((J0, 0), (J1, 1)):
        for j in range(3):
            e = np.zeros(3)
            e[j] = h
            ws_p = (w0 + e, w1) if end == 0 else (w0, w1 + e)
            ws_m = (w0 - e, w1) if end == 0 else (w0, w1 - e)
            np.testing.assert_allclose(J[:, j], (error_after(xs, *ws_p) - error_after(xs, *ws_m)) / (2 * h),
                                       atol=1e-7)


def _close(a, b, rel=1e-9):
    """``a`` equals ``b`` to ``rel`` of ``b``'s largest entry (entries near zero within the same absolute error)."""
    assert a.shape == b.shape and np.max(np.abs(a - b)) <= rel * np.max(np.abs(b)), np.max(np.abs(a - b))


@pytest.mark.parametrize("scenario, seed, settings, noise_factor", [
    ("paper", 0, {}, 1.0),
    ("vision-50hz", 4, {"offset": True}, 1.0),        # multi-rate, with the offset column
    ("other-payload", 2, {}, 0.5),                    # told half the noise: the level rises
])
@pytest.mark.slow
def test_compiled_run_matches_filterpy(scenario, seed, settings, noise_factor):
    """The whole step compiled (the default) and filterpy's ExtendedKalmanFilter (``compiled=False``) agree to
    1e-9 relative: estimate, ``P``, ``S_std``, the compensation and the random-walk level; the filter left where
    either path ended."""
    sc = plant.get_scenario(scenario).with_(duration=2.0)
    log, truth, _ = sc.generate(seed)
    ekf = AugmentedEKF(sc.payload, noise=truth.noise.scaled(noise_factor), **settings)
    runs = []
    for compiled in (True, False):
        result = ekf.run(log, truth.S0, compiled=compiled)
        kf = ekf.run_data.state.kf
        runs.append((result, kf.P.copy(), kf.x.copy(), ekf.eiv.T, ekf.level.q, ekf.level.eps_bar))
    (fast, P_fast, x_fast, T_fast, *level_fast), (slow, P_slow, x_slow, T_slow, *level_slow) = runs
    assert not fast.diverged and len(fast.t) == len(slow.t) == len(log)
    # over the first 0.1 s the compensation solves with a rank-deficient information: rounding amplified
    early = int(round(0.1 / log.dt))
    _close(fast.S_hat_history[early:], slow.S_hat_history[early:])
    _close(fast.S_hat_history, slow.S_hat_history, 1e-6)
    _close(fast.x_hat_history, slow.x_hat_history)
    _close(fast.S_std, slow.S_std)
    if settings.get("offset"):
        _close(fast.b, slow.b)
        _close(fast.b_std, slow.b_std)
    _close(P_fast, P_slow)
    _close(x_fast, x_slow)
    _close(T_fast, T_slow)
    _close(fast.info["q_S_history"], slow.info["q_S_history"])
    _close(np.array(level_fast), np.array(level_slow))
    raised = slow.info["q_S_history"] > 0
    assert raised.any() if noise_factor < 1 else not raised.any()     # the level is exercised, and only there


@pytest.mark.slow
def test_the_whole_step_runs_on_casadis_virtual_machine_too(monkeypatch):
    """Without a C compiler the whole step runs on casadi's virtual machine, with the same numbers."""
    from fmscal.observers.kalman import _error_state
    monkeypatch.setenv("FMSCAL_COMPILER", "none")
    monkeypatch.setattr(_error_state, "_WHOLE", {})          # built afresh here, and not kept
    log, truth, _ = plant.get_scenario("paper").with_(duration=0.5).generate(0)
    ekf = AugmentedEKF(plant.PAPER_PAYLOAD, noise=truth.noise)
    fast = ekf.run(log, truth.S0)
    assert _error_state.whole_error_step(ekf.model, 3, True).fun.class_name() != "External"
    slow = ekf.run(log, truth.S0, compiled=False)
    early = int(round(0.1 / log.dt))
    _close(fast.S_hat_history[early:], slow.S_hat_history[early:])
    _close(fast.S_std, slow.S_std)


def test_compiled_run_stops_where_the_filter_diverges():
    """The health test runs on the compiled path too: readings that jump to 1e9 at sample 1200 throw S_hat past
    the divergence bound within 0.2 s; both paths stop there and report the run diverged, with every reported
    S_hat finite. (The error-state filter takes 78 and 113 samples on the two paths: at readings of 1e9 their
    rounding parts, so they are not held to one sample.) A covariance that is not finite or not positive on its
    diagonal stops it as well."""
    from fmscal.observers.kalman import output_layout
    sc = plant.get_scenario("paper").with_(duration=1.5)
    log, truth, _ = sc.generate(0)
    w_hat = log.w_hat.copy()
    w_hat[1200:] = 1e9
    bad = plant.Log(log.t, log.pose, w_hat)
    ekf = AugmentedEKF(sc.payload, noise=truth.noise)
    fast, slow = ekf.run(bad, truth.S0), ekf.run(bad, truth.S0, compiled=False)
    assert fast.diverged and slow.diverged and fast.S_std is None
    for run in (fast, slow):
        assert 1201 <= len(run.t) < 1400 and np.all(np.isfinite(run.S_hat_history))
    assert abs(len(fast.t) - len(slow.t)) <= 50                # the paths stop within 0.05 s of each other
    _close(fast.S_hat_history[:1200], slow.S_hat_history[:1200])   # and are one filter up to the jump
    out = output_layout(ekf.model, ekf.n_cols)
    Y = np.tile(out.pack(None, x=np.zeros(6), s=np.eye(3).ravel(), q=0.0, P_sum=1.0, P_min=1e-6), (5, 1))
    assert ekf._healthy_outputs(Y, 2000) == 5
    for column, value in (("P_min", 0.0), ("P_min", np.nan), ("P_sum", np.inf)):
        Z = Y.copy()
        Z[3, out.slices[column]] = value
        assert ekf._healthy_outputs(Z, 2000) == 3, column


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


@pytest.mark.slow
def test_covariance_stays_symmetric_positive_definite(paper_30s):
    log, truth, _ = paper_30s
    ekf = AugmentedEKF(plant.PAPER_PAYLOAD, noise=truth.noise)
    ekf.reset(truth.S0)
    for k in range(10000):
        ekf.step(log.dt, log.pose[k], log.w_hat[k])
        if k % 250 == 0:
            P = ekf.run_data.state.kf.P
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
    """Within 10 s of each step of Table 1 (100 s, 200 s) the EKF is back below 0.02, and below 0.01 at its end."""
    log, truth, _ = plant.get_scenario("time-varying").generate(0)
    result = AugmentedEKF(plant.PAPER_PAYLOAD, noise=truth.noise).run(log, truth.S0)
    E = error_history(result.S_hat_history, truth.S_at(result.t))
    q = result.info["q_S_history"]
    at = lambda t: int(round(t / log.dt))                                   # noqa: E731
    for step in (100.0, 200.0):
        assert E[at(step + 1)] > 0.1                                        # the step is there
        assert E[at(step + 10)] < 0.02
        assert q[at(step - 1)] == 0.0 and q[at(step):at(step + 2)].max() > 1e-6    # raised by the step
    for end in (99.0, 199.0, 299.0):
        assert E[at(end)] < 0.01


def test_without_its_adjustable_level_the_ekf_recovers_slowly_from_a_step():
    """The adaptation does the tracking: the same base random walk, held fixed, is still far off 10 s after the step."""
    log, truth, _ = plant.get_scenario("time-varying").with_(duration=111.0).generate(0)
    E = {}
    for adapt_q in (True, False):
        result = AugmentedEKF(plant.PAPER_PAYLOAD, noise=truth.noise, adapt_q=adapt_q).run(log, truth.S0)
        E[adapt_q] = error_history(result.S_hat_history[-1:], truth.S_at(result.t[-1:]))[0]
    assert E[True] < 0.02 and E[False] > 0.05


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


@pytest.mark.parametrize("scenario, seed, noise_factor", [
    ("paper", 0, 1.0),
    ("other-payload", 1, 1.0),
    ("random-S", 2, 1.0),
    ("paper", 3, 0.8),           # told 20 % too little noise: within the adaptation's tolerance
    ("paper", 4, None),          # the noise estimated from the log
])
@pytest.mark.slow
def test_ekf_with_its_defaults_is_near_least_squares_on_the_same_data(scenario, seed, noise_factor):
    """Issue 4: with its defaults, the EKF within 1.5x of a least-squares fit of the same log."""
    from fmscal.observers import LeastSquares
    sc = plant.get_scenario(scenario).with_(duration=60)
    log, truth, _ = sc.generate(seed)
    S = truth.S_at(0.0)
    noise = None if noise_factor is None else truth.noise.scaled(noise_factor)
    E_ls = calibration_error(LeastSquares(sc.payload).run(log).S_hat, S)
    result = AugmentedEKF(sc.payload, noise=noise).run(log, truth.S0)
    assert calibration_error(result.S_hat, S) < 1.5 * E_ls
    assert np.all(result.info["q_S_history"][len(log) // 2:] == 0.0)       # the level stayed at its base


def test_a_fixed_random_walk_trades_accuracy_for_forgetting():
    """The old default (q_S = 1e-5, fixed) stays well above the adjustable level on a constant S."""
    log, truth, _ = plant.get_scenario("paper").with_(duration=60).generate(0)
    E = [calibration_error(AugmentedEKF(plant.PAPER_PAYLOAD, noise=truth.noise, **kw).run(log, truth.S0).S_hat,
                           plant.PAPER_S) for kw in ({}, {"q_S": 1e-5, "adapt_q": False})]
    assert 2 * E[0] < E[1]


@pytest.mark.parametrize("kwargs, match", [
    ({"q_S": -1.0}, "q_S must be non-negative"),
    ({"q_S": -1.0, "adapt_q": False}, "q_S must be non-negative"),
    ({"q_S_max": 1e-9}, "q_S_max must be at least q_S and q_S_start"),
    ({"q_S": 1e-6, "q_S_max": 1e-7}, "q_S_max must be at least q_S and q_S_start"),
    ({"q_S_start": 0.0}, "q_S_start must be positive"),
    ({"nis_tolerance": -0.1}, "nis_tolerance must be non-negative"),
    ({"S0_sd": 0.0}, "S0_sd must be positive"),
    ({"q_S": "a"}, "q_S must be a number"),
    ({"noise_at": "end"}, "noise_at must be 'estimate', 'start' or None"),
])
def test_ekf_refuses_bad_settings(kwargs, match):
    with pytest.raises(ValueError, match=match):
        AugmentedEKF(plant.PAPER_PAYLOAD, **kwargs)


def test_ekf_with_q_S_zero_and_no_adaptation_has_no_random_walk():
    """``q_S=0, adapt_q=False``: no random walk at all; the recorded intensity is 0 throughout."""
    log, truth, _ = plant.get_scenario("paper").with_(duration=5).generate(0)
    result = AugmentedEKF(plant.PAPER_PAYLOAD, noise=truth.noise, q_S=0.0, adapt_q=False).run(log, truth.S0)
    assert not result.diverged and np.all(result.info["q_S_history"] == 0.0)


def _median_E_last_10pct(result, truth):
    E = error_history(result.S_hat_history, truth.S_at(result.t))
    return float(np.median(E[int(0.9 * len(E)):]))


@pytest.mark.slow
@pytest.mark.parametrize("scenario, seed", [("paper", 0), ("paper", 1), ("random-S", 2), ("random-S", 3)])
def test_ekf_defaults_reach_the_constant_S_filter_on_a_constant_S(scenario, seed):
    """Issue 15: with its defaults (no random walk until the innovations raise one) the EKF is within 1.3x
    of the same filter with no random walk at all, told the true noise, on a sensor that does not change."""
    from fmscal.analysis._comparison import simulate_case
    sc, log, truth, noise = simulate_case(scenario, seed, 40.0)
    E = {name: _median_E_last_10pct(AugmentedEKF(sc.payload, noise=noise, **kw).run(log, truth.S0), truth)
         for name, kw in (("default", {}), ("floor", {"q_S": 0.0, "adapt_q": False}))}
    assert E["floor"] / 1.3 < E["default"] < 1.3 * E["floor"]


def _z_scores(scenario, seed, duration, told):
    """``(S_hat - S) / S_std`` (9,) and, with an offset, ``(b_hat - b) / b_std`` (3,) of one seeded run."""
    from fmscal.analysis._comparison import simulate_case
    sc, log, truth, noise = simulate_case(scenario, seed, duration)
    offset = truth.offset is not None
    result = AugmentedEKF(sc.payload, noise=noise if told else None, offset=offset).run(
        log.shift_poses(truth.latency), truth.S0)
    z_S = ((result.S_hat - truth.S_at(log.t[-1])) / result.S_std).ravel()
    z_b = (result.b - truth.offset) / result.b_std if offset else np.zeros(0)
    return z_S, z_b


@pytest.mark.slow
@pytest.mark.parametrize("scenario, duration, told", [("paper", 25.0, True), ("real-rig", 30.0, False)])
def test_ekf_uncertainties_are_honest_over_seeds(scenario, duration, told):
    """Issue 15: over 20 seeds the z-scores of S_hat (and of b_hat on the rig, with its offset) have a spread
    between 0.8 and 1.25, told the noise or estimating it from the log: neither overconfident nor needlessly
    cautious."""
    z = [_z_scores(scenario, seed, duration, told) for seed in range(20)]
    z_S, z_b = np.array([zs for zs, _ in z]), np.array([zb for _, zb in z])
    assert 0.8 < z_S.std() < 1.25 and abs(z_S.mean()) < 0.3
    if z_b.size:
        assert 0.8 < z_b.std() < 1.25 and abs(z_b.mean()) < 0.3


@pytest.mark.slow
def test_ekf_uncertainties_are_honest_on_random_S():
    """The same two-sided spread on random S (entries up to 3, condition number up to 20), where the noisy
    reading in the regressor biased the uncompensated filter (spread 1.45): the compensation (observers.kalman._eiv)
    and the uncertainty of S in Q make it honest."""
    z = np.array([_z_scores("random-S", seed, 25.0, True)[0] for seed in range(20)])
    assert 0.8 < z.std() < 1.25 and abs(z.mean()) < 0.3


@pytest.mark.slow
def test_ekf_defaults_are_at_the_floor_where_the_reading_is_noisy():
    """Issue 15: on ``noisy`` and ``random-S`` (where the noisy reading in the regressor cost the uncompensated
    EKF 1.4-1.8x) the EKF with its defaults is within 1.3x of the floor on the median over seeds, and no seed is
    below 0.7x (the floor is what the data allow) or above 1.6x."""
    from fmscal.analysis._comparison import compare
    table = compare(["noisy", "random-S"], 3, ["ekf"], duration=60, progress=False)
    for scenario, g in table[table["observer"] == "ekf"].groupby("scenario"):
        ratio = g["E_over_floor"].to_numpy()
        assert np.median(ratio) < 1.3, (scenario, ratio)
        assert np.all((ratio > 0.7) & (ratio < 1.6)), (scenario, ratio)


@pytest.mark.slow
def test_the_one_ekf_holds_the_planar_filters_accuracy_against_the_floor():
    """Issue 'One library for both cases', item 2: the error-state EKF on the planar model (Q at the running
    estimate, the separate-bias compensation) against the floor, the median over seeds 0-2 of E / floor_E on each
    planar scenario with a floor, within 1.02x either way of the planar filter it replaced
    (``benchmarks/ekf_planar_floor.py``, :data:`RECORDED`)."""
    import importlib.util
    from pathlib import Path
    path = Path(__file__).parent.parent / "benchmarks" / "ekf_planar_floor.py"
    spec = importlib.util.spec_from_file_location("ekf_planar_floor", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    now = bench.medians()
    assert set(bench.RECORDED) <= set(now)
    for name, before in bench.RECORDED.items():
        assert before / 1.02 < now[name] < 1.02 * before, (name, now[name], before)


@pytest.mark.slow
def test_eiv_false_reports_the_filters_own_estimate_on_both_paths():
    """``eiv=False`` on the planar model: the compiled step carries the separate-bias filter unused, both paths
    report the filter's own estimate and agree; the compensation moves the estimate, by a few per cent this early
    in a run of ``noisy`` (5 % of the largest entry after 2 s), not by nothing and not wholesale."""
    sc = plant.get_scenario("noisy").with_(duration=2.0)
    log, truth, _ = sc.generate(0)
    plain = AugmentedEKF(sc.payload, noise=truth.noise, eiv=False)
    assert plain.eiv is None
    fast, slow = plain.run(log, truth.S0), plain.run(log, truth.S0, compiled=False)
    _close(fast.S_hat_history, slow.S_hat_history)
    compensated = AugmentedEKF(sc.payload, noise=truth.noise).run(log, truth.S0)
    gap = np.max(np.abs(compensated.S_hat - fast.S_hat)) / np.max(np.abs(fast.S_hat))
    assert 1e-3 < gap < 0.2, gap
