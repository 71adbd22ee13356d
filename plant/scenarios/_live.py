"""Logs for compensation on a running robot: another log of the same rig, a contact, a drifting offset.

A scenario draws ``S`` and ``b`` with its seed, so two logs of one scenario are two sensors. A calibration
from one of them is used on another log of the same sensor by moving that log's readings onto the first
sensor (:func:`same_rig`). The reading is ``w_hat = S^-1 w + b + n`` (``w`` the wrench the mount applies to
the payload, :mod:`fmscal.plant.scenarios`); on top of a log of free motion:

- a **contact** is a wrench ``w_c`` the environment applies to the tool while the motion is imposed: the
  mount then applies ``w - w_c``, and the reading loses ``S^-1 w_c`` (:func:`with_contact`; rising linearly,
  a slow push, :func:`with_push`);
- a **drift** is a temperature-like change of the offset, the calibrated reading moved by
  ``d (1 - exp(-t / tau))`` (:func:`with_drift`);

and :func:`drift_contact_log` puts them together as issue 38's drift scenario does: a drift of up to 2 N and
0.05 N m with a time constant of 15 s, and a 15 N contact of 2 s at 30 s.

A **grasp** (:func:`with_grasp`) changes the payload itself: the scenario drawn twice with one seed (one motion,
one sensor, one noise), with its tool and with the tool holding a part, the readings passing from the first to the
second over :data:`GRASP_RAMP` (the part's weight taken up as it lifts off).

Every function here takes the readings in the toolkit's convention, ``reading="reaction"`` (the wrench the
mount applies to the payload, as the scenarios write them): the contact is subtracted and the drift added
with that sign. A log of a sensor that reads the other way (``"load"``, :func:`fmscal.plant.io.reading_sign`
``= -1``) is turned first (``w_hat`` times that sign) and back after, as the sign applies to the reading.
"""

import numpy as np

from fmscal.plant.io import Log
from fmscal.plant.numerics import FmscalError
from fmscal.plant.physics import SpatialPayload

__all__ = ["same_rig", "contact_wrench", "with_contact", "with_push", "with_drift", "drift_contact_log",
           "with_grasp", "DRIFT_SIZE", "DRIFT_TAU", "GRASP_RAMP"]

#: The drift's size per channel of a 6-axis reading (tx, ty, tz in N m; fx, fy, fz in N): issue 38's scenario.
DRIFT_SIZE = (0.05, 0.05, 0.05, 2.0, 2.0, 2.0)
#: The drift's time constant, s.
DRIFT_TAU = 15.0
#: A grasp's duration, s: the part's weight taken up linearly over it.
GRASP_RAMP = 0.1


class ScenarioInputError(FmscalError):
    """A scenario's argument of the wrong shape or value: the message names it."""


def _square(S, log):
    """``S`` as an (n_w, n_w) array for ``log``'s reading, checked."""
    S = np.asarray(S, dtype=float)
    n = log.w_hat.shape[1]
    if S.shape != (n, n) or not np.isfinite(S).all():
        raise ScenarioInputError(f"S must be a finite {n}x{n} matrix for {log.name}'s reading; got shape {S.shape}")
    return S


def _wrench(wrench, log, what="the wrench"):
    """``wrench`` as an (n_w,) array for ``log``'s reading, checked."""
    wrench = np.asarray(wrench, dtype=float)
    n = log.w_hat.shape[1]
    if wrench.shape != (n,) or not np.isfinite(wrench).all():
        raise ScenarioInputError(f"{what} must be {n} finite numbers for {log.name}'s reading; "
                                 f"got shape {wrench.shape}")
    return wrench


def same_rig(log, S_log, b_log, S, b):
    """``log``'s readings as the sensor ``(S, b)`` reads the same wrenches: ``S^-1 S_log (w_hat - b_log) + b``.

    The reading's noise becomes ``S^-1 S_log n``: compensated with ``S``, it is ``S_log n``.

    Parameters
    ----------
    log : plant.Log
        A log of the sensor ``(S_log, b_log)`` (a scenario's log and its truth).
    S_log, b_log : array_like
        That sensor's calibration matrix (n_w, n_w) and offset (n_w,).
    S, b : array_like
        The sensor the readings are moved onto.

    Returns
    -------
    plant.Log
    """
    S, S_log = _square(S, log), _square(S_log, log)
    w_hat = (log.w_hat - _wrench(b_log, log, "b_log")) @ np.linalg.solve(S, S_log).T + _wrench(b, log, "b")
    return Log(log.t, log.pose, w_hat, name=f"{log.name}-same-rig", model=log._model)


def contact_wrench(force=15.0, direction=(0.6, 0.0, -0.8), point=(0.0, 0.0, 0.12)):
    """A force of ``force`` N along ``direction`` applied at ``point`` (m, sensor frame), as a 6-axis wrench at
    the sensor point: ``[r x f, f]``.

    Returns
    -------
    ndarray, shape (6,)
        N m and N.
    """
    f = force * np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    return np.r_[np.cross(point, f), f]


def with_contact(log, S, wrench, start, duration):
    """``log`` with the environment's wrench ``wrench`` (sensor frame, at the sensor point) on the tool over
    ``[start, start + duration)``: the reading loses ``S^-1 wrench`` there.

    Returns
    -------
    log : plant.Log
    on : ndarray of bool, shape (N,)
        The samples in contact.
    """
    S, wrench = _square(S, log), _wrench(wrench, log)
    on = (log.t >= start) & (log.t < start + duration)
    w_hat = log.w_hat.copy()
    w_hat[on] -= np.linalg.solve(S, wrench)
    return Log(log.t, log.pose, w_hat, name=f"{log.name}-contact", model=log._model), on


def with_push(log, S, wrench, start, duration):
    """``log`` with a contact rising linearly from 0 to ``wrench`` over ``[start, start + duration)``, then
    released: the reading loses ``S^-1 wrench (t - start) / duration`` there.

    Returns
    -------
    log : plant.Log
    applied : ndarray, shape (N, n_w)
        The environment's wrench on the tool per sample.
    """
    S, wrench = _square(S, log), _wrench(wrench, log)
    ramp = np.clip((log.t - start) / duration, 0.0, 1.0) * ((log.t >= start) & (log.t < start + duration))
    w = np.outer(ramp, wrench)
    return Log(log.t, log.pose, log.w_hat - np.linalg.solve(S, w.T).T, name=f"{log.name}-push",
               model=log._model), w


def with_drift(log, S, size=DRIFT_SIZE, tau=DRIFT_TAU, seed=0):
    """``log`` with a temperature-like offset drift: the calibrated reading moves by ``d (1 - exp(-t / tau))``
    (``t`` from the log's start; ``d`` each channel's ``size`` with a seeded random sign), i.e. the raw offset
    by ``S^-1 d (1 - exp(-t / tau))``.

    Parameters
    ----------
    log : plant.Log
    S : array_like, shape (n_w, n_w)
        The sensor's calibration matrix.
    size : sequence of n_w floats
        The drift's final size per channel, the calibrated reading's units (default :data:`DRIFT_SIZE`, a
        6-axis reading's).
    tau : float
        The time constant, s.
    seed : int
        Draws the signs.

    Returns
    -------
    log : plant.Log
    change : ndarray, shape (N, n_w)
        The raw offset's change per sample: the true offset is the sensor's ``b`` plus it.
    """
    S = _square(S, log)
    size = _wrench(size, log, "the drift's size")
    if not (isinstance(tau, (int, float)) and tau > 0):
        raise ScenarioInputError(f"tau must be a positive number of seconds; got {tau!r}")
    sign = np.random.default_rng(seed).choice([-1.0, 1.0], size=len(size))
    d = np.linalg.solve(S, sign * size)
    change = np.outer(1.0 - np.exp(-(log.t - log.t[0]) / tau), d)
    return Log(log.t, log.pose, log.w_hat + change, name=f"{log.name}-drift", model=log._model), change


def drift_contact_log(log, S, *, size=DRIFT_SIZE, tau=DRIFT_TAU, contact=None, contact_at=(30.0, 2.0),
                      push=None, push_at=(40.0, 10.0), seed=0):
    """Issue 38's drift scenario on a log of free motion: a temperature-like offset drift (:func:`with_drift`),
    a contact held for a while (:func:`with_contact`) and a slow push (:func:`with_push`), each where given.

    Parameters
    ----------
    log : plant.Log
        A log of free motion of the sensor ``S`` (e.g. moved onto it by :func:`same_rig`).
    S : array_like, shape (n_w, n_w)
    size, tau, seed
        The drift, as for :func:`with_drift`; ``size`` zeros for none.
    contact : array_like of n_w floats, optional
        The environment's wrench on the tool during the contact (sensor frame, at the sensor point; e.g.
        ``contact_wrench(15.0)``); None for none.
    contact_at : (float, float)
        The contact's start and duration, s.
    push : array_like of n_w floats, optional
        The slow push's final wrench, reached linearly; None for none.
    push_at : (float, float)
        The push's start and duration, s.

    Returns
    -------
    log : plant.Log
    change : ndarray, shape (N, n_w)
        The raw offset's change per sample (the true offset is the sensor's ``b`` plus it).
    applied : ndarray, shape (N, n_w)
        The environment's wrench on the tool per sample (zero where there is no contact).
    """
    out, change = with_drift(log, S, size=size, tau=tau, seed=seed)
    applied = np.zeros_like(change)
    if contact is not None:
        out, on = with_contact(out, S, contact, *contact_at)
        applied[on] += np.asarray(contact, dtype=float)
    if push is not None:
        out, w = with_push(out, S, push, *push_at)
        applied += w
    return out, change, applied


def with_grasp(scenario, seed, part, at, ramp=GRASP_RAMP):
    """A log of a spatial ``scenario`` whose tool grasps ``part`` at ``at`` s (module docstring).

    Parameters
    ----------
    scenario : plant.SpatialScenario
    seed : int
        As for its :meth:`~fmscal.plant.SpatialScenario.generate`: both draws share it.
    part : plant.SpatialPayload
        The part, its centre of mass and inertia in the sensor's frame.
    at, ramp : float
        The grasp's start and duration, s.

    Returns
    -------
    log : plant.Log
    truth : plant.Truth
        The tool's (``S``, the offset, the noise).
    total : plant.SpatialPayload
        The tool holding the part: the payload of their inertial parameters' sum.
    """
    part = SpatialPayload.check(part, "with_grasp")
    if not (isinstance(ramp, (int, float)) and ramp > 0):
        raise ScenarioInputError(f"ramp must be a positive number of seconds; got {ramp!r}")
    total = SpatialPayload.from_inertial_parameters(scenario.payload.inertial_parameters + part.inertial_parameters)
    before, truth, _ = scenario.generate(seed)
    after, _, _ = scenario.with_(payload=total).generate(seed)
    s = np.clip((before.t - at) / ramp, 0.0, 1.0)[:, None]
    return (Log(before.t, before.pose, (1 - s) * before.w_hat + s * after.w_hat, name=f"{before.name}-grasp"),
            truth, total)
