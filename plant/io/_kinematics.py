"""Poses from joint angles: a robot's forward kinematics to the sensor frame, by pinocchio.

A wrist sensor's log often holds the arm's joint angles, not a pose. With the
robot's URDF and the name of the sensor's frame in it, pinocchio's forward
kinematics (``pin.framesForwardKinematics``, ``data.oMf``) gives the frame's
attitude and position in the base frame: the pose the spatial log format
holds (:mod:`fmscal.plant.io._log`), so that every command takes such a log or
table once the joints are turned into poses.

The joint columns are named ``q1 .. qn`` in the URDF's joint order (pinocchio's
``model.names``, the universe left out) or by the joints' own names, in rad
(m for a prismatic joint). pinocchio is a runtime extra:
``pip install "fmscal[robot]"``.
"""

import os
import sys
from contextlib import contextmanager

import numpy as np

from fmscal.plant.numerics import FmscalError
from ._log import (Log, LogError, _as_path, _check_finite, _check_magnitudes, _check_steps, _echo, _read_csv,
                   csv_header)
from ._pose_table import PoseTable

__all__ = ["RobotKinematics", "joint_columns", "read_joint_data", "JointLog", "read_joint_log"]

_WRENCH = ("tx", "ty", "tz", "fx", "fy", "fz")
_OTHERS = ("t", *_WRENCH)                   # the columns of a joint log that are not joints


@contextmanager
def _quiet_stderr():
    """File descriptor 2 on the null device for the block, restored after it (as it was, even on an error).

    urdfdom, under pinocchio, writes its parse errors to the C library's
    stderr before pinocchio raises; the error the caller reports says the same
    in one line.
    """
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
            try:
                yield
            finally:
                os.dup2(saved, 2)
    finally:
        os.close(saved)


class RobotKinematics:
    """A robot's forward kinematics to one frame, from its URDF.

    Parameters
    ----------
    urdf : str or Path
        The robot's URDF file (kinematics only: meshes are not read).
    frame : str
        The sensor frame's name in the URDF (a link or a fixed joint's frame).

    Attributes
    ----------
    joint_names : tuple of str
        The URDF's joints in pinocchio's order, one coordinate each.

    Raises
    ------
    FmscalError
        pinocchio missing, a URDF it cannot read, a frame the URDF lacks, or
        a joint of more than one coordinate (a free or a continuous joint).
    """

    def __init__(self, urdf, frame):
        try:
            import pinocchio as pin         # optional (the robot extra): only --urdf needs it
        except ImportError:
            raise FmscalError("--urdf needs pinocchio: pip install \"fmscal[robot]\"") from None
        self._pin = pin
        urdf = _as_path(urdf, "URDF")
        try:
            with _quiet_stderr():                               # urdfdom prints its own two lines there
                self.model = pin.buildModelFromUrdf(str(urdf))
        except Exception as err:                              # pinocchio raises plain ValueError/RuntimeError
            raise FmscalError(f"{urdf}: not a URDF pinocchio can read ({str(err).splitlines()[0][:120]})") from None
        if not self.model.existFrame(str(frame)):
            names = [f.name for f in self.model.frames][1:]
            raise FmscalError(f"{urdf}: has no frame {frame!r}; its frames include {', '.join(names[-8:])}")
        self.frame_id = self.model.getFrameId(str(frame))
        if self.model.nq != self.model.njoints - 1 or self.model.nq != self.model.nv:
            raise FmscalError(f"{urdf}: a joint with more than one coordinate (continuous or free); only revolute "
                              "and prismatic joints are taken")
        self.joint_names = tuple(self.model.names[1:])
        self._data = self.model.createData()

    def poses(self, joints):
        """The frame's pose for every row of joint values, in the spatial log's order ``[qw, qx, qy, qz, x, y, z]``.

        Parameters
        ----------
        joints : array_like, shape (N, n)
            Joint values in :attr:`joint_names` order, rad (m for prismatic joints).

        Returns
        -------
        ndarray, shape (N, 7)
            Unit quaternions (scalar first, frame to base) and positions, m.
        """
        joints = np.asarray(joints, dtype=float)
        pin = self._pin
        out = np.empty((len(joints), 7))
        for k, q in enumerate(joints):
            pin.framesForwardKinematics(self.model, self._data, q)
            placement = self._data.oMf[self.frame_id]
            x, y, z, w = pin.Quaternion(placement.rotation).coeffs()
            out[k] = [w, x, y, z, *placement.translation]
        return out

    def motion(self, joints, velocities, accelerations):
        """The frame's pose, velocity and acceleration for every row of joint values and their rates.

        By pinocchio: ``forwardKinematics(model, data, q, dq, ddq)``, ``updateFramePlacements``, the frame's
        velocity ``getFrameVelocity`` and its *classical* acceleration ``getFrameClassicalAcceleration``, both
        in the frame's own (``LOCAL``) axes::

            v, omega   = the frame origin's velocity and the angular velocity, frame axes
            a, alpha   = the origin's acceleration (d/dt of its world velocity, in frame axes) and the
                         angular acceleration, frame axes

        The spatial acceleration (``getFrameAcceleration``) differs from the classical one by ``omega x v``
        (in its linear part): the one a body's Newton-Euler takes as ``R^T p_ddot`` is the classical.

        Parameters
        ----------
        joints, velocities, accelerations : array_like, shape (N, n)
            ``q`` (rad, m), ``dq`` (rad/s, m/s) and ``ddq`` (rad/s^2, m/s^2) in :attr:`joint_names` order.

        Returns
        -------
        pose : ndarray, shape (N, 7)
            ``[qw, qx, qy, qz, x, y, z]`` as :meth:`poses`.
        v, omega, a, alpha : ndarray, shape (N, 3) each
            Frame axes, SI.
        """
        pin = self._pin
        q, dq, ddq = (np.atleast_2d(np.asarray(v, dtype=float)) for v in (joints, velocities, accelerations))
        n = len(q)
        pose, v, omega, a, alpha = np.empty((n, 7)), *(np.empty((n, 3)) for _ in range(4))
        for k in range(n):
            pin.forwardKinematics(self.model, self._data, q[k], dq[k], ddq[k])
            pin.updateFramePlacements(self.model, self._data)
            placement = self._data.oMf[self.frame_id]
            x, y, z, w = pin.Quaternion(placement.rotation).coeffs()
            pose[k] = [w, x, y, z, *placement.translation]
            twist = pin.getFrameVelocity(self.model, self._data, self.frame_id, pin.LOCAL)
            acc = pin.getFrameClassicalAcceleration(self.model, self._data, self.frame_id, pin.LOCAL)
            v[k], omega[k] = twist.linear, twist.angular
            a[k], alpha[k] = acc.linear, acc.angular
        return pose, v, omega, a, alpha

    def jacobian(self, joints):
        """The frame's Jacobian in its own axes at ``joints`` (n,): shape (6, n), rows ``[v; omega]``
        (pinocchio's ``computeFrameJacobian``, ``LOCAL``); at each row of ``joints`` (N, n): shape (N, 6, n)."""
        joints = np.asarray(joints, dtype=float)
        if joints.ndim == 2:
            return np.array([self.jacobian(q) for q in joints]).reshape(len(joints), 6, joints.shape[1])
        return np.array(self._pin.computeFrameJacobian(self.model, self._data, joints, self.frame_id,
                                                       self._pin.LOCAL))


def joint_columns(header, joint_names):
    """Which columns of ``header`` hold the joints, in the URDF's order: ``q1`` to ``qn``, or the joints' names.

    Parameters
    ----------
    header : sequence of str
    joint_names : sequence of str

    Returns
    -------
    list of str

    Raises
    ------
    FmscalError
        The header holds neither all of ``q1 .. qn`` nor all of the joints' names.
    """
    numbered = [f"q{i + 1}" for i in range(len(joint_names))]
    for names in (numbered, list(joint_names)):
        if set(names) <= set(header):
            extra = [h for h in header if h not in (*_OTHERS, *names)]
            if extra:
                raise FmscalError(f"the header has {len(names) + len(extra)} joint columns ({_echo(','.join(extra))} "
                                  f"beyond {names[0]}..{names[-1]}); the URDF has {len(joint_names)} joints: "
                                  "drop the extra columns, or give the URDF of the robot that logged them")
            return names
    return _mismatch(header, joint_names, numbered)


def _mismatch(header, joint_names, numbered):
    others = [h for h in header if h not in _OTHERS]
    raise FmscalError(f"the joint columns {','.join(others)[:120]} do not match the URDF's {len(joint_names)} joints: "
                      f"name them {','.join(numbered)} (the URDF's order) or {','.join(joint_names)}")


def read_joint_data(path, kinematics):
    """A log or a table whose pose columns are joint angles, turned into poses of the sensor frame.

    Parameters
    ----------
    path : str or Path
        A CSV with ``t`` (a log) or without (a table, one row per held
        pose), the joint columns (:func:`joint_columns`) and
        ``tx,ty,tz,fx,fy,fz``.
    kinematics : RobotKinematics

    Returns
    -------
    plant.Log or plant.PoseTable
        A spatial log (poses from the forward kinematics) or a pose table.

    Raises
    ------
    plant.LogError, FmscalError
        The file's problems, or joint columns that do not match the URDF.
    """
    path = _as_path(path, "log")
    header = csv_header(path)
    joints = joint_columns(header, kinematics.joint_names)
    timed = "t" in header
    frame = _read_csv(path, (*(("t",) if timed else ()), *joints, *_WRENCH),
                      "only joint cells may be empty (no pose)" if timed else "every cell of a table is a number")
    values = frame[joints].to_numpy()
    missing = np.isnan(values).all(axis=1)
    partial = np.isnan(values).any(axis=1) & ~missing
    if partial.any() or (missing.any() and not timed):
        row = int(np.argmax(partial | missing)) + 1
        raise LogError(f"{_echo(path.name)}: row {row} has some but not all joint values"
                       if partial.any() else f"{_echo(path.name)}: row {row} has no joint values")
    _refuse_degrees(values[~missing], kinematics, joints, _echo(path.name))
    pose = np.full((len(values), 7), np.nan)
    pose[~missing] = kinematics.poses(values[~missing])
    w_hat = frame[list(_WRENCH)].to_numpy()
    if timed:
        return Log(frame["t"].to_numpy(), pose, w_hat, name=_echo(path.name))
    return PoseTable(pose[:, :4], w_hat, name=_echo(path.name))


def _refuse_degrees(values, kinematics, joints, name):
    """Refuse joint angles in degrees, told by the URDF's joint limits: a revolute joint beyond its limit in rad
    while every revolute joint in rad, the values times pi/180, is within its own, and the values span more than
    a turn or pass a limit by more than a turn (a joint unwrapped by one turn is not taken for degrees): one line
    naming degrees.

    Parameters
    ----------
    values : ndarray, shape (N, n)
        The joint values, in the URDF's order.
    kinematics : RobotKinematics
    joints : list of str
        The joint columns' names, in that order.
    name : str
        The file's name, for the message.

    Raises
    ------
    plant.LogError
    """
    model = kinematics.model
    lower, upper = np.asarray(model.lowerPositionLimit, float), np.asarray(model.upperPositionLimit, float)
    revolute = np.array([j.shortname().removeprefix("JointModel").startswith("R") for j in model.joints[1:]])
    limited = revolute & np.isfinite(lower) & np.isfinite(upper) & (upper > lower)
    if not limited.any() or not len(values):
        return
    v = values[:, limited]
    lo, hi = lower[limited], upper[limited]
    beyond = (v < lo - 1e-6) | (v > hi + 1e-6)
    if not beyond.any():
        return
    radians = np.deg2rad(v)
    if ((radians < lo - 1e-6) | (radians > hi + 1e-6)).any():
        return
    # a joint unwrapped a turn beyond its limit (the same attitude) is not degrees: degrees span more than a turn
    # in rad somewhere, or pass a limit by more than one
    turn = 2 * np.pi
    if not ((np.ptp(v, axis=0) > turn).any() or ((v < lo - turn) | (v > hi + turn)).any()):
        return
    k = int(np.argmax(beyond.any(axis=0)))
    column = [c for c, keep in zip(joints, limited) if keep][k]
    worst = v[np.argmax(np.abs(v[:, k])), k]
    raise LogError(f"{name}: the joint angles look like degrees, not radians: {column} reaches {worst:.4g}, beyond "
                   f"the URDF's limits [{lo[k]:.3g}, {hi[k]:.3g}] rad, while every joint in degrees (times pi/180) "
                   f"is within its limits; convert the joint columns to rad")


class JointLog:
    """A log of joint states and raw readings: the motion's source for compensation with a URDF.

    Parameters
    ----------
    t : array_like, shape (N,)
        s, strictly increasing and evenly sampled (as :class:`fmscal.plant.Log`'s).
    joints : array_like, shape (N, n)
        ``q`` per sample, rad (m for a prismatic joint), in the order the motion's source takes; a row of NaN
        where no joint state came with that reading (all of a row's values or none).
    w_hat : array_like, shape (N, n_w)
        The raw readings.
    velocities, accelerations : array_like, shape (N, n), optional
        ``dq``, ``ddq`` where measured (NaN where not); otherwise differentiated from ``joints``.
    name : str
    kinematics : RobotKinematics, optional
        Given, the joint angles are checked against its URDF's limits (:meth:`check_kinematics`).
    joint_names : sequence of str, optional
        The joints' names in the columns' order; default ``kinematics.joint_names``.

    Raises
    ------
    plant.LogError
        Shapes that do not agree, times not increasing or not evenly sampled, readings not finite, a value
        beyond :data:`fmscal.plant.io._log.MAX_MAGNITUDE` or infinite, a row with some but not all joints,
        joint angles in degrees.
    """

    def __init__(self, t, joints, w_hat, velocities=None, accelerations=None, name="joint-log", kinematics=None,
                 joint_names=None):
        self.t = np.asarray(t, dtype=float).ravel()
        self.joints = np.atleast_2d(np.asarray(joints, dtype=float))
        self.w_hat = np.atleast_2d(np.asarray(w_hat, dtype=float))
        self.name = name
        n = len(self.t)
        if len(self.joints) != n or len(self.w_hat) != n or self.joints.ndim != 2 or self.w_hat.ndim != 2:
            raise LogError(f"{name}: t (N,), joints (N, n) and w_hat (N, n_w) need one row per sample; got "
                           f"{self.t.shape}, {self.joints.shape}, {self.w_hat.shape}")
        rates = []
        for what, v in (("velocities", velocities), ("accelerations", accelerations)):
            v = None if v is None else np.asarray(v, dtype=float)
            if v is not None and v.shape != self.joints.shape:
                raise LogError(f"{name}: {what} must be shape {self.joints.shape}, as the joints; got {v.shape}")
            rates.append(v)
        self.velocities, self.accelerations = rates
        columns = [f"q{j + 1}" for j in range(self.joints.shape[1])]
        _check_samples(name, self.t, self.w_hat, [
            *((c, self.joints[:, j]) for j, c in enumerate(columns)),
            *((f"d{c}", v[:, j]) for v in rates[:1] if v is not None for j, c in enumerate(columns)),
            *((f"dd{c}", v[:, j]) for v in rates[1:] if v is not None for j, c in enumerate(columns))])
        missing = np.isnan(self.joints).all(axis=1)
        partial = np.isnan(self.joints).any(axis=1) & ~missing
        if partial.any():
            raise LogError(f"{name}: row {int(np.argmax(partial)) + 1} has some but not all joint values")
        if kinematics is not None:
            self.check_kinematics(kinematics, joint_names)

    def check_kinematics(self, kinematics, joint_names=None):
        """Refuse joint angles in degrees, told by the URDF's limits (:func:`_refuse_degrees`).

        Parameters
        ----------
        kinematics : RobotKinematics
        joint_names : sequence of str, optional
            The joints' names in the columns' order; default ``kinematics.joint_names``.

        Raises
        ------
        plant.LogError
        """
        names = tuple(kinematics.joint_names if joint_names is None else joint_names)
        if len(names) != self.joints.shape[1] or sorted(names) != sorted(kinematics.joint_names):
            raise LogError(f"{self.name}: {self.joints.shape[1]} joint columns; the URDF has "
                           f"{len(kinematics.joint_names)} joints")
        order = [names.index(j) for j in kinematics.joint_names]
        given = ~np.isnan(self.joints).all(axis=1)
        _refuse_degrees(self.joints[given][:, order], kinematics, [names[k] for k in order], self.name)

    @property
    def dt(self):
        """The median sample time, s."""
        return float(np.median(np.diff(self.t)))

    def __len__(self):
        return len(self.t)


def _check_samples(name, t, w_hat, others=()):
    """A source log's times and readings as :class:`fmscal.plant.Log` checks them (one definition, its
    ``_check_*``): at least two samples, times and readings finite, no value (``others``' ``(column, values)``
    too, where NaN is a missing cell) beyond ``MAX_MAGNITUDE`` or infinite, times strictly increasing and evenly
    sampled; a one-line :class:`LogError`."""
    if len(t) < 2:
        raise LogError(f"{name}: needs at least two samples")
    readings = [(_WRENCH[j] if w_hat.shape[1] == len(_WRENCH) else f"w{j + 1}", w_hat[:, j])
                for j in range(w_hat.shape[1])]
    _check_finite(name, [("t", t), *readings])
    _check_magnitudes(name, [("t", t), *others, *readings])
    _check_steps(name, t)


def read_joint_log(path, kinematics):
    """A log of joint angles and raw readings (``t``, the joint columns of :func:`joint_columns`,
    ``tx,ty,tz,fx,fy,fz``) as a :class:`JointLog` in :attr:`RobotKinematics.joint_names` order.

    Parameters
    ----------
    path : str or Path
    kinematics : RobotKinematics

    Returns
    -------
    JointLog

    Raises
    ------
    plant.LogError, FmscalError
        The file's problems, joint columns that do not match the URDF, joint angles in degrees, a row with some
        but not all joints.
    """
    path = _as_path(path, "log")
    header = csv_header(path)
    if "t" not in header:
        raise LogError(f"{_echo(path.name)}: no column t; a joint log needs t, the joints' columns and "
                       f"{','.join(_WRENCH)}")
    joints = joint_columns(header, kinematics.joint_names)
    frame = _read_csv(path, ("t", *joints, *_WRENCH), "only joint cells may be empty (no joint state)")
    return JointLog(frame["t"].to_numpy(), frame[joints].to_numpy(), frame[list(_WRENCH)].to_numpy(),
                    name=_echo(path.name), kinematics=kinematics)
