"""A second, minimal model through the same code: a payload on a rail (issue 27).

One position ``x``, one force ``f``, a 1x1 ``S`` and an offset: least squares,
the maximum-likelihood floor, the EKF and the adaptive default take every size
from the model, so they run on it unchanged; the first three recover its ``S``
within their reported uncertainty, the adaptive default (which reports none)
as closely as the floor does. A call without a model, or a log of another
case, is one ``FmscalError``; so is a planar-only observer on the rail.
"""

import numpy as np
import pytest

from fmscal import plant
from fmscal.observers import (AdaptiveObserver, AugmentedEKF, HighGainObserver, LeastSquares, MaximumLikelihood,
                              PaperAdaptiveObserver, get_method)
from fmscal.plant.numerics._errors import FmscalError
from fmscal.observers.diagnostics import has_evidence

from rail import RailModel, RailPayload

S_TRUE, B_TRUE = 1.3, 0.4          # w = S (w_hat - b): N per unit of the reading, reading units
MASS = 2.0                         # kg
DT, DURATION = 1e-3, 20.0
POSE_SD, WRENCH_SD = 1e-4, 0.02    # m, reading units


MODEL = RailModel(RailPayload(MASS))


def _rail_log(seed, at_rest=False):
    """20 s at 1 kHz of a multisine force, the motion exact (the force's double integral), the pose and the
    reading noisy, the reading offset and scaled: ``w_hat = w / S + b``. ``at_rest``: the payload starts at
    rest (``x'(0) = 0``), as every simulated planar log does; else it starts moving."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, DURATION, DT)
    amp, freq, phase = rng.uniform(0.5, 1.5, 4), np.array([0.3, 0.7, 1.3, 2.1]), rng.uniform(0, 2 * np.pi, 4)
    w = (amp * np.sin(2 * np.pi * freq * t[:, None] + phase)).sum(axis=1)
    # x(t) = sum of -a / (m (2 pi f)^2) sin(...): it starts moving (least squares, the floor and the EKF take any
    # start); at rest, plus the line t sum a cos(phase) / (m 2 pi f) that cancels x'(0)
    x = (-amp / (MASS * (2 * np.pi * freq) ** 2) * np.sin(2 * np.pi * freq * t[:, None] + phase)).sum(axis=1)
    if at_rest:
        x = x + t * (amp * np.cos(phase) / (MASS * 2 * np.pi * freq)).sum()
    pose = (x + rng.normal(scale=POSE_SD, size=len(t)))[:, None]
    w_hat = (w / S_TRUE + B_TRUE + rng.normal(scale=WRENCH_SD, size=len(t)))[:, None]
    return plant.Log(t, pose, w_hat, name="rail", model=MODEL)


@pytest.fixture(scope="module")
def rail_log():
    return _rail_log(7)


@pytest.fixture(scope="module")
def rail_log_at_rest():
    return _rail_log(7, at_rest=True)


@pytest.fixture(scope="module")
def results(rail_log):
    return {name: cls(MODEL, offset=True).run(rail_log) for name, cls in
            (("least-squares", LeastSquares), ("max-likelihood", MaximumLikelihood), ("ekf", AugmentedEKF))}


def test_the_model_gives_the_sizes():
    assert (MODEL.n_w, MODEL.nq, MODEL.nv, MODEL.nx, MODEL.n_pose) == (1, 1, 1, 2, 1)
    assert MODEL.columns == ("t", "x", "f") and MODEL.input_layout.size == 3
    np.testing.assert_allclose(MODEL.regressor(np.zeros(2), np.array([2.0, 1.0])), [[1.0, 0.5]])


@pytest.mark.parametrize("name", ["least-squares", "max-likelihood", "ekf"])
def test_each_method_recovers_S_and_b_within_its_uncertainty(results, name):
    """Each estimate is within 4 of its own sigma of the truth, and the sigma is informative (a method that
    reported nothing, or returned its start, fails)."""
    r = results[name]
    assert r.S_hat.shape == (1, 1) and r.S_std.shape == (1, 1) and r.b.shape == (1,)
    assert r.x_hat_history.shape[1] == 2 and not r.diverged
    assert 0 < r.S_std[0, 0] < 2e-3 and 0 < r.b_std[0] < 2e-3
    assert abs(r.S_hat[0, 0] - S_TRUE) < 4 * r.S_std[0, 0]
    assert abs(r.b[0] - B_TRUE) < 4 * r.b_std[0]
    assert abs(r.S_hat[0, 0] - 1.0) > 0.1                     # it left the identity it starts from


def test_the_floor_is_at_least_as_tight_as_least_squares(results):
    assert results["max-likelihood"].S_std[0, 0] <= 1.05 * results["least-squares"].S_std[0, 0]


def test_a_call_without_a_model_is_one_error():
    for cls in (LeastSquares, MaximumLikelihood, AugmentedEKF):
        with pytest.raises(FmscalError, match="needs a model"):
            cls(None)
        with pytest.raises(FmscalError, match="got dict"):
            cls({"mass": 2.0})


def test_a_log_of_another_case_is_one_error(rail_log):
    planar_log, _, _ = plant.get_scenario("paper").with_(duration=2.0).generate(0)
    with pytest.raises(FmscalError, match="set up for rail logs .* got a planar log"):
        LeastSquares(MODEL).run(planar_log)
    with pytest.raises(FmscalError, match="set up for planar logs .* got a rail log"):
        MaximumLikelihood(plant.PAPER_PAYLOAD).run(rail_log)
    with pytest.raises(FmscalError, match="set up for planar logs .* got a rail log"):
        AugmentedEKF(plant.PAPER_PAYLOAD).run(rail_log)


def test_the_adaptive_default_recovers_S_and_b_as_closely_as_the_floor(rail_log_at_rest):
    """The adaptive default (as the registry builds it) on the rail, against the maximum-likelihood floor on the
    same log.

    It reports no uncertainty, so its error is held to the floor's own: within 1.3x of the floor's
    ``|S_hat - S|`` (issue 15's margin) plus one of the floor's sigma, since on one log and one entry the floor's
    error is one Gaussian draw of that sigma and may fall near zero by chance. An estimate still carrying its
    start, or a bias of a few sigma, fails; over seeds 1-8 the margin holds with room.

    The log starts at rest, as the observer does (:meth:`fmscal.plant.Model.rest_state`): from a moving start
    the first second's velocity error is fitted as data and biases ``S_hat`` for a while (it fades as 1/t).
    """
    adaptive = get_method("adaptive").build(MODEL, None, {"offset": True}).run(rail_log_at_rest, S0=np.eye(1))
    floor = MaximumLikelihood(MODEL, offset=True).run(rail_log_at_rest)
    assert adaptive.S_hat.shape == (1, 1) and adaptive.b.shape == (1,) and adaptive.S_std is None
    assert adaptive.x_hat_history.shape == (len(rail_log_at_rest), 2) and not adaptive.diverged and adaptive.converged
    assert has_evidence(adaptive, rail_log_at_rest, MODEL, offset=True)     # the workflow's half of converged
    assert abs(adaptive.S_hat[0, 0] - S_TRUE) <= 1.3 * abs(floor.S_hat[0, 0] - S_TRUE) + floor.S_std[0, 0]
    assert abs(adaptive.b[0] - B_TRUE) <= 1.3 * abs(floor.b[0] - B_TRUE) + floor.b_std[0]
    assert abs(adaptive.S_hat[0, 0] - 1.0) > 0.1                # it left the identity it starts from


def test_the_adaptive_default_step_by_step_is_its_run(rail_log_at_rest):
    log = rail_log_at_rest.head(2000)
    obs = AdaptiveObserver(MODEL, offset=True)
    slow, fast = obs.run(log, compiled=False), obs.run(log, compiled=True)
    assert np.max(np.abs(slow.S_hat_history - fast.S_hat_history)) < 1e-9
    assert np.max(np.abs(slow.x_hat_history - fast.x_hat_history)) < 1e-9
    obs.reset()
    for k in range(len(log)):
        x_hat, S_hat = obs.step(log.dt, log.pose[k] if log.has_pose[k] else None, log.w_hat[k])
    assert np.allclose(S_hat, slow.S_hat, rtol=0, atol=1e-12)
    assert np.allclose(x_hat, slow.x_hat_history[-1], rtol=0, atol=1e-12)
    # without the offset the calibration is one number; it runs as well
    assert AdaptiveObserver(MODEL).run(log).S_hat.shape == (1, 1)


def test_the_planar_only_observers_refuse_another_model():
    for cls in (HighGainObserver, PaperAdaptiveObserver):
        with pytest.raises(FmscalError, match="defined for planar models; got a rail model"):
            cls(MODEL)


def test_the_adaptive_default_refuses_a_model_not_linear_in_its_channels():
    """Linear in its channels, or the spatial model (its own law, tests/test_spatial_adaptive.py); nothing else."""

    class BentRail(RailModel):
        name = "bent-rail"
        linear_channels = False

    with pytest.raises(FmscalError, match="needs a model linear in its channels or the spatial model; it does not "
                                          "run on a bent-rail model"):
        AdaptiveObserver(BentRail(RailPayload(MASS)))


def test_a_noise_model_of_another_size_is_one_error():
    with pytest.raises(FmscalError, match="wrench_sd has the wrong shape; expected 1"):
        AugmentedEKF(MODEL, noise=plant.NoiseSpec((0.1, 0.1, 0.1), 0.0, 1e-4))


def test_a_model_that_builds_its_payload_in_has_no_payload_part_in_the_steps_parameters():
    """``payload_size`` 0 (a model of the user's own, here a rail without linear channels): the compiled
    steps' parameters (the spatial floor's, the spatial EKF's) have no payload part, and a step written on the
    model keeps its own numbers and is cached by the whole model."""
    from fmscal.observers.batch import _linearised_floor as linearised_floor
    from fmscal.observers.kalman._error_state import error_params_layout

    class BentRail(RailModel):
        name = "bent-rail"
        linear_channels = False

    model = BentRail(RailPayload(MASS))
    assert model.payload_size == 0 and model.payload_parts() == [] and model.payload_values() == {}
    assert "payload" not in linearised_floor._params_layout(model, 2).names
    assert "payload" not in error_params_layout(model).names
    assert model.compiled_key() == model._key() and model.with_payload_symbols(None) is model
