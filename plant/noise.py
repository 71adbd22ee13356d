"""Noise standard deviations estimated from a log."""

import numpy as np

from .sensor import NoiseSpec

__all__ = ["estimate_noise"]


def estimate_noise(log):
    """Estimate measurement noise from the high-frequency residual of a log.

    For white noise of standard deviation ``sd`` on a smooth signal, the
    second difference ``y(n+1) - 2 y(n) + y(n-1)`` has variance ``6 sd^2``
    (the smooth part contributes ``y'' dt^2``, negligible at the log's
    rate). A robust scale (1.4826 MAD) keeps outliers out of the estimate.

    Parameters
    ----------
    log : plant.Log

    Returns
    -------
    plant.NoiseSpec
        ``wrench_sd`` from the raw reading; ``angle_sd`` and ``position_sd``
        from the pose (runs of consecutive measurements only; the position
        standard deviation is the mean of X and Y).
    """
    def sd(values):
        d2 = values[2:] - 2 * values[1:-1] + values[:-2]
        d2 = d2[np.isfinite(d2)]
        if len(d2) == 0:
            return 0.0
        return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))

    wrench = tuple(sd(log.w_hat[:, j]) for j in range(3))
    return NoiseSpec(wrench, sd(log.pose[:, 0]), 0.5 * (sd(log.pose[:, 1]) + sd(log.pose[:, 2])))
