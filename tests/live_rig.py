"""Logs for the compensation's tests and benchmark: another log of the same rig, and a contact added.

A scenario draws ``S`` and ``b`` with its seed; a calibration from one seed is used on another log of the
same sensor by moving that log's readings onto the first sensor (:func:`same_rig`). A contact is a wrench
the environment applies to the tool while the motion is imposed: the mount then applies ``W_p - w_c``
(:func:`with_contact`). The drift scenario of issue 38 (:func:`drift_run`): a temperature-like offset drift
(:func:`with_drift`), a contact, and a slow push (:func:`with_push`).
"""

import numpy as np

from fmscal.analysis import compensate
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


#: The drift scenario's contact (15 N for 2 s from 30 s) and slow push (10 N over 10 s from 40 s).
DRIFT_CONTACT = (30.0, 2.0)
DRIFT_PUSH = (40.0, 10.0)


def drift_run(cal, S, b, log, log_S, log_b, wrench_sd, seed, intensity, causal, push=True):
    """The drift scenario on ``log`` (another log of the rig, moved onto the sensor ``(S, b)``): a drift
    (:func:`with_drift`) and a 15 N contact of 2 s; the same with a slow push of 10 N over 10 s instead. Compensated
    with ``track_offset`` at ``intensity`` (per channel, per sqrt(s)). Returns a dict: ``residual`` (rms after
    the first 5 s outside the contact, per channel, over the noise times S), ``coverage`` (per channel: the
    share of samples whose true offset is within the 95 % interval), ``contact_error`` (relative, the mean over
    the contact's samples), ``contact_flagged``, ``push_taken`` (the share of the push's wrench the offset has
    taken at its end: ``-(S Delta b) . w / |w|^2``, ``Delta b`` the offset estimate's error) and
    ``push_flagged`` (the share of the push's samples flagged); those two left out where ``push`` is False."""
    base = same_rig(log, log_S, log_b, S, b)
    drifted, change = with_drift(base, S, seed=seed)
    wrench = contact_wrench(15.0)
    touched, on = with_contact(drifted, S, wrench, *DRIFT_CONTACT)
    ref = noise_rms(log_S, wrench_sd)
    out = {}
    c = compensate(cal, touched, causal=causal, track_offset=True, drift_intensity=intensity)
    idx = np.searchsorted(touched.t, np.round(c.t, 9))
    truth = b + change[idx]
    inside = on[idx]
    quiet = (c.t > 5.0) & ~inside & ~((c.t >= DRIFT_CONTACT[0] - 0.1) & (c.t < sum(DRIFT_CONTACT) + 0.1))
    out["residual"] = np.sqrt(np.mean(c.wrench[quiet] ** 2, axis=0)) / ref
    out["coverage"] = np.mean(np.abs(c.offset - truth) <= 1.959964 * c.offset_sd, axis=0)
    out["contact_error"] = np.linalg.norm(c.wrench[inside].mean(axis=0) - wrench) / np.linalg.norm(wrench)
    out["contact_flagged"] = c.contact[inside].mean()
    out["false_alarm"] = c.contact[quiet].mean()
    if not push:
        return out
    push = contact_wrench(10.0, direction=(0.0, 0.6, -0.8))
    pushed, _ = with_push(drifted, S, push, *DRIFT_PUSH)
    p = compensate(cal, pushed, causal=causal, track_offset=True, drift_intensity=intensity)
    idx = np.searchsorted(pushed.t, np.round(p.t, 9))
    end = int(np.searchsorted(p.t, sum(DRIFT_PUSH))) - 1
    error = S @ (p.offset[end] - (b + change[idx[end]]))
    out["push_taken"] = float(-error @ push / (push @ push))
    during = (p.t >= DRIFT_PUSH[0]) & (p.t < sum(DRIFT_PUSH))
    out["push_flagged"] = p.contact[during].mean()
    return out
