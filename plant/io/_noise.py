"""Noise standard deviations estimated from a log."""

from math import comb

import numpy as np

from fmscal.plant.physics import NoiseSpec

__all__ = ["estimate_noise", "difference_noise"]


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

    Returns
    -------
    plant.NoiseSpec
        ``wrench_sd`` from the raw reading (3 or 6 channels); ``angle_sd``
        and ``position_sd`` from the measured poses (the position standard
        deviation is the mean over the axes; in a spatial log the angle's
        from the quaternion's four components).
    """
    sd = _runs_sd
    wrench = tuple(sd([log.w_hat[:, j]]) for j in range(log.w_hat.shape[1]))
    runs = _even_runs(np.flatnonzero(log.has_pose))
    if getattr(log, "kind", "planar") == "spatial":
        # a turn n about the sensor's axes moves the unit quaternion by |n| / 2 over its four
        # components: sum_j var(q_j) = E|n|^2 / 4 = 3 angle_sd^2 / 4
        angle = np.sqrt(4.0 / 3.0 * sum(sd([log.pose[r, j] for r in runs]) ** 2 for j in range(4)))
        position = float(np.mean([sd([log.pose[r, j] for r in runs]) for j in range(4, 7)]))
        return NoiseSpec(wrench, float(angle), position)
    if log.kind == "planar":
        angle = sd([log.pose[r, 0] for r in runs])
        position = 0.5 * (sd([log.pose[r, 1] for r in runs]) + sd([log.pose[r, 2] for r in runs]))
        return NoiseSpec(wrench, angle, position)
    # another model's log: its angle and position columns by name, each kind's mean
    model, names = log._model, log.columns[1:1 + log.pose.shape[1]]
    angle = [sd([log.pose[r, j] for r in runs]) for j, c in enumerate(names) if c in model.angle_names]
    position = [sd([log.pose[r, j] for r in runs]) for j, c in enumerate(names) if c in model.position_names]
    return NoiseSpec(wrench, float(np.mean(angle)) if angle else 0.0, float(np.mean(position)) if position else 0.0)


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
