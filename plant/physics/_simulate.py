"""Integrate eq. (1): fixed-step RK4 with the wrench continuous in time."""

from functools import lru_cache

import casadi as ca
import numpy as np

from fmscal.plant.numerics import ChunkedSteps, FmscalError, as_finite_array
from ._dynamics import state_derivative

__all__ = ["integrate", "rk4_step"]

_CHUNK = 500          # steps per compiled call (casadi mapaccum)


def rk4_step(x, w0, w_mid, w1, dt, payload):
    """One classical RK4 step of eq. (1) with the wrench given at three times.

    The wrench is continuous in time: it is evaluated at the start ``t``,
    the middle ``t + dt/2`` and the end ``t + dt`` of the step, as RK4
    needs, not held over the step.

    Parameters
    ----------
    x : ndarray or casadi.SX, shape (6,)
        State ``[theta, theta', X, X', Y, Y']`` at ``t``.
    w0, w_mid, w1 : ndarray or casadi.SX, shape (3,)
        True wrench at ``t``, ``t + dt/2`` and ``t + dt``.
    dt : float
        Step in s.
    payload : plant.Payload

    Returns
    -------
    ndarray or casadi.SX, shape (6,)
        State at ``t + dt``.
    """
    k1 = state_derivative(x, w0, payload)
    k2 = state_derivative(x + dt / 2 * k1, w_mid, payload)
    k3 = state_derivative(x + dt / 2 * k2, w_mid, payload)
    k4 = state_derivative(x + dt * k3, w1, payload)
    return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


@lru_cache(maxsize=16)
def _compiled_steps(payload):
    """RK4 step from :func:`rk4_step`, run in compiled chunks (:class:`plant.numerics.ChunkedSteps`)."""
    x = ca.SX.sym("x", 6)
    w = ca.SX.sym("w", 9)
    dt = ca.SX.sym("dt")
    x_next = rk4_step(x, w[0:3], w[3:6], w[6:9], dt, payload)
    return ChunkedSteps(ca.Function("rk4", [x, w, dt], [ca.densify(x_next)]), _CHUNK)


def integrate(payload, excitation, t, x0=None, compiled=True):
    """Integrate eq. (1) along the time grid ``t`` with RK4.

    Parameters
    ----------
    payload : plant.Payload
    excitation : callable
        ``excitation(t)`` gives the true wrench, shape (N, 3), for times
        shape (N,): a :class:`plant.Excitation`. It is evaluated at each grid
        point and at each mid-step.
    t : array_like, shape (N,)
        Strictly increasing times in s (the grid may be uneven).
    x0 : array_like, shape (6,), optional
        Initial state; default at rest at the origin.
    compiled : bool
        True (default) runs the step compiled by casadi; False runs the same
        :func:`rk4_step` in numpy, one step at a time (the readable path).

    Returns
    -------
    ndarray, shape (N, 6)
        The state at each time of ``t``.
    """
    t = as_finite_array(t, (-1,), "t")
    if len(t) < 2 or np.any(np.diff(t) <= 0):
        raise FmscalError("t must hold at least 2 strictly increasing times")
    x = np.zeros(6) if x0 is None else as_finite_array(x0, (6,), "x0")
    dts = np.diff(t)
    w_start, w_mid, w_end = excitation(t[:-1]), excitation(t[:-1] + dts / 2), excitation(t[1:])
    out = np.empty((len(t), 6))
    out[0] = x
    if not compiled:
        for k, dt in enumerate(dts):
            x = rk4_step(x, w_start[k], w_mid[k], w_end[k], dt, payload)
            out[k + 1] = x
        return out
    out[1:] = _compiled_steps(payload).run(x, [np.hstack([w_start, w_mid, w_end]), dts[:, None]])
    return out
