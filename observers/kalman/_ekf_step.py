"""The EKF's model and its whole step as casadi functions (:class:`observers.AugmentedEKF`).

:func:`model` writes the transition of eq. (1) with ``w = S w_hat`` (from
:func:`plant.rk4_step`, the plant's single definition), its Jacobians and the
process noise ``Q`` of the tuning rule, once. The readable path calls it
each step and hands ``x_next``, ``F`` and ``Q`` to filterpy's
``ExtendedKalmanFilter``; the fast path inlines it in :func:`whole_step`:
the predict and the pose update in Joseph form (:mod:`observers.kalman._kalman`, the functions the
readable path calls too), the random-walk level
(:func:`observers.kalman.level_update`) and the errors-in-variables
filter beside it (:func:`observers.eiv._compensation`), one function run in
compiled chunks (:class:`plant.numerics.ChunkedSteps`). The two paths run the
same arithmetic in another order; they agree to rounding (``tests/test_ekf.py``).
"""

from functools import lru_cache

import casadi as ca

from fmscal.plant.numerics import ChunkedSteps, StateLayout, ops

from ._eiv import _compensation
from ._filter import filter_layout, pack_lower, unpack_lower
from ._kalman import predict, update
from ._noise_level import level_update

__all__ = ["model_step", "whole_step", "state_layout", "output_layout", "params_layout"]

_CHUNK = 1000


def params_layout(model):
    """Per-log parameters of :func:`whole_step`: the pose noise variances (``R``), the reading's noise
    variances, those the errors-in-variables filter holds (:attr:`observers.kalman.EivCompensation.state`
    without its step), the level's settings (:attr:`observers.kalman.NoiseLevel.settings`) and
    whether it adapts (1 or 0)."""
    return StateLayout(("R", model.n_pose), ("var_w", model.n_w), ("eiv_q", model.n_pose + model.n_w),
                       ("level", 7), ("adapt", 1))


def output_layout(model, n):
    """The per-step outputs of :func:`whole_step`: the motion ``x`` (nx), the reported ``[S | c]`` (``n_w n``,
    row order), the intensity ``q`` after the step (1/s), and ``sum(P)``, ``min(diag(P))`` for the health test."""
    return StateLayout(("x", model.nx), ("s", model.n_w * n), ("q", 1), ("P_sum", 1), ("P_min", 1))


def state_layout(model, n, eiv):
    """The packed state of :func:`whole_step`: ``x`` (``d = nx + n_w n``), ``P`` (packed lower), the level's
    ``q`` and NIS average, the time since the last pose, and the errors-in-variables filter's state."""
    d = model.nx + model.n_w * n
    parts = [("x", d), ("P", d * (d + 1) // 2), ("q", 1), ("eps_bar", 1), ("since", 1)]
    return StateLayout(*parts, *([("eiv", filter_layout(model, n).size)] if eiv else []))


@lru_cache(maxsize=8)
def model_step(model, offset):
    """The step of the model's dynamics with ``w = S w_hat``, its Jacobians and ``Q`` (``AugmentedEKF`` docstring).

    The motion is :meth:`fmscal.plant.Model.rk4_step` (eq. (1) in the plane,
    the plant's single definition), the raw reading linear over the step.

    Returns
    -------
    jacobians : casadi.Function
        ``(xs, w0, w1, dt) -> (x_next, F, J0, J1)``.
    predict : casadi.Function
        ``(xs, w0, w1, dt, var_w, P_S, q_dt) -> (x_next, F, Q)``; ``P_S`` the
        covariance of ``[S | c]`` (flat, symmetric), ``q_dt`` the random walk's
        ``q dt``. Dense outputs (for buffers, column-major).
    predict_sparse : casadi.Function
        The same with ``F`` and ``Q`` sparse, for :func:`whole_step` to inline.
    """
    n_w, nx = model.n_w, model.nx
    n = n_w + 1 if offset else n_w
    m = n_w * n
    dim = nx + m
    xs = ca.SX.sym("xs", dim)
    w0 = ca.SX.sym("w0", n_w)
    w1 = ca.SX.sym("w1", n_w)
    dt = ca.SX.sym("dt")
    S = ca.reshape(xs[nx:dim], n, n_w).T                # [S | c], row order
    a0, a1 = (ca.vertcat(w, 1) if offset else w for w in (w0, w1))
    d0, d1 = ca.SX.sym("d0", n_w), ca.SX.sym("d1", n_w)     # a perturbation of the true wrench, at 0
    d = ca.vertcat(d0, d1)
    x_d = model.rk4_step(xs[0:nx], S @ a0 + d0, S @ (a0 + a1) / 2 + (d0 + d1) / 2, S @ a1 + d1, dt)
    x_next = ca.substitute(x_d, d, ca.DM.zeros(2 * n_w))
    f = ca.vertcat(x_next, xs[nx:dim])
    F = ca.jacobian(f, xs)
    J0 = ca.densify(ca.jacobian(f, w0))
    J1 = ca.densify(ca.jacobian(f, w1))
    var_w = ca.SX.sym("var_w", n_w)                     # wrench noise variances
    P_S_flat = ca.SX.sym("P_S", m * m)
    P_S = ca.reshape(P_S_flat, m, m)                    # covariance of [S | c] (symmetric: either order)
    q_dt = ca.SX.sym("q_dt")                            # q_S dt
    # the true wrench's noise S n, with S uncertain: E[S Sigma S^T] = S_hat Sigma S_hat^T + Delta,
    # Delta_ij = sum_l Sigma_l cov(s_il, s_jl), carried through the step as the wrench itself is:
    # J_d, the step's Jacobian with respect to the true wrench at both ends (one reading's whole
    # effect, once a step), so that J_d S_hat = J_0 + J_1 of the motion
    W = S[:, 0:n_w] @ ca.diag(var_w) @ S[:, 0:n_w].T
    for i in range(n_w):
        for j in range(n_w):
            W[i, j] += sum(var_w[l] * P_S[n * i + l, n * j + l] for l in range(n_w))
    J_d = ca.substitute(ca.jacobian(x_d, d0) + ca.jacobian(x_d, d1), d, ca.DM.zeros(2 * n_w))
    Q = (ca.diagcat(J_d @ W @ J_d.T, ca.SX(m, m))
         + ca.diag(ca.vertcat(ca.DM.zeros(nx), q_dt * ca.DM.ones(m))))
    jacobians = ca.Function("ekf_jacobians", [xs, w0, w1, dt], [f, ca.densify(F), J0, J1])
    inputs = [xs, w0, w1, dt, var_w, P_S_flat, q_dt]
    predict = ca.Function("ekf_predict", inputs, [f, ca.densify(F), ca.densify(Q)])
    sparse = ca.Function("ekf_predict_sparse", inputs, [f, F, Q])
    return jacobians, predict, sparse


def _step(model, z, u_prev, u, dt, p, n, eiv):
    """One sample of the whole filter (module docstring; the motion of the model), on casadi symbols.

    ``z`` is packed by :func:`state_layout`, ``u_prev`` and ``u`` are the
    samples at the step's ends (:attr:`fmscal.plant.Model.input_layout`), ``dt`` the
    step (s), ``p`` the parameters (:func:`params_layout`). Returns ``z`` after the
    sample and the outputs (:func:`output_layout`).
    """
    nx, n_w = model.nx, model.n_w
    d = nx + n_w * n
    L = state_layout(model, n, eiv)
    st, pp = L.unpack(z), params_layout(model).unpack(p, scalars=False)
    a, b = model.input_layout.unpack(u_prev, scalars=False), model.input_layout.unpack(u, scalars=False)
    has = u[0]
    o = ops(z)
    pose = list(model.q_index)                            # the pose is the configuration (H selects it)
    P = unpack_lower(o, st.P, d)
    # predict, eqs. (K1, K2) (observers.kalman._kalman)
    x_next, F, Q = model_step(model, n == n_w + 1)[2](st.x, a.w_hat, b.w_hat, dt, pp.var_w, ca.vec(P[nx:, nx:]),
                                                      st.q * dt)
    x_pred, P_pred = predict(x_next, P, F, Q)
    # update with the pose, eqs. (K3-K7); no pose: K = 0 leaves both as they are
    y = b.pose - x_pred[pose]                             # the pose is the configuration (an angle: additive)
    x_new, P_new, nis = update(o, x_pred, P_pred, y, ca.diag(pp.R), pose, has)
    P_packed = pack_lower(P_new, d)
    # the random-walk level, at each pose
    q, eps_bar = level_update(st.q, st.eps_bar, nis, st.since + dt, tuple(pp.level[i] for i in range(7)))
    adapt = has * pp.adapt > 0.5
    q, eps_bar = ca.if_else(adapt, q, st.q), ca.if_else(adapt, eps_bar, st.eps_bar)
    since = (1 - has) * (st.since + dt)
    s = x_new[nx:]
    parts = dict(x=x_new, P=P_packed, q=q, eps_bar=eps_bar, since=since)
    if eiv:     # the errors-in-variables compensation, with the filter's configuration
        u_eiv = ca.vertcat(has, model.configuration(st.x), model.configuration(x_new), b.pose, a.w_hat, b.w_hat)
        parts["eiv"], s = _compensation(model, st.eiv, u_eiv, ca.vertcat(dt, pp.eiv_q), s, n)
    P_min = P_new[0, 0]
    for i in range(1, d):
        P_min = ca.fmin(P_min, P_new[i, i])
    P_sum = 2 * ca.sum1(P_packed) - ca.sum1(ca.diag(P_new))
    out = output_layout(model, n).pack(o, x=x_new[:nx], s=s, q=q, P_sum=P_sum, P_min=P_min)
    return L.pack(o, **parts), out


@lru_cache(maxsize=8)
def whole_step(model, n, eiv):
    """:func:`_step` for one model, run in compiled chunks (:class:`plant.numerics.ChunkedSteps`).

    Run it with the inputs ``[U[:-1], U[1:], dt, p]`` (``U`` the log's
    samples, :func:`observers.core.log_inputs`; ``dt`` and ``p`` one row per step).
    """
    size = model.input_layout.size
    z = ca.SX.sym("z", state_layout(model, n, eiv).size)
    u_prev = ca.SX.sym("u_prev", size)
    u = ca.SX.sym("u", size)
    dt = ca.SX.sym("dt")
    p = ca.SX.sym("p", params_layout(model).size)
    z_next, out = _step(model, z, u_prev, u, dt, p, n, eiv)
    step = ca.Function(f"ekf_{model.name}{n}{'' if eiv else '_plain'}_step", [z, u_prev, u, dt, p],
                       ca.cse([ca.densify(z_next), ca.densify(out)]))     # each repeated expression once
    return ChunkedSteps(step, _CHUNK, keep_states=False)
