"""A UR5 carrying the tool, for the motion sources' tests and benchmark: joint angles, the tool frame's motion
and the payload's wrench by an independent Newton-Euler, and an IMU's readings of that motion.

The truth is pinocchio's ``rnea`` on a free-flying body carrying the payload, driven by the UR5 tool frame's
velocity and *spatial* acceleration (rnea's own convention): the wrench the mount applies, computed without
fmscal's dynamics.
"""

import sysconfig
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from fmscal.analysis import JointMotion
from fmscal.plant.physics import inertia_matrix, rotation_matrix
from fmscal.plant.scenarios._spatial import TOOL

#: The IMU of the tests and the benchmark: its axes in the sensor's, and its point from the sensor's, m.
C_IMU = Rotation.from_euler("xyz", [0.3, -0.5, 1.1]).as_matrix()
R_IMU = np.array([0.03, -0.04, 0.05])


def ur5_urdf():
    """The UR5's URDF as example-robot-data (a test dependency) installs it."""
    roots = {Path(sysconfig.get_paths()[k]) for k in ("purelib", "platlib")}
    for root in roots:
        path = root / "cmeel.prefix/share/example-robot-data/robots/ur_description/urdf/ur5_robot.urdf"
        if path.exists():
            return path
    raise AssertionError(f"example-robot-data's UR5 URDF not found under {sorted(map(str, roots))}: "
                         "pip install -e \".[test]\"")


def ur5_run(duration=1.5, dt=1e-3, payload=TOOL, start=0.0):
    """The UR5 moving every joint sinusoidally (rotation and translation together: ``|omega x v|`` up to about
    3 m/s^2) with the tool frame ``tool0`` as the sensor's, ``duration`` s from ``start``. Returns a dict:
    ``motion`` (a JointMotion), ``t``, ``q``, ``dq``, ``ddq`` (N, 6), the frame's ``pose`` (N, 7), ``v``,
    ``omega``, ``acc`` (classical), ``alpha`` (its axes) and ``W`` (N, 6), the mount's wrench on the payload
    ``[tau; f]`` by rnea."""
    import pinocchio as pin
    motion = JointMotion(ur5_urdf(), "tool0")
    t = start + np.arange(0.0, duration, dt)
    q0 = np.array([0.3, -1.2, 1.4, -1.6, -1.5, 0.4])
    amp = np.array([0.8, 0.4, 0.5, 0.9, 0.8, 1.2])
    w = 2 * np.pi * np.array([0.31, 0.23, 0.37, 0.29, 0.41, 0.35])
    phase = w * t[:, None] + np.arange(6)
    q, dq, ddq = q0 + amp * np.sin(phase), amp * w * np.cos(phase), -amp * w ** 2 * np.sin(phase)
    pose, v, omega, acc, alpha = motion.kinematics.motion(q, dq, ddq)
    spatial = frame_motion(q, dq, ddq)[3]
    body = pin.Model()
    joint = body.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "payload")
    inertia = pin.Inertia(payload.mass, np.array(payload.com), np.asarray(inertia_matrix(payload.inertia)))
    body.appendBodyToJoint(joint, inertia, pin.SE3.Identity())
    data = body.createData()
    W = np.empty((len(t), 6))
    for k in range(len(t)):
        tau = pin.rnea(body, data, np.r_[pose[k, 4:], pose[k, 1:4], pose[k, 0]], np.r_[v[k], omega[k]],
                       np.r_[spatial[k], alpha[k]])
        W[k] = np.r_[tau[3:], tau[:3]]                                 # [tau; f], fmscal's order
    return dict(motion=motion, t=t, q=q, dq=dq, ddq=ddq, pose=pose, v=v, omega=omega, acc=acc, alpha=alpha, W=W)


def jittered_rows(run, jitter, seed, slip=0.0):
    """Rows of a 10 kHz ``run`` (:func:`ur5_run` with ``dt`` 1e-4) taken at 1 kHz, each stamp moved off its grid
    uniformly by up to ``jitter`` of a step, and from the run's middle on by ``slip`` of a step too (a clock's phase
    that slipped); the first row at 0. Returns the rows and the generator drawn from (seeded ``seed``)."""
    rng = np.random.default_rng(seed)
    rows = np.arange(0, len(run["t"]) - 10, 10)
    rows = rows + np.round(10 * (slip * (rows >= len(run["t"]) // 2)
                                 + rng.uniform(-jitter, jitter, len(rows)))).astype(int)
    rows[0] = 0
    return rows, rng


def frame_motion(q, dq, ddq, frame="tool0", placement=None, classical=False):
    """Straight from pinocchio, not through fmscal: a frame's attitudes ``R`` (N, 3, 3), its velocity ``v``,
    ``omega`` and acceleration (``getFrameAcceleration``, the spatial one, or with ``classical``
    ``getFrameClassicalAcceleration``) ``a``, ``alpha``, all in its own axes (``LOCAL``); ``placement`` (a
    ``pin.SE3``) adds a frame at that placement on ``frame``'s parent body, relative to ``frame``."""
    import pinocchio as pin
    model = pin.buildModelFromUrdf(str(ur5_urdf()))
    fid = model.getFrameId(frame)
    if placement is not None:
        parent = model.frames[fid]
        fid = model.addFrame(pin.Frame("probe", parent.parentJoint, fid, parent.placement * placement,
                                       pin.FrameType.OP_FRAME))
    data = model.createData()
    accel = pin.getFrameClassicalAcceleration if classical else pin.getFrameAcceleration
    n = len(q)
    R, v, omega, a, alpha = np.empty((n, 3, 3)), *(np.empty((n, 3)) for _ in range(4))
    for k in range(n):
        pin.forwardKinematics(model, data, q[k], dq[k], ddq[k])
        pin.updateFramePlacements(model, data)
        R[k] = data.oMf[fid].rotation
        twist, acc = pin.getFrameVelocity(model, data, fid, pin.LOCAL), accel(model, data, fid, pin.LOCAL)
        v[k], omega[k], a[k], alpha[k] = twist.linear, twist.angular, acc.linear, acc.angular
    return R, v, omega, a, alpha


def imu_readings(run, rng=None, gyro_sd=0.0, accel_sd=0.0, rotation=C_IMU, lever_arm=R_IMU):
    """An IMU's orientation (scalar first), rate and specific force of ``run``'s motion, in its axes, at its point,
    plus white noise; and the sensor's attitude ``R``.

    Independent of fmscal's eq. C6: the IMU is a frame of its own on the tool's body in pinocchio (axes
    ``rotation`` and point ``lever_arm`` in the sensor frame's), its classical acceleration
    (``getFrameClassicalAcceleration``, its axes) less gravity in its axes is the specific force, and its
    ``getFrameVelocity``'s angular part the rate."""
    import pinocchio as pin
    placement = pin.SE3(np.asarray(rotation, float), np.asarray(lever_arm, float))
    R_i, _, omega_i, acc_i, _ = frame_motion(run["q"], run["dq"], run["ddq"], placement=placement, classical=True)
    f_i = acc_i - np.einsum("nji,j->ni", R_i, np.array([0.0, 0.0, -9.81]))                # R_i^T (p_ddot - g)
    R = np.array([rotation_matrix(q) for q in run["pose"][:, :4]], dtype=float)
    quaternion = Rotation.from_matrix(R_i).as_quat(scalar_first=True)
    if rng is not None:
        omega_i = omega_i + rng.normal(0, gyro_sd, omega_i.shape)
        f_i = f_i + rng.normal(0, accel_sd, f_i.shape)
    return quaternion, omega_i, f_i, R
