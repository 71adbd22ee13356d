"""Array operations shared by numeric (numpy) and symbolic (casadi) code.

The dynamics of eq. (1) and each observer's step are written once with these
operations, so the same lines give plain numbers, casadi expressions for
Jacobians, and compiled casadi functions.
"""

import casadi as ca
import numpy as np

__all__ = ["is_symbolic", "ops"]


def is_symbolic(*values):
    """Return True if any value is a casadi symbolic expression."""
    return any(isinstance(v, (ca.SX, ca.MX)) for v in values)


class _NumpyOps:
    cos = staticmethod(np.cos)
    sin = staticmethod(np.sin)
    sqrt = staticmethod(np.sqrt)
    exp = staticmethod(np.exp)
    fmax = staticmethod(np.maximum)
    fmin = staticmethod(np.minimum)
    fabs = staticmethod(np.abs)
    atan2 = staticmethod(np.arctan2)

    @staticmethod
    def vcat(items):
        """Stack scalars and vectors into one flat vector."""
        return np.concatenate([np.ravel(np.asarray(v, dtype=float)) for v in items])

    @staticmethod
    def matrix(rows):
        """Build an array from a list of rows of scalars.

        Entries may be arrays of one common shape (a batch, for example one
        angle per sample): the result is then ``(rows, cols, *batch)``.
        """
        shape = np.broadcast_shapes(*[np.shape(v) for row in rows for v in row])
        if not shape:
            return np.array(rows, dtype=float)
        return np.array([[np.broadcast_to(np.asarray(v, dtype=float), shape) for v in row] for row in rows])

    @staticmethod
    def dot(a, b):
        return a @ b

    @staticmethod
    def if_else(cond, a, b):
        return a if cond else b

    @staticmethod
    def solve(A, b):
        return np.linalg.solve(A, b)


class _CasadiOps:
    cos = staticmethod(ca.cos)
    sin = staticmethod(ca.sin)
    sqrt = staticmethod(ca.sqrt)
    exp = staticmethod(ca.exp)
    fmax = staticmethod(ca.fmax)
    fmin = staticmethod(ca.fmin)
    fabs = staticmethod(ca.fabs)
    atan2 = staticmethod(ca.atan2)

    @staticmethod
    def vcat(items):
        return ca.vertcat(*[ca.vec(ca.SX(v)) if not isinstance(v, ca.SX) else ca.vec(v) for v in items])

    @staticmethod
    def matrix(rows):
        return ca.vertcat(*[ca.horzcat(*row) for row in rows])

    @staticmethod
    def dot(a, b):
        return ca.mtimes(a, b)

    @staticmethod
    def if_else(cond, a, b):
        return ca.if_else(cond, a, b)

    @staticmethod
    def solve(A, b):
        return ca.solve(A, b)


def ops(*values):
    """Return the operations namespace for these values (casadi or numpy)."""
    return _CasadiOps if is_symbolic(*values) else _NumpyOps
