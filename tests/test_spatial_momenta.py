"""The spatial model's pieces the adaptive observer's law reads (the momenta about the centre of mass, eq. (M) of
:class:`fmscal.plant.SpatialModel`): against Newton-Euler, their own inverses, and the same numbers from casadi."""

import casadi as ca
import numpy as np
import pytest

from fmscal.plant import SpatialModel
from fmscal.plant.physics import rotation_matrix
from fmscal.plant.scenarios._spatial import SPATIAL_SCENARIOS

ARM = SPATIAL_SCENARIOS["spatial-arm"]
MODEL = SpatialModel(ARM.payload, ARM.gravity)


def _state(rng):
    q = rng.normal(size=4)
    return np.r_[rng.normal(size=3), q / np.linalg.norm(q), rng.normal(size=3), rng.normal(size=3)]


def _momenta(x):
    """``m p_C``, ``m v_C`` and ``H`` of a state ``[p, q, v, omega]``, from the payload's definitions."""
    p, R, v, omega = x[0:3], rotation_matrix(x[3:7]), x[7:10], x[10:13]
    m, com, I_c = ARM.payload.mass, np.asarray(ARM.payload.com), ARM.payload.I_c
    return m * (p + R @ com), m * (v + R @ np.cross(omega, com)), R @ I_c @ omega


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_drives_are_the_momenta_rates_under_newton_euler(seed):
    """``momentum_drives`` of ``phi`` from ``[S | c]``, at a reading ``w_hat``, are the central differences
    of ``m v_C`` and ``H`` along Newton-Euler driven by ``S w_hat + c`` (step 1e-4 s: error ~1e-8)."""
    rng = np.random.default_rng(seed)
    x = _state(rng)
    S_aug = np.c_[np.eye(6) + 0.1 * rng.normal(size=(6, 6)), rng.normal(size=6)]
    w_hat = rng.normal(size=6) * np.r_[np.full(3, 0.5), np.full(3, 5.0)]
    w_aug = np.r_[w_hat, 1.0]
    w = S_aug @ w_aug
    h = 1e-4
    ahead, back = (MODEL.rk4_step(x, w, w, w, s * h) for s in (1.0, -1.0))
    rates = [(a - b) / (2 * h) for a, b in zip(_momenta(ahead)[1:], _momenta(back)[1:])]
    phis = MODEL.momentum_phi_from_params(S_aug.ravel(), 7, ARM.payload.com)
    torque, force = MODEL.momentum_drives(rotation_matrix(x[3:7]), w_aug, phis)
    np.testing.assert_allclose(force, rates[0], rtol=0, atol=1e-6 * (1 + np.abs(rates[0]).max()))
    np.testing.assert_allclose(torque, rates[1], rtol=0, atol=1e-6 * (1 + np.abs(rates[1]).max()))
    assert np.abs(torque).max() > 1e-3 and np.abs(force - ARM.payload.mass * np.asarray(ARM.gravity)).max() > 1e-3
    # the regressor is the drive's: Psi phi = R (Phi w), the same matrix for both groups
    Psi = MODEL.momentum_regressor(rotation_matrix(x[3:7]), w_aug)
    assert Psi.shape == (3, 21)
    np.testing.assert_allclose(Psi @ phis[0], torque, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_state_is_read_back_from_its_momenta_and_the_inertias_invert(seed):
    rng = np.random.default_rng(seed)
    x = _state(rng)
    y, lin, H = _momenta(x)
    np.testing.assert_allclose(MODEL.state_from_momenta(y, lin, x[3:7], H), x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(MODEL.centre_of_mass_momentum(np.r_[x[3:7], x[0:3]]), y, rtol=0, atol=1e-12)
    R = rotation_matrix(x[3:7])
    np.testing.assert_allclose(MODEL.world_inverse_inertia(R) @ MODEL.world_inertia(R), np.eye(3), rtol=0,
                               atol=1e-9)
    np.testing.assert_allclose(MODEL.world_rate(R, H), R @ x[10:13], rtol=0, atol=1e-12)


def test_a_turn_is_the_models_integrate_and_its_first_order_and_third_order_forms():
    rng = np.random.default_rng(4)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    R, v = rotation_matrix(q), 1e-3 * rng.normal(size=3)
    turned = MODEL.turn(q, R, v)
    angle = np.linalg.norm(v)
    exp_v = np.r_[np.cos(angle / 2), np.sin(angle / 2) * v / angle]
    np.testing.assert_allclose(rotation_matrix(turned), rotation_matrix(exp_v) @ R, rtol=0, atol=1e-14)
    # first order: the error is of second order in the turn (|v|^2 / 2 = 5e-7 here), not of first
    error = np.abs(MODEL.turned_rotation(R, v, 1.0) - rotation_matrix(turned)).max()
    assert 1e-8 < error < 2e-6, error
    # a constant rate over the step: the third-order rotation vector is the rate times the step
    np.testing.assert_allclose(MODEL.turn_over_step(v, v, 0.5), 0.5 * v, rtol=1e-15, atol=0)


def test_casadi_gives_the_numbers_numpy_does():
    rng = np.random.default_rng(5)
    x = _state(rng)
    s, w_aug = rng.normal(size=42), np.r_[rng.normal(size=6), 1.0]
    R, H, y, lin = rotation_matrix(x[3:7]), rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
    sym = {name: ca.SX.sym(name, n) for name, n in (("s", 42), ("w", 7), ("q", 4), ("H", 3), ("y", 3), ("l", 3))}
    R_sym = rotation_matrix(sym["q"])

    def pieces(model, s, w, q, R, H, y, lin):
        phis = model.momentum_phi_from_params(s, 7, ARM.payload.com)
        return [*phis, model.momentum_params_from_phi(phis, 7, ARM.payload.com), model.momentum_regressor(R, w),
                *model.momentum_drives(R, w, phis), model.world_inverse_inertia(R), model.world_inertia(R),
                model.world_rate(R, H), model.turn(q, R, 1e-2 * H), model.turned_rotation(R, H, 1e-2),
                model.turn_over_step(H, y, 1e-2), model.state_from_momenta(y, lin, q, H)]

    numbers = pieces(MODEL, s, w_aug, x[3:7], R, H, y, lin)
    symbols = pieces(MODEL, sym["s"], sym["w"], sym["q"], R_sym, sym["H"], sym["y"], sym["l"])
    f = ca.Function("f", [sym[k] for k in ("s", "w", "q", "H", "y", "l")], [ca.densify(ca.SX(v)) for v in symbols])
    values = f(s, w_aug, x[3:7], H, y, lin)
    assert len(values) == len(numbers) == 13
    for got, want in zip(values, numbers):
        got, want = np.asarray(got, dtype=float), np.asarray(want, dtype=float)
        np.testing.assert_allclose(got.reshape(want.shape), want, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(numbers[2], s, rtol=0, atol=1e-14)
