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


def with_drift(log, S, size=(0.05, 0.05, 0.05, 2.0, 2.0, 2.0), tau=15.0, seed=0):
    """``log`` with a temperature-like offset drift: the calibrated reading moves by
    ``d (1 - exp(-t / tau))`` (``d`` of each channel's ``size`` with a seeded random sign; N m and N), i.e.
    the raw offset by ``S^-1 d (1 - exp(-t / tau))``. Returns the log and the raw offset's change per sample
    (N, n_w)."""
    sign = np.random.default_rng(seed).choice([-1.0, 1.0], size=len(size))
    d = np.linalg.solve(S, sign * np.asarray(size, dtype=float))
    change = np.outer(1.0 - np.exp(-(log.t - log.t[0]) / tau), d)
    return Log(log.t, log.pose, log.w_hat + change, name=f"{log.name}-drift", model=log._model), change


def with_push(log, S, wrench, start, duration):
    """``log`` with a contact rising linearly from 0 to ``wrench`` over ``[start, start + duration)`` (then
    released): the reading loses ``S^-1 wrench (t - start) / duration`` there. Returns the log and the
    environment's wrench per sample (N, n_w)."""
    ramp = np.clip((log.t - start) / duration, 0.0, 1.0) * ((log.t >= start) & (log.t < start + duration))
    w = np.outer(ramp, np.asarray(wrench, dtype=float))
    return Log(log.t, log.pose, log.w_hat - np.linalg.solve(S, w.T).T, name=f"{log.name}-push",
               model=log._model), w
