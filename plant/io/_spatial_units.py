"""Unit slips in 3D, told from the data before any fit: one line naming the unit.

A spatial log, a pose table or an attitude-only log's held poses fix the
wrench the payload needs only up to the units they are written in. These
checks read the data against what a wrist sensor on a robot can show, and
name the slip before an expensive fit runs on it (a log with positions in mm
would otherwise run for minutes and return a wrong mass):

- a reading channel that never changes (all zero: not connected), and a pose
  stream that never changes (a stalled tracker);
- gravity's size against Earth's, :data:`EARTH_G` (``--gravity 0 0 -981`` is in cm/s^2);
- the payload's mass against what a wrist sensor carries, :data:`MAX_WRIST_MASS`;
- the time step against a force sensor's rate (``t`` in ms gives steps of 1 s);
- the attitude's convention and the reading's block order, by the data: the
  weight seen in the pose frame must be one constant vector (eq. U1 below);
  the quaternion as written (scalar first, sensor to pose frame), conjugated,
  or scalar last, and the reading's torque and force blocks as written or
  swapped, each fitted, and the one that fits far better named;
- the torque against the force through a lever arm (eq. U2): a lever arm
  beyond :data:`MAX_LEVER_ARM` is torques in N mm;
- the weight the force reading shows against ``m |g|`` (readings in mN);
- the translational acceleration the positions imply against the force's
  share of it (the mass the accelerations imply against the weight's:
  positions in mm or in cm, told by the ratio), and against :data:`MAX_ACCELERATION`;
- the centre of mass given against a wrist's lever arm, :data:`MAX_LEVER_ARM`
  (in mm or cm, told by its ratio to the lever arm of eq. U2).

The fit of the weight in the pose frame (eq. U1): with ``R`` the attitude
(sensor to pose frame), ``p`` the position, ``h = m rho`` and ``b`` the
force offset, Newton's law for the centre of mass ``p + R rho`` reads, with
``S = I`` and the reading in the reaction convention (the load convention
turns every unknown's sign, which the check does not read)::

    R f_hat = m_a p'' + R'' h + R b + c,        c = -m g          (U1)

linear in ``m_a``, ``h``, ``b``, ``c``. The mass the weight shows is
``m_g = |c| / |g|``; ``m_a`` is the mass the accelerations show: the two
agree in SI units. The torque about the sensor point (eq. U2), quasi-static::

    tau_hat = rho x f_hat + d                                      (U2)

with ``d`` a constant (the torque offset, and ``rho`` times the force offset).
"""

import numpy as np

from fmscal.plant.numerics import FmscalError
from fmscal.plant.physics import rotation_matrices, sign_continuous
from ._log import LogError
from ._noise import estimate_noise

__all__ = ["UnitsError", "check_readings_change", "check_poses_move", "stalled_poses", "STALL_SPREAD",
           "check_gravity", "check_mass",
           "check_spatial_log_units", "check_table_units", "check_imu_units", "MAX_GYRO_RATE",
           "EARTH_G", "MAX_WRIST_MASS", "MAX_LEVER_ARM", "MAX_ACCELERATION", "MAX_STEP"]

#: Earth's gravity, m/s^2; a given ``|g|`` more than :data:`_G_TOLERANCE` from it is refused.
EARTH_G = 9.81
_G_TOLERANCE = 0.03
#: The largest payload a wrist sensor carries, kg (the big 6-axis sensors are rated for a few hundred N).
MAX_WRIST_MASS = 50.0
#: The largest lever arm from the sensor to the payload's centre of mass, m.
MAX_LEVER_ARM = 1.0
#: The largest rms translational acceleration a robot or a hand gives a payload, m/s^2.
MAX_ACCELERATION = 50.0
#: The largest time step of a force-sensor log, s (a log stamped in ms shows steps of 1).
MAX_STEP = 0.5
#: An IMU's specific force: its median size within this band of :data:`EARTH_G` (a slow or moderate motion).
_IMU_FORCE_BAND = (0.5, 2.0)
#: The largest angular rate a gyro on a robot's tool reads, rad/s (2000 deg/s, a MEMS gyro's widest range).
MAX_GYRO_RATE = np.deg2rad(2000.0)
#: A ratio further than this from 1, either way, is a unit slip (the slips are factors 100 and 1000).
_FAR = 30.0
#: Window over which poses and readings are averaged before differentiating twice, s.
_WINDOW = 0.05
#: A convention or block order is named when its fit's residual is this many times smaller ...
_BETTER = 5.0
#: ... and the one written leaves more than this share of the force's spread unexplained, and the one named
#: less than :data:`_GOOD` (a sensor bolted at an angle to the tracked frame fits no convention well: nothing
#: is named).
_POOR = 0.2
_GOOD = 0.12

_CONVENTIONS = (("as written", lambda c: c),
                ("conjugated", lambda c: c * np.array([1.0, -1, -1, -1])),
                ("scalar last", lambda c: c[:, [3, 0, 1, 2]]),
                ("scalar last and conjugated", lambda c: c[:, [3, 0, 1, 2]] * np.array([1.0, -1, -1, -1])))


class UnitsError(FmscalError):
    """A unit slip or a convention the data say is not the one the toolkit reads: the message names it."""


def check_gravity(gravity):
    """Refuse a gravity whose size is not Earth's: ``|g|`` within 3 % of :data:`EARTH_G`.

    Parameters
    ----------
    gravity : array_like, shape (3,)
        Gravity in the pose frame, m/s^2.

    Raises
    ------
    UnitsError
        Naming the unit the size suggests (cm/s^2, mm/s^2, or g).
    """
    size = float(np.linalg.norm(np.asarray(gravity, dtype=float)))
    if abs(size / EARTH_G - 1) <= _G_TOLERANCE:
        return
    units = {"cm/s^2": 100.0, "mm/s^2": 1000.0, "g (multiples of 9.81)": 1 / EARTH_G}
    unit = next((u for u, k in units.items() if abs(size / (EARTH_G * k) - 1) < 0.1), None)
    guess = f": in {unit}? give gravity in m/s^2" if unit else f" (more than {_G_TOLERANCE:.0%} from it): give Earth's"
    raise UnitsError(f"gravity's size is {size:.4g}, not Earth's {EARTH_G} m/s^2{guess}" + ("" if unit else
                     " gravity in the pose frame, m/s^2"))


def _max_mass(max_mass):
    """``max_mass`` checked (None: :data:`MAX_WRIST_MASS`)."""
    if max_mass is None:
        return MAX_WRIST_MASS
    if isinstance(max_mass, bool) or not isinstance(max_mass, (int, float, np.integer, np.floating)) \
            or not np.isfinite(max_mass) or max_mass <= 0:
        raise UnitsError(f"max_mass must be a positive number of kg; got {max_mass!r}")
    return float(max_mass)


def _carried(limit):
    """The mass limit in words."""
    return (f"what a wrist sensor carries ({limit:g} kg)" if limit == MAX_WRIST_MASS
            else f"the largest mass allowed (max_mass, {limit:g} kg)")


def _heavier(limit):
    """The end of a refusal by the mass limit: how to raise it for a payload that heavy."""
    return f"; a payload heavier than {limit:g} kg: raise max_mass (--max-mass)" if limit == MAX_WRIST_MASS else ""


def check_mass(mass, what="the payload's mass", max_mass=None):
    """Refuse a mass that is not positive, or beyond what a wrist sensor carries (``max_mass``, default
    :data:`MAX_WRIST_MASS`), naming grams.

    Raises
    ------
    UnitsError
    """
    limit = _max_mass(max_mass)
    number = not isinstance(mass, (bool, np.bool_)) and np.ndim(mass) == 0 \
        and np.issubdtype(np.asarray(mass).dtype, np.number)
    if not (number and np.isfinite(mass) and mass > 0):
        raise UnitsError(f"{what} must be a positive number of kg; got {mass!r}")
    if mass > limit:
        raise UnitsError(f"{what} is {mass:.4g} kg, beyond {_carried(limit)}: in g? give it in kg" + _heavier(limit))


def check_readings_change(name, w_hat, names=("tx", "ty", "tz", "fx", "fy", "fz")):
    """Refuse readings with a channel that never changes (all zero: a channel not connected), as ``calibrate`` does.

    Raises
    ------
    UnitsError
    """
    w_hat = np.asarray(w_hat, dtype=float)
    constant = [n for n, column in zip(names, w_hat.T) if np.ptp(column) == 0]
    if constant:
        raise UnitsError(f"{name}: column(s) {', '.join(constant)} of the reading never change (every row "
                         f"{w_hat[0, names.index(constant[0])]:g}): a channel not connected or a column written "
                         "empty; check the recording")


#: A reading channel spanning more than this many of its noise's sd moves: beside pose rows all the same, a stalled
#: tracker rather than a payload at rest.
STALL_SPREAD = 20.0


def stalled_poses(log, wrench_sd=None):
    """Every pose row of ``log`` the same (a stalled tracker, or a payload at rest), and how far the readings move.

    Parameters
    ----------
    log : plant.Log
    wrench_sd : array_like, optional
        The readings' noise sd per channel (None: :func:`fmscal.plant.estimate_noise`'s from the log).

    Returns
    -------
    tuple or None
        None where the poses move or there are none; else ``(poses, spread)``: the pose rows and each reading
        channel's span over its noise sd (beyond :data:`STALL_SPREAD`, the readings move).
    """
    poses = log.pose[log.has_pose]
    if len(poses) == 0 or np.ptp(poses, axis=0).any():
        return None
    sd = estimate_noise(log).wrench_sd if wrench_sd is None else wrench_sd
    return poses, np.ptp(log.w_hat, axis=0) / np.maximum(np.asarray(sd, dtype=float), 1e-300)


def check_poses_move(log, names=("tx", "ty", "tz", "fx", "fy", "fz")):
    """Refuse a log whose every pose row is the same: its pose stream never moved, and nothing can be fitted.

    A tracker that stalls repeats its last pose to the last digit, where a real one's noise changes each row;
    the readings then say which it was: moving far beyond their noise (a channel's spread over
    :data:`STALL_SPREAD` of its noise standard deviations, :func:`stalled_poses`), a stalled tracker beside a
    moving payload; else a payload at rest.

    Parameters
    ----------
    log : plant.Log
    names : sequence of str
        The reading's channels, for the message.

    Raises
    ------
    LogError
    """
    stall = stalled_poses(log)
    if stall is None:
        return
    poses, spread = stall
    what = f"all {len(poses)} pose rows are the same ({','.join(f'{v:g}' for v in poses[0])})"
    if np.max(spread) > STALL_SPREAD:
        k = int(np.argmax(spread))
        raise LogError(f"{log.name}: {what} while the readings move ({names[k]} spans "
                       f"{np.ptp(log.w_hat[:, k]):.3g}): the pose stream does not move, a stalled tracker; check "
                       "the pose source (its connection, its frame, the topic recorded)")
    raise LogError(f"{log.name}: {what} and the readings stay within their noise: the payload was at rest "
                   "throughout, which determines nothing; record it moving")


def check_imu_units(name, angular_velocity, specific_force, orientation=None, dt=None):
    """Refuse an IMU's specific force or rate in another unit than m/s^2 and rad/s, naming the unit.

    The specific force ``f = R^T (p_ddot - g)`` has ``|f|`` near ``|g|`` wherever the motion is slow
    (:data:`EARTH_G`): its median size over the samples is within 0.5-2 g, else the size names the unit (g,
    cm/s^2, mm/s^2). The rate is checked against the orientation's: with ``R_k`` the IMU's attitudes (scalar-first
    quaternions, :func:`fmscal.plant.physics.rotation_matrices`), ``R_k^T R_(k+1) = I + [omega] dt`` to first
    order, so ``omega`` from consecutive orientations (the skew part's vector over ``dt``); the gyro's
    least-squares scale against it near ``180/pi`` is a gyro in deg/s. Without orientations, a rate beyond
    :data:`MAX_GYRO_RATE` is one.

    Parameters
    ----------
    name : str
        The log's name, for the message.
    angular_velocity, specific_force : array_like, shape (N, 3)
        rad/s and m/s^2, the IMU's axes; NaN rows where no sample.
    orientation : array_like, shape (N, 4), optional
        The IMU's attitudes (its axes to its world), scalar first; NaN rows where none.
    dt : float, optional
        The time step between rows, s (needed for the rate's check against the orientations).

    Raises
    ------
    UnitsError
    """
    omega, f = np.asarray(angular_velocity, dtype=float), np.asarray(specific_force, dtype=float)
    given = np.isfinite(omega).all(axis=1) & np.isfinite(f).all(axis=1)
    if not given.any():
        return
    size = float(np.median(np.linalg.norm(f[given], axis=1))) / EARTH_G
    lo, hi = _IMU_FORCE_BAND
    if not lo <= size <= hi:
        units = {"g (multiples of 9.81)": 1 / EARTH_G, "cm/s^2": 100.0, "mm/s^2": 1000.0}
        unit = next((u for u, k in units.items() if lo <= size / k <= hi), None)
        raise UnitsError(f"{name}: the IMU's specific force has a median size of {size * EARTH_G:.4g}, not near "
                         f"|g| = {EARTH_G} m/s^2 (within {lo:g}-{hi:g} g)" + (f": in {unit}? give it in m/s^2"
                                                                            if unit else ": give it in m/s^2"))
    deg = 180 / np.pi
    q = None if orientation is None else np.asarray(orientation, dtype=float)
    both = None if q is None or dt is None else given[:-1] & given[1:] & np.isfinite(q).all(axis=1)[:-1] \
        & np.isfinite(q).all(axis=1)[1:]
    if both is not None and both.sum() >= 10:
        rows = np.flatnonzero(both)
        R0, R1 = rotation_matrices(q[rows], normalise=True), rotation_matrices(q[rows + 1], normalise=True)
        D = np.einsum("nji,njk->nik", R0, R1)                                    # R_k^T R_(k+1)
        from_q = np.c_[D[:, 2, 1] - D[:, 1, 2], D[:, 0, 2] - D[:, 2, 0], D[:, 1, 0] - D[:, 0, 1]] / (2 * dt)
        gyro = (omega[rows] + omega[rows + 1]) / 2
        energy = float(np.sum(from_q ** 2))
        if energy > len(rows) * 1e-4:                                            # it turns: rms above 0.01 rad/s
            scale = float(np.sum(gyro * from_q)) / energy
            if deg / 2 < scale < deg * 2:
                raise UnitsError(f"{name}: the IMU's rate is {scale:.3g} times the rate its orientations show: in "
                                 "deg/s? give it in rad/s")
            return
    top = float(np.max(np.linalg.norm(omega[given], axis=1)))
    if top > MAX_GYRO_RATE:
        raise UnitsError(f"{name}: the IMU's rate reaches {top:.4g}, beyond what a gyro reads "
                         f"({MAX_GYRO_RATE:.3g} rad/s, 2000 deg/s): in deg/s? give it in rad/s")


def _weight_fit(R, f, acc=None, R_ddot=None):
    """Eq. (U1) by least squares: ``(m_a, m_a_std, c, relative residual)``.

    ``m_a`` is None without accelerations; the relative residual is the rms
    residual over the rms spread of ``f`` about its mean.
    """
    n = len(R)
    columns = [R, np.broadcast_to(np.eye(3), (n, 3, 3))]
    if acc is not None:
        columns = [acc[:, :, None], R_ddot, *columns]
    X = np.concatenate(columns, axis=2).reshape(3 * n, -1)
    y = np.einsum("nij,nj->ni", R, f).ravel()
    theta, *_ = np.linalg.lstsq(X, y, rcond=None)
    residual = y - X @ theta
    spread = np.sqrt(np.mean(np.var(f, axis=0)))
    relative = float(np.sqrt(np.mean(residual ** 2)) / max(spread, 1e-300))
    c = theta[-3:]
    if acc is None:
        return None, None, c, relative
    dof = max(len(y) - X.shape[1], 1)
    try:
        cov = np.linalg.inv(X.T @ X) * (residual @ residual / dof)
        std = float(np.sqrt(cov[0, 0]))
    except np.linalg.LinAlgError:
        std = np.inf
    return float(theta[0]), std, c, relative


def _lever_arm(tau, f):
    """Eq. (U2) by least squares: the lever arm ``rho`` (m in SI units)."""
    n = len(f)
    fx = np.zeros((n, 3, 3))                       # rho x f = -[f]x rho
    fx[:, 0, 1], fx[:, 0, 2], fx[:, 1, 2] = f[:, 2], -f[:, 1], f[:, 0]
    fx[:, 1, 0], fx[:, 2, 0], fx[:, 2, 1] = -f[:, 2], f[:, 1], -f[:, 0]
    X = np.concatenate([fx, np.broadcast_to(np.eye(3), (n, 3, 3))], axis=2).reshape(3 * n, 6)
    theta, *_ = np.linalg.lstsq(X, tau.ravel(), rcond=None)
    return theta[:3]


def _conventions(name, quaternions, w_hat, fits):
    """Which attitude convention and block order the weight's fit (eq. U1) says; a refusal naming another.

    ``fits(R, f)`` gives the relative residual of eq. (U1) for the rotations ``R`` and the force ``f``.
    """
    results = {}
    for blocks, (tau_cols, f_cols) in (("as written", (slice(0, 3), slice(3, 6))),
                                       ("swapped", (slice(3, 6), slice(0, 3)))):
        for convention, turn in _CONVENTIONS:
            results[(convention, blocks)] = fits(rotation_matrices(turn(quaternions), normalise=True), w_hat[:, f_cols])
    written = results[("as written", "as written")]
    (convention, blocks), best = min(results.items(), key=lambda item: item[1])
    if (written <= _POOR or best > _GOOD or best * _BETTER > written
            or (convention, blocks) == ("as written", "as written")):
        return
    fit = (f"the weight in the pose frame is one constant vector only with {{}} (the fit leaves {best:.1%} of the "
           f"force's spread unexplained, against {written:.0%} as written)")
    if blocks == "swapped":
        raise UnitsError(f"{name}: the reading's torque and force blocks look swapped (fx,fy,fz,tx,ty,tz, not "
                         f"tx,ty,tz,fx,fy,fz): " + fit.format("the blocks swapped") + "; reorder the columns")
    if convention == "conjugated":
        raise UnitsError(f"{name}: the quaternions look conjugated (pose frame to sensor, not sensor to pose frame): "
                         + fit.format("them conjugated") + "; write their inverse (negate qx, qy, qz)")
    raise UnitsError(f"{name}: the quaternions look scalar last (qx,qy,qz,qw written in the qw,qx,qy,qz columns): "
                     + fit.format(f"them read {convention}") + "; move qw to the first column")


def _unit_of(ratio, units):
    """The unit (a key of ``units``, its factor to SI) whose factor ``ratio`` is within a factor 3 of, or None."""
    return next((u for u, k in units.items() if k / 3 < ratio < k * 3), None)


def _torque_and_weight(name, w_hat, c, gravity, mass, com, max_mass=None):
    """The lever arm (eq. U2) and the weight ``|c|`` (eq. U1; None where eq. U1 does not fit) against the
    payload's: a centre of mass in mm (beyond :data:`MAX_LEVER_ARM`, the unit named by its ratio to the lever
    arm), N mm torques, mN readings."""
    rho = _lever_arm(w_hat[:, 0:3], w_hat[:, 3:6])
    arm = float(np.linalg.norm(rho))
    known = None if com is None else float(np.linalg.norm(com))
    if known is not None and known > MAX_LEVER_ARM:
        scales = {"mm": 1e3, "cm": 1e2}
        unit = _unit_of(known / max(arm, 1e-12), scales)
        in_m = "" if not unit else " ".join(f"{v / scales[unit]:.4g}" for v in com)
        raise UnitsError(f"{name}: the centre of mass given is {known:.4g} m from the sensor, beyond a wrist's "
                         f"{MAX_LEVER_ARM:g} m, where torque over force puts it {arm * 1e3:.3g} mm away: "
                         + (f"the centre of mass given in {unit}? give it in m (--com {in_m})" if unit
                            else "give com in m, in the sensor frame"))
    if arm > MAX_LEVER_ARM or (known is not None and known > 0.01 and arm > _FAR * known):
        told = f" (the payload's is {known * 1e3:.3g} mm)" if known is not None else ""
        raise UnitsError(f"{name}: the torques look like N mm, not N m: torque over force gives a lever arm of "
                         f"{arm:.3g} m{told}, beyond a wrist's {MAX_LEVER_ARM:g} m; convert tx, ty, tz to N m")
    if c is None:
        return
    weighed = float(np.linalg.norm(c)) / float(np.linalg.norm(gravity))
    if mass is None:
        limit = _max_mass(max_mass)
        if weighed > limit:
            raise UnitsError(f"{name}: the force reading weighs {weighed:.4g} kg (its weight over |g|), beyond "
                             f"{_carried(limit)}: readings in mN? give them in N and N m" + _heavier(limit))
        return
    ratio = weighed / mass
    error = None
    if ratio > _FAR:
        error = UnitsError(f"{name}: the force reading shows a weight {ratio:.3g} times m |g| ({weighed:.4g} kg "
                           f"against the payload's {mass:.4g} kg): readings in mN (1000)? give them in N and N m, or "
                           "check the mass")
    elif ratio < 1 / _FAR:
        error = UnitsError(f"{name}: the force reading shows a weight {ratio:.3g} times m |g| ({weighed:.4g} kg "
                           f"against the payload's {mass:.4g} kg): readings in kN, or the mass in g? give the readings "
                           "in N and the mass in kg")
    if error is not None:
        error.quantity = "weight"               # (a steady push along gravity weighs too: compensate says so)
        raise error


def check_table_units(table, gravity, mass=None, com=None, S=None, max_mass=None):
    """The unit and convention checks on held poses: gravity, mass, conventions, torques, the weight.

    Parameters
    ----------
    table : plant.io.PoseTable
    gravity : array_like, shape (3,)
        m/s^2, the pose frame's.
    mass : float, optional
        The payload's mass, kg (where known: ``calibrate``); without it, the weight the readings show is held
        to :data:`MAX_WRIST_MASS`.
    com : array_like, shape (3,), optional
        The payload's centre of mass in the sensor frame, m (where known).
    S : array_like, shape (6, 6), optional
        A calibration the readings go through first (default the identity).
    max_mass : float, optional
        The heaviest payload taken, kg (default :data:`MAX_WRIST_MASS`): the mass given, or without one the
        weight the readings show, beyond it is refused as a slipped unit.

    Raises
    ------
    UnitsError
        The first slip found, named in one line.
    """
    check_readings_change(table.name, table.w_hat)
    check_gravity(gravity)
    _max_mass(max_mass)
    if mass is not None:
        check_mass(mass, max_mass=max_mass)
    w_hat = _calibrated(table.w_hat, S)
    q = np.asarray(table.q, dtype=float)
    _conventions(table.name, q, w_hat, lambda R, f: _weight_fit(R, f)[3])
    _, _, c, relative = _weight_fit(rotation_matrices(q, normalise=True), w_hat[:, 3:6])
    _torque_and_weight(table.name, w_hat, c if relative <= _POOR else None, gravity, mass, com, max_mass)


def _calibrated(w_hat, S):
    return np.asarray(w_hat, dtype=float) if S is None else np.asarray(w_hat, dtype=float) @ np.asarray(S).T


def _coarse(log, window):
    """Quaternions, positions, mean readings on a grid of step ``window`` (at least the log's), and the step."""
    k = max(1, int(round(window / log.dt)))
    n = len(log.t) // k
    if n < 7 or log.has_pose.sum() < 7:
        return None
    t = log.t[:n * k].reshape(n, k).mean(axis=1)
    have = log.has_pose
    measured = log.pose[have].copy()
    measured[:, :4] = sign_continuous(measured[:, :4])
    pose = np.column_stack([np.interp(t, log.t[have], measured[:, j]) for j in range(7)])
    w_hat = log.w_hat[:n * k].reshape(n, k, 6).mean(axis=1)
    return pose, w_hat, k * log.dt


def check_spatial_log_units(log, gravity, mass=None, com=None, S=None, max_mass=None):
    """The unit and convention checks on a spatial log, before any fit: one line naming the first slip.

    In order: gravity's size (:func:`check_gravity`), the mass given (:func:`check_mass`), the time step
    (at most :data:`MAX_STEP`: ``t`` in ms), the attitude's convention and the reading's block order
    (eq. U1 fitted each way), the torque's lever arm (eq. U2, :data:`MAX_LEVER_ARM`: N mm), the weight the
    force shows against ``m |g|`` (mN), and the positions: the rms acceleration (:data:`MAX_ACCELERATION`)
    and the mass the accelerations imply (``m_a`` of eq. U1) against the weight's (mm). Poses and readings
    are averaged over 50 ms windows first; the cost is a few least-squares fits of a few thousand rows.

    Parameters
    ----------
    log : plant.Log
        A spatial log.
    gravity : array_like, shape (3,)
    mass, com, S, max_mass
        As :func:`check_table_units`.

    Raises
    ------
    UnitsError
        The first slip found, named in one line.
    """
    if np.shape(log.pose)[1:] != (7,) or np.shape(log.w_hat)[1:] != (6,):
        return                                          # not a spatial log: the caller says so
    check_readings_change(log.name, log.w_hat)
    check_poses_move(log)
    check_gravity(gravity)
    _max_mass(max_mass)
    if mass is not None:
        check_mass(mass, max_mass=max_mass)
    steps = np.diff(log.t)
    step = float(np.median(steps)) if len(steps) else 0.0
    if step > MAX_STEP:
        unit = "milliseconds" if step < 100 else "microseconds or another unit"
        raise UnitsError(f"{log.name}: t looks like {unit}, not seconds: its time steps are {step:.4g} s (a rate of "
                         f"{1 / step:.3g} Hz, where a force sensor reads at tens of Hz or more); convert t to s")
    coarse = _coarse(log, _WINDOW)
    if coarse is None:
        return
    pose, w_hat, h = coarse
    w_hat = _calibrated(w_hat, S)
    acc = np.diff(pose[:, 4:7], n=2, axis=0) / h ** 2

    def residual_of(R, f):
        R_ddot = (R[2:] - 2 * R[1:-1] + R[:-2]) / h ** 2
        return _weight_fit(R[1:-1], f[1:-1], acc, R_ddot)[3]
    _conventions(log.name, pose[:, :4], w_hat, residual_of)
    R = rotation_matrices(pose[:, :4], normalise=True)
    R_ddot = (R[2:] - 2 * R[1:-1] + R[:-2]) / h ** 2
    m_a, m_a_std, c, relative = _weight_fit(R[1:-1], w_hat[1:-1, 3:6], acc, R_ddot)
    fits = relative <= _POOR                       # else a mounting the fit does not hold: no weight read from it
    _torque_and_weight(log.name, w_hat, c if fits else None, gravity, mass, com, max_mass)
    rms = float(np.sqrt(np.mean(np.sum(acc ** 2, axis=1))))
    slower = _coarse(log, 4 * _WINDOW)
    if slower is None:
        return
    acc4 = np.diff(slower[0][:, 4:7], n=2, axis=0) / slower[2] ** 2
    if np.sqrt(np.mean(np.sum(acc4 ** 2, axis=1))) < 0.5 * rms:
        return                  # the accelerations are the positions' noise (it falls 32-fold over a 4-fold step)
    m_g = float(np.linalg.norm(c)) / float(np.linalg.norm(gravity))
    told = fits and abs(m_g - abs(m_a)) > 10 * m_a_std and m_g > 0
    if rms > MAX_ACCELERATION or (told and abs(m_a) < m_g / _FAR):
        unit = _unit_of(m_g / abs(m_a), {"millimetres": 1e3, "centimetres": 1e2}) if told and m_a else None
        share = f"the accelerations weigh the payload {abs(m_a) / m_g:.2g} times its weight (1e-3 for mm, 1e-2 for cm)"
        size = f"their rms acceleration is {rms:.3g} m/s^2 (a robot's stays under {MAX_ACCELERATION:g})"
        why = "; ".join([*([size] if rms > MAX_ACCELERATION else []), *([share] if told else [])])
        raise UnitsError(f"{log.name}: x, y, z look like {unit or 'millimetres or centimetres'}, not metres: {why}; "
                         "convert x, y, z to m")
