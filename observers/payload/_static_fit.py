"""The static fit of a pose table: mass, centre of mass and offset, with gravity and mounting if asked.

A held pose does not accelerate, so the corrected reading is the weight's
wrench at the sensor (SPATIAL facts, Newton-Euler at rest) plus the offset::

    y_k = sigma S w_hat_k = [com x f_k; f_k / g_f] + c,       f_k = m M^T R_k^T (-g)

with ``R_k`` the tracked frame's attitude at pose ``k``, ``M`` the sensor's
axes on it (the mounting; the identity unless estimated), ``g`` gravity in the
pose frame, ``c = S b`` the offset and ``sigma = +1`` for a sensor that
reports the wrench the mount applies to the payload (the toolkit's
convention, ``reaction``) or ``-1`` for one that reports the wrench the tool
applies to the sensor (``load``: ATI, Robotiq, Bota, OnRobot).

The unknowns are ``m``, ``com`` (3), ``c`` (6), the force axes' gains ``g_f``
relative to their mean (two numbers, eq. (P0) of :class:`fmscal.plant.PayloadModel`:
a sensor's gains disagree by a few percent where ``S`` is the maker's; estimated where
the poses are enough for them, :func:`min_poses`), and where asked the direction
of gravity (two angles; its size is the standard 9.81 m/s^2 unless told) and
the mounting ``M`` (a rotation, three angles). The fit is nonlinear least
squares (Levenberg-Marquardt, :func:`scipy.optimize.least_squares`), started
from linear fits of the forces and then the torques, the torques and the
forces each weighted by their noise over their own degrees of freedom (eq.
N2); the rows are independent (each an average over a held pose), so the
covariance is ``(J^T W J)^-1``, each variance widened to the Student-t's
(eq. N3). Where the model does not fit, the covariance widens: for rows in
sequence, to the block sandwich's (N6); force axes whose gains disagree
where too few poses leave the gains unestimated (N7) are named with what
compensation would leave; an offset drifting along the rows (N9) and a
narrow cone of attitudes are warned. The fewest poses each estimated rotation
and the gains need: :func:`min_poses` (N4). The payload counts as determined
by what its uncertainty does to the compensated wrench over the cone of
attitudes the poses span (:mod:`fmscal.observers.payload._effect`, eqs.
E1-E4), against a tolerance tied to the rows' scatter.

What the table covers: the gravity directions it holds in the sensor frame
(the half-angle of the cone around their mean), the parameters it leaves
undetermined (the information's weak directions, in words), and the next
poses that would most reduce the payload's effect on the compensated wrench:
candidate turns of 45, 90 and 180 degrees about the sensor's axes from the
table's poses, each scored by the covariance the fit would have with it added
(:mod:`fmscal.observers.payload._coverage`, the machinery a log's fit shares).

Gravity along ``-z`` and the sensor square on the tracked frame are checked:
the fit is repeated with gravity's direction estimated and with the mounting,
and where one of them explains the residuals the fit says which flag to add
(:func:`rotation_warning`).
"""

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import chi2, f as f_dist

from fmscal.plant.io import MIN_POSES, PoseTable, check_table_units, reading_sign
from fmscal.plant.numerics import FmscalError, as_bool, as_finite_array
from fmscal.plant.physics import GRAVITY, PayloadModel, check_calibration, regressor, rotation_matrix, skew

from fmscal.observers.batch import (MIN_BLOCKS, InverseDynamicsFit, correlation_time, fit_readings, pseudo_inverse,
                                   sandwich)
from ._coverage import _OFFSET_NAMES, cone_deg as _cone, covariance, in_words, next_poses, rotation as _exp
from ._effect import (DEFAULT_TOLERANCE, TABLE_TOLERANCE,
                      check_tolerance, circle_axis, cone_attitudes, judge, static_effect)
from ._estimate import INERTIA_ROWS, PayloadEstimate, _angle_deg, _axis, propagate_covariance

__all__ = ["StaticFit", "fit_static", "calibrate_table", "other_convention", "tilt_warning", "mounting_warning",
           "rotation_warning", "both_rotations_warning", "rotation_check", "Refit", "gravity_up", "TILT_RATIO",
           "TILT_SIGMAS", "MIN_CONE_DEG", "ODDS", "min_poses", "sign_separated", "rotations_unresolved",
           "gains_warning", "NARROW_CONE_DEG", "cone_warning", "gains_of", "gains_differ"]

#: With gravity's direction (or the mounting) fixed, the fit is told to estimate it when estimating it lowers
#: the force residuals' rms by more than this factor ...
TILT_RATIO = 3.0
#: ... and the tilt it finds is more than this many of its standard deviations.
TILT_SIGMAS = 5.0
#: Poses whose gravity directions in the sensor frame all lie within a cone of this half-angle (degrees)
#: do not separate the weight from the offset: refused.
MIN_CONE_DEG = 1.0
#: Poses whose gravity directions lie within a cone of this half-angle (degrees) are warned: the weight is told from
#: the offset by small differences, which a gain error or a drifting offset moves.
NARROW_CONE_DEG = 30.0
#: The chance below which a fit's misfit counts as beyond the noise (one in a thousand): the F and chi-square
#: quantiles of the checks that state a probability.
ODDS = 1e-3


@dataclass(kw_only=True)
class StaticFit(PayloadEstimate):
    """The static fit of a pose table (module docstring): a :class:`PayloadEstimate` with no inertia, and the fit's
    covariance.

    Attributes
    ----------
    mass, mass_std, com, com_std, b, b_std, gains, gains_std, effect, tolerance, payload_determined, ...
        As a log's fit gives them (:class:`fmscal.observers.payload.PayloadEstimate`); ``b`` is the offset in
        ``w = diag(gains) S (sigma w_hat - b)``, reading order, N m and N.
    inertia, inertia_std : None
        Held poses never determine it.
    reading : str
        The reading's sign convention the fit used (:data:`fmscal.plant.io._calibration.READINGS`).
    cone_deg : float
        Half-angle of the cone of gravity directions the table holds in the sensor frame, degrees.
    undetermined : list of str
        The parameters the table leaves undetermined, in words.
    converged : bool
        Mass, centre of mass, offset (and gravity, mounting where asked) all determined, and the model fits.
    cov : ndarray
        Covariance of the fitted parameters (:attr:`names` order).
    names : tuple of str
        The fitted parameters (the force gains' two free numbers last, where estimated).
    payload_cov : ndarray, shape (16, 16)
        Covariance over :data:`fmscal.observers.payload.PAYLOAD_PARAMETERS` (eq. E1 of
        :mod:`fmscal.observers.payload._estimate`), the inertia's rows and columns infinite: held poses do not
        give it.
    noise_sd : ndarray, shape (6,)
        The noise of a row the fit weighed the corrected reading by (each group's, eq. N2); ``noise_of`` "pose".
    """

    inertia: np.ndarray = None
    inertia_std: np.ndarray = None
    residual_rms: np.ndarray = None
    inertia_reason: str = "held poses do not accelerate: the inertia needs angular acceleration (a log of motion)"
    noise_of: str = "pose"
    reading: str = "reaction"
    cone_deg: float = 0.0
    cov: np.ndarray = None
    names: tuple = ()
    payload_cov: np.ndarray = None

    def payload_covariance(self):
        """:attr:`payload_cov`: the covariance over :data:`fmscal.observers.payload.PAYLOAD_PARAMETERS`."""
        return self.payload_cov

    def to_dict(self):
        """The fields as JSON-ready numbers and lists (None where not estimated); the keys of ``identify-payload``."""
        return {**super().to_dict(), "reading": self.reading}


def min_poses(estimate_gravity=False, estimate_mounting=False, estimate_gains=False):
    """The fewest held poses that determine the static fit, with the noise measured from its residuals.

    The forces carry every rotation: ``f_k = m M^T R_k^T (-g) / g_f + c_f`` holds
    ``p_f = 4`` unknowns (the mass, the force offset), two more for gravity's
    direction, three for the mounting and two for the force gains; the torques ``com x f_k + c_tau``
    add six unknowns and three numbers a pose. Each pose gives three forces,
    and the forces' noise, measured from their ``3N - p_f`` residual degrees
    of freedom, has a finite Student-t variance only beyond two (eq. N3)::

        3 N - p_f > 2,   N >= floor((p_f + 2) / 3) + 1                        (N4)

    that is 3 with gravity and the mounting as given or gravity's direction
    estimated, 4 with the mounting estimated (alone or with gravity's); with the gains,
    3, 4, 4 and 5; a pose table holds at
    least :data:`fmscal.plant.io.MIN_POSES` (four) for the torques' six
    unknowns and the offset. :func:`fit_static` estimates the gains where the table
    holds enough poses for them. Poses that do not tilt gravity, or tilt it
    within one plane, leave the fit undetermined at any count (the
    fit's weak directions; :func:`sign_separated`).

    Returns
    -------
    int
    """
    p_f = 4 + 2 * bool(estimate_gravity) + 3 * bool(estimate_mounting) + 2 * bool(estimate_gains)
    return (p_f + 2) // 3 + 1


def _tangent_basis(d):
    """Two unit vectors orthogonal to the unit vector ``d`` and to each other."""
    a = np.eye(3)[int(np.argmin(np.abs(d)))]
    e1 = np.cross(d, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(d, e1)


class _Model:
    """The residuals of the static fit for one table, its parameter layout and its start.

    ``problem``: the :class:`fmscal.plant.PayloadModel` whose gains the fit estimates (their free numbers last
    in the layout: the force gains' two, and with ``torque_gain`` the torques' common one, as a log's fit
    has it), or None (the gains one).
    """

    def __init__(self, R, y, g_size, d0, M0, estimate_gravity, estimate_mounting, problem=None, torque_gain=False):
        self.R, self.y, self.g_size = R, y, g_size
        self.fixed_mass = None
        self.d0, self.M0 = d0, M0
        self.e1, self.e2 = _tangent_basis(d0)
        self.estimate_gravity, self.estimate_mounting = estimate_gravity, estimate_mounting
        self.problem = problem
        self.names = ("m", "com_x", "com_y", "com_z", *(f"c_{n}" for n in _OFFSET_NAMES),
                      *(("gravity_1", "gravity_2") if estimate_gravity else ()),
                      *(("mount_x", "mount_y", "mount_z") if estimate_mounting else ()),
                      *(problem.gain_names[:3 if torque_gain else 2] if problem is not None else ()))

    @property
    def gain_index(self):
        """The gains' numbers in the layout (empty where not estimated)."""
        count = sum(name.startswith("gain_") for name in self.names)
        return list(range(len(self.names) - count, len(self.names)))

    def channel_gains(self, theta):
        """The six channel gains of eq. (P0) at ``theta`` (ones where the gains are not estimated)."""
        return np.ones(6) if self.problem is None else self.problem.gains(theta[self.gain_index])

    def parts(self, theta):
        """``m, com, c, gravity direction, M`` from the parameter vector."""
        m, com, c = theta[0], theta[1:4], theta[4:10]
        k = 10
        d = self.d0
        if self.estimate_gravity:
            d = _exp(theta[k] * self.e1 + theta[k + 1] * self.e2) @ self.d0
            k += 2
        M = self.M0 @ _exp(theta[k:k + 3]) if self.estimate_mounting else self.M0
        return m, com, c, d, M

    def predict(self, theta, R=None):
        """The corrected reading each pose would show, shape (N, 6)."""
        m, com, c, d, M = self.parts(theta)
        R = self.R if R is None else R
        a = np.einsum("ji,nkj,k->ni", M, R, -self.g_size * d)              # M^T R^T (-g), sensor axes
        f = m * a
        return np.hstack([np.cross(com, f), f]) / self.channel_gains(theta) + c          # eq. (P0) at rest

    def jacobian(self, theta, R=None, step=1e-7):
        """d predict / d theta by central differences, shape (6N, p)."""
        cols = []
        for i in range(len(theta)):
            h = step * max(abs(theta[i]), 1.0)
            up, down = theta.copy(), theta.copy()
            up[i] += h
            down[i] -= h
            cols.append(((self.predict(up, R) - self.predict(down, R)) / (2 * h)).ravel())
        return np.column_stack(cols)


def _start(R, y, g, estimate_gravity, estimate_mounting, acc=None, signs=(1.0, -1.0)):
    """Linear fits for the start: the forces (``f = B a + c_f``, or ``f = -R^T u + c_f``), then the torques.

    ``signs``: the signs of the mass the mounting's fit may take (:func:`_procrustes`).
    ``acc`` (N, 3), the tracked point's acceleration in the pose frame, m/s^2,
    for samples of a log (default: held, none); its share of the force,
    ``m M^T R^T acc``, joins the linear fits, and the rotation's share is left
    to the nonlinear fit that follows.
    """
    n = len(R)
    a0 = np.einsum("nkj,k->nj", R, -g)                                      # R^T (-g), tracked-frame axes
    if acc is not None:
        a0 = a0 + np.einsum("nkj,nk->nj", R, acc)
    f = y[:, 3:]
    M0, d0, g_size = np.eye(3), g / np.linalg.norm(g), float(np.linalg.norm(g))
    if estimate_mounting:           # f = m M^T a0 + c_f: M by Kabsch, for each sign of m, the better kept
        m, Mt = _procrustes(a0, f, signs)
        M0 = Mt.T
    if estimate_gravity:            # f = M0^T R^T (m acc - u) + c_f with u = m g: linear in u and c_f (and m)
        X = np.concatenate([-np.einsum("ji,nkj->nik", M0, R), np.broadcast_to(np.eye(3), (n, 3, 3))], axis=2)
        if acc is not None:
            X = np.concatenate([X, np.einsum("ji,nkj,nk->ni", M0, R, acc)[:, :, None]], axis=2)
        sol = np.linalg.lstsq(X.reshape(3 * n, X.shape[2]), f.ravel(), rcond=None)[0]
        u = sol[:3]
        m = float(np.linalg.norm(u) / g_size)
        d0 = u / max(np.linalg.norm(u), 1e-300)
    if not (estimate_gravity or estimate_mounting):     # f = m a + c_f
        a = np.einsum("ji,nj->ni", M0, a0)
        X = np.concatenate([a[:, :, None], np.broadcast_to(np.eye(3), (n, 3, 3))], axis=2)
        m = float(np.linalg.lstsq(X.reshape(3 * n, 4), f.ravel(), rcond=None)[0][0])
    a = np.einsum("ji,nkj,k->ni", M0, R, -g_size * d0)
    force = m * a
    c_f = np.mean(f - force, axis=0)
    # the torques: tau = com x f + c_tau = -[f]x com + c_tau, linear in com and c_tau
    X = np.concatenate([-skew(force), np.broadcast_to(np.eye(3), (n, 3, 3))], axis=2).reshape(3 * n, 6)
    sol = np.linalg.lstsq(X, y[:, :3].ravel(), rcond=None)[0]
    return np.r_[m, sol[:3], sol[3:], c_f], d0, M0, g_size


def _procrustes(a, f, signs=(1.0, -1.0)):
    """The scaled rotation that best maps the directions ``a`` onto the forces ``f``, each less its mean.

    Minimises ``sum_k |f_k - c - m Q a_k|^2`` over ``c``, ``m`` and the
    rotation ``Q`` (Kabsch: ``Q`` the rotation nearest the correlation
    ``H = sum f_k a_k^T`` of the centred rows, its determinant kept at +1),
    for ``m`` of either sign (``m < 0``: the rotation of ``-H``), and keeps the
    sign that fits better. Defined for any number of poses, where the
    unconstrained ``f = B a + c`` needs four to be determined and its
    determinant's sign is noise at four.

    Returns
    -------
    m : float
    Q : ndarray, shape (3, 3)
    """
    ac, fc = a - a.mean(axis=0), f - f.mean(axis=0)
    best = None
    for sign in signs:
        U, _, Vt = np.linalg.svd(sign * fc.T @ ac)
        Q = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
        m = sign * max(float(np.sum(fc * (ac @ Q.T)) * sign), 0.0) / max(float(np.sum(ac ** 2)), 1e-300)
        cost = float(np.sum((fc - m * ac @ Q.T) ** 2))
        if best is None or cost < best[0]:
            best = (cost, m, Q)
    return best[1], best[2]


def sign_separated(R, f, g, noise):
    """Whether held poses tell the reading's sign from a mounting turned half a turn: a chi-square test.

    With the mounting free, ``f_k = m M^T a_k + c`` (``a_k = R_k^T (-g)``) for
    ``m > 0`` and for ``m < 0`` (:func:`_procrustes` with each sign) differ
    only where the centred directions ``a_k`` leave a plane: on a plane a
    reflection is a half turn about its normal. The sign counts as told when
    the two fits' sums of squares differ by more than the chi-square
    distribution's ``1 - ODDS`` quantile on three degrees of freedom (the
    rotation's), in units of the forces' noise variance::

        |SS_+ - SS_-| / s_f^2 > chi2_{1 - ODDS}(3)                           (N5)

    Parameters
    ----------
    R : ndarray, shape (N, 3, 3)
    f : ndarray, shape (N, 3)
        The force readings, N.
    g : array_like, shape (3,)
    noise : float
        The forces' noise ``s_f``, N (eq. N2, of the fit as asked).

    Returns
    -------
    bool
    """
    a = np.einsum("nkj,k->nj", R, -np.asarray(g, dtype=float))
    ac, fc = a - a.mean(axis=0), f - f.mean(axis=0)
    costs = []
    for sign in (1.0, -1.0):
        m, Q = _procrustes(a, f, (sign,))
        costs.append(float(np.sum((fc - m * ac @ Q.T) ** 2)))
    return bool(abs(costs[0] - costs[1]) > chi2.ppf(1 - ODDS, 3) * noise ** 2)


def _weighted(model, theta0, weights):
    """Levenberg-Marquardt from ``theta0`` on the weighted residuals; returns the solution."""
    fun = lambda th: ((model.predict(th) - model.y) * weights).ravel()     # noqa: E731
    return least_squares(fun, theta0, method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=2000).x


def _extra(theta, model):
    """Zeros for the gravity and mounting angles and the force gains: they start at the linear fit's values."""
    return np.r_[theta, np.zeros(len(model.names) - len(theta))]


def _rows_named(rows):
    return (f"row {rows[0]}" if len(rows) == 1 else
            f"rows {', '.join(map(str, rows[:8]))}{', ...' if len(rows) > 8 else ''}")


def _distinct_rows(table):
    """``(table, repeated, kept)``: the table without the rows that repeat an earlier row to the last digit, its
    attitude and its reading (a copy: no held pose's noise gives the same reading twice, and a copy counted
    again would shrink the fit's sd as if it were a new pose), those rows' numbers (1-based), and the kept rows'
    indices in ``table`` (for the poses' names in later advice)."""
    rows = np.column_stack([table.q, table.w_hat])
    keep = np.sort(np.unique(rows, axis=0, return_index=True)[1])
    if len(keep) == len(rows):
        return table, [], keep
    repeated = [int(i) + 1 for i in np.setdiff1d(np.arange(len(rows)), keep)]
    if len(keep) < MIN_POSES:
        raise FmscalError(f"{table.name}: {len(keep)} distinct poses ({_rows_named(repeated)} the same as earlier rows "
                          f"to the last digit); a pose table needs at least {MIN_POSES}")
    return PoseTable(table.q[keep], table.w_hat[keep], name=table.name,
                     noise=None if table.noise is None else np.asarray(table.noise)[keep]), repeated, keep


def fit_static(table, S=None, gravity=GRAVITY, estimate_gravity=False, estimate_mounting=False, reading="reaction",
               max_mass=None, tolerance=None, noise=None):
    """Mass, centre of mass, offset and force gains from a pose table (and gravity's direction, the mounting, if asked).

    Parameters
    ----------
    table : plant.PoseTable
    S : array_like, shape (6, 6), optional
        The calibration (default: the identity).
    gravity : array_like, shape (3,)
        Gravity in the pose frame, m/s^2; with ``estimate_gravity`` only its
        size is taken (and its direction is where the fit starts from).
    estimate_gravity : bool
        Estimate gravity's direction in the pose frame (a tilted or
        wall-mounted base).
    estimate_mounting : bool
        Estimate the rotation of the sensor's axes on the tracked frame.
    reading : {"reaction", "load"}
        The reading's sign (module docstring).
    max_mass : float, optional
        The heaviest payload taken, kg (default :data:`fmscal.plant.io.MAX_WRIST_MASS`): readings that weigh
        more are refused as a slipped unit (mN).
    tolerance : (float, float), optional
        The largest standard deviation the payload may add to the compensated wrench within the poses' cone,
        N and N m (eq. E3 of :mod:`fmscal.observers.payload._effect`); default one standard deviation of the
        rows' scatter about the fit (eq. N2; a table's rows are averages, so this is stricter than a reading's
        own noise), or of ``noise`` where given.
    noise : (float, float), optional
        The reading's own noise, N and N m, where the raw readings behind the rows are at hand (the held segments
        of an attitude-only log: :func:`fmscal.observers.payload._effect.reading_noise`): the default tolerance.

    Returns
    -------
    StaticFit
        ``payload_determined`` by the effect (eq. E3), ``why_undetermined`` where not; the force gains where
        the table holds :func:`min_poses` for them with the rotations asked (else None).

    Raises
    ------
    plant.io.UnitsError
        A unit slip or a convention the data show, named in one line before the fit
        (:func:`fmscal.plant.io.check_spatial_log_units`, :func:`fmscal.plant.io.check_table_units`).
    FmscalError
        A reading convention that is neither, a tolerance that is not two positive numbers, or a table whose
        data say the other convention (a negative mass, or gravity pointing up with ``estimate_gravity``).
    """
    if not isinstance(table, PoseTable):
        raise TypeError(f"table must be a plant.PoseTable; got {type(table).__name__}")
    estimate_gravity = as_bool(estimate_gravity, "estimate_gravity")       # text ("False") is refused, not true
    estimate_mounting = as_bool(estimate_mounting, "estimate_mounting")
    sign = reading_sign(reading)
    S = np.eye(6) if S is None else check_calibration(S, "S", size=6)
    g = as_finite_array(gravity, (3,), "gravity")
    if not np.linalg.norm(g) > 0:
        raise FmscalError("gravity must not be zero")
    given = check_tolerance(tolerance)
    noise_given = check_tolerance(noise, "noise")
    table, repeated, kept = _distinct_rows(table)       # a row copied counts once
    check_table_units(table, g, S=S, max_mass=max_mass)  # a slipped unit named in one line, before the fit
    problem = PayloadModel(S, g)
    y = problem.corrected(table.w_hat, sign)
    R = np.moveaxis(rotation_matrix(table.q.T), -1, 0)
    if len(R) < (needed := max(min_poses(estimate_gravity, estimate_mounting), MIN_POSES)):
        raise FmscalError(f"{table.name}: {len(R)} poses; the fit as asked needs at least {needed} (min_poses)")
    # gravity's directions in the sensor frame (a mounting turns them all alike); with gravity estimated,
    # those of the first pose's gravity: poses that all hold one attitude
    _refuse_untilted(table.name, R, g if not estimate_gravity else R[0] @ np.array([0.0, 0.0, 1.0]),
                     "the mass and the offset")
    with_gains = len(R) >= min_poses(estimate_gravity, estimate_mounting, estimate_gains=True)
    model, theta, weights, sd, g_size = _two_passes(R, y, g, estimate_gravity, estimate_mounting,
                                                    problem if with_gains else None)
    m, com, c, d, M = model.parts(theta)
    if (m <= 0 or (estimate_gravity and d[2] > 0 and g[2] < 0)) and model.fixed_mass > 0:
        raise FmscalError(rotations_unresolved(table.name, len(R), model.fixed_mass))
    if m <= 0:
        raise FmscalError(other_convention(table.name, m, reading))
    if estimate_gravity and d[2] > 0 and g[2] < 0:
        raise FmscalError(gravity_up(table.name, d[2], reading))
    s2, information = _weighted_information(model, theta, weights, y)
    cov, weak = covariance(information, s2)
    cov, _ = _small_sample(model, theta, weights, y, cov)
    cov = _in_sequence(model, theta, weights, y, cov)
    disagree = None if with_gains else _gain_spread(model, theta, y)     # eq. (N7): the gains, not estimated
    std = np.sqrt(np.maximum(np.diag(cov), 0))
    S_inv = np.linalg.inv(S)
    b = S_inv @ c
    T = np.zeros((16, len(theta)))          # (m, com, c, angles) -> (m, com, I_c, b): eq. (E1) of _estimate
    T[:4, :4], T[10:, 4:10] = np.eye(4), S_inv
    payload_cov = propagate_covariance(T, cov, INERTIA_ROWS)
    b_std = np.sqrt(np.maximum(np.diag(payload_cov)[10:], 0))
    out = StaticFit(mass=float(m), mass_std=float(std[0]), com=com, com_std=std[1:4], b=b, b_std=b_std,
                    reading=reading, residual_rms=sd, cov=cov, names=model.names, payload_cov=payload_cov,
                    noise_sd=1.0 / weights, gravity_given=None if estimate_gravity else g)
    k = 10
    if estimate_gravity:
        out.gravity = g_size * d
        out.gravity_std_deg = float(np.degrees(np.sqrt(max(std[k] ** 2 + std[k + 1] ** 2, 0.0) / 2)))
        k += 2
    if estimate_mounting:
        out.mounting = M
        out.mounting_deg = _angle_deg(M)
        out.mounting_axis = _axis(M)
        out.mounting_std_deg = float(np.degrees(np.sqrt(np.sum(std[k:k + 3] ** 2) / 3)))
    if model.gain_index:
        out.gains, out.gains_std = gains_of(problem, theta[model.gain_index], cov[np.ix_(model.gain_index,
                                                                                         model.gain_index)])
    a = np.einsum("ji,nkj,k->ni", M, R, -d)
    out.cone_deg = _cone(a)
    out.undetermined = in_words(model.names, [(v, np.inf) for v in weak])
    out.warnings = list(out.undetermined)
    if repeated:
        verb = "repeats an earlier row" if len(repeated) == 1 else "repeat earlier rows"
        out.warnings.append(f"{table.name}: {_rows_named(repeated)} {verb} to the last digit (copies: a held pose's "
                            "noise never repeats), counted once")
    noise = _group_noise(model, theta, weights, y)[0]                 # the rows' scatter: torques N m, forces N
    out.tolerance = given if given is not None else (TABLE_TOLERANCE * noise[::-1] if noise_given is None else
                                                     DEFAULT_TOLERANCE * noise_given)
    attitudes = cone_attitudes(R, M, d, out.cone_deg)
    effect = static_effect(model, theta, cov, attitudes, len(R))
    out.effect = effect.cone
    determined, why, _ = judge(effect, out.tolerance, "given" if given is not None else
                               f"{TABLE_TOLERANCE:g} sd of the rows' scatter about the fit" if noise_given is None
                               else f"{DEFAULT_TOLERANCE:g} sd of the reading's noise", out.cone_deg,
                               bool(weak), circle_axis(a), with_gains)
    converged = not out.undetermined
    both = estimate_gravity and estimate_mounting
    rotated = None if both or out.undetermined else _rotation_check(R, y, g, estimate_gravity, estimate_mounting,
                                                                    model.predict(theta) - y, model.problem)
    if estimate_mounting and not sign_separated(R, y[:, 3:], g, noise[1]):
        out.warnings.append(f"these {len(R)} poses do not tell the reading's sign from a mounting turned half a turn "
                            "(their gravity directions in the sensor frame lie near one plane): record poses "
                            "out of that plane")
        converged = False
    residual = model.predict(theta) - y
    if disagree is not None:                # too few poses for the gains: what compensation would leave is said
        why = gains_warning(disagree, np.allclose(S, np.eye(6)), _noise_ratio(table, y, residual), residual,
                            (len(R), min_poses(estimate_gravity, estimate_mounting, estimate_gains=True)))
        determined = False
    elif (drift := _drift(model, theta, weights, y)) is not None:
        out.warnings.append(drift)
        converged = False
    elif out.gains is not None and rotated is None and (line := gains_differ(out.gains, cov[np.ix_(model.gain_index[:2],
                                                                                 model.gain_index[:2])],
                                                         np.allclose(S, np.eye(6)))) is not None:
        out.warnings.append(line)                   # estimated and taken into the compensation: said, not a fault
    if not out.undetermined and (line := cone_warning(out.cone_deg)) is not None:
        out.warnings.append(line)
        converged = False
    if rotated is not None:                 # the model is wrong: more poses would not help
        why, determined = rotated, False
    elif why is not None or determined:
        out.next_poses = next_poses(model, theta, information, weights, s2, R,
                                    [f"pose {k + 1}" for k in kept], attitudes, out.tolerance,
                                    widened=lambda Rc: _widened(R, M, d, Rc))
    if why is not None:
        out.warnings.append(why)
    out.payload_determined, out.why_undetermined = bool(determined), why
    out.converged = bool(converged and determined)
    return out


def _widened(R, M, d, candidate):
    """The attitudes of the cone the attitudes ``R`` and ``candidate`` span (:func:`cone_attitudes`): where a next
    pose is scored (:func:`fmscal.observers.payload.next_poses`)."""
    both = np.concatenate([R, candidate[None]])
    return cone_attitudes(both, M, d, _cone(np.einsum("ji,nkj,k->ni", M, both, -d)))


def gains_of(problem, e, cov):
    """The six channel gains of eq. (P0) and their standard deviations, from their free numbers ``e`` (the force
    gains' two, and a log's torque gain) and their covariance: the force gains' ``G C_e G^T`` (``G`` the
    :meth:`fmscal.plant.PayloadModel.gain_map`), the torques' the third number's (0 without it).

    Parameters
    ----------
    problem : fmscal.plant.PayloadModel
    e : ndarray, shape (2,) or (3,)
    cov : ndarray, shape (len(e), len(e))

    Returns
    -------
    gains, gains_std : ndarray, shape (6,)
    """
    G = problem.gain_map()
    finite = np.isfinite(cov)
    C = np.where(finite, cov, 0.0)
    std = np.zeros(6)
    std[3:] = np.sqrt(np.maximum(np.diag(G @ C[:2, :2] @ G.T), 0.0))
    if not finite[:2, :2].all():
        std[3:] = np.inf
    if len(e) > 2:
        std[:3] = np.sqrt(max(C[2, 2], 0.0)) if finite[2, 2] else np.inf
    return problem.gains(e), std


def gains_differ(gains, cov, identity):
    """The one line for force gains, estimated with the payload, that differ between the axes beyond chance, else
    None: the chi-square of their two free numbers on two degrees of freedom, at :data:`ODDS`.

    Parameters
    ----------
    gains : ndarray, shape (6,)
    cov : ndarray, shape (2, 2)
        The covariance of the force gains' two free numbers (eq. P0).
    identity : bool
        The fit took ``S = I``.

    Returns
    -------
    str or None
    """
    e = gains[3:5] - 1.0
    if not np.all(np.isfinite(cov)) or np.linalg.det(cov) <= 0 or float(e @ np.linalg.solve(cov, e)) <= chi2.ppf(
            1 - ODDS, 2):
        return None
    told = "S = I may be off: calibrate S for the cross-talk" if identity else "the calibration given may be off"
    return ("the force gains differ between axes (relative to their mean: "
            + ", ".join(f"{axis} {v:.4f}" for axis, v in zip("xyz", gains[3:]))
            + f"); estimated with the payload, the compensation takes them; {told}")


def _two_passes(R, y, g, estimate_gravity, estimate_mounting, problem=None):
    """The fit's start, an unweighted pass, and passes weighted by each group's noise (torques, forces).

    Each group's noise is its residuals' variance over the group's own
    degrees of freedom, ``s_g^2 = RSS_g / nu_g`` with ``nu_g = n_g - sum of
    the leverages of its rows`` (eq. N2, :func:`_group_noise`): the
    small-sample correction for the parameters fitted, shared between the
    groups as the fit uses them (the leverages of all rows sum to the
    parameters' count). A group, not a channel: four poses leave each
    channel one or two degrees of freedom, too few to weigh it by.

    Returns
    -------
    model : _Model
    theta : ndarray
        The parameters after the weighted passes.
    weights : ndarray, shape (6,)
        Each reading channel's weight, 1 / its group's noise (N m, N).
    sd : ndarray, shape (6,)
        The weighted fit's residual rms per channel (N m, N).
    g_size : float
        Gravity's magnitude, m/s^2.
    """
    model, theta = _best_start(R, y, g, estimate_gravity, estimate_mounting, problem)
    g_size = model.g_size
    floor = 1e-9 * max(np.abs(y).max(), 1e-300)
    weights = np.ones(6)
    for _ in range(2):
        noise, _ = _group_noise(model, theta, weights, y)
        weights = 1.0 / np.maximum(np.repeat(noise, 3), floor)
        theta = _weighted(model, theta, weights)
    sd = np.sqrt(np.mean((model.predict(theta) - y) ** 2, axis=0))
    return model, theta, weights, sd, g_size


def _best_start(R, y, g, estimate_gravity, estimate_mounting, problem=None):
    """The unweighted fit from the linear start and, with gravity estimated, from gravity's given direction with a
    positive mass; which one is kept follows the fit with gravity held fixed.

    The sign of the mass with gravity fixed (:func:`_start` with gravity as
    given: a linear fit, or with the mounting a rotation fitted for either
    sign of the mass, :func:`_procrustes`) is what the data say of the
    reading's convention; a rotation cannot turn it. Where it is positive, the
    fit kept is the one with a positive mass and gravity on the side given
    (the lower residuals of those); where none is, the one with the lower
    residuals; where the mass with gravity fixed is negative, one with a
    positive mass where there is one (gravity then up: a reading of the other
    sign and a base upside down fit alike, and :func:`gravity_up` names both),
    else the lower residuals. With few poses the
    linear start of gravity's direction can fall near the opposite one, a
    local minimum that reads as gravity pointing up: the second start finds
    the minimum near the direction given.

    Returns
    -------
    model : _Model
        With ``fixed_mass`` (the mass with gravity fixed, kg) set.
    theta : ndarray
    """
    fixed = _start(R, y, g, False, estimate_mounting)
    starts = [_start(R, y, g, estimate_gravity, estimate_mounting) if estimate_gravity else fixed]
    if estimate_gravity:
        starts.append(_start(R, y, g, False, estimate_mounting, signs=(1.0,)))
    found = []
    for theta0, d0, M0, g_size in starts:
        model = _Model(R, y, g_size, d0, M0, estimate_gravity, estimate_mounting, problem)
        theta = _weighted(model, _extra(theta0, model), np.ones(6))
        m, _, _, d, _ = model.parts(theta)
        physical = bool(m > 0 and d @ g > 0)
        found.append((not physical, float(np.sum((model.predict(theta) - y) ** 2)), len(found), model, theta))
    fixed_mass = float(fixed[0][0])
    # the mass with gravity fixed negative: a reading of the other sign or a base upside down fit alike, and the fit
    # with a positive mass (gravity up) is kept where there is one, so that the line names both (gravity_up)
    best = min(found, key=lambda item: item[:3] if fixed_mass > 0 else (item[4][0] <= 0, *item[1:3]))
    best[3].fixed_mass = fixed_mass
    return best[3], best[4]


def _leverages(J):
    """The diagonal of the hat matrix ``J (J^T J)^+ J^T``, over the directions ``J`` determines."""
    U, sv, _ = np.linalg.svd(J, full_matrices=False)
    keep = sv > 1e-10 * max(sv[0], 1e-300)
    return np.sum(U[:, keep] ** 2, axis=1)


def _group_noise(model, theta, weights, y):
    """The noise of the torques and of the forces, each over its own degrees of freedom::

        s_g^2 = sum_{rows of g} r^2 / nu_g,   nu_g = n_g - sum_{rows of g} h_ii          (N2)

    ``r`` the residuals, ``h_ii`` the leverages of the fit weighted by ``weights`` (eq. N2 is the
    unbiased variance of a linear fit, each group charged with the parameters its rows determine).

    Returns
    -------
    noise : ndarray, shape (2,)
        ``s_g`` of the torques (N m) and the forces (N); ``inf`` where ``nu_g`` is below a half.
    dof : ndarray, shape (2,)
        ``nu_g``.
    """
    residual = model.predict(theta) - y
    h = _leverages(model.jacobian(theta) * np.tile(weights, len(y))[:, None]).reshape(len(y), 6)
    rss = np.array([np.sum(residual[:, :3] ** 2), np.sum(residual[:, 3:] ** 2)])
    dof = np.array([3 * len(y) - h[:, :3].sum(), 3 * len(y) - h[:, 3:].sum()])
    noise = np.where(dof > 0.5, np.sqrt(rss / np.maximum(dof, 0.5)), np.inf)
    return noise, dof


def _weighted_information(model, theta, weights, y):
    """The weighted residuals' variance per degree of freedom and the information ``J^T J`` of the weighted fit.

    Returns
    -------
    s2 : float
    information : ndarray, shape (p, p)
    """
    residual = (model.predict(theta) - y) * weights
    s2 = float(np.sum(residual ** 2) / max(residual.size - len(theta), 1))
    J = model.jacobian(theta) * np.tile(weights, len(y))[:, None]
    return s2, J.T @ J


def _in_sequence(model, theta, weights, y, cov):
    """``cov`` widened where the cluster-robust covariance over blocks of consecutive rows exceeds it.

    Rows recorded in sequence (a joint recording's quasi-static rows, an
    attitude-only log's held segments) share slow errors, which the fit's
    own covariance, taking them as independent, does not see. The rows'
    blocks are five of the residuals' correlation lengths, in rows (eq. U2
    of :mod:`fmscal.observers.batch`; one row where they are white),
    and :func:`fmscal.observers.batch.sandwich` gives the covariance over
    them. Where there are at least :data:`fmscal.observers.batch.MIN_BLOCKS`
    blocks, each parameter's variance is the larger of the two (the
    correlations kept, the rows and columns scaled)::

        cov_i = cov * d d^T,   d_i = max(1, sqrt(sandwich_ii / cov_ii))     (N6)
    """
    n = len(y)
    residual = (model.predict(theta) - y) * weights
    if n < 2 * MIN_BLOCKS or not np.all(np.isfinite(np.diag(cov))):
        return cov
    tau = correlation_time(residual)
    blocks = np.repeat((np.arange(n) // max(5.0 * tau, 1.0)).astype(int), 6)
    if blocks.max() + 1 < MIN_BLOCKS:             # too few blocks for the sandwich: the rows count 1 / tau each
        return cov * max(tau, 1.0)
    J = model.jacobian(theta) * np.tile(weights, n)[:, None]
    inverse, columns = pseudo_inverse(J)
    robust = sandwich(J, residual.ravel(), blocks, inverse, columns)
    d = np.sqrt(np.maximum(np.diag(robust) / np.maximum(np.diag(cov), 1e-300), 1.0))
    return cov * np.outer(d, d)


def _gain_spread(model, theta, y):
    """The three force axes' own masses where they disagree beyond chance, else None.

    At the fitted rotations, each force axis ``j`` is fitted alone,
    ``f_kj = m_j a_kj + c_j`` (``a_k = M^T R_k^T (-g)``), against one mass
    for the three: the F test on ``2`` and ``3N - 6`` degrees of freedom, at
    :data:`ODDS`::

        F = ((SS_1 - SS_3) / 2) / (SS_3 / (3N - 6))                          (N7)

    Returns
    -------
    ndarray, shape (3,), or None
        ``m_x, m_y, m_z``, kg.
    """
    n = len(y)
    if 3 * n <= 8:
        return None
    m, _, c, d, M = model.parts(theta)
    a = np.einsum("ji,nkj,k->ni", M, model.R, -model.g_size * d)
    f = y[:, 3:]
    masses, ss3 = np.zeros(3), 0.0
    for j in range(3):
        X = np.c_[a[:, j], np.ones(n)]
        coef, *_ = np.linalg.lstsq(X, f[:, j], rcond=None)
        masses[j] = coef[0]
        ss3 += float(np.sum((f[:, j] - X @ coef) ** 2))
    X = np.zeros((3 * n, 4))
    X[:, 0] = a.ravel()
    X[:, 1:] = np.tile(np.eye(3), (n, 1))
    coef, *_ = np.linalg.lstsq(X, f.ravel(), rcond=None)
    ss1 = float(np.sum((f.ravel() - X @ coef) ** 2))
    dof = 3 * n - 6
    if ss3 <= 0 or (ss1 - ss3) / 2 / (ss3 / dof) <= f_dist.ppf(1 - ODDS, 2, dof):
        return None
    return masses


def cone_warning(cone):
    """The one line for gravity directions within a cone narrower than :data:`NARROW_CONE_DEG`, else None.

    Parameters
    ----------
    cone : float
        The cone's half-angle in the sensor frame, degrees.

    Returns
    -------
    str or None
    """
    if not MIN_CONE_DEG <= cone < NARROW_CONE_DEG:
        return None
    return (f"the gravity directions span a cone of only {cone:.0f} degrees in the sensor frame: the weight is told "
            "from the offset by small differences, which a gain error or a drifting offset moves; tilt the tool "
            f"further ({NARROW_CONE_DEG:.0f} degrees or more, about two axes)")


def _drift(model, theta, weights, y):
    """The one line for residuals that trend along the rows (an offset drifting while they were recorded), else None.

    Each channel's weighted residuals are regressed on the centred row index
    ``x``; their trends' squared sizes, in units of the noise, sum to a
    chi-square on six degrees of freedom where there is no trend::

        X = sum_j (sum_k r_kj x_k)^2 / sum_k x_k^2 > chi2_{1 - ODDS}(6)     (N9)

    Rows in an order that is not time's (a table of poses taken in any order)
    trend only by chance.
    """
    n = len(y)
    if n < 8:
        return None
    x = np.arange(n) - (n - 1) / 2
    raw = model.predict(theta) - y
    trend = (raw * weights).T @ x / np.sum(x ** 2)
    if float(np.sum(trend ** 2) * np.sum(x ** 2)) <= chi2.ppf(1 - ODDS, 6):
        return None
    force = np.abs(raw[:, 3:].T @ x / np.sum(x ** 2)) * (n - 1)
    torque = np.abs(raw[:, :3].T @ x / np.sum(x ** 2)) * (n - 1)
    return (f"the residuals trend along the rows: taken in time order, the offset drifts by up to {force.max():.2g} N "
            f"and {torque.max():.2g} N m over the recording; re-zero the sensor and let it warm up, or record faster")


def _noise_ratio(table, y, residual):
    """The force residuals' rms over the reading's noise measured from the data, or None where it is not.

    The noise is the rows' own standard errors where the table has them (an
    attitude-only log's held segments), else, for at least ``2 MIN_BLOCKS``
    rows, the forces' row-to-row scatter ``rms(diff) / sqrt 2`` (rows in
    sequence: a joint recording's high-frequency noise; a table of poses in
    any order scatters far more, and no ratio is claimed from it).
    """
    if table.noise is not None:
        noise = float(np.sqrt(np.mean(np.square(table.noise[:, 3:]))))
    elif len(y) >= 2 * MIN_BLOCKS:
        noise = float(np.sqrt(np.mean(np.diff(y[:, 3:], axis=0) ** 2) / 2))
    else:
        return None
    return float(np.sqrt(np.mean(residual[:, 3:] ** 2))) / max(noise, 1e-300)


def gains_warning(masses, identity, ratio=None, residual=None, poses=None):
    """The one line for force axes whose gains disagree (eq. N7) where the fit did not estimate them: what
    compensation with the gains taken as one would leave.

    Parameters
    ----------
    masses : ndarray, shape (3,)
        The mass each force axis gives alone, kg.
    identity : bool
        The fit took ``S = I``.
    ratio : float, optional
        The force residuals over the reading's noise, where measured (:func:`_noise_ratio`).
    residual : ndarray, shape (N, 6), optional
        The fit's residuals: their rms, forces (N) and torques (N m), is what compensation would leave.
    poses : (int, int), optional
        The table's poses and the fewest that estimate the gains with the rotations asked (:func:`min_poses`).

    Returns
    -------
    str
    """
    spread = float((masses.max() - masses.min()) / masses.mean())
    told = ("S = I may be wrong: calibrate S (fmscal calibrate) and pass --calibration" if identity
            else "the calibration given may be wrong, or the payload's mass changed")
    times = "" if ratio is None else f"the residual is {ratio:{'.2g' if ratio < 10 else '.0f'}} times the noise; "
    left = "" if residual is None else (
        f"; compensation with them taken as one would leave about {np.sqrt(np.mean(residual[:, 3:] ** 2)):.2g} N "
        f"and {np.sqrt(np.mean(residual[:, :3] ** 2)):.2g} N m (rms)")
    more = "" if poses is None else (f"; {poses[0]} poses are too few to estimate them with the rotations asked, "
                                     f"{poses[1]} are enough")
    return (times + f"the force gains seem to differ by {spread:.1%} between axes (each axis alone weighs "
            + ", ".join(f"{v:.4g}" for v in masses) + f" kg){left}{more}; {told}")


def _small_sample(model, theta, weights, y, cov):
    """``cov`` with each parameter's variance widened to the Student-t's, ``nu / (nu - 2)`` times::

        v_i = sum_g v_ig,   v_ig = [C J_g^T J_g C]_ii,   nu_i = v_i^2 / sum_g (v_ig^2 / nu_g)      (N3)

    ``C`` the covariance of the weighted fit, ``J_g`` the weighted rows of group ``g`` (torques, forces) and
    ``nu_g`` its degrees of freedom (eq. N2): each variance is estimated from the groups' noise, with ``nu_i``
    degrees of freedom (Welch-Satterthwaite), so the error over the estimated sigma is Student-t, whose variance
    is ``nu / (nu - 2)``: the one-sigma reported is the error's standard deviation. Where ``nu_i <= 2`` that is
    infinite: the parameter is not determined.

    Returns
    -------
    cov : ndarray, shape (p, p)
    dof : ndarray, shape (p,)
        ``nu_i``.
    """
    _, dof_g = _group_noise(model, theta, weights, y)
    J = (model.jacobian(theta) * np.tile(weights, len(y))[:, None]).reshape(len(y), 6, -1)
    C = np.where(np.isfinite(cov), cov, 0.0)
    v = np.stack([np.einsum("ij,ji->i", C @ (Jg.T @ Jg), C)
                  for Jg in (J[:, :3].reshape(-1, J.shape[2]), J[:, 3:].reshape(-1, J.shape[2]))], axis=1)
    total = v.sum(axis=1)
    dof = total ** 2 / np.maximum(np.sum(v ** 2 / np.maximum(dof_g, 1e-300), axis=1), 1e-300)
    factor = np.where(dof > 2, dof / np.maximum(dof - 2, 1e-300), np.inf)
    factor[~np.isfinite(np.diag(cov))] = np.inf
    root = np.sqrt(factor)
    with np.errstate(invalid="ignore"):
        out = cov * np.outer(root, root)
    out[~np.isfinite(root), :] = np.inf
    out[:, ~np.isfinite(root)] = np.inf
    return out, dof


def _rotation_check(R, y, g, estimate_gravity, estimate_mounting, residual, problem=None):
    """The warning of :func:`rotation_check` when the table needs gravity's direction or the mounting
    estimated, else None.

    The fit is repeated with the rotations free (the start and the two
    weighted passes of :func:`fit_static`, without its report), and its force
    residuals compared with ``residual``, those of the fit as asked.
    """
    def refit(gravity_free, mounting_free):
        model, theta, weights, _, _ = _two_passes(R, y, g, gravity_free, mounting_free, problem)
        s2, information = _weighted_information(model, theta, weights, y)
        cov, weak = covariance(information, s2)
        cov, _ = _small_sample(model, theta, weights, y, cov)
        if weak:
            return None
        std = np.sqrt(np.maximum(np.diag(cov), 0))
        parts = model.parts(theta)
        k = 12 if gravity_free else 10                      # the mounting's angles follow gravity's two
        return Refit(_force_rms(model.predict(theta) - y),
                     parts[3] if gravity_free else None,
                     float(np.degrees(np.sqrt((std[10] ** 2 + std[11] ** 2) / 2))) if gravity_free else None,
                     _angle_deg(parts[4]) if mounting_free else None,
                     float(np.degrees(np.sqrt(np.sum(std[k:k + 3] ** 2) / 3))) if mounting_free else None)

    return rotation_check(_force_rms(residual), g, refit, estimate_gravity, estimate_mounting)


class Refit(NamedTuple):
    """A fit repeated with gravity's direction or the mounting free, as :func:`rotation_check` compares it.

    Attributes
    ----------
    force_rms : float
        Its force residuals' rms, N.
    gravity : ndarray, shape (3,), or None
        Gravity's estimated direction (pose frame), where free.
    gravity_std_deg : float or None
        Its one-sigma uncertainty, degrees.
    mounting_deg, mounting_std_deg : float or None
        The mounting's angle and its one-sigma uncertainty, degrees, where free.
    """

    force_rms: float
    gravity: np.ndarray
    gravity_std_deg: float
    mounting_deg: float
    mounting_std_deg: float


def rotation_check(fixed_rms, gravity, refit, estimate_gravity, estimate_mounting):
    """The one line for data that a rotation the fit did not estimate explains, else None; tables and logs alike.

    Fits again with gravity's direction free, and with the mounting free (each
    where the fit did not estimate it), and names the one that explains the
    data (:func:`rotation_warning`); where neither alone does and the fit
    estimated neither, with both free (:func:`both_rotations_warning`).

    Parameters
    ----------
    fixed_rms : float
        The force residuals' rms of the fit as asked, N.
    gravity : array_like, shape (3,)
        The gravity given, pose frame.
    refit : callable
        ``refit(gravity_free, mounting_free)``: the fit repeated so, a :class:`Refit`, or None where it does
        not determine its parameters.
    estimate_gravity, estimate_mounting : bool
        What the fit as asked estimated.

    Returns
    -------
    str or None
    """
    tilted = mounted = None
    if not estimate_gravity and (free := refit(True, estimate_mounting)) is not None:
        tilted = (free.force_rms, free.gravity, free.gravity_std_deg)
    if not estimate_mounting and (free := refit(estimate_gravity, True)) is not None:
        mounted = (free.force_rms, free.mounting_deg, free.mounting_std_deg)
    warning = rotation_warning(fixed_rms, gravity, tilted, mounted)
    if warning is None and not (estimate_gravity or estimate_mounting) and (free := refit(True, True)) is not None:
        warning = both_rotations_warning(fixed_rms, free.force_rms, gravity, free.gravity, free.gravity_std_deg,
                                         free.mounting_deg, free.mounting_std_deg)
    return warning


def _force_rms(residual):
    """The rms of the force channels of residuals shaped (N, 6), N."""
    return float(np.sqrt(np.mean(np.square(residual[:, 3:]))))


def tilt_warning(fixed_rms, free_rms, gravity, direction, std_deg):
    """The warning for data that gravity along the direction given does not explain, and a tilted one does.

    Parameters
    ----------
    fixed_rms, free_rms : float
        The force residuals' rms with gravity's direction fixed and estimated, N.
    gravity : array_like, shape (3,)
        The gravity given, pose frame.
    direction : array_like, shape (3,)
        Gravity's direction as estimated, pose frame.
    std_deg : float
        One-sigma uncertainty of the estimated direction about each axis across it, degrees.

    Returns
    -------
    str or None
        None unless the residuals fall by more than :data:`TILT_RATIO` and
        the tilt is more than :data:`TILT_SIGMAS` standard deviations.
    """
    tilt, along = _tilt(gravity, direction)
    if not _explains(fixed_rms, free_rms, tilt, std_deg):
        return None
    return (f"the force residuals are {fixed_rms / max(free_rms, 1e-300):.0f} times the noise with gravity along "
            f"{along}; the data are explained with gravity tilted {tilt:.2g} degrees from it (+- {std_deg:.1g}): add "
            "--gravity estimate (a tilted or wall-mounted base)")


def mounting_warning(fixed_rms, free_rms, angle_deg, std_deg):
    """The warning for data that the sensor square on the tracked frame does not explain, and a mounting rotation does.

    Parameters
    ----------
    fixed_rms, free_rms : float
        The force residuals' rms with the mounting fixed (the identity) and estimated, N.
    angle_deg, std_deg : float
        The estimated mounting's angle, and the one-sigma uncertainty of its rotation about each axis, degrees.

    Returns
    -------
    str or None
        None unless the residuals fall by more than :data:`TILT_RATIO` and
        the angle is more than :data:`TILT_SIGMAS` standard deviations.
    """
    if not _explains(fixed_rms, free_rms, angle_deg, std_deg):
        return None
    return (f"the force residuals are {fixed_rms / max(free_rms, 1e-300):.0f} times the noise with the sensor square "
            f"on the tracked frame; the data are explained with the sensor turned {angle_deg:.2g} degrees on it (+- "
            f"{std_deg:.1g}): add --mounting estimate (a sensor bolted askew)")


def both_rotations_warning(fixed_rms, free_rms, gravity, direction, gravity_std_deg, angle_deg, mounting_std_deg):
    """The warning for data that neither gravity's tilt nor the mounting explains alone, and both together do.

    A tilted base and a sensor bolted askew at once: each rotation alone
    leaves the other's residuals, so neither single check fires
    (:func:`rotation_warning`). The fit with both estimated explains the
    data when its force residuals fall by more than :data:`TILT_RATIO` and
    both angles are beyond :data:`TILT_SIGMAS` standard deviations.

    Parameters
    ----------
    fixed_rms, free_rms : float
        The force residuals' rms of the fit as asked and with both rotations estimated, N.
    gravity : array_like, shape (3,)
        The gravity given, pose frame.
    direction : array_like, shape (3,)
        Gravity's direction as estimated, pose frame.
    gravity_std_deg, angle_deg, mounting_std_deg : float
        The direction's one-sigma uncertainty, the mounting's angle and its one-sigma uncertainty, degrees.

    Returns
    -------
    str or None
    """
    tilt, along = _tilt(gravity, direction)
    if not (_explains(fixed_rms, free_rms, tilt, gravity_std_deg)
            and _explains(fixed_rms, free_rms, angle_deg, mounting_std_deg)):
        return None
    return (f"the force residuals are {fixed_rms / max(free_rms, 1e-300):.0f} times the noise with gravity along "
            f"{along} and the sensor square on the tracked frame; the data are explained with gravity tilted "
            f"{tilt:.2g} degrees (+- {gravity_std_deg:.1g}) and the sensor turned {angle_deg:.2g} degrees (+- "
            f"{mounting_std_deg:.1g}): add --gravity estimate --mounting estimate")


def _tilt(gravity, direction):
    """The angle between the gravity given and the direction estimated, degrees, and the given one in words."""
    given = np.asarray(gravity, dtype=float) / np.linalg.norm(gravity)
    direction = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    along = "-z" if np.allclose(given, [0.0, 0.0, -1.0]) else "the direction given"
    return float(np.degrees(np.arccos(np.clip(given @ direction, -1.0, 1.0)))), along


def _explains(fixed_rms, free_rms, angle_deg, std_deg):
    """The residuals fall by more than :data:`TILT_RATIO`, at an angle beyond :data:`TILT_SIGMAS` sigmas."""
    return bool(fixed_rms > TILT_RATIO * max(free_rms, 1e-300) and np.isfinite(std_deg)
                and angle_deg > TILT_SIGMAS * std_deg)


def rotation_warning(fixed_rms, gravity, tilted=None, mounted=None):
    """The one line for data the fit's rotations do not explain: which of gravity's tilt and the mounting does.

    Each explains when estimating it lowers the force residuals' rms more
    than :data:`TILT_RATIO` times and finds an angle beyond
    :data:`TILT_SIGMAS` standard deviations (:func:`tilt_warning`,
    :func:`mounting_warning`); where both do, the one with the lower
    residuals is named (the poses tell a turn of the world from a turn on
    the tool when they turn the tool about several axes).

    Parameters
    ----------
    fixed_rms : float
        The force residuals' rms of the fit as asked, N.
    gravity : array_like, shape (3,)
        The gravity given, pose frame.
    tilted : tuple (free_rms, direction, std_deg), optional
        The fit with gravity's direction estimated (:func:`tilt_warning`); None: not tried.
    mounted : tuple (free_rms, angle_deg, std_deg), optional
        The fit with the mounting estimated (:func:`mounting_warning`); None: not tried.

    Returns
    -------
    str or None
    """
    tilt = None if tilted is None else tilt_warning(fixed_rms, tilted[0], gravity, tilted[1], tilted[2])
    mount = None if mounted is None else mounting_warning(fixed_rms, *mounted)
    if tilt is not None and (mount is None or tilted[0] <= mounted[0]):
        return tilt
    return mount


def calibrate_table(table, mass, com, gravity=GRAVITY, reading="reaction"):
    """``S`` and the offset from a pose table, the payload known: what held poses can and cannot determine.

    At a held pose the payload needs the weight's wrench at the sensor,
    ``w_k = [com x f_k; f_k]`` with ``f_k = -m R_k^T g`` (Newton-Euler at
    rest, :func:`fmscal.plant.physics.regressor` with no motion),
    exact given the pose. The reading is ``sigma w_hat_k = A w_k + b`` with
    ``A = S^-1`` (eq. 3 inverted); it is fitted row by row by least squares
    on the exact regressor ``[w_k; 1]``, the rows independent
    (:func:`fmscal.observers.batch.fit_readings`): no errors
    in variables. The wrenches ``w_k`` span at most three of the six
    directions (the torque is ``com x f``, fixed by the force), so ``A``, and
    with it ``S``, is determined on at most three: on the others the estimate
    keeps the identity, and they are reported as undetermined directions of
    the reading (where ``S_hat`` is the identity, the same directions). No
    single entry of ``S`` is determined (``S_std`` is infinite) and the fit
    never counts as converged. The offset ``b`` is the fit's intercept,
    determined when gravity turns through more than one direction in the
    sensor frame.

    Parameters
    ----------
    table : plant.PoseTable
    mass : float
        The payload's mass, kg.
    com : array_like, shape (3,)
        Its centre of mass in the sensor frame, m.
    gravity : array_like, shape (3,)
        Gravity in the pose frame, m/s^2.
    reading : {"reaction", "load"}
        The reading's sign convention (:data:`fmscal.plant.io._calibration.READINGS`).

    Returns
    -------
    InverseDynamicsFit
        ``S_hat`` and ``S_std`` (6, 6), ``b`` and ``b_std`` (6; reading
        order, N m and N), ``undetermined`` (unit directions of ``[tx .. fz,
        1]``, each component scaled by the wrench's spread) and their
        warnings; ``converged`` False.
    """
    if not isinstance(table, PoseTable):
        raise TypeError(f"table must be a plant.PoseTable; got {type(table).__name__}")
    sign = reading_sign(reading)
    g = as_finite_array(gravity, (3,), "gravity")
    com = as_finite_array(com, (3,), "com")
    if not (np.isfinite(mass) and mass > 0):
        raise FmscalError(f"mass must be a positive number of kg; got {mass}")
    if not np.linalg.norm(g) > 0:
        raise FmscalError("gravity must not be zero")
    _refuse_untilted(table.name, np.moveaxis(rotation_matrix(table.q.T), -1, 0), g, "S and the offset")
    still = np.zeros((len(table), 3))
    pi = np.r_[mass, mass * com, np.zeros(6)]                         # (m, h, I_O): the inertia plays no part
    w = regressor(table.q, still, still, still, g) @ pi                # (N, 6), exact given the poses
    # the reading on the wrench: [A | b], A = S^-1, the identity where the poses say nothing
    inverse = fit_readings(sign * table.w_hat, w, prior=np.c_[np.eye(6), np.zeros(6)], held=True)
    A, b = inverse.S_hat, inverse.c
    if np.trace(A[3:, 3:]) < 0:                     # the reading falls where the weight rises: the other sign
        raise FmscalError(other_convention(table.name, None, reading))
    b_std = np.sqrt(np.maximum(np.diag(inverse.cov)[6::7], 0))
    if np.linalg.cond(A) > 1e12:
        raise FmscalError(f"{table.name}: the readings do not follow the weight (the fitted map from wrench to "
                          "reading is singular): check the units (N, N m) and the quaternions' frame")
    S_hat = np.linalg.inv(A)
    return InverseDynamicsFit(S_hat=S_hat, S_std=np.full((6, 6), np.inf), b=b, b_std=b_std,
                              cov=np.full((42, 42), np.inf), undetermined=inverse.undetermined,
                              warnings=inverse.warnings, converged=False, residual_rms=inverse.residual_rms,
                              c=-S_hat @ b)


def _who(reading):
    return "mount applies to the payload" if reading == "reaction" else "tool applies to the sensor"


def other_convention(name, mass, reading):
    """The one line for data whose mass (or force gain) comes out negative: it follows the other sign convention.

    Parameters
    ----------
    name : str
        The data's name.
    mass : float or None
        The (negative) mass the fit gave, kg; None: a fit of ``S`` whose
        force gain came out negative (or gravity pointing up).
    reading : str
        The convention the fit used (:data:`fmscal.plant.io._calibration.READINGS`).

    Returns
    -------
    str
    """
    other = "load" if reading == "reaction" else "reaction"
    what = ("the force reading falls where the weight rises (a negative gain)" if mass is None
            else f"the mass comes out negative ({mass:.4g} kg)")
    return (f"{name}: {what}: the reading follows the other sign convention; pass reading=\"{other}\" (on the "
            f"command line --reading {other}: the wrench the {_who(other)})")


def rotations_unresolved(name, poses, fixed_mass, data="poses"):
    """The one line for a fit with gravity or the mounting estimated that finds gravity up or a negative mass,
    where the fit with gravity held fixed gives a positive mass: the reading's sign is not the cause.

    Parameters
    ----------
    name : str
    poses : int
        The poses (or samples) fitted.
    fixed_mass : float
        The mass with gravity held fixed, kg (positive).
    data : str
        What ``poses`` counts.

    Returns
    -------
    str
    """
    return (f"{name}: with the rotations estimated the fit finds gravity pointing up or a negative mass, though with "
            f"gravity held as given the mass is positive ({fixed_mass:.4g} kg), so the reading's sign is not the "
            f"cause: {poses} {data} do not resolve gravity's direction and the mounting; record more poses, tilted "
            "about two axes, or give --gravity")


def gravity_up(name, z, reading):
    """The one line for a fit whose estimated gravity points up in the pose frame.

    A weight read in the other sign convention and a base upside down (a robot
    hung from a ceiling) give the same data: ``m R^T g`` changes sign either
    way. The line names both, and the flag for each.

    Parameters
    ----------
    name : str
        The data's name.
    z : float
        The estimated gravity direction's z component (positive).
    reading : str
        The convention the fit used.

    Returns
    -------
    str
    """
    other = "load" if reading == "reaction" else "reaction"
    return (f"{name}: gravity comes out pointing up in the pose frame (z = {z:+.2f}): the reading follows the other "
            f"sign convention, pass --reading {other} (the wrench the {_who(other)}); or the base hangs upside down "
            "(a robot on a ceiling), give --gravity 0 0 9.81")


def _refuse_untilted(name, R, g, what):
    """Raise :class:`FmscalError` when the attitudes ``R`` (N, 3, 3) keep gravity ``g`` within
    :data:`MIN_CONE_DEG` of one direction in the sensor frame (one attitude held, or turns about gravity)."""
    cone = _cone(np.einsum("nkj,k->nj", R, -np.asarray(g, dtype=float)))
    if cone < MIN_CONE_DEG:
        raise FmscalError(f"{name}: the poses do not tilt gravity in the sensor frame (all within {cone:.1f} "
                          f"degrees of one direction; {MIN_CONE_DEG:g} needed, tens of degrees useful): {what} "
                          "cannot be separated; hold the tool in at least four attitudes tilted 30 degrees or "
                          "more about two different horizontal axes")
