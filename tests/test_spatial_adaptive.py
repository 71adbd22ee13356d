"""The adaptive observer on a spatial log (issue 23): the planar law's class on the spatial model, against the floor.

Each group of logs is simulated once (module fixtures); E is the median over the last tenth of the run,
the floor's E that of ``make_observer("max-likelihood", ..., {"offset": True})`` on the samples that median
has seen (:func:`fmscal.analysis._metrics.tail_seen`: the first 95 % of the log). Against the floor of the
whole log the ratio also counts what the last 5 % of the log adds, which on 20 s of ``spatial-arm`` is up
to a third of the floor's E (seed 2: 0.131 on 95 %, 0.091 on all; the observer's own E 0.122 and 0.103).
"""

import numpy as np
import pytest

from fmscal.analysis._metrics import calibration_error, error_history, tail_median, tail_seen
from fmscal.observers import AdaptiveObserver, make_observer
from fmscal.observers.adaptive._spatial import SPATIAL_LAM, params_from_phi, phi_from_params
from fmscal.plant import SpatialModel
from fmscal.plant.scenarios._spatial import SPATIAL_SCENARIOS

ARM = SPATIAL_SCENARIOS["spatial-arm"]
MOCAP = SPATIAL_SCENARIOS["spatial-mocap"]
MODEL = SpatialModel(ARM.payload, ARM.gravity)


def _ratio(log, S, model=MODEL, whole=False):
    """The adaptive default's E (median over the run's last tenth) over the floor's E on the samples it has seen;
    ``whole``: also over the floor's E on the whole log."""
    result = AdaptiveObserver(model, offset=True).run(log)
    assert not result.diverged and np.all(np.isfinite(result.S_hat_history))
    E = tail_median(error_history(result.S_hat_history, S))
    floors = [log.head(tail_seen(len(log)))] + ([log] if whole else [])
    ratios = [E / calibration_error(make_observer("max-likelihood", model, settings={"offset": True}).run(part).S_hat,
                                    S) for part in floors]
    return ratios if whole else ratios[0]


@pytest.fixture(scope="module")
def short_log():
    log, truth, _ = ARM.with_(duration=0.5).generate(1)
    return log, truth


@pytest.fixture(scope="module")
def three_arms():
    """E / floor on 3 seeds of a 20 s ``spatial-arm``: ``(3, 2)``, the floor on the samples seen, on the whole log."""
    ratios = []
    for seed in range(3):
        log, truth, _ = ARM.with_(duration=20.0).generate(seed)
        ratios.append(_ratio(log, truth.S_at(log.t[-1]), whole=True))
    return np.array(ratios)


@pytest.fixture(scope="module")
def three_mocaps():
    """E / floor on 3 seeds of a 20 s ``spatial-mocap``, its poses moved back by the known latency (both told)."""
    ratios = []
    for seed in range(3):
        log, truth, _ = MOCAP.with_(duration=20.0).generate(seed)
        log = log.shift_poses(truth.latency)
        ratios.append(_ratio(log, truth.S_at(log.t[-1])))
    return np.array(ratios)


def test_the_adaptive_observer_runs_on_the_spatial_model_with_its_own_poles():
    obs = AdaptiveObserver(MODEL, offset=True)
    assert AdaptiveObserver.refusal(MODEL) is None and obs.lam == SPATIAL_LAM
    assert make_observer("adaptive", MODEL).lam == SPATIAL_LAM
    assert AdaptiveObserver(MODEL, lam=7.0).lam == 7.0


def test_the_parameter_groups_are_the_torque_about_c_and_the_force():
    """``[phi_t, phi_f]`` from ``[S | c]`` and back is the identity; ``phi_t`` is the torque about ``C``."""
    rng = np.random.default_rng(3)
    s = rng.normal(size=42)
    phis = phi_from_params(s, 7, ARM.payload.com)
    np.testing.assert_allclose(params_from_phi(phis, 7, ARM.payload.com), s, rtol=0, atol=1e-14)
    S = s.reshape(6, 7)
    w = rng.normal(size=7)
    tau_C = S[:3] @ w - np.cross(ARM.payload.com, S[3:] @ w)
    np.testing.assert_allclose(np.reshape(phis[0], (3, 7)) @ w, tau_C, rtol=0, atol=1e-12)


@pytest.mark.slow
def test_compiled_and_numpy_steps_agree(short_log):
    log, _ = short_log
    obs = AdaptiveObserver(MODEL, offset=True)
    fast, slow = obs.run(log, compiled=True), obs.run(log, compiled=False)
    assert not fast.diverged and len(fast.t) == len(slow.t) == len(log)
    assert np.abs(slow.S_hat_history[-1] - np.eye(6)).max() > 1e-6          # the law moved S
    np.testing.assert_allclose(fast.S_hat_history, slow.S_hat_history, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(fast.x_hat_history, slow.x_hat_history, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(fast.x_hat_history[:, 3:7], axis=1), 1.0, rtol=0, atol=1e-9)


@pytest.mark.slow
def test_step_after_reset_equals_run_and_takes_missing_poses():
    """On 200 Hz poses with some dropped (``spatial-mocap``): ``None`` where no pose arrived."""
    gappy, _, _ = MOCAP.with_(duration=0.5).generate(1)
    assert not gappy.has_pose.all()
    obs = AdaptiveObserver(MODEL, offset=True)
    result = obs.run(gappy, compiled=False)
    obs.reset()
    S_steps, x_steps = [], []
    for k in range(len(gappy)):
        x, S_hat = obs.step(gappy.dt, gappy.pose[k] if gappy.has_pose[k] else None, gappy.w_hat[k])
        S_steps.append(S_hat)
        x_steps.append(x)
    np.testing.assert_array_equal(np.array(S_steps), result.S_hat_history)
    np.testing.assert_array_equal(np.array(x_steps), result.x_hat_history)


@pytest.mark.slow
def test_a_flipped_quaternion_is_the_same_attitude(short_log):
    log, _ = short_log
    runs = []
    for flip in (False, True):
        obs = AdaptiveObserver(MODEL, offset=True)
        obs.reset()
        for k in range(300):
            pose = log.pose[k] if not (flip and k % 7 == 3) else np.r_[-log.pose[k, :4], log.pose[k, 4:]]
            x, S_hat = obs.step(log.dt, pose, log.w_hat[k])
        runs.append((x, S_hat))
    np.testing.assert_allclose(runs[1][1], runs[0][1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(runs[1][0], runs[0][0], rtol=0, atol=1e-12)


@pytest.mark.slow
@pytest.mark.filterwarnings("error::RuntimeWarning")
@pytest.mark.parametrize("compiled", [True, False])
def test_a_diverging_run_is_an_error_not_an_answer(compiled):
    """The normalised gradient at a rate far beyond the data's drives S_hat out of the divergence bound: the
    run stops there, diverged and not converged, on either path at the same step, and says so in its result,
    not in numpy's overflow warnings."""
    log = ARM.with_(duration=2.0).generate(0)[0]
    result = AdaptiveObserver(MODEL, offset=True, gain="gradient", gamma=GAMMA_DIVERGING).run(log, compiled=compiled)
    assert result.diverged and not result.converged and result.S_std is None
    assert len(result.t) < len(log)
    assert np.all(np.isfinite(result.S_hat_history)) and np.all(np.isfinite(result.x_hat_history))


GAMMA_DIVERGING = 1e6


@pytest.mark.slow
def test_the_adaptive_default_against_the_floor_on_spatial_arm(three_arms):
    """Measured (20 s, seeds 0-2): E / floor of the same samples = 1.01, 0.98, 0.93; against the floor of the whole
    log 1.02, 1.03, 1.35, the third seed's last 5 % adding much (module docstring). The issue's 1.3x on every seed,
    and the whole log's ratio held too."""
    seen, whole = three_arms[:, 0], three_arms[:, 1]
    assert np.all((0.7 < seen) & (seen < 1.3)), seen
    assert 0.85 < np.median(seen) < 1.15, seen
    assert np.all((0.7 < whole) & (whole < 1.45)), whole


@pytest.mark.slow
def test_the_adaptive_default_against_the_floor_on_spatial_mocap(three_mocaps):
    """Measured (20 s, seeds 0-2, 200 Hz poses with 2 % dropped): E / floor of the same samples = 1.42, 0.97,
    1.01 (of the whole log 1.44, 1.03, 1.19; target 2x)."""
    assert np.all((0.7 < three_mocaps) & (three_mocaps < 1.5)), three_mocaps


@pytest.mark.slow
def test_a_log_written_by_mujoco_is_fitted_at_the_floor():
    """Another engine's log (tests/mujoco_log.py, 20 s of ``spatial-arm``, seed 4): E within 1.3x of the floor's
    on the same samples (the issue's bound; measured 1.18, as on fmscal's own log of that seed; 1.27 against the
    floor of the whole log)."""
    pytest.importorskip("mujoco")
    from mujoco_log import mujoco_log
    log, S, _ = mujoco_log(ARM.with_(duration=20.0), seed=4)
    ratio = _ratio(log, S)
    assert 0.7 < ratio < 1.3, ratio
