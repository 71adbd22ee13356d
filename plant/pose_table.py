"""Pose tables: what static calibration scripts record, one row per held pose.

A wrist sensor is often calibrated by holding the tool still at a few
attitudes and averaging the reading at each. The table has the spatial log's
header without ``t``::

    qw,qx,qy,qz,x,y,z,tx,ty,tz,fx,fy,fz        (or without x,y,z)

``qw .. qz`` is the attitude of the sensor frame in the pose frame (a unit
quaternion, scalar first, sensor to world), ``tx .. fz`` the raw reading
averaged while the pose was held, torque first, as in a spatial log
(:mod:`fmscal.plant.log`). The position is not needed (a held pose does not
accelerate) and is ignored where given. Every row is an independent
measurement. Every cell is a number; a row of the table is a pose.
"""

from dataclasses import dataclass

import numpy as np

from ._checks import as_finite_array
from .errors import FmscalError
from .files import atomic_write_text
from .log import QUATERNION_TOLERANCE, LogError, _as_path, _echo, _read_csv
from .rigid_body import GRAVITY, SpatialPayload, rotation_matrix

__all__ = ["PoseTable", "read_pose_table", "write_pose_table", "is_pose_table", "simulate_table",
           "TABLE_COLUMNS", "MIN_POSES"]

#: The columns a pose table must hold (``x, y, z`` may be given too and are ignored).
TABLE_COLUMNS = ("qw", "qx", "qy", "qz", "tx", "ty", "tz", "fx", "fy", "fz")
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
    """

    q: np.ndarray
    w_hat: np.ndarray
    name: str = "table"

    def __post_init__(self):
        self.q = as_finite_array(self.q, (-1, 4), "q")
        self.w_hat = as_finite_array(self.w_hat, (len(self.q), 6), "w_hat")
        if len(self.q) < MIN_POSES:
            raise LogError(f"{self.name}: a pose table needs at least {MIN_POSES} poses for its ten unknowns "
                           f"(mass, centre of mass, offset); got {len(self.q)}")
        norm = np.linalg.norm(self.q, axis=1)
        off = np.abs(norm - 1) > QUATERNION_TOLERANCE
        if off.any():
            k = int(np.argmax(off))
            raise LogError(f"{self.name}: the quaternion qw,qx,qy,qz at row {k + 1} has norm {norm[k]:.6g}; "
                           f"expected a unit quaternion (norm 1 within {QUATERNION_TOLERANCE:g})")
        self.q = self.q / norm[:, None]

    def __len__(self):
        return len(self.q)


def is_pose_table(path):
    """True when a file's header is a pose table's (the spatial columns and no ``t``)."""
    with open(path, "rb") as f:
        first = f.readline(4096).decode("utf-8", errors="replace").removeprefix("\ufeff")
    header = {h.strip() for h in first.split(",")}
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
    tau = np.cross(np.asarray(payload.rho), f)
    w = np.hstack([tau, f])
    S = np.eye(6) if S is None else np.asarray(S, dtype=float)
    b = np.zeros(6) if offset is None else np.asarray(offset, dtype=float)
    w_hat = np.linalg.solve(S, w.T).T + b + rng.normal(size=(n, 6)) * np.asarray(wrench_sd, dtype=float)
    if reading == "load":
        w_hat = -w_hat
    return PoseTable(q, w_hat, name=f"simulated table (seed {seed})")

