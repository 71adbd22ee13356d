"""Does the model fit a log? The reference fit's residual against the noise measured from the log.

A fit of ``w_k = S w_hat_k + c`` (the wrench each sample needed, from the
smoothed poses: :func:`fmscal.observers.batch.needed_wrench`) leaves a
residual. Where the dynamics fit, it is the noise: the reading's, through
``S``, and the poses', through the differentiation. Where they do not (the
payload's mass properties or axes wrong, poses of another frame than the
sensor's), a part of it is the model's error. Two measures, both from the
data alone (:func:`misfit`):

1. **The residual against the noise**, per wrench component ``i``::

       rho_i = rms(e_i) / sqrt(sum_j S_ij^2 sigma_j^2 + p_i^2)                   (M1)

   ``sigma_j`` the reading's white noise measured from the log's
   high-frequency scatter (:func:`fmscal.observers.core.reading_noise`), ``p_i``
   the poses' share: the needed wrench recomputed from the poses with a
   seeded draw of their noise added (its standard deviations estimated from
   the log, :func:`fmscal.plant.estimate_noise`) less the wrench from the
   poses as they are. ``rho`` is about 1 where the model fits.
2. **One S for slow and fast motion.** ``S`` absorbs much of a wrong model
   (a frame turned by a few degrees turns the wrench nearly as a constant
   ``S`` would: the residual grows by a few per cent while ``S_hat`` moves by
   many sigma). What it cannot absorb is the part that grows with the
   speed (the centripetal and gyroscopic terms). The samples are split at
   the median of the motion's speed (``|v_k|``, each velocity component
   scaled by its spread), ``[S | c]`` fitted to each half with the
   cluster-robust covariance over blocks of time
   (:mod:`fmscal.observers.batch._cluster_covariance`), and::

       X2_i = d_i^T (C_slow,i + C_fast,i)^+ d_i,   d_i = [S | c]_slow,i - [S | c]_fast,i      (M2)

   for each row ``i`` of ``[S | c]`` (``C_i`` its block of the covariance),
   chi-square with ``K = rank(C_slow,i + C_fast,i)`` degrees of freedom
   where the model fits and the covariances are known; estimated from ``G``
   blocks of time it is Hotelling's ``T^2``, and ``(G - K) / (K (G - 1))
   X2_i`` is ``F(K, G - K)`` (no test with ``G <= K + 1``). The smallest
   p-value times the rows (Bonferroni) below :data:`MISFIT_SIGNIFICANCE` is
   a misfit (or an ``S`` that depends on the speed: no calibration either
   way). Row by row, so that a log of a few dozen blocks still tests ``K =
   n_w + 1`` numbers at a time. Where either half leaves a direction of the
   reading undetermined (held poses and slow moves) there is no test.
"""

import copy
from dataclasses import dataclass

import numpy as np
from scipy.stats import f as f_dist

from fmscal.plant import estimate_noise
from fmscal.plant.numerics import FmscalError

from fmscal.observers.batch import block_length, fit_readings, needed_wrench, nominal_motion
from fmscal.observers.core import reading_noise

__all__ = ["Misfit", "misfit", "inflate", "MISFIT_SIGNIFICANCE", "MISFIT_RATIO", "GROSS_RATIO"]

#: The probability, for a log the model fits, of calling it misfit by (M2).
MISFIT_SIGNIFICANCE = 1e-3
#: A residual this many times the noise (M1) or more is reported in words (and the covariance inflated). Not
#: much closer to 1: the reference's smoothed accelerations leave a bias of their own, which on a quiet log
#: sampled at 50 Hz (tests/data/golden/spatial_late.csv) already leaves a residual well above it.
MISFIT_RATIO = 2.0
#: A residual this many times the noise (M1) or more is a gross misfit: not converged.
GROSS_RATIO = 3.0
#: The slow and the fast part of eq. (M2): the samples below this quantile of the speed and above one less it.
#: The median: the extremes would see a misfit better, but the smoothed accelerations' bias grows with the
#: speed too, and over a long log it would pass for one.
SPLIT = 0.5
_SEED = 20261126        # the draw of the poses' noise (M1): fixed, so a check is repeatable


@dataclass
class Misfit:
    """The outcome of :func:`misfit`.

    Attributes
    ----------
    ratio : ndarray, shape (n_w,)
        ``rho_i`` of eq. (M1): the residual over the noise, per wrench component.
    residual_rms : ndarray, shape (n_w,)
        The reference fit's residual, N m and N.
    noise : ndarray, shape (n_w,)
        The residual the noise alone leaves (the denominator of (M1)).
    statistic : float
        ``X2_i`` of eq. (M2), the row with the smallest p-value.
    dof : int
        Its degrees of freedom.
    p_value : float
        That row's p-value times the rows (Bonferroni).
    fits : bool
        ``p_value`` at least :data:`MISFIT_SIGNIFICANCE` and every ``rho_i`` below :data:`MISFIT_RATIO`.
    gross : bool
        ``p_value`` below :data:`MISFIT_SIGNIFICANCE`, or a ``rho_i`` of :data:`GROSS_RATIO` or more: no
        calibration.
    warning : str or None
        One line when the model does not fit.
    S_spread : ndarray, shape (n_w, n_w)
        Half the difference of the ``S`` fitted to the fast and the slow half
        of the motion, entry by entry: how far the estimate depends on which
        motion it is fitted to (:func:`inflate`).
    """

    ratio: np.ndarray
    residual_rms: np.ndarray
    noise: np.ndarray
    statistic: float
    dof: int
    p_value: float
    fits: bool
    gross: bool
    warning: str = None
    S_spread: np.ndarray = None

    def to_dict(self):
        """The JSON form."""
        return {"ratio": [float(r) for r in self.ratio], "statistic": float(self.statistic), "dof": int(self.dof),
                "p_value": float(self.p_value), "fits": bool(self.fits), "gross": bool(self.gross)}


def _pose_share(log, model, w, window):
    """``p_i`` of eq. (M1): the needed wrench's change under a seeded draw of the poses' noise, rms per component."""
    noise = estimate_noise(log)
    sd = np.asarray(model.pose_sd(noise), dtype=float)
    if not np.any(sd > 0):
        return np.zeros(w.shape[1])
    rows = np.flatnonzero(log.has_pose)
    shaken = copy.copy(log)
    shaken.pose = log.pose.copy()
    shaken.pose[rows] += np.random.default_rng(_SEED).standard_normal((len(rows), len(sd))) * sd
    _, w_shaken = needed_wrench(shaken, model, window)
    return np.sqrt(np.mean((w_shaken - w) ** 2, axis=0))


def _split_statistic(w, w_hat, t, speed, wrench_sd, block):
    """Eq. (M2) row by row, the samples split at the median speed: the largest row's ``X2``, its degrees of
    freedom, the p-value (Bonferroni over the rows), and ``[S | c]_fast - [S | c]_slow``."""
    blocks = ((t - t[0]) // block).astype(int)
    g = int(np.unique(blocks).size)
    low, high = np.quantile(speed, [SPLIT, 1.0 - SPLIT])
    halves = (speed > high, speed <= low)
    if not all(h.any() for h in halves):            # one speed throughout (a pose that never moves): no split
        return 0.0, 0, 1.0, np.zeros((w.shape[1], w_hat.shape[1] + 1))
    fits = [fit_readings(w[h], w_hat[h], blocks[h], wrench_sd) for h in halves]
    n_w, k = fits[0].S_aug.shape
    worst = (0.0, 0, 1.0)
    difference = fits[0].S_aug - fits[1].S_aug
    if fits[0].undetermined or fits[1].undetermined:    # a half that leaves S undetermined: nothing to compare
        return 0.0, 0, 1.0, np.zeros_like(difference)
    for i in range(n_w):
        rows = slice(k * i, k * (i + 1))
        d = fits[0].S_aug[i] - fits[1].S_aug[i]
        C = fits[0].cov[rows, rows] + fits[1].cov[rows, rows]
        if not np.all(np.isfinite(C)):
            continue
        scale = np.sqrt(np.maximum(np.diag(C), 1e-300))
        u, s, _ = np.linalg.svd(C / np.outer(scale, scale))
        keep = s > 1e-10 * s[0]
        y = (u[:, keep].T @ (d / scale)) / np.sqrt(s[keep])
        statistic, dof = float(y @ y), int(keep.sum())
        if dof == 0 or g <= dof + 1:            # nothing to compare, or too few blocks to estimate d's covariance
            continue
        # the covariance estimated from g blocks: Hotelling's T^2 scaled to an F (module docstring)
        p = float(f_dist.sf((g - dof) / (dof * (g - 1)) * statistic, dof, g - dof))
        if p < worst[2]:
            worst = (statistic, dof, p)
    return worst[0], worst[1], min(1.0, n_w * worst[2]), difference


def misfit(log, model, window=0.2, significance=MISFIT_SIGNIFICANCE):
    """Measure how far a log is from the model: eqs. (M1) and (M2) of the module docstring.

    Parameters
    ----------
    log : plant.Log
        A log of the model's case, its poses aligned with the reading (the latency taken out).
    model : plant.Model
        Its payload known (the model's).
    window : float
        Smoothing window of the pose differentiation, s.
    significance : float
        The p-value of (M2) below which the log is misfit.

    Returns
    -------
    Misfit

    Raises
    ------
    FmscalError
        A log shorter than the smoothing window, or of another case.
    """
    model.check_log(log, "misfit")
    trim, w = needed_wrench(log, model, window)
    w_hat, t = log.w_hat[trim], log.t[trim]
    wrench_sd = reading_noise(log.w_hat)
    fit = fit_readings(w, w_hat, None, wrench_sd)
    e = w - w_hat @ fit.S_hat.T - fit.c
    noise = np.sqrt(np.square(fit.S_hat) @ np.square(wrench_sd) + np.square(_pose_share(log, model, w, window)))
    ratio = fit.residual_rms / np.maximum(noise, 1e-300)
    v = nominal_motion(log, model, window)[trim][:, list(model.v_index)]
    speed = np.sum((v / np.maximum(np.std(v, axis=0), 1e-300)) ** 2, axis=1)
    if len(w) < 8 * (model.n_w + 1):
        raise FmscalError(f"{log.name}: too short to measure the model's misfit ({len(w)} samples)")
    block = block_length(e, log.dt, window)
    statistic, dof, p_value, difference = _split_statistic(w, w_hat, t, speed, wrench_sd, block)
    split = p_value < significance
    worst = int(np.argmax(ratio))
    gross = bool(split or ratio[worst] >= GROSS_RATIO)
    fits = bool(not split and ratio[worst] < MISFIT_RATIO)
    warning = None if fits else _words(model, ratio, worst, statistic, dof, p_value, split)
    return Misfit(ratio=ratio, residual_rms=fit.residual_rms, noise=noise, statistic=statistic, dof=dof,
                  p_value=p_value, fits=fits, gross=gross, warning=warning,
                  S_spread=np.abs(difference[:, :model.n_w]) / 2)


def _words(model, ratio, worst, statistic, dof, p_value, split):
    """The warning: how far the residual is above the noise, and the S of slow and fast motion."""
    name = model.wrench_names[worst]
    parts = [f"the model does not fit the log: the residual is {ratio[worst]:.2g} times the noise (on {name}; "
             + ", ".join(f"{n} {r:.2g}" for n, r in zip(model.wrench_names, ratio)) + ")"]
    if split:
        parts.append(f"the S fitted to the slow half of the motion and to the fast half differ (chi-square "
                     f"{statistic:.3g} on {dof}, p = {p_value:.2g}), which one S that fits cannot do")
    parts.append("check the payload's mass properties and their axes (the sensor's), and that the poses are the "
                 "sensor's frame (not one turned from it); S_std is inflated by the misfit")
    return "; ".join(parts)


def inflate(S_std, found):
    """``S_std`` widened where the model does not fit: each entry by the residual's ratio to the noise of its
    row (M1), and by the spread between the fast and the slow half's ``S`` (M2), in quadrature::

        S_std'_ij = sqrt((max(1, rho_i) S_std_ij)^2 + S_spread_ij^2)                (M3)

    Parameters
    ----------
    S_std : ndarray, shape (n_w, n_w)
    found : Misfit

    Returns
    -------
    ndarray, shape (n_w, n_w)
        ``S_std`` itself where the model fits (``found.fits``).
    """
    if found.fits:
        return S_std
    return np.sqrt((np.maximum(found.ratio, 1.0)[:, None] * S_std) ** 2 + np.square(found.S_spread))
