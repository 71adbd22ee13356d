"""Checks and packing of one live sample for :meth:`observers.Observer.step`."""

import numpy as np

from fmscal.plant.numerics import FmscalError, as_finite_array, as_number
from fmscal.plant.physics import Model, PlanarModel

__all__ = ["check_sample", "pack_input"]

_PLANAR = PlanarModel


def check_sample(dt, pose, w_hat, first, model=_PLANAR):
    """Validate one live sample for :meth:`Observer.step`; return ``(pose, w_hat)`` as arrays.

    Parameters
    ----------
    dt : float or None
        Time since the previous sample, s (may be None on the first).
    pose : array_like, shape (n_pose,), or None
    w_hat : array_like, shape (n_w,)
    first : bool
        The first sample after a reset (it needs a pose).
    model : plant.Model or its class
        Gives the sizes; default planar.

    Raises
    ------
    FmscalError
        ``w_hat`` not ``n_w`` finite numbers, ``pose`` neither None nor
        ``n_pose`` finite numbers (spatial: its quaternion not of unit norm
        within :data:`fmscal.plant.io._log.QUATERNION_TOLERANCE`), no pose on the
        first sample, or ``dt`` not positive after it.
    """
    if not first or dt is not None:
        dt = as_number(dt, "dt")
    n_w, n_pose = len(model.wrench_names), len(model.pose_names)
    w_hat = _sized(w_hat, n_w, f"w_hat must be {n_w} finite numbers")
    if pose is not None:
        pose = _sized(pose, n_pose, f"pose must be {n_pose} finite numbers or None")
        if isinstance(model, Model):
            pose = model.check_pose(pose)          # the model's own rule (a unit quaternion in space)
    if first:
        if pose is None:
            raise FmscalError("the first sample after reset() needs a pose measurement")
    elif not (np.isfinite(dt) and dt > 0):
        raise FmscalError(f"dt must be positive; got {dt!r}")
    return pose, w_hat


def _sized(value, size, rule):
    """``value`` as ``size`` finite floats (text refused), or FmscalError stating ``rule``."""
    try:
        return as_finite_array(value, (size,), "")
    except FmscalError:
        raise FmscalError(f"{rule}; got {value!r}"[:200]) from None


def pack_input(pose, w_hat, model=_PLANAR):
    """One step's input ``[has_pose, pose, w_hat]`` (:attr:`fmscal.plant.Model.input_layout`).

    Parameters
    ----------
    pose : ndarray, shape (n_pose,), or None
        None: no pose at this sample (zeros, ``has_pose`` 0).
    w_hat : ndarray, shape (n_w,)
    model : plant.Model or its class
        Gives the layout; default planar (``[has_pose, theta, X, Y, M, f_x, f_y]``).

    Returns
    -------
    ndarray, shape (1 + n_pose + n_w,)
    """
    n_pose = len(model.pose_names)
    if pose is None:
        return np.concatenate([[0.0], np.zeros(n_pose), w_hat])
    return np.concatenate([[1.0], pose, w_hat])
