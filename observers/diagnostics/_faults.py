"""Sensor faults the model ``w = S (w_hat - b)`` cannot absorb: saturation and a moving offset.

Two checks ``fmscal calibrate`` runs on every log, beside
:func:`observers.diagnostics.consistency_check` (one constant ``S``):

* :func:`saturation`: a channel of the raw reading pinned at a constant
  extreme value (a sensor or amplifier that saturates); the model is linear,
  so a clipped reading biases every entry of ``S``.
* :func:`offset_drift`: the offset ``b`` changes during the log (a step, a
  ramp). A least-squares fit of the whole log leaves, in each of its 0.5 s
  windows, a residual that a change of ``b`` explains; those per-window
  offsets must not change level over the log, and must be white.
"""

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2
from scipy.stats import f as f_dist

from fmscal.observers.batch import LeastSquares, phi_to_S_map

__all__ = ["saturation", "offset_drift", "OffsetDrift", "SATURATION_SHARE", "SATURATION_RATIO",
           "DRIFT_SIGNIFICANCE", "DRIFT_PARTS", "DRIFT_LAGS"]

#: A channel is saturated where at least this share of its samples sits exactly at one extreme ...
SATURATION_SHARE = 0.005
#: ... and that extreme holds at least this many times the samples of one level just inside it
#: (averaged over a band of 0.5 % of the channel's range, or two quantisation steps): a quantised
#: reading's top level holds about as many as its neighbours (a sine's at most 2.4x), a clipped
#: one far more; an unquantised reading repeats no value.
SATURATION_RATIO = 5.0
#: Probability, for a log with a constant offset, of calling it moving (the two tests of
#: :func:`offset_drift`, nominal).
DRIFT_SIGNIFICANCE = 1e-3
#: Equal parts of the log whose mean offsets are compared.
DRIFT_PARTS = 6
#: Lags of the whiteness test (Ljung-Box) of the per-window offsets.
DRIFT_LAGS = 5

_CHANNELS = ("M", "fx", "fy")
_UNITS = ("N m", "N", "N")


def saturation(log):
    """Channels of the raw reading pinned at a constant extreme value.

    Parameters
    ----------
    log : plant.Log
        Planar or spatial: every channel of its reading is checked.

    Returns
    -------
    list of str
        One line per saturated channel: its name, the pinned value(s) and
        the share of the samples there. Empty when none is.
    """
    out = []
    names = log.columns[-log.w_hat.shape[1]:] if hasattr(log, "columns") else _CHANNELS
    for j, name in enumerate(names):
        v = log.w_hat[:, j]
        levels = np.unique(v)
        if len(levels) < 2:
            continue                    # a constant channel: the excitation check speaks for it
        step = float(np.min(np.diff(levels)))              # the quantisation step, if any
        band = max(0.005 * (levels[-1] - levels[0]), 2 * step)
        pinned, count = [], 0
        for extreme in (levels[0], levels[-1]):
            at = int(np.count_nonzero(v == extreme))
            inside = np.count_nonzero((np.abs(v - extreme) <= band) & (v != extreme))
            per_level = inside * step / band                   # samples per level just inside
            if at >= SATURATION_SHARE * len(v) and at >= SATURATION_RATIO * max(per_level, 1):
                pinned.append(extreme)
                count += at
        if pinned:
            values = " and ".join(f"{p:.4g}" for p in pinned)
            out.append(f"the reading {name} is pinned at {values} in {100 * count / len(v):.3g} % of the samples: "
                       f"the sensor saturates, and a clipped reading biases every entry of S (reduce the load "
                       f"or the speed, or use a larger range)")
    return out


@dataclass
class OffsetDrift:
    """The outcome of :func:`offset_drift`.

    Attributes
    ----------
    constant : bool
        The per-window offsets keep one level.
    statistic : float
        The F statistic of the part means (about 1 for a constant offset).
    p_value : float
        Of the F test (a change of level).
    offsets : ndarray, shape (K, 3)
        The offset change ``delta b`` each window's residual asks for (N m, N, N).
    t : ndarray, shape (K,)
        The middle of each window, s.
    warning : str or None
        One line when the offset moves: which channel, a step or a ramp, and when.
    white_p : float
        The smallest over channels of the Ljung-Box p-value of the
        standardised per-window offsets (white for a constant offset).
    """

    constant: bool
    statistic: float
    p_value: float
    offsets: np.ndarray
    t: np.ndarray
    warning: str = None
    white_p: float = np.nan


def offset_drift(log, payload, S_hat, b=None, window=0.5, parts=DRIFT_PARTS, significance=DRIFT_SIGNIFICANCE):
    """Whether the sensor's offset changed during the log: the residuals of a fit change level.

    The fit ``[S_hat | c]`` (``c = -S_hat b``, zero without ``b``) leaves a
    residual in each window of the least-squares model (positions against
    the twice-integrated regressor, a line per window projected out). Per
    window, the change of ``b`` that best explains it is fitted (weighted by
    each channel's residual variance), with its information ``I_w``. The log
    is cut into ``parts`` equal parts; the weighted between-part scatter of
    these offsets over their within-part scatter is F-distributed with
    ``3 (parts - 1)`` and ``3 (K - parts)`` degrees of freedom for a constant
    offset (the within-part scatter sets the noise level: no noise model).
    Where it is too large, a level that steps or ramps between two window
    boundaries is fitted to the channel that moved most, and the warning
    says which. The offsets must also be white: each channel's, standardised,
    passes a Ljung-Box test over :data:`DRIFT_LAGS` lags (an offset that
    wanders faster than a part of the log). Each test takes half of
    ``significance``.

    Parameters
    ----------
    log : plant.Log
        Lined up (the poses moved back by the latency).
    payload : plant.Payload
    S_hat : array_like, shape (3, 3)
        The fit of the whole log.
    b : array_like, shape (3,), optional
        Its offset; None: the fit had none.
    window : float
        Window length, s (least squares', :class:`observers.LeastSquares`).
    parts : int
    significance : float
        Probability, for a constant offset, of calling it moving (both tests).

    Returns
    -------
    OffsetDrift
        ``constant`` True (with NaN statistics) where the log has fewer
        than ``2 parts`` usable windows: too short to tell.
    """
    S_hat = np.asarray(S_hat, dtype=float)
    c = np.zeros(3) if b is None else -S_hat @ np.asarray(b, dtype=float)
    fit = LeastSquares(payload, window, offset=True)
    Z = fit._double_integrals(log)
    windows = fit._windows(log)
    T_inv = np.linalg.inv(phi_to_S_map(fit.model, [4, 8], 4))
    phi = T_inv @ np.column_stack([S_hat, c]).ravel()
    # each channel's prediction is Z phi_g; d phi / d b through c = -S b (entries 3, 7, 11 of [S | c])
    groups = ((0, slice(0, 4)), (1, slice(4, 12)), (2, slice(4, 12)))
    D = -T_inv[:, [3, 7, 11]] @ S_hat
    per_window = []
    for rows in windows:
        tau = log.t[rows] - log.t[rows[0]]
        Q, _ = np.linalg.qr(np.column_stack([np.ones_like(tau), tau]))
        chans = []
        for ch, g in groups:
            R = Z[ch][rows] @ D[g]
            r = log.pose[rows, ch] - Z[ch][rows] @ phi[g]
            chans.append((R - Q @ (Q.T @ R), r - Q @ (Q.T @ r)))
        per_window.append((float(np.mean(log.t[rows])), chans))
    K = len(per_window)
    if K < 2 * parts:
        return OffsetDrift(True, np.nan, np.nan, np.zeros((K, 3)), np.zeros(K))
    var = [max(np.mean(np.concatenate([w[1][ch][1] for w in per_window]) ** 2), 1e-300) for ch in range(3)]
    t, est, info = [], [], []
    for tw, chans in per_window:
        Iw = sum(R.T @ R / v for (R, _), v in zip(chans, var))
        gw = sum(R.T @ r / v for (R, r), v in zip(chans, var))
        if np.linalg.cond(Iw) < 1e10:
            t.append(tw)
            est.append(np.linalg.solve(Iw, gw))
            info.append(Iw)
    t, est, info = np.array(t), np.array(est), np.array(info)
    K = len(t)
    if K < 2 * parts:
        return OffsetDrift(True, np.nan, np.nan, est.reshape(K, 3), t)
    part = np.minimum((parts * (t - log.t[0]) / (log.t[-1] - log.t[0] + log.dt)).astype(int), parts - 1)

    def pooled(mask):
        I = info[mask].sum(axis=0)
        return np.linalg.solve(I, np.einsum("kij,kj->i", info[mask], est[mask])), I

    overall, _ = pooled(np.ones(K, bool))
    between = within = 0.0
    for p in range(parts):
        mask = part == p
        if not mask.any():
            continue
        m, I = pooled(mask)
        between += (m - overall) @ I @ (m - overall)
        d = est[mask] - m
        within += float(np.einsum("ki,kij,kj->", d, info[mask], d))
    dof_b, dof_w = 3 * (len(np.unique(part)) - 1), 3 * (K - len(np.unique(part)))
    stat = (between / dof_b) / max(within / dof_w, 1e-300)
    p_value = float(f_dist.sf(stat, dof_b, dof_w))
    # white: each channel's standardised offsets, uncorrelated from window to window
    z = (est - overall) / np.sqrt(np.array([np.diag(np.linalg.inv(I)) for I in info]) * within / dof_w)
    white = [_ljung_box(z[:, j], DRIFT_LAGS) for j in range(3)]
    worst = int(np.argmin(white))
    # half the significance to each test, a third of the whiteness half to each channel
    out = OffsetDrift(p_value >= significance / 2 and white[worst] >= significance / 6, float(stat), p_value,
                      est, t, white_p=float(white[worst]))
    if p_value < significance / 2:
        out.warning = describe_offset(t, est, info, within / dof_w, p_value, _CHANNELS, _UNITS,
                                      "the residuals of a least-squares fit change level")
    elif not out.constant:
        out.warning = (f"the residuals of a least-squares fit are not white from window to window (as an offset "
                       f"of {_CHANNELS[worst]}: Ljung-Box p = {white[worst]:.2g} over {DRIFT_LAGS} lags): the "
                       f"sensor's offset wanders, or S changes, during the log")
    if out.warning and b is None:
        out.warning += " (or an offset left out: the fit estimated none)"
    return out


def _ljung_box(z, lags):
    """p-value of the Ljung-Box statistic of the series ``z`` (white: chi-square with ``lags`` dof)."""
    z = z - np.mean(z)
    n, denom = len(z), float(z @ z)
    if denom <= 0:
        return 1.0
    rho = np.array([float(z[k:] @ z[:-k]) / denom for k in range(1, lags + 1)])
    Q = n * (n + 2) * float(np.sum(rho ** 2 / (n - np.arange(1, lags + 1))))
    return float(chi2.sf(Q, lags))


def describe_offset(t, est, info, scale, p_value, names, units, evidence, channels=None):
    """One line: which channel's offset moved, as a step or a ramp, and when.

    Parameters
    ----------
    t : ndarray, shape (K,)
        The middle of each window, s.
    est : ndarray, shape (K, n)
        The offset change each window asks for, per channel of the reading.
    info : ndarray, shape (K, n, n)
        Each window's information about it (its inverse, times ``scale``, the covariance).
    scale : float
    p_value : float
        Of the test that found the offset moving.
    names, units : tuple of str
        The reading's channels and their units.
    evidence : str
        What the test saw, in words ("the residuals of a least-squares fit change level").
    channels : sequence of int, optional
        The channels the test found moving, to choose among (None: all).

    Returns
    -------
    str
    """
    sd2 = np.array([np.diag(np.linalg.inv(I)) for I in info]) * scale          # (K, 3) variances
    w = 1.0 / sd2
    spread = [np.sum(w[:, j] * (est[:, j] - np.average(est[:, j], weights=w[:, j])) ** 2) for j in range(len(names))]
    among = range(len(names)) if channels is None or not len(channels) else channels
    j = int(max(among, key=lambda k: spread[k]))
    y, sw = est[:, j], np.sqrt(w[:, j])
    bounds = np.concatenate([[t[0]], 0.5 * (t[1:] + t[:-1]), [t[-1]]])      # between windows, K + 1
    grid = np.unique(np.linspace(0, len(t), min(len(t), 60) + 1).astype(int))
    # a step at every boundary, and a ramp between any two boundaries of a coarser grid
    shapes = [(a, a) for a in range(1, len(t))] + [(a, b) for a in grid[:-1] for b in grid if b > a + 1]
    best = (np.inf, 0.0, 0, 0)
    for a, b in shapes:
        level = (t >= bounds[a]) * 1.0 if a == b else np.clip((t - bounds[a]) / (bounds[b] - bounds[a]), 0, 1)
        A = np.column_stack([1 - level, level]) * sw[:, None]
        coef, *_ = np.linalg.lstsq(A, y * sw, rcond=None)
        sse = float(np.sum((A @ coef - y * sw) ** 2))
        if sse < best[0]:
            best = (sse, float(coef[1] - coef[0]), a, b)
    _, size, a, b = best
    end = None if a == b or bounds[b] - bounds[a] <= 2 * (t[1] - t[0]) else bounds[b]
    start = bounds[a] if end is not None else 0.5 * (bounds[a] + bounds[b])
    what = (f"steps by {size:+.3g} {units[j]} at t = {start:.3g} s" if end is None else
            f"drifts by {size:+.3g} {units[j]} from t = {start:.3g} to {end:.3g} s")
    return (f"the sensor's offset moves during the log: the offset of {names[j]} {what} ({evidence}, "
            f"p = {p_value:.2g}); one constant offset does not describe it")
