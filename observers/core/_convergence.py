"""When an estimate counts as settled, and when as diverged."""

import numpy as np

from fmscal.plant.io import implied_scale
from fmscal.plant.numerics import FmscalError
from fmscal.plant.physics import as_model

__all__ = ["settled", "moved", "informed", "divergence_bound", "DIVERGENCE_FACTOR", "DIVERGENCE_GRACE",
           "SETTLE_FRACTION", "SETTLE_TOLERANCE", "EVIDENCE_TOLERANCE"]

#: An entry of S_hat beyond this many times the scale (of S0 and of the data) counts as diverged ...
DIVERGENCE_FACTOR = 20.0
#: ... after this first stretch of a run, s, where only a non-finite estimate does (a recursive
#: least-squares fit swings wide on its first few poses, before they excite every entry).
DIVERGENCE_GRACE = 1.0
#: ``converged`` looks at this final fraction of the run ...
SETTLE_FRACTION = 0.2
#: ... and asks that ``S_hat`` stay within this relative 2-norm distance of its final value.
SETTLE_TOLERANCE = 0.05
#: ``converged`` needs the one-sigma uncertainty of ``S`` (``||S_std||_2 / ||S_hat||_2``: the
#: method's own in :meth:`observers.Observer.run`; a least-squares fit's of the log for a method
#: without one, :func:`observers.diagnostics.has_evidence`) at most this: the log held information
#: in every direction of ``S``.
EVIDENCE_TOLERANCE = 0.05


def settled(S_history, fraction=SETTLE_FRACTION, tolerance=SETTLE_TOLERANCE):
    """Whether an estimate settled: no truth needed.

    True when, over the last ``fraction`` of the run, every ``S_hat(t)`` is
    within ``tolerance`` of the final ``S_hat`` in relative induced 2-norm.

    Parameters
    ----------
    S_history : ndarray, shape (N, n_w, n_w)

    Returns
    -------
    bool

    Examples
    --------
    >>> import numpy as np
    >>> from fmscal.observers import settled
    >>> still = np.tile(np.eye(3), (100, 1, 1))
    >>> settled(still), settled(still * np.linspace(0.5, 1.0, 100)[:, None, None])
    (True, False)
    """
    n = len(S_history)
    tail = S_history[int(n * (1 - fraction)):]
    final = S_history[-1]
    bound = tolerance * max(np.linalg.norm(final, 2), 1e-12)
    gap = tail - final
    # the 2-norm never exceeds the Frobenius norm: take SVDs only where the cheap bound fails
    unsure = np.sqrt(np.einsum("nij,nij->n", gap, gap)) > bound
    return bool(not unsure.any() or np.max(np.linalg.norm(gap[unsure], ord=2, axis=(1, 2))) <= bound)


def moved(S_history, tolerance=SETTLE_TOLERANCE):
    """Whether an estimate left its start: settling means nothing until it has.

    True when some ``S_hat(t)`` is farther than ``tolerance`` from
    ``S_hat(0)`` in relative induced 2-norm (relative to the final
    ``S_hat``). An online method that never leaves ``S0`` has learned
    nothing the run can show, however still it stands.

    Parameters
    ----------
    S_history : ndarray, shape (N, n_w, n_w)
    tolerance : float

    Returns
    -------
    bool
    """
    gap = S_history - S_history[0]
    bound = tolerance * max(np.linalg.norm(S_history[-1], 2), 1e-12)
    # the 2-norm is at least the Frobenius norm over sqrt(rank): the cheap test first
    frob = np.sqrt(np.einsum("nij,nij->n", gap, gap))
    if np.any(frob > np.sqrt(S_history.shape[-1]) * bound):
        return True
    near = frob > bound
    return bool(near.any() and np.max(np.linalg.norm(gap[near], ord=2, axis=(1, 2))) > bound)


def informed(S_hat, S_std, tolerance=EVIDENCE_TOLERANCE):
    """Whether an uncertainty says the data pinned ``S`` down: ``||S_std||_2 <= tolerance ||S_hat||_2``.

    Parameters
    ----------
    S_hat : array_like, shape (n_w, n_w)
    S_std : array_like, shape (n_w, n_w)
        One-sigma uncertainty of each entry.
    tolerance : float

    Returns
    -------
    bool
        False where either is not finite.
    """
    S_hat, S_std = np.asarray(S_hat, dtype=float), np.asarray(S_std, dtype=float)
    if not (np.all(np.isfinite(S_hat)) and np.all(np.isfinite(S_std))):
        return False
    return bool(np.linalg.norm(S_std, 2) <= tolerance * np.linalg.norm(S_hat, 2))


def divergence_bound(S0, log=None, payload=None, factor=DIVERGENCE_FACTOR):
    """The size of an entry of ``S_hat`` beyond which an estimate has diverged.

    ``factor`` times the larger of the largest entry of ``S0`` and the scale
    of ``S`` the data imply (:func:`plant.io.implied_scale`: the wrench
    the poses imply over the reading, the larger of the moment's and the
    force's ratio). A sensor read in counts (``S`` near 1e-4) and one read in
    small units (``S`` near 1e4) each get a bound of their own size; the
    paper's observer under noise, whose entries reach 80 where the true ones
    are at most 2.7, counts as diverged.

    Parameters
    ----------
    S0 : array_like, shape (n_w, n_w)
        The initial estimate.
    log : plant.Log, optional
        Without a log (a live sensor, :meth:`observers.Observer.step`), the
        scale is that of ``S0`` and at least 1.
    payload : plant.Model or plant.Payload, optional
        The log's model (a payload stands for its case's model); needed
        with ``log``. The data's scale is read off eq. (1) where the model
        has :attr:`fmscal.plant.Model.paper_equations`; on another model it
        is 1.
    factor : float

    Returns
    -------
    float
        Bound on ``max |s_ij|`` of ``S_hat``.
    """
    S0 = np.asarray(S0, dtype=float)
    if S0.ndim != 2 or S0.shape[0] != S0.shape[1] or not np.all(np.isfinite(S0)):
        raise FmscalError(f"S0 must be a finite square matrix; got shape {S0.shape}")
    # the scale the poses imply is read off the planar eq. (1); other models go by S0 (and at least 1)
    model = None if log is None else as_model(payload, "divergence_bound")
    paper = model is not None and model.paper_equations
    scale = implied_scale(log, model.payload) if paper else None
    data = max(scale) if scale is not None else (0.0 if paper else 1.0)
    size = max(float(np.max(np.abs(S0))), data)
    if size == 0:
        size = 1.0             # nothing to go by: S of order one, as for N m and N
    return float(factor * size)
