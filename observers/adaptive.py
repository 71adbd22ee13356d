"""The paper's Lyapunov adaptive observer, eqs. (6)-(8), (14), (15).

Reading of the paper: ``docs/reading-the-paper.md``. In matrix form, with
``G(theta)`` the matrix of eq. (1) (:func:`plant.input_matrix`), the observer
is

* eqs. (6), (7): ``x_hat' = A x_hat + G(theta) S_hat w_hat + K C e``, since
  ``B_1(w_hat) phi_1 = [0, row 1 of G S w_hat]`` and likewise ``B_2 phi_2``;
* eq. (8): ``S_hat' = delta G(theta)^T W e_v w_hat^T``, where
  ``e_v = [e_theta', e_X', e_Y']`` are the velocity errors (true minus
  estimate) and ``W = diag(1, m, m)`` for the law as printed (no ``1/m`` on
  the translational terms) or ``W = I`` for the law the Lyapunov proof
  derives. Written out, row 2 is
  ``s_2j' = delta w_hat_j [-rho_y e_theta'/I_G + (e_X' cos + e_Y' sin) W_22/m]``,
  exactly the printed eq. (8) when ``W_22 = m``.
"""

import numpy as np

from plant import input_matrix
from plant._backend import ops
from plant._checks import as_finite_array, as_positive_scalar

from . import _matrix as mx
from .base import Observer
from .gains import double_pole_gains

__all__ = ["AdaptiveObserver", "PAPER_K1", "PAPER_K2", "PAPER_DELTA", "DEFAULT_POLE"]

#: Eq. (14): ``K_1 = [25, 25]^T``, rows theta, theta'.
PAPER_K1 = np.array([[25.0], [25.0]])
#: Eq. (14): ``K_2``, rows X, X', Y, Y'; columns the X and Y output errors.
PAPER_K2 = np.array([[5.0, 5.0], [10.0, 5.0], [2.0, 15.0], [5.0, 15.0]])
#: Section 4: the stiffness constant, with the time step absorbed (eq. 15).
PAPER_DELTA = 20.0
#: Default configuration: every channel's observer poles at -DEFAULT_POLE rad/s (double).
DEFAULT_POLE = 20.0
_R_TIME = 2.0          # s, averaging time of w_hat w_hat^T in the normalisation
_R_REG = 1e-3          # regularisation of R, relative to its mean eigenvalue
_R_MIN = 1e-12


class AdaptiveObserver(Observer):
    """Lyapunov adaptive observer of the paper, eqs. (6)-(8), (14), (15).

    Two configurations:

    * :meth:`paper` (named ``adaptive-paper``): the paper exactly: forward
      Euler at the log's step, ``delta = 20`` absorbing the step, ``K_1``,
      ``K_2`` as printed, velocity errors by the backward difference of the
      position errors (eq. 15, ``e_v = e(n) - e(n-1)`` per step), and the law
      as printed (``W = diag(1, m, m)``).
    * the default (named ``adaptive``): what a user can trust on data that
      is not the paper's. It keeps the structure (the same ``K_1``, ``K_2``,
      the gradient of eq. (8) on velocity errors) and changes six things,
      each measured in ``tests/test_adaptive.py`` and the README:

      1. the velocity error is ``e_v = e' + K_pos e`` (the reading the
         observer equations imply, docs/reading-the-paper.md), with ``e'`` a first-order
         filtered derivative (time constant ``tau``), not a raw difference
         that turns pose noise into large steps;
      2. the law adapts ``phi_1`` and ``phi_2`` of eqs. (4), (5) with a
         matrix gain: ``phi_1' = gain I_G R^-1 w_hat e_theta'`` and
         ``[s_2, s_3]' = gain m R^-1 w_hat (R(theta)^T [e_X', e_Y'])``, with
         ``R`` a running mean of ``w_hat w_hat^T``. The printed law's rate
         scales with ``|w_hat|^2 / I_G^2`` (unstable for light payloads) and
         its slowest direction with ``1 / cond(S)^2`` (the regressor
         ``w_hat = S^-1 w``); this one is free of both;
      3. the gain decays as ``gamma / (1 + t / t_decay)`` down to a floor
         ``gamma * floor``, trading tracking speed for less noise late in
         the run;
      4. the injection gains place every channel's poles at -20 rad/s
         (double) instead of the printed ones (slowest -1.04): the gradient
         needs ``Re H(jw) > 0`` of the error model at the frequencies of the
         regressor, and a payload spinning at tens of rad/s moves the
         translational regressor far above the printed gains' bandwidth;
      5. the motion is propagated with the exact double-integrator step and
         the wrench interpolated over the step, not forward Euler;
      6. where poses arrive slower than the sensor (a 30-120 Hz vision
         system, dropped frames), the injection, the derivative filter and
         the adaptation at each pose use the time since the previous pose,
         not the sensor's step: a correction stands for the whole interval.
         Without it the observer diverged within 3 s with poses at 50 Hz.

    Parameters
    ----------
    payload : plant.Payload
    K1 : array_like, shape (2, 1), optional
        Injection gain of the angular observer (6). Default: the paper's
        ``K_1`` (eq. 14) for :meth:`paper`; poles at ``-DEFAULT_POLE``
        (double, :func:`observers.gains.double_pole_gains`) otherwise.
    K2 : array_like, shape (4, 2), optional
        Injection gain of the translational observer (7), likewise.
    delta : float
        Paper configuration: stiffness constant of eq. (8), step absorbed.
    literal : bool
        True: the configuration of the paper; False: the default.
    gamma : float
        Default configuration: adaptation gain, 1/s.
    tau : float
        Default configuration: time constant of the derivative filter, s.
    t_decay : float
        Default configuration: time over which the gain halves, s.
    floor : float
        Default configuration: the gain never falls below ``floor * gamma``.
    offset : bool
        Also estimate the sensor's offset ``b`` (``result.b``): the laws run
        on ``[S | c]`` and the reading ``[w_hat, 1]``
        (:class:`observers.Observer`). Off by default, as in the paper.

    Examples
    --------
    >>> from plant import PAPER_PAYLOAD, get_scenario
    >>> log, truth, _ = get_scenario("paper").with_(duration=2.0).generate(0)
    >>> result = AdaptiveObserver(PAPER_PAYLOAD).run(log, truth.S0)
    >>> result.S_hat.shape
    (3, 3)
    """

    def __init__(self, payload, K1=None, K2=None, delta=PAPER_DELTA, literal=False,
                 gamma=30.0, tau=0.01, t_decay=20.0, floor=0.1, offset=False):
        default_K1, default_K2 = (PAPER_K1, PAPER_K2) if literal else double_pole_gains(DEFAULT_POLE)
        self.K1 = as_finite_array(default_K1 if K1 is None else K1, (2, 1), "K1")
        self.K2 = as_finite_array(default_K2 if K2 is None else K2, (4, 2), "K2")
        self.delta = as_positive_scalar(delta, "delta")
        self.literal = bool(literal)
        self.gamma = as_positive_scalar(gamma, "gamma")
        self.tau = as_positive_scalar(tau, "tau")
        self.t_decay = as_positive_scalar(t_decay, "t_decay")
        self.floor = as_positive_scalar(floor, "floor")
        self.name = "adaptive-paper" if self.literal else "adaptive"
        # K as a 6x3 gain on the output errors [e_theta, e_X, e_Y], state order of plant
        self.K = np.zeros((6, 3))
        self.K[0:2, 0] = self.K1[:, 0]
        self.K[2:6, 1:3] = self.K2
        super().__init__(payload, offset=offset)

    @classmethod
    def paper(cls, payload, offset=False):
        """The paper's configuration exactly (``adaptive-paper``)."""
        return cls(payload, literal=True, offset=offset)

    # packed state: x_hat(6) [S_hat | c_hat](3n) e_prev(3) pose_n(3) has_n(1) w_n(3) t(1) xi(3) R(n x n)
    # since(1), n = n_cols (3, or 4 with the offset); since: time from the last pose before sample n to n
    def _split(self, z):
        """The packed state's parts, in the order above."""
        k = self._S.stop
        n = self.n_cols
        return (z[0:6], z[self._S], z[k:k + 3], z[k + 3:k + 6], z[k + 6], z[k + 7:k + 10], z[k + 10],
                z[k + 11:k + 14], z[k + 14:k + 14 + n * n], z[k + 14 + n * n])

    def _initial_state(self, S0, pose, w_hat):
        x = np.array([pose[0], 0.0, pose[1], 0.0, pose[2], 0.0])
        w = self._augmented(ops(w_hat), w_hat)
        R = np.eye(self.n_cols) * max(float(w @ w), _R_MIN) / self.n_cols     # isotropic until excited
        return np.concatenate([x, self._initial_S(S0), np.zeros(3), pose, [1.0], w_hat, [0.0], np.zeros(3),
                               R.ravel(), [0.0]])

    def _transition(self, z, u, dt):
        if self.literal:
            return self._paper_step(z, u, dt)
        return self._default_step(z, u, dt)

    def _paper_step(self, z, u, dt):
        """Eqs. (6), (7), (14) by forward Euler; eq. (8) with eq. (15)."""
        o = ops(z, u)
        x, S, e_prev, pose, has, w_raw, t, xi, R_flat, since = self._split(z)
        w = self._augmented(o, w_raw)
        # output errors, true minus estimate (the proof's sign, docs/reading-the-paper.md)
        e = has * o.vcat([pose[0] - x[0], pose[1] - x[2], pose[2] - x[4]])
        theta = has * pose[0] + (1 - has) * x[0]            # eq. (5) uses the measured angle
        G = input_matrix(theta, self.payload)
        S_mat = mx.as_matrix(o, S, 3, self.n_cols)
        # eq. (15): velocity errors by backward difference, step absorbed in delta
        e_v = has * (e - e_prev)
        # eq. (8) as printed: S_hat += delta G^T diag(1, m, m) e_v w_hat^T
        W_e_v = o.vcat([e_v[0], self.payload.mass * e_v[1], self.payload.mass * e_v[2]])
        S_next = S_mat + self.delta * o.dot(mx.col(o.dot(G.T, W_e_v)), mx.row(w))
        # eqs. (6), (7), (14): x_hat' = A x_hat + G S_hat w_hat + K C e, forward Euler
        a = o.dot(G, o.dot(S_mat, w))
        x_dot = o.vcat([x[1], a[0], x[3], a[1], x[5], a[2]]) + o.dot(self.K, e)
        x_next = x + dt * x_dot
        e_keep = has * e + (1 - has) * e_prev
        return o.vcat([x_next, mx.flat(o, S_next), e_keep, u[1:4], u[0], u[4:7], t + dt, xi, R_flat,
                       dt + (1 - has) * since])

    def _default_step(self, z, u, dt):
        """The default configuration (class docstring, points 1-4)."""
        o = ops(z, u)
        p = self.payload
        x, S, e_prev, pose, has, w_raw, t, xi, R_flat, since = self._split(z)
        n = self.n_cols
        # 6. h: the time the correction at this pose stands for (dt at full rate, 20 ms for
        #    poses at 50 Hz): injection, derivative filter and adaptation all scale with it
        h = o.fmax(since, dt)
        w, w_next = self._augmented(o, w_raw), self._augmented(o, u[4:7])
        has_next, pose_next = u[0], u[1:4]
        e = has * o.vcat([pose[0] - x[0], pose[1] - x[2], pose[2] - x[4]])
        theta = has * pose[0] + (1 - has) * x[0]
        G = input_matrix(theta, p)
        S_mat = mx.as_matrix(o, S, 3, n)
        # 1. velocity error e_v = e' + K_pos e, e' from the filter xi' = (e - xi)/tau
        e_dot = (e - xi) / self.tau
        K_pos = self.K[[0, 2, 4], :]
        e_v = has * (e_dot + o.dot(K_pos, e))
        alpha = 1 - o.exp(-h / self.tau)
        xi_next = xi + has * alpha * (e - xi)
        # 2. normalised gradient on phi_1 (angular) and phi_2 (translational):
        #    phi_1' = gain I_G R^-1 w_hat e_theta',  [s_2, s_3]' = gain m R^-1 w_hat (R(theta)^T e_XY'),
        #    R a running mean of w_hat w_hat^T (time constant 2 s): the rate is free of I_G, m
        #    and of how well S is conditioned.
        gain = self.gamma * o.fmax(1.0 / (1.0 + t / self.t_decay), self.floor)   # 3. decaying gain
        R_mat = mx.as_matrix(o, R_flat, n)
        w_col = mx.col(w)
        R_next = R_mat + (1 - o.exp(-dt / _R_TIME)) * (o.dot(w_col, mx.row(w)) - R_mat)
        g_w = mx.vec(mx.regularised_solve(o, R_mat, w_col, n, rel=_R_REG, floor=0.0))   # R^-1 w_hat
        d_phi1 = gain * h * p.inertia * g_w * e_v[0]
        c, s = o.cos(theta), o.sin(theta)
        e_b = o.vcat([c * e_v[1] + s * e_v[2], -s * e_v[1] + c * e_v[2]])   # R(theta)^T e_v
        d_s2 = gain * h * p.mass * g_w * e_b[0]
        d_s3 = gain * h * p.mass * g_w * e_b[1]
        rho_x, rho_y = p.rho
        d_s1 = d_phi1 + rho_y * d_s2 - rho_x * d_s3      # S from phi, eqs. (4), (5)
        S_next = S + o.vcat([d_s1, d_s2, d_s3])
        # 4. exact double-integrator step, wrench interpolated over the step
        theta_pred = x[0] + dt * x[1]
        a0 = o.dot(G, o.dot(S_mat, w))
        a1 = o.dot(input_matrix(theta_pred, p), o.dot(S_mat, w_next))
        inj = o.dot(self.K, e)
        x_next = o.vcat([
            x[2 * i + j] + (dt * x[2 * i + 1] + dt * dt * (2 * a0[i] + a1[i]) / 6 if j == 0
                            else dt * (a0[i] + a1[i]) / 2)
            for i in range(3) for j in range(2)]) + h * inj
        return o.vcat([x_next, S_next, e_prev, pose_next, has_next, u[4:7], t + dt, xi_next, mx.flat(o, R_next),
                       dt + (1 - has) * since])

