"""The model object: one place for the problem's sizes, layouts, measurement and dynamics (issue 27)."""

import casadi as ca
import numpy as np
import pytest

from fmscal.plant import PAPER_PAYLOAD, FmscalError
from fmscal.plant.physics._model import PlanarModel, SpatialModel, model_for_columns
from fmscal.plant.physics._rigid_body import PayloadSymbols, SpatialPayload

from rail import RailModel, RailPayload

TOOL = SpatialPayload(1.7, [0.012, 0.015, 0.009, 0.001, -0.0005, 0.0008], [0.02, -0.03, 0.08])


MODELS = [PlanarModel(PAPER_PAYLOAD), SpatialModel(TOOL), RailModel(RailPayload(2.0))]


def _state(model, rng):
    x = rng.normal(size=model.nx)
    if model.name == "spatial":
        x[3:7] /= np.linalg.norm(x[3:7])
    return x


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
def test_sizes_and_layouts_agree(model):
    assert model.state.size == model.nx == len(model.q_index) + len(model.v_index)
    assert model.columns == ("t", *model.pose_names, *model.wrench_names)
    assert model.params(offset=True).size == model.n_params(offset=True) == model.n_w * (model.n_w + 1)
    assert model.n_params() == model.n_w ** 2


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
def test_the_regressor_is_the_dynamics_written_for_S(model):
    """``A(x) (S w_hat + c) + d(x) = U s + d(x)``, and casadi gives the same numbers."""
    rng = np.random.default_rng(0)
    x, S, c, w_hat = _state(model, rng), rng.normal(size=(model.n_w, model.n_w)), rng.normal(size=model.n_w), \
        rng.normal(size=model.n_w)
    a = model.acceleration(x, S @ w_hat + c)
    U = model.regressor(x, np.r_[w_hat, 1.0])
    np.testing.assert_allclose(U @ np.c_[S, c].ravel() + model.drift(x), a, rtol=1e-12, atol=1e-12)
    xs, ws = ca.SX.sym("x", model.nx), ca.SX.sym("w", model.n_w + 1)
    f = ca.Function("f", [xs, ws], [model.regressor(xs, ws), model.drift(xs), model.measure(xs)])
    U_ca, d_ca, y_ca = f(x, np.r_[w_hat, 1.0])
    np.testing.assert_allclose(np.array(U_ca), U, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.array(d_ca).ravel(), model.drift(x), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.array(y_ca).ravel(), model.measure(x), rtol=0, atol=0)


@pytest.mark.parametrize("model", [MODELS[0], MODELS[2]], ids=lambda m: m.name)
def test_the_channel_regressors_are_the_dynamics_in_each_groups_parameters(model):
    """``a_c = psi_c . phi_g`` per channel, ``phi`` from ``[S | c]`` and back, for numbers and casadi symbols, one
    sample at a time or a whole log (the hooks least squares and the adaptive default read)."""
    rng = np.random.default_rng(1)
    q, S, c, w_hat = rng.normal(size=model.nq), rng.normal(size=(model.n_w, model.n_w)), rng.normal(size=model.n_w), \
        rng.normal(size=model.n_w)
    w_aug, s = np.r_[w_hat, 1.0], np.c_[S, c].ravel()
    n = model.n_w + 1
    a = model.acceleration(model.state_from(q, np.zeros(model.nv)), S @ w_hat + c)
    rows, phis = model.channel_regressor_rows(q, w_aug), model.phi_from_params(s, n)
    group_of = {ch: g for g, channels in enumerate(model.parameter_groups()) for ch in channels}
    np.testing.assert_allclose([np.dot(rows[ch], phis[group_of[ch]]) for ch in range(model.nv)], a, rtol=1e-12,
                               atol=1e-12)
    np.testing.assert_allclose(np.ravel(model.params_from_phi(phis, n)), s, rtol=1e-12, atol=1e-12)
    qs, ws, ss = ca.SX.sym("q", model.nq), ca.SX.sym("w", n), ca.SX.sym("s", model.n_w * n)
    f = ca.Function("f", [qs, ws, ss], [ca.vertcat(*[v for r in model.channel_regressor_rows(qs, ws) for v in r]),
                                        model.params_from_phi(model.phi_from_params(ss, n), n)])
    rows_ca, s_ca = f(q, w_aug, s)
    np.testing.assert_allclose(np.array(rows_ca).ravel(), np.concatenate(rows), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.array(s_ca).ravel(), s, rtol=1e-12, atol=1e-12)
    Q, W = rng.normal(size=(model.nq, 5)), np.vstack([rng.normal(size=(model.n_w, 5)), np.ones(5)])
    whole = model.channel_regressors(Q, W)
    for k in range(5):
        for ch, row in enumerate(model.channel_regressor_rows(Q[:, k], W[:, k])):
            np.testing.assert_allclose(whole[ch][k], row, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
def test_the_acceleration_is_the_state_derivative(model):
    rng = np.random.default_rng(1)
    x, w = _state(model, rng), rng.normal(size=model.n_w)
    np.testing.assert_allclose(np.asarray(model.state_derivative(x, w))[list(model.v_index)],
                               model.acceleration(x, w), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("model", MODELS[:2], ids=lambda m: m.name)
def test_integrate_and_difference_are_inverse_and_rest_shows_its_pose(model):
    rng = np.random.default_rng(2)
    for _ in range(20):
        q0 = model.configuration(_state(model, rng))
        dq = rng.normal(size=model.nv) * 0.8
        np.testing.assert_allclose(model.difference(q0, model.integrate(q0, dq)), dq, rtol=0, atol=1e-12)
        pose = model.measure(np.r_[q0, np.zeros(model.nv)] if model.name == "spatial" else
                             np.r_[q0[0], 0, q0[1], 0, q0[2], 0])
        x = model.rest_state(pose)
        np.testing.assert_allclose(model.measure(x), pose, atol=1e-15)
        np.testing.assert_array_equal(model.velocity(x), np.zeros(model.nv))


def test_a_quaternion_and_its_negative_are_one_attitude():
    model = SpatialModel(TOOL)
    q0 = np.r_[0.1, 0.2, 0.3, 0.5, 0.5, 0.5, 0.5]
    q1 = model.integrate(q0, np.r_[0, 0, 0, 0.3, -0.2, 0.1])
    flipped = np.r_[q1[:3], -q1[3:]]
    np.testing.assert_allclose(model.difference(q0, flipped), model.difference(q0, q1), atol=1e-14)


def test_the_header_picks_the_case():
    assert model_for_columns(["t", "theta", "x", "y", "M", "fx", "fy"]) == "planar"
    assert model_for_columns(["t", *SpatialModel.pose_names, *SpatialModel.wrench_names]) == "spatial"
    with pytest.raises(FmscalError, match="planar.*spatial"):
        model_for_columns(["t", "a", "b"])


def test_a_model_refuses_the_other_case_payload():
    with pytest.raises(FmscalError, match="SpatialPayload"):
        SpatialModel(PAPER_PAYLOAD)
    with pytest.raises(FmscalError, match="Payload"):
        PlanarModel(TOOL)
    with pytest.raises(FmscalError, match="gravity"):
        SpatialModel(TOOL, gravity=[0, 0])


def test_the_payload_read_at_run_time_gives_the_numbers_dynamics():
    """The spatial model with its payload and gravity read from a vector (what the floor's and the EKF's
    compiled steps take as an input) gives the acceleration, ``A`` and ``d`` of the model built on the numbers,
    to the last bit or so, for two payloads and a tilted gravity through one casadi function; a payload or
    a gravity read from the wrong entries would be off by their own size."""
    model = SpatialModel(TOOL)
    values = ca.SX.sym("payload", model.payload_size)
    x, w = ca.SX.sym("x", model.nx), ca.SX.sym("w", model.n_w)
    symbolic = model.with_payload_symbols(values)
    f = ca.Function("f", [x, w, values], [symbolic.acceleration(x, w), symbolic.input_matrix(x), symbolic.drift(x)])
    rng = np.random.default_rng(5)
    other = SpatialPayload(0.6, [2e-3, 3e-3, 4e-3, 0.0, 2e-4, 0.0], [0.0, 0.04, -0.02])
    for numbers in (model, SpatialModel(other, gravity=(0.8, -0.3, -9.7))):
        for _ in range(5):
            xk, wk = _state(numbers, rng), rng.normal(size=6)
            acc, A, d = (np.asarray(v) for v in f(xk, wk, numbers.payload_vector()))
            np.testing.assert_allclose(acc.ravel(), numbers.acceleration(xk, wk), rtol=1e-13, atol=1e-13)
            np.testing.assert_allclose(A, numbers.input_matrix(xk), rtol=1e-13, atol=1e-13)
            np.testing.assert_allclose(d.ravel(), numbers.drift(xk), rtol=1e-13, atol=1e-13)
    assert PlanarModel(PAPER_PAYLOAD).payload_size == 0 and PlanarModel(PAPER_PAYLOAD).payload_vector().size == 0
    with pytest.raises(ValueError, match="takes a casadi.SX of 22 entries; got a casadi.SX of 3 entries"):
        PayloadSymbols(ca.SX.sym("short", 3))


@pytest.mark.slow
def test_the_spatial_floor_and_ekf_are_built_once_for_every_payload_and_gravity(monkeypatch):
    """The compiled steps of the spatial floor and EKF take the payload and the gravity as inputs: another
    payload or gravity finds the same step, and the step built afresh for it is the same function (no number
    of the payload in it), where each payload once built its own (10-17 s on a fresh machine). The steps are
    kept as casadi functions here, not compiled."""
    from fmscal.observers.kalman import _error_state as ekf_error_state
    from fmscal.observers.batch import _linearised_floor as linearised_floor
    for module in (ekf_error_state, linearised_floor):
        monkeypatch.setattr(module, "ChunkedSteps", lambda step, chunk, **kwargs: step)
    monkeypatch.setattr(linearised_floor, "_CHUNKED", {})
    monkeypatch.setattr(ekf_error_state, "_WHOLE", {})
    a = SpatialModel(TOOL)
    b = SpatialModel(SpatialPayload(0.6, [2e-3, 3e-3, 4e-3, 0.0, 2e-4, 0.0], [0.0, 0.04, -0.02]),
                     gravity=(0.8, 0, -9.7))
    floor, ekf = linearised_floor._chunked(a, 7, True, True), ekf_error_state.whole_error_step(a, 7)
    assert linearised_floor._chunked(b, 7, True, True) is floor and ekf_error_state.whole_error_step(b, 7) is ekf
    linearised_floor._CHUNKED.clear()
    ekf_error_state._WHOLE.clear()
    assert linearised_floor._chunked(b, 7, True, True).serialize() == floor.serialize()
    assert ekf_error_state.whole_error_step(b, 7).serialize() == ekf.serialize()
    assert floor.nnz_in(2) == linearised_floor._params_layout(a, 7).size and not np.array_equal(
        a.payload_vector(), b.payload_vector())
