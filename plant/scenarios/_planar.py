"""Named simulation scenarios: the paper's section 4 and the cases users meet.

Noise follows docs/paper/reading-the-paper.md: the wrench noise is added to the raw reading
``w_hat``, with a standard deviation that is a fraction of the peak amplitude of
each component of the noise-free reading; angle and position noise are
standard deviations in rad and m.
"""

from dataclasses import dataclass, replace

import numpy as np

from fmscal.plant.io import MIN_SAMPLES, Log, Truth
from fmscal.plant.numerics import FmscalError
from fmscal.plant.physics import (PAPER_PAYLOAD, PlanarModel, CalibrationSchedule, Multisine, NoiseSpec, PaperWrench,
                                  Payload, integrate)

__all__ = ["Scenario", "SCENARIOS", "get_scenario", "PAPER_S", "TABLE_1", "draw_S", "MAX_SAMPLES"]

#: Most samples a simulated log may have (2e7: 5.6 h at 1 kHz, about 2.5 GB of arrays while simulating).
MAX_SAMPLES = 20_000_000

#: The true calibration matrix printed in section 4.
PAPER_S = np.array([[0.6110, -0.0372, -0.1445],
                    [-0.3361, 1.0020, -0.1443],
                    [-0.1147, 0.1674, 0.9598]])

#: Table 1: ``s_11, s_22, s_33`` on [0, 100), [100, 200), [200, 300] s.
TABLE_1 = {"starts": (0.0, 100.0, 200.0),
           "s11": (0.6110, 0.3847, -0.2839),
           "s22": (1.0020, 0.8144, 0.5472),
           "s33": (0.9598, 0.9169, 1.1172)}


def draw_S(rng, low=-3.0, high=3.0, max_cond=20.0):
    """Draw ``S`` uniformly in ``[low, high]``, redrawn while cond(S) > ``max_cond``."""
    while True:
        S = rng.uniform(low, high, (3, 3))
        if np.linalg.cond(S) <= max_cond:
            return S


def pose_frames(n, dt, pose_rate, drop_rate, rng):
    """Which of ``n`` samples carry a pose: one every ``1 / (pose_rate dt)`` samples, less random drops.

    Parameters
    ----------
    n : int
    dt : float
        Sample time, s.
    pose_rate : float or None
        Poses per second (None: every sample).
    drop_rate : float
        Fraction of frames dropped at random (never the first).
    rng : numpy.random.Generator
        Drawn from only when ``drop_rate > 0``.

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    keep = np.ones(n, dtype=bool)
    if pose_rate is not None:
        keep = np.arange(n) % max(1, int(round(1.0 / (pose_rate * dt)))) == 0
    if drop_rate > 0:
        dropped = rng.random(n) < drop_rate
        dropped[0] = False
        keep &= ~dropped
    return keep


def _table_1_schedule():
    steps = []
    for k, t0 in enumerate(TABLE_1["starts"]):
        S = PAPER_S.copy()
        S[0, 0], S[1, 1], S[2, 2] = TABLE_1["s11"][k], TABLE_1["s22"][k], TABLE_1["s33"][k]
        steps.append((t0, S))
    return steps


@dataclass(frozen=True)
class Scenario:
    """A recipe for a simulated log.

    Parameters
    ----------
    name : str
    description : str
        One sentence, shown in tables and ``fmscal simulate --help``.
    payload : plant.Payload
    excitation : plant.Excitation
        The true wrench.
    S : str or ndarray
        ``"paper"`` (the printed matrix), ``"random"`` (uniform in [-3, 3],
        redrawn while its condition number exceeds 20), ``"table-1"`` (the
        schedule of Table 1), or ``"drift"`` (the printed matrix drifting
        linearly by ``drift`` over the run, in 1 s steps).
    duration, dt : float
        Length and sample time, s.
    wrench_noise : float
        Wrench noise standard deviation as a fraction of each component's
        peak raw reading.
    angle_sd, position_sd : float
        Pose noise standard deviations, rad and m.
    S0_range : (float, float)
        The initial estimate ``S0`` is drawn uniformly in this range.
    pose_rate : float or None
        Rate of pose measurements in Hz (None: every sample).
    drop_rate : float
        Fraction of pose frames dropped at random.
    outlier_rate : float
        Fraction of pose measurements replaced by an outlier of
        ``outlier_sd`` standard deviations.
    told_noise : float
        Factor on the noise standard deviations that an observer needing a
        noise model is told (1: the truth).
    drift : float
        Total change of each entry of ``S`` over the run, for ``S="drift"``.
    offset : tuple of 3 floats, optional
        The sensor's offset ``b = [M, f_x, f_y]`` (N m, N): the raw reading is
        ``w_hat = S^-1 w + b``, so that ``w = S (w_hat - b)``. None: no offset.
    latency : float
        Delay of the pose stream behind the sensor stream, s: the pose logged
        at ``t`` is the one of ``t - latency``.
    """

    name: str
    description: str
    payload: Payload = PAPER_PAYLOAD
    excitation: object = PaperWrench()
    S: object = "paper"
    duration: float = 100.0
    dt: float = 1e-3
    wrench_noise: float = 0.05
    angle_sd: float = np.deg2rad(0.1)
    position_sd: float = 1e-4
    S0_range: tuple = (0.0, 3.0)
    pose_rate: float = None
    drop_rate: float = 0.0
    outlier_rate: float = 0.0
    outlier_sd: float = 20.0
    told_noise: float = 1.0
    drift: float = 0.2
    offset: tuple = None
    latency: float = 0.0

    #: The settings of the payload and the sensor a user may change (``fmscal simulate``'s ``--mass``,
    #: ``--inertia``, ``--rho``, ``--offset``): the payload's mass, ``I_G`` and ``rho``, and the offset.
    payload_settings = ("mass", "inertia", "rho", "offset")

    def model(self):
        """The model the methods run on for this scenario: :class:`plant.PlanarModel` of its payload."""
        return PlanarModel(self.payload)

    def with_noise_scaled(self, factor):
        """A copy with every noise standard deviation times ``factor``: ``wrench_noise``, ``angle_sd``,
        ``position_sd``."""
        return self.with_(wrench_noise=self.wrench_noise * factor, angle_sd=self.angle_sd * factor,
                          position_sd=self.position_sd * factor)

    def check_size(self):
        """Raise :class:`FmscalError` for fewer than ``MIN_SAMPLES`` or more than :data:`MAX_SAMPLES` samples."""
        if not (np.isfinite(self.duration) and self.duration > 0 and np.isfinite(self.dt) and self.dt > 0):
            raise FmscalError(f"duration and dt must be positive and finite; got {self.duration} s and {self.dt} s")
        n = self.duration / self.dt
        if n + 1 < MIN_SAMPLES:
            raise FmscalError(f"{self.name}: {self.duration:g} s at dt = {self.dt:g} s is {int(round(n)) + 1} "
                              f"sample(s); a log needs at least {MIN_SAMPLES}")
        if n + 1 > MAX_SAMPLES:
            raise FmscalError(f"{self.name}: {self.duration:g} s at dt = {self.dt:g} s is {n + 1:.3g} samples; "
                              f"at most {MAX_SAMPLES:.0e} fit in memory (shorten the duration or raise dt)")

    def with_(self, **changes):
        """A copy with some settings changed (duration, dt, ...)."""
        return replace(self, **changes)

    def schedule(self, rng):
        """The true ``S`` as a :class:`plant.CalibrationSchedule`."""
        if isinstance(self.S, str):
            if self.S == "paper":
                return CalibrationSchedule(PAPER_S)
            if self.S == "random":
                return CalibrationSchedule(draw_S(rng))
            if self.S == "table-1":
                return CalibrationSchedule(_table_1_schedule())
            if self.S == "drift":
                direction = rng.choice([-1.0, 1.0], (3, 3))
                n = int(np.ceil(self.duration))
                return CalibrationSchedule(
                    [(float(k), PAPER_S + direction * self.drift * k / n) for k in range(n)])
            raise FmscalError(f"unknown S setting {self.S!r}")
        return CalibrationSchedule(np.asarray(self.S, dtype=float))

    def generate(self, seed=0, noise_free=False):
        """Simulate the scenario.

        Parameters
        ----------
        seed : int
            Seeds every random draw (``S``, ``S0``, noise, dropped frames), in
            that order.
        noise_free : bool
            Leave out all measurement noise and outliers.

        Returns
        -------
        log : plant.Log
        truth : plant.Truth
            ``truth.noise`` is the noise actually added; the true states
            ``x`` are not stored.
        x_true : ndarray, shape (N, 6)
            True ``[theta, theta', X, X', Y, Y']``.
        """
        self.check_size()
        rng = np.random.default_rng(seed)
        schedule = self.schedule(rng)
        S0 = rng.uniform(*self.S0_range, (3, 3))
        n = int(round(self.duration / self.dt)) + 1
        t = np.arange(n) * self.dt
        x_true = integrate(self.payload, self.excitation, t)
        w_hat = schedule.raw_reading(t, self.excitation(t))
        pose = x_true[:, [0, 2, 4]].copy()
        if self.latency:
            pose = np.column_stack([np.interp(t - self.latency, t, pose[:, j]) for j in range(3)])
        peak = np.max(np.abs(w_hat), axis=0)              # noise relative to the signal, offset aside
        if self.offset is not None:
            w_hat = w_hat + np.asarray(self.offset, dtype=float)
        noise = NoiseSpec(tuple(self.wrench_noise * peak), self.angle_sd, self.position_sd)
        if noise_free:
            noise = NoiseSpec()
        w_hat = w_hat + rng.standard_normal(w_hat.shape) * np.array(noise.wrench_sd)
        pose = pose + rng.standard_normal(pose.shape) * noise.pose_sd
        if not noise_free and self.outlier_rate > 0:
            hit = rng.random(n) < self.outlier_rate
            pose[hit] += self.outlier_sd * noise.pose_sd * rng.choice([-1.0, 1.0], (hit.sum(), 3))
        pose[~pose_frames(n, self.dt, self.pose_rate, self.drop_rate, rng)] = np.nan
        settings = {"duration": self.duration, "dt": self.dt, "pose_rate": self.pose_rate,
                    "drop_rate": self.drop_rate, "outlier_rate": 0.0 if noise_free else self.outlier_rate,
                    "description": self.description}
        truth = Truth(self.name, int(seed), schedule, S0, self.payload, noise, told_noise=self.told_noise,
                      offset=None if self.offset is None else np.array(self.offset, dtype=float),
                      latency=float(self.latency or 0.0), settings=settings)
        log = Log(t, pose, w_hat, name=f"{self.name}-seed{seed}")
        return log, truth, x_true


_OTHER_PAYLOAD = Payload(6.0, 0.3, (-0.15, 0.4))
_WEAK = Multisine([[(1.0, 2.0, 0.0)], [(1.0, 1.0, 0.0)], [(2.0, 3.0, 0.0)]])

#: The named scenarios, ``{name: Scenario}`` (``fmscal simulate --help`` lists them).
SCENARIOS = {s.name: s for s in [
    Scenario("paper", "Section 4: printed S, 5 % wrench noise, 0.1 deg, 0.1 mm, 100 s at 1 ms."),
    Scenario("noisy", "Fig. 3: 10 % wrench noise, 1 deg, 0.2 mm (the printed '0.2 m' read as mm), "
                      "S drawn in [-3, 3] and redrawn while cond(S) > 20.",
             S="random", wrench_noise=0.10, angle_sd=np.deg2rad(1.0), position_sd=2e-4),
    Scenario("time-varying", "Fig. 4: s_11, s_22, s_33 step as in Table 1, 300 s.",
             S="table-1", duration=300.0),
    Scenario("other-payload", "A 6 kg, 0.3 kg m^2 payload with rho = [-0.15, 0.4] m, paper noise.",
             payload=_OTHER_PAYLOAD),
    Scenario("random-S", "S drawn in [-3, 3] (cond <= 20), paper noise.", S="random"),
    Scenario("weak-excitation", "One sine per wrench component instead of three, paper noise.",
             excitation=_WEAK),
    Scenario("ekf-noise-low", "Paper scenario; an observer with a noise model is told 10x smaller "
                              "standard deviations.", told_noise=0.1),
    Scenario("ekf-noise-high", "Paper scenario; an observer with a noise model is told 10x larger "
                               "standard deviations.", told_noise=10.0),
    Scenario("drift", "Every entry of S drifts linearly by 0.2 over the run.", S="drift"),
    Scenario("vision-50hz", "Pose at 50 Hz beside a 1 kHz sensor, 10 % of frames dropped.",
             pose_rate=50.0, drop_rate=0.10),
    Scenario("outliers", "0.5 % of pose measurements are 20-sigma outliers.", outlier_rate=0.005),
    Scenario("real-rig", "Paper scenario on a rig: sensor offset b = [0.3 N m, 2 N, -1.5 N], pose at 50 Hz "
                         "with 10 % of frames dropped and 20 ms behind the sensor.",
             offset=(0.3, 2.0, -1.5), pose_rate=50.0, drop_rate=0.10, latency=0.02),
]}


def get_scenario(name):
    """Return the named :class:`Scenario`, or raise ValueError listing the names."""
    try:
        return SCENARIOS[name]
    except KeyError:
        raise FmscalError(f"unknown scenario {name!r}; expected one of {', '.join(SCENARIOS)}") from None
