"""The drift scenario's measurements, for the compensation's tests and benchmarks.

The logs come from :mod:`fmscal.plant.scenarios` (``same_rig``, ``with_contact``, ``with_drift``,
``with_push``, ``drift_contact_log``; re-exported here for the files that import them from this module):
another log of the same rig, a contact, a temperature-like offset drift, a slow push. This module adds the
noise the residual is measured against (:func:`noise_rms`) and the drift scenario of issue 38, run and
measured (:func:`drift_run`).
"""

import numpy as np

from fmscal.analysis import compensate
from fmscal.plant.scenarios import (contact_wrench, drift_contact_log, same_rig, with_contact, with_drift,  # noqa: F401
                                    with_push)


def noise_rms(S_log, wrench_sd):
    """The calibrated reading's noise per channel, ``sqrt(diag(S Sigma S^T))``: a log moved onto another sensor
    by ``same_rig`` and compensated with its ``S`` has the noise ``S_log n``."""
    return np.sqrt(np.diag(S_log @ np.diag(np.square(wrench_sd)) @ S_log.T))


#: The drift scenario's contact (15 N for 2 s from 30 s) and slow push (10 N over 10 s from 40 s).
DRIFT_CONTACT = (30.0, 2.0)
DRIFT_PUSH = (40.0, 10.0)


def drift_run(cal, S, b, log, log_S, log_b, wrench_sd, seed, intensity, causal, push=True):
    """The drift scenario on ``log`` (another log of the rig, moved onto the sensor ``(S, b)``): a drift
    and a 15 N contact of 2 s (``drift_contact_log``); the same with a slow push of 10 N over 10 s instead. Compensated
    with ``track_offset`` at ``intensity`` (per channel, per sqrt(s)). Returns a dict: ``residual`` (rms after
    the first 5 s outside the contact, per channel, over the noise times S), ``coverage`` (per channel: the
    share of samples whose true offset is within the 95 % interval), ``contact_error`` (relative, the mean over
    the contact's samples), ``contact_flagged``, ``push_taken`` (the share of the push's wrench the offset has
    taken at its end: ``-(S Delta b) . w / |w|^2``, ``Delta b`` the offset estimate's error) and
    ``push_flagged`` (the share of the push's samples flagged) and ``push_coverage`` (as ``coverage``, on the
    log with the push); those left out where ``push`` is False.
    ``intensity``, ``push_intensity``: the intensity each compensation used (``compensate``'s result; fitted where
    ``intensity`` is ``"fit"``, or None offline)."""
    base = same_rig(log, log_S, log_b, S, b)
    wrench = contact_wrench(15.0)
    touched, change, applied = drift_contact_log(base, S, contact=wrench, contact_at=DRIFT_CONTACT, seed=seed)
    on = applied.any(axis=1)
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
    out["intensity"] = c.drift_intensity
    if not push:
        return out
    push = contact_wrench(10.0, direction=(0.0, 0.6, -0.8))
    pushed, change, _ = drift_contact_log(base, S, push=push, push_at=DRIFT_PUSH, seed=seed)
    p = compensate(cal, pushed, causal=causal, track_offset=True, drift_intensity=intensity)
    idx = np.searchsorted(pushed.t, np.round(p.t, 9))
    end = int(np.searchsorted(p.t, sum(DRIFT_PUSH))) - 1
    error = S @ (p.offset[end] - (b + change[idx[end]]))
    out["push_taken"] = float(-error @ push / (push @ push))
    during = (p.t >= DRIFT_PUSH[0]) & (p.t < sum(DRIFT_PUSH))
    out["push_flagged"] = p.contact[during].mean()
    out["push_coverage"] = np.mean(np.abs(p.offset - (b + change[idx])) <= 1.959964 * p.offset_sd, axis=0)
    out["push_intensity"] = p.drift_intensity
    return out
