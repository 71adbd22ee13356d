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
from ._log import Log, LogError, _as_path, _echo, _read_csv
from ._pose_table import PoseTable

__all__ = ["RobotKinematics", "joint_columns", "read_joint_data"]

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
    with open(path, "rb") as f:
        header = [h.strip() for h in f.readline(65536).decode("utf-8", errors="replace").removeprefix("\ufeff")
                  .split(",")]
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
