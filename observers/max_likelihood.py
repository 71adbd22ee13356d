"""Maximum-likelihood estimate of ``S`` from a whole log: the information floor.

The model is the log's own (eq. 1, :func:`plant.input_matrix`), with ``S``
constant and every noise white:

* the pose ``y_k = [theta, X, Y]`` is measured with white noise of variance
  ``R = diag(angle_sd^2, position_sd^2, position_sd^2)``;
* the raw reading is ``w_hat_k = w_hat_true(t_k) + n_k``, ``n_k`` white per
  sample with variance ``Sigma = diag(wrench_sd^2)``, the true reading linear
  between samples;
* the accelerations are ``a = G(theta) [S | c] [w_hat_true; 1]`` (eq. 1; the
  offset column ``c`` only with ``offset=True``), ``theta`` in ``G`` taken
  from the measured poses (interpolated between them on a multi-rate log, as
  least squares does), so that the model is linear in the state and in ``S``.

Exact discretisation. With the acceleration linear over a step ``h`` (the
reading at both ends of the step, as the observers take it), each channel
``[p, v]`` moves by::

    p_{k+1} = p_k + h v_k + h^2 (2 a_k + a_{k+1}) / 6,    v_{k+1} = v_k + h (a_k + a_{k+1}) / 2

so the reading noise ``eps_k = G(theta_k) S n_k`` enters two consecutive steps,
and a filter that took ``J_0 Sigma J_0^T + J_1 Sigma J_1^T`` per step would
see half the velocity random walk the noise actually drives (the velocity
error after ``N`` steps is ``h sum eps_k``, variance ``N h^2``, not
``N h^2 / 2``). The state ``x~_k = x_k + [h^2 / 6, h / 2] eps_k`` (the part of
the last step that ``n_k`` already moved) removes the correlation exactly::

    x~_{k+1} = Phi x~_k + U_k s - [h^2, h] eps_k                       (white)
    y_k      = C x~_k - (h^2 / 6) eps_k + v_k

``U_k`` is the regressor of ``s = vec([S | c])`` (row order) at both ends of
the step, from ``G(theta_k) [w_hat_k; 1]`` and ``G(theta_k+1)
[w_hat_k+1; 1]``. The process noise of the three channels is joint, ``[h^2,
h] [h^2, h]^T (x) G S Sigma S^T G^T``: the angular and translational
accelerations are driven by the same ``n``, and their cross-covariance is
kept. The one term the filter's noise model leaves out is ``(h^2 / 6) eps_k``
in the measurement, about ``1e-7`` of the pose noise variance in the
scenarios (``h^2 |eps| / 6 ~ 3e-8 m`` against ``1e-4 m``); the
errors-in-variables moments below do take it.

The filter. ``S`` is constant and enters linearly, with a flat (diffuse)
prior: the Kalman filter on ``[x, s]`` then splits exactly into a filter on
``x`` alone, run as if ``s = 0``, and a sensitivity ``M_k = d x_k / d s``
(Friedland's separate-bias filter; the same sensitivity as the Kreisselmeier
filter of :mod:`observers.highgain`, with the Kalman gain)::

    x-  = Phi x,   P- = Phi P Phi^T + Q_k,   M- = Phi M + U_k
    H   = C M-,    e = y - C x-,   V = C P- C^T + R,   K = P- C^T V^-1
    x   = x- + K e,    P = P- - K V K^T,    M = M- - K H
    J  += H^T V^-1 H,  r += H^T V^-1 e

``J^-1 r`` would be the maximum-likelihood estimate of ``s`` if the
regressor ``U_k`` were exact. It is not: it is built from the noisy reading,
whose noise also drives the motion's process noise, and that correlation
(errors in variables) biases ``J^-1 r`` towards zero, by a fraction that
grows with the reading's noise and with the filter's bandwidth (on
some seeds of ``random-S`` and ``noisy`` it doubled E or more, above what
least squares gives; an EKF that takes the reading as its input shares the
bias). The estimate
solves instead the bias-compensated
equations (the first-order equivalent of the errors-in-variables maximum
likelihood, Deming's regression for a known noise ratio)::

    (J - B) s_hat = r,      B = E[D_n^T V^-1 D_n]

with ``D_n`` the part of the batch design that the reading's noise makes;
``B_(i l),(a l) = Sigma_l beta_ai`` (entries ``s_il``; none for the offset
column), and ``beta`` (3x3) follows from the cross-moments ``Gamma_ai`` of
the filter's error with the noise-driven part of ``M``, propagated forward
with the filter (six 6x6 matrices, :func:`_filter_step`). Its covariance is the
sandwich ``(J - B)^-1 J (J - B)^-1``, the motion ``x + M s_hat``. ``Q``
depends on ``S`` itself, so the filter runs again with ``Q`` at the first
pass's estimate (``passes=2``).

Two paths run the same step (:func:`_step`, written once for numpy and
casadi): a numpy loop (the readable path) and the step compiled with casadi
over chunks of 1000 samples (the fast path); they agree to rounding (1e-9
on the accumulated information; the estimate to rounding amplified by the
information's condition number).
"""

import time
from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from fmscal.plant import Log, NoiseSpec, Payload, input_matrix
from fmscal.plant._backend import ops
from fmscal.plant._compile import ChunkedSteps
from fmscal.plant.errors import FmscalError
from fmscal.plant.noise import estimate_noise
from fmscal.plant.sensor import check_calibration

from . import _matrix as mx
from .progress import progress_bar
from .state import StateLayout
from .result import initial_calibration, offset_from_c, offset_std

__all__ = ["MaximumLikelihoodFit", "fit_max_likelihood", "V0_SD", "POSE_SD_FLOOR"]

#: Prior standard deviation of the initial velocities (rad/s, m/s); the first pose is the
#: prior of the initial position. A few samples of poses outweigh it.
V0_SD = 1.0
#: Floor on the pose noise standard deviations (rad, m), so that a noise-free log keeps a
#: well-conditioned filter.
POSE_SD_FLOOR = 1e-6
_CHUNK = 1000            # samples per compiled call
_REG_REL = 1e-10         # history only: S_hat_k = S0 + (J + lam I)^-1 (r - J S0), lam relative to trace(J)
_REG_ABS = 1e-12
_CORRECTION_LIMIT = 0.1  # history only: the bias correction at most this fraction of |s_hat|
_HISTORY_RADIUS = 10.0   # history only: |S_hat - S0| <= this times (|S0| + 1), Frobenius norms
_PAIRS = [(a, b) for a in range(3) for b in range(a + 1)]     # (a, i), i <= a: Gamma and beta, packed
_N_IN = 12               # per-step input: has_next, theta_k, theta_k+1, pose_k+1 (3), w_k (3), w_k+1 (3)


@dataclass
class MaximumLikelihoodFit:
    """The maximum-likelihood estimate of ``[S | c]`` from a whole log.

    Attributes
    ----------
    S_aug : ndarray, shape (3, n)
        The estimate of ``[S | c]`` in ``w = S w_hat + c``; ``n`` = 3, or 4
        with the offset.
    cov_aug : ndarray, shape (3n, 3n)
        Its covariance, entries in row order, from the information the log
        held about them: ``(J - B)^-1 J (J - B)^-1`` (module docstring).
    S_history : ndarray, shape (N, 3, n)
        The filtered estimate after each sample (the data up to it), for E
        against time; its last row is ``S_aug``. Defined from the first
        sample by a negligible pull towards ``S0`` (relative weight ``1e-10``
        of the information), corrected for the errors in variables to first
        order (the square of that correction, about 1e-6 relative, left
        out), and held within ``10 (|S0| + 1)`` of ``S0`` (Frobenius norm of
        the ``S`` entries) over the first samples, where the information
        does not yet pin every entry and the estimate is ill-determined.
    x_history : ndarray, shape (N, 6)
        The filtered motion ``[theta, theta', X, X', Y, Y']`` (rad, rad/s, m,
        m/s) after each sample, with the estimate of that sample: filtered,
        not smoothed.
    noise : plant.NoiseSpec
        The noise model used.
    noise_estimated : bool
        True when ``noise`` was estimated from the log.
    passes : int
        Filter passes run; each after the first takes the process noise at
        the previous pass's ``S``.
    payload : plant.Payload
    information : ndarray, shape (3n, 3n)
        ``J``, the information the last pass accumulated about ``[S | c]``
        (row order), as if the readings were exact.
    eiv_bias : ndarray, shape (3n, 3n)
        ``B``, its part that the reading's own noise contributes (the
        errors in variables): the estimate solves ``(J - B) s = r``.
    wall_time : float
        Seconds of computation, all passes.
    """

    S_aug: np.ndarray
    cov_aug: np.ndarray
    S_history: np.ndarray
    x_history: np.ndarray
    noise: NoiseSpec
    noise_estimated: bool
    passes: int
    payload: Payload = None
    information: np.ndarray = None
    eiv_bias: np.ndarray = None
    wall_time: float = 0.0

    @property
    def offset(self):
        """True when the fit estimated the offset column ``c``."""
        return self.S_aug.shape[1] == 4

    @property
    def S_hat(self):
        """The estimate of ``S``, shape (3, 3)."""
        return self.S_aug[:, :3].copy()

    @property
    def S_std(self):
        """One-sigma uncertainty of each entry of ``S``, shape (3, 3)."""
        n = self.S_aug.shape[1]
        return np.sqrt(np.maximum(np.diag(self.cov_aug), 0)).reshape(3, n)[:, :3]

    @property
    def b(self):
        """The sensor's offset ``b = -S^-1 c`` (N m, N), shape (3,); None without the offset."""
        return offset_from_c(self.S_hat, self.S_aug[:, 3]) if self.offset else None

    @property
    def b_std(self):
        """One-sigma uncertainty of :attr:`b`, shape (3,); None without the offset."""
        return offset_std(self.S_hat, self.b, self.cov_aug) if self.offset else None


def fit_max_likelihood(log, payload, noise=None, offset=False, passes=2, S0=None, compiled=True):
    """The maximum-likelihood estimate of ``S`` (and the offset) from a whole log.

    Module docstring for the model and the filter: a Kalman filter on the
    motion with the exact discretisation of eq. (1), the reading's noise as
    process noise, the information about ``[S | c]`` accumulated with a flat
    prior, and the bias of the noisy reading in the regressor (errors in
    variables) removed.

    Parameters
    ----------
    log : plant.Log
        Full-rate or multi-rate (samples without a pose only predict). For a
        pose stream that lags the sensor, pass ``log.shift_poses(latency)``.
    payload : plant.Payload
        The payload's known mass properties.
    noise : plant.NoiseSpec, optional
        Noise standard deviations of the log. None: estimated from the log
        (:func:`plant.estimate_noise`). Pose standard deviations are floored
        at :data:`POSE_SD_FLOOR`.
    offset : bool
        Also estimate the offset column ``c`` of ``w = S w_hat + c`` (the
        reading augmented by a constant 1); the fit reports ``b = -S^-1 c``.
    passes : int
        Filter passes, at least 1. The first takes the process noise at
        ``S0``, each further one at the previous estimate; two are enough
        (the second changes ``E`` by a few per cent, a third by far less).
        Only the last pass carries the errors-in-variables moments (the
        others only set the next pass's noise model), at about twice the
        cost of each of the others.
    S0 : array_like, shape (3, 3), optional
        Where the first pass evaluates the process noise, and where the
        history starts; default the identity (a sensor's nominal calibration).
    compiled : bool
        True (default): the step compiled by casadi; False: the same step in
        numpy, sample by sample (slow; for checks). Results agree to
        rounding (module docstring).

    Returns
    -------
    MaximumLikelihoodFit
        ``S_history`` and ``x_history`` are those of the last pass.

    Raises
    ------
    TypeError
        ``log`` not a :class:`plant.Log`, ``payload`` not a
        :class:`plant.Payload`, ``noise`` neither None nor a
        :class:`plant.NoiseSpec`.
    FmscalError
        ``passes`` not a positive integer, ``S0`` not a finite 3x3 matrix, or
        a log that does not excite every entry of ``[S | c]`` (singular
        information).
    """
    if not isinstance(log, Log):
        raise TypeError(f"log must be a plant.Log; got {type(log).__name__}")
    if not isinstance(payload, Payload):
        raise TypeError(f"payload must be a plant.Payload; got {type(payload).__name__}")
    if noise is not None and not isinstance(noise, NoiseSpec):
        raise TypeError(f"noise must be a plant.NoiseSpec or None; got {type(noise).__name__}")
    if isinstance(passes, bool) or not isinstance(passes, (int, np.integer)) or passes < 1:
        raise FmscalError(f"passes must be a positive integer; got {passes!r}")
    start = time.perf_counter()
    S0 = np.eye(3) if S0 is None else check_calibration(S0, "S0", max_cond=np.inf)
    noise_estimated = noise is None
    if noise_estimated:
        noise = estimate_noise(log)
    n = 4 if offset else 3
    s0 = initial_calibration(S0, offset)
    theta = np.interp(log.t, log.t[log.has_pose], log.pose[log.has_pose, 0])
    U = np.column_stack([log.has_pose[1:], theta[:-1], theta[1:], np.nan_to_num(log.pose[1:]),
                         log.w_hat[:-1], log.w_hat[1:]])
    pose_var = np.maximum(noise.pose_sd, POSE_SD_FLOOR) ** 2
    z0 = _initial_state(log.pose[0], pose_var, n)
    S_noise = S0
    with progress_bar(int(passes) * len(U), "max-likelihood") as bar:     # a long log in a terminal only
        for k in range(int(passes)):
            # the process noise at the current S: G(theta) S Sigma S^T G(theta)^T, eq. (1)
            W = S_noise @ np.diag(np.square(noise.wrench_sd)) @ S_noise.T
            var_w = np.square(noise.wrench_sd)
            p = np.concatenate([[log.dt, pose_var[0], pose_var[1]], W.ravel(), var_w, s0])
            # the bias moments only where the estimate is the result (the last pass)
            if compiled:     # the history only where it is the result (the last pass)
                z_end, Y = _run_compiled(z0, U, p, payload, n, k == passes - 1, bar.update, k == passes - 1)
            else:
                z_end, Y = _run_numpy(z0, U, p, payload, n, k == passes - 1)
            S_aug, cov_aug, J, B = _solve_information(z_end, n, var_w, log.name)
            S_noise = S_aug[:, :3]
    Y = np.vstack([np.concatenate([z0[:6], s0]), Y])
    Y[-1, 6:] = S_aug.ravel()                          # the history ends at the estimate
    return MaximumLikelihoodFit(
        S_aug=S_aug, cov_aug=cov_aug, S_history=Y[:, 6:].reshape(-1, 3, n), x_history=Y[:, :6].copy(),
        noise=noise, noise_estimated=noise_estimated, passes=int(passes), payload=payload,
        information=J, eiv_bias=B, wall_time=time.perf_counter() - start)


# --- the packed state -------------------------------------------------------------------------

def _layout(n):
    """The packed state for ``n`` columns of ``[S | c]`` (``m = 3 n`` unknowns), a :class:`observers.state.StateLayout`.

    x (6), P (6x6 packed lower, 21), M (6 x m), J (m x m packed lower), r (m), and the
    moments of the errors-in-variables correction (:func:`_filter_step`): N (6 x 3), K (the last
    gain, 6 x 3), Gamma (6 matrices 6 x 6, row order, for (a, i) with i <= a), beta (3 x 3
    symmetric, packed lower, 6)
    """
    m = 3 * n
    return StateLayout(("x", 6), ("P", 21), ("M", 6 * m), ("J", m * (m + 1) // 2), ("r", m),
                       ("N", 18), ("K", 18), ("Gam", 6 * 36), ("beta", 6))


def _initial_state(pose, pose_var, n):
    """The filter at the first sample: the first pose, velocities with prior :data:`V0_SD`, no information."""
    L = _layout(n)
    z = np.zeros(L.size)
    z[L.slices["x"]] = [pose[0], 0.0, pose[1], 0.0, pose[2], 0.0]
    P = np.diag([pose_var[0], V0_SD ** 2, pose_var[1], V0_SD ** 2, pose_var[1], V0_SD ** 2])
    z[L.slices["P"]] = _pack(P, 6)
    return z


def _pack(A, k):
    """Lower triangle of a symmetric ``k x k`` matrix, row by row (numpy or casadi)."""
    o = ops(A)
    return o.vcat([A[i, j] for i in range(k) for j in range(i + 1)])


def _unpack(o, v, k):
    """The symmetric ``k x k`` matrix from its packed lower triangle."""
    idx = lambda i, j: i * (i + 1) // 2 + j if j <= i else j * (j + 1) // 2 + i     # noqa: E731
    return o.matrix([[v[idx(i, j)] for j in range(k)] for i in range(k)])


def _cholesky(o, A, k):
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


def _cholesky_apply(o, Lc, B, k):
    """``A^-1 B`` from the factor of :func:`_cholesky`; ``B`` is ``k x cols``."""
    cols = B.shape[1]
    out = [[None] * cols for _ in range(k)]
    for c in range(cols):
        yv = [None] * k
        for i in range(k):
            yv[i] = (B[i, c] - sum(Lc[i][q] * yv[q] for q in range(i))) / Lc[i][i]
        for i in reversed(range(k)):
            out[i][c] = (yv[i] - sum(Lc[q][i] * out[q][c] for q in range(i + 1, k))) / Lc[i][i]
    return o.matrix(out)


def _cholesky_solve(o, A, B, k):
    """``A^-1 B`` for a symmetric positive definite ``k x k`` ``A``."""
    return _cholesky_apply(o, _cholesky(o, A, k), B, k)


# --- one step ---------------------------------------------------------------------------------

def _regressor_rows(o, theta, w_hat, payload, n):
    """``d a / d s`` at one sample: row ``c`` of ``G(theta) kron [w_hat; 1]^T``, shape (3, 3n).

    ``a = G(theta) [S | c] w_aug`` (eq. 1, :func:`plant.input_matrix`), so
    ``d a_c / d s_ij = G_ci w_aug_j`` with ``s`` in row order.
    """
    G = input_matrix(theta, payload)
    w = [w_hat[j] for j in range(3)] + ([1.0] if n == 4 else [])
    return o.matrix([[G[c, i] * w[j] for i in range(3) for j in range(n)] for c in range(3)])


def _step(z, u, p, payload, n, eiv=True):
    """One sample of the filter (:func:`_filter_step`) and the estimate so far, for the history.

    Parameters are those of :func:`_filter_step`.

    Returns
    -------
    z_next : shape (size,)
    out : shape (6 + 3n,)
        The motion ``x + M s_hat`` and ``s_hat`` after the sample.
    """
    o = ops(z, u, p)
    m, L = 3 * n, _layout(n)
    z_next = _filter_step(z, u, p, payload, n, eiv)
    st = L.unpack(z_next)
    J = _unpack(o, st.J, m)
    M = mx.as_matrix(o, st.M, 6, m)
    var_w, s0 = p[12:15], p[15:15 + m]
    # the estimate so far (the final one is solved exactly, in numpy): the uncorrected
    # s_u = S0 + (J + lam I)^-1 (r - J S0), then s_u + (J + lam I)^-1 B s_u, the first-order
    # solution of (J - B) s = r, the correction limited (:func:`_correction_limit`) while the
    # information is still rank-deficient (the first samples)
    chol = _information_factor(o, J, m)
    s_u = mx.col(s0) + _cholesky_apply(o, chol, mx.col(st.r) - o.dot(J, mx.col(s0)), m)
    corr = (_cholesky_apply(o, chol, o.dot(_bias_matrix(o, st.beta, var_w, n), s_u), m) if eiv
            else 0.0 * s_u)
    s_hat = s_u + corr * _correction_limit(o, s_u, corr, m)
    # and held within a radius of S0 while the information cannot place every entry yet
    s_entries = [n * i + j for i in range(3) for j in range(3)]
    step_size = o.sqrt(sum((s_hat[k, 0] - s0[k]) ** 2 for k in s_entries))
    radius = _HISTORY_RADIUS * (o.sqrt(sum(s0[k] * s0[k] for k in s_entries)) + 1.0)
    s_hat = mx.col(s0) + (s_hat - mx.col(s0)) / o.fmax(1.0, step_size / radius)
    x_hat = mx.col(st.x) + o.dot(M, s_hat)
    return z_next, o.vcat([mx.vec(x_hat), mx.vec(s_hat)])


def _information_factor(o, J, m):
    """Cholesky factor (:func:`_cholesky`) of ``J + lam I``, ``lam`` a ``1e-10`` of ``J``'s mean diagonal.

    The information is rank-deficient over the first samples; the small
    ``lam`` (a pull towards the start, negligible once every entry is
    excited) keeps the estimate defined from the first sample.
    """
    trace = sum(J[i, i] for i in range(m))
    return _cholesky(o, J + (_REG_REL * trace / m + _REG_ABS) * mx.eye(o, m), m)


def _correction_limit(o, s, corr, m):
    """The factor (<= 1) that keeps a bias correction ``corr`` within a tenth of ``|s|``.

    The correction is a first-order term, about 1e-3 of ``|s|`` once the
    log has excited every entry; the limit only acts over the first samples,
    where the information is still rank-deficient.
    """
    size_s = o.sqrt(sum(s[i, 0] * s[i, 0] for i in range(m)))
    size_c = o.sqrt(sum(corr[i, 0] * corr[i, 0] for i in range(m)))
    return 1.0 / o.fmax(1.0, size_c / (_CORRECTION_LIMIT * size_s + _REG_ABS))


def _filter_step(z, u, p, payload, n, eiv=True):
    """One sample of the separate-bias Kalman filter and its bias moments (module docstring).

    Parameters
    ----------
    z : ndarray or casadi.SX, shape (size,)
        Packed state at sample ``k`` (:func:`_layout`).
    u : ndarray or casadi.SX, shape (12,)
        ``[has_pose_k+1, theta_k, theta_k+1, pose_k+1 (3), w_hat_k (3), w_hat_k+1 (3)]``:
        ``theta`` the measured angle (interpolated between poses), the pose
        zeros where there is none.
    p : ndarray or casadi.SX, shape (15 + 3n,)
        ``[h, angle variance, position variance, W (3x3, row order), Sigma (3), s0 (3n)]``
        with ``W = S Sigma S^T`` the reading's noise in true-wrench units and
        ``Sigma`` the reading's noise variances.
    payload : plant.Payload
    n : int
        Columns of ``[S | c]``: 3, or 4 with the offset.
    eiv : bool
        Propagate the moments of the errors-in-variables correction (False:
        they are carried unchanged, and the history is uncorrected; for a
        pass whose estimate only sets the next pass's noise model).

    Returns
    -------
    z_next : shape (size,)
        Packed state after the sample.
    """
    o = ops(z, u, p)
    m, st = 3 * n, _layout(n).unpack(z)
    x = st.x
    P = _unpack(o, st.P, 6)
    M = mx.as_matrix(o, st.M, 6, m)
    J = _unpack(o, st.J, m)
    r = st.r
    Nz = mx.as_matrix(o, st.N, 6, 3)
    K_last = mx.as_matrix(o, st.K, 6, 3)
    gam = st.Gam
    beta = st.beta
    has, h = u[0], p[0]
    W = mx.as_matrix(o, p[3:12], 3)
    # prediction over the step: Phi = diag of [[1, h], [0, 1]] per channel theta, X, Y
    Phi = o.matrix([[1.0 if i == j else (h if (j == i + 1 and i % 2 == 0) else 0.0) for j in range(6)]
                    for i in range(6)])
    x_pred = o.dot(Phi, mx.col(x))
    # process noise: [h^2, h] [h^2, h]^T (x) G W G^T at the step's start (white, module docstring)
    G0 = input_matrix(u[1], payload)
    G1 = input_matrix(u[2], payload)
    A = o.dot(o.dot(G0, W), G0.T)
    g = [h * h, h]
    Q = o.matrix([[g[i % 2] * g[j % 2] * A[i // 2, j // 2] for j in range(6)] for i in range(6)])
    P_pred = o.dot(o.dot(Phi, P), Phi.T) + Q
    # the regressor linear over the step: U = [h^2 (2 u_k + u_k+1) / 6; h (u_k + u_k+1) / 2] per channel
    R0 = _regressor_rows(o, u[1], u[6:9], payload, n)
    R1 = _regressor_rows(o, u[2], u[9:12], payload, n)
    U = o.matrix([[(h * h * (2 * R0[i // 2, j] + R1[i // 2, j]) / 6 if i % 2 == 0
                    else h * (R0[i // 2, j] + R1[i // 2, j]) / 2) for j in range(m)] for i in range(6)])
    M_pred = o.dot(Phi, M) + U
    # errors in variables: Gamma_(a, i) = E[filter error x (part of M's column i driven by the
    # reading's noise)], per unit S_a. and variance; its source is the noise n_k, which drives both
    # the step's process noise ([h^2, h] (x) G_k e_a) and the regressor (A (x) G_k e_i, plus
    # N e_i = (I - K C) (D (x) G_k e_i) already in M from the last step)
    w_p = [h * h, h]
    w_a = [h * h / 3, h / 2]
    gam_pred = []
    # (the pose at k carried -(h^2 / 6) eps_k: the last update put K (h^2 / 6) eps_k in the error)
    # beta is symmetric (it is E[D_n^T V^-1 D_n] of the batch form, D_n the design's part
    # driven by the noise): the pairs i <= a are enough
    if eiv:
        PhiKG = o.dot(o.dot(Phi, K_last), G0)
        src_left = [[w_p[i % 2] * G0[i // 2, a] - h * h / 6 * PhiKG[i, a] for i in range(6)]
                    for a in range(3)]
        PhiN = o.dot(Phi, Nz)
        src_right = [[PhiN[i, b] + w_a[i % 2] * G0[i // 2, b] for i in range(6)] for b in range(3)]
        for q, (a, b) in enumerate(_PAIRS):
            Gm = mx.as_matrix(o, gam[36 * q:36 * (q + 1)], 6)
            source = o.matrix([[src_left[a][i] * src_right[b][j] for j in range(6)] for i in range(6)])
            gam_pred.append(o.dot(o.dot(Phi, Gm), Phi.T) + source)
    # correction with the pose (none without one: has = 0)
    pos = [0, 2, 4]
    CP = P_pred[pos, :]                                   # C P-, 3 x 6
    H = M_pred[pos, :]                                    # C M-, 3 x m
    e = mx.col(u[3:6]) - x_pred[pos, :]                   # innovation of the filter run with s = 0
    V = P_pred[pos, :][:, pos] + o.matrix([[p[1], 0.0, 0.0], [0.0, p[2], 0.0], [0.0, 0.0, p[2]]])
    rhs = o.matrix([[CP[i, j] for j in range(6)] + [H[i, j] for j in range(m)] + [e[i, 0]]
                    + [1.0 if i == j else 0.0 for j in range(3)] for i in range(3)])
    X = _cholesky_solve(o, V, rhs, 3)                     # V^-1 [C P-, H, e, I]
    Vi_CP, Vi_H, Vi_e, Vi = X[:, 0:6], X[:, 6:6 + m], X[:, 6 + m:7 + m], X[:, 7 + m:10 + m]
    K = has * Vi_CP.T                                     # Kalman gain, 6 x 3 (zero without a pose)
    x_next = x_pred + o.dot(K, e)
    P_next = P_pred - o.dot(K, CP)
    M_next = M_pred - o.dot(K, H)
    J_next = J + has * o.dot(H.T, Vi_H)
    r_next = mx.col(r) + has * o.dot(H.T, Vi_e)
    # the bias moments: beta_ab += trace(V^-1 C Gamma_ab C^T), plus the pose at k+1 itself
    # (its -(h^2 / 6) eps_k+1 against H's (h^2 / 6) G_k+1 n_k+1); Gamma <- (I - K C) Gamma (I - K C)^T
    GViG = o.dot(o.dot(G1.T, Vi), G1)
    beta_next, gam_next = [], []
    if not eiv:
        beta_next, gam_next = [beta[q] for q in range(len(_PAIRS))], [gam]
    for q, ((a, b), Gm) in enumerate(zip(_PAIRS, gam_pred)):
        CGC = Gm[pos, :][:, pos]
        beta_next.append(beta[q] + has * (sum(Vi[i, j] * CGC[j, i] for i in range(3) for j in range(3))
                                          + (h * h / 6) ** 2 * GViG[a, b]))
        Gk = Gm - o.dot(K, Gm[pos, :])
        gam_next.append(mx.flat(o, Gk - o.dot(Gk[:, pos], K.T)))
    d_end = o.matrix([[(h * h / 6 if i % 2 == 0 else h / 2) * G1[i // 2, b] for b in range(3)]
                      for i in range(6)])
    N_next = d_end - o.dot(K, d_end[pos, :]) if eiv else Nz
    z_next = o.vcat([mx.vec(x_next), _pack(P_next, 6), mx.flat(o, M_next), _pack(J_next, m), mx.vec(r_next),
                     mx.flat(o, N_next), mx.flat(o, K if eiv else K_last), o.vcat(gam_next),
                     o.vcat(beta_next)])
    return z_next


def _bias_matrix(o, beta, var_w, n):
    """The errors-in-variables bias of the information, ``B`` with ``E[r - J s] = -B s``; shape (3n, 3n).

    ``B_(i l),(a l') = delta_l l' Sigma_l beta_(a i)`` for entries ``s_il`` in row
    order, ``beta`` (3 x 3, symmetric) packed lower; the offset column
    (``l = 3``, a constant 1 without noise) has none.
    """
    idx = lambda a, i: a * (a + 1) // 2 + i if i <= a else i * (i + 1) // 2 + a     # noqa: E731
    rows = []
    for i in range(3):
        for l in range(n):
            rows.append([beta[idx(a, i)] * var_w[l] if (l2 == l and l < 3) else 0.0
                         for a in range(3) for l2 in range(n)])
    return o.matrix(rows)


def _solve_information(z, n, var_w, name):
    """``s_hat = (J - B)^-1 r`` and its covariance from the final state (numpy, no prior).

    ``J`` is the information, ``B`` the errors-in-variables bias
    (:func:`_bias_matrix`); the covariance is the sandwich
    ``(J - B)^-1 J (J - B)^-1``.

    Raises
    ------
    FmscalError
        The information is singular: the log does not excite every entry.
    """
    m, L = 3 * n, _layout(n)
    o = ops(z)
    J = _unpack(o, z[L.slices["J"]], m)
    r = z[L.slices["r"]]
    B = _bias_matrix(o, z[L.slices["beta"]], var_w, n)
    d = np.sqrt(np.maximum(np.diag(J), 1e-300))
    scaled = J / np.outer(d, d)                         # unit diagonal: a unit-free condition number
    Jc = (J - B) / np.outer(d, d)
    if not np.all(np.isfinite(J)) or np.linalg.cond(scaled) > 1e12 or np.linalg.cond(Jc) > 1e12:
        what = "all nine entries of S" if n == 3 else "all nine entries of S and the offset"
        raise FmscalError(f"{name}: the log does not excite {what}; the information matrix is singular")
    Jc_inv = np.linalg.inv(Jc)
    s = (Jc_inv @ (r / d)) / d
    cov = (Jc_inv @ scaled @ Jc_inv.T) / np.outer(d, d)
    cov = (cov + cov.T) / 2
    return s.reshape(3, n), cov, J, B


# --- the two paths ----------------------------------------------------------------------------

def _run_numpy(z0, U, p, payload, n, eiv):
    """The step in numpy, sample by sample (the readable path)."""
    Y = np.empty((len(U), 6 + 3 * n))
    z = z0
    for k in range(len(U)):
        z, Y[k] = _step(z, U[k], p, payload, n, eiv)
    return z, Y


@lru_cache(maxsize=8)
def _chunked_steps(payload, n, eiv, history=True):
    """:func:`_step` run in compiled chunks of :data:`_CHUNK` samples (:class:`plant._compile.ChunkedSteps`);
    ``history=False``: :func:`_filter_step` alone (a pass whose estimate history is not wanted)."""
    size = _layout(n).size
    z = ca.SX.sym("z", size)
    u = ca.SX.sym("u", _N_IN)
    p = ca.SX.sym("p", 15 + 3 * n)
    if history:
        z_next, out = _step(z, u, p, payload, n, eiv)
        outputs = [ca.densify(z_next), ca.densify(out)]
    else:
        outputs = [ca.densify(_filter_step(z, u, p, payload, n, eiv))]
    name = f"max_likelihood{n}{'' if eiv else '_plain'}{'' if history else '_filter'}"
    step = ca.Function(f"{name}_step", [z, u, p], outputs)
    return ChunkedSteps(step, _CHUNK)


def _run_compiled(z0, U, p, payload, n, eiv, progress=None, history=True):
    """The step compiled, :data:`_CHUNK` samples per call; same numbers as :func:`_run_numpy`.

    Returns the last state and the history (None with ``history=False``).
    """
    steps = _chunked_steps(payload, n, eiv, history)
    inputs = [U, np.broadcast_to(p, (len(U), len(p)))]
    if not history:
        return steps.run(z0, inputs, states=False, progress=progress), None
    z_end, (Y,) = steps.run(z0, inputs, outputs=True, states=False, progress=progress)
    return z_end, Y
