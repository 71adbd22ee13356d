"""The high-gain adaptive observer of [4] (a reconstruction): poles, convergence, both paths."""

import control
import numpy as np
import pytest

from fmscal import plant
from fmscal.analysis import calibration_error
from fmscal.observers import HighGainObserver, check_gains, double_pole_gains
from fmscal.observers.diagnostics import has_evidence
from fmscal.observers.core._gains import sampled_poles
from fmscal.observers.adaptive._highgain import discrete_gain


@pytest.mark.parametrize("lam", [5.0, 20.0, 80.0])
def test_poles_sit_at_minus_lam_and_scale_with_it(lam):
    obs = HighGainObserver(plant.PAPER_PAYLOAD, lam=lam)
    report = check_gains(obs.K1, obs.K2)          # python-control: poles of A - K C, obsv
    for sub in ("angular", "translational"):
        np.testing.assert_allclose(getattr(report, sub).poles.real, -lam, rtol=1e-6)
        assert getattr(report, sub).observable and getattr(report, sub).stable
    # the sampled error recursion (I - L C) Phi has the sampled images of those poles
    dt = 1e-3
    l1, l2 = discrete_gain(np, lam, dt)
    error_matrix = (np.eye(2) - np.array([[l1], [l2]]) @ plant.C_1) @ np.array([[1.0, dt], [0.0, 1.0]])
    eig = np.sort_complex(np.linalg.eigvals(error_matrix))
    np.testing.assert_allclose(eig, sampled_poles(obs.K1, dt), atol=1e-5)
    np.testing.assert_allclose(np.abs(eig), np.exp(-lam * dt), rtol=1e-4)


def test_doubling_lam_doubles_the_bandwidth_of_the_error_dynamics():
    bandwidth = []
    for lam in (10.0, 20.0):
        K1, _ = double_pole_gains(lam)
        closed = control.ss(plant.A_1 - K1 @ plant.C_1, K1, plant.C_1, 0)
        bandwidth.append(control.bandwidth(closed))
    assert bandwidth[1] / bandwidth[0] == pytest.approx(2.0, rel=1e-6)


def test_converges_on_noise_free_data():
    log, truth, _ = plant.get_scenario("paper").with_(duration=30).generate(0, noise_free=True)
    result = HighGainObserver(plant.PAPER_PAYLOAD).run(log, truth.S0)
    assert not result.diverged and result.converged                 # settled (the run's own judgement)
    assert has_evidence(result, log, plant.PAPER_PAYLOAD)           # and the log pinned S down (the workflow's)
    assert calibration_error(truth.S0, plant.PAPER_S) > 1.0
    assert calibration_error(result.S_hat, plant.PAPER_S) < 1e-4


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["paper", "vision-50hz"])
def test_compiled_and_readable_paths_agree(scenario):
    log, truth, _ = plant.get_scenario(scenario).with_(duration=2).generate(3)
    obs = HighGainObserver(plant.PAPER_PAYLOAD)
    fast, slow = obs.run(log, truth.S0), obs.run(log, truth.S0, compiled=False)
    np.testing.assert_allclose(fast.S_hat_history, slow.S_hat_history, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(fast.x_hat_history, slow.x_hat_history, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("payload, seed", [
    (plant.Payload(0.5, 0.05, [0.35, -0.35]), 1),     # light, spins at about 40 rad/s
    (plant.Payload(10.0, 0.05, [-0.5, 0.5]), 5),      # heavy, small inertia, cond(S) 12.8
    (plant.Payload(6.0, 0.3, [-0.15, 0.4]), 2),
])
def test_default_converges_on_other_payloads_and_S_under_noise(payload, seed):
    log, truth, _ = plant.get_scenario("random-S").with_(payload=payload, duration=60).generate(seed)
    S = truth.S_at(0.0)
    result = HighGainObserver(payload).run(log, truth.S0)
    assert not result.diverged
    assert calibration_error(result.S_hat, S) < 0.05
    assert calibration_error(result.S_hat, S) < calibration_error(truth.S0, S) / 50


def test_ref4_configuration_is_slower_than_the_default_under_paper_noise():
    """The seed paper's account of [4] (high gain, scalar gain) converges slowly."""
    log, truth, _ = plant.get_scenario("paper").with_(duration=50).generate(0)
    E = {obs.name: calibration_error(obs.run(log, truth.S0).S_hat, plant.PAPER_S)
         for obs in (HighGainObserver(plant.PAPER_PAYLOAD), HighGainObserver.ref4(plant.PAPER_PAYLOAD))}
    assert E["high-gain-ref4"] > 2 * E["high-gain"]


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="lam must be positive"):
        HighGainObserver(plant.PAPER_PAYLOAD, lam=-1)
    with pytest.raises(ValueError, match="normalisation must be"):
        HighGainObserver(plant.PAPER_PAYLOAD, normalisation="vector")
