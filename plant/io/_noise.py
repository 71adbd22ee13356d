"""Noise standard deviations estimated from a log, and the reading noise's correlation in time.

The reading's noise is white sample by sample in the simulator, but a real sensor's may not be: its own
low-pass filter (ATI's Net F/T offers several), an interpolation onto another clock, readings averaged over
a few samples. Differences of neighbouring samples (:func:`estimate_noise`'s robust scale) then see only the
noise's high frequencies and read its standard deviation small, and a fit over many samples, which averages
the noise, sees more of it than white noise of that standard deviation would leave. The noise's spectrum is
therefore measured from the reading, where the motion leaves it alone. Per channel, with ``h`` the sample
interval, the reading's second difference ``d_k = w_k+1 - 2 w_k + w_k-1`` removes the motion (a wrench
changing over seconds moves it by ``(omega h)^2`` of its size), and its spectrum over the difference's gain
is the noise's (one-sided, Welch's average over :data:`SEGMENT` s segments, a Hann window)::

    G(f) = G_d(f) / (2 sin(pi f h))^4                                                          (N1)

Below :data:`LOW_BAND` Hz the motion's own harmonics are in it; ``G`` there is taken flat at its mean
``G_0`` over ``[LOW_BAND, 2 LOW_BAND)``. The noise's variance and its integrated correlation time
``tau = 1 + 2 sum_k rho_k`` (in samples; 1 for white noise) are::

    sd^2 = integral_0^(1/2h) G(f) df,    tau = G_0 / (2 h sd^2)                                 (N2)

``sd^2 tau`` the long-run variance: a fit over many samples sees the noise as white noise of that variance
(:attr:`fmscal.plant.NoiseSpec.long_run_wrench_sd`). A channel is taken as coloured only where its spectrum is
not flat: ``r = G_lo / G_hi``, the means of ``G`` over ``[LOW_BAND, 1/8h)`` and ``[1/4h, 1/2h]``, beyond its
scatter::

    |log r| > WHITENESS_Z s_r,   s_r^2 = var(G_lo,j) / (J G_lo^2) + var(G_hi,j) / (J G_hi^2)          (N3)

``G_lo,j``, ``G_hi,j`` the bands' means in each of the ``J`` segments (they are independent: no overlap). The
test's bands are wide, so that a filter's corner near the Nyquist frequency (300 Hz at 1 kHz) is seen; ``G_0``
keeps to the lowest band, so that a corner at 30 Hz leaves it nearly whole.
Elsewhere the channel is white and keeps the robust difference estimate exactly, so that a white log's noise
model is the one it always had. A first-order filter's spectrum falls by a half at its corner: below a corner
of about 30 Hz the band already sees it, and ``tau`` comes out short (by a fifth at 30 Hz).
"""

from math import comb

import numpy as np
from scipy.signal import welch

from fmscal.plant.physics import NoiseSpec

__all__ = ["estimate_noise", "difference_noise", "wrench_noise", "reading_colour", "colour_samples", "SEGMENT",
           "LOW_BAND", "WHITENESS_Z"]

#: Welch's segments of eq. (N1), s.
SEGMENT = 0.5
#: The lowest frequency at which the reading's spectrum is taken as the noise's (N1), Hz: above the motion's.
LOW_BAND = 10.0
#: A reading channel whose spectrum is not flat beyond this many of its standard deviations is coloured (N3).
WHITENESS_Z = 5.0
#: At least this many segments of eq. (N1) to measure the colour; fewer: the reading taken as white.
_MIN_SEGMENTS = 8


def estimate_noise(log):
    """Estimate measurement noise from the high-frequency residual of a log.

    For white noise of standard deviation ``sd``, the k-th difference of a
    series has variance ``C(2k, k) sd^2``; a smooth signal adds about
    ``(omega h)^k`` times its amplitude, negligible at 1 kHz but not for
    poses at 50 Hz. The estimate is the smallest over k = 2, 4, 6, 8 (a smooth
    part only ever adds), each with a robust scale (1.4826 MAD) that keeps
    outliers out. The pose is taken over its own measurements, so that a
    multi-rate log (poses at 50 Hz beside a 1 kHz sensor) is estimated too,
    over the runs of evenly spaced poses (a dropped frame ends a run).

    Parameters
    ----------
    log : plant.Log

    The reading's channels whose noise is coloured (eq. (N3) of the module
    docstring) take its standard deviation and correlation time from the
    spectrum instead (eqs. (N1), (N2)); the others keep the difference
    estimate.

    Returns
    -------
    plant.NoiseSpec
        ``wrench_sd`` from the raw reading (3 or 6 channels), and
        ``wrench_tau`` where a channel's noise is coloured (else None); ``angle_sd``
        and ``position_sd`` from the measured poses (the position standard
        deviation is the mean over the axes; in a spatial log the angle's
        from the quaternion's four components).
    """
    sd = _runs_sd
    wrench, tau = wrench_noise(log.w_hat, log.dt)
    runs = _even_runs(np.flatnonzero(log.has_pose))
    if getattr(log, "kind", "planar") == "spatial":
        # a turn n about the sensor's axes moves the unit quaternion by |n| / 2 over its four
        # components: sum_j var(q_j) = E|n|^2 / 4 = 3 angle_sd^2 / 4
        angle = np.sqrt(4.0 / 3.0 * sum(sd([log.pose[r, j] for r in runs]) ** 2 for j in range(4)))
        position = float(np.mean([sd([log.pose[r, j] for r in runs]) for j in range(4, 7)]))
        return NoiseSpec(wrench, float(angle), position, tau)
    if log.kind == "planar":
        angle = sd([log.pose[r, 0] for r in runs])
        position = 0.5 * (sd([log.pose[r, 1] for r in runs]) + sd([log.pose[r, 2] for r in runs]))
        return NoiseSpec(wrench, angle, position, tau)
    # another model's log: its angle and position columns by name, each kind's mean
    model, names = log._model, log.columns[1:1 + log.pose.shape[1]]
    angle = [sd([log.pose[r, j] for r in runs]) for j, c in enumerate(names) if c in model.angle_names]
    position = [sd([log.pose[r, j] for r in runs]) for j, c in enumerate(names) if c in model.position_names]
    return NoiseSpec(wrench, float(np.mean(angle)) if angle else 0.0, float(np.mean(position)) if position else 0.0,
                     tau)


def _runs_sd(runs):
    """The noise sd of one channel's evenly spaced runs (1-D arrays): :func:`estimate_noise`'s robust estimate,
    the smallest over k = 2, 4, 6, 8 of ``1.4826 MAD(diff_k) / sqrt(C(2k, k))``; 0.0 where too few samples."""
    estimates = []
    for k in (2, 4, 6, 8):
        d = np.concatenate([np.diff(r, n=k, axis=0) for r in runs if len(r) > k] or [np.empty((0,))])
        if len(d) >= 10:
            mad = np.median(np.abs(d - np.median(d)))
            estimates.append(1.4826 * mad / np.sqrt(comb(2 * k, k)))
    return float(min(estimates)) if estimates else 0.0


def difference_noise(values, rows=None):
    """Each column's noise sd by :func:`estimate_noise`'s robust estimate, for an array rather than a log.

    Parameters
    ----------
    values : array_like, shape (N, m)
    rows : array_like of int, optional
        The rows that hold samples (the others skipped), split into runs of even spacing as
        :func:`estimate_noise` splits a log's poses; default every row.

    Returns
    -------
    ndarray, shape (m,)
        0.0 for a column with too few samples or none that changes.
    """
    values = np.asarray(values, dtype=float)
    runs = [np.arange(len(values))] if rows is None else _even_runs(np.asarray(rows, dtype=int))
    return np.array([_runs_sd([values[r, j] for r in runs]) for j in range(values.shape[1])])


def _even_runs(rows):
    """Split sample indices into runs at the most common spacing (a dropped frame ends a run)."""
    if len(rows) < 2:
        return [rows]
    gaps = np.diff(rows)
    step = np.bincount(gaps).argmax()
    breaks = np.flatnonzero(gaps != step) + 1
    return np.split(rows, breaks)


def wrench_noise(w_hat, dt):
    """The reading's noise model: each channel's sd, and its correlation time where it is coloured.

    The robust difference estimate of :func:`estimate_noise` on every channel; the channels eq. (N3) finds
    coloured take eq. (N2)'s sd and ``tau`` instead (:func:`reading_colour`).

    Parameters
    ----------
    w_hat : ndarray, shape (N, c)
        The raw reading at evenly spaced samples.
    dt : float
        The sample interval, s.

    Returns
    -------
    wrench_sd : tuple of float, shape (c,)
    wrench_tau : tuple of float or None
        1.0 on the white channels; None where every channel is white (:class:`fmscal.plant.NoiseSpec`).
    """
    w = np.asarray(w_hat, dtype=float)
    wrench = tuple(_runs_sd([w[:, j]]) for j in range(w.shape[1]))
    colour = reading_colour(w, dt)
    if colour is None or not np.any(colour[2]):
        return wrench, None
    sd, tau, coloured = colour                       # eq. (N3): the coloured channels take eq. (N2)'s figures
    return (tuple(float(c) if k else v for v, c, k in zip(wrench, sd, coloured)),
            tuple(float(t) if k else 1.0 for t, k in zip(tau, coloured)))


def colour_samples(dt):
    """The fewest evenly spaced readings :func:`reading_colour` measures the noise's colour from, at interval ``dt``.

    Eq. (N1)'s spectrum over 8 segments of :data:`SEGMENT` s of the second difference (2 readings fewer): ``8
    round(SEGMENT / dt) + 2`` readings, 4 s at any rate. None where the readings are too slow for the bands of
    (N1)-(N3) (a sample rate of ``16 LOW_BAND`` Hz or less, or a segment under 16 samples): the reading is then
    taken as white, however many there are.

    Parameters
    ----------
    dt : float
        The sample interval ``h``, s.

    Returns
    -------
    int or None
    """
    per = int(round(SEGMENT / dt))
    if 2 * LOW_BAND >= 0.125 / dt or per < 16:
        return None
    return _MIN_SEGMENTS * per + 2


def reading_colour(w_hat, dt):
    """Each reading channel's noise spectrum: its standard deviation, correlation time and whether it is coloured.

    Eqs. (N1)-(N3) of the module docstring, on the whole reading (evenly spaced: a log's readings).

    Parameters
    ----------
    w_hat : ndarray, shape (N, c)
        The raw reading, its glitches bridged.
    dt : float
        The sample interval ``h``, s.

    Returns
    -------
    tuple of (ndarray, ndarray, ndarray of bool), each shape (c,), or None
        ``sd`` and ``tau`` of eq. (N2) and the test (N3); None where the log holds fewer than 8 segments of
        :data:`SEGMENT` s or samples too slow for the bands (:func:`colour_samples`; the reading is then taken as
        white).
    """
    w = np.asarray(w_hat, dtype=float)
    need = colour_samples(dt)
    if need is None or len(w) < need:
        return None
    per = int(round(SEGMENT / dt))
    d = np.diff(w, n=2, axis=0)
    count = len(d) // per
    segments = d[:count * per].reshape(count, per, -1)
    f, G_d = welch(segments, fs=1.0 / dt, nperseg=per, noverlap=0, window="hann", detrend="constant", axis=1)
    keep = f >= LOW_BAND
    G = G_d[:, keep] / (2.0 * np.sin(np.pi * f[keep] * dt))[None, :, None] ** 4            # (N1)
    f = f[keep]
    G_0 = G[:, f < 2 * LOW_BAND].mean(axis=(0, 1))
    low, high = G[:, f < 0.125 / dt].mean(axis=1), G[:, f >= 0.25 / dt].mean(axis=1)      # per segment (N3)
    G_lo, G_hi = low.mean(axis=0), high.mean(axis=0)
    floor = np.finfo(float).tiny
    with np.errstate(divide="ignore", invalid="ignore"):       # a dead channel (G zero): not coloured, below
        scatter = np.sqrt(low.var(axis=0, ddof=1) / (count * np.maximum(G_lo, floor) ** 2)
                          + high.var(axis=0, ddof=1) / (count * np.maximum(G_hi, floor) ** 2))
    coloured = np.abs(np.log(np.maximum(G_lo, floor) / np.maximum(G_hi, floor))) > WHITENESS_Z * scatter
    variance = G.mean(axis=0).sum(axis=0) * (f[1] - f[0]) + LOW_BAND * G_0                # (N2)
    tau = np.maximum(G_0 / np.maximum(2.0 * dt * variance, floor), 1.0)
    return np.sqrt(variance), tau, coloured & (G_lo > 0) & (G_hi > 0)
