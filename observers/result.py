"""What a method returns, and the algebra of the calibration entries ``[S | c]``.

Every method estimates ``S`` (3x3), and with ``offset=True`` the augmented
``[S | c]`` (3x4) of ``w = S w_hat + c = S (w_hat - b)``: the raw reading is
augmented by a constant 1. The entries are kept flat in row order.
"""

from dataclasses import dataclass, field

import numpy as np

__all__ = ["ObserverResult", "initial_calibration", "split_calibration", "offset_from_c", "offset_std"]


@dataclass
class ObserverResult:
    """What an observer's :meth:`Observer.run` returns.

    Attributes
    ----------
    observer : str
        The method's name in the registry (:data:`observers.METHODS`).
    t : ndarray, shape (N,)
        Times, s. Shorter than the log's if the run diverged and stopped.
    S_hat : ndarray, shape (3, 3)
        The final estimate of ``S``.
    S_hat_history : ndarray, shape (N, 3, 3)
    x_hat_history : ndarray, shape (N, 6)
        ``[theta, theta', X, X', Y, Y']``.
    S_std : ndarray, shape (3, 3), or None
        One-sigma uncertainty of each entry, where the method has one.
    diverged : bool
        After the first second, an entry of ``S_hat`` left the divergence
        bound (20 times the scale of ``S0`` and of the data,
        :func:`observers.convergence.divergence_bound`), or at any time the
        estimate became non-finite; the run stopped at the last healthy step.
    converged : bool
        Not diverged, the estimate settled over the last 20 % of the run
        (:func:`observers.convergence.settled`) after moving (an online
        method's left ``S0``, :func:`observers.convergence.moved`), the log
        pinned ``S`` down (its uncertainty, the method's own or else a
        least-squares fit's, within
        :data:`observers.convergence.EVIDENCE_TOLERANCE`;
        :meth:`observers.Observer._evidence`), its uncertainty (where it
        has one) finite and non-zero, and the method's own checks of the log
        passed (least squares: excitation and consistency).
    wall_time : float
        Seconds of computation, without the one-off build of a compiled step
        (its symbolic graph, C generation and loading; ``info["build_time"]``)
        and without the least-squares fit that gives a method without an
        uncertainty its evidence (:mod:`observers.evidence`).
    info : dict
        Method-specific extras (noise estimates, fit diagnostics, ...).
    b : ndarray, shape (3,), or None
        The sensor's offset in ``w = S (w_hat - b)`` (N m, N), where the
        method was asked to estimate it; None otherwise.
    b_std : ndarray, shape (3,), or None
        Its one-sigma uncertainty, where the method has one.
    warnings : list of str
        What the method noticed about the log or its own run, one line each.
    """

    observer: str
    t: np.ndarray
    S_hat: np.ndarray
    S_hat_history: np.ndarray
    x_hat_history: np.ndarray
    S_std: np.ndarray = None
    diverged: bool = False
    converged: bool = False
    wall_time: float = 0.0
    info: dict = field(default_factory=dict)
    b: np.ndarray = None
    b_std: np.ndarray = None
    warnings: list = field(default_factory=list)


def initial_calibration(S0, offset):
    """The calibration entries an estimator starts from: ``S0``, or ``[S0 | 0]`` with the offset.

    Returns
    -------
    ndarray, shape (9,) or (12,)
        Row order.
    """
    return np.column_stack([S0, np.zeros(3)]).ravel() if offset else np.ravel(S0)


def split_calibration(history, n_cols):
    """``S_hat`` history and the final offset from a history of ``[S_hat | c_hat]``.

    Parameters
    ----------
    history : ndarray, shape (N, 3 n_cols)
        Calibration entries in row order, per sample.
    n_cols : int
        3, or 4 with the offset column.

    Returns
    -------
    S_history : ndarray, shape (N, 3, 3)
    b : ndarray, shape (3,), or None
        :func:`offset_from_c` of the last sample; None without the offset.
    """
    aug = history.reshape(-1, 3, n_cols)
    S_hist = aug[:, :, :3]
    return S_hist, (offset_from_c(S_hist[-1], aug[-1, :, 3]) if n_cols == 4 else None)


def offset_from_c(S, c):
    """The sensor's offset ``b = -S^-1 c`` from ``w = S w_hat + c = S (w_hat - b)``; shape (3,).

    NaN where ``S`` is singular (the offset is then undefined).
    """
    try:
        return -np.linalg.solve(S, c)
    except np.linalg.LinAlgError:
        return np.full(3, np.nan)


def offset_std(S, b, cov_aug):
    """One-sigma uncertainty of ``b = -S^-1 c``, linearised.

    ``db = -S^-1 (dc + dS b)``: the column of entry ``(i, j)`` of ``[S | c]``
    is ``-S^-1 e_i`` times ``b_j`` (``j < 3``) or 1 (the offset column).

    Parameters
    ----------
    S : ndarray, shape (3, 3)
    b : ndarray, shape (3,)
    cov_aug : ndarray, shape (12, 12)
        Covariance of ``[S | c]`` in row order.

    Returns
    -------
    ndarray, shape (3,)
        NaN where ``S`` is singular (as :func:`offset_from_c`).
    """
    try:
        S_inv = np.linalg.inv(S)
    except np.linalg.LinAlgError:
        return np.full(3, np.nan)
    J = np.zeros((3, 12))
    for i in range(3):
        for j in range(4):
            J[:, 4 * i + j] = -S_inv[:, i] * (b[j] if j < 3 else 1.0)
    return np.sqrt(np.maximum(np.diag(J @ cov_aug @ J.T), 0))
