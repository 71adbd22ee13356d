"""The covariance of a fit to a log: cluster-robust over blocks of time, the blocks chosen from the residuals.

A log's samples are not independent: the differentiated poses share their
errors over the smoothing window, and a drift or a slow model error
correlates the residuals for longer. The covariance of a weighted least
squares fit ``theta = (J^T J)^+ J^T e`` (``J`` the weighted design) is the
cluster-robust sandwich over blocks of time of length ``L``, with the
small-sample factor of Stata's CR1::

    tau = 1 + 2 sum_{k=1}^{K} rho_k,   K the first lag with K >= 5 tau(K)        (U1)
    L   = max(window, 5 tau dt)                                                (U2)
    cov = G / (G - 1) (N - 1) / (N - K) B (sum_b s_b s_b^T) B,   B = (J^T J)^+   (U3)

``rho_k`` the residuals' autocorrelation at lag ``k`` (the channels'
average), ``dt`` the sample interval, ``s_b`` a block's ``J^T e``, ``G``
the blocks, ``N`` the rows, ``K`` (in (U3)) the parameters determined.

Why: the sandwich over ``G`` blocks estimates the variance from ``G``
scores, so it falls short by about ``(G - 1) / G`` and is itself noisy with
``G - 1`` degrees of freedom; with 1 s blocks a 5 s log has five, and its
z-scores (error over the reported uncertainty) run well above 1 (what they are
over seeds: ``tests/test_spatial_floor.py``, docs/guide/spatial.md). Blocks
of five correlation times (U2) miss at most a tenth
of the variance across their borders (``tau / (2 L)`` for an exponential
correlation); white residuals get blocks of the smoothing window, 25 in 5 s.

A test of numbers ``x`` against such a covariance ``C`` is Hotelling's
``T^2`` over its ``G`` blocks, scaled to an ``F``, on the ``k`` directions
``C`` determines (its correlation matrix's eigenvalues above ``1e-10`` of
the largest)::

    X2 = x^T C^+ x,   (G - k) / (k (G - 1)) X2 ~ F(k, G - k)                     (U4)

chi-square's tail is too thin where the blocks are few; with ``G`` at most
``k + 1`` there is no test (p-value 1).
"""

import numpy as np
from scipy.fft import next_fast_len
from scipy.stats import f as f_dist

__all__ = ["weighted_fit", "pseudo_inverse", "sandwich", "small_sample_factor", "correlation_time", "block_length",
           "time_blocks", "few_blocks", "hotelling", "MIN_BLOCKS"]

#: Fewer blocks than this and the variance itself has under nine degrees of freedom: z-scores then run
#: above 1.13 of their rms (``sqrt((G - 1) / (G - 3))``) and the fit warns.
MIN_BLOCKS = 10


def weighted_fit(X, y, weights, blocks=None):
    """Weighted least squares ``y ~ X theta``, with the cluster-robust covariance over ``blocks`` (None: none).

    Parameters
    ----------
    X : ndarray, shape (N, p)
        The design.
    y : ndarray, shape (N,)
        The observations.
    weights : ndarray, shape (N,)
        Each row's weight (one over its noise's standard deviation).
    blocks : ndarray of int, shape (N,), optional
        Each row's block of time (:func:`time_blocks`).

    Returns
    -------
    theta : ndarray, shape (p,)
    cov : ndarray, shape (p, p) or None
        Eq. (U3) (:func:`sandwich`); None without ``blocks``.
    residual : ndarray, shape (N,)
        ``y - X theta``, unweighted.
    """
    Xw = X * weights[:, None]
    inverse, columns = pseudo_inverse(Xw)
    theta = inverse @ (Xw.T @ (y * weights))
    cov = None if blocks is None else sandwich(Xw, (y - X @ theta) * weights, blocks, inverse, columns)
    return theta, cov, y - X @ theta


def correlation_time(residual):
    """The integrated correlation time of residuals, in samples (1 for white noise), eq. (U1).

    ``tau = 1 + 2 sum_{k=1}^{K} rho_k`` with ``rho_k`` the autocorrelation at
    lag ``k`` averaged over the channels (each channel's mean removed and its
    variance scaled to one), summed up to the first ``K >= 5 tau(K)``
    (Sokal's automatic window: long enough to take the correlation in, short
    enough to leave out the estimate's noise at long lags).

    Parameters
    ----------
    residual : ndarray, shape (N, c)
        Residuals of ``c`` channels at ``N`` evenly spaced samples.

    Returns
    -------
    float
    """
    r = residual - residual.mean(axis=0)
    r = r / np.maximum(r.std(axis=0), 1e-300)
    n = len(r)
    size = next_fast_len(2 * n, real=True)      # zero-padded past 2n - 1: the linear autocorrelation, at FFT speed
    spectrum = np.fft.rfft(r, n=size, axis=0)
    rho = np.fft.irfft(np.abs(spectrum) ** 2, n=size, axis=0)[:n].mean(axis=1) / n
    tau = 1.0 + 2.0 * np.cumsum(rho[1:])
    window = np.flatnonzero(np.arange(1, n) >= 5.0 * tau)
    return float(max(tau[window[0]] if len(window) else tau[-1], 1.0))


def block_length(residual, dt, window):
    """The blocks of the cluster-robust covariance: ``L = max(window, 5 tau dt)``, s, eq. (U2).

    ``tau`` the residuals' integrated correlation time (:func:`correlation_time`,
    eq. (U1)): five of it, so that the share of the variance a block misses
    across its two borders (``tau / (2 L)`` for an exponential correlation) is
    a tenth at most; and not shorter than the smoothing window of the pose
    differentiation, over which the motion's errors are shared. White
    residuals get blocks of the window (0.2 s: 25 blocks in 5 s, against 5 of
    1 s); a drift or slow model error, longer blocks.

    Parameters
    ----------
    residual : ndarray, shape (N, c)
        The fit's residuals, per channel, at the log's samples.
    dt : float
        Sample interval, s.
    window : float
        Smoothing window of the differentiation, s.

    Returns
    -------
    float
    """
    return max(float(window), 5.0 * correlation_time(residual) * dt)


def pseudo_inverse(J):
    """``(J^T J)^+`` on the directions it determines (scaled to a unit diagonal), and the columns those alone touch.

    Parameters
    ----------
    J : ndarray, shape (N, p)
        The weighted design.

    Returns
    -------
    inverse : ndarray, shape (p, p)
        The pseudo-inverse of the information, singular values below ``1e-12`` of the largest dropped.
    columns : ndarray of bool, shape (p,)
        The parameters that touch no dropped direction.
    """
    information = J.T @ J
    scale = np.sqrt(np.maximum(np.diag(information), 1e-300))
    u, s, vt = np.linalg.svd(information / np.outer(scale, scale))
    keep = s > 1e-12 * s[0]
    return (vt[keep].T / s[keep]) @ u[:, keep].T / np.outer(scale, scale), _columns(keep, vt)


def sandwich(J, e, blocks, inverse, columns):
    """The cluster-robust covariance over ``blocks``, with the small-sample factor, eq. (U3)::

        cov = G / (G - 1) (N - 1) / (N - K) B (sum_b s_b s_b^T) B

    ``s_b`` a block's ``J^T e``, ``B = (J^T J)^+``, ``G`` the blocks, ``N``
    the rows and ``K`` the parameters determined (Stata's CR1: the sum over
    few blocks falls short of the variance by about ``(G - 1) / G``);
    infinite for the parameters that touch a direction not determined.

    Parameters
    ----------
    J : ndarray, shape (N, p)
        The weighted design.
    e : ndarray, shape (N,)
        The weighted residuals.
    blocks : ndarray of int, shape (N,)
        Each row's block.
    inverse, columns
        :func:`pseudo_inverse` of ``J``.

    Returns
    -------
    ndarray, shape (p, p)
    """
    scores = np.zeros((blocks.max() + 1, J.shape[1]))
    np.add.at(scores, blocks, J * e[:, None])
    factor = small_sample_factor(blocks, J.shape[0], int(np.linalg.matrix_rank(inverse)))
    cov = factor * inverse @ (scores.T @ scores) @ inverse
    cov[:, ~columns] = np.inf
    cov[~columns, :] = np.inf
    return cov


def small_sample_factor(blocks, n, k):
    """The small-sample factor of eq. (U3), ``G / (G - 1) (N - 1) / (N - K)`` (Stata's CR1).

    Parameters
    ----------
    blocks : ndarray of int
        Each row's block (``G`` the blocks holding a row).
    n : int
        The rows ``N``.
    k : int
        The parameters determined ``K``.

    Returns
    -------
    float
    """
    g = int(np.count_nonzero(np.bincount(blocks)))
    return g / max(g - 1, 1) * (n - 1) / max(n - k, 1)


def _columns(keep, vt):
    """Parameters that touch only the kept directions of the information."""
    return np.abs(vt[~keep]).max(axis=0) < 1e-6 if (~keep).any() else np.ones(vt.shape[1], dtype=bool)


def time_blocks(residual, t, window, block=None):
    """Each row's block of time, and the blocks' length, for a fit whose rows are ``c`` channels per sample.

    Parameters
    ----------
    residual : ndarray, shape (N, c)
        The fit's residuals at the samples.
    t : ndarray, shape (N,)
        The samples' times, s.
    window : float
        Smoothing window of the differentiation, s.
    block : float, optional
        The blocks' length, s; default :func:`block_length` (eq. (U2)).

    Returns
    -------
    blocks : ndarray of int, shape (N c,)
        The block of each row (the ``c`` rows of a sample alike).
    length : float
        s.
    """
    if block is None:
        block = block_length(residual, float(np.median(np.diff(t))), window)
    return np.repeat(((t - t[0]) // block).astype(int), residual.shape[1]), block


def few_blocks(blocks, length):
    """The warning for a covariance over fewer than :data:`MIN_BLOCKS` blocks, else None.

    Parameters
    ----------
    blocks : ndarray of int
        Each row's block (:func:`time_blocks`).
    length : float
        The blocks' length, s.

    Returns
    -------
    str or None
    """
    count = int(np.unique(blocks).size)
    if count >= MIN_BLOCKS:
        return None
    return (f"the uncertainties are rough: the log holds only {count} blocks of {length:.2g} s, the time over which "
            f"its residuals are correlated ({MIN_BLOCKS} wanted); record a longer log")


def hotelling(x, C, g):
    """Hotelling's test of ``x`` against its covariance ``C`` estimated from ``g`` blocks of time, eq. (U4).

    Parameters
    ----------
    x : ndarray, shape (k,)
    C : ndarray, shape (k, k)
        Symmetric, positive semidefinite; singular directions are left out.
    g : int
        The blocks of time ``C`` was estimated from.

    Returns
    -------
    statistic : float
        ``x^T C^+ x``.
    dof : int
        The directions ``C`` determines.
    p_value : float
        1 where none is determined, or ``g`` is at most ``dof + 1``.
    """
    d = np.sqrt(np.maximum(np.diag(C), 1e-300))
    lam, u = np.linalg.eigh((C + C.T) / 2 / np.outer(d, d))
    keep = lam > 1e-10 * max(lam.max(), 1e-300)
    y = (u[:, keep].T @ (x / d)) / np.sqrt(lam[keep])
    statistic, dof = float(y @ y), int(keep.sum())
    if dof == 0 or g <= dof + 1:
        return statistic, dof, 1.0
    return statistic, dof, float(f_dist.sf((g - dof) / (dof * (g - 1)) * statistic, dof, g - dof))
