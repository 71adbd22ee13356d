"""An adaptive observer at the information floor: eqs. (6)-(8) with filtered regressors and a least-squares gain.

The observer keeps the paper's structure: ``x_hat`` follows eqs. (6), (7),
propagated with ``G(theta) S_hat w_hat`` and corrected by an output injection
``K C e``; the adaptation acts on ``phi_1``, ``phi_2`` of eqs. (4), (5) with the
regressor of eq. (8), ``G(theta)^T . w_hat^T`` (the rows of ``B_1``, ``B_2``,
:func:`plant.regressors`). What changes is how the error and the
gain are formed (class docstring, numbered).

Why it reaches the floor. With both poles of each channel's observer at
``-lam``, the output error is the regressor passed through one stable
second-order filter, ``e = psi_f . phi_tilde + noise`` with
``psi_f = 1/(s + lam)^2 psi`` (Kreisselmeier's sensitivity filter
``Upsilon`` keeps this exact while ``phi_hat`` moves). Equivalently
``s^2/(s + lam)^2 y = psi_f . phi + noise``: the double integrator's signals
through one filter, no differentiated poses. A recursive least-squares fit
of that linear regression, without forgetting while ``S`` is constant,
averages the whole log as an offline fit would; the noise in the regressor
(the raw reading's) is filtered to a negligible bias.

Discrete form (as :mod:`observers.highgain`): the exact double-integrator
step with the regressor linear over the step; per pose, with ``h`` the time
since the previous pose,

    x^-           = Phi x_n + G_n phi_n          Upsilon^- = Phi Upsilon_n + G_n
    e             = y_{n+1} - C x^-               H = C Upsilon^-
    phi_{n+1}     = phi_n + P_{n+1} H^T e         (recursive least squares)
    Upsilon_{n+1} = (I - L_h C) Upsilon^-
    x_{n+1}       = x^- + L_h e + Upsilon_{n+1} (phi_{n+1} - phi_n)

with ``L_h`` placing the eigenvalues of ``(I - L_h C) Phi(h)`` at
``exp(-lam h)``.
"""

import numpy as np

from fmscal.plant import S_from_phi, phi_1, phi_2, regressors
from fmscal.plant._backend import ops
from fmscal.plant._checks import as_bool, as_positive_scalar
from fmscal.plant.errors import FmscalError

from . import _matrix as mx
from .base import RecursiveObserver
from .gains import double_pole_gains
from .highgain import discrete_gain
from .discretise import position_increment, velocity_increment
from .state import INPUT, StateLayout

__all__ = ["AdaptiveObserver", "DEFAULT_LAM", "GAINS"]

#: Default pole of each channel's observer (double), rad/s: the filter ``1/(s + lam)^2``.
DEFAULT_LAM = 5.0
#: Adaptation gains :class:`AdaptiveObserver` offers.
GAINS = ("least-squares", "gradient")
_PRIOR = 1e-3          # weight of the start S0, in samples' worth of information
_FLOOR = 1e-300
_DRIFT_WINDOWS = 20   # the drift statistic averages the windowed score over this many windows
_T_STEP = 0.05         # s, time constant of the forgetting while the step test fires


class AdaptiveObserver(RecursiveObserver):
    """Adaptive observer of eqs. (6)-(8) with filtered regressors and a least-squares gain.

    Module docstring for the equations. The changes from the paper's
    observer (:class:`observers.PaperAdaptiveObserver`), each switched by a
    setting so that :func:`analysis.ablation.ablation` measures them one by
    one:

    1. **Discrete observer, poles at -lam** (eqs. 6, 7, 14): the exact
       double-integrator step with the wrench linear over the step, and the
       injection gain ``L_h`` placing each channel's sampled poles at
       ``exp(-lam h)`` (both at ``-lam``), in place of forward Euler and the
       printed ``K_1``, ``K_2``.
    2. **Filtered regressor, position error** (eqs. 8, 15): the law is driven
       by the position error ``e`` and the regressor of eq. (8) passed through
       the observer's own error filter (Kreisselmeier's sensitivity filter
       ``Upsilon``, ``H = C Upsilon``), in place of velocity errors from
       differenced poses (eq. 15) and the raw regressor. The correction
       ``Upsilon dphi`` keeps ``e = H phi_tilde`` exact while ``phi_hat``
       moves. Without the least-squares gain (``gain="gradient"``) the step
       is the normalised gradient ``dphi = gamma h H^T e / |H|^2``
       (eq. 8's ``delta`` made scale-free).
    3. **Least-squares gain** (eq. 8's ``delta``): ``delta`` becomes the
       recursive least-squares covariance ``P`` of each parameter set, so
       the estimate is the least-squares fit of all poses so far
       (``gain="least-squares"``). ``P`` starts from a prior worth a
       thousandth of a sample; no noise model is needed (the innovations
       are weighted alike). ``phi_2`` is fitted from the X and Y errors
       together in complex form: eq. (1) rotates the force, so
       ``X + iY = zeta . (s_2 + i s_3)`` with ``zeta`` the filtered
       ``exp(i theta) w_hat / m``, and ``P`` is a 3x3 Hermitian matrix (the
       same fit as a 6x6 real one, for a quarter of the work).
    4. **Forgetting on evidence of change** (``track=True``; the paper's
       law has a constant gain and so never stops adapting): a change test
       per parameter set on the a priori errors, free of the noise's level
       and colour (:meth:`_change_test`): a t-statistic of the windowed
       score ``H^T e`` over ``20 window`` s (a persistent lag: drift) and the ratio of the
       innovation power over ``window / 4`` s to its mean over
       ``10 window`` s (a step). While the first exceeds ``threshold``
       (about 1 while ``S`` is constant), ``P`` grows at up to
       ``1/t_forget``; while the second exceeds ``step_ratio``, at up to
       1/(0.05 s); never beyond the covariance of ``memory`` s of poses.
       The fit forgets until the errors are consistent again: it follows
       the steps of Table 1 and a drifting ``S``, and on a constant ``S``
       stays (nearly) off.
    5. **Multi-rate poses**: where no pose arrives the observer and the
       filter only predict and nothing adapts; at a pose the gain ``L_h``
       and the test's averages use ``h``, the time since the previous pose.

    The discrete observer with the sensitivity filter is the one
    :class:`observers.HighGainObserver` reconstructs for [4]; what differs
    is the gain (least squares, change 3) and when it forgets (change 4).

    With ``offset=True`` each parameter set gains the offset column (the
    reading augmented by 1, :class:`observers.Observer`).

    Parameters
    ----------
    model : plant.PlanarModel or plant.Payload
        The planar problem (a payload stands for its planar model).
    lam : float
        Pole of each channel (double), rad/s: the bandwidth of the filter
        ``1/(s + lam)^2`` on the regressor (change 1, 2).
    gain : {"least-squares", "gradient"}
        Change 3 on or off.
    gamma : float
        Rate of the normalised gradient, 1/s (``gain="gradient"`` only).
    track : bool
        Change 4: forget on evidence of a change in ``S``.
    window : float
        Time constant of the change test's score average, s.
    threshold : float
        The drift statistic fires above this value (about 1 while ``S`` is
        constant).
    step_ratio : float
        The step statistic fires above this ratio of fast to slow
        innovation power.
    t_forget : float
        Shortest time constant of the forgetting on a drift, s.
    memory : float
        The forgetting never leaves less information than ``memory`` s of
        poses, s.
    offset : bool
        Also estimate the sensor's offset ``b`` (``result.b``).

    Examples
    --------
    >>> from fmscal.plant import PAPER_PAYLOAD, get_scenario
    >>> log, truth, _ = get_scenario("paper").with_(duration=2.0).generate(0)
    >>> AdaptiveObserver(PAPER_PAYLOAD).run(log, truth.S0).S_hat.shape
    (3, 3)
    """

    def __init__(self, model, lam=DEFAULT_LAM, gain="least-squares", gamma=1.0, track=True, window=1.0,
                 threshold=8.0, step_ratio=5.0, t_forget=0.05, memory=0.2, offset=False):
        self.lam = as_positive_scalar(lam, "lam")
        if gain not in GAINS:
            raise FmscalError(f"gain must be one of {', '.join(GAINS)}; got {gain!r}")
        self.gain = gain
        self.gamma = as_positive_scalar(gamma, "gamma")
        self.track = as_bool(track, "track")
        self.window = as_positive_scalar(window, "window")
        self.threshold = as_positive_scalar(threshold, "threshold")
        self.step_ratio = as_positive_scalar(step_ratio, "step_ratio")
        self.t_forget = as_positive_scalar(t_forget, "t_forget")
        self.memory = as_positive_scalar(memory, "memory")
        #: The continuous-time injection gains whose double poles at ``-lam`` the sampled gain
        #: ``L_h`` images (eqs. 6, 7, 14; ``fmscal check-gains --config adaptive``).
        self.K1, self.K2 = double_pole_gains(self.lam)
        super().__init__(model, offset=offset)

    name = "adaptive"
    models = ("planar",)        # eqs. (4)-(8): the paper's planar structure

    def _layout(self):
        # since: time from the last pose to sample n; scale: each parameter set's prior information;
        # ups_c, ups_s: the filtered cos(theta) w_hat / m and sin(theta) w_hat / m, from which both
        # translational regressors are made; Pre + i Pim: the translational covariance in complex form
        # (change 3); test1, test2: the averages of each parameter set's change test (_change_test)
        n = self.n_cols
        return StateLayout(("x", 6), ("S", 3 * n), ("since", 1), ("scale", 2), ("ups_t", 2 * n), ("ups_c", 2 * n),
                           ("ups_s", 2 * n), ("P1", n * n), ("Pre", n * n), ("Pim", n * n), ("test1", 4 * n + 2),
                           ("test2", 8 * n + 2))

    def _initial_state(self, S0, u):
        n = self.n_cols
        pose = u.pose
        # the size H = C Upsilon will have, |psi| / lam^2 (the filter's DC gain), sets the prior
        w = self._augmented(ops(u.w_hat), u.w_hat)
        psi_t, psi_x, psi_y = (np.array(v) for v in regressors(pose[0], w, self.payload))
        info = [max(psi_t @ psi_t / n, 1e-12) / self.lam ** 4,
                max((psi_x @ psi_x + psi_y @ psi_y) / (2 * n), 1e-12) / self.lam ** 4]
        test1, test2 = np.zeros(4 * n + 2), np.zeros(8 * n + 2)
        test1[3 * n:4 * n] = info[0]
        test2[6 * n:8 * n] = info[1]
        return self.state.pack(None, x=self.model.rest_state(pose), S=self._initial_S(S0),
                               since=0.0, scale=info, ups_t=np.zeros(2 * n), ups_c=np.zeros(2 * n),
                               ups_s=np.zeros(2 * n), P1=(np.eye(n) / (_PRIOR * info[0])).ravel(),
                               Pre=(np.eye(n) / (_PRIOR * info[1])).ravel(), Pim=np.zeros(n * n),
                               test1=test1, test2=test2)

    # --- the adaptation -------------------------------------------------------
    @staticmethod
    def _rls(P, h, e, k):
        """Recursive least squares, one measurement ``e = h . phi_tilde`` (change 3).

        Returns ``(d_phi, P_next)``; ``P`` a list of ``k`` rows.
        """
        Ph = [sum(P[i][j] * h[j] for j in range(k)) for i in range(k)]
        denom = 1.0 + sum(h[i] * Ph[i] for i in range(k))
        d_phi = [Ph[i] * e / denom for i in range(k)]
        return d_phi, [[P[i][j] - Ph[i] * Ph[j] / denom for j in range(k)] for i in range(k)]

    @staticmethod
    def _complex_rls(A, B, hc, hs, e_x, e_y, k):
        """Recursive least squares of ``phi_2`` from the X and Y errors together, in complex form.

        ``X + iY = zeta . (s_2 + i s_3)`` with ``zeta = hc + i hs`` (the
        filtered ``exp(i theta) w_hat / m``); ``P = A + iB`` Hermitian, ``A``
        symmetric and ``B`` antisymmetric (lists of ``k`` rows). With
        ``h = conj(zeta)``: ``g = P h / (1 + h^H P h)``, ``phi += g e``,
        ``P -= g (P h)^H``, the same as the real update on both rows.

        Returns
        -------
        d_s2, d_s3 : lists of k
        A_next, B_next : lists of k rows
        """
        hr, hi = hc, [-v for v in hs]
        pr = [sum(A[i][j] * hr[j] - B[i][j] * hi[j] for j in range(k)) for i in range(k)]
        pi = [sum(A[i][j] * hi[j] + B[i][j] * hr[j] for j in range(k)) for i in range(k)]
        denom = 1.0 + sum(hr[i] * pr[i] + hi[i] * pi[i] for i in range(k))
        d_s2 = [(pr[i] * e_x - pi[i] * e_y) / denom for i in range(k)]
        d_s3 = [(pr[i] * e_y + pi[i] * e_x) / denom for i in range(k)]
        A = [[A[i][j] - (pr[i] * pr[j] + pi[i] * pi[j]) / denom for j in range(k)] for i in range(k)]
        B = [[B[i][j] - (pi[i] * pr[j] - pr[i] * pi[j]) / denom for j in range(k)] for i in range(k)]
        return d_s2, d_s3, A, B

    def _gradient(self, rows, errors, k, step, scale):
        """Normalised gradient ``gamma h H^T e / |H|^2`` (change 2 without 3)."""
        num = [sum(h[i] * e for h, e in zip(rows, errors)) for i in range(k)]
        norm = sum(h[i] * h[i] for h in rows for i in range(k)) + 1e-6 * scale
        return [self.gamma * step * v / norm for v in num]

    def _change_test(self, o, rows, errors, state, alphas, k):
        """The change test of one parameter set (change 4): its averages and the forgetting rate.

        Two statistics, both free of the noise's level and colour:

        * drift: ``g``, the mean of ``H^T e`` per pose over ``window`` s (the
          score), is zero-mean while ``S_hat`` fits; its mean ``m`` and
          spread ``v`` over ``20 window`` s give a t-statistic per entry,
          ``20 m_j^2 / v_j`` (averaged over the entries), about 1 while ``S``
          is constant and growing with a persistent lag;
        * step: the innovation power over ``window / 4`` s against its
          mean over ``10 window`` s.

        Parameters
        ----------
        rows, errors : lists
            Regressor rows ``H`` and a priori errors (zero without a pose).
        state : vector, shape (4 k + 2,)
            ``[g, m, v, d, power_fast, power_slow]``; ``d`` the mean of
            ``diag(H^T H)`` per pose over ``window``.
        alphas : tuple of 4
            Weights of the new sample in the averages over ``window``,
            ``20 window``, ``10 window`` and ``window / 4`` (0 without a pose).

        Returns
        -------
        state : list of 4 k + 2
        rate : float or casadi.SX
            Forgetting rate, 1/s: up to ``1/t_forget`` as the drift
            statistic fires, plus up to ``1/0.05 s`` as the step statistic does.
        """
        n_rows = len(rows)
        a_w, a_drift, a_long, a_fast = alphas
        g, m, v, d = ([state[i * k + j] for j in range(k)] for i in range(4))
        fast, slow = state[4 * k], state[4 * k + 1]
        score = [sum(r[j] * e for r, e in zip(rows, errors)) / n_rows for j in range(k)]
        diag = [sum(r[j] * r[j] for r in rows) / n_rows for j in range(k)]
        power = sum(e * e for e in errors) / n_rows
        g = [g[j] + a_w * (score[j] - g[j]) for j in range(k)]
        m = [m[j] + a_drift * (g[j] - m[j]) for j in range(k)]
        v = [v[j] + a_drift * ((g[j] - m[j]) ** 2 - v[j]) for j in range(k)]
        d = [d[j] + a_w * (diag[j] - d[j]) for j in range(k)]
        fast = fast + a_fast * (power - fast)
        slow = slow + a_long * (power - slow)
        t2 = sum(m[j] * m[j] / (v[j] + _FLOOR) for j in range(k)) * _DRIFT_WINDOWS / k
        drift = o.fmin(o.fmax(t2 / self.threshold - 1, 0), 1)
        step = o.fmin(o.fmax(fast / (self.step_ratio * slow + _FLOOR) - 1, 0), 1)
        return g + m + v + d + [fast, slow], drift / self.t_forget + step / _T_STEP

    def _growth(self, o, trace, d, rate, h):
        """Factor on ``P`` while the change test fires (change 4), at most to ``memory``'s covariance.

        ``trace`` of ``P``; ``d`` the mean information per pose of each
        entry; ``h`` the time since the previous pose (0 without a pose).
        """
        cap = sum(1.0 / (d_i * self.memory + _FLOOR) for d_i in d) * h
        return o.fmin(o.exp(h * rate), o.fmax(cap / (trace + _FLOOR), 1.0))

    def _transition(self, z, u_prev, u, dt):
        """One step (module docstring), the class docstring's changes 1-5."""
        o = ops(z, u)
        p, n = self.payload, self.n_cols
        st, now, nxt = self.state.unpack(z), INPUT.unpack(u_prev), INPUT.unpack(u)
        x, S, pose, has = st.x, st.S, now.pose, now.has_pose
        since, scale = st.since, st.scale
        w = self._augmented(o, now.w_hat)
        has_next, pose_next, w_next = nxt.has_pose, nxt.pose, self._augmented(o, nxt.w_hat)
        phi1 = phi_1(S, p)                      # eq. (4)
        phi2 = phi_2(S)                         # eq. (5): rows 2, 3 of [S | c]
        s2, s3 = phi2[:n], phi2[n:]
        # 1. regressors of eq. (8) at both ends of the step (rows of B_1, B_2), linear over it;
        #    the angle at n is the measured one where there is one. Eq. (1) rotates the force:
        #    psi_X = [c, -s] and psi_Y = [s, c] with c = cos(theta) w_hat / m, s = sin(theta) w_hat / m,
        #    so three filtered vectors carry all three regressors.
        theta = has * pose[0] + (1 - has) * x[0]
        psi0 = regressors(theta, w, p)
        psi1 = regressors(x[0] + dt * x[1], w_next, p)
        bases = [(psi0[0], psi1[0]), (psi0[1][:n], psi1[1][:n]), (psi0[2][:n], psi1[2][:n])]   # theta, c, s
        ups = [st.ups_t, st.ups_c, st.ups_s]
        g_p, g_v, ups_pred = [], [], []
        for (b0, b1), up in zip(bases, ups):
            g_p.append([position_increment(dt, b0[j], b1[j]) for j in range(n)])
            g_v.append([velocity_increment(dt, b0[j], b1[j]) for j in range(n)])
            ups_pred.append([[up[j] + dt * up[n + j] + g_p[-1][j] for j in range(n)],
                             [up[n + j] + g_v[-1][j] for j in range(n)]])
        dot = lambda a, b: sum(a[j] * b[j] for j in range(n))
        # eqs. (6), (7): x_hat propagated with G(theta) S_hat w_hat (= B_1 phi_1, B_2 phi_2)
        push = [(dot(g_p[0], phi1), dot(g_v[0], phi1)),
                (dot(g_p[1], s2) - dot(g_p[2], s3), dot(g_v[1], s2) - dot(g_v[2], s3)),
                (dot(g_p[2], s2) + dot(g_p[1], s3), dot(g_v[2], s2) + dot(g_v[1], s3))]
        x_pred = [[x[2 * c] + dt * x[2 * c + 1] + push[c][0], x[2 * c + 1] + push[c][1]] for c in range(3)]
        # a priori position errors at n+1 (true minus estimate), zero without a pose
        e = [has_next * (pose_next[c] - x_pred[c][0]) for c in range(3)]
        # 2. the filtered regressors C Upsilon^- (zero without a pose)
        h_t, h_c, h_s = ([has_next * v for v in up[0]] for up in ups_pred)
        rows_t, rows_xy = [h_t], [h_c + [-v for v in h_s], h_s + h_c]
        P1 = [[st.P1[n * i + j] for j in range(n)] for i in range(n)]
        A = [[st.Pre[n * i + j] for j in range(n)] for i in range(n)]
        B = [[st.Pim[n * i + j] for j in range(n)] for i in range(n)]
        h = since + dt                            # 5. time since the previous pose
        if self.gain == "least-squares":          # 3. recursive least squares
            d_phi1, P1 = self._rls(P1, h_t, e[0], n)
            d_s2, d_s3, A, B = self._complex_rls(A, B, h_c, h_s, e[1], e[2], n)
            d_phi2 = d_s2 + d_s3
        else:
            d_phi1 = self._gradient(rows_t, e[0:1], n, has_next * h, scale[0])
            d_phi2 = self._gradient(rows_xy, e[1:3], 2 * n, has_next * h, scale[1])
            d_s2, d_s3 = d_phi2[:n], d_phi2[n:]
        # 4. the change test, and forgetting while it fires (off: the test's averages stay put)
        test1, test2 = st.test1, st.test2
        if self.track:
            hp = has_next * h
            alphas = [1 - o.exp(-hp / tau) for tau in (self.window, _DRIFT_WINDOWS * self.window, 10 * self.window,
                                                         self.window / 4)]
            test1, rate1 = self._change_test(o, rows_t, e[0:1], test1, alphas, n)
            test2, rate2 = self._change_test(o, rows_xy, e[1:3], test2, alphas, 2 * n)
            f1 = self._growth(o, sum(P1[i][i] for i in range(n)), test1[3 * n:4 * n], rate1, hp)
            f2 = self._growth(o, 2 * sum(A[i][i] for i in range(n)), test2[6 * n:8 * n], rate2, hp)
            P1 = [[f1 * v for v in r] for r in P1]
            A = [[f2 * v for v in r] for r in A]
            B = [[f2 * v for v in r] for r in B]
            test1, test2 = o.vcat(test1), o.vcat(test2)
        # 1. correction: Upsilon_n+1 = (I - L_h C) Upsilon^-, x_n+1 = x^- + L_h e + Upsilon_n+1 d_phi
        l1, l2 = discrete_gain(o, self.lam, h)
        l1, l2 = has_next * l1, has_next * l2
        new = [[[(1 - l1) * up[0][j] for j in range(n)], [up[1][j] - l2 * up[0][j] for j in range(n)]]
               for up in ups_pred]
        shift = [[dot(new[0][r], d_phi1) for r in range(2)],
                 [dot(new[1][r], d_s2) - dot(new[2][r], d_s3) for r in range(2)],
                 [dot(new[2][r], d_s2) + dot(new[1][r], d_s3) for r in range(2)]]
        x_next = []
        for c in range(3):
            x_next += [x_pred[c][0] + l1 * e[c] + shift[c][0], x_pred[c][1] + l2 * e[c] + shift[c][1]]
        S_next = mx.flat(o, S_from_phi(phi1 + o.vcat(d_phi1), phi2 + o.vcat(d_phi2), p))
        flat = lambda M: o.vcat([v for r in M for v in r])
        return self.state.pack(o, x=o.vcat(x_next), S=S_next, since=(1 - has_next) * h, scale=scale,
                               ups_t=o.vcat(new[0][0] + new[0][1]), ups_c=o.vcat(new[1][0] + new[1][1]),
                               ups_s=o.vcat(new[2][0] + new[2][1]), P1=flat(P1), Pre=flat(A), Pim=flat(B),
                               test1=test1, test2=test2)
