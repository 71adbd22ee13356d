"""Newton-Euler at the sensor point (the spatial case), against two independent engines.

pinocchio's RNEA on a free-floating body checks the inverse dynamics; MuJoCo,
driven through six motors on a site at the sensor point (so that the wrench
is held in sensor axes over each step, as in our simulator), checks the
forward dynamics and the integration over 20 s of the spatial-arm
scenario's motion, which turns the payload through large angles.
"""

import casadi as ca
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fmscal.plant import FmscalError
from fmscal.plant.physics._rigid_body import (GRAVITY, SpatialPayload, body_acceleration, quaternion_multiply, rk4_step,
                                     rotation_matrix, sensor_wrench)
from fmscal.plant.scenarios._spatial import SPATIAL_SCENARIOS

pin = pytest.importorskip("pinocchio")          # the [test] extra installs it; on CI a skip fails
mujoco = pytest.importorskip("mujoco")

#: A tool on a wrist sensor: 1.7 kg, centre of mass 8 cm out, a full inertia tensor.
TOOL = SpatialPayload(1.7, [0.012, 0.015, 0.009, 0.001, -0.0005, 0.0008], [0.02, -0.03, 0.08])


def _random_states(n, seed):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q, rng.normal(size=(n, 3)), rng.normal(size=(n, 3)) * 2, rng.normal(size=(n, 3)) * 5, \
        rng.normal(size=(n, 3)) * 3


def test_inverse_dynamics_matches_pinocchio_rnea():
    model = pin.Model()
    joint = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "payload")
    model.appendBodyToJoint(joint, pin.Inertia(TOOL.mass, np.array(TOOL.com), TOOL.I_c), pin.SE3.Identity())
    model.gravity.linear = np.array(GRAVITY)
    data = model.createData()
    worst = 0.0
    for q, p_dot, omega, alpha, p_ddot in zip(*_random_states(200, seed=0)):
        R = rotation_matrix(q)
        v_local = R.T @ p_dot                    # pinocchio's free-flyer velocity is in the local frame
        v = np.r_[v_local, omega]
        a = np.r_[R.T @ p_ddot - np.cross(omega, v_local), alpha]     # d/dt of the local velocity
        q_pin = np.r_[0.1, -0.2, 0.3, q[1:], q[0]]                    # pinocchio: (x, y, z, w)
        tau = pin.rnea(model, data, q_pin, v, a)                      # [f, tau_O], local frame
        w = sensor_wrench(q, omega, alpha, p_ddot, TOOL)
        worst = max(worst, np.abs(np.r_[tau[3:], tau[:3]] - w).max() / max(1.0, np.abs(w).max()))
    assert worst < 1e-9


def test_forward_dynamics_inverts_the_inverse_dynamics():
    for q, _, omega, alpha, p_ddot in zip(*_random_states(50, seed=1)):
        a, pdd = body_acceleration(q, omega, sensor_wrench(q, omega, alpha, p_ddot, TOOL), TOOL)
        np.testing.assert_allclose(a, alpha, rtol=0, atol=1e-10)
        np.testing.assert_allclose(pdd, p_ddot, rtol=0, atol=1e-10)


def test_rotation_and_product_agree_with_scipy():
    q, *_ = _random_states(20, seed=2)
    for a, b in zip(q[:-1], q[1:]):
        ra, rb = Rotation.from_quat(np.roll(a, -1)), Rotation.from_quat(np.roll(b, -1))      # scipy: scalar last
        np.testing.assert_allclose(rotation_matrix(a), ra.as_matrix(), atol=1e-14)
        np.testing.assert_allclose(rotation_matrix(quaternion_multiply(a, b)), (ra * rb).as_matrix(), atol=1e-14)


def test_numpy_and_casadi_give_the_same_step():
    x, w = ca.SX.sym("x", 13), ca.SX.sym("w", 6)
    step = ca.Function("step", [x, w], [rk4_step(x, w, 1e-3, TOOL)])
    q, p_dot, omega, *_ = _random_states(5, seed=3)
    rng = np.random.default_rng(3)
    for k in range(5):
        x0, w0 = np.r_[rng.normal(size=3), q[k], p_dot[k], omega[k]], rng.normal(size=6)
        np.testing.assert_allclose(np.array(step(x0, w0)).ravel(), rk4_step(x0, w0, 1e-3, TOOL), rtol=1e-13, atol=1e-15)


def test_simulator_matches_mujoco_over_20_s_of_spatial_arm():
    """20 s of the spatial-arm scenario's motion (tens of degrees about every axis), its true wrench as logged."""
    dt, n = 1e-3, 20_000
    motion = SPATIAL_SCENARIOS["spatial-arm"].with_(payload=TOOL).motion_function(np.random.default_rng(0))
    x0 = np.array(motion(0.0)[0]).ravel()
    wrench = np.array(motion.map(n)(np.arange(n) * dt)[1]).T            # the logged wrench, one row a sample
    xs, ws = ca.SX.sym("x", 13), ca.SX.sym("w", 6)
    ours = ca.Function("step", [xs, ws], [rk4_step(xs, ws, dt, TOOL)]).mapaccum(n)
    x = np.array(ours(x0, wrench.T)).T                                   # x[k] after k + 1 steps

    from mujoco_log import mujoco_model            # tests/mujoco_log.py: the one MuJoCo model of a payload
    model = mujoco_model(TOOL, GRAVITY, dt)
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = x0[:7], np.r_[x0[7:10], x0[10:13]]      # free joint: v in W, omega in B
    qpos = np.empty((n, 7))
    for k in range(n):
        data.ctrl[:] = np.r_[wrench[k, 3:], wrench[k, :3]]              # motors: force first
        mujoco.mj_step(model, data)
        qpos[k] = data.qpos
    assert np.abs(x[:, :3] - qpos[:, :3]).max() < 1e-4                  # m
    attitude_error = 2 * np.arccos(np.clip(np.abs(np.sum(x[:, 3:7] * qpos[:, 3:7], axis=1)), 0, 1))
    assert attitude_error.max() < 1e-4                                   # rad
    angles = Rotation.from_quat(np.roll(x[:, 3:7], -1, axis=1)).magnitude()
    assert angles.max() > 1.0                                            # it did turn through large angles
    assert np.abs(x[:, 10:13]).max() > 1.0                                # rad/s


@pytest.mark.parametrize("inertia, message", [
    ([1.0, 1.0, 1.0, 2.0, 0, 0], "positive definite"),
    ([1.0, 1.0, 3.0, 0, 0, 0], "triangle inequality"),
    ([1.0, 1.0], "6 entries"),
    ([1.0, 1.0, 1.0, 0, 0, np.nan], "finite"),
])
def test_an_impossible_inertia_is_one_error(inertia, message):
    with pytest.raises(FmscalError, match=message):
        SpatialPayload(1.0, inertia, [0, 0, 0.1])


def test_com_needs_three_numbers():
    with pytest.raises(FmscalError, match="com has the wrong shape; expected 3 instead of 2"):
        SpatialPayload(1.0, [1, 1, 1, 0, 0, 0], [0, 0.1])
