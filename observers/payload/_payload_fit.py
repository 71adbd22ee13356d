"""What practitioners estimate with ``S`` known: the payload's mass properties, the force gains and the offset.

With the calibration ``S`` known (the identity, or a calibration file such
as the factory matrix), the corrected reading ``y = sigma S w_hat`` of a spatial log
is linear in the ten inertial parameters ``pi = (m, h = m com, I_O)`` and in
the offset ``c = S b`` for given force gains (eq. (P0) of
:class:`fmscal.plant.PayloadModel`; Newton-Euler at the sensor point, in sensor axes,
``I_O`` the inertia about the sensor point)::

    f     = m a_g + alpha x h + omega x (omega x h)
    tau_O = I_O alpha + omega x (I_O omega) + h x a_g
    y = [tau_O; f / g_f] + c

with ``a_g = R^T (p_ddot - g)`` and ``g_f`` the force axes' gains relative to
their mean (a sensor whose ``S`` is its maker's reads its force axes a few
percent apart). Static poses (``omega = alpha = 0``)
determine ``m``, ``h``, the gains and ``c`` when gravity covers enough directions in
the sensor frame; the inertia needs angular acceleration. The motion comes
from the poses by smoothing differentiation (:func:`fmscal.plant.
differentiate.spatial_motion`); the fit is weighted least squares (the
channel's noise estimated from a first pass) for given gains, the gains
minimising what it leaves (variable projection, :func:`_fit_log`), and its
covariance is the cluster-robust sandwich over blocks of time, so that correlated residuals
(drift, smoothing) do not make it claim too much: the blocks five times the
residuals' correlation time, not shorter than the smoothing window, and the
small-sample factor of few blocks (:mod:`fmscal.observers.batch._cluster_covariance`).
Then ``com = h / m`` and ``I_c = I_O + m [com]x^2`` (the parallel-axis
theorem), their uncertainties by the delta method.

The payload counts as determined by what its uncertainty does to the
compensated wrench over the cone of attitudes the log spans, against a
tolerance tied to the reading's noise (:mod:`fmscal.observers.payload._effect`,
eqs. E1-E4); the inertia keeps its own rule (:data:`DETERMINED`) and must also
leave the compensated torque within the tolerance at the recorded motion.
Like a pose table's fit, the log's reports what it covered and the held
poses to record next (:mod:`fmscal.observers.payload._coverage`), and names the flag
(``--gravity estimate`` or ``--mounting estimate``) whose rotation explains
residuals far above the noise.

:func:`identify_payload` takes every shape of data (a log, a pose table, an
attitude-only log's held segments), as :func:`fmscal.analysis.calibrate` does.
"""

from typing import NamedTuple

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import norm

from fmscal.plant.io import AttitudeLog, Log, PoseTable, check_spatial_log_units, held_table, reading_sign
from fmscal.plant.numerics import FmscalError, as_bool, as_finite_array, as_positive_scalar
from fmscal.plant.physics import (GRAVITY, INERTIA_NAMES, PayloadModel, SpatialPayload, check_calibration, edge,
                                  find_model, rotation_matrix, skew, spatial_motion)

from fmscal.observers.batch import few_blocks, pseudo_inverse, sandwich, time_blocks
from ._coverage import cone_deg, in_words, next_poses, weak_directions
from ._effect import (DEFAULT_TOLERANCE, check_tolerance, circle_axis, cone_attitudes, inertia_effect, judge,
                      reading_noise, static_effect)
from ._estimate import INERTIA_ROWS, PayloadEstimate, propagate_covariance
from ._static_fit import (ODDS, TILT_RATIO, _OFFSET_NAMES, Refit, _Model, _angle_deg, _axis, _exp, _start,
                          _tangent_basis, _widened, cone_warning, fit_static, gains_differ, gains_of, gravity_up,
                          other_convention, rotation_check, rotations_unresolved)

__all__ = ["identify_payload", "DETERMINED", "HOLD", "REFERENCES"]


#: The inertia counts as determined when each entry's one-sigma uncertainty is below this fraction of its mean
#: diagonal: above it, the noise of the differentiated poses biases the fit by as much (errors in variables: on
#: spatial-weak and spatial-static the inertia comes out low by several sigma). It must also leave the compensated
#: torque within the tolerance at the recorded motion (:func:`fmscal.observers.payload._effect.inertia_effect`).
DETERMINED = 0.02


def identify_payload(data, S=None, gravity=GRAVITY, window=0.2, block=None, reading="reaction",
                     estimate_gravity=False, estimate_mounting=False, max_mass=None, tolerance=None):
    """Estimate the payload's mass properties, the force gains and the sensor's offset with ``S`` known, from any data.

    One call for every shape :func:`fmscal.analysis.read_data` returns: a spatial log (the offset, the mass,
    the centre of mass, the force gains and, where the motion turns the payload fast enough, the inertia), a
    pose table or joint angles read as one (:func:`fmscal.observers.payload.fit_static`), or an attitude-only
    log (its held segments as a table, :func:`fmscal.plant.io.held_table`, said in ``notes``). The problem is
    :class:`fmscal.plant.PayloadModel`'s (eq. P0): ``w = diag(gains) S (sigma w_hat - b)``. The payload counts
    as determined by what its uncertainty does to the compensated wrench over the cone of attitudes the data
    span, against ``tolerance`` (:mod:`fmscal.observers.payload._effect`).

    Parameters
    ----------
    data : plant.Log, plant.io.PoseTable or plant.io.AttitudeLog
        What was recorded (a planar log is refused in one line: it weighs nothing).
    S : array_like, shape (6, 6), optional
        The calibration (default: the identity).
    gravity : array_like, shape (3,)
        Gravity in the pose frame, m/s^2.
    window : float
        A log's: smoothing window of the pose differentiation, s.
    block : float, optional
        A log's: length of the blocks of the robust covariance, s; default the rule of
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
    tolerance : (float, float), optional
        The largest standard deviation the payload may add to the compensated wrench within the data's cone,
        N and N m (eq. E3); default one standard deviation of the reading's noise (a log's: its
        sample-to-sample scatter; a table's: its rows' scatter about the fit), eq. (E4).

    Returns
    -------
    PayloadEstimate
        A :class:`fmscal.observers.payload.StaticFit` from held poses (no inertia; the fit's covariance).

    Raises
    ------
    plant.io.UnitsError
        A unit slip or a convention the data show, named in one line before the fit
        (:func:`fmscal.plant.io.check_spatial_log_units`, :func:`fmscal.plant.io.check_table_units`).
    FmscalError
        Data of another shape or a planar log (one line), the log does not determine the mass, or its mass
        comes out negative (the reading follows the other sign convention: the message names the flag).

    Examples
    --------
    >>> from fmscal.plant import SPATIAL_SCENARIOS
    >>> arm = SPATIAL_SCENARIOS["spatial-arm"].with_(crosstalk=0.0)      # a sensor with S's force block diagonal
    >>> table, truth = arm.generate_table(seed=0, poses=12)
    >>> fit = identify_payload(table)
    >>> fit.payload_determined, abs(fit.mass - truth.payload.mass) < 3 * fit.mass_std, fit.gains.shape
    (True, True, (6,))
    """
    estimate_gravity = as_bool(estimate_gravity, "estimate_gravity")       # text ("False") is refused, not true
    estimate_mounting = as_bool(estimate_mounting, "estimate_mounting")
    options = dict(S=S, gravity=gravity, estimate_gravity=estimate_gravity, estimate_mounting=estimate_mounting,
                   reading=reading, max_mass=max_mass, tolerance=tolerance)
    if isinstance(data, (PoseTable, AttitudeLog)):
        if block is not None:
            raise FmscalError("block is taken on a log with poses (its robust covariance's blocks of time); held "
                              "poses are independent rows")
        notes = []
        if isinstance(data, AttitudeLog):                   # its held segments give the reading's noise (E4)
            n = len(data.t)
            data, used, note = held_table(data)
            options["noise"] = reading_noise(data.noise, S, samples=used * n / len(data))
            notes.append(note)
        fit = fit_static(data, **options)
        fit.notes = notes + fit.notes
        return fit
    if not isinstance(data, Log):
        raise FmscalError(f"data must be what fmscal.analysis.read_data returns: a spatial log, a pose table, an "
                          f"attitude-only log or joint angles with a URDF; got {type(data).__name__}")
    if find_model(columns=data.columns, estimates="mass") is None:
        raise FmscalError(f"{data.name}: a {data.kind} log weighs no payload under gravity; identify_payload takes "
                          "a spatial log, a pose table, an attitude-only log or joint angles with a URDF")
    return _identify_log(data, window=window, block=block, **options)


def _identify_log(log, S=None, gravity=GRAVITY, window=0.2, block=None, reading="reaction", estimate_gravity=False,
                  estimate_mounting=False, max_mass=None, tolerance=None):
    """:func:`identify_payload` on a spatial log."""
    sign = reading_sign(reading)
    S = np.eye(6) if S is None else check_calibration(S, "S", size=6)
    gravity = as_finite_array(gravity, (3,), "gravity")
    if not np.linalg.norm(gravity) > 0:                  # as fit_static: a direction is needed to weigh anything
        raise FmscalError("gravity must not be zero")
    block = None if block is None else as_positive_scalar(block, "block")
    given = check_tolerance(tolerance)
    check_spatial_log_units(log, gravity, S=S, max_mass=max_mass)   # a slipped unit named in one line
    problem = PayloadModel(S, gravity)
    q, omega, alpha, p_ddot = spatial_motion(log, window)
    trim = slice(edge(log, window), len(log.t) - edge(log, window))                   # the filter's edges
    y = problem.corrected(log.w_hat, sign)[trim]
    times = (log.t[trim], window, block)
    motion = tuple(v[trim] for v in (q, omega, alpha, p_ddot))
    try:
        fit, information = _fit_log(log.name, motion, y, problem, times, reading, estimate_gravity,
                                    estimate_mounting)
    except FmscalError as err:      # gravity up or a negative mass: the sign only where gravity fixed says so
        if not estimate_gravity or estimate_mounting or "the reading follows the other sign convention" not in str(
                err):
            raise
        W = problem.wrench_regressor(*motion)
        fixed_mass = float(np.linalg.lstsq(_design(W), y.ravel(), rcond=None)[0][0])
        if not fixed_mass > 0:
            raise
        raise FmscalError(rotations_unresolved(log.name, len(y), fixed_mass, "samples")) from None
    fit.notes = list(log.notes)
    noise = reading_noise(y)                                                   # the reading's, eq. (E4)
    fit.tolerance = given if given is not None else DEFAULT_TOLERANCE * noise
    words = "given" if given is not None else f"{DEFAULT_TOLERANCE:g} sd of the reading's noise"
    effect = _coverage(fit, motion[0], log.t[trim], information, words, (_groups(fit.residual_rms), noise),
                       np.allclose(S, np.eye(6)))
    named = False
    if not (estimate_gravity and estimate_mounting):
        named = _check_rotations(fit, log.name, motion, y, problem, times, reading, estimate_gravity,
                                 estimate_mounting)
    _check_misfit(fit, y, np.allclose(S, np.eye(6)), named)
    if named:                             # the model is wrong: the payload is not what the data say, poses won't mend
        fit.payload_determined, fit.why_undetermined, fit.next_poses = False, fit.warnings[0], []
    elif fit.why_undetermined is not None:
        fit.warnings.append(fit.why_undetermined)
    fit.converged = bool(fit.converged and fit.payload_determined)
    if effect is not None:
        fit.effect = effect.cone
    # what the file records: the sign, the noise the fit weighed by, the gravity it took as given
    fit.reading, fit.noise_sd = reading, 1.0 / information.weights
    fit.gravity_given = None if estimate_gravity else gravity
    return fit


def _groups(values):
    """The rms over the force channels and over the torque channels of six per-channel values: ``(N, N m)``."""
    values = np.asarray(values, dtype=float)
    return np.array([np.sqrt(np.mean(values[3:] ** 2)), np.sqrt(np.mean(values[:3] ** 2))])


def _check_misfit(fit, y, identity, named=False):
    """Warn, and clear ``converged``, where the force residuals exceed the reading's noise or the attitudes span a
    narrow cone.

    The noise is the reading's sample-to-sample scatter (``rms(diff) /
    sqrt 2``, as :func:`_check_rotations`); residuals beyond
    :data:`fmscal.observers.payload.TILT_RATIO` times it, where no rotation
    was named (``named``), are a model that does not fit: ``S`` (cross-talk)
    the likely cause, and the line says what compensation will leave (the
    residuals' rms, N and N m), which more poses do not lower. The cone is
    :func:`fmscal.observers.payload.cone_warning`'s.
    """
    noise = float(np.sqrt(np.mean(np.diff(y[:, 3:], axis=0) ** 2) / 2))
    fixed = float(np.sqrt(np.mean(np.square(fit.residual_rms[3:]))))
    if fixed > TILT_RATIO * noise and not named:
        told = "S = I may be wrong: calibrate S" if identity else "the calibration given may be wrong"
        torque = float(np.sqrt(np.mean(np.square(fit.residual_rms[:3]))))
        fit.warnings.append(f"the force residuals are {fixed / max(noise, 1e-300):.0f} times the reading's noise (its "
                            f"sample-to-sample scatter): the model does not fit; compensation will leave about "
                            f"{fixed:.2g} N and {torque:.2g} N m (rms); {told}")
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


def _check_rotations(fit, name, motion, y, problem, times, reading, estimate_gravity, estimate_mounting):
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
            free = _fit_log(name, motion, y, problem, times, reading, gravity_free, mounting_free)[0]
        except FmscalError:
            return None
        return Refit(float(np.sqrt(np.mean(np.square(free.residual_rms[3:])))), free.gravity, free.gravity_std_deg,
                     free.mounting_deg, free.mounting_std_deg)

    warning = rotation_check(fixed, problem.gravity, refit, estimate_gravity, estimate_mounting)
    if warning is not None:                 # first: the model is wrong, and the other warnings may follow from it
        fit.warnings.insert(0, warning)
        fit.converged = False
    return warning is not None


class _Information(NamedTuple):
    """What the coverage of a log's fit needs (:func:`_coverage`).

    Attributes
    ----------
    information : ndarray, shape (p, p)
        The weighted information over ``(pi (10), c (6), eta)``.
    theta : ndarray, shape (16,)
        ``pi`` and ``c``.
    eta : ndarray
        The angles of gravity's direction and of the mounting, where estimated, and the force gains' two
        numbers (the parameters of :class:`fmscal.observers.payload._static_fit._Model` after ``c``).
    residual : ndarray
        The weighted residuals.
    weights : ndarray, shape (6,)
        Each channel's weight.
    frame : tuple
        ``(g_size, d0, M0, estimate_gravity, estimate_mounting)``: the angles' origin.
    cov : ndarray, shape (p, p)
        The cluster-robust covariance over ``(pi, c, eta)``.
    W : ndarray, shape (N, 6, 10)
        The regressor of eq. (P0) at the fit's rotations.
    problem : fmscal.plant.PayloadModel
    torque_gain : bool
        The torques' common gain was estimated.
    """

    information: np.ndarray
    theta: np.ndarray
    eta: np.ndarray
    residual: np.ndarray
    weights: np.ndarray
    frame: tuple
    cov: np.ndarray
    W: np.ndarray
    problem: PayloadModel
    torque_gain: bool


#: How long a suggested pose of a log is held, s: its samples count in the score of the next poses
#: (eq. (N1) of :mod:`fmscal.observers.payload._coverage`).
HOLD = 3.0
#: How many attitudes, evenly spaced along a log, the suggested turns start from.
REFERENCES = 10
#: How many of a log's attitudes, evenly spaced along it, stand for its recorded attitudes in the effect (E2).
SAMPLED = 200


def _coverage(fit, q, t, info, words, misfit=None, identity=True):
    """A log's ``cone_deg``, ``undetermined``, the payload's effect and its verdict, and ``next_poses``, as a
    table's (:mod:`fmscal.observers.payload._coverage`, :mod:`fmscal.observers.payload._effect`).

    The cone is of gravity's directions in the sensor frame over the log's
    samples. The information and the covariance are taken to the physical
    parameters ``(m, com, I_c, c, angles, gains)`` (``F' = T^-T F T^-1``,
    ``C' = T C T^T``, ``T`` their Jacobian in ``pi``). The parameters not
    determined at all, and the inertia worse than :data:`DETERMINED` of its
    mean diagonal (and gravity's and the mounting's angles worse than 0.2
    degrees), are named in words. The payload's effect (eqs. E1-E3) is over
    the covariance with the inertia left out (held attitudes do not need it),
    at :data:`SAMPLED` of the log's attitudes and over its cone; the
    inertia's, at every sample (:func:`fmscal.observers.payload._effect.
    inertia_effect`), must be within the torques' tolerance too, else it is
    not determined. ``misfit`` (the residuals' and the noise's rms, forces
    and torques) and ``identity`` are :func:`fmscal.observers.payload.
    _effect.judge`'s. The next poses, where they would help, are scored as a table's, eq. (N1), on the
    information with the inertia eliminated, each pose held :data:`HOLD` s,
    from :data:`REFERENCES` attitudes along the log, over the cone's grid;
    the model-based ``s^2 F^-1`` there, the cluster-robust covariance in
    the verdict.

    Returns
    -------
    Effect
    """
    g_size, d0, M0, estimate_gravity, estimate_mounting = info.frame
    model = _Model(None, None, g_size, d0, M0, estimate_gravity, estimate_mounting, info.problem, info.torque_gain)
    theta = info.theta
    R = np.moveaxis(rotation_matrix(q.T), -1, 0)
    values = _physical(theta[:10])
    static = np.r_[values[:4], theta[10:16], info.eta]
    _, _, _, d, M = model.parts(static)
    u = np.einsum("ji,nkj,k->ni", M, R, -d)
    fit.cone_deg = cone_deg(u)
    T = np.eye(len(info.information))
    T[:10, :10] = _physical_jacobian(theta[:10])
    T_inv = np.linalg.inv(T)
    F = T_inv.T @ info.information @ T_inv
    s2 = float(np.sum(info.residual ** 2) / max(info.residual.size - len(F), 1))
    names = ("m", "com_x", "com_y", "com_z", *(f"I_{n}" for n in INERTIA_NAMES), *(f"c_{n}" for n in _OFFSET_NAMES),
             *model.names[10:])
    k_angles = len(model.names) - 10 - len(model.gain_index)
    scale = np.r_[np.full(4, np.inf), np.full(6, DETERMINED * max(np.mean(values[4:7]), 1e-9)), np.full(6, np.inf),
                  np.full(k_angles, np.radians(0.2)), np.full(len(model.gain_index), np.inf)]
    fit.undetermined = in_words(names, weak_directions(F, s2, scale), "this log")
    finite = np.isfinite(np.diag(info.cov))
    C = T @ np.where(np.outer(finite, finite), info.cov, 0.0) @ T.T
    touched = np.abs(T[:, ~finite]).max(axis=1) > 0 if (~finite).any() else np.zeros(len(T), dtype=bool)
    C[touched, :] = np.inf
    C[:, touched] = np.inf
    keep = np.r_[0:4, 10:len(F)]                          # the inertia left out: the static payload's
    sampled = np.unique(np.linspace(0, len(t) - 1, min(SAMPLED, len(t))).round().astype(int))
    attitudes = cone_attitudes(R[sampled], M, d, fit.cone_deg)
    effect = static_effect(model, static, C[np.ix_(keep, keep)], attitudes, len(sampled))
    fit.effect = effect.cone
    determined, why, helps = judge(effect, fit.tolerance, words, fit.cone_deg,
                                   not np.all(np.isfinite(np.diag(C)[keep])), circle_axis(u), misfit=misfit,
                                   identity=identity)
    fit.payload_determined, fit.why_undetermined = determined, why
    if fit.inertia is not None:                           # its own rule passed: its effect at the recorded motion
        torque = inertia_effect(info.W[:, :3, 4:10], info.cov[4:10, 4:10])
        if torque > fit.tolerance[1]:
            fit.warnings.append(f"the inertia is not determined: it leaves up to {torque:.2g} N m (1 sd) in the "
                                f"compensated torque at the recorded motion, beyond the tolerance of "
                                f"{fit.tolerance[1]:.2g} N m: the log holds too little angular acceleration "
                                "(rotate faster, or about more axes)")
            fit.inertia = fit.inertia_std = None
            fit.converged = False
    F_t = F[np.ix_(keep, keep)] - F[np.ix_(keep, range(4, 10))] @ np.linalg.pinv(F[4:10, 4:10]) @ F[np.ix_(
        range(4, 10), keep)]                              # the inertia eliminated: F_kk - F_ki F_ii^+ F_ik
    if not helps:                                         # the model does not fit: more poses would not mend it
        return effect
    refs = np.unique(np.linspace(0, len(t) - 1, REFERENCES).round().astype(int))
    dt = float(np.median(np.diff(t)))
    fit.next_poses = next_poses(model, static, F_t, info.weights, s2, R[refs],
                                [f"the attitude at t = {t[k]:.1f} s" for k in refs], attitudes[len(sampled):],
                                fit.tolerance, widened=lambda Rc: _widened(R[sampled], M, d, Rc)[len(sampled) + 1:],
                                rows=HOLD / dt, held=f" and hold it {HOLD:g} s")
    return effect


def _design(W):
    """The design matrix of ``[tau_O; f] + c = W pi + c``: ``[W | I]`` stacked, shape (6N, 16)."""
    n = len(W)
    return np.concatenate([W, np.broadcast_to(np.eye(6), (n, 6, 6))], axis=2).reshape(6 * n, 16)


def _fit_log(name, motion, y, problem, times, reading, estimate_gravity, estimate_mounting, torque_gain=True):
    """The log's fit of eq. (P0): the payload, the offset and the force gains, with gravity's direction and/or
    the mounting estimated where asked.

    Variable projection: for given nonlinear numbers ``eta`` (gravity's two
    angles across its start direction, the mounting's rotation vector about
    its start, the gains' two or three free numbers) the payload and the offset
    are the weighted least squares of the linear model ``y = diag(1/g) W pi +
    c``; ``eta`` minimises what is left. For given angles the gains are found
    on the channels' Gram matrices of the design at them (:class:`_Gram`,
    Newton's method), and the angles, where estimated, by Levenberg-Marquardt
    on what that leaves. Two passes: plain, then each channel weighted by its residual
    spread. The covariance is the cluster-robust sandwich over the full
    Jacobian (the linear parameters and ``eta`` together: the gains' columns
    ``-(W pi) / g^2 dg/de``, the angles' by central differences), so the
    angles' and the gains' uncertainty enter the payload's.

    ``torque_gain``: estimate the torques' common gain (eq. P0's ``e_tau``)
    where the log tells it from zero (beyond chance at
    :data:`fmscal.observers.payload.ODDS`, two-sided, against its standard
    deviation; else the fit is repeated with it zero, held poses'
    convention); False: zero. The motion ties the torques' scale to the
    forces' through ``alpha x h``, which a slow or short log holds little of:
    there the gain, free, wanders as far as its uncertainty and takes the
    centre of mass and the inertia with it.

    Returns
    -------
    fit : PayloadEstimate
    information : _Information
    """
    q, omega, alpha, p_ddot = motion
    g = np.asarray(problem.gravity, dtype=float)
    R = np.moveaxis(rotation_matrix(q.T), -1, 0)
    _, d0, M0, g_size = _start(R, y, g, estimate_gravity, estimate_mounting, acc=p_ddot)
    e1, e2 = _tangent_basis(d0)
    k_g = 2 if estimate_gravity else 0
    k_m = 3 if estimate_mounting else 0
    n = len(y)
    fixed = None if (estimate_gravity or estimate_mounting) else _design(problem.wrench_regressor(q, omega, alpha,
                                                                                                 p_ddot))

    def parts(eta):
        d = _exp(eta[0] * e1 + eta[1] * e2) @ d0 if estimate_gravity else d0
        M = M0 @ _exp(eta[k_g:k_g + k_m]) if estimate_mounting else M0
        return g_size * d, M

    last = {}

    def unscaled(eta):                      # the design of [W | I] at eta's rotations, the gains one (the last kept)
        if fixed is not None:
            return fixed
        key = np.asarray(eta[:k_g + k_m], dtype=float).tobytes()
        if key not in last:
            g_eta, M = parts(eta)
            last.clear()
            last[key] = _design(problem.wrench_regressor(q, omega, alpha, p_ddot, g_eta,
                                                         M if estimate_mounting else None))
        return last[key]

    def design(eta):
        X = unscaled(eta).copy()
        X[:, :10] /= np.tile(problem.gains(eta[k_g + k_m:]), n)[:, None]          # eq. (P0): y = W pi / g + c
        return X

    def solve(eta, weights):
        X = design(eta)
        Xw = X * weights[:, None]
        return X, pseudo_inverse(Xw)[0] @ (Xw.T @ (y.ravel() * weights))

    def projected(angles, weights, k_e):    # the gains and the linear parameters projected out (:class:`_Gram`)
        gram = _Gram(unscaled(angles), y, weights[:6])
        e = gram.gains(problem, k_e)
        return gram, e, gram.theta(problem.gains(e))[0]

    def residual(angles, weights, k_e):
        gram, e, theta = projected(angles, weights, k_e)
        return (gram.residual(problem.gains(e), theta) * weights[:6]).ravel()

    def fitted(k_e):                        # eta, theta, the weights, the residuals, the blocks and the covariance
        angles = np.zeros(k_g + k_m)
        weights = np.ones(6 * n)
        for _ in range(2):                  # plain, then each channel weighted by its residual spread
            if len(angles):
                angles = least_squares(residual, angles, args=(weights, k_e), method="lm", xtol=1e-12,
                                       ftol=1e-12).x
            gram, e, theta = projected(angles, weights, k_e)
            sd = np.sqrt(np.mean(gram.residual(problem.gains(e), theta) ** 2, axis=0))
            weights = np.tile(1.0 / np.maximum(sd, 1e-12), n)
        eta = np.r_[angles, projected(angles, weights, k_e)[1]]
        X, theta = solve(eta, weights)
        e = (y.ravel() - X @ theta) * weights
        blocks, length = time_blocks(e.reshape(n, 6), *times)
        # the full Jacobian: the linear parameters' columns, the gains' -(W pi) / g^2 dg/de, the angles' numerically
        columns = []
        for i in range(k_g + k_m):
            step = np.zeros(len(eta))
            step[i] = 1e-6
            columns.append((design(eta + step) @ theta - design(eta - step) @ theta) / 2e-6)
        gains = np.tile(problem.gains(eta[k_g + k_m:]), n)
        payload_rows = unscaled(eta)[:, :10] @ theta[:10]                              # W pi, row by row
        for j in range(k_e):
            step = np.zeros(k_e)
            step[j] = 1.0
            slope = np.tile(problem.gains(step) - problem.gains(np.zeros(k_e)), n)       # dg/de_j, exact: linear
            columns.append(-payload_rows / gains ** 2 * slope)
        J = np.column_stack([X, *columns]) * weights[:, None]
        inverse, determined = pseudo_inverse(J)
        return eta, theta, weights, e, blocks, length, J, sandwich(J, e, blocks, inverse, determined)

    eta, theta, weights, e, blocks, length, J, cov = fitted(3 if torque_gain else 2)
    k_e = len(eta) - k_g - k_m
    if k_e == 3:                            # the torques' gain kept only where the log tells it from one
        var = cov[-1, -1]
        if not (np.isfinite(var) and abs(eta[-1]) > norm.isf(ODDS / 2) * np.sqrt(max(var, 0.0))):
            eta, theta, weights, e, blocks, length, J, cov = fitted(2)
            k_e = 2
    g_hat, M = parts(eta)
    std = np.sqrt(np.maximum(np.diag(cov)[16:], 0))
    # gravity up, where its direction is determined: the reading's sign is the other one, or the base upside down
    if estimate_gravity and g_hat[2] > 0 > g[2] and np.all(np.isfinite(std[:2])) and np.all(std[:2] < 0.5):
        raise FmscalError(gravity_up(name, g_hat[2] / np.linalg.norm(g_hat), reading))
    if np.isfinite(cov[0, 0]) and theta[0] < 0:
        raise FmscalError(other_convention(name, theta[0], reading))
    fit = _report(theta, cov[:16, :16], problem.S, np.sqrt(np.mean((e / weights).reshape(n, 6) ** 2, axis=0)))
    _blocks_used(fit, blocks, length)
    if estimate_gravity:
        fit.gravity = g_hat
        fit.gravity_std_deg = float(np.degrees(np.sqrt((std[0] ** 2 + std[1] ** 2) / 2)))
    if estimate_mounting:
        fit.mounting = M
        fit.mounting_deg = _angle_deg(M)
        fit.mounting_std_deg = float(np.degrees(np.sqrt(np.sum(std[k_g:k_g + 3] ** 2) / 3)))
        fit.mounting_axis = _axis(M)
    index = list(range(16 + k_g + k_m, 16 + k_g + k_m + k_e))
    C_e = cov[np.ix_(index, index)]
    fit.gains, fit.gains_std = gains_of(problem, eta[k_g + k_m:], C_e)
    loose = fit.gains_std[3:] > DETERMINED          # told by the motion alone: the smoothed poses bias it (as I's)
    if loose.any():
        worst = "xyz"[int(np.argmax(fit.gains_std[3:]))]
        fit.warnings.append("the force gains are not determined by this log (" + ", ".join(
            f"{axis} +- {sd:.1%}" for axis, sd in zip("xyz", fit.gains_std[3:])) + f"; beyond {DETERMINED:.0%}): it "
            f"turns gravity too little along {worst}, and what the motion tells of its gain the smoothed poses "
            f"bias; tilt the tool to turn gravity along {worst} (see the next poses)")
        fit.gains_std[3:] = np.where(loose, np.inf, fit.gains_std[3:])
        cov[index[:2], :] = np.inf
        cov[:, index[:2]] = np.inf
        fit.converged = False
    elif np.all(np.isfinite(C_e[:2, :2])) and (line := gains_differ(fit.gains, C_e[:2, :2],
                                                                     np.allclose(problem.S, np.eye(6)))) is not None:
        fit.warnings.append(line)                   # estimated and taken into the compensation: said, not a fault
    frame = (g_size, d0, M0, estimate_gravity, estimate_mounting)
    return fit, _Information(J.T @ J, theta, eta, e, weights[:6], frame, cov,
                             unscaled(eta).reshape(n, 6, 16)[:, :, :10], problem, k_e == 3)


class _Gram:
    """The per-channel Gram matrices of a log's design and reading: its fit for given gains, without the
    design rebuilt (variable projection over the gains of eq. P0, :func:`_fit_log`).

    With ``D_k = diag(s_k)``, ``s_k = (1/g_k (10 times), 1 (6 times))`` scaling channel ``k``'s rows of the
    design ``X`` (its payload columns by its gain), the weighted normal equations are ``A theta = b``, ``A =
    sum_k D_k A_k D_k``, ``b = sum_k D_k b_k`` (``A_k = w_k^2 X_k^T X_k``, ``b_k = w_k^2 X_k^T y_k``), the
    weighted residuals' sum of squares ``F = c - b^T theta``, and its slope in the gains::

        dF / dg_k = 2 (t_k o theta)^T (A_k (s_k o theta) - b_k),     t_k = ds_k / dg_k = (-1/g_k^2, 0)      (P3)
    """

    def __init__(self, X, y, weights):
        Xc, yc, w2 = X.reshape(len(y), 6, -1), y.reshape(len(y), 6), np.asarray(weights, dtype=float) ** 2
        by_channel = Xc.transpose(1, 2, 0)                                   # (6, p, N): each channel's rows
        self.X, self.y = Xc, yc
        self.A = by_channel @ by_channel.transpose(0, 2, 1) * w2[:, None, None]
        self.b = (by_channel @ yc.T[:, :, None])[:, :, 0] * w2[:, None]
        self.c = float(np.sum((yc ** 2).sum(axis=0) * w2))

    @staticmethod
    def _scales(gains):
        """``s_k`` of each channel, shape (6, 16)."""
        s = np.ones((6, 16))
        s[:, :10] = 1.0 / np.asarray(gains, dtype=float)[:, None]
        return s

    def theta(self, gains):
        """The payload and the offset ``theta`` at the channel gains ``gains`` (6,), and ``b``."""
        s = self._scales(gains)
        A = np.einsum("kp,kpq,kq->pq", s, self.A, s)
        b = np.einsum("kp,kp->p", s, self.b)
        scale = np.sqrt(np.maximum(np.diag(A), 1e-300))
        return np.linalg.pinv(A / np.outer(scale, scale), rcond=1e-12) @ (b / scale) / scale, b

    def residual(self, gains, theta):
        """``y - X_g theta``, unweighted, shape (N, 6): each channel's rows of the design at its gain."""
        return self.y - np.einsum("nkp,kp->nk", self.X, self._scales(gains) * theta)

    def cost(self, gains):
        """``F`` and ``dF / dg`` (eq. P3) at the channel gains ``gains`` (6,)."""
        gains = np.asarray(gains, dtype=float)
        s = self._scales(gains)
        theta, b = self.theta(gains)
        t = np.zeros_like(s)
        t[:, :10] = -1.0 / gains[:, None] ** 2
        slope = 2 * np.einsum("kp,kp->k", t * theta, np.einsum("kpq,kq->kp", self.A, s * theta) - self.b)
        return self.c - float(theta @ b), slope

    def gains(self, problem, count=3, steps=20):
        """The gains' ``count`` free numbers (eq. P0: the force gains' two, and the torques' one) that minimise
        ``F``: Newton's method from gains of one, on the slope (P3) and its differences, to a step below
        ``1e-12``."""
        G = np.array([problem.gains(v) - problem.gains(np.zeros(count)) for v in np.eye(count)]).T     # dg/de

        def slope(e):
            return G.T @ self.cost(problem.gains(e))[1]

        e = np.zeros(count)
        for _ in range(steps):
            h = 1e-6
            H = np.column_stack([(slope(e + h * v) - slope(e - h * v)) / (2 * h) for v in np.eye(count)])
            step = -np.linalg.lstsq((H + H.T) / 2, slope(e), rcond=None)[0]
            e = e + step
            if np.max(np.abs(step)) < 1e-12:
                break
        return e


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
    """The :class:`PayloadEstimate` of the linear parameters ``(pi, c)`` and their covariance: the physical values
    with their delta-method sigmas, the offset ``b = S^-1 c``, and the inertia by its own rule (:data:`DETERMINED`
    of its mean diagonal, a body that can exist); the payload's verdict is :func:`_coverage`'s."""
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
    inertia_scale = max(np.mean(values[4:7]), 1e-9)
    inertia_ok = bool(np.all(std[4:] < DETERMINED * inertia_scale)) and _possible(values)
    offset_ok = bool(np.all(np.isfinite(b_std)))
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
                           converged=bool(inertia_ok and offset_ok), inertia_reason=inertia_reason,
                           cov=propagate_covariance(np.eye(16), full, () if inertia_ok else INERTIA_ROWS))
