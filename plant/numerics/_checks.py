"""Input checks used at the public boundary of every package."""

import numbers

import numpy as np

from ._errors import FmscalError

__all__ = ["as_finite_array", "as_positive_scalar", "as_bool", "as_number", "MAX_SCALAR", "short_repr", "numbers_only"]

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
        if np.asarray(value).dtype.kind in "USVO" and not _numbers_only(value):    # no text read as numbers
            raise TypeError
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise FmscalError(f"{name} must be numeric; got {short_repr(value)}") from None
    if arr.ndim != len(shape) or any(s not in (-1, a) for s, a in zip(shape, arr.shape)):
        expected = "x".join("N" if s == -1 else str(s) for s in shape) or "scalar"
        actual = "x".join(str(a) for a in arr.shape) or "scalar"
        raise FmscalError(f"{name} has the wrong shape; expected {expected} instead of {actual}")
    if not np.all(np.isfinite(arr)):
        raise FmscalError(f"{name} must be finite; got {value!r}")
    return arr


def as_positive_scalar(value, name, allow_zero=False):
    """Return ``value`` as a positive (or, with ``allow_zero``, non-negative) finite float, or raise FmscalError.

    Values above :data:`MAX_SCALAR` are refused too: their squares overflow;
    so are text (``"0.5"``) and booleans, which are not numbers here.
    """
    x = as_number(value, name)
    if not np.isfinite(x) or x < 0 or (x == 0 and not allow_zero):
        raise FmscalError(f"{name} must be {'non-negative' if allow_zero else 'positive'} and finite; got {value!r}")
    if x > MAX_SCALAR:
        raise FmscalError(f"{name} must be at most {MAX_SCALAR:g} (larger values overflow); got {value!r}")
    return x


def as_number(value, name):
    """Return ``value`` as a float if it is a real number (not text, not a boolean), or raise FmscalError."""
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "fiu":
        value = value[()]
    if not isinstance(value, numbers.Real) or isinstance(value, (bool, np.bool_)):
        raise FmscalError(f"{name} must be a number; got {short_repr(value)}")
    return float(value)


def as_bool(value, name):
    """Return ``value`` if it is a boolean (``True``, ``False`` or a numpy bool), or raise FmscalError.

    Text is refused: ``"false"`` would be true as a Python truth value.
    """
    if not isinstance(value, (bool, np.bool_)):
        raise FmscalError(f"{name} must be True or False; got {short_repr(value)}")
    return bool(value)


def _numbers_only(value):
    """True if the nested lists of ``value`` hold real numbers only (an object array of numbers)."""
    if isinstance(value, (str, bytes)):
        return False
    if isinstance(value, (list, tuple, np.ndarray)):
        return all(_numbers_only(v) for v in value)
    return isinstance(value, numbers.Real)


def numbers_only(value, allow_null=False):
    """True when ``value`` holds numbers only (and ``None``/``null`` where ``allow_null``): no text, no booleans.

    Nested lists or tuples as a JSON file gives them, or a numeric array as a Python caller does.
    """
    if isinstance(value, np.ndarray):
        return value.dtype.kind in "fiu" or (value.dtype == object and numbers_only(value.tolist(), allow_null))
    if isinstance(value, (list, tuple)):
        return all(numbers_only(v, allow_null) for v in value)
    if value is None:
        return allow_null
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def short_repr(value, limit=60):
    """``repr(value)`` cut to ``limit`` characters, for a one-line message.

    Examples
    --------
    >>> short_repr("x" * 100, limit=5)
    "'xxxx..."
    """
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."
