"""The paper's error metric, eq. (16), and a convergence time."""

import numpy as np

from plant._checks import as_finite_array

__all__ = ["calibration_error", "error_history", "convergence_time", "CONVERGENCE_THRESHOLD"]

#: Default threshold on E for :func:`convergence_time`.
CONVERGENCE_THRESHOLD = 0.05


def calibration_error(S_hat, S):
    """Eq. (16): ``E = ||I - S_hat S^-1||_2``, the induced 2-norm.

    Parameters
    ----------
    S_hat, S : array_like, shape (3, 3)
        Estimate and true calibration matrix.

    Returns
    -------
    float
        The largest singular value of ``I - S_hat S^-1``.

    Examples
    --------
    >>> calibration_error(np.eye(3), np.eye(3))
    0.0
    """
    S_hat = as_finite_array(S_hat, (3, 3), "S_hat")
    S = as_finite_array(S, (3, 3), "S")
    return float(np.linalg.norm(np.eye(3) - S_hat @ np.linalg.inv(S), 2))


def error_history(S_hat_history, S_true):
    """E of eq. (16) at every sample.

    Parameters
    ----------
    S_hat_history : ndarray, shape (N, 3, 3)
    S_true : ndarray, shape (3, 3) or (N, 3, 3)
        The true ``S``, constant or at each sample.

    Returns
    -------
    ndarray, shape (N,)
    """
    S_true = np.broadcast_to(S_true, np.shape(S_hat_history))
    D = np.eye(3) - S_hat_history @ np.linalg.inv(S_true)
    return np.linalg.norm(D, ord=2, axis=(1, 2))


def convergence_time(t, E, threshold=CONVERGENCE_THRESHOLD):
    """First time after which E stays below ``threshold`` for the rest of the run.

    Parameters
    ----------
    t : ndarray, shape (N,)
    E : ndarray, shape (N,)
    threshold : float

    Returns
    -------
    float or None
        None where E never settles below the threshold (or ends above it).
    """
    above = np.nonzero(np.asarray(E) >= threshold)[0]
    if len(above) == 0:
        return float(t[0])
    if above[-1] == len(E) - 1:
        return None
    return float(t[above[-1] + 1])
