"""Glitches in the reading: single samples far from their neighbours, found and bridged before a batch fit.

A spike in the raw reading (a bit flip, an electrical glitch, a dropped
byte) is one sample far from the smooth wrench around it. A whole-log fit
weighs every sample alike, so a few spikes of many noise standard
deviations steer ``S_hat`` (20 spikes of 100 standard deviations in a
60 s log move an entry of ``S`` by many of its sigmas). The rule, once for
every batch method (:meth:`fmscal.observers.Observer.run` applies it to a
method with ``online = False``):

1. **Each sample's residual about its neighbours.** Per channel ``j``, the
   leave-one-out prediction of ``w_hat_k`` by the cubic fitted by least
   squares to the ``2 h`` samples around it (``h`` = :data:`HALF_WINDOW`;
   the window shifted inward at the log's ends), and the residual::

       r_kj = w_hat_kj - sum_i c_i w_hat_(k+i)j,   i in -h..h, i != 0        (G1)

   The sample itself is not in its prediction, so a spike of height ``A``
   gives ``r = A`` at its sample and at most ``|c|_max A`` at a neighbour.
   Per unit of white noise ``r_kj`` has the standard deviation
   ``s_k = sqrt(1 + sum c_i^2)``, larger at the ends (an extrapolation).
2. **A robust scale.** ``sigma_j = 1.4826 MAD(r_j) / s_mid`` over the
   samples away from the ends (the median absolute deviation about the
   median: a Gaussian residual's standard deviation, unmoved by a few per
   cent of spikes; ``s_mid`` the interior's ``s_k``): the reading's white
   noise (:func:`reading_noise`); the standard deviation of ``r_j`` where the
   MAD is zero (a quantised reading).
3. **The threshold.** A sample is rejected when ``|r_kj - median(r_j)| >
   k s_k sigma_j`` in any channel, its largest such ratio is the largest
   within ``h`` samples of it (a spike's neighbours are not rejected with
   it), and in that channel it stands apart from both sides: the line
   through its two neighbours on either side misses it by half its residual
   or more, on the same side (a step in the reading, a true change of the
   wrench, is near one of them), with::

       k = Phi^-1(1 - alpha / (2 N c)),   alpha = FALSE_ALARM                 (G2)

   ``N`` the samples and ``c`` the channels: the Bonferroni bound, so a
   clean log of Gaussian noise rejects a sample by chance with probability
   below ``alpha`` whatever its length (``k`` about 5.5 for 5 s of six channels
   at 1 kHz, 5.9 for 60 s).
4. **Bridged, and again.** A rejected sample's reading (every channel) is
   replaced by its prediction (G1) from its neighbours, and steps 1-3 are
   repeated on the bridged reading (a second spike next to a first shows
   once the first is gone; every sample rejected so far is bridged again
   from its neighbours as they now are), at most :data:`MAX_ROUNDS` times. The batch
   fits need evenly spaced samples: the bridged sample carries what its
   neighbours say, not what the glitch said.

Before the spikes, the reading's *frozen* runs (every channel repeated,
sample after sample, where the wrench around them moves beyond what the
reading's resolution and noise allow: a driver holding its last value) are
found and bridged by the rule of :mod:`fmscal.observers.core._frozen`
(eqs. (F1)-(F3)); :attr:`Glitches.frozen` lists them.

A log with nothing rejected is returned as it was: its fit does not move.
What the rule cannot tell from a glitch is a true event shorter than a few
samples (an impact): such a log is not a calibration log.
"""

import copy
from dataclasses import dataclass, field

import numpy as np
from scipy.special import ndtri

from ._frozen import find_frozen

__all__ = ["Glitches", "find_glitches", "bridge_glitches", "reading_noise", "HALF_WINDOW", "FALSE_ALARM",
           "MAX_ROUNDS", "glitch_threshold"]

#: Samples each side of the leave-one-out prediction (G1): short enough that a cubic follows the wrench
#: of a motion of a few hertz at 100 Hz, long enough that the prediction's own noise is small.
HALF_WINDOW = 4
#: The chance that a clean log of Gaussian noise has any sample rejected, eq. (G2).
FALSE_ALARM = 1e-3
#: Rounds of find-and-bridge (a run of adjacent glitches shows one by one).
MAX_ROUNDS = 6
_DEGREE = 3
_MAD_SCALE = 1.4826


@dataclass
class Glitches:
    """The samples of a log's reading rejected as glitches (module docstring, eqs. (G1), (G2)).

    Attributes
    ----------
    indices : ndarray of int
        The rejected samples (rows of the log), ascending.
    times : ndarray
        Their times, s.
    channels : list of list of str
        Per rejected sample, the channels whose residual passed the threshold.
    size : ndarray
        Per rejected sample, its largest residual in robust standard deviations.
    threshold : float
        ``k`` of eq. (G2).
    noise : ndarray, shape (c,)
        The reading's white noise per channel measured from the log (:func:`reading_noise`).
    frozen : list of dict
        The reading's frozen runs (:mod:`fmscal.observers.core._frozen`, eqs. (F1)-(F3)): per run
        ``start`` (its first held row), ``time`` (s), ``length`` (the held samples), ``chance``
        (``log10`` of its chance, eq. (F1)) and ``bridged`` (False: too long to bridge, eq. (F3)); empty
        when none is.
    """

    indices: np.ndarray
    times: np.ndarray
    channels: list = field(default_factory=list)
    size: np.ndarray = None
    threshold: float = float("nan")
    noise: np.ndarray = None
    frozen: list = field(default_factory=list)

    @property
    def count(self):
        """The samples rejected as spikes (eq. (G2)); the frozen runs' are :attr:`frozen_count`."""
        return int(len(self.indices))

    @property
    def frozen_count(self):
        """The held samples of the frozen runs (eq. (F2))."""
        return int(sum(run["length"] for run in self.frozen))

    @property
    def found(self):
        """Anything rejected: a spike or a frozen run."""
        return bool(self.count or self.frozen)

    @property
    def unbridged(self):
        """The frozen runs too long to bridge (eq. (F3))."""
        return [run for run in self.frozen if not run["bridged"]]

    def frozen_summary(self, runs=None, limit=5):
        """One line naming the frozen runs ``runs`` (default all): where, and how many samples each."""
        runs = self.frozen if runs is None else runs
        shown = ", ".join(f"{run['length']} at t = {run['time']:.3f} s" for run in runs[:limit])
        more = ", ..." if len(runs) > limit else ""
        return (f"{len(runs)} frozen stretch(es) of the reading (every channel repeating its last value beyond "
                f"what its resolution and noise allow, eq. (F2); held samples {shown}{more})")

    def summary(self, limit=5):
        """One line: how many samples were rejected and where (the first ``limit`` times), and the frozen
        runs."""
        parts = []
        if self.count:
            shown = ", ".join(f"{t:.3f}" for t in self.times[:limit]) + (", ..." if self.count > limit else "")
            parts.append(f"{self.count} sample(s) of the reading rejected as glitches (a residual above "
                         f"{self.threshold:.2g} robust standard deviations of its neighbours'; bridged from them) "
                         f"at t = {shown} s")
        if self.frozen:
            parts.append(f"{self.frozen_summary(limit=limit)}, bridged from the samples around them")
        return "; ".join(parts)

    def to_dict(self):
        """The JSON form: count, indices, times, channels, sizes (robust standard deviations), threshold."""
        out = {"count": self.count, "indices": [int(i) for i in self.indices],
               "times": [float(t) for t in self.times], "channels": [list(c) for c in self.channels],
               "size": [float(s) for s in self.size], "threshold": float(self.threshold)}
        if self.frozen:                             # only a log with frozen runs: a clean log's report as before
            out["frozen"] = {"count": self.frozen_count, "runs": [dict(run) for run in self.frozen]}
        return out


def _coefficients(n, h=HALF_WINDOW, degree=_DEGREE):
    """The leave-one-out prediction weights of eq. (G1): for each sample the window's start and its weights.

    Returns ``(start, weights)``: ``start`` (n,) the first sample of each window of ``2 h + 1``, ``weights``
    (n, 2 h + 1) with a zero at the sample itself.
    """
    width = 2 * h + 1
    start = np.clip(np.arange(n) - h, 0, max(n - width, 0))
    positions = np.arange(n) - start                       # the sample's place in its window
    table = np.zeros((width, width))
    offsets = np.arange(width)
    for p in range(width):
        others = offsets[offsets != p]
        A = np.vander(others - p, degree + 1, increasing=True)          # the cubic about the sample
        table[p, others] = np.linalg.pinv(A)[0]                           # its value at the sample
    return start, table[positions]


def _residuals(w, start, weights):
    """Eq. (G1) for every channel, shape (n, c)."""
    prediction = np.zeros_like(w)
    for i in range(weights.shape[1]):                   # one offset of the window at a time: no (n, width, c) copy
        prediction += weights[:, i, None] * w[start + i]
    return w - prediction


def _robust_scale(r):
    """``1.4826 MAD`` per column (the standard deviation where it is zero), and the medians."""
    median = np.median(r, axis=0)
    scale = _MAD_SCALE * np.median(np.abs(r - median), axis=0)
    flat = scale <= 0
    scale[flat] = np.std(r[:, flat], axis=0)
    return scale, median


def glitch_threshold(n, c, alpha=FALSE_ALARM):
    """``k`` of eq. (G2): ``Phi^-1(1 - alpha / (2 N c))`` robust standard deviations."""
    return float(ndtri(1.0 - alpha / (2.0 * max(n, 1) * max(c, 1))))


def reading_noise(w_hat):
    """The reading's white noise per channel, from its scatter about its neighbours: ``sigma_j`` of the
    module docstring (step 2).

    Parameters
    ----------
    w_hat : ndarray, shape (N, c)

    Returns
    -------
    ndarray, shape (c,)
    """
    w = np.asarray(w_hat, dtype=float)
    n = len(w)
    start, weights = _coefficients(n)
    scale, _ = _robust_scale(_residuals(w, start, weights)[HALF_WINDOW:n - HALF_WINDOW])
    return scale / np.sqrt(1.0 + np.sum(weights[n // 2] ** 2))


def find_glitches(t, w_hat, names=None, alpha=FALSE_ALARM):
    """The glitches of a reading and the reading with them bridged (module docstring).

    Parameters
    ----------
    t : ndarray, shape (N,)
        The samples' times, s.
    w_hat : ndarray, shape (N, c)
        The raw reading.
    names : sequence of str, optional
        The channels' names (default ``"0"``, ``"1"``, ...).
    alpha : float
        The false-alarm probability of eq. (G2).

    Returns
    -------
    glitches : Glitches
    bridged : ndarray, shape (N, c)
        ``w_hat`` with the rejected samples replaced by their predictions and the frozen runs bridged (the
        same array when none is).
    """
    w = np.asarray(w_hat, dtype=float)
    n, c = w.shape
    names = [str(j) for j in range(c)] if names is None else list(names)
    empty = Glitches(np.zeros(0, dtype=int), np.zeros(0), [], np.zeros(0), float("nan"), np.zeros(c))
    if n < 4 * HALF_WINDOW + 1:                                 # too short to tell a glitch from the motion
        return empty, w
    start, weights = _coefficients(n)
    k = glitch_threshold(n, c, alpha)
    rejected = {}
    # the frozen runs first (_frozen, eqs. (F1)-(F3)): bridged, the spikes are sought on the bridged reading
    frozen, w = find_frozen(t, w, reading_noise, alpha, HALF_WINDOW)
    empty.frozen = frozen
    bridged = w
    noise = None
    # the residual's standard deviation per unit of white noise: larger at the ends, where (G1) extrapolates
    spread = np.sqrt(1.0 + np.sum(weights ** 2, axis=1))
    for _ in range(MAX_ROUNDS):
        r = _residuals(bridged, start, weights)
        scale, median = _robust_scale(r[HALF_WINDOW:n - HALF_WINDOW])
        if noise is None:
            noise = scale / spread[n // 2]
        z = np.abs(r - median) / np.where(scale > 0, scale / spread[n // 2], np.inf) / spread[:, None]
        peak = z.max(axis=1)
        # the largest within HALF_WINDOW samples: a spike's neighbours, pulled by it through (G1), are not it
        padded = np.pad(peak, HALF_WINDOW, constant_values=-np.inf)
        local = np.lib.stride_tricks.sliding_window_view(padded, 2 * HALF_WINDOW + 1).max(axis=1)
        new = np.flatnonzero((peak > k) & (peak >= local))
        taken = set(rejected) | set(np.flatnonzero(peak > k).tolist())    # not a side's reference
        new = new[[_apart(bridged, r, i, int(np.argmax(z[i])), taken) for i in new]] if len(new) else new
        if not len(new):
            break
        if bridged is w:
            bridged = w.copy()
        for i in new:
            if i not in rejected:
                rejected[int(i)] = ([names[j] for j in np.flatnonzero(z[i] > k)], float(peak[i]))
        every = np.array(sorted(rejected))          # each rejected sample bridged again from the neighbours now
        bridged[every] = (bridged - r)[every]
    if not rejected:
        empty.threshold, empty.noise = k, noise
        return empty, w
    indices = np.array(sorted(rejected), dtype=int)
    for _ in range(2):                              # neighbours rejected together: bridged from each other's
        bridged[indices] = (bridged - _residuals(bridged, start, weights))[indices]
    return Glitches(indices, np.asarray(t, dtype=float)[indices], [rejected[i][0] for i in indices],
                    np.array([rejected[i][1] for i in indices]), k, noise, frozen), bridged


def _apart(w, r, i, j, taken):
    """Sample ``i`` stands apart from both sides in channel ``j``: the lines through its two nearest
    neighbours on each side (other than the samples ``taken``: rejected, or above the threshold) miss it by
    at least half its residual ``r_ij``, on the same side (a step is near one of them)."""
    for side in (-1, 1):
        near = [m for m in range(i + side, i + side * (2 * HALF_WINDOW + 1), side)
                if 0 <= m < len(w) and m not in taken][:2]
        if len(near) < 2:
            continue
        a, b = near
        off = w[i, j] - (w[a, j] + (w[a, j] - w[b, j]) * (i - a) / (a - b))
        if off * r[i, j] <= 0 or abs(off) < 0.5 * abs(r[i, j]):
            return False
    return True


def bridge_glitches(log, names=None):
    """A log whose reading's glitches are bridged (:func:`find_glitches`), and the glitches.

    Parameters
    ----------
    log : plant.Log
    names : sequence of str, optional
        The reading's channel names (the model's ``wrench_names``).

    Returns
    -------
    bridged : plant.Log
        ``log`` itself when nothing is rejected; else a copy with the bridged reading and a note.
    glitches : Glitches
    """
    glitches, w = find_glitches(log.t, log.w_hat, names)
    if not glitches.found:
        return log, glitches
    bridged = copy.copy(log)
    bridged.w_hat = w
    bridged.notes = [*log.notes, f"{log.name}: {glitches.summary()}"]
    return bridged, glitches
