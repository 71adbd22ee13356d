"""The EKF's model and its whole step as casadi functions (:class:`observers.AugmentedEKF`).

:func:`model` writes the transition of eq. (1) with ``w = S w_hat`` (from
:func:`plant.rk4_step`, the plant's single definition), its Jacobians and the
process noise ``Q`` of the tuning rule, once. The readable path calls it
each step and hands ``x_next``, ``F`` and ``Q`` to filterpy's
``ExtendedKalmanFilter``; the fast path inlines it in :func:`whole_step`:
the predict, the pose update in Joseph form, the random-walk level
(:func:`observers.noise_level.level_update`) and the errors-in-variables
filter beside it (:func:`observers.eiv._compensation`), one function run in
compiled chunks (:class:`plant._compile.ChunkedSteps`). The two paths run the
same arithmetic in another order; they agree to rounding (``tests/test_ekf.py``).
"""

from functools import lru_cache

import casadi as ca

from fmscal.plant._backend import ops

from fmscal.plant import rk4_step
from fmscal.plant._compile import ChunkedSteps

from .eiv import _compensation
from .max_likelihood import _cholesky_solve, _layout as _eiv_layout, _pack, _unpack
from .noise_level import level_update
from .state import INPUT, StateLayout

__all__ = ["model", "whole_step", "state_layout", "output_layout", "PARAMS"]

#: Measured states ``[theta, X, Y]`` (``H`` selects them).
POSE = [0, 2, 4]
#: Per-log parameters of :func:`whole_step`: the pose noise variances (``R``), the reading's noise
#: variances, those the errors-in-variables filter holds (:attr:`observers.eiv.EivCompensation.state`),
#: the level's settings (:attr:`observers.noise_level.NoiseLevel.settings`) and whether it adapts (1 or 0).
PARAMS = StateLayout(("R", 3), ("var_w", 3), ("eiv_q", 5), ("level", 7), ("adapt", 1))
_CHUNK = 1000


def output_layout(n):
    """The per-step outputs of :func:`whole_step`: the motion ``x`` (6), the reported ``[S | c]`` (``3n``, row
    order), the intensity ``q`` after the step (1/s), and ``sum(P)``, ``min(diag(P))`` for the health test."""
    return StateLayout(("x", 6), ("s", 3 * n), ("q", 1), ("P_sum", 1), ("P_min", 1))


def state_layout(n, eiv):
    """The packed state of :func:`whole_step`: ``x`` (``d = 6 + 3n``), ``P`` (packed lower), the level's
    ``q`` and NIS average, the time since the last pose, and the errors-in-variables filter's state."""
    d = 6 + 3 * n
    parts = [("x", d), ("P", d * (d + 1) // 2), ("q", 1), ("eps_bar", 1), ("since", 1)]
    return StateLayout(*parts, *([("eiv", _eiv_layout(n).size)] if eiv else []))


@lru_cache(maxsize=8)
def model(payload, offset):
    """The step of eq. (1) with ``w = S w_hat``, its Jacobians and ``Q`` (``AugmentedEKF`` docstring).

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
    n = 4 if offset else 3
    dim = 6 + 3 * n
    xs = ca.SX.sym("xs", dim)
    w0 = ca.SX.sym("w0", 3)
    w1 = ca.SX.sym("w1", 3)
    dt = ca.SX.sym("dt")
    S = ca.reshape(xs[6:dim], n, 3).T                   # [S | c], row order
    a0, a1 = (ca.vertcat(w, 1) if offset else w for w in (w0, w1))
    d0, d1 = ca.SX.sym("d0", 3), ca.SX.sym("d1", 3)     # a perturbation of the true wrench, at 0
    d = ca.vertcat(d0, d1)
    x_d = rk4_step(xs[0:6], S @ a0 + d0, S @ (a0 + a1) / 2 + (d0 + d1) / 2, S @ a1 + d1, dt, payload)
    x_next = ca.substitute(x_d, d, ca.DM.zeros(6))
    f = ca.vertcat(x_next, xs[6:dim])
    F = ca.jacobian(f, xs)
    J0 = ca.densify(ca.jacobian(f, w0))
    J1 = ca.densify(ca.jacobian(f, w1))
    var_w = ca.SX.sym("var_w", 3)                       # wrench noise variances
    P_S_flat = ca.SX.sym("P_S", (3 * n) ** 2)
    P_S = ca.reshape(P_S_flat, 3 * n, 3 * n)              # covariance of [S | c] (symmetric: either order)
    q_dt = ca.SX.sym("q_dt")                            # q_S dt
    # the true wrench's noise S n, with S uncertain: E[S Sigma S^T] = S_hat Sigma S_hat^T + Delta,
    # Delta_ij = sum_l Sigma_l cov(s_il, s_jl), carried through the step as the wrench itself is:
    # J_d, the step's Jacobian with respect to the true wrench at both ends (one reading's whole
    # effect, once a step), so that J_d S_hat = J_0 + J_1 of the motion
    W = S[:, 0:3] @ ca.diag(var_w) @ S[:, 0:3].T
    for i in range(3):
        for j in range(3):
            W[i, j] += sum(var_w[l] * P_S[n * i + l, n * j + l] for l in range(3))
    J_d = ca.substitute(ca.jacobian(x_d, d0) + ca.jacobian(x_d, d1), d, ca.DM.zeros(6))
    Q = (ca.diagcat(J_d @ W @ J_d.T, ca.SX(3 * n, 3 * n))
         + ca.diag(ca.vertcat(ca.DM.zeros(6), q_dt * ca.DM.ones(3 * n))))
    jacobians = ca.Function("ekf_jacobians", [xs, w0, w1, dt], [f, ca.densify(F), J0, J1])
    inputs = [xs, w0, w1, dt, var_w, P_S_flat, q_dt]
    predict = ca.Function("ekf_predict", inputs, [f, ca.densify(F), ca.densify(Q)])
    sparse = ca.Function("ekf_predict_sparse", inputs, [f, F, Q])
    return jacobians, predict, sparse


def _step(z, u_prev, u, dt, p, payload, n, eiv):
    """One sample of the whole filter (module docstring; the motion of eq. (1)), on casadi symbols.

    ``z`` is packed by :func:`state_layout`, ``u_prev`` and ``u`` are the
    samples at the step's ends (:data:`observers.state.INPUT`), ``dt`` the
    step (s), ``p`` the parameters (:data:`PARAMS`). Returns ``z`` after the
    sample and the outputs (:func:`output_layout`).
    """
    d = 6 + 3 * n
    L = state_layout(n, eiv)
    st, pp = L.unpack(z), PARAMS.unpack(p)
    a, b = INPUT.unpack(u_prev), INPUT.unpack(u)
    has = b.has_pose
    o = ops(z)
    P = _unpack(o, st.P, d)
    # predict (filterpy's predict: x = x_next, P = F P F^T + Q); only the lower triangle is kept
    x_pred, F, Q = model(payload, n == 4)[2](st.x, a.w_hat, b.w_hat, dt, pp.var_w, ca.vec(P[6:, 6:]), st.q * dt)
    P_pred = _unpack(o, _pack(F @ (P @ F.T) + Q, d), d)    # F (P F^T): P F^T's lower rows are P_pred's
    # update with the pose (filterpy's update, Joseph form); no pose: K = 0 leaves both as they are
    PHT = P_pred[:, POSE]
    R = ca.diag(pp.R)
    y = b.pose - x_pred[POSE]
    X = _cholesky_solve(o, P_pred[POSE, POSE] + R, ca.horzcat(PHT.T, y), 3)    # S^-1 [H P, y]
    K = has * X[:, :d].T
    nis = ca.dot(y, X[:, d])
    x_new = x_pred + K @ y
    A = P_pred - K @ PHT.T                                # (I - K H) P
    P_new = A - (A[:, POSE] - K @ R) @ K.T                 # (I - K H) P (I - K H)^T + K R K^T
    P_packed = _pack(P_new, d)
    # the random-walk level, at each pose
    q, eps_bar = level_update(st.q, st.eps_bar, nis, st.since + dt, tuple(pp.level[i] for i in range(7)))
    adapt = has * pp.adapt > 0.5
    q, eps_bar = ca.if_else(adapt, q, st.q), ca.if_else(adapt, eps_bar, st.eps_bar)
    since = (1 - has) * (st.since + dt)
    s = x_new[6:]
    parts = dict(x=x_new, P=P_packed, q=q, eps_bar=eps_bar, since=since)
    if eiv:     # the errors-in-variables compensation, with the filter's angles
        u_eiv = ca.vertcat(has, st.x[0], x_new[0], b.pose, a.w_hat, b.w_hat)
        parts["eiv"], s = _compensation(st.eiv, u_eiv, ca.vertcat(dt, pp.eiv_q), s, payload, n)
    P_min = P_new[0, 0]
    for i in range(1, d):
        P_min = ca.fmin(P_min, P_new[i, i])
    P_sum = 2 * ca.sum1(P_packed) - ca.sum1(ca.diag(P_new))
    out = output_layout(n).pack(o, x=x_new[:6], s=s, q=q, P_sum=P_sum, P_min=P_min)
    return L.pack(o, **parts), out


@lru_cache(maxsize=8)
def whole_step(payload, n, eiv):
    """:func:`_step` for one payload, run in compiled chunks (:class:`plant._compile.ChunkedSteps`).

    Run it with the inputs ``[U[:-1], U[1:], dt, p]`` (``U`` the log's
    samples, :func:`observers.base.log_inputs`; ``dt`` and ``p`` one row per step).
    """
    z = ca.SX.sym("z", state_layout(n, eiv).size)
    u_prev = ca.SX.sym("u_prev", INPUT.size)
    u = ca.SX.sym("u", INPUT.size)
    dt = ca.SX.sym("dt")
    p = ca.SX.sym("p", PARAMS.size)
    z_next, out = _step(z, u_prev, u, dt, p, payload, n, eiv)
    step = ca.Function(f"ekf{n}{'' if eiv else '_plain'}_step", [z, u_prev, u, dt, p],
                       [ca.densify(z_next), ca.densify(out)])
    return ChunkedSteps(step, _CHUNK)

