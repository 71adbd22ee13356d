"""Logs of an IMU on the tool and the raw readings: the motion's source for compensation without a pose.

The columns (SI; the orientation scalar first, as fmscal's logs hold quaternions)::

    t, iqw, iqx, iqy, iqz, iwx, iwy, iwz, iax, iay, iaz, tx, ty, tz, fx, fy, fz

``iq`` the IMU's orientation in its world (its axes to the world's), ``iw`` its angular velocity (rad/s)
and ``ia`` its specific force (m/s^2: ``R^T (p_ddot - g)`` at its point, +9.81 along up at rest), both in
the IMU's axes. The orientation cells may be empty (an IMU that gives none: only the sensor frame's output
is then possible); the rate and force cells of a row are all given or all empty (no IMU sample).
"""

import numpy as np

from ._kinematics import _check_samples
from ._log import LogError, _as_path, _echo, _read_csv
from ._spatial_units import check_imu_units

__all__ = ["ImuLog", "read_imu_log", "IMU_COLUMNS"]

#: An IMU log's columns besides ``t`` and the reading's.
IMU_COLUMNS = ("iqw", "iqx", "iqy", "iqz", "iwx", "iwy", "iwz", "iax", "iay", "iaz")
_WRENCH = ("tx", "ty", "tz", "fx", "fy", "fz")


class ImuLog:
    """An IMU's samples and the raw readings, one row per reading.

    Parameters
    ----------
    t : array_like, shape (N,)
        s, strictly increasing and evenly sampled (as :class:`fmscal.plant.Log`'s).
    orientation : array_like, shape (N, 4) or None
        The IMU's orientation in its world, unit quaternions scalar first; rows of NaN where none.
    angular_velocity, specific_force : array_like, shape (N, 3)
        In the IMU's axes, rad/s and m/s^2; rows of NaN where no IMU sample came with the reading.
    w_hat : array_like, shape (N, n_w)
    name : str

    Raises
    ------
    plant.LogError
        Shapes that do not agree, times not increasing or not evenly sampled, readings not finite, a value
        beyond :data:`fmscal.plant.io._log.MAX_MAGNITUDE` or infinite, a row with some but not all of the rate
        and specific force, a quaternion not a unit one; ``UnitsError`` (a ``LogError``'s sibling) for a specific
        force or a rate in other units than m/s^2 and rad/s (:func:`check_imu_units`).
    """

    def __init__(self, t, orientation, angular_velocity, specific_force, w_hat, name="imu-log"):
        self.t = np.asarray(t, dtype=float).ravel()
        n = len(self.t)
        self.orientation = np.full((n, 4), np.nan) if orientation is None else np.asarray(orientation, dtype=float)
        self.angular_velocity = np.asarray(angular_velocity, dtype=float)
        self.specific_force = np.asarray(specific_force, dtype=float)
        self.w_hat = np.atleast_2d(np.asarray(w_hat, dtype=float))
        self.name = name
        for what, v, m in (("orientation", self.orientation, 4), ("angular_velocity", self.angular_velocity, 3),
                           ("specific_force", self.specific_force, 3)):
            if v.shape != (n, m):
                raise LogError(f"{name}: {what} must be shape ({n}, {m}); got {v.shape}")
        if len(self.w_hat) != n:
            raise LogError(f"{name}: w_hat needs one row per sample; got {len(self.w_hat)} for {n} times")
        _check_samples(name, self.t, self.w_hat, [(c, v) for c, v in zip(IMU_COLUMNS, np.c_[
            self.orientation, self.angular_velocity, self.specific_force].T)])
        rates = np.c_[self.angular_velocity, self.specific_force]
        partial = np.isnan(rates).any(axis=1) & ~np.isnan(rates).all(axis=1)
        if partial.any():
            raise LogError(f"{name}: row {int(np.argmax(partial)) + 1} has some but not all of the IMU's rate and "
                           "specific force")
        given = np.isfinite(self.orientation).all(axis=1)
        norm = np.linalg.norm(self.orientation[given], axis=1)
        if len(norm) and np.abs(norm - 1).max() > 1e-3:
            row = int(np.flatnonzero(given)[np.argmax(np.abs(norm - 1))]) + 1
            raise LogError(f"{name}: row {row}: the IMU's orientation is not a unit quaternion (norm "
                           f"{norm.max() if norm.max() - 1 > 1 - norm.min() else norm.min():.4g}); iqw..iqz are "
                           "scalar first")
        check_imu_units(name, self.angular_velocity, self.specific_force, self.orientation, self.dt)

    @property
    def dt(self):
        """The median sample time, s."""
        return float(np.median(np.diff(self.t)))

    def __len__(self):
        return len(self.t)


def read_imu_log(path):
    """An IMU log (the module's columns) as an :class:`ImuLog`.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    ImuLog

    Raises
    ------
    plant.LogError
        The file's problems (one line).
    """
    path = _as_path(path, "log")
    frame = _read_csv(path, ("t", *IMU_COLUMNS, *_WRENCH), "only the IMU's cells may be empty (no IMU sample)")
    q = frame[list(IMU_COLUMNS[:4])].to_numpy()
    return ImuLog(frame["t"].to_numpy(), q, frame[list(IMU_COLUMNS[4:7])].to_numpy(),
                  frame[list(IMU_COLUMNS[7:])].to_numpy(), frame[list(_WRENCH)].to_numpy(), name=_echo(path.name))
