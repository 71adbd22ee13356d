"""The paper's error metric, eq. (16), its robust end-of-run value, and a convergence time."""

import numpy as np

from fmscal.plant.numerics import as_finite_array

__all__ = ["calibration_error", "block_errors", "error_history", "tail_median", "tail_seen", "convergence_time",
           "CONVERGENCE_THRESHOLD", "CONVERGENCE_HOLD", "TAIL_FRACTION"]

#: Default threshold on E for :func:`convergence_time`.
CONVERGENCE_THRESHOLD = 0.05
#: ... and the stretch, s, for which E must hold below it.
CONVERGENCE_HOLD = 10.0
#: Share of a run at its end over which :func:`tail_median` takes E.
TAIL_FRACTION = 0.1


def calibration_error(S_hat, S):
    """Eq. (16): ``E = ||I - S_hat S^-1||_2``, the induced 2-norm.

    Parameters
    ----------
    S_hat, S : array_like, shape (n, n)
        Estimate and true calibration matrix, in SI units: ``n`` is the
        model's ``n_w`` (3 planar; 6 spatial, where N and N m mix:
        :func:`block_errors`).

    Returns
    -------
    float
        The largest singular value of ``I - S_hat S^-1``.

    Examples
    --------
    >>> calibration_error(np.eye(3), np.eye(3))
    0.0
    """
    n = np.shape(S)[0] if np.ndim(S) == 2 and np.shape(S)[0] >= 1 else 3
    S_hat = as_finite_array(S_hat, (n, n), "S_hat")
    S = as_finite_array(S, (n, n), "S")
    return float(np.linalg.norm(np.eye(n) - S_hat @ np.linalg.inv(S), 2))


def block_errors(S_hat, S):
    """E of eq. (16) on a 6x6 ``S``, whole and by its torque and force blocks.

    ``I - S_hat S^-1`` mixes N and N m in its off-diagonal blocks (a force
    reading's share of a torque, in m; a torque's share of a force, in 1/m),
    so the whole E changes with the units: in mm and N mm the torque-force
    blocks scale by 1000 and its inverse. The diagonal blocks (torque rows
    and columns, force rows and columns) are unit-free.

    Parameters
    ----------
    S_hat, S : array_like, shape (6, 6)

    Returns
    -------
    E, E_torque, E_force : float
        The 2-norm of ``I - S_hat S^-1`` and of its two diagonal 3x3 blocks.
    """
    S_hat = as_finite_array(S_hat, (6, 6), "S_hat")
    S = as_finite_array(S, (6, 6), "S")
    D = np.eye(6) - S_hat @ np.linalg.inv(S)
    return (float(np.linalg.norm(D, 2)), float(np.linalg.norm(D[:3, :3], 2)), float(np.linalg.norm(D[3:, 3:], 2)))


def error_history(S_hat_history, S_true):
    """E of eq. (16) at every sample.

    Parameters
    ----------
    S_hat_history : ndarray, shape (N, n, n)
    S_true : ndarray, shape (n, n) or (N, n, n)
        The true ``S``, constant or at each sample.

    Returns
    -------
    ndarray, shape (N,)
    """
    S_true = np.asarray(S_true, dtype=float)
    if S_true.ndim == 3 and len(S_true) and np.all(S_true == S_true[:1]):
        S_true = S_true[0]                      # a constant S given at every sample: inverted once
    D = np.eye(S_true.shape[-1]) - np.asarray(S_hat_history, dtype=float) @ np.linalg.inv(S_true)
    # the largest singular value, as the root of the largest eigenvalue of D^T D (half an SVD's time)
    return np.sqrt(np.maximum(np.linalg.eigvalsh(np.swapaxes(D, -1, -2) @ D)[:, -1], 0.0))


def tail_median(E, fraction=TAIL_FRACTION):
    """The median of E over the last ``fraction`` of a run: the run's E, robust to one sample.

    E moves from sample to sample (a tenfold swing within seconds is common
    for an online observer); tables rank methods on this statistic, never
    on one sample.

    Parameters
    ----------
    E : array_like, shape (N,)
    fraction : float
        Share of the run at its end, in (0, 1].

    Returns
    -------
    float
        NaN for an empty history.
    """
    E = np.asarray(E, dtype=float)
    if len(E) == 0:
        return float("nan")
    return float(np.median(E[min(int((1 - fraction) * len(E)), len(E) - 1):]))


def tail_seen(n, fraction=TAIL_FRACTION):
    """The samples an online estimate has seen at the middle of the tail that :func:`tail_median` takes.

    The rule for holding an online method's tail median to the floor: the
    floor is fitted on the same samples. An estimate after sample ``k`` has
    seen ``k`` samples; over the last ``fraction`` of a run of ``n`` the
    median of a settling estimate is its value at the tail's middle, after
    ``n (1 - fraction / 2)`` samples, while a fit of the whole log has seen
    all ``n``. On a log whose last tenth still adds much information (a
    short spatial log: docs/comparison.md, "In 3D";
    ``benchmarks/online_floor_3d.py`` prints both floors seed by seed), the
    two differ by more than the methods do.

    Parameters
    ----------
    n : int
        Samples in the run.
    fraction : float
        Share of the run at its end, in (0, 1], as for :func:`tail_median`.

    Returns
    -------
    int
        At least 1.
    """
    return max(int(round(n * (1 - fraction / 2))), 1)


def convergence_time(t, E, threshold=CONVERGENCE_THRESHOLD, hold=CONVERGENCE_HOLD):
    """First time after which E stays below ``threshold`` for at least ``hold`` seconds.

    The stretch must fit in the run: a run that ends less than ``hold``
    after E last fell below the threshold has not shown that it converged.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Times, s, increasing.
    E : ndarray, shape (N,)
    threshold : float
    hold : float
        Minimum stretch below the threshold, s.

    Returns
    -------
    float or None
        None where E never holds below the threshold that long.
    """
    t, E = np.asarray(t, dtype=float), np.asarray(E, dtype=float)
    below = E < threshold
    start = None
    for k in range(len(E)):
        if not below[k]:
            start = None
            continue
        if start is None:
            start = k
        if t[k] - t[start] >= hold:
            return float(t[start])
    return None
