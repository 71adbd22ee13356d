"""A frame's pose from a robot's transform tree (``/tf`` and ``/tf_static``): the chain, composed.

An arm's bag rarely holds the sensor's pose as one topic: it holds the tree
of transforms ``robot_state_publisher`` and the drivers broadcast, each
``geometry_msgs/TransformStamped`` from a parent frame to a child. The
sensor frame's pose in a chosen parent frame (the robot's base, say) is the
product of the transforms down the chain from the parent to it::

    T_parent_sensor = T_parent_a T_a_b ... T_y_sensor

The fixed links (``/tf_static``) are taken once; the moving ones (``/tf``)
are each a time series. The pose is composed at the stamps of the chain's
first moving link, the other moving links interpolated there (linearly in
position, by spherical interpolation in attitude), within their span.
"""

import numpy as np

from fmscal.plant.numerics import FmscalError

__all__ = ["chain_poses"]


def _matrix(transform):
    """A ``geometry_msgs/Transform`` as ``(R, p)``."""
    from scipy.spatial.transform import Rotation
    r, t = transform.rotation, transform.translation
    norm = np.sqrt(r.x ** 2 + r.y ** 2 + r.z ** 2 + r.w ** 2)
    if not norm > 1e-6:
        raise FmscalError("a transform has a zero quaternion")
    return Rotation.from_quat([r.x / norm, r.y / norm, r.z / norm, r.w / norm]), np.array([t.x, t.y, t.z])


def _edges(messages):
    """``{child: (parent, [(stamp ns, Rotation, p)])}`` of every transform in ``messages``."""
    edges = {}
    for msg in messages:
        for tf in msg.transforms:
            stamp = int(tf.header.stamp.sec) * 1_000_000_000 + int(tf.header.stamp.nanosec)
            parent, child = tf.header.frame_id.lstrip("/"), tf.child_frame_id.lstrip("/")
            R, p = _matrix(tf.transform)
            known = edges.setdefault(child, (parent, []))
            if known[0] != parent:
                raise FmscalError(f"the frame {child!r} has two parents in the transform tree ({known[0]!r} and "
                                  f"{parent!r})")
            known[1].append((stamp, R, p))
    return edges


def _chain(parent, frame, edges, name):
    """The links from ``parent`` down to ``frame``: a list of children, parent side first."""
    links, at, seen = [], frame, set()
    while at != parent:
        if at not in edges or at in seen:
            root = at
            raise FmscalError(f"{name}: no chain of transforms from {parent!r} to {frame!r} (it goes up to {root!r}); "
                              f"the tree's frames are {', '.join(sorted({*edges, *(p for p, _ in edges.values())}))}")
        seen.add(at)
        links.append(at)
        at = edges[at][0]
    return links[::-1]


def chain_poses(dynamic, static, parent, frame, name="bag"):
    """The pose of ``frame`` in ``parent`` at the stamps of the chain's first moving link.

    Parameters
    ----------
    dynamic, static : list of tf2_msgs/TFMessage
        The messages of ``/tf`` and of ``/tf_static``.
    parent, frame : str
        The frames (ROS names, a leading ``/`` ignored).
    name : str
        The bag's name, for the messages.

    Returns
    -------
    list of (int, tuple)
        ``(stamp ns, (x, y, z, qx, qy, qz, qw))`` of ``frame`` in ``parent``.

    Raises
    ------
    FmscalError
        No chain from ``parent`` to ``frame``, a frame with two parents, or a
        chain that never moves.
    """
    from scipy.spatial.transform import Rotation, Slerp
    parent, frame = parent.lstrip("/"), frame.lstrip("/")
    fixed = {child: (p, series[-1]) for child, (p, series) in _edges(static).items()}
    moving = {child: (p, sorted(series, key=lambda s: s[0])) for child, (p, series) in _edges(dynamic).items()}
    edges = {**{c: (p, [s]) for c, (p, s) in fixed.items()}, **moving}
    links = _chain(parent, frame, edges, name)
    movers = [c for c in links if c in moving]
    if not movers:
        raise FmscalError(f"{name}: the chain from {parent!r} to {frame!r} never moves (all of it on /tf_static)")
    stamps = np.array(sorted({s for s, _, _ in moving[movers[0]][1]}), dtype=np.int64)
    for c in movers[1:]:
        own = np.array([s for s, _, _ in moving[c][1]])
        stamps = stamps[(stamps >= own[0]) & (stamps <= own[-1])]
    if len(stamps) < 2:
        raise FmscalError(f"{name}: the moving links of the chain from {parent!r} to {frame!r} share no span of time")
    R = Rotation.identity(len(stamps))
    p = np.zeros((len(stamps), 3))
    for c in links:
        if c in moving:
            series = moving[c][1]
            own = np.array([s for s, _, _ in series], dtype=np.int64)
            keep = np.concatenate([[True], np.diff(own) > 0])
            times = (own[keep] - stamps[0]) * 1e-9
            at = (stamps - stamps[0]) * 1e-9
            rotations = Rotation.concatenate([r for (_, r, _), k in zip(series, keep) if k])
            R_link = Slerp(times, rotations)(at) if len(times) > 1 else Rotation.concatenate([rotations] * len(at))
            positions = np.array([q for (_, _, q), k in zip(series, keep) if k])
            p_link = np.column_stack([np.interp(at, times, positions[:, j]) for j in range(3)])
        else:
            _, (_, r, q) = fixed[c]
            R_link, p_link = Rotation.concatenate([r] * len(stamps)), np.tile(q, (len(stamps), 1))
        p = p + R.apply(p_link)
        R = R * R_link
    quat = R.as_quat()                                              # x, y, z, w
    return [(int(s), (*p[k], *quat[k])) for k, s in enumerate(stamps)]
