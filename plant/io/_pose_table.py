"""Pose tables: what static calibration scripts record, one row per held pose.

A wrist sensor is often calibrated by holding the tool still at a few
attitudes and averaging the reading at each. The table has the spatial log's
header without ``t``::

    qw,qx,qy,qz,x,y,z,tx,ty,tz,fx,fy,fz        (or without x,y,z)

``qw .. qz`` is the attitude of the sensor frame in the pose frame (a unit
quaternion, scalar first, sensor to world), ``tx .. fz`` the raw reading
averaged while the pose was held, torque first, as in a spatial log
(:mod:`fmscal.plant.io._log`). The position is not needed (a held pose does not
accelerate) and is ignored where given. Every row is an independent
measurement. Every cell is a number; a row of the table is a pose.

An **attitude-only log** (an IMU on the tool, or a robot that logs its
orientation only) has the header ``t,qw,qx,qy,qz,tx,ty,tz,fx,fy,fz``. Without
the position the acceleration is unknown, so only the held segments are
used: where the attitude turns slower than :data:`HOLD_RATE` over
:data:`HOLD_WINDOW` for at least :data:`MIN_HOLD` seconds, each segment
(less its settling ends) averaged into one row of a table
(:func:`held_table`), which says what share of the log it used and why.
"""

from dataclasses import dataclass

import numpy as np

from fmscal.plant.numerics import FmscalError, as_finite_array
from fmscal.plant.physics import GRAVITY, SpatialPayload, rotation_matrix
from ._files import atomic_write_text
from ._log import LogError, _as_path, _check_magnitudes, _echo, _read_csv, csv_header, unit_quaternions

__all__ = ["PoseTable", "read_pose_table", "write_pose_table", "is_pose_table", "simulate_table",
           "AttitudeLog", "read_attitude_log", "is_attitude_log", "held_table", "simulate_attitude_log",
           "TABLE_COLUMNS", "ATTITUDE_COLUMNS", "MIN_POSES", "HOLD_RATE", "HOLD_WINDOW", "MIN_HOLD"]

#: The columns a pose table must hold (``x, y, z`` may be given too and are ignored).
TABLE_COLUMNS = ("qw", "qx", "qy", "qz", "tx", "ty", "tz", "fx", "fy", "fz")
#: The columns of an attitude-only log.
ATTITUDE_COLUMNS = ("t", *TABLE_COLUMNS)
#: A segment counts as held where the attitude turns slower than this, rad/s ...
HOLD_RATE = 0.05
#: ... measured over this window, s (a shorter one would see the tracker's noise as motion) ...
HOLD_WINDOW = 0.2
#: ... for at least this long, s.
MIN_HOLD = 0.5
#: Fewest poses a table may hold: ten unknowns (mass, centre of mass, offset) need at least four
#: attitudes whose gravity directions span space.
MIN_POSES = 4


@dataclass
class PoseTable:
    """Held attitudes and the readings averaged at each.

    Attributes
    ----------
    q : ndarray, shape (N, 4)
        Unit quaternions, scalar first, sensor frame to pose frame.
    w_hat : ndarray, shape (N, 6)
        The raw reading ``[tx, ty, tz, fx, fy, fz]`` at each pose.
    name : str
        Where the table came from.
    noise : ndarray, shape (N, 6), optional
        The standard error of each row's reading, where the data give it (an
        attitude-only log's held segments: their scatter over the square root
        of their samples); None for a table.
    """

    q: np.ndarray
    w_hat: np.ndarray
    name: str = "table"
    noise: np.ndarray = None

    def __post_init__(self):
        self.q = as_finite_array(self.q, (-1, 4), "q")
        self.w_hat = as_finite_array(self.w_hat, (len(self.q), 6), "w_hat")
        _check_magnitudes(self.name, zip(TABLE_COLUMNS[4:], self.w_hat.T))
        if len(self.q) < MIN_POSES:
            raise LogError(f"{self.name}: a pose table needs at least {MIN_POSES} poses for its ten unknowns "
                           f"(mass, centre of mass, offset); got {len(self.q)}")
        self.q = unit_quaternions(self.q, self.name)

    def __len__(self):
        return len(self.q)


def is_pose_table(path):
    """True when a file's header is a pose table's (the spatial columns and no ``t``; in any case, so that a
    header in capitals is read as a table and told its case)."""
    header = {h.lower() for h in csv_header(path)}
    return "t" not in header and set(TABLE_COLUMNS) <= header


def read_pose_table(path):
    """Read a pose table CSV (module docstring).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    PoseTable

    Raises
    ------
    LogError
        Missing file, missing columns, a cell that is not a number, too few
        poses, a quaternion not of unit norm.
    """
    path = _as_path(path, "pose table")
    frame = _read_csv(path, TABLE_COLUMNS, "every cell of a pose table is a number")
    bad = ~np.isfinite(frame[list(TABLE_COLUMNS)].to_numpy()).all(axis=1)
    if bad.any():
        raise LogError(f"{path.name}: row {int(np.argmax(bad)) + 1} has an empty cell; every cell of a pose table "
                       "is a number (a row is one held pose)")
    return PoseTable(frame[["qw", "qx", "qy", "qz"]].to_numpy(), frame[list(TABLE_COLUMNS[4:])].to_numpy(),
                     name=_echo(path.name))


def write_pose_table(table, path):
    """Write ``table`` as a CSV with the header ``qw,qx,qy,qz,tx,ty,tz,fx,fy,fz``."""
    rows = np.hstack([table.q, table.w_hat])
    text = ",".join(TABLE_COLUMNS) + "\n" + "\n".join(",".join(f"{v:.17g}" for v in row) for row in rows) + "\n"
    atomic_write_text(path, text)


def _random_attitudes(rng, n, spread):
    """``n`` unit quaternions: turns of up to ``spread`` rad about random axes (uniform on the sphere)."""
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    angles = rng.uniform(0.0, spread, n)
    return np.column_stack([np.cos(angles / 2), np.sin(angles / 2)[:, None] * axes])


def simulate_table(payload, n=12, seed=0, gravity=GRAVITY, S=None, offset=None, wrench_sd=(0.005,) * 3 + (0.05,) * 3,
                   mounting=None, reading="reaction", spread=np.pi, q=None):
    """A pose table of a payload held at ``n`` attitudes: the test bench of the static fits.

    Parameters
    ----------
    payload : SpatialPayload
    n : int
        Poses.
    seed : int
        Seeds the attitudes and the noise.
    gravity : array_like, shape (3,)
        Gravity in the pose frame, m/s^2 (a tilted base: not along -z).
    S : array_like, shape (6, 6), optional
        The calibration (``w = S (w_hat - b)``); default the identity.
    offset : array_like, shape (6,), optional
        The sensor's offset ``b``; default zero.
    wrench_sd : array_like, shape (6,)
        Noise of each averaged reading, N m and N.
    mounting : array_like, shape (3, 3), optional
        The sensor's axes on the tracked frame: the table's attitudes are the
        tracked frame's, the sensor's are ``R M`` (default the identity).
    reading : {"reaction", "load"}
        ``"load"``: the reading is the wrench the tool applies to the sensor,
        the negative of the toolkit's.
    spread : float
        Largest turn of an attitude from the identity, rad.
    q : ndarray, shape (n, 4), optional
        The attitudes; default random.

    Returns
    -------
    PoseTable
    """
    if not isinstance(payload, SpatialPayload):
        raise FmscalError(f"simulate_table takes a SpatialPayload; got {type(payload).__name__}")
    rng = np.random.default_rng(seed)
    q = _random_attitudes(rng, n, spread) if q is None else np.asarray(q, dtype=float)
    R = np.moveaxis(rotation_matrix(q.T), -1, 0)                             # (n, 3, 3) tracked frame to world
    M = np.eye(3) if mounting is None else np.asarray(mounting, dtype=float)
    g = np.asarray(gravity, dtype=float)
    a_g = np.einsum("ji,nkj,k->ni", M, R, -g)                                # -M^T R^T g: the sensor's axes
    f = payload.mass * a_g
    tau = np.cross(np.asarray(payload.com), f)
    w = np.hstack([tau, f])
    S = np.eye(6) if S is None else np.asarray(S, dtype=float)
    b = np.zeros(6) if offset is None else np.asarray(offset, dtype=float)
    w_hat = np.linalg.solve(S, w.T).T + b + rng.normal(size=(n, 6)) * np.asarray(wrench_sd, dtype=float)
    if reading == "load":
        w_hat = -w_hat
    return PoseTable(q, w_hat, name=f"simulated table (seed {seed})")



@dataclass
class AttitudeLog:
    """A log of attitudes and readings without positions (module docstring).

    Attributes
    ----------
    t : ndarray, shape (N,)
        Time, s, strictly increasing.
    q : ndarray, shape (N, 4)
        Unit quaternions, scalar first, sign-continuous.
    w_hat : ndarray, shape (N, 6)
    name : str
    """

    t: np.ndarray
    q: np.ndarray
    w_hat: np.ndarray
    name: str = "log"

    def __post_init__(self):
        self.t = as_finite_array(self.t, (-1,), "t")
        self.q = as_finite_array(self.q, (len(self.t), 4), "q")
        self.w_hat = as_finite_array(self.w_hat, (len(self.t), 6), "w_hat")
        _check_magnitudes(self.name, zip(TABLE_COLUMNS[4:], self.w_hat.T))    # t: Unix seconds are a clock's
        steps = np.diff(self.t)
        if np.any(steps <= 0):
            raise LogError(f"{self.name}: time is not strictly increasing at row {int(np.argmax(steps <= 0)) + 2}")
        q = unit_quaternions(self.q, self.name, hint="; a norm that drifts is a tracker or an integration to "
                                                      "fix first")
        flips = np.sum(q[1:] * q[:-1], axis=1) < 0
        self.q = q * np.cumprod(np.r_[1.0, np.where(flips, -1.0, 1.0)])[:, None]


def is_attitude_log(path):
    """True when a file's header is an attitude-only log's (``t``, the quaternion and the reading, no position;
    in any case)."""
    header = {h.lower() for h in csv_header(path)}
    return set(ATTITUDE_COLUMNS) <= header and not {"x", "y", "z"} & header


def read_attitude_log(path):
    """Read an attitude-only log CSV (module docstring).

    Raises
    ------
    LogError
        Missing file or columns, a cell that is not a number, time not
        increasing, a quaternion off unit norm.
    """
    path = _as_path(path, "log")
    frame = _read_csv(path, ATTITUDE_COLUMNS, "every cell of an attitude-only log is a number")
    values = frame[list(ATTITUDE_COLUMNS)].to_numpy()
    bad = ~np.isfinite(values).all(axis=1)
    if bad.any():
        raise LogError(f"{path.name}: row {int(np.argmax(bad)) + 1} has an empty cell; every cell of an "
                       "attitude-only log is a number")
    return AttitudeLog(values[:, 0], values[:, 1:5], values[:, 5:], name=_echo(path.name))


def _turn_rate(t, q, window):
    """The attitude's rate of turn at each sample, rad/s: the angle between ``q(t - window/2)`` and
    ``q(t + window/2)`` over the time between them (one-sided at the ends)."""
    half = max(int(round(window / 2 / np.median(np.diff(t)))), 1)
    lo = np.clip(np.arange(len(t)) - half, 0, len(t) - 1)
    hi = np.clip(np.arange(len(t)) + half, 0, len(t) - 1)
    dot = np.clip(np.abs(np.sum(q[lo] * q[hi], axis=1)), 0.0, 1.0)
    return 2 * np.arccos(dot) / np.maximum(t[hi] - t[lo], 1e-12)


def held_table(log, rate=HOLD_RATE, window=HOLD_WINDOW, min_hold=MIN_HOLD):
    """The held segments of an attitude-only log as a pose table (module docstring).

    Each run of samples turning slower than ``rate`` for at least
    ``min_hold`` s, less a window at each end (the settling), whose reading
    is steady (its spread at most three times the median spread of the runs:
    a slow turn under a load is not a held pose), becomes one row: the mean
    attitude (normalised) and the mean reading.

    Parameters
    ----------
    log : AttitudeLog
    rate, window, min_hold : float
        :data:`HOLD_RATE` (rad/s), :data:`HOLD_WINDOW` (s), :data:`MIN_HOLD` (s).

    Returns
    -------
    table : PoseTable
    used : float
        The share of the log's samples the table averages.
    why : str
        What was used and why, one line.

    Raises
    ------
    LogError
        Fewer than :data:`MIN_POSES` held segments.
    """
    held = _turn_rate(log.t, log.q, window) < rate
    edges = np.flatnonzero(np.diff(np.r_[0, held.astype(int), 0]))
    dt = float(np.median(np.diff(log.t)))
    trim = max(int(round(window / dt)), 1)
    runs = [(start + trim, stop - trim) for start, stop in zip(edges[::2], edges[1::2])
            if (stop - start) * dt >= min_hold and stop - start - 2 * trim >= 2]
    spread = np.array([np.linalg.norm(np.std(log.w_hat[a:b], axis=0)) for a, b in runs])
    steady = spread <= 3 * np.median(spread) if len(runs) else np.zeros(0, dtype=bool)
    rows, used = [], 0
    for (a, b), keep in zip(runs, steady):
        if keep:
            q = log.q[a:b].mean(axis=0)
            rows.append((q / np.linalg.norm(q), log.w_hat[a:b].mean(axis=0),
                         log.w_hat[a:b].std(axis=0, ddof=1) / np.sqrt(b - a)))
            used += b - a
    unsteady = f", {int((~steady).sum())} more whose reading was not steady" if (~steady).any() else ""
    why = (f"{len(rows)} held segments (turning slower than {rate:g} rad/s for at least {min_hold:g} s, less "
           f"{window:g} s at each end{unsteady}): {used / len(log.t):.0%} of the log; the rest moves, and without "
           "positions its acceleration is unknown")
    if len(rows) < MIN_POSES:
        raise LogError(f"{log.name}: {why}; a static fit needs at least {MIN_POSES} held poses: hold the tool still "
                       f"for {min_hold:g} s or more at each of several attitudes")
    q, w, noise = (np.array(v) for v in zip(*rows))
    return PoseTable(q, w, name=log.name, noise=noise), used / len(log.t), why


def simulate_attitude_log(payload, poses=10, hold=2.0, move=1.5, dt=0.01, seed=0, gravity=GRAVITY, offset=None,
                          drift=None, wrench_sd=(0.005,) * 3 + (0.05,) * 3, angle_sd=np.radians(0.1)):
    """An attitude-only log: the tool held at ``poses`` attitudes, moved between them (the test bench of
    :func:`held_table`).

    While moving, the reading holds the weight's wrench at the current attitude
    plus a disturbance (the unknown acceleration's share), so that only the
    held segments fit the static model.

    Parameters
    ----------
    payload : SpatialPayload
    poses : int
    hold, move : float
        Seconds held at each attitude and spent moving to the next.
    dt : float
        Sample time, s.
    seed : int
    gravity : array_like, shape (3,)
    offset : array_like, shape (6,), optional
        The sensor's offset at the start.
    drift : array_like, shape (6,), optional
        The offset's rate of change, per second (a warming sensor).
    wrench_sd : array_like, shape (6,)
        The reading's noise per sample.
    angle_sd : float
        The attitude's noise, rad.

    Returns
    -------
    AttitudeLog
    """
    from scipy.spatial.transform import Rotation, Slerp
    rng = np.random.default_rng(seed)
    q_held = _random_attitudes(rng, poses, np.pi)
    key_t, key_q = [], []
    for k in range(poses):
        start = k * (hold + move)
        key_t += [start, start + hold]
        key_q += [q_held[k], q_held[k]]
    key_t = np.array(key_t)
    rot = Rotation.from_quat(np.array(key_q)[:, [1, 2, 3, 0]])
    t = np.arange(0.0, key_t[-1], dt)
    R = Slerp(key_t, rot)(t)
    a = np.einsum("nkj,k->nj", R.as_matrix(), -np.asarray(gravity, dtype=float))
    f = payload.mass * a
    w = np.hstack([np.cross(np.asarray(payload.com), f), f])
    moving = np.ones(len(t), dtype=bool)
    for k in range(poses):
        moving &= ~((t >= k * (hold + move)) & (t <= k * (hold + move) + hold))
    w[moving] += rng.normal(size=(int(moving.sum()), 6)) * np.r_[np.full(3, 0.05), np.full(3, 1.0)]
    b = np.zeros(6) if offset is None else np.asarray(offset, dtype=float)
    b = b + (0.0 if drift is None else np.outer(t, drift))
    w_hat = w + b + rng.normal(size=(len(t), 6)) * np.asarray(wrench_sd, dtype=float)
    turn = Rotation.from_rotvec(rng.normal(size=(len(t), 3)) * angle_sd)
    q_meas = (R * turn).as_quat()[:, [3, 0, 1, 2]]
    return AttitudeLog(t, q_meas, w_hat, name=f"simulated attitude log (seed {seed})")
