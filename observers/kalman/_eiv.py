"""Errors-in-variables compensation for an online filter that takes the noisy reading as its regressor.

A filter that propagates eq. (1) with the raw reading ``w_hat`` (the EKF,
:class:`observers.AugmentedEKF`) uses that reading twice: as the regressor of
``[S | c]`` (the ``S`` block of its transition Jacobian) and, through its
noise ``n``, as the process noise ``G(theta) S n`` of the same step. The two
are correlated, and the estimate of ``s = vec([S | c])`` is attenuated
towards zero: with ``J`` the information it accumulated and ``B`` the part of
``J`` that the reading's own noise makes, it solves ``J s = r`` where the
unbiased estimate solves ``(J - B) s = r`` (:mod:`observers.batch._max_likelihood`,
module docstring). The attenuation grows with the square of the wrench
noise and with the amplification of ``S``: on the ``noisy`` and ``random-S``
scenarios it doubles the EKF's E on some seeds.

:class:`EivCompensation` runs, beside the filter and one sample at a time,
the separate-bias Kalman filter of :mod:`observers.batch._max_likelihood` (the
motion filter run as if ``s = 0``, its sensitivity ``M = dx/ds``, the
information ``J`` and the bias moments ``beta``; the same compiled step,
:func:`fmscal.observers.kalman.filter_step`), with the process noise at the
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

from fmscal.plant.numerics import BufferedCall, StateLayout, compile_function, ops

from fmscal.observers.core import matrix as mx, position_increment, velocity_increment
from ._filter import (POSE_SD_FLOOR, bias_matrix, cholesky_apply, correction_limit, filter_layout, filter_step,
                      information_factor, initial_state, input_layout, pack_lower, unpack_lower)

__all__ = ["EivCompensation", "compensation_layout", "regressor_step", "copy_predict", "error_variances",
           "beta_from_copy"]


def compensation_layout(model):
    """The per-log settings of :func:`_compensation`: the step ``h`` (s), the pose noise variances ``R``
    and the raw reading's noise variances ``var_w``."""
    return StateLayout(("h", 1), ("R", model.n_pose), ("var_w", model.n_w))


def _compensation(model, z, u, q, s, n):
    """One sample of the separate-bias filter and the compensation of ``s`` (module docstring).

    Parameters
    ----------
    model : plant.Model
        A model linear in its channels.
    z : ndarray or casadi.SX, shape (size,)
        Packed state of the separate-bias filter (:func:`fmscal.observers.kalman.filter_layout`).
    u : ndarray or casadi.SX
        The step's input (:func:`fmscal.observers.kalman.input_layout`), the
        configuration at both ends the filter's estimates.
    q : ndarray or casadi.SX
        :func:`compensation_layout`: the step, the pose noise and the raw
        reading's noise variances.
    s : shape (n_w n,)
        The filter's estimate of ``vec([S | c])`` after the sample, row order;
        the separate-bias filter takes its process noise
        ``W = S Sigma S^T`` at it.
    n : int
        Columns of ``[S | c]``.

    Returns
    -------
    z_next : shape (size,)
    s_c : shape (n_w n,)
        The compensated estimate ``T s = s + g A s`` (:func:`compensation_matrix` gives ``T``).
    """
    o = ops(z, u, q, s)
    n_w = model.n_w
    m = n_w * n
    qq = compensation_layout(model).unpack(q, scalars=False)
    var_w = qq.var_w
    S = o.matrix([[s[n * i + j] for j in range(n_w)] for i in range(n_w)])
    W = o.dot(o.dot(S, o.matrix([[var_w[i] if i == j else 0.0 for j in range(n_w)] for i in range(n_w)])), S.T)
    # the parameters of kalman.filter_step (it reads no s0)
    p = o.vcat([qq.h, qq.R, mx.flat(o, W), var_w, o.vcat([0.0] * m)])
    z_next = filter_step(model, z, u, p, n, eiv=True)
    st = filter_layout(model, n).unpack(z_next, scalars=False)
    factor = information_factor(o, unpack_lower(o, st.J, m), m)
    s_col = mx.col(s)
    corr = cholesky_apply(o, factor, o.dot(bias_matrix(o, st.beta, var_w, n_w, n), s_col), m)    # A s
    return z_next, mx.vec(s_col + correction_limit(o, s_col, corr, m) * corr)


def compensation_matrix(model, z, var_w, s, n):
    """The compensation ``T = I + g A`` after a sample (module docstring), in numpy.

    Parameters
    ----------
    model : plant.Model
    z : ndarray, shape (size,)
        Packed state of the separate-bias filter after the sample.
    var_w : ndarray, shape (n_w,)
        The raw reading's noise variances.
    s : ndarray, shape (n_w n,)
        The filter's estimate after the sample (the ``s`` of :func:`_compensation`).
    n : int
        Columns of ``[S | c]``.

    Returns
    -------
    ndarray, shape (n_w n, n_w n)
    """
    o, m = ops(z), model.n_w * n
    st = filter_layout(model, n).unpack(z, scalars=False)
    A = cholesky_apply(o, information_factor(o, unpack_lower(o, st.J, m), m),
                       bias_matrix(o, st.beta, var_w, model.n_w, n), m)
    s_col = mx.col(s)
    return mx.eye(o, m) + correction_limit(o, s_col, o.dot(A, s_col), m) * A


@lru_cache(maxsize=8)
def _compiled(model, n):
    """:func:`_compensation` compiled by casadi for one model, called through buffers."""
    z = ca.SX.sym("z", filter_layout(model, n).size)
    u = ca.SX.sym("u", input_layout(model).size)
    q = ca.SX.sym("q", compensation_layout(model).size)
    s = ca.SX.sym("s", model.n_w * n)
    z_next, s_c = _compensation(model, z, u, q, s, n)
    fun = ca.Function(f"eiv_compensation_{model.name}{n}", [z, u, q, s], [ca.densify(z_next), ca.densify(s_c)])
    return compile_function(fun)


class EivCompensation:
    """The errors-in-variables compensation of an online estimate of ``[S | c]`` (module docstring).

    Parameters
    ----------
    model : plant.Model
        A model linear in its channels (:attr:`fmscal.plant.Model.linear_channels`).
    n : int
        Columns of ``[S | c]``: ``n_w``, or ``n_w + 1`` with the offset.
    """

    def __init__(self, model, n):
        self.model, self.n = model, int(n)
        self._call = BufferedCall(_compiled(model, self.n))
        self._inputs = input_layout(model)
        self._settings = compensation_layout(model)
        self._s = None                           # the last step's s (None: no step yet)

    def reset(self, pose, pose_sd, wrench_sd):
        """Start at the first sample.

        Parameters
        ----------
        pose : array_like, shape (n_pose,)
            The first pose (planar ``[theta, X, Y]``, rad, m).
        pose_sd : array_like, shape (n_pose,)
            Each pose column's noise standard deviation (:meth:`fmscal.plant.Model.pose_sd`).
        wrench_sd : array_like, shape (n_w,)
            The raw reading's noise standard deviations.
        """
        pose_var = np.maximum(np.asarray(pose_sd, dtype=float), POSE_SD_FLOOR) ** 2
        z_in, _, q_in, _ = self._call.inputs
        z_in[:] = initial_state(self.model, np.asarray(pose, dtype=float), pose_var, self.n)
        q_in[self._settings.slices["R"]] = pose_var
        q_in[self._settings.slices["var_w"]] = np.square(np.asarray(wrench_sd, dtype=float))
        self._s = None

    def step(self, has_pose, q, pose, w_hat, dt, s):
        """One sample: advance the separate-bias filter and compensate ``s``.

        Parameters
        ----------
        has_pose : bool
            A pose arrived at the sample's end.
        q : tuple of array_like, each shape (nq,)
            The configuration at the step's start and end (the filter's estimates).
        pose : array_like, shape (n_pose,)
            The pose at the step's end; ignored without one.
        w_hat : tuple of array_like, each shape (n_w,)
            The raw readings at the step's start and end.
        dt : float
            The step, s.
        s : ndarray, shape (n_w n,)
            The filter's estimate of ``vec([S | c])`` after the sample.

        Returns
        -------
        ndarray, shape (n_w n,)
            The compensated estimate; :attr:`T` holds the compensation.
        """
        call = self._call
        z_in, u_in, q_in, s_in = call.inputs
        u_in[:] = self._inputs.pack(None, has_pose=1.0 if has_pose else 0.0, q0=q[0], q1=q[1],
                                    pose=pose if has_pose else np.zeros(self.model.n_pose), w0=w_hat[0], w1=w_hat[1])
        q_in[0] = dt
        s_in[:] = s
        call()
        z_next, s_c = call.outputs
        z_in[:] = z_next
        self._s = np.array(s, dtype=float)
        return s_c.copy()

    @property
    def state(self):
        """The separate-bias filter's packed state and its settings (:func:`compensation_layout`)
        (views: writing them sets the filter, as :meth:`step` leaves it)."""
        z_in, _, q_in, _ = self._call.inputs
        return z_in, q_in

    def set_last(self, s):
        """Take ``s`` as the estimate of the last step (for :attr:`T`), after :attr:`state` was written."""
        self._s = np.array(s, dtype=float)

    @property
    def T(self):
        """The compensation after the last :meth:`step`, shape (n_w n, n_w n) (identity before any)."""
        if self._s is None:
            return np.eye(self.model.n_w * self.n)
        z_in, q_in = self.state
        return compensation_matrix(self.model, z_in, q_in[self._settings.slices["var_w"]], self._s, self.n)


# --- the errors-in-variables copy of the error-state filter (spatial), shared by the EKF on a model without
# linear channels (observers.kalman.AugmentedEKF) and the linearised floor (observers.batch.fit_linearised),
# which runs this filter over a whole log: the batch method builds on the filter, so the pieces live here.

def regressor_step(model, x0, x1, w0, w1, h):
    """``U_k`` (12 x n_w len(w)): what ``s`` adds to the error state over a step (the linearised floor's
    module docstring, :func:`observers.batch.fit_linearised`)."""
    R0, R1 = model.regressor(x0, w0), model.regressor(x1, w1)
    return ca.vertcat(position_increment(h, R0, R1), velocity_increment(h, R0, R1))


def copy_predict(model, x0, x1, S, n0, n1, h, Phi, eps, Mn):
    """The errors-in-variables copy over one step (the linearised floor's module docstring), on casadi symbols.

    A seeded draw ``n`` of the reading's noise moves the truth by ``-A S n``
    against the model (the filter's error ``eps``) and enters the regressor
    as ``A (I (x) n^T)`` (the sensitivity ``Mn``)::

        eps- = Phi eps - [h^2 (2 A_k S n_k + A_k+1 S n_k+1) / 6; h (A_k S n_k + A_k+1 S n_k+1) / 2]
        Mn-  = Phi Mn + U_k(n)

    Parameters
    ----------
    model : plant.Model
    x0, x1 : casadi.SX, shape (nx,)
        The motion at the step's ends.
    S : casadi.SX, shape (n_w, n_w)
        The calibration that carries the noise (without the offset column).
    n0, n1 : casadi.SX, shape (n_w,)
        The draw of the reading's noise at the step's ends.
    h : casadi.SX
        The step, s.
    Phi : casadi.SX, shape (ne, ne)
        The error state's transition.
    eps : casadi.SX, shape (ne,)
    Mn : casadi.SX, shape (ne, n_w n_w)

    Returns
    -------
    eps_pred : casadi.SX, shape (ne,)
    Mn_pred : casadi.SX, shape (ne, n_w n_w)
    """
    an0 = ca.mtimes(model.input_matrix(x0), ca.mtimes(S, n0))
    an1 = ca.mtimes(model.input_matrix(x1), ca.mtimes(S, n1))
    drive = ca.vertcat(position_increment(h, an0, an1), velocity_increment(h, an0, an1))
    return ca.mtimes(Phi, eps) - drive, ca.mtimes(Phi, Mn) + regressor_step(model, x0, x1, n0, n1, h)


def error_variances(model, noise):
    """The pose noise in the error state (``nv``): ``position_sd^2`` on each entry of the configuration's
    difference (:meth:`fmscal.plant.SpatialModel.difference`) that the pose's position columns alone move,
    ``angle_sd^2`` on the others (spatial ``[dp, dphi]``: position then a turn about the sensor axes; planar
    ``[dtheta, dX, dY]``); each at least :data:`POSE_SD_FLOOR` squared."""
    position = _position_entries(model)
    sd = np.where(position, noise.position_sd, noise.angle_sd)
    return np.maximum(sd, POSE_SD_FLOOR) ** 2


@lru_cache(maxsize=8)
def _position_entries(model):
    """Whether each entry of the configuration's difference depends on the pose's position columns only
    (the structure of its Jacobian with respect to the measured pose), shape (nv,) of bool."""
    p0, p1 = ca.SX.sym("p0", model.n_pose), ca.SX.sym("p1", model.n_pose)
    J = ca.jacobian(model.difference(model.pose_configuration(p0), model.pose_configuration(p1)), p1).sparsity()
    is_position = [name in model.position_names for name in model.pose_names]
    return np.array([all(is_position[j] for j in range(model.n_pose) if J.has_nz(i, j)) for i in range(model.nv)])


def beta_from_copy(bn, s_bar, var_w, n_w, n):
    """``beta`` (packed lower, as :func:`fmscal.observers.kalman.bias_matrix` reads it) from the copy's
    ``sum D_n^T V^-1 nu``, whose mean is ``-B s_bar``: ``(B s)_il = Sigma_l (beta S)_il``."""
    S_bar = s_bar.reshape(n_w, n)[:, :n_w]
    beta_S = -bn.reshape(n_w, n_w) / np.maximum(var_w, 1e-300)[None, :]
    beta = beta_S @ np.linalg.inv(S_bar)
    beta = (beta + beta.T) / 2
    return pack_lower(beta, n_w)
