"""How much a log says about ``S``, for a method that reports no uncertainty of its own.

The adaptive and high-gain observers give no ``S_std``; their ``converged``
flag takes the evidence from a least-squares fit of the same log
(:class:`observers.LeastSquares`): the log must excite every direction of
``S`` (the fit's excitation check) and pin it down to
:data:`observers.core._convergence.EVIDENCE_TOLERANCE`. Information only grows
with data, so a prefix that already holds enough answers for the whole log.
"""

import numpy as np

from fmscal.plant.numerics._errors import FmscalError

from fmscal.observers.batch._least_squares import EXCITATION_COND_LIMIT, LeastSquares

__all__ = ["log_uncertainty", "EVIDENCE_PREFIX"]

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
                    else not fit.report["information_cond"] <= EXCITATION_COND_LIMIT)
            value = np.inf if poor or result.S_std is None else float(
                np.linalg.norm(result.S_std, 2) / max(np.linalg.norm(result.S_hat, 2), 1e-300))
        if enough is None or value <= enough:
            return value
    return value
