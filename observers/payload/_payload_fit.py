"""What practitioners estimate with ``S`` known: the payload's mass properties and the offset.

With the calibration ``S`` known (the identity, or a calibration file such
as the factory matrix), the corrected reading ``S w_hat`` of a spatial log
is linear in the ten inertial parameters ``pi = (m, h = m com, I_O)`` and in
the offset ``c = S b`` (Newton-Euler at the sensor point, in sensor axes;
``I_O`` the inertia about the sensor point)::

    f     = m a_g + alpha x h + omega x (omega x h)
    tau_O = I_O alpha + omega x (I_O omega) + h x a_g
    S w_hat = [tau_O; f] + c

with ``a_g = R^T (p_ddot - g)``. Static poses (``omega = alpha = 0``)
determine ``m``, ``h`` and ``c`` when gravity covers enough directions in
the sensor frame; the inertia needs angular acceleration. The motion comes
from the poses by smoothing differentiation (:func:`fmscal.plant.
differentiate.spatial_motion`); the fit is weighted least squares (the
channel's noise estimated from a first pass), and its covariance is the
cluster-robust sandwich over blocks of time, so that correlated residuals
(drift, smoothing) do not make it claim too much: the blocks five times the
residuals' correlation time, not shorter than the smoothing window, and the
small-sample factor of few blocks (:mod:`fmscal.observers.batch._cluster_covariance`).
Then ``com = h / m`` and ``I_c = I_O + m [com]x^2`` (the parallel-axis
theorem), their uncertainties by the delta method.

Like a pose table's fit, the log's reports what it covered and the held
poses to record next (:mod:`fmscal.observers.payload._coverage`), and names the flag
(``--gravity estimate`` or ``--mounting estimate``) whose rotation explains
residuals far above the noise.

Where ``S`` is not the one given (``S = I`` on a sensor whose force gains
differ), the three force axes each ask for their own mass: the fit is
repeated with one mass per axis, their disagreement tested against the
cluster-robust covariance (eq. P1, :func:`_axis_masses`), and where it is
beyond chance the mass's variance takes their spread (eq. P2, as a pose
table's N8), with a warning naming the gains.
"""

from typing import NamedTuple

import numpy as np
from scipy.optimize import least_squares

from fmscal.plant.io import check_spatial_log_units, reading_sign
from fmscal.plant.numerics import FmscalError, as_bool, as_finite_array, as_positive_scalar
from fmscal.plant.physics import (GRAVITY, INERTIA_NAMES, SpatialPayload, check_calibration, edge, regressor,
                                  rotation_matrix, skew, spatial_motion)

from scipy.stats import f as f_dist

from fmscal.observers.batch import few_blocks, pseudo_inverse, sandwich, time_blocks, weighted_fit
from ._coverage import cone_deg, in_words, next_poses, weak_directions
from ._estimate import INERTIA_ROWS, PayloadEstimate, propagate_covariance
from ._static_fit import (ODDS, TILT_RATIO, _OFFSET_NAMES, Refit, _Model, _angle_deg, _axis, _exp, _start,
                          _tangent_basis, cone_warning, gravity_up, other_convention, rotation_check,
                          rotations_unresolved)

__all__ = ["identify_payload", "DETERMINED", "HOLD", "REFERENCES"]


#: A group (mass, centre of mass, inertia) counts as determined when its one-sigma uncertainty is below
#: this fraction of its size: above it, the noise of the differentiated poses biases the fit by as much
#: (errors in variables: on spatial-weak and spatial-static the inertia comes out low by several sigma).
DETERMINED = 0.02


def identify_payload(log, S=None, gravity=GRAVITY, window=0.2, block=None, reading="reaction", estimate_gravity=False,
                     estimate_mounting=False, max_mass=None):
    """Estimate the payload's mass, centre of mass, inertia and the sensor's offset, with ``S`` known.

    Parameters
    ----------
    log : plant.Log
        A spatial log.
    S : array_like, shape (6, 6), optional
        The calibration (default: the identity).
    gravity : array_like, shape (3,)
        Gravity in the pose frame, m/s^2.
    window : float
        Smoothing window of the pose differentiation, s.
    block : float, optional
        Length of the blocks of the robust covariance, s; default the rule of
        :func:`block_length` (eq. (U2)) on the fit's residuals.
    reading : {"reaction", "load"}
        The reading's sign: the wrench the mount applies to the payload (the
        toolkit's convention), or the wrench the tool applies to the sensor
        (``load``: the reading is negated first).
    estimate_gravity : bool
        Estimate gravity's direction in the pose frame too (a tilted or
        wall-mounted base); only the size of ``gravity`` is taken.
    estimate_mounting : bool
        Estimate the rotation ``M`` of the sensor's axes on the tracked frame
        too (a sensor bolted at an angle): :func:`regressor` with ``mounting``.
    max_mass : float, optional
        The heaviest payload taken, kg (default :data:`fmscal.plant.io.MAX_WRIST_MASS`): readings that weigh
        more are refused as a slipped unit (mN).

    Returns
    -------
    PayloadEstimate

    Raises
    ------
    plant.io.UnitsError
        A unit slip or a convention the data show, named in one line before the fit
        (:func:`fmscal.plant.io.check_spatial_log_units`, :func:`fmscal.plant.io.check_table_units`).
    FmscalError
        The log does not determine the mass, or its mass comes out negative
        (the reading follows the other sign convention: the message names the flag).
    """
    estimate_gravity = as_bool(estimate_gravity, "estimate_gravity")       # text ("False") is refused, not true
    estimate_mounting = as_bool(estimate_mounting, "estimate_mounting")
    sign = reading_sign(reading)
    S = np.eye(6) if S is None else check_calibration(S, "S", size=6)
    gravity = as_finite_array(gravity, (3,), "gravity")
    if not np.linalg.norm(gravity) > 0:                  # as fit_static: a direction is needed to weigh anything
        raise FmscalError("gravity must not be zero")
    block = None if block is None else as_positive_scalar(block, "block")
    check_spatial_log_units(log, gravity, S=S, max_mass=max_mass)   # a slipped unit named in one line
    q, omega, alpha, p_ddot = spatial_motion(log, window)
    trim = slice(edge(log, window), len(log.t) - edge(log, window))                   # the filter's edges
    W = regressor(q, omega, alpha, p_ddot, gravity)[trim]
    y = (sign * log.w_hat @ S.T)[trim]
    n = len(y)
    times = (log.t[trim], window, block)
    motion = tuple(v[trim] for v in (q, omega, alpha, p_ddot))
    masses = None                                   # each force axis's own mass, where they disagree (eq. P1)
    if estimate_gravity or estimate_mounting:
        try:
            fit, information = _identify_rotations(log.name, motion, y, gravity, times, S, reading, estimate_gravity,
                                                   estimate_mounting)
        except FmscalError as err:      # gravity up or a negative mass: the sign only where gravity fixed says so
            if estimate_mounting or "the reading follows the other sign convention" not in str(err):
                raise
            fixed_mass = float(np.linalg.lstsq(_design(W), y.ravel(), rcond=None)[0][0])
            if not fixed_mass > 0:
                raise
            raise FmscalError(rotations_unresolved(log.name, len(y), fixed_mass, "samples")) from None
    else:
        X = _design(W)
        theta, _, residual = weighted_fit(X, y.ravel(), np.ones(6 * n))
        sd = np.sqrt(np.mean(residual.reshape(n, 6) ** 2, axis=0))
        blocks, length = time_blocks(residual.reshape(n, 6), *times)
        theta, cov, residual = weighted_fit(X, y.ravel(), np.tile(1.0 / np.maximum(sd, 1e-12), n), blocks)
        if np.isfinite(cov[0, 0]) and theta[0] < 0:
            raise FmscalError(other_convention(log.name, theta[0], reading))
        masses = _axis_masses(X, y.ravel(), np.tile(1.0 / np.maximum(sd, 1e-12), n), blocks, theta[0])
        if masses is not None:                                                   # eq. (P2)
            m = np.array(list(masses.values()))
            cov = cov.copy()
            cov[0, 0] += float(np.sum((m - m.mean()) ** 2) / (2 * len(m)))
        fit = _report(theta, cov, S, np.sqrt(np.mean(residual.reshape(n, 6) ** 2, axis=0)))
        _blocks_used(fit, blocks, length)
        Xw = X / np.tile(np.maximum(sd, 1e-12), n)[:, None]
        information = _Information(Xw.T @ Xw, theta, np.zeros(0), residual / np.tile(np.maximum(sd, 1e-12), n),
                                   1.0 / np.maximum(sd, 1e-12), (float(np.linalg.norm(gravity)),
                                   gravity / np.linalg.norm(gravity), np.eye(3), False, False))
    _coverage(fit, motion[0], log.t[trim], information)
    named = False
    if not (estimate_gravity and estimate_mounting):
        named = _check_rotations(fit, log.name, motion, y, gravity, times, S, reading, estimate_gravity,
                                 estimate_mounting)
    _check_misfit(fit, y, S is None or np.allclose(S, np.eye(6)), named, None if named else masses)
    # what the file records: the sign, the noise the fit weighed by, the gravity it took as given
    fit.reading, fit.noise_sd = reading, 1.0 / information.weights
    fit.gravity_given = None if estimate_gravity else gravity
    return fit


def _axis_masses(X, y, weights, blocks, mass):
    """Each force axis's own mass where the three disagree beyond chance, else None.

    The fit is repeated with the mass's column split by force axis (``f_kj =
    m_j a_kj + ...``, the rest of the model as it is); the two differences
    ``d = (m_x - m_z, m_y - m_z)`` with their cluster-robust covariance ``C``
    over the ``G`` blocks of time (eq. (U3)) give Hotelling's statistic, as
    eq. (M2) of :mod:`fmscal.observers.diagnostics._misfit` takes it::

        (G - 2) / (2 (G - 1)) d^T C^-1 d  ~  F(2, G - 2)                    (P1)

    Only the axes whose own mass the log determines (a standard deviation
    below :data:`DETERMINED` of it: an axis the motion barely loads has a mass
    the smoothed accelerations bias) are compared, ``K`` differences from the
    last of them (``K = 2`` above, ``F(K, G - K)``). Below
    :data:`fmscal.observers.payload._static_fit.ODDS` the force gains
    differ between the axes (``S`` is not the one given), and the mass's
    variance takes their spread, as a pose table's (eq. N8)::

        var(m) += sum_j (m_j - mean m)^2 / (2 (K + 1))                      (P2)

    (the centre of mass and the inertia about it, computed from the mass, widen
    with it by the delta method). No test with fewer than two such axes, or
    ``K + 1`` blocks or fewer.

    Parameters
    ----------
    X, y, weights, blocks
        The fit's design, observations, weights and blocks (:func:`weighted_fit`).
    mass : float
        The fit's mass, kg.

    Returns
    -------
    dict or None
        The compared axes' masses, kg, by axis (``"x"``, ``"y"``, ``"z"``).
    """
    count = len(np.unique(blocks))
    if count <= 3:
        return None
    axis = np.arange(len(y)) % 6
    split = np.column_stack([X[:, 0] * (axis == j) for j in (3, 4, 5)] + [X[:, 1:]])
    theta, cov, _ = weighted_fit(split, y, weights, blocks)
    masses, std = theta[:3], np.sqrt(np.maximum(np.diag(cov[:3, :3]), 0))
    kept = np.flatnonzero(np.isfinite(std) & (std < DETERMINED * abs(mass)))
    k = len(kept) - 1
    if k < 1 or count <= k + 1:
        return None
    D = np.c_[np.eye(k), -np.ones(k)]
    d, C = D @ masses[kept], D @ cov[np.ix_(kept, kept)] @ D.T
    if not (np.all(np.isfinite(C)) and np.linalg.det(C) > 0):
        return None
    statistic = (count - k) / (k * (count - 1)) * float(d @ np.linalg.solve(C, d))
    if f_dist.sf(statistic, k, count - k) >= ODDS:
        return None
    return {"xyz"[j]: float(masses[j]) for j in kept}


def _check_misfit(fit, y, identity, named=False, masses=None):
    """Warn, and clear ``converged``, where the force residuals exceed the reading's noise, the force axes' own
    masses disagree, or the attitudes span a narrow cone.

    The noise is the reading's sample-to-sample scatter (``rms(diff) /
    sqrt 2``, as :func:`_check_rotations`); residuals beyond
    :data:`fmscal.observers.payload.TILT_RATIO` times it, where no rotation
    was named (``named``), are a model that does not fit: ``S`` (cross-talk,
    gains) the likely cause. ``masses`` (:func:`_axis_masses`): the force
    gains differ between the axes, by the masses' spread over their mean.
    One line names both. The cone is :func:`fmscal.observers.payload.cone_warning`'s.
    """
    noise = float(np.sqrt(np.mean(np.diff(y[:, 3:], axis=0) ** 2) / 2))
    fixed = float(np.sqrt(np.mean(np.square(fit.residual_rms[3:]))))
    parts = []
    if fixed > TILT_RATIO * noise and not named:
        parts.append(f"the force residuals are {fixed / max(noise, 1e-300):.0f} times the reading's noise (its "
                     "sample-to-sample scatter): the model does not fit")
    if masses is not None:
        m = np.array(list(masses.values()))
        spread = 100 * float(np.ptp(m) / abs(np.mean(m)))
        parts.append(f"the force gains seem to differ by {spread:.2g} % between axes (each force axis's own mass: "
                     + ", ".join(f"{axis} {value:.4g} kg" for axis, value in masses.items())
                     + "; the mass's uncertainty takes their spread)")
    if parts:
        told = "S = I may be wrong: calibrate S" if identity else "the calibration given may be wrong"
        fit.warnings.append("; ".join(parts) + f"; {told}")
        fit.converged = False
    if (line := cone_warning(fit.cone_deg)) is not None:
        fit.warnings.append(line)
        fit.converged = False


def _blocks_used(fit, blocks, length):
    """Record the blocks' length in ``fit``, and warn when they are too few (:func:`few_blocks`)."""
    fit.block = float(length)
    warning = few_blocks(blocks, length)
    if warning is not None:
        fit.warnings.append(warning)


def _check_rotations(fit, name, motion, y, gravity, times, S, reading, estimate_gravity, estimate_mounting):
    """Warn, and clear ``converged``, when gravity's tilt or the mounting explains what ``fit`` leaves.

    Cheap on the common path: the fit is repeated, once with gravity's
    direction estimated and once with the mounting (each where ``fit`` did
    not), only when the force residuals exceed :data:`fmscal.observers.
    static_fit.TILT_RATIO` times the reading's noise, estimated from the
    differences of consecutive samples (``rms(diff) / sqrt 2``; white noise
    assumed, a log whose reading changes much between samples opens the
    check less often); the warning is :func:`fmscal.observers.payload.rotation_check`'s. Returns whether it
    named a rotation.
    """
    force = y[:, 3:]
    noise = float(np.sqrt(np.mean(np.diff(force, axis=0) ** 2) / 2))
    fixed = float(np.sqrt(np.mean(np.square(fit.residual_rms[3:]))))
    if not fixed > TILT_RATIO * noise:
        return False

    def refit(gravity_free, mounting_free):
        try:
            free = _identify_rotations(name, motion, y, gravity, times, S, reading, gravity_free, mounting_free)[0]
        except FmscalError:
            return None
        return Refit(float(np.sqrt(np.mean(np.square(free.residual_rms[3:])))), free.gravity, free.gravity_std_deg,
                     free.mounting_deg, free.mounting_std_deg)

    warning = rotation_check(fixed, gravity, refit, estimate_gravity, estimate_mounting)
    if warning is not None:                 # first: the model is wrong, and the other warnings may follow from it
        fit.warnings.insert(0, warning)
        fit.converged = False
    return warning is not None


class _Information(NamedTuple):
    """What the coverage of a log's fit needs (:func:`_coverage`).

    Attributes
    ----------
    information : ndarray, shape (p, p)
        The weighted information over ``(pi (10), c (6), angles)``.
    theta : ndarray, shape (16,)
        ``pi`` and ``c``.
    eta : ndarray
        The angles of gravity's direction and of the mounting, where estimated (the parameters of
        :class:`fmscal.observers.payload._static_fit._Model`).
    residual : ndarray
        The weighted residuals.
    weights : ndarray, shape (6,)
        Each channel's weight.
    frame : tuple
        ``(g_size, d0, M0, estimate_gravity, estimate_mounting)``: the angles' origin.
    """

    information: np.ndarray
    theta: np.ndarray
    eta: np.ndarray
    residual: np.ndarray
    weights: np.ndarray
    frame: tuple


#: How long a suggested pose of a log is held, s: its samples count in the score of the next poses
#: (eq. (N1) of :mod:`fmscal.observers.payload._coverage`).
HOLD = 3.0
#: How many attitudes, evenly spaced along a log, the suggested turns start from.
REFERENCES = 10


def _coverage(fit, q, t, info):
    """A log's ``cone_deg``, ``undetermined`` and ``next_poses`` in ``fit``, as a table's (:mod:`fmscal.observers.
    coverage`).

    The cone is of gravity's directions in the sensor frame over the log's
    samples. The information is taken to the physical parameters ``(m, com,
    I_c, c, angles)`` (``F' = T^-T F T^-1``, ``T`` their Jacobian in ``pi``);
    the parameters the log determines worse than :data:`DETERMINED` (2 % of
    the mass, of the centre of mass's distance or 1 mm, of the inertia's mean
    diagonal; the offset only where not determined) are named in words. The
    next poses are scored as a table's, eq. (N1), on the information with the
    inertia eliminated (held poses do not inform it), each pose held
    :data:`HOLD` s, from :data:`REFERENCES` attitudes along the log. The
    covariance there is the model-based ``s^2 F^-1``; the reported
    uncertainties are the cluster-robust ones.
    """
    g_size, d0, M0, estimate_gravity, estimate_mounting = info.frame
    model = _Model(None, None, g_size, d0, M0, estimate_gravity, estimate_mounting)
    theta = info.theta
    R = np.moveaxis(rotation_matrix(q.T), -1, 0)
    values = _physical(theta[:10])
    _, _, _, d, M = model.parts(np.r_[values[:4], theta[10:16], info.eta])
    fit.cone_deg = cone_deg(np.einsum("ji,nkj,k->ni", M, R, -d))
    T = np.eye(len(info.information))
    T[:10, :10] = _physical_jacobian(theta[:10])
    T_inv = np.linalg.inv(T)
    F = T_inv.T @ info.information @ T_inv
    s2 = float(np.sum(info.residual ** 2) / max(info.residual.size - len(F), 1))
    names = ("m", "com_x", "com_y", "com_z", *(f"I_{n}" for n in INERTIA_NAMES), *(f"c_{n}" for n in _OFFSET_NAMES),
             *model.names[10:])
    scale = np.r_[DETERMINED * values[0], np.full(3, max(DETERMINED * np.linalg.norm(values[1:4]), 1e-3)),
                  np.full(6, DETERMINED * max(np.mean(values[4:7]), 1e-9)), np.full(6, np.inf),
                  np.full(len(info.eta), np.radians(0.2))]
    fit.undetermined = in_words(names, weak_directions(F, s2, scale), "this log")
    keep = np.r_[0:4, 10:len(F)]                          # the inertia eliminated: F_kk - F_ki F_ii^+ F_ik
    F_t = F[np.ix_(keep, keep)] - F[np.ix_(keep, range(4, 10))] @ np.linalg.pinv(F[4:10, 4:10]) @ F[np.ix_(
        range(4, 10), keep)]
    refs = np.unique(np.linspace(0, len(t) - 1, REFERENCES).round().astype(int))
    dt = float(np.median(np.diff(t)))
    fit.next_poses = next_poses(model, np.r_[values[:4], theta[10:16], info.eta], F_t, info.weights, s2, R[refs],
                                [f"the attitude at t = {t[k]:.1f} s" for k in refs], rows=HOLD / dt,
                                held=f" and hold it {HOLD:g} s")


def _design(W):
    """The design matrix of ``[tau_O; f] + c = W pi + c``: ``[W | I]`` stacked, shape (6N, 16)."""
    n = len(W)
    return np.concatenate([W, np.broadcast_to(np.eye(6), (n, 6, 6))], axis=2).reshape(6 * n, 16)


def _identify_rotations(name, motion, y, gravity, times, S, reading, estimate_gravity, estimate_mounting):
    """:func:`identify_payload` with gravity's direction and/or the mounting estimated too.

    Variable projection: for given angles (gravity's two across its start
    direction, the mounting's rotation vector about its start) the payload
    and the offset are the weighted least squares of the linear model; the
    angles minimise what is left (Levenberg-Marquardt). The covariance is the
    cluster-robust sandwich over the full Jacobian (the linear parameters and
    the angles together), so the angles' uncertainty enters the payload's.
    """
    q, omega, alpha, p_ddot = motion
    g = np.asarray(gravity, dtype=float)
    R = np.moveaxis(rotation_matrix(q.T), -1, 0)
    _, d0, M0, g_size = _start(R, y, g, estimate_gravity, estimate_mounting, acc=p_ddot)
    e1, e2 = _tangent_basis(d0)
    k_g = 2 if estimate_gravity else 0

    def parts(eta):
        d = _exp(eta[0] * e1 + eta[1] * e2) @ d0 if estimate_gravity else d0
        M = M0 @ _exp(eta[k_g:k_g + 3]) if estimate_mounting else M0
        return g_size * d, M

    def design(eta):
        g_eta, M = parts(eta)
        return _design(regressor(q, omega, alpha, p_ddot, g_eta, M if estimate_mounting else None))

    def solve(eta, weights):
        X = design(eta)
        Xw = X * weights[:, None]
        theta = pseudo_inverse(Xw)[0] @ (Xw.T @ (y.ravel() * weights))
        return X, theta

    def residual(eta, weights):
        X, theta = solve(eta, weights)
        return (y.ravel() - X @ theta) * weights

    n = len(y)
    eta = np.zeros(k_g + (3 if estimate_mounting else 0))
    weights = np.ones(6 * n)
    for _ in range(2):                      # plain, then each channel weighted by its residual spread
        eta = least_squares(residual, eta, args=(weights,), method="lm", xtol=1e-12, ftol=1e-12).x
        sd = np.sqrt(np.mean((residual(eta, weights) / weights).reshape(n, 6) ** 2, axis=0))
        weights = np.tile(1.0 / np.maximum(sd, 1e-12), n)
    X, theta = solve(eta, weights)
    e = (y.ravel() - X @ theta) * weights
    blocks, length = time_blocks(e.reshape(n, 6), *times)
    # the full Jacobian: the linear parameters' columns, and the angles' by central differences
    columns = []
    for i in range(len(eta)):
        step = np.zeros(len(eta))
        step[i] = 1e-6
        columns.append((design(eta + step) @ theta - design(eta - step) @ theta) / 2e-6)
    J = np.column_stack([X, *columns]) * weights[:, None]
    inverse, determined = pseudo_inverse(J)
    cov = sandwich(J, e, blocks, inverse, determined)
    g_hat, M = parts(eta)
    std = np.sqrt(np.maximum(np.diag(cov)[16:], 0))
    # gravity up, where its direction is determined: the reading's sign is the other one, or the base upside down
    if estimate_gravity and g_hat[2] > 0 > g[2] and np.all(np.isfinite(std[:2])) and np.all(std[:2] < 0.5):
        raise FmscalError(gravity_up(name, g_hat[2] / np.linalg.norm(g_hat), reading))
    if np.isfinite(cov[0, 0]) and theta[0] < 0:
        raise FmscalError(other_convention(name, theta[0], reading))
    fit = _report(theta, cov[:16, :16], S, np.sqrt(np.mean((e / weights).reshape(n, 6) ** 2, axis=0)))
    _blocks_used(fit, blocks, length)
    if estimate_gravity:
        fit.gravity = g_hat
        fit.gravity_std_deg = float(np.degrees(np.sqrt((std[0] ** 2 + std[1] ** 2) / 2)))
    if estimate_mounting:
        fit.mounting = M
        fit.mounting_deg = _angle_deg(M)
        fit.mounting_std_deg = float(np.degrees(np.sqrt(np.sum(std[k_g:k_g + 3] ** 2) / 3)))
        fit.mounting_axis = _axis(M)
    frame = (g_size, d0, M0, estimate_gravity, estimate_mounting)
    return fit, _Information(J.T @ J, theta, eta, e, weights[:6], frame)


def _physical(theta):
    """``(m, com, I_c entries)`` from ``pi = (m, h, I_O)``: ``com = h / m``, ``I_c = I_O + m [com]x^2``."""
    m, h, io = theta[0], theta[1:4], theta[4:10]
    com = h / m
    I_O = np.array([[io[0], io[3], io[4]], [io[3], io[1], io[5]], [io[4], io[5], io[2]]])
    r = skew(com)
    I_c = I_O + m * r @ r
    return np.r_[m, com, I_c[0, 0], I_c[1, 1], I_c[2, 2], I_c[0, 1], I_c[0, 2], I_c[1, 2]]


def _physical_jacobian(pi):
    """``d (m, com, I_c) / d pi`` by central differences, shape (10, 10)."""
    J = np.zeros((10, 10))
    step = 1e-7 * np.maximum(np.abs(pi), 1e-6)
    for i in range(10):
        d = np.zeros(10)
        d[i] = step[i]
        J[:, i] = (_physical(pi + d) - _physical(pi - d)) / (2 * step[i])
    return J


def _possible(values):
    """True when ``(m, com, I_c)`` is a body that can exist (positive definite, triangle inequality)."""
    try:
        SpatialPayload(values[0], values[4:10], values[1:4])
    except FmscalError:
        return False
    return True


def _report(theta, cov, S, residual_rms):
    if not np.isfinite(cov[0, 0]) or theta[0] <= 0:
        raise FmscalError("the log does not determine the payload's mass: it holds no force that gravity or "
                          "motion explains (is the reading in N and the pose in m and unit quaternions?)")
    values = _physical(theta[:10])
    S_inv = np.linalg.inv(S)
    T = np.zeros((16, 16))                       # (pi, c) -> (m, com, I_c, b): eq. (E1) of _estimate
    T[:10, :10], T[10:, 10:] = _physical_jacobian(theta[:10]), S_inv
    full = propagate_covariance(T, cov)
    std = np.sqrt(np.maximum(np.diag(full)[:10], 0))
    b = S_inv @ theta[10:]
    b_std = np.sqrt(np.maximum(np.diag(full)[10:], 0))
    warnings = []
    mass_ok = std[0] < DETERMINED * values[0]
    com_ok = np.all(std[1:4] < np.maximum(DETERMINED * np.linalg.norm(values[1:4]), 1e-3))
    inertia_scale = max(np.mean(values[4:7]), 1e-9)
    inertia_ok = bool(np.all(std[4:] < DETERMINED * inertia_scale)) and _possible(values)
    offset_ok = bool(np.all(np.isfinite(b_std)))
    if not mass_ok or not com_ok:
        warnings.append("the mass and centre of mass are not determined: hold the payload at attitudes that turn "
                        "gravity through several directions in the sensor frame")
    inertia_reason = None if inertia_ok else ("the log holds too little angular acceleration (rotate faster, or "
                                              "about more axes)")
    if not inertia_ok:
        warnings.append(f"the inertia is not determined: {inertia_reason}")
    if not offset_ok:
        warnings.append("the offset is not separated from the weight: turn gravity through more directions "
                        "in the sensor frame")
    return PayloadEstimate(mass=values[0], mass_std=std[0], com=values[1:4], com_std=std[1:4],
                      inertia=values[4:] if inertia_ok else None, inertia_std=std[4:] if inertia_ok else None,
                      b=b, b_std=b_std, residual_rms=residual_rms, warnings=warnings,
                      converged=bool(mass_ok and com_ok and inertia_ok and offset_ok),
                      payload_determined=bool(mass_ok and com_ok), inertia_reason=inertia_reason,
                      cov=propagate_covariance(np.eye(16), full, () if inertia_ok else INERTIA_ROWS))
