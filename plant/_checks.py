"""Input checks used at the public boundary of every package."""

import numpy as np

from .errors import FmscalError

__all__ = ["as_finite_array", "as_positive_scalar", "MAX_SCALAR"]

#: Largest setting (a gain, a standard deviation, ...) accepted: beyond it squares and products of
#: settings overflow double precision, and no physical quantity in SI units comes near it.
MAX_SCALAR = 1e50


def as_finite_array(value, shape, name):
    """Return ``value`` as a float ndarray of ``shape``, or raise FmscalError.

    Parameters
    ----------
    value : array_like
        The value to check.
    shape : tuple of int
        Expected shape; ``-1`` in a position accepts any length there.
    name : str
        Name used in the error message.

    Returns
    -------
    ndarray
        A float copy of ``value``.
    """
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise FmscalError(f"{name} must be numeric; got {value!r}") from None
    if arr.ndim != len(shape) or any(s not in (-1, a) for s, a in zip(shape, arr.shape)):
        expected = "x".join("N" if s == -1 else str(s) for s in shape) or "scalar"
        actual = "x".join(str(a) for a in arr.shape) or "scalar"
        raise FmscalError(f"{name} has the wrong shape; expected {expected} instead of {actual}")
    if not np.all(np.isfinite(arr)):
        raise FmscalError(f"{name} must be finite; got {value!r}")
    return arr


def as_positive_scalar(value, name, allow_zero=False):
    """Return ``value`` as a positive (or, with ``allow_zero``, non-negative) finite float, or raise FmscalError.

    Values above :data:`MAX_SCALAR` are refused too: their squares overflow.
    """
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise FmscalError(f"{name} must be a number; got {value!r}") from None
    if not np.isfinite(x) or x < 0 or (x == 0 and not allow_zero):
        raise FmscalError(f"{name} must be {'non-negative' if allow_zero else 'positive'} and finite; got {value!r}")
    if x > MAX_SCALAR:
        raise FmscalError(f"{name} must be at most {MAX_SCALAR:g} (larger values overflow); got {value!r}")
    return x
