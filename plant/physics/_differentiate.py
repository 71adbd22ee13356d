"""The motion of a spatial log by smoothing differentiation of its poses.

The plain reference's way to the motion (and the practitioners'): poses
resampled on the log's grid, smoothed and differentiated by a
Savitzky-Golay filter (a local quintic fitted over a window), and the angular
velocity and acceleration read from the quaternion's derivatives::

    omega = 2 vec(q* (x) q_dot),    alpha = 2 vec(q* (x) q_ddot)

(:mod:`fmscal.plant.physics._rigid_body`). Smoothing cuts the motion's high
frequencies and, with a noisy pose, differentiating still amplifies its
noise: the floor uses the motion model instead. The window should be short
against the motion's period and long against the pose interval.
"""

import numpy as np
from scipy.signal import oaconvolve, savgol_coeffs, savgol_filter

from fmscal.plant.numerics import FmscalError
from ._rigid_body import quaternion_multiply

__all__ = ["spatial_motion", "smoothed_state", "edge", "ORDER"]
#: Degree of the local polynomial (a quintic keeps the smoothing bias of a 0.2 s window below 0.1 % at 0.5 Hz).
ORDER = 5


def _samples(log, window):
    """The window's length in samples: odd, at least 7."""
    if not (isinstance(window, (int, float)) and np.isfinite(window) and window > 0):
        raise FmscalError(f"window must be a positive number of seconds; got {window!r}")
    return max(7, int(round(window / log.dt)) // 2 * 2 + 1)


def edge(log, window=0.2):
    """Samples at each end of the log where the smoothing window runs off it (its half length).

    Parameters
    ----------
    log : plant.Log
    window : float
        s, as for :func:`spatial_motion`.

    Returns
    -------
    int
    """
    return _samples(log, window) // 2


def spatial_motion(log, window=0.2):
    """Attitude, angular velocity and acceleration, and the acceleration of ``O``, at every sample.

    Parameters
    ----------
    log : plant.Log
        A spatial log.
    window : float
        Savitzky-Golay window, s (a quintic, :data:`ORDER`; at least 7 samples).

    Returns
    -------
    q : ndarray, shape (N, 4)
        Smoothed unit quaternions, scalar first.
    omega, alpha : ndarray, shape (N, 3)
        In sensor axes, rad/s and rad/s^2.
    p_ddot : ndarray, shape (N, 3)
        Acceleration of the sensor point in the world, m/s^2.

    Raises
    ------
    FmscalError
        Not a spatial log, or a window shorter than 7 samples or longer than the log.
    """
    q, omega, alpha, _, _, p_ddot = _smoothed(log, window)
    return q, omega, alpha, p_ddot


def smoothed_state(log, window=0.2):
    """The motion state ``[p, q, v, omega]`` at every sample from the smoothed poses, shape (N, 13).

    The layout of :class:`fmscal.plant.SpatialModel`'s state: position (m)
    and velocity (m/s) of the sensor point in the world, unit quaternion,
    angular velocity in sensor axes (rad/s). The nominal motion the spatial
    floor is linearised about (:mod:`fmscal.observers.batch._linearised_floor`).

    Parameters
    ----------
    log : plant.Log
        A spatial log.
    window : float
        Savitzky-Golay window, s, as for :func:`spatial_motion`.

    Returns
    -------
    ndarray, shape (N, 13)
    """
    q, omega, _, p, v, _ = _smoothed(log, window)
    return np.column_stack([p, q, v, omega])


def _smoothed(log, window):
    """``q, omega, alpha, p, p_dot, p_ddot`` from the Savitzky-Golay filter of the poses."""
    if getattr(log, "kind", None) != "spatial":
        raise FmscalError(f"spatial_motion takes a spatial log; got a {getattr(log, 'kind', type(log).__name__)} one")
    k = _samples(log, window)
    if k > len(log):
        raise FmscalError(f"{log.name}: the log is {log.duration:g} s; differentiating its poses needs at least "
                          f"{window:g} s (the smoothing window)")
    rows = np.flatnonzero(log.has_pose)
    pose = np.column_stack([np.interp(log.t, log.t[rows], log.pose[rows, j]) for j in range(7)])

    def smooth(values, derivative):
        return _savgol(values, k, derivative, log.dt)

    q = smooth(pose[:, :4], 0)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    conj = q * np.array([1.0, -1.0, -1.0, -1.0])                 # q*, row by row
    omega = 2 * quaternion_multiply(conj.T, smooth(pose[:, :4], 1).T)[1:].T
    alpha = 2 * quaternion_multiply(conj.T, smooth(pose[:, :4], 2).T)[1:].T
    return q, omega, alpha, smooth(pose[:, 4:], 0), smooth(pose[:, 4:], 1), smooth(pose[:, 4:], 2)


def _savgol(values, k, derivative, dt):
    """``scipy.signal.savgol_filter(values, k, ORDER, derivative, delta=dt, axis=0, mode="interp")``, its interior
    convolved by overlap-add (faster than the direct convolution for a window of hundreds of samples; equal to
    it to rounding, ``tests/test_inverse_dynamics_fit.py``) and its ends, where the window runs off the log, from
    the polynomial fitted to the first and last ``k`` samples as ``mode="interp"`` does. The rounding scales with
    the largest value of the input."""
    coefficients = savgol_coeffs(k, ORDER, deriv=derivative, delta=dt, use="conv")
    out = oaconvolve(values, coefficients[:, None], mode="same", axes=0)
    h = k // 2
    out[:h] = savgol_filter(values[:k], k, ORDER, deriv=derivative, delta=dt, axis=0, mode="interp")[:h]
    out[-h:] = savgol_filter(values[-k:], k, ORDER, deriv=derivative, delta=dt, axis=0, mode="interp")[-h:]
    return out
