"""Is a log consistent with one constant ``S``? A check ``fmscal calibrate`` runs on every log.

:func:`consistency_check`: least squares fitted to the first and the second
half of the log must agree within their uncertainty; where they do not, fits
over shorter windows say roughly when ``S`` changed. (When an estimate counts
as diverged: :func:`observers.core.divergence_bound`.)
"""

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from fmscal.plant.numerics import FmscalError

from fmscal.observers.batch import LeastSquares

__all__ = ["Consistency", "consistency_check", "DEFAULT_SIGNIFICANCE", "DEFAULT_WINDOWS"]

#: Probability, for a log with one constant S, of wrongly calling it inconsistent.
DEFAULT_SIGNIFICANCE = 1e-3
#: Windows of the fits that locate a change.
DEFAULT_WINDOWS = 6


@dataclass
class Consistency:
    """The outcome of :func:`consistency_check`.

    Attributes
    ----------
    consistent : bool
        The two halves agree within their uncertainty.
    statistic : float
        ``sum((S_a - S_b)^2 / (sd_a^2 + sd_b^2))`` over the ``n_w^2`` entries
        (9 in the plane); about chi-square with as many degrees of freedom
        for a constant ``S``.
    p_value : float
        Probability of a statistic at least this large for a constant ``S``.
    S_halves : (ndarray, ndarray)
        The two fits, each shape (n_w, n_w).
    change_time : float or None
        Where the windowed fits place the largest change, s (None when
        consistent).
    warning : str or None
        One line for the user when inconsistent: S changed, and roughly when.
    """

    consistent: bool
    statistic: float
    p_value: float
    S_halves: tuple
    change_time: float = None
    warning: str = None


def _difference_statistic(a, b):
    """Chi-square-like distance of two least-squares fits (``ObserverResult``), and its p-value (one degree
    of freedom per entry of ``S``)."""
    var = np.asarray(a.S_std) ** 2 + np.asarray(b.S_std) ** 2
    d2 = (a.S_hat - b.S_hat) ** 2
    if not np.all(var > 0):
        # an exactly known entry: any difference at all is a disagreement
        return (np.inf, 0.0) if np.any(d2[var <= 0] > 0) else (0.0, 1.0)
    stat = float(np.sum(d2 / var))
    return stat, float(chi2.sf(stat, d2.size))


def consistency_check(log, model, offset=True, significance=DEFAULT_SIGNIFICANCE, windows=DEFAULT_WINDOWS):
    """Whether a log is consistent with one constant ``S``: fits of its two halves agree.

    Each half is fitted by least squares (:class:`observers.LeastSquares`);
    the difference of the two ``S`` estimates, entry by entry over their
    combined variance (``S_std`` of each; correlations between entries are
    ignored), is compared with chi-square with one degree of freedom per
    entry (9 in the plane). When it
    is too large, the log is cut into ``windows`` equal parts and fitted part
    by part; the largest difference between neighbouring parts places the
    change.

    Parameters
    ----------
    log : plant.Log
    model : plant.Model or plant.Payload
        The problem (a payload stands for its case's model).
    offset : bool
        Fit the sensor's offset too (as ``fmscal calibrate`` does by default).
    significance : float
        Probability of calling a constant-``S`` log inconsistent.
    windows : int
        Number of parts for locating a change (each must hold enough data for
        least squares: at least two of its 0.5 s windows).

    Returns
    -------
    Consistency

    Raises
    ------
    FmscalError
        A log too short to be halved for least squares.
    """
    if not 0 < significance < 1:
        raise FmscalError(f"significance must be in (0, 1); got {significance}")
    t0, t1 = float(log.t[0]), float(log.t[-1]) + log.dt
    middle = 0.5 * (t0 + t1)
    fit = LeastSquares(model, offset=offset)
    first, second = fit.run(log.between(t0, middle)), fit.run(log.between(middle, t1))
    stat, p = _difference_statistic(first, second)
    out = Consistency(consistent=p >= significance, statistic=stat, p_value=p,
                      S_halves=(first.S_hat, second.S_hat))
    if out.consistent:
        return out
    edges = np.linspace(t0, t1, int(windows) + 1)
    parts = []
    for a, b in zip(edges[:-1], edges[1:]):
        try:
            parts.append(fit.run(log.between(a, b)))
        except FmscalError:           # a part too short or without poses: locate with the others
            parts.append(None)
    jumps = [(_difference_statistic(x, y)[0] if x is not None and y is not None else -1.0, edge)
             for x, y, edge in zip(parts[:-1], parts[1:], edges[1:-1])]
    best, when = max(jumps)
    dof = first.S_hat.size
    threshold = chi2.isf(significance, dof)
    changed = [edge for stat_, edge in jumps if stat_ > threshold]
    if len(changed) > 1:
        out.change_time = float(when)
        where = (f"gradually (neighbouring {(t1 - t0) / windows:.3g} s parts differ at {len(changed)} of "
                 f"{len(jumps)} boundaries, most around t = {when:.3g} s)")
    elif best > 0:
        out.change_time = float(when)
        where = f"around t = {when:.3g} s (between t = {when - (t1 - t0) / windows:.3g} and " \
                f"{when + (t1 - t0) / windows:.3g} s)"
    else:
        where = f"somewhere in t = {t0:.3g} .. {t1:.3g} s"
    worst = np.unravel_index(np.argmax(np.abs(first.S_hat - second.S_hat)), first.S_hat.shape)
    out.warning = (f"S changed during the log {where}: fits of its two halves differ by "
                   f"{np.sqrt(stat / dof):.3g} sigma per entry (s_{worst[0] + 1}{worst[1] + 1}: "
                   f"{first.S_hat[worst]:.4g} then {second.S_hat[worst]:.4g}); one constant S does not "
                   f"describe it")
    return out
