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

The motion's source is a type (``motion=``, :mod:`fmscal.analysis._motion`): the sensor frame's poses
(:class:`PoseMotion`, the default), joint states with the robot's URDF (:class:`JointMotion`: pinocchio's frame
velocity and *classical* acceleration, (C5)) and an IMU on the tool (:class:`ImuMotion`: its specific force moved
to the sensor's point, (C6), read at ``R = I`` so that no pose and no gravity vector is needed, (C7)). Their
channels (the poses; the joint angles; the IMU's rate and specific force) go through the same filters, offline
both ways and causally with the same stated delay; only the accelerations the source does not measure are
differentiated. A stream is as of the readings' times unless its source's ``latency`` says how late it is (a
pose stream's default the calibration's; ``JointMotion(..., latency=)``, ``ImuMotion(..., latency=)``): offline
the stream is moved onto the readings' times, causally the filter is read that much nearer its newest sample.

**One step.** Every path (offline, causal, :class:`Compensator`'s push and push_many, and through them the ROS 2
node) hands the rows' :class:`Motion` to one function, :func:`_step`: the payload's wrench (C2), the contact
wrench (C1), its covariance (C3) and test (C4), the offset's tracker (D1)-(D3), the output's axes and point (C8).

**Stamps.** The causal filter assumes evenly spaced samples (:class:`Compensator`'s ``dt``). Each push's stamp is
placed on that grid: the first intervals must be ``dt`` (within :data:`DT_TOLERANCE`, else an error names both);
a reading whose stamp repeats the last one, or falls within half a step after it (its grid cell: a second
publisher interleaving), is dropped (``duplicate``); a gap of ``g`` missing samples is filled
with ``g`` empty rows (no reading, no motion: the fit takes the samples the window holds), the readings whose
output falls due inside the gap withheld (``gap``); a gap longer than the filter's window and delay, a stamp
stepping back restarts the window (``restart``): no output until it is full again; so does
:meth:`Compensator.restart`, for a break the stamps do not show. Each is counted by cause in
:attr:`Compensator.events`, and the first of each kind said in :attr:`Compensator.warnings`. A stamp off the grid
(its interval from the last further than :data:`GRID_SLIP` of a step from a whole number of steps: a clock that
jitters, a phase that slipped) takes the cell its interval rounds to, and each window that holds it is fitted at its
samples' own times (the filter's polynomial solved for them, :func:`_fit_coefficients`, as for a window with
samples missing), not read as evenly spaced.

**Glitches** of the motion. A motion sample that keeps its form (a unit quaternion turned by a degree, a joint
angle a burst of counts off) passes every check of its values, and through the filter's derivatives would move the
outputs far beyond their covariance. Each sample is compared with the cubic fitted to the stream's last
:data:`GLITCH_SAMPLES` samples (at their own times), read at its time, ``c`` that read-out's coefficients
(:func:`_fit_coefficients`)::

    z_j = (x_j - c . X_j) / (sigma_j sqrt(1 + c . c))                                            (G1)

``X_j`` channel ``j`` of those samples, ``sigma_j`` its noise sd: a pose column's from the noise model
(:meth:`fmscal.plant.Model.pose_sd`), a joint's, an IMU's or a payload file's pose stream's the running estimate as of
the samples before it, once it holds :data:`GLITCH_WARMUP` differences (no check before; each difference enters it
bounded, eq. (G3) of :class:`_RunningNoise`, so that a glitch among the samples no check sees does not widen it for
good); a channel whose sd is zero
(poses given as exact, a joint held exactly still) is not checked. With the noise's own sd, the cubic's bias on a
smooth motion at 1 kHz is far below it (the largest ``|z|`` over a run of a UR5 is the noise's alone down to joint
noise of 1e-9 rad); a stream sampled coarsely for its motion (poses at 25 Hz) is predicted less well than its noise,
and its bound scales with its own predictions::

    bound = GLITCH_SD max(1, median(max_j |z_j|) / m_n)                                          (G2)

the median over its last :data:`GLITCH_WARMUP` samples, ``m_n`` that median for ``n`` channels of white noise
(``Phi^-1((1 + 2^(-1/n)) / 2)``: 0.674 for one, 1.60 for six), none checked before it holds as many.

A sample whose largest ``|z_j|`` exceeds the bound is a glitch: taken as missing (the windows that would hold it fit
the samples they hold, as for a gap), counted (``glitch``: a run once, a pair at most twice) and said. Its
quaternion's sign is not the next sample's reference. A sample after a glitch that lies at the glitch's offset
(its residuals ``r_j / sigma_j`` within half the glitch's largest of them) goes on with it, within the bound or
not: predicted across the glitch, a motion that stepped by a little more than the bound reads within it at the next
sample, and taken as data the step moved the outputs tens of sd for the filter's window.
:data:`GLITCH_RUN` glitches in a row:

- whose residuals ``r_j / sigma_j`` share one offset (the last's within half the first's largest of it) are the
  motion's jump (a tracker that re-acquired, a joint re-homed): the motion before them is forgotten and the stream
  goes on from them, counted (``jump``); an output whose window then holds too few samples either side of its time
  gives none, counted in :attr:`Compensator.withheld` (``jump``);
- otherwise the motion turned off the cubic (an acceleration that stepped, a noise that grew): they are its own
  samples, put back in the window, and the stream goes on with them; not counted.

A glitch below the bound enters the next sample's prediction (the newest sample weighs 1.45 in it) and can make that
one look off: a sample off the prediction makes the sample before it the glitch instead where that one's ``|z|`` was
beyond half the bound and the prediction without it (from the :data:`GLITCH_SAMPLES` samples before that) takes this
one within half the bound. No prediction is made across a hole: where the predicted sample lies more than four times
the predicting samples' mean interval after the newest of them. A stream's first samples, and those after a gap or
a restart (before :data:`GLITCH_SAMPLES` samples are in again), are not checked. :meth:`Compensator.push_many`
checks each row as :meth:`Compensator.push` would, and cuts its blocks before a glitch.

**Noise** of a payload file's stream. A payload file (:mod:`fmscal.analysis._setup`) holds no pose noise, and a
table's fit holds its rows' noise, not a sample's: a :class:`Compensator` given none estimates the poses' from
their second differences as they come (the model's :meth:`~fmscal.plant.Model.pose_sd` fitted to each column's), and
the readings' from its first readings, with no output before them, by the rule a log's noise model is measured
with (:func:`fmscal.plant.io.wrench_noise`, eqs. N1-N3 of ``plant/io/_noise.py``): each channel's sd by the robust
difference estimate, or, where its spectrum shows a correlation in time (a sensor's filter, an average), the
spectrum's sd and correlation time. The spectrum needs :func:`fmscal.plant.io.colour_samples` readings (4 s at any
rate above 160 Hz: 4002 at 1 kHz), the default count; fewer (``noise_samples``, at least
:data:`NOISE_SAMPLES`), or readings too slow for its bands, take the noise as white with a warning, as a
coloured noise read by its differences is read small.

**The output's axes and point** (``frame``, ``point``). With ``r_t`` the tool point (sensor axes, from the
sensor's point) and ``R`` the sensor's attitude (``frame="base"``), the published wrench and its covariance
are moved by one linear map::

    M = blockdiag(R, R) [[I, -[r_t]x], [0, I]],    w -> M w,    Cov -> M Cov M^T                   (C8)

(the force unchanged by the point, the torque about the tool ``tau_t = tau_s - r_t x f``). The contact test
(C4) is the same in any axes and point (``M`` is invertible), and the offset's tracker runs in the sensor's.

Where most samples are flagged a contact, :func:`compensate` asks whether the calibrated readings
``w_s`` follow the payload's wrench at another scale or sign, block by block (torques, forces), by the least
squares slope of their changes about the mean::

    k = sum (w_s - mean w_s) . (W_p - mean W_p) / sum |W_p - mean W_p|^2                            (C9)

A slope near 1000 (or 1/1000) names readings in mN or N mm (or kN); near -1, the reading's other sign
convention (or gravity given reversed, or a steady push of twice the tool's weight along it, which gives the
forces the same slope); each a warning beside the contacts, with the checks ``identify-payload`` runs on its data
(poses and joint states; an IMU's stream and a planar log have none of them). Causally, eq. (C9) is fitted where
the output is in the sensor's axes at its point (no ``frame``, ``point`` or mounting).

The covariance of ``w_e`` per sample is the sum of three independent parts::

    Cov = S Sigma_r S^T + J cov J^T + A^-1 Sigma_a A^-T                                           (C3)

``Sigma_r`` the reading's noise (``diag(wrench_sd^2)``, the calibration's noise model or the log's,
:func:`fmscal.plant.io.estimate_noise`): its variance sample by sample, which for a noise a sensor's filter or an
average correlated in time is measured from its spectrum (eqs. N1-N3 there), and which (C4) tests each sample
against (the correlation changes how the false alarms bunch, not their rate); ``cov`` the calibration's
covariance of ``vec([S | c])`` (row order), ``J = I (x) [sigma w_hat; 1]^T`` (``I (x) (sigma w_hat - b)^T``
where ``cov`` is of ``S`` alone; entries the data left undetermined, infinite in ``cov``, are left out and a
warning says so); and ``Sigma_a`` the accelerations' noise, the pose's noise through the second-derivative filter
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

Where the readings' noise is correlated in time (``tau`` of eq. (N2) of :mod:`fmscal.plant.io._noise`: a sensor's
filter, an average), the offset, which averages many samples, sees their long-run variance ``sd^2 tau``, not
``sd^2``: the gain and ``P`` take it, the test (D2) and the covariance published the sample's own::

    K = P S^T (Cov_total + S diag(sd^2 max(tau - 1, 0)) S^T)^-1                                  (D6)

(taken as white, the offset's sd came out ``sqrt(tau)`` times too small).

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

from collections import Counter, deque
from dataclasses import dataclass, field, replace
from functools import lru_cache

import casadi as ca
import numpy as np
from scipy.signal import savgol_coeffs
from scipy.stats import binom, chi2, norm

from fmscal.plant import Calibration
from fmscal.plant.io import (MAX_WRIST_MASS, STALL_SPREAD, PoseTable, UnitsError, check_spatial_log_units,
                             check_table_units, colour_samples, difference_noise, reading_sign, stalled_poses,
                             wrench_noise)
from fmscal.plant.numerics import FmscalError
from fmscal.plant.physics import MODELS, NoiseSpec, regressor, rotation_matrices, sign_continuous, skew
from fmscal.observers.payload import PayloadEstimate

from ._motion import configuration_variance, kinematics, source
from ._setup import Setup, payload_jacobian, setup
from ._tool_change import GUARD, REIDENTIFY_POSES, TOOL_CHANGE, ToolChangeError, _Detector, check_mode, new_setup

__all__ = ["compensate", "Compensation", "Compensator", "ContactSample", "compensation_model", "DIRECTIONS",
           "OFFLINE_WINDOW", "CAUSAL_WINDOW", "CAUSAL_DELAY", "CAUSAL_ORDER", "FALSE_ALARM", "DRIFT_INTENSITY",
           "FRAMES", "DRIFT_FIT_GRID", "DRIFT_FIT_LIMITS", "DT_TOLERANCE", "EVENTS"]

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
#: :class:`Compensator`: the median of its first :data:`DT_INTERVALS` stamps' intervals must be ``dt`` within this
#: fraction (module docstring, Stamps).
DT_TOLERANCE = 0.1
DT_INTERVALS = 8
#: A window whose stamps lie further than this fraction of ``dt`` from a grid (an interval not near a whole number
#: of steps: a jittering clock, a phase that slipped) is fitted at its samples' own times (module docstring,
#: Stamps). Read as evenly spaced, samples off the grid bias the filter's derivatives beyond the covariance. (Above
#: a stamp's rounding: a float of epoch seconds holds 0.24 us, 1e-3 of a step at 5 kHz.)
GRID_SLIP = 0.01
#: The fewest rows :meth:`Compensator.push_many` fits as one block (fewer go one at a time: the block's fixed cost
#: is higher, ``python benchmarks/compensation.py --blocks``).
BLOCK_MIN = 3
#: The most rows (G1) checks one at a time (more: vectorised over sliding windows, whose fixed cost is higher).
GLITCH_LOOP = 16
#: A payload file's stream of poses: their noise re-estimated every this many poses (:class:`Compensator`).
POSE_NOISE_EVERY = 100
#: A motion stream's running noise estimate: three samples make a second difference only where the longer of
#: their two intervals is within this factor of the shorter (:class:`_RunningNoise`: across a hole, a sample
#: missing, the motion's curvature would enter; a stamp's jitter is within it).
EVEN = 1.5
#: A motion stream's running noise estimate: a second difference's term larger than this many times the estimate
#: enters at that bound (:class:`_RunningNoise`, eq. (G3)); a term of white Gaussian noise (its variance times a
#: chi-square of one degree of freedom) exceeds it with probability 1.5e-12.
RUNNING_BOUND = 50.0
#: A motion stream's running noise estimate: the most first terms that wait for a level to bound them by (G3).
RUNNING_OPEN = 1000
#: The median of a chi-square of one degree of freedom: the level the first :data:`GLITCH_WARMUP` terms' median
#: reads (G3).
CHI2_MEDIAN = 0.45493642311957283
#: A payload file's stream without the readings' noise: the fewest first readings it is estimated from (their
#: differences: white), no output before; by default as many as its colour needs (module docstring, Noise).
NOISE_SAMPLES = 500
#: A motion sample further than this many of its sd from the motion its last :data:`GLITCH_SAMPLES` samples predict is
#: a glitch (module docstring, Glitches, eq. (G1)).
GLITCH_SD = 8.0
#: The motion samples a sample is predicted from (a cubic through them).
GLITCH_SAMPLES = 11
#: The predictions (and running noise estimate's differences) a stream needs before its samples are checked, and the
#: last predictions' ``|z|`` whose median scales the bound (G2).
GLITCH_WARMUP = 50
#: This many glitches in a row are the motion's jump (a tracker that re-acquired, a joint re-homed): the motion
#: before them forgotten (module docstring, Glitches).
GLITCH_RUN = 3
#: The predicting samples are on the stream's grid (the prediction's coefficients the grid's) within this fraction of a
#: step (a stamp's rounding; off it they are fitted at their own times, as the filter's windows are, :data:`GRID_SLIP`).
GLITCH_SLIP = GRID_SLIP
#: The most samples the causal filter's window (or delay) may span: a ``dt`` far below the stream's step (given in
#: another unit) would otherwise ask for memory by the gigabyte.
WINDOW_SAMPLES = 100_000
#: (L3): a stream learns the inertia (L1) from one sample in this many causal windows (samples whose windows share
#: no sample, and so none of the motion's noise).
INERTIA_SPACING = 1.0
#: The events :attr:`Compensator.events` counts (module docstring, Stamps and Glitches).
EVENTS = ("duplicate", "gap", "restart", "glitch", "jump")


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
    tool_changes : list of ToolChange
        The payload's changes declared (:mod:`fmscal.analysis._tool_change`), oldest first.
    tool_change : ndarray of int, shape (N,), or None
        The changes declared by each row's output (the detector's count); None where it did not run.
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
    tool_changes: list = field(default_factory=list)
    tool_change: np.ndarray = None

    @property
    def sd(self):
        """One-sigma uncertainty of each component, shape (N, n_w)."""
        return np.sqrt(np.maximum(np.einsum("nii->ni", self.cov), 0.0))


# --- the model and its dynamics --------------------------------------------------------------------------------
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
        tool's mass properties, e.g. ``PayloadEstimate.load("payload.json")`` of ``identify-payload``; an
        inertia it does not hold is bounded, (K3) of :mod:`fmscal.analysis._setup`).
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
        payload = setup(calibration, payload).payload                      # an undetermined inertia bounded (K3)
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
    ``[p; p'; p'']`` (3 n_pose), the output ``[x; a; A(x) (column-major); d(x)]`` (:func:`fmscal.analysis._motion.
    kinematics`, then :func:`_dynamics`'s expressions). Evaluated through a :class:`_SampleDynamics` buffer: a
    streamed sample pays no conversion of casadi's matrices."""
    p = ca.SX.sym("p", 3 * model.n_pose)
    n = model.n_pose
    configuration, velocity, acceleration = kinematics(model, p[:n], p[n:2 * n], p[2 * n:])
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
    """:func:`_one_sample` (a pose) and :func:`_dynamics` (a joint or IMU source's state) through casadi's
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
        (1, nv)."""
        m = self.model
        self._x[:] = np.asarray(x, dtype=float).ravel()
        self._state_call()
        A_inv = np.linalg.inv(self._A.reshape(m.n_w, m.nv).T)
        return (A_inv @ (np.asarray(a, dtype=float).ravel() - self._d))[None], A_inv[None]


def _payload_wrench(model, x, a, dynamics=None):
    """``W_p = A(x)^-1 (a - d(x))`` (C2) at each row of ``x`` (N, nx), ``a`` (N, nv); and ``A^-1``. A few rows
    through ``dynamics``' buffer (a :class:`_SampleDynamics`) where given, more through the mapped Function."""
    if dynamics is not None and len(x) <= _ROW_BY_ROW:
        W_p, A_inv = zip(*(dynamics.from_state(x[i:i + 1], a[i:i + 1]) for i in range(len(x))))
        return np.concatenate(W_p), np.concatenate(A_inv)
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


# --- what the step needs besides the motion --------------------------------------------------------------------
class _Parts:
    """What (C1)-(C4) need besides the motion: ``S``, ``b``, the sign, the covariances, the bound; a payload
    file's covariance of ``(m, c, I_c, b)`` (``payload_cov``, (K2) of :mod:`fmscal.analysis._setup`)."""

    def __init__(self, calibration, model, noise, direction, false_alarm, payload_cov=None):
        if direction not in DIRECTIONS:
            raise CompensationError(f"direction must be one of {', '.join(DIRECTIONS)}; got {direction!r}")
        if not (isinstance(false_alarm, float) and 0 < false_alarm < 1):
            raise CompensationError(f"false_alarm must be a probability in (0, 1); got {false_alarm!r}")
        model.check_noise(noise)
        n = model.n_w
        self.n, self.names, self.direction = n, tuple(model.wrench_names), direction
        self.S, self.b = np.asarray(calibration.S, dtype=float), calibration.offset
        self.S_inv = np.linalg.inv(self.S)
        self.sign = reading_sign(calibration.reading)
        self.out_sign = 1.0 if direction == DIRECTIONS[0] else -1.0
        self.set_noise(noise)
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
        self.model, self.payload_cov = model, payload_cov
        self.offset_tracked = self.inertia_learned = False      # their shares of (K2) a tracker's (L1)
        if payload_cov is not None:
            payload = model.payload
            self._J = payload_jacobian(payload.mass, payload.com)                             # (K2)

    def set_noise(self, noise):
        """The readings' share of (C3), ``S Sigma_r S^T``; and the further share of their long-run variance the
        offset's gain takes (D6), None where the noise is white."""
        var = np.square(np.asarray(noise.wrench_sd, dtype=float))
        self.reading_cov = self.S @ np.diag(var) @ self.S.T
        tau = getattr(noise, "wrench_tau", None)
        more = None if tau is None else var * np.maximum(np.asarray(tau, dtype=float) - 1.0, 0.0)
        self.long_run = None if more is None or not more.any() else self.S @ np.diag(more) @ self.S.T

    def regressor(self, motion):
        """The Newton-Euler regressor ``Y`` (N, n_w, 10) of the rows' motion (K2), where a payload file's
        covariance is carried; None otherwise."""
        if self.payload_cov is None:
            return None
        model = self.model
        x, a = motion.x, motion.a
        q = x[:, list(model.q_index)][:, 3:7]
        omega = x[:, list(model.v_index)][:, 3:]
        return regressor(q / np.linalg.norm(q, axis=1, keepdims=True), omega, a[:, 3:], a[:, :3], model.gravity)

    def noise(self, A_inv, accel_var):
        """The first and third terms of (C3), the share independent from sample to sample: the reading's noise
        and the motion's; ``accel_var`` (nv,) for every row, or (N, nv)."""
        accel_var = np.asarray(accel_var, dtype=float)
        return self.reading_cov + (np.einsum("nij,j,nkj->nik", A_inv, accel_var, A_inv) if accel_var.ndim == 1
                                   else np.einsum("nij,nj,nkj->nik", A_inv, accel_var, A_inv))

    def covariance(self, signed, noise, Y=None):
        """(C3) for rows of signed readings ``signed`` (N, n_w): their :meth:`noise` and the calibration's term; a
        payload file's term (K2) at the rows' regressor ``Y`` (:meth:`regressor`)."""
        cov = noise
        if self.cov4 is not None:
            u = np.concatenate([signed, np.ones((len(signed), 1))], axis=1) if self.m == self.n + 1 \
                else signed - self.b
            cov = cov + np.einsum("na,iajb,nb->nij", u, self.cov4, u)
        if self.payload_cov is not None:
            G = np.concatenate([Y @ self._J, np.broadcast_to(self.S, (len(Y), 6, 6))], axis=2)      # (K2)
            if self.offset_tracked:
                G[:, :, 10:] = 0.0
            if self.inertia_learned:
                G[:, :, 4:10] = 0.0
            cov = cov + G @ self.payload_cov @ np.swapaxes(G, 1, 2)
        return cov

    def inertia_cov(self):
        """A payload file's inertia's covariance (6, 6), the (L1) tracker's start; None where none is carried."""
        return None if self.payload_cov is None else self.payload_cov[4:10, 4:10].copy()

    def offset_cov(self):
        """The covariance of ``b``: a payload file's (K2), or the calibration's (``c = -S b``: ``S^-1 Cov(c) S^-T``);
        zero where neither holds one."""
        if self.payload_cov is not None:
            return self.payload_cov[10:, 10:].copy()
        if self.cov4 is None or self.m != self.n + 1:
            return np.zeros((self.n, self.n))
        return self.S_inv @ self.cov4[:, self.n, :, self.n] @ self.S_inv.T

    def finish(self, signed, W_p, cov, tracker=None, t=None, Y=None):
        """(C1), (C4) for rows of signed readings (N, n_w), payload wrenches ``W_p`` and their (C3) ``cov``; with an
        :class:`_OffsetTracker`, (D1)-(D3), (L1) sample by sample at times ``t`` (``Y`` the rows' regressor, the
        intensity fitted first where (D5) asks), ``Cov_total`` the covariance. ``(w_e, cov, d^2, b, sd(b))``, the
        last two None where the offset is not tracked."""
        if tracker is None:
            w_e = W_p - (signed - self.b) @ self.S.T
            statistic = np.einsum("ni,ni->n", w_e, np.linalg.solve(cov, w_e[..., None])[..., 0])
            return w_e, cov, statistic, None, None
        Y_I = None if not tracker.k else Y[:, :, 4:]                  # the inertia's columns (L1)
        if tracker.q2 is None:                                                                 # (D5)
            w_e0 = W_p - (signed - tracker.b) @ self.S.T
            tracker.fit(t, w_e0 if Y_I is None else w_e0 + Y_I @ tracker.dI, cov, Y_I)
        rows = (zip(t, signed, W_p, cov) if Y_I is None else zip(t, signed, W_p, cov, Y_I))
        steps = [tracker.step(*row) for row in rows]
        w_e, total, statistic, b, b_sd = zip(*steps)
        tracked = tracker.tracks_offset
        return (np.array(w_e), np.array(total), np.array(statistic), np.array(b) if tracked else None,
                np.array(b_sd) if tracked else None)


class _Output:
    """The output's axes and point (C8): ``M = blockdiag(R, R) T(r_t)`` (``R`` only for ``frame="base"``), the
    wrench ``M w`` and its covariance ``M Cov M^T``; the identity, and not applied, for the sensor's axes and
    point."""

    def __init__(self, model, frame, point, axes=None):
        if frame not in FRAMES:
            raise CompensationError(f"frame must be one of {', '.join(FRAMES)}; got {frame!r}")
        self.model, self.frame, self.point = model, frame, None
        if point is not None:
            try:
                r = np.asarray(point, dtype=float)
            except (TypeError, ValueError):
                r = None
            if r is None or r.shape != (3,) or not np.isfinite(r).all():
                raise CompensationError(f"point must be 3 finite numbers (the tool point in the sensor's axes, m); "
                                        f"got {point!r}"[:200])
            self.point = r
        self.identity = frame == FRAMES[0] and point is None and axes is None
        if not self.identity and model.attitude != "quaternion":
            raise CompensationError(f"frame and point move a 6-axis wrench in 3D; the calibration is of a "
                                    f"{model.name} reading: leave frame='sensor' and point=None")
        # the model's axes may be a tracked frame's with the sensor's turned on it (a payload file's mounting,
        # K1): A = M^T turns them into the sensor's; the point is given in the sensor's axes
        self.T = np.eye(6)
        r = self.point if axes is None or self.point is None else np.asarray(axes, dtype=float).T @ self.point
        if r is not None:
            self.T[:3, 3:] = -skew(r)                                 # tau_t = tau_s - r_t x f
        if axes is not None and frame == FRAMES[0]:                   # the sensor's own axes
            self.T = _blocks(np.asarray(axes, dtype=float)) @ self.T

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
            M = _blocks(R) @ M
        return np.einsum("nij,nj->ni", M, wrench), M @ cov @ np.swapaxes(M, 1, 2)


def _blocks(R):
    """``blockdiag(R, R)``, (6, 6) or (N, 6, 6)."""
    R = np.asarray(R, dtype=float)
    B = np.zeros(R.shape[:-2] + (6, 6))
    B[..., :3, :3] = R
    B[..., 3:, 3:] = R
    return B


def _pose_attitudes(x, model):
    """The sensor frame's attitude ``R`` (N, 3, 3) of rows of the state ``x`` (a unit quaternion's)."""
    q = x[:, list(model.q_index)][:, 3:7]
    return rotation_matrices(q, normalise=True)


# --- the one step ------------------------------------------------------------------------------------------------
@dataclass
class _Rows:
    """What :func:`_step` gives for rows of samples: the published wrench, its covariance (with the offset's,
    (D2)), the contact flag and ``d^2``; the offset and its sd after each row (None without a tracker); the
    payload's wrench ``W_p`` and the rows' own (C3), for tare; the contact wrench ``w_e`` of (C1) in the model's
    axes and its noise (:meth:`_Parts.noise`), with the further share of the readings' long-run variance (D6; None
    where they are white), for the tool change's detector (:mod:`fmscal.analysis._tool_change`)."""

    wrench: np.ndarray
    cov: np.ndarray
    contact: np.ndarray
    statistic: np.ndarray
    offset: np.ndarray
    offset_sd: np.ndarray
    W_p: np.ndarray
    own: np.ndarray
    w_e: np.ndarray
    noise: np.ndarray
    long_run: np.ndarray = None


def _step(parts, output, tracker, t, w_hat, motion, dynamics=None):
    """Compensation's one step, for rows of samples of any source: motion -> payload wrench -> parts -> output.

    The payload's wrench ``W_p = A(x)^-1 (a - d(x))`` (C2) where the source has not evaluated it; the covariance
    (C3) with the motion's noise ``A^-1 M diag(var) M^T A^-T``; the contact wrench (C1) and its test (C4), with
    the offset's tracker (D1)-(D3) where one runs; the output's axes and point (C8). Every path calls it: the
    offline and causal :func:`compensate`, :meth:`Compensator.push` and :meth:`Compensator.push_many` (and
    through them the ROS 2 node).

    Parameters
    ----------
    parts : _Parts
    output : _Output
    tracker : _OffsetTracker or None
    t : array_like, shape (N,)
        The readings' times, s.
    w_hat : ndarray, shape (N, n_w)
        The raw readings.
    motion : Motion
        Their motion (:mod:`fmscal.analysis._motion`).
    dynamics : _SampleDynamics, optional
        A stream's buffered dynamics, for a few rows.

    Returns
    -------
    _Rows
    """
    model = output.model
    if motion.W_p is None:
        W_p, A_inv = _payload_wrench(model, motion.x, motion.a, dynamics)                     # (C2)
    else:
        W_p, A_inv = motion.W_p, motion.A_inv
    if motion.accel_map is not None:
        A_inv = A_inv @ motion.accel_map                 # Cov(a) = M diag(var) M^T: A^-1 Cov(a) A^-T
    signed = parts.sign * w_hat
    Y = parts.regressor(motion)
    noise = parts.noise(A_inv, motion.accel_var)
    own = parts.covariance(signed, noise, Y)                                                 # (C3), (K2)
    w_e, cov, statistic, b, b_sd = parts.finish(signed, W_p, own, tracker, t, Y)             # (C1), (C4), (D), (L1)
    R = None
    if output.needs_attitude:
        R = motion.R if motion.R is not None else _pose_attitudes(motion.x, model)
    wrench, cov = output.apply(parts.out_sign * w_e, cov, R)                                 # (C8)
    return _Rows(wrench, cov, statistic > parts.threshold, statistic, b, b_sd, W_p, own, w_e, noise, parts.long_run)


# --- the offset's drift -------------------------------------------------------------------------------------------
class _OffsetTracker:
    """The offset as a random walk (D1) and, where a payload file's poses left it bounded (K3), the payload's
    inertia as a constant learned from the motion (L1), stepped by (D2)-(D3) on each sample; the one
    implementation of every path. ``intensity`` per channel, the reading's units per sqrt(s); ``P0`` the offset's
    initial covariance; ``offset`` False: the offset is not tracked (its covariance zero, no walk);
    ``inertia_cov`` the inertia's initial covariance (6, 6), None where it is not learned.

    The state is ``theta = [b; dI]`` (``dI`` the inertia's departure from the payload's, :data:`fmscal.plant.
    physics.INERTIA_NAMES` order), the measurement (D2)'s with ``H = [S, Y_I]``, ``Y_I`` the inertia's columns of
    the sample's regressor (K2)::

        w_e = W_p + Y_I dI - S (sigma w_hat - b),    Cov_total = Cov + H P H^T                     (L1)

    ``Y_I`` holds the motion's angular acceleration and rates, fitted from a window of noisy samples: successive
    samples' windows share most of their samples, and so their motion's noise; taken as independent, the inertia
    would be learned as if from far more data than it is, its covariance too small, and the offset, correlated
    with it in ``P``, would move beyond its sd with it. A stream's tracker (:class:`Compensator`) therefore learns
    the inertia from one sample in each ``spacing`` s (the causal filter's window: samples of windows that share
    none); the samples between update the offset alone, the inertia's uncertainty considered (a Schmidt update,
    its gain's inertia rows zero, ``P`` in Joseph form with the noise the gain took)::

        K_I = 0,    P' = (I - K H) P (I - K H)^T + K (Cov + Sigma_long) K^T                         (L3)

    ``spacing`` 0 (the default; :func:`compensate`, offline): every sample teaches the inertia (there, learned
    once in the smoothing's 0.2 s, it fitted the example rig's torques measurably worse).
    """

    def __init__(self, parts, intensity, P0, shape=None, offset=True, inertia_cov=None):
        n, k = parts.n, (0 if inertia_cov is None else 6)
        self.parts, self.S, self.n, self.k, self.tracks_offset = parts, parts.S, n, k, offset
        self.q2 = (None if intensity is None else np.square(intensity)) if offset else np.zeros(n)
        self.shape, self.warnings = shape, []
        self.b = np.array(parts.b if parts.b is not None else np.zeros(n), dtype=float)
        self.dI = np.zeros(k)
        self.P = np.zeros((n + k, n + k))
        self.P[:n, :n] = np.asarray(P0, dtype=float) if offset else 0.0
        if k:
            self.P[n:, n:] = inertia_cov
        self.t = None
        self.spacing, self._next = 0.0, None       # (L3): a stream's sets the spacing; the next time it learns

    def _learns(self, t):
        """(L3): whether the sample at ``t`` teaches the inertia (the first at or after the next learning time, the
        time then moved ``spacing`` on; a time stepping back starts afresh)."""
        if not self.k:
            return False
        if self._next is None or t >= self._next - 1e-9 * self.spacing or t < self._next - 2 * self.spacing:
            self._next = t + self.spacing
            return True
        return False

    def _H(self, Y):
        """``H = [S, Y_I]`` (n_w, n + k)."""
        return self.S if not self.k else np.concatenate([self.S, Y], axis=1)

    def step(self, t, signed, W_p, cov, Y=None):
        """One sample: ``(w_e, Cov_total, d^2, b, sd(b))``, ``w_e`` with the predicted offset (D2), (L1); ``Y``
        the sample's inertia regressor where the inertia is learned."""
        n = self.n
        if self.t is not None and self.tracks_offset:
            self.P[:n, :n] += np.diag(self.q2 * max(t - self.t, 0.0))                          # (D1)
        self.t = t
        w_e = W_p - self.S @ (signed - self.b)
        if self.k:
            w_e = w_e + Y @ self.dI                                                            # (L1)
        H = self._H(Y)
        HP = H @ self.P
        total = cov + HP @ H.T
        total = 0.5 * (total + total.T)
        solved = np.linalg.solve(total, np.c_[w_e, HP])                                        # (D2)
        statistic = float(w_e @ solved[:, 0])
        if statistic <= self.parts.threshold:                                                  # (D3)
            long_run = self.parts.long_run
            K = solved[:, 1:].T if long_run is None else np.linalg.solve(total + long_run, HP).T      # (D6)
            if self.k and not self._learns(t):       # (L3); a sample (D3) leaves out does not take the turn
                K[n:] = 0.0
                A = np.eye(n + self.k) - K @ H
                self.P = A @ self.P @ A.T + K @ (cov if long_run is None else cov + long_run) @ K.T
            else:
                self.P = self.P - K @ HP
            theta = np.r_[self.b, self.dI] - K @ w_e
            self.b, self.dI = theta[:n], theta[n:]
            self.P = 0.5 * (self.P + self.P.T)
        if not self.tracks_offset:
            return w_e, total, statistic, None, None
        return w_e, total, statistic, self.b.copy(), np.sqrt(np.maximum(np.diag(self.P)[:n], 0.0))

    def tare(self, b, P):
        """Restart from the offset ``b`` of covariance ``P`` (D4); a learned inertia kept."""
        n = self.n
        self.b = np.array(b, dtype=float)
        self.P[:n, :] = 0.0
        self.P[:, :n] = 0.0
        self.P[:n, :n] = np.array(P, dtype=float)

    @property
    def intensity(self):
        """The random walk's intensity per channel (D1), the reading's units per sqrt(s); None where the offset is
        not tracked."""
        return None if self.q2 is None or not self.tracks_offset else np.sqrt(self.q2)

    @property
    def inertia_sd(self):
        """The learned inertia's departure's sd (6,), None where it is not learned."""
        return None if not self.k else np.sqrt(np.maximum(np.diag(self.P)[self.n:], 0.0))

    def fit(self, t, w_e0, cov, Y=None):
        """Set the intensity to ``s`` times :attr:`shape`, ``s`` maximising (D5) over the rows ``w_e0`` (the
        compensated wrench with this tracker's offset ``b``, (C1)), their covariances ``cov`` (C3), times ``t`` and
        inertia regressors ``Y`` (where it is learned, (L1)); the tracker's state is left as it was. A maximum at
        the grid's edge adds to :attr:`warnings`."""
        first = np.log2(DRIFT_FIT_GRID)
        step, width, (low, high) = first[1] - first[0], len(first) - 1, np.log2(DRIFT_FIT_LIMITS)
        bound = self.parts.threshold
        grid, d2, logdet = np.empty(0), np.empty((len(t), 0)), np.empty((len(t), 0))
        new = first
        while len(new):
            H = self.S if not self.k else np.concatenate([np.broadcast_to(self.S, (len(t), self.n, self.n)), Y], 2)
            q2 = np.zeros((len(new), self.n + self.k))
            q2[:, :self.n] = (2.0 ** new[:, None] * self.shape) ** 2
            more = _likelihood_terms(t, w_e0, cov, H, self.P, q2, bound, self.parts.long_run)
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


def _likelihood_terms(t, w_e0, cov, H, P0, q2, bound, long_run=None):
    """(D1)-(D3), (L1) run for ``K`` intensities at once over rows ``w_e0`` (N, n) (the wrench with the state
    ``theta0`` the trackers start from), their covariances ``cov`` (N, n, n) and times ``t``, from the state's
    covariance ``P0`` (p, p); ``H`` (n, p), or (N, n, p) per row; ``q2`` (K, p) the walks' ``q^2``; ``long_run``
    the readings' further long-run share (D6), None where white (offline only: the inertia learned from every row,
    no (L3)). Returns
    ``d^2`` of (D2) and ``log det Cov_total``, each (N, K): the terms of (D5)."""
    K, p = q2.shape
    Q = np.zeros((K, p, p))
    Q[:, np.arange(p), np.arange(p)] = q2
    P = np.array(np.broadcast_to(P0, (K, p, p)), dtype=float)
    dtheta = np.zeros((K, p))                                   # each tracker's theta - theta0
    d2, logdet = np.empty((len(t), K)), np.empty((len(t), K))
    dt = np.maximum(np.diff(t, prepend=t[0]), 0.0)
    per_row = H.ndim == 3
    for k in range(len(t)):
        Hk = H[k] if per_row else H
        P += Q * dt[k]                                                                         # (D1)
        w = w_e0[k] + dtheta @ Hk.T
        HP = Hk @ P
        total = cov[k] + HP @ Hk.T
        solved = np.linalg.solve(total, np.concatenate([w[:, :, None], HP], axis=2))          # (D2)
        d2[k] = np.einsum("ki,ki->k", w, solved[:, :, 0])
        logdet[k] = np.linalg.slogdet(total)[1]
        gain = np.swapaxes(solved[:, :, 1:] if long_run is None else np.linalg.solve(total + long_run, HP), 1, 2) \
            * (d2[k] <= bound)[:, None, None]                                                  # (D3), (D6)
        dtheta -= np.einsum("kij,kj->ki", gain, w)
        P -= gain @ HP
    return d2, logdet


def _tracker(parts, noise, track_offset, drift_intensity, offset_sd, offline=False, inertia_cov=None):
    """The tracker of the offset (``track_offset``) and of a bounded inertia (``inertia_cov``, (L1); a stream sets its
    ``spacing``, (L3)); None where neither; its settings checked. ``drift_intensity="fit"`` (``offline`` only, and
    its default there) leaves the offset's intensity to (D5), fitted on the log's first pass (:meth:`_Parts.finish`)."""
    if not isinstance(track_offset, bool):
        raise CompensationError(f"track_offset must be True or False; got {track_offset!r}")
    if not track_offset:
        if drift_intensity is not None or offset_sd is not None:
            raise CompensationError("drift_intensity and offset_sd are the offset tracker's: add track_offset=True")
        if inertia_cov is None:
            return None
        parts.inertia_learned = True                     # the bounded inertia's share is the tracker's (K2)
        return _OffsetTracker(parts, None, None, offset=False, inertia_cov=inertia_cov)
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
    parts.offset_tracked = True                          # a payload file's offset's share is the tracker's (K2)
    parts.inertia_learned = inertia_cov is not None
    return _OffsetTracker(parts, None if fit else values["drift_intensity"], P0, shape, inertia_cov=inertia_cov)


def _causal_coefficients(k, order, lead, dt):
    """The causal filter's coefficients: a polynomial of degree ``order`` fitted to ``k`` samples, read ``lead``
    samples before the newest, value and first two derivatives (each (k,), oldest sample first)."""
    return [savgol_coeffs(k, order, deriv=d, delta=dt, pos=k - 1 - lead, use="dot") for d in range(3)]


def _fit_coefficients(s, order, dt):
    """The coefficients of a polynomial of degree ``order`` fitted by least squares to samples at times ``s``
    (..., n) from the time it is read at: value and first two derivatives, (..., 3, n). On an even grid, the
    causal filter's (:func:`_causal_coefficients`); otherwise a window's samples at their own times (module
    docstring, Stamps), or the samples a window with some missing holds."""
    V = (np.asarray(s, dtype=float) / dt)[..., None] ** np.arange(order + 1)        # in steps: well conditioned
    pinv = np.linalg.pinv(V)                                                         # (..., order + 1, n)
    return np.stack([pinv[..., 0, :], pinv[..., 1, :] / dt, 2 * pinv[..., 2, :] / dt ** 2], axis=-2)


@lru_cache(maxsize=None)
def _median_largest(n):
    """``m_n`` of (G2): the median of the largest ``|z|`` of ``n`` independent standard normals."""
    return float(norm.ppf((1 + 0.5 ** (1 / n)) / 2))


def _even(times, dt):
    """Whether each window of stamps ``times`` (M, k; NaN or None rows: a gap's) lies on a grid of ``dt``: every
    interval within :data:`GRID_SLIP` of a whole number of steps."""
    steps = np.diff(np.asarray(times, dtype=float), axis=-1) / dt
    off = np.abs(steps - np.round(steps))
    return ~(off > GRID_SLIP).any(axis=-1)


def _causal_settings(window, delay, order, dt, latency):
    """The window and the delay in samples, checked: ``(k, L, lead)``, the pose window, the reading's delay and
    how far the poses reach past the time they are read at (the pose stream's latency taken off)."""
    for name, value in (("window", window), ("delay", delay)):
        if not (isinstance(value, (int, float)) and np.isfinite(value) and value >= 0):
            raise CompensationError(f"{name} must be a non-negative number of seconds; got {value!r}")
    if not (isinstance(order, int) and 2 <= order <= 7):
        raise CompensationError(f"order must be an integer from 2 to 7 (a second derivative); got {order!r}")
    if window / dt > WINDOW_SAMPLES or delay / dt > WINDOW_SAMPLES:
        raise CompensationError(f"window {window:g} s and delay {delay:g} s are {window / dt:.3g} and "
                                f"{delay / dt:.3g} samples at dt = {dt:g} s: at most {WINDOW_SAMPLES} (dt in s?)")
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


def _noise(st, noise, estimate=None, moves=True):
    """The noise model: given, the calibration's, or the log's (``estimate()``, the source's estimate from it); a
    payload file's holds the readings' noise only, the poses' then the log's (a stream's: estimated as it comes;
    held poses, ``moves`` False, need none)."""
    if noise is not None:
        if not isinstance(noise, NoiseSpec):
            raise CompensationError(f"noise must be a plant.NoiseSpec; got {type(noise).__name__}")
        return noise
    calibration = st.calibration
    own = calibration.noise
    if not moves and st.held_noise is not None:         # a table's payload file, checked on held poses
        return st.held_noise
    if own is not None and len(own.wrench_sd) == calibration.size:
        if st.pose_noise_known or estimate is None or not moves:
            return own
        log = estimate()
        return NoiseSpec(own.wrench_sd, log.angle_sd, log.position_sd)
    if estimate is None:
        raise CompensationError(f"{st.source} holds no noise model: give noise=plant.NoiseSpec(...)")
    if not moves and own is None:                       # held poses: nothing to estimate the noise from
        again = ("identify the tool again (fmscal identify-payload --save)" if st.source == "the payload file" else
                 "calibrate again (fmscal calibrate --save)")
        raise CompensationError(f"neither the pose table nor {st.source} holds the readings' noise (a file written by "
                                f"hand or by an older fmscal holds none): {again}, or give noise=plant.NoiseSpec(...)")
    return estimate()


def _latency_warnings(calibration, motion):
    """The warning that the calibration's latency (its pose stream's) is not the source's, where the source has
    none of its own: its stream is then taken as of the readings' times."""
    if not calibration.latency or motion.latency:
        return []
    return [f"the calibration's latency ({calibration.latency * 1e3:.3g} ms, its pose stream's) is not applied to "
            f"the {motion.source} stream, and it has none of its own: it is taken as of the readings' times (give "
            f"{type(motion).__name__}(..., latency=S), or --motion-latency S, where it lags them)"]


# --- a log ---------------------------------------------------------------------------------------------------------
def _unit_warnings(pose_log, calibration, noise):
    """The checks ``identify-payload`` runs on its data, as warnings: readings in mN or N mm, positions in mm,
    stamps in ms, a quaternion's convention, a dead channel (:func:`fmscal.plant.io.check_spatial_log_units`,
    :func:`fmscal.plant.io.check_table_units`, the payload's mass and centre of mass given), and every pose row
    the same while the readings move beyond :data:`fmscal.plant.io.STALL_SPREAD` of their noise's sd
    (:func:`fmscal.plant.io.stalled_poses`: a stalled tracker). Any of these flags every
    sample a contact; the warning names why. Warnings, not refusals: a log compensated holds contacts, and a tool
    held still and pushed has still poses beside moving readings.

    ``pose_log`` is the source's :meth:`pose_log` (None: nothing to check; a log whose poses make no
    :class:`fmscal.plant.Log`, too few of them, is not checked)."""
    try:
        data = pose_log()
    except FmscalError:
        return []
    if data is None:
        return []
    payload = calibration.payload
    given = dict(mass=payload.mass, com=payload.com, S=calibration.S, max_mass=max(MAX_WRIST_MASS, payload.mass))
    try:
        if isinstance(data, PoseTable):
            check_table_units(data, calibration.gravity, **given)
            return []
        stall = stalled_poses(data, noise.wrench_sd)
        if stall is not None and len(stall[0]) > 1:
            poses, moved = stall
            if np.max(moved) <= STALL_SPREAD:
                return []
            return [f"{data.name}: all {len(poses)} pose rows are the same while the readings move (by up to "
                    f"{np.max(moved):.3g} of their noise's sd): a stalled tracker, whose every change of the reading "
                    "is flagged a contact, or a tool held still and pushed"]
        check_spatial_log_units(data, calibration.gravity, **given)
    except UnitsError as error:
        steady = " or a steady push that large along gravity" if getattr(error, "quantity", None) == "weight" else ""
        return [f"{error} (every contact flagged may be this{steady})"]
    return []


def _scale_warnings(name, names, w_s, W_p, contact):
    """Readings at another scale or sign than the payload's wrench, where most samples are flagged a contact:
    the slope ``k`` of eq. (C9) per block (the torques', the forces'), named where it is within 3x of 1000 or
    1/1000 (a unit) or within 0.3 of -1 (the sign), and 10 of its standard errors from 1. ``w_s`` and ``W_p``
    are rows in the model's axes."""
    if len(contact) < 10 or np.mean(contact) < 0.5:
        return []
    said = []
    for what, cols in (("torques", [i for i, n in enumerate(names) if n[0] in "tM"]),
                       ("forces", [i for i, n in enumerate(names) if n[0] == "f"])):
        y = w_s[:, cols] - w_s[:, cols].mean(axis=0)
        x = W_p[:, cols] - W_p[:, cols].mean(axis=0)
        xx = float(np.sum(x * x))
        if not xx > 0:
            continue
        k = float(np.sum(x * y)) / xx
        k_se = float(np.sqrt(np.sum((y - k * x) ** 2) / max(y.size - 1, 1) / xx))
        if abs(k - 1) < 10 * k_se:
            continue
        unit = ("mN" if what == "forces" else "N mm") if 1e3 / 3 < k < 3e3 else \
            ("kN" if what == "forces" else "kN m") if 1e-3 / 3 < k < 3e-3 else None
        if unit:
            said.append(f"{name}: the {what} read vary {k:.3g} times as much as the payload's (eq. C9), and "
                        f"{np.mean(contact):.0%} of the samples are flagged a contact: readings in {unit}? give "
                        "them in N and N m")
        elif abs(k + 1) < 0.3:
            said.append(f"{name}: the {what} read vary against the payload's (slope {k:.3g}, eq. C9), and "
                        f"{np.mean(contact):.0%} of the samples are flagged a contact: the readings follow the other "
                        "sign convention from the one the calibration or the payload file states (its reading: "
                        "reaction or load), or gravity is given pointing the other way, or a steady push about "
                        "twice the tool's weight holds the tool down")
    return said


def compensate(setup_, /, log, causal=False, *, calibration=None, payload=None, tool_radius=None,
               direction="on_tool", noise=None, window=None, delay=CAUSAL_DELAY, order=CAUSAL_ORDER,
               false_alarm=FALSE_ALARM, track_offset=False, drift_intensity=None, offset_sd=None, motion=None,
               frame="sensor", point=None, tool_change=None):
    """The contact wrench of a log: ``w_e = W_p - S (sigma w_hat - b)`` (C1), its covariance and a contact flag.

    Parameters
    ----------
    setup_ : plant.Calibration or observers.payload.PayloadEstimate
        A calibration (``fmscal calibrate --save``): ``S``, ``b``, the reading's sign, the payload, gravity,
        latency and (where saved) the noise model and the covariance of ``[S | c]``. Or a payload estimate
        (``fmscal identify-payload --save``, ``PayloadEstimate.load``): the sensor's own ``S`` (the identity, or
        ``calibration``'s), the file's offset, gravity, mounting, sign, gains and noise, and the payload's
        covariance carried into the wrench's ((K1)-(K3) of :mod:`fmscal.analysis._setup`).
    log : plant.Log, plant.io.JointLog or plant.io.ImuLog
        A log of the calibration's case (its poses and readings; or, with ``motion``, its joint states or its
        IMU's samples and readings); no contact needed anywhere.
    causal : bool
        False: the motion smoothed both ways (no delay). True: the causal filter (module docstring), the
        result's :attr:`Compensation.delay` its delay: :class:`Compensator` fed the log.
    calibration : plant.Calibration, optional
        With a payload estimate: the sensor's calibrated ``S`` (and its latency); default the identity.
    payload : plant.Payload, plant.SpatialPayload or observers.payload.PayloadEstimate, optional
        With a calibration: replaces its payload (a tool change: ``S`` does not depend on the tool).
    tool_radius : float, optional
        A payload estimate whose inertia its poses did not determine: the tool's radius about its centre of mass,
        m, that bounds it (K3); default twice the centre of mass's distance from the sensor, at least 5 cm.
    direction : {"on_tool", "on_environment"}
        The published wrench: the environment's on the tool, ``w_e`` (default), or the tool's on the
        environment, ``-w_e``.
    noise : plant.NoiseSpec, optional
        The reading's and the pose's noise; default the calibration's, else the log's.
    window : float, optional
        The smoothing window, s: offline default :data:`OFFLINE_WINDOW`; causal :data:`CAUSAL_WINDOW`.
    delay : float
        Causal: where the fitted polynomial is read, s before the newest sample (:data:`CAUSAL_DELAY`); at
        least the motion stream's latency.
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
    motion : PoseMotion, JointMotion or ImuMotion, optional
        The motion's source (:mod:`fmscal.analysis._motion`): None, the log's poses (a :class:`PoseMotion` of
        the calibration's latency); a :class:`JointMotion` (C5) for a :class:`fmscal.plant.io.JointLog`; an
        :class:`ImuMotion` (C6, C7) for a :class:`fmscal.plant.io.ImuLog`. Their streams are as of
        ``t - motion.latency`` for the reading at ``t``.
    frame : {"sensor", "base"}
        The output's axes (C8): the sensor's, or the base's (the world of the poses, the URDF's base, the IMU's
        world; the sensor's attitude rotates the torque and the force).
    point : array_like of 3 floats, optional
        The tool point the torque is taken about, in the sensor's axes from the sensor's point, m (C8); default
        the sensor's point.
    tool_change : {None, "off", "detect", "reidentify"}
        A change of the payload detected and reported (:mod:`fmscal.analysis._tool_change`,
        :attr:`Compensation.tool_changes`); None: "detect" on a 6-axis reading in 3D, "off" otherwise.
        "reidentify" (causal only) goes on with the new payload fitted to the held attitudes after each change;
        offline each change is reported with that fit (``ToolChange.reidentified``), to compensate again with.

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
    st = setup(setup_, payload, calibration, tool_radius)
    calibration = st.calibration
    src = source(motion, calibration.latency or 0.0, log)
    model = compensation_model(calibration, st.payload, src.check_log(log))
    src.check(model)
    if np.shape(log.w_hat)[1:] != (model.n_w,):
        raise CompensationError(f"{log.name}: {np.shape(log.w_hat)[1:]} reading columns; the calibration's reading "
                                f"has {model.n_w}")
    if st.axes is not None and not src.turns_with_mounting:
        raise CompensationError(f"the payload file's sensor is mounted turned on the tracked frame: its motion "
                                f"comes from poses or joint states, not an {src.source} (whose axes are its "
                                "rotation's)")
    noise = _noise(st, noise, lambda: src.log_noise(log), src.moves)
    checked = _unit_warnings(lambda: src.pose_log(log), calibration, noise)
    if causal and not hasattr(log, "dt"):
        raise CompensationError(f"{getattr(log, 'name', 'the data')}: a pose table's rows are held poses, not a "
                                "stream: compensate it offline (causal=False)")
    mode = check_mode(tool_change, model)
    if mode != TOOL_CHANGE[0] and not src.moves:
        if tool_change is not None:
            raise CompensationError(f"{log.name}: a pose table's rows are held poses, not a stream: no tool change "
                                    "to detect between them (leave tool_change None or 'off')")
        mode = TOOL_CHANGE[0]
    if mode == TOOL_CHANGE[2] and not causal:
        raise CompensationError("tool_change='reidentify' goes on with the new payload as the stream goes: causal "
                                "only; offline each change is reported with its held attitudes' fit "
                                "(ToolChange.reidentified), to compensate again with (payload=...)")
    if causal:
        stream = Compensator(st, log.dt, noise=noise, direction=direction,
                             window=CAUSAL_WINDOW if window is None else window, delay=delay, order=order,
                             false_alarm=false_alarm, track_offset=track_offset, drift_intensity=drift_intensity,
                             offset_sd=offset_sd, motion=src, frame=frame, point=point, tool_change=mode)
        given = src.of_log(log)
        out = stream.push_many(log.t, log.w_hat, **{src.keyword: given})
        if not out:
            raise CompensationError(f"{log.name}: no window of the causal filter holds enough {src.source}")
        missing = stream.missing
        if not checked and stream._output.identity:        # the scale (C9): w_s = S (sigma w_hat - b), W_p = w_e + w_s
            rows = np.searchsorted(log.t, [o.t for o in out])
            w_s = (stream._parts.sign * log.w_hat[rows] - stream._parts.b) @ stream._parts.S.T
            w_e = stream._parts.out_sign * np.array([o.wrench for o in out])
            checked = _scale_warnings(log.name, stream._parts.names, w_s, w_e + w_s,
                                      np.array([o.contact for o in out]))
        return _streamed(stream, out, direction, checked + list(stream.warnings) + (
            [f"missing {src.source}: each window fitted to the samples it holds"] if missing else []))
    aligned = src.aligned(log)
    parts = _Parts(calibration, model, noise, direction, false_alarm, st.cov)
    output = _Output(model, frame, point, st.axes)
    tracker = _tracker(parts, noise, track_offset, drift_intensity, offset_sd, offline=True,
                       inertia_cov=parts.inertia_cov() if st.inertia_bounded else None)
    keep, m = src.offline(aligned, model, noise, OFFLINE_WINDOW if window is None else window)
    t = src.times(aligned)[keep]
    rows = _step(parts, output, tracker, t, aligned.w_hat[keep], m)
    if not checked:
        checked = _scale_warnings(log.name, parts.names, rows.W_p - rows.w_e, rows.W_p, rows.contact)    # (C9)
    changes, counts = [], None
    if mode != TOOL_CHANGE[0]:                          # (T1)-(T8), and each change's held attitudes fitted (T9)
        detector = _Detector(model, log.dt, mode, st.cov, false_alarm)
        counts = detector.add(t, aligned.w_hat[keep], m, rows)
        changes = detector.events
        for k, change in enumerate(changes):
            until = changes[k + 1].t if k + 1 < len(changes) else np.inf
            try:
                change.reidentified, table = detector.reidentify(calibration, change.t + GUARD, until=until)
                change.poses = len(table.q)
            except ToolChangeError:
                pass
    return Compensation(t=t, wrench=rows.wrench, cov=rows.cov, contact=rows.contact, statistic=rows.statistic,
                        threshold=parts.threshold, names=parts.names, delay=0.0, direction=direction,
                        warnings=(checked + st.warnings_for(src.moves) + list(parts.warnings)
                                  + _latency_warnings(calibration, src)
                                  + ([] if tracker is None else tracker.warnings)),
                        offset=rows.offset, offset_sd=rows.offset_sd, frame=frame, point=output.point,
                        drift_intensity=None if tracker is None else tracker.intensity, tool_changes=changes,
                        tool_change=counts)


def _stamps(t, rows):
    """A push's time ``t`` (``rows`` None: one number) or a block's times (1-D), checked: finite seconds, or a
    one-line :class:`CompensationError` before the stream takes anything."""
    if rows is None:
        if isinstance(t, (bool, np.bool_)) or np.ndim(t) != 0 or np.iscomplexobj(t):
            raise CompensationError(f"t must be a number of seconds; got {t!r}"[:200])
        try:
            value = float(t)
        except (TypeError, ValueError):
            raise CompensationError(f"t must be a number of seconds; got {t!r}"[:200]) from None
        if not np.isfinite(value):
            raise CompensationError(f"t must be a finite number of seconds; got {value!r}")
        return value
    if np.iscomplexobj(t):
        raise CompensationError("t must be real numbers of seconds; got complex ones")
    try:
        values = np.asarray(t, dtype=float)
    except (TypeError, ValueError):
        raise CompensationError(f"t must be numbers of seconds; got {t!r}"[:200]) from None
    if values.ndim == 0 or (values.ndim == 2 and values.shape[1] == 1):
        values = values.ravel()
    if values.ndim != 1:
        raise CompensationError(f"t must be one column of seconds; got shape {values.shape}")
    if not np.isfinite(values).all():
        r = int(np.argmax(~np.isfinite(values)))
        raise CompensationError(f"t must be finite seconds: row {r} is {float(values[r])!r}")
    return values


def _readings(w_hat):
    """Raw readings as real floats, or a one-line :class:`CompensationError`."""
    if np.iscomplexobj(w_hat):
        raise CompensationError("w_hat must be real numbers; got complex ones")
    try:
        return np.asarray(w_hat, dtype=float)
    except (TypeError, ValueError):
        raise CompensationError(f"w_hat must be numbers; got {w_hat!r}"[:200]) from None


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
                        drift_intensity=None if stream._tracker is None else stream._tracker.intensity,
                        tool_changes=list(stream.tool_changes),
                        tool_change=None if stream._detector is None else np.array([o.tool_change for o in out]))


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
    tool_change : int
        The payload's changes declared by this output (:attr:`Compensator.tool_changes`).
    """

    t: float
    wrench: np.ndarray
    cov: np.ndarray
    contact: bool
    statistic: float
    offset: np.ndarray = None
    offset_sd: np.ndarray = None
    tool_change: int = 0


class Compensator:
    """The causal compensation one sample at a time: a reading and its motion in, the contact wrench out.

    Each :meth:`push` takes the newest sample (time, raw reading, and a pose, joint states or an IMU's sample,
    as ``motion`` declares, or None) and returns the contact wrench of the reading taken :attr:`delay` s
    earlier (:class:`ContactSample`: (C1), (C3), (C4) of the module, (C8) for ``frame`` and ``point``), or
    None until the window is full or where it holds too few motion samples. The motion's channels (the poses,
    the joint angles, or the IMU's rate and specific force) are fitted by the causal filter of
    :func:`compensate`, which feeds a log to one of these. The stamps are placed on the grid of ``dt``: a
    duplicate dropped, a gap filled with empty rows, a stamp stepping back or a gap beyond the window restarting
    it, each counted (module docstring, Stamps; :attr:`events`, :attr:`withheld`).

    Parameters
    ----------
    calibration : plant.Calibration
    dt : float
        The sample time, s (the readings' rate; a motion sample may come with any of them).
    payload, direction, noise, window, delay, order, false_alarm, track_offset, drift_intensity, offset_sd
        As for :func:`compensate` (``noise`` default the calibration's: required where it has none).
    noise_samples : int, optional
        Where neither ``noise`` nor the calibration gives the readings' noise of a sample (a payload file's
        stream): the first readings it is estimated from, no output before (module docstring, Noise); default
        :func:`fmscal.plant.io.colour_samples` (its correlation in time measured, eqs. N1-N3 of
        ``plant/io/_noise.py``), or :data:`NOISE_SAMPLES` where the readings are too slow for that. Fewer than the
        colour needs: the noise taken as white, with a warning. At least :data:`NOISE_SAMPLES`.
    motion : PoseMotion, JointMotion or ImuMotion, optional
        The motion's source (module :mod:`fmscal.analysis._motion`): None, poses of the calibration's latency
        (``push(t, w_hat, pose)``); a :class:`JointMotion` (``push(t, w_hat, joints=(q, dq, ddq))``, ``dq``/``ddq``
        None where not given: then differentiated by the causal filter); an :class:`ImuMotion` (``push(t, w_hat,
        imu=(quaternion_wxyz, angular_velocity, specific_force))``, the IMU's axes: only the angular acceleration
        is differentiated). Either way the delay is the filter's, :attr:`delay`; the stream is as of
        ``t - motion.latency`` for the reading at ``t`` (the filter read that much nearer its newest sample, in
        whole samples).
    frame : {"sensor", "base"}
        The output's axes (C8); "base" needs an attitude (a pose, the joints, or the IMU's orientation).
    point : array_like of 3 floats, optional
        The tool point, sensor axes, m: the torque about it (C8); default the sensor's point.
    tool_change : {None, "off", "detect", "reidentify"}
        A change of the payload detected (:mod:`fmscal.analysis._tool_change`, :attr:`tool_changes`); None:
        "detect" on a 6-axis reading in 3D, "off" otherwise. "reidentify": after each change, the compensation
        goes on with the payload fitted to the next :data:`fmscal.analysis._tool_change.REIDENTIFY_POSES` held
        attitudes (:meth:`reidentify` does it on request).

    Attributes
    ----------
    events : collections.Counter
        The events by cause (:data:`EVENTS`): the stamps' (a duplicate, a gap, a restart) and the motion's (a
        glitch, a jump: module docstring, Glitches).
    withheld : collections.Counter
        The readings given no output, by the same causes (a jump's: those whose window held too few samples after
        it).
    warnings : list of str
        The calibration's and the source's warnings, and the first event of each kind.
    """

    def __init__(self, setup_, /, dt, *, calibration=None, payload=None, tool_radius=None, direction="on_tool",
                 noise=None, window=CAUSAL_WINDOW, delay=CAUSAL_DELAY, order=CAUSAL_ORDER, false_alarm=FALSE_ALARM,
                 track_offset=False, drift_intensity=None, offset_sd=None, motion=None, frame="sensor", point=None,
                 tool_change=None, noise_samples=None):
        if not (isinstance(dt, (int, float)) and np.isfinite(dt) and dt > 0):
            raise CompensationError(f"dt must be a positive number of seconds; got {dt!r}")
        if noise_samples is not None and not (isinstance(noise_samples, (int, np.integer))
                                              and not isinstance(noise_samples, bool)
                                              and noise_samples >= NOISE_SAMPLES):
            raise CompensationError(f"noise_samples must be a whole number of readings, at least {NOISE_SAMPLES}; "
                                    f"got {noise_samples!r}")
        st = setup_ if isinstance(setup_, Setup) else setup(setup_, payload, calibration, tool_radius)
        calibration = st.calibration
        self.model = compensation_model(calibration, st.payload)
        self.motion = source(motion, calibration.latency or 0.0)
        self.motion.check(self.model)
        if st.axes is not None and not self.motion.turns_with_mounting:
            raise CompensationError(f"the payload file's sensor is mounted turned on the tracked frame: its motion "
                                    f"comes from poses or joint states, not an {self.motion.source} (whose axes are "
                                    "its rotation's)")
        self._output = _Output(self.model, frame, point, st.axes)
        self._sample = _SampleDynamics(self.model)
        self.frame, self.point = frame, self._output.point
        # a payload file's stream of poses: their noise estimated as they come (the file holds the readings')
        self._pose_noise = None
        if noise is None and not st.pose_noise_known and not self.motion.estimates_noise:
            self._pose_noise = _RunningNoise(self.motion.channels(self.model))
        # a payload file with no readings' noise of a sample (a table's fit holds its rows'): estimated from the
        # first readings (module docstring, Noise), no output before
        self._first = None
        if noise is None and not st.pose_noise_known and st.calibration.noise is None:
            self._first = []
            noise = NoiseSpec((1.0,) * self.model.n_w)              # replaced once the first readings are in
            self._colour = colour_samples(float(dt))                # the readings eqs. (N1)-(N3) need; None: too slow
            self._noise_samples = (int(noise_samples) if noise_samples is not None
                                   else NOISE_SAMPLES if self._colour is None else max(self._colour, NOISE_SAMPLES))
        noise = _noise(st, noise)
        self._parts = _Parts(calibration, self.model, noise, direction, false_alarm, st.cov)
        self._tracker = _tracker(self._parts, noise, track_offset, drift_intensity, offset_sd,
                                 inertia_cov=self._parts.inertia_cov() if st.inertia_bounded else None)
        self._default_intensity = drift_intensity is None
        self._setup, self._settings = st, dict(direction=direction, false_alarm=false_alarm, track_offset=track_offset,
                                               drift_intensity=drift_intensity, offset_sd=offset_sd)
        mode = check_mode(tool_change, self.model)
        self._detector = None if mode == TOOL_CHANGE[0] else _Detector(self.model, float(dt), mode, st.cov, false_alarm)
        # the newest compensated samples, for tare: (sigma w_hat - S^-1 W_p, Cov of (C3), contact)
        self._last = deque(maxlen=max(1, int(round(TARE_WINDOW / float(dt)))))
        self.dt, self.order, self._noise = float(dt), order, noise
        self._k, self._L, self._lead = _causal_settings(window, delay, order, self.dt, self.motion.latency)
        if self._tracker is not None:
            self._tracker.spacing = INERTIA_SPACING * self._k * self.dt       # (L3): windows that share no sample
        self._coefficients = np.array(_causal_coefficients(self._k, order, self._lead, self.dt))    # (3, k)
        self._c_sums = np.sum(self._coefficients ** 2, axis=1)
        # the last k motion samples' channels and extras (None where none came): the newest, latency samples
        # late, is the motion of the reading lead samples after the one read out, the oldest of the last L + 1
        self._channels = deque(maxlen=self._k)
        self._times = deque(maxlen=self._k)             # their readings' stamps (None: a gap's row)
        self._extras = deque(maxlen=self._k)
        self._readings = deque(maxlen=self._L + 1)      # (t, w_hat) of the last L + 1 samples; w_hat None: a gap
        self._quaternion = self.motion.quaternion(self.model)
        self._last_q = None
        self._var = None                                # a pose stream's configuration variance (its first pose)
        self._running = _RunningNoise(self.motion.channels(self.model)) if self.motion.estimates_noise else None
        self._units_checked = False
        self._t, self._intervals = None, []
        self.events, self.withheld = Counter(), Counter()
        self.missing = False                            # a motion sample missing from a full window, once
        # the glitches' check (G1): the last motion samples taken (t, channels), the glitches in a row (t, channels,
        # |z|), a pose stream's columns' sd, and the read-out of the cubic through samples on the grid
        self._recent_motion = deque(maxlen=GLITCH_SAMPLES + 1)
        self._z_history = deque(maxlen=GLITCH_WARMUP)  # the last samples' |z| (G2)
        self._last_z = None                             # the newest sample's |z| (None: none made)
        self._jumped = False                            # since a jump, no output yet: those withheld counted
        self._suspects = []
        self._pose_sd = None
        self._glitch_c = _fit_coefficients(-self.dt * np.arange(GLITCH_SAMPLES, 0, -1), CAUSAL_ORDER, self.dt)[0]
        self._glitch_scale = float(np.sqrt(1 + self._glitch_c @ self._glitch_c))
        self.warnings = st.warnings + list(self._parts.warnings) + _latency_warnings(calibration, self.motion)

    @property
    def delay(self):
        """The delay the causal filter adds, s: each output is the wrench of the reading this much older."""
        return round(self._L * self.dt, 12)

    @property
    def noise(self):
        """The noise model in use (:class:`fmscal.plant.NoiseSpec`): given, the calibration's, or learned from the
        first readings (module docstring, Noise: its pose noise then the poses' as they come); None until learned."""
        return None if self._first is not None else self._noise

    # --- input ---------------------------------------------------------------------------------------------------
    def _given(self, pose, joints, imu):
        """The motion's value from the keyword its source takes; another keyword refused."""
        given = {"pose": pose, "joints": joints, "imu": imu}
        wanted = self.motion.keyword
        extra = [k for k, v in given.items() if v is not None and k != wanted]
        if extra:
            raise CompensationError(f"this Compensator takes {self.motion.source} ({type(self.motion).__name__}): "
                                    f"{extra[0]}= was given; give {wanted}= only")
        return given[wanted]

    def push(self, t, w_hat, pose=None, *, joints=None, imu=None):
        """Take the newest sample; the contact wrench of the reading :attr:`delay` s older, or None.

        Parameters
        ----------
        t : float
            s.
        w_hat : array_like, shape (n_w,)
            The raw reading.
        pose : array_like, shape (n_pose,), optional
            Poses: the pose stream's newest pose, None (or NaN) where none came with this reading.
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
        t = _stamps(t, None)
        w_hat = _readings(w_hat)
        if w_hat.shape != (self._parts.n,) or not np.isfinite(w_hat).all():
            raise CompensationError(f"w_hat must be {self._parts.n} finite numbers; got {w_hat!r}")
        channels, extras = self.motion.samples(self._given(pose, joints, imu), 1, self.model)
        return self._one(t, w_hat, channels[0], None if extras is None else extras[0])

    def push_many(self, t, w_hat, pose=None, *, joints=None, imu=None):
        """:meth:`push` over rows, vectorised: the same samples, for a block that came together (a backlog).

        Rows whose windows are full are fitted together (one causal filter over the block, one evaluation of the
        dynamics); the others go through :meth:`push`'s path one at a time.

        Parameters
        ----------
        t : array_like, shape (M,)
        w_hat : array_like, shape (M, n_w)
        pose : array_like, shape (M, n_pose), optional
            Poses: NaN rows where no pose came with the reading.
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
        t = _stamps(t, "rows")
        w_hat = _readings(w_hat)
        if w_hat.shape != (len(t), self._parts.n):
            raise CompensationError(f"w_hat must be {len(t)} rows of {self._parts.n} finite numbers; got shape "
                                    f"{w_hat.shape}")
        if not np.isfinite(w_hat).all():
            raise CompensationError(f"w_hat must be finite: row {int(np.argmax(~np.isfinite(w_hat).all(axis=1)))} "
                                    "is not")
        channels, extras = self.motion.samples(self._given(pose, joints, imu), len(t), self.model)
        present = np.isfinite(channels).all(axis=1)
        out = []
        i = 0
        # a re-identification goes on with the new payload from the next block: blocks no longer than the detector's
        cap = self._detector.n if self._detector is not None and self._detector.mode == TOOL_CHANGE[2] else len(t)
        while i < len(t):
            j, last = i, min(len(t), i + cap)
            if self._blockable():       # the contiguous rows with a motion sample each go as one block
                # (one grid cell on: ``_advance``'s one step, neither a duplicate nor a gap; off the grid within it,
                # the windows that hold it fitted at their own times)
                while j < last and present[j] and 0.5 * self.dt <= t[j] - (self._t if j == i else t[j - 1]) \
                        < 1.5 * self.dt:
                    j += 1
            z = None
            if j - i >= BLOCK_MIN:      # cut before a glitch (G1): it goes alone, as push takes it
                clean, z = self._clean_rows(t[i:j], channels[i:j])
                j = i + clean
            if j - i >= BLOCK_MIN:
                out.extend(self._block(t[i:j], w_hat[i:j], channels[i:j], None if extras is None else extras[i:j],
                                       z[:j - i]))
                i = j
                continue
            sample = self._one(float(t[i]), w_hat[i], channels[i], None if extras is None else extras[i])
            if sample is not None:
                out.append(sample)
            i += 1
        return out

    # --- the stamps ------------------------------------------------------------------------------------------------
    def _advance(self, t):
        """Place a stamp on the grid of ``dt`` (module docstring, Stamps): False where the reading is dropped."""
        if self._t is None:
            self._t = t
            return True
        step = t - self._t
        if abs(step) <= 1e-6 * self.dt:
            self._event("duplicate", 1, f"a reading stamped {t:.9g} s twice: the second dropped")
            return False
        if 0 < step < 0.5 * self.dt:                   # the last one's grid cell: it cannot be a sample after it
            self._event("duplicate", 1, f"a reading stamped {t:.9g} s, {step:.3g} s after the last (within half a "
                                        "step): dropped")
            return False
        if step < 0:
            self._restart(f"the stamps stepped back by {-step:.6g} s (to {t:.9g} s)")
            self._t = t
            return True
        if len(self._intervals) < DT_INTERVALS:
            intervals = self._intervals + [step]      # taken only once checked: a refusal leaves the stream as it was
            if len(intervals) == DT_INTERVALS:
                typical = float(np.median(intervals))
                if abs(typical / self.dt - 1) > DT_TOLERANCE:
                    unit = next((u for u, k in (("ms", 1e3), ("us", 1e6), ("ns", 1e9))
                                 if abs(typical / (self.dt * k) - 1) <= DT_TOLERANCE), None)
                    raise CompensationError(f"the stamps come {typical:.6g} s apart; dt is {self.dt:g} s: " + (
                        f"stamps in {unit}? give t in s" if unit else
                        f"give dt={typical:.6g} (the readings' sample time)"))
            self._intervals = intervals
        n = max(1, int(round(step / self.dt)))
        if n - 1 >= self._k + self._L:
            self._restart(f"a gap of {step:.6g} s ({n - 1} samples) beyond the filter's window and delay")
        elif n > 1:
            self._gap(n - 1, step)
        self._t = t
        return True

    def _event(self, cause, withheld, message):
        """Count an event and the readings it withheld; the first of its kind said in :attr:`warnings`."""
        if not self.events[cause]:
            plural = cause + ("es" if cause.endswith("ch") else "s")
            self.warnings.append(message + f" (further {plural} counted in Compensator.events)")
        self.events[cause] += 1
        self.withheld[cause] += withheld
        self.last_event = (cause, message)

    def _gap(self, g, step):
        """``g`` empty rows (no reading, no motion) for a gap: the readings whose output fell due in it withheld."""
        withheld = 0
        for _ in range(g):
            self._readings.append((None, None))
            self._channels.append(None)
            self._times.append(None)
            self._extras.append(None)
            if len(self._readings) > self._L and self._readings[0][1] is not None:
                withheld += 1
        self._forget_noise_runs()
        self._event("gap", withheld, f"a gap of {step:.6g} s ({g} samples) in the stamps: filled with empty rows, "
                                     f"{withheld} outputs withheld at its edge")

    def _forget_noise_runs(self):
        """The running noise estimates' last samples forgotten (a gap, a restart): no difference spans it; nor does
        a glitch's prediction (G1), the glitches held so far counted."""
        self._clear_running()
        self._settle()
        self._recent_motion.clear()
        self._last_z = None

    def _clear_running(self):
        """The running noise estimates' last samples forgotten: the next difference starts after them."""
        for running in (self._running, self._pose_noise):
            if running is not None:
                running.clear()

    def restart(self, why="restarted by the caller"):
        """Start the window again, as a stamp stepping back does (module docstring, Stamps): the readings in it
        get no output, and none comes until it is full again; counted in :attr:`events` and :attr:`withheld`
        (``restart``), the first said in :attr:`warnings` with ``why``. For a break the stamps do not show: a
        motion whose clock stepped back while the readings' went on (the ROS 2 node's pipeline, where the
        readings rejoin that clock). The stamps' grid goes on."""
        self._restart(str(why))

    def _restart(self, why):
        """Start the window again: no output until it is full (module docstring, Stamps)."""
        pending = sum(1 for _, w in list(self._readings)[1:] if w is not None)
        for d in (self._readings, self._channels, self._times, self._extras, self._last):
            d.clear()
        self._forget_noise_runs()
        self._jumped = False
        self._event("restart", pending, f"{why}: the window restarted, no output until it is full again")

    # --- one sample, or a block -------------------------------------------------------------------------------
    def _one(self, t, w_hat, channels, extra):
        """:meth:`push`'s path for one checked sample: ``channels`` NaN where no motion came."""
        if not self._advance(t):
            return None
        if self._first is not None:
            self._learn_noise(w_hat[None])
        channels = self._signed(channels[None])[0] if np.isfinite(channels).all() else None
        if channels is not None and self._glitched(t, channels):
            channels = None                                             # taken as missing (G1)
        if channels is not None and self._quaternion is not None:     # the sign of a sample taken: the next's
            self._last_q = channels[self._quaternion].copy()
        if channels is not None:
            if self._running is not None:
                self._running.add(channels, t)
            else:
                self._pose_variance(channels[None], np.array([t]))
        self._readings.append((t, w_hat))
        self._channels.append(channels)
        self._times.append(t)
        self._extras.append(extra)
        if len(self._readings) <= self._L or len(self._channels) < self._k:
            return None
        t0, reading = self._readings[0]
        if reading is None or self._first is not None:
            return None
        present = [c is not None for c in self._channels]
        if not self._units_checked and any(present):
            self.motion.check_units(np.array([c for c in self._channels if c is not None]))
            self._units_checked = True
        if all(present) and self._window_even():
            P, sums = self._coefficients @ np.array(self._channels), self._c_sums
        else:
            self.missing = self.missing or not all(present)
            fitted = self._fit(present, t0)
            if fitted is None:
                if self._jumped:                                        # the window holds too little since a jump
                    self.withheld["jump"] += 1
                return None
            P, c = fitted
            sums = np.sum(c ** 2, axis=1)
        i0 = self._k - 1 - self._lead                                   # the read-out sample in the window
        if extra is not None:                                          # a source with extras (rates, orientation)
            extra = self.motion.read_out(self._extras_array(), np.array([i0]), i0, self._k)
        raw = self._channels[i0]
        motion = self.motion.motion(self.model, P[:, None, :], sums, self._variance(), extra,
                                    None if raw is None else raw[None], self._sample)
        rows = _step(self._parts, self._output, self._tracker, [t0], reading[None], motion, self._sample)
        self._jumped = False
        self._remember(reading[None], rows)
        return self._sample_of(t0, rows, 0, self._notice(np.array([t0]), reading[None], motion, rows))

    def _window_even(self):
        """:func:`_even` for the window's stamps, in plain arithmetic (one sample's path)."""
        times, dt = self._times, self.dt
        if None in times:
            return False
        previous = None
        for ti in times:
            if previous is not None:
                step = (ti - previous) / dt
                if abs(step - round(step)) > GRID_SLIP:
                    return False
            previous = ti
        return True

    def _blockable(self):
        """Both windows full of samples, none missing: the next rows may go as one block."""
        return (self._t is not None and self._first is None and len(self._intervals) >= DT_INTERVALS
                and len(self._readings) > self._L
                and len(self._channels) == self._k and all(w is not None for _, w in self._readings)
                and all(c is not None for c in self._channels))

    def _block(self, t, w_hat, channels, extras, z):
        """:meth:`push_many`'s rows with the windows full, every sample present and the stamps ``dt`` apart, none a
        glitch; ``z`` their predictions' ``|z|`` (G1; NaN where none was made)."""
        m, k, i0 = len(t), self._k, self._k - 1 - self._lead
        channels = self._continuous(channels)
        if self._running is None:
            self._pose_variance(channels, t)
        var = self._variance() if self._running is None else self._running.block(channels, t)
        window = np.concatenate([np.array(list(self._channels)[1:]), channels])          # (k - 1 + m, n)
        windows = np.lib.stride_tricks.sliding_window_view(window, k, axis=0)           # (m, n, k)
        P = np.einsum("dk,mpk->dmp", self._coefficients, windows)                        # (3, m, n)
        readings = list(self._readings)[1:] + list(zip(t.tolist(), w_hat))
        t0 = np.array([r[0] for r in readings[:m]])
        sums = self._c_sums
        times = np.lib.stride_tricks.sliding_window_view(np.r_[np.array(list(self._times)[1:], dtype=float), t], k)
        uneven = ~_even(times, self.dt)
        if uneven.any():                            # those windows fitted at their samples' own times (Stamps)
            c = _fit_coefficients(times[uneven] - (t0[uneven] + (self._L - self._lead) * self.dt)[:, None],
                                  self.order, self.dt)                                  # (u, 3, k)
            P[:, uneven] = np.einsum("udk,upk->dup", c, windows[uneven])
            sums = np.repeat(self._c_sums[:, None, None], m, axis=1)                     # (3, m, 1): per row
            sums[:, uneven, 0] = np.sum(c ** 2, axis=2).T
        reading = np.array([r[1] for r in readings[:m]])
        rows_out = i0 + np.arange(m)
        extra = None
        if extras is not None:
            extra = self.motion.read_out(np.concatenate([self._extras_array()[1:], extras]), rows_out, i0, k)
        motion = self.motion.motion(self.model, P, sums, var, extra, window[rows_out],
                                    self._sample if m <= _ROW_BY_ROW else None)
        rows = _step(self._parts, self._output, self._tracker, t0, reading, motion,
                     self._sample if m <= _ROW_BY_ROW else None)
        self._remember(reading, rows)
        counts = self._notice(t0, reading, motion, rows)
        self._channels.extend(channels)
        self._times.extend(t.tolist())
        self._recent_motion.extend(zip(t.tolist(), channels))
        self._z_history.extend(z[~np.isnan(z)].tolist())
        self._last_z = None if np.isnan(z[-1]) else float(z[-1])
        if extras is not None:
            self._extras.extend(extras)
        else:
            self._extras.extend([None] * m)
        self._readings.extend(zip(t.tolist(), w_hat))
        self._t = float(t[-1])
        return [self._sample_of(float(t0[r]), rows, r, counts) for r in range(m)]

    # --- glitches of the motion (module docstring, Glitches) ---------------------------------------------------
    def _channel_sd(self):
        """Each motion channel's noise sd for (G1): a pose stream's columns' from the noise model, else the running
        estimate's once it holds :data:`GLITCH_WARMUP` differences; None before."""
        running = self._running if self._running is not None else self._pose_noise
        if running is not None:
            return np.sqrt(running.variance()) if running.n >= GLITCH_WARMUP else None
        if self._pose_sd is None:
            self._pose_sd = np.asarray(self.model.pose_sd(self._noise), dtype=float)
        return self._pose_sd

    def _glitch_z(self, t, rows, sd):
        """(G1) for a block's motion samples ``rows`` (M, n, sign-continuous) at times ``t`` (M,) following the last
        ones taken, each predicted from the :data:`GLITCH_SAMPLES` before it: the largest ``|z_j|`` of each, (M,),
        NaN where none is made (too few before it, a hole, no sd yet), and each row's channels checked, (M,).
        ``sd``: each row's channels' sd (M, n; NaN where not known)."""
        m = len(t)
        if m <= GLITCH_LOOP:                                            # a few rows: one at a time, cheaper
            z, count = np.full(m, np.nan), np.zeros(m, dtype=int)
            before = list(self._recent_motion)
            for i in range(m):
                z[i], count[i], _ = self._glitch_one(float(t[i]), rows[i], before, sd[i])
                before.append((float(t[i]), rows[i]))
            return z, count
        z = np.full(m, np.nan)
        with np.errstate(invalid="ignore"):
            checked = sd > 0
        count = checked.sum(axis=1)
        before = list(self._recent_motion)[-GLITCH_SAMPLES:]
        recent = len(before)
        first = max(0, GLITCH_SAMPLES - recent)                         # the first row with enough before it
        if first >= m or not count.any():
            return z, count
        X = np.concatenate([np.array([r for _, r in before]).reshape(recent, rows.shape[1]), rows])
        T = np.r_[[ti for ti, _ in before], t]
        at = recent + np.arange(first, m) - GLITCH_SAMPLES             # each checked row's first predicting sample
        W = np.lib.stride_tricks.sliding_window_view(X, GLITCH_SAMPLES + 1, axis=0)[at]     # (u, n, G + 1)
        s = np.lib.stride_tricks.sliding_window_view(T, GLITCH_SAMPLES + 1)[at]
        s = s[:, :-1] - s[:, -1:]                                       # (u, G): from the predicted sample
        steps = np.diff(np.c_[s, np.zeros(len(s))], axis=1) / self.dt
        on_grid = np.abs(steps - 1).max(axis=1) <= GLITCH_SLIP
        c = np.broadcast_to(self._glitch_c, s.shape).copy()
        if not on_grid.all():
            c[~on_grid] = _fit_coefficients(s[~on_grid], CAUSAL_ORDER, self.dt)[:, 0]
        spacing = (s[:, -1] - s[:, 0]) / (GLITCH_SAMPLES - 1)
        made = (-s[:, -1] <= 4 * spacing) & (count[first:] > 0)       # no prediction across a hole
        r = np.abs(W[:, :, -1] - np.einsum("uk,unk->un", c, W[:, :, :-1]))
        with np.errstate(divide="ignore", invalid="ignore"):
            e = np.where(checked[first:], r / np.where(checked[first:], sd[first:], 1.0), 0.0)
        zs = e.max(axis=1) / np.sqrt(1 + np.sum(c ** 2, axis=1))
        z[first:] = np.where(made, zs, np.nan)
        return z, count

    def _glitch_one(self, t, row, before=None, sd=None):
        """:meth:`_glitch_z` for one sample ``row`` (n,) at ``t``, in plain arithmetic: ``(|z|, channels checked,
        residuals)``, the residuals in sd ``r_j / sigma_j`` (n,); NaN and None where no prediction is made. ``before``
        default the last samples taken, ``sd`` the current."""
        sd = self._channel_sd() if sd is None else sd
        if sd is None:
            return np.nan, 0, None
        checked = sd > 0                                                # NaN: not known, not checked
        count = int(np.count_nonzero(checked))
        before = self._recent_motion if before is None else before
        if len(before) < GLITCH_SAMPLES or not count:
            return np.nan, count, None
        before = list(before)[-GLITCH_SAMPLES:]
        ts = [ti for ti, _ in before]
        if t - ts[-1] > 4 * (ts[-1] - ts[0]) / (GLITCH_SAMPLES - 1):   # no prediction across a hole
            return np.nan, count, None
        tol, dt = GLITCH_SLIP * self.dt, self.dt
        if all(abs(b - a - dt) <= tol for a, b in zip(ts, ts[1:] + [t])):
            c, scale = self._glitch_c, self._glitch_scale
        else:
            c = _fit_coefficients(np.array(ts) - t, CAUSAL_ORDER, self.dt)[0]
            scale = np.sqrt(1 + c @ c)
        e = np.where(checked, row - c @ np.array([x for _, x in before]), 0.0) / np.where(checked, sd, 1.0)
        return float(np.abs(e).max()) / scale, count, e

    def _bound(self, history, n):
        """(G2): the bound on a prediction's largest ``|z_j|`` over ``n`` channels, :data:`GLITCH_SD` times the
        stream's own scale (the median of its last over white noise's, at least 1); infinite before
        :data:`GLITCH_WARMUP` predictions."""
        if len(history) < GLITCH_WARMUP or n < 1:
            return np.inf
        return GLITCH_SD * max(1.0, float(np.median(history)) / _median_largest(int(n)))

    def _block_sd(self, t, rows):
        """Each of a block's rows' channel sd as :meth:`push` would check it (M, n; NaN where not yet known): a
        running estimate's as it takes the rows before it (a copy of it run through them), else the noise model's."""
        running = self._running if self._running is not None else self._pose_noise
        if running is None:
            sd = self._channel_sd()
            return np.broadcast_to(sd, rows.shape)
        trial, out = running.copy(), np.full(rows.shape, np.nan)
        for i, (row, ti) in enumerate(zip(rows, t)):
            if trial.n >= GLITCH_WARMUP:
                out[i] = np.sqrt(trial.variance())
            trial.add(row, ti)
        return out

    def _signed(self, rows):
        """Rows with their unit quaternion (where the source has one) sign-continuous with the last kept."""
        if self._quaternion is None:
            return rows
        rows = np.array(rows, dtype=float)
        rows[:, self._quaternion] = sign_continuous(rows[:, self._quaternion], self._last_q)
        return rows

    def _clean_rows(self, t, rows):
        """How many of a block's first rows are no glitch (G1, G2), the block going up to the first; and the
        rows' ``|z|``. Each row is checked as :meth:`push` checks it (the noise estimate as of the rows before it)."""
        rows = self._signed(rows)
        z, count = self._glitch_z(t, rows, sd=self._block_sd(t, rows))
        history, made = list(self._z_history), ~np.isnan(z)
        for r in np.flatnonzero(made & (z > GLITCH_SD)):          # the bound is at least GLITCH_SD (G2)
            if z[r] > self._bound((history + z[:r][made[:r]].tolist())[-GLITCH_WARMUP:], count[r]):
                return int(r), z
        return len(t), z

    def _glitched(self, t, row):
        """(G1), (G2) for one motion sample: True where it is a glitch (held with those in a row before it); the
        :data:`GLITCH_RUN`-th in a row is the motion's jump (:meth:`_jump`) or its turn, taken."""
        z, n, e = self._glitch_one(t, row)
        bound = GLITCH_SD if np.isnan(z) or z <= GLITCH_SD else self._bound(self._z_history, n)  # (G2): >= GLITCH_SD
        if not (np.isnan(z) or z <= bound) and not self._suspects \
                and len(self._recent_motion) > GLITCH_SAMPLES and (self._last_z or 0.0) > bound / 2:
            # the sample before it a glitch below the bound, in this one's prediction? (module docstring, Glitches)
            older = list(self._recent_motion)[:-1]
            alone = self._glitch_one(t, row, older)[0]
            if alone <= bound / 2:
                t1, row1 = self._recent_motion.pop()
                self._put_back({t1: None})
                self._z_history.pop()
                self._suspects = [(t1, row1, self._last_z, None)]
                z = alone
        first = self._suspects[0][3] if self._suspects else None
        goes_on = first is not None and e is not None and np.max(np.abs(e - first)) <= 0.5 * np.max(np.abs(first))
        if (np.isnan(z) or z <= bound) and not goes_on:      # (a sample at the glitches' offset goes on with them)
            if self._suspects:
                self._settle()
            self._recent_motion.append((t, row))
            self._last_z = None if np.isnan(z) else z
            if not np.isnan(z):
                self._z_history.append(z)
            return False
        self._last_z = None
        self._suspects.append((t, row, z, e))
        if len(self._suspects) < GLITCH_RUN:
            return True
        first, last = self._suspects[0][3], self._suspects[-1][3]
        if first is not None and np.max(np.abs(last - first)) <= 0.5 * np.max(np.abs(first)):
            self._jump()                                # the run shares one offset: a step of the motion
        else:
            self._turned()                              # the motion turned off the cubic: its samples, late
        return False

    def _settle(self):
        """The glitches held (one run) counted and said: a sample after them fits the motion before them."""
        if not self._suspects:
            return
        t0, n, z = self._suspects[0][0], len(self._suspects), max(s[2] for s in self._suspects)
        self._suspects = []
        self._event("glitch", 0, f"a glitch of the motion ({self.motion.source}): {n} sample{'s' if n > 1 else ''} "
                                 f"from {t0:.9g} s up to {z:.3g} sd from the motion the samples before predict (G1), "
                                 "taken as missing")

    def _jump(self):
        """:data:`GLITCH_RUN` glitches in a row: the motion jumped. The samples before them forgotten (None in the
        window), theirs put back (the newest, not yet in the window, is taken by the caller); the stream goes on
        from them."""
        suspects, self._suspects = self._suspects, []
        self._clear_running()
        self._put_back({ti: row for ti, row, *_ in suspects[:-1]}, forget=True)
        self._recent_motion.clear()
        self._recent_motion.extend((ti, row) for ti, row, *_ in suspects)
        self._last_z = None
        self._z_history.extend(s[2] for s in suspects)                # the motion's own, now
        self._jumped = True
        t0, z = suspects[0][0], max(s[2] for s in suspects)
        self._event("jump", 0, f"the motion ({self.motion.source}) jumped at {t0:.9g} s ({len(suspects)} samples in a "
                               f"row up to {z:.3g} sd from the motion before, G1): the motion before forgotten, no "
                               "output until the window holds samples either side of it")

    def _turned(self):
        """:data:`GLITCH_RUN` samples in a row off the prediction, each further off than the one before (not one
        offset: an acceleration that stepped, a noise that grew): the motion's own, taken late. Put back in the
        window (the newest, not yet in it, is taken by the caller), and the stream goes on with them; not counted."""
        suspects, self._suspects = self._suspects, []
        self._put_back({ti: row for ti, row, *_ in suspects[:-1]})
        for ti, row, z, _ in suspects:
            self._recent_motion.append((ti, row))
            self._z_history.append(z)
        self._last_z = None

    def _put_back(self, rows, forget=False):
        """Set the window's motion samples at the stamps of ``rows`` (``{t: channels}``; None: taken out); with
        ``forget``, every other one of the window's samples forgotten."""
        for i, ti in enumerate(self._times):
            if ti in rows:
                self._channels[i] = rows[ti]
            elif forget:
                self._channels[i] = None

    def _continuous(self, rows):
        """Rows of channels with their unit quaternion (where the source has one) kept sign-continuous with the
        stream's last (q and -q: one attitude)."""
        rows = self._signed(rows)
        if self._quaternion is not None:
            self._last_q = rows[-1, self._quaternion].copy()
        return rows

    def _variance(self):
        """The channels' noise variance: a pose stream's configuration's (the noise model's, at its first pose),
        or the running estimate of a joint or IMU stream's."""
        return self._var if self._running is None else self._running.variance()

    def _learn_noise(self, w_hat):
        """A payload file's stream without the readings' noise: it from the first ``noise_samples`` readings, by a
        log's rule (:func:`fmscal.plant.io.wrench_noise`: the robust difference estimate, robust to a contact's
        steps, and eqs. N1-N3 where a channel's spectrum is not flat); white, with a warning, where they are fewer
        than the colour needs or too slow for it (module docstring, Noise). Until then no output."""
        self._first.extend(w_hat)
        if len(self._first) < self._noise_samples:
            return
        first = np.array(self._first)
        n = len(first)
        if self._colour is not None and n >= self._colour:
            sd, tau = wrench_noise(first, self.dt)
            sd = np.asarray(sd, dtype=float)
        else:
            sd, tau = difference_noise(first), None
        if not (sd > 0).all():
            raise CompensationError("the readings' noise estimated from the first readings is zero (a constant or "
                                    "coarsely quantised reading): give noise=plant.NoiseSpec(...)")
        self._noise = replace(self._noise, wrench_sd=tuple(float(v) for v in sd), wrench_tau=tau)
        self._parts.set_noise(self._noise)
        if self._tracker is not None and self._default_intensity and self._tracker.tracks_offset:
            self._tracker.shape = DRIFT_INTENSITY * sd                 # (D1)'s default: the noise's sd
            self._tracker.q2 = np.square(self._tracker.shape)
        said = f"the readings' noise estimated from the first {n} readings (sd " + " ".join(f"{v:.3g}" for v in sd)
        if tau is not None:
            said += "; correlated in time, tau " + " ".join(f"{v:.3g}" for v in tau) + " samples"
        self.warnings.append(said + "): the payload file holds none of a sample")
        if self._colour is None:
            self.warnings.append(f"readings at {1 / self.dt:.4g} Hz are too slow to measure their noise's correlation "
                                 "in time: taken as white (a sensor's filter or an average would make the contact "
                                 "test's sd small)")
        elif n < self._colour:
            self.warnings.append(f"the readings' noise taken as white from {n} readings: its correlation in time (a "
                                 f"sensor's filter, an average) needs {self._colour} ({self._colour * self.dt:.3g} s; "
                                 "noise_samples); a correlated noise would make the contact test's sd small")
        self._first = None

    def _pose_variance(self, rows, t):
        """A pose stream's configuration variance (:func:`fmscal.analysis._motion.configuration_variance`): the
        noise model's, at its first pose; a payload file's stream (no pose noise given) from the poses' second
        differences as they come (the pose's angle and position sds fitted to each column's by the model's
        :meth:`~fmscal.plant.Model.pose_sd`), again every :data:`POSE_NOISE_EVERY` poses."""
        if self._pose_noise is None:
            if self._var is None:
                self._var = configuration_variance(self.model, self._noise, rows[0])
            return
        for row, ti in zip(rows, t):
            self._pose_noise.add(row, ti)
        n = self._pose_noise.n
        if n and (self._var is None or n // POSE_NOISE_EVERY != (n - len(rows)) // POSE_NOISE_EVERY):
            var = self._pose_noise.variance()
            sds = []
            for unit in ((1.0, 0.0), (0.0, 1.0)):                     # each column's sd per unit angle, position
                per = np.asarray(self.model.pose_sd(NoiseSpec(self._noise.wrench_sd, *unit)), dtype=float)
                used = per > 0
                sds.append(float(np.sqrt(np.mean(var[used] / per[used] ** 2))) if used.any() else 0.0)
            spec = NoiseSpec(self._noise.wrench_sd, *sds)
            self._var = configuration_variance(self.model, spec, rows[-1])

    def _extras_array(self):
        """The window's extras as rows (NaN where none)."""
        width = next((len(e) for e in self._extras if e is not None), 0)
        return np.array([np.full(width, np.nan) if e is None else e for e in self._extras])

    def _remember(self, reading, rows):
        """Keep the newest outputs' ``sigma w_hat - S^-1 W_p``, their own (C3) and contact flag, for tare (D4)."""
        found = self._parts.sign * reading - rows.W_p @ self._parts.S_inv.T
        for r in range(max(0, len(found) - self._last.maxlen), len(found)):
            self._last.append((found[r], rows.own[r].copy(), bool(rows.contact[r])))

    @staticmethod
    def _sample_of(t, rows, r, counts=None):
        return ContactSample(t, rows.wrench[r], rows.cov[r], bool(rows.contact[r]), float(rows.statistic[r]),
                             None if rows.offset is None else rows.offset[r],
                             None if rows.offset_sd is None else rows.offset_sd[r],
                             0 if counts is None else int(counts[r]))

    # --- a tool change ---------------------------------------------------------------------------------------
    def _notice(self, t, reading, motion, rows):
        """The tool change's detector on the rows (T1)-(T8) and, where due, a re-identification (T9); the changes
        declared by each row (None where detection is off)."""
        if self._detector is None:
            return None
        counts = self._detector.add(t, reading, motion, rows)
        if self._detector.due():
            try:
                self._reidentify(poses=REIDENTIFY_POSES)
            except ToolChangeError:
                pass                                   # not yet: more held attitudes to come
        return counts

    @property
    def tool_changes(self):
        """The payload's changes declared so far (:class:`fmscal.analysis._tool_change.ToolChange`), oldest first;
        empty where detection is off. The list itself: its length counts them."""
        return [] if self._detector is None else self._detector.events

    def reidentify(self, since=None):
        """Re-identify the payload from the held attitudes since the last tool change (T9) and go on with it.

        The blocks' mean attitudes and raw readings since ``since`` (default the last declared change's time, else
        the oldest kept, :data:`fmscal.analysis._tool_change.REIDENTIFY_BUFFER` s) are fitted statically at their
        held segments: the new mass and centre of mass; the inertia bounded (K3) and learned (L1); the offset
        kept. The compensation, and the detector, go on with it from the next sample.

        Parameters
        ----------
        since : float, optional
            s: the held attitudes from this time on.

        Returns
        -------
        observers.payload.StaticFit
            The fit; the last :class:`~fmscal.analysis._tool_change.ToolChange` records it.

        Raises
        ------
        FmscalError
            Detection is off, too few held attitudes, or a fit that does not determine the payload (one line).
        """
        if self._detector is None:
            raise ToolChangeError("re-identification works on the tool change's detector: give tool_change='detect' "
                                  "or 'reidentify' (a 6-axis reading in 3D)")
        return self._reidentify(since)

    def _reidentify(self, since=None, poses=None):
        detector = self._detector
        fit, table = detector.reidentify(self._setup.calibration, since, poses)
        self._use(new_setup(self._setup, self._setup.calibration, fit))
        if detector.events and since is None:
            change = detector.events[-1]
            change.reidentified, change.poses, change.reidentified_at = fit, len(table.q), self._t
        return fit

    def _use(self, st):
        """Go on with a new payload (T9): the model, its dynamics, (C3)'s parts and the tracker made anew; the
        offset, its covariance and intensity, the filter's windows and the stamps kept."""
        old_parts, old = self._parts, self._tracker
        self._setup = st
        self.model = compensation_model(st.calibration, st.payload)
        self._sample = _SampleDynamics(self.model)
        self._output = _Output(self.model, self.frame, self.point, st.axes)
        s = self._settings
        self._parts = _Parts(st.calibration, self.model, self._noise, s["direction"], s["false_alarm"], st.cov)
        self._parts.b = old_parts.b
        self._tracker = _tracker(self._parts, self._noise, s["track_offset"], s["drift_intensity"], s["offset_sd"],
                                 inertia_cov=self._parts.inertia_cov() if st.inertia_bounded else None)
        if self._tracker is not None:
            self._tracker.spacing = INERTIA_SPACING * self._k * self.dt       # (L3), as in __init__
        if old is not None and old.tracks_offset and self._tracker is not None:
            n = self._parts.n
            self._tracker.b, self._tracker.q2, self._tracker.t = old.b.copy(), old.q2, old.t
            self._tracker.P[:n, :n] = old.P[:n, :n]
        self._last.clear()
        self._detector.use(self.model, st.cov)

    def _fit(self, present, t0):
        """The polynomial fitted to the samples the window holds, at their own times (their readings' stamps):
        ``(P, c)``, the value and first two derivatives (3, n_channels) and their coefficients (3, n_present), read
        at the time of the reading ``t0`` read out (and the motion's latency in whole samples); None where they are
        too few or all more than half a step to one side of that time (a stale stream: no extrapolation; within
        half a step, a stamp's jitter about it)."""
        rows = np.flatnonzero(present)
        if len(rows) < self.order + 3:
            return None
        at = t0 + (self._L - self._lead) * self.dt                     # the read-out row's time on the grid
        s = np.array([self._times[i] for i in rows]) - at              # each sample's time from it
        if s.min() > 0.5 * self.dt or s.max() < -0.5 * self.dt:        # none on one side: an extrapolation (not
            return None                                                # a stamp's jitter about the read-out time)
        c = _fit_coefficients(s, self.order, self.dt)
        P = c @ np.array([self._channels[i] for i in rows])
        return P, c

    @property
    def setup(self):
        """The :class:`~fmscal.analysis._setup.Setup` in use: the one given, or a re-identified payload's (T9)."""
        return self._setup

    # --- the offset ----------------------------------------------------------------------------------------------
    @property
    def offset(self):
        """The offset ``b`` in use (the reading's units): the tracker's, a tare's or the calibration's."""
        return (self._tracker.b if self._tracker is not None else np.asarray(self._parts.b, dtype=float)).copy()

    def tare(self, force=False):
        """Re-bias at the current pose (D4): ``b = sigma w_hat - S^-1 W_p(pose)``, the mean over the newest
        compensated samples (:data:`TARE_WINDOW`, fewer where fewer came out), its covariance that of a mean.

        The payload's own wrench at that pose is restored, so the output does not jump beyond the noise; a
        sensor zeroed by its hardware at an unknown pose is one more offset found this way. With
        ``track_offset``, the tracker restarts from it, its covariance ``S^-1 Cov S^-T / n`` over the ``n`` samples
        (``Cov`` with the readings' long-run share where their noise is correlated, (D6)).

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
        S_inv = self._parts.S_inv
        if self._tracker is None:
            self._parts.b = found.mean(axis=0)
        else:
            long_run = 0.0 if self._parts.long_run is None else self._parts.long_run          # (D6)
            self._tracker.tare(found.mean(axis=0), S_inv @ (cov.mean(axis=0) + long_run) @ S_inv.T / len(found))
        return self.offset


class _RunningNoise:
    """A motion channel's noise variance from the second divided differences of its samples (the last three that
    came, at their own times): with intervals ``h1``, ``h2``, ``d = (x2 - x1) / h2 - (x1 - x0) / h1``, which a
    signal smooth at the sample rate leaves near zero, and a white noise of sd ``sigma`` gives the variance
    ``sigma^2 (1/h1^2 + 1/h2^2 + (1/h1 + 1/h2)^2)`` (``6 sigma^2 / h^2`` where even). Read as evenly spaced, the
    plain difference of jittered samples holds the motion's velocity times their intervals' difference, which
    would enter the variance. Only three samples about evenly spaced make one (:data:`EVEN`; a stream sparser than
    the readings counts): across a hole (a sample dropped, a gap) the motion's own curvature would enter the
    variance, and stay in it.

    The estimate is the terms' mean, each term bounded::

        term <= RUNNING_BOUND * v                                                                      (G3)

    ``v`` the estimate before it, or for the first :data:`GLITCH_WARMUP` terms (once they are all in) their
    median over :data:`CHI2_MEDIAN`; where that is zero (a quantised channel at rest, most differences zero), their
    least above zero but for the three largest (a glitch's): a step of the quantum. Where there is none yet, the
    first terms are bounded once there is, up to :data:`RUNNING_OPEN` of them, then not (a channel exactly at
    rest); later, a channel whose ``v`` is zero is not bounded.

    The samples no glitch check has seen (a stream's first, the first after a gap or a restart: module docstring,
    Glitches) enter the estimate; a glitch among them, 2000 sd off, entered the plain mean for good, its sd tens of
    times the noise for seconds and a later glitch passing beneath the check's bound. Bounded, a glitch's three
    terms still widen it for a while, by at most ``sqrt(1 + 3 RUNNING_BOUND / n)`` at ``n`` terms, not for good."""

    def __init__(self, size):
        self.recent = deque(maxlen=3)
        self.times = deque(maxlen=3)
        self.sum, self.n = np.zeros(size), 0
        self.first = []                                  # the first GLITCH_WARMUP terms, until they are all in

    def add(self, values, t):
        """One sample ``values`` (n,) at time ``t``: a second difference where the last three are even."""
        self.recent.append(values)
        self.times.append(float(t))
        if len(self.recent) == self.recent.maxlen:
            h1, h2 = self.times[1] - self.times[0], self.times[2] - self.times[1]
            if 0 < min(h1, h2) and max(h1, h2) <= EVEN * min(h1, h2):
                d = (self.recent[2] - self.recent[1]) / h2 - (self.recent[1] - self.recent[0]) / h1
                self._term(np.square(d) / (1 / h1 ** 2 + 1 / h2 ** 2 + (1 / h1 + 1 / h2) ** 2))

    def _term(self, term):
        """One term into the mean, bounded (G3)."""
        if self.first is None:
            np.minimum(term, (RUNNING_BOUND / self.n) * self.sum, out=term, where=self.sum > 0)
        else:
            self.first.append(term)
        self.sum += term
        self.n += 1
        if self.first is not None and self.n >= GLITCH_WARMUP:
            terms = np.array(self.first)
            level = np.median(terms, axis=0) / CHI2_MEDIAN
            rest = np.sort(terms, axis=0)[:-3]                              # a glitch's three terms left out
            least = np.where(rest > 0, rest, np.inf).min(axis=0)            # a quantised channel at rest: a step
            level = np.where(level > 0, level, least)
            if np.isfinite(level).all() or self.n >= RUNNING_OPEN:
                self.sum = np.minimum(terms, RUNNING_BOUND * level).sum(axis=0)
                self.first = None

    def copy(self):
        """An estimate of its own in the same state."""
        other = _RunningNoise(len(self.sum))
        other.recent, other.times = deque(self.recent, maxlen=3), deque(self.times, maxlen=3)
        other.sum, other.n = self.sum.copy(), self.n
        other.first = None if self.first is None else list(self.first)
        return other

    def clear(self):
        """Forget the last samples (the next difference starts after them)."""
        self.recent.clear()
        self.times.clear()

    def variance(self):
        return self.sum / self.n if self.n else np.zeros_like(self.sum)

    def block(self, rows, t):
        """:meth:`add` each of ``rows`` (M, n), at times ``t`` (M,), in turn: the variance after each, (M, n)."""
        out = np.empty_like(rows)
        for i, (row, ti) in enumerate(zip(rows, t)):
            self.add(row, ti)
            out[i] = self.variance()
        return out
