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
3. **The inertia's shape.** Given the payload's sensitivity
   (:func:`fmscal.observers.batch.payload_sensitivity`), the log's own
   estimate of the inertia against the one given: each entry's change
   ``delta`` over its scale (:meth:`fmscal.plant.Model.inertia_scale`), their
   common scale taken out (no log can see it: it moves ``S`` exactly). With
   ``C_j`` the needed wrench's change per entry (eq. (Y2)), ``R_j`` its part
   the readings do not absorb (eq. (Y3)), ``e`` the reference fit's residual
   and ``W`` one over each component's residual variance::

       delta = -(sum_k C_k^T W R_k)^-1 sum_k C_k^T W e_k                       (M4)

   ``C`` on the left, not ``R``: ``R`` holds the readings' noise through the
   fit, as ``e`` does, and their product would bias ``delta`` by several per
   cent on a noisy log; ``C`` comes from the poses alone. Its covariance
   ``V`` is cluster-robust over blocks of time (eq. (U3), the scores
   ``C_k^T W (e_k + R_k delta)``). Two Hotelling's tests over its ``G``
   blocks (eq. (U4) of :mod:`fmscal.observers.batch._cluster_covariance`),
   on the directions ``V`` determines, at most the entries less one (none
   with ``G`` at most one more than those, a misfit whose correlation leaves
   few blocks): the log **sees** the shape where ``delta^T V^+ delta`` is
   significant, and the shape is **beyond its stated uncertainty** where
   ``delta^T (V + Sigma_I)^+ delta`` is (``Sigma_I`` the inertia's stated
   covariance, its common scale taken out): ``S_std`` then does not cover
   ``S``'s error, and the model does not fit. Within it, (M1) and (M2) are
   measured on the wrench of the inertia the log prefers: a shape the stated
   uncertainty covers is carried by ``S_std`` (its payload part), not a misfit.
4. **The centre of mass.** The same on its coordinates, none left out
   (``S`` absorbs a centre of mass given wrong on a log held still, not the
   part that moves with the rotation's rate and acceleration), fitted beside
   the inertia's shape (the directions of M4)::

       delta_c = -(sum_k C_k^T W R_k)^-1 sum_k C_k^T W e_k                     (M5)

   its covariance cluster-robust over the scores ``R_k^T W (e_k + R_k
   delta)`` (``R``, not ``C``: the centre of mass's columns are mostly what
   the readings absorb, whose share of each block's score cancels over the
   log), and its two tests Hotelling's, as (M2). It is not a warning of its
   own: on noisy poses (0.1 degree) it is biased beyond its sd on clean logs.
   It tests a latency that seems to step along the log: a step gone at the
   centre of mass the log prefers is the payload's, not the stamps'
   (:func:`fmscal.analysis.calibrate`).
"""

import copy
from dataclasses import dataclass

import numpy as np

from fmscal.plant import estimate_noise
from fmscal.plant.numerics import FmscalError

from fmscal.observers.batch import (block_length, fit_readings, hotelling, needed_wrench, nominal_motion,
                                    small_sample_factor)
from fmscal.observers.core import reading_noise

__all__ = ["Misfit", "InertiaShape", "CentreOfMass", "centre_of_mass_words", "misfit", "inertia_note", "inflate",
           "MISFIT_SIGNIFICANCE", "MISFIT_RATIO", "GROSS_RATIO"]

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
#: A misfit whose worst row, a force channel's, is :data:`MISFIT_RATIO` times its noise or more while every other
#: row's residual is within this many times its own is that channel's alone: the words point at its reading first
#: (a mass given wrong ``S`` takes up, an inertia's shape leaves the torques; a centre of mass given wrong is still
#: named beside it).
ALONE_RATIO = 1.2
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
    inertia : InertiaShape or None
        Eq. (M4), where the payload's sensitivity was given and the inertia has a shape (two entries or more).
    centre_of_mass : CentreOfMass or None
        Eq. (M5), where the payload's sensitivity was given and the log can tell the centre of mass.
    alone : int or None
        The force channel a misfit is alone on (its residual :data:`MISFIT_RATIO` times its noise or more, every
        other row's within :data:`ALONE_RATIO` of its own); None otherwise.
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
    inertia: object = None
    alone: int = None
    centre_of_mass: object = None

    def to_dict(self):
        """The JSON form."""
        out = {"ratio": [float(r) for r in self.ratio], "statistic": float(self.statistic), "dof": int(self.dof),
               "p_value": float(self.p_value), "fits": bool(self.fits), "gross": bool(self.gross)}
        if self.inertia is not None:
            out["inertia"] = self.inertia.to_dict()
        if self.alone is not None:
            out["alone"] = int(self.alone)
        if self.centre_of_mass is not None:
            out["centre_of_mass"] = self.centre_of_mass.to_dict()
        return out


@dataclass
class InertiaShape:
    """The inertia's shape as the log's torques see it, against the one given: eq. (M4).

    Attributes
    ----------
    names : tuple of str
        The inertia's entries (:attr:`fmscal.plant.Model.inertia_names`).
    delta, std : ndarray, shape (len(names),)
        The log's estimate of each entry less the one given, over its scale
        (:meth:`fmscal.plant.Model.inertia_scale`), their common scale taken
        out; and its one-sigma uncertainty from the log.
    statistic : float
        ``delta^T V^+ delta`` (on the directions ``V`` determines).
    dof : int
        Its degrees of freedom: the directions ``V`` determines, at most the entries less one (the common scale).
    p_value : float
        Of ``statistic``, Hotelling's over the blocks of time of ``V`` (1 with at most ``dof + 1`` of them): below
        the significance, the log sees the shape.
    p_stated : float
        Of ``delta^T (V + Sigma_I)^+ delta``: below the significance, the shape is beyond its stated uncertainty.
    seen, covered : bool
        ``p_value`` below the significance; ``p_stated`` at least the significance.
    preferred : ndarray, shape (len(names),), or None
        The inertia the log prefers: the entries given moved by ``delta`` times their scale (kg m^2, the
        common scale as given); None where that is no valid inertia.
    """

    names: tuple
    delta: np.ndarray
    std: np.ndarray
    statistic: float
    dof: int
    p_value: float
    p_stated: float
    seen: bool
    covered: bool
    preferred: np.ndarray = None

    def words(self):
        """The log's inertia in words: each entry's change in per cent of its scale, the common scale left out."""
        return ", ".join(f"{n} {100 * d:+.0f} %" for n, d in zip(self.names, self.delta))

    def to_dict(self):
        """The JSON form."""
        return {"names": list(self.names), "delta": [float(v) for v in self.delta],
                "std": [float(v) for v in self.std], "statistic": float(self.statistic), "dof": int(self.dof),
                "p_value": float(self.p_value), "p_stated": float(self.p_stated), "seen": bool(self.seen),
                "covered": bool(self.covered),
                "preferred": None if self.preferred is None else [float(v) for v in self.preferred]}


@dataclass
class CentreOfMass:
    """The centre of mass the log prefers, against the one given: eq. (M5).

    Attributes
    ----------
    names : tuple of str
        Its coordinates (:attr:`fmscal.plant.Model.payload_position_names`).
    delta, std : ndarray, shape (len(names),)
        The log's estimate less the one given, m, and its one-sigma uncertainty from the log.
    statistic : float
        ``delta^T V^+ delta``: Hotelling's ``T^2`` over the blocks of time of ``V``.
    p_value, p_stated : float
        Of ``statistic``, and of ``delta^T (V + Sigma_c)^+ delta`` (``Sigma_c`` the stated covariance), each
        scaled to an ``F`` (eq. (U4) of :mod:`fmscal.observers.batch._cluster_covariance`; 1 with too few
        blocks).
    seen, covered : bool
        ``p_value`` below the significance (the log sees a centre of mass other than the one given);
        ``p_stated`` at least the significance (the stated uncertainty covers it).
    preferred : ndarray, shape (len(names),)
        The centre of mass the log prefers, m.
    """

    names: tuple
    delta: np.ndarray
    std: np.ndarray
    statistic: float
    p_value: float
    p_stated: float
    seen: bool
    covered: bool
    preferred: np.ndarray

    def to_dict(self):
        """The JSON form."""
        return {"names": list(self.names), "delta": [float(v) for v in self.delta],
                "std": [float(v) for v in self.std], "statistic": float(self.statistic),
                "p_value": float(self.p_value), "p_stated": float(self.p_stated), "seen": bool(self.seen),
                "covered": bool(self.covered), "preferred": [float(v) for v in self.preferred]}


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
        # the covariance estimated from g blocks: Hotelling's T^2 scaled to an F (module docstring); p 1 where
        # nothing is compared, or too few blocks estimate d's covariance
        statistic, dof, p = hotelling(d, C, g)
        if p < worst[2]:
            worst = (statistic, dof, p)
    return worst[0], worst[1], min(1.0, n_w * worst[2]), difference


def misfit(log, model, window=0.2, significance=MISFIT_SIGNIFICANCE, sensitivity=None, payload_cov=None):
    """Measure how far a log is from the model: eqs. (M1), (M2) and (M4) of the module docstring.

    Parameters
    ----------
    log : plant.Log
        A log of the model's case, its poses aligned with the reading (the latency taken out).
    model : plant.Model
        Its payload known (the model's).
    window : float
        Smoothing window of the pose differentiation, s.
    significance : float
        The p-value of (M2) and (M4) below which the log is misfit.
    sensitivity : observers.batch.PayloadSensitivity, optional
        The payload's sensitivity on this log and model, with this ``window``
        (:func:`fmscal.observers.batch.payload_sensitivity`): its needed wrench
        is used, and with ``payload_cov`` the inertia's shape is tested (M4) and the centre of mass estimated (M5).
    payload_cov : ndarray, shape (k, k), optional
        The payload's covariance over its :meth:`~fmscal.plant.Model.payload_parameter_names`
        (:meth:`fmscal.plant.physics.PayloadStd.covariance`).

    Returns
    -------
    Misfit

    Raises
    ------
    FmscalError
        A log shorter than the smoothing window, or of another case.
    """
    model.check_log(log, "misfit")
    if sensitivity is None:
        trim, w = needed_wrench(log, model, window)
        wrench_sd = reading_noise(log.w_hat)
    else:
        trim, w, wrench_sd = sensitivity.rows, sensitivity.wrench, sensitivity.wrench_sd
    w_hat, t = log.w_hat[trim], log.t[trim]
    if len(w) < 8 * (model.n_w + 1):
        raise FmscalError(f"{log.name}: too short to measure the model's misfit ({len(w)} samples)")
    fit = fit_readings(w, w_hat, None, wrench_sd)
    e = w - w_hat @ fit.S_hat.T - fit.c
    pose_share = _pose_share(log, model, w, window)
    inertia, preferred, com = None, w, None
    if sensitivity is not None and payload_cov is not None:
        try:
            com = _centre_of_mass(sensitivity, model, e, t, log.dt, window, payload_cov, significance)
        except np.linalg.LinAlgError:                     # a log that cannot tell the centre of mass
            com = None
        inertia, correction = _inertia_shape(sensitivity, model, e, t, log.dt, window, payload_cov, significance)
        if inertia is not None and inertia.covered:       # (M1), (M2) on the wrench of the inertia the log prefers
            preferred = w + correction
            fit = fit_readings(preferred, w_hat, None, wrench_sd)
            e = preferred - w_hat @ fit.S_hat.T - fit.c
    noise = np.sqrt(np.square(fit.S_hat) @ np.square(wrench_sd) + np.square(pose_share))
    ratio = fit.residual_rms / np.maximum(noise, 1e-300)
    v = nominal_motion(log, model, window)[trim][:, list(model.v_index)]
    speed = np.sum((v / np.maximum(np.std(v, axis=0), 1e-300)) ** 2, axis=1)
    block = block_length(e, log.dt, window)
    statistic, dof, p_value, difference = _split_statistic(preferred, w_hat, t, speed, wrench_sd, block)
    split = p_value < significance
    worst = int(np.argmax(ratio))
    beyond = inertia is not None and not inertia.covered
    gross = bool(split or ratio[worst] >= GROSS_RATIO or beyond)
    fits = bool(not split and ratio[worst] < MISFIT_RATIO and not beyond)
    parts = [_inertia_words(inertia)] if beyond else []
    others = np.delete(ratio, worst)
    alone = worst if (worst in model.force_channels and ratio[worst] >= MISFIT_RATIO and others.size
                      and np.all(others < ALONE_RATIO)) else None
    if split or ratio[worst] >= MISFIT_RATIO:
        parts.append(_words(model, ratio, worst, statistic, dof, p_value, split, alone is not None))
    return Misfit(ratio=ratio, residual_rms=fit.residual_rms, noise=noise, statistic=statistic, dof=dof,
                  p_value=p_value, fits=fits, gross=gross, warning="; ".join(parts) if parts else None,
                  S_spread=np.abs(difference[:, :model.n_w]) / 2, inertia=inertia, alone=alone,
                  centre_of_mass=com)


def _shift(sensitivity, index, scale, Q, e, t, dt, window, payload_cov, unabsorbed_scores=False):
    """Eqs. (M4), (M5): the payload's numbers ``index`` the log prefers, over their ``scale``, in the directions
    ``Q`` (``a``; ``delta = Q a``), the needed wrench's change per unit of ``a`` (``C Q``), the covariance ``V``
    of ``a``, the stated covariance in the same directions, and the blocks of time ``G`` of ``V``.
    The scores of ``V`` take ``C`` (M4), or its unabsorbed part ``R`` (M5: the centre of mass's columns are
    mostly what the readings absorb, whose share of each block's score cancels over the log and would
    widen ``V`` many times)."""
    C = (sensitivity.columns[:, :, index] * scale) @ Q
    R = (sensitivity.unabsorbed(index) * scale) @ Q
    weight = 1.0 / np.maximum(np.mean(e ** 2, axis=0), 1e-300)
    H = np.einsum("mcj,c,mck->jk", C, weight, R)
    H = (H + H.T) / 2
    a = -np.linalg.solve(H, np.einsum("mcj,c,mc->j", C, weight, e))
    scores = np.einsum("mcj,c,mc->mj", R if unabsorbed_scores else C, weight, e + R @ a)
    blocks = ((t - t[0]) // block_length(e + R @ a, dt, window)).astype(int)
    summed = np.zeros((blocks.max() + 1, len(a)))
    np.add.at(summed, blocks, scores)
    H_inv = np.linalg.inv(H)
    V = small_sample_factor(blocks, len(e), len(a)) * H_inv @ (summed.T @ summed) @ H_inv
    stated = Q.T @ (np.asarray(payload_cov, dtype=float)[np.ix_(index, index)] / np.outer(scale, scale)) @ Q
    return a, C, V, stated, int(blocks.max() + 1)


def _tests(a, V, stated, g):
    """Eq. (U4) of :mod:`fmscal.observers.batch._cluster_covariance` (Hotelling's over ``g`` blocks, on the
    directions the covariance determines: one from fewer blocks than numbers is singular) of ``a`` against ``V``,
    and against ``V`` plus ``stated`` (p-value 1 where ``stated`` is not finite: any change covered): the statistic
    against ``V``, the directions ``V`` determines, and the two p-values."""
    statistic, dof, p_value = hotelling(a, V, g)
    p_stated = hotelling(a, V + stated, g)[2] if np.all(np.isfinite(stated)) else 1.0
    return statistic, dof, p_value, p_stated


def _shapes(sensitivity, model):
    """The inertia's entries (indices into the sensitivity's names), their scales, and the shapes: the directions
    orthogonal to their common scale (M4); None for an inertia of one entry."""
    index = [sensitivity.names.index(name) for name in model.inertia_names]
    if len(index) < 2:
        return None
    scale = model.inertia_scale()
    u = sensitivity.values[index] / scale                       # the common scale, in each entry's own scale
    return index, scale, np.linalg.svd(u[None, :] / np.linalg.norm(u))[2][1:].T


def _inertia_shape(sensitivity, model, e, t, dt, window, payload_cov, significance):
    """Eq. (M4): the inertia's shape the log prefers, its tests, and the needed wrench's change to it
    (``(InertiaShape, correction)``; ``(None, None)`` for an inertia of one entry)."""
    shapes = _shapes(sensitivity, model)
    if shapes is None:
        return None, None
    index, scale, Q = shapes
    a, C, V, stated, g = _shift(sensitivity, index, scale, Q, e, t, dt, window, payload_cov)
    statistic, dof, p_value, p_stated = _tests(a, V, stated, g)
    delta = Q @ a
    preferred = sensitivity.values.copy()
    preferred[index] += delta * scale
    try:
        model.with_payload_parameters(preferred)
        preferred = preferred[index]
    except FmscalError:                                         # the shape the log says is no body's
        preferred = None
    shape = InertiaShape(names=tuple(model.inertia_names), delta=delta, std=np.sqrt(np.diag(Q @ V @ Q.T)),
                         statistic=statistic, dof=dof, p_value=p_value, p_stated=p_stated,
                         seen=p_value < significance, covered=p_stated >= significance, preferred=preferred)
    return shape, C @ a


def _centre_of_mass(sensitivity, model, e, t, dt, window, payload_cov, significance):
    """Eq. (M5): the centre of mass the log prefers against the one given, and its tests (None for a model whose
    payload's position is not its centre of mass); fitted beside the inertia's shape (M4's directions), which would
    otherwise lean on it."""
    if model.payload_position != "com":
        return None
    index = [sensitivity.names.index(name) for name in model.payload_position_names]
    n = len(index)
    scale, Q = np.ones(n), np.eye(n)
    shapes = _shapes(sensitivity, model)
    if shapes is not None:                                      # beside the inertia's shapes (M4's directions)
        inertia, inertia_scale, shape_Q = shapes
        Q = np.block([[Q, np.zeros((n, shape_Q.shape[1]))], [np.zeros((len(inertia), n)), shape_Q]])
        index, scale = index + inertia, np.r_[scale, inertia_scale]
    a, _, V, _, g = _shift(sensitivity, index, scale, Q, e, t, dt, window, payload_cov, unabsorbed_scores=True)
    stated = np.asarray(payload_cov, dtype=float)[np.ix_(index[:n], index[:n])]
    a, V = a[:n], V[:n, :n]
    statistic, _, p_value, p_stated = _tests(a, V, stated, g)
    return CentreOfMass(names=tuple(model.payload_position_names), delta=a, std=np.sqrt(np.diag(V)),
                        statistic=statistic, p_value=p_value, p_stated=p_stated, seen=p_value < significance,
                        covered=p_stated >= significance, preferred=sensitivity.values[index[:n]] + a)


def centre_of_mass_words(com):
    """The centre of mass the log prefers, in words (M5): each coordinate's change and sd, mm, against the one
    given, and the test against its stated uncertainty."""
    mm = ", ".join(f"{n} {1e3 * d:+.1f} +- {1e3 * sd:.1f} mm" for n, d, sd in zip(com.names, com.delta, com.std))
    return (f"the log prefers a centre of mass {mm} from the one given, beyond its stated uncertainty (p = "
            f"{com.p_stated:.2g}): check the centre of mass (--com {' '.join(f'{v:.4g}' for v in com.preferred)}, "
            "the one the log prefers), and that the poses are the sensor's frame (a turn of it moves the centre "
            "of mass the log prefers alike)")


def _inertia_words(shape):
    """The warning of an inertia's shape beyond its stated uncertainty (M4)."""
    return (f"the payload's inertia does not fit the log's torques: they say {shape.words()} of each entry's scale "
            f"against the inertia given (a common scale aside, which no log can see), beyond the inertia's stated "
            f"uncertainty (p = {shape.p_stated:.2g}), which S_std's payload part takes; check the inertia's entries, "
            f"that it is about the centre of mass in the sensor's axes{_preferred_words(shape)}, or state its "
            "uncertainty (--inertia-std)")


def _preferred_words(shape):
    """``", or try the inertia the log prefers (--inertia ...)"``, where that is a valid inertia; else empty."""
    if shape.preferred is None:
        return ""
    return (f", or try the inertia the log prefers (--inertia {' '.join(f'{v:.3g}' for v in shape.preferred)}, "
            "the common scale as given)")


def inertia_note(shape, converged=True):
    """What a calibration says of an inertia whose shape the log sees within its stated uncertainty (M4).

    Parameters
    ----------
    shape : InertiaShape or None
    converged : bool
        Whether the calibration converged: where it did not, the inertia is named as a likely cause (its shape
        moves the fit with the motion: the estimate does not settle, the latency seems to step; the calibration
        checks that step at the inertia the log prefers).

    Returns
    -------
    str or None
        None where the log does not see the shape, or sees it beyond its stated uncertainty (the misfit's
        warning says so).
    """
    if shape is None or not shape.seen or not shape.covered:
        return None
    seen = (f"the log's torques see the payload's inertia's shape: {shape.words()} of each entry's scale against "
            f"the inertia given (a common scale aside; p = {shape.p_value:.2g})")
    if converged:
        return f"{seen}, within its stated uncertainty, which S_std's payload part carries"
    return (f"{seen}: such a shape moves the fit with the motion (S_hat, and the latency found along the log), and "
            f"may be why the calibration did not converge (S_std's payload part covers S's error)"
            f"{_preferred_words(shape)}")


def _words(model, ratio, worst, statistic, dof, p_value, split, alone=False):
    """The warning: how far the residual is above the noise, and the S of slow and fast motion; the payload
    suspected, or, where the misfit is one force channel's alone (:data:`ALONE_RATIO`), that channel's reading first."""
    name = model.wrench_names[worst]
    parts = [f"the model does not fit the log: the residual is {ratio[worst]:.2g} times the noise (on {name}; "
             + ", ".join(f"{n} {r:.2g}" for n, r in zip(model.wrench_names, ratio)) + ")"]
    if split:
        parts.append(f"the S fitted to the slow half of the motion and to the fast half differ (chi-square "
                     f"{statistic:.3g} on {dof}, p = {p_value:.2g}), which one S that fits cannot do")
    if alone:
        parts.append(f"the misfit is on {name} alone (every other channel within {ALONE_RATIO:g} times its noise): "
                     f"check {name}'s reading first (an offset that moves, glitches), then the payload's centre of "
                     "mass; S_std is inflated by the misfit")
    else:
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
