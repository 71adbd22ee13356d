"""The floor linearised about the smoothed motion: the spatial floor, and on request any model's.

In the plane the accelerations are linear in ``[S | c]`` once the angle in
``G(theta)`` is read from the measured poses, and the floor
(:mod:`fmscal.observers.batch._max_likelihood`) is an exact linear Kalman filter.
In 3D they are not: the attitude turns the force into the world, the
angular velocity adds gyroscopic and centripetal terms, and the attitude is
a unit quaternion. The floor then takes the Gauss-Newton road:

1. **A nominal motion** ``x_bar_k`` (``[p, q, v, omega]``) from the poses,
   smoothed and differentiated (:func:`fmscal.plant.physics.smoothed_state`),
   and a nominal calibration ``s_bar`` (the identity, then the last pass's
   estimate).
2. **The error state** ``delta = [dp, dphi, dv, domega]`` (12) with
   ``x = x_bar (+) delta`` (:meth:`fmscal.plant.SpatialModel.integrate`:
   ``dphi`` a turn about the sensor's axes). One step of the dynamics,
   the acceleration ``a = A(x) [S | c] [w_hat; 1] + d(x)`` (Newton-Euler,
   :meth:`fmscal.plant.SpatialModel.acceleration`) linear over the step as in
   the plane::

       nu_k+1 = nu_k + h (a_k + a_k+1) / 2
       q_k+1  = q_k (+) (h nu_k + h^2 (2 a_k + a_k+1) / 6)

   linearised in ``delta`` (its Jacobian ``Phi_k`` by casadi's automatic
   differentiation of that one map) and in ``s = vec([S | c])`` about
   ``s_bar``::

       delta_k+1 = Phi_k delta_k + U_k s + c_k + (reading noise)

   ``U_k = [h^2 (2 A_k W_k + A_k+1 W_k+1) / 6; h (A_k W_k + A_k+1 W_k+1) / 2]``
   (``W_k = I (x) [w_hat_k; 1]^T``; the turn's small-angle Jacobian over one
   step, ``1 - O(|omega| h)``, taken as 1) and ``c_k`` the one-step map at
   ``delta = 0, s = s_bar`` less ``U_k s_bar``. The acceleration at the
   step's end is taken at ``x_bar_k+1 (+) delta_k`` (the error carried to
   the end, which the step changes by ``O(h)``): both ends' accelerations
   then depend on the error in ``Phi_k``. Taken at the nominal ``x_bar_k+1``,
   half of each step's coupling of the state's error into the acceleration
   (the attitude turning the force) would be left out, an error of the
   first order in the nominal's own error, which the noise of the poses
   sets: ``S_std`` would come out too small on logs of noisy attitudes.
3. **The pose**, in the error state: ``[p_meas - p_bar, 2 log(q_bar* (x) q_meas)]
   = delta[:6] + v``, ``v`` white with the position's and the attitude's
   variances (a turn about the sensor's axes, as the scenarios draw it).
4. **The filter and the information** exactly as in the plane
   (:mod:`fmscal.observers.kalman._filter`: Friedland's separate-bias filter, a
   flat prior on ``s``, the reading's noise as process noise ``[h^2, h]
   [h^2, h]^T (x) A S Sigma S^T A^T``): ``J = sum H^T V^-1 H``,
   ``r = sum H^T V^-1 e``, and ``s_hat`` solves ``(J - B) s = r``.

Given the nominal, the model is linear in ``delta`` and ``s``, and ``J^-1 r``
is its exact maximum-likelihood estimate; a second pass relinearises at the
first pass's estimate (``passes=2``): the nominal motion enters only through
``Phi_k`` and ``c_k``, whose errors (the smoothing's bias, the pose noise
left in the nominal) change ``delta`` to second order.

**Errors in variables.** As in the plane, the noisy reading in the
regressor correlates with the process noise it drives, and biases ``J^-1 r``
towards zero: ``E[r - J s] = -B s`` with ``B_(i l),(a l') = delta_l l'
Sigma_l beta_ai`` (:func:`fmscal.observers.kalman.bias_matrix`). In the plane
``beta`` is propagated in closed form (21 12x12 moments per step here: too
slow); here it is measured on the log's own filter: a copy of the filter's
error, driven by a seeded draw of the reading's and the pose's noise through
the same gains, gives ``sum D_n^T V^-1 nu``, whose mean is ``-B s_bar``, so
``beta = -(that / Sigma_l) s_bar^-1``. The draw's own scatter is the noise's
share of the regressor (``|Sigma|^1/2`` over the reading's spread, a few
per cent) times one standard deviation of ``s``: a thousandth of a sigma.

**The latency the fit prefers.** The log is given with its poses moved
back by a latency (:meth:`fmscal.plant.Log.shift_poses`). Were they a
further ``eps`` late, the motion at each pose would be the one the wrench
drove ``eps`` earlier: ``S [w_hat(t - eps); 1] = S [w_hat; 1] - eps S w_hat'``
to first order. The passes before the last (which only set the next pass's
noise model and linearisation) carry ``eps`` as one more parameter beside
``s``, its column of the step's regressor that of the wrench
``-S_bar w_hat'``::

    U_eps,k = [h^2 (2 A_k u_k + A_k+1 u_k+1) / 6; h (A_k u_k + A_k+1 u_k+1) / 2],
    u_k = -S_bar w_hat'_k                                                   (LF1)

(``w_hat'`` the reading's smoothed rate,
:func:`fmscal.observers.batch.reading_rate`). With the information ``J``
and ``r`` about ``[s; eps]``, ``s`` profiled out::

    eps_hat = (r_e - J_es J_ss^-1 r_s) / I_e,    std = I_e^-1/2,
    I_e = J_ee - J_es J_ss^-1 J_se                                         (LF2)

the Gauss-Newton step of the profile likelihood in the latency from the
latency the log was aligned at, and its standard deviation
(``latency_step``; :mod:`fmscal.observers.batch._latency`, rules 8 and 9,
compares it with the cross-correlation's estimate). The blocks of ``s``
are those the pass had without it, so its estimate is unchanged.

**Coloured reading noise.** The filter takes the reading's noise as white
from sample to sample. A sensor's own low-pass filter, an interpolation or
an average over a few samples correlates it over ``tau`` samples (its
integrated correlation time, :func:`fmscal.plant.io.estimate_noise`, eq.
(N2)), and the motion, which integrates the noise twice, sees its power at
frequencies far below the filter's corner: that of white noise of ``tau``
times its variance. The process noise and the errors-in-variables copy take
that variance::

    Sigma = diag(wrench_sd^2 tau)                                            (LF3)

(:attr:`fmscal.plant.NoiseSpec.long_run_wrench_sd`; ``tau`` = 1, the white
noise's, where the noise model holds none). The filter's bandwidth on the
scenarios' poses is a few Hz, well below a corner of 30 Hz and more, so the
white noise of (LF3) drives the motion as the coloured one does there.

What the log determines: the information ``J`` along each direction of the
augmented reading ``[tx .. fz, 1]`` (:func:`undetermined_directions`), as
the reference fit reports it; an undetermined direction leaves ``converged``
False.

**On a model with linear channels** (the planar one, with
``fit_max_likelihood(..., linearised=True)``). Nothing above is spatial: the
nominal motion is :func:`fmscal.observers.batch.nominal_motion` (each
additive configuration column smoothed and differentiated), the error state
is ``[dq, dnu]`` of the model's own ``state_integrate``, the pose residual
``difference(x_bar, pose)``. Linearising is exact there in the state (the
step is linear in ``delta`` but for ``G(theta)``, whose angle error the
error state carries to first order), and the fit agrees with the exact
filter of :mod:`fmscal.observers.batch._max_likelihood` up to what the two
take differently:

* the angle in ``G(theta)``: the exact filter reads the measured, noisy
  angle (interpolated between frames on a multi-rate log), this one the
  smoothed nominal plus the filter's first-order correction; the
  information ``J`` differs by the order of the angle's noise (relative);
* the errors-in-variables moments: closed form there, the seeded copy here
  (its scatter, a few per cent of ``B``).

With an almost exact angle both vanish but the copy's scatter
(``tests/test_general_batch.py`` states the bounds).
"""

from functools import lru_cache

import casadi as ca
import numpy as np
from scipy.linalg import cho_factor, cho_solve

from fmscal.plant.numerics import ChunkedSteps, StateLayout, build_once, ops

from fmscal.observers.core import matrix as mx, move, position_increment, progress_bar, velocity_increment
from fmscal.observers.kalman import (POSE_SD_FLOOR, V0_SD, beta_from_copy, bias_matrix, cholesky, cholesky_apply,
                                     copy_predict, correction_limit, error_variances, information_pull, pack_lower,
                                     regressor_step, solve_information, unpack_lower)
from ._inverse_dynamics import READING_NAMES, UNDETERMINED_STD, describe_direction, nominal_motion, reading_rate

__all__ = ["fit_linearised", "undetermined_directions", "configuration_residuals", "error_layout"]

_CHUNK = 1000            # the history's resolution, samples
_CALL = 100              # samples per compiled call (casadi builds a longer accumulation of this step slowly)
_SEED = 20261124         # the draw of the errors-in-variables copy: fixed, so a fit is repeatable
_HISTORY_RADIUS = 10.0   # history only: |S_hat - S0| <= this times (|S0| + 1), Frobenius norms
_COND_MAX = 1e12         # scaled information above this condition number: a direction undetermined


def error_layout(model, n, eiv, latency=False):
    """The filter's packed state: the error state's filter, the information, and the noise copy.

    ``d`` (12, the error state run as if ``s = 0``), ``P`` (packed lower),
    ``M`` (12 x m, ``d x / d s``), ``J`` (m x m packed lower), ``r`` (m);
    with ``eiv``: ``eps`` (the copy's error), ``Mn`` (12 x n_w^2, the copy's
    noise part of ``M``), ``bn`` (n_w^2, its ``sum D_n^T V^-1 nu``). With
    ``latency``, ``M``, ``J`` and ``r`` take one more parameter after ``s``:
    the poses' remaining latency (eq. LF1).
    """
    ne, m, ms = 2 * model.nv, model.n_w * n + int(bool(latency)), model.n_w * model.n_w
    parts = [("d", ne), ("P", ne * (ne + 1) // 2), ("M", ne * m), ("J", m * (m + 1) // 2), ("r", m)]
    if eiv:
        parts += [("eps", ne), ("Mn", ne * ms), ("bn", ms)]
    return StateLayout(*parts)


def _input_layout(model, eiv, latency=False):
    parts = [("has", 1), ("x0", model.nx), ("x1", model.nx), ("w0", model.n_w), ("w1", model.n_w),
             ("y", model.nv)]
    if eiv:
        parts += [("n0", model.n_w), ("n1", model.n_w), ("v", model.nv)]
    if latency:                                 # the true wrench's rate at the step's ends (eq. LF1)
        parts += [("rate0", model.n_w), ("rate1", model.n_w)]
    return StateLayout(*parts)


def _params_layout(model, n):
    """``h``, the error-state pose variances ``R``, ``W = S Sigma S^T``, ``s_bar``, and the payload and the
    gravity (:meth:`fmscal.plant.Model.payload_vector`: one build of the step serves every payload)."""
    return StateLayout(("h", 1), ("R", model.nv), ("W", model.n_w * model.n_w), ("s", model.n_w * n),
                       *model.payload_parts())


def _one_step(model, x0, x1, w0, w1, delta, h):
    """The one-step map of the module docstring: ``x_bar_k (+) delta`` moved by a step, less ``x_bar_k+1``.

    ``w0``, ``w1`` are the true wrench at the step's ends; the acceleration
    at the end is taken at ``x_bar_k+1 (+) delta`` (the error carried to the
    step's end, which it changes only by ``O(h)``), so that ``Phi_k`` holds
    the end's acceleration's dependence on the error too. Returns the error
    state at ``k+1``.
    """
    start = model.state_integrate(x0, delta)
    end = model.state_integrate(x1, delta)
    return model.state_difference(x1, move(model, start, model.acceleration(start, w0), model.acceleration(end, w1), h))


def _augment(w, n_w, n):
    return ca.vertcat(w, 1.0) if n == n_w + 1 else w


def _step(model, n, eiv, history, latency=False):
    """The filter's step as a casadi Function ``(z, u, p) -> (z_next[, motion])`` (module docstring); with
    ``latency``, the remaining latency's column beside ``s`` (eq. LF1)."""
    nv, n_w = model.nv, model.n_w
    ne, ms = 2 * nv, n_w * n_w
    m = n_w * n + int(bool(latency))
    L = error_layout(model, n, eiv, latency)
    z = ca.SX.sym("z", L.size)
    u = ca.SX.sym("u", _input_layout(model, eiv, latency).size)
    p = ca.SX.sym("p", _params_layout(model, n).size)
    st = L.unpack(z, scalars=False)
    uu = _input_layout(model, eiv, latency).unpack(u, scalars=False)
    pp = _params_layout(model, n).unpack(p, scalars=False)
    model = model.with_payload_symbols(getattr(pp, "payload", None))   # the payload read from p, not built in
    o = _ops()
    h, has = pp.h, uu.has
    S_bar = mx.as_matrix(o, pp.s, n_w, n)
    wa0, wa1 = _augment(uu.w0, n_w, n), _augment(uu.w1, n_w, n)
    wt0, wt1 = ca.mtimes(S_bar, wa0), ca.mtimes(S_bar, wa1)            # the true wrench at s_bar
    # Phi_k by automatic differentiation of the one-step map; c_k its value less U_k s_bar
    delta = ca.SX.sym("delta", ne)
    step_map = _one_step(model, uu.x0, uu.x1, wt0, wt1, delta, h)
    zero = ca.DM.zeros(ne)
    Phi = ca.substitute(ca.jacobian(step_map, delta), delta, zero)
    U = regressor_step(model, uu.x0, uu.x1, wa0, wa1, h)
    c = ca.substitute(step_map, delta, zero) - ca.mtimes(U, pp.s)
    if latency:         # eq. (LF1): the poses a further eps late move the wrench by -eps times its rate
        a0 = ca.mtimes(model.input_matrix(uu.x0), -uu.rate0)
        a1 = ca.mtimes(model.input_matrix(uu.x1), -uu.rate1)
        U = ca.horzcat(U, ca.vertcat(position_increment(h, a0, a1), velocity_increment(h, a0, a1)))
    # the reading's noise as process noise: [h^2, h] [h^2, h]^T (x) A S Sigma S^T A^T
    A0 = model.input_matrix(uu.x0)
    AWA = ca.mtimes(ca.mtimes(A0, mx.as_matrix(o, pp.W, n_w)), A0.T)
    Q = ca.vertcat(ca.horzcat(h ** 4 * AWA, h ** 3 * AWA), ca.horzcat(h ** 3 * AWA, h * h * AWA))
    P = unpack_lower(o, st.P, ne)
    M = mx.as_matrix(o, st.M, ne, m)
    x_pred = ca.mtimes(Phi, st.d) + c                                   # the filter run as if s = 0
    P_pred = ca.mtimes(ca.mtimes(Phi, P), Phi.T) + Q
    M_pred = ca.mtimes(Phi, M) + U
    CP, H, e = P_pred[0:nv, :], M_pred[0:nv, :], uu.y - x_pred[0:nv]
    V = P_pred[0:nv, 0:nv] + ca.diag(pp.R)
    cols = [CP, H, e]
    if eiv:
        # the copy: the reading's noise n (a seeded draw) moves the truth by -A S n against the
        # model, and enters the regressor as A (x) n; the pose's noise v
        eps_pred, Mn_pred = copy_predict(model, uu.x0, uu.x1, S_bar[:, 0:n_w], uu.n0, uu.n1, h, Phi, st.eps,
                                         mx.as_matrix(o, st.Mn, ne, ms))
        nu = eps_pred[0:nv] + uu.v
        Hn = Mn_pred[0:nv, :]
        cols += [Hn, nu]
    rhs = ca.horzcat(*cols)
    chol = cholesky(o, V, nv)
    X = cholesky_apply(o, chol, rhs, nv)                                 # V^-1 [C P-, H, e, (Hn, nu)]
    Vi_CP, Vi_H, Vi_e = X[:, 0:ne], X[:, ne:ne + m], X[:, ne + m]
    K = has * Vi_CP.T                                                    # K = P- C^T V^-1
    d_next = x_pred + ca.mtimes(K, e)
    P_next = P_pred - ca.mtimes(K, CP)
    M_next = M_pred - ca.mtimes(K, H)
    J_next = unpack_lower(o, st.J, m) + has * ca.mtimes(H.T, Vi_H)
    r_next = st.r + has * ca.mtimes(H.T, Vi_e)
    parts = [d_next, pack_lower(P_next, ne), mx.flat(o, M_next), pack_lower(J_next, m), r_next]
    if eiv:
        Vi_nu = X[:, ne + m + 1 + ms]
        eps_next = eps_pred - ca.mtimes(K, nu)
        Mn_next = Mn_pred - ca.mtimes(K, Hn)
        bn_next = st.bn + has * ca.mtimes(Hn.T, Vi_nu)
        parts += [eps_next, mx.flat(o, Mn_next), bn_next]
    outputs = [ca.densify(ca.vertcat(*parts))]
    if history:                                # the motion at s_bar: x_bar (+) (d + M s_bar)
        outputs.append(ca.densify(d_next + ca.mtimes(M_next, pp.s)))
    tag = f"{model.name}{n}{'_eiv' if eiv else ''}{'_history' if history else ''}{'_latency' if latency else ''}"
    return ca.Function(f"linearised_floor_{tag}", [z, u, p], outputs)


def _ops():
    return ops(ca.SX.sym("o"))


_CHUNKED = {}           # (model.compiled_key(), n, eiv, history, latency) -> ChunkedSteps


def _chunked(model, n, eiv, history, latency=False):
    """:func:`_step` compiled in chunks of :data:`_CALL` samples, once for every payload and gravity of a
    model whose step reads them at run time (:meth:`fmscal.plant.Model.compiled_key`)."""
    return build_once(_CHUNKED, (model.compiled_key(), n, eiv, history, latency),
                      lambda: ChunkedSteps(_step(model, n, eiv, history, latency), _CALL), 8)


# --- the driver -----------------------------------------------------------------------------------

@lru_cache(maxsize=4)
def _mapped(model, what, N):
    """``model.difference`` (a state's configuration to a measured pose) or ``model.state_integrate`` over ``N``
    samples at once, on the model's own layouts (any model: the configuration need not lead the state)."""
    x = ca.SX.sym("x", model.nx)
    if what == "difference":                    # y: a measured pose, in the log's columns
        y = ca.SX.sym("y", model.n_pose)
        out = model.difference(model.configuration(x), model.pose_configuration(y))
    else:                                       # y: an error state [dq, dnu]
        y = ca.SX.sym("y", 2 * model.nv)
        out = model.state_integrate(x, y)
    return ca.Function(f"{what}_{model.name}", [x, y], [out]).map(N)


def configuration_residuals(model, states, poses):
    """The measured poses less the configurations of ``states``: ``difference(x, pose)`` row by row.

    Parameters
    ----------
    model : plant.Model
    states : ndarray, shape (M, nx)
    poses : ndarray, shape (M, n_pose)
        Measured poses in the log's columns (spatial: ``qw qx qy qz x y z``; planar ``theta x y``).

    Returns
    -------
    ndarray, shape (M, nv)
        Spatial: ``[dp (m, world), dphi (rad, a turn about the sensor's axes)]``; planar ``[dtheta, dX, dY]``.
    """
    if not len(states):
        return np.zeros((0, model.nv))
    return np.asarray(_mapped(model, "difference", len(states))(np.asarray(states).T, np.asarray(poses).T)).T


def _pose_residuals(model, log, nominal):
    """The pose in the error state, ``difference(x_bar, pose)`` (``[dp, dphi]``), zeros where there is none."""
    rows = np.flatnonzero(log.has_pose)
    y = np.zeros((len(log), model.nv))
    y[rows] = configuration_residuals(model, nominal[rows], log.pose[rows])
    return y


def _error_variances(model, noise):
    """The pose noise's variances in the error state's configuration part ``dq`` (``nv``).

    A unit-quaternion attitude: :func:`fmscal.observers.kalman.error_variances` (``[dp, dphi]``); a
    configuration that moves additively (the pose is the configuration): each pose column's variance
    (:meth:`fmscal.plant.Model.pose_sd`), as the planar floor takes them. Floored at :data:`POSE_SD_FLOOR`.
    """
    if model.attitude == "quaternion":
        return error_variances(model, noise)
    return np.maximum(model.pose_sd(noise), POSE_SD_FLOOR) ** 2


def _initial_state(model, n, eiv, y0, var, latency=False):
    L = error_layout(model, n, eiv, latency)
    ne = 2 * model.nv
    z = np.zeros(L.size)
    z[L.slices["d"]][:model.nv] = y0
    z[L.slices["P"]] = pack_lower(np.diag(np.r_[var, np.full(model.nv, V0_SD ** 2)]), ne)
    return z


def _history_estimate(J, r, B, s0, m, n_w, n):
    """The estimate from the data so far (the history's rows), as the planar floor's history: a
    negligible pull towards ``s0``, the errors-in-variables correction to first order (limited while
    the information is rank-deficient), held within :data:`_HISTORY_RADIUS` of ``s0``. The equations of
    :func:`fmscal.observers.kalman.information_factor` and ``cholesky_apply``, solved by LAPACK (equal to
    rounding; the scalar loops those run for casadi took a tenth of a 60 s log's fit)."""
    o = _np_ops()
    factor = cho_factor(J + information_pull(o, J, m) * np.eye(m), lower=True)
    s_u = s0[:, None] + cho_solve(factor, (r - J @ s0)[:, None])
    corr = cho_solve(factor, B @ s_u)
    s = np.ravel(s_u + corr * correction_limit(o, s_u, corr, m))
    entries = [n * i + j for i in range(n_w) for j in range(n_w)]
    size = np.linalg.norm((s - s0)[entries])
    radius = _HISTORY_RADIUS * (np.linalg.norm(s0[entries]) + 1.0)
    return s0 + (s - s0) / max(1.0, size / radius)


def _latency_step(J, r, m):
    """The remaining latency the pass's likelihood prefers, and its standard deviation (eq. LF2).

    ``J``, ``r`` are the information and its right-hand side about ``[s; eps]`` (``m`` entries of ``s``
    then ``eps``); ``s`` is profiled out by the Schur complement on the determined directions of ``J_ss``.
    Returns ``{"step": s, "std": s}`` (std infinite where the log holds no information about it).
    """
    d = np.sqrt(np.maximum(np.diag(J), 1e-300))
    Js = J / np.outer(d, d)
    rs = r / d
    lam, u = np.linalg.eigh(Js[:m, :m])
    kept = lam > 1e-12 * lam.max()
    inv = (u[:, kept] / lam[kept]) @ u[:, kept].T
    information = float(Js[m, m] - Js[m, :m] @ inv @ Js[:m, m])
    if not information > 1e-12:
        return {"step": 0.0, "std": float("inf")}
    step = float(rs[m] - Js[m, :m] @ inv @ rs[:m]) / information
    return {"step": step / d[m], "std": 1.0 / (np.sqrt(information) * d[m])}


def _np_ops():
    return ops(np.zeros(1))


def fit_linearised(log, model, noise, offset, passes, S0, compiled=True, window=0.2):
    """The maximum-likelihood ``[S | c]`` linearised about the smoothed motion (module docstring).

    Called by :func:`fmscal.observers.batch.fit_max_likelihood` for a
    model without linear channels (the spatial one), or for any model with
    ``linearised=True``; its arguments are checked there. Written on the
    model's pieces alone (``state_integrate``, ``difference``,
    ``acceleration``, ``input_matrix``, ``regressor``), it runs on the
    planar model too, where it agrees with the exact planar filter up to
    what the two take differently (the angle in ``G(theta)``, the
    errors-in-variables moments: module docstring, "On a model with linear
    channels").

    Parameters
    ----------
    log : plant.Log
    model : plant.Model
    noise : plant.NoiseSpec
    offset : bool
    passes : int
    S0 : ndarray, shape (n_w, n_w)
        The first pass's linearisation point and the history's start.
    compiled : bool
        True: the step compiled to C; False: casadi's virtual machine, one
        sample at a time (slow; for checks).
    window : float
        The smoothing window of the nominal motion, s
        (:func:`fmscal.observers.batch.nominal_motion`).

    Returns
    -------
    dict
        ``S_aug``, ``cov_aug``, ``S_history``, ``x_history``, ``information``,
        ``eiv_bias``, ``undetermined``, ``warnings`` (the fields of
        :class:`fmscal.observers.batch.MaximumLikelihoodFit`).
    """
    n_w, N = model.n_w, len(log)
    n = n_w + int(bool(offset))
    m = n_w * n
    nominal = nominal_motion(log, model, window)
    y = _pose_residuals(model, log, nominal)
    var = _error_variances(model, noise)
    var_w = np.square(noise.long_run_wrench_sd)          # eq. (LF3): the reading noise's power at low frequencies
    s_bar = np.c_[S0, np.zeros(n_w)].ravel() if offset else np.asarray(S0, dtype=float).ravel()
    s0 = s_bar.copy()
    rng = np.random.default_rng(_SEED)
    draw_n = rng.standard_normal((N, n_w)) * np.sqrt(var_w)
    draw_v = rng.standard_normal((N, model.nv)) * np.sqrt(var) * log.has_pose[:, None]
    base = [log.has_pose[1:, None].astype(float), nominal[:-1], nominal[1:], log.w_hat[:-1], log.w_hat[1:], y[1:]]
    starts = list(range(0, N - 1, _CHUNK))
    rate_hat = reading_rate(log, window) if passes > 1 else None
    latency_step = None
    with progress_bar(int(passes) * (N - 1), "max-likelihood") as bar:
        for k in range(int(passes)):
            last = k == passes - 1
            eiv = last
            latency = not last            # eq. (LF1): the passes before the last carry the latency's column
            S_noise = s_bar.reshape(n_w, n)[:, :n_w]
            rate = rate_hat @ S_noise.T if latency else None      # the true wrench's rate, at s_bar
            inputs = np.hstack(base + ([draw_n[:-1], draw_n[1:], draw_v[1:]] if eiv else [])
                               + ([rate[:-1], rate[1:]] if latency else []))
            W = S_noise @ np.diag(var_w) @ S_noise.T
            p = _params_layout(model, n).pack(None, h=log.dt, R=var, W=W.ravel(), s=s_bar, **model.payload_values())
            L = error_layout(model, n, eiv, latency)
            z = _initial_state(model, n, eiv, y[0] if log.has_pose[0] else np.zeros(model.nv), var, latency)
            motion, snapshots = [], []
            steps = _chunked(model, n, eiv, last, latency) if compiled else _step(model, n, eiv, last, latency)
            for k0 in starts:
                chunk = inputs[k0:k0 + _CHUNK]
                if compiled:
                    if last:
                        z, (out,) = steps.run(z, [chunk, np.broadcast_to(p, (len(chunk), len(p)))],
                                              outputs=True, states=False)
                        motion.append(out)
                    else:
                        z = steps.run(z, [chunk, np.broadcast_to(p, (len(chunk), len(p)))], states=False)
                else:
                    for row in chunk:
                        res = steps(z, row, p)
                        z = np.ravel(np.asarray(res[0] if last else res))
                        if last:
                            motion.append(np.asarray(res[1]).T)
                bar.update(len(chunk))
                if last:
                    snapshots.append((min(k0 + _CHUNK, N - 1), z.copy()))
            o = _np_ops()
            J = unpack_lower(o, z[L.slices["J"]], m + int(latency))
            r = z[L.slices["r"]]
            if latency:
                latency_step = _latency_step(J, r, m)
                J, r = J[:m, :m], r[:m]
            B = (bias_matrix(o, beta_from_copy(z[L.slices["bn"]], s_bar, var_w, n_w, n), var_w, n_w, n)
                 if eiv else np.zeros((m, m)))
            S_aug, cov = solve_information(J, r, B, model, n, log.name, singular="truncate")
            s_hist_bar, s_bar = s_bar, S_aug.ravel()
    # the history: the estimate from the data up to each chunk's end, held over the chunk
    S_history = np.empty((N, m))
    S_history[0] = s0
    for (end, zp), k0 in zip(snapshots, starts):
        Bp = (bias_matrix(o, beta_from_copy(zp[L.slices["bn"]], s_hist_bar, var_w, n_w, n), var_w, n_w, n)
              if "bn" in L.slices else np.zeros((m, m)))
        S_history[k0 + 1:end + 1] = _history_estimate(unpack_lower(o, zp[L.slices["J"]], m), zp[L.slices["r"]], Bp,
                                                       s0, m, n_w, n)
    S_history[-1] = S_aug.ravel()
    deltas = np.vstack([np.r_[y[0], np.zeros(model.nv)], np.vstack(motion)])
    x_history = np.asarray(_mapped(model, "integrate", N)(nominal.T, deltas.T)).T
    names = (*model.wrench_names, "1")
    undetermined = undetermined_directions(cov, S_aug, log, names) if n == n_w + 1 else []
    return dict(S_aug=S_aug, cov_aug=cov, S_history=S_history.reshape(N, n_w, n), x_history=x_history,
                information=J, eiv_bias=B, undetermined=undetermined, latency_step=latency_step,
                warnings=[describe_direction(d, names=names) for d in undetermined])


def undetermined_directions(cov, S_aug, log, names=READING_NAMES):
    """Directions of the augmented reading along which the log leaves ``S`` undetermined.

    A unit direction ``d`` of the reading, each component scaled by its
    spread in the log (``u = d * spread``, the constant's spread 1), moves
    the wrench by ``S u``; its uncertainty in row ``i`` is ``sqrt(u^T C_i u)``
    (``C_i`` the covariance of row ``i`` of ``[S | c]``). Relative to the
    move a unit gain makes (the reference fit's scale,
    :func:`fmscal.observers.batch.fit_inverse_dynamics`), a
    direction whose largest row exceeds :data:`~fmscal.observers.batch._inverse_dynamics.UNDETERMINED_STD`
    is undetermined. The candidates are the eigenvectors of the summed
    row covariances, in scaled units.

    Parameters
    ----------
    cov : ndarray, shape (n_w (n_w + 1), n_w (n_w + 1))
        Covariance of ``vec([S | c])``, row order (infinite or huge entries
        along a direction the information did not hold).
    S_aug : ndarray, shape (n_w, n_w + 1)
    log : plant.Log
        The log (the reading's spread).
    names : tuple of str
        The augmented reading's components: the force components (names
        starting with ``f``) give the constant's scale, as in
        :func:`fmscal.observers.batch.fit_readings`. Default the spatial reading's.

    Returns
    -------
    list of ndarray, shape (n_w + 1,)
    """
    n_w, n = S_aug.shape
    spread = np.r_[np.std(log.w_hat, axis=0), 1.0]
    force = [j for j, name in enumerate(names[:n_w]) if name.startswith("f")] or list(range(n_w))
    scale = np.r_[spread[:n_w], spread[force].mean()]
    blocks = [cov[n * i:n * (i + 1), n * i:n * (i + 1)] * np.outer(spread, spread) for i in range(n_w)]
    _, vectors = np.linalg.eigh(sum(blocks))
    out = []
    for d in vectors.T:
        worst = max(np.sqrt(max(d @ C @ d, 0.0)) for C in blocks)
        if not np.isfinite(worst) or worst / max(np.linalg.norm(d * scale), 1e-300) > UNDETERMINED_STD:
            out.append(d * np.sign(d[np.argmax(np.abs(d))]))
    return out

