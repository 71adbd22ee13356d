"""Logs for the compensation's tests and benchmark: another log of the same rig, and a contact added.

A scenario draws ``S`` and ``b`` with its seed; a calibration from one seed is used on another log of the
same sensor by moving that log's readings onto the first sensor (:func:`same_rig`). A contact is a wrench
the environment applies to the tool while the motion is imposed: the mount then applies ``W_p - w_c``
(:func:`with_contact`).
"""

import numpy as np

from fmscal.plant import Log


def same_rig(log, S_log, b_log, S, b):
    """``log``'s readings as the sensor ``(S, b)`` reads the same wrenches: ``S^-1 S_log (w_hat - b_log) + b``.

    The reading's noise becomes ``S^-1 S_log n``: compensated with ``S``, it is ``S_log n``, the noise the
    residual is measured against (:func:`noise_rms`).
    """
    w_hat = (log.w_hat - b_log) @ np.linalg.solve(S, S_log).T + b
    return Log(log.t, log.pose, w_hat, name=f"{log.name}-same-rig", model=log._model)


def noise_rms(S_log, wrench_sd):
    """The calibrated reading's noise per channel, ``sqrt(diag(S Sigma S^T))``."""
    return np.sqrt(np.diag(S_log @ np.diag(np.square(wrench_sd)) @ S_log.T))


def with_contact(log, S, wrench, start, duration):
    """``log`` with the environment's wrench ``wrench`` (sensor frame, at the sensor point) on the tool over
    ``[start, start + duration)``: the reading loses ``S^-1 wrench`` there. Returns the log and the mask."""
    on = (log.t >= start) & (log.t < start + duration)
    w_hat = log.w_hat.copy()
    w_hat[on] -= np.linalg.solve(S, np.asarray(wrench, dtype=float))
    return Log(log.t, log.pose, w_hat, name=f"{log.name}-contact", model=log._model), on


def contact_wrench(force=15.0, direction=(0.6, 0.0, -0.8), point=(0.0, 0.0, 0.12)):
    """A force of ``force`` N along ``direction`` at ``point`` (m, sensor frame): ``[r x f, f]``."""
    f = force * np.asarray(direction) / np.linalg.norm(direction)
    return np.r_[np.cross(point, f), f]
