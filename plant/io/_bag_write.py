"""A log written as a ROS bag, as a rig's recorder would write it (tests, trying ``fmscal import``)."""

from pathlib import Path

import numpy as np

from fmscal.plant.physics import rotation_matrix
from ._bag import WRENCH_TYPE, BagError, _numbers

__all__ = ["write_bag", "write_tf_bag"]


def _header(T, ns, frame_id="world", ros1=False):
    """A ``std_msgs/Header`` stamped ``ns`` (absolute, ns) in ``frame_id`` (ROS 1's with ``seq`` 0)."""
    kw = {"stamp": T["builtin_interfaces/msg/Time"](sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000)),
          "frame_id": frame_id}
    if ros1:
        kw["seq"] = 0
    return T["std_msgs/msg/Header"](**kw)


def _wrench(T, header, row):
    """A ``WrenchStamped`` of one reading ``(tx, ty, tz, fx, fy, fz)``, N m and N."""
    V = T["geometry_msgs/msg/Vector3"]
    tx, ty, tz, fx, fy, fz = (float(v) for v in row)
    return T["geometry_msgs/msg/WrenchStamped"](header=header, wrench=T["geometry_msgs/msg/Wrench"](
        force=V(x=fx, y=fy, z=fz), torque=V(x=tx, y=ty, z=tz)))


def write_bag(log, path, storage="mcap", wrench_topic="/ft_sensor/wrench", pose_topic="/mocap/payload/pose",
              pose_type="PoseStamped", start_time_ns=1_700_000_000_000_000_000, receive_jitter=0.0,
              pose_offset=(0.0, 0.0), pose_stamp_jitter=0.0, wrench_drop_rate=0.0, seed=0, joints=None,
              joint_names=None, wrench_frame_id="world"):
    """Write a log as a ROS bag, as a rig's recorder would.

    The reading goes out as ``WrenchStamped`` at every sample, the pose as
    ``pose_type`` where the log has one (the yaw as a quaternion about z,
    so it wraps into (-pi, pi]; the position of a marker at ``pose_offset``
    from the centre of mass). Header stamps are ``start_time_ns`` plus the
    log's ``t``; the bag's receive times are later by 1 ms plus a uniform
    jitter of up to ``receive_jitter`` s, and messages are written in
    receive order. ``pose_stamp_jitter`` moves each pose's header stamp by
    up to that much either way (a motion-capture clock off the sensor's
    sample grid), the pose itself unchanged.

    Parameters
    ----------
    log : plant.Log
    path : str or Path
        A new folder (ROS 2) or ``.bag`` file (ROS 1); never overwritten.
    storage : str
        ``"mcap"`` or ``"sqlite3"`` (ROS 2), ``"ros1"``.
    wrench_topic, pose_topic : str
    pose_type : str
        ``"PoseStamped"``, ``"TransformStamped"``, ``"Odometry"``, or
        ``"JointState"`` (the arm's joints ``joints`` at every pose, named
        ``joint_names``; the log's poses are then not written).
    start_time_ns : int
        Absolute time of the log's first sample, ns.
    receive_jitter : float
        s, at least 0.
    pose_offset : (float, float), or (float, float, float) for a spatial log
        The marker's origin relative to the centre of mass, body frame, m.
    pose_stamp_jitter : float
        s, at least 0, less than half a sample.
    wrench_drop_rate : float
        Fraction of wrench messages left out at random (never the first or
        the last), in [0, 0.5).
    seed : int
        Seeds the jitters.
    joints : array_like, shape (N, n), optional
        The joint angles at every sample of the log (``pose_type="JointState"``), rad.
    joint_names : sequence of str, optional
        Their names, as the URDF names its joints.
    wrench_frame_id : str or sequence of str
        The wrench messages' ``header.frame_id``: one for all, or one per sample of the log.

    Returns
    -------
    pathlib.Path
        The bag written.
    """
    from rosbags.typesys import Stores, get_typestore      # optional (the ros extra): only bags need it

    path = Path(path)
    if path.exists():
        raise BagError(f"{path}: exists already; a bag is never overwritten")
    if storage not in ("mcap", "sqlite3", "ros1"):
        raise BagError(f"storage must be mcap, sqlite3 or ros1; got {storage!r}")
    full = {"PoseStamped": "geometry_msgs/msg/PoseStamped", "TransformStamped": "geometry_msgs/msg/TransformStamped",
            "Odometry": "nav_msgs/msg/Odometry", "JointState": "sensor_msgs/msg/JointState"}
    if pose_type not in full:
        raise BagError(f"pose_type must be one of {', '.join(full)}; got {pose_type!r}")
    if pose_type == "JointState" and (joints is None or joint_names is None or np.shape(joints)[0] != len(log.t)):
        raise BagError("a JointState bag needs joints (one row per sample of the log) and joint_names")
    if not (np.isfinite(receive_jitter) and receive_jitter >= 0):
        raise BagError(f"receive_jitter must be a non-negative number of seconds; got {receive_jitter}")
    if not (np.isfinite(pose_stamp_jitter) and 0 <= pose_stamp_jitter < log.dt / 2):
        raise BagError(f"pose_stamp_jitter must be in [0, {log.dt / 2:g}) s; got {pose_stamp_jitter}")
    if not (np.isfinite(wrench_drop_rate) and 0 <= wrench_drop_rate < 0.5):
        raise BagError(f"wrench_drop_rate must be in [0, 0.5); got {wrench_drop_rate}")
    spatial = getattr(log, "kind", "planar") == "spatial"
    if spatial and len(pose_offset) == 2 and not any(pose_offset):
        pose_offset = (0.0, 0.0, 0.0)
    offset = np.asarray(_numbers(pose_offset, "pose_offset", 3 if spatial else 2))
    ts = get_typestore(Stores.ROS1_NOETIC if storage == "ros1" else Stores.ROS2_HUMBLE)
    T = ts.types
    Vector3, Point = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Point"]
    Quaternion = T["geometry_msgs/msg/Quaternion"]
    rng = np.random.default_rng(seed)
    stamps = start_time_ns + np.round(log.t * 1e9).astype(np.int64)

    def header(ns):
        return _header(T, ns, ros1=storage == "ros1")

    def wrench_msg(ns, row, frame_id):
        head = _header(T, ns, frame_id, ros1=storage == "ros1")
        return _wrench(T, head, row if spatial else (0.0, 0.0, row[0], row[1], row[2], 0.0))

    def marker(pose):
        """The tracked frame's position and attitude ``(px, py, pz, q)`` at a log's pose."""
        if spatial:
            qw, qx, qy, qz = pose[:4]
            px, py, pz = pose[4:] + rotation_matrix(pose[:4]) @ offset
            return px, py, pz, Quaternion(x=float(qx), y=float(qy), z=float(qz), w=float(qw))
        theta, X, Y = pose
        c, s = np.cos(theta), np.sin(theta)
        px, py = X + c * offset[0] - s * offset[1], Y + s * offset[0] + c * offset[1]
        return px, py, 0.0, Quaternion(x=0.0, y=0.0, z=float(np.sin(theta / 2)), w=float(np.cos(theta / 2)))

    def pose_msg(ns, pose, k):
        if pose_type == "JointState":
            return T[full[pose_type]](header=header(ns), name=list(joint_names),
                                      position=np.ascontiguousarray(joints[k], dtype=np.float64),
                                      velocity=np.zeros(0), effort=np.zeros(0))
        px, py, pz, q = marker(pose)
        if pose_type == "TransformStamped":
            return T[full[pose_type]](header=header(ns), child_frame_id="payload",
                                      transform=T["geometry_msgs/msg/Transform"](
                                          translation=Vector3(x=float(px), y=float(py), z=float(pz)), rotation=q))
        pose = T["geometry_msgs/msg/Pose"](position=Point(x=float(px), y=float(py), z=float(pz)), orientation=q)
        if pose_type == "PoseStamped":
            return T[full[pose_type]](header=header(ns), pose=pose)
        cov = np.zeros(36)
        return T[full[pose_type]](header=header(ns), child_frame_id="payload",
                                  pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
                                  twist=T["geometry_msgs/msg/TwistWithCovariance"](
                                      twist=T["geometry_msgs/msg/Twist"](linear=Vector3(x=0.0, y=0.0, z=0.0),
                                                                          angular=Vector3(x=0.0, y=0.0, z=0.0)),
                                      covariance=cov))

    sent = rng.random(len(stamps)) >= wrench_drop_rate
    sent[0] = sent[-1] = True
    frames = [wrench_frame_id] * len(stamps) if isinstance(wrench_frame_id, str) else list(wrench_frame_id)
    if len(frames) != len(stamps):
        raise BagError(f"wrench_frame_id must be one name or one per sample ({len(stamps)}); got {len(frames)}")
    messages = [(0, ns, wrench_msg(ns, row, f)) for ns, row, ok, f in zip(stamps, log.w_hat, sent, frames) if ok]
    rows = np.flatnonzero(log.has_pose)
    shift = np.round(rng.uniform(-pose_stamp_jitter, pose_stamp_jitter, len(rows)) * 1e9).astype(np.int64)
    messages += [(1, stamps[k] + d, pose_msg(stamps[k] + d, log.pose[k], k)) for k, d in zip(rows, shift)]
    received = [int(ns) + 1_000_000 + int(rng.uniform(0, receive_jitter) * 1e9) for _, ns, _ in messages]
    order = np.argsort(received, kind="stable")
    if storage == "ros1":
        from rosbags.rosbag1 import Writer                 # optional (the ros extra)
        writer, serialize = Writer(path), ts.serialize_ros1
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer  # optional (the ros extra)
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        writer, serialize = Writer(path, version=9, storage_plugin=plugin), ts.serialize_cdr
    with writer:
        conns = [writer.add_connection(wrench_topic, WRENCH_TYPE, typestore=ts),
                 writer.add_connection(pose_topic, full[pose_type], typestore=ts)]
        for i in order:
            which, _, msg = messages[i]
            writer.write(conns[which], int(received[i]), serialize(msg, msg.__msgtype__))
    return path


def write_tf_bag(path, t, wrench, links, static=(), wrench_topic="/ft_sensor/wrench", tf_every=1,
                 start_time_ns=1_700_000_000_000_000_000, storage="sqlite3"):
    """Write a robot's run as a ROS 2 bag of ``/tf``, ``/tf_static`` and a ``WrenchStamped`` topic.

    A robot driver publishes its transform tree: the moving links on ``/tf``
    (``tf2_msgs/TFMessage``), the fixed ones once on ``/tf_static``; the
    sensor's driver publishes the reading. Header stamps are
    ``start_time_ns`` plus ``t``; each message is received 1 ms after its
    stamp.

    Parameters
    ----------
    path : str or Path
        A new folder (a ROS 2 bag); never overwritten.
    t : array_like, shape (N,)
        Sample times, s, increasing.
    wrench : array_like, shape (N, 6)
        The reading at every sample, ``(tx, ty, tz, fx, fy, fz)``, N m and N.
    links : sequence of (str, str, scipy.spatial.transform.Rotation, array_like)
        The moving links ``(parent, child, R, p)``: ``R`` (N rotations) and
        ``p`` (N, 3), m, the child's attitude and origin in the parent's frame
        at every sample.
    static : sequence of (str, str, scipy.spatial.transform.Rotation, array_like)
        The fixed links ``(parent, child, R, p)`` (one rotation, ``p`` (3,)).
    wrench_topic : str
    tf_every : int
        ``/tf`` is published at every ``tf_every``-th sample (from the first).
    start_time_ns : int
        Absolute time of ``t = 0``, ns.
    storage : str
        ``"sqlite3"`` or ``"mcap"``.

    Returns
    -------
    pathlib.Path
        The bag written.

    Raises
    ------
    BagError
        The path exists, the storage is neither, or the arrays' shapes do not match ``t``.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer      # optional (the ros extra)
    from rosbags.typesys import Stores, get_typestore      # optional (the ros extra): only bags need it

    path = Path(path)
    if path.exists():
        raise BagError(f"{path}: exists already; a bag is never overwritten")
    t = np.asarray(t, dtype=float)
    wrench = np.asarray(wrench, dtype=float)
    if t.ndim != 1 or wrench.shape != (len(t), 6):
        raise BagError(f"wrench must have shape (len(t), 6) = ({len(t)}, 6); got {wrench.shape}")
    for parent, child, R, p in links:
        if len(R) != len(t) or np.shape(p) != (len(t), 3):
            raise BagError(f"the moving link {parent} -> {child} needs {len(t)} rotations and positions of shape "
                           f"({len(t)}, 3); got {len(R)} and {np.shape(p)}")
    if not (isinstance(tf_every, (int, np.integer)) and tf_every >= 1):
        raise BagError(f"tf_every must be a positive integer; got {tf_every!r}")
    if storage not in ("sqlite3", "mcap"):
        raise BagError(f"storage must be sqlite3 or mcap; got {storage!r}")
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    V = T["geometry_msgs/msg/Vector3"]

    def transform(ns, parent, child, R, p):
        x, y, z, w = (float(v) for v in R.as_quat())
        return T["geometry_msgs/msg/TransformStamped"](
            header=_header(T, ns, parent), child_frame_id=child, transform=T["geometry_msgs/msg/Transform"](
                translation=V(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                rotation=T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)))

    def write(connection, ns, msg):
        writer.write(connection, ns + 1_000_000, ts.serialize_cdr(msg, msg.__msgtype__))

    TF = T["tf2_msgs/msg/TFMessage"]
    stamps = start_time_ns + np.round(t * 1e9).astype(np.int64)
    writer = (Writer(path, version=8) if storage == "sqlite3"            # the format this function has always written
              else Writer(path, version=9, storage_plugin=StoragePlugin.MCAP))
    with writer:
        wc = writer.add_connection(wrench_topic, WRENCH_TYPE, typestore=ts)
        tc = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=ts)
        if len(static):
            sc = writer.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", typestore=ts)
            write(sc, int(stamps[0]), TF(transforms=[transform(int(stamps[0]), *link) for link in static]))
        for k, ns in enumerate(int(s) for s in stamps):
            write(wc, ns, _wrench(T, _header(T, ns), wrench[k]))
            if k % tf_every == 0:
                write(tc, ns, TF(transforms=[transform(ns, parent, child, R[k], p[k])
                                             for parent, child, R, p in links]))
    return path
