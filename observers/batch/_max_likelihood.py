"""Maximum-likelihood estimate of ``S`` from a whole log: the information floor.

The model is the log's own (eq. 1, :func:`plant.input_matrix`), with ``S``
constant and every noise white:

* the pose ``y_k = [theta, X, Y]`` is measured with white noise of variance
  ``R = diag(angle_sd^2, position_sd^2, position_sd^2)``;
* the raw reading is ``w_hat_k = w_hat_true(t_k) + n_k``, ``n_k`` white per
  sample with variance ``Sigma = diag(wrench_sd^2)``, the true reading linear
  between samples (a coloured noise, correlated over ``tau`` samples, as
  white noise of its power at low frequencies, ``diag(wrench_sd^2 tau)``: eq.
  (LF3) of :mod:`fmscal.observers.batch._linearised_floor`);
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
filter of :mod:`observers.adaptive._highgain`, with the Kalman gain)::

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
with the filter (six 6x6 matrices, :func:`fmscal.observers.kalman.filter_step`). Its covariance is the
sandwich ``(J - B)^-1 J (J - B)^-1``, the motion ``x + M s_hat``. ``Q``
depends on ``S`` itself, so the filter runs again with ``Q`` at the first
pass's estimate (``passes=2``).

The filter's pieces are :mod:`fmscal.observers.kalman._filter`, written for any
model linear in its channels (:attr:`fmscal.plant.Model.linear_channels`:
the planar model, and the tests' rail); the sizes all come from the model.
Two paths run the same step (:func:`_step`, written once for numpy and
casadi): a numpy loop (the readable path) and the step compiled with casadi
over chunks of 1000 samples (the fast path); they agree to rounding (1e-9
on the accumulated information; the estimate to rounding amplified by the
information's condition number).
"""

import time
from dataclasses import dataclass, field
from functools import lru_cache

import casadi as ca
import numpy as np

from fmscal.plant import Log
from fmscal.plant.io import estimate_noise
from fmscal.plant.numerics import ChunkedSteps, FmscalError, ops
from fmscal.plant.physics import Model, NoiseSpec, as_model, check_calibration

from fmscal.observers.core import calibration_uncertainty, initial_calibration, matrix as mx, progress_bar
from fmscal.observers.kalman import (POSE_SD_FLOOR, bias_matrix, cholesky_apply, correction_limit, filter_layout,
                                     filter_step, information_factor, initial_state, input_layout, params_layout,
                                     solve_information, unpack_lower)
from ._linearised_floor import fit_linearised

__all__ = ["MaximumLikelihoodFit", "fit_max_likelihood", "log_steps"]

_CHUNK = 1000            # samples per compiled call
_HISTORY_RADIUS = 10.0   # history only: |S_hat - S0| <= this times (|S0| + 1), Frobenius norms


@dataclass
class MaximumLikelihoodFit:
    """The maximum-likelihood estimate of ``[S | c]`` from a whole log.

    Attributes
    ----------
    S_aug : ndarray, shape (n_w, n)
        The estimate of ``[S | c]`` in ``w = S w_hat + c``; ``n`` = ``n_w``
        (3 in the plane), or ``n_w + 1`` with the offset.
    cov_aug : ndarray, shape (n_w n, n_w n)
        Its covariance, entries in row order, from the information the log
        held about them: ``(J - B)^-1 J (J - B)^-1`` (module docstring).
    S_history : ndarray, shape (N, n_w, n)
        The filtered estimate after each sample (the data up to it), for E
        against time; its last row is ``S_aug``. Defined from the first
        sample by a negligible pull towards ``S0`` (relative weight ``1e-10``
        of the information), corrected for the errors in variables to first
        order (the square of that correction, about 1e-6 relative, left
        out), and held within ``10 (|S0| + 1)`` of ``S0`` (Frobenius norm of
        the ``S`` entries) over the first samples, where the information
        does not yet pin every entry and the estimate is ill-determined.
    x_history : ndarray, shape (N, nx)
        The filtered motion in the model's layout (planar ``[theta, theta',
        X, X', Y, Y']``, rad, rad/s, m, m/s) after each sample, with the
        estimate of that sample: filtered, not smoothed.
    noise : plant.NoiseSpec
        The noise model used.
    noise_estimated : bool
        True when ``noise`` was estimated from the log.
    passes : int
        Filter passes run; each after the first takes the process noise at
        the previous pass's ``S``.
    model : plant.Model
    information : ndarray, shape (n_w n, n_w n)
        ``J``, the information the last pass accumulated about ``[S | c]``
        (row order), as if the readings were exact.
    eiv_bias : ndarray, shape (n_w n, n_w n)
        ``B``, its part that the reading's own noise contributes (the
        errors in variables): the estimate solves ``(J - B) s = r``.
    wall_time : float
        Seconds of computation, all passes.
    undetermined : list of ndarray, shape (n_w + 1,)
        Directions of the augmented reading the log did not determine (a
        model without linear channels, with the offset:
        :func:`fmscal.observers.batch.undetermined_directions`);
        empty otherwise (a planar log that does not determine ``S`` is an error).
    warnings : list of str
        What to record to determine them, one line each.
    latency_step : dict or None
        The linearised engine's first pass (:func:`fmscal.observers.batch.fit_linearised`, eq. LF2): the
        further delay of the poses behind the readings that the fit's own likelihood prefers, ``{"step": s,
        "std": s}``, relative to the log as given; None from the exact filter or with one pass.
    """

    S_aug: np.ndarray
    cov_aug: np.ndarray
    S_history: np.ndarray
    x_history: np.ndarray
    noise: NoiseSpec
    noise_estimated: bool
    passes: int
    model: Model = None
    information: np.ndarray = None
    eiv_bias: np.ndarray = None
    wall_time: float = 0.0
    undetermined: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    latency_step: dict = None

    @property
    def offset(self):
        """True when the fit estimated the offset column ``c``."""
        return self.S_aug.shape[1] == self.S_aug.shape[0] + 1

    @property
    def payload(self):
        """The model's payload."""
        return self.model.payload

    @property
    def S_hat(self):
        """The estimate of ``S``, shape (n_w, n_w)."""
        return self.S_aug[:, :len(self.S_aug)].copy()

    @property
    def cov(self):
        """The covariance of the entries of ``[S | c]``, row by row (``cov_aug``: the name every result uses)."""
        return self.cov_aug

    @property
    def S_std(self):
        """One-sigma uncertainty of each entry of ``S``, shape (n_w, n_w)."""
        return calibration_uncertainty(self.S_aug, self.cov_aug, self.offset)[0]

    @property
    def b(self):
        """The sensor's offset ``b = -S^-1 c`` (N m, N), shape (n_w,); None without the offset."""
        return calibration_uncertainty(self.S_aug, self.cov_aug, self.offset)[1]

    @property
    def b_std(self):
        """One-sigma uncertainty of :attr:`b`, shape (n_w,); None without the offset."""
        return calibration_uncertainty(self.S_aug, self.cov_aug, self.offset)[2]


def log_steps(log, model):
    """Every step's input to the filter (:func:`fmscal.observers.kalman.input_layout`), shape (N - 1, size).

    The configuration in ``A(q)`` is the measured pose, interpolated between
    poses on a multi-rate log (as least squares takes it).
    """
    rows = log.has_pose
    q = np.column_stack([np.interp(log.t, log.t[rows], log.pose[rows, j]) for j in range(model.n_pose)])
    return np.column_stack([log.has_pose[1:], q[:-1], q[1:], np.nan_to_num(log.pose[1:]),
                            log.w_hat[:-1], log.w_hat[1:]])


def fit_max_likelihood(log, model, noise=None, offset=False, passes=2, S0=None, compiled=True, linearised=None):
    """The maximum-likelihood estimate of ``S`` (and the offset) from a whole log.

    Module docstring for the model and the filter: a Kalman filter on the
    motion with the exact discretisation of eq. (1), the reading's noise as
    process noise, the information about ``[S | c]`` accumulated with a flat
    prior, and the bias of the noisy reading in the regressor (errors in
    variables) removed.

    Parameters
    ----------
    log : plant.Log
        A log of the model's case, full-rate or multi-rate (samples without
        a pose only predict). For a pose stream that lags the sensor, pass
        ``log.shift_poses(latency)``, and ``noise`` measured on the log before the shift.
    model : plant.Model or plant.Payload
        The problem (a model with :attr:`fmscal.plant.Model.linear_channels`);
        a :class:`plant.Payload` stands for the planar model of it.
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
        (a third moves the noise model, and so the estimate, far less than
        the second did).
        Only the last pass carries the errors-in-variables moments (the
        others only set the next pass's noise model), at about twice the
        cost of each of the others.
    S0 : array_like, shape (n_w, n_w), optional
        Where the first pass evaluates the process noise, and where the
        history starts; default the identity (a sensor's nominal calibration).
    compiled : bool
        True (default): the step compiled by casadi; False: the same step in
        numpy, sample by sample (slow; for checks). Results agree to
        rounding (module docstring).
    linearised : bool, optional
        Which engine: None (default) as the model declares, the exact filter
        of this module on a model with
        :attr:`fmscal.plant.Model.linear_channels` and
        :func:`fmscal.observers.batch.fit_linearised` (linearised about the
        smoothed motion) on one without; True: the linearised engine on any
        model (on the planar one it agrees with the exact filter within
        what the two take differently: :mod:`fmscal.observers.batch._linearised_floor`);
        False: the exact filter, refused on a model without linear channels.

    Returns
    -------
    MaximumLikelihoodFit
        ``S_history`` and ``x_history`` are those of the last pass.

    Raises
    ------
    TypeError
        ``log`` not a :class:`plant.Log`, ``noise`` neither None nor a
        :class:`plant.NoiseSpec`.
    FmscalError
        No model, a log of another case, ``passes`` not a positive integer,
        ``S0`` not a finite ``n_w x n_w`` matrix, ``linearised=False`` on a
        model without linear channels, or a log that does not excite every
        entry of ``[S | c]`` (singular information).
    """
    model = as_model(model, "fit_max_likelihood")
    if not isinstance(log, Log):
        raise TypeError(f"log must be a plant.Log; got {type(log).__name__}")
    model.check_log(log, "the maximum-likelihood fit")
    if noise is not None:
        model.check_noise(noise)
    if isinstance(passes, bool) or not isinstance(passes, (int, np.integer)) or passes < 1:
        raise FmscalError(f"passes must be a positive integer; got {passes!r}")
    if linearised is None:
        linearised = not model.linear_channels
    elif not isinstance(linearised, (bool, np.bool_)):
        raise FmscalError(f"linearised must be None, True or False; got {linearised!r}")
    elif not linearised and not model.linear_channels:
        raise FmscalError(f"the exact maximum-likelihood filter needs a model linear in its channels; a "
                          f"{model.name} model is linearised (linearised=None or True)")
    start = time.perf_counter()
    n_w = model.n_w
    S0 = np.eye(n_w) if S0 is None else check_calibration(S0, "S0", max_cond=np.inf, size=n_w)
    noise_estimated = noise is None
    if noise_estimated:
        noise = estimate_noise(log)
    if linearised:
        fit = fit_linearised(log, model, noise, offset, int(passes), S0, compiled)
        return MaximumLikelihoodFit(noise=noise, noise_estimated=noise_estimated, passes=int(passes), model=model,
                                    wall_time=time.perf_counter() - start, **fit)
    n = n_w + int(bool(offset))
    s0 = initial_calibration(S0, offset)
    U = log_steps(log, model)
    pose_var = np.maximum(model.pose_sd(noise), POSE_SD_FLOOR) ** 2
    z0 = initial_state(model, log.pose[0], pose_var, n)
    var_w = np.square(noise.long_run_wrench_sd)        # coloured noise: eq. (LF3) of _linearised_floor
    S_noise = S0
    nx = model.nx
    with progress_bar(int(passes) * len(U), "max-likelihood") as bar:     # a long log in a terminal only
        for k in range(int(passes)):
            # the process noise at the current S: A(q) S Sigma S^T A(q)^T (eq. 1 in the plane)
            W = S_noise @ np.diag(var_w) @ S_noise.T
            p = params_layout(model, n).pack(None, h=log.dt, R=pose_var, W=W.ravel(), var_w=var_w, s0=s0)
            last = k == passes - 1       # the bias moments and the history only where the estimate is the result
            if compiled:
                z_end, Y = _run_compiled(z0, U, p, model, n, last, bar.update, last)
            else:
                z_end, Y = _run_numpy(z0, U, p, model, n, last)
            S_aug, cov_aug, J, B = _solve_information(z_end, model, n, var_w, log.name)
            S_noise = S_aug[:, :n_w]
    Y = np.vstack([np.concatenate([z0[:nx], s0]), Y])
    Y[-1, nx:] = S_aug.ravel()                          # the history ends at the estimate
    return MaximumLikelihoodFit(
        S_aug=S_aug, cov_aug=cov_aug, S_history=Y[:, nx:].reshape(-1, n_w, n), x_history=Y[:, :nx].copy(),
        noise=noise, noise_estimated=noise_estimated, passes=int(passes), model=model,
        information=J, eiv_bias=B, wall_time=time.perf_counter() - start)


def _step(z, u, p, model, n, eiv=True):
    """One sample of the filter (:func:`fmscal.observers.kalman.filter_step`) and the estimate so far.

    Parameters are those of :func:`fmscal.observers.kalman.filter_step`.

    Returns
    -------
    z_next : shape (size,)
    out : shape (nx + n_w n,)
        The motion ``x + M s_hat`` and ``s_hat`` after the sample.
    """
    o = ops(z, u, p)
    nx, n_w = model.nx, model.n_w
    m = n_w * n
    z_next = filter_step(model, z, u, p, n, eiv)
    st = filter_layout(model, n).unpack(z_next, scalars=False)
    pp = params_layout(model, n).unpack(p, scalars=False)
    J = unpack_lower(o, st.J, m)
    M = mx.as_matrix(o, st.M, nx, m)
    var_w, s0 = pp.var_w, pp.s0
    # the estimate so far (the final one is solved exactly, in numpy): the uncorrected
    # s_u = S0 + (J + lam I)^-1 (r - J S0), then s_u + (J + lam I)^-1 B s_u, the first-order
    # solution of (J - B) s = r, the correction limited (kalman.correction_limit) while the
    # information is still rank-deficient (the first samples)
    chol = information_factor(o, J, m)
    s_u = mx.col(s0) + cholesky_apply(o, chol, mx.col(st.r) - o.dot(J, mx.col(s0)), m)
    corr = (cholesky_apply(o, chol, o.dot(bias_matrix(o, st.beta, var_w, n_w, n), s_u), m) if eiv
            else 0.0 * s_u)
    s_hat = s_u + corr * correction_limit(o, s_u, corr, m)
    # and held within a radius of S0 while the information cannot place every entry yet
    s_entries = [n * i + j for i in range(n_w) for j in range(n_w)]
    step_size = o.sqrt(sum((s_hat[k, 0] - s0[k]) ** 2 for k in s_entries))
    radius = _HISTORY_RADIUS * (o.sqrt(sum(s0[k] * s0[k] for k in s_entries)) + 1.0)
    s_hat = mx.col(s0) + (s_hat - mx.col(s0)) / o.fmax(1.0, step_size / radius)
    x_hat = mx.col(st.x) + o.dot(M, s_hat)
    return z_next, o.vcat([mx.vec(x_hat), mx.vec(s_hat)])


def _solve_information(z, model, n, var_w, name):
    """``s_hat = (J - B)^-1 r`` and its covariance from the final state (numpy, no prior).

    ``J`` is the information, ``B`` the errors-in-variables bias
    (:func:`fmscal.observers.kalman.bias_matrix`); :func:`fmscal.observers.kalman.solve_information`.
    """
    L = filter_layout(model, n)
    o = ops(z)
    J = unpack_lower(o, z[L.slices["J"]], model.n_w * n)
    B = bias_matrix(o, z[L.slices["beta"]], var_w, model.n_w, n)
    S_aug, cov = solve_information(J, z[L.slices["r"]], B, model, n, name)
    return S_aug, cov, J, B


# --- the two paths ----------------------------------------------------------------------------

def _run_numpy(z0, U, p, model, n, eiv):
    """The step in numpy, sample by sample (the readable path)."""
    Y = np.empty((len(U), model.nx + model.n_w * n))
    z = z0
    for k in range(len(U)):
        z, Y[k] = _step(z, U[k], p, model, n, eiv)
    return z, Y


def _carried(model, n, eiv):
    """The size of the leading part of the state that a compiled pass carries: all of it with the
    errors-in-variables moments, else the filter's own ``x, P, M, J, r`` (the moments pass unchanged)."""
    L = filter_layout(model, n)
    return L.size if eiv else L.slices["r"].stop


@lru_cache(maxsize=8)
def _chunked_steps(model, n, eiv, history=True):
    """:func:`_step` run in compiled chunks of :data:`_CHUNK` samples (:class:`plant.numerics.ChunkedSteps`);
    ``history=False``: :func:`fmscal.observers.kalman.filter_step` alone (a pass whose history is not wanted).
    The state is the part :func:`_carried` names."""
    L = filter_layout(model, n)
    size = _carried(model, n, eiv)
    z = ca.SX.sym("z", size)
    z_full = ca.vertcat(z, ca.SX.zeros(L.size - size))       # moments that eiv=False does not read
    u = ca.SX.sym("u", input_layout(model).size)
    p = ca.SX.sym("p", params_layout(model, n).size)
    if history:
        z_next, out = _step(z_full, u, p, model, n, eiv)
        outputs = [ca.densify(z_next[:size]), ca.densify(out)]
    else:
        outputs = [ca.densify(filter_step(model, z_full, u, p, n, eiv)[:size])]
    outputs = ca.cse(outputs)                                 # one evaluation of each repeated expression
    name = f"max_likelihood_{model.name}{n}{'' if eiv else '_plain'}{'' if history else '_filter'}"
    step = ca.Function(f"{name}_step", [z, u, p], outputs)
    return ChunkedSteps(step, _CHUNK, keep_states=False)


def _run_compiled(z0, U, p, model, n, eiv, progress=None, history=True):
    """The step compiled, :data:`_CHUNK` samples per call; same numbers as :func:`_run_numpy`.

    Returns the last state and the history (None with ``history=False``).
    """
    steps = _chunked_steps(model, n, eiv, history)
    inputs = [U, np.broadcast_to(p, (len(U), len(p)))]
    size = _carried(model, n, eiv)
    z_end, Y = steps.run(z0[:size], inputs, outputs=True, states=False, progress=progress)
    return np.concatenate([z_end, z0[size:]]), (Y[0] if history else None)
