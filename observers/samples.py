"""Checks and packing of one live sample for :meth:`observers.Observer.step`."""

import numpy as np

from fmscal.plant._checks import as_finite_array, as_number
from fmscal.plant.errors import FmscalError

from .state import INPUT

__all__ = ["check_sample", "pack_input"]


def check_sample(dt, pose, w_hat, first):
    """Validate one live sample for :meth:`Observer.step`; return ``(pose, w_hat)`` as arrays.

    Raises
    ------
    FmscalError
        ``w_hat`` not 3 finite numbers, ``pose`` neither None nor 3 finite
        numbers, no pose on the first sample, or ``dt`` not positive after it.
    """
    if not first or dt is not None:
        dt = as_number(dt, "dt")
    w_hat = _three(w_hat, "w_hat must be 3 finite numbers")
    if pose is not None:
        pose = _three(pose, "pose must be 3 finite numbers or None")
    if first:
        if pose is None:
            raise FmscalError("the first sample after reset() needs a pose measurement")
    elif not (np.isfinite(dt) and dt > 0):
        raise FmscalError(f"dt must be positive; got {dt!r}")
    return pose, w_hat


def _three(value, rule):
    """``value`` as 3 finite floats (text refused), or FmscalError stating ``rule``."""
    try:
        return as_finite_array(value, (3,), "")
    except FmscalError:
        raise FmscalError(f"{rule}; got {value!r}"[:200]) from None


def pack_input(pose, w_hat):
    """One step's input ``[has_pose, theta, X, Y, M, f_x, f_y]`` (:data:`observers.state.INPUT`).

    Parameters
    ----------
    pose : ndarray, shape (3,), or None
        None: no pose at this sample (zeros, ``has_pose`` 0).
    w_hat : ndarray, shape (3,)

    Returns
    -------
    ndarray, shape (7,)
    """
    if pose is None:
        return INPUT.pack(None, has_pose=0.0, pose=np.zeros(3), w_hat=w_hat)
    return INPUT.pack(None, has_pose=1.0, pose=pose, w_hat=w_hat)
