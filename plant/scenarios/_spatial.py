"""Named spatial scenarios: a 6-axis sensor on a payload moving in 3D under gravity.

The motion is imposed (a robot arm or a hand moves the payload) and the
sensor reads the wrench that motion needs (:func:`fmscal.plant.physics._rigid_body.
prescribed_motion`: inverse dynamics, differentiated exactly). The raw
reading is ``w_hat = S^-1 w + b + n`` (so that ``w = S (w_hat - b)``), with
``S`` the identity plus cross-talk, ``b`` an offset and ``n`` white noise;
the pose is the true one, turned by a white attitude noise about the sensor's
axes and moved by a white position noise, at the pose rate, with dropped
frames and a latency where the scenario says.

Scenarios (:data:`SPATIAL_SCENARIOS`):

- ``spatial-arm``: a tool on a robot's wrist, poses from joint encoders at
  1 kHz with small noise, a multisine that turns the tool through large
  angles (tens of degrees about every axis);
- ``spatial-mocap``: the same kind of motion tracked by motion capture at
  200 Hz, 2 % of frames dropped, 5 ms behind the sensor, 0.1 mm and 0.1 deg;
- ``spatial-static``: ten held attitudes under gravity (3 s each), joined
  by slow 5 s moves: the log determines only part of ``S``;
- ``spatial-weak``: small rotations (a few degrees) and small translations;
- ``spatial-drift``: ``spatial-arm`` with each channel's gain drifting by
  5 % over the run.
"""

from dataclasses import dataclass, replace

import casadi as ca
import numpy as np
from scipy.spatial.transform import Rotation

from fmscal.plant.io import MIN_POSES, MIN_SAMPLES, Log, Truth, simulate_table
from fmscal.plant.numerics import FmscalError
from fmscal.plant.physics import (GRAVITY, SpatialModel, CalibrationSchedule, NoiseSpec, SpatialPayload,
                                  prescribed_motion, quaternion_multiply)
from ._planar import pose_frames

__all__ = ["SpatialScenario", "SPATIAL_SCENARIOS", "TOOL", "draw_spatial_S"]

#: A 1.2 kg tool on a wrist sensor: centre of mass 6 cm out along z, a full inertia tensor (kg m^2).
TOOL = SpatialPayload(1.2, (4e-3, 5e-3, 2.5e-3, 2e-4, -1e-4, 1.5e-4), (0.01, -0.005, 0.06))
#: Most samples a simulated spatial log may have (2000 s at 1 kHz): the casadi map of the motion holds every
#: sample at once while the log is drawn, and its memory grows with them.
_MAX_SAMPLES = 2_000_000
#: Most held poses a simulated pose table may have.
MAX_POSES = 100_000


def draw_spatial_S(rng, crosstalk=0.02):
    """Draw a 6x6 ``S``: the identity plus cross-talk, in the reading's units.

    Gains ``1 + N(0, 1.5 crosstalk)`` on the diagonal; the torque-torque and
    force-force blocks' off-diagonal entries ``N(0, crosstalk)``; force into
    torque ``N(0, crosstalk * 0.1 m)``; torque into force ``N(0, crosstalk *
    10 / m)`` (a sensor's cross-talk is a fraction of the full scale, whose
    torque and force differ by about a tenth of a metre).

    Parameters
    ----------
    rng : numpy.random.Generator
    crosstalk : float

    Returns
    -------
    ndarray, shape (6, 6)
    """
    scale = np.block([[np.full((3, 3), 1.0), np.full((3, 3), 0.1)], [np.full((3, 3), 10.0), np.full((3, 3), 1.0)]])
    S = np.eye(6) + crosstalk * scale * rng.standard_normal((6, 6))
    S[np.diag_indices(6)] = 1.0 + 1.5 * crosstalk * rng.standard_normal(6)
    return S


def _about(angle, axis):
    """The unit quaternion of a turn by ``angle`` about a coordinate axis (0, 1, 2)."""
    return ca.vertcat(ca.cos(angle / 2), *[ca.sin(angle / 2) * (i == axis) for i in range(3)])


def _zyx(yaw, pitch, roll):
    """The attitude ``Rz(yaw) Ry(pitch) Rx(roll)`` as a quaternion expression."""
    return quaternion_multiply(quaternion_multiply(_about(yaw, 2), _about(pitch, 1)), _about(roll, 0))


def _multisine(t, rng, amplitude, frequencies):
    """``amplitude / n * sum_k sin(2 pi f_k t + phase_k)`` with phases drawn from ``rng``."""
    phases = rng.uniform(0, 2 * np.pi, len(frequencies))
    return sum(amplitude / len(frequencies) * ca.sin(2 * np.pi * f * t + p) for f, p in zip(frequencies, phases))


def _smoothstep(u):
    """``6u^5 - 15u^4 + 10u^3`` on u clamped to [0, 1]: a move that starts and ends at rest (C2)."""
    u = ca.fmin(ca.fmax(u, 0), 1)
    return u ** 3 * (10 - 15 * u + 6 * u ** 2)


@dataclass(frozen=True)
class SpatialScenario:
    """A recipe for a simulated spatial log.

    Parameters
    ----------
    name, description : str
    payload : SpatialPayload
    motion : str
        ``"multisine"`` (position and ZYX angles each a sum of three sines
        with random phases) or ``"static"`` (held attitudes joined by slow
        moves).
    angle_amplitude : tuple of 3 float
        Peak ZYX angles (yaw, pitch, roll), rad; for ``"static"``, the
        largest turn about each from one held attitude to the next.
    position_amplitude : float
        Peak displacement along each axis, m.
    duration, dt : float
        Length and sample time, s.
    torque_sd, force_sd : float
        Reading noise standard deviations, N m and N.
    angle_sd, position_sd : float
        Pose noise standard deviations, rad (about each axis) and m.
    pose_rate : float or None
        Pose measurements per second (None: every sample).
    drop_rate : float
        Fraction of pose frames dropped at random.
    latency : float
        Delay of the pose stream behind the sensor stream, s.
    crosstalk : float
        Size of ``S - I`` (:func:`draw_spatial_S`).
    offset_sd : (float, float)
        Standard deviations of the offset's torque and force parts, N m and N.
    gravity : tuple of 3 float
        m/s^2, world frame.
    drift : float
        Relative change of each channel's gain over the run (a sensor
        warming up): ``S(t) = S (I + drift diag(d) t / T)``, ``d`` a random
        sign per channel, in 1 s steps; 0: ``S`` constant.
    targets : tuple of (yaw, pitch, roll), optional
        For ``"static"``: the held attitudes as ZYX angles, rad, in turn
        (the first from the start, each next one reached 8 s later; the last
        held to the end); default drawn from ``angle_amplitude``.
    """

    name: str
    description: str
    payload: SpatialPayload = TOOL
    motion: str = "multisine"
    angle_amplitude: tuple = (1.4, 0.8, 1.2)
    position_amplitude: float = 0.15
    duration: float = 60.0
    dt: float = 1e-3
    torque_sd: float = 2e-3
    force_sd: float = 0.05
    angle_sd: float = 1e-4
    position_sd: float = 2e-5
    pose_rate: float = None
    drop_rate: float = 0.0
    latency: float = 0.0
    crosstalk: float = 0.02
    offset_sd: tuple = (0.05, 1.0)
    gravity: tuple = GRAVITY
    drift: float = 0.0
    targets: tuple = None

    #: The settings of the payload and the sensor a user may change (:attr:`plant.Scenario.payload_settings`):
    #: the tool's mass, inertia and centre of mass (``payload``); the offset is drawn.
    payload_settings = ("mass", "inertia", "com")

    def model(self):
        """The model the methods run on for this scenario: :class:`plant.SpatialModel` of its payload, under
        its gravity."""
        return SpatialModel(self.payload, self.gravity)

    def with_noise_scaled(self, factor):
        """A copy with every noise standard deviation times ``factor``: ``torque_sd``, ``force_sd``,
        ``angle_sd``, ``position_sd``."""
        return self.with_(torque_sd=self.torque_sd * factor, force_sd=self.force_sd * factor,
                          angle_sd=self.angle_sd * factor, position_sd=self.position_sd * factor)

    def with_(self, **changes):
        """A copy with some settings changed (duration, dt, ...)."""
        return replace(self, **changes)

    def check_size(self):
        """Raise :class:`FmscalError` if the log would be too short or too long."""
        if not (np.isfinite(self.duration) and self.duration > 0 and np.isfinite(self.dt) and self.dt > 0):
            raise FmscalError(f"duration and dt must be positive and finite; got {self.duration} s and {self.dt} s")
        n = self.duration / self.dt + 1
        if not MIN_SAMPLES <= n <= _MAX_SAMPLES:
            raise FmscalError(f"{self.name}: {self.duration:g} s at dt = {self.dt:g} s is {n:.3g} samples; "
                              f"a simulated spatial log has {MIN_SAMPLES} to {_MAX_SAMPLES:.0e} (shorten the "
                              "duration or raise dt)")

    def motion_function(self, rng):
        """The imposed motion and the wrench it needs, ``t -> (x, w)`` (a casadi Function)."""
        t = ca.SX.sym("t")
        if self.motion == "multisine":
            angles = [_multisine(t, rng, a, f) for a, f in zip(self.angle_amplitude,
                                                               ((0.11, 0.23, 0.37), (0.13, 0.29, 0.43),
                                                                (0.17, 0.31, 0.47)))]
            position = ca.vertcat(*[_multisine(t, rng, self.position_amplitude, f)
                                    for f in ((0.12, 0.27, 0.41), (0.14, 0.33, 0.45), (0.16, 0.25, 0.39))])
        elif self.motion == "static":
            hold, move = 3.0, 5.0
            if self.targets is None:
                k = int(np.ceil(self.duration / (hold + move))) + 1
                targets = np.cumsum(rng.uniform(-1, 1, (k, 3)) * np.asarray(self.angle_amplitude), axis=0)
            else:
                targets = np.asarray(self.targets, dtype=float).reshape(-1, 3)
                k = len(targets)
            angles = [targets[0, j] + sum((targets[i, j] - targets[i - 1, j]) *
                                          _smoothstep((t - i * (hold + move) + move) / move) for i in range(1, k))
                      for j in range(3)]
            position = ca.vertcat(0.5, 0.0, 0.3) + 0 * t
        else:
            raise FmscalError(f"unknown motion {self.motion!r}; expected 'multisine' or 'static'")
        return prescribed_motion(t, position, _zyx(*angles), self.payload, self.gravity)

    def _schedule(self, S, rng):
        """``S(t)``: constant, or with :attr:`drift` each channel's gain moved linearly over the run in 1 s steps
        (the signs drawn only then, so that a scenario without drift keeps its draws)."""
        if not self.drift:
            return CalibrationSchedule(S)
        signs = rng.choice([-1.0, 1.0], 6)
        n = int(np.ceil(self.duration))
        return CalibrationSchedule([(float(k), S @ np.diag(1.0 + self.drift * signs * k / n)) for k in range(n)])

    def generate(self, seed=0, noise_free=False):
        """Simulate the scenario.

        Parameters
        ----------
        seed : int
            Seeds every random draw (motion phases, ``S``, offset, noise,
            dropped frames), in that order.
        noise_free : bool
            Leave out all measurement noise.

        Returns
        -------
        log : plant.Log
            A spatial log.
        truth : plant.Truth
            ``S`` (6x6), ``S0`` (the identity: the factory calibration a
            user starts from), the offset, the noise added.
        x_true : ndarray, shape (N, 13)
            The true state ``[p, q, v, omega]`` at each sample.
        """
        self.check_size()
        rng = np.random.default_rng(seed)
        motion = self.motion_function(rng)
        S = draw_spatial_S(rng, self.crosstalk)
        schedule = self._schedule(S, rng)
        b = np.r_[rng.normal(0, self.offset_sd[0], 3), rng.normal(0, self.offset_sd[1], 3)]
        n = int(round(self.duration / self.dt)) + 1
        t = np.arange(n) * self.dt
        batch = motion.map(n)
        x_true, w = (np.array(v).T for v in batch(t))
        pose = np.array(batch(t - self.latency)[0]).T if self.latency else x_true
        pose = np.c_[pose[:, 3:7], pose[:, 0:3]]                       # log order: q, p
        noise = NoiseSpec((self.torque_sd,) * 3 + (self.force_sd,) * 3, self.angle_sd, self.position_sd)
        if noise_free:
            noise = NoiseSpec((0.0,) * 6)
        w_hat = schedule.raw_reading(t, w) + b + rng.standard_normal((n, 6)) * np.array(noise.wrench_sd)
        turn = Rotation.from_rotvec(rng.standard_normal((n, 3)) * noise.angle_sd)    # about the sensor's axes
        measured = Rotation.from_quat(np.roll(pose[:, :4], -1, axis=1)) * turn       # scipy: scalar last
        pose[:, :4] = np.roll(measured.as_quat(), 1, axis=1)
        pose[:, 4:] += rng.standard_normal((n, 3)) * noise.position_sd
        pose[~pose_frames(n, self.dt, self.pose_rate, self.drop_rate, rng)] = np.nan
        settings = {"duration": self.duration, "dt": self.dt, "pose_rate": self.pose_rate,
                    "drop_rate": self.drop_rate, "gravity": list(self.gravity), "drift": self.drift,
                    "description": self.description}
        truth = Truth(self.name, int(seed), schedule, np.eye(6), self.payload, noise, offset=b,
                      latency=float(self.latency), settings=settings)
        return Log(t, pose, w_hat, name=f"{self.name}-seed{seed}"), truth, x_true


    def generate_table(self, seed=0, poses=12, hold=1.0, noise_free=False):
        """A pose table of the scenario's tool and sensor: ``poses`` held attitudes, one row each.

        The table a static calibration script writes (:mod:`fmscal.plant.io._pose_table`): the tool
        held still at random attitudes (turns of up to 180 degrees about random axes), the raw
        reading averaged over ``hold`` s at each. At rest the wrench is the weight's alone,
        ``w_k = [com x f_k; f_k]`` with ``f_k = -m R_k^T g``, and the reading is ``w_hat_k = S^-1 w_k
        + b + n_k``, the noise ``n_k`` the scenario's per-sample noise averaged over the hold's
        ``hold / dt`` samples (standard deviation ``sd / sqrt(hold / dt)``). ``S`` and ``b`` are drawn
        as :meth:`generate` draws them.

        Parameters
        ----------
        seed : int
            Seeds ``S``, the offset, the attitudes and the noise, in that order.
        poses : int
            Rows of the table, at least :data:`fmscal.plant.io.MIN_POSES`.
        hold : float
            Seconds each pose is held and averaged, s (positive).
        noise_free : bool
            Leave out the reading's noise.

        Returns
        -------
        table : plant.io.PoseTable
        truth : plant.Truth
            ``S``, the payload, the offset and the averaged reading's noise; its ``settings`` record
            ``poses`` and ``hold``.

        Raises
        ------
        FmscalError
            Fewer than :data:`~fmscal.plant.io.MIN_POSES` poses or more than :data:`MAX_POSES`, or a
            hold that is not a positive number of seconds.
        """
        if isinstance(poses, bool) or not isinstance(poses, (int, np.integer)) or poses < MIN_POSES:
            raise FmscalError(f"a pose table needs at least {MIN_POSES} poses (an integer); got {poses!r}")
        if poses > MAX_POSES:
            raise FmscalError(f"a simulated pose table has at most {MAX_POSES} poses; got {poses}")
        if isinstance(hold, bool) or not (isinstance(hold, (int, float)) and np.isfinite(hold) and hold > 0):
            raise FmscalError(f"hold must be a positive number of seconds; got {hold!r}")
        rng = np.random.default_rng(seed)
        S = draw_spatial_S(rng, self.crosstalk)
        b = np.r_[rng.normal(0, self.offset_sd[0], 3), rng.normal(0, self.offset_sd[1], 3)]
        per_sample = np.array((self.torque_sd,) * 3 + (self.force_sd,) * 3)
        wrench_sd = np.zeros(6) if noise_free else per_sample / np.sqrt(max(hold / self.dt, 1.0))
        table = simulate_table(self.payload, n=int(poses), seed=int(rng.integers(2 ** 32)), gravity=self.gravity,
                               S=S, offset=b, wrench_sd=wrench_sd)
        table.name = f"{self.name}-table-seed{seed}"
        settings = {"poses": int(poses), "hold": float(hold), "dt": self.dt, "gravity": list(self.gravity),
                    "description": f"{self.description} Held at {int(poses)} random attitudes, {hold:g} s each."}
        truth = Truth(self.name, int(seed), CalibrationSchedule(S), np.eye(6), self.payload,
                      NoiseSpec(tuple(float(v) for v in wrench_sd)), offset=b, latency=0.0, settings=settings)
        return table, truth


#: The spatial scenarios by name (module docstring).
SPATIAL_SCENARIOS = {s.name: s for s in [
    SpatialScenario("spatial-arm", "A tool on a robot's wrist: poses from joint encoders at 1 kHz (0.02 mm, "
                                   "0.006 deg), a multisine turning the tool through tens of degrees, 60 s."),
    SpatialScenario("spatial-mocap", "The arm's motion tracked by motion capture at 200 Hz, 2 % of frames "
                                     "dropped, 5 ms behind the sensor, 0.1 mm and 0.1 deg.",
                    pose_rate=200.0, drop_rate=0.02, latency=0.005, angle_sd=np.deg2rad(0.1), position_sd=1e-4),
    SpatialScenario("spatial-static", "Ten held attitudes under gravity (3 s each) joined by slow 5 s moves "
                                      "(at most 0.8 rad about each axis): only part of S is determined.",
                    motion="static", angle_amplitude=(0.8, 0.8, 0.8), duration=80.0),
    SpatialScenario("spatial-weak", "Small motions: a few degrees, 3 cm.",
                    angle_amplitude=(0.06, 0.06, 0.06), position_amplitude=0.03),
    SpatialScenario("spatial-drift", "The arm's motion and encoders, each channel's gain drifting by 5 % over "
                                     "the 60 s (a sensor warming up): which methods follow it.", drift=0.05),
]}
