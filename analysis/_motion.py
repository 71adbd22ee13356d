"""The motion's sources: the sensor frame's poses, joint states with a URDF, an IMU on the tool.

Compensation (:mod:`fmscal.analysis._compensate`) needs the model's state ``x`` and accelerations ``a``
(the spatial model: ``x = [p, q, v, omega]``, ``v`` in the world and ``omega`` in the sensor's axes,
``a = [p_ddot, alpha]``, ``p_ddot`` in the world and ``alpha`` in the sensor's axes) to invert its dynamics
(C2), and the noise of ``a`` for the covariance (C3). Each source is a type (:class:`PoseMotion`,
:class:`JointMotion`, :class:`ImuMotion`) that says what it measures and how the motion follows from it; the
compensation's filters and its one step are the same for all (:class:`Motion` is what a source hands over).

What a source declares, and what compensation and the ROS 2 node call on it:

- its **channels**: the numbers the filters smooth and differentiate (the pose's columns; the joint angles; the
  IMU's rate and specific force), and the **extras** that come with a sample unfiltered (measured joint rates;
  the IMU's orientation);
- :meth:`~PoseMotion.samples`: rows of a push checked into channels and extras (NaN rows where none came);
- :meth:`~PoseMotion.motion`: the :class:`Motion` of rows of filtered channels, their two derivatives and their
  noise; :meth:`~PoseMotion.offline`: the same over a whole log, smoothed both ways;
- its ``latency`` and, for the node, how a sample is interpolated between two stamps, a sample at rest, what
  ``~/identify_payload`` holds of it and the log it fits.

**Poses** (:class:`PoseMotion`, the default). The smoothed pose and its two derivatives give the state; a unit
quaternion's rates give ``omega = 2 vec(q* (x) q')``, ``alpha = 2 vec(q* (x) q'')`` (:func:`kinematics`), a
configuration that moves additively is the pose itself. Offline, the poses are smoothed by the filter the
calibration's least squares uses (:func:`fmscal.plant.physics.spatial_motion`,
:func:`fmscal.observers.batch.smoothed_channels`). The noise: each pose column's (the noise model's
:meth:`fmscal.plant.Model.pose_sd`) moved into the configuration's tangent space (:func:`configuration_variance`)
and through the second-derivative filter, ``var(a_j) = var(q_j) sum(c2^2)``.

**Joint states** (:class:`JointMotion`). pinocchio's forward kinematics of ``q, dq, ddq`` gives the sensor
frame's placement ``(R, p)``, its velocity ``(v_l, omega)`` and its *classical* acceleration
``(a_l, alpha)`` in its own axes (``LOCAL``; :meth:`fmscal.plant.io.RobotKinematics.motion`), so::

    x = [p, q(R), R v_l, omega],    a = [R a_l, alpha]                                            (C5)

The classical acceleration is the derivative of the origin's world velocity; the spatial one
(``getFrameAcceleration``) differs from it by ``omega x v_l``, and taken for ``R^T p_ddot`` it is wrong by
``m omega x v_l`` in force wherever the frame rotates and translates together. The URDF's base frame is the
world: gravity is the calibration's, in the base's axes. ``dq`` and ``ddq`` not given are differentiated from
``q`` by the same polynomial filter as poses (offline both ways; causally with its stated delay).

**An IMU on the tool** (:class:`ImuMotion`). The IMU measures its orientation in its world ``R_i``, its
angular velocity ``omega_i`` and its specific force ``f_i = R_i^T (p_ddot_i - g)`` in its own axes. With
``C`` its axes in the sensor's (``v_s = C v_i``) and ``r`` its point from the sensor's point (sensor axes),
on one rigid body::

    omega = C omega_i,   alpha = d/dt omega,   f_s = C f_i - (alpha x r + omega x (omega x r))    (C6)

``f_s = R^T (p_ddot - g)`` at the sensor's point, in its axes: all the payload's wrench needs of the
attitude and the translation. Only ``alpha`` is differentiated. The model is then read at the attitude
``R = I`` with ``p_ddot = f_s + g`` (its own gravity ``g``), so that ``R^T (p_ddot - g) = f_s``::

    x = [0, (1, 0, 0, 0), 0, omega],    a = [f_s + g, alpha]                                     (C7)

no gravity vector and no pose is needed. The sensor frame's attitude, for an output in the base frame, is
``R = R_i C^T`` (the IMU's world).

**Latency.** A source's stream may lag the readings (a tracker's processing, a joint-state topic published
after the controller's cycle, an IMU's own filter): ``latency`` (s, either sign) says that its sample given
with the reading at ``t`` is as of ``t - latency``. Offline the stream is moved onto the readings' times
(:meth:`~PoseMotion.aligned`: poses by :meth:`fmscal.plant.Log.shift_poses`; a joint or IMU stream by linear
interpolation, a stream sparser than the readings staying as sparse, each sample on the row nearest its time);
causally the filter is read ``latency`` (whole samples) nearer its newest sample, so that the motion and the
reading are of one time; the delay the causal path states is unchanged, and must be at least the latency.
A pose stream's latency is the calibration's (its pose stream's) unless a :class:`PoseMotion` says otherwise.

**Noise** (the third term of (C3)). A joint or IMU source's channels' noise is estimated from their
differences (a white noise of sd ``sigma`` on a signal smooth at the sample rate gives second differences of
variance ``6 sigma^2``; offline by :func:`fmscal.plant.io.difference_noise`, ``estimate_noise``'s robust
estimate, causally from the second differences as the samples come) and carried through the filter's
coefficients: the joints' ``var(ddq_j) = var(q_j) sum(c2^2)`` through the frame's Jacobian ``J``
(``var(a_l) = (J_v o J_v) var(ddq)``, ``o`` the entrywise product, ``var(alpha)`` likewise with ``J_omega``), at
each sample's ``q``, per component; the IMU's as a full covariance, ``Cov(a) = M diag(var) M^T`` with
``M = [[C, [r]x C], [0, C]]`` on ``[f_i; alpha_i]`` and ``var = [var(f_i) sum(c0^2); var(omega_i) sum(c1^2)]``
(:meth:`ImuMotion.accel_noise`): the lever arm's ``alpha x r`` carries the differentiated gyro's noise
(``var(alpha) |r|^2`` in size). Left out: measured ``dq`` and ``ddq`` add none, and ``omega x (omega x r)``
carries the gyro's smoothed noise, at most about ``2 |omega| |r| sd(omega_i) sqrt(sum(c0^2))``, against
``alpha x r``'s ``|r| sd(omega_i) sqrt(sum(c1^2))``: a share ``2 |omega| sqrt(sum(c0^2) / sum(c1^2))`` of it,
small while ``|omega|`` is well below ``sqrt(sum(c1^2) / sum(c0^2)) / 2`` (the filter's bandwidth).
"""

import copy
from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import savgol_coeffs, savgol_filter

from fmscal.plant import Log
from fmscal.plant.io import (AttitudeLog, ImuLog, JointLog, PoseTable, RobotKinematics, check_imu_units,
                             difference_noise, estimate_noise, wrench_noise)
from fmscal.plant.numerics import FmscalError
from fmscal.plant.physics import (ORDER, QUATERNION_TOLERANCE, NoiseSpec, SpatialModel, edge, quaternion_multiply,
                                  rotation_matrices, rotation_matrix, sign_continuous, smoothed_state, spatial_motion)
from fmscal.observers.batch import smoothed_channels

from ._calibrate import log_model_class

__all__ = ["PoseMotion", "JointMotion", "ImuMotion", "HeldPoses", "Motion", "MotionError", "kinematics",
           "configuration_variance", "quaternion_from_matrix", "quaternion_to_matrix"]


#: The fewest rows a log's readings' noise is estimated from (:meth:`_Source.log_noise`).
MIN_NOISE_ROWS = 20


class MotionError(FmscalError):
    """A motion source's input that cannot be used: the message names the problem."""


@dataclass
class Motion:
    """The motion of ``N`` samples, as compensation's one step takes it from any source.

    Attributes
    ----------
    x : ndarray, shape (N, nx)
        The model's state.
    a : ndarray, shape (N, nv)
        Its accelerations.
    accel_var : ndarray, shape (nv,) or (N, nv)
        The variance of the noise of ``a``: ``Cov(a) = M diag(accel_var) M^T``.
    accel_map : ndarray, shape (nv, nv), or None
        ``M``; None: the identity.
    R : ndarray, shape (N, 3, 3), or None
        The sensor's attitude where the source gives it apart from ``x`` (an IMU's, NaN where none); None:
        read from ``x``'s unit quaternion (only an output in the base's axes reads it, (C8)).
    W_p, A_inv : ndarray, shape (N, n_w) and (N, n_w, nv), or None
        The payload's wrench and ``A(x)^-1`` of (C2), where the source evaluated the dynamics with its
        kinematics (one compiled call for a streamed pose); None: the step evaluates them.
    """

    x: np.ndarray
    a: np.ndarray
    accel_var: np.ndarray
    accel_map: np.ndarray = None
    R: np.ndarray = None
    W_p: np.ndarray = None
    A_inv: np.ndarray = None


# --- helpers every source shares -------------------------------------------------------------------------------
def quaternion_from_matrix(R):
    """Unit quaternions ``(qw, qx, qy, qz)``, ``qw >= 0``, of rotation matrices ``R`` (N, 3, 3)."""
    R = np.asarray(R, dtype=float)
    m00, m11, m22 = R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]
    q = np.empty((len(R), 4))
    q[:, 0] = np.sqrt(np.maximum(0.0, 1 + m00 + m11 + m22)) / 2
    q[:, 1] = np.copysign(np.sqrt(np.maximum(0.0, 1 + m00 - m11 - m22)) / 2, R[:, 2, 1] - R[:, 1, 2])
    q[:, 2] = np.copysign(np.sqrt(np.maximum(0.0, 1 - m00 + m11 - m22)) / 2, R[:, 0, 2] - R[:, 2, 0])
    q[:, 3] = np.copysign(np.sqrt(np.maximum(0.0, 1 - m00 - m11 + m22)) / 2, R[:, 1, 0] - R[:, 0, 1])
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def quaternion_to_matrix(q):
    """``R(q)`` of a unit quaternion ``(qw, qx, qy, qz)``, shape (3, 3)."""
    return np.asarray(rotation_matrix(np.asarray(q, dtype=float) / np.linalg.norm(q)), dtype=float)


def kinematics(model, p0, p1, p2):
    """The configuration, velocities and accelerations from the smoothed pose and its first two derivatives:
    columns ``(n_pose, N)`` of numbers, or casadi column vectors (the log's pose order). A unit quaternion's
    rates give ``omega``, ``alpha`` (module docstring); a configuration that moves additively is the pose
    itself. Written once for numbers and casadi alike."""
    if model.attitude != "quaternion":
        return p0, p1, p2
    symbolic = isinstance(p0, (ca.SX, ca.MX))
    cat = ca.vertcat if symbolic else (lambda *rows: np.concatenate(rows, axis=0))
    norm = (p0[0] ** 2 + p0[1] ** 2 + p0[2] ** 2 + p0[3] ** 2) ** 0.5
    q = p0[:4] / norm
    conj = cat(q[:1], -q[1:4])
    omega = 2 * quaternion_multiply(conj, p1[:4] / norm)[1:]
    alpha = 2 * quaternion_multiply(conj, p2[:4] / norm)[1:]
    return cat(p0[4:], q), cat(p1[4:], omega), cat(p2[4:], alpha)          # [p, q], from the pose [q, p]


def _state(model, P0, P1, P2):
    """The state ``x`` (N, nx) and the accelerations ``a`` (N, nv) from the smoothed poses and their first two
    derivatives (each (N, n_pose), the log's pose order): :func:`kinematics` row by row."""
    configuration, velocity, acceleration = (v.T for v in kinematics(model, P0.T, P1.T, P2.T))
    return _packed(model, configuration, velocity), acceleration


def _packed(model, configuration, velocity):
    """The state ``x`` (N, nx) of rows of the configuration and velocity, as the model lays it out."""
    x = np.empty((len(configuration), model.nx))
    x[:, list(model.q_index)] = configuration
    x[:, list(model.v_index)] = velocity
    return x


def configuration_variance(model, noise, pose):
    """The variance of each velocity-space component of the configuration a pose of noise ``noise`` measures
    (``nv``): each pose column's noise (:meth:`fmscal.plant.Model.pose_sd`) moved into the configuration's
    tangent space by :meth:`fmscal.plant.Model.difference` at ``pose``."""
    sd = np.asarray(model.pose_sd(noise), dtype=float)
    pose = np.asarray(pose, dtype=float)
    q0 = np.asarray(model.pose_configuration(pose), dtype=float).ravel()
    var = np.zeros(model.nv)
    for j in range(model.n_pose):
        moved = pose.copy()
        moved[j] += sd[j]
        var += np.asarray(model.difference(q0, np.asarray(model.pose_configuration(moved), dtype=float).ravel()),
                          dtype=float).ravel() ** 2
    return var


def _cross(a, b):
    """Row-wise cross product of (N, 3) arrays (np.cross's overhead is large for a few rows)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def _check_spatial(model, who):
    if model.attitude != "quaternion":
        raise MotionError(f"{who} gives a motion in 3D: the calibration is of a {model.name} reading")


def _vector(value, n, name, finite=True):
    """``value`` as (n,) floats, or a one-line error."""
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise MotionError(f"{name} must be {n} numbers; got {value!r}"[:200]) from None
    if v.shape != (n,):
        raise MotionError(f"{name} must be {n} numbers; got shape {v.shape}")
    if finite and not np.isfinite(v).all():
        raise MotionError(f"{name} must be finite; got {v}")
    return v


def _rows(value, m, n, name):
    """``value`` as (m, n) floats (NaN rows: not given), or a one-line error; None stays None. One sample may come
    as its (n,) numbers."""
    if value is None:
        return None
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise MotionError(f"{name} must be numbers; got {value!r}"[:200]) from None
    if m == 1 and v.ndim <= 1:
        if v.shape != (n,):
            raise MotionError(f"{name} must be {n} numbers; got shape {v.shape}")
        return v[None]
    if v.shape != (m, n):
        raise MotionError(f"{name} must be {m} row(s) of {n} numbers, one per reading; got shape {v.shape}")
    return v


def _latency(value):
    """A stream's latency, s: a finite number of either sign, or a one-line error."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
            or not np.isfinite(value):
        raise MotionError(f"latency must be a finite number of seconds (either sign); got {value!r}"[:200])
    return float(value)


def _linear(t, t0, v0, t1, v1):
    """Linear interpolation of arrays (or None) at ``t`` between ``(t0, v0)`` and ``(t1, v1)``."""
    if v0 is None or v1 is None:
        return None
    u = 0.0 if t1 == t0 else (t - t0) / (t1 - t0)
    return (1 - u) * v0 + u * v1


def _fill(t, values):
    """Rows of NaN (no sample) between the first and the last sample filled by a cubic spline through the
    samples (twice differentiable, unlike a linear interpolation)."""
    present = np.isfinite(values).all(axis=1)
    if present.all():
        return values
    return CubicSpline(t[present], values[present], axis=0)(t)


def _filled_orientation(t, q):
    """An IMU's orientations (N, 4) at every row: the rows without a sample (a stream sparser than the readings)
    interpolated between their neighbours' (sign-continuous, normalised: SLERP to second order in the turn between
    two samples); NaN before the first and after the last sample. Only the output in the base's axes reads them
    (C8)."""
    q = sign_continuous(q)
    present = np.flatnonzero(np.isfinite(q).all(axis=1))
    if len(present) < 2 or len(present) == len(q):
        return q
    missing = np.flatnonzero(~np.isfinite(q).all(axis=1))
    for c in range(4):
        q[missing, c] = np.interp(t[missing], t[present], q[present, c], left=np.nan, right=np.nan)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _moved(log, latency, columns, orientation=None):
    """A joint or IMU log with its stream moved onto the readings' times: the sample given with the reading at
    ``t_j`` is as of ``t_j - latency``; it goes to the row nearest that time (``round(latency / dt)`` rows back), its
    value there the stream's at the row's time, interpolated linearly between its samples (an orientation made
    sign-continuous first and normalised after: SLERP to second order in the turn between two samples). A stream
    sparser than the readings stays as sparse, its rows between samples empty as with no latency: filled, its
    noise, estimated from its samples' differences, would vanish from the covariance. NaN where the stream does not
    reach. ``columns`` the attributes moved; ``orientation`` the attribute holding a quaternion. The log itself is
    not changed."""
    if latency == 0:
        return log
    moved = copy.copy(log)
    shift = int(round(latency / log.dt))     # the rows a sample moves by (the log evenly sampled), as causally
    reach = 1e-9 * log.dt

    def at(values):
        if values is None:
            return None
        present = np.flatnonzero(np.isfinite(values).all(axis=1))
        out = np.full(values.shape, np.nan)
        if len(present) < 2:
            return out
        taken = log.t[present] - latency
        rows = present - shift
        rows = rows[(rows >= 0) & (rows < len(log.t))]
        rows = rows[(log.t[rows] >= taken[0] - reach) & (log.t[rows] <= taken[-1] + reach)]
        for c in range(values.shape[1]):
            out[rows, c] = np.interp(log.t[rows], taken, values[present, c])
        return out
    for name in columns:
        setattr(moved, name, at(getattr(log, name)))
    if orientation is not None:
        q = at(sign_continuous(getattr(log, orientation)))
        setattr(moved, orientation, q / np.linalg.norm(q, axis=1, keepdims=True))
    return moved


@dataclass
class _Smoothed:
    """A source's channels over a log smoothed both ways: the rows kept (``keep``), the value and its two
    derivatives there (``P``, 3 x (N, n)), the filter's ``sum(c_d^2)`` per derivative (``sums``, times the
    samples' spacing ``r``) and the channels' noise variance (``var``)."""

    keep: slice
    P: list
    sums: list
    var: np.ndarray


def _smoothed(log, raw, window, source):
    """A joint or IMU log's channels ``raw`` (N, n; NaN rows where no sample) smoothed and differentiated both
    ways by the pose path's filter (a polynomial of degree :data:`fmscal.plant.physics.ORDER` over ``window``
    s), the rows before the first sample and after the last one dropped, the missing rows between filled by a
    cubic spline; the noise by :func:`fmscal.plant.io.difference_noise` over the samples, the filter's sums
    times the samples' spacing (a sample every ``r`` rows weighs about ``r`` times a row's share of the filter,
    as the pose path's)."""
    dt = log.dt
    h = edge(log, window)                                               # the pose path's window, checked
    k = 2 * h + 1
    present = np.flatnonzero(np.isfinite(raw).all(axis=1))
    if len(present) < 4:
        moved = (f" once moved by its latency ({source.latency:g} s; the log spans {log.t[-1] - log.t[0]:g} s)"
                 if source.latency else "")
        raise MotionError(f"{log.name}: fewer than four samples of the {source.source}{moved}")
    first, last = present[0], present[-1] + 1           # the rows before the first sample and after the last dropped
    if last - first < k + 1:
        raise MotionError(f"{log.name}: {last - first} samples with the {source.source}; the smoothing window "
                          f"{window:g} s needs more than {k}")
    filled = _fill(log.t[first:last], raw[first:last])
    smooth = [savgol_filter(filled, k, ORDER, deriv=d, delta=dt, axis=0, mode="interp") for d in range(3)]
    smooth = [np.concatenate([np.full((first, v.shape[1]), np.nan), v]) for v in smooth]
    r = max(float(np.median(np.diff(present))), 1.0)
    sums = [float(np.sum(savgol_coeffs(k, ORDER, deriv=d, delta=dt, use="dot") ** 2)) * r for d in range(3)]
    keep = slice(first + h, last - h)
    return _Smoothed(keep, [v[keep] for v in smooth], sums, difference_noise(raw, present) ** 2)


# --- the sources ------------------------------------------------------------------------------------------------
class _Source:
    """What every motion source shares (module docstring): its name, its push keyword, its log's type, its
    latency; the channels' sign continuity and the node's hooks default to none."""

    #: The source in words, for messages.
    source = ""
    #: :meth:`fmscal.analysis.Compensator.push`'s keyword for its samples.
    keyword = ""
    #: The log it compensates offline.
    log_type = None
    #: The samples move (False: held poses, whose motion and its noise are none).
    moves = True
    #: Its channels' noise is estimated from their differences as they come (True), or given by the noise
    #: model (False: poses, :class:`fmscal.plant.NoiseSpec`).
    estimates_noise = True

    def quaternion(self, model):
        """The channels holding a unit quaternion, kept sign-continuous as they come; None where none."""
        return None

    def check_log(self, log):
        """``log`` of :attr:`log_type`, or a one-line error; the model class its columns give (None: any)."""
        if not isinstance(log, self.log_type):
            raise MotionError(f"a {type(self).__name__} takes a plant.io.{self.log_type.__name__}; got "
                              f"{type(log).__name__}")
        return None

    def check_units(self, rows):
        """A first window of channels (rows) in the units the source takes, or a one-line error."""

    def pose_log(self, log):
        """The sensor's tracked poses with ``log``'s readings, for the unit checks ``identify-payload`` runs
        (:func:`fmscal.plant.io.check_spatial_log_units`): a spatial :class:`fmscal.plant.Log`, a pose table,
        or None where the source gives no pose (an IMU; a planar log)."""
        return None

    def times(self, log):
        """The rows' times, s (a table's: its row numbers)."""
        return log.t

    def log_noise(self, log):
        """The readings' noise model estimated from a log (:func:`fmscal.plant.io.wrench_noise`, the estimate
        :func:`fmscal.plant.io.estimate_noise` takes of the readings: their correlation in time too)."""
        if len(log.t) < MIN_NOISE_ROWS:
            raise MotionError(f"{log.name}: {len(log.t)} rows are too few to estimate the readings' noise from (at "
                              f"least {MIN_NOISE_ROWS}): give a longer log, or noise=plant.NoiseSpec(...)")
        sd, tau = wrench_noise(log.w_hat, float(np.median(np.diff(log.t))))
        noise = NoiseSpec(sd, wrench_tau=tau)
        if min(noise.wrench_sd) <= 0:
            raise MotionError(f"{log.name}: the readings' noise estimated from the log is zero (a constant or "
                              "coarsely quantised reading): give noise=plant.NoiseSpec(...), or a calibration "
                              "holding its noise")
        return noise

    def aligned(self, log):
        """``log`` with the stream moved onto the readings' times by :attr:`latency` (module docstring)."""
        raise NotImplementedError

    #: A sensor turned on the tracked frame (a payload file's mounting) is followed through the frame's motion: poses
    #: and joint states give the tracked frame's; an IMU gives its own axes (its rotation), so it does not.
    turns_with_mounting = True
    #: For ``~/identify_payload``: a reading without a motion sample ends the held stretch (True), or is only
    #: skipped (False: an IMU's held segments are found by their attitudes, not by a continuous stretch).
    breaks_hold = True

    def angle_columns(self, model):
        """The channels that are angles a publisher may wrap (the node unwraps them, eq. U1); none by default."""
        return []

    def held(self, value):
        """What ``~/identify_payload`` holds of a sample ``value`` (as :meth:`interpolate` gives it); None:
        nothing to hold (an IMU without an orientation)."""
        raise NotImplementedError


class PoseMotion(_Source):
    """The motion from the sensor frame's poses: the default source (``motion=None``).

    Parameters
    ----------
    latency : float, optional
        s, either sign: the pose given with the reading at ``t`` was taken at ``t - latency`` (module docstring,
        Latency); default None, the calibration's (its pose stream's).
    """

    source = "poses"
    keyword = "pose"
    log_type = Log
    estimates_noise = False

    def __init__(self, latency=None):
        self.latency = None if latency is None else _latency(latency)

    def __repr__(self):
        return f"PoseMotion(latency={self.latency!r})"

    def check(self, model):
        """Every model has poses."""

    def channels(self, model):
        return model.n_pose

    def quaternion(self, model):
        return slice(0, 4) if model.attitude == "quaternion" else None

    def check_log(self, log):
        if not isinstance(log, Log):
            raise MotionError(f"compensate takes a plant.Log; got {type(log).__name__}")
        return log_model_class(log)

    def log_noise(self, log):
        """The noise model estimated from a pose log (:func:`fmscal.plant.io.estimate_noise`)."""
        return estimate_noise(log)

    def of_log(self, log):
        """What :meth:`fmscal.analysis.Compensator.push_many` takes of a log: its poses."""
        return log.pose

    def pose_log(self, log):
        return log if np.shape(log.pose)[1:] == (7,) else None

    def samples(self, value, m, model):
        """``(channels (m, n_pose), None)``: a push's ``pose`` rows, NaN rows where none came (or any is not
        finite)."""
        if value is None:
            return np.full((m, model.n_pose), np.nan), None
        pose = _rows(value, m, model.n_pose, "pose")
        finite = np.isfinite(pose).all(axis=1)
        turn = self.quaternion(model)
        if turn is not None:             # a tracker that lost its target sends no pose (NaN), not a zero quaternion
            norm = np.linalg.norm(pose[:, turn], axis=1)
            bad = finite & (np.abs(norm - 1) > QUATERNION_TOLERANCE)
            if bad.any():
                r = int(np.argmax(bad))
                raise MotionError(f"{'the pose' if m == 1 else f'pose row {r}'}: its quaternion (qw, qx, qy, qz) "
                                  f"has norm {norm[r]:.4g}, not 1 within {QUATERNION_TOLERANCE:g}; a pose not "
                                  "measured is None or NaN")
        return (pose if finite.all() else np.where(finite[:, None], pose, np.nan)), None

    def read_out(self, extras, rows, i0, k):
        return None

    def motion(self, model, P, sums, var, extra=None, raw=None, dynamics=None):
        """The :class:`Motion` of rows of the filtered poses ``P`` (3, N, n_pose): (C2)'s state by
        :func:`kinematics`, the noise ``var`` (the configuration's, (nv,)) times ``sums[2]``; each row through
        ``dynamics``' compiled step (kinematics and dynamics in one call) where given."""
        accel_var = var * sums[2]
        if dynamics is not None and P.shape[1] == 1:    # one row through the compiled step
            x, a, W_p, A_inv = dynamics(P[:, 0])
            return Motion(x, a, accel_var, W_p=W_p, A_inv=A_inv)
        if dynamics is not None:                        # a few rows: each through the compiled step
            x, a, W_p, A_inv = (np.concatenate(v) for v in zip(*(dynamics(P[:, i]) for i in range(P.shape[1]))))
            return Motion(x, a, accel_var, W_p=W_p, A_inv=A_inv)
        x, a = _state(model, P[0], P[1], P[2])
        return Motion(x, a, accel_var)

    def aligned(self, log):
        latency = self.latency or 0.0
        if latency == 0:
            return log
        aligned = log.shift_poses(latency)    # each pose at the time it was taken; the rows after the last dropped
        return aligned.head(int(np.flatnonzero(aligned.has_pose)[-1]) + 1)

    def offline(self, log, model, noise, window):
        """``(keep, Motion)``: the motion of the rows ``keep`` of an aligned pose log, by the filter of the
        calibration's least squares (both ways); the noise of the second derivative's filter, the poses
        interpolated onto the log's grid (a pose every ``r`` samples weighs about ``r`` times a sample's share of
        the filter, so the variance of the derivative is about ``r`` times the grid's ``sum(c2^2)``)."""
        if model.attitude == "quaternion":
            _, _, alpha, p_ddot = spatial_motion(log, window)
            x, a = smoothed_state(log, window), np.c_[p_ddot, alpha]
        else:
            x, a = _state(model, *smoothed_channels(log, model, window))
        h = edge(log, window)
        keep = slice(h, len(log) - h)
        r = float(np.median(np.diff(np.flatnonzero(log.has_pose)))) if log.has_pose.sum() > 1 else 1.0
        c2 = savgol_coeffs(2 * h + 1, ORDER, deriv=2, delta=log.dt, use="dot") * np.sqrt(max(r, 1.0))
        var = configuration_variance(model, noise, log.pose[np.argmax(log.has_pose)])
        return keep, Motion(x[keep], a[keep], var * np.sum(c2 ** 2))

    # --- the node ------------------------------------------------------------------------------------------
    def interpolate(self, model, t, t0, v0, t1, v1):
        """The pose at ``t`` between two samples: the model's :meth:`fmscal.plant.Model.interpolate_pose`."""
        return model.interpolate_pose(np.array([t]), np.array([t0, t1]), np.array([v0, v1]))[0]

    def rest(self, model):
        """A sample at rest: the identity at the origin."""
        rest = np.zeros(model.n_pose)
        if model.attitude == "quaternion":
            rest[0] = 1.0
        return rest

    def angle_columns(self, model):
        return [model.pose_names.index(n) for n in model.angle_names]

    def stack(self, values, model):
        """Samples as :meth:`interpolate` gives them (None where none) as :meth:`fmscal.analysis.Compensator.
        push_many` takes them: rows of poses, NaN where none."""
        nan = np.full(model.n_pose, np.nan)
        return np.array([nan if v is None else v for v in values])

    def held(self, value):
        return np.asarray(value, dtype=float)

    def held_log(self, t, held, w_hat):
        """The held samples as the log ``~/identify_payload`` fits."""
        return Log(t, held, w_hat, name="held")


class JointMotion(_Source):
    """The sensor frame's motion from joint states and the robot's URDF, by pinocchio (C5).

    Parameters
    ----------
    urdf : str or Path
        The robot's URDF (kinematics only).
    frame : str
        The sensor frame's name in it (its origin the sensor's point, its axes the sensor's).
    joints : sequence of str, optional
        The joints' names in the order the arrays come in; default the URDF's movable joints' order.
    latency : float
        s, either sign: the joint states given with the reading at ``t`` are as of ``t - latency`` (module
        docstring, Latency); default 0, as of the readings' times.

    Attributes
    ----------
    joints : tuple of str
        That order (a ROS node matches ``JointState.name`` to it).
    kinematics : plant.io.RobotKinematics

    Raises
    ------
    FmscalError
        pinocchio missing, a URDF it cannot read, a frame it lacks, ``joints`` not the URDF's joints.
    """

    source = "joint states"
    keyword = "joints"
    log_type = JointLog

    def __init__(self, urdf, frame, joints=None, latency=0.0):
        self.latency = _latency(latency)
        self.kinematics = RobotKinematics(urdf, frame)
        names = self.kinematics.joint_names
        if joints is None:
            joints = names
        elif isinstance(joints, str) or not all(isinstance(j, str) for j in joints):
            raise MotionError(f"joints must be a sequence of joint names; got {joints!r}"[:200])
        joints = tuple(joints)
        if sorted(joints) != sorted(names):
            raise MotionError(f"joints {', '.join(joints)[:120]} are not the URDF's {len(names)} movable joints "
                              f"({', '.join(names)[:160]})")
        self.joints = joints
        self._to_urdf = np.array([joints.index(n) for n in names])
        self.size = len(joints)

    def __repr__(self):
        return f"JointMotion({self.kinematics.frame_id}, joints={self.joints}, latency={self.latency!r})"

    def poses(self, q):
        """The frame's poses for rows of joint values in :attr:`joints` order (forward kinematics).

        Parameters
        ----------
        q : array_like, shape (N, size)

        Returns
        -------
        ndarray, shape (N, 7)
            ``[qw, qx, qy, qz, x, y, z]`` in the URDF's base frame, as a spatial log holds them.
        """
        q = np.asarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] != self.size:
            raise MotionError(f"q must be rows of {self.size} joint values; got shape {q.shape}")
        return self.kinematics.poses(q[:, self._to_urdf])

    def check(self, model):
        _check_spatial(model, "JointMotion")

    def channels(self, model):
        return self.size

    def check_log(self, log):
        super().check_log(log)
        if log.joints.shape[1] != self.size:
            raise MotionError(f"{log.name}: {log.joints.shape[1]} joint columns; the URDF has {self.size} joints")
        log.check_kinematics(self.kinematics, self.joints)             # joint angles in degrees refused
        return None

    def of_log(self, log):
        """What :meth:`fmscal.analysis.Compensator.push_many` takes of a log: ``(q, dq, ddq)``."""
        return log.joints, log.velocities, log.accelerations

    def pose_log(self, log):
        return Log(log.t, self.poses(log.joints), log.w_hat, name=log.name)

    def samples(self, value, m, model):
        """A push's ``joints=(q, dq, ddq)`` (rows, :attr:`joints` order; ``dq``/``ddq`` None where not given)
        checked: ``(q (m, n), [dq, ddq] (m, 2n))``, NaN rows where not given."""
        n = self.size
        if value is None:
            return np.full((m, n), np.nan), np.full((m, 2 * n), np.nan)
        if not (isinstance(value, (tuple, list)) and len(value) == 3):
            raise MotionError("joints must be (q, dq, ddq): arrays in JointMotion.joints order, dq and ddq None "
                              "where not given")
        q, dq, ddq = (_rows(v, m, n, name) for v, name in zip(value, ("joints' q", "joints' dq", "joints' ddq")))
        if q is None:
            return np.full((m, n), np.nan), np.full((m, 2 * n), np.nan)
        q = np.where(np.isfinite(q).all(axis=1, keepdims=True), q, np.nan)
        rates = np.full((m, 2 * n), np.nan)
        for i, v in enumerate((dq, ddq)):
            if v is not None:
                given = ~np.isnan(v).all(axis=1)
                if not np.isfinite(v[given]).all():
                    raise MotionError(f"joints' {('dq', 'ddq')[i]} must be finite where given; got {v[given]}"[:200])
                rates[given, i * n:(i + 1) * n] = v[given]
        rates[~np.isfinite(q).all(axis=1)] = np.nan                     # no joint state: no rates either
        return q, rates

    def read_out(self, extras, rows, i0, k):
        """The measured rates of the read-out rows (NaN where not given)."""
        return extras[rows]

    def motion(self, model, P, sums, var, extra=None, raw=None, dynamics=None):
        """The :class:`Motion` of rows of the filtered joint angles ``P`` (3, N, n): the measured rates where
        given (their noise none), a sample's own angles where its rates are all measured; (C5)."""
        q, dq, ddq = P[0], P[1], P[2]
        var_ddq = np.broadcast_to(var * sums[2], q.shape)
        if extra is not None:
            n = self.size
            given_dq, given_ddq = extra[:, :n], extra[:, n:]
            measured = np.isfinite(given_ddq)
            dq = np.where(np.isfinite(given_dq), given_dq, dq)
            ddq = np.where(measured, given_ddq, ddq)
            var_ddq = np.where(measured, 0.0, var_ddq)
            if raw is not None:
                whole = (np.isfinite(given_dq).all(axis=1) & measured.all(axis=1))[:, None]
                q = np.where(whole, raw, q)
        x, a, R = self.state(model, q, dq, ddq)
        return Motion(x, a, self.accel_var(q, var_ddq, R), R=R)

    def aligned(self, log):
        return _moved(log, self.latency, ("joints", "velocities", "accelerations"))

    def offline(self, log, model, noise, window):
        """``(keep, Motion)`` of an aligned joint log: its angles smoothed both ways, the measured rates where
        given."""
        s = _smoothed(log, log.joints, window, self)
        dq, ddq, var_ddq = s.P[1], s.P[2], s.var * s.sums[2]
        if log.velocities is not None:
            dq = np.where(np.isfinite(log.velocities[s.keep]), log.velocities[s.keep], dq)
        if log.accelerations is not None:
            measured = np.isfinite(log.accelerations[s.keep])
            ddq = np.where(measured, log.accelerations[s.keep], ddq)
            var_ddq = np.where(measured.all(axis=0), 0.0, var_ddq)
        x, a, R = self.state(model, s.P[0], dq, ddq)
        return s.keep, Motion(x, a, self.accel_var(s.P[0], var_ddq, R), R=R)

    def state(self, model, q, dq, ddq):
        """``(x, a, R)`` of (C5) for rows of ``q, dq, ddq`` (N, n) in :attr:`joints` order; ``R`` (N, 3, 3) the
        sensor frame's attitude."""
        order = self._to_urdf
        pose, v, omega, acc, alpha = self.kinematics.motion(np.asarray(q)[:, order], np.asarray(dq)[:, order],
                                                            np.asarray(ddq)[:, order])
        R = rotation_matrices(pose[:, :4])
        n = len(pose)
        configuration, velocity, a = np.empty((n, 7)), np.empty((n, 6)), np.empty((n, 6))
        configuration[:, :3], configuration[:, 3:] = pose[:, 4:], pose[:, :4]
        velocity[:, :3], velocity[:, 3:] = np.einsum("nij,nj->ni", R, v), omega
        a[:, :3], a[:, 3:] = np.einsum("nij,nj->ni", R, acc), alpha
        return _packed(model, configuration, velocity), a, R

    def accel_var(self, q, var_ddq, R):
        """The variance of ``a = [p_ddot; alpha]`` a joint noise of ``var_ddq`` in ``ddq`` gives, row by row.

        ``var(a_l) = (J_v o J_v) var(ddq)``, ``var(alpha) = (J_omega o J_omega) var(ddq)`` at each row's ``J``
        and ``var(p_ddot) = (R o R) var(a_l)`` at its ``R`` (module's Noise).

        Parameters
        ----------
        q : array_like, shape (N, n)
            Joint values in :attr:`joints` order.
        var_ddq : array_like, shape (n,) or (N, n)
        R : array_like, shape (N, 3, 3)
            The sensor frame's attitudes.

        Returns
        -------
        ndarray, shape (N, 6)
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))[:, self._to_urdf]
        var_ddq = np.broadcast_to(np.asarray(var_ddq, dtype=float), q.shape)[:, self._to_urdf]
        J = self.kinematics.jacobian(q)                                     # (N, 6, n)
        var = np.einsum("nij,nj->ni", J ** 2, var_ddq)
        return np.c_[np.einsum("nij,nj->ni", np.asarray(R, dtype=float) ** 2, var[:, :3]), var[:, 3:]]

    # --- the node ------------------------------------------------------------------------------------------
    def interpolate(self, model, t, t0, v0, t1, v1):
        """``(q, dq, ddq)`` at ``t``, each linearly (None where not given)."""
        return tuple(_linear(t, t0, a, t1, b) for a, b in zip(v0, v1))

    def rest(self, model):
        return np.zeros(self.size), None, None

    def stack(self, values, model):
        """Samples ``(q, dq, ddq)`` (None where none; a rate None where not given) as :meth:`fmscal.analysis.
        Compensator.push_many` takes them: three arrays of rows, NaN where not given."""
        nan = np.full(self.size, np.nan)
        return tuple(np.array([nan if v is None or v[i] is None else v[i] for v in values]) for i in range(3))

    def held(self, value):
        return np.asarray(value[0], dtype=float)

    def held_log(self, t, held, w_hat):
        """The held joint angles' poses (the sensor frame's, in the URDF's base frame) as a log."""
        return Log(t, self.poses(held), w_hat, name="held")


class ImuMotion(_Source):
    """The sensor's motion from an IMU on the tool (C6, C7): no pose and no gravity vector needed.

    Parameters
    ----------
    rotation : array_like, shape (3, 3), optional
        The IMU's axes in the sensor's: ``v_sensor = rotation @ v_imu``; default identity.
    lever_arm : array_like, shape (3,), optional
        The IMU's point from the sensor's point, in the sensor's axes, m; default zero.
    latency : float
        s, either sign: the IMU's sample given with the reading at ``t`` is as of ``t - latency`` (module
        docstring, Latency); default 0, as of the readings' times.

    Raises
    ------
    FmscalError
        Not a rotation matrix, or not three finite numbers.
    """

    source = "IMU"
    keyword = "imu"
    log_type = ImuLog
    size = 6                         # the channels filtered: the IMU's angular velocity and specific force

    def __init__(self, rotation=None, lever_arm=None, latency=0.0):
        self.latency = _latency(latency)
        C = np.eye(3) if rotation is None else np.asarray(rotation, dtype=float)
        if C.shape != (3, 3) or not np.isfinite(C).all():
            raise MotionError(f"the IMU's rotation must be a 3x3 matrix; got shape {C.shape}")
        if np.abs(C @ C.T - np.eye(3)).max() > 1e-6 or np.linalg.det(C) < 0:
            raise MotionError("the IMU's rotation must be a proper rotation matrix (C C^T = I, det +1): the IMU's "
                              "axes in the sensor's, v_sensor = C v_imu")
        self.rotation = C
        self.lever_arm = np.zeros(3) if lever_arm is None else _vector(lever_arm, 3, "the IMU's lever arm")

    def __repr__(self):
        return (f"ImuMotion(rotation={self.rotation.tolist()}, lever_arm={self.lever_arm.tolist()}, "
                f"latency={self.latency!r})")

    def check(self, model):
        _check_spatial(model, "ImuMotion")

    def channels(self, model):
        return self.size

    def of_log(self, log):
        """What :meth:`fmscal.analysis.Compensator.push_many` takes of a log: ``(quaternion, rate, force)``."""
        return log.orientation, log.angular_velocity, log.specific_force

    def check_units(self, rows):
        check_imu_units("the IMU stream", rows[:, :3], rows[:, 3:])          # in g or deg/s: one line

    def samples(self, value, m, model):
        """A push's ``imu=(quaternion_wxyz, angular_velocity, specific_force)`` (rows, the IMU's axes; the
        quaternion None where the IMU gives none) checked: ``([omega_i, f_i] (m, 6), quaternion (m, 4))``, NaN
        rows where not given."""
        if value is None:
            return np.full((m, 6), np.nan), np.full((m, 4), np.nan)
        if not (isinstance(value, (tuple, list)) and len(value) == 3):
            raise MotionError("imu must be (quaternion_wxyz, angular_velocity, specific_force), the IMU's axes")
        quaternion, omega, force = (_rows(v, m, n, name) for v, n, name in
                                    zip(value, (4, 3, 3), ("the IMU's quaternion", "the IMU's angular velocity",
                                                          "the IMU's specific force")))
        if omega is None or force is None:
            return np.full((m, 6), np.nan), np.full((m, 4), np.nan)
        channels = np.c_[omega, force]
        given = ~np.isnan(channels).all(axis=1)
        if not np.isfinite(channels[given]).all():
            raise MotionError("the IMU's angular velocity and specific force must be finite where given")
        channels[~given] = np.nan
        q = np.full((m, 4), np.nan) if quaternion is None else quaternion.copy()
        oriented = np.isfinite(q).all(axis=1)
        q[~oriented] = np.nan
        norm = np.linalg.norm(q[oriented], axis=1)
        if (np.abs(norm - 1) > 1e-3).any():
            raise MotionError(f"the IMU's quaternion must be a unit quaternion, scalar first; got norm "
                              f"{norm[np.argmax(np.abs(norm - 1))]:.4g}")
        return channels, q

    def read_out(self, extras, rows, i0, k):
        """The orientation of each read-out row ``rows`` of ``extras``, or where it has none the nearest one in
        the row's window (``k`` rows from ``row - i0``); NaN where the window holds none."""
        out = extras[rows].copy()
        for j in np.flatnonzero(~np.isfinite(out).all(axis=1)):
            lo = int(rows[j]) - i0
            window = [i for i in range(max(lo, 0), min(lo + k, len(extras))) if np.isfinite(extras[i]).all()]
            if window:
                out[j] = extras[min(window, key=lambda i: abs(i - int(rows[j])))]
        return out

    def sensor_motion(self, omega_i, domega_i, f_i):
        """(C6): ``omega``, ``alpha`` and ``f_s`` at the sensor's point, its axes, from rows (N, 3) of the IMU's
        angular velocity, its derivative and its specific force."""
        C, r = self.rotation, self.lever_arm[None]
        omega, alpha = np.asarray(omega_i) @ C.T, np.asarray(domega_i) @ C.T
        f_s = np.asarray(f_i) @ C.T - (_cross(alpha, r) + _cross(omega, _cross(omega, r)))
        return omega, alpha, f_s

    def motion(self, model, P, sums, var, extra=None, raw=None, dynamics=None):
        """The :class:`Motion` of rows of the filtered ``[omega_i, f_i]`` ``P`` (3, N, 6) and the orientations
        ``extra`` (N, 4): (C6), (C7), ``Cov(a)`` by :meth:`accel_noise`."""
        x, a, R = self.state(model, P[0], P[1], extra)
        M, accel_var = self.accel_noise(var, sums[0], sums[1])
        return Motion(x, a, accel_var, accel_map=M, R=R)

    def aligned(self, log):
        return _moved(log, self.latency, ("angular_velocity", "specific_force"), "orientation")

    def offline(self, log, model, noise, window):
        """``(keep, Motion)`` of an aligned IMU log: its rate and specific force smoothed both ways; the
        orientation filled between samples (for the base's axes)."""
        s = _smoothed(log, np.c_[log.angular_velocity, log.specific_force], window, self)
        x, a, R = self.state(model, s.P[0], s.P[1], _filled_orientation(log.t, log.orientation)[s.keep])
        M, accel_var = self.accel_noise(s.var, s.sums[0], s.sums[1])
        return s.keep, Motion(x, a, accel_var, accel_map=M, R=R)

    def state(self, model, channels, d1, orientation):
        """``(x, a, R)`` of (C7) for rows of the filtered channels ``[omega_i, f_i]`` (N, 6), their derivatives
        and the IMU's orientations (N, 4; NaN rows where none): ``R`` the sensor frame's attitude in the IMU's
        world (NaN where no orientation)."""
        omega, alpha, f_s = self.sensor_motion(channels[:, :3], d1[:, :3], channels[:, 3:])
        n = len(channels)
        configuration, velocity = np.zeros((n, 7)), np.zeros((n, 6))
        configuration[:, 3] = 1.0                                           # [p, q] = [0, (1, 0, 0, 0)]
        velocity[:, 3:] = omega
        a = np.empty((n, 6))
        a[:, :3] = f_s + np.asarray(model.gravity, dtype=float)
        a[:, 3:] = alpha
        R = np.full((n, 3, 3), np.nan)
        orientation = np.full((n, 4), np.nan) if orientation is None else np.asarray(orientation, dtype=float)
        given = np.isfinite(orientation).all(axis=1)
        if given.any():
            q = orientation[given] / np.linalg.norm(orientation[given], axis=1, keepdims=True)
            R[given] = rotation_matrices(q) @ self.rotation.T
        return _packed(model, configuration, velocity), a, R

    def accel_noise(self, var_channels, c0_sq, c1_sq):
        """The covariance of ``a = [f_s + g; alpha]`` (sensor axes) from the channels' noise variance (6,) or
        (N, 6), as ``Cov(a) = M diag(var) M^T``.

        With ``alpha_i`` the differentiated rate in the IMU's axes, (C6) is linear in the filtered channels'
        noise: ``alpha = C alpha_i`` and ``f_s = C f_i + [r]x C alpha_i`` (``-alpha x r = r x alpha``, ``[r]x``
        the cross-product matrix), so ``M = [[C, [r]x C], [0, C]]`` on ``[f_i; alpha_i]`` and
        ``var = [var(f_i) sum(c0^2); var(omega_i) sum(c1^2)]``: the lever arm's ``alpha x r`` carries the
        differentiated gyro's noise (``var(alpha) |r|^2`` in size), correlated with ``alpha``'s own.

        Returns
        -------
        M : ndarray, shape (6, 6)
        var : ndarray, shape (6,) or (N, 6)
        """
        C = self.rotation
        x, y, z = self.lever_arm
        skew = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
        M = np.zeros((6, 6))
        M[:3, :3], M[:3, 3:], M[3:, 3:] = C, skew @ C, C
        v = np.asarray(var_channels, dtype=float)
        return M, np.concatenate([v[..., 3:] * c0_sq, v[..., :3] * c1_sq], axis=-1)

    # --- the node ------------------------------------------------------------------------------------------
    def interpolate(self, model, t, t0, v0, t1, v1):
        """``(quaternion, rate, specific force)`` at ``t``: the orientation by SLERP, the rate and the specific
        force linearly (the orientation None where the IMU gives none)."""
        if v0[0] is None or v1[0] is None:                  # an IMU that gives no orientation
            return None, _linear(t, t0, v0[1], t1, v1[1]), _linear(t, t0, v0[2], t1, v1[2])
        q = SpatialModel.interpolate_pose(np.array([t]), np.array([t0, t1]),     # SLERP, the rate linearly
                                          np.array([np.r_[v0[0], v0[1]], np.r_[v1[0], v1[1]]]))[0]
        return q[:4], q[4:], _linear(t, t0, v0[2], t1, v1[2])

    def rest(self, model):
        return np.array([1.0, 0, 0, 0]), np.zeros(3), np.array([0, 0, 9.81])

    breaks_hold = False
    turns_with_mounting = False

    def stack(self, values, model):
        """Samples ``(quaternion, rate, specific force)`` (None where none; the quaternion None where the IMU
        gives none) as :meth:`fmscal.analysis.Compensator.push_many` takes them: rows, NaN where not given."""
        sizes = (4, 3, 3)
        return tuple(np.array([np.full(n, np.nan) if v is None or v[i] is None else v[i] for v in values])
                     for i, n in enumerate(sizes))

    def held(self, value):
        """The IMU's orientation (None where it gives none: nothing to hold)."""
        return None if value[0] is None else np.asarray(value[0], dtype=float)

    def held_log(self, t, held, w_hat):
        """The held orientations turned into the sensor's attitudes, ``R_S = R_IMU C^T``, as an attitude-only
        log (its held segments fitted statically)."""
        q = quaternion_from_matrix(rotation_matrices(held) @ self.rotation.T)
        return AttitudeLog(t, q, w_hat, name="the held IMU samples")


class HeldPoses(_Source):
    """A pose table's held attitudes (:class:`fmscal.plant.io.PoseTable`): no motion, the payload's static wrench
    at each row; the check after identifying a tool (a few new poses: does the tool vanish to the noise?). Offline
    only; a row's "time" is its number."""

    source = "held poses"
    keyword = "pose"
    log_type = PoseTable
    moves = False

    def check(self, model):
        _check_spatial(model, "a pose table")

    def channels(self, model):
        return model.n_pose

    def times(self, log):
        return np.arange(len(log.w_hat), dtype=float)

    def log_noise(self, log):
        """The rows' noise: the table's standard errors where it holds them (an attitude-only log's held
        segments), their median per channel; a table of averaged readings holds none."""
        if log.noise is None:
            raise MotionError(f"{log.name}: a pose table holds no noise of its rows: give noise=plant.NoiseSpec(...), "
                              "or a payload file (it holds the reading's noise)")
        return NoiseSpec(tuple(float(v) for v in np.median(log.noise, axis=0)))

    def aligned(self, log):
        return log

    def pose_log(self, log):
        return log

    def offline(self, log, model, noise, window):
        """``(every row, Motion)``: each held attitude at rest, its noise none."""
        n = len(log.w_hat)
        configuration = np.zeros((n, 7))
        configuration[:, 3:] = log.q
        x = _packed(model, configuration, np.zeros((n, 6)))
        return slice(None), Motion(x, np.zeros((n, model.nv)), np.zeros(model.nv))


def source(motion, latency=0.0, log=None):
    """The source a compensation takes: ``motion`` itself, or a :class:`PoseMotion` of ``latency`` (the
    calibration's) where None (:class:`HeldPoses` for a pose table); a pose source without its own latency takes
    ``latency``."""
    if motion is None and isinstance(log, PoseTable):
        return HeldPoses()
    if motion is None:
        return PoseMotion(latency)
    if not isinstance(motion, (PoseMotion, JointMotion, ImuMotion, HeldPoses)):
        raise MotionError(f"motion must be None (poses), a PoseMotion, a JointMotion, an ImuMotion or HeldPoses; "
                          f"got {type(motion).__name__}")
    if isinstance(motion, PoseMotion) and motion.latency is None:
        return PoseMotion(latency)
    return motion
