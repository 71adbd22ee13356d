"""Small matrix helpers that work on numpy arrays and casadi SX alike.

Observer steps are written once for both back ends (:mod:`plant.numerics._backend`);
these helpers hide the one difference that matters there: numpy vectors are
1-D, casadi vectors are columns.
"""

import numpy as np

from fmscal.plant.numerics import is_symbolic


def as_matrix(o, flat, n=3, cols=None):
    """An ``n x cols`` matrix (default square) from its entries in row order."""
    cols = n if cols is None else cols
    if not is_symbolic(flat):
        return np.asarray(flat).reshape(n, cols)
    return o.matrix([[flat[cols * i + j] for j in range(cols)] for i in range(n)])


def flat(o, mat):
    """The entries of a matrix in row order, as a flat vector."""
    if is_symbolic(mat):
        rows, cols = mat.shape
        return o.vcat([mat[i, j] for i in range(rows) for j in range(cols)])
    return np.ravel(mat)


def col(v):
    """A vector as a column."""
    return v if is_symbolic(v) else np.asarray(v)[:, None]


def row(v):
    """A vector as a row."""
    if is_symbolic(v):
        return v.T
    v = np.asarray(v)
    return v[None, :] if v.ndim == 1 else v


def vec(v):
    """A column (casadi) or 1-D array (numpy) as a flat vector."""
    return v if is_symbolic(v) else np.ravel(v)


def eye(o, n=3):
    """The ``n x n`` identity in the back end of ``o``."""
    return o.matrix([[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)])


def regularised_solve(o, R, b, n, rel=1e-3, floor=1e-12):
    """``(R + eps I)^-1 b`` with ``eps = rel * trace(R) / n + floor``.

    The normalisation of the adaptive laws: ``R`` is a running mean of a
    regressor's outer product, rank-deficient until the regressor has
    explored every direction.
    """
    trace = sum(R[i, i] for i in range(n))
    return o.solve(R + (rel * trace / n + floor) * eye(o, n), b)


def symmetric_from_upper(v, k):
    """A symmetric ``k x k`` matrix (list of rows) from its upper triangle in row order
    (``k (k + 1) / 2`` entries, :func:`upper`): each entry below the diagonal is its mirror's."""
    index, at = {}, 0
    for i in range(k):
        for j in range(i, k):
            index[i, j] = at
            at += 1
    return [[v[index[min(i, j), max(i, j)]] for j in range(k)] for i in range(k)]


def upper(M):
    """The upper triangle of a square matrix (list of rows or ndarray) in row order."""
    k = len(M)
    return [M[i][j] for i in range(k) for j in range(i, k)]
