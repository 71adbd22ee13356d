"""How much a log says about ``S``: the evidence a method without an uncertainty of its own lacks.

The adaptive and high-gain observers give no ``S_std``; their run's
``converged`` flag says only that the estimate settled
(:class:`observers.Observer`, Notes). The workflow that decides convergence
adds the evidence, :func:`has_evidence`: for such a method, a least-squares
fit of the same log (:class:`observers.LeastSquares`) must find every
direction of ``S`` excited (the fit's excitation check) and pinned down to
:data:`observers.core._convergence.EVIDENCE_TOLERANCE`. Information only
grows with data, so a prefix that already holds enough answers for the whole
log.
"""

import numpy as np

from fmscal.plant.numerics import FmscalError
from fmscal.plant.physics import as_model

from fmscal.observers.batch import EXCITATION_COND_LIMIT, LeastSquares
from fmscal.observers.core import EVIDENCE_TOLERANCE, informed

__all__ = ["has_evidence", "log_uncertainty", "EVIDENCE_PREFIX"]

#: Seconds of the log fitted first; the whole log only where they do not hold enough.
EVIDENCE_PREFIX = 20.0


def log_uncertainty(log, model, offset=False, enough=None, prefix=EVIDENCE_PREFIX):
    """The relative one-sigma uncertainty of ``S`` that a least-squares fit of the log leaves.

    Parameters
    ----------
    log : plant.Log
    model : plant.Model or plant.Payload
    offset : bool
        Fit the sensor's offset too (as the method that asks did).
    enough : float, optional
        An uncertainty that suffices: where the first ``prefix`` s already
        reach it, the rest of the log is not fitted.
    prefix : float
        s.

    Returns
    -------
    float
        ``||S_std||_2 / ||S_hat||_2`` of the fit (eq. 16's norm);
        ``inf`` where the log is too short for the fit or does not excite
        every entry (information condition number above
        :data:`observers.batch._least_squares.EXCITATION_COND_LIMIT`).
    """
    fit = LeastSquares(model, offset=offset)
    parts = [log]
    if enough is not None and log.duration > 2 * prefix:
        parts.insert(0, log.between(log.t[0], log.t[0] + prefix))
    for part in parts:
        try:
            result = fit.run(part)
        except (FmscalError, np.linalg.LinAlgError):
            value = np.inf
        else:
            # planar: the fit's excitation check; spatial (a batch fit with no report): its undetermined directions
            poor = (bool(result.info["undetermined"]) if "undetermined" in result.info
                    else not fit.report.information_cond <= EXCITATION_COND_LIMIT)
            value = np.inf if poor or result.S_std is None else float(
                np.linalg.norm(result.S_std, 2) / max(np.linalg.norm(result.S_hat, 2), 1e-300))
        if enough is None or value <= enough:
            return value
    return value


def has_evidence(result, log, model, offset=False, tolerance=EVIDENCE_TOLERANCE):
    """Whether the log pinned ``S`` down for a result: the second half of a workflow's ``converged``.

    A workflow's convergence is ``result.converged and has_evidence(result, log, model, offset)``
    (:class:`observers.Observer`, Notes). Where the method reported an
    uncertainty, it is its own: ``||S_std||_2 <= tolerance ||S_hat||_2``
    (:func:`observers.core.informed`), the check :meth:`observers.Observer.run`
    already made. Where it reported none, a least-squares fit of the log
    (:func:`log_uncertainty`) must excite every direction of ``S`` and leave a
    relative uncertainty of at most ``tolerance``. Both are judged in the
    reading's own scale where the model has one
    (:meth:`fmscal.plant.Model.reading_scale`; 3D: N m and N), entry ``(i, j)``
    of ``S`` times ``scale_j / scale_i``.

    Parameters
    ----------
    result : observers.ObserverResult
        A run of ``log``.
    log : plant.Log
        The log the method ran on (after any shift of its poses).
    model : plant.Model, plant.Payload or plant.SpatialPayload
        The method's model (``observer.model``).
    offset : bool
        The method estimated the sensor's offset (``observer.offset``); the
        least-squares fit then does too.
    tolerance : float
        Largest relative one-sigma uncertainty, ``||S_std||_2 / ||S_hat||_2``.

    Returns
    -------
    bool
        False for a diverged result.
    """
    if result.diverged:
        return False
    model = as_model(model, "has_evidence")
    if result.S_std is None:
        return bool(log_uncertainty(log, model, offset, enough=tolerance) <= tolerance)
    S_hat, S_std = np.asarray(result.S_hat, dtype=float), np.asarray(result.S_std, dtype=float)
    scale = model.reading_scale(log)
    if scale is not None:
        ratio = scale[None, :] / scale[:, None]
        S_hat, S_std = S_hat * ratio, S_std * ratio
    return informed(S_hat, S_std, tolerance)
