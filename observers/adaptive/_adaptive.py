"""An adaptive observer at the information floor: eqs. (6)-(8) with filtered regressors and a least-squares gain.

The observer keeps the paper's structure, written for any model linear in its
channels (:attr:`fmscal.plant.Model.linear_channels`; on a unit-quaternion
attitude the same class runs the law of :mod:`observers.adaptive._spatial` on
the momenta about the centre of mass): each velocity channel
``c`` is a double integrator of its position (a configuration entry, which the
pose measures) driven by ``a_c = psi_c(q, w_hat) . phi_g``, ``phi_g`` the
parameters of the channel's group (:meth:`fmscal.plant.Model.parameter_groups`,
:meth:`fmscal.plant.Model.channel_regressor_rows`). For the planar model these
are eqs. (4), (5): ``phi_1`` drives ``theta``, ``phi_2`` drives ``X`` and ``Y``,
with the regressor of eq. (8), ``G(theta)^T . w_hat^T`` (the rows of ``B_1``,
``B_2``, :func:`plant.regressors`). ``x_hat`` follows eqs. (6), (7), propagated
with ``A(q) S_hat w_hat`` (planar: ``G(theta) S_hat w_hat``) and corrected by an
output injection ``K C e``; the adaptation acts on the groups' parameters.
What changes from the paper is how the error and the gain are formed (class
docstring, numbered).

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

Discrete form (as :mod:`observers.adaptive._highgain`): the exact double-integrator
step with the regressor linear over the step (:mod:`observers.core._discretise`);
per channel and pose, with ``h`` the time since the previous pose,

    x^-           = Phi x_n + G_n phi_n          Upsilon^- = Phi Upsilon_n + G_n
    e             = y_{n+1} - C x^-               H = C Upsilon^-
    phi_{n+1}     = phi_n + P_{n+1} H^T e         (recursive least squares)
    Upsilon_{n+1} = (I - L_h C) Upsilon^-
    x_{n+1}       = x^- + L_h e + Upsilon_{n+1} (phi_{n+1} - phi_n)

with ``L_h`` placing the eigenvalues of ``(I - L_h C) Phi(h)`` at
``exp(-lam h)``; ``S_hat`` is ``[S | c]`` of the groups' ``phi``
(:meth:`fmscal.plant.Model.params_from_phi`; planar: :func:`plant.S_from_phi`).
"""

import numpy as np

from fmscal.plant.numerics import FmscalError, as_bool, as_positive_scalar, ops
from fmscal.plant.physics import as_model, rotation_matrix

from fmscal.observers.core import (RecursiveObserver, StateLayout, double_pole_gains, matrix as mx, position_increment,
                                   velocity_increment)
from ._highgain import discrete_gain
from ._spatial import SPATIAL_LAM, WARM_UP

__all__ = ["AdaptiveObserver", "SpatialAdaptiveObserver", "DEFAULT_LAM", "GAINS"]

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

    Module docstring for the equations. It runs on any model linear in its
    channels (:attr:`fmscal.plant.Model.linear_channels`: the planar model,
    the tests' rail) and takes every size and layout from it: the motion
    state (``nx``), one channel per velocity (``nv``), one parameter set
    ``phi_g`` per group of :meth:`fmscal.plant.Model.parameter_groups`
    (planar: ``phi_1`` of eq. (4), ``phi_2`` of eq. (5)). On a model whose
    attitude is a unit quaternion (:attr:`fmscal.plant.Model.attitude`, a
    body in 3D) the same class runs the law on the momenta about the centre
    of mass (:mod:`observers.adaptive._spatial`), from the pieces
    :class:`fmscal.plant.SpatialModel` declares for it (``momentum_*``,
    ``world_*``, ``turn``): two parameter groups, the torque about ``C`` and
    the force, with the same adaptation (changes 3-5). The changes from
    the paper's observer (:class:`observers.PaperAdaptiveObserver`), each
    switched by a setting so that :func:`analysis._ablation`
    measures them one by one:

    1. **Discrete observer, poles at -lam** (eqs. 6, 7, 14): the exact
       double-integrator step with the wrench linear over the step, and the
       injection gain ``L_h`` placing each channel's sampled poles at
       ``exp(-lam h)`` (both at ``-lam``), in place of forward Euler and the
       printed ``K_1``, ``K_2``.
    2. **Filtered regressor, position error** (eqs. 8, 15): the law is driven
       by the position error ``e`` and the regressor of eq. (8) passed through
       the observer's own error filter (Kreisselmeier's sensitivity filter
       ``Upsilon``, one per channel, ``H = C Upsilon``), in place of velocity
       errors from differenced poses (eq. 15) and the raw regressor. The
       correction ``Upsilon dphi`` keeps ``e = H phi_tilde`` exact while
       ``phi_hat`` moves. Without the least-squares gain (``gain="gradient"``)
       the step is the normalised gradient ``dphi = gamma h H^T e / |H|^2``
       (eq. 8's ``delta`` made scale-free).
    3. **Least-squares gain** (eq. 8's ``delta``): ``delta`` becomes the
       recursive least-squares covariance ``P`` of each parameter set, so
       the estimate is the least-squares fit of all poses so far
       (``gain="least-squares"``). The channels of one group update it in
       turn (:meth:`_group_rls`; planar: ``phi_2`` from the X error, then
       the Y error), the same fit as both rows at once. ``P`` starts from a
       prior worth a thousandth of a sample; no noise model is needed (the
       innovations are weighted alike). (Planar ``phi_2`` could also be
       fitted in complex form, ``X + iY = zeta . (s_2 + i s_3)`` with a 3x3
       Hermitian ``P``: the same fit, which earlier releases used. The real
       6x6 form costs a little more per step, for one code path for every
       model; the two estimates differ by rounding. The step's cost:
       ``fmscal bench``, docs/speed.md.)
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
    model : plant.Model or plant.Payload
        The problem, a model with :attr:`fmscal.plant.Model.linear_channels`
        (a payload stands for its case's model; the planar one).
    lam : float or None
        Pole of each channel (double), rad/s: the bandwidth of the filter
        ``1/(s + lam)^2`` on the regressor (change 1, 2). None: the
        engine's :attr:`default_lam`, :data:`DEFAULT_LAM` (5) on a model
        linear in its channels, :data:`observers.adaptive._spatial.SPATIAL_LAM`
        (20) on a unit-quaternion attitude (the name the registry builds
        there, :class:`SpatialAdaptiveObserver`, carries only this default).
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

    Raises
    ------
    FmscalError
        A model that is not linear in its channels and has no unit-quaternion
        attitude, or a bad setting.

    Examples
    --------
    >>> from fmscal.plant import PAPER_PAYLOAD, get_scenario
    >>> log, truth, _ = get_scenario("paper").with_(duration=2.0).generate(0)
    >>> AdaptiveObserver(PAPER_PAYLOAD).run(log, truth.S0).S_hat.shape
    (3, 3)
    """

    name = "adaptive"
    #: The pole of each channel (double) where ``lam`` is None, rad/s.
    default_lam = DEFAULT_LAM

    @classmethod
    def _refusal(cls, model):
        """None on a model linear in its channels or with a unit-quaternion attitude (the law on the momenta
        about the centre of mass); else why not, in one line."""
        if model.linear_channels or model.attitude == "quaternion":
            return super()._refusal(model)
        return (f"{cls.__name__} needs a model linear in its channels or the spatial model; "
                f"it does not run on a {model.name} model")

    def __init__(self, model, lam=None, gain="least-squares", gamma=1.0, track=True, window=1.0,
                 threshold=8.0, step_ratio=5.0, t_forget=0.05, memory=0.2, offset=False):
        model = as_model(model, type(self).__name__)
        refusal = self.refusal(model)
        if refusal is not None:                  # before the layouts below read the model's channels
            raise FmscalError(refusal)
        if lam is None:
            lam = self.default_lam
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
        #: ``L_h`` images (eqs. 6, 7, 14; ``fmscal check-gains --config adaptive``): ``K1`` of each
        #: channel, ``K2`` the planar translational pair.
        self.K1, self.K2 = double_pole_gains(self.lam)
        super().__init__(model, offset=offset)

    # --- the structure, from the model ------------------------------------------------------
    def _groups(self):
        """Each parameter group of the model: its channels and its parameter count ``k``.

        Linear channels: :meth:`fmscal.plant.Model.parameter_groups`; a body in 3D: the momenta's two groups
        of ``3 n`` (:meth:`fmscal.plant.SpatialModel.momentum_groups`, the torque about ``C`` and the force).
        """
        model = self.model
        if not model.linear_channels:
            return [(list(channels), 3 * self.n_cols) for channels in model.momentum_groups()]
        rows = model.channel_regressor_rows(np.zeros(model.nq), np.ones(self.n_cols))
        return [(list(channels), len(rows[channels[0]])) for channels in model.parameter_groups()]

    def _filter_parts(self):
        """The packed state's parts between ``scale`` and the covariances.

        Linear channels: ``ups<c>``, channel ``c``'s sensitivity filter ``Upsilon`` (position row, velocity
        row: 2 x k of its group). A body in 3D: the motion about ``C`` and the law's four filters
        (:mod:`observers.adaptive._spatial`); ``chi`` is the observer's turn (the integral of its world rate),
        ``chi_ref`` the measured turn at the last pose (``q_ref``), ``chi_pose`` the observer's turn just
        after that pose's correction.
        """
        if not self.model.linear_channels:
            k = 3 * self.n_cols
            return [("age", 1), ("y", 3), ("l", 3), ("chi", 3), ("chi_ref", 3), ("chi_pose", 3), ("q_ref", 4),
                    ("H", 3), ("ups_y", 3 * k), ("ups_l", 3 * k), ("ups_d", 3 * k), ("ups_H", 3 * k)]
        return [(f"ups{c}", 2 * k) for channels, k in self._structure for c in channels]

    def _layout(self):
        # called once by RecursiveObserver.__init__: the groups' structure is read from the model here.
        # since: time from the last pose to sample n; scale: each parameter group's prior information;
        # the filters (_filter_parts); P<g>: group g's covariance (k x k, change 3; its upper triangle,
        # row order); test<g>: the averages of its change test (_change_test)
        self._structure = self._groups()
        parts = [("x", self.model.nx), ("S", self.n_w * self.n_cols), ("since", 1), ("scale", len(self._structure))]
        parts += self._filter_parts()
        parts += [(f"P{g}", k * (k + 1) // 2) for g, (_, k) in enumerate(self._structure)]     # upper triangle
        parts += [(f"test{g}", 4 * k + 2) for g, (_, k) in enumerate(self._structure)]
        return StateLayout(*parts)

    def _initial_state(self, S0, u):
        model = self.model
        pose, w_hat = np.atleast_1d(u.pose), np.atleast_1d(u.w_hat)
        # the size H = C Upsilon will have, |psi| / lam^2 (the filter's DC gain), sets the prior
        w = self._augmented(ops(w_hat), w_hat)
        parts, info = (self._channels_start if model.linear_channels else self._momenta_start)(pose, w)
        for g, (_, k) in enumerate(self._structure):
            parts[f"P{g}"] = np.array(mx.upper(np.eye(k) / (_PRIOR * info[g])))
            parts[f"test{g}"] = np.zeros(4 * k + 2)
            parts[f"test{g}"][3 * k:4 * k] = info[g]
        return self.state.pack(None, x=model.rest_state(pose), S=self._initial_S(S0), since=0.0, scale=info,
                               **parts)

    def _channels_start(self, pose, w):
        """Linear channels at rest at the first pose: the filters, and each group's prior information
        ``|psi|^2 / k / lam^4`` (the size of ``H = C Upsilon``)."""
        psi = [np.array(row, dtype=float) for row in self.model.channel_regressor_rows(pose, w)]
        parts, info = {}, []
        for channels, k in self._structure:
            info.append(max(sum(psi[c] @ psi[c] for c in channels) / k, 1e-12) / self.lam ** 4)
            parts.update({f"ups{c}": np.zeros(2 * k) for c in channels})
        return parts, info

    def _momenta_start(self, pose, w):
        """The motion about ``C`` at rest at the first pose, and each group's prior information
        ``|Psi|^2 / k / lam^4``; the attitude's rows carry ``I_W^-1`` too (``trace(I_c^-2) / 3``)."""
        model = self.model
        q = pose[:4] / np.linalg.norm(pose[:4])
        psi = model.momentum_regressor(rotation_matrix(q), w)
        k = 3 * self.n_cols
        base = max(float(np.sum(psi * psi)) / k, 1e-12) / self.lam ** 4
        K = self.payload.I_c_inv
        info = [base * float(np.trace(K @ K)) / 3, base]
        parts = {"age": 0.0, "y": model.centre_of_mass_momentum(np.r_[q, pose[4:]]), "l": np.zeros(3),
                 "chi": np.zeros(3), "chi_ref": np.zeros(3), "chi_pose": np.zeros(3), "q_ref": q, "H": np.zeros(3),
                 **{name: np.zeros(3 * k) for name in ("ups_y", "ups_l", "ups_d", "ups_H")}}
        return parts, info

    # --- the adaptation -------------------------------------------------------
    @staticmethod
    def _group_rls(P, rows, errors, k):
        """Recursive least squares of one group from each of its channels in turn (change 3).

        Per channel ``c``, one measurement ``e_c = H_c . phi_tilde``:
        ``g_c = P_c H_c / (1 + H_c^T P_c H_c)``, ``phi += g_c e_c``,
        ``P_c+1 = P_c - g_c (P_c H_c)^T``. The channel after the first sees
        its error with the update so far taken out, ``e_c - H_c . d_phi``:
        the same fit as all rows at once. The updates are kept as their
        rank-one terms, so that ``P_c H_c = P H_c - sum_{b<c} g_b ((P_b H_b) . H_c)``
        costs ``k`` products per earlier channel in place of a product by
        ``P_c``, and ``P`` is written once, ``P - sum_c g_c (P_c H_c)^T``;
        one division per channel (``g_c``).

        Parameters
        ----------
        P : list of k lists of k
            The covariance, symmetric.
        rows : list of lists of k
            Each channel's regressor row ``H_c``.
        errors : list
            Each channel's a priori error.
        k : int

        Returns
        -------
        d_phi : list of k
        P_next : list of k lists of k
            Symmetric: each entry below the diagonal is its mirror's.
        """
        gains, products, d_phi = [], [], None
        for h, e in zip(rows, errors):
            Ph = [sum(P[i][j] * h[j] for j in range(k)) for i in range(k)]
            for g, Pb in zip(gains, products):
                c = sum(Pb[j] * h[j] for j in range(k))
                Ph = [Ph[i] - g[i] * c for i in range(k)]
            denom = 1.0 + sum(h[i] * Ph[i] for i in range(k))
            g = [v / denom for v in Ph]
            if d_phi is None:
                d_phi = [g[i] * e for i in range(k)]
            else:
                e = e - sum(h[j] * d_phi[j] for j in range(k))
                d_phi = [d_phi[j] + g[j] * e for j in range(k)]
            gains.append(g)
            products.append(Ph)
        upper = {(i, j): P[i][j] - sum(g[i] * Pb[j] for g, Pb in zip(gains, products))
                 for i in range(k) for j in range(i, k)}
        return d_phi, [[upper[min(i, j), max(i, j)] for j in range(k)] for i in range(k)]

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

    def _adapt(self, o, st, rows, errors, hp, scale):
        """The adaptation of every parameter group from its channels' rows and errors (changes 3, 4, 5).

        Parameters
        ----------
        o : ops namespace
        st : namespace
            The packed state's parts (``P<g>``, ``test<g>``).
        rows, errors : lists
            Each channel's regressor row ``H_c = C Upsilon_c^-`` and a priori
            error (zero without a pose), indexed as the groups' channels.
        hp : float or casadi.SX
            The time since the previous pose where a pose arrives, else 0, s.
        scale : vector
            Each group's prior information.

        Returns
        -------
        d_phis : list of lists
            Each group's step ``d_phi``.
        parts : dict
            The packed state's new ``P<g>`` and ``test<g>``.
        """
        if self.track:
            alphas = [1 - o.exp(-hp / tau) for tau in (self.window, _DRIFT_WINDOWS * self.window, 10 * self.window,
                                                         self.window / 4)]
        d_phis, parts = [], {}
        for g, (channels, k) in enumerate(self._structure):
            g_rows, g_errors = [rows[c] for c in channels], [errors[c] for c in channels]
            P = mx.symmetric_from_upper(getattr(st, f"P{g}"), k)
            if self.gain == "least-squares":      # 3. recursive least squares, the group's channels in turn
                d_phi, P = self._group_rls(P, g_rows, g_errors, k)
            else:
                d_phi = self._gradient(g_rows, g_errors, k, hp, scale[g])
            # 4. the change test, and forgetting while it fires (off: the test's averages stay put)
            test = getattr(st, f"test{g}")
            if self.track:
                test, rate = self._change_test(o, g_rows, g_errors, test, alphas, k)
                f = self._growth(o, sum(P[i][i] for i in range(k)), test[3 * k:4 * k], rate, hp)
                P = [[f * v for v in r] for r in P]
                test = o.vcat(test)
            parts[f"P{g}"], parts[f"test{g}"] = o.vcat(mx.upper(P)), test
            d_phis.append(d_phi)
        return d_phis, parts

    @staticmethod
    def _filter_predict(o, U_p, U_v, G_p, G_v, dt, M=None):
        """The sensitivity filter's prediction over a step (change 2; module docstring's ``Upsilon^-``).

        For a double integrator ``p' = M v``, ``v' = psi . phi`` with ``psi`` linear over the step::

            U_p^- = U_p + M (h U_v + G_p)        U_v^- = U_v + G_v

        (``M`` None: the identity, ``U_p + h U_v + G_p``), ``G_p``, ``G_v`` the position and velocity
        increments of ``psi`` (:mod:`observers.core._discretise`). Rows of numbers or symbols, or
        ``3 x k`` matrices with ``M`` (3D: ``M = I_W^-1``, :mod:`observers.adaptive._spatial`).

        Returns
        -------
        U_p, U_v : the predicted filter
        """
        pos = U_p + dt * U_v + G_p if M is None else U_p + o.dot(M, dt * U_v + G_p)
        return pos, U_v + G_v

    @staticmethod
    def _filter_correct(o, U_p, U_v, l1, l2, gain=None):
        """The sensitivity filter's correction at a pose, ``Upsilon_n+1 = (I - L_h C) Upsilon^-`` (change 1, 2)::

            U_p = (1 - l_1) U_p^-                U_v = U_v^- - l_2 M^-1 U_p^-

        ``gain`` is ``l_2 M^-1`` where ``M`` is not the identity (3D: ``l_2 I_W``); None: ``l_2``.
        """
        return (1 - l1) * U_p, U_v - (l2 * U_p if gain is None else o.dot(gain, U_p))

    def _transition(self, z, u_prev, u, dt):
        """One step (module docstring), the class docstring's changes 1-5: on the channels the model declares
        (:meth:`_channels_step`), or on the momenta about the centre of mass (:meth:`_momenta_step`)."""
        o = ops(z, u)
        model = self.model
        st = self.state.unpack(z, scalars=False)
        now, nxt = model.input_layout.unpack(u_prev, scalars=False), model.input_layout.unpack(u, scalars=False)
        return (self._channels_step if model.linear_channels else self._momenta_step)(o, st, now, nxt, dt)

    def _channels_step(self, o, st, now, nxt, dt):
        """One step on linear channels, channel by channel from the model (eqs. (6)-(8))."""
        model, n = self.model, self.n_cols
        x, S, pose, has = st.x, st.S, now.pose, now.has_pose[0]
        since, scale = st.since[0], st.scale
        w = self._augmented(o, now.w_hat)
        has_next, pose_next, w_next = nxt.has_pose[0], nxt.pose, self._augmented(o, nxt.w_hat)
        qi, vi = model.q_index, model.v_index
        phis = model.phi_from_params(S, n)             # planar: phi_1, phi_2 of eqs. (4), (5)
        # 1. regressors of eq. (8) at both ends of the step (planar: the rows of B_1, B_2), linear over it;
        #    the configuration at n is the measured one where there is one (the pose is the configuration)
        q0 = o.vcat([has * pose[c] + (1 - has) * x[qi[c]] for c in range(model.nq)])
        q1 = o.vcat([x[qi[c]] + dt * x[vi[c]] for c in range(model.nq)])
        psi0, psi1 = model.channel_regressor_rows(q0, w), model.channel_regressor_rows(q1, w_next)
        dot = lambda a, b: sum(a[j] * b[j] for j in range(a.shape[0]))
        group_of = {c: g for g, (channels, _) in enumerate(self._structure) for c in channels}
        # eqs. (6), (7): x_hat propagated with A(q) S_hat w_hat (planar: G(theta) S_hat w_hat = B_1 phi_1,
        # B_2 phi_2); each channel's filter Upsilon^- and its C Upsilon^- (zero without a pose)
        x_pred, ups_pred, rows = [], [], []
        for c in range(model.nv):
            phi, up, k = phis[group_of[c]], getattr(st, f"ups{c}"), len(psi0[c])
            g_p = position_increment(dt, o.vcat(psi0[c]), o.vcat(psi1[c]))
            g_v = velocity_increment(dt, o.vcat(psi0[c]), o.vcat(psi1[c]))
            x_pred.append([x[qi[c]] + dt * x[vi[c]] + dot(g_p, phi), x[vi[c]] + dot(g_v, phi)])
            ups_pred.append(self._filter_predict(o, up[0:k], up[k:2 * k], g_p, g_v, dt))
            rows.append([has_next * ups_pred[c][0][j] for j in range(k)])
        # a priori position errors at n+1 (true minus estimate), zero without a pose
        e = [has_next * (pose_next[c] - x_pred[c][0]) for c in range(model.nv)]
        h = since + dt                            # 5. time since the previous pose
        d_phis, parts = self._adapt(o, st, rows, e, has_next * h, scale)
        # 1. correction: Upsilon_n+1 = (I - L_h C) Upsilon^-, x_n+1 = x^- + L_h e + Upsilon_n+1 d_phi
        l1, l2 = discrete_gain(o, self.lam, h)
        l1, l2 = has_next * l1, has_next * l2
        entries = [None] * model.nx
        for c in range(model.nv):
            d_phi = d_phis[group_of[c]]
            new = self._filter_correct(o, *ups_pred[c], l1, l2)
            parts[f"ups{c}"] = o.vcat(new)
            entries[qi[c]] = x_pred[c][0] + l1 * e[c] + dot(new[0], d_phi)
            entries[vi[c]] = x_pred[c][1] + l2 * e[c] + dot(new[1], d_phi)
        S_next = mx.flat(o, model.params_from_phi([phi + o.vcat(d) for phi, d in zip(phis, d_phis)], n))
        return self.state.pack(o, x=o.vcat(entries), S=S_next, since=(1 - has_next) * h, scale=scale, **parts)

    def _momenta_step(self, o, st, now, nxt, dt):
        """One step on the momenta about the centre of mass, a body in 3D (:mod:`observers.adaptive._spatial`),
        from the model's pieces (:class:`fmscal.plant.SpatialModel`: ``momentum_*``, ``world_*``, ``turn``)."""
        model, n, com = self.model, self.n_cols, self.payload.com
        k = 3 * n
        has, has_next = now.has_pose[0], nxt.has_pose[0]
        H, y, lin, chi, chi_ref, q_ref = st.H, st.y, st.l, st.chi, st.chi_ref, st.q_ref
        w0, w1 = self._augmented(o, now.w_hat), self._augmented(o, nxt.w_hat)
        R_ref = rotation_matrix(q_ref)
        # the attitude in the drives: the measured one where a pose arrives (q_ref), else the last measured one
        # turned by the observer's own turn since it (chi - chi_pose), not by its error at that pose
        R0 = rotation_matrix(model.turn(q_ref, R_ref, (1 - has) * (chi - st.chi_pose)))
        M0 = model.world_inverse_inertia(R0)                           # I_W^-1 at n
        spin0 = o.dot(M0, H)                                           # omega in the world frame
        # at n+1: measured, else turned by omega over the step (first order)
        R_next = rotation_matrix(nxt.pose[0:4])
        R1 = has_next * R_next + (1 - has_next) * model.turned_rotation(R0, spin0, dt)
        # the drives, linear over the step: eq. (M) at both ends, [torque about C, force plus m g]
        phis = model.momentum_phi_from_params(st.S, n, com)
        (t0, f0), (t1, f1) = model.momentum_drives(R0, w0, phis), model.momentum_drives(R1, w1, phis)
        y_pred = y + dt * lin + position_increment(dt, f0, f1)
        l_pred = lin + velocity_increment(dt, f0, f1)
        H_pred = H + velocity_increment(dt, t0, t1)
        chi_pred = chi + model.turn_over_step(spin0, model.world_rate(R1, H_pred), dt)
        # the filters' prediction (3 x k each)
        psi0, psi1 = model.momentum_regressor(R0, w0), model.momentum_regressor(R1, w1)
        G_p, G_v = position_increment(dt, psi0, psi1), velocity_increment(dt, psi0, psi1)
        U_y, U_l, U_d, U_H = (mx.as_matrix(o, getattr(st, f"ups_{name}"), 3, k) for name in ("y", "l", "d", "H"))
        U_y, U_l = self._filter_predict(o, U_y, U_l, G_p, G_v, dt)             # p' = v: m p_C, m v_C
        U_d, U_H = self._filter_predict(o, U_d, U_H, G_p, G_v, dt, M0)         # p' = I_W^-1 v: chi, H
        # a priori errors at n+1, zero without a pose: the unwrapped attitude's (the measured turn from the last
        # pose, in the world frame, added to chi_ref), m p_C's
        q_meas = has_next * nxt.pose[0:4] + (1 - has_next) * q_ref                 # no pose: no turn
        body = model.difference(o.vcat([0.0, 0.0, 0.0, q_ref]), o.vcat([0.0, 0.0, 0.0, q_meas]))[3:6]
        chi_meas = chi_ref + o.dot(R_ref, body)
        e_d = has_next * (chi_meas - chi_pred)
        e_y = has_next * (model.centre_of_mass_momentum(nxt.pose) - y_pred)
        # the fit starts once the observer's own transient from rest has decayed (WARM_UP poles' time constants)
        age = st.age[0] + dt
        fit = has_next * (age >= WARM_UP / self.lam)
        rows = [[fit * U[i, j] for j in range(k)] for U in (U_d, U_y) for i in range(3)]
        h = st.since[0] + dt
        d_phis, parts = self._adapt(o, st, rows, [fit * e[i] for e in (e_d, e_y) for i in range(3)], fit * h,
                                    st.scale)
        d_t, d_f = (o.vcat(d) for d in d_phis)
        # the correction: the filters, then the motion with the filters' share of the parameters' step
        l1, l2 = discrete_gain(o, self.lam, h)
        l1, l2 = has_next * l1, has_next * l2
        l2_IW = l2 * model.world_inertia(R1)
        U_d_new, U_H_new = self._filter_correct(o, U_d, U_H, l1, l2, l2_IW)
        U_y_new, U_l_new = self._filter_correct(o, U_y, U_l, l1, l2)
        chi_new = chi_pred + l1 * e_d + o.dot(U_d_new, d_t)
        H_new = H_pred + o.dot(l2_IW, e_d) + o.dot(U_H_new, d_t)
        y_new = y_pred + l1 * e_y + o.dot(U_y_new, d_f)
        l_new = l_pred + l2 * e_y + o.dot(U_l_new, d_f)
        # the last pose becomes the reference (sign-continuous), and the observer's attitude is it turned
        sign = o.if_else(sum(q_meas[i] * q_ref[i] for i in range(4)) < 0, -1.0, 1.0)
        q_ref_new = has_next * sign * q_meas + (1 - has_next) * q_ref
        chi_ref_new = has_next * chi_meas + (1 - has_next) * chi_ref
        R_ref_new = has_next * R_next + (1 - has_next) * R_ref
        q_new = model.turn(q_ref_new, R_ref_new, chi_new - chi_ref_new)
        chi_pose_new = has_next * chi_new + (1 - has_next) * st.chi_pose
        S_next = model.momentum_params_from_phi([phi + o.vcat(d) for phi, d in zip(phis, d_phis)], n, com)
        return self.state.pack(o, x=model.state_from_momenta(y_new, l_new, q_new, H_new), S=S_next,
                               since=(1 - has_next) * h, scale=st.scale, age=age, y=y_new, l=l_new, chi=chi_new,
                               chi_ref=chi_ref_new, chi_pose=chi_pose_new, q_ref=q_ref_new, H=H_new,
                               ups_y=mx.flat(o, U_y_new), ups_l=mx.flat(o, U_l_new), ups_d=mx.flat(o, U_d_new),
                               ups_H=mx.flat(o, U_H_new), **parts)


class SpatialAdaptiveObserver(AdaptiveObserver):
    """:class:`AdaptiveObserver` on a body in 3D, under its own name: the same class but for its default pole.

    Built by ``AdaptiveObserver(model, ...)`` (registry name ``adaptive``)
    when the model's attitude is a unit quaternion (the registry's engine for
    that declaration, :data:`fmscal.observers._registry.ENGINES`); it takes the
    same settings and has no law of its own: :class:`AdaptiveObserver` runs
    the law on the momenta about the centre of mass from the model's pieces.
    Its default pole is :data:`observers.adaptive._spatial.SPATIAL_LAM`.
    """

    default_lam = SPATIAL_LAM
