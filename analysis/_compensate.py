"""Compensation: the wrench the environment applies to the tool, the payload's gravity and inertia removed.

With the calibrated reading ``w_s = S (sigma w_hat - b)`` (the wrench the mount applies to the payload,
:class:`fmscal.plant.Calibration`) and ``W_p`` the wrench the payload's motion needs at the sensor point
under gravity, the environment's wrench on the tool, at the sensor point and in the sensor's axes, is::

    w_e = W_p - w_s                                                                              (C1)

(``w_s + w_e = W_p``: the mount and the environment together drive the payload). Its negative,
``w_s - W_p``, is the wrench the tool applies to the environment, which force control often wants:
``direction="on_environment"`` publishes it; the default, ``"on_tool"``, publishes ``w_e``.

``W_p`` is the model's own dynamics inverted: a model declares ``a = A(x) w + d(x)``
(:class:`fmscal.plant.Model`; Newton-Euler at the sensor point in 3D, eq. (1) in the plane), so::

    W_p = A(x)^-1 (a - d(x))                                                                     (C2)

with the state ``x`` and the accelerations ``a`` from the measured poses. The same code runs on every model.

The motion comes from the poses, smoothed and differentiated by a Savitzky-Golay filter:

- **offline** (``causal=False``) both ways, by the filter calibration's least squares uses
  (:func:`fmscal.plant.physics.spatial_motion`, :func:`fmscal.observers.batch.smoothed_channels`): no delay;
- **causal** (``causal=True``, and :class:`Compensator`, one sample at a time): a polynomial of degree
  ``order`` fitted to the last ``window`` s of poses and read ``delay`` s before the newest sample. The
  output at the newest sample is the wrench of the reading taken ``delay`` s earlier: the reading is delayed
  alike, so that the reading and the motion are of one time. :attr:`Compensator.delay` states it.

A unit quaternion's rates give the angular velocity and acceleration in the sensor's axes,
``omega = 2 vec(q* (x) q')``, ``alpha = 2 vec(q* (x) q'')``.

Two more sources of the motion (``motion=``, :mod:`fmscal.analysis._motion`): joint states with the robot's
URDF (:class:`JointMotion`: pinocchio's frame velocity and *classical* acceleration, (C5)) and an IMU on the
tool (:class:`ImuMotion`: its specific force moved to the sensor's point, (C6), read at ``R = I`` so that no
pose and no gravity vector is needed, (C7)). Their channels (the joint angles; the IMU's rate and specific
force) go through the same filters as poses, offline both ways and causally with the same stated delay; only
the accelerations the source does not measure are differentiated. Their streams are as of the readings'
times unless the source's own ``latency`` says how late they are (``JointMotion(..., latency=)``,
``ImuMotion(..., latency=)``): it is applied where the poses' is (offline the stream interpolated onto the
readings' times, causally the filter read that much nearer its newest sample); the calibration's latency is its
pose stream's and is not applied to them.

**The output's axes and point** (``frame``, ``point``). With ``r_t`` the tool point (sensor axes, from the
sensor's point) and ``R`` the sensor's attitude (``frame="base"``), the published wrench and its covariance
are moved by one linear map::

    M = blockdiag(R, R) [[I, -[r_t]x], [0, I]],    w -> M w,    Cov -> M Cov M^T                   (C8)

(the force unchanged by the point, the torque about the tool ``tau_t = tau_s - r_t x f``). The contact test
(C4) is the same in any axes and point (``M`` is invertible), and the offset's tracker runs in the sensor's.

The covariance of ``w_e`` per sample is the sum of three independent parts::

    Cov = S Sigma_r S^T + J cov J^T + A^-1 Sigma_a A^-T                                           (C3)

``Sigma_r`` the reading's noise (``diag(wrench_sd^2)``, the calibration's noise model or the log's,
:func:`fmscal.plant.io.estimate_noise`); ``cov`` the calibration's covariance of ``vec([S | c])`` (row
order), ``J = I (x) [sigma w_hat; 1]^T`` (``I (x) (sigma w_hat - b)^T`` where ``cov`` is of ``S`` alone;
entries the data left undetermined, infinite in ``cov``, are left out and a warning says so); and
``Sigma_a`` the accelerations' noise, the pose's noise through the second-derivative filter
(``var(a_j) = var(q_j) sum(c_k^2)``, ``c`` the filter's coefficients; offline, poses sparser than the
readings are interpolated onto the readings' grid first, and the sum is taken times the number of samples
between poses). The differentiated velocity's noise and the filter's bias are not counted.

A sample is a contact where the compensated wrench is beyond its noise: its normalised squared norm
``d^2 = w_e^T Cov^-1 w_e`` above the chi-square quantile of ``n_w`` degrees of freedom (6 in 3D) at
``1 - false_alarm``                                                                          (C4)

**The offset's drift** (``track_offset=True``). The offset is a random walk, one per reading channel::

    b_k = b_{k-1} + n_k,    n_k ~ N(0, diag(q^2) (t_k - t_{k-1}))                                (D1)

``q`` the drift's intensity (units per sqrt(s); causal default :data:`DRIFT_INTENSITY` times the reading's
noise sd, offline default fitted to the log by (D5)). Each sample first predicts ``P <- P + diag(q^2) dt``; the
compensated wrench with the predicted offset, ``w_e = W_p - S (sigma w_hat - b)``, is then the innovation of the
measurement ``-w_e = S (b_true - b) + e``, with the covariance ``Cov_total = Cov + S P S^T`` (Cov of (C3)), the
covariance published::

    d^2 = w_e^T Cov_total^-1 w_e                                                                 (D2)

is the contact test (C4). Where it is within the bound (no contact), a Kalman step::

    K = P S^T Cov_total^-1,   b <- b - K w_e,   P <- (I - K S) P                                  (D3)

During a contact the offset is frozen (its sd grows by (D1)), so a contact is not taken for drift; a push
slower than the tracker's time constant is, in part: the intensity sets the trade-off
(docs/guide/compensation.md). The offset and its sd are reported per sample (after the sample's step).

The sd is the random walk's: ``P`` counts the noise's share of the estimate's error and the share a walk of
intensity ``q`` would add since the last samples, about equal where ``q^2 dt`` is small beside the noise. An
offset that moves more smoothly than such a walk (a sensor warming) leaves only the first: the error's variance
is then about half of ``P``, and the 95 % intervals cover about ``2 Phi(1.96 sqrt(2)) - 1`` (99 %) of the
samples, conservative. A smoother over the whole log (Rauch-Tung-Striebel) narrows ``P`` and the error alike and
does not change that; only an intensity matched to the drift does (``benchmarks/drift.py --why``): (D5) fits
one.

**The intensity fitted** (``drift_intensity="fit"``, offline only and its default). The intensity is
``q = s q_0``, ``q_0`` the causal default (:data:`DRIFT_INTENSITY` times the reading's noise sd, per channel)
and ``s`` the scale maximising the innovations' likelihood of (D2)::

    l(s) = -1/2 sum_k [min(d_k^2(s), chi2) + log det Cov_total,k(s)]                               (D5)

``d_k^2`` and ``Cov_total,k`` those of (D2) for a tracker run at ``s``, ``chi2`` the contact bound (C4). A
sample a tracker flags counts as at the bound (a robust likelihood: a contact is not a walk's step, and a
tracker left behind by the drift pays for each sample it flags); the samples every candidate flags (the
contacts) are left out. The trackers of the grid :data:`DRIFT_FIT_GRID` of ``s`` run in one vectorised pass
over the log (a maximum at its edge extends it by as many steps again that way, up to :data:`DRIFT_FIT_LIMITS`);
``log s`` is refined by the parabola through the best three. A maximum at the lower limit is taken there (an
offset that does not drift: the walk all but stopped); at the upper limit, with a warning.

**Tare** (:meth:`Compensator.tare`) re-biases at the newest compensated sample's pose::

    b = sigma w_hat - S^-1 W_p(pose),   P = S^-1 Cov S^-T                                          (D4)

the payload's own wrench at that pose restored, so the output does not jump beyond the noise. A sensor
zeroed by its hardware at an unknown pose reads ``-S^-1 W_p`` of that pose off; (D4) at any pose finds it.
"""

import copy
from collections import deque
from dataclasses import dataclass, field
from functools import lru_cache

import casadi as ca
import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import savgol_coeffs, savgol_filter
from scipy.stats import binom, chi2

from fmscal.plant import Calibration, Log
from fmscal.plant.io import ImuLog, JointLog, check_imu_units, difference_noise, estimate_noise, reading_sign
from fmscal.plant.numerics import FmscalError
from fmscal.plant.physics import (MODELS, ORDER, NoiseSpec, edge, quaternion_multiply, rotation_matrices, skew,
                                  smoothed_state, spatial_motion)
from fmscal.observers.batch import smoothed_channels
from fmscal.observers.payload import PayloadEstimate

from ._calibrate import log_model_class
from ._motion import ImuMotion, JointMotion

__all__ = ["compensate", "Compensation", "Compensator", "ContactSample", "compensation_model", "DIRECTIONS",
           "OFFLINE_WINDOW", "CAUSAL_WINDOW", "CAUSAL_DELAY", "CAUSAL_ORDER", "FALSE_ALARM", "DRIFT_INTENSITY",
           "FRAMES", "DRIFT_FIT_GRID", "DRIFT_FIT_LIMITS"]

#: The published wrench: the environment's on the tool (``w_e``, the default) or the tool's on the environment.
DIRECTIONS = ("on_tool", "on_environment")
#: Offline smoothing window, s (the calibration's least squares' own).
OFFLINE_WINDOW = 0.2
#: The causal filter's window, s: the poses it fits a polynomial to.
CAUSAL_WINDOW = 0.06
#: The causal filter's delay, s: each output is the wrench of the reading this much older than the newest.
CAUSAL_DELAY = 0.03
#: The causal filter's degree.
CAUSAL_ORDER = 3
#: The contact test's false-alarm probability per sample (C4).
FALSE_ALARM = 1e-3
#: The offset's random walk (D1): its default intensity per channel, per sqrt(s), in the reading's noise sd.
DRIFT_INTENSITY = 1.0
#: ``drift_intensity="fit"`` (D5): the scales of the default intensity the likelihood is evaluated at first
#: (equal steps in ``log s``), and the smallest and largest scale an extension of that grid goes to.
DRIFT_FIT_GRID = tuple(2.0 ** np.arange(-2.0, 2.01, 0.5))
DRIFT_FIT_LIMITS = (2.0 ** -8, 2.0 ** 6)
#: Tare (D4): the span of the newest compensated samples it averages, s.
TARE_WINDOW = 0.1
#: Tare's contact test: the chance that false alarms alone refuse a tare of a free tool (a binomial tail).
TARE_FALSE_REFUSAL = 1e-6
#: The output's axes (C8): the sensor's, or the base's (the world's: the pose's, the URDF's base, the IMU's world).
FRAMES = ("sensor", "base")


class CompensationError(FmscalError):
    """Input that cannot be compensated: the message names the problem."""


@dataclass
class Compensation:
    """The contact wrench of a log, per sample (module docstring).

    Attributes
    ----------
    t : ndarray, shape (N,)
        The readings' times, s (causal: the output at ``t + delay``).
    wrench : ndarray, shape (N, n_w)
        The published wrench: ``w_e`` (``direction="on_tool"``) or ``-w_e``; N m and N in the reading's order;
        in the sensor's axes at the sensor's point, or as ``frame`` and ``point`` say (C8).
    cov : ndarray, shape (N, n_w, n_w)
        Its covariance (C3), moved with it (C8).
    contact : ndarray of bool, shape (N,)
        A contact beyond the noise (C4).
    statistic : ndarray, shape (N,)
        ``d^2``, the normalised squared norm of the wrench.
    threshold : float
        The chi-square bound ``d^2`` is compared with.
    names : tuple of str
        The wrench's components (the model's).
    delay : float
        s: what the causal filter adds (0 offline).
    direction : str
        One of :data:`DIRECTIONS`.
    warnings : list of str
    offset, offset_sd : ndarray, shape (N, n_w), or None
        ``track_offset``: the offset ``b`` (the reading's units) after each sample's step (D3), and its sd;
        None otherwise.
    frame : str
        One of :data:`FRAMES`: the wrench's axes.
    point : ndarray, shape (3,), or None
        The point the torque is about (sensor axes, m, from the sensor's point); None: the sensor's point.
    drift_intensity : ndarray, shape (n_w,), or None
        ``track_offset``: the random walk's intensity used, per channel, the reading's units per sqrt(s)
        (fitted by (D5) where ``drift_intensity="fit"``); None otherwise.
    """

    t: np.ndarray
    wrench: np.ndarray
    cov: np.ndarray
    contact: np.ndarray
    statistic: np.ndarray
    threshold: float
    names: tuple
    delay: float
    direction: str
    warnings: list = field(default_factory=list)
    offset: np.ndarray = None
    offset_sd: np.ndarray = None
    frame: str = "sensor"
    point: np.ndarray = None
    drift_intensity: np.ndarray = None

    @property
    def sd(self):
        """One-sigma uncertainty of each component, shape (N, n_w)."""
        return np.sqrt(np.maximum(np.einsum("nii->ni", self.cov), 0.0))


# --- the pieces both paths share ------------------------------------------------------------------------------
def _model_class(calibration):
    """The model class whose reading ``calibration`` calibrates."""
    return next(m for m in MODELS if len(m.wrench_names) == calibration.size)


def compensation_model(calibration, payload=None, cls=None):
    """The model the payload's wrench is computed on: the calibration's case, payload and gravity.

    Parameters
    ----------
    calibration : plant.Calibration
    payload : plant.Payload or plant.SpatialPayload or observers.payload.PayloadEstimate, optional
        Replaces the calibration's (``S`` does not depend on the tool: after a tool change, the new
        tool's mass properties, e.g. ``PayloadEstimate.load("payload.json")`` of ``identify-payload``;
        refused where the estimate holds no inertia).
    cls : type, optional
        The model class a log's columns give; refused if the calibration is of another case.

    Returns
    -------
    plant.Model
    """
    if not isinstance(calibration, Calibration):
        raise CompensationError(f"compensate takes a plant.Calibration; got {type(calibration).__name__}")
    own = _model_class(calibration)
    if cls is not None and cls is not own:
        raise CompensationError(f"the calibration is of a {own.name} reading ({calibration.size}x{calibration.size} "
                                f"S); the log's columns are {cls.name}")
    payload = calibration.payload if payload is None else payload
    if payload is None:
        raise CompensationError("the calibration holds no payload: give the tool's (payload=..., or --payload)")
    if isinstance(payload, PayloadEstimate):         # in the tracked frame's axes, as calibrate takes it
        payload = payload.tracked()
        if payload.inertia is None:
            raise CompensationError("the payload estimate holds no inertia (its log did not determine it): the "
                                    "motion's wrench needs it; identify the payload from a log with more angular "
                                    "acceleration, or give a calibration that holds the tool")
        payload = own.payload_from(payload.mass, payload.inertia, payload.com)
    if not isinstance(payload, own.payload_type):
        raise CompensationError(f"a {own.name} calibration takes a plant.{own.payload_type.__name__}; "
                                f"got {type(payload).__name__}")
    if own.under_gravity and calibration.gravity is not None:
        return own(payload, calibration.gravity)
    return own(payload)


@lru_cache(maxsize=8)
def _dynamics(model):
    """``x -> (A(x), d(x))``, the model's dynamics ``a = A(x) w + d(x)``, as a casadi Function."""
    x = ca.SX.sym("x", model.nx)
    return ca.Function(f"dynamics_{model.name}", [x], [ca.densify(ca.SX(model.input_matrix(x))),
                                                       ca.densify(ca.SX(model.drift(x)))])


@lru_cache(maxsize=64)
def _mapped(model, n):
    """:func:`_dynamics` over ``n`` states at once (kept: a stream's blocks come in a few sizes)."""
    return _dynamics(model).map(n)


#: A block of at most this many rows goes through :class:`_SampleDynamics` row by row; a longer one through the
#: mapped Function at once (fewer calls, each converting casadi's matrices).
_ROW_BY_ROW = 16


@lru_cache(maxsize=8)
def _one_sample(model):
    """One sample's (C2) from its smoothed pose and two derivatives, as one casadi Function: the input
    ``[p; p'; p'']`` (3 n_pose), the output ``[x; a; A(x) (column-major); d(x)]`` (:func:`_kinematics`, then
    :func:`_dynamics`'s expressions). Evaluated through a :class:`_SampleDynamics` buffer: a streaming sample
    pays no conversion of casadi's matrices."""
    p = ca.SX.sym("p", 3 * model.n_pose)
    n = model.n_pose
    configuration, velocity, acceleration = _kinematics(model, p[:n], p[n:2 * n], p[2 * n:])
    x = ca.SX.zeros(model.nx)
    x[list(model.q_index)] = configuration
    x[list(model.v_index)] = velocity
    A, d = ca.SX(model.input_matrix(x)), ca.SX(model.drift(x))
    return ca.Function(f"one_sample_{model.name}", [p], [ca.densify(ca.vertcat(x, acceleration, ca.vec(A), d))])


def _buffered(f, inputs, outputs):
    """``f`` evaluated in place through casadi's low-overhead buffer (``Function.buffer``): ``(buffer, call)``,
    ``call()`` reading the arrays ``inputs`` and writing ``outputs`` (keep ``buffer`` alive with them)."""
    buffer, call = f.buffer()
    for i, a in enumerate(inputs):
        buffer.set_arg(i, memoryview(a))
    for i, a in enumerate(outputs):
        buffer.set_res(i, memoryview(a))
    return buffer, call


class _SampleDynamics:
    """:func:`_one_sample` (poses) and :func:`_dynamics` (a joint or IMU source's state) through casadi's
    low-overhead buffers: one sample's ``x``, ``a``, ``W_p`` and ``A^-1`` of (C2). One per :class:`Compensator`
    (the buffers' memory is its own)."""

    def __init__(self, model):
        f = _one_sample(model)
        self.model = model
        self._in, self._out = np.zeros(3 * model.n_pose), np.zeros(f.nnz_out(0))
        self._buffer, self._call = _buffered(f, [self._in], [self._out])
        self._x, self._A, self._d = np.zeros(model.nx), np.zeros(model.nv * model.n_w), np.zeros(model.nv)
        self._state_buffer, self._state_call = _buffered(_dynamics(model), [self._x], [self._A, self._d])

    def __call__(self, P):
        """``(x (1, nx), a (1, nv), W_p (1, n_w), A^-1 (1, n_w, nv))`` from ``P`` (3, n_pose)."""
        m = self.model
        self._in[:] = P.ravel()
        self._call()
        out = self._out
        x, a = out[:m.nx], out[m.nx:m.nx + m.nv]
        start = m.nx + m.nv
        A = out[start:start + m.nv * m.n_w].reshape(m.n_w, m.nv).T
        d = out[start + m.nv * m.n_w:]
        A_inv = np.linalg.inv(A)
        return x[None].copy(), a[None].copy(), (A_inv @ (a - d))[None], A_inv[None]

    def from_state(self, x, a):
        """``(W_p (1, n_w), A^-1 (1, n_w, nv))`` of (C2) from one state ``x`` (1, nx) and its accelerations ``a``
        (1, nv), for a joint or IMU source."""
        m = self.model
        self._x[:] = np.asarray(x, dtype=float).ravel()
        self._state_call()
        A_inv = np.linalg.inv(self._A.reshape(m.n_w, m.nv).T)
        return (A_inv @ (np.asarray(a, dtype=float).ravel() - self._d))[None], A_inv[None]


def _payload_wrench(model, x, a):
    """``W_p = A(x)^-1 (a - d(x))`` (C2) at each row of ``x`` (N, nx), ``a`` (N, nv); and ``A^-1``."""
    f = _dynamics(model)
    if len(x) == 1:
        A, d = (np.asarray(v) for v in f(x[0]))
        A, d = A[None], d.T
    else:
        A, d = (np.asarray(v) for v in _mapped(model, len(x))(x.T))
        A = A.reshape(model.nv, len(x), model.n_w).transpose(1, 0, 2)
        d = d.T
    A_inv = np.linalg.inv(A)
    return np.einsum("nij,nj->ni", A_inv, a - d), A_inv


def _kinematics(model, p0, p1, p2):
    """The configuration, velocities and accelerations from the smoothed pose and its first two derivatives:
    columns ``(n_pose, N)`` of numbers, or casadi column vectors (the log's pose order). A unit quaternion's
    rates give ``omega``, ``alpha`` (module docstring); a configuration that moves additively is the pose
    itself."""
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
    derivatives (each (N, n_pose), the log's pose order): :func:`_kinematics` row by row."""
    configuration, velocity, acceleration = (v.T for v in _kinematics(model, P0.T, P1.T, P2.T))
    x = np.empty((len(P0), model.nx))
    x[:, list(model.q_index)] = configuration
    x[:, list(model.v_index)] = velocity
    return x, acceleration


def _configuration_variance(model, noise, pose):
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


class _Parts:
    """What (C1)-(C4) need besides the motion: ``S``, ``b``, the sign, the covariances, the bound."""

    def __init__(self, calibration, model, noise, direction, false_alarm):
        if direction not in DIRECTIONS:
            raise CompensationError(f"direction must be one of {', '.join(DIRECTIONS)}; got {direction!r}")
        if not (isinstance(false_alarm, float) and 0 < false_alarm < 1):
            raise CompensationError(f"false_alarm must be a probability in (0, 1); got {false_alarm!r}")
        model.check_noise(noise)
        n = model.n_w
        self.n, self.names, self.direction = n, tuple(model.wrench_names), direction
        self.S, self.b = np.asarray(calibration.S, dtype=float), calibration.offset
        self.sign = reading_sign(calibration.reading)
        self.out_sign = 1.0 if direction == DIRECTIONS[0] else -1.0
        self.reading_cov = self.S @ np.diag(np.square(noise.wrench_sd)) @ self.S.T
        self.warnings = []
        self.cov4 = None
        if calibration.cov is not None:
            cov = np.array(calibration.cov, dtype=float)
            bad = ~np.isfinite(np.diag(cov))
            if bad.any():
                self.warnings.append(f"the calibration left {int(bad.sum())} entries of [S | c] undetermined: the "
                                     "covariance counts the determined ones only")
            cov[bad, :] = 0.0
            cov[:, bad] = 0.0
            cov[~np.isfinite(cov)] = 0.0
            self.m = len(cov) // n
            self.cov4 = cov.reshape(n, self.m, n, self.m)
        self.threshold = float(chi2.ppf(1.0 - false_alarm, n))
        self.false_alarm = false_alarm

    def covariance(self, signed, A_inv, accel_var):
        """(C3) for rows of signed readings ``signed`` (N, n_w); ``accel_var`` (nv,) for every row, or (N, nv)."""
        accel_var = np.asarray(accel_var, dtype=float)
        cov = self.reading_cov + (np.einsum("nij,j,nkj->nik", A_inv, accel_var, A_inv) if accel_var.ndim == 1
                                  else np.einsum("nij,nj,nkj->nik", A_inv, accel_var, A_inv))
        if self.cov4 is not None:
            u = np.concatenate([signed, np.ones((len(signed), 1))], axis=1) if self.m == self.n + 1 \
                else signed - self.b
            cov = cov + np.einsum("na,iajb,nb->nij", u, self.cov4, u)
        return cov

    def offset_cov(self):
        """The calibration's covariance of ``b`` (``c = -S b``: ``S^-1 Cov(c) S^-T``), zero where it holds none."""
        if self.cov4 is None or self.m != self.n + 1:
            return np.zeros((self.n, self.n))
        S_inv = np.linalg.inv(self.S)
        return S_inv @ self.cov4[:, self.n, :, self.n] @ S_inv.T

    def finish(self, w_hat, W_p, A_inv, accel_var, tracker=None, t=None, cov=None):
        """(C1), (C3), (C4) for rows of readings ``w_hat`` (N, n_w) and payload wrenches ``W_p``; with an
        :class:`_OffsetTracker`, (D1)-(D3) sample by sample at times ``t``, and its offsets and sds. ``cov``: the
        rows' (C3), where the caller has it already."""
        signed = self.sign * w_hat
        cov = self.covariance(signed, A_inv, accel_var) if cov is None else cov
        if tracker is not None:
            if tracker.q2 is None:                                                             # (D5)
                tracker.fit(t, W_p - (signed - tracker.b) @ self.S.T, cov)
            steps = [tracker.step(ti, si, wi, ci) for ti, si, wi, ci in zip(t, signed, W_p, cov)]
            w_e, cov, statistic, b, b_sd = (np.array(v) for v in zip(*steps))
            return self.out_sign * w_e, cov, statistic > self.threshold, statistic, b, b_sd
        w_e = W_p - (signed - self.b) @ self.S.T
        statistic = np.einsum("ni,ni->n", w_e, np.linalg.solve(cov, w_e[..., None])[..., 0])
        return self.out_sign * w_e, cov, statistic > self.threshold, statistic


class _Output:
    """The output's axes and point (C8): ``M = blockdiag(R, R) T(r_t)`` (``R`` only for ``frame="base"``), the
    wrench ``M w`` and its covariance ``M Cov M^T``; the identity, and not applied, for the sensor's axes and
    point."""

    def __init__(self, model, frame, point):
        if frame not in FRAMES:
            raise CompensationError(f"frame must be one of {', '.join(FRAMES)}; got {frame!r}")
        self.frame, self.point = frame, None
        if point is not None:
            try:
                r = np.asarray(point, dtype=float)
            except (TypeError, ValueError):
                r = None
            if r is None or r.shape != (3,) or not np.isfinite(r).all():
                raise CompensationError(f"point must be 3 finite numbers (the tool point in the sensor's axes, m); "
                                        f"got {point!r}"[:200])
            self.point = r
        self.identity = frame == FRAMES[0] and point is None
        if not self.identity and model.attitude != "quaternion":
            raise CompensationError(f"frame and point move a 6-axis wrench in 3D; the calibration is of a "
                                    f"{model.name} reading: leave frame='sensor' and point=None")
        self.T = np.eye(6)
        if self.point is not None:
            self.T[:3, 3:] = -skew(self.point)                        # tau_t = tau_s - r_t x f

    @property
    def needs_attitude(self):
        return self.frame == FRAMES[1]

    def apply(self, wrench, cov, R=None):
        """``(M w, M Cov M^T)`` for rows ``wrench`` (N, 6), ``cov`` (N, 6, 6); ``R`` (N, 3, 3) for the base."""
        if self.identity:
            return wrench, cov
        M = np.broadcast_to(self.T, (len(wrench), 6, 6))
        if self.needs_attitude:
            R = np.asarray(R, dtype=float)
            if not np.isfinite(R).all():
                raise CompensationError("the base frame needs the sensor's attitude: the IMU gave no orientation "
                                        "for a sample; give it, or keep the sensor frame")
            B = np.zeros((len(wrench), 6, 6))
            B[:, :3, :3] = R
            B[:, 3:, 3:] = R
            M = B @ M
        return np.einsum("nij,nj->ni", M, wrench), M @ cov @ np.swapaxes(M, 1, 2)


def _pose_attitudes(x, model):
    """The sensor frame's attitude ``R`` (N, 3, 3) of rows of the state ``x`` (a unit quaternion's)."""
    q = x[:, list(model.q_index)][:, 3:7]
    return rotation_matrices(q, normalise=True)


class _OffsetTracker:
    """The offset as a random walk (D1), stepped by (D2)-(D3) on each sample; the one implementation of both
    paths. ``intensity`` per channel, the reading's units per sqrt(s); ``P0`` the initial covariance."""

    def __init__(self, parts, intensity, P0, shape=None):
        self.parts, self.S = parts, parts.S
        self.q2 = None if intensity is None else np.square(intensity)
        self.shape, self.warnings = shape, []
        self.b = np.array(parts.b if parts.b is not None else np.zeros(parts.n), dtype=float)
        self.P = np.array(P0, dtype=float)
        self.t = None

    def step(self, t, signed, W_p, cov):
        """One sample: ``(w_e, Cov_total, d^2, b, sd(b))``, ``w_e`` with the predicted offset (D2)."""
        if self.t is not None:
            self.P = self.P + np.diag(self.q2 * max(t - self.t, 0.0))                          # (D1)
        self.t = t
        w_e = W_p - self.S @ (signed - self.b)
        SP = self.S @ self.P
        total = cov + SP @ self.S.T
        total = 0.5 * (total + total.T)
        solved = np.linalg.solve(total, np.c_[w_e, SP])                                        # (D2)
        statistic = float(w_e @ solved[:, 0])
        if statistic <= self.parts.threshold:                                                  # (D3)
            K = solved[:, 1:].T                                                                # P S^T total^-1
            self.b = self.b - K @ w_e
            self.P = self.P - K @ SP
            self.P = 0.5 * (self.P + self.P.T)
        return w_e, total, statistic, self.b.copy(), np.sqrt(np.maximum(np.diag(self.P), 0.0))

    def tare(self, b, P):
        """Restart from the offset ``b`` of covariance ``P`` (D4)."""
        self.b, self.P = np.array(b, dtype=float), np.array(P, dtype=float)

    @property
    def intensity(self):
        """The random walk's intensity per channel (D1), the reading's units per sqrt(s)."""
        return None if self.q2 is None else np.sqrt(self.q2)

    def fit(self, t, w_e0, cov):
        """Set the intensity to ``s`` times :attr:`shape`, ``s`` maximising (D5) over the rows ``w_e0`` (the
        compensated wrench with this tracker's offset ``b``, (C1)), their covariances ``cov`` (C3) and times
        ``t``; the tracker's state is left as it was. A maximum at the grid's edge adds to :attr:`warnings`."""
        first = np.log2(DRIFT_FIT_GRID)
        step, width, (low, high) = first[1] - first[0], len(first) - 1, np.log2(DRIFT_FIT_LIMITS)
        bound = self.parts.threshold
        grid, d2, logdet = np.empty(0), np.empty((len(t), 0)), np.empty((len(t), 0))
        new = first
        while len(new):
            more = _likelihood_terms(t, w_e0, cov, self.S, self.P, (2.0 ** new[:, None] * self.shape) ** 2, bound)
            grid, d2, logdet = np.r_[grid, new], np.c_[d2, more[0]], np.c_[logdet, more[1]]
            order = np.argsort(grid)
            grid, d2, logdet = grid[order], d2[:, order], logdet[:, order]
            kept = ~(d2 > bound).all(axis=1)                          # the samples every candidate flags left out
            if not kept.any():
                self.q2 = np.square(self.shape)
                self.warnings.append("the drift intensity's fit (D5) found no sample free of a contact: the "
                                     f"default ({DRIFT_INTENSITY:g} x the reading's noise sd) taken")
                return
            ell = -0.5 * (np.minimum(d2, bound) + logdet)[kept].sum(axis=0)                     # (D5)
            i = int(np.argmax(ell))
            new = (grid[0] - step * np.arange(1, width + 1) if i == 0 else
                   grid[-1] + step * np.arange(1, width + 1) if i == len(grid) - 1 else np.empty(0))
            new = new[(new >= low - 1e-9) & (new <= high + 1e-9)]
        if 0 < i < len(grid) - 1:
            lo, mid, hi = ell[i - 1:i + 2]
            curvature = lo - 2 * mid + hi
            best = grid[i] + (0.5 * step * (lo - hi) / curvature if curvature < 0 else 0.0)
        else:
            best = grid[i]
            if i > 0:                       # the lower limit is a log with no drift: the answer, not a failure
                self.warnings.append(f"the drift intensity's fit (D5) reached its upper limit: {2.0 ** best:g} x "
                                     "the causal default taken; the likelihood rises beyond (an offset that jumps, "
                                     "or a contact not flagged?)")
        self.q2 = np.square(2.0 ** best * self.shape)


def _likelihood_terms(t, w_e0, cov, S, P0, q2, bound):
    """(D1)-(D3) run for ``K`` intensities at once over rows ``w_e0`` (N, n) (the wrench with the offset
    ``b0`` where the trackers start), their covariances ``cov`` (N, n, n) and times ``t``, from the offset's
    covariance ``P0``; ``q2`` (K, n) the walks' ``q^2``. Returns ``d^2`` of (D2) and ``log det Cov_total``,
    each (N, K): the terms of (D5)."""
    K, n = q2.shape
    Q = np.zeros((K, n, n))
    Q[:, np.arange(n), np.arange(n)] = q2
    P = np.array(np.broadcast_to(P0, (K, n, n)), dtype=float)
    db = np.zeros((K, n))                                       # each tracker's b - b0
    d2, logdet = np.empty((len(t), K)), np.empty((len(t), K))
    dt = np.maximum(np.diff(t, prepend=t[0]), 0.0)
    ST = S.T
    for k in range(len(t)):
        P += Q * dt[k]                                                                         # (D1)
        w = w_e0[k] + db @ ST
        SP = S @ P
        total = cov[k] + SP @ ST
        solved = np.linalg.solve(total, np.concatenate([w[:, :, None], SP], axis=2))          # (D2)
        d2[k] = np.einsum("ki,ki->k", w, solved[:, :, 0])
        logdet[k] = np.linalg.slogdet(total)[1]
        gain = np.swapaxes(solved[:, :, 1:], 1, 2) * (d2[k] <= bound)[:, None, None]           # (D3)
        db -= np.einsum("kij,kj->ki", gain, w)
        P -= gain @ SP
    return d2, logdet


def _tracker(parts, noise, track_offset, drift_intensity, offset_sd, offline=False):
    """The offset tracker of ``track_offset`` (None where off), its settings checked; ``drift_intensity="fit"``
    (``offline`` only, and its default there) leaves its intensity to (D5), fitted on the log's first pass
    (:meth:`_Parts.finish`)."""
    if not isinstance(track_offset, bool):
        raise CompensationError(f"track_offset must be True or False; got {track_offset!r}")
    if not track_offset:
        if drift_intensity is not None or offset_sd is not None:
            raise CompensationError("drift_intensity and offset_sd are the offset tracker's: add track_offset=True")
        return None
    values = {}
    shape = DRIFT_INTENSITY * np.asarray(noise.wrench_sd, dtype=float)
    fit = (isinstance(drift_intensity, str) and drift_intensity == "fit") or (drift_intensity is None and offline)
    if fit and not offline:
        raise CompensationError("drift_intensity='fit' is fitted over a whole log (D5): offline only "
                                "(compensate with causal=False); a stream takes a number")
    for name, value, default in (("drift_intensity", None if fit else drift_intensity, shape),
                                 ("offset_sd", offset_sd, None)):
        if value is None:
            values[name] = default
            continue
        try:
            v = np.broadcast_to(np.asarray(value, dtype=float), (parts.n,)) if np.ndim(value) == 0 \
                else np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            v = None
        if v is None or v.shape != (parts.n,) or not np.isfinite(v).all() or (v < 0).any():
            raise CompensationError(f"{name} must be one or {parts.n} non-negative numbers (per channel, the "
                                    f"reading's units{' per sqrt(s)' if name == 'drift_intensity' else ''}"
                                    f"{'; or fit, offline' if name == 'drift_intensity' else ''}); got {value!r}")
        values[name] = v
    P0 = parts.offset_cov() if values["offset_sd"] is None else np.diag(np.square(values["offset_sd"]))
    return _OffsetTracker(parts, None if fit else values["drift_intensity"], P0, shape)


def _causal_coefficients(k, order, lead, dt):
    """The causal filter's coefficients: a polynomial of degree ``order`` fitted to ``k`` samples, read ``lead``
    samples before the newest, value and first two derivatives (each (k,), oldest sample first)."""
    return [savgol_coeffs(k, order, deriv=d, delta=dt, pos=k - 1 - lead, use="dot") for d in range(3)]


def _causal_settings(window, delay, order, dt, latency):
    """The window and the delay in samples, checked: ``(k, L, lead)``, the pose window, the reading's delay and
    how far the poses reach past the time they are read at (the pose stream's latency taken off)."""
    for name, value in (("window", window), ("delay", delay)):
        if not (isinstance(value, (int, float)) and np.isfinite(value) and value >= 0):
            raise CompensationError(f"{name} must be a non-negative number of seconds; got {value!r}")
    if not (isinstance(order, int) and 2 <= order <= 7):
        raise CompensationError(f"order must be an integer from 2 to 7 (a second derivative); got {order!r}")
    k = int(round(window / dt))
    if k < order + 3:
        raise CompensationError(f"window {window:g} s is {k} samples at dt = {dt:g} s; the causal filter of degree "
                                f"{order} needs at least {order + 3}")
    L, shift = int(round(delay / dt)), int(round(latency / dt))
    if L < shift:
        raise CompensationError(f"delay {delay:g} s is shorter than the motion stream's latency {latency:g} s: the "
                                "motion at the reading's time has not arrived yet; give a delay of at least the "
                                "latency")
    if L - shift > k - 1:
        lag = f" less the motion stream's latency {latency:g} s" if shift else ""
        raise CompensationError(f"delay {delay:g} s{lag} reaches past the window {window:g} s: give a window of at "
                                f"least {(L - shift + 1) * dt:g} s")
    return k, L, L - shift


def _noise(calibration, noise, log=None):
    """The noise model: given, the calibration's, or the log's (:func:`fmscal.plant.io.estimate_noise`)."""
    if noise is not None:
        if not isinstance(noise, NoiseSpec):
            raise CompensationError(f"noise must be a plant.NoiseSpec; got {type(noise).__name__}")
        return noise
    if calibration.noise is not None and len(calibration.noise.wrench_sd) == calibration.size:
        return calibration.noise
    if log is None:
        raise CompensationError("the calibration holds no noise model: give noise=plant.NoiseSpec(...)")
    return estimate_noise(log)


# --- offline ---------------------------------------------------------------------------------------------------
def compensate(calibration, log, causal=False, *, payload=None, direction="on_tool", noise=None,
               window=None, delay=CAUSAL_DELAY, order=CAUSAL_ORDER, false_alarm=FALSE_ALARM, track_offset=False,
               drift_intensity=None, offset_sd=None, motion=None, frame="sensor", point=None):
    """The contact wrench of a log: ``w_e = W_p - S (sigma w_hat - b)`` (C1), its covariance and a contact flag.

    Parameters
    ----------
    calibration : plant.Calibration
        ``S``, ``b``, the reading's sign, the payload, gravity, latency and (where saved) the noise model and
        the covariance of ``[S | c]``.
    log : plant.Log, plant.io.JointLog or plant.io.ImuLog
        A log of the calibration's case (its poses and readings; or, with ``motion``, its joint states or its
        IMU's samples and readings); no contact needed anywhere.
    causal : bool
        False: the poses smoothed both ways (no delay). True: the causal filter (module docstring), the
        result's :attr:`Compensation.delay` its delay; the same numbers as :class:`Compensator` fed the log
        one sample at a time.
    payload : plant.Payload or plant.SpatialPayload, optional
        Replaces the calibration's (a tool change: ``S`` does not depend on the tool).
    direction : {"on_tool", "on_environment"}
        The published wrench: the environment's on the tool, ``w_e`` (default), or the tool's on the
        environment, ``-w_e``.
    noise : plant.NoiseSpec, optional
        The reading's and the pose's noise; default the calibration's, else the log's.
    window : float, optional
        The smoothing window, s: offline default :data:`OFFLINE_WINDOW`; causal :data:`CAUSAL_WINDOW`.
    delay : float
        Causal: where the fitted polynomial is read, s before the newest sample (:data:`CAUSAL_DELAY`); at
        least the calibration's latency.
    order : int
        Causal: the polynomial's degree.
    false_alarm : float
        The contact test's false-alarm probability per sample (C4).
    track_offset : bool
        Follow the offset's drift (D1)-(D3): updated on the samples with no contact, frozen during one.
    drift_intensity : float, array_like of n_w floats or "fit", optional
        ``track_offset``: the random walk's intensity ``q`` per channel, the reading's units per sqrt(s).
        ``"fit"`` (offline only, and the offline default): :data:`DRIFT_INTENSITY` times the reading's noise sd
        scaled by the maximum of the innovations' likelihood (D5), two to four times the cost; causal default
        :data:`DRIFT_INTENSITY` times the noise sd (the streaming one's). The result's
        :attr:`Compensation.drift_intensity` holds the one used.
    offset_sd : float or array_like of n_w floats, optional
        ``track_offset``: the initial offset's sd (e.g. large for a sensor zeroed at an unknown pose);
        default the calibration's covariance of ``b`` (zero where it holds none).
    motion : JointMotion or ImuMotion, optional
        The motion's source: None, the log's poses; a :class:`JointMotion` (C5) for a
        :class:`fmscal.plant.io.JointLog`; an :class:`ImuMotion` (C6, C7) for a :class:`fmscal.plant.io.ImuLog`.
        Their streams are as of ``t - motion.latency`` for the reading at ``t`` (the source's own latency;
        the calibration's is its pose stream's).
    frame : {"sensor", "base"}
        The output's axes (C8): the sensor's, or the base's (the world of the poses, the URDF's base, the IMU's
        world; the sensor's attitude rotates the torque and the force).
    point : array_like of 3 floats, optional
        The tool point the torque is taken about, in the sensor's axes from the sensor's point, m (C8); default
        the sensor's point.

    Returns
    -------
    Compensation
        Offline: every sample the smoothing window covers (its half-length dropped at each end). Causal: from
        the first full window on, at the readings' own times.

    Raises
    ------
    FmscalError
        Not a calibration or a log, a log of another case, no payload, a window longer than the log, a delay
        shorter than the latency.
    """
    if motion is not None:
        return _compensate_source(calibration, log, causal, motion, payload=payload, direction=direction,
                                  noise=noise, window=window, delay=delay, order=order, false_alarm=false_alarm,
                                  track_offset=track_offset, drift_intensity=drift_intensity, offset_sd=offset_sd,
                                  frame=frame, point=point)
    if not isinstance(log, Log):
        raise CompensationError(f"compensate takes a plant.Log; got {type(log).__name__}")
    model = compensation_model(calibration, payload, log_model_class(log))
    noise = _noise(calibration, noise, log)
    parts = _Parts(calibration, model, noise, direction, false_alarm)
    output = _Output(model, frame, point)
    tracker = _tracker(parts, noise, track_offset, drift_intensity, offset_sd, offline=not causal)
    latency = calibration.latency or 0.0
    aligned = log
    if latency != 0:                     # each pose at the time it was taken; the rows after the last one dropped
        aligned = log.shift_poses(latency)
        aligned = aligned.head(int(np.flatnonzero(aligned.has_pose)[-1]) + 1)
    if not causal:
        window = OFFLINE_WINDOW if window is None else window
        x, a = _smoothed_motion(aligned, model, window)
        keep = slice(edge(aligned, window), len(aligned) - edge(aligned, window))
        k = 2 * edge(aligned, window) + 1
        # the poses interpolated onto the log's grid: a pose every r samples weighs about r times a sample's
        # share of the filter, so the variance of the derivative is about r times the grid's sum(c^2)
        r = float(np.median(np.diff(np.flatnonzero(aligned.has_pose)))) if aligned.has_pose.sum() > 1 else 1.0
        c2 = savgol_coeffs(k, ORDER, deriv=2, delta=aligned.dt, use="dot") * np.sqrt(max(r, 1.0))
        t, w_hat, x, a, lag = aligned.t[keep], aligned.w_hat[keep], x[keep], a[keep], 0.0
    else:
        window = CAUSAL_WINDOW if window is None else window
        k, L, lead = _causal_settings(window, delay, order, aligned.dt, latency)
        if not aligned.has_pose.all():
            return _by_stream(calibration, log, model, noise, direction, window, delay, order, false_alarm, parts,
                              dict(track_offset=track_offset, drift_intensity=drift_intensity, offset_sd=offset_sd,
                                   frame=frame, point=point))
        coefficients = _causal_coefficients(k, order, lead, aligned.dt)
        c2 = coefficients[2]
        P = [_causal_filter(aligned.pose, c) for c in coefficients]         # read at sample n - lead
        # sample j of the filtered poses is read at the pose index j + k - 1 - lead; the reading there
        first = k - 1 - lead
        rows = slice(first, first + len(P[0]))
        x, a = _state(model, *P)
        t, w_hat, lag = aligned.t[rows], aligned.w_hat[rows], round(L * aligned.dt, 12)
    W_p, A_inv = _payload_wrench(model, x, a)
    accel_var = _configuration_variance(model, noise, aligned.pose[np.argmax(aligned.has_pose)]) * np.sum(c2 ** 2)
    wrench, cov, contact, statistic, *offset = parts.finish(w_hat, W_p, A_inv, accel_var, tracker, t)
    offset, offset_sd = offset if offset else (None, None)
    if not output.identity:
        wrench, cov = output.apply(wrench, cov, _pose_attitudes(x, model) if output.needs_attitude else None)
    return Compensation(t=t, wrench=wrench, cov=cov, contact=contact, statistic=statistic,
                        threshold=parts.threshold, names=parts.names, delay=float(lag), direction=direction,
                        warnings=list(parts.warnings) + ([] if tracker is None else tracker.warnings),
                        offset=offset, offset_sd=offset_sd, frame=frame, point=output.point,
                        drift_intensity=None if tracker is None else tracker.intensity)


def _causal_filter(values, c):
    """``y_j = sum_i c_i values_{j + i}`` over every full window, shape (N - k + 1, ...)."""
    k = len(c)
    n = len(values) - k + 1
    out = np.zeros((n,) + values.shape[1:])
    for i in range(k):
        out += c[i] * values[i:i + n]
    return out


def _smoothed_motion(log, model, window):
    """The state and accelerations of every sample by the filter of the calibration's least squares (both
    ways): :func:`fmscal.plant.physics.spatial_motion` for a unit quaternion, else
    :func:`fmscal.observers.batch.smoothed_channels`."""
    if model.attitude == "quaternion":
        _, _, alpha, p_ddot = spatial_motion(log, window)
        return smoothed_state(log, window), np.c_[p_ddot, alpha]
    q, v, a = smoothed_channels(log, model, window)
    return _state(model, q, v, a)


def _by_stream(calibration, log, model, noise, direction, window, delay, order, false_alarm, parts, tracking):
    """The causal path of a log with missing poses: :class:`Compensator` fed it sample by sample."""
    stream = Compensator(calibration, log.dt, payload=model.payload, noise=noise, direction=direction,
                         window=window, delay=delay, order=order, false_alarm=false_alarm, **tracking)
    out = [stream.push(t, w, p) for t, w, p in zip(log.t, log.w_hat, log.pose)]
    out = [o for o in out if o is not None]
    if not out:
        raise CompensationError(f"{log.name}: no window of the causal filter holds enough poses")
    return _streamed(stream, out, direction,
                     list(parts.warnings) + ["missing poses: each window fitted to the poses it holds"])


def _streamed(stream, out, direction, warnings):
    """The :class:`Compensation` of a :class:`Compensator`'s samples ``out`` (oldest first, none None)."""
    offset = out[0].offset is not None
    return Compensation(t=np.array([o.t for o in out]), wrench=np.array([o.wrench for o in out]),
                        cov=np.array([o.cov for o in out]), contact=np.array([o.contact for o in out]),
                        statistic=np.array([o.statistic for o in out]), threshold=stream._parts.threshold,
                        names=stream._parts.names, delay=stream.delay, direction=direction, warnings=warnings,
                        offset=np.array([o.offset for o in out]) if offset else None,
                        offset_sd=np.array([o.offset_sd for o in out]) if offset else None,
                        frame=stream.frame, point=stream.point,
                        drift_intensity=None if stream._tracker is None else stream._tracker.intensity)


def _compensate_source(calibration, log, causal, motion, *, payload, direction, noise, window, delay, order,
                       false_alarm, track_offset, drift_intensity, offset_sd, frame, point):
    """:func:`compensate` with a joint or IMU source: causal, :class:`Compensator` fed the log; offline, the
    source's channels smoothed and differentiated both ways (the filter of the pose path), then (C5)-(C7)."""
    if not isinstance(motion, (JointMotion, ImuMotion)):
        raise CompensationError(f"motion must be None (poses), a JointMotion or an ImuMotion; got "
                                f"{type(motion).__name__}")
    joint = isinstance(motion, JointMotion)
    kind = JointLog if joint else ImuLog
    if not isinstance(log, kind):
        raise CompensationError(f"a {type(motion).__name__} takes a plant.io.{kind.__name__}; got "
                                f"{type(log).__name__}")
    if joint and log.joints.shape[1] != motion.size:
        raise CompensationError(f"{log.name}: {log.joints.shape[1]} joint columns; the URDF has {motion.size} "
                                "joints")
    if joint:
        log.check_kinematics(motion.kinematics, motion.joints)          # joint angles in degrees refused
    model = compensation_model(calibration, payload)
    motion.check(model)
    if len(log.w_hat[0]) != model.n_w:
        raise CompensationError(f"{log.name}: {len(log.w_hat[0])} reading columns; the calibration's reading has "
                                f"{model.n_w}")
    if noise is None and (calibration.noise is None or len(calibration.noise.wrench_sd) != calibration.size):
        noise = NoiseSpec(tuple(difference_noise(log.w_hat)))               # plant.io.estimate_noise's estimate
        if min(noise.wrench_sd) <= 0:
            raise CompensationError(f"{log.name}: the readings' noise estimated from the log is zero (a constant or "
                                    "coarsely quantised reading): give noise=plant.NoiseSpec(...), or a calibration "
                                    "holding its noise")
    if causal:
        stream = Compensator(calibration, log.dt, payload=model.payload, noise=noise, direction=direction,
                             window=CAUSAL_WINDOW if window is None else window, delay=delay, order=order,
                             false_alarm=false_alarm, track_offset=track_offset, drift_intensity=drift_intensity,
                             offset_sd=offset_sd, motion=motion, frame=frame, point=point)
        out = []
        for i, t in enumerate(log.t):
            if joint:
                q = log.joints[i]
                sample = dict(joints=None if np.isnan(q).all() else
                              (q, *(None if v is None or np.isnan(v[i]).all() else v[i]
                                    for v in (log.velocities, log.accelerations))))
            else:
                rates = (log.angular_velocity[i], log.specific_force[i])
                sample = dict(imu=None if np.isnan(rates[0]).all() else (log.orientation[i], *rates))
            o = stream.push(t, log.w_hat[i], **sample)
            if o is not None:
                out.append(o)
        if not out:
            raise CompensationError(f"{log.name}: no window of the causal filter holds enough {motion.source}")
        return _streamed(stream, out, direction, list(stream.warnings))
    log = _at_readings(log, motion.latency, joint)         # offline: the stream at the readings' times
    noise = _noise(calibration, noise)
    parts = _Parts(calibration, model, noise, direction, false_alarm)
    output = _Output(model, frame, point)
    tracker = _tracker(parts, noise, track_offset, drift_intensity, offset_sd, offline=True)
    warnings = list(parts.warnings) + _latency_warnings(calibration, motion)
    window = OFFLINE_WINDOW if window is None else window
    dt = log.dt
    h = edge(log, window)                                               # the pose path's window, checked
    k = 2 * h + 1
    raw = log.joints if joint else np.c_[log.angular_velocity, log.specific_force]
    present = np.flatnonzero(np.isfinite(raw).all(axis=1))
    if len(present) < 4:
        moved = (f" once moved by its latency ({motion.latency:g} s; the log spans {log.t[-1] - log.t[0]:g} s)"
                 if motion.latency else "")
        raise CompensationError(f"{log.name}: fewer than four samples of the {motion.source}{moved}")
    first, last = present[0], present[-1] + 1           # the rows before the first sample and after the last dropped
    if last - first < k + 1:
        raise CompensationError(f"{log.name}: {last - first} samples with the {motion.source}; the smoothing window "
                                f"{window:g} s needs more than {k}")
    filled = _fill(log.t[first:last], raw[first:last])
    smooth = [savgol_filter(filled, k, ORDER, deriv=d, delta=dt, axis=0, mode="interp") for d in range(3)]
    smooth = [np.concatenate([np.full((first, v.shape[1]), np.nan), v]) for v in smooth]
    sums = [float(np.sum(savgol_coeffs(k, ORDER, deriv=d, delta=dt, use="dot") ** 2)) for d in range(3)]
    keep = slice(first + h, last - h)
    # each channel's noise by plant.io.estimate_noise's robust estimate over its samples; the samples interpolated
    # onto the readings' grid, one every r rows weighs about r times a row's share of the filter (as the pose path)
    var = difference_noise(raw, present) ** 2
    r = float(np.median(np.diff(present)))
    sums = [v * max(r, 1.0) for v in sums]
    P = [v[keep] for v in smooth]
    if joint:
        dq, ddq, var_ddq = P[1], P[2], var * sums[2]
        if log.velocities is not None:
            dq = np.where(np.isfinite(log.velocities[keep]), log.velocities[keep], dq)
        if log.accelerations is not None:
            measured = np.isfinite(log.accelerations[keep])
            ddq = np.where(measured, log.accelerations[keep], ddq)
            var_ddq = np.where(measured.all(axis=0), 0.0, var_ddq)
        x, a, R = motion.state(model, P[0], dq, ddq)
        accel_var = motion.accel_var(P[0], var_ddq, R)                  # (N, 6): each row's Jacobian and R
    else:
        x, a, R = motion.state(model, P[0], P[1], _filled_orientation(log.t, log.orientation)[keep])
        M, accel_var = motion.accel_noise(var, sums[0], sums[1])
    t, w_hat = log.t[keep], log.w_hat[keep]
    W_p, A_inv = _payload_wrench(model, x, a)
    if not joint:
        A_inv = A_inv @ M                           # Cov(a) = M diag(var) M^T: A^-1 Cov(a) A^-T
    wrench, cov, contact, statistic, *offset = parts.finish(w_hat, W_p, A_inv, accel_var, tracker, t)
    offset, offset_sd = offset if offset else (None, None)
    wrench, cov = output.apply(wrench, cov, R)
    return Compensation(t=t, wrench=wrench, cov=cov, contact=contact, statistic=statistic,
                        threshold=parts.threshold, names=parts.names, delay=0.0, direction=direction,
                        warnings=warnings + ([] if tracker is None else tracker.warnings), offset=offset,
                        offset_sd=offset_sd, frame=frame, point=output.point,
                        drift_intensity=None if tracker is None else tracker.intensity)


def _latency_warnings(calibration, motion):
    """The warning that the calibration's latency (its pose stream's) is not the source's, where the source has
    none given: its stream is then taken as of the readings' times."""
    if not calibration.latency or motion.latency:
        return []
    return [f"the calibration's latency ({calibration.latency * 1e3:.3g} ms, its pose stream's) is not applied to "
            f"the {motion.source} stream, and it has none of its own: it is taken as of the readings' times (give "
            f"{type(motion).__name__}(..., latency=S), or --motion-latency S, where it lags them)"]


def _at_readings(log, latency, joint):
    """A joint or IMU log with its stream moved onto the readings' times: the sample given with the reading at
    ``t_j`` is as of ``t_j - latency``; it goes to the row nearest that time (``round(latency / dt)`` rows back), its
    value there the stream's at the row's time, interpolated linearly between its samples (an orientation made
    sign-continuous first and normalised after: SLERP to second order in the turn between two samples). A stream
    sparser than the readings stays as sparse, its rows between samples empty as with no latency: filled, its
    noise, estimated from its samples' differences, would vanish from the covariance. NaN where the stream does not
    reach. The log itself is not changed."""
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
    if joint:
        moved.joints, moved.velocities, moved.accelerations = (at(v) for v in (log.joints, log.velocities,
                                                                               log.accelerations))
    else:
        moved.angular_velocity, moved.specific_force = at(log.angular_velocity), at(log.specific_force)
        q = at(_sign_continuous(log.orientation))
        moved.orientation = q / np.linalg.norm(q, axis=1, keepdims=True)
    return moved


def _sign_continuous(q):
    """Rows of quaternions (N, 4), NaN rows kept, each sample's sign turned into its predecessor's hemisphere
    (``q`` and ``-q`` are one attitude; an IMU may publish either): interpolated component by component, two
    samples of opposite signs would pass near zero, not through the turn between them."""
    q = np.array(q, dtype=float)
    rows = np.flatnonzero(np.isfinite(q).all(axis=1))
    if len(rows) > 1:
        flips = np.einsum("ij,ij->i", q[rows[1:]], q[rows[:-1]]) < 0
        q[rows[1:]] *= np.cumprod(np.where(flips, -1.0, 1.0))[:, None]
    return q


def _filled_orientation(t, q):
    """An IMU's orientations (N, 4) at every row: the rows without a sample (a stream sparser than the readings)
    interpolated between their neighbours' as :func:`_at_readings` does (sign-continuous, normalised); NaN
    before the first and after the last sample. Only the output in the base's axes reads them (C8)."""
    q = _sign_continuous(q)
    present = np.flatnonzero(np.isfinite(q).all(axis=1))
    if len(present) < 2 or len(present) == len(q):
        return q
    missing = np.flatnonzero(~np.isfinite(q).all(axis=1))
    for c in range(4):
        q[missing, c] = np.interp(t[missing], t[present], q[present, c], left=np.nan, right=np.nan)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _fill(t, values):
    """Rows of NaN (no sample) between the first and the last sample filled by a cubic spline through the
    samples (twice differentiable, unlike a linear interpolation)."""
    present = np.isfinite(values).all(axis=1)
    if present.all():
        return values
    return CubicSpline(t[present], values[present], axis=0)(t)


# --- streaming --------------------------------------------------------------------------------------------------
@dataclass
class ContactSample:
    """One compensated sample from :class:`Compensator`.

    Attributes
    ----------
    t : float
        The reading's time, s (it comes out :attr:`Compensator.delay` s later).
    wrench : ndarray, shape (n_w,)
    cov : ndarray, shape (n_w, n_w)
    contact : bool
    statistic : float
    offset, offset_sd : ndarray, shape (n_w,), or None
        ``track_offset``: the offset after this sample's step (D3) and its sd; None otherwise.
    """

    t: float
    wrench: np.ndarray
    cov: np.ndarray
    contact: bool
    statistic: float
    offset: np.ndarray = None
    offset_sd: np.ndarray = None


class Compensator:
    """The causal compensation one sample at a time: a reading and its motion in, the contact wrench out.

    Each :meth:`push` takes the newest sample (time, raw reading, and a pose, joint states or an IMU's sample,
    as ``motion`` declares, or None) and returns the contact wrench of the reading taken :attr:`delay` s
    earlier (:class:`ContactSample`: (C1), (C3), (C4) of the module, (C8) for ``frame`` and ``point``), or
    None until the window is full or where it holds too few motion samples. The poses (or the joint angles,
    or the IMU's rate and specific force) are fitted by the causal filter of :func:`compensate`; fed a log,
    the two give the same numbers.

    Parameters
    ----------
    calibration : plant.Calibration
    dt : float
        The sample time, s (the readings' rate; a motion sample may come with any of them).
    payload, direction, noise, window, delay, order, false_alarm, track_offset, drift_intensity, offset_sd
        As for :func:`compensate` (``noise`` default the calibration's: required where it has none).
    motion : JointMotion or ImuMotion, optional
        The motion's source (module :mod:`fmscal.analysis._motion`): None, poses (``push(t, w_hat, pose)``);
        a :class:`JointMotion` (``push(t, w_hat, joints=(q, dq, ddq))``, ``dq``/``ddq`` None where not given:
        then differentiated by the causal filter); an :class:`ImuMotion` (``push(t, w_hat, imu=(quaternion_wxyz,
        angular_velocity, specific_force))``, the IMU's axes: only the angular acceleration is differentiated).
        Either way the delay is the filter's, :attr:`delay`; the stream is as of ``t - motion.latency`` for
        the reading at ``t`` (the filter read that much nearer its newest sample, in whole samples).
    frame : {"sensor", "base"}
        The output's axes (C8); "base" needs an attitude (a pose, the joints, or the IMU's orientation).
    point : array_like of 3 floats, optional
        The tool point, sensor axes, m: the torque about it (C8); default the sensor's point.
    """

    def __init__(self, calibration, dt, *, payload=None, direction="on_tool", noise=None, window=CAUSAL_WINDOW,
                 delay=CAUSAL_DELAY, order=CAUSAL_ORDER, false_alarm=FALSE_ALARM, track_offset=False,
                 drift_intensity=None, offset_sd=None, motion=None, frame="sensor", point=None):
        if not (isinstance(dt, (int, float)) and np.isfinite(dt) and dt > 0):
            raise CompensationError(f"dt must be a positive number of seconds; got {dt!r}")
        self.model = compensation_model(calibration, payload)
        if motion is not None and not isinstance(motion, (JointMotion, ImuMotion)):
            raise CompensationError(f"motion must be None (poses), a JointMotion or an ImuMotion; got "
                                    f"{type(motion).__name__}")
        if motion is not None:
            motion.check(self.model)
        self.motion = motion
        self._output = _Output(self.model, frame, point)
        self._sample = _SampleDynamics(self.model)
        self.frame, self.point = frame, self._output.point
        noise = _noise(calibration, noise)
        self._parts = _Parts(calibration, self.model, noise, direction, false_alarm)
        self._tracker = _tracker(self._parts, noise, track_offset, drift_intensity, offset_sd)
        # the newest compensated samples, for tare: (sigma w_hat - S^-1 W_p, Cov of (C3), contact)
        self._last = deque(maxlen=max(1, int(round(TARE_WINDOW / float(dt)))))
        latency = (calibration.latency or 0.0) if motion is None else motion.latency
        self.dt, self.order, self._noise = float(dt), order, noise
        self._k, self._L, self._lead = _causal_settings(window, delay, order, self.dt, latency)
        self._coefficients = np.array(_causal_coefficients(self._k, order, self._lead, self.dt))    # (3, k)
        # the last k poses received (None where none came): the newest, latency samples late, is the pose of
        # the reading lead samples after the one read out, the oldest of the last L + 1 readings
        self._poses = deque(maxlen=self._k)
        self._readings = deque(maxlen=self._L + 1)      # (t, w_hat) of the last L + 1 samples
        self._accel_var = None
        self._last_q = None
        self.warnings = list(self._parts.warnings)
        if motion is not None:
            self._extras = deque(maxlen=self._k)           # per motion sample: (dq, ddq) or the IMU's quaternion
            self._channel_noise = _RunningNoise(motion.size)
            self._units_checked = False                    # an IMU's units, checked on its first full window
            self.warnings += _latency_warnings(calibration, motion)

    @property
    def delay(self):
        """The delay the causal filter adds, s: each output is the wrench of the reading this much older."""
        return round(self._L * self.dt, 12)

    def push(self, t, w_hat, pose=None, *, joints=None, imu=None):
        """Take the newest sample; the contact wrench of the reading :attr:`delay` s older, or None.

        Parameters
        ----------
        t : float
            s.
        w_hat : array_like, shape (n_w,)
            The raw reading.
        pose : array_like, shape (n_pose,), optional
            ``motion=None``: the pose stream's newest pose, None (or NaN) where none came with this reading.
        joints : tuple (q, dq, ddq), optional
            A :class:`JointMotion`: arrays in its ``joints`` order (rad, rad/s, rad/s^2; m for a prismatic
            joint), ``dq``/``ddq`` None where not given; None where no joint state came.
        imu : tuple (quaternion_wxyz, angular_velocity, specific_force), optional
            An :class:`ImuMotion`: the IMU's orientation in its world (scalar first; None where it gives none),
            rate (rad/s) and specific force (m/s^2) in its axes; None where no IMU sample came.

        Returns
        -------
        ContactSample or None
        """
        w_hat = np.asarray(w_hat, dtype=float)
        if w_hat.shape != (self._parts.n,) or not np.isfinite(w_hat).all():
            raise CompensationError(f"w_hat must be {self._parts.n} finite numbers; got {w_hat!r}")
        if self.motion is not None or joints is not None or imu is not None:
            return self._push_source(float(t), w_hat, pose, joints, imu)
        if pose is not None:
            pose = np.asarray(pose, dtype=float)
            if pose.shape != (self.model.n_pose,):
                raise CompensationError(f"pose must be {self.model.n_pose} numbers; got shape {pose.shape}")
            if not np.isfinite(pose).all():
                pose = None
        if pose is not None and self.model.attitude == "quaternion":     # q and -q: one attitude, kept continuous
            if self._last_q is not None and pose[:4] @ self._last_q < 0:
                pose = pose.copy()
                pose[:4] *= -1
            self._last_q = pose[:4]
        if pose is not None and self._accel_var is None:
            self._accel_var = _configuration_variance(self.model, self._noise, pose)
        self._readings.append((float(t), w_hat))
        self._poses.append(pose)
        if len(self._readings) <= self._L or len(self._poses) < self._k:
            return None
        t0, reading = self._readings[0]
        present = [p is not None for p in self._poses]
        if all(present):
            P = self._coefficients @ np.array(self._poses)                # (3, n_pose)
            c2_sq = float(np.sum(self._coefficients[2] ** 2))
        else:
            fitted = self._irregular(present)
            if fitted is None:
                return None
            P, c2_sq = fitted
        x, a, W_p, A_inv = self._sample(P)
        signed = self._parts.sign * reading
        own = self._parts.covariance(signed[None], A_inv, self._accel_var * c2_sq)      # (C3), once
        wrench, cov, contact, statistic, *offset = self._parts.finish(reading[None], W_p, A_inv,
                                                                      self._accel_var * c2_sq, self._tracker, [t0],
                                                                      own)
        self._last.append((signed - np.linalg.solve(self._parts.S, W_p[0]), own[0].copy(), bool(contact[0])))
        offset, offset_sd = (offset[0][0], offset[1][0]) if offset else (None, None)
        if not self._output.identity:
            wrench, cov = self._output.apply(wrench, cov, _pose_attitudes(x, self.model)
                                             if self._output.needs_attitude else None)
        return ContactSample(t0, wrench[0], cov[0], bool(contact[0]), float(statistic[0]), offset, offset_sd)

    def _push_source(self, t, w_hat, pose, joints, imu):
        """:meth:`push` for a joint or IMU source: its channels filtered causally, (C5)-(C7), then (C1)-(C4)."""
        motion = self.motion
        given = {"pose": pose, "joints": joints, "imu": imu}
        wanted = "pose" if motion is None else "joints" if isinstance(motion, JointMotion) else "imu"
        extra = [k for k, v in given.items() if v is not None and k != wanted]
        if extra:
            what = "poses (motion=None)" if motion is None else f"{motion.source} ({type(motion).__name__})"
            raise CompensationError(f"this Compensator takes {what}: {extra[0]}= was given; give {wanted}= only")
        sample = motion.sample(given[wanted])
        if sample is None:
            channels, extra_value = None, None
        elif wanted == "joints":
            channels, extra_value = sample[0], (sample[1], sample[2])
        else:
            channels, extra_value = sample
            extra_value = extra_value if np.isfinite(extra_value).all() else None
        self._channel_noise.add(channels)
        self._readings.append((t, w_hat))
        self._poses.append(channels)
        self._extras.append(extra_value)
        if len(self._readings) <= self._L or len(self._poses) < self._k:
            return None
        t0, reading = self._readings[0]
        present = [p is not None for p in self._poses]
        if wanted == "imu" and not self._units_checked and any(present):
            rows = np.array([p for p in self._poses if p is not None])
            check_imu_units("the IMU stream", rows[:, :3], rows[:, 3:])       # in g or deg/s: one line
            self._units_checked = True
        if all(present):
            P, c = self._coefficients @ np.array(self._poses), self._coefficients
        else:
            fitted = self._fit(present)
            if fitted is None:
                return None
            P, c = fitted
        sums = np.sum(c ** 2, axis=1)                                   # sum c0^2, c1^2, c2^2
        var = self._channel_noise.variance()
        i0 = self._k - 1 - self._lead                                   # the read-out sample in the window
        if wanted == "joints":
            q, dq, ddq = P[0], P[1], P[2]
            var_ddq = var * sums[2]
            if self._extras[i0] is not None:
                given_dq, given_ddq = self._extras[i0]
                measured = np.isfinite(given_ddq)
                dq = np.where(np.isfinite(given_dq), given_dq, dq)
                ddq = np.where(measured, given_ddq, ddq)
                var_ddq = np.where(measured, 0.0, var_ddq)
                if np.isfinite(given_dq).all() and measured.all():
                    q = self._poses[i0]
            x, a, R = motion.state(self.model, q[None], dq[None], ddq[None])
            accel_var = motion.accel_var(q[None], var_ddq, R)[0]
        else:
            x, a, R = motion.state(self.model, P[0:1], P[1:2], self._orientation(i0)[None])
            M, accel_var = motion.accel_noise(var, sums[0], sums[1])
        W_p, A_inv = self._sample.from_state(x, a)
        if wanted == "imu":
            A_inv = A_inv @ M                       # Cov(a) = M diag(var) M^T: A^-1 Cov(a) A^-T
        signed = self._parts.sign * reading
        own = self._parts.covariance(signed[None], A_inv, accel_var)                  # (C3), once
        wrench, cov, contact, statistic, *offset = self._parts.finish(reading[None], W_p, A_inv, accel_var,
                                                                      self._tracker, [t0], own)
        self._last.append((signed - np.linalg.solve(self._parts.S, W_p[0]), own[0].copy(), bool(contact[0])))
        offset, offset_sd = (offset[0][0], offset[1][0]) if offset else (None, None)
        wrench, cov = self._output.apply(wrench, cov, R)
        return ContactSample(t0, wrench[0], cov[0], bool(contact[0]), float(statistic[0]), offset, offset_sd)

    def _orientation(self, i0):
        """The IMU's orientation nearest the read-out sample ``i0`` in the window (NaN where none came)."""
        if self._extras[i0] is not None:
            return self._extras[i0]
        rows = [i for i, e in enumerate(self._extras) if e is not None]
        if not rows:
            return np.full(4, np.nan)
        return self._extras[min(rows, key=lambda i: abs(i - i0))]

    @property
    def offset(self):
        """The offset ``b`` in use (the reading's units): the tracker's, a tare's or the calibration's."""
        return (self._tracker.b if self._tracker is not None else np.asarray(self._parts.b, dtype=float)).copy()

    def tare(self, force=False):
        """Re-bias at the current pose (D4): ``b = sigma w_hat - S^-1 W_p(pose)``, the mean over the newest
        compensated samples (:data:`TARE_WINDOW`, fewer where fewer came out), its covariance that of a mean.

        The payload's own wrench at that pose is restored, so the output does not jump beyond the noise; a
        sensor zeroed by its hardware at an unknown pose is one more offset found this way. With
        ``track_offset``, the tracker restarts from it, its covariance ``S^-1 Cov S^-T / n`` over the ``n`` samples.

        Parameters
        ----------
        force : bool
            Tare even where these samples read as a contact: for an offset itself far off (a sensor
            zeroed by its hardware reads its payload's wrench at the zero pose as a contact everywhere else),
            the tool known to be free.

        Returns
        -------
        ndarray, shape (n_w,)
            The new offset.

        Raises
        ------
        FmscalError
            No sample compensated yet, or a contact detected (without ``force``): more of these samples
            flagged (C4) than false alarms give but with probability :data:`TARE_FALSE_REFUSAL` (a binomial
            tail at the test's false-alarm rate), so that a free tool is not refused by chance.
        """
        if not self._last:
            raise CompensationError("tare needs a compensated sample: push readings and poses until one comes out")
        found, cov, contact = (np.array(v) for v in zip(*self._last))
        chance = binom.isf(TARE_FALSE_REFUSAL, len(contact), self._parts.false_alarm)
        if contact.sum() > chance and not force:
            raise CompensationError(f"tare refused: a contact is detected ({int(contact.sum())} of the last "
                                    f"{len(contact)} samples); tare with the tool free, or with force=True where "
                                    "the offset itself is off (a sensor zeroed by its hardware)")
        S_inv = np.linalg.inv(self._parts.S)
        if self._tracker is None:
            self._parts.b = found.mean(axis=0)
        else:
            self._tracker.tare(found.mean(axis=0), S_inv @ cov.mean(axis=0) @ S_inv.T / len(found))
        return self.offset

    def push_many(self, t, w_hat, pose=None, *, joints=None, imu=None):
        """:meth:`push` over rows, vectorised: the same samples, for a block that came together (a backlog).

        Rows whose pose windows are full are fitted together (one causal filter over the block, one call of
        the dynamics); the others go through :meth:`push` one at a time, and so do the rows of a joint or IMU
        source (``joints=`` or ``imu=``, as :meth:`push` takes them, one row per reading).

        Parameters
        ----------
        t : array_like, shape (M,)
        w_hat : array_like, shape (M, n_w)
        pose : array_like, shape (M, n_pose), optional
            ``motion=None``: NaN rows where no pose came with the reading.
        joints : tuple (q, dq, ddq), optional
            A :class:`JointMotion`: ``q`` (M, n) with NaN rows where no joint state came, ``dq`` and ``ddq``
            (M, n) or None where not given (NaN rows where not given with that reading).
        imu : tuple (quaternion_wxyz, angular_velocity, specific_force), optional
            An :class:`ImuMotion`: (M, 4) or None, (M, 3), (M, 3); NaN rows where no IMU sample came.

        Returns
        -------
        list of ContactSample
            The samples :meth:`push` returns, Nones left out, oldest first.
        """
        t = np.asarray(t, dtype=float)
        w_hat = np.asarray(w_hat, dtype=float)
        if self.motion is not None or joints is not None or imu is not None:
            return self._push_many_source(t, w_hat, pose, joints, imu)
        pose = np.asarray(pose, dtype=float)
        out = []
        i = 0
        # one at a time until both windows are full of poses, and for a row without one
        while i < len(t) and (len(self._readings) <= self._L or len(self._poses) < self._k
                              or any(p is None for p in self._poses) or not np.isfinite(pose[i]).all()):
            sample = self.push(t[i], w_hat[i], pose[i])
            if sample is not None:
                out.append(sample)
            i += 1
        j = i
        while j < len(t) and np.isfinite(pose[j]).all():
            j += 1
        if j - i >= 2:
            out.extend(self._push_block(t[i:j], w_hat[i:j], pose[i:j]))
        elif j > i:
            out.extend(s for s in [self.push(t[i], w_hat[i], pose[i])] if s is not None)
        if j < len(t):
            out.extend(self.push_many(t[j:], w_hat[j:], pose[j:]))
        return out

    def _push_many_source(self, t, w_hat, pose, joints, imu):
        """:meth:`push_many` for a joint or IMU source: its rows through :meth:`push`, one at a time."""
        if pose is not None:
            return [s for s in [self.push(t[0], w_hat[0], pose[0], joints=joints, imu=imu)] if s is not None]
        keyword, given = ("joints", joints) if joints is not None else ("imu", imu)
        if given is None:
            return [s for s in (self.push(ti, wi) for ti, wi in zip(t, w_hat)) if s is not None]
        if not (isinstance(given, (tuple, list)) and len(given) == 3):
            raise CompensationError(f"{keyword} must be a tuple of three arrays of rows, one row per reading, as "
                                    f"push takes them (None where not given)")
        columns = []
        for v in given:
            v = None if v is None else np.asarray(v, dtype=float)
            if v is not None and (v.ndim != 2 or len(v) != len(t)):
                raise CompensationError(f"{keyword}: arrays of {len(t)} rows, one per reading; got shape {v.shape}")
            columns.append(v)
        out = []
        for i in range(len(t)):
            row = tuple(None if v is None or np.isnan(v[i]).all() else v[i] for v in columns)
            if keyword == "joints":
                row = None if row[0] is None else row
            else:
                row = None if row[1] is None and row[2] is None else row
            sample = self.push(t[i], w_hat[i], **{keyword: row})
            if sample is not None:
                out.append(sample)
        return out

    def _push_block(self, t, w_hat, pose):
        """:meth:`push_many`'s rows with the windows full and every pose present."""
        if w_hat.shape != (len(t), self._parts.n) or not np.isfinite(w_hat).all():
            raise CompensationError(f"w_hat must be rows of {self._parts.n} finite numbers; got shape {w_hat.shape}")
        if pose.shape != (len(t), self.model.n_pose):
            raise CompensationError(f"pose must be rows of {self.model.n_pose} numbers; got shape {pose.shape}")
        pose = pose.copy()
        if self.model.attitude == "quaternion":                       # q and -q: one attitude, kept continuous
            last = self._last_q
            for row in pose:
                if last is not None and row[:4] @ last < 0:
                    row[:4] *= -1
                last = row[:4]
            self._last_q = last
        m, k = len(t), self._k
        poses = np.concatenate([np.array(list(self._poses)[1:]), pose])          # (k - 1 + m, n_pose)
        windows = np.lib.stride_tricks.sliding_window_view(poses, k, axis=0)   # (m, n_pose, k)
        P = np.einsum("dk,mpk->dmp", self._coefficients, windows)
        readings = list(self._readings)[1:] + list(zip(t.tolist(), w_hat))
        t0 = np.array([r[0] for r in readings[:m]])
        reading = np.array([r[1] for r in readings[:m]])
        c2_sq = float(np.sum(self._coefficients[2] ** 2))
        if m <= _ROW_BY_ROW:                                   # a few rows: the sample's buffer, row by row
            x, a, W_p, A_inv = (np.concatenate(v) for v in zip(*(self._sample(P[:, i]) for i in range(m))))
        else:
            x, a = _state(self.model, P[0], P[1], P[2])
            W_p, A_inv = _payload_wrench(self.model, x, a)
        accel_var = self._accel_var * c2_sq
        signed = self._parts.sign * reading
        own = self._parts.covariance(signed, A_inv, accel_var)                        # (C3), once
        wrench, cov, contact, statistic, *offset = self._parts.finish(reading, W_p, A_inv, accel_var, self._tracker,
                                                                      t0, own)
        found = signed - np.linalg.solve(self._parts.S, W_p.T).T
        for row in range(max(0, m - self._last.maxlen), m):
            self._last.append((found[row], own[row].copy(), bool(contact[row])))
        if not self._output.identity:
            wrench, cov = self._output.apply(wrench, cov, _pose_attitudes(x, self.model)
                                             if self._output.needs_attitude else None)
        self._poses.extend(pose)
        self._readings.extend(zip(t.tolist(), w_hat))
        b, b_sd = offset if offset else ([None] * m, [None] * m)
        return [ContactSample(float(t0[r]), wrench[r], cov[r], bool(contact[r]), float(statistic[r]), b[r], b_sd[r])
                for r in range(m)]

    def _irregular(self, present):
        """The polynomial fitted to the poses the window holds; ``(P, sum c2^2)``, or None where they are too few
        or all on one side of the time it is read at (a stale pose stream: no extrapolation)."""
        fitted = self._fit(present)
        if fitted is None:
            return None
        P, c = fitted
        return P, float(np.sum(c[2] ** 2))

    def _fit(self, present):
        """The polynomial fitted to the samples the window holds: ``(P, c)``, the value and first two
        derivatives (3, n_channels) and their coefficients (3, n_present); None as for :meth:`_irregular`."""
        rows = np.flatnonzero(present)
        if len(rows) < self.order + 3:
            return None
        s = (rows - (self._k - 1 - self._lead)) * self.dt             # each pose's time from the evaluation time
        if s.min() > 0 or s.max() < 0:                                 # no pose on one side: an extrapolation
            return None
        V = np.vander(s, self.order + 1, increasing=True)
        pinv = np.linalg.pinv(V)                                      # (order + 1, n): the polynomial's coefficients
        c = np.array([pinv[0], pinv[1], 2 * pinv[2]])
        P = c @ np.array([self._poses[i] for i in rows])
        return P, c


class _RunningNoise:
    """A motion channel's noise variance from the second differences of its samples (the last three that came):
    a white noise of sd ``sigma`` on a signal smooth at the sample rate gives differences of variance
    ``6 sigma^2``."""

    def __init__(self, size):
        self.recent = deque(maxlen=3)
        self.sum, self.n = np.zeros(size), 0

    def add(self, values):
        if values is None:
            return
        self.recent.append(values)
        if len(self.recent) == self.recent.maxlen:
            self.sum += np.square(self.recent[2] - 2 * self.recent[1] + self.recent[0])
            self.n += 1

    def variance(self):
        return self.sum / (6 * self.n) if self.n else np.zeros_like(self.sum)

