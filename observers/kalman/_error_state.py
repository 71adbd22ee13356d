"""The EKF's step on an error state, for every model (:class:`observers.AugmentedEKF`), as casadi functions.

One filter for the planar and the spatial model: the model's pieces
(``integrate``, ``difference``, ``acceleration``) are all it takes. A unit
quaternion is not a vector: adding a Kalman correction to it leaves the unit
sphere, and its covariance (4x4 for 3 degrees of freedom) is singular; an
angle is, and its error is the angle's difference. The filter holds

- a **nominal** state: the motion ``x`` (:attr:`fmscal.plant.Model.state`;
  spatial ``[p, q, v, omega]``, planar ``[theta, theta', X, X', Y, Y']``)
  and ``s = vec([S | c])`` (row order), propagated by the model;
- an **error state** ``e = [dq, dnu, ds]`` (``d = 2 nv + n_w n``), ``x_true
  = x (+) e`` (:meth:`fmscal.plant.Model.state_integrate`; spatial ``[dp,
  dphi, dv, domega]``, ``dphi`` a turn about the sensor's axes, ``q (x)
  exp(dphi / 2)``; planar ``[dtheta, dX, dY, dtheta', dX', dY']``, an
  addition), ``s_true = s + ds``. filterpy's ``x`` is ``e`` and ``P`` its
  covariance; ``e`` is zero between steps.

One step, eqs. (K1-K8) of :mod:`observers.kalman._kalman` with the model's
pieces (one equation a line)::

    x-   = f(x, s, w_hat_k, w_hat_k+1)                 nominal (below)
    F    = d e_k+1 / d e_k,   J_i = d e_k+1 / d w_hat_i  (casadi, at e = 0)
    P-   = F P F^T + Q
    y    = difference(q(x-), pose)   = [dp, dphi]       (the pose in the error state)
    V    = H P- H^T + R,   K = P- H^T V^-1,   H = [I_nv 0]
    e    = K y
    P    = (I - K H) P- (I - K H)^T + K R K^T           (Joseph form)
    x, s = x- (+) e[:12],  s + e[12:]                    (injection)
    P    = G P G^T,   G = d e+ / d e at e               (the reset; I but for
                                                        I - [dphi / 2]x on a turn)
    e    = 0

The nominal step ``f`` is the discretisation every method shares
(:func:`observers.core.move`: the acceleration linear over the step,
the configuration moved on the manifold), with the acceleration at the
step's end taken at the state that the start's acceleration reaches (Heun's
predictor); the acceleration is the model's (:meth:`fmscal.plant.Model.acceleration`,
``a = A(x) w + d(x)``; in 3D Newton-Euler, in the plane eq. (1)) of
the true wrench ``w = [S | c] [w_hat; 1]``. ``F``, the reading Jacobians
and ``G`` are casadi's automatic derivatives of that one map and of the
model's ``integrate`` and ``difference``: nothing is differentiated by hand.

Tuning rule. ``R`` the pose noise in the error state
(:func:`observers.kalman.error_variances`: spatial ``diag(position_sd^2 (x3),
angle_sd^2 (x3))``, planar ``diag(angle_sd^2, position_sd^2 (x2))``);
``Q = J_d W J_d^T`` with ``J_d`` the step's Jacobian with respect to a
perturbation of the true wrench at both ends (one reading's whole effect,
once a step: ``[h^2 / 2, h] A`` to first order) and ``W`` the covariance of
the true wrench's noise ``S n`` (:func:`wrench_noise`), either::

    W = S_Q Sigma S_Q^T                                          (Q1, noise_at="start")
    W = S_hat Sigma S_hat^T + Delta,  Delta_ij = sum_l Sigma_l cov(s_il, s_jl)   (Q2, "estimate")

``Sigma`` the reading's noise, ``S_Q`` the ``S`` the run starts from
(``run(log, S0)``, ``reset(S0)``; the identity by default: a sensor's
nominal calibration), as the floor's first pass takes it
(:mod:`observers.batch._linearised_floor`), ``cov`` from the calibration block
of ``P``; plus ``q dt`` on each calibration entry, the random walk that the
NIS of the poses raises (``adapt_q``). (Q2) is the default on a model linear
in its channels (the plane, where a run starts from an ``S0`` far from ``S``
and (Q1) would mistune the filter by as much), (Q1) otherwise.

Why not the running estimate in 3D. ``Delta`` itself is derived, with no factor: for an error ``dS``
of ``S_hat`` and the noise ``n`` independent and Gaussian, ``E[(dS n)(dS
n)^T] = Delta``, what a second-order filter adds. What fails in 3D is the
term it is added to. Over the first seconds the torque readings are barely
excited, the errors in variables pull their gains in ``S_hat`` towards
zero, and ``Q``'s row of that torque falls with the gain squared: the
filter takes the yaw for noise-free, its ``P`` of ``S`` falls below its
error (the z-scores of ``S`` spread well above 1) and, ``S`` being
constant, that error stays. The factor 4 on ``Delta`` (issue 23's empirical
setting) drowned part of it. With the noise at ``S0`` the filter is the
floor's linear filter, online: its estimate ends a small fraction of the
floor's standard deviations from the floor's, as with ``Q`` at the true
``S``. An ``S0`` off by a gain scales ``Q`` and so ``S_std`` by that gain,
not the estimate (start from the sensor's factory calibration: the noise
model is then off by as much as it is). The figures, seed by seed:
docs/observers.md, ``tests/test_spatial_ekf.py``,
``benchmarks/online_floor_3d.py``.

Errors in variables (:mod:`observers.kalman._eiv`). On a model linear in its
channels the separate-bias filter runs beside the filter and gives ``J`` and
``B`` (:class:`observers.kalman.EivCompensation`, ``separate`` below). Otherwise
the floor's seeded copy (:mod:`observers.batch._linearised_floor`). The step's
Jacobian with respect to ``s`` holds the noisy reading, whose noise is also
the process noise of the same step; the estimate is attenuated by
``J^-1 B s``. Beside the filter runs a copy of its motion error driven by a
seeded draw of the reading's and the pose's noise (a motion-only filter
``P_m``, the copy ``eps``, its regressor ``Mn`` and ``b_n = sum Mn^T V^-1
nu``, :func:`observers.kalman.copy_predict`), whose mean is
``-B s``. The reported estimate is compensated to first order, with the
filter's own ``P`` of ``s`` for ``J^-1``::

    s_c = s + g P_ss (B s) = s - g P_ss b_n,      P_c = T P_ss T^T,  T = I + g P_ss B

(``g <= 1`` keeps the correction within a tenth of ``|s|`` while ``P`` is
still the prior, :func:`observers.kalman.correction_limit`); the filter runs
on its own estimate, ``eiv=False`` reports it as it is.
"""

from functools import lru_cache

import casadi as ca

from fmscal.plant.numerics import ChunkedSteps, StateLayout, build_once, ops

from fmscal.observers.core import matrix as mx, move
from ._eiv import _compensation, copy_predict
from ._filter import cholesky_solve, correction_limit, filter_layout, pack_lower, unpack_lower
from ._kalman import predict, reset, update
from ._noise_level import level_update

__all__ = ["error_step", "wrench_noise", "injection", "whole_error_step", "error_state_layout",
           "error_params_layout", "output_layout", "copy_layout", "eiv_copy"]

_CHUNK = 1000
_SEED = 20261124          # the errors-in-variables copy's draw: fixed, so that a run is repeatable


# --- the model's step, its Jacobians and Q ------------------------------------------------------------

def _predicted(model, x, w0, w1, h):
    """The nominal step (module docstring): :func:`observers.core.move` with the acceleration at the
    step's end taken at the state the start's acceleration, held over the step, reaches."""
    a0 = model.acceleration(x, w0)
    return move(model, x, a0, model.acceleration(move(model, x, a0, a0, h), w1), h)


def _sizes(model, offset):
    """``n`` (columns of ``[S | c]``), ``m`` (its entries), ``ne`` (the motion's error state) and ``d``."""
    n = model.n_w + int(bool(offset))
    m, ne = model.n_w * n, 2 * model.nv
    return n, m, ne, ne + m


@lru_cache(maxsize=8)
def error_step(model, offset):
    """The nominal step, its error-state Jacobians and ``Q`` (module docstring), as casadi Functions.

    Parameters
    ----------
    model : plant.Model
        A model with ``integrate`` and ``difference`` (the spatial one).
    offset : bool
        With the offset column ``c``.

    Returns
    -------
    jacobians : casadi.Function
        ``(xs, w0, w1, dt) -> (xs_next, F, J0, J1)``: ``xs = [x, s]`` the
        nominal (``nx + m``), ``F`` (d x d) the error state's transition,
        ``J0``, ``J1`` (d x n_w) its Jacobians with respect to the raw
        readings at the step's start and end.
    predict : casadi.Function
        ``(xs, w0, w1, dt, var_w, S_Q, P_S, at_estimate, q_dt) -> (xs_next, F, Q)``;
        ``S_Q`` the ``S`` (n_w x n_w, flat, row order) at which the reading's
        noise is carried into the wrench with ``at_estimate`` 0 (the run's start
        ``S0``), ``P_S`` the covariance of ``[S | c]`` (m x m, flat) that
        ``at_estimate`` 1 adds to the running estimate (:func:`wrench_noise`),
        ``q_dt`` the random walk's ``q dt``. Dense outputs.
    predict_sparse : casadi.Function
        The same with ``F`` and ``Q`` sparse, for :func:`whole_error_step` to inline.
    """
    n_w, nx = model.n_w, model.nx
    n, m, ne, d = _sizes(model, offset)
    xs = ca.SX.sym("xs", nx + m)
    w0, w1 = ca.SX.sym("w0", n_w), ca.SX.sym("w1", n_w)
    dt = ca.SX.sym("dt")
    var_w = ca.SX.sym("var_w", n_w)
    S_Q_flat = ca.SX.sym("S_Q", n_w * n_w)
    P_S_flat = ca.SX.sym("P_S", m * m)
    at_estimate = ca.SX.sym("at_estimate")
    q_dt = ca.SX.sym("q_dt")
    W = wrench_noise(xs[nx:], P_S_flat, var_w, S_Q_flat, at_estimate, n_w, n)
    xs_next, F, Q, J0, J1 = _error_step(model, offset, xs, w0, w1, dt, W, q_dt)
    inputs = [xs, w0, w1, dt, var_w, S_Q_flat, P_S_flat, at_estimate, q_dt]
    jacobians = ca.Function("ekf_error_jacobians", [xs, w0, w1, dt], [xs_next, ca.densify(F), J0, J1])
    predict = ca.Function("ekf_error_predict", inputs, [xs_next, ca.densify(F), ca.densify(Q)])
    sparse = ca.Function("ekf_error_predict_sparse", inputs, [xs_next, F, Q])
    return jacobians, predict, sparse


def wrench_noise(s, P_S_flat, var_w, S_Q_flat, at_estimate, n_w, n):
    """The covariance ``W`` of the true wrench's noise ``S n`` (module docstring, tuning rule), on casadi symbols.

    At the run's start (``at_estimate`` 0): ``W = S_Q Sigma S_Q^T`` (eq. Q1).
    At the running estimate (``at_estimate`` 1): ``W = S_hat Sigma S_hat^T +
    Delta``, ``Delta_ij = sum_l Sigma_l cov(s_il, s_jl)`` (eq. Q2), ``cov``
    from ``P_S``, the covariance of ``s = vec([S | c])`` (row order).

    Returns
    -------
    casadi.SX, shape (n_w, n_w)
    """
    m = n_w * n
    Sigma = ca.diag(var_w)
    S_Q = ca.reshape(S_Q_flat, n_w, n_w).T                                     # row order
    S_hat = ca.reshape(s, n, n_w).T[:, 0:n_w]
    P_S = ca.reshape(P_S_flat, m, m)                                          # symmetric: either order
    Delta = ca.vertcat(*[ca.horzcat(*[sum(var_w[l] * P_S[n * i + l, n * j + l] for l in range(n_w))
                                      for j in range(n_w)]) for i in range(n_w)])
    W_start = S_Q @ Sigma @ S_Q.T                                             # (Q1)
    W_estimate = S_hat @ Sigma @ S_hat.T + Delta                              # (Q2)
    return at_estimate * W_estimate + (1 - at_estimate) * W_start


def _error_step(model, offset, xs, w0, w1, dt, W, q_dt):
    """:func:`error_step`'s expressions on the given casadi symbols: ``xs_next``, ``F`` (sparse), ``Q``
    (sparse), ``J0``, ``J1``; ``W`` the covariance of the true wrench's noise (:func:`wrench_noise`). The
    whole compiled step (:func:`_step`) writes them on its own inputs, the payload among them."""
    n_w, nx = model.n_w, model.nx
    n, m, ne, d = _sizes(model, offset)
    e = ca.SX.sym("e", d)                                   # the error state at the step's start
    dw = ca.SX.sym("dw", n_w)                               # a perturbation of the true wrench at both ends
    d0, d1 = ca.SX.sym("d0", n_w), ca.SX.sym("d1", n_w)     # perturbations of the raw readings
    x, s = xs[0:nx], xs[nx:]
    S = ca.reshape(s + e[ne:], n, n_w).T                    # [S | c] (x) the error, row order
    a0, a1 = (ca.vertcat(w, 1) if offset else w for w in (w0 + d0, w1 + d1))
    moved = _predicted(model, model.state_integrate(x, e[0:ne]), S @ a0 + dw, S @ a1 + dw, dt)
    nominal = ca.vertcat(e, dw, d0, d1)
    at_nominal = lambda expr: ca.substitute(expr, nominal, ca.DM.zeros(d + 3 * n_w))     # noqa: E731
    x_next = at_nominal(moved)
    error = ca.vertcat(model.state_difference(x_next, moved), e[ne:])      # e_k+1 = moved (-) x_next
    F = at_nominal(ca.jacobian(error, e))
    J0, J1, J_d = (ca.densify(at_nominal(ca.jacobian(error, v))) for v in (d0, d1, dw))
    xs_next = ca.vertcat(x_next, s)
    # the true wrench's noise S n carried through the step, and the random walk on s (module docstring)
    Q = J_d @ W @ J_d.T + ca.diag(ca.vertcat(ca.DM.zeros(ne), q_dt * ca.DM.ones(m)))
    return xs_next, F, Q, J0, J1


@lru_cache(maxsize=8)
def injection(model, offset):
    """The injection of an error state into the nominal and the reset of ``P`` (module docstring).

    Returns
    -------
    dense : casadi.Function
        ``(xs, pose, e) -> (y, xs_new, G)``: ``y = difference(q(x), pose)``,
        the pose (log columns) in the error state (``nv``); ``xs_new = xs
        (+) e``; ``G`` (d x d) the Jacobian of the error after the
        injection with respect to the error before it, at ``e``.
    sparse : casadi.Function
        The same with ``G`` sparse (the identity but for the turn's 3x3 block).
    """
    nx = model.nx
    n, m, ne, d = _sizes(model, offset)
    xs = ca.SX.sym("xs", nx + m)
    pose = ca.SX.sym("pose", model.n_pose)
    e = ca.SX.sym("e", d)
    x = xs[0:nx]
    y = model.difference(model.configuration(x), model.pose_configuration(pose))
    x_new = model.state_integrate(x, e[0:ne])
    xs_new = ca.vertcat(x_new, xs[nx:] + e[ne:])
    before = ca.SX.sym("before", d)                         # the true error before the injection
    after = ca.vertcat(model.state_difference(x_new, model.state_integrate(x, before[0:ne])), before[ne:] - e[ne:])
    G = ca.substitute(ca.jacobian(after, before), before, e)
    return (ca.Function("ekf_error_injection", [xs, pose, e], [y, xs_new, ca.densify(G)]),
            ca.Function("ekf_error_injection_sparse", [xs, pose, e], [y, xs_new, G]))


@lru_cache(maxsize=8)
def _readable(model, offset):
    """:func:`error_step`'s ``jacobians`` and ``predict`` and :func:`injection` (dense), for the readable path.

    Evaluated by casadi's virtual machine, not built as C: the readable path
    is for reading and checking, and building these in C too would lengthen a
    fresh machine's first run (the compiled run builds its own whole step).
    """
    jacobians, predict, _ = error_step(model, offset)
    return jacobians, predict, injection(model, offset)[0]


# --- the errors-in-variables copy --------------------------------------------------------------------

def copy_layout(model):
    """The copy's packed state (module docstring): the motion-only filter's ``P_m`` (packed lower, ``2 nv``),
    the copy's error ``eps``, its regressor ``Mn`` (``2 nv x n_w^2``, row order) and ``b_n`` (``n_w^2``)."""
    ne, ms = 2 * model.nv, model.n_w ** 2
    return StateLayout(("Pm", ne * (ne + 1) // 2), ("eps", ne), ("Mn", ne * ms), ("bn", ms))


def _copy(model, c, Phi, Q, x0, x1, S, n0, n1, v, has, R, h):
    """One step of the copy (module docstring) on casadi symbols: ``Phi``, ``Q`` the filter's motion blocks,
    ``S`` the filter's ``S`` at the step's start, ``n0``, ``n1``, ``v`` the scaled draws."""
    nv, ne, ms = model.nv, 2 * model.nv, model.n_w ** 2
    o = ops(c)
    st = copy_layout(model).unpack(c, scalars=False)
    Pm = unpack_lower(o, st.Pm, ne)
    Pm_pred = Phi @ Pm @ Phi.T + Q                                     # P_m- = Phi P_m Phi^T + Q
    eps_pred, Mn_pred = copy_predict(model, x0, x1, S, n0, n1, h, Phi, st.eps, mx.as_matrix(o, st.Mn, ne, ms))
    nu = eps_pred[0:nv] + v                                            # the copy's innovation
    Hn = Mn_pred[0:nv, :]
    X = cholesky_solve(o, Pm_pred[0:nv, 0:nv] + ca.diag(R), ca.horzcat(Pm_pred[0:nv, :], Hn, nu), nv)
    K = has * X[:, 0:ne].T                                             # K = P_m- H^T V^-1
    bn = st.bn + has * (Hn.T @ X[:, ne + ms])                          # b_n += Hn^T V^-1 nu
    Pm_new = Pm_pred - K @ Pm_pred[0:nv, :]
    return copy_layout(model).pack(o, Pm=pack_lower(Pm_new, ne), eps=eps_pred - K @ nu,
                                   Mn=mx.flat(o, Mn_pred - K @ Hn), bn=bn)


def _compensated(model, P_ss, s, bn, n):
    """``s_c = s - g P_ss b_n`` (``b_n`` on the ``S`` columns of ``s``; module docstring), on casadi symbols."""
    n_w = model.n_w
    o = ops(s)
    idx = [n * i + j for i in range(n_w) for j in range(n_w)]
    corr = -(P_ss[:, idx] @ bn)                                        # P_ss (B s), B s = -b_n in expectation
    return s + correction_limit(o, s, corr, n_w * n) * corr


def _copy_step(model, offset, c, F, Q, x0, x1, s, draw, has, R, var_w, h):
    """:func:`eiv_copy`'s step on the given casadi symbols (``F``, ``Q`` the whole error state's): the draws
    scaled, ``S`` read from ``s``, then :func:`_copy`."""
    n_w, nv = model.n_w, model.nv
    n, _, ne, _ = _sizes(model, offset)
    k = n_w + nv
    sd = ca.sqrt(var_w)
    S = ca.reshape(s, n, n_w).T[:, 0:n_w]
    return _copy(model, c, F[0:ne, 0:ne], Q[0:ne, 0:ne], x0, x1, S, draw[0:n_w] * sd, draw[k:k + n_w] * sd,
                 draw[k + n_w:2 * k] * ca.sqrt(R), has, R, h)


@lru_cache(maxsize=8)
def eiv_copy(model, offset):
    """The copy's step and the compensation as casadi Functions (module docstring).

    Returns
    -------
    step : casadi.Function
        ``(c, F, Q, x0, x1, s, draw, has, R, var_w, h) -> c_next``; ``draw``
        the standard normal draws at the step's two samples (``[n, v]`` each,
        ``n_w + nv``), scaled here by ``sqrt(var_w)`` and ``sqrt(R)``.
    compensate : casadi.Function
        ``(P_ss, s, bn) -> s_c``.
    """
    n_w, nv, nx = model.n_w, model.nv, model.nx
    n, m, ne, d = _sizes(model, offset)
    k = n_w + nv
    c = ca.SX.sym("c", copy_layout(model).size)
    F, Q = ca.SX.sym("F", d, d), ca.SX.sym("Q", d, d)
    x0, x1 = ca.SX.sym("x0", nx), ca.SX.sym("x1", nx)
    s = ca.SX.sym("s", m)
    draw = ca.SX.sym("draw", 2 * k)
    has, h = ca.SX.sym("has"), ca.SX.sym("h")
    R, var_w = ca.SX.sym("R", nv), ca.SX.sym("var_w", n_w)
    c_next = _copy_step(model, offset, c, F, Q, x0, x1, s, draw, has, R, var_w, h)
    step = ca.Function("ekf_eiv_copy", [c, F, Q, x0, x1, s, draw, has, R, var_w, h], [ca.densify(c_next)])
    P_ss, bn = ca.SX.sym("P_ss", m, m), ca.SX.sym("bn", n_w * n_w)
    compensate = ca.Function("ekf_eiv_compensate", [P_ss, s, bn], [ca.densify(_compensated(model, P_ss, s, bn, n))])
    return step, compensate


# --- the whole step, compiled ----------------------------------------------------------------------

def output_layout(model, n):
    """The per-step outputs of :func:`whole_error_step`: the motion ``x`` (nx), the reported ``[S | c]``
    (``n_w n``, row order), the intensity ``q`` after the step (1/s), and ``sum(P)``, ``min(diag(P))`` for the
    health test."""
    return StateLayout(("x", model.nx), ("s", model.n_w * n), ("q", 1), ("P_sum", 1), ("P_min", 1))


def error_state_layout(model, n):
    """The packed state of :func:`whole_error_step`: the nominal ``xs = [x, s]`` (``nx + n_w n``), ``P``
    (packed lower, ``d = 2 nv + n_w n``), the level's ``q`` and NIS average, the time since the last pose,
    the errors-in-variables copy (:func:`copy_layout`) and, on a model linear in its channels, the
    separate-bias filter of the compensation (:func:`observers.kalman.filter_layout`)."""
    m, d = model.n_w * n, 2 * model.nv + model.n_w * n
    separate = [("eiv", filter_layout(model, n).size)] if model.linear_channels else []
    return StateLayout(("xs", model.nx + m), ("P", d * (d + 1) // 2), ("q", 1), ("eps_bar", 1), ("since", 1),
                       ("copy", copy_layout(model).size), *separate)


def error_params_layout(model):
    """Per-log parameters of :func:`whole_error_step`: the pose noise variances in the error state (``R``,
    ``nv``), the reading's noise variances, the ``S`` at which ``Q`` carries them (``S_Q``, the run's ``S0``,
    row order) and whether it carries them at the running estimate instead (``at_estimate``,
    :func:`wrench_noise`), the level's settings, whether it adapts and whether the estimate is compensated for
    the errors in variables (1 or 0 each), on a model linear in its channels the separate-bias filter's
    settings but the step (``eiv_q``: :func:`observers.kalman.compensation_layout`), and the payload and the
    gravity (:meth:`fmscal.plant.Model.payload_vector`, where the model's step reads them at run time)."""
    return StateLayout(("R", model.nv), ("var_w", model.n_w), ("S_Q", model.n_w ** 2), ("at_estimate", 1),
                       ("level", 7), ("adapt", 1), ("eiv", 1),
                       *([("eiv_q", model.n_pose + model.n_w)] if model.linear_channels else []),
                       *model.payload_parts())


def _step(model, z, u_prev, u, dt, p, draw, n, separate=False):
    """One sample of the whole error-state filter (module docstring), on casadi symbols; ``separate``: the
    errors-in-variables compensation by the separate-bias filter (a model linear in its channels) instead of
    the copy."""
    nv, n_w, nx = model.nv, model.n_w, model.nx
    offset = n == n_w + 1
    _, m, ne, d = _sizes(model, offset)
    L = error_state_layout(model, n)
    st, pp = L.unpack(z), error_params_layout(model).unpack(p, scalars=False)
    a, b = model.input_layout.unpack(u_prev, scalars=False), model.input_layout.unpack(u, scalars=False)
    has = u[0]
    o = ops(z)
    P = unpack_lower(o, st.P, d)
    dynamics = model.with_payload_symbols(getattr(pp, "payload", None))     # the payload and gravity, read from p
    # predict, eqs. (K1, K2) (observers.kalman._kalman): the nominal moves, the error stays zero
    W = wrench_noise(st.xs[nx:], ca.vec(P[ne:, ne:]), pp.var_w, pp.S_Q, pp.at_estimate, n_w, n)
    xs_pred, F, Q, _, _ = _error_step(dynamics, offset, st.xs, a.w_hat, b.w_hat, dt, W, st.q * dt)
    e_pred, P_pred = predict(ca.DM.zeros(d), P, F, Q)
    # update with the pose in the error state (H = [I 0]), eqs. (K3-K7); no pose: the pose the nominal shows, K = 0
    pose = has * b.pose + (1 - has) * model.measure(xs_pred[0:nx])
    inject = injection(model, offset)[1]
    y = inject(xs_pred, pose, ca.DM.zeros(d))[0]
    e, P_upd, nis = update(o, e_pred, P_pred, y, ca.diag(pp.R), list(range(nv)), has)
    _, xs_new, G = inject(xs_pred, pose, e)
    P_new = reset(P_upd, G)                                  # eq. (K8)
    P_packed = pack_lower(P_new, d)
    q, eps_bar = level_update(st.q, st.eps_bar, nis, st.since + dt, tuple(pp.level[i] for i in range(7)), nv)
    adapt = has * pp.adapt > 0.5
    q, eps_bar = ca.if_else(adapt, q, st.q), ca.if_else(adapt, eps_bar, st.eps_bar)
    since = (1 - has) * (st.since + dt)
    P_min = ca.mmin(ca.diag(P_new))
    P_sum = 2 * ca.sum1(P_packed) - ca.sum1(ca.diag(P_new))
    parts = dict(xs=xs_new, P=P_packed, q=q, eps_bar=eps_bar, since=since, copy=st.copy)
    if model.linear_channels:       # the separate-bias filter's state, carried unused without the compensation
        parts["eiv"] = st.eiv
    if separate:    # the separate-bias filter beside the filter (observers.kalman._eiv), its configuration
        u_eiv = ca.vertcat(has, model.configuration(st.xs[0:nx]), model.configuration(xs_new[0:nx]), b.pose,
                           a.w_hat, b.w_hat)
        parts["eiv"], s_c = _compensation(model, st.eiv, u_eiv, ca.vertcat(dt, pp.eiv_q), xs_new[nx:], n)
    else:           # the errors-in-variables copy and the compensated estimate
        compensate = eiv_copy(model, offset)[1]
        parts["copy"] = _copy_step(dynamics, offset, st.copy, F, Q, st.xs[0:nx], xs_pred[0:nx], st.xs[nx:], draw,
                                   has, pp.R, pp.var_w, dt)
        s_c = compensate(P_new[ne:, ne:], xs_new[nx:], copy_layout(model).unpack(parts["copy"], scalars=False).bn)
    s_out = pp.eiv * s_c + (1 - pp.eiv) * xs_new[nx:]
    out = output_layout(model, n).pack(o, x=xs_new[0:nx], s=s_out, q=q, P_sum=P_sum, P_min=P_min)
    return L.pack(o, **parts), out


_WHOLE = {}             # (model.compiled_key(), n, separate) -> ChunkedSteps


def whole_error_step(model, n, separate=False):
    """:func:`_step` run in compiled chunks (:class:`plant.numerics.ChunkedSteps`), built once for every
    payload and gravity of a model class (they are inputs, in ``p``).

    Run it with the inputs ``[U[:-1], U[1:], dt, p, draw]`` (``U`` the log's
    samples, :func:`observers.core.log_inputs`; ``dt``, ``p``
    (:func:`error_params_layout`) and the copy's standard normal draws at
    the step's two samples one row per step); its per-step outputs are
    :func:`observers.kalman.output_layout`'s. ``separate``: the compensation by the separate-bias filter
    (:func:`_step`; a model linear in its channels, with ``eiv``).
    """
    def build():
        size = model.input_layout.size
        z = ca.SX.sym("z", error_state_layout(model, n).size)
        u_prev, u = ca.SX.sym("u_prev", size), ca.SX.sym("u", size)
        dt = ca.SX.sym("dt")
        p = ca.SX.sym("p", error_params_layout(model).size)
        draw = ca.SX.sym("draw", 2 * (model.n_w + model.nv))
        z_next, out = _step(model, z, u_prev, u, dt, p, draw, n, separate)
        step = ca.Function(f"ekf_error_{model.name}{n}{'_separate' if separate else ''}_step",
                           [z, u_prev, u, dt, p, draw],
                           [ca.densify(z_next), ca.densify(out)])
        return ChunkedSteps(step, _CHUNK)

    return build_once(_WHOLE, (model.compiled_key(), n, bool(separate)), build, 8)
