"""When an estimate counts as settled, and when as diverged."""

import numpy as np

__all__ = ["settled", "DIVERGENCE_BOUND", "SETTLE_FRACTION", "SETTLE_TOLERANCE"]

#: A run whose calibration estimate has an entry beyond this is declared diverged.
DIVERGENCE_BOUND = 1e3
#: ``converged`` looks at this final fraction of the run ...
SETTLE_FRACTION = 0.2
#: ... and asks that ``S_hat`` stay within this relative 2-norm distance of its final value.
SETTLE_TOLERANCE = 0.05


def settled(S_history, fraction=SETTLE_FRACTION, tolerance=SETTLE_TOLERANCE):
    """Whether an estimate settled: no truth needed.

    True when, over the last ``fraction`` of the run, every ``S_hat(t)`` is
    within ``tolerance`` of the final ``S_hat`` in relative induced 2-norm.

    Parameters
    ----------
    S_history : ndarray, shape (N, 3, 3)

    Returns
    -------
    bool
    """
    n = len(S_history)
    tail = S_history[int(n * (1 - fraction)):]
    final = S_history[-1]
    bound = tolerance * max(np.linalg.norm(final, 2), 1e-12)
    gap = tail - final
    # the 2-norm never exceeds the Frobenius norm: take SVDs only where the cheap bound fails
    unsure = np.sqrt(np.einsum("nij,nij->n", gap, gap)) > bound
    return bool(not unsure.any() or np.max(np.linalg.norm(gap[unsure], ord=2, axis=(1, 2))) <= bound)
