"""High-gain adaptive observer after Parsa and Aghili (ICRA 2006): a reconstruction.

The full text of [4] is not at hand (``docs/paper/reading-the-paper.md``). What is known of it: two
observers, angular and translational, on the state-affine form of eqs. (4),
(5); a high gain; an adaptation gain that must be tuned; slow convergence.
This module reconstructs it as the standard adaptive observer for state-affine
(linear time-varying) systems with a sensitivity (Kreisselmeier) filter,
Q. Zhang, IEEE TAC 47(3), 2002. For each subsystem ``i = 1, 2`` with
``x_i' = A_i x_i + B_i(w_hat, theta) phi_i``, ``y_i = C_i x_i``::

    Upsilon_i' = (A_i - K_i C_i) Upsilon_i + B_i                          (sensitivity filter)
    phi_i'     = Gamma_i Upsilon_i^T C_i^T (y_i - C_i x_i)                (adaptation)
    x_i'       = A_i x_i + B_i phi_i + K_i (y_i - C_i x_i) + Upsilon_i phi_i'

``epsilon = x_tilde - Upsilon phi_tilde`` then obeys ``epsilon' = (A - K C)
epsilon``, so the output error is ``C Upsilon phi_tilde`` plus a decaying
term: the law needs only the position error, no velocity error (which is what
makes it rigorous where eq. (8) is not, ``docs/paper/reading-the-paper.md``).

Discrete form. A sampled high-gain observer that integrates ``K y`` turns the
integration error of each step into an estimation bias that grows as
``lam^2``; this module uses the discrete observer whose error recursion is
exact instead (Zhang's observer written for the sampled system). Per step,
with ``G_n`` the input map of ``phi`` over the step::

    x^-         = Phi x_n + G_n phi_n           Upsilon^- = Phi Upsilon_n + G_n
    e           = y_{n+1} - C x^-               H = C Upsilon^-
    phi_{n+1}   = phi_n + Gamma H^T e
    Upsilon_{n+1} = (I - L C) Upsilon^-
    x_{n+1}     = x^- + L e + Upsilon_{n+1} (phi_{n+1} - phi_n)

so that ``epsilon = x_tilde - Upsilon phi_tilde`` obeys
``epsilon_{n+1} = (I - L C) Phi epsilon_n``, and ``L`` places the
eigenvalues of ``(I - L C) Phi`` at ``exp(-lam dt)``, the image of the
continuous double pole at ``-lam``.
"""

import numpy as np

from fmscal.plant import S_from_phi, phi_1, phi_2, regressors
from fmscal.plant.numerics import FmscalError, as_positive_scalar, ops

from fmscal.observers.core import (INPUT, RecursiveObserver, StateLayout, double_pole_gains, matrix as mx,
                                   position_increment, velocity_increment)

__all__ = ["HighGainObserver", "DEFAULT_HIGH_GAIN", "REF4_HIGH_GAIN"]

#: Default high-gain parameter: both poles of each channel at -lambda, rad/s.
DEFAULT_HIGH_GAIN = 20.0
#: The configuration read from the seed paper's account of [4]: a high gain.
REF4_HIGH_GAIN = 100.0
_R_TIME = 2.0        # s, averaging time of the regressor's outer product
_R_REG = 1e-3        # regularisation of the normalisation, relative to its mean eigenvalue
_R_FLOOR = 1e-12



def discrete_gain(o, lam, dt):
    """Gain ``L`` of one channel ``[p, v]``, sampled, with a position measurement.

    For ``Phi = [[1, dt], [0, 1]]`` and ``C = [1, 0]``, the error matrix
    ``(I - L C) Phi`` has trace ``2 - l_1 - l_2 dt`` and determinant
    ``1 - l_1``; a double eigenvalue at ``r = exp(-lam dt)`` (the continuous
    double pole at ``-lam``, :func:`observers.double_pole_gains`) needs
    ``l_1 = 1 - r^2`` and ``l_2 = (1 - r)^2 / dt``.

    Parameters
    ----------
    o : ops namespace
    lam : float
        Pole magnitude, rad/s.
    dt : float or casadi.SX
        Step, s.

    Returns
    -------
    l_1 : dimensionless, l_2 : 1/s
    """
    r = o.exp(-lam * dt)
    return 1 - r * r, (1 - r) ** 2 / dt


class HighGainObserver(RecursiveObserver):
    """The high-gain adaptive observer of Parsa and Aghili [4]: a reconstruction.

    Two observers, angular (``phi_1`` of eq. 4, 3 parameters) and
    translational (``phi_2`` of eq. 5, 6 parameters), each a Kreisselmeier
    sensitivity filter and a Luenberger gain with both poles of each channel
    at ``-lam`` (:func:`observers.double_pole_gains`), as in Zhang (2002);
    module docstring for the equations. ``S_hat`` is recovered from
    ``phi_1, phi_2`` by :func:`plant.S_from_phi`.

    Tuning rule, in one sentence: put the poles at ``-lam``, about twice the
    fastest frequency in the regressor (``lam = 20`` rad/s for the paper's
    wrench, whose fastest component is 10 rad/s), and set the adaptation gain to
    ``gamma`` times the inverse of the running mean of
    ``(C Upsilon)^T (C Upsilon)``, so that every direction of ``phi``
    converges at about ``gamma`` 1/s whatever the payload and the
    conditioning of ``S``; ``gamma`` decays as ``1/(1 + t/t_decay)`` to a
    floor to average the noise out.

    Two configurations:

    * the default (``high-gain``): the rule above;
    * :meth:`ref4` (``high-gain-ref4``): the seed paper's account of [4] as
      closely as it can be read: a high gain (``lam = 100``), and a scalar
      adaptation gain normalised by the mean of ``|C Upsilon|^2``
      (``normalisation="scalar"``), constant in time, which must be tuned and
      converges slowly along the weakly excited directions.

    Sampled form (module docstring): the discrete observer whose error
    recursion is exact, with ``L`` (:func:`discrete_gain`) the sampled image
    of ``K``; the regressor is taken linear over each step. Where no pose
    arrives the step only predicts and nothing adapts.

    Parameters
    ----------
    model : plant.PlanarModel or plant.Payload
        The planar problem (a payload stands for its planar model).
    lam : float
        High-gain parameter, rad/s: poles of ``A_i - K_i C_i`` at ``-lam``.
    gamma : float
        Adaptation rate, 1/s (with ``normalisation="matrix"``, the rate of
        every direction; with ``"scalar"``, of the average direction).
    normalisation : {"matrix", "scalar"}
        ``Gamma = gamma R^-1`` or ``Gamma = gamma n / trace(R)``, ``R`` the
        running mean (2 s) of ``(C Upsilon)^T (C Upsilon)``, ``n`` its size.
    t_decay : float or None
        Time over which the gain halves, s; None keeps it constant.
    floor : float
        The gain never falls below ``floor * gamma``.
    offset : bool
        Also estimate the sensor's offset ``b`` (``result.b``): ``phi_1``,
        ``phi_2`` gain the offset column (the reading augmented by a
        constant 1, :class:`observers.Observer`). Off by default.

    Examples
    --------
    >>> from fmscal.plant import PAPER_PAYLOAD, get_scenario
    >>> log, truth, _ = get_scenario("paper").with_(duration=2.0).generate(0)
    >>> HighGainObserver(PAPER_PAYLOAD).run(log, truth.S0).S_hat.shape
    (3, 3)
    """

    paper_equations_only = True        # [4] is planar by definition

    def __init__(self, model, lam=DEFAULT_HIGH_GAIN, gamma=1.0, normalisation="matrix",
                 t_decay=20.0, floor=0.1, name="high-gain", offset=False):
        self.lam = as_positive_scalar(lam, "lam")
        self.gamma = as_positive_scalar(gamma, "gamma")
        if normalisation not in ("matrix", "scalar"):
            raise FmscalError(f"normalisation must be 'matrix' or 'scalar'; got {normalisation!r}")
        self.normalisation = normalisation
        self.t_decay = None if t_decay is None else as_positive_scalar(t_decay, "t_decay")
        self.floor = as_positive_scalar(floor, "floor")
        self.name = str(name)
        self.K1, self.K2 = double_pole_gains(self.lam)
        super().__init__(model, offset=offset)

    #: The configuration closest to the seed paper's account of [4] (``high-gain-ref4``).
    REF4_SETTINGS = {"lam": REF4_HIGH_GAIN, "gamma": 1.0, "normalisation": "scalar", "t_decay": None,
                     "name": "high-gain-ref4"}

    @classmethod
    def ref4(cls, model, **overrides):
        """The configuration closest to the seed paper's account of [4] (``high-gain-ref4``).

        ``overrides`` change single settings (keywords of the constructor).
        """
        return cls(model, **{**cls.REF4_SETTINGS, **overrides})

    def _layout(self):
        # t: time since the start (gain decay); ups_*: the sensitivity filters Upsilon of the
        # theta, X and Y channels (2 x n, 2 x 2n, 2 x 2n, row order); R1, R2: running means
        # of H^T H of the angular and translational laws
        n = self.n_cols
        return StateLayout(("x", 6), ("S", 3 * n), ("t", 1), ("ups_t", 2 * n), ("ups_x", 4 * n),
                           ("ups_y", 4 * n), ("R1", n * n), ("R2", 4 * n * n))

    def _initial_state(self, S0, u):
        n = self.n_cols
        x = self.model.rest_state(u.pose)
        # R starts isotropic at the size C Upsilon will have, |psi| / lam^2 (the filter's DC gain)
        w = self._augmented(ops(u.w_hat), u.w_hat)
        psi_t, psi_x, psi_y = (np.array(v) for v in regressors(u.pose[0], w, self.payload))
        R1 = np.eye(n) * max(psi_t @ psi_t / n, _R_FLOOR) / self.lam ** 4
        R2 = np.eye(2 * n) * max((psi_x @ psi_x + psi_y @ psi_y) / (2 * n), _R_FLOOR) / self.lam ** 4
        return self.state.pack(None, x=x, S=self._initial_S(S0), t=0.0, ups_t=np.zeros(2 * n),
                               ups_x=np.zeros(4 * n), ups_y=np.zeros(4 * n), R1=R1.ravel(), R2=R2.ravel())

    def _gain(self, o, t):
        if self.t_decay is None:
            return self.gamma
        return self.gamma * o.fmax(1.0 / (1.0 + t / self.t_decay), self.floor)

    def _normalised(self, o, R_mean, H_T_e, n):
        """``Gamma H^T e / gamma`` of the adaptation law, per :attr:`normalisation`."""
        if self.normalisation == "matrix":
            return mx.vec(mx.regularised_solve(o, R_mean, H_T_e, n, rel=_R_REG, floor=_R_FLOOR))
        trace = sum(R_mean[i, i] for i in range(n))
        return mx.vec(H_T_e) * (n / (trace + _R_FLOOR))

    def _transition(self, z, u_prev, u, dt):
        """One step of the sampled observer (module docstring)."""
        o = ops(z, u)
        p, n = self.payload, self.n_cols
        s, now, nxt = self.state.unpack(z), INPUT.unpack(u_prev), INPUT.unpack(u)
        x, S, pose, has, t = s.x, s.S, now.pose, now.has_pose, s.t
        w = self._augmented(o, now.w_hat)
        has_next, pose_next, w_next = nxt.has_pose, nxt.pose, self._augmented(o, nxt.w_hat)
        ups = [mx.as_matrix(o, s.ups_t, 2, n), mx.as_matrix(o, s.ups_x, 2, 2 * n),
               mx.as_matrix(o, s.ups_y, 2, 2 * n)]
        R1, R2 = mx.as_matrix(o, s.R1, n), mx.as_matrix(o, s.R2, 2 * n)
        # the parameters of eqs. (4), (5): phi_1 = [1, -rho_y, rho_x] S, phi_2 = rows 2, 3 of S
        # (each row with its offset entry when the offset is estimated)
        phi1 = phi_1(S, p)
        phi2 = phi_2(S)
        phis = [phi1, phi2, phi2]
        # regressors of eqs. (4), (5) at both ends of the step; the angle at n is the
        # measured one where there is one, at n+1 the prediction
        theta = has * pose[0] + (1 - has) * x[0]
        psi0 = regressors(theta, w, p)
        psi1 = regressors(x[0] + dt * x[1], w_next, p)
        # prediction: exact double integrator, the regressor linear over the step, so
        # G_n = [dt^2 (2 psi_n + psi_n+1) / 6, dt (psi_n + psi_n+1) / 2] for each channel
        x_pred, ups_pred, H = [], [], []
        for c in range(3):
            n_par = len(psi0[c])
            g_p = [position_increment(dt, psi0[c][j], psi1[c][j]) for j in range(n_par)]
            g_v = [velocity_increment(dt, psi0[c][j], psi1[c][j]) for j in range(n_par)]
            phi = phis[c]
            pos, vel = x[2 * c], x[2 * c + 1]
            x_pred.append([pos + dt * vel + sum(g_p[j] * phi[j] for j in range(n_par)),
                           vel + sum(g_v[j] * phi[j] for j in range(n_par))])
            ups_pred.append([[ups[c][0, j] + dt * ups[c][1, j] + g_p[j] for j in range(n_par)],
                             [ups[c][1, j] + g_v[j] for j in range(n_par)]])
            H.append(ups_pred[c][0])                                     # C Upsilon^-
        # a priori output errors at n+1 (true minus estimate), zero without a pose
        e = [has_next * (pose_next[c] - x_pred[c][0]) for c in range(3)]
        # adaptation: phi_i += Gamma_i H_i^T e_i, Gamma_i normalised by the running mean of H_i^T H_i
        alpha = has_next * (1 - o.exp(-dt / _R_TIME))
        H1 = o.matrix([H[0]])
        H2 = o.matrix([H[1], H[2]])
        R1_next = R1 + alpha * (o.dot(H1.T, H1) - R1)
        R2_next = R2 + alpha * (o.dot(H2.T, H2) - R2)
        gain = self._gain(o, t)
        d_phi1 = gain * dt * self._normalised(o, R1_next, o.dot(H1.T, mx.col(o.vcat(e[0:1]))), n)
        d_phi2 = gain * dt * self._normalised(o, R2_next, o.dot(H2.T, mx.col(o.vcat(e[1:3]))), 2 * n)
        d_phis = [d_phi1, d_phi2, d_phi2]
        # correction: Upsilon_n+1 = (I - L C) Upsilon^-, x_n+1 = x^- + L e + Upsilon_n+1 d_phi
        l1, l2 = discrete_gain(o, self.lam, dt)
        l1, l2 = has_next * l1, has_next * l2
        x_next, ups_next = [], []
        for c in range(3):
            n_par = len(psi0[c])
            up = ups_pred[c]
            new = [[(1 - l1) * up[0][j] for j in range(n_par)],
                   [up[1][j] - l2 * up[0][j] for j in range(n_par)]]
            shift = [sum(new[i][j] * d_phis[c][j] for j in range(n_par)) for i in range(2)]
            x_next += [x_pred[c][0] + l1 * e[c] + shift[0], x_pred[c][1] + l2 * e[c] + shift[1]]
            ups_next += new[0] + new[1]
        S_next = mx.flat(o, S_from_phi(phi1 + d_phi1, phi2 + d_phi2, p))
        return self.state.pack(o, x=o.vcat(x_next), S=S_next, t=t + dt, ups_t=o.vcat(ups_next[:2 * n]),
                               ups_x=o.vcat(ups_next[2 * n:6 * n]), ups_y=o.vcat(ups_next[6 * n:]),
                               R1=mx.flat(o, R1_next), R2=mx.flat(o, R2_next))
