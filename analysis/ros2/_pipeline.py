"""What the node does between its messages, without rclpy: readings and motion matched by their stamps, the
motion interpolated at each reading's time, the compensation, the services' work, the node's state.

The node (:mod:`._node`) turns messages into numbers and calls :class:`Pipeline`; every call here takes and
returns plain numbers, so the matching is tested without ROS too.

Matching. A motion sample stamped ``s`` was taken at ``s - latency`` (the ``latency`` parameter; unset, the
calibration's for a pose stream, 0 for joint states and an IMU). A reading stamped ``t`` waits until the
motion's newest sample reaches ``t``; the motion is then interpolated at ``t`` (the model's
:meth:`fmscal.plant.Model.interpolate_pose`: SLERP for a quaternion, linear otherwise; joint states and an IMU's
rates and specific force linearly) and the reading is pushed into :class:`fmscal.analysis.Compensator` with it.
A reading the motion has not reached when a reading ``stale_timeout`` s newer arrives is pushed with no motion:
the motion is stale, and the compensator, which never extrapolates, stops the output until the motion covers
its window again.

Angles. A pose's angle columns (the model's :attr:`fmscal.plant.Model.angle_names`: the planar ``theta``, which
the node takes from the quaternion, ``2 atan2(q_z, q_w)``, and a publisher may wrap into (-pi, pi]) are unwrapped
against the motion's previous sample as they come::

    theta_k <- theta_k - 2 pi round((theta_k - theta_{k-1}) / (2 pi))                               (U1)

so that a payload turning through many revolutions is differentiated without the 2 pi steps (a turn of more
than pi between two motion samples cannot be told from one the other way). A quaternion's sign is made
continuous by :class:`fmscal.analysis.Compensator`.
"""

import threading
import time
from collections import deque
from dataclasses import replace

import numpy as np

from fmscal.plant import Calibration, SpatialModel
from fmscal.plant.io import AttitudeLog, held_table
from fmscal.plant.physics import quaternion_multiply
from fmscal.observers.payload import PayloadEstimate, fit_static, identify_payload, reading_noise

from .._compensate import Compensator, compensation_model
from .._motion import PoseMotion, quaternion_from_matrix, quaternion_to_matrix
from ._parameters import Ros2Error

__all__ = ["Pipeline", "Output", "STATES", "DT_SAMPLES", "sensor_pose"]

#: The node's states (diagnostics): no output yet, outputs coming, the motion stale, a reading saturated.
STATES = ("not ready", "running", "motion stale", "saturated")
#: The number of wrench stamps whose median interval is the sample time (parameter ``sample_time`` 0).
DT_SAMPLES = 21
#: How long a saturated reading keeps the state ``saturated``, s.
SATURATED_HOLD = 1.0


class Output:
    """One output: the :class:`fmscal.analysis.ContactSample`, the reading's stamp (as it came: any object)
    and frame, and the reading's arrival time (``time.monotonic``)."""

    __slots__ = ("sample", "stamp", "frame_id", "arrival")

    def __init__(self, sample, stamp, frame_id, arrival):
        self.sample, self.stamp, self.frame_id, self.arrival = sample, stamp, frame_id, arrival


def _load(settings):
    """The calibration (as saved), the payload replacing its own (or None), and the latency in use."""
    calibration = Calibration.load(settings.calibration)
    payload = None
    if settings.payload:                              # the model's payload (refused here: no inertia, another case)
        payload = compensation_model(calibration, PayloadEstimate.load(settings.payload)).payload
    # the calibration's latency is its pose stream's: a joint-state or an IMU stream has its own (the parameter)
    own = (calibration.latency or 0.0) if settings.source == "pose_topic" else 0.0
    latency = settings.latency if settings.latency is not None else own
    return calibration, payload, latency


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


class Pipeline:
    """Readings and motion in, contact wrenches out (module docstring); thread-safe (one lock).

    Parameters
    ----------
    settings : Settings
        The node's parameters, checked (:func:`fmscal.analysis.ros2.settings`).
    motion : PoseMotion, JointMotion or ImuMotion, optional
        The motion's source (None: poses); :meth:`add_motion` takes its samples as its ``interpolate`` gives
        them (a pose in the model's order, ``(q, dq, ddq)``, ``(q_wxyz, omega, f)``).
    """

    def __init__(self, settings, motion=None):
        self.settings, self.motion = settings, PoseMotion() if motion is None else motion
        self.lock = threading.Lock()
        self.calibration, self.payload, self.latency = _load(settings)
        self.model = compensation_model(self.calibration, self.payload)
        self.n = self.model.n_w
        self.dt = settings.sample_time or None
        self.compensator = None
        self._pending = deque()                       # (t, w_hat, stamp, frame_id, arrival)
        self._motion = deque()                        # (t taken, value)
        self._frames = {}                             # t -> (stamp, frame_id, arrival) of pushed readings
        self._saturated = set()                       # t of pushed saturated readings
        self._held = deque()                          # (t, pose, w_hat) for identify_payload
        self._unoriented = 0                          # IMU samples without an orientation since the last call
        self._recent = deque()                        # (t, w_hat, motion) of the rows the filter still holds
        self._last_t = None
        # the angle columns (U1), by what the source and the model declare; their last values
        self._angles = self.motion.angle_columns(self.model)
        self._last_angles = None
        self.last_arrival = -np.inf                   # time.monotonic() of the newest reading
        self.motion_frame = ""
        self.identified = None
        self.counts = dict(received=0, published=0, stale=0, saturated=0, out_of_order=0, gaps=0, motion=0)
        self.contact = False
        self.last_sample = None
        self.stale = False
        self._saturated_at = -np.inf
        self.warnings = []
        self._limit = None if settings.saturation is None else np.broadcast_to(settings.saturation, (self.n,))
        self._warm_up()

    def _warm_up(self):
        """A compensator run on a few samples at rest before any message: what it builds on its first samples
        (the dynamics' compiled function, the filter) is built now, not while the first readings queue up."""
        dt = self.dt or 0.001
        saved, self.dt = self.dt, dt
        try:
            warm = self._build()
        except Exception:                       # a setting the real sample time may accept: found then
            return
        finally:
            self.dt = saved
        n = int(round((self.settings.window + self.settings.delay) / dt)) + 4
        rest = self.motion.rest(self.model)
        self._feed(warm, [(i * dt, np.zeros(self.n), rest) for i in range(n)])

    # --- the compensator --------------------------------------------------------------------------------------
    def _build(self, calibration=None, payload=None):
        """A Compensator of the calibration (its latency 0: the stamps are aligned here), at ``self.dt``."""
        s = self.settings
        calibration = self.calibration if calibration is None else calibration
        changes = {"latency": 0.0}
        if s.reading is not None:
            changes["reading"] = s.reading
        if s.gravity is not None:
            changes["gravity"] = s.gravity
        kwargs = dict(payload=self.payload if payload is None else payload, direction=s.direction,
                      window=s.window, delay=s.delay, false_alarm=float(s.contact_threshold),
                      track_offset=bool(s.track_offset))
        if s.drift_intensity is not None:
            kwargs["drift_intensity"] = s.drift_intensity[0] if len(s.drift_intensity) == 1 else s.drift_intensity
        kwargs.update(motion=self.motion, frame=s.output_frame, point=s.tool_point)
        compensator = Compensator(replace(calibration, **changes), self.dt, **kwargs)
        self.warnings = list(compensator.warnings)
        return compensator

    @property
    def delay(self):
        """s: the causal filter's delay (None before the sample time is known)."""
        return None if self.compensator is None else self.compensator.delay

    # --- the streams ------------------------------------------------------------------------------------------
    def add_motion(self, t, value, frame_id=""):
        """A motion sample stamped ``t`` (s): a pose (model order), ``(q, dq, ddq)`` or ``(q_wxyz, omega, f)``."""
        t = float(t) - self.latency
        with self.lock:
            self.counts["motion"] += 1
            self.motion_frame = frame_id
            if self._motion and t <= self._motion[-1][0]:
                return
            if self._angles:
                value = self._unwrapped(value)
            self._motion.append((t, value))

    def _unwrapped(self, pose):
        """``pose`` with its angle columns unwrapped against the previous motion sample's (U1)."""
        pose = np.array(pose, dtype=float)
        angles = pose[self._angles]
        if self._last_angles is not None:
            angles = angles - 2 * np.pi * np.round((angles - self._last_angles) / (2 * np.pi))
            pose[self._angles] = angles
        self._last_angles = angles
        return pose

    def add_reading(self, t, w_hat, stamp=None, frame_id="", arrival=None):
        """A raw reading stamped ``t`` (s), queued; :meth:`process` compensates it once the motion covers it.
        Returns False where it was dropped (not newer than the last reading)."""
        arrival = time.monotonic() if arrival is None else arrival
        with self.lock:
            self.counts["received"] += 1
            self.last_arrival = arrival
            newest = self._pending[-1][0] if self._pending else self._last_t
            if newest is not None and t <= newest:
                self.counts["out_of_order"] += 1
                return False
            self._pending.append((float(t), np.asarray(w_hat, dtype=float), stamp, frame_id, arrival))
            return True

    def process(self):
        """Compensate every queued reading the motion covers, or has left stale; the outputs (list of
        :class:`Output`), oldest first."""
        with self.lock:
            if self.compensator is None:
                if self.dt is None:
                    if len(self._pending) < DT_SAMPLES:
                        return []
                    self.dt = float(np.median(np.diff([p[0] for p in self._pending])))
                    if not self.dt > 0:
                        raise Ros2Error("the wrench stamps do not increase: set sample_time")
                self.compensator = self._build()
            if not self._pending:
                return []
            return self._drain(self._pending[-1][0])

    def _drain(self, newest):
        """Push every pending reading the motion covers, or has left stale, as one block; the outputs."""
        timeout = self.settings.stale_timeout
        rows = []
        while self._pending:
            t, w_hat, stamp, frame_id, arrival = self._pending[0]
            value = self._at(t)
            gap = value is _GAP
            if value is _WAIT:
                if newest - t <= timeout:
                    break
                value = None
                self.counts["stale"] += 1
                self.stale = True
            elif gap:
                value = None
            elif value is not None:
                self.stale = False
            self._pending.popleft()
            rows.append((t, w_hat, value))
            self._note(t, w_hat, stamp, frame_id, arrival, value, gap)
        if not rows:
            return []
        samples = self._feed(self.compensator, rows)
        self._recent.extend(rows)
        while len(self._recent) > int(round((self.settings.window + self.settings.delay) / self.dt)) + 4:
            self._recent.popleft()
        out = [o for o in (self._output(s) for s in samples) if o is not None]
        self._forget(rows[-1][0] - self.compensator.delay)
        return out

    def _at(self, t):
        """The motion at ``t`` (interpolated), None where it starts after ``t``, or ``_WAIT``; ``_GAP`` where no
        motion sample lies within half a reading's step of ``t`` (a motion slower than the readings).

        Each motion sample is given to the reading nearest it only, interpolated to that reading's stamp; the
        readings between get none, as :meth:`fmscal.analysis.Compensator.push` takes a sparser stream. Given to
        every reading, interpolated values would count as independent samples: the motion's noise, and with it
        the output's covariance, would come out too small."""
        m = self._motion
        while len(m) >= 2 and m[1][0] <= t:
            m.popleft()
        if not m or m[-1][0] < t:
            return _WAIT
        if m[0][0] > t:
            return None
        (t0, v0), (t1, v1) = m[0], (m[1] if len(m) > 1 else m[0])
        if t0 == t or t1 == t0:
            return v0
        if self.dt is not None and t - t0 >= 0.5 * self.dt and t1 - t > 0.5 * self.dt:
            return _GAP
        return self.motion.interpolate(self.model, t, t0, v0, t1, v1)

    def _feed(self, compensator, rows):
        """Push rows ``(t, w_hat, motion)`` into ``compensator`` as one block; its samples."""
        return compensator.push_many([r[0] for r in rows], [r[1] for r in rows],
                                     **{self.motion.keyword: self.motion.stack([r[2] for r in rows], self.model)})

    def _rebuild(self, calibration=None, payload=None):
        """A new compensator (a new calibration or payload) fed the rows the old one's filter holds, their
        outputs (already published) dropped: the output goes on with no gap."""
        compensator = self._build(calibration, payload)
        if self._recent:
            self._feed(compensator, list(self._recent))
        self.compensator = compensator

    def _note(self, t, w_hat, stamp, frame_id, arrival, value, gap=False):
        """A reading about to be pushed: its stamp kept for its output, saturation, the held motion (``gap``: no
        motion sample at this reading, the stream still running)."""
        if self._last_t is not None and t - self._last_t > 1.5 * self.dt:
            self.counts["gaps"] += 1
        self._last_t = t
        if self._limit is not None and (np.abs(w_hat) >= self._limit).any():
            self._saturated.add(t)
            self._saturated_at = t
        self._frames[t] = (stamp, frame_id, arrival)
        if gap:
            return
        if value is None:
            if self.motion.breaks_hold:                # identify_payload takes the newest stretch without a gap
                self._held.clear()
            return
        held = self.motion.held(value)                 # a pose, joint angles, or an IMU's attitude
        if held is None:                               # an IMU without orientation: nothing to hold
            self._unoriented += 1
        else:
            self._hold(t, held, w_hat)

    def _hold(self, t, motion, w_hat):
        """Keep a sample for ``~/identify_payload`` (the newest ``identify_buffer`` s)."""
        self._held.append((t, motion, w_hat))
        while self._held and self._held[0][0] < t - self.settings.identify_buffer:
            self._held.popleft()

    def _output(self, sample):
        """The :class:`Output` of a compensated sample, None where its reading was saturated."""
        stamp, frame_id, arrival = self._frames.pop(sample.t, (None, "", time.monotonic()))
        if sample.t in self._saturated:
            self._saturated.discard(sample.t)
            self.counts["saturated"] += 1
            return None
        self.contact, self.last_sample = sample.contact, sample
        if self.settings.output_frame == "base":
            frame_id = self.settings.base_frame or self.motion_frame
        return Output(sample, stamp, frame_id, arrival)

    def _forget(self, before):
        """Drop the stamps of readings older than ``before`` (their outputs will not come)."""
        for key in [k for k in self._frames if k < before - 1e-9]:
            del self._frames[key]
        self._saturated = {k for k in self._saturated if k >= before - 1e-9}

    # --- the state --------------------------------------------------------------------------------------------
    def state(self):
        """One of :data:`STATES`: "not ready" too where no reading has come for ``stale_timeout`` s (wall time)."""
        with self.lock:
            if self._last_t is not None and self._last_t - self._saturated_at < SATURATED_HOLD:
                return STATES[3]
            if self.stale:
                return STATES[2]
            silent = time.monotonic() - self.last_arrival > self.settings.stale_timeout
            return STATES[1] if self.last_sample is not None and not silent else STATES[0]

    def backlog(self):
        """The readings waiting for the motion."""
        return len(self._pending)

    # --- the services -----------------------------------------------------------------------------------------
    def tare(self, force=False):
        """``(success, message)`` of ``~/tare`` (:meth:`fmscal.analysis.Compensator.tare`)."""
        with self.lock:
            if self.compensator is None:
                return False, "tare refused: no reading compensated yet"
            try:
                b = self.compensator.tare(force=force)
            except Ros2Error as err:
                return False, str(err)
            except Exception as err:                   # the Compensator's refusal (a contact, no sample yet)
                first = str(err).splitlines()[0]
                return False, ((first.split(";")[0] + "; tare with the tool free, or call ~/tare_force where the "
                                "offset itself is off (a sensor zeroed by its hardware, a drift without "
                                "track_offset)") if "contact" in first else first)
        return True, "tared: offset " + " ".join(f"{v:.6g}" for v in b) + " (the reading's units)"

    def tare_force(self):
        """``(success, message)`` of ``~/tare_force``: :meth:`tare` even where the samples read as a contact
        (``Compensator.tare(force=True)``), for an offset itself far off; the tool must be free."""
        return self.tare(force=True)

    def identify(self):
        """``(success, message)`` of ``~/identify_payload``: the payload fitted to the motion and readings held
        since the last call; the compensation then uses it (and ``~/save`` writes it).

        Poses (a pose stream, or joint states through the URDF): :func:`fmscal.observers.payload.identify_payload`
        on the held stretch (mass, centre of mass and inertia). An IMU: its orientation turned into the sensor's
        attitude, ``R_S = R_IMU C^T`` (``C`` the IMU's axes in the sensor's, ``imu_rotation``), the samples an
        attitude-only log whose held segments (:func:`fmscal.plant.io.held_table`) are fitted statically
        (:func:`fmscal.observers.payload.fit_static`, gravity the ``gravity`` parameter's or the calibration's, in
        the IMU's world): the mass and centre of mass; the inertia, which no held pose shows, is kept from the
        payload in use. An IMU that publishes no orientation (``orientation_covariance[0] == -1``) is refused."""
        if self.model.attitude != "quaternion":
            return False, (f"identify_payload refused: fmscal's payload fits are a 6-axis sensor's, and this "
                           f"calibration is of a {self.model.name} reading ({' '.join(self.model.wrench_names)}); "
                           "the payload in use is the calibration's")
        with self.lock:
            held = list(self._held)
            self._held.clear()
            unoriented, self._unoriented = self._unoriented, 0
            b = None if self.compensator is None else self.compensator.offset
        if not held and unoriented:
            return False, (f"identify_payload refused: the IMU gave no orientation ({unoriented} samples with "
                           "orientation_covariance[0] == -1 since the last call); the static fit needs the sensor's "
                           "attitude at each held pose: an IMU that estimates its orientation, or pose_topic")
        if len(held) < 2 or held[-1][0] - held[0][0] < 1.0:
            return False, f"identify_payload refused: {len(held)} samples held since the last call (at least 1 s " \
                          "of motion without a gap needed)"
        t, motion, w_hat = (np.array(v) for v in zip(*held))
        cal = self.calibration
        gravity = self.settings.gravity if self.settings.gravity is not None else cal.gravity
        reading = self.settings.reading or cal.reading
        try:
            data = self.motion.held_log(t - t[0], motion, w_hat)   # poses; joint angles' poses; IMU attitudes
        except Exception as err:
            return False, "identify_payload refused: " + (str(err).splitlines()[0] if str(err) else repr(err))
        if isinstance(data, AttitudeLog):
            return self._identify_held(data, gravity, reading, b)
        try:
            estimate = identify_payload(data, S=cal.S, gravity=gravity, reading=reading)
        except Exception as err:
            return False, "identify_payload refused: " + (str(err).splitlines()[0] if str(err) else repr(err))
        if estimate.inertia is None or not estimate.payload_determined:
            return False, (f"identify_payload: the held motion does not determine the payload (mass "
                           f"{estimate.mass:.4g} +- {estimate.mass_std:.2g} kg); kept the one in use")
        self._use(SpatialModel.payload_from(estimate.mass, estimate.inertia, estimate.com), b)
        return True, (f"payload identified from {len(t)} samples ({t[-1] - t[0]:.3g} s): mass {estimate.mass:.4g} +- "
                      f"{estimate.mass_std:.2g} kg, com " + " ".join(f"{v:.4g}" for v in estimate.com) + " m"
                      + ("" if estimate.converged else "; not converged: " + "; ".join(estimate.warnings[:1])))

    def _identify_held(self, log, gravity, reading, b):
        """:meth:`identify` of an IMU: the held segments of its attitudes (``R_S = R_IMU C^T``), fitted
        statically."""
        t = log.t
        try:
            table, used, why = held_table(log)
            fit = fit_static(table, S=self.calibration.S, gravity=gravity, reading=reading,
                             noise=reading_noise(table.noise, self.calibration.S, used * len(t) / len(table)))
        except Exception as err:
            return False, "identify_payload refused: " + (str(err).splitlines()[0] if str(err) else repr(err))
        if not fit.payload_determined:
            return False, (f"identify_payload: the held poses do not determine the payload (mass {fit.mass:.4g} +- "
                           f"{fit.mass_std:.2g} kg, {len(table)} held poses); kept the one in use")
        self._use(SpatialModel.payload_from(fit.mass, self.model.payload.inertia, fit.com), b)
        return True, (f"payload identified from {len(table)} held poses ({used:.0%} of {t[-1] - t[0]:.3g} s): mass "
                      f"{fit.mass:.4g} +- {fit.mass_std:.2g} kg, com " + " ".join(f"{v:.4g}" for v in fit.com)
                      + " m; the inertia kept (no held pose shows it)"
                      + ("" if fit.converged else "; not converged: " + "; ".join(fit.warnings[:1])))

    def _use(self, payload, b):
        """The compensation goes on with ``payload`` (and the offset ``b`` it had), with no gap."""
        with self.lock:
            if self.compensator is not None:
                self._rebuild(self.calibration if b is None else replace(self.calibration, b=b), payload)
            self.payload = self.identified = payload
            self.model = compensation_model(self.calibration, payload)

    def save(self):
        """``(success, message)`` of ``~/save``: the calibration with the offset in use and the payload in use,
        dated now."""
        path = self.settings.save_path
        if not path:
            return False, "save refused: set the parameter save_path"
        with self.lock:
            b = None if self.compensator is None else self.compensator.offset
            cal = replace(self.calibration, b=self.calibration.b if b is None else b,
                          payload=self.payload or self.calibration.payload, date=None,
                          latency=self.latency if self.settings.source == "pose_topic" else self.calibration.latency)
        try:
            cal.save(path, force=True, overwrite=True)       # ~/save rewrites save_path by design
        except Exception as err:
            return False, "save failed: " + (str(err).splitlines()[0] if str(err) else repr(err))
        return True, f"saved {path}: offset " + " ".join(f"{v:.6g}" for v in (cal.offset)) + \
            ("" if self.identified is None else f", the identified payload (mass {cal.payload.mass:.4g} kg)")

    def reload(self):
        """``(success, message)`` of ``~/reload``: the calibration (and payload) files read again."""
        try:
            calibration, payload, latency = _load(self.settings)
            model = compensation_model(calibration, payload)
            if model.n_w != self.n:
                raise Ros2Error(f"the calibration is now of a {model.name} reading; the node started with another")
        except Exception as err:
            return False, "reload refused, the calibration in use kept: " + (str(err).splitlines()[0] or repr(err))
        with self.lock:
            self.calibration, self.payload, self.latency, self.model = calibration, payload, latency, model
            self.identified = None
            if self.compensator is not None:
                self._rebuild()
        return True, f"reloaded {self.settings.calibration}: offset " + " ".join(f"{v:.6g}" for v in calibration.offset)


_WAIT = object()
_GAP = object()
