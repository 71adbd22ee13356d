"""What the node does between its messages, without rclpy: readings and motion matched by their stamps, the
motion interpolated at each reading's time, the compensation, the services' work, the node's state and its
ledger of every reading.

The node (:mod:`._node`) turns messages into numbers and calls :class:`Pipeline`; every call here takes and
returns plain numbers, so the matching is tested without ROS too.

Matching. A motion sample stamped ``s`` was taken at ``s - latency`` (the ``latency`` parameter; unset, the
calibration's for a pose stream, 0 for joint states and an IMU). A reading stamped ``t`` waits until the
motion's newest sample reaches ``t``; the motion is then interpolated at ``t`` (the model's
:meth:`fmscal.plant.Model.interpolate_pose`: SLERP for a quaternion, linear otherwise; joint states and an IMU's
rates and specific force linearly) and the reading is pushed into :class:`fmscal.analysis.Compensator` with it.
A reading the motion has not reached when a reading ``stale_timeout`` s newer arrives is pushed with no motion:
the motion is stale, and the compensator, which never extrapolates, stops the output until the motion covers
its window again. A reading inside a gap of the motion longer than ``stale_timeout`` is withheld as ``stale``
too, where the motion came back before the reading was taken (a node behind its inputs sees the gap late): the
cause is the same whatever the node's load.

The streams' breaks. The readings go to the compensator in the order they came, and it owns their stamps'
events (:attr:`fmscal.analysis.Compensator.events`: a duplicate dropped, a gap filled, a stamp stepping back or a
gap beyond its window restarting the window). Here: a reading stamped before the newest one queued sends the
queued ones on at once (with the motion that covers them, else none), so that the compensator sees the step;
the motion's own stamps stepping back restart the motion's buffer (``motion_restart``), a motion stamp repeated
is dropped (``motion_duplicate``). Readings missing from the stamps' grid are counted as ``lost`` (the input's
period, before any decimation).

The ledger. Every reading taken ends in one place, counted once: published; withheld by its cause (:data:`WITHHELD`:
a ``duplicate``, at a ``gap``'s edge, at a ``restart``, while the ``window`` fills after a start or a restart, with
the motion ``stale``, its stamp ``apart`` from the motion's clock, without enough ``motion`` in its window,
``saturated``, ``decimated``, ``invalid`` (a NaN, or an output the middleware refused), held when the compensation
failed (``error``, a bug said in the log)); or still
``waiting`` (for the motion, or for the readings after it that its output needs). So
``received = published + sum(withheld) + waiting`` at any time.

Decimation. Readings faster than ``max_rate`` are thinned to every ``N``-th stamp of their grid, ``N`` the
smallest integer that brings them within it (``decimated``): the compensator runs at ``N`` times the readings'
period, each kept reading as it came (no averaging: its noise is the calibration's).

Angles. A pose's angle columns (the model's :attr:`fmscal.plant.Model.angle_names`: the planar ``theta``, which
the node takes from the quaternion, ``2 atan2(q_z, q_w)``, and a publisher may wrap into (-pi, pi]) are unwrapped
against the motion's previous sample as they come::

    theta_k <- theta_k - 2 pi round((theta_k - theta_{k-1}) / (2 pi))                               (U1)

so that a payload turning through many revolutions is differentiated without the 2 pi steps (a turn of more
than pi between two motion samples cannot be told from one the other way). A quaternion's sign is made
continuous by :class:`fmscal.analysis.Compensator`.

Tool changes. The compensator's detector (:mod:`fmscal.analysis._tool_change`, parameter ``tool_change``)
declares a change of the payload; each is counted (``tool_changes``), said in the log with its time, and sets the
condition ``tool_change``, which flags every output until the new payload is in use: re-identified from the held
attitudes since the change (``tool_change`` reidentify, or ``~/reidentify``), identified (``~/identify_payload``)
or read again (``~/reload``). A re-identified payload becomes the one in use: a restart of the window keeps it,
and ``~/save`` writes it.

Snapshot. :attr:`Pipeline.snapshot` is replaced, never changed, after each pass: the diagnostics read it without
the lock the compensation holds.
"""

import threading
import time
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.stats import binom

from fmscal.plant import Calibration, NoiseSpec, SpatialModel
from fmscal.plant.numerics import FmscalError
from fmscal.plant.io import AttitudeLog, held_table
from fmscal.plant.physics import quaternion_multiply
from fmscal.observers.payload import PayloadEstimate, fit_static, identify_payload, reading_noise

from .._compensate import TARE_FALSE_REFUSAL, TARE_WINDOW, Compensator, compensation_model
from .._tool_change import check_mode
from .._setup import load_setup, setup
from .._motion import ImuMotion, JointMotion, PoseMotion, quaternion_from_matrix, quaternion_to_matrix
from ._parameters import Ros2Error

__all__ = ["Pipeline", "Output", "Snapshot", "STATES", "LEVELS", "WITHHELD", "FLAGS", "DT_SAMPLES", "sensor_pose",
           "motion_source", "fit_held", "state_of"]

#: The outputs' states (diagnostics): no output yet, outputs coming, the motion stale, the readings' stamps apart
#: from the motion's, a reading saturated, the window filling again after a break in the streams.
STATES = ("not ready", "running", "motion stale", "streams apart", "saturated", "restarting")
#: Each state's level: 0 OK, 1 WARN, 2 ERROR (diagnostic_msgs' own).
LEVELS = {"not ready": 1, "running": 0, "motion stale": 2, "streams apart": 2, "saturated": 1, "restarting": 1}
#: Why a reading taken gave no output (module docstring, The ledger).
WITHHELD = ("duplicate", "stray", "gap", "restart", "window", "stale", "apart", "motion", "saturated",
            "decimated", "invalid", "error")
#: The conditions that flag an output (it may be wrong beyond its covariance): another publisher on an input
#: topic, a frame that is not the one configured, a tool change declared and not yet re-identified.
FLAGS = ("publishers", "frame", "tool_change")
#: The number of wrench stamps whose median interval is the sample time (parameter ``sample_time`` 0).
DT_SAMPLES = 21
#: How long a saturated reading keeps the state ``saturated``, s.
SATURATED_HOLD = 1.0
#: s of motion kept beyond the newest reading that needs it (a wrench stream paused, or delivered late, while the
#: motion goes on).
MOTION_KEPT = 10.0
#: The readings' stamps remembered: one repeated among them is a duplicate, not a step back.
TAKEN_KEPT = 2000
#: The fewest repeated stamps, each a step on from the last, that can be the readings' clock stepping back (a bag
#: played again, a driver restarted on its old stamps), and the readings in a row whose lead must agree for a join
#: on the lead alone (:meth:`Pipeline._joins`).
REPLAYED = 3
#: s between two renewals of :attr:`Pipeline.snapshot` while readings come.
SNAP_EVERY = 0.01
#: ``~/identify_payload``: the shortest stretch without a gap or a contact it fits, s.
MIN_HELD = 1.0


_WAIT, _GAP = object(), object()
#: A block size the compensator's warm-up runs through (its casadi map built before the first backlog).
_BLOCK = 40


class Output:
    """One output: the :class:`fmscal.analysis.ContactSample`, the reading's stamp (as it came: any object)
    and frame, the reading's reception (s, the wall clock of ``time.time``) and its flags (names of :data:`FLAGS`,
    empty: right within its covariance)."""

    __slots__ = ("sample", "stamp", "frame_id", "arrival", "flags")

    def __init__(self, sample, stamp, frame_id, arrival, flags=()):
        self.sample, self.stamp, self.frame_id, self.arrival, self.flags = sample, stamp, frame_id, arrival, flags


@dataclass(frozen=True)
class Snapshot:
    """The pipeline's state after a pass, read without its lock (module docstring)."""

    counts: dict = field(default_factory=dict)
    withheld: dict = field(default_factory=dict)
    events: dict = field(default_factory=dict)
    conditions: dict = field(default_factory=dict)
    contact: bool = False
    offset: object = None
    offset_sd: object = None
    stale: bool = False
    apart: bool = False
    saturated: bool = False
    restarting: bool = False
    started: bool = False
    last_arrival: float = -np.inf
    backlog: int = 0
    waiting: int = 0
    dt: object = None
    delay: object = None
    decimation: int = 1
    motion_lag: object = None
    tool_change: str = ""


def state_of(snapshot, now, stale_timeout):
    """The state (one of :data:`STATES`) of a :class:`Snapshot` at ``now``
    (``time.monotonic``): "not ready" too where no reading has come for ``stale_timeout`` s."""
    if snapshot.saturated:
        return "saturated"
    if snapshot.stale:
        return "motion stale"
    if snapshot.apart:
        return "streams apart"
    if now - snapshot.last_arrival > stale_timeout or not snapshot.started:
        return "not ready"
    return "restarting" if snapshot.restarting else "running"


def _load(settings):
    """What the compensation runs on (:func:`fmscal.analysis.setup`): a calibration; a payload file alone, ``S`` the
    identity (K1); or both, the file's payload in place of the calibration's. The :class:`~fmscal.analysis.Setup`,
    the payload file's estimate (None without one), and the latency in use."""
    calibration = estimate = None
    if settings.calibration:
        calibration = _read(settings.calibration, Calibration, "calibration", "payload")
    if settings.payload:
        estimate = _read(settings.payload, PayloadEstimate, "payload", "calibration")
    if calibration is None:
        st = setup(estimate, tool_radius=settings.tool_radius)
    else:
        st = setup(calibration, estimate, tool_radius=settings.tool_radius)
    compensation_model(st.calibration, st.payload)            # the payload's case checked now, in one line
    # the calibration's latency is its pose stream's: a joint-state or an IMU stream has its own (the parameter)
    own = (st.calibration.latency or 0.0) if settings.source == "pose_topic" else 0.0
    latency = settings.latency if settings.latency is not None else own
    return st, estimate, latency


def _read(path, kind, name, other):
    """The file of parameter ``name``, a ``kind`` (its own loader's one-line error where it is not one); a file of
    the other kind (a payload file given as the calibration, or the other way) named as such."""
    try:
        return kind.load(path)
    except FmscalError:
        try:
            found = load_setup(path)
        except FmscalError:
            found = None
        if found is not None and not isinstance(found, kind):
            raise Ros2Error(f"parameter {name}: {path} is a {other} file; give it as {other} (-p {other}:={path})") \
                from None
        raise


def motion_source(settings):
    """The motion's source the parameters name (its stamps aligned by the pipeline: no latency here)."""
    if settings.source == "pose_topic":
        return PoseMotion()
    if settings.source == "joint_states_topic":
        return JointMotion(settings.urdf, settings.frame)
    return ImuMotion(rotation=settings.imu_rotation, lever_arm=settings.imu_lever_arm)


def sensor_pose(q, position, extrinsics=None):
    """The sensor frame's pose from a tracked frame's (a marker, a flange) and the sensor's place on it.

    With ``R`` and ``t`` the sensor's axes and point in the tracked frame's::

        R_S = R(q_M) R,   p_S = p_M + R(q_M) t                                                     (R1)

    Parameters
    ----------
    q : ndarray, shape (4,)
        The tracked frame's attitude, a unit quaternion ``(w, x, y, z)``.
    position : ndarray, shape (3,)
        Its position, m.
    extrinsics : (ndarray (3, 3), ndarray (3,)), optional
        ``(R, t)``: the sensor's axes and point in the tracked frame's; None: the tracked frame is the sensor's.

    Returns
    -------
    (ndarray (4,), ndarray (3,))
        The sensor's attitude ``q_M (x) q(R)`` and position.
    """
    if extrinsics is None:
        return q, position
    R, t = extrinsics
    return (quaternion_multiply(q, quaternion_from_matrix(np.asarray(R)[None])[0]),
            position + quaternion_to_matrix(q) @ np.asarray(t, dtype=float))


class _Held:
    """What ``~/identify_payload`` fits: the newest ``capacity`` samples (time, motion, reading) in place, each with
    its contact flag (set when its output comes) and whether a stretch starts at it (after a gap)."""

    def __init__(self, capacity):
        self.capacity, self.count, self.arrays, self._break = int(capacity), 0, None, True

    def __len__(self):
        return min(self.count, self.capacity)

    def append(self, t, motion, w_hat):
        """Hold a sample; its sequence number (for :meth:`contact`)."""
        motion = np.asarray(motion, dtype=float)
        if self.arrays is None or self.arrays[1].shape[1] != motion.size:
            n = self.capacity
            self.arrays = (np.zeros(n), np.zeros((n, motion.size)), np.zeros((n, len(w_hat))), np.zeros(n, bool),
                           np.zeros(n, bool))
            self.count = 0
        i = self.count % self.capacity
        t_, m_, w_, contact, starts = self.arrays
        t_[i], m_[i], w_[i], contact[i], starts[i] = t, motion, w_hat, False, self._break
        self._break = False
        self.count += 1
        return self.count - 1

    def gap(self):
        """The next sample starts a new stretch."""
        self._break = True

    def contact(self, seq):
        """Sample ``seq`` read as a contact (C4)."""
        if self.arrays is not None and 0 <= self.count - 1 - seq < self.capacity:
            self.arrays[3][seq % self.capacity] = True

    def take(self):
        """The held samples, oldest first (copies), and none held after: ``(t, motion, w_hat, contact, starts)``."""
        if not len(self):
            return None
        n, i = len(self), self.count % self.capacity
        order = np.r_[i:self.capacity, 0:i] if self.count > self.capacity else np.arange(n)
        out = tuple(a[order] for a in self.arrays)
        out[4][0] = True
        self.count, self._break = 0, True
        return out


class Pipeline:
    """Readings and motion in, contact wrenches out (module docstring); thread-safe (one lock).

    Parameters
    ----------
    settings : Settings
        The node's parameters, checked (:func:`fmscal.analysis.ros2.settings`).
    motion : PoseMotion, JointMotion or ImuMotion, optional
        The motion's source (None: the one ``settings`` names, :func:`motion_source`); :meth:`add_motion` takes
        its samples as its ``interpolate`` gives them (a pose in the model's order, ``(q, dq, ddq)``,
        ``(q_wxyz, omega, f)``).

    Attributes
    ----------
    counts : dict
        ``received`` (readings taken), ``published``, ``lost`` (readings missing from the stamps' grid),
        ``motion`` (motion samples taken), ``motion_skipped`` (motion messages the node skipped: a quaternion not
        of unit norm, a NaN), ``motion_duplicate``, ``motion_restart``, ``output_gaps`` (runs of readings without
        an output between two outputs), ``unmatched`` (outputs without their reading's stamp: none, else a bug).
    withheld : dict
        The readings taken that gave no output, by cause (:data:`WITHHELD`).
    conditions : dict
        What the node found wrong about its inputs (a name to a message; :data:`FLAGS` flag the outputs).
    """

    def __init__(self, settings, motion=None):
        self.settings = settings
        self.motion = motion_source(settings) if motion is None else motion
        self.lock = threading.Lock()
        self.setup, self.estimate, self.latency = _load(settings)
        if self.setup.axes is not None and not self.motion.turns_with_mounting:
            raise Ros2Error(f"parameter payload: {settings.payload}'s sensor is mounted turned on the tracked frame; "
                            f"an {self.motion.source}'s axes are its rotation's (imu_rotation): use poses or joint "
                            "states with it")
        self.model = compensation_model(self.calibration, self.setup.payload)
        try:
            check_mode(settings.tool_change or None, self.model)
        except FmscalError as err:
            raise Ros2Error("parameter tool_change: " + str(err).splitlines()[0].replace(
                "leave tool_change None or 'off'", "leave it empty or off")) from None
        self.n = self.model.n_w
        self.dt_in = settings.sample_time or None      # the readings' period
        self.decimation = 1
        self.dt = None                                 # the compensator's (the readings' times the decimation)
        self.compensator = None
        self._pending = deque()                        # (t, w_hat, stamp, frame_id, arrival, segment, apart, epoch)
        self._segment = 0                              # readings stamped before the newest taken start another
        self._newest_in = None                         # the newest reading's stamp taken
        self._taken, self._taken_order = set(), deque()   # the last TAKEN_KEPT stamps taken
        self._lead = None                              # the newest motion's stamp less a reading's, at its arrival
        self._apart_from = None                        # a step back's reference lead while the streams are apart
        self._apart_said = False                       # the readings found apart since that step back
        self._motion_at_take = None                    # the motion's newest stamp when the last reading was taken
        self._reading_back = None                      # (segment, stamp) of the readings' last step back
        self._stray, self._motion_stray = None, None   # a reading, a motion sample stamped back: held aside
        self._reading_epoch = self._motion_epoch = 0   # the clocks' epochs (a confirmed step back begins one)
        self._motion = deque()                         # (t taken, value)
        self._motion_back_to = None                    # the motion's first stamp after its last step back
        self._motion_back_by = 0.0                     # and how far it stepped back, s
        self._repeats = None                           # the readings' run of repeats (:meth:`_repeated`)
        self._replayed = None                          # the last such run that replayed the stamps to the newest
        self._same_leads = 0                           # readings behind a stepped-back motion, its lead unchanged
        self._window_epoch = None                      # the epoch of the motion in the compensator's window
        self._old_motion = None                        # (epoch, segment, newest t, buffer) before a step back
        self._motion_step = None                       # the motion's typical interval, s
        self._frames = {}                              # t -> (stamp, frame_id, arrival, tag, held seq) pushed
        self._held = _Held(1)
        self._unoriented = 0                           # IMU samples without an orientation since the last call
        self._recent = deque()                         # (t, w_hat, motion) of the rows the filter still holds
        self._last_t = None                            # the last reading pushed
        self._last_seen = None                         # the last reading taken from the queue (the input's grid)
        self._grid0 = None                             # the decimation's grid: a kept stamp
        self._segment_start = None                     # the first reading pushed since the start or a restart
        self._last_out = None                          # the last output's reading time
        self._gap_budget = 0                           # readings the compensator withheld at a gap, to forget
        self._withheld_gap = 0                         # the compensator's count of those so far
        # the angle columns (U1), by what the source and the model declare; their last values
        self._angles = self.motion.angle_columns(self.model)
        self._last_angles = None
        self.last_arrival = -np.inf                    # time.monotonic() of the newest reading
        self.motion_frame = ""
        self.identified = None
        self.counts = dict(received=0, published=0, lost=0, motion=0, motion_skipped=0, motion_duplicate=0,
                           motion_restart=0, motion_stray=0, output_gaps=0, unmatched=0, tool_changes=0)
        self.withheld = dict.fromkeys(WITHHELD, 0)
        self.conditions = {}
        self.tool_change = ""                          # the newest tool change's line
        self.time_origin = 0.0                         # s: a stamp's time less the time given here (the node's)
        self._changes = (None, 0)                      # (the compensator, its tool changes counted)
        self._flag_until = {}                          # a flag's condition: monotonic time it holds until
        self.notices = deque(maxlen=64)                # (key, message) for the node's log
        self.dropped = deque(maxlen=100000)            # (stamp, frame_id, cause) of readings withheld, for the node
        self.contact = False
        self.last_sample = None
        self.stale = False
        self._stale_gap = None                         # the start of the newest motion gap said stale, seen late
        self.restarting = False
        self._saturated_at = -np.inf
        self.warnings = []
        self._limit = None if settings.saturation is None else np.broadcast_to(settings.saturation, (self.n,))
        self.expected_sensor_frame = settings.sensor_frame or ""
        self.snapshot, self._snapped = Snapshot(), -np.inf
        self._base = settings.output_frame == "base"
        self._recent_kept = 0
        self._warm_up()

    def _warm_up(self):
        """A compensator run on a few samples at rest before any message: what it builds on its first samples
        (the dynamics' compiled function, the filter) is built now, not while the first readings queue up."""
        dt = (self.dt_in or 0.001) * self._decimation_of(self.dt_in or 0.001)
        saved, self.dt = self.dt, dt
        try:
            self._rebuilt()
        except Exception:                       # a setting the real sample time may accept: found then
            pass
        finally:
            self.dt = saved

    def _decimation_of(self, dt_in):
        """The decimation that brings readings ``dt_in`` s apart within ``max_rate`` (5 % leeway)."""
        return max(1, int(np.ceil(1.0 / (dt_in * self.settings.max_rate) - 0.05)))

    # --- the compensator --------------------------------------------------------------------------------------
    @property
    def calibration(self):
        """The calibration in use: a saved one, or the one a payload file stands for (K1)."""
        return self.setup.calibration

    @property
    def payload(self):
        """The payload in use: the one identified, the payload file's, or the calibration's."""
        return self.setup.payload if self.setup.payload is not None else self.calibration.payload

    @property
    def source(self):
        """What the compensation runs on, in words (the node's first log line)."""
        s = self.settings
        if not s.payload:
            return f"calibration {s.calibration}"
        return f"payload {s.payload}" + (f" on calibration {s.calibration}" if s.calibration else
                                         " (S the identity: no calibration)")

    def _build(self, setup_=None):
        """A Compensator of the setup (default the one in use; its latency 0: the stamps are aligned here), at
        ``self.dt``."""
        s = self.settings
        st = self.setup if setup_ is None else setup_
        changes = {"latency": 0.0}
        if s.reading is not None:
            changes["reading"] = s.reading
        if s.gravity is not None:
            changes["gravity"] = s.gravity
        learned = None if self.compensator is None else self.compensator.noise
        if st.calibration.noise is None and not st.pose_noise_known and learned is not None:
            # a payload file without the readings' noise of a sample: the one the running compensator learned from
            # its first readings, not learned again (no output until it is)
            changes["noise"] = NoiseSpec(learned.wrench_sd, wrench_tau=learned.wrench_tau)
        kwargs = dict(direction=s.direction, window=s.window, delay=s.delay, false_alarm=float(s.contact_threshold),
                      track_offset=bool(s.track_offset))
        if s.drift_intensity is not None:
            kwargs["drift_intensity"] = s.drift_intensity[0] if len(s.drift_intensity) == 1 else s.drift_intensity
        kwargs.update(motion=self.motion, frame=s.output_frame, point=s.tool_point, tool_change=s.tool_change or None)
        compensator = Compensator(replace(st, calibration=replace(st.calibration, **changes)), self.dt, **kwargs)
        self.warnings = list(compensator.warnings)
        return compensator

    def _rebuilt(self, setup_=None):
        """A new compensator (:meth:`_build`), its casadi functions built first by a twin fed samples at rest: done
        outside the lock, then handed to :meth:`_swap` under it."""
        warm = self._build(setup_)
        n = int(round((self.settings.window + self.settings.delay) / self.dt)) + 4
        rest = self.motion.rest(self.model)
        self._feed(warm, [(i * self.dt, np.zeros(self.n), rest) for i in range(n)])
        for size in (2, _BLOCK):                          # the first blocks' sizes, as a backlog brings them
            start = n * self.dt
            self._feed(warm, [(start + i * self.dt, np.zeros(self.n), rest) for i in range(size)])
        return self._build(setup_)

    def _swap(self, compensator):
        """The compensation goes on with ``compensator`` (lock held), fed the rows the filter holds (their outputs
        already published): no gap."""
        if self._recent:
            self._feed(compensator, list(self._recent))
            compensator.events.clear()
            compensator.withheld.clear()
        self._withheld_gap = 0
        self.compensator = compensator
        self._changes = (compensator, len(compensator.tool_changes))

    @property
    def delay(self):
        """s: the causal filter's delay (None before the sample time is known)."""
        return None if self.compensator is None else self.compensator.delay

    def _notice(self, key, message):
        """A line for the node's log (it says at most one of a key every few seconds)."""
        self.notices.append((key, message))

    # --- the conditions ---------------------------------------------------------------------------------------
    def condition(self, name, message=None, hold=0.0, wait=True):
        """Set (``message``) or clear (None) a condition of the inputs (:attr:`conditions`); one of :data:`FLAGS`
        flags the outputs while it holds and ``hold`` s after it clears (the filter's window still holds its
        samples). Returns whether it changed; with ``wait`` False, None where :attr:`lock` is held (a compensation
        running: nothing set)."""
        if not self.lock.acquire(blocking=wait):
            return None
        try:
            changed = self._condition(name, message, hold)
            if changed:
                self._snap()
            return changed
        finally:
            self.lock.release()

    def _condition(self, name, message=None, hold=0.0):
        before = self.conditions.get(name)
        if message is None:
            self.conditions.pop(name, None)
            if before is not None and name in FLAGS:
                self._flag_until[name] = time.monotonic() + hold
        else:
            self.conditions[name] = message
            self._flag_until.pop(name, None)
        return before != message

    def _flags(self):
        """The flags an output published now carries."""
        now = time.monotonic()
        return tuple(f for f in FLAGS if f in self.conditions or self._flag_until.get(f, -np.inf) > now)

    def _check_frame(self, which, got, expected):
        """A frame_id compared with the one configured: a mismatch sets the condition ``frame`` (a message naming
        both), a match clears it (the outputs flagged a window and delay more)."""
        if not (got and expected):
            return
        key, hold = f"frame {which}", self.settings.window + self.settings.delay
        if got == expected:
            if key in self.conditions:
                self._condition(key)
                if not any(k.startswith("frame ") for k in self.conditions):
                    self._condition("frame", None, hold)
            return
        if key not in self.conditions:
            option = "sensor_frame" if which == "wrench" else "base_frame"
            message = f"the {which} come in frame_id {got!r}, {option} is {expected!r}: the outputs flagged"
            self._condition(key, message)
            self._condition("frame", message)
            self._notice("frame", message)

    # --- the streams ------------------------------------------------------------------------------------------
    def add_motion(self, t, value, frame_id=""):
        """A motion sample stamped ``t`` (s): a pose (model order), ``(q, dq, ddq)`` or ``(q_wxyz, omega, f)``.

        A sample stamped before the newest is held aside: where the next goes on from the newest, it was a stray
        (``motion_stray``, dropped); where the next goes on from it, the motion's clock stepped back: its buffer
        restarts (``motion_restart``) and a new epoch begins, which readings stamped on the old clock do not
        share: those the old motion covers are still compensated with it (taken late as they would be live,
        :meth:`_old_clock`), the others get none (``apart``). A stamp repeated is dropped (``motion_duplicate``)."""
        t = float(t) - self.latency
        with self.lock:
            self.counts["motion"] += 1
            self.motion_frame = frame_id
            if self.settings.output_frame == "base" and self.settings.source == "pose_topic":
                self._check_frame("poses", frame_id, self.settings.base_frame)
            m = self._motion
            newest = m[-1][0] if m else None
            stray, self._motion_stray = self._motion_stray, None
            if stray is not None:
                if newest is not None and t > newest:          # the old timeline goes on: it was a stray
                    self.counts["motion_stray"] += 1
                elif t > stray[0]:                              # this one goes on from it: the clock stepped back
                    self._motion_restart(stray[0], newest)
                    self._append_motion(*stray)
                    newest = stray[0]
                else:                                           # back again: the first a stray, this one held
                    self.counts["motion_stray"] += 1
                    self._motion_stray = (t, value)
                    return
            if newest is not None and t <= newest:
                if t > newest - 1e-9:
                    self.counts["motion_duplicate"] += 1
                else:
                    self._motion_stray = (t, value)
                return
            if newest is not None:
                step = t - newest
                self._motion_step = step if self._motion_step is None else \
                    self._motion_step + 0.05 * (min(step, 10 * self._motion_step) - self._motion_step)
            self._append_motion(t, value)

    def _append_motion(self, t, value):
        m = self._motion
        if self._angles:
            value = self._unwrapped(value)
        m.append((t, value))
        while len(m) > 2 and m[0][0] < t - MOTION_KEPT - self.settings.stale_timeout:
            m.popleft()

    def _motion_restart(self, t, newest):
        """The motion's clock stepped back to ``t`` from ``newest``: its buffer restarted, a new epoch; readings
        stepped back before, alone (apart) or to about these stamps (within the tolerance), now share it: the
        compensator's window, which holds the old clock's motion, restarts at their next reading (:meth:`_drain`)."""
        self.counts["motion_restart"] += 1
        self._notice("motion_restart", f"the motion's stamps stepped back by {newest - t:.6g} s: its buffer "
                                       "restarted; readings stamped on the old clock past its last "
                                       "sample get no motion")
        back, self._reading_back = self._reading_back, None
        stepped = back is not None and back[0] == self._segment and abs(t - back[1]) <= self.settings.stale_timeout
        self._old_motion = None
        if self._apart_from is None and not stepped and self._motion:
            # readings still to come on the old clock (not already on a new one, stepped back by less than the
            # tolerance to about these stamps): its motion kept for them
            self._old_motion = (self._motion_epoch, self._segment, self._motion[-1][0], deque(self._motion))
        self._motion = deque()
        self._last_angles = None
        self._motion_epoch += 1
        self._motion_back_to, self._motion_back_by = t, newest - t
        if self._replayed is not None and abs(self._replayed[0] - t) > self._apart_tolerance():
            self._replayed = None                      # the readings' replay was of another step
        self._same_leads = 0
        if self._apart_from is not None or stepped:    # the readings stepped back first: the motion followed
            self._apart_from, self._apart_said = None, False
            self._join()

    def _joins(self, lead, moved):
        """Whether readings going on from the newest, behind a motion whose clock stepped back (``lead``: theirs
        on its newest; ``moved``: it moved since the last reading), are on its new clock too. Either their own
        step back to its first new stamp was seen: a replay of the stamps from there to the newest taken, each a
        step on and delivered over about as long as they span (:meth:`_repeated`: a bag played again, a driver
        restarted on its old stamps), not old messages delivered again in a burst. Or their lead is what it was
        on the old clock, on :data:`REPLAYED` readings in a row taken as the motion moves (within a burst of
        readings after a stall, the lead sweeps past any value), where the motion stepped back by more than twice
        the tolerance (alone, it shifts the lead by all of that: the readings back after a silence). A motion
        stepping back alone by less stays apart: within the tolerance, the lead cannot tell a step from
        delivery."""
        tolerance = self._apart_tolerance()
        if self._replayed is not None and abs(self._replayed[0] - self._motion_back_to) <= tolerance:
            return True
        if not moved or self._motion_back_by <= 2 * tolerance:
            return False
        same = lead is not None and self._lead is not None and abs(lead - self._lead) <= tolerance
        self._same_leads = self._same_leads + 1 if same else 0
        return self._same_leads >= REPLAYED

    def _join(self):
        """The readings take the motion's epoch (their clock is its new one); those queued of the old epoch in
        the current segment that the old clock's motion does not cover take it too (they came on the new clock
        before the join was seen; else each would be withheld as ``apart``)."""
        old, new = self._reading_epoch, self._motion_epoch
        self._reading_epoch = new
        self._pending = deque((*e[:7], new) if e[7] == old and not e[6] and e[5] == self._segment
                              and self._old_clock(e[0], old, e[5]) is None else e for e in self._pending)

    def _old_clock(self, t, epoch, segment):
        """The motion kept from before the motion's step back, where it covers the reading at ``t`` of that
        ``epoch`` and ``segment`` (a reading taken late, by a node behind its inputs, as it was covered live);
        else None."""
        old = self._old_motion
        if old is not None and old[0] == epoch and old[1] == segment and t <= old[2]:
            return old[3]
        return None

    def skip_motion(self):
        """A motion message the node skipped (a quaternion not of unit norm, a NaN): counted."""
        with self.lock:
            self.counts["motion_skipped"] += 1

    def _unwrapped(self, pose):
        """``pose`` with its angle columns unwrapped against the previous motion sample's (U1)."""
        pose = np.array(pose, dtype=float)
        angles = pose[self._angles]
        if self._last_angles is not None:
            angles = angles - 2 * np.pi * np.round((angles - self._last_angles) / (2 * np.pi))
            pose[self._angles] = angles
        self._last_angles = angles
        return pose

    def _repeated(self, t, arrival):
        """A reading at ``t``, received at ``arrival`` (s), repeats a stamp taken: the run of repeats it goes on
        (the last a step on, or a few lost between), or starts. A run that reaches the newest reading taken,
        :data:`REPLAYED` or more delivered over at least half the time their stamps span, replayed the stamps
        from its first: kept for :meth:`_joins` (old messages delivered again come in a burst, and rarely all the
        way to the newest)."""
        run = self._repeats
        if run is None or not 0 < t - run[1] <= self._apart_tolerance():
            run = self._repeats = [t, t, 0, arrival, arrival]             # first, last, count, first and last arrival
        run[1], run[2], run[4] = t, run[2] + 1, arrival
        step = self.dt_in or self._motion_step or 0.0
        if run[2] >= REPLAYED and t >= self._newest_in - 1.5 * step and run[4] - run[3] >= 0.5 * (t - run[0]):
            self._replayed = run

    def _apart_tolerance(self):
        """s a reading's lead on the motion may grow past a step back's before the streams are apart: the
        motion's interval twice, and 20 ms of delivery."""
        return 0.02 + 2 * (self._motion_step or 0.0)

    def add_reading(self, t, w_hat, stamp=None, frame_id="", arrival=None):
        """A raw reading stamped ``t`` (s), queued; :meth:`process` compensates it once the motion covers it.

        A reading repeating the stamp of one of the last :data:`TAKEN_KEPT` taken (not the newest: the compensator
        drops that one) is dropped (``duplicate``): its stamp's output came already (a run of them that replays the
        stamps is the readings' clock stepping back, :meth:`_repeated`, for :meth:`_joins`). A reading stamped
        before the newest is held aside: where the next goes on from the newest, it was a stray (``stray``, dropped:
        an old message, a second publisher on another clock); where the next goes on from it, the readings' clock
        stepped back: the queued readings go on at once, and the compensator restarts its window. Where the motion's
        clock had stepped back before, the readings now share its epoch; where it had not, and the readings' stamps
        now trail the motion's newest by more than they did before (:meth:`_apart_tolerance`), the streams are
        apart: each such reading is pushed with no motion (``apart``) until their stamps agree again. A reading of
        an older epoch than the motion's gets no motion either. A reading with a NaN or infinite component is
        counted (``invalid``) and dropped: returns False. ``arrival``: its reception, s of the wall clock
        (``time.time``; default now), for the node's measure of how long its readings wait."""
        arrival = time.time() if arrival is None else arrival
        w_hat = np.asarray(w_hat, dtype=float)
        t = float(t)
        with self.lock:
            self.counts["received"] += 1
            self.last_arrival = time.monotonic()
            if not (np.isfinite(w_hat).all() and np.isfinite(t)):
                self._withhold("invalid", stamp, frame_id)
                return False
            self._check_frame("wrench", frame_id, self.expected_sensor_frame)
            if t in self._taken and self._newest_in is not None and t < self._newest_in:
                self._repeated(t, arrival)
                self._withhold("duplicate", stamp, frame_id)  # a repeat of a stamp taken before the newest
                return True
            self._repeats = None
            entry = (t, w_hat, stamp, frame_id, arrival)
            stray, self._stray = self._stray, None
            if stray is not None:
                if t > self._newest_in:                     # the old timeline goes on: it was a stray
                    self._withhold("stray", stray[2], stray[3])
                    self._notice("stray", f"a reading stamped {stray[0]:.9g} s, before the newest, and the next "
                                          "going on from the newest: dropped (an old message, or a second "
                                          "publisher on another clock)")
                elif t > stray[0]:                          # this one goes on from it: the clock stepped back
                    self._take(stray, back=True)
                else:                                       # back again: the first a stray, this one held
                    self._withhold("stray", stray[2], stray[3])
                    self._stray = entry
                    return True
            if self._newest_in is not None and t < self._newest_in - 1e-9:
                self._stray = entry                         # held aside until the next says what it is
                return True
            self._take(entry)
            return True

    def _take(self, entry, back=False):
        """Queue a reading (lock held); ``back``: its stamp steps back (confirmed by the next)."""
        t = entry[0]
        self._taken.add(t)
        self._taken_order.append(t)
        if len(self._taken_order) > TAKEN_KEPT:
            self._taken.discard(self._taken_order.popleft())
        lead = self._motion[-1][0] - t if self._motion else None
        if back:
            self._segment += 1                          # the queued readings go on at once
            if self._motion_epoch > self._reading_epoch:    # the motion's clock stepped back first: the same step
                self._reading_epoch = self._motion_epoch
                self._apart_from, self._apart_said = None, False
            else:
                self._reading_back = (self._segment, t)
                if self._apart_from is None and self._lead is not None:
                    self._apart_from = self._lead
        self._newest_in = t
        newest_motion = self._motion[-1][0] if self._motion else None
        moved, self._motion_at_take = newest_motion != self._motion_at_take, newest_motion
        apart = False
        if self._apart_from is not None and lead is not None:
            if lead - self._apart_from > self._apart_tolerance() or (self._apart_said and not moved):
                # apart; and stays apart while the motion has not moved since the last reading: a lead that
                # shrinks as the readings go on alone is the motion stalled, not the clocks agreeing
                apart = self._apart_said = True
                if "apart" not in self.conditions:
                    self._condition("apart", f"the readings' stamps stepped back {lead - self._apart_from:.6g} s "
                                             "behind the motion's: the streams no longer share a clock; no output "
                                             "until they do")
                    self._notice("apart", self.conditions["apart"])
            else:
                self._apart_from, self._apart_said = None, False
        behind = self._reading_epoch != self._motion_epoch and \
            self._old_clock(t, self._reading_epoch, self._segment) is None
        if behind and not apart and self._joins(lead, moved):
            self._join()
            behind, self._replayed = False, None
        if behind and "apart" not in self.conditions:
            self._condition("apart", "the motion's stamps stepped back and the readings' did not: the streams no "
                                     "longer share a clock; no output until they do")
            self._notice("apart", self.conditions["apart"])
        if not (apart or behind) and "apart" in self.conditions:
            self._condition("apart")
            self._notice("apart", "the readings' stamps agree with the motion's again")
        if not apart and lead is not None and self._reading_epoch == self._motion_epoch:
            self._lead = lead                           # (a lead on another clock's motion means nothing)
        self._pending.append((*entry, self._segment, apart, self._reading_epoch))

    def process(self):
        """Compensate every queued reading the motion covers, or has left stale; the outputs (list of
        :class:`Output`), oldest first. :attr:`snapshot` is renewed at most every :data:`SNAP_EVERY` s (and by
        :meth:`snap`)."""
        with self.lock:
            try:
                if self.compensator is None and not self._start():
                    return []
                return self._drain() if self._pending else []
            finally:
                if time.monotonic() - self._snapped > SNAP_EVERY:
                    self._snap()

    def snap(self):
        """Renew :attr:`snapshot` now (the node does when its inputs fall silent)."""
        with self.lock:
            self._snap()

    def _start(self):
        """The sample time (given, or the median interval of the first readings), the decimation and the
        compensator; False while too few readings have come."""
        if self.dt_in is None:
            if len(self._pending) < DT_SAMPLES:
                return False
            steps = np.diff([p[0] for p in self._pending])
            dt = float(np.median(steps[steps > 0])) if (steps > 0).sum() > DT_SAMPLES // 2 else 0.0
            if not dt > 0:
                self._notice("dt", f"the wrench stamps do not increase ({len(self._pending)} readings): waiting for "
                                   "more (or set sample_time)")
                while len(self._pending) > DT_SAMPLES // 2:
                    dropped = self._pending.popleft()
                    self._withhold("window", dropped[2], dropped[3])
                return False
            self.dt_in = dt
        self.decimation = self._decimation_of(self.dt_in)
        self.dt = self.dt_in * self.decimation
        if self.decimation > 1:
            self._notice("decimation", f"the readings come at {1 / self.dt_in:.0f} Hz, beyond max_rate "
                                       f"{self.settings.max_rate:g} Hz: 1 in {self.decimation} compensated (outputs "
                                       f"at {1 / self.dt:.0f} Hz)")
        self.compensator = self._build()
        self._held = _Held(int(round(self.settings.identify_buffer / self.dt)) + 1)
        self._recent_kept = int(round((self.settings.window + self.settings.delay) / self.dt)) + 4
        return True

    def _drain(self):
        """Push every pending reading the motion covers, or has left stale (or that a step back sends on); the
        outputs.

        A reading given the motion of another epoch than the compensator's window holds, its stamp going on from
        the last pushed (the readings rejoined the motion's clock after it stepped back: :meth:`_motion_restart`,
        :meth:`_joins`), restarts the window first: a window holding both clocks' motion puts the outputs far
        beyond their covariance. (A stamp stepping back restarts it by itself.)"""
        timeout = self.settings.stale_timeout
        newest, last_segment = self._pending[-1][0], self._pending[-1][5]
        rows, previous = [], self._last_t
        while self._pending:
            t, w_hat, stamp, frame_id, arrival, segment, apart, epoch = self._pending[0]
            old = None if apart or epoch == self._motion_epoch else self._old_clock(t, epoch, segment)
            apart = apart or (epoch != self._motion_epoch and old is None)    # the motion's clock stepped back
            if not self._kept(t):
                self._pending.popleft()
                self.withheld["decimated"] += 1
                continue
            value = None if apart else self._at(t, old)
            tag = "apart" if apart else None
            if value is _WAIT:
                if segment == last_segment and newest - t <= timeout:
                    break
                value, tag = None, "stale"
                if segment == last_segment:
                    if not self.stale:
                        self._notice("stale", f"motion stale: {self.settings.topic} has no sample within "
                                              f"{timeout:g} s of the readings' stamps; no output until it covers the "
                                              "filter's window again")
                    self.stale = True
            elif value is _GAP:
                value, tag = None, "motion"
                m = self._motion if old is None else old
                (t0, _), (t1, _) = m[0], m[1]
                if t1 - t0 > timeout:                   # the motion was stale here, though it came back before
                    tag = "stale"                       # this reading was taken (a node behind its inputs)
                    if self._stale_gap != t0 and not self.stale:      # (not said already, seen live)
                        self._stale_gap = t0
                        self._notice("stale", f"motion stale: {self.settings.topic} has no sample for "
                                              f"{t1 - t0:.3f} s of the readings' stamps (come back before they "
                                              "were taken); no output for the readings there")
            elif value is None:
                tag = tag or "motion"
            else:
                self.stale = False
            self._pending.popleft()
            why = None
            if value is not None:
                if self._window_epoch not in (None, epoch) and previous is not None and t > previous:
                    why = "the readings joined the motion's clock after it stepped back"
                self._window_epoch = epoch
            previous = t
            rows.append((t, w_hat, value, stamp, frame_id, arrival, tag, why))
        return self._push(rows) if rows else []

    def _kept(self, t):
        """Whether the reading at ``t`` is compensated (decimation: every N-th stamp of the input's grid); counts
        the readings missing from that grid (``lost``).

        After a restart of the window the grid starts at the reading that restarted it (:meth:`_push_run`), which
        the old grid kept: the readings of the same pass past it, taken on the old grid, stay on the new one. A
        grid started at the next pass's first reading put the stamps off the compensator's ``dt`` with no gap
        (a step of 0.8 ``dt`` at 5 kHz, 1 in 5)."""
        seen, self._last_seen = self._last_seen, t
        if seen is not None and t - seen > 1.5 * self.dt_in:
            self.counts["lost"] += int(round((t - seen) / self.dt_in)) - 1
        if self.decimation == 1:
            return True
        if self._grid0 is None or t < self._grid0:
            self._grid0 = t                             # a new grid after a start, a restart, a step back
        return int(round((t - self._grid0) / self.dt_in)) % self.decimation == 0

    def _at(self, t, m=None):
        """The motion at ``t`` (interpolated), None where it starts after ``t``, or ``_WAIT``; ``_GAP`` where no
        motion sample lies within half a reading's step of ``t`` (a motion slower than the readings). ``m``: the
        buffer (default the motion's; :meth:`_old_clock`).

        Each motion sample is given to the reading nearest it only, interpolated to that reading's stamp; the
        readings between get none, as :meth:`fmscal.analysis.Compensator.push` takes a sparser stream. Given to
        every reading, interpolated values would count as independent samples: the motion's noise, and with it
        the output's covariance, would come out too small.

        Across a hole in the motion (samples lost), ``_GAP`` too: a straight line's error at ``t`` between samples
        at ``t0`` and ``t1`` is ``(t - t0) (t1 - t) |x''| / 2``, which the output's covariance does not hold; it is
        kept within what the stream's own spacing gives, ``(t - t0) (t1 - t) <= (0.75 h)^2`` with ``h`` its typical
        interval (the largest product of a bracket 1.5 ``h`` wide). Interpolated across a 60 ms hole, one reading's
        motion put outputs 15 sd off where the filter's window held few samples (after a gap in the readings)."""
        m = self._motion if m is None else m
        while len(m) >= 2 and m[1][0] <= t:
            m.popleft()
        if not m or m[-1][0] < t:
            return _WAIT
        if m[0][0] > t:
            return None
        (t0, v0), (t1, v1) = m[0], (m[1] if len(m) > 1 else m[0])
        if t0 == t or t1 == t0:
            return v0
        if t - t0 >= 0.5 * self.dt and t1 - t > 0.5 * self.dt:
            return _GAP
        if self._motion_step is not None and (t - t0) * (t1 - t) > (0.75 * self._motion_step) ** 2:
            return _GAP                                 # across a hole in the motion (the docstring)
        return self.motion.interpolate(self.model, t, t0, v0, t1, v1)

    def _push(self, rows):
        """Push rows ``(t, w_hat, motion, stamp, frame_id, arrival, tag, why)`` into the compensator (``why``: a
        restart due before the row, else None): runs of stamps one step apart as one block, any other stamp, and a
        row with a restart, alone (so that each of the compensator's events is known to be its); the outputs."""
        out, i, dt = [], 0, self.dt
        while i < len(rows):
            j, previous = i, self._last_t
            while j < len(rows) and previous is not None and 0.5 * dt <= rows[j][0] - previous < 1.5 * dt \
                    and rows[j][7] is None:
                previous = rows[j][0]
                j += 1
            j = max(j, i + 1)
            out.extend(self._push_run(rows[i:j]))
            i = j
        return out

    def _push_run(self, run):
        """One push of :meth:`_push`: its rows' stamps kept for their outputs, the compensator's events of it
        counted in the ledger; the outputs."""
        c = self.compensator
        events = dict(c.events)
        added = []
        if run[0][7] is not None:                     # (a run of one) a restart the stamps do not show
            c.restart(run[0][7])
        for t, w_hat, value, stamp, frame_id, arrival, tag, _ in run:
            if t in self._frames and self._last_t is not None and t < self._last_t:
                # (a run of one, stepping back: a restart) a stamp the old clock's window still holds, taken again
                # (a repeat older than the TAKEN_KEPT stamps remembered: inputs above 20 kHz), its reading withheld
                # with that window
                frame = self._frames.pop(t)
                self._withhold("restart", frame[0], frame[1])
            if t not in self._frames:
                tag, seq = self._note(t, w_hat, value, tag)
                self._frames[t] = (stamp, frame_id, arrival, tag, seq)
                added.append(t)
        seen = self._changes_seen(c)                                     # the changes declared before this run
        was = "tool_change" in self._flags()
        samples = self._feed(c, [(r[0], r[1], r[2]) for r in run])
        self._tool_changes(c)
        new = {k: n - events.get(k, 0) for k, n in c.events.items() if n != events.get(k, 0)}
        if new.get("duplicate"):                      # (a run of one) the reading dropped
            self.withheld["duplicate"] += 1
            if added:
                del self._frames[added[0]]
        else:
            self._last_t = run[-1][0]
        if new.get("restart"):                        # (a run of one) every reading before it withheld
            keep = run[0][0]
            for t in [t for t in self._frames if t != keep]:
                frame = self._frames.pop(t)
                self._withhold("restart", frame[0], frame[1])
            while len(self._recent) > 0:
                self._recent.pop()
            self._segment_start, self._grid0, self.restarting = keep, keep, True     # (:meth:`_kept`)
            self._held.gap()
        elif self._segment_start is None and not new.get("duplicate"):
            self._segment_start = run[0][0]
        if new.get("gap"):
            self._gap_budget += c.withheld.get("gap", 0) - self._withheld_gap
            if self.motion.breaks_hold:
                self._held.gap()
        self._withheld_gap = c.withheld.get("gap", 0)
        last = getattr(c, "last_event", None)
        for cause in new:
            self._notice(cause, last[1] if last and last[0] == cause else f"the readings' stamps: a {cause}")
        self._recent.extend((r[0], r[1], r[2]) for r in run)
        while len(self._recent) > self._recent_kept:
            self._recent.popleft()
        flags = self._flags()
        if was and "tool_change" not in flags:      # re-identified in this run: each of its outputs kept flagged
            flags = tuple(f for f in FLAGS if f in flags or f == "tool_change")
        # a change declared in this run flags the outputs from the one that declared it (the sample's count), not
        # those before it (a node behind its inputs pushes long runs)
        early = tuple(f for f in flags if f != "tool_change") if not was else flags
        base = (self.settings.base_frame or self.motion_frame) if self._base else None
        out = [o for o in (self._output(sample, flags if sample.tool_change > seen else early, base)
                           for sample in samples) if o is not None]
        if self._last_t is not None:
            self._forget(self._last_t - c.delay)
        return out

    def _changes_seen(self, c):
        """How many of the compensator ``c``'s tool changes were taken (counted, said) already."""
        return self._changes[1] if self._changes[0] is c else 0

    def _tool_changes(self, c):
        """The changes ``c`` declared since the last look: counted, said, the condition ``tool_change`` set; a
        re-identification ``c`` made (``tool_change`` reidentify) taken as the payload in use (lock held)."""
        changes = c.tool_changes
        seen = self._changes_seen(c)
        if len(changes) == seen:
            if changes and changes[-1].reidentified_at is not None and "tool_change" in self.conditions:
                self._reidentified(c)
                self._snap()
            return
        for change in changes[seen:]:
            self.counts["tool_changes"] += 1
            self.tool_change = self._described(change)
            self._notice("tool_change", self.tool_change + "; the outputs flagged tool_change until it is "
                         "re-identified" + (" (from the next held attitudes)"
                                            if self.settings.tool_change == "reidentify" else
                                            ": hold the tool still at a few attitudes, then ~/reidentify"))
            self._condition("tool_change", f"tool change at {change.t + self.time_origin:.3f} s: mass "
                            f"{change.mass_change:+.4g} kg, not yet re-identified")
        self._changes = (c, len(changes))
        self._snap()

    def _reidentified(self, c):
        """The compensator ``c`` went on with a re-identified payload (T9): it is the one in use, the condition
        ``tool_change`` cleared, the line said (lock held)."""
        st = c.setup
        self.setup = replace(self.setup, payload=st.payload, cov=st.cov, inertia_bounded=st.inertia_bounded,
                             warnings=[])
        self.model, self.identified = compensation_model(self.calibration, st.payload), {"payload": st.payload}
        self._condition("tool_change", None)
        if c.tool_changes and c.tool_changes[-1].reidentified is not None:
            self.tool_change = self._described(c.tool_changes[-1])
            self._notice("tool_change", self.tool_change)

    def _described(self, change):
        """A tool change's line, its times the stamps' (:attr:`time_origin` added)."""
        o = self.time_origin
        return replace(change, t=change.t + o, declared=change.declared + o,
                       reidentified_at=None if change.reidentified_at is None else change.reidentified_at + o
                       ).describe()

    def reidentify(self):
        """``(success, message)`` of ``~/reidentify``: the payload fitted to the held attitudes since the last
        tool change declared (else the detector's newest, :meth:`fmscal.analysis.Compensator.reidentify`); the
        compensation goes on with it, and ``~/save`` writes it."""
        with self.lock:
            c = self.compensator
            if c is None:
                return False, "reidentify refused: no reading compensated yet"
            try:
                fit = c.reidentify()
            except FmscalError as err:
                return False, "reidentify refused: " + str(err).splitlines()[0].replace(
                    "tool_change='detect' or 'reidentify'", "tool_change:=detect or reidentify")
            self._changes = (c, len(c.tool_changes))
            self._reidentified(c)
            self._snap()
        return True, (f"re-identified: mass {fit.mass:.4g} +- {fit.mass_std:.2g} kg, com "
                      + " ".join(f"{v:.4g}" for v in fit.com) + " m (+- " + " ".join(f"{v:.2g}" for v in fit.com_std)
                      + "); the compensation goes on with it")

    def _feed(self, compensator, rows):
        """Push rows ``(t, w_hat, motion)`` into ``compensator`` as one block; its samples."""
        return compensator.push_many([r[0] for r in rows], [r[1] for r in rows],
                                     **{self.motion.keyword: self.motion.stack([r[2] for r in rows], self.model)})

    def _note(self, t, w_hat, value, tag):
        """A reading about to be pushed: saturation, the held motion; ``(tag, seq)``, its tag ("saturated" where
        it is) and its sequence number among the held samples (-1: not held)."""
        if self._limit is not None and (np.abs(w_hat) >= self._limit).any():
            self._saturated_at = t
            tag = "saturated"
        if value is None:
            if tag != "motion" or not self._motion or self._motion[0][0] > t:
                if self.motion.breaks_hold:            # identify_payload fits stretches without a gap
                    self._held.gap()
            return tag, -1
        held = self.motion.held(value)                 # a pose, joint angles, or an IMU's attitude
        if held is None:                               # an IMU without orientation: nothing to hold
            self._unoriented += 1
            return tag, -1
        return tag, self._held.append(t, held, w_hat)

    def _output(self, sample, flags=(), base=None):
        """The :class:`Output` of a compensated sample (``flags`` its flags; ``base`` the frame_id of an output in
        the base's axes), None where its reading was saturated (or its stamp is not known: counted, never
        published)."""
        frame = self._frames.pop(sample.t, None)
        if frame is None:
            self.counts["unmatched"] += 1
            return None
        stamp, frame_id, arrival, tag, seq = frame
        if sample.contact and seq >= 0:
            self._held.contact(seq)
        if tag == "saturated":
            self._withhold("saturated", stamp, frame_id)
            return None
        if self._last_out is not None and sample.t - self._last_out > 1.5 * self.dt:
            self.counts["output_gaps"] += 1
        self._last_out = sample.t
        self.contact, self.last_sample, self.restarting = sample.contact, sample, False
        self.counts["published"] += 1
        return Output(sample, stamp, frame_id if base is None else base, arrival, flags)

    def _forget(self, before):
        """The readings older than ``before`` whose output did not come: withheld, by cause (module docstring)."""
        window_end = (self._segment_start if self._segment_start is not None else -np.inf) + self.settings.window
        frames = self._frames                           # in stamp order: the readings since the last restart
        while frames and (t := next(iter(frames))) < before - 1e-9:
            frame = frames.pop(t)
            tag = frame[3]
            if self._gap_budget > 0:
                self._gap_budget -= 1
                cause = "gap"
            elif tag in ("saturated", "apart"):
                cause = tag
            elif t < window_end:
                cause = "window"
            else:
                cause = "stale" if tag == "stale" else "motion"
            self._withhold(cause, frame[0], frame[1])
        self._gap_budget = 0

    def reset(self, why):
        """After a failure (``why``): the readings held counted (``error``), the window restarted with a new
        compensator; the motion kept."""
        with self.lock:
            for entry in list(self._pending) + list(self._frames.values()):
                self._withhold("error", entry[2] if len(entry) > 5 else entry[0],
                               entry[3] if len(entry) > 5 else entry[1])
            self._pending.clear()
            self._frames.clear()
            self._recent.clear()
            self._last_t = self._segment_start = self._grid0 = self._window_epoch = None
            self._gap_budget = 0
            if self.dt is not None:
                self.compensator = self._build()
                self._withheld_gap = 0
            self.restarting = True
            self._notice("error", f"the window restarted after a failure ({why})")
            self._snap()

    def _withhold(self, cause, stamp, frame_id, said=True):
        """A reading given no output, counted by its cause; kept for the node's flags (:attr:`dropped`) unless
        it is a repeated stamp's (published under that stamp) or decimated (said once, at start)."""
        self.withheld[cause] += 1
        if stamp is not None and cause not in ("duplicate", "decimated"):
            self.dropped.append((stamp, frame_id, cause))

    def unpublished(self, outputs):
        """Outputs the node could not publish (a failure said in its log): out of ``published``, into the ledger's
        ``invalid``."""
        with self.lock:
            self.counts["published"] -= len(outputs)
            self.withheld["invalid"] += len(outputs)

    # --- the state --------------------------------------------------------------------------------------------
    def _snap(self):
        """Replace :attr:`snapshot` (lock held)."""
        c, sample = self.compensator, self.last_sample
        self._snapped = time.monotonic()
        self.snapshot = Snapshot(
            counts=dict(self.counts), withheld=dict(self.withheld), conditions=dict(self.conditions),
            events={} if c is None else dict(c.events), contact=bool(self.contact),
            offset=None if c is None else c.offset, offset_sd=None if sample is None else sample.offset_sd,
            stale=self.stale, apart=self._apart_from is not None or "apart" in self.conditions,
            restarting=self.restarting,
            started=sample is not None,
            saturated=self._last_t is not None and 0 <= self._last_t - self._saturated_at < SATURATED_HOLD,
            last_arrival=self.last_arrival, backlog=len(self._pending),
            waiting=len(self._pending) + len(self._frames) + (self._stray is not None),
            dt=self.dt, delay=self.delay, decimation=self.decimation,
            motion_lag=None if self._newest_in is None or not self._motion else self._newest_in - self._motion[-1][0],
            tool_change=self.tool_change)

    def state(self):
        """One of :data:`STATES`: "not ready" too where no reading has come for
        ``stale_timeout`` s (wall time). Takes the lock (the node's diagnostics read :attr:`snapshot` instead)."""
        self.snap()
        return state_of(self.snapshot, time.monotonic(), self.settings.stale_timeout)

    def backlog(self):
        """The readings waiting for the motion."""
        return len(self._pending)

    # --- the services -----------------------------------------------------------------------------------------
    def tare(self, force=False):
        """``(success, message)`` of ``~/tare`` (:meth:`fmscal.analysis.Compensator.tare`); ``force``: the
        contact's size it absorbed said (the change of the output's force, N)."""
        with self.lock:
            if self.compensator is None:
                return False, "tare refused: no reading compensated yet"
            before = self.compensator.offset
            try:
                b = self.compensator.tare(force=force)
            except Exception as err:                   # the Compensator's refusal (a contact, no sample yet)
                first = str(err).splitlines()[0]
                return False, ((first.split(";")[0] + "; tare with the tool free, or call ~/tare_force where the "
                                "offset itself is off (a sensor zeroed by its hardware, a drift without "
                                "track_offset); ~/reload undoes a wrong ~/tare_force") if "contact" in first
                               else first)
            self._snap()
        message = "tared: offset " + " ".join(f"{v:.6g}" for v in b) + " (the reading's units)"
        if force:
            moved = np.asarray(self.calibration.S) @ (b - before)      # the output's change, sensor axes
            names = list(self.model.wrench_names)
            force_part = [moved[names.index(n)] for n in ("fx", "fy", "fz") if n in names]
            torque = [moved[names.index(n)] for n in ("tx", "ty", "tz", "M") if n in names]
            message += (f"; absorbed {np.linalg.norm(force_part):.4g} N and {np.linalg.norm(torque):.4g} N m "
                        "(were that a contact, ~/reload undoes it)")
        return True, message

    def tare_force(self):
        """``(success, message)`` of ``~/tare_force``: :meth:`tare` even where the samples read as a contact
        (``Compensator.tare(force=True)``), for an offset itself far off; the tool must be free. The answer
        names the wrench it absorbed."""
        return self.tare(force=True)

    def identify(self):
        """``(success, message)`` of ``~/identify_payload``: the payload fitted to the motion and readings held
        since the last call (:func:`fit_held`, here in this thread); the compensation then uses it (and ``~/save``
        writes it). The node runs the fit in a process of its own (:meth:`identify_job`, :meth:`identified_by`).
        """
        job = self.identify_job()
        if isinstance(job, tuple):
            return job
        return self.identified_by(fit_held(job, self.motion))

    def identify_job(self):
        """What :func:`fit_held` needs of the held samples (a dict, the held samples then released), or
        ``(False, refusal)``."""
        if self.model.attitude != "quaternion":
            return False, (f"identify_payload refused: fmscal's payload fits are a 6-axis sensor's, and this "
                           f"calibration is of a {self.model.name} reading ({' '.join(self.model.wrench_names)}); "
                           "the payload in use is the calibration's")
        with self.lock:
            held = self._held.take()
            unoriented, self._unoriented = self._unoriented, 0
            b = None if self.compensator is None else self.compensator.offset
        if held is None and unoriented:
            return False, (f"identify_payload refused: the IMU gave no orientation ({unoriented} samples with "
                           "orientation_covariance[0] == -1 since the last call); the static fit needs the sensor's "
                           "attitude at each held pose: an IMU that estimates its orientation, or pose_topic")
        if held is None or len(held[0]) < 2 or held[0][-1] - held[0][0] < MIN_HELD:
            n = 0 if held is None else len(held[0])
            return False, f"identify_payload refused: {n} samples held since the last call (at least " \
                          f"{MIN_HELD:g} s of motion without a gap needed)"
        cal = self.calibration
        return dict(held=held, S=np.asarray(cal.S), offset=b,
                    gravity=self.settings.gravity if self.settings.gravity is not None else cal.gravity,
                    reading=self.settings.reading or cal.reading, inertia=self.model.payload.inertia,
                    false_alarm=float(self.settings.contact_threshold), dt=self.dt,
                    margin=self.settings.window + self.settings.delay)

    def identified_by(self, result):
        """Apply :func:`fit_held`'s result (the payload in use replaced where it succeeded);
        ``(success, message)``."""
        if result.get("payload") is not None:
            mass, inertia, com = result["payload"]
            payload = SpatialModel.payload_from(mass, inertia, com)
            b = result.get("offset")
            st = _identified_setup(self.setup, payload, result, b)
            compensator = None if self.compensator is None else self._rebuilt(st)
            with self.lock:
                if compensator is not None:
                    self._swap(compensator)
                self.setup, self.identified = st, result
                self.model = compensation_model(self.calibration, payload)
                self._condition("tool_change", None)
                self._snap()
        return bool(result["ok"]), result["message"]

    def save(self):
        """``(success, message)`` of ``~/save``: with a calibration, the calibration with the offset in use and the
        payload in use, dated now; with a payload file alone, a payload file (``fmscal-payload``, as
        ``fmscal identify-payload --save`` writes): the payload in use with its uncertainty, the offset in use,
        the file's gravity, mounting, sign and noise."""
        path = self.settings.save_path
        if not path:
            return False, "save refused: set the parameter save_path"
        with self.lock:
            st, identified = self.setup, self.identified
            if not self.settings.calibration:
                document = self.payload_document()
            else:
                b = None if self.compensator is None else self.compensator.offset
                document = replace(self.calibration, b=self.calibration.b if b is None else b,
                                   payload=st.payload or self.calibration.payload, date=None,
                                   latency=self.latency if self.settings.source == "pose_topic" else
                                   self.calibration.latency)
        try:
            if isinstance(document, PayloadEstimate):
                document.save(path)
            else:
                document.save(path, force=True, overwrite=True)       # ~/save rewrites save_path by design
        except Exception as err:
            return False, "save failed: " + (str(err).splitlines()[0] if str(err) else repr(err))
        what = " (a payload file)" if isinstance(document, PayloadEstimate) else ""
        offset = document.b if isinstance(document, PayloadEstimate) else document.offset
        mass = st.payload.mass if st.payload is not None else self.calibration.payload.mass
        return True, f"saved {path}{what}: offset " + " ".join(f"{v:.6g}" for v in offset) + \
            ("" if identified is None else f", the identified payload (mass {mass:.4g} kg)")

    def payload_document(self):
        """The payload file ``~/save`` writes with a payload file alone (:class:`PayloadEstimate`): the payload and
        the offset in use, with their uncertainty (lock held, or taken here)."""
        b = None if self.compensator is None else self.compensator.offset
        return _payload_document(self.estimate, self.setup, b)

    def reload(self):
        """``(success, message)`` of ``~/reload``: the calibration (and payload) files read again."""
        try:
            st, estimate, latency = _load(self.settings)
            model = compensation_model(st.calibration, st.payload)
            if model.n_w != self.n:
                raise Ros2Error(f"the calibration is now of a {model.name} reading; the node started with another")
            compensator = None if self.compensator is None else self._rebuilt(st)
        except Exception as err:
            return False, "reload refused, the calibration in use kept: " + (str(err).splitlines()[0] or repr(err))
        with self.lock:
            self.setup, self.estimate, self.latency, self.model = st, estimate, latency, model
            self.identified = None
            if compensator is not None:
                self._swap(compensator)
            self._condition("tool_change", None)
            self._snap()
        offset = " ".join(f"{v:.6g}" for v in st.calibration.offset)
        return True, f"reloaded {self.settings.calibration or self.settings.payload}: offset {offset}"


def _identified_setup(st, payload, result, b):
    """The setup after ``~/identify_payload``: its payload the fit's, the offset it was fitted at (``b``; None:
    kept); where a payload file's covariance is in use (K2), the fit's sds in place of the file's for what it
    determined (an inertia it did not determine keeps its bound, K3)."""
    calibration = st.calibration if b is None else replace(st.calibration, b=np.asarray(b, dtype=float))
    cov, bounded = None, False
    if st.cov is not None:
        cov = np.array(st.cov, dtype=float)
        sd = result["sd"]
        groups = [(slice(0, 1), [sd["mass"]]), (slice(1, 4), sd["com"])]
        if sd.get("inertia") is not None:
            groups.append((slice(4, 10), sd["inertia"]))
        else:
            bounded = st.inertia_bounded
        for rows, values in groups:
            cov[rows, :], cov[:, rows] = 0.0, 0.0
            cov[rows, rows] = np.diag(np.square(np.asarray(values, dtype=float)))
    return replace(st, calibration=calibration, payload=payload, cov=cov, inertia_bounded=bounded, warnings=[])


def _payload_document(estimate, st, b):
    """The payload file ``~/save`` writes with a payload file alone: ``estimate`` (the file read at start) with
    the payload in use, its sds (the diagonal of the setup's covariance, K2), and the offset in use ``b``."""
    payload = st.payload if st.payload is not None else st.calibration.payload     # the file's own (K1), or a fit's
    cov = np.array(estimate.tracked().cov if estimate.cov is not None else st.cov, dtype=float)
    if st.cov is not None:
        cov[:10, :] = cov[:, :10] = 0.0
        cov[:10, :10] = st.cov[:10, :10]
    inertia = None if st.inertia_bounded else np.asarray(payload.inertia, dtype=float)
    if inertia is None:
        cov[4:10, :] = cov[:, 4:10] = np.inf
    sd = np.sqrt(np.diag(cov))
    return replace(estimate.tracked(), mass=float(payload.mass), mass_std=float(sd[0]),
                   com=np.asarray(payload.com, dtype=float), com_std=sd[1:4], inertia=inertia,
                   inertia_std=None if inertia is None else sd[4:10],
                   b=np.asarray(estimate.b if b is None else b, dtype=float), cov=cov, payload_determined=True)


def _clean_stretches(t, contact, starts, false_alarm, dt, margin):
    """The held samples' stretches without a gap or a contact: ``(start, stop)`` index pairs. A contact is a run of
    flagged samples (C4) beyond what false alarms give in :data:`fmscal.analysis.TARE_WINDOW` s but with probability
    :data:`TARE_FALSE_REFUSAL` (tare's rule), widened by ``margin`` s each way."""
    n = len(t)
    width = max(1, int(round(TARE_WINDOW / dt)))
    bound = binom.isf(TARE_FALSE_REFUSAL, width, false_alarm)
    flagged = np.convolve(contact.astype(float), np.ones(width), mode="same") > bound
    bad = np.zeros(n, bool)
    if flagged.any():
        grow = int(round(margin / dt)) + width
        bad = np.convolve(flagged.astype(float), np.ones(2 * grow + 1), mode="same") > 0
    cuts = np.flatnonzero(starts | np.r_[True, bad[1:] != bad[:-1]])
    bounds = np.r_[cuts, n]
    return [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:]) if not bad[a] and b - a >= 2]


def fit_held(job, motion):
    """``~/identify_payload``'s fit of :meth:`Pipeline.identify_job`'s held samples (here, or in a process of its
    own: :mod:`._worker`): a dict, ``ok``, ``message``, and ``payload`` ``(mass, inertia, com)`` to use (None:
    keep the one in use) with the ``offset`` it was fitted at and ``sd`` (``mass``, ``com``, and ``inertia``,
    None where the fit kept the one in use).

    Poses (a pose stream, or joint states through the URDF): :func:`fmscal.observers.payload.identify_payload`
    on the longest held stretch without a gap or a contact (mass, centre of mass and inertia). An IMU: its
    orientation turned into the sensor's attitude, ``R_S = R_IMU C^T`` (``C`` the IMU's axes in the sensor's,
    ``imu_rotation``), the samples outside contacts an attitude-only log whose held segments
    (:func:`fmscal.plant.io.held_table`) are fitted statically (:func:`fmscal.observers.payload.fit_static`,
    gravity the ``gravity`` parameter's or the calibration's, in the IMU's world): the mass and centre of mass;
    the inertia, which no held pose shows, is kept from the payload in use."""
    t, held, w_hat, contact, starts = job["held"]

    def refused(why):
        return dict(ok=False, message="identify_payload refused: " + why, payload=None)
    if not motion.breaks_hold:
        starts = np.zeros_like(starts)
        starts[0] = True
    stretches = _clean_stretches(t, contact, starts, job["false_alarm"], job["dt"], job["margin"])
    if not stretches:
        return refused(f"{len(t)} samples held, all within a contact (at least {MIN_HELD:g} s without one needed)")
    left = f"{len(t) - sum(b - a for a, b in stretches)} samples in contacts or gaps left out"
    if motion.breaks_hold:
        a, b = max(stretches, key=lambda s: (t[s[1] - 1] - t[s[0]], s[0]))
        if t[b - 1] - t[a] < MIN_HELD:
            return refused(f"the longest stretch held without a gap or a contact is {t[b - 1] - t[a]:.3g} s (at "
                           f"least {MIN_HELD:g} s of motion needed)")
        keep = np.arange(a, b)
    else:
        keep = np.concatenate([np.arange(a, b) for a, b in stretches])
    t, held, w_hat = t[keep], held[keep], w_hat[keep]
    try:
        data = motion.held_log(t - t[0], held, w_hat)   # poses; joint angles' poses; IMU attitudes
    except Exception as err:
        return refused(str(err).splitlines()[0] if str(err) else repr(err))
    reading, gravity, S = job["reading"], job["gravity"], job["S"]
    if isinstance(data, AttitudeLog):
        try:
            table, used, why = held_table(data)
            fit = fit_static(table, S=S, gravity=gravity, reading=reading,   # the reading's own noise, eq. (E4)
                             noise=reading_noise(table.noise, S, used * len(t) / len(table)))
        except Exception as err:
            return refused(str(err).splitlines()[0] if str(err) else repr(err))
        if not fit.payload_determined:
            return dict(ok=False, payload=None, message=(
                f"identify_payload: the held poses do not determine the payload (mass {fit.mass:.4g} +- "
                f"{fit.mass_std:.2g} kg, {len(table)} held poses); kept the one in use"))
        return dict(ok=True, payload=(fit.mass, job["inertia"], fit.com), offset=job["offset"],
                    sd=dict(mass=float(fit.mass_std), com=np.asarray(fit.com_std, dtype=float), inertia=None), message=(
            f"payload identified from {len(table)} held poses ({used:.0%} of {t[-1] - t[0]:.3g} s; {left}): mass "
            f"{fit.mass:.4g} +- {fit.mass_std:.2g} kg, com " + " ".join(f"{v:.4g}" for v in fit.com)
            + " m; the inertia kept (no held pose shows it)"
            + ("" if fit.converged else "; not converged: " + "; ".join(fit.warnings[:1]))))
    try:
        estimate = identify_payload(data, S=S, gravity=gravity, reading=reading)
    except Exception as err:
        return refused(str(err).splitlines()[0] if str(err) else repr(err))
    if estimate.inertia is None or not estimate.payload_determined:
        return dict(ok=False, payload=None, message=(
            f"identify_payload: the held motion does not determine the payload (mass {estimate.mass:.4g} +- "
            f"{estimate.mass_std:.2g} kg); kept the one in use"))
    return dict(ok=True, payload=(estimate.mass, estimate.inertia, estimate.com), offset=job["offset"],
                sd=dict(mass=float(estimate.mass_std), com=np.asarray(estimate.com_std, dtype=float),
                        inertia=np.asarray(estimate.inertia_std, dtype=float)), message=(
        f"payload identified from {len(t)} samples ({t[-1] - t[0]:.3g} s; {left}): mass {estimate.mass:.4g} +- "
        f"{estimate.mass_std:.2g} kg, com " + " ".join(f"{v:.4g}" for v in estimate.com) + " m"
        + ("" if estimate.converged else "; not converged: " + "; ".join(estimate.warnings[:1]))))


