"""Augmented-state extended Kalman filter in the manner of Aghili (ICRA 2000)."""

import math
import time
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from fmscal.plant import NoiseSpec
from fmscal.plant.io import estimate_noise
from fmscal.plant.numerics import BufferedCall, FmscalError, as_bool, as_finite_array, as_positive_scalar, ops

from fmscal.observers.core import Estimate, Observer, log_inputs, progress_bar, start_velocity
from ._eiv import EivCompensation, beta_from_copy, error_variances
from ._error_state import (_SEED, _readable, _sizes, copy_layout, eiv_copy, error_params_layout, error_state_layout,
                           output_layout, whole_error_step)
from ._filter import bias_matrix, correction_limit, initial_state, pack_lower, unpack_lower
from ._kalman import predict, reset, update
from ._noise_level import DEFAULT_Q_START, DEFAULT_TOLERANCE, NoiseLevel

__all__ = ["AugmentedEKF", "FilterRun"]



class _CalibrationEKF(ExtendedKalmanFilter):
    """filterpy's EKF whose predict and update are :mod:`observers.kalman._kalman`'s (eqs. K1-K7).

    The compiled whole step calls the same two functions, so the two paths
    run one filter. ``x_next``, ``F`` and ``Q`` are set before every
    :meth:`predict` (the model's step, from one compiled call); ``x`` and
    ``P`` hold filterpy's state, ``R`` its pose noise, and an update leaves
    filterpy's ``y`` (the innovation), ``K`` and ``nis`` (eq. K7).
    """

    def __init__(self, dim_x, dim_z):
        super().__init__(dim_x=dim_x, dim_z=dim_z)
        self.x_next = np.zeros((dim_x, 1))
        self.nis = 0.0

    def predict(self, u=0):
        """Eqs. (K1, K2): ``x = x_next``, ``P = F P F^T + Q``."""
        self.x, self.P = predict(np.reshape(self.x_next, (-1, 1)), self.P, self.F, self.Q)
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()

    def update(self, y, pose):
        """Eqs. (K3-K7) with the innovation ``y`` (length ``dim_z``), ``H`` selecting the state's entries ``pose``."""
        self.y = np.reshape(y, (-1, 1))
        self.x, self.P, self.nis = update(ops(self.P), self.x, self.P, self.y, self.R, list(pose))
        self.x_post, self.P_post = self.x.copy(), self.P.copy()


@dataclass
class FilterRun:
    """The EKF's running state (:attr:`observers.RunData.state`): what one run holds.

    Attributes
    ----------
    kf : filterpy.kalman.ExtendedKalmanFilter
        The filter: ``x``, ``P``, ``R`` (filterpy's own).
    var_w : ndarray, shape (n_w,)
        The raw reading's noise variances this run uses.
    s_out : ndarray, shape (n_w n,)
        The reported ``[S | c]`` (compensated for the errors in variables).
    since_pose : float
        Seconds since the last pose.
    q_history : list of float
        The random walk's intensity after each sample, 1/s.
    xs : ndarray, shape (nx + n_w n,)
        The nominal ``[x, s]``: the motion (planar ``[theta, theta', X, X', Y, Y']``, spatial
        ``[p, q, v, omega]``) and ``vec([S | c])``, row order. ``kf.x`` is the error state ``e``
        (zero between steps) and ``kf.P`` its covariance (d x d).
    copy : ndarray, shape (copy_layout(model).size,)
        The errors-in-variables copy (:func:`observers.kalman.copy_layout`; unused where the model is
        linear in its channels).
    rng : numpy.random.Generator
        The copy's draws, seeded at the run's start.
    draw : ndarray, shape (n_w + nv,)
        The copy's standard normal draw at the last sample (reading, pose).
    S_Q : ndarray, shape (n_w, n_w)
        The ``S`` at which ``Q`` carries the reading's noise with ``noise_at="start"``: the run's ``S0``.
    """

    kf: object
    var_w: np.ndarray
    s_out: np.ndarray
    since_pose: float
    q_history: list
    xs: np.ndarray = None
    copy: np.ndarray = None
    rng: object = None
    draw: np.ndarray = None
    S_Q: np.ndarray = None


class AugmentedEKF(Observer):
    """Extended Kalman filter on the motion and the calibration, on an error state: one filter for every model.

    A reconstruction of [3]: the calibration entries are states (random
    walks), the motion follows the model's dynamics (eq. (1) in the plane)
    with ``w = S w_hat``, and the measurement is the pose. The filter holds a
    nominal ``[x, s]`` and, in filterpy's ``x``, the error state ``e = [dq,
    dnu, ds]`` (:mod:`observers.kalman._error_state`): in the plane the
    attitude is an angle, its error the angle's difference and the injection
    an addition; in 3D a unit quaternion, its error a turn. casadi derives
    ``F``, the noise Jacobians and the reset from the model's single
    definition. Predict and update (eqs. K1-K8, the update in Joseph form so
    that ``P`` stays symmetric positive definite) are written once
    (:mod:`observers.kalman._kalman`), and two paths call them:
    :meth:`run` by default generates the whole step (predict, update, the
    adjustable random walk and the errors-in-variables compensation below)
    with casadi and runs it in compiled chunks
    (:func:`observers.kalman.whole_error_step`); ``run(compiled=False)``, and
    :meth:`step` sample by sample, hand the compiled ``F`` and ``Q`` to
    filterpy's ``ExtendedKalmanFilter``, whose ``predict`` and ``update`` are
    the same two functions. They agree to rounding (``tests/test_ekf.py``,
    ``tests/test_spatial_ekf.py``).

    Tuning rule: ``R`` the pose noise in the error state (planar
    ``diag(angle_sd^2, position_sd^2, position_sd^2)``); ``Q`` is the raw
    reading's noise carried through the dynamics, ``Q = J diag(wrench_sd^2)
    J^T`` (a reading noise correlated in time as white noise of its power at
    low frequencies, ``wrench_sd^2 tau``: eq. (LF3) of
    :mod:`fmscal.observers.batch._linearised_floor`) with ``J = J_0 + J_1`` the
    sum of the step's Jacobians with respect to the raw readings at its two
    ends. Each reading's noise enters two consecutive steps (through ``J_1``
    of one and ``J_0`` of the next), so the process noise of eq. (1) is
    correlated from step to step; the filter's white ``Q`` must carry each
    reading once, with its whole effect: ``J_0 Sigma J_0^T + J_1 Sigma
    J_1^T`` (each end as an independent draw) would give the motion half
    the wrench noise's low-frequency power and make ``S_std`` about
    ``sqrt(2)`` too small. The true wrench's noise is ``S n`` with ``S``
    itself uncertain: its covariance is ``E[S Sigma S^T] = S_hat Sigma
    S_hat^T + Delta``, ``Delta_ij = sum_l Sigma_l cov(s_il, s_jl)`` from the
    calibration block of ``P`` (``noise_at="estimate"``, the default on a
    model linear in its channels; in 3D ``S0 Sigma S0^T``, ``"start"``:
    :mod:`observers.kalman._error_state` says why), carried through the step as the wrench is
    (``J_d Delta J_d^T``, ``J_d`` the step's Jacobian with respect to the true
    wrench at both ends). ``Delta`` matters only while ``S`` is still
    uncertain (the first seconds); without it the filter, evaluating the
    noise at a wrong early ``S_hat``, weights its first poses wrongly and,
    never forgetting on a constant ``S``, keeps that error (the site's
    comparison page measures what ``Delta`` is worth). On top, ``q dt`` on each
    calibration entry: a random walk whose intensity ``q`` is 0 (``q_S``, a
    constant ``S``) until the normalized innovation squared of the poses
    says that ``S`` moved; then it starts at ``q_S_start`` and rises
    towards ``q_S_max``, and falls back to 0 once the innovations are
    consistent again (:class:`observers.kalman.NoiseLevel`,
    ``adapt_q``). ``P_0`` is the pose noise on the positions, ``v0_sd^2``
    on the velocities and ``S0_sd^2`` on the calibration entries.

    Errors in variables (``eiv``, a change from [3]). The step's Jacobian
    with respect to ``S`` holds the noisy reading, whose noise is also the
    process noise of the same step; the correlation attenuates ``S_hat``
    towards zero by a fraction that grows with the square of the wrench
    noise (largest on the ``noisy`` scenario). The reported
    estimate is compensated to first order, ``S_c = T S_hat`` and
    ``P_c = T P T^T`` with ``T = I + (J + lam I)^-1 B`` (the correction
    limited to a tenth of ``|S_hat|`` over the first samples, while ``J``
    is still rank-deficient), from the information
    ``J`` and its noise-made part ``B`` that a separate-bias filter run
    beside the EKF accumulates on a model linear in its channels
    (:class:`observers.kalman.EivCompensation`, the same step as the floor's;
    in 3D the floor's seeded copy, :mod:`observers.kalman._error_state`); the
    filter itself runs on its own estimate.
    ``eiv=False`` reports the filter's estimate as it is.

    With a fixed random walk the filter must choose between averaging (a
    constant ``S``) and forgetting (a moving ``S``); the adjustable level
    does both: on a constant ``S`` it stays at zero and the filter is the
    constant-``S`` filter, and after a step in ``S`` (Table 1) it raises
    the intensity until the innovations are consistent again. A sensor that
    drifts fast and steadily (the ``drift`` scenario, 0.2 per 100 s) keeps
    the innovations only a little above their bound; it is followed better
    with a fixed random walk of its rate (``q_S=1e-5, adapt_q=False``).

    ``S_std`` (and ``b_std``) come from ``P`` (compensated). Over seeds,
    the z-scores ``(S_hat - S) / S_std`` have a spread near 1 on the
    ``paper``, ``real-rig`` and ``random-S`` scenarios, told the noise or
    estimating it (``tests/test_ekf.py``).

    Parameters
    ----------
    model : plant.Model, plant.Payload or plant.SpatialPayload
        The problem (a model with ``integrate`` and ``difference``: the
        planar, the spatial); a payload stands for its case's model. Every
        size of the filter comes from the model.
    noise : plant.NoiseSpec, optional
        Noise standard deviations in the units of the log. None: estimated
        from the log (:func:`plant.io._noise.estimate_noise`) and reported in
        ``result.info["noise"]``. ``result.info["q_S_history"]`` (N,) holds
        the random-walk intensity after each sample, 1/s.
    q_S : float
        Base random-walk intensity of each calibration entry, 1/s: the
        entries are assumed to wander by ``sqrt(q_S t)`` over ``t`` seconds
        (1e-8: about 0.006 an hour). Default 0: a constant ``S`` while the
        innovations are consistent (with ``adapt_q=False``: throughout).
    S0_sd : float
        Initial standard deviation of each calibration entry.
    v0_sd : float
        Initial standard deviation of the velocities (rad/s, m/s).
    offset : bool
        Also estimate the sensor's offset ``b`` (``result.b``, with
        ``result.b_std`` from ``P``): three more states ``c_1..c_3`` in
        ``w = S w_hat + c``, ``c = -S b``, with the same random walk. Off by
        default, as in the paper.
    c0_sd : float, optional
        Initial standard deviation of each ``c_i`` (N m, N); default
        ``S0_sd`` times the size of the first reading (at least 1).
    adapt_q : bool
        Raise the intensity while the innovations say ``S`` moved (default).
        False: a fixed random walk of ``q_S``.
    q_S_max : float
        Largest intensity the adaptation reaches, 1/s.
    q_S_start : float
        Intensity the adaptation starts from when the innovations first say
        that ``S`` moved, 1/s (at least ``q_S``).
    eiv : bool
        Compensate the reported estimate and ``P`` for the noisy reading in
        the regressor (default; class docstring). False: the filter's
        estimate as it is, as in [3].
    nis_tolerance : float
        Relative error of the noise standard deviations that the adaptation
        tolerates without raising the intensity (0.25: 25 %); a larger value
        reacts to larger changes only.
    noise_at : {"estimate", "start"}, optional
        The ``S`` at which ``Q`` carries the reading's noise into the wrench:
        the running estimate with its uncertainty (``W = S_hat Sigma S_hat^T
        + Delta``, eq. Q2) or the run's ``S0`` (``W = S0 Sigma S0^T``, eq.
        Q1; :mod:`observers.kalman._error_state`). Default: ``"estimate"`` on
        a model linear in its channels, ``"start"`` otherwise (the spatial
        model: the module docstring says why).

    Attributes
    ----------
    level : observers.kalman.NoiseLevel or None
        The adjustable random-walk intensity (None with ``adapt_q=False``).
    dim_x : int
        The error state's size, ``2 nv + n_w n`` (planar 15, 18 with the offset; spatial 48, 54).

    Examples
    --------
    >>> from fmscal.plant import PAPER_PAYLOAD, get_scenario
    >>> log, truth, _ = get_scenario("paper").with_(duration=2.0).generate(0)
    >>> from fmscal.plant import NoiseSpec
    >>> from fmscal.observers import AugmentedEKF
    >>> ekf = AugmentedEKF(PAPER_PAYLOAD, noise=NoiseSpec((0.05, 0.5, 0.5), 1e-3, 1e-4))
    >>> result = ekf.run(log)
    >>> result.S_hat.shape, result.S_std.shape, result.diverged
    ((3, 3), (3, 3), False)
    """

    name = "ekf"

    def __init__(self, model, noise=None, q_S=0.0, S0_sd=3.0, v0_sd=1.0, offset=False, c0_sd=None,
                 adapt_q=True, q_S_max=1e-4, nis_tolerance=DEFAULT_TOLERANCE, q_S_start=DEFAULT_Q_START,
                 eiv=True, noise_at=None):
        super().__init__(model, offset=offset)
        if noise_at not in (None, "estimate", "start"):
            raise FmscalError(f"noise_at must be 'estimate', 'start' or None; got {noise_at!r}")
        #: Where ``Q`` takes the ``S`` that carries the reading's noise into the wrench: ``"estimate"`` (the
        #: running estimate and its uncertainty, eq. Q2) or ``"start"`` (the run's ``S0``, eq. Q1).
        self.noise_at = noise_at or ("estimate" if self.model.linear_channels else "start")
        self.noise = None if noise is None else self.model.check_noise(noise)
        self.adapt_q = as_bool(adapt_q, "adapt_q")
        self.q_S = as_positive_scalar(q_S, "q_S", allow_zero=True)
        self.S0_sd, self.v0_sd = as_positive_scalar(S0_sd, "S0_sd"), as_positive_scalar(v0_sd, "v0_sd")
        self.level = None
        if self.adapt_q:
            q_S_max = as_positive_scalar(q_S_max, "q_S_max")
            q_S_start = max(as_positive_scalar(q_S_start, "q_S_start"), self.q_S)
            if q_S_max < q_S_start:
                raise FmscalError(f"q_S_max must be at least q_S and q_S_start ({q_S_start:g}); got {q_S_max:g}")
            self.level = NoiseLevel(self.q_S, q_S_max, as_positive_scalar(nis_tolerance, "nis_tolerance",
                                                                          allow_zero=True), q_start=q_S_start,
                                    dof=self._innovation_size())
        self.c0_sd = None if c0_sd is None else as_positive_scalar(c0_sd, "c0_sd")
        self._build(as_bool(eiv, "eiv"))
        self.reset()

    def _innovation_size(self):
        """The pose innovation in the error state (spatial ``[dp, dphi]``, planar ``[dtheta, dX, dY]``): ``nv``
        entries."""
        return self.model.nv

    def _build(self, eiv):
        model = self.model
        _, m, self._ne, self.dim_x = _sizes(model, self.offset)
        #: The error state's entries ``H`` selects: the pose's error, the first ``nv``.
        self.pose_index = list(range(model.nv))
        #: Whether the reported estimate is compensated for the errors in variables (module docstring).
        self.eiv_on = bool(eiv)
        # a model linear in its channels: the separate-bias filter's compensation (observers.kalman._eiv, its
        # expected bias); otherwise the seeded copy (module docstring), which needs no linear channels
        self.eiv = EivCompensation(model, self.n_cols) if self.eiv_on and model.linear_channels else None

    @cached_property
    def _calls(self):
        """The readable path's calls (``jacobians``, ``predict``, ``inject``, the copy's ``copy_step`` and
        ``compensate``; :func:`_readable`, :func:`eiv_copy`), made on first use: the compiled run needs none."""
        names = ("jacobians", "predict", "inject", "copy_step", "compensate")
        functions = (*_readable(self.model, self.offset), *eiv_copy(self.model, self.offset))
        return dict(zip(names, (BufferedCall(f) for f in functions)))

    @property
    def _predict(self):
        """The readable path's predict call through its buffers (:meth:`predict_matrices`; ``fmscal bench``
        times it alone)."""
        return self._calls["predict"]

    def transition(self, xs, w0, w1, dt):
        """The nominal step and the error state's Jacobians (the compiled casadi call).

        Parameters
        ----------
        xs : ndarray, shape (nx + n_w n,)
            The nominal ``[x, s]``.
        w0, w1 : ndarray, shape (n_w,)
            The raw readings at the step's start and end.
        dt : float
            The step, s.

        Returns
        -------
        xs_next : ndarray, shape (nx + n_w n,)
        F : ndarray, shape (d, d)
        J0, J1 : ndarray, shape (d, n_w)
            Jacobians of the error state with respect to the raw readings at
            the step's start and end.
        """
        call, d, n_w = self._calls["jacobians"], self.dim_x, self.n_w
        for buffer, value in zip(call.inputs, (xs, w0, w1, dt)):
            buffer[:] = value
        call()
        f, F, J0, J1 = call.outputs
        return f.copy(), F.reshape(d, d).T.copy(), J0.reshape(n_w, d).T.copy(), J1.reshape(n_w, d).T.copy()

    def predict_matrices(self, xs, w0, w1, dt, S_Q=None):
        """``xs_next``, ``F`` and ``Q`` of the tuning rule, in one compiled call.

        Parameters as :meth:`transition`; ``S_Q`` (``n_w`` square) the ``S``
        at which ``Q`` carries the reading's noise (default the running
        filter's: the run's ``S0``).

        Returns
        -------
        xs_next : ndarray, shape (nx + n_w n,)
        F, Q : ndarray, shape (d, d)
            Views of the call's buffers, overwritten by the next call.
        """
        f, d = self.run_data.state, self.dim_x
        call = self._calls["predict"]
        xs_in, w0_in, w1_in, dt_in, var_in, S_in, P_in, at_in, q_in = call.inputs
        xs_in[:], w0_in[:], w1_in[:], dt_in[0] = xs, w0, w1, dt
        var_in[:] = f.var_w
        S_in[:] = np.ravel(f.S_Q if S_Q is None else S_Q)
        P_in[:] = np.ravel(f.kf.P[self._ne:, self._ne:])                      # symmetric: either order
        at_in[0] = float(self.noise_at == "estimate")
        q_in[0] = self._q_now() * dt
        call()
        xs_next, F, Q = call.outputs
        return xs_next.copy(), F.reshape(d, d).T, Q.reshape(d, d).T

    def inject(self, xs, pose, e):
        """The pose in the error state, and the injection of ``e`` (:func:`injection`).

        Returns
        -------
        y : ndarray, shape (nv,)
            ``difference(q(x), pose)``: ``[dp (m, world), dphi (rad, sensor axes)]``.
        xs_new : ndarray, shape (nx + n_w n,)
            ``xs (+) e``.
        G : ndarray, shape (d, d)
            The reset of ``P`` (``P <- G P G^T``).
        """
        call, d = self._calls["inject"], self.dim_x
        for buffer, value in zip(call.inputs, (xs, pose, e)):
            buffer[:] = value
        call()
        y, xs_new, G = call.outputs
        return y.copy(), xs_new.copy(), G.reshape(d, d).T.copy()

    def innovation(self, pose):
        """The pose in the error state, ``difference(q(x-), pose)`` (:meth:`inject`), shape (nv,)."""
        return self.inject(self.run_data.state.xs, pose, np.zeros(self.dim_x))[0]

    def reset(self, S0=None, velocity=None):
        """Forget the run; the next :meth:`step` starts from ``S0`` (default identity) and ``velocity``.

        Parameters
        ----------
        S0 : array_like, shape (n_w, n_w), optional
        velocity : array_like, shape (nv,), optional
            The motion's velocity at the first sample, in the model's layout
            (:meth:`fmscal.plant.Model.velocity`; in 3D ``[v (world), omega
            (sensor axes)]``); default rest. :meth:`run` takes it from the
            log's first poses (eq. D1, :func:`fmscal.observers.core.start_velocity`).
        """
        super().reset(S0)
        self._velocity0 = None if velocity is None else as_finite_array(velocity, (self.model.nv,), "velocity")
        if self.level is not None:
            self.level.reset()

    def _estimate(self, log, S0):
        """The filter over the log, with the noise model told or estimated from the log, its motion started at
        the velocity the first poses show (eq. D1, :func:`fmscal.observers.core.start_velocity`)."""
        run = self.run_data
        run.noise = self.noise
        self._velocity0 = start_velocity(log, self.model)
        info = {}
        if run.noise is None:
            run.noise = estimate_noise(log)
            info["noise"] = run.noise.to_dict()
            info["noise_estimated"] = True
        if run.compiled:
            estimate, q = self._estimate_compiled(log)
        else:
            estimate = super()._estimate(log, S0)
            q = np.array(run.state.q_history[:len(estimate.calibration)])
        info["q_S_history"] = q
        estimate.info = info
        estimate.warnings = _random_walk_warnings(log.t[:len(q)], q)
        return estimate

    def _estimate_compiled(self, log):
        """The whole log through :func:`observers.kalman.whole_error_step`; the filter left where it ended.

        Returns
        -------
        Estimate
        q_history : ndarray, shape (M,)
        """
        U = log_inputs(log)
        self._start(U[0])
        f = self.run_data.state
        start = time.perf_counter()
        chunks = self._whole_step()
        self.run_data.build_time = time.perf_counter() - start              # one-off: not the run's cost
        n_steps = len(U) - 1
        params = self._params()
        inputs = [U[:-1], U[1:], np.full((n_steps, 1), log.dt), np.broadcast_to(params, (n_steps, len(params))),
                  *self._extra_inputs(n_steps)]
        with progress_bar(len(U), self.name) as bar:
            z, (Y,) = chunks.run(self._packed(), inputs, healthy=self._healthy_outputs, outputs=True, states=False,
                                 progress=bar.update)
        out = output_layout(self.model, self.n_cols)
        x0, s0 = self._current()
        calibration = np.vstack([s0, out.part(Y, "s")])
        x = np.vstack([x0, out.part(Y, "x")])
        q = np.concatenate([f.q_history[:1], out.part(Y, "q")[:, 0]])
        self._unpacked(z, calibration[-1])
        self.run_data.u_prev = U[len(calibration) - 1]
        return Estimate(calibration, x, cov=self._covariance(), diverged=len(Y) < n_steps), q

    def _extra_inputs(self, n_steps):
        """The copy's draws at each step's two samples, continuing the run's stream (as :meth:`_advance` draws)."""
        f = self.run_data.state
        rows = np.vstack([f.draw, f.rng.standard_normal((n_steps, self.model.n_w + self.model.nv))])
        f.draw = rows[-1]                    # where the run ends (a stopped run is not continued)
        return [np.hstack([rows[:-1], rows[1:]])]

    def _whole_step(self):
        return whole_error_step(self.model, self.n_cols, self.eiv is not None)

    def _level_settings(self):
        """The random-walk level's settings for a compiled step, and whether it adapts (1 or 0)."""
        level = self.level.settings if self.level is not None else (0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
        return level, float(self.level is not None)

    def _params(self):
        f = self.run_data.state
        level, adapt = self._level_settings()
        return error_params_layout(self.model).pack(None, R=np.diag(f.kf.R), var_w=f.var_w, S_Q=f.S_Q.ravel(),
                                                    at_estimate=float(self.noise_at == "estimate"), level=level,
                                                    adapt=adapt, eiv=float(self.eiv_on), **self._eiv_settings(),
                                                    **self.model.payload_values())

    def _eiv_settings(self):
        """The separate-bias filter's settings but the step, where the model is linear in its channels."""
        if not self.model.linear_channels:
            return {}
        size = self.model.n_pose + self.n_w
        return {"eiv_q": self.eiv.state[1][1:] if self.eiv is not None else np.ones(size)}

    def _packed(self):
        f = self.run_data.state
        return error_state_layout(self.model, self.n_cols).pack(
            None, xs=f.xs, P=pack_lower(f.kf.P, self.dim_x), q=f.q_history[-1],
            eps_bar=self.level.eps_bar if self.level is not None else 0.0, since=f.since_pose, copy=f.copy,
            **self._eiv_state())

    def _eiv_state(self):
        """The separate-bias filter's packed state, where the model is linear in its channels (its initial
        state without the compensation: the compiled step carries it unused)."""
        if not self.model.linear_channels:
            return {}
        if self.eiv is not None:
            return {"eiv": self.eiv.state[0]}
        f, model = self.run_data.state, self.model
        var = np.maximum(model.pose_sd(self.run_data.noise or self.noise or _nominal_noise(model)), 1e-6) ** 2
        return {"eiv": initial_state(model, model.configuration(f.xs[:model.nx]), var, self.n_cols)}

    def _unpacked(self, z, s_out):
        f = self.run_data.state
        st = error_state_layout(self.model, self.n_cols).unpack(z)
        f.xs = st.xs.copy()
        f.copy = st.copy.copy()
        f.kf.P = np.asarray(unpack_lower(ops(z), st.P, self.dim_x))
        f.kf.x = np.zeros((self.dim_x, 1))
        f.since_pose = float(st.since)
        if self.level is not None:
            self.level.q, self.level.eps_bar = float(st.q), float(st.eps_bar)
        f.q_history = [float(st.q)]
        if self.eiv is not None:
            self.eiv.state[0][:] = st.eiv
            self.eiv.set_last(st.xs[self.model.nx:])
        f.s_out = np.array(s_out, dtype=float)

    def _healthy_outputs(self, Y, k0):
        """Leading rows of the compiled step's outputs that :meth:`_healthy` would pass."""
        out = output_layout(self.model, self.n_cols)
        with np.errstate(invalid="ignore"):
            return self._healthy_rows(Y, out.part(Y, "s"), k0, bad=~(out.part(Y, "P_min")[:, 0] > 0))

    def _start(self, u):
        model = self.model
        u = model.input_layout.unpack(np.asarray(u, dtype=float), scalars=False)
        noise, S_var, var_w = self._prior(u.w_hat)
        kf = _CalibrationEKF(self.dim_x, model.nv)           # x_next = 0: the error stays zero over a predict
        R = error_variances(model, noise)
        kf.P = np.diag(np.concatenate([R, np.full(model.nv, self.v0_sd ** 2), S_var]))
        kf.R = np.diag(R)
        s = self._initial_S(self.run_data.S0)
        ne = self._ne
        copy = np.zeros(copy_layout(model).size)
        copy[copy_layout(model).slices["Pm"]] = pack_lower(kf.P[:ne, :ne], ne)
        rng = np.random.default_rng(_SEED)
        if self.eiv is not None:
            self.eiv.reset(u.pose, model.pose_sd(noise), np.sqrt(var_w))
        self.run_data.state = FilterRun(kf=kf, var_w=var_w, s_out=s.copy(), since_pose=0.0,
                                         q_history=[self._q_now()], xs=np.concatenate([self._motion0(u.pose), s]),
                                         copy=copy, rng=rng, draw=rng.standard_normal(model.n_w + model.nv),
                                         S_Q=s.reshape(model.n_w, -1)[:, :model.n_w].copy())

    def _motion0(self, pose):
        """The motion the filter starts from: at the first pose, with the velocity :meth:`_estimate` found in the
        log (eq. D1), or at rest (a live run, :meth:`step`).

        At rest on a payload already moving, the first step misses by the velocity times the step: on a 25 Hz
        log with poses good to microradians (``examples/arm.csv``), thousands of the poses' standard deviations,
        which the filter's first updates, linearised at that wrong motion, put into ``S`` (it diverged there).
        ``P_0`` keeps ``v0_sd`` on the velocity: the start moves the nominal, not the prior.
        """
        x = self.model.rest_state(pose)
        if self._velocity0 is None:
            return x
        return np.asarray(self.model.state_from(self.model.configuration(x), self._velocity0), dtype=float).ravel()

    def _prior(self, w_hat):
        """The noise model of the run, the prior variances of ``[S | c]`` (flat, row order) and the reading's
        noise variances, at the first sample's reading ``w_hat``.

        ``S0_sd^2`` on each entry of ``S``; ``c0_sd^2`` on the offset column,
        by default ``S0_sd`` times the size of the first reading (at least 1).
        """
        noise = self.run_data.noise or self.noise or _nominal_noise(self.model)
        S_var = np.full((self.n_w, self.n_cols), self.S0_sd ** 2)
        if self.offset:
            c0_sd = self.c0_sd if self.c0_sd is not None else self.S0_sd * max(float(np.linalg.norm(w_hat)), 1.0)
            S_var[:, self.n_w] = c0_sd ** 2
        return noise, S_var.ravel(), np.maximum(noise.long_run_wrench_sd, 1e-6) ** 2

    def _q_now(self):
        """The random walk's intensity now, 1/s."""
        return self.level.q if self.level is not None else self.q_S

    def _pose_update(self, y):
        """The update with the innovation ``y`` (eqs. K3-K7, :mod:`observers.kalman._kalman`), then the level at
        its NIS."""
        f = self.run_data.state
        f.kf.update(y, self.pose_index)
        if self.level is not None:
            self.level.update(float(f.kf.nis), f.since_pose)      # NIS of this pose
        f.since_pose = 0.0

    def _advance(self, u_prev, u, dt):
        """Predict the nominal and ``P`` over ``dt``; with a pose, update, inject and reset."""
        f = self.run_data.state
        kf, layout = f.kf, self.model.input_layout
        has_pose, pose, w_hat = u[0], u[layout.slices["pose"]], u[layout.slices["w_hat"]]
        nx = self.model.nx
        xs_start = f.xs
        f.xs, F, Q = self.predict_matrices(f.xs, u_prev[layout.slices["w_hat"]], w_hat, dt)
        kf.F, kf.Q = F.copy(), Q.copy()
        kf.predict()
        f.since_pose += dt
        x_pred = f.xs[:nx].copy()
        if has_pose:
            self._pose_update(self.innovation(pose))
            _, f.xs, G = self.inject(f.xs, pose, kf.x[:, 0])
            kf.P = reset(kf.P, G)                               # eq. (K8)
            kf.x = np.zeros((self.dim_x, 1))
        f.q_history.append(self._q_now())
        s = f.xs[nx:]
        if self.eiv is not None:     # the separate-bias filter's compensation, with the filter's configuration
            model = self.model
            f.s_out = self.eiv.step(has_pose, (model.configuration(xs_start[:nx]), model.configuration(f.xs[:nx])),
                                    pose, (u_prev[layout.slices["w_hat"]], w_hat), dt, s)
            return
        # the errors-in-variables copy (module docstring), the compensated estimate
        draw = f.rng.standard_normal(self.model.n_w + self.model.nv)
        f.copy = self._call(self._calls["copy_step"], f.copy, kf.F, kf.Q, xs_start[:nx], x_pred, xs_start[nx:],
                            np.r_[f.draw, draw], float(has_pose), np.diag(kf.R), f.var_w, dt)
        f.draw = draw
        f.s_out = (self._call(self._calls["compensate"], kf.P[self._ne:, self._ne:], s, self._bn()) if self.eiv_on
                   else s.copy())

    @staticmethod
    def _call(call, *values):
        """A compiled call through its buffers (matrices column-major); its first output, copied."""
        for buffer, value in zip(call.inputs, values):
            buffer[:] = np.ravel(value, order="F")
        call()
        return call.outputs[0].copy()

    def _bn(self):
        """The copy's ``b_n`` (module docstring)."""
        return self.run_data.state.copy[copy_layout(self.model).slices["bn"]]

    def _current(self):
        f = self.run_data.state
        return f.xs[:self.model.nx], f.s_out

    def _covariance(self):
        """``P`` of ``[S | c]``, compensated (``T P T^T``, module docstring) unless ``eiv=False``."""
        f = self.run_data.state
        P = f.kf.P[self._ne:, self._ne:]
        if not self.eiv_on:
            return P.copy()
        if self.eiv is not None:
            T = self.eiv.T
            return T @ P @ T.T
        n_w, n = self.n_w, self.n_cols
        s = f.xs[self.model.nx:]
        o = ops(P)
        B = bias_matrix(o, beta_from_copy(self._bn(), s, f.var_w, n_w, n), f.var_w, n_w, n)
        A = P @ B
        s_col = s.reshape(-1, 1)
        T = np.eye(len(s)) + correction_limit(o, s_col, A @ s_col, len(s)) * A
        return T @ P @ T.T

    def _healthy(self, x, calibration, k=None):
        """The base class's test (finite, within the bound), and a finite, positive definite-looking ``P``."""
        f = self.run_data.state
        P = f.kf.P
        # a NaN or inf anywhere makes the sum non-finite: one reduction
        return super()._healthy(x, calibration, k) and math.isfinite(float(P.sum())) and bool(P.diagonal().min() > 0)



def _nominal_noise(model):
    """The noise model of a live filter that was told none (``step`` without a log to estimate it from):
    0.05 on each reading component, 0.1 degree and 0.1 mm on the pose."""
    return NoiseSpec((0.05,) * model.n_w, np.deg2rad(0.1), 1e-4)


def _random_walk_warnings(t, q_history):
    """A warning if the EKF raised its random walk on S (its innovations said S moved)."""
    raised = q_history > 1.01 * q_history.min()
    if not raised.any():
        return []
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.0
    return [f"the EKF raised its random walk on S for {raised.sum() * dt:.1f} s (first at t = "
            f"{t[np.argmax(raised)]:.1f} s): S may have changed during the log, or the noise model is "
            f"more than {DEFAULT_TOLERANCE * 100:g} % off"]
