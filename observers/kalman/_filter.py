"""Filter pieces: the separate-bias Kalman filter on a model's motion, and its errors-in-variables moments.

What the floor (:mod:`fmscal.observers.batch._max_likelihood`) and the EKF's
errors-in-variables compensation (:mod:`fmscal.observers.kalman._eiv`) share, written
once for numpy and casadi (:func:`fmscal.plant.numerics.ops`) and for any
model with :attr:`fmscal.plant.Model.linear_channels` (the planar model, a
rail in the tests): the configuration moves additively, the pose is the
configuration, and the accelerations are ``a = A(q) [S | c] [w_hat; 1]``
(eq. 1 in the plane) with ``q`` taken from the measured poses, so that the
model is linear in the state and in ``s = vec([S | c])``.

Each velocity channel ``c`` (configuration entry ``q_index[c]``, velocity
``v_index[c]`` of the model's state) moves over a step ``h``, the reading
linear over it, by::

    p_{k+1} = p_k + h v_k + h^2 (2 a_k + a_{k+1}) / 6,    v_{k+1} = v_k + h (a_k + a_{k+1}) / 2

The filter (Friedland's separate-bias filter, the motion run as if ``s = 0``
and its sensitivity ``M = dx/ds``), one equation a line::

    x-  = Phi x                      (predict)
    P-  = Phi P Phi^T + Q
    M-  = Phi M + U
    e   = y - C x-                   (correct; none without a pose)
    V   = C P- C^T + R
    K   = P- C^T V^-1
    x   = x- + K e
    P   = P- - K C P-
    M   = M- - K C M-
    J  += (C M-)^T V^-1 (C M-)       (the information about s)
    r  += (C M-)^T V^-1 e

and the errors-in-variables moments ``Gamma`` and ``beta`` beside it, from
which ``B = E[D_n^T V^-1 D_n]`` (:func:`bias_matrix`) follows: the estimate
solves ``(J - B) s = r``. The derivation is in the module docstring of
:mod:`fmscal.observers.batch._max_likelihood`.
"""

import numpy as np

from fmscal.plant.numerics import FmscalError, StateLayout, is_symbolic, ops

from fmscal.observers.core import matrix as mx, position_increment, velocity_increment

__all__ = ["filter_layout", "input_layout", "params_layout", "initial_state", "filter_step", "bias_matrix",
           "information_factor", "correction_limit", "pack_lower", "unpack_lower", "cholesky", "cholesky_apply",
           "cholesky_solve", "spd_inverse", "solve_information", "V0_SD", "POSE_SD_FLOOR"]

#: Prior standard deviation of the initial velocities (rad/s, m/s); the first pose is the
#: prior of the initial position. A few samples of poses outweigh it.
V0_SD = 1.0
#: Floor on the pose noise standard deviations (rad, m), so that a noise-free log keeps a
#: well-conditioned filter.
POSE_SD_FLOOR = 1e-6
_REG_REL = 1e-10         # the pull towards the start: lam = _REG_REL trace(J) / m + _REG_ABS
_REG_ABS = 1e-12
_CORRECTION_LIMIT = 0.1  # the bias correction at most this fraction of |s_hat| (rank-deficient J)


def _check(model):
    if not model.linear_channels:
        raise FmscalError(f"the separate-bias filter needs a model linear in its channels (planar, or one of the "
                          f"tests' rails); got a {model.name} model")


def _pairs(n_w):
    """The pairs ``(a, b)``, ``b <= a``, of the reading's components: ``Gamma`` and ``beta`` are symmetric in them."""
    return [(a, b) for a in range(n_w) for b in range(a + 1)]


# --- layouts ------------------------------------------------------------------------------------

def filter_layout(model, n):
    """The filter's packed state for ``n`` columns of ``[S | c]`` (``m = n_w n`` unknowns).

    ``x`` (nx), ``P`` (nx x nx, packed lower), ``M`` (nx x m), ``J`` (m x m,
    packed lower), ``r`` (m), and the errors-in-variables moments: ``N``
    (nx x n_w), ``K`` (the last gain, nx x n_pose), ``Gam`` (one nx x nx
    matrix, row order, per pair ``(a, b)``, ``b <= a``), ``beta`` (n_w x n_w
    symmetric, packed lower).

    Returns
    -------
    fmscal.plant.numerics.StateLayout
    """
    _check(model)
    nx, n_w, m = model.nx, model.n_w, model.n_w * n
    pairs = len(_pairs(n_w))
    return StateLayout(("x", nx), ("P", nx * (nx + 1) // 2), ("M", nx * m), ("J", m * (m + 1) // 2), ("r", m),
                       ("N", nx * n_w), ("K", nx * model.n_pose), ("Gam", pairs * nx * nx), ("beta", pairs))


def input_layout(model):
    """One step's input: ``has_pose`` (at the step's end), the configuration at both ends (from the
    measured poses, interpolated between them), the pose at the end (zeros without one), the raw
    reading at both ends."""
    return StateLayout(("has_pose", 1), ("q0", model.nq), ("q1", model.nq), ("pose", model.n_pose),
                       ("w0", model.n_w), ("w1", model.n_w))


def params_layout(model, n):
    """The per-log parameters: the step ``h`` (s), the pose noise variances ``R`` (diagonal), the
    reading's noise in true-wrench units ``W = S Sigma S^T`` (row order), its variances ``Sigma``,
    and ``s0`` (the start of the history; :func:`filter_step` reads none)."""
    n_w = model.n_w
    return StateLayout(("h", 1), ("R", model.n_pose), ("W", n_w * n_w), ("var_w", n_w), ("s0", n_w * n))


def initial_state(model, pose, pose_var, n):
    """The filter at the first sample: the first pose, velocities with prior :data:`V0_SD`, no information.

    Parameters
    ----------
    model : plant.Model
    pose : ndarray, shape (n_pose,)
    pose_var : ndarray, shape (n_pose,)
        The pose noise variances.
    n : int
        Columns of ``[S | c]``.

    Returns
    -------
    ndarray, shape (filter_layout(model, n).size,)
    """
    L = filter_layout(model, n)
    z = np.zeros(L.size)
    z[L.slices["x"]] = model.rest_state(pose)
    P = np.zeros((model.nx, model.nx))
    for c in range(model.nv):
        P[model.q_index[c], model.q_index[c]] = pose_var[c]
        P[model.v_index[c], model.v_index[c]] = V0_SD ** 2
    z[L.slices["P"]] = pack_lower(P, model.nx)
    return z


# --- symmetric matrices and their Cholesky factor, in scalar operations (numpy and casadi alike) ----

def pack_lower(A, k):
    """Lower triangle of a symmetric ``k x k`` matrix, row by row (numpy or casadi)."""
    o = ops(A)
    return o.vcat([A[i, j] for i in range(k) for j in range(i + 1)])


def unpack_lower(o, v, k):
    """The symmetric ``k x k`` matrix from its packed lower triangle (numbers: one gather, the same entries)."""
    idx = lambda i, j: i * (i + 1) // 2 + j if j <= i else j * (j + 1) // 2 + i     # noqa: E731
    if not is_symbolic(v) and np.ndim(v) == 1:
        return np.asarray(v, dtype=float)[_lower_index(k)]
    return o.matrix([[v[idx(i, j)] for j in range(k)] for i in range(k)])


def _lower_index(k):
    """Where each entry of a symmetric ``k x k`` matrix sits in its packed lower triangle, shape (k, k)."""
    i, j = np.indices((k, k))
    low, high = np.minimum(i, j), np.maximum(i, j)
    return high * (high + 1) // 2 + low


def cholesky(o, A, k):
    """Lower Cholesky factor of a symmetric positive definite ``k x k`` ``A``, as lists of scalars.

    Written in scalar operations so that numpy and casadi run the same
    arithmetic; only the lower triangle of ``A`` is read.
    """
    Lc = [[None] * k for _ in range(k)]
    for j in range(k):
        Lc[j][j] = o.sqrt(A[j, j] - sum(Lc[j][q] * Lc[j][q] for q in range(j)))
        for i in range(j + 1, k):
            Lc[i][j] = (A[i, j] - sum(Lc[i][q] * Lc[j][q] for q in range(j))) / Lc[j][j]
    return Lc


def cholesky_apply(o, Lc, B, k):
    """``A^-1 B`` from the factor of :func:`cholesky`; ``B`` is ``k x cols``."""
    cols = B.shape[1]
    out = [[None] * cols for _ in range(k)]
    for c in range(cols):
        yv = [None] * k
        for i in range(k):
            yv[i] = (B[i, c] - sum(Lc[i][q] * yv[q] for q in range(i))) / Lc[i][i]
        for i in reversed(range(k)):
            out[i][c] = (yv[i] - sum(Lc[q][i] * out[q][c] for q in range(i + 1, k))) / Lc[i][i]
    return o.matrix(out)


def cholesky_solve(o, A, B, k):
    """``A^-1 B`` for a symmetric positive definite ``k x k`` ``A``."""
    return cholesky_apply(o, cholesky(o, A, k), B, k)


def spd_inverse(o, A, k):
    """``A^-1`` of a small symmetric positive definite ``k x k`` ``A``: ``L^-T L^-1`` (``L``: :func:`cholesky`).

    For a matrix that many columns are divided by (the innovation covariance
    of a few poses): a product with it costs no divisions, where a solve per
    column (:func:`cholesky_apply`) takes ``2 k``. Only the lower triangle of
    ``A`` is read; the result is symmetric.
    """
    Lc = cholesky(o, A, k)
    inv = [[None] * k for _ in range(k)]                  # L^-1, lower triangular, by forward substitution
    for j in range(k):
        inv[j][j] = 1.0 / Lc[j][j]
        for i in range(j + 1, k):
            inv[i][j] = -sum(Lc[i][q] * inv[q][j] for q in range(j, i)) / Lc[i][i]
    lower = [[sum(inv[q][i] * inv[q][j] for q in range(i, k)) for j in range(i + 1)] for i in range(k)]
    return o.matrix([[lower[max(i, j)][min(i, j)] for j in range(k)] for i in range(k)])


def information_factor(o, J, m):
    """Cholesky factor (:func:`cholesky`) of ``J + lam I``, ``lam`` a ``1e-10`` of ``J``'s mean diagonal.

    The information is rank-deficient over the first samples; the small
    ``lam`` (a pull towards the start, negligible once every entry is
    excited) keeps the estimate defined from the first sample.
    """
    return cholesky(o, J + information_pull(o, J, m) * mx.eye(o, m), m)


def information_pull(o, J, m):
    """``lam`` of :func:`information_factor`: ``1e-10`` of ``J``'s mean diagonal (and ``1e-12``)."""
    trace = sum(J[i, i] for i in range(m))
    return _REG_REL * trace / m + _REG_ABS


def correction_limit(o, s, corr, m):
    """The factor (<= 1) that keeps a bias correction ``corr`` within a tenth of ``|s|``.

    The correction is a first-order term, about 1e-3 of ``|s|`` once the
    log has excited every entry; the limit only acts over the first samples,
    where the information is still rank-deficient.
    """
    size_s = o.sqrt(sum(s[i, 0] * s[i, 0] for i in range(m)))
    size_c = o.sqrt(sum(corr[i, 0] * corr[i, 0] for i in range(m)))
    return 1.0 / o.fmax(1.0, size_c / (_CORRECTION_LIMIT * size_s + _REG_ABS))


# --- one step -----------------------------------------------------------------------------------

def _input_matrix(model, q):
    """``A(q)`` at a measured configuration (eq. (1)'s ``G(theta)`` in the plane), shape (nv, n_w)."""
    return model.input_matrix(model.state_from(q, [0.0] * model.nv))


def _regressor_rows(o, model, A, w_hat, n):
    """``d a / d s`` at one sample: ``A (I (x) [w_hat; 1]^T)``, shape (nv, n_w n), ``s`` in row order.

    ``a = A [S | c] w_aug``, so ``d a_c / d s_ij = A_ci w_aug_j``.
    """
    n_w = model.n_w
    w = [w_hat[j] for j in range(n_w)] + ([1.0] if n == n_w + 1 else [])
    return o.matrix([[A[c, i] * w[j] for i in range(n_w) for j in range(n)] for c in range(model.nv)])


def filter_step(model, z, u, p, n, eiv=True):
    """One sample of the separate-bias Kalman filter and its errors-in-variables moments (module docstring).

    Parameters
    ----------
    model : plant.Model
        A model with :attr:`fmscal.plant.Model.linear_channels`.
    z : ndarray or casadi.SX, shape (size,)
        Packed state at sample ``k`` (:func:`filter_layout`).
    u : ndarray or casadi.SX
        The step's input (:func:`input_layout`).
    p : ndarray or casadi.SX
        The parameters (:func:`params_layout`); ``s0`` is not read.
    n : int
        Columns of ``[S | c]``: ``n_w``, or ``n_w + 1`` with the offset.
    eiv : bool
        Propagate the moments of the errors-in-variables correction (False:
        they are carried unchanged; for a pass whose estimate only sets the
        next pass's noise model).

    Returns
    -------
    ndarray or casadi.SX, shape (size,)
        Packed state after the sample.
    """
    o = ops(z, u, p)
    nx, n_w, n_y, m = model.nx, model.n_w, model.n_pose, model.n_w * n
    pairs = _pairs(n_w)
    st = filter_layout(model, n).unpack(z, scalars=False)
    uu = input_layout(model).unpack(u, scalars=False)
    pp = params_layout(model, n).unpack(p, scalars=False)
    x = st.x
    P = unpack_lower(o, st.P, nx)
    M = mx.as_matrix(o, st.M, nx, m)
    J = unpack_lower(o, st.J, m)
    r = st.r
    Nz = mx.as_matrix(o, st.N, nx, n_w)
    K_last = mx.as_matrix(o, st.K, nx, n_y)
    gam, beta = st.Gam, st.beta
    has, h = u[0], p[0]
    W = mx.as_matrix(o, pp.W, n_w)
    channel = [model.channel(i) for i in range(nx)]
    is_q = [i in model.q_index for i in range(nx)]
    # prediction over the step: Phi moves each channel's configuration by h times its velocity
    Phi = o.matrix([[1.0 if i == j else (h if (is_q[i] and not is_q[j] and channel[i] == channel[j]) else 0.0)
                     for j in range(nx)] for i in range(nx)])
    x_pred = o.dot(Phi, mx.col(x))                                          # x- = Phi x
    # process noise: [h^2, h] [h^2, h]^T (x) A W A^T at the step's start (white; max_likelihood docstring)
    A0 = _input_matrix(model, uu.q0)
    A1 = _input_matrix(model, uu.q1)
    AWA = o.dot(o.dot(A0, W), A0.T)
    g = [h * h if is_q[i] else h for i in range(nx)]
    Q = o.matrix([[g[i] * g[j] * AWA[channel[i], channel[j]] for j in range(nx)] for i in range(nx)])
    P_pred = o.dot(o.dot(Phi, P), Phi.T) + Q                               # P- = Phi P Phi^T + Q
    # the regressor linear over the step: U = [h^2 (2 u_k + u_k+1) / 6; h (u_k + u_k+1) / 2] per channel
    R0 = _regressor_rows(o, model, A0, uu.w0, n)
    R1 = _regressor_rows(o, model, A1, uu.w1, n)
    U = o.matrix([[(position_increment(h, R0[channel[i], j], R1[channel[i], j]) if is_q[i]
                    else velocity_increment(h, R0[channel[i], j], R1[channel[i], j])) for j in range(m)]
                  for i in range(nx)])
    M_pred = o.dot(Phi, M) + U                                              # M- = Phi M + U
    # errors in variables: Gamma_(a, b) = E[filter error x (part of M's column b driven by the
    # reading's noise)], per unit S_a. and variance; its source is the noise n_k, which drives both
    # the step's process noise ([h^2, h] (x) A_k e_a) and the regressor (A (x) A_k e_b, plus
    # N e_b = (I - K C) (D (x) A_k e_b) already in M from the last step)
    w_p = [h * h if is_q[i] else h for i in range(nx)]
    w_a = [h * h / 3 if is_q[i] else h / 2 for i in range(nx)]
    gam_pred = []
    # (the pose at k carried -(h^2 / 6) eps_k: the last update put K (h^2 / 6) eps_k in the error)
    if eiv:
        PhiKA = o.dot(o.dot(Phi, K_last), A0)             # the pose's row k is channel k
        src_left = [[w_p[i] * A0[channel[i], a] - h * h / 6 * PhiKA[i, a] for i in range(nx)] for a in range(n_w)]
        PhiN = o.dot(Phi, Nz)
        src_right = [[PhiN[i, b] + w_a[i] * A0[channel[i], b] for i in range(nx)] for b in range(n_w)]
        for q, (a, b) in enumerate(pairs):
            Gm = mx.as_matrix(o, gam[nx * nx * q:nx * nx * (q + 1)], nx)
            source = o.matrix([[src_left[a][i] * src_right[b][j] for j in range(nx)] for i in range(nx)])
            gam_pred.append(o.dot(o.dot(Phi, Gm), Phi.T) + source)
    # correction with the pose (none without one: has = 0)
    pos = list(model.q_index)
    CP = P_pred[pos, :]                                   # C P-
    H = M_pred[pos, :]                                    # C M-
    e = mx.col(uu.pose) - x_pred[pos, :]                  # e = y - C x- (the filter run with s = 0)
    R = o.matrix([[pp.R[i] if i == j else 0.0 for j in range(n_y)] for i in range(n_y)])
    V = P_pred[pos, :][:, pos] + R                        # V = C P- C^T + R
    Vi = spd_inverse(o, V, n_y)                           # V^-1, then products with it (no division per column)
    Vi_CP, Vi_H, Vi_e = o.dot(Vi, CP), o.dot(Vi, H), o.dot(Vi, e)
    K = has * Vi_CP.T                                     # K = P- C^T V^-1 (zero without a pose)
    x_next = x_pred + o.dot(K, e)                         # x = x- + K e
    P_next = P_pred - o.dot(K, CP)                        # P = P- - K C P-
    M_next = M_pred - o.dot(K, H)                         # M = M- - K C M-
    J_next = J + has * o.dot(H.T, Vi_H)                   # J += H^T V^-1 H
    r_next = mx.col(r) + has * o.dot(H.T, Vi_e)           # r += H^T V^-1 e
    # the bias moments: beta_ab += trace(V^-1 C Gamma_ab C^T), plus the pose at k+1 itself
    # (its -(h^2 / 6) eps_k+1 against H's (h^2 / 6) A_k+1 n_k+1); Gamma <- (I - K C) Gamma (I - K C)^T
    AViA = o.dot(o.dot(A1.T, Vi), A1)                     # the pose's row k is channel k
    beta_next, gam_next = [], []
    if not eiv:
        beta_next, gam_next = [beta[q] for q in range(len(pairs))], [gam]
    for q, ((a, b), Gm) in enumerate(zip(pairs, gam_pred)):
        CGC = Gm[pos, :][:, pos]
        beta_next.append(beta[q] + has * (sum(Vi[i, j] * CGC[j, i] for i in range(n_y) for j in range(n_y))
                                          + (h * h / 6) ** 2 * AViA[a, b]))
        Gk = Gm - o.dot(K, Gm[pos, :])
        gam_next.append(mx.flat(o, Gk - o.dot(Gk[:, pos], K.T)))
    d_end = o.matrix([[(h * h / 6 if is_q[i] else h / 2) * A1[channel[i], b] for b in range(n_w)]
                      for i in range(nx)])
    N_next = d_end - o.dot(K, d_end[pos, :]) if eiv else Nz
    return o.vcat([mx.vec(x_next), pack_lower(P_next, nx), mx.flat(o, M_next), pack_lower(J_next, m),
                   mx.vec(r_next), mx.flat(o, N_next), mx.flat(o, K if eiv else K_last), o.vcat(gam_next),
                   o.vcat(beta_next)])


def bias_matrix(o, beta, var_w, n_w, n):
    """The errors-in-variables bias of the information, ``B`` with ``E[r - J s] = -B s``; shape (m, m).

    ``B_(i l),(a l') = delta_l l' Sigma_l beta_(a i)`` for entries ``s_il`` in row
    order, ``beta`` (``n_w x n_w``, symmetric) packed lower; the offset column
    (``l = n_w``, a constant 1 without noise) has none.
    """
    idx = lambda a, i: a * (a + 1) // 2 + i if i <= a else i * (i + 1) // 2 + a     # noqa: E731
    if not is_symbolic(beta, var_w) and np.ndim(beta) == 1:       # numbers: the same products, in one Kronecker
        weights = np.zeros(n)
        weights[:n_w] = np.asarray(var_w, dtype=float)[:n_w]
        return np.kron(np.asarray(beta, dtype=float)[_lower_index(n_w)].T, np.diag(weights))
    rows = []
    for i in range(n_w):
        for l in range(n):
            rows.append([beta[idx(a, i)] * var_w[l] if (l2 == l and l < n_w) else 0.0
                         for a in range(n_w) for l2 in range(n)])
    return o.matrix(rows)


def solve_information(J, r, B, model, n, name, singular="raise"):
    """``s_hat`` solving ``(J - B) s = r``, and its covariance ``(J - B)^-1 J (J - B)^-1``.

    Parameters
    ----------
    J : ndarray, shape (m, m)
        The information about ``s = vec([S | c])`` (row order).
    r : ndarray, shape (m,)
    B : ndarray, shape (m, m)
        The errors-in-variables bias (zeros for none).
    model : plant.Model
    n : int
        Columns of ``[S | c]``.
    name : str
        The log's name, for the message.
    singular : {"raise", "truncate"}
        On a singular information (scaled condition number above 1e12):
        raise, or solve on the determined directions only (the others left
        at zero and at an infinite variance, reported by the caller).

    Returns
    -------
    S_aug : ndarray, shape (n_w, n)
    cov : ndarray, shape (m, m)

    Raises
    ------
    FmscalError
        The information is singular and ``singular="raise"``: the log does
        not excite every entry.
    """
    n_w = model.n_w
    d = np.sqrt(np.maximum(np.diag(J), 1e-300))
    scaled = J / np.outer(d, d)                         # unit diagonal: a unit-free condition number
    Jc = (J - B) / np.outer(d, d)
    finite = bool(np.all(np.isfinite(J)) and np.all(np.isfinite(Jc)))
    if not finite or np.linalg.cond(scaled) > 1e12 or np.linalg.cond(Jc) > 1e12:
        if singular == "raise" or not finite:
            entries = {1: "S", 3: "all nine entries of S"}.get(n_w, f"all {n_w * n_w} entries of S")
            what = entries if n == n_w else f"{entries} and the offset"
            raise FmscalError(f"{name}: the log does not excite {what}; the information matrix is singular")
        lam, u = np.linalg.eigh((Jc + Jc.T) / 2)
        kept = lam > 1e-12 * lam.max()
        Jc_inv = (u[:, kept] / lam[kept]) @ u[:, kept].T
    else:
        Jc_inv = np.linalg.inv(Jc)
    s = (Jc_inv @ (r / d)) / d
    cov = (Jc_inv @ scaled @ Jc_inv.T) / np.outer(d, d)
    cov = (cov + cov.T) / 2
    return s.reshape(n_w, n), cov
