"""ROS bags in and out: a recorded rig run as a :class:`plant.Log`.

A rig that records with ROS publishes the sensor as
``geometry_msgs/WrenchStamped`` (0.5-1 kHz) and the motion capture as
``geometry_msgs/PoseStamped``, ``geometry_msgs/TransformStamped`` or
``nav_msgs/Odometry`` (50-240 Hz). :func:`import_bag` reads a ROS 2 bag
(MCAP or sqlite3: the bag's folder, or its ``.mcap`` / ``.db3`` file) or a
ROS 1 ``.bag`` with ``rosbags`` (pure Python, no ROS installation; the optional
extra ``fmscal[ros]``) and returns the log with a report of what was imported.

How a bag becomes a log:

* Time is the messages' header stamps, not the bag's receive times (those
  jitter by milliseconds). ``t`` is zero at the first wrench sample of the
  log; the absolute start is in the report.
* The wrench stream sets the sample times. ``M = torque.z``,
  ``f_x = force.x``, ``f_y = force.y`` (the sensor's frame). Stamps evenly
  spaced within the log format's 1 % are kept; others are resampled onto an
  even grid by linear interpolation (the report says so, with the spread),
  unless the stream has a hole longer than :data:`MAX_WRENCH_GAP` steps,
  which is refused.
* Each pose goes to the nearest wrench sample (the report gives the largest
  snapping error); samples with no pose are empty pose cells. ``theta`` is
  the yaw of the quaternion, unwrapped into a continuous angle; ``X, Y``
  the position, moved from the tracked marker to the centre of mass by the
  pose offset.
* The log runs over the span both streams share, cut further by
  ``start``/``end``.
* With ``spatial=True`` the log is spatial: all six wrench components
  (``tx .. fz``) and the whole pose (the quaternion, and the position moved
  from the tracked frame to the sensor point by the pose offset).

:func:`plant.io._bag_write.write_bag` writes a log as a bag (for tests, and to try
the import on a simulated run).
"""

import datetime
from collections import Counter
from pathlib import Path

import numpy as np

from fmscal.plant.physics import SpatialModel, rotation_matrix
from ._files import not_a_file
from ._log import Log, LogError
from ._tf_chain import chain_poses

__all__ = ["BagError", "import_bag", "read_bag", "format_report",
           "WRENCH_TYPE", "POSE_TYPES", "JOINT_TYPE", "TF_TYPE", "MAX_WRENCH_GAP", "MAX_TILT_DEG", "MAX_OUT_OF_PLANE"]

#: The sensor's message type (rosbags' normalised name).
WRENCH_TYPE = "geometry_msgs/msg/WrenchStamped"
#: Pose message types read, and where each keeps its pose.
POSE_TYPES = {"geometry_msgs/msg/PoseStamped": ("pose", "position", "orientation"),
              "geometry_msgs/msg/TransformStamped": ("transform", "translation", "rotation"),
              "nav_msgs/msg/Odometry": ("pose.pose", "position", "orientation")}
#: The arm's joint angles (with a URDF, the sensor frame's pose by forward kinematics).
JOINT_TYPE = "sensor_msgs/msg/JointState"
#: A robot's transform tree (``/tf``, with the fixed transforms on ``/tf_static``): the sensor frame's pose is
#: the chain from a parent frame to it, composed.
TF_TYPE = "tf2_msgs/msg/TFMessage"
#: Longest hole in the wrench stream that is resampled over, in time steps.
MAX_WRENCH_GAP = 10
#: Tilt of the tracked body beyond which the planar model is warned about, degrees.
MAX_TILT_DEG = 2.0
#: Travel out of the plane beyond which the planar model is warned about, m.
MAX_OUT_OF_PLANE = 0.01
_SAMPLING_TOLERANCE = 0.01     # as the log format (plant.io._log)


class BagError(LogError):
    """A bag that cannot be imported: one line, naming the topics present where relevant."""


def read_bag(path, wrench_topic, pose_topic, pose_offset=(0.0, 0.0), start=None, end=None):
    """Read a ROS bag into a log; :func:`import_bag` also returns the report.

    Parameters
    ----------
    path, wrench_topic, pose_topic, pose_offset, start, end
        As :func:`import_bag`.

    Returns
    -------
    plant.Log
    """
    return import_bag(path, wrench_topic, pose_topic, pose_offset, start, end)[0]


def import_bag(path, wrench_topic, pose_topic, pose_offset=(0.0, 0.0), start=None, end=None, spatial=False,
               kinematics=None, tf_frames=None):
    """Read a ROS bag into a log, with a report of what was imported.

    Parameters
    ----------
    path : str or Path
        A ROS 2 bag folder, its ``.mcap`` or ``.db3`` file, or a ROS 1 ``.bag``.
    wrench_topic : str
        Topic of ``geometry_msgs/WrenchStamped`` (the raw sensor reading).
    pose_topic : str
        Topic of ``geometry_msgs/PoseStamped``, ``geometry_msgs/TransformStamped``
        or ``nav_msgs/Odometry`` (the tracked payload).
    pose_offset : (float, float), or (float, float, float) with ``spatial``
        ``[DX, DY]``, m: the tracked marker frame's origin relative to the
        payload's centre of mass, in the body frame. The log's position is the
        centre of mass, ``[X, Y] = marker - R(theta) [DX, DY]``. With
        ``spatial``, ``[DX, DY, DZ]``: the tracked frame's origin from the
        sensor point, in the sensor's axes (the tracked frame's axes are the
        sensor's); the log's position is ``p = marker - R(q) [DX, DY, DZ]``.
    start, end : float, optional
        Keep only stamps in ``[start, end]`` s after the first wrench stamp
        of the bag.
    spatial : bool
        Keep the whole pose and all six wrench components: a spatial log
        (``t,qw,qx,qy,qz,x,y,z,tx,ty,tz,fx,fy,fz``) of a 6-axis sensor.
    kinematics : plant.io.RobotKinematics, optional
        The pose topic is the arm's ``sensor_msgs/JointState``: each message's
        joints (by name) give the sensor frame's pose by forward kinematics
        (a spatial log; the pose offset is then zero).
    tf_frames : (str, str), optional
        ``(parent, frame)``: the pose topic is ``/tf`` (``tf2_msgs/TFMessage``,
        with ``/tf_static`` read too where the bag has it), and the sensor
        frame's pose is the chain of transforms from ``parent`` down to
        ``frame``, composed at the stamps of its first moving link (the
        other moving links interpolated there). A spatial log.

    Returns
    -------
    log : plant.Log
        Named after the bag.
    report : dict
        ``bag``, ``wrench_topic``, ``pose_topic``, ``pose_type``,
        ``start_time_ns`` / ``start_time_utc`` (absolute time of the log's
        ``t = 0``), ``span_s`` (the shared span used, relative to the
        first wrench stamp), ``wrench`` and ``pose`` (per stream: messages
        read, messages used, nominal rate in Hz (one over the median step;
        the pose's mean rate too), frames dropped within the span used
        (gaps of 1.5 steps and more), duplicate stamps; the wrench's
        ``frame_id``, the most common ``header.frame_id``, which the ROS 2
        node's ``sensor_frame`` expects, and ``frame_ids``, each one's count),
        ``resampled`` (None, or the spread of the wrench steps that made it
        necessary), ``snap_error_max_s``, ``poses_merged`` (poses that fell on
        the same sample as a nearer one), ``tilt_max_deg``,
        ``out_of_plane_m`` (range of the position's z), ``in_plane_m``
        (largest range of X, Y), ``rms_used`` (``M, fx, fy``),
        ``rms_ignored`` (``torque.x, torque.y, force.z``), ``pose_offset``,
        ``window`` and ``warnings`` (list of str).

    Raises
    ------
    BagError
        Not a bag, a missing topic or one of the wrong type (naming the topics
        present), no header stamps, streams that do not overlap, a hole in the
        wrench stream, or too little data for a log.
    """
    path = Path(path)
    if (kinematics is not None or tf_frames is not None) and not spatial:
        raise BagError("joint angles and transforms give a spatial pose: import them with spatial=True (--spatial)")
    offset = _numbers(pose_offset, "pose_offset", 3 if spatial else 2)
    for name, value in (("start", start), ("end", end)):
        if value is not None and not np.isfinite(value):
            raise BagError(f"{name} must be a finite number of seconds; got {value}")
    if start is not None and end is not None and not end > start:
        raise BagError(f"end must be after start; got start {start}, end {end}")
    pose_type, wrench_msgs, pose_msgs, frames = _read_messages(path, wrench_topic, pose_topic, kinematics,
                                                               tf_frames)
    t_w, w, w_ignored, w_info = _stream(wrench_msgs, "wrench", path.name)
    if spatial:                                 # [torque.x, torque.y, torque.z, force.x, force.y, force.z]
        w, w_ignored = np.column_stack([w_ignored[:, :2], w[:, :1], w[:, 1:], w_ignored[:, 2:]]), w_ignored[:, :0]
    t_p, p, p_info = _stream(pose_msgs, "pose", path.name)
    origin = t_w[0]                                     # ns of the bag's first wrench stamp
    tw = (t_w - origin) * 1e-9
    tp = (t_p - origin) * 1e-9
    lo, hi = max(tw[0], tp[0]), min(tw[-1], tp[-1])
    if hi <= lo:
        raise BagError(f"{path.name}: the wrench stamps ({tw[0]:.3f} to {tw[-1]:.3f} s) and the pose stamps "
                       f"({tp[0]:.3f} to {tp[-1]:.3f} s, from the first wrench stamp) do not overlap")
    lo, hi = max(lo, start if start is not None else lo), min(hi, end if end is not None else hi)
    if hi <= lo:
        raise BagError(f"{path.name}: the window [{start}, {end}] s holds none of the span both streams "
                       f"share ({max(tw[0], tp[0]):.3f} to {min(tw[-1], tp[-1]):.3f} s)")
    dt = float(np.median(np.diff(tw)))
    keep_w = (tw >= lo - dt / 2) & (tw <= hi + dt / 2)
    keep_p = (tp >= lo - dt / 2) & (tp <= hi + dt / 2)
    tw, w, w_ignored = tw[keep_w], w[keep_w], w_ignored[keep_w]
    tp, p = tp[keep_p], p[keep_p]
    if len(tw) < 2 or len(tp) < 2:
        raise BagError(f"{path.name}: too few messages in the span both streams share "
                       f"({len(tw)} wrench, {len(tp)} pose)")

    if spatial:
        values, xyz = _spatial_pose(p, offset), p[:, :3]
    else:
        theta, xy, tilt, z = _planar_pose(p, offset)
        values = np.column_stack([theta, xy])
    grid, w_grid, resampled = _even_grid(tw, w, path.name)
    k = np.clip(np.round((tp - grid[0]) / (grid[1] - grid[0])).astype(int), 0, len(grid) - 1)
    snap = np.abs(grid[k] - tp)
    pose = np.full((len(grid), values.shape[1]), np.nan)
    best = np.full(len(grid), np.inf)
    merged = 0
    for i in np.argsort(snap, kind="stable"):           # nearest pose wins a sample
        if np.isfinite(best[k[i]]):
            merged += 1
            continue
        best[k[i]] = snap[i]
        pose[k[i]] = values[i]
    rows = np.flatnonzero(~np.isnan(pose[:, 0]))
    first, last = rows[0], rows[-1]
    t0 = grid[first]
    log = Log(grid[first:last + 1] - t0, pose[first:last + 1], w_grid[first:last + 1], name=path.name)
    used_w = (tw >= t0 - dt / 2) & (tw <= grid[last] + dt / 2)

    def rms(a):
        return [float(v) for v in np.sqrt(np.mean(np.square(a), axis=0))]

    names = SpatialModel.wrench_names if spatial else ("M", "fx", "fy")
    report = {
        "bag": str(path), "wrench_topic": wrench_topic, "pose_topic": pose_topic, "pose_type": pose_type,
        "start_time_ns": int(origin + round(t0 * 1e9)),
        "start_time_utc": _utc(origin + round(t0 * 1e9)),
        "span_s": [float(t0), float(grid[last])],
        "window": [start, end],
        "wrench": {**w_info, "used": int(used_w.sum()), "rate_hz": 1.0 / dt, "dropped": 0,
                   "frame_id": frames.most_common(1)[0][0], "frame_ids": dict(frames.most_common())},
        "pose": {**p_info, "used": int(len(rows)), "rate_hz": 1.0 / float(np.median(np.diff(tp))),
                 "mean_rate_hz": _rate(tp)},
        "resampled": resampled,
        "snap_error_max_s": float(snap.max()),
        "poses_merged": int(merged),
        "spatial": bool(spatial),
        "rms_used": dict(zip(names, rms(w[used_w]))),
        "rms_ignored": {} if spatial else dict(zip(("torque.x", "torque.y", "force.z"), rms(w_ignored[used_w]))),
        "pose_offset": list(offset),
    }
    if spatial:
        report["motion_m"] = float(np.max(np.ptp(xyz, axis=0)))
    else:
        report.update({"tilt_max_deg": float(np.degrees(tilt.max())), "out_of_plane_m": float(np.ptp(z)),
                       "in_plane_m": float(np.max(np.ptp(xy, axis=0)))})
    report["wrench"]["dropped"] = _dropped(tw)             # frames missing within the span used
    report["pose"]["dropped"] = _dropped(tp)
    report["warnings"] = _warnings(report)
    return log, report


def _numbers(value, name, n):
    """``value`` as ``n`` finite numbers (m), or a one-line :class:`BagError`."""
    word = {2: "two", 3: "three"}[n]
    try:
        numbers = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise BagError(f"{name} must be {word} numbers in m; got {value!r}") from None
    if len(numbers) != n or not all(np.isfinite(numbers)):
        raise BagError(f"{name} must be {word} finite numbers in m; got {value!r}")
    return numbers


def _open_reader(path):
    """An open ``rosbags`` AnyReader on ``path``, or a one-line BagError."""
    try:
        from rosbags.highlevel import AnyReader          # optional (the ros extra): only bags need it
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise BagError("reading ROS bags needs rosbags: pip install 'fmscal[ros]'") from None
    problem = not_a_file(path, folder_ok=True)
    if problem == "no such file":
        raise BagError(f"{path}: no such file or folder")
    if problem is not None:
        raise BagError(f"{path}: is {problem}, not a ROS bag")
    kind = "folder" if path.is_dir() else path.suffix
    if kind not in ("folder", ".bag", ".mcap", ".db3"):
        raise BagError(f"{path.name}: not a ROS bag; expected a ROS 2 bag folder, a .mcap or .db3 file, "
                       f"or a ROS 1 .bag (got a {path.suffix or 'file without suffix'})")
    if path.is_dir() and not (path / "metadata.yaml").exists():
        files = sorted(path.glob("*.mcap")) + sorted(path.glob("*.db3"))
        if len(files) != 1:
            raise BagError(f"{path.name}: not a ROS 2 bag folder (no metadata.yaml"
                           + (f", and {len(files)} .mcap/.db3 files)" if files else ", no .mcap or .db3 file)"))
        path = files[0]
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.LATEST))
        reader.open()
    except Exception as err:
        _refuse_foreign(err, f"{path.name}: not a readable ROS bag")
    return reader


#: Where the errors of a damaged or foreign file come from (rosbags and the storage it reads).
_FOREIGN = ("rosbags", "sqlite3", "struct", "zstandard", "lz4", "ruamel", "yaml")


def _refuse_foreign(err, what):
    """A BagError for an error raised by rosbags or its storage on a bad file; anything else re-raised."""
    module = type(err).__module__ or ""
    if not (module.split(".")[0] in _FOREIGN or isinstance(err, (EOFError, UnicodeDecodeError))):
        raise err
    message = str(err).splitlines()[0] if str(err) else type(err).__name__
    raise BagError(f"{what} ({message})") from None


def _read_messages(path, wrench_topic, pose_topic, kinematics=None, tf_frames=None):
    """The pose type, the (stamp ns, values) lists of both topics (poses as ``x, y, z, qx, qy, qz, qw``) and the
    wrench messages' ``header.frame_id`` counted (a Counter)."""
    reader = _open_reader(path)
    try:
        topics = {name: info.msgtype for name, info in reader.topics.items()}
        present = ", ".join(f"{name} ({typ})" for name, typ in sorted(topics.items())) or "none"
        pose_types = ((JOINT_TYPE,) if kinematics is not None else (TF_TYPE,) if tf_frames is not None
                      else tuple(POSE_TYPES))
        for role, topic, wanted in (("wrench", wrench_topic, (WRENCH_TYPE,)),
                                    ("pose", pose_topic, pose_types)):
            if topic not in topics:
                raise BagError(f"{path.name}: no {role} topic {topic!r}; topics present: {present}")
            if topics[topic] not in wanted:
                raise BagError(f"{path.name}: {role} topic {topic!r} is {topics[topic]}, expected "
                               f"{' or '.join(wanted)}; topics present: {present}")
        out = {wrench_topic: [], pose_topic: []}
        if wrench_topic == pose_topic:
            raise BagError(f"the wrench and pose topics must differ; got {wrench_topic!r} for both")
        static = "/tf_static" if tf_frames is not None and topics.get("/tf_static") == TF_TYPE else None
        if static:
            out[static] = []
        connections = [c for c in reader.connections if c.topic in out]
        try:
            for connection, _, raw in reader.messages(connections=connections):
                msg = reader.deserialize(raw, connection.msgtype)
                if connection.msgtype == TF_TYPE:             # no header of its own: one per transform
                    out[connection.topic].append((0, msg))
                    continue
                stamp = msg.header.stamp
                out[connection.topic].append((int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec), msg))
        except Exception as err:
            _refuse_foreign(err, f"{path.name}: a message could not be read; the bag is damaged")
        pose_type = topics[pose_topic]
    finally:
        reader.close()
    frames = Counter(m.header.frame_id for _, m in out[wrench_topic])
    if tf_frames is not None:
        return (pose_type, [(s, _wrench_values(m)) for s, m in out[wrench_topic]],
                chain_poses([m for _, m in out[pose_topic]], [m for _, m in out.get(static, [])], *tf_frames,
                            path.name), frames)
    if kinematics is not None:
        poses = _joint_poses([m for _, m in out[pose_topic]], kinematics, path.name)
        return (pose_type, [(s, _wrench_values(m)) for s, m in out[wrench_topic]],
                [(s, (*p[4:], *p[1:4], p[0])) for (s, _), p in zip(out[pose_topic], poses)], frames)
    where = POSE_TYPES[pose_type]

    def pose_values(msg):
        for attr in where[0].split("."):
            msg = getattr(msg, attr)
        p, q = getattr(msg, where[1]), getattr(msg, where[2])
        return (p.x, p.y, p.z, q.x, q.y, q.z, q.w)

    return (pose_type, [(s, _wrench_values(m)) for s, m in out[wrench_topic]],
            [(s, pose_values(m)) for s, m in out[pose_topic]], frames)


def _wrench_values(msg):
    """``[torque.z, force.x, force.y, torque.x, torque.y, force.z]`` of a WrenchStamped (planar first)."""
    f, m = msg.wrench.force, msg.wrench.torque
    return (m.z, f.x, f.y, m.x, m.y, f.z)


def _joint_poses(messages, kinematics, name):
    """The sensor frame's pose (``[qw, qx, qy, qz, x, y, z]``) of every JointState message, its joints by name."""
    wanted = kinematics.joint_names
    rows = np.empty((len(messages), len(wanted)))
    for k, msg in enumerate(messages):
        by_name = dict(zip(msg.name, np.asarray(msg.position, dtype=float)))
        missing = [j for j in wanted if j not in by_name]
        if missing:
            raise BagError(f"{name}: JointState message {k + 1} has no {', '.join(missing)} (it names "
                           f"{', '.join(msg.name) or 'no joint'}); the URDF's joints are {', '.join(wanted)}")
        rows[k] = [by_name[j] for j in wanted]
    if not np.all(np.isfinite(rows)):
        raise BagError(f"{name}: a JointState message holds a NaN or infinite position "
                       f"(message {int(np.argmax(~np.isfinite(rows).all(axis=1))) + 1})")
    return kinematics.poses(rows) if len(rows) else np.empty((0, 7))


#: A stamp earlier than the one recorded before it by more than this many of the stream's steps is a
#: clock that jumped back (a few steps: messages reordered in transport, sorted by stamp).
_MAX_BACK_STEPS = 10


def _stream(messages, role, name):
    """Stamps (int ns, sorted, duplicates dropped) and values of one stream, with counts."""
    if len(messages) < 2:
        raise BagError(f"{name}: the {role} topic has {len(messages)} message(s); need many more")
    stamps = np.array([s for s, _ in messages], dtype=np.int64)
    values = np.array([v for _, v in messages], dtype=float)
    if np.all(stamps == stamps[0]):
        raise BagError(f"{name}: every {role} message has the header stamp {stamps[0]} ns; "
                       "the publisher did not stamp its messages")
    zero = np.flatnonzero(stamps == 0)
    if len(zero):
        raise BagError(f"{name}: {len(zero)} {role} message(s) have the header stamp 0 (unstamped), the first "
                       f"message {zero[0] + 1} as recorded; the publisher did not stamp them")
    steps = np.diff(stamps)
    nominal = np.median(steps[steps > 0]) if np.any(steps > 0) else 0
    # the largest step back of the clock, in the order recorded: a step under half the nominal one lost
    # (nominal - step) against an even clock
    worst = int(np.argmin(steps))
    step_back = {"step_back_ns": int(nominal - steps[worst]), "step_back_at_ns": int(stamps[worst + 1])} \
        if steps[worst] < 0.5 * nominal else {"step_back_ns": 0, "step_back_at_ns": None}
    back = np.flatnonzero(steps < -_MAX_BACK_STEPS * nominal)
    if len(back):
        k = int(back[0])
        raise BagError(f"{name}: the {role} clock jumps back by {-steps[k] / 1e9:.6g} s at message {k + 2} "
                       f"as recorded ({_utc(int(stamps[k]))} then {_utc(int(stamps[k + 1]))}); a restarted clock or "
                       "publisher; split the bag there and import each part")
    order = np.argsort(stamps, kind="stable")
    stamps, values = stamps[order], values[order]
    unique = np.concatenate([[True], np.diff(stamps) > 0])
    # messages reordered in transport sort back into an even stream; a clock that stepped back leaves stamps
    # that overlap the ones before the step once sorted: closer than half a step to a neighbour, or the same
    close = np.flatnonzero(np.diff(stamps) < 0.5 * nominal)
    info = {"messages": int(len(stamps)), "duplicate_stamps": int((~unique).sum()),
            "out_of_order": int(np.sum(np.diff(order) < 0)), "overlapping_stamps": int(len(close)),
            "first_overlap_ns": int(stamps[close[0] + 1]) if len(close) else None, **step_back}
    stamps, values = stamps[unique], values[unique]
    if not np.all(np.isfinite(values)):
        raise BagError(f"{name}: a {role} message holds a NaN or infinite value "
                       f"(message {int(np.argmax(~np.isfinite(values).all(axis=1))) + 1} by stamp)")
    if role == "wrench":
        return stamps, values[:, :3], values[:, 3:], info
    return stamps, values, info


def _rate(t):
    return float((len(t) - 1) / (t[-1] - t[0]))


def _dropped(t):
    """Frames missing from a stream of nominal step the median step: gaps of 1.5 steps and more."""
    steps = np.diff(t)
    nominal = np.median(steps)
    gaps = steps[steps > 1.5 * nominal]
    return int(np.sum(np.round(gaps / nominal) - 1))


def _even_grid(t, w, name):
    """The wrench on an even grid: as stamped when even within 1 %, else linearly resampled."""
    steps = np.diff(t)
    dt = float(np.median(steps))
    spread = float(np.max(np.abs(steps - dt)) / dt)
    if spread <= _SAMPLING_TOLERANCE:
        return t, w, None
    if steps.max() > MAX_WRENCH_GAP * dt:
        at = float(t[np.argmax(steps)])
        raise BagError(f"{name}: the wrench stream has a hole of {steps.max():.4g} s at t = {at:.3f} s "
                       f"({steps.max() / dt:.0f} steps of {dt:.4g} s; at most {MAX_WRENCH_GAP} are "
                       "resampled over); cut it out with start/end")
    grid = t[0] + dt * np.arange(int(np.floor((t[-1] - t[0]) / dt + 1e-9)) + 1)
    w_grid = np.column_stack([np.interp(grid, t, w[:, j]) for j in range(w.shape[1])])
    return grid, w_grid, {"step_s": dt, "steps_min_s": float(steps.min()), "steps_max_s": float(steps.max()),
                          "spread": spread}


def _unit_quaternions(p):
    """The ``[qx, qy, qz, qw]`` columns of pose rows, normalised; a zero quaternion is one line."""
    q = p[:, 3:7]
    norm = np.linalg.norm(q, axis=1)
    if np.any(norm < 1e-6):
        raise BagError(f"a pose message has a zero quaternion (message {int(np.argmax(norm < 1e-6)) + 1} by stamp)")
    return q / norm[:, None]


def _spatial_pose(p, offset):
    """Rows ``[qw, qx, qy, qz, x, y, z]`` of the sensor frame from ``[x, y, z, qx, qy, qz, qw]`` of the tracked one."""
    x, y, z, w = _unit_quaternions(p).T
    q = np.column_stack([w, x, y, z])
    R = np.moveaxis(rotation_matrix(q.T), -1, 0)
    return np.column_stack([q, p[:, :3] - R @ np.asarray(offset, dtype=float)])


def _planar_pose(p, offset):
    """Yaw (unwrapped), centre-of-mass position, tilt and height from ``[x, y, z, qx, qy, qz, qw]`` rows."""
    x, y, z, w = _unit_quaternions(p).T
    yaw = np.unwrap(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
    tilt = np.arccos(np.clip(1 - 2 * (x * x + y * y), -1.0, 1.0))     # body z against world z
    c, s = np.cos(yaw), np.sin(yaw)
    dx, dy = offset
    xy = np.column_stack([p[:, 0] - (c * dx - s * dy), p[:, 1] - (s * dx + c * dy)])
    return yaw, xy, tilt, p[:, 2]


def _utc(ns):
    return datetime.datetime.fromtimestamp(ns * 1e-9, tz=datetime.timezone.utc).isoformat()


def _warnings(r):
    out = []
    if not r.get("spatial") and r["tilt_max_deg"] > MAX_TILT_DEG:
        out.append(f"the tracked body tilts up to {r['tilt_max_deg']:.2g} deg (more than {MAX_TILT_DEG:g}): "
                   "the motion is not planar and the planar model does not hold")
    if not r.get("spatial") and r["out_of_plane_m"] > MAX_OUT_OF_PLANE:
        out.append(f"the tracked body travels {r['out_of_plane_m']:.3g} m out of the plane (more than "
                   f"{MAX_OUT_OF_PLANE:g} m): the planar model does not hold")
    if r["resampled"] is not None:
        out.append(f"the wrench stamps are uneven (steps {r['resampled']['steps_min_s']:.4g} to "
                   f"{r['resampled']['steps_max_s']:.4g} s, {100 * r['resampled']['spread']:.3g} % off the "
                   f"median, more than the log format's {100 * _SAMPLING_TOLERANCE:g} %): resampled to an even "
                   f"step of {r['resampled']['step_s']:.4g} s by linear interpolation")
    for role in ("wrench", "pose"):
        stream = r.get(role, {})
        if stream.get("overlapping_stamps"):
            out.append(f"the {role} stamps overlap: {stream['overlapping_stamps']} fall within half a step of "
                       f"another (the first at {_utc(stream['first_overlap_ns'])}): a clock that stepped back, "
                       f"or a message stamped twice; the samples were sorted by stamp, and those after the step "
                       f"may be shifted against the other stream"
                       + (f" (the clock steps back by {stream['step_back_ns'] / 1e6:.6g} ms at "
                          f"{_utc(stream['step_back_at_ns'])}, in the order recorded)"
                          if stream.get("step_back_ns") else ""))
    frames = r.get("wrench", {}).get("frame_ids", {})
    if len(frames) > 1:
        out.append(f"the wrench messages name {len(frames)} frames: "
                   + ", ".join(f"{name or '(empty)'!s} ({n})" for name, n in frames.items())
                   + f"; the most common, {r['wrench']['frame_id'] or '(empty)'}, is recorded as the sensor's")
    if r["poses_merged"]:
        out.append(f"{r['poses_merged']} pose(s) fell on a wrench sample already holding a nearer pose and "
                   "were left out (poses faster than the sensor?)")
    return out


def format_report(report):
    """The import report as lines of text (what ``fmscal import`` prints).

    Parameters
    ----------
    report : dict
        From :func:`import_bag`.

    Returns
    -------
    str
    """
    w, p = report["wrench"], report["pose"]
    used, ignored = report["rms_used"], report["rms_ignored"]
    lines = [
        f"{Path(report['bag']).name}: wrench {report['wrench_topic']} (WrenchStamped), "
        f"pose {report['pose_topic']} ({report['pose_type'].rsplit('/', 1)[-1]})",
        f"  wrench: {w['messages']} messages at {w['rate_hz']:.4g} Hz, {w['dropped']} dropped, "
        f"{w['duplicate_stamps']} duplicate stamps; {w['used']} used; frame_id "
        + (repr(w['frame_id']) + " (the node's sensor_frame)" if w.get('frame_id') else "empty"),
        f"  pose:   {p['messages']} messages at {p['rate_hz']:.4g} Hz (mean {p['mean_rate_hz']:.4g} Hz), "
        f"{p['dropped']} dropped, "
        f"{p['duplicate_stamps']} duplicate stamps; {p['used']} used",
        f"  shared span: {report['span_s'][0]:.3f} to {report['span_s'][1]:.3f} s after the first wrench stamp "
        f"({report['span_s'][1] - report['span_s'][0]:.3f} s); t = 0 is {report['start_time_utc']} "
        f"({report['start_time_ns']} ns)",
        f"  poses snapped to the nearest wrench sample: largest error {report['snap_error_max_s'] * 1e3:.3g} ms",
        (f"  spatial: the whole pose and all six wrench components; the motion spans {report['motion_m']:.3g} m"
         if report["spatial"] else
         f"  planarity: tilt up to {report['tilt_max_deg']:.3g} deg, {report['out_of_plane_m'] * 1e3:.3g} mm out of "
         f"the plane (the motion spans {report['in_plane_m']:.3g} m in it)"),
        "  rms used:    " + ", ".join(f"{k} {v:.4g}" for k, v in used.items()) + " (N m, N)",
    ]
    if ignored:
        lines.append("  rms ignored: " + ", ".join(f"{k} {v:.4g}" for k, v in ignored.items()) + " (N m, N)")
    if any(report["pose_offset"]):
        frame = "the sensor point, sensor axes" if report["spatial"] else "the centre of mass, body frame"
        lines.append(f"  pose offset (marker from {frame}): "
                     + ", ".join(f"{v:g}" for v in report["pose_offset"]) + " m")
    return "\n".join(lines)
