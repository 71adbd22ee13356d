"""What a method returns, and the algebra of the calibration entries ``[S | c]``.

Every method estimates ``S`` (``n_w x n_w``: 3x3 in the plane, 6x6 in space;
the model's :attr:`fmscal.plant.Model.n_w`), and with ``offset=True`` the
augmented ``[S | c]`` (``n_w x (n_w + 1)``) of ``w = S w_hat + c = S (w_hat -
b)``: the raw reading is augmented by a constant 1. The entries are kept flat
in row order.
"""

from dataclasses import dataclass, field

import numpy as np

__all__ = ["ObserverResult", "initial_calibration", "split_calibration", "calibration_uncertainty", "offset_from_c",
           "offset_std"]


@dataclass
class ObserverResult:
    """What an observer's :meth:`Observer.run` returns.

    Attributes
    ----------
    observer : str
        The method's name in the registry (:data:`observers.METHODS`).
    t : ndarray, shape (N,)
        Times, s. Shorter than the log's if the run diverged and stopped.
    S_hat : ndarray, shape (n_w, n_w)
        The final estimate of ``S`` (``n_w`` = 3 in the plane, the model's
        :attr:`fmscal.plant.Model.n_w`).
    S_hat_history : ndarray, shape (N, n_w, n_w)
    x_hat_history : ndarray, shape (N, nx)
        The motion state in the model's layout (planar: ``[theta, theta',
        X, X', Y, Y']``).
    S_std : ndarray, shape (n_w, n_w), or None
        One-sigma uncertainty of each entry, where the method has one.
    diverged : bool
        After the first second, an entry of ``S_hat`` left the divergence
        bound (20 times the scale of ``S0`` and of the data,
        :func:`observers.core.divergence_bound`), or at any time the
        estimate became non-finite; the run stopped at the last healthy step.
    converged : bool
        From the run alone (:class:`observers.Observer`, Notes): not
        diverged, the estimate settled over the last 20 % of the run
        (:func:`observers.settled`) after moving (an online
        method's left ``S0``, :func:`observers.core.moved`), the method's own
        checks of the log passed (least squares: excitation and consistency),
        and, where the method has an uncertainty, it is finite, non-zero and
        within :data:`observers.core._convergence.EVIDENCE_TOLERANCE` of
        ``S_hat``. A method without one (adaptive, high-gain) is judged on
        settling only; whether its log pinned ``S`` down is
        :func:`observers.diagnostics.has_evidence`, which the workflows ask.
    wall_time : float
        Seconds of computation, without the one-off build of a compiled step
        (its symbolic graph, C generation and loading; ``info["build_time"]``).
    info : dict
        Method-specific extras (noise estimates, fit diagnostics, ...).
    b : ndarray, shape (n_w,), or None
        The sensor's offset in ``w = S (w_hat - b)`` (N m, N), where the
        method was asked to estimate it; None otherwise.
    b_std : ndarray, shape (n_w,), or None
        Its one-sigma uncertainty, where the method has one.
    warnings : list of str
        What the method noticed about the log or its own run, one line each.
    cov : ndarray, shape (k, k), or None
        Covariance of the final estimate's entries ``[S | c]`` flat in row
        order (``k = n_w (n_w + 1)``; ``n_w^2``, ``S`` alone, without the
        offset), where the method has one and did not diverge.

    Examples
    --------
    >>> from fmscal.plant import PAPER_PAYLOAD, get_scenario
    >>> log, truth, _ = get_scenario("paper").with_(duration=2.0).generate(0)
    >>> from fmscal.observers import LeastSquares
    >>> result = LeastSquares(PAPER_PAYLOAD, offset=True).run(log)
    >>> result.observer, result.S_hat.shape, result.S_std.shape, result.b.shape
    ('least-squares', (3, 3), (3, 3), (3,))
    >>> len(result.S_hat_history) == len(log)
    True
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
    cov: np.ndarray = None


def initial_calibration(S0, offset):
    """The calibration entries an estimator starts from: ``S0``, or ``[S0 | 0]`` with the offset.

    Returns
    -------
    ndarray, shape (n_w^2,) or (n_w (n_w + 1),)
        Row order.
    """
    S0 = np.asarray(S0, dtype=float)
    return np.column_stack([S0, np.zeros(len(S0))]).ravel() if offset else np.ravel(S0)


def split_calibration(history, n_cols, offset=None):
    """``S_hat`` history and the final offset from a history of ``[S_hat | c_hat]``.

    Parameters
    ----------
    history : ndarray, shape (N, n_w n_cols)
        Calibration entries in row order, per sample.
    n_cols : int
        ``n_w``, or ``n_w + 1`` with the offset column.
    offset : bool, optional
        Whether the last column is the offset; default: ``n_cols`` is 4 (planar) .

    Returns
    -------
    S_history : ndarray, shape (N, n_w, n_w)
    b : ndarray, shape (n_w,), or None
        :func:`offset_from_c` of the last sample; None without the offset.
    """
    n_w = n_cols - 1 if (offset if offset is not None else n_cols == 4) else n_cols
    aug = np.asarray(history).reshape(len(history), n_w, n_cols)
    S_hist = aug[:, :, :n_w]
    return S_hist, (offset_from_c(S_hist[-1], aug[-1, :, n_w]) if n_cols > n_w else None)


def calibration_uncertainty(S_aug, cov, offset):
    """``S_std``, ``b`` and ``b_std`` of an estimate of ``[S | c]`` and its covariance: every method's, in one place.

    Parameters
    ----------
    S_aug : ndarray, shape (n_w, n)
        ``[S | c]`` (``n = n_w + 1``) or ``S`` (``n = n_w``).
    cov : ndarray, shape (n_w n, n_w n), or None
        Covariance of its entries, row order.
    offset : bool
        The last column is the offset ``c``.

    Returns
    -------
    S_std : ndarray, shape (n_w, n_w), or None
        None without a covariance.
    b, b_std : ndarray, shape (n_w,), or None
        None without the offset (``b_std`` also without a covariance).
    """
    S_aug = np.asarray(S_aug, dtype=float)
    n_w, n = S_aug.shape
    S = S_aug[:, :n_w]
    b = offset_from_c(S, S_aug[:, n_w]) if offset else None
    if cov is None:
        return None, b, None
    S_std = np.sqrt(np.maximum(np.diag(cov), 0)).reshape(n_w, n)[:, :n_w]
    return S_std, b, (offset_std(S, b, cov) if offset else None)


def offset_from_c(S, c):
    """The sensor's offset ``b = -S^-1 c`` from ``w = S w_hat + c = S (w_hat - b)``; shape (n_w,).

    NaN where ``S`` is singular (the offset is then undefined).
    """
    try:
        return -np.linalg.solve(S, c)
    except np.linalg.LinAlgError:
        return np.full(len(c), np.nan)


def offset_std(S, b, cov_aug):
    """One-sigma uncertainty of ``b = -S^-1 c``, linearised.

    ``db = -S^-1 (dc + dS b)``: the column of entry ``(i, j)`` of ``[S | c]``
    is ``-S^-1 e_i`` times ``b_j`` (``j < n_w``) or 1 (the offset column).

    Parameters
    ----------
    S : ndarray, shape (n_w, n_w)
    b : ndarray, shape (n_w,)
    cov_aug : ndarray, shape (n_w (n_w + 1), n_w (n_w + 1))
        Covariance of ``[S | c]`` in row order.

    Returns
    -------
    ndarray, shape (n_w,)
        NaN where ``S`` is singular (as :func:`offset_from_c`).
    """
    try:
        S_inv = np.linalg.inv(S)
    except np.linalg.LinAlgError:
        return np.full(len(b), np.nan)
    k = len(b)
    J = np.zeros((k, k * (k + 1)))
    for i in range(k):
        for j in range(k + 1):
            J[:, (k + 1) * i + j] = -S_inv[:, i] * (b[j] if j < k else 1.0)
    cov_aug = np.asarray(cov_aug, dtype=float)
    if not np.isfinite(cov_aug).all():   # an undetermined part (an infinite variance): its offsets undetermined
        cov_aug = np.where(np.isfinite(cov_aug), cov_aug, np.inf)
        with np.errstate(invalid="ignore"):
            var = np.diag(J @ cov_aug @ J.T)
        return np.sqrt(np.where(np.isnan(var), np.inf, np.maximum(var, 0)))
    return np.sqrt(np.maximum(np.diag(J @ cov_aug @ J.T), 0))
