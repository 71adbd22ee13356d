"""The delay of the pose stream behind the sensor stream, to a fraction of a sample, with its uncertainty.

A vision system delivers each pose a roughly constant time after it was
taken (a positive latency); a sensor's internal filter delays the wrench
instead (a negative one). Shifted back by the right delay, the log fits its
dynamics best.

The fit. The wrench each sample needed, ``w(t)``, is computed once from the
smoothed and differentiated poses (:func:`fmscal.observers.batch.needed_wrench`:
Newton-Euler in 3D, eq. (1) inverted in the plane). Moving the poses back by
``tau`` moves it to ``w(t + tau)``, so every candidate delay is the same
motion read at shifted times, not a new fit of the poses. On a fixed set of
rows ``k`` (those ``w(t_k + tau)`` covers for every ``|tau| <= max_latency``),
``w(t_k + tau) = [S | c] [w_hat_k; 1] + e_k`` is fitted by least squares,
and the cost is the sum over the wrench components of the share of their
variance the fit leaves unexplained::

    J(tau) = sum_c RSS_c(tau) / TSS_c(tau)                       (L1)

The rule.

1. ``J`` on a grid of whole samples over ``[-K, K]``, ``K = round(max_latency / dt)``, about ten
   steps each side, then at every whole sample within a step of the grid's best.
2. A parabola through the best whole sample ``k*`` and its two neighbours:
   ``tau_0 = (k* + (J(k*-1) - J(k*+1)) / (2 (J(k*-1) - 2 J(k*) + J(k*+1)))) dt``,
   the fraction clipped to one sample. No clear minimum (``k*`` at ``+-K``,
   or the parabola not convex): the latency is undetermined.
3. Two Newton steps on the residual sum of squares weighted by each
   component's residual variance ``s_c^2``: with ``g_k = (I - P) w'(t_k + tau)``
   and ``h_k = (I - P) w''(t_k + tau)`` (the time derivatives of the needed
   wrench, ``P`` the projection on the readings ``[w_hat; 1]``)::

       H = sum_kc (g_kc^2 + e_kc h_kc) / s_c^2,    tau <- tau - sum_kc e_kc g_kc / s_c^2 / H      (L2)

   The curvature ``H`` is the cost's own, not Gauss-Newton's ``sum g^2``:
   the needed wrench carries the differentiated noise of the poses ``n``
   in ``e`` and its derivative ``n'`` in ``g``, so ``sum g^2`` counts
   ``sum n'^2`` as information about ``tau`` (the noise moves with the
   poses it came from); ``sum e h`` carries ``sum n n'' = -sum n'^2`` (by
   parts) and takes it out. On noisy poses ``sum n'^2`` is most of
   ``sum g^2``, and Gauss-Newton's standard deviation was many times too
   small.
4. Its variance, cluster-robust over blocks of time (length
   :func:`block_length` of the scores, eq. (U2), or longer where the
   scores' variance grows with the length, eq. (L7)), with the small-sample
   factor (eq. (U3))::

       var(tau) = CR1 * sum_b (sum_{k in b, c} e_kc g_kc / s_c^2)^2 / H^2                  (L3)

   The latency is undetermined when its standard deviation exceeds
   :data:`UNDETERMINED_SAMPLES` samples, or when the curvature is not
   clearly above its own noise: the products of the readings' noise and
   the differentiated poses' in ``e h`` make ``H`` noisy, and where the
   motion's own curvature is below that noise, the minimum found is the
   noise's (it moves from one noisy log to the next, and ``H`` at it is
   biased upwards by the choice of the lowest point). With ``H_b`` each
   block's ``sum e h / s^2`` and ``n_b`` its rows (the motion's share,
   ``sum g^2``, differs from block to block and is not noise)::

       std(H)^2 = CR1 * sum_b (H_b - n_b / N sum_b H_b)^2,   determined only if H > CURVATURE_SIGMAS std(H)   (L6)

   The blocks: the scores' correlation time (eq. U1) is the rows', where
   the noise's products are white; a weak correlation over the motion's
   own time (a systematic residual along a slow move) is lost under them
   and shows only as block sums whose variance grows with the blocks'
   length. Lengths ``2^j L_0`` (``L_0`` of eq. U2) are tried while
   :data:`~fmscal.observers.batch.MIN_BLOCKS` blocks remain, and the
   longest whose variance ``V_j`` exceeds the shortest's by two of its own
   standard errors is taken::

       V_j = CR1 sum_b s_b^2  (blocks of 2^j L_0),  taken where  V_j > V_0 (1 + 2 sqrt(2 / (G_j - 1)))   (L7)

5. ``d[S | c] / d tau = (X^T X)^-1 X^T w'(t + tau)`` (``X`` the readings
   ``[w_hat; 1]``), for the calibration to carry ``var(tau)`` into ``S_std``.   (L4)
6. One latency for the whole log: the scores of (L3) summed over
   :data:`SEGMENTS` consecutive parts of the log give each part's own step
   from ``tau`` and its variance; parts that disagree (chi-square of their
   spread above its ``1 - STEP_P`` quantile, the change at least ``MIN_STEP`` samples) mean a latency that
   changes mid-log
   (a dropped or duplicated sample, a clock step). The change is placed at the
   block border that best splits the blocks' scores into two constant latencies.
   Each block's curvature is its Gauss-Newton share of ``H`` (a part's own
   ``H`` is too noisy to divide by).
7. The smoothing window biases the needed wrench a little differently at
   each length: the search is repeated with half the window and half the
   difference of the two estimates is added to the standard deviation::

       std^2 = std_L3^2 + ((tau_window - tau_window/2) / 2)^2                (L5)

The fit's own latency. The rule above finds the delay at which the needed
wrench, read off the smoothed poses, best matches the readings: a model
continuous in time. The maximum-likelihood floor has its own: the reading
linear between samples, the motion integrated over each step
(:mod:`fmscal.observers.batch._linearised_floor`). Its first pass profiles its
likelihood in a further delay ``eps`` of the poses (eq. LF1 there: the
poses ``eps`` later move the wrench that drives them by ``-eps S w_hat'``),
which gives the step ``eps_hat`` its likelihood prefers from the latency the
log was aligned at, and the step's standard deviation ``s_fit`` (eq. LF2).
On a log recorded as the two models take it, they agree: a wrench held
over each step from the sample that records it (a zero-order hold, as an
engine steps) drives the motion as that reading does half a step later, in
either model, so both find ``dt / 2`` more than the stamps say.

8. The estimate and the fit. Where the fit's step exceeds
   :data:`AGREEMENT_SIGMAS` standard deviations of the estimate, the two
   models disagree about the log, and the fit's latency ``tau + eps_hat``
   is taken, with the fit's standard deviation (:func:`fit_latency`): the
   calibration is the fit's, and its ``E`` is lowest where its own
   likelihood is highest.
9. A latency given (:func:`given_latency_warnings`) is compared with the
   estimate: beyond :data:`AGREEMENT_SIGMAS` standard deviations, a warning
   that names both. The fit at the latency given is measurably worse where
   its own step from it exceeds :data:`AGREEMENT_SIGMAS` of its standard
   deviations (or, for a method without the fit's step, where the estimate
   is that far): ``converged`` False.
"""

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.stats import chi2

from fmscal.plant import Log
from fmscal.plant.numerics import FmscalError, as_positive_scalar
from fmscal.plant.physics import as_model

from ._cluster_covariance import MIN_BLOCKS, block_length, small_sample_factor
from ._inverse_dynamics import needed_wrench

__all__ = ["estimate_latency", "LatencyEstimate", "UNDETERMINED_SAMPLES", "AGREEMENT_SIGMAS", "CURVATURE_SIGMAS",
           "fit_latency", "given_latency_warnings"]

#: The latency counts as undetermined when its standard deviation is above this many samples.
UNDETERMINED_SAMPLES = 3.0
#: Rule 1's coarse grid: about this many steps on each side of zero.
_COARSE = 10
#: The blocks of eq. (L3) are this many times eq. (U2)'s length of the scores' own correlation.
_BLOCK_WINDOWS = 1.0
#: Consecutive parts of the log whose latencies are compared (rule 6).
SEGMENTS = 6
#: A latency that changes along the log is reported when the parts' chi-square has a p-value below this ...
STEP_P = 1e-4
#: ... and the change between the two sides is at least this many samples (a lost or repeated sample is one).
MIN_STEP = 0.5
#: Rules 8 and 9: the fit's own latency, or a latency given, this many standard deviations from the estimate.
AGREEMENT_SIGMAS = 3.0
#: Eq. (L6): the cost's curvature at the estimate must exceed this many of its own standard deviations.
CURVATURE_SIGMAS = 3.0


@dataclass
class LatencyEstimate:
    """The pose stream's delay behind the sensor stream, estimated from a log (module docstring).

    Attributes
    ----------
    latency : float
        s, of either sign (positive: the poses are late), a fraction of a sample.
    std : float
        Its one-sigma uncertainty, s (eq. L3); infinite where the cost has no clear minimum.
    costs : dict
        ``{latency_s: cost}`` at every whole sample tried (eq. L1).
    determined : bool
        The log tells the candidate delays apart: a clear minimum, and ``std`` within
        :data:`UNDETERMINED_SAMPLES` samples.
    dS_dlatency : ndarray, shape (n_w, n_w + 1), or None
        ``d[S | c] / d latency`` of the least-squares fit at the estimate (eq. L4), per s.
    step : dict or None
        Where the latency changes mid-log (rule 6): ``{"t": s, "size": s, "before": s, "after": s}``.
    warnings : list of str
        Why the latency is undetermined, or where it changes, in words.
    unresolved : list of str
        Those of ``warnings`` that say the log's data leave the latency undetermined (no clear minimum, a
        curvature within its noise, too large an uncertainty): not a search too narrow, nor a step along the log.
    source : str
        ``"cross-correlation"`` (rules 1-7), or ``"fit"``: the fit's own latency, taken where the two
        disagree (rule 8).
    notes : list of str
        What rule 8 did, in words.
    curvature : tuple of float or None
        ``(H, std(H))``: the cost's curvature in the latency at the estimate and its standard deviation
        (eqs. L2, L6); None without a clear minimum.
    """

    latency: float
    std: float
    costs: dict
    determined: bool = True
    dS_dlatency: np.ndarray = None
    step: dict = None
    warnings: list = field(default_factory=list)
    unresolved: list = field(default_factory=list)
    source: str = "cross-correlation"
    notes: list = field(default_factory=list)
    curvature: tuple = None
    _blocks: tuple = field(default=None, repr=False)        # rule 6's inputs: scores, information, times, length


def _interp(t_query, t, w):
    """``w`` (rows at ``t``) at ``t_query``, column by column, linearly."""
    return np.column_stack([np.interp(t_query, t, w[:, c]) for c in range(w.shape[1])])


def estimate_latency(log, model, max_latency=0.1, offset=False, window=0.4):
    """Delay of the pose stream behind the sensor stream, of either sign, with its standard deviation.

    Parameters
    ----------
    log : plant.Log
        A log of the model's case.
    model : plant.Model, plant.Payload or plant.SpatialPayload
        The problem (a payload stands for its case's model; a spatial
        model carries the gravity).
    max_latency : float
        Largest magnitude of the delay considered, s: the search covers
        ``[-max_latency, max_latency]``.
    offset : bool
        Kept for the callers that pass it: the fit of eq. (L1) always takes
        the constant ``c`` (the sensor's offset).
    window : float
        Smoothing window of the pose differentiation, s; the estimate is
        repeated with half of it, and half their difference is taken as a
        systematic uncertainty (eq. L5).

    Returns
    -------
    LatencyEstimate
        The rule is the module docstring's.

    Raises
    ------
    TypeError
        ``log`` is not a :class:`plant.Log`.
    FmscalError
        No model, a log of another case, or a ``max_latency`` too long for the log.
    """
    model = as_model(model, "estimate_latency")
    if not isinstance(log, Log):
        raise TypeError(f"log must be a plant.Log; got {type(log).__name__}")
    model.check_log(log, "the latency search")
    max_latency = as_positive_scalar(max_latency, "max_latency")
    window = as_positive_scalar(window, "window")
    K = int(round(max_latency / log.dt))
    if K * log.dt >= log.duration / 4:
        raise FmscalError(f"max_latency {max_latency:g} s is too long for a {log.duration:g} s log")
    estimate = _search(log, model, K, window)
    if np.isfinite(estimate.std):                                             # eq. (L5)
        other = _search(log, model, K, window / 2, start=estimate.latency)
        estimate.std = float(np.hypot(estimate.std, (estimate.latency - other.latency) / 2))
    _judge(estimate, log.dt, K)
    return estimate


def _search(log, model, K, window, start=None):
    """Rules 1 to 5 of the module docstring with one smoothing window; the estimate not yet judged."""
    dt = log.dt
    trim, w = needed_wrench(log, model, window)
    t_w = log.t[trim]
    w_hat = log.w_hat[trim]
    M = len(t_w)
    rows = np.arange(K + 1, M - K - 1)                 # w(t_k + tau) inside for every |tau| <= (K + 1) dt
    if len(rows) < 10 * (model.n_w + 2):
        raise FmscalError(f"max_latency {K * dt:g} s is too long for a {log.duration:g} s log")
    X = np.c_[w_hat[rows], np.ones(len(rows))]
    spread = np.r_[np.maximum(np.std(X[:, :-1], axis=0), 1e-300), 1.0]
    Xs = X / spread
    solve = np.linalg.inv(Xs.T @ Xs)

    def fitted(wt):
        return solve @ (Xs.T @ wt)

    def residual(wt):
        return wt - Xs @ fitted(wt)

    n = len(rows)

    def cost(k):                                                              # eq. (L1), at a whole sample k
        wt = w[rows[0] + k:rows[-1] + 1 + k]
        xw = Xs.T @ wt
        square = np.einsum("ij,ij->j", wt, wt)
        rss = square - np.einsum("ij,ij->j", xw, solve @ xw)
        tss = square - n * wt.mean(axis=0) ** 2
        return float(np.sum(rss / np.maximum(tss, 1e-300)))

    costs = {}
    if start is None:                           # rule 1: a coarse grid, then every sample about its best point
        step = max(1, K // _COARSE)
        for k in range(-K, K + 1, step):
            costs[k] = cost(k)
        coarse = min(costs, key=costs.get)
        candidates = range(max(-K, coarse - step), min(K, coarse + step) + 1)
    else:                                       # about a known estimate (rule 7)
        centre = int(round(start / dt))
        candidates = range(max(-K, centre - 1), min(K, centre + 1) + 1)
    for k in candidates:
        if k not in costs:
            costs[k] = cost(k)
    best = min(costs, key=costs.get)
    while -K < best < K and (best - 1 not in costs or best + 1 not in costs):   # the minimum's two neighbours
        for k in (best - 1, best + 1):
            if k not in costs:
                costs[k] = cost(k)
        best = min(costs, key=costs.get)
    clear = -K < best < K
    frac = 0.0
    if clear:
        c_minus, c_0, c_plus = costs[best - 1], costs[best], costs[best + 1]
        bend = c_minus - 2 * c_0 + c_plus
        clear = bend > 0
        if clear:
            frac = float(np.clip((c_minus - c_plus) / (2 * bend), -1.0, 1.0))
    tau = (best + frac) * dt
    w_dot = np.gradient(w, t_w, axis=0)
    w_ddot = np.gradient(w_dot, t_w, axis=0)
    t_rows = t_w[rows]

    def terms(tau):
        """Each row's residual ``e``, its derivative's residual ``g``, the weights, and each row's ``e h`` (L2)."""
        e = residual(_interp(t_rows + tau, t_w, w))
        g = residual(_interp(t_rows + tau, t_w, w_dot))
        h = residual(_interp(t_rows + tau, t_w, w_ddot))
        weight = 1.0 / np.maximum(np.mean(e ** 2, axis=0), 1e-300)
        return e, g, weight, np.sum(e * h * weight, axis=1)

    for _ in range(2):                                                         # eq. (L2)
        e, g, weight, eh = terms(tau)
        curvature = float(np.sum(g ** 2 * weight) + eh.sum())
        if not clear or curvature <= 0:
            break
        tau = float(np.clip(tau - np.sum(e * g * weight) / curvature, -K * dt, K * dt))
    e, g, weight, eh = terms(tau)
    per_row = np.sum(e * g * weight, axis=1)                                   # each row's score
    info_row = np.sum(g ** 2 * weight, axis=1)                                 # Gauss-Newton's information
    curvature = float(info_row.sum() + eh.sum())
    length, blocks = _score_blocks(per_row, t_rows, _BLOCK_WINDOWS * block_length(per_row[:, None], dt, window))
    scores = np.bincount(blocks, per_row)
    factor = small_sample_factor(blocks, len(rows), 1)
    share = np.bincount(blocks) / len(rows)
    curvature_std = float(np.sqrt(factor * np.sum((np.bincount(blocks, eh) - eh.sum() * share) ** 2)))   # (L6)
    determined = clear and curvature > CURVATURE_SIGMAS * curvature_std
    several = determined and blocks.max() > 0
    std = float(np.sqrt(factor * np.sum(scores ** 2)) / curvature) if several else np.inf                 # eq. (L3)
    # rule 6's information per block: the Gauss-Newton shares of the curvature
    infos = np.bincount(blocks, info_row) * (curvature / max(float(info_row.sum()), 1e-300))
    # eq. (L4): d[S | c]/d tau of the least-squares fit, in the readings' units
    theta_dot = fitted(_interp(t_rows + tau, t_w, w_dot)) / spread[:, None]
    estimate = LatencyEstimate(latency=float(tau), std=std, costs={k * dt: c for k, c in sorted(costs.items())},
                               dS_dlatency=theta_dot.T, determined=determined,
                               curvature=(curvature, curvature_std) if clear else None)
    estimate._blocks = (scores, infos, t_rows, length)
    return estimate


def _score_blocks(per_row, t_rows, shortest):
    """The blocks of eq. (L3): ``shortest`` (eq. U2) long, or longer where the scores' variance grows with the
    length (eq. L7, rule 4 of the module docstring).

    Returns
    -------
    length : float
        s.
    blocks : ndarray of int
        Each row's block.
    """
    def variance(length):
        blocks = ((t_rows - t_rows[0]) // length).astype(int)
        return blocks, small_sample_factor(blocks, len(per_row), 1) * np.sum(np.bincount(blocks, per_row) ** 2)

    best_blocks, base = variance(shortest)
    best = shortest
    length = 2 * shortest
    while (t_rows[-1] - t_rows[0]) // length + 1 >= MIN_BLOCKS:
        blocks, v = variance(length)
        g = int(blocks.max()) + 1
        if v > base * (1 + 2 * np.sqrt(2 / (g - 1))):
            best, best_blocks = length, blocks
        length *= 2
    return best, best_blocks


def _judge(estimate, dt, K):
    """Whether the log determines the latency (rule 2's clear minimum, :data:`UNDETERMINED_SAMPLES`) and keeps one
    along the log (rule 6); the warnings in words, those of the data's (``unresolved``) among them."""
    ms = 1e3
    tau, std = estimate.latency, estimate.std
    if not estimate.determined and K < 2:    # rule 2's parabola needs a sample each side of the best in range
        estimate.std = np.inf
        estimate.warnings.append(
            f"the pose stream's latency is not determined: the delays searched (+-{K * dt * ms:g} ms) span under "
            f"two samples of this log (dt = {dt * ms:g} ms), too few to find a minimum between them; search "
            "further (--max-latency), or give the latency if it is known (--latency)")
    elif not estimate.determined and estimate.curvature is not None and 0 < estimate.curvature[1] \
            and estimate.curvature[0] <= CURVATURE_SIGMAS * estimate.curvature[1]:
        estimate.std = np.inf
        h, h_std = estimate.curvature
        estimate.unresolved.append(
            f"the pose stream's latency is not determined: the cost's curvature in the delay at its lowest point, "
            f"{tau * ms:.3g} ms, is {h / h_std:.1f} of its own standard deviations ({CURVATURE_SIGMAS:g} asked): "
            "the log's noise, not its motion, places that point, and it moves from one noisy log to the next (too "
            "little motion for its noise); S may be off by the latency's effect; give the latency if it is known "
            "(--latency)")
    elif not estimate.determined:
        best = min(estimate.costs, key=estimate.costs.get)
        estimate.std = np.inf
        estimate.unresolved.append(
            f"the pose stream's latency is not determined: the fit has no clear minimum over the delays searched "
            f"(+-{K * dt * ms:g} ms; best {best * ms:g} ms); the log cannot tell them apart, so S may be "
            "off by the latency's effect; give the latency if it is known (--latency)")
    elif std > UNDETERMINED_SAMPLES * dt:
        estimate.determined = False
        estimate.unresolved.append(
            f"the pose stream's latency is not determined: {tau * ms:.3g} +- {std * ms:.2g} ms, more than "
            f"{UNDETERMINED_SAMPLES:g} samples ({UNDETERMINED_SAMPLES * dt * ms:g} ms) of uncertainty: the log "
            "cannot tell the candidate delays apart (too little motion for its noise); give the latency if it "
            "is known (--latency)")
    else:
        estimate.step = _step(*estimate._blocks, tau, dt)
        if estimate.step is not None:
            s = estimate.step
            estimate.determined = False
            estimate.warnings.append(
                f"the latency changes along the log: {s['before'] * ms:.3g} ms before t = {s['t']:.3g} s and "
                f"{s['after'] * ms:.3g} ms after it ({s['size'] / dt:+.2g} samples): a dropped or duplicated "
                "sample or a clock step there; one latency cannot align the log (cut it at that time, or fix "
                "the stamps)")
    estimate.warnings.extend(estimate.unresolved)


def _step(scores, infos, t_rows, length, tau, dt):
    """Rule 6: where the latency changes mid-log, or None.

    Each block's score ``s_b`` and information ``h_b`` give a part's step from
    ``tau`` as ``-sum s_b / sum h_b`` (L2 on that part), its variance
    ``V / sum h_b`` with ``V = sum_parts sum_b (s_b + h_b d_part)^2 / sum_all h_b``
    the scores' variance per unit of information about each part's own step,
    pooled over the log (a part's few blocks alone would estimate it poorly). A change of less than :data:`MIN_STEP`
    samples is not reported.
    """
    n_blocks = len(scores)
    if n_blocks < 2 * SEGMENTS:
        return None
    parts = np.array_split(np.arange(n_blocks), SEGMENTS)
    h = np.array([infos[part].sum() for part in parts])
    if np.any(h <= 0):
        return None
    d = np.array([-scores[part].sum() for part in parts]) / h
    # the scores' variance per unit of information, about each part's own latency, pooled over the parts
    pooled = sum(np.sum((scores[part] + infos[part] * step) ** 2) for part, step in zip(parts, d)) / h.sum()
    var = pooled / h * SEGMENTS / (SEGMENTS - 1)          # the parts' means fitted: one degree of freedom each
    mean = np.sum(d / var) / np.sum(1 / var)
    statistic = float(np.sum((d - mean) ** 2 / var))
    if chi2.sf(statistic, SEGMENTS - 1) >= STEP_P:
        return None
    # the border that best splits the blocks into two constant latencies (the largest drop of the weighted sum of
    # squares, sum_b s_b^2 / h_b less each side's (sum s)^2 / sum h)
    cs, ch = np.cumsum(scores), np.cumsum(infos)
    total_s, total_h = cs[-1], ch[-1]
    j = np.arange(1, n_blocks)
    left_s, left_h = cs[:-1], ch[:-1]
    gain = left_s ** 2 / np.maximum(left_h, 1e-300) + (total_s - left_s) ** 2 / np.maximum(total_h - left_h, 1e-300)
    border = int(j[np.argmax(gain)])
    before = tau - left_s[border - 1] / left_h[border - 1]
    after = tau - (total_s - left_s[border - 1]) / (total_h - left_h[border - 1])
    if abs(after - before) < MIN_STEP * dt:              # a slip of less than half a sample: not a lost sample
        return None
    return {"t": float(t_rows[0] + border * length), "size": float(after - before), "before": float(before),
            "after": float(after)}


def _step_of(fit_step):
    """The fit's step and its standard deviation (eq. LF2), or None where it is missing or not finite."""
    if not fit_step:
        return None
    step, std = float(fit_step.get("step", np.nan)), float(fit_step.get("std", np.nan))
    return (step, std) if np.isfinite(step) and np.isfinite(std) and std > 0 else None


def fit_latency(estimate, fit_step):
    """Rule 8: the latency the fit itself prefers, where it disagrees with the estimate; else None.

    Parameters
    ----------
    estimate : LatencyEstimate
        The estimate the log was aligned at (rules 1-7).
    fit_step : dict
        ``{"step": s, "std": s}``: the further delay the fit's own likelihood prefers from it (eq. LF2 of
        :mod:`fmscal.observers.batch._linearised_floor`; ``result.info["latency_step"]`` of the floor).

    Returns
    -------
    LatencyEstimate or None
        Where ``|step|`` exceeds :data:`AGREEMENT_SIGMAS` of the estimate's standard deviation (the estimate
        determined): a copy at ``latency + step`` with the fit's standard deviation, ``source="fit"`` and a
        note in words; None where they agree (or there is nothing to compare).
    """
    found = _step_of(fit_step)
    if found is None or not estimate.determined or not np.isfinite(estimate.std):
        return None
    step, std = found
    if abs(step) <= AGREEMENT_SIGMAS * estimate.std:
        return None
    ms = 1e3
    moved = replace(estimate, latency=float(estimate.latency + step), std=float(std), source="fit",
                    notes=list(estimate.notes), warnings=list(estimate.warnings),
                    unresolved=list(estimate.unresolved))
    moved.notes.append(
        f"the pose stream's latency: the maximum-likelihood fit's own likelihood prefers {moved.latency * ms:.4g} "
        f"+- {std * ms:.2g} ms, where the needed wrench's cross-correlation found {estimate.latency * ms:.4g} +- "
        f"{estimate.std * ms:.2g} ms ({abs(step) / estimate.std:.1f} of its standard deviations away: the two "
        "take the reading between samples differently); the fit's latency is taken")
    return moved


def given_latency_warnings(given, estimate, fit_step=None):
    """Rule 9: a latency given, checked against the log's estimate and the fit's own.

    Parameters
    ----------
    given : float
        The latency the log was aligned at, s.
    estimate : LatencyEstimate or None
        The log's own estimate (rules 1-7); None where none could be made.
    fit_step : dict, optional
        The fit's step from ``given`` (eq. LF2), where the method gives one.

    Returns
    -------
    warnings : list of str
        One where the estimate is more than :data:`AGREEMENT_SIGMAS` standard deviations from ``given``
        (both figures named), one where the fit at ``given`` is measurably worse.
    worse : bool
        The fit at ``given`` is measurably worse: its own step beyond :data:`AGREEMENT_SIGMAS` of its standard
        deviations; for a method without one, the estimate beyond :data:`AGREEMENT_SIGMAS` of its own.
    """
    ms = 1e3
    warnings, worse = [], False
    if estimate is not None and estimate.determined and np.isfinite(estimate.std) and estimate.std > 0:
        z = (given - estimate.latency) / estimate.std
        if abs(z) > AGREEMENT_SIGMAS:
            warnings.append(
                f"the latency given, {given * ms:.4g} ms, is {abs(z):.1f} standard deviations from the log's own "
                f"estimate, {estimate.latency * ms:.4g} +- {estimate.std * ms:.2g} ms: S fitted at a wrong "
                "latency is biased; check the latency given, or leave it to be estimated")
            worse = True
    found = _step_of(fit_step)
    if found is not None:                      # the fit's own step judges the fit; the estimate's warning stands
        step, std = found
        worse = abs(step) > AGREEMENT_SIGMAS * std
        if worse:
            warnings.append(
                f"the maximum-likelihood fit is measurably worse at the latency given ({given * ms:.4g} ms) than "
                f"at the one its own likelihood prefers, {(given + step) * ms:.4g} +- {std * ms:.2g} ms "
                f"({abs(step) / std:.1f} standard deviations away): S fitted at the latency given is biased")
    return warnings, worse
