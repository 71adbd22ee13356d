"""The motion's sources besides a pose stream: joint states with a URDF, and an IMU on the tool.

Compensation (:mod:`fmscal.analysis._compensate`) needs the model's state ``x`` and accelerations ``a``
(the spatial model: ``x = [p, q, v, omega]``, ``v`` in the world and ``omega`` in the sensor's axes,
``a = [p_ddot, alpha]``, ``p_ddot`` in the world and ``alpha`` in the sensor's axes) to invert its dynamics
(C2). Each source gives them from what it measures; the dynamics stay the model's.

**Joint states** (:class:`JointMotion`). pinocchio's forward kinematics of ``q, dq, ddq`` gives the sensor
frame's placement ``(R, p)``, its velocity ``(v_l, omega)`` and its *classical* acceleration
``(a_l, alpha)`` in its own axes (``LOCAL``; :meth:`fmscal.plant.io.RobotKinematics.motion`), so::

    x = [p, q(R), R v_l, omega],    a = [R a_l, alpha]                                            (C5)

The classical acceleration is the derivative of the origin's world velocity; the spatial one
(``getFrameAcceleration``) differs from it by ``omega x v_l``, and taken for ``R^T p_ddot`` it is wrong by
``m omega x v_l`` in force wherever the frame rotates and translates together. The URDF's base frame is the
world: gravity is the calibration's, in the base's axes. ``dq`` and ``ddq`` not given are differentiated from
``q`` by the same polynomial filter as poses (offline both ways; causally with its stated delay).

**An IMU on the tool** (:class:`ImuMotion`). The IMU measures its orientation in its world ``R_i``, its
angular velocity ``omega_i`` and its specific force ``f_i = R_i^T (p_ddot_i - g)`` in its own axes. With
``C`` its axes in the sensor's (``v_s = C v_i``) and ``r`` its point from the sensor's point (sensor axes),
on one rigid body::

    omega = C omega_i,   alpha = d/dt omega,   f_s = C f_i - (alpha x r + omega x (omega x r))    (C6)

``f_s = R^T (p_ddot - g)`` at the sensor's point, in its axes: all the payload's wrench needs of the
attitude and the translation. Only ``alpha`` is differentiated. The model is then read at the attitude
``R = I`` with ``p_ddot = f_s + g`` (its own gravity ``g``), so that ``R^T (p_ddot - g) = f_s``::

    x = [0, (1, 0, 0, 0), 0, omega],    a = [f_s + g, alpha]                                     (C7)

no gravity vector and no pose is needed. The sensor frame's attitude, for an output in the base frame, is
``R = R_i C^T`` (the IMU's world).

**Latency.** A source's stream may lag the readings (a joint-state topic published after the controller's
cycle, an IMU's own filter): ``latency`` (s, either sign) says that its sample given with the reading at ``t``
is as of ``t - latency``, as a calibration's latency says of its pose stream. It is applied where the poses'
is: offline the stream is moved onto the readings' times by interpolation (any fraction of a sample; a stream
sparser than the readings stays as sparse, each sample on the row nearest its time), causally
the filter is read ``latency`` (whole samples) nearer its newest sample, so that the motion and the reading
are of one time; the delay the causal path states is unchanged, and must be at least the latency.

**Noise** (the third term of (C3)). A source's channels' noise is estimated from their differences (a white
noise of sd ``sigma`` on a signal smooth at the sample rate gives second differences of variance
``6 sigma^2``; offline by :func:`fmscal.plant.io.difference_noise`, ``estimate_noise``'s robust estimate,
causally from the second differences as the samples come) and carried through the filter's coefficients: the
joints' ``var(ddq_j) = var(q_j) sum(c2^2)`` through the frame's Jacobian ``J`` (``var(a_l) = (J_v o J_v)
var(ddq)``, ``o`` the entrywise product,
``var(alpha)`` likewise with ``J_omega``), at each sample's ``q``, per component; the IMU's as a full
covariance, ``Cov(a) = M diag(var) M^T`` with ``M = [[C, [r]x C], [0, C]]`` on ``[f_i; alpha_i]`` and
``var = [var(f_i) sum(c0^2); var(omega_i) sum(c1^2)]`` (:meth:`ImuMotion.accel_noise`): the lever arm's
``alpha x r`` carries the differentiated gyro's noise (``var(alpha) |r|^2`` in size). Left out: measured
``dq`` and ``ddq`` add none, and ``omega x (omega x r)`` carries the gyro's smoothed noise, at most about
``2 |omega| |r| sd(omega_i) sqrt(sum(c0^2))``, against ``alpha x r``'s ``|r| sd(omega_i) sqrt(sum(c1^2))``:
a share ``2 |omega| sqrt(sum(c0^2) / sum(c1^2))`` of it, small while ``|omega|`` is well below
``sqrt(sum(c1^2) / sum(c0^2)) / 2`` (the filter's bandwidth).
"""

import numpy as np

from fmscal.plant.io import RobotKinematics
from fmscal.plant.numerics import FmscalError
from fmscal.plant.physics import rotation_matrices, rotation_matrix

__all__ = ["JointMotion", "ImuMotion", "MotionError", "quaternion_from_matrix", "quaternion_to_matrix"]


class MotionError(FmscalError):
    """A motion source's input that cannot be used: the message names the problem."""


def quaternion_from_matrix(R):
    """Unit quaternions ``(qw, qx, qy, qz)``, ``qw >= 0``, of rotation matrices ``R`` (N, 3, 3)."""
    R = np.asarray(R, dtype=float)
    m00, m11, m22 = R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]
    q = np.empty((len(R), 4))
    q[:, 0] = np.sqrt(np.maximum(0.0, 1 + m00 + m11 + m22)) / 2
    q[:, 1] = np.copysign(np.sqrt(np.maximum(0.0, 1 + m00 - m11 - m22)) / 2, R[:, 2, 1] - R[:, 1, 2])
    q[:, 2] = np.copysign(np.sqrt(np.maximum(0.0, 1 - m00 + m11 - m22)) / 2, R[:, 0, 2] - R[:, 2, 0])
    q[:, 3] = np.copysign(np.sqrt(np.maximum(0.0, 1 - m00 - m11 + m22)) / 2, R[:, 1, 0] - R[:, 0, 1])
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def quaternion_to_matrix(q):
    """``R(q)`` of a unit quaternion ``(qw, qx, qy, qz)``, shape (3, 3)."""
    return np.asarray(rotation_matrix(np.asarray(q, dtype=float) / np.linalg.norm(q)), dtype=float)


def _cross(a, b):
    """Row-wise cross product of (N, 3) arrays (np.cross's overhead is large for a few rows)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def _check_spatial(model, who):
    if model.attitude != "quaternion":
        raise MotionError(f"{who} gives a motion in 3D: the calibration is of a {model.name} reading")


def _vector(value, n, name, finite=True):
    """``value`` as (n,) floats, or a one-line error."""
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise MotionError(f"{name} must be {n} numbers; got {value!r}"[:200]) from None
    if v.shape != (n,):
        raise MotionError(f"{name} must be {n} numbers; got shape {v.shape}")
    if finite and not np.isfinite(v).all():
        raise MotionError(f"{name} must be finite; got {v}")
    return v


def _latency(value):
    """A stream's latency, s: a finite number of either sign, or a one-line error."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
            or not np.isfinite(value):
        raise MotionError(f"latency must be a finite number of seconds (either sign); got {value!r}"[:200])
    return float(value)


class JointMotion:
    """The sensor frame's motion from joint states and the robot's URDF, by pinocchio (C5).

    Parameters
    ----------
    urdf : str or Path
        The robot's URDF (kinematics only).
    frame : str
        The sensor frame's name in it (its origin the sensor's point, its axes the sensor's).
    joints : sequence of str, optional
        The joints' names in the order the arrays come in; default the URDF's movable joints' order.
    latency : float
        s, either sign: the joint states given with the reading at ``t`` are as of ``t - latency`` (module
        docstring, Latency); default 0, as of the readings' times.

    Attributes
    ----------
    joints : tuple of str
        That order (a ROS node matches ``JointState.name`` to it).
    kinematics : plant.io.RobotKinematics

    Raises
    ------
    FmscalError
        pinocchio missing, a URDF it cannot read, a frame it lacks, ``joints`` not the URDF's joints.
    """

    source = "joint states"

    def __init__(self, urdf, frame, joints=None, latency=0.0):
        self.latency = _latency(latency)
        self.kinematics = RobotKinematics(urdf, frame)
        names = self.kinematics.joint_names
        if joints is None:
            joints = names
        elif isinstance(joints, str) or not all(isinstance(j, str) for j in joints):
            raise MotionError(f"joints must be a sequence of joint names; got {joints!r}"[:200])
        joints = tuple(joints)
        if sorted(joints) != sorted(names):
            raise MotionError(f"joints {', '.join(joints)[:120]} are not the URDF's {len(names)} movable joints "
                              f"({', '.join(names)[:160]})")
        self.joints = joints
        self._to_urdf = np.array([joints.index(n) for n in names])
        self.size = len(joints)

    def __repr__(self):
        return f"JointMotion({self.kinematics.frame_id}, joints={self.joints}, latency={self.latency!r})"

    def poses(self, q):
        """The frame's poses for rows of joint values in :attr:`joints` order (forward kinematics).

        Parameters
        ----------
        q : array_like, shape (N, size)

        Returns
        -------
        ndarray, shape (N, 7)
            ``[qw, qx, qy, qz, x, y, z]`` in the URDF's base frame, as a spatial log holds them.
        """
        q = np.asarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] != self.size:
            raise MotionError(f"q must be rows of {self.size} joint values; got shape {q.shape}")
        return self.kinematics.poses(q[:, self._to_urdf])

    def check(self, model):
        _check_spatial(model, "JointMotion")

    def sample(self, joints):
        """A push's ``joints=(q, dq, ddq)`` checked: ``(q, dq, ddq)``, the rates NaN where not given; None for a
        sample with no joint state."""
        if joints is None:
            return None
        if not (isinstance(joints, (tuple, list)) and len(joints) == 3):
            raise MotionError("joints must be (q, dq, ddq): arrays in JointMotion.joints order, dq and ddq None "
                              "where not given")
        q, dq, ddq = joints
        if q is None:
            return None
        q = _vector(q, self.size, "joints' q", finite=False)
        if not np.isfinite(q).all():
            return None
        rates = [np.full(self.size, np.nan) if v is None else _vector(v, self.size, name)
                 for v, name in ((dq, "joints' dq"), (ddq, "joints' ddq"))]
        return q, *rates

    def state(self, model, q, dq, ddq):
        """``(x, a, R)`` of (C5) for rows of ``q, dq, ddq`` (N, n) in :attr:`joints` order; ``R`` (N, 3, 3) the
        sensor frame's attitude."""
        order = self._to_urdf
        pose, v, omega, acc, alpha = self.kinematics.motion(np.asarray(q)[:, order], np.asarray(dq)[:, order],
                                                            np.asarray(ddq)[:, order])
        R = rotation_matrices(pose[:, :4])
        n = len(pose)
        configuration, velocity, a = np.empty((n, 7)), np.empty((n, 6)), np.empty((n, 6))
        configuration[:, :3], configuration[:, 3:] = pose[:, 4:], pose[:, :4]
        velocity[:, :3], velocity[:, 3:] = np.einsum("nij,nj->ni", R, v), omega
        a[:, :3], a[:, 3:] = np.einsum("nij,nj->ni", R, acc), alpha
        x = np.empty((n, model.nx))
        x[:, list(model.q_index)] = configuration
        x[:, list(model.v_index)] = velocity
        return x, a, R

    def accel_var(self, q, var_ddq, R):
        """The variance of ``a = [p_ddot; alpha]`` a joint noise of ``var_ddq`` in ``ddq`` gives, row by row.

        ``var(a_l) = (J_v o J_v) var(ddq)``, ``var(alpha) = (J_omega o J_omega) var(ddq)`` at each row's ``J``
        and ``var(p_ddot) = (R o R) var(a_l)`` at its ``R`` (module's Noise).

        Parameters
        ----------
        q : array_like, shape (N, n)
            Joint values in :attr:`joints` order.
        var_ddq : array_like, shape (n,) or (N, n)
        R : array_like, shape (N, 3, 3)
            The sensor frame's attitudes.

        Returns
        -------
        ndarray, shape (N, 6)
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))[:, self._to_urdf]
        var_ddq = np.broadcast_to(np.asarray(var_ddq, dtype=float), q.shape)[:, self._to_urdf]
        J = self.kinematics.jacobian(q)                                     # (N, 6, n)
        var = np.einsum("nij,nj->ni", J ** 2, var_ddq)
        return np.c_[np.einsum("nij,nj->ni", np.asarray(R, dtype=float) ** 2, var[:, :3]), var[:, 3:]]


class ImuMotion:
    """The sensor's motion from an IMU on the tool (C6, C7): no pose and no gravity vector needed.

    Parameters
    ----------
    rotation : array_like, shape (3, 3), optional
        The IMU's axes in the sensor's: ``v_sensor = rotation @ v_imu``; default identity.
    lever_arm : array_like, shape (3,), optional
        The IMU's point from the sensor's point, in the sensor's axes, m; default zero.
    latency : float
        s, either sign: the IMU's sample given with the reading at ``t`` is as of ``t - latency`` (module
        docstring, Latency); default 0, as of the readings' times.

    Raises
    ------
    FmscalError
        Not a rotation matrix, or not three finite numbers.
    """

    source = "IMU"
    size = 6                         # the channels filtered: the IMU's angular velocity and specific force

    def __init__(self, rotation=None, lever_arm=None, latency=0.0):
        self.latency = _latency(latency)
        C = np.eye(3) if rotation is None else np.asarray(rotation, dtype=float)
        if C.shape != (3, 3) or not np.isfinite(C).all():
            raise MotionError(f"the IMU's rotation must be a 3x3 matrix; got shape {C.shape}")
        if np.abs(C @ C.T - np.eye(3)).max() > 1e-6 or np.linalg.det(C) < 0:
            raise MotionError("the IMU's rotation must be a proper rotation matrix (C C^T = I, det +1): the IMU's "
                              "axes in the sensor's, v_sensor = C v_imu")
        self.rotation = C
        self.lever_arm = np.zeros(3) if lever_arm is None else _vector(lever_arm, 3, "the IMU's lever arm")

    def __repr__(self):
        return (f"ImuMotion(rotation={self.rotation.tolist()}, lever_arm={self.lever_arm.tolist()}, "
                f"latency={self.latency!r})")

    def check(self, model):
        _check_spatial(model, "ImuMotion")

    def sample(self, imu):
        """A push's ``imu=(quaternion_wxyz, angular_velocity, specific_force)`` checked: ``(channels (6,),
        quaternion (4,) or NaN)``; None for a sample with no IMU reading."""
        if imu is None:
            return None
        if not (isinstance(imu, (tuple, list)) and len(imu) == 3):
            raise MotionError("imu must be (quaternion_wxyz, angular_velocity, specific_force), the IMU's axes")
        quaternion, omega, force = imu
        if omega is None or force is None:
            return None
        channels = np.r_[_vector(omega, 3, "the IMU's angular velocity"), _vector(force, 3, "the IMU's specific force")]
        q = np.full(4, np.nan) if quaternion is None else _vector(quaternion, 4, "the IMU's quaternion", finite=False)
        if np.isfinite(q).all() and abs(np.linalg.norm(q) - 1) > 1e-3:
            raise MotionError(f"the IMU's quaternion must be a unit quaternion, scalar first; got norm "
                              f"{np.linalg.norm(q):.4g}")
        return channels, q

    def sensor_motion(self, omega_i, domega_i, f_i):
        """(C6): ``omega``, ``alpha`` and ``f_s`` at the sensor's point, its axes, from rows (N, 3) of the IMU's
        angular velocity, its derivative and its specific force."""
        C, r = self.rotation, self.lever_arm[None]
        omega, alpha = np.asarray(omega_i) @ C.T, np.asarray(domega_i) @ C.T
        f_s = np.asarray(f_i) @ C.T - (_cross(alpha, r) + _cross(omega, _cross(omega, r)))
        return omega, alpha, f_s

    def state(self, model, channels, d1, orientation):
        """``(x, a, R)`` of (C7) for rows of the filtered channels ``[omega_i, f_i]`` (N, 6), their derivatives
        and the IMU's orientations (N, 4; NaN rows where none): ``R`` the sensor frame's attitude in the IMU's
        world (NaN where no orientation)."""
        omega, alpha, f_s = self.sensor_motion(channels[:, :3], d1[:, :3], channels[:, 3:])
        n = len(channels)
        configuration, velocity = np.zeros((n, 7)), np.zeros((n, 6))
        configuration[:, 3] = 1.0                                           # [p, q] = [0, (1, 0, 0, 0)]
        velocity[:, 3:] = omega
        x = np.empty((n, model.nx))
        x[:, list(model.q_index)] = configuration
        x[:, list(model.v_index)] = velocity
        a = np.empty((n, 6))
        a[:, :3] = f_s + np.asarray(model.gravity, dtype=float)
        a[:, 3:] = alpha
        R = np.full((n, 3, 3), np.nan)
        given = np.isfinite(orientation).all(axis=1)
        if given.any():
            q = orientation[given] / np.linalg.norm(orientation[given], axis=1, keepdims=True)
            R[given] = rotation_matrices(q) @ self.rotation.T
        return x, a, R

    def accel_noise(self, var_channels, c0_sq, c1_sq):
        """The covariance of ``a = [f_s + g; alpha]`` (sensor axes) from the channels' noise variance (6,), as
        ``Cov(a) = M diag(var) M^T``.

        With ``alpha_i`` the differentiated rate in the IMU's axes, (C6) is linear in the filtered channels'
        noise: ``alpha = C alpha_i`` and ``f_s = C f_i + [r]x C alpha_i`` (``-alpha x r = r x alpha``, ``[r]x``
        the cross-product matrix), so ``M = [[C, [r]x C], [0, C]]`` on ``[f_i; alpha_i]`` and
        ``var = [var(f_i) sum(c0^2); var(omega_i) sum(c1^2)]``: the lever arm's ``alpha x r`` carries the
        differentiated gyro's noise (``var(alpha) |r|^2`` in size), correlated with ``alpha``'s own.

        Returns
        -------
        M : ndarray, shape (6, 6)
        var : ndarray, shape (6,)
        """
        C = self.rotation
        x, y, z = self.lever_arm
        skew = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
        M = np.zeros((6, 6))
        M[:3, :3], M[:3, 3:], M[3:, 3:] = C, skew @ C, C
        var_channels = np.asarray(var_channels, dtype=float)
        return M, np.r_[var_channels[3:] * c0_sq, var_channels[:3] * c1_sq]
