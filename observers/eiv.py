"""Errors-in-variables compensation for an online filter that takes the noisy reading as its regressor.

A filter that propagates eq. (1) with the raw reading ``w_hat`` (the EKF,
:class:`observers.AugmentedEKF`) uses that reading twice: as the regressor of
``[S | c]`` (the ``S`` block of its transition Jacobian) and, through its
noise ``n``, as the process noise ``G(theta) S n`` of the same step. The two
are correlated, and the estimate of ``s = vec([S | c])`` is attenuated
towards zero: with ``J`` the information it accumulated and ``B`` the part of
``J`` that the reading's own noise makes, it solves ``J s = r`` where the
unbiased estimate solves ``(J - B) s = r`` (:mod:`observers.max_likelihood`,
module docstring). The attenuation grows with the square of the wrench
noise and with the amplification of ``S``: on the ``noisy`` and ``random-S``
scenarios it doubles the EKF's E on some seeds.

:class:`EivCompensation` runs, beside the filter and one sample at a time,
the separate-bias Kalman filter of :mod:`observers.max_likelihood` (the
motion filter run as if ``s = 0``, its sensitivity ``M = dx/ds``, the
information ``J`` and the bias moments ``beta``; the same compiled step,
:func:`observers.max_likelihood._filter_step`), with the process noise at the
filter's current ``S``. From ``J`` and ``B`` it forms the first-order
compensation (bias-compensated least squares)::

    A = (J + lam I)^-1 B,      T = I + g A,      s_c = T s,      cov_c = T P_ss T^T

(``s_c`` is formed as ``s + g (J + lam I)^-1 (B s)`` each sample; ``T`` itself only
when asked, for the covariance).

with ``g <= 1`` limiting the correction to a tenth of ``|s|`` while the
information is still rank-deficient (the first samples; ``g = 1`` after).
``A`` is the relative attenuation, a property of the signals and the noise
(the noise-to-signal ratio of the regressor within the filter's band), not
of how much the filter remembers: it applies as well to an estimate whose
random walk on ``S`` has been raised (it then tracks a recent window of the
same signals).
"""

from functools import lru_cache

import casadi as ca
import numpy as np

from fmscal.plant._backend import ops
from fmscal.plant._compile import BufferedCall, compile_function

from . import _matrix as mx
from .max_likelihood import (POSE_SD_FLOOR, _bias_matrix, _cholesky_apply, _correction_limit, _filter_step,
                             _information_factor, _initial_state, _layout, _unpack)

__all__ = ["EivCompensation"]


def _compensation(z, u, q, s, payload, n):
    """One sample of the separate-bias filter and the compensation of ``s`` (module docstring).

    Parameters
    ----------
    z : ndarray or casadi.SX, shape (size,)
        Packed state of the separate-bias filter (:func:`observers.max_likelihood._layout`).
    u : shape (12,)
        ``[has_pose_k+1, theta_k, theta_k+1, pose_k+1 (3), w_hat_k (3), w_hat_k+1 (3)]``.
    q : shape (6,)
        ``[h, angle variance, position variance, Sigma (3)]``: the step (s),
        the pose noise and the raw reading's noise variances.
    s : shape (3n,)
        The filter's estimate of ``vec([S | c])`` after the sample, row order;
        the separate-bias filter takes its process noise
        ``W = S Sigma S^T`` at it.
    payload : plant.Payload
    n : int
        Columns of ``[S | c]``: 3, or 4 with the offset.

    Returns
    -------
    z_next : shape (size,)
    s_c : shape (3n,)
        The compensated estimate ``T s = s + g A s`` (:func:`compensation_matrix` gives ``T``).
    """
    o = ops(z, u, q, s)
    m = 3 * n
    var_w = q[3:6]
    S = o.matrix([[s[n * i + j] for j in range(3)] for i in range(3)])
    W = o.dot(o.dot(S, o.matrix([[var_w[i] if i == j else 0.0 for j in range(3)] for i in range(3)])), S.T)
    p = o.vcat([q[0:3], mx.flat(o, W), q[3:6]])          # the parameters of _filter_step (it reads no s0)
    z_next = _filter_step(z, u, p, payload, n, eiv=True)
    st = _layout(n).unpack(z_next)
    factor = _information_factor(o, _unpack(o, st.J, m), m)
    s_col = mx.col(s)
    corr = _cholesky_apply(o, factor, o.dot(_bias_matrix(o, st.beta, var_w, n), s_col), m)    # A s
    return z_next, mx.vec(s_col + _correction_limit(o, s_col, corr, m) * corr)


def compensation_matrix(z, var_w, s, n):
    """The compensation ``T = I + g A`` after a sample (module docstring), in numpy.

    Parameters
    ----------
    z : ndarray, shape (size,)
        Packed state of the separate-bias filter after the sample.
    var_w : ndarray, shape (3,)
        The raw reading's noise variances.
    s : ndarray, shape (3n,)
        The filter's estimate after the sample (the ``s`` of :func:`_compensation`).
    n : int
        Columns of ``[S | c]``: 3, or 4 with the offset.

    Returns
    -------
    ndarray, shape (3n, 3n)
    """
    o, m = ops(z), 3 * n
    st = _layout(n).unpack(z)
    A = _cholesky_apply(o, _information_factor(o, _unpack(o, st.J, m), m), _bias_matrix(o, st.beta, var_w, n), m)
    s_col = mx.col(s)
    return mx.eye(o, m) + _correction_limit(o, s_col, o.dot(A, s_col), m) * A


@lru_cache(maxsize=8)
def _compiled(payload, n):
    """:func:`_compensation` compiled by casadi for one payload, called through buffers."""
    size = _layout(n).size
    z = ca.SX.sym("z", size)
    u = ca.SX.sym("u", 12)
    q = ca.SX.sym("q", 6)
    s = ca.SX.sym("s", 3 * n)
    z_next, s_c = _compensation(z, u, q, s, payload, n)
    fun = ca.Function(f"eiv_compensation{n}", [z, u, q, s], [ca.densify(z_next), ca.densify(s_c)])
    return compile_function(fun)


class EivCompensation:
    """The errors-in-variables compensation of an online estimate of ``[S | c]`` (module docstring).

    Parameters
    ----------
    payload : plant.Payload
    n : int
        Columns of ``[S | c]``: 3, or 4 with the offset.
    """

    def __init__(self, payload, n):
        self.payload, self.n = payload, int(n)
        self._call = BufferedCall(_compiled(payload, self.n))
        self._s = None                           # the last step's s (None: no step yet)

    def reset(self, pose, pose_sd, wrench_sd):
        """Start at the first sample.

        Parameters
        ----------
        pose : array_like, shape (3,)
            The first pose ``[theta, X, Y]`` (rad, m).
        pose_sd : array_like, shape (3,)
            Pose noise standard deviations ``[angle, X, Y]`` (rad, m, m);
            ``X`` and ``Y`` share the position's.
        wrench_sd : array_like, shape (3,)
            The raw reading's noise standard deviations.
        """
        pose_var = np.maximum(np.asarray(pose_sd, dtype=float), POSE_SD_FLOOR) ** 2
        z_in, _, q_in, _ = self._call.inputs
        z_in[:] = _initial_state(np.asarray(pose, dtype=float), pose_var, self.n)
        q_in[1:3] = pose_var[:2]
        q_in[3:6] = np.square(np.asarray(wrench_sd, dtype=float))
        self._s = None

    def step(self, has_pose, theta, pose, w_hat, dt, s):
        """One sample: advance the separate-bias filter and compensate ``s``.

        Parameters
        ----------
        has_pose : bool
            A pose arrived at the sample's end.
        theta : tuple of float
            The angle at the step's start and end, rad (the filter's estimates).
        pose : array_like, shape (3,)
            The pose at the step's end ``[theta, X, Y]`` (rad, m); ignored
            without one.
        w_hat : tuple of array_like, each shape (3,)
            The raw readings at the step's start and end.
        dt : float
            The step, s.
        s : ndarray, shape (3n,)
            The filter's estimate of ``vec([S | c])`` after the sample.

        Returns
        -------
        ndarray, shape (3n,)
            The compensated estimate; :attr:`T` holds the compensation.
        """
        call = self._call
        z_in, u_in, q_in, s_in = call.inputs
        u_in[0] = 1.0 if has_pose else 0.0
        u_in[1:3] = theta
        u_in[3:6] = pose if has_pose else 0.0
        u_in[6:9], u_in[9:12] = w_hat
        q_in[0] = dt
        s_in[:] = s
        call()
        z_next, s_c = call.outputs
        z_in[:] = z_next
        self._s = np.array(s, dtype=float)
        return s_c.copy()

    @property
    def state(self):
        """The separate-bias filter's packed state and its parameters ``[h, angle variance, position variance,
        Sigma (3)]`` (views: writing them sets the filter, as :meth:`step` leaves it)."""
        z_in, _, q_in, _ = self._call.inputs
        return z_in, q_in

    def set_last(self, s):
        """Take ``s`` as the estimate of the last step (for :attr:`T`), after :attr:`state` was written."""
        self._s = np.array(s, dtype=float)

    @property
    def T(self):
        """The compensation after the last :meth:`step`, shape (3n, 3n) (identity before any)."""
        if self._s is None:
            return np.eye(3 * self.n)
        z_in, q_in = self.state
        return compensation_matrix(z_in, q_in[3:6], self._s, self.n)
