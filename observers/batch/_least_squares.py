"""Offline least-squares calibration: a reference that needs no noise model.

Eq. (1) with ``w = S w_hat`` is linear in the parameters ``phi_1``, ``phi_2`` of
eqs. (4), (5)::

    theta'' = psi_theta(t) . phi_1,   X'' = psi_X(t) . phi_2,   Y'' = psi_Y(t) . phi_2

with the regressors of :func:`plant.regressors` (built from
:func:`plant.input_matrix`). The channels and their parameter groups come
from the model (:meth:`fmscal.plant.Model.parameter_groups`,
:meth:`fmscal.plant.Model.channel_regressors`): any model linear in its
channels runs through the same code. Integrated twice over a window starting at
``t_0``, each measured position is ``p(t) = p_0 + v_0 (t - t_0) + Z(t) . phi``
with ``Z`` the double integral of the regressor. The fit eliminates ``p_0``
and ``v_0`` in each window (it projects out a line) and solves the normal
equations of all windows for ``phi``; windows are kept short so that the
twice-integrated wrench noise stays near the pose noise.
"""

from dataclasses import asdict, dataclass, field

import numpy as np

from fmscal.plant import S_from_phi, phi_1
from fmscal.plant.io import estimate_noise
from fmscal.plant.numerics import FmscalError, as_positive_scalar
from fmscal.plant.physics import as_model

from fmscal.observers.core import Estimate, Observer, position_increment, velocity_increment
from ._inverse_dynamics import fit_inverse_dynamics, nominal_motion

__all__ = ["LeastSquares", "InverseDynamicsLeastSquares", "SpatialLeastSquares", "FitReport", "phi_to_S_map",
           "EXCITATION_COND_LIMIT", "CONSISTENCY_RATIO_LIMIT", "LEAST_SQUARES_ENGINES"]

#: Above this condition number of the (scaled) information matrix, the log is said not to
#: excite all nine entries of S.
EXCITATION_COND_LIMIT = 1e4
#: Above this ratio of fit residual to the pose noise estimated from the log, the log is
#: said not to match the model.
CONSISTENCY_RATIO_LIMIT = 10.0


@dataclass
class FitReport:
    """Diagnostics of a least-squares fit (None before a run).

    Attributes
    ----------
    information_cond : float
        Condition number of the information matrix, columns scaled to unit diagonal.
    weakest_direction : list
        The entries of ``S`` (n_w x n_w) along which the data say least.
    residual_rms : list
        The fit's residual per pose channel (planar ``[theta, X, Y]``).
    pose_noise_estimate : list
        The pose noise per channel, from the log's high-frequency content.
    consistency_ratio : float
        The largest residual over noise ratio.
    warnings : list of str
        One line each.
    """

    information_cond: float = None
    weakest_direction: list = None
    residual_rms: list = None
    pose_noise_estimate: list = None
    consistency_ratio: float = None
    warnings: list = field(default_factory=list)

    def to_dict(self):
        """The diagnostics as JSON-ready values (``fmscal calibrate --json``'s ``fit``, with the warnings)."""
        return asdict(self)


class LeastSquares(Observer):
    """Offline least squares for ``S``: the one least-squares entry, two engines.

    ``LeastSquares(model, ...)`` builds the engine that fits ``model``:

    - ``"windows"`` (this class): weighted least squares over
      double-integrated windows, for a model linear in its channels (the
      planar one; the default there);
    - ``"inverse-dynamics"`` (:class:`InverseDynamicsLeastSquares`):
      smoothed inverse dynamics and least squares on the augmented reading
      (:func:`fmscal.observers.batch.fit_inverse_dynamics`), for the
      spatial model (the default there, by the registry's row
      ``(LeastSquares, "attitude", "quaternion")``,
      :data:`fmscal.observers._registry.ENGINES`) and for the planar one on
      request (``engine="inverse-dynamics"``); it always estimates the
      offset.

    On a planar log the two agree within what their different smoothing
    allows (``tests/test_general_batch.py``: E within a factor of three
    either way on seeds of the paper scenario, the median ``S_std`` within
    a factor of 1.5).

    The windows engine. Module docstring for the model. Angular and translational parameters are
    fitted separately (they share no unknown); ``S_hat`` follows from
    :func:`plant.S_from_phi`, and its covariance from the residual variance of
    each channel, mapped linearly. The covariance is the cluster-robust
    (sandwich) estimate with the windows as clusters: the twice-integrated
    wrench noise makes residuals within a window correlated, and the textbook
    ``sigma^2 (Z^T Z)^-1`` would claim two to three times too little.

    Parameters
    ----------
    model : plant.Model or plant.Payload
        The problem (a payload stands for its case's model).
    window : float
        Window length in s over which the raw reading is integrated twice
        (the windows engine; the inverse-dynamics engine does not read it).
    offset : bool
        Also estimate the sensor's offset ``b`` in ``w = S (w_hat - b)``:
        the model ``w = S w_hat + c`` stays linear (``c = -S b``, the
        reading augmented by a constant 1). ``b`` and its one-sigma
        uncertainty are in ``result.b``, ``result.b_std``. The
        inverse-dynamics engine requires it.
    engine : {None, "windows", "inverse-dynamics"}
        None (default): the engine the registry lists for what the model
        declares (:meth:`observers.Observer.engine`); a name: that engine
        (:data:`LEAST_SQUARES_ENGINES`), refused on a model it does not fit.

    Attributes
    ----------
    report : FitReport
        Diagnostics of the last :meth:`run`.

    Examples
    --------
    >>> from fmscal.plant import PAPER_PAYLOAD, get_scenario
    >>> log, truth, _ = get_scenario("paper").with_(duration=2.0).generate(0)
    >>> from fmscal.observers import LeastSquares
    >>> result = LeastSquares(PAPER_PAYLOAD, offset=True).run(log)     # S, its uncertainty and the offset b
    >>> result.S_hat.shape, result.b.shape
    ((3, 3), (3,))
    >>> result.converged in (True, False)              # with its own checks: excitation and consistency
    True
    """

    name = "least-squares"
    online = False
    #: The engine estimates the offset always (``offset=False`` is refused).
    offset_required = False

    def __new__(cls, model=None, *args, **kwargs):
        """The engine ``engine`` names (the 4th argument or the keyword), else the registry's for ``model``
        (:meth:`observers.Observer.__new__`)."""
        engine = kwargs.get("engine", args[2] if len(args) > 2 else None)
        if model is None or engine is None:
            return super().__new__(cls, model)
        return Observer.__new__(_engine_named(engine))

    def __init__(self, model, window=0.5, offset=False, engine=None):
        if engine is not None:
            _engine_named(engine)
            refusal = type(self)._refusal(as_model(model, type(self).__name__))
            if refusal is not None:
                raise FmscalError(refusal)
        super().__init__(model, offset=offset)
        self.engine_name = next(name for name, cls in LEAST_SQUARES_ENGINES.items() if cls is type(self))
        if self.offset_required and not self.offset:
            raise FmscalError("least squares by smoothed inverse dynamics always estimates the offset "
                              "(fmscal.observers.batch.fit_inverse_dynamics); pass offset=True")
        self.window = as_positive_scalar(window, "window")
        self.report = FitReport()

    @classmethod
    def _refusal(cls, model):
        """Least squares fits models linear in their channels, and the spatial one (smoothed inverse dynamics,
        :class:`SpatialLeastSquares`, :data:`fmscal.observers._registry.ENGINES`)."""
        if not model.linear_channels:
            return f"LeastSquares fits models linear in their channels, or the spatial one; got a {model.name} model"
        return super()._refusal(model)

    def latency_cost(self, log):
        """The fit's misfit on ``log``, which the latency search (:func:`fmscal.observers.batch.estimate_latency`)
        minimises over the poses' delay: ``sum_c (r_c / sigma_c)^2`` over the pose channels ``c``, ``r_c``
        the fit's residual rms and ``sigma_c`` the pose noise estimated from the log (floored at 1e-12)."""
        self.run(log)
        rms = np.asarray(self.report.residual_rms)
        sd = np.maximum(np.asarray(self.report.pose_noise_estimate), 1e-12)
        return float(np.sum((rms / sd) ** 2))

    def _double_integrals(self, log):
        """Double integrals of each channel's regressor from the log's start.

        The regressor is taken linear between samples (as the observers do),
        the configuration interpolated between pose measurements.

        Returns
        -------
        list of ndarrays, one per channel, each shape (N, len(phi) of its group)
            Planar: (N, n), (N, 2n), (N, 2n), ``n`` = 3, or 4 with the offset.
        """
        t = log.t
        q = np.array([np.interp(t, t[log.has_pose], log.pose[log.has_pose, j]) for j in range(self.model.n_pose)])
        reading = log.w_hat.T if not self.offset else np.vstack([log.w_hat.T, np.ones(len(t))])
        psi = self.model.channel_regressors(q, reading)
        h = np.diff(t)[:, None]
        out = []
        for P in psi:
            dv = velocity_increment(h, P[:-1], P[1:])
            V = np.vstack([np.zeros(P.shape[1]), np.cumsum(dv, axis=0)])
            dp = V[:-1] * h + position_increment(h, P[:-1], P[1:])
            out.append(np.vstack([np.zeros(P.shape[1]), np.cumsum(dp, axis=0)]))
        return out

    def _windows(self, log):
        """The pose rows of each window that holds at least 3 poses (a line and a curvature)."""
        idx = np.floor((log.t - log.t[0]) / self.window).astype(int)
        rows = (np.flatnonzero((idx == k) & log.has_pose) for k in np.unique(idx))
        return [r for r in rows if len(r) >= 3]

    def _normal_equations(self, log, Z, channels, windows, y=None):
        """Information matrix and right side for the channels sharing one parameter set.

        Each window's positions and regressors have a line in time projected out.
        ``y`` (``{channel: (N,) array}``) replaces the logged positions.

        Returns
        -------
        info, rhs : ndarray
        per_window : list of (rows, Iw, bw, projected)
            ``projected`` maps each channel to its window's projected
            ``(Z, y)``, kept for the residuals.
        """
        n_par = Z[channels[0]].shape[1]
        info, rhs, per_window = np.zeros((n_par, n_par)), np.zeros(n_par), []
        for rows in windows:
            tau = log.t[rows] - log.t[rows[0]]
            Q, _ = np.linalg.qr(np.column_stack([np.ones_like(tau), tau]))
            Iw, bw, projected = np.zeros((n_par, n_par)), np.zeros(n_par), {}
            for c in channels:
                Zc = Z[c][rows] - Q @ (Q.T @ Z[c][rows])
                yr = log.pose[rows, c] if y is None else y[c][rows]
                yc = yr - Q @ (Q.T @ yr)
                Iw += Zc.T @ Zc
                bw += Zc.T @ yc
                projected[c] = (Zc, yc)
            info += Iw
            rhs += bw
            per_window.append((rows, Iw, bw, projected))
        return info, rhs, per_window

    def _estimate(self, log, S0):
        """Fit ``S`` to the whole log (:meth:`observers.Observer.run`).

        ``S_hat_history`` of the result holds the fit on the data up to the
        end of each window (held within it); ``x_hat_history`` the fitted
        motion; ``S_std`` the one-sigma uncertainty from the residuals; the
        method's checks pass when the excitation and consistency checks find
        nothing (``result.info["fit"]`` holds the :class:`FitReport`, and
        ``result.warnings`` its warnings).

        The inverse-dynamics engine has its own
        (:meth:`InverseDynamicsLeastSquares._estimate`).
        """
        Z = self._double_integrals(log)
        windows = self._windows(log)
        if len(windows) < 2 and log.duration >= 2 * self.window:      # long enough: the poses too sparse
            unit = f"; the time step is {log.dt:g} s: is t in milliseconds? t must be in s" if log.dt >= 0.1 else ""
            raise FmscalError(f"{log.name}: too few pose measurements for least squares with {self.window:g} s "
                              f"windows: need at least 2 windows of 3 pose measurements, got {len(windows)}{unit}")
        if len(windows) < 2:
            raise FmscalError(f"{log.name}: too short for least squares with {self.window:g} s windows: "
                             f"need at least 2 windows of 3 pose measurements, got {len(windows)}")
        groups = self.model.parameter_groups()      # planar: phi_1 <- theta; phi_2 <- X, Y
        phis, covs, residuals, histories = [], [], {}, []
        for channels in groups:
            info, rhs, per_window = self._normal_equations(log, Z, channels, windows)
            phi = np.linalg.lstsq(info, rhs, rcond=None)[0]
            # residuals per channel, and a covariance robust to their correlation within a
            # window (the twice-integrated wrench noise): the cluster sandwich I^-1 (sum g g^T) I^-1
            sq, dof = {c: 0.0 for c in channels}, {c: 0 for c in channels}
            meat = np.zeros((len(phi), len(phi)))
            for rows, _, _, projected in per_window:
                g = np.zeros(len(phi))
                for c in channels:
                    Zc, yc = projected[c]
                    r = yc - Zc @ phi               # the projection is linear: P (y - Z phi)
                    sq[c] += float(r @ r)
                    dof[c] += len(rows) - 2
                    g += Zc.T @ r
                meat += np.outer(g, g)
            for c in channels:
                residuals[c] = np.sqrt(sq[c] / max(dof[c] - len(phi) / len(channels), 1))
            info_inv = np.linalg.pinv(info)
            covs.append(info_inv @ meat @ info_inv * len(per_window) / max(len(per_window) - len(phi), 1))
            phis.append(phi)
            histories.append(_running_fits(per_window, len(log)))
        n, m = self.n_cols, self.n_w * self.n_cols
        S_aug = self.model.params_from_phi(phis, n)
        T = phi_to_S_map(self.model, [len(phi) for phi in phis], n)
        cov_phi, k = np.zeros((m, m)), 0
        for cov in covs:                              # the groups share no unknown: block diagonal
            cov_phi[k:k + len(cov), k:k + len(cov)] = cov
            k += len(cov)
        cov_S = T @ cov_phi @ T.T                     # of [S | c], row order
        self.report = self._diagnose(log, cov_S, residuals, n)
        # the running fits mapped to [S | c] in one product (S_from_phi is the linear map T);
        # the last window's fit is the fit of the whole log
        calibration = np.hstack(histories) @ T.T
        calibration[-1] = S_aug.ravel()
        return Estimate(calibration, self._fitted_motion(log, Z, phis, windows), cov=cov_S,
                        checks_passed=not self.report.warnings, info={"fit": self.report},
                        warnings=list(self.report.warnings))

    def offset_bias(self, log, S, b):
        """What an offset left out does to the fit: the predicted ``S_hat - S`` (the planar model).

        An offset ``b`` adds ``G(theta) c`` (``c = -S b``) to the
        accelerations; a fit without it projects that motion onto the
        regressors of ``S`` (the omitted-variable bias of least squares):
        ``delta phi = (Z^T Z)^-1 Z^T Z_c c`` per parameter set, window by window.

        Parameters
        ----------
        log : plant.Log
            Supplies the angle, the readings and the windows.
        S : array_like, shape (3, 3)
        b : array_like, shape (3,)
            The sensor's offset, N m and N.

        Returns
        -------
        ndarray, shape (3, 3)
            ``S_hat - S`` of :meth:`run` with ``offset=False`` on noise-free data.

        Raises
        ------
        FmscalError
            The model is not planar (this reads eqs. (4), (5) directly).
        """
        if not self.model.paper_equations:
            raise FmscalError(f"offset_bias reads eqs. (4), (5) of the planar model; got a {self.model.name} model")
        S = np.asarray(S, dtype=float)
        c = -S @ np.asarray(b, dtype=float)
        with_c = LeastSquares(self.model, self.window, offset=True)
        Z_all = with_c._double_integrals(log)                    # (N, 4), (N, 8), (N, 8)
        S_c = np.column_stack([np.zeros((3, 3)), c])             # the offset alone, as [0 | c]
        phi_c = [phi_1(S_c, self.payload), S_c[1:].ravel()]
        keep = [[0, 1, 2], [0, 1, 2, 4, 5, 6], [0, 1, 2, 4, 5, 6]]     # the columns of S
        y = {ch: Z_all[ch] @ phi_c[min(ch, 1)] for ch in range(3)}        # the motion c alone causes
        Z = [Z_all[ch][:, keep[ch]] for ch in range(3)]
        windows = self._windows(log)
        d_phi = []
        for channels in ([0], [1, 2]):
            info, rhs, _ = self._normal_equations(log, Z, channels, windows, y)
            d_phi.append(np.linalg.lstsq(info, rhs, rcond=None)[0])
        return S_from_phi(d_phi[0], d_phi[1], self.payload)

    def _diagnose(self, log, cov_S, residuals, n):
        # information about S, columns scaled to unit diagonal: unit-free conditioning
        with np.errstate(all="ignore"):
            info_S = np.linalg.pinv(cov_S) if np.all(np.isfinite(cov_S)) else np.zeros_like(cov_S)
            d = np.sqrt(np.maximum(np.diag(info_S), 1e-300))
            scaled = info_S / np.outer(d, d)
        if np.all(np.isfinite(scaled)):
            eigval, eigvec = np.linalg.eigh(scaled)
        else:                               # a covariance that overflowed: nothing is known
            eigval, eigvec = np.zeros(len(scaled)), np.eye(len(scaled))
        cond = float(eigval[-1] / eigval[0]) if eigval[0] > 0 else float("inf")
        noise = estimate_noise(log)
        pose_sd = self.model.pose_sd(noise)
        rms = np.array([residuals[c] for c in range(self.model.nv)])
        ratio = float(np.max(rms / np.maximum(pose_sd, 1e-12))) if np.all(pose_sd > 0) else float("nan")
        warnings = []
        n_w = self.n_w
        if cond > EXCITATION_COND_LIMIT:
            weakest = eigvec[:, 0].reshape(n_w, n)
            i, j = np.unravel_index(np.argmax(np.abs(weakest)), (n_w, n))
            entry = f"s_{i + 1}{j + 1}" if j < n_w else f"the offset c_{i + 1}"
            entries = {1: "S", 3: "all nine entries of S"}.get(n_w, f"all {n_w * n_w} entries of S")
            what = entries if n == n_w else f"{entries} and the offset"
            warnings.append(f"the log does not excite {what} (information matrix condition "
                            f"number {cond:.3g} > {EXCITATION_COND_LIMIT:.0e}; weakest along {entry}): "
                            "drive every wrench component, or no method can recover S")
        if np.isfinite(ratio) and ratio > CONSISTENCY_RATIO_LIMIT:
            names = [name if name == "theta" else name.upper() for name in self.model.pose_names]
            worst = int(np.argmax(rms / np.maximum(pose_sd, 1e-12)))
            warnings.append(f"the log does not match the model: the fit residual of {names[worst]} is "
                            f"{ratio:.3g}x the pose noise estimated from the log (> {CONSISTENCY_RATIO_LIMIT:g}); "
                            "check units (angles in rad, positions in m), the mass properties (m, I_G, rho), "
                            "a sensor offset left out and the pose latency")
        return FitReport(information_cond=cond, weakest_direction=eigvec[:, 0].reshape(n_w, n)[:, :n_w].tolist(),
                         residual_rms=rms.tolist(), pose_noise_estimate=pose_sd.tolist(),
                         consistency_ratio=ratio, warnings=warnings)

    def _fitted_motion(self, log, Z, phis, windows):
        """The motion of the fit (planar ``[theta, theta', X, X', Y, Y']``): per window a line plus ``Z phi``."""
        model = self.model
        x = np.full((len(log), model.nx), np.nan)
        t = log.t
        group_of = {c: g for g, channels in enumerate(model.parameter_groups()) for c in channels}
        for c in range(model.nv):
            phi = phis[group_of[c]]
            forced = Z[c] @ phi
            dforced = np.gradient(forced, t)
            for rows in windows:
                if len(rows) < 2:
                    continue
                A = np.column_stack([np.ones(len(rows)), t[rows] - t[rows[0]]])
                p0, v0 = np.linalg.lstsq(A, log.pose[rows, c] - forced[rows], rcond=None)[0]
                span = slice(rows[0], rows[-1] + 1)
                x[span, model.q_index[c]] = p0 + v0 * (t[span] - t[rows[0]]) + forced[span]
                x[span, model.v_index[c]] = v0 + dforced[span]
        # samples between windows without a fit (rare): hold the last value
        for col in range(model.nx):
            good = np.isfinite(x[:, col])
            x[:, col] = np.interp(t, t[good], x[good, col]) if good.any() else 0.0
        return x


def _running_fits(per_window, n):
    """The fit on the windows so far, held over each window: shape (n, n_par)."""
    n_par = len(per_window[0][2])          # entries (rows, Iw, bw, projected)
    out = np.zeros((n, n_par))
    info, rhs = np.zeros((n_par, n_par)), np.zeros(n_par)
    last_end, phi = 0, np.zeros(n_par)
    for rows, Iw, bw, _ in per_window:
        info += Iw
        rhs += bw
        phi = np.linalg.lstsq(info, rhs, rcond=None)[0]
        out[last_end:rows[-1] + 1] = phi
        last_end = rows[-1] + 1
    out[last_end:] = phi
    return out


def phi_to_S_map(model, sizes, n):
    """The matrix ``T`` with ``vec([S | c]) = T [phi_1, phi_2, ...]`` (row order): the model's
    :meth:`fmscal.plant.Model.params_from_phi` (planar: eqs. (4), (5) inverted), column by column.

    ``sizes`` are the groups' parameter counts, ``n`` the columns of ``[S | c]``.
    """
    m = sum(sizes)
    T = np.zeros((m, m))
    ends = np.cumsum(sizes)[:-1]
    for k in range(m):
        e = np.zeros(m)
        e[k] = 1.0
        T[:, k] = np.ravel(model.params_from_phi(np.split(e, ends), n))
    return T


class InverseDynamicsLeastSquares(LeastSquares):
    """:class:`LeastSquares` by smoothed inverse dynamics: one batch fit of ``w_k = S w_hat_k + c``.

    Built by ``LeastSquares(model, ...)`` (registry name ``least-squares``)
    when the model's attitude is a unit quaternion (the registry's engine for
    that declaration, :data:`fmscal.observers._registry.ENGINES`), or on any
    model whose dynamics invert (``input_matrix`` square: the planar one)
    with ``engine="inverse-dynamics"``; the same settings, and it always
    estimates the offset (``offset=True``). The fit is
    :func:`fmscal.observers.batch.fit_inverse_dynamics` on the model
    (Newton-Euler in 3D with the model's payload and gravity, eq. (1)
    inverted in the plane); ``window`` is not read.
    """

    offset_required = True

    @classmethod
    def _refusal(cls, model):
        """The base class's limits (:meth:`observers.Observer._refusal`), and dynamics that invert: as many
        wrench components as accelerations."""
        if model.n_w != model.nv:
            return (f"least squares by inverse dynamics inverts the model's input matrix; a {model.name} model has "
                    f"{model.n_w} wrench components and {model.nv} accelerations")
        return super(LeastSquares, cls)._refusal(model)

    def _fit(self, log):
        return fit_inverse_dynamics(log, self.model)

    def _estimate(self, log, S0):
        """Smoothed inverse dynamics and least squares, one batch fit.

        Every row of the calibration history holds the whole log's fit (a
        batch fit has no running estimate); the motion is the smoothed poses'
        (:func:`fmscal.observers.batch.nominal_motion`); the checks pass
        when the log determines every direction of the reading
        (``result.info["undetermined"]``, the warnings say what to record).
        """
        fit = self._fit(log)
        calibration = np.tile(fit.S_aug.ravel(), (len(log), 1))
        info = {"undetermined": [d.tolist() for d in fit.undetermined], "residual_rms": fit.residual_rms.tolist()}
        return Estimate(calibration, nominal_motion(log, self.model), cov=fit.cov, checks_passed=fit.converged,
                        info=info, warnings=list(fit.warnings))

    def latency_cost(self, log):
        """The fit's misfit on ``log`` for the latency search: the sum over the wrench components of the share
        of each the inverse-dynamics fit leaves unexplained (:attr:`InverseDynamicsFit.unexplained`)."""
        return float(np.sum(self._fit(log).unexplained))


#: The name the registry and the tables knew the inverse-dynamics engine by (the spatial model's engine).
SpatialLeastSquares = InverseDynamicsLeastSquares

#: The least-squares engines by the name ``LeastSquares(model, engine=...)`` takes.
LEAST_SQUARES_ENGINES = {"windows": LeastSquares, "inverse-dynamics": InverseDynamicsLeastSquares}


def _engine_named(engine):
    """The engine class :data:`LEAST_SQUARES_ENGINES` names, or a one-line :class:`FmscalError`."""
    try:
        return LEAST_SQUARES_ENGINES[engine]
    except (KeyError, TypeError):
        raise FmscalError(f"least squares: no engine {engine!r}; expected None or one of "
                          f"{', '.join(LEAST_SQUARES_ENGINES)}") from None
