"""The plain reference: smoothed inverse dynamics, then least squares for ``[S | c]``.

The spatial model's least squares, and on request the planar one's
(:class:`fmscal.observers.batch.InverseDynamicsLeastSquares`): what follows
is written for the body in 3D; on a model whose configuration moves
additively the wrench each sample needed is its dynamics inverted,
``w = A(x)^-1 (a - d(x))`` (eq. (1): ``G(theta)^-1 [theta'', X'', Y'']``),
on the poses smoothed and differentiated by the same filter
(:func:`smoothed_channels`), and the fit of ``[S | c]`` is the same.

What a practitioner would write first. The poses are smoothed and
differentiated (:func:`fmscal.plant.physics.spatial_motion`); with the
payload known, Newton-Euler gives the wrench each sample needed
(``w_k = W_k pi``, :func:`fmscal.plant.physics.regressor`); and
``w_k = S w_hat_k + c`` is fitted row by row by least squares on the
augmented reading ``[w_hat_k; 1]``, the covariance cluster-robust over
blocks of time. The smoothing biases the accelerations and the
differentiated noise enters ``w_k``: the floor (the motion model, not a
differentiated pose) is what this is measured against.

What the log determines. Every row of ``[S | c]`` is read off the same
regressor, the augmented reading, so the information about ``S`` lies in
the second-moment matrix of ``[w_hat; 1]``: a direction of the reading
along which the log does not vary leaves ``S`` undetermined on it, for every
row at once. Static poses make every wrench ``[com x f; f]`` (3 dimensions
of 6), so three directions of the reading stay undetermined: mostly torque
directions, which only angular acceleration (``I alpha + omega x I omega``)
can excite. :attr:`InverseDynamicsFit.undetermined` lists them, and the
warnings say what to record.
"""

from dataclasses import dataclass, field
from functools import lru_cache

import casadi as ca
import numpy as np
from scipy.signal import savgol_filter

from fmscal.plant.io import estimate_noise
from fmscal.plant.numerics import FmscalError, as_finite_array, as_positive_scalar
from fmscal.plant.physics import (ORDER, GRAVITY, Model, SpatialPayload, edge, regressor, smoothed_state,
                                  spatial_motion)

from ._cluster_covariance import block_length, few_blocks, small_sample_factor

__all__ = ["InverseDynamicsFit", "fit_inverse_dynamics", "needed_wrench", "fit_readings", "describe_direction",
           "UNDETERMINED_STD", "READING_NAMES", "nominal_motion", "smoothed_channels",
           "needed_wrenches", "reading_rate"]

#: The augmented reading's components, the directions in which the information is reported.
READING_NAMES = ("tx", "ty", "tz", "fx", "fy", "fz", "1")
#: A direction of the reading counts as undetermined when ``S`` along it (a unit direction of the
#: readings scaled to their spread) has a one-sigma uncertainty above this: 5 % of a unit gain.
UNDETERMINED_STD = 0.05


@dataclass
class InverseDynamicsFit:
    """``[S | c]`` of a log by smoothed inverse dynamics and least squares (shapes for the spatial
    reading, ``n_w = 6``; ``n_w`` and ``n_w + 1`` on another model).

    Attributes
    ----------
    S_hat, S_std : ndarray, shape (6, 6)
        The estimate of ``S`` in ``w = S (w_hat - b)`` and its one-sigma uncertainty.
    b, b_std : ndarray, shape (6,)
        The offset (reading order, N m and N) and its uncertainty.
    cov : ndarray, shape (42, 42)
        Covariance of ``vec([S | c])``, row order.
    undetermined : list of ndarray, shape (7,)
        Unit directions of the augmented reading ``[tx .. fz, 1]`` (each
        component scaled by its spread in the log) along which ``S`` is not
        determined.
    warnings : list of str
    converged : bool
        No direction undetermined.
    residual_rms : ndarray, shape (6,)
        The fit's residual per wrench component (N m, N): what the motion
        asked of the sensor less what the fitted reading gave.
    c : ndarray, shape (6,)
        The offset column of ``[S | c]`` (``c = -S b``), as fitted.
    unexplained : ndarray, shape (6,)
        The share of each wrench component's variance the fit does not
        explain (residual variance over the component's variance), for the
        latency search (:func:`fmscal.observers.batch.estimate_latency`).
    """

    S_hat: np.ndarray
    S_std: np.ndarray
    b: np.ndarray
    b_std: np.ndarray
    cov: np.ndarray
    undetermined: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    converged: bool = False
    residual_rms: np.ndarray = None
    unexplained: np.ndarray = None
    c: np.ndarray = None

    @property
    def S_aug(self):
        """``[S | c]``, shape (n_w, n_w + 1), of ``w = S w_hat + c``, the fitted matrix (``c = -S b``)."""
        return np.c_[self.S_hat, self.c]


def smoothed_channels(log, model, window=0.2):
    """The configuration, velocity and acceleration of a model whose configuration moves additively.

    The poses (the configuration itself: the model's attitude is not a
    unit quaternion) interpolated on the log's grid and smoothed and
    differentiated column by column by the Savitzky-Golay filter of
    :func:`fmscal.plant.physics.spatial_motion` (a local polynomial of
    degree :data:`fmscal.plant.physics.ORDER`, ``mode="interp"`` at the
    ends), with the same window in samples (odd, at least 7).

    Parameters
    ----------
    log : plant.Log
        A log of the model's case.
    model : plant.Model
        Its attitude ``None`` or ``"angle"`` (positions and angles that add).
    window : float
        s.

    Returns
    -------
    q, v, a : ndarray, shape (N, nv) each
        Configuration, velocity and acceleration, in the configuration's order.

    Raises
    ------
    FmscalError
        A unit-quaternion attitude (:func:`fmscal.plant.physics.spatial_motion` is its smoothing), or a log
        shorter than the window.
    """
    if model.attitude == "quaternion":
        raise FmscalError("smoothed_channels takes a model whose configuration moves additively; a unit "
                          "quaternion's motion is fmscal.plant.physics.spatial_motion")
    k = 2 * edge(log, window) + 1
    if k > len(log):
        raise FmscalError(f"{log.name}: the log is {log.duration:g} s; differentiating its poses needs at least "
                          f"{window:g} s (the smoothing window)")
    rows = np.flatnonzero(log.has_pose)
    pose = np.column_stack([np.interp(log.t, log.t[rows], log.pose[rows, j]) for j in range(model.n_pose)])
    return tuple(savgol_filter(pose, k, ORDER, deriv=d, delta=log.dt, axis=0, mode="interp") for d in range(3))


def reading_rate(log, window=0.2):
    """The reading's rate of change at every sample, smoothed, shape (N, n_w).

    The Savitzky-Golay derivative of ``w_hat`` (a local polynomial of degree
    :data:`fmscal.plant.physics.ORDER`, ``mode="interp"`` at the ends) over the window
    :func:`smoothed_channels` takes for the poses: the rate a latency moves the reading by
    (eq. LF1 of :mod:`fmscal.observers.batch._linearised_floor`).

    Parameters
    ----------
    log : plant.Log
    window : float
        s.

    Returns
    -------
    ndarray, shape (N, n_w)
        Reading units per s.
    """
    k = min(2 * edge(log, window) + 1, (len(log) - 1) // 2 * 2 + 1)
    return savgol_filter(log.w_hat, k, min(ORDER, k - 1), deriv=1, delta=log.dt, axis=0, mode="interp")


def nominal_motion(log, model, window=0.2):
    """The motion state at every sample from the smoothed poses, in the model's layout, shape (N, nx).

    A unit-quaternion attitude: :func:`fmscal.plant.physics.smoothed_state`; a configuration that
    moves additively: :func:`smoothed_channels` (configuration and velocity) placed by
    :meth:`fmscal.plant.Model.state_from`. The nominal motion the linearised floor is linearised about.
    """
    if model.attitude == "quaternion":
        return smoothed_state(log, window)
    q, v, _ = smoothed_channels(log, model, window)
    x = np.empty((len(log), model.nx))
    x[:, list(model.q_index)] = q
    x[:, list(model.v_index)] = v
    return x


def describe_direction(direction, held=False, names=READING_NAMES):
    """A user's words for an undetermined direction of the reading (its components scaled to their spread).

    Parameters
    ----------
    direction : ndarray, shape (n_w + 1,)
        A unit direction of the augmented reading (``[tx .. fz, 1]`` in 3D).
    held : bool
        The data are held poses (a pose table): the remedy is what held
        poses can and cannot give.
    names : tuple of str
        The augmented reading's components; other than the spatial
        reading's (:data:`READING_NAMES`), the words are the plain ones
        (no gravity to turn, no torque about the centre of mass).

    Returns
    -------
    str

    A direction with a torque share (a quarter of its square or more) is torque
    the force does not already explain, which only angular acceleration makes.
    """
    parts = " ".join(f"{'+' if c >= 0 else '-'}{abs(c):.2f} {name}" for c, name in zip(direction, names)
                     if abs(c) >= 0.2).lstrip("+")
    if tuple(names) != READING_NAMES:
        return (f"S is not determined along the reading {parts}: the log hardly moves the reading there; drive "
                "every wrench component")
    torque = float(np.sum(direction[:3] ** 2))
    if held and torque >= 0.25:
        return (f"S is not determined along the reading {parts}: the torque there is only what the force makes "
                "about the centre of mass, and held poses never make more (that needs angular acceleration); "
                "record a moving log (t,qw,qx,qy,qz,x,y,z,tx,ty,tz,fx,fy,fz) to determine it")
    if held:
        return (f"S is not determined along the reading {parts}: the force hardly changes there; hold the tool at "
                "attitudes that turn gravity through more directions in the sensor frame (tilt it about another axis)")
    if torque >= 0.25:
        return (f"S is not determined along the reading {parts}: the torque there is only what the force makes "
                "about the centre of mass; the log holds too little angular acceleration (rotate the payload "
                "faster, about more axes)")
    return (f"S is not determined along the reading {parts}: the force hardly changes there; turn gravity "
            "through more directions in the sensor frame, or accelerate the payload")


def fit_inverse_dynamics(log, payload, gravity=GRAVITY, window=0.2, block=None, eiv=True):
    """Estimate ``S`` and the offset of a log by smoothed inverse dynamics and least squares.

    The wrench each sample needed, from the smoothed and differentiated
    poses: in 3D by Newton-Euler (``w_k = W_k pi``,
    :func:`fmscal.plant.physics.regressor`); on a model whose configuration
    moves additively (the planar one) by its dynamics inverted,
    ``w_k = A(x_k)^-1 (a_k - d(x_k))`` (eq. (1): ``w = G(theta)^-1 [theta'',
    X'', Y'']``), the state ``x_k`` and the accelerations ``a_k`` from
    :func:`smoothed_channels`. Then ``w_k = S w_hat_k + c`` (eq. (3) with
    the offset) row by row (:func:`fit_readings`).

    Parameters
    ----------
    log : plant.Log
        A log of the payload's (the model's) case.
    payload : plant.SpatialPayload or plant.Model
        The payload's mass properties (known), or the model: a spatial
        model stands for its payload and gravity (``gravity`` is then not
        read), any other model's dynamics are inverted as above (its
        ``input_matrix`` square, ``n_w == nv``).
    gravity : array_like, shape (3,)
        Gravity in the pose frame, m/s^2 (3D).
    window : float
        Smoothing window of the pose differentiation, s.
    block : float, optional
        Length of the blocks of the robust covariance, s. None (default):
        five correlation times of the residuals of a first fit, not shorter
        than ``window`` (eqs. (U1), (U2) of :mod:`fmscal.observers.batch._cluster_covariance`).
    eiv : bool
        Compensate the errors in variables: the reading is the regressor and
        its noise shrinks ``S`` along the directions the log barely excites
        (the torque not explained by the force, above all). With ``eiv``
        the normal equations lose the noise's share, ``(X^T X - N Sigma)
        theta = X^T w`` (Deming's regression), ``Sigma`` the reading's noise
        covariance estimated from the log (:func:`fmscal.plant.estimate_noise`).
        False gives the plain least squares, the reference in its simplest form.

    Returns
    -------
    InverseDynamicsFit
        Shapes ``n_w`` (6 in 3D, 3 in the plane) and ``n_w + 1``.

    Raises
    ------
    FmscalError
        A log of another case, a log shorter than the window, a reading that
        does not move beyond its noise, or a model whose ``input_matrix`` is
        not square.
    """
    names = READING_NAMES
    if isinstance(payload, Model) and payload.attitude == "quaternion":
        payload, gravity = payload.payload, payload.gravity
    if isinstance(payload, Model):
        model = payload
        model.check_log(log, "fit_inverse_dynamics")
        if model.n_w != model.nv:
            raise FmscalError(f"fit_inverse_dynamics inverts a square input matrix; a {model.name} model has "
                              f"{model.n_w} wrench components and {model.nv} accelerations")
        names = (*model.wrench_names, "1")
    else:
        SpatialPayload.check(payload, "fit_inverse_dynamics")
        gravity = as_finite_array(gravity, (3,), "gravity")
    if block is not None:
        block = as_positive_scalar(block, "block")
    trim = slice(edge(log, window), len(log.t) - edge(log, window))                   # the filter's edges
    if names is READING_NAMES:
        q, omega, alpha, p_ddot = spatial_motion(log, window)
        w = regressor(q[trim], omega[trim], alpha[trim], p_ddot[trim], gravity) @ payload.inertial_parameters
    else:
        w = _inverse_dynamics(log, model, window)[trim]
    wrench_sd = np.array(estimate_noise(log).wrench_sd)
    spread = np.std(log.w_hat[trim], axis=0)
    dead = np.flatnonzero(spread <= np.maximum(3 * wrench_sd, 1e-12 * np.abs(log.w_hat[trim]).max(axis=0)))
    if len(dead):
        raise FmscalError(f"{log.name}: the reading {', '.join(names[j] for j in dead)} does not move beyond "
                          "its noise: a stuck or dead channel, or a log that never loads it; S cannot be estimated")
    t = log.t[trim]
    if block is None:                                       # eq. (U2) on the residuals of a first fit
        first = fit_readings(w, log.w_hat[trim], None, wrench_sd if eiv else None, names=names)
        block = block_length(w - log.w_hat[trim] @ first.S_hat.T - first.c, log.dt, window)
    blocks = ((t - t[0]) // block).astype(int)
    fit = fit_readings(w, log.w_hat[trim], blocks, wrench_sd if eiv else None, names=names)
    warning = few_blocks(blocks, block)
    if warning is not None:
        fit.warnings.append(warning)
    return fit


def needed_wrench(log, model, window=0.2):
    """The wrench each sample needed, from the smoothed and differentiated poses, as :func:`fit_inverse_dynamics`
    computes it: Newton-Euler in 3D (``w_k = W_k pi``), the dynamics inverted on a model whose configuration
    moves additively (``w_k = A(x_k)^-1 (a_k - d(x_k))``, eq. (1) inverted in the plane).

    Parameters
    ----------
    log : plant.Log
        A log of the model's case.
    model : plant.Model
        Its payload known (and, in 3D, its gravity).
    window : float
        Smoothing window of the pose differentiation, s.

    Returns
    -------
    rows : slice
        The log's rows the filter's edges leave (``edge`` samples dropped at each end).
    w : ndarray, shape (len(rows), n_w)
        N m and N.

    Raises
    ------
    FmscalError
        A model whose dynamics do not invert (``input_matrix`` not square) and whose attitude is not a unit
        quaternion, or a log shorter than the window.
    """
    trim, (w,) = needed_wrenches(log, [model], window)
    return trim, w


def needed_wrenches(log, models, window=0.2):
    """:func:`needed_wrench` of one log for several models of its case (other payloads, other gravities): the
    poses smoothed and differentiated once.

    Parameters
    ----------
    log : plant.Log
    models : sequence of plant.Model
        Of one case (the first one's declarations are read).
    window : float
        s.

    Returns
    -------
    rows : slice
    w : list of ndarray, each shape (len(rows), n_w)
        One per model, N m and N.
    """
    first = models[0]
    trim = slice(edge(log, window), len(log.t) - edge(log, window))
    if first.attitude == "quaternion":
        q, omega, alpha, p_ddot = (v[trim] for v in spatial_motion(log, window))
        out = [None] * len(models)
        for gravity in dict.fromkeys(m.gravity for m in models):   # one regressor per gravity: w is linear in pi
            W = regressor(q, omega, alpha, p_ddot, gravity)
            which = [i for i, m in enumerate(models) if m.gravity == gravity]
            pis = np.column_stack([models[i].payload.inertial_parameters for i in which])
            w = (W.reshape(-1, W.shape[-1]) @ pis).reshape(len(W), W.shape[1], len(which))
            for col, i in enumerate(which):
                out[i] = w[:, :, col]
        return trim, out
    if first.n_w != first.nv:
        raise FmscalError(f"the wrench a {first.name} model's motion needs is its dynamics inverted; it has "
                          f"{first.n_w} wrench components and {first.nv} accelerations")
    x, a = _smoothed_motion(log, first, window)
    return trim, [np.asarray(_inverse_map(model, len(log))(x.T, a.T)).T[trim] for model in models]


def _smoothed_motion(log, model, window):
    """The state ``x`` and the accelerations ``a`` at every sample of a model whose configuration moves
    additively, from :func:`smoothed_channels`."""
    q, v, a = smoothed_channels(log, model, window)
    x = np.empty((len(log), model.nx))
    x[:, list(model.q_index)] = q
    x[:, list(model.v_index)] = v
    return x, a


def _inverse_dynamics(log, model, window):
    """The wrench each sample needed, ``w_k = A(x_k)^-1 (a_k - d(x_k))``, shape (N, n_w): the model's
    dynamics (eq. (1) in the plane) inverted on the smoothed motion (:func:`smoothed_channels`)."""
    x, a = _smoothed_motion(log, model, window)
    return np.asarray(_inverse_map(model, len(log))(x.T, a.T)).T


@lru_cache(maxsize=4)
def _inverse_map(model, N):
    """``(x, a) -> A(x)^-1 (a - d(x))`` (the model's dynamics inverted) as a casadi Function mapped over ``N``."""
    x, a = ca.SX.sym("x", model.nx), ca.SX.sym("a", model.nv)
    w = ca.solve(model.input_matrix(x), a - model.drift(x))
    return ca.Function(f"inverse_dynamics_{model.name}", [x, a], [w]).map(N)


def fit_readings(w, w_hat, blocks=None, wrench_sd=None, prior=None, held=False, names=READING_NAMES):
    """Least squares of ``[S | c]`` in ``w_k = S w_hat_k + c`` (eq. 3 with the offset ``c = -S b``), row by row.

    The regressor of every row is the augmented reading ``[w_hat_k; 1]``,
    each component scaled by its spread; what it leaves undetermined is
    reported as directions of that reading (module docstring).

    Parameters
    ----------
    w : ndarray, shape (N, n_w)
        The wrench each sample needed (Newton-Euler in 3D, eq. (1) inverted
        in the plane), N m and N.
    w_hat : ndarray, shape (N, n_w)
        The readings (sign-corrected), N m and N.
    blocks : ndarray of int, shape (N,), optional
        Each sample's block of time: the covariance is the cluster-robust
        sandwich over them, with the small-sample factor of eq. (U3)
        (:mod:`fmscal.observers.batch._cluster_covariance`). None: the samples are independent (the rows of a
        pose table), the covariance is ``s_i^2 (X^T X)^-1`` for row ``i``
        with ``s_i^2`` its residual variance over ``N - k`` degrees of
        freedom (``k`` the directions fitted).
    wrench_sd : ndarray, shape (n_w,), optional
        The reading's noise: the normal equations lose its share,
        ``(X^T X - N Sigma) theta = X^T w`` (errors in variables, Deming's
        regression); None: plain least squares.
    prior : ndarray, shape (n_w, n_w + 1), optional
        ``[S | c]`` where the data say nothing: the estimate is the least
        squares fit on the determined directions and the prior on the
        undetermined ones (the fit nearest the prior). None: every direction
        is fitted.
    held : bool
        The data are held poses: the warnings say what held poses cannot give.
    names : tuple of str
        The augmented reading's components (``n_w`` names and ``"1"``), for
        the warnings; the force components (names starting with ``f``) give
        the constant's scale. Default the spatial reading's.

    Returns
    -------
    InverseDynamicsFit
        With ``S_std`` infinite on every entry an undetermined direction
        touches, when ``prior`` is given.
    """
    n_w = w.shape[1]
    k = n_w + 1                                                                        # the augmented reading
    X = np.c_[w_hat, np.ones(len(w))]                                                  # (N, k)
    spread = np.r_[np.std(X[:, :n_w], axis=0), 1.0]
    spread[spread <= 0] = 1.0                               # a constant component: the constant's direction
    Xs = X / spread
    # the reading's noise covariance in scaled units (the constant 1 has none)
    sigma = np.diag((np.r_[wrench_sd, 0.0] / spread) ** 2 if wrench_sd is not None else np.zeros(k))
    information = Xs.T @ Xs - len(Xs) * sigma
    lam, u = np.linalg.eigh(information)            # symmetric; with the noise taken out, maybe indefinite
    kept = lam > 1e-12 * lam.max()
    theta0 = np.zeros((k, n_w)) if prior is None else (np.asarray(prior, dtype=float) * spread).T
    inverse = (u[:, kept] / lam[kept]) @ u[:, kept].T
    theta = theta0 + inverse @ Xs.T @ (w - Xs @ theta0)                                 # (k, n_w): rows of [S|c]^T
    e = w - Xs @ theta
    force = [j for j, name in enumerate(names[:n_w]) if name.startswith("f")] or list(range(n_w))
    weak = np.array([not kept[j] or _relative_std(u[:, j], lam[j], e, spread, force) > UNDETERMINED_STD
                     for j in range(k)])
    if prior is not None and (weak & kept).any():                   # the weak directions left at the prior
        kept &= ~weak
        inverse = (u[:, kept] / lam[kept]) @ u[:, kept].T
        theta = theta0 + inverse @ Xs.T @ (w - Xs @ theta0)
        e = w - Xs @ theta
    bread = np.kron(np.eye(n_w), inverse)
    if blocks is None:                                      # independent rows: s_i^2 (X^T X)^-1 for row i
        s2 = np.sum(e ** 2, axis=0) / max(len(e) - int(kept.sum()), 1)
        cov_scaled = np.kron(np.diag(s2), inverse)
    else:
        scores = np.zeros((blocks.max() + 1, k, n_w))
        # each sample's share of the estimating equation X^T e + Sigma theta = 0
        np.add.at(scores, blocks, Xs[:, :, None] * e[:, None, :] + (sigma @ theta)[None])
        scores = scores.transpose(0, 2, 1).reshape(len(scores), n_w * k)                 # row order of [S|c]
        cov_scaled = small_sample_factor(blocks, len(e), int(kept.sum())) * bread @ (scores.T @ scores) @ bread
    unscale = np.tile(1.0 / np.maximum(spread, 1e-300), n_w)
    cov = cov_scaled * np.outer(unscale, unscale)
    S_aug = (theta / np.maximum(spread, 1e-300)[:, None]).T                              # (n_w, k)
    undetermined = [u[:, j] for j in np.flatnonzero(weak)]
    warnings = [describe_direction(d, held, names) for d in undetermined]
    S_hat, c = S_aug[:, :n_w], S_aug[:, n_w]
    b, b_std = _offset(S_hat, c, cov)
    if prior is not None and undetermined:                  # the prior's entries are not estimates
        touched = np.tile(np.abs(np.array(undetermined)).max(axis=0) > 1e-6, n_w)
        cov[touched, :] = np.inf
        cov[:, touched] = np.inf
    S_std = np.sqrt(np.maximum(np.diag(cov), 0)).reshape(n_w, k)[:, :n_w]
    residual_rms = np.sqrt(np.mean(e ** 2, axis=0))
    unexplained = residual_rms ** 2 / np.maximum(np.var(w, axis=0), 1e-300)
    return InverseDynamicsFit(S_hat=S_hat, S_std=S_std, b=b, b_std=b_std, cov=cov, undetermined=undetermined,
                              warnings=warnings, converged=not undetermined, residual_rms=residual_rms,
                              unexplained=unexplained, c=c)


def _relative_std(direction, information, e, spread, force):
    """The uncertainty of ``S`` along a direction of the scaled reading, relative to a unit gain.

    Along the unit direction ``d`` of the scaled reading the fit's uncertainty
    is ``sigma / sqrt(lambda)`` (wrench units per scaled unit, ``lambda`` the
    information along ``d``, ``sigma`` the largest residual spread of a row);
    a unit gain maps the same move of the reading to ``|d * spread|`` of
    wrench, the force channels' (indices ``force``) mean spread standing in for the constant's.
    """
    sigma = np.sqrt(np.mean(e ** 2, axis=0).max())
    scale = np.r_[spread[:-1], spread[force].mean()]
    return sigma / np.sqrt(max(information, 1e-300)) / max(np.linalg.norm(direction * scale), 1e-300)


def _offset(S_hat, c, cov):
    """``b = -S^-1 c`` and its uncertainty by the delta method (``S`` and ``c`` both uncertain).

    NaN where ``S_hat`` is singular (a direction the log did not determine left at zero).
    """
    n_w = len(c)
    if not np.isfinite(np.linalg.cond(S_hat)) or np.linalg.cond(S_hat) > 1e12:
        return np.full(n_w, np.nan), np.full(n_w, np.nan)
    S_inv = np.linalg.inv(S_hat)
    b = -S_inv @ c
    # d b = -S^-1 (dS b + dc): Jacobian with respect to vec([S | c]) in row order
    k = n_w + 1
    J = np.zeros((n_w, n_w * k))
    for i in range(n_w):
        J[:, k * i:k * i + n_w] = -np.outer(S_inv[:, i], b)
        J[:, k * i + n_w] = -S_inv[:, i]
    return b, np.sqrt(np.maximum(np.diag(J @ cov @ J.T), 0))
