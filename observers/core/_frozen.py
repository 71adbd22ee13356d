"""Frozen readings: the whole reading repeated, sample after sample, where the wrench around it moves.

A driver that repeats its last value (a dropped packet on an Ethernet
sensor, a held register) writes the same reading, every channel to the
last bit, for several samples. A whole-log fit takes those samples as
measurements of a wrench that stood still while the motion went on, and
``S_hat`` leaves its sigmas. A quantised, quiet reading repeats too, by
chance, and for long where the wrench moves slowly: repeats are judged
against what the reading's resolution and noise allow there, all channels
together.

1. **The candidates.** Every run of samples equal to their predecessor in
   every channel: its ``L`` held samples ``a .. a + L - 1`` (sample
   ``a - 1``, the last that came, holds the value ``v``).
2. **The wrench under them.** Per channel ``j``, the cubic fitted by least
   squares to the ``m = max(h, L)`` samples on each side (``h`` the
   glitches' ``HALF_WINDOW``), as a spike is bridged by eq. (G1), gives
   ``b_kj`` over the run, with the variance ``u_j^2 l_k`` of a fit (``l_k``
   the leverage of sample ``k``; ``u_j`` the reading's scatter, eq. (F2)).
3. **The chance of a repeat.** A channel of resolution ``q_j`` (the
   smallest step between consecutive samples) finer than its noise
   ``sigma_j`` (eq. (G1)'s scale) repeats its last value with at most the
   chance that the difference of two noise draws, ``N(0, 2 sigma_j^2)``,
   falls in a cell of width ``q_j`` about zero (the wrench's own change
   only lowers it); a coarser channel may repeat for long, and tells
   nothing. The noise taken as independent from channel to channel and
   sample to sample, a run of ``L`` held samples is that common by
   chance::

       p_j = min(1, q_j / (2 sqrt(pi) sigma_j)),
       log Pr(run) = L sum_j log p_j                                             (F1)

4. **Beyond chance, or beyond the wrench.** A run is frozen when it is
   rarer than the false-alarm rate over the log's ``N`` places (the
   Bonferroni bound, as eq. (G2)), or when in some channel the wrench
   under it leaves the held value's cell by more than ``k`` (eq. (G2)'s
   threshold) of its standard deviations at some held sample ``k'``::

       N Pr(run) < alpha,   alpha = FALSE_ALARM,                            or
       |b_k'j - v_j| - q_j / 2 > k u_j sqrt(1 + l_k'),   u_j^2 = sigma_j^2 + q_j^2 / 12   (F2)

   (``q_j^2 / 12`` the quantisation's share, which a slow, coarse reading
   hides from ``sigma_j``). A float reading makes every exact repeat
   improbable by the first; a coarse one is judged by the second: a repeat
   the wrench under it allows is not frozen, whatever its length.

5. **Bridged, or too long to bridge.** The held samples are replaced by
   ``b_kj``. Whether a gap of ``L`` can be bridged is measured on the log
   itself: the same bridge laid over :data:`FROZEN_TRIALS` clean stretches
   of ``L`` samples spread over the log misses their readings by::

       B_L = mean over the stretches, samples and channels of
             ((bridge_kj - w_hat_kj) / u_j)^2                                  (F3)

   A bridge no worse than a reading misses by the reading's scatter alone,
   ``B_L <= 2``; a run with ``B_L > 2``, or with fewer than ``h`` samples on a side
   (at an end of the log: an extrapolation), is too long to bridge. It is
   bridged all the same where it has two sides (the fits need evenly
   spaced samples), and the calibration is not converged, with a warning
   naming the stretch.
"""

import numpy as np
from scipy.special import ndtri

__all__ = ["find_frozen", "FROZEN_TRIALS"]

#: The clean stretches each run's bridge is tried on, eq. (F3).
FROZEN_TRIALS = 16
_DEGREE = 3
_BRIDGE_LIMIT = 2.0
_FLOOR = 1e-300


def _runs(same):
    """The runs of True in ``same`` (a boolean per pair): ``(first held sample, length)`` each."""
    edges = np.diff(np.r_[0, same.astype(np.int8), 0])
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1)
    return starts + 1, ends - starts                    # pair k compares samples k and k + 1


def _weights(offsets, length):
    """The cubic of step 2 as weights: ``(W, l)``, ``W`` (L, len(offsets)) taking the samples at ``offsets``
    from the run's first held sample to the bridge over its ``L`` held samples, ``l`` their leverages."""
    scale = max(length, 1.0)
    A = np.vander(offsets / scale, _DEGREE + 1, increasing=True)
    X = np.vander(np.arange(length) / scale, _DEGREE + 1, increasing=True)
    inverse = np.linalg.pinv(A.T @ A)
    return X @ inverse @ A.T, np.einsum("ki,ij,kj->k", X, inverse, X)


def _around(a, length, h, n):
    """The samples a bridge of the held samples ``a .. a + L - 1`` is fitted to: ``max(h, L)`` each side."""
    m = max(h, length)
    return np.r_[np.arange(max(a - m, 0), a), np.arange(a + length, min(a + length + m, n))]


def _bridge(w, a, length, h):
    """The cubic of step 2 over the held samples ``a .. a + L - 1`` and its leverages ``l_k``."""
    around = _around(a, length, h, len(w))
    W, leverage = _weights(around - a, length)
    return W @ w[around], leverage


def _departures(w, starts, lengths, noise, q, h):
    """The departure of eq. (F2) of every run, the runs of one length in the log's interior at once."""
    n = len(w)
    out = np.empty(len(starts))
    for length in np.unique(lengths):
        m = max(h, length)
        these = np.flatnonzero(lengths == length)
        inner = these[(starts[these] >= m) & (starts[these] + length + m <= n)]
        if len(inner):
            offsets = np.r_[np.arange(-m, 0), np.arange(length, length + m)]
            W, leverage = _weights(offsets, length)
            bridges = np.einsum("kj,rjc->rkc", W, w[starts[inner, None] + offsets])
            out[inner] = departure(w[starts[inner] - 1][:, None, :], bridges, leverage, noise, q)
        for r in np.setdiff1d(these, inner):            # at an end: fewer samples on one side
            bridge, leverage = _bridge(w, starts[r], length, h)
            out[r] = departure(w[starts[r] - 1], bridge, leverage, noise, q)
    return out


def _bridge_error(w, length, u, blocked, h):
    """``B_L`` of eq. (F3): the bridge of ``length`` samples laid over :data:`FROZEN_TRIALS` clean stretches."""
    m = max(h, length)
    lo, hi = m, len(w) - length - m
    if hi <= lo:
        return np.inf
    starts = np.linspace(lo, hi, FROZEN_TRIALS + 2)[1:-1].astype(int)
    starts = [s for s in starts if not blocked[max(s - m, 0):s + length + m].any()]
    if not starts:
        return np.inf
    scale = np.where(u > 0, u, np.inf)
    misses = [np.mean(((_bridge(w, s, length, h)[0] - w[s:s + length]) / scale) ** 2) for s in starts]
    return float(np.mean(misses))


def resolution(w):
    """``q_j`` of eq. (F1): per channel the smallest step between consecutive samples (0 where none)."""
    steps = np.abs(np.diff(w, axis=0))
    steps = np.where(steps > 0, steps, np.inf)
    q = steps.min(axis=0)
    return np.where(np.isfinite(q), q, 0.0)


def run_chance(length, noise, q):
    """``log Pr(run)`` of eq. (F1) for a run of ``length`` held samples."""
    p = np.minimum(1.0, q / np.where(noise > 0, 2.0 * np.sqrt(np.pi) * noise, np.inf))
    p = np.where(noise > 0, p, 1.0)
    return float(length * np.sum(np.log(np.maximum(p, _FLOOR))))


def departure(v, bridge, leverage, noise, q):
    """The largest ``(|b_k'j - v_j| - q_j / 2) / (u_j sqrt(1 + l_k'))`` of eq. (F2): ``v`` (..., 1, c) or
    (c,), ``bridge`` (..., L, c); one value per run."""
    u = np.sqrt(noise ** 2 + q ** 2 / 12.0)
    s = u * np.sqrt(1.0 + leverage)[:, None]
    out = (np.abs(bridge - v) - q / 2) / np.where(s > 0, s, np.inf)
    return out.max(axis=(-2, -1))


def find_frozen(t, w, noise, alpha, h):
    """The frozen runs of a reading (module docstring), and the reading with them bridged.

    Parameters
    ----------
    t : ndarray, shape (N,)
        The samples' times, s.
    w : ndarray, shape (N, c)
        The reading.
    noise : callable
        ``noise(w)``, its noise per channel, shape (c,) (:func:`fmscal.observers.core.reading_noise`):
        called only on a reading with a repeat.
    alpha : float
        The false-alarm probability of eq. (F2) (the glitches' ``FALSE_ALARM``).
    h : int
        Samples each side of a bridge at least (the glitches' ``HALF_WINDOW``).

    Returns
    -------
    runs : list of dict
        Per frozen run: ``start`` (the first held row), ``time`` (its time, s), ``length`` (the held
        samples), ``chance`` (``log10 Pr(run)``, eq. (F1); 0 for a coarse reading) and ``bridged``
        (False: too long to bridge, eq. (F3)).
    bridged : ndarray, shape (N, c)
        ``w`` with the held samples bridged (the same array when no run is frozen).
    """
    n = len(w)
    starts, lengths = _runs(np.all(w[1:] == w[:-1], axis=1))
    if not len(starts):
        return [], w
    noise = np.asarray(noise(w), dtype=float)
    q = resolution(w)
    k = float(ndtri(1.0 - alpha / (2.0 * n * w.shape[1])))          # eq. (G2)'s threshold
    chance = lengths * run_chance(1, noise, q)
    rare = np.log(n) + chance < np.log(alpha)
    moved = np.zeros(len(starts), dtype=bool)
    moved[~rare] = _departures(w, starts[~rare], lengths[~rare], noise, q, h) > k
    frozen = [(int(starts[i]), int(lengths[i]), float(chance[i])) for i in np.flatnonzero(rare | moved)]
    if not frozen:
        return [], w
    blocked = np.zeros(n, dtype=bool)
    for a, L, _ in frozen:
        blocked[a - 1:a + L] = True
    bridged = w.copy()
    runs = []
    for a, L, chance in frozen:
        inside = a >= h and a + L + h <= n
        ok = inside and _bridge_error(w, L, np.sqrt(noise ** 2 + q ** 2 / 12.0), blocked, h) <= _BRIDGE_LIMIT
        if a + L < n:                                   # a run to the log's end is left as it came
            bridged[a:a + L] = _bridge(bridged, a, L, h)[0]
        runs.append({"start": int(a), "time": float(t[a]), "length": int(L),
                     "chance": float(chance / np.log(10)), "bridged": bool(ok)})
    return runs, bridged
