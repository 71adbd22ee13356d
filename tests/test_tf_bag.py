"""``fmscal import --parent FRAME --frame FRAME``: the sensor's pose from a bag's /tf and /tf_static (issue 28)."""

import numpy as np
import pytest

from fmscal.analysis.cli import main
from fmscal.plant import read_log
from fmscal.plant.rigid_body import rotation_matrix
from scipy.spatial.transform import Rotation

START = 1_700_000_000_000_000_000


def _write(path, t, wrench, links, static):
    """A ROS 2 bag: WrenchStamped at every t; /tf with each moving link ``(parent, child, R (N,), p (N, 3))`` at
    every other t; /tf_static once with the fixed links ``(parent, child, R, p)``."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Time, Header, V = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"], T["geometry_msgs/msg/Vector3"]

    def header(ns, frame="world"):
        return Header(stamp=Time(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000)), frame_id=frame)

    def tf(ns, parent, child, R, p):
        x, y, z, w = R.as_quat()
        return T["geometry_msgs/msg/TransformStamped"](
            header=header(ns, parent), child_frame_id=child, transform=T["geometry_msgs/msg/Transform"](
                translation=V(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                rotation=T["geometry_msgs/msg/Quaternion"](x=float(x), y=float(y), z=float(z), w=float(w))))

    with Writer(path, version=8) as writer:
        wc = writer.add_connection("/ft_sensor/wrench", "geometry_msgs/msg/WrenchStamped", typestore=ts)
        tc = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=ts)
        sc = writer.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", typestore=ts)
        msg = T["tf2_msgs/msg/TFMessage"](transforms=[tf(START, *link) for link in static])
        writer.write(sc, START, ts.serialize_cdr(msg, msg.__msgtype__))
        for k, s in enumerate(t):
            ns = START + int(round(s * 1e9))
            w = wrench[k]
            msg = T["geometry_msgs/msg/WrenchStamped"](header=header(ns), wrench=T["geometry_msgs/msg/Wrench"](
                force=V(x=w[3], y=w[4], z=w[5]), torque=V(x=w[0], y=w[1], z=w[2])))
            writer.write(wc, ns + 1_000_000, ts.serialize_cdr(msg, msg.__msgtype__))
            if k % 2 == 0:
                msg = T["tf2_msgs/msg/TFMessage"](transforms=[tf(ns, parent, child, R[k], p[k])
                                                              for parent, child, R, p in links])
                writer.write(tc, ns + 1_000_000, ts.serialize_cdr(msg, msg.__msgtype__))


def test_the_chain_from_the_base_to_the_sensor_is_composed(tmp_path, capsys):
    t = np.arange(0.0, 2.0, 0.002)
    rng = np.random.default_rng(0)
    wrench = rng.normal(size=(len(t), 6))
    shoulder = Rotation.from_rotvec(np.outer(np.sin(2 * t), [0, 0, 1.0]))
    elbow = Rotation.from_rotvec(np.outer(0.5 * np.cos(3 * t), [0, 1.0, 0]))
    links = [("base", "shoulder", shoulder, np.tile([0, 0, 0.3], (len(t), 1))),
             ("shoulder", "forearm", elbow, np.column_stack([0.4 + 0.01 * t, 0 * t, 0 * t]))]
    mount = Rotation.from_rotvec([0.1, 0.0, 0.2])
    static = [("forearm", "flange", Rotation.identity(), [0.35, 0.0, 0.0]), ("flange", "ft_sensor", mount,
                                                                             [0.0, 0.0, 0.05])]
    _write(tmp_path / "arm_bag", t, wrench, links, static)
    out = tmp_path / "arm.csv"
    args = ["import", str(tmp_path / "arm_bag"), "--wrench-topic", "/ft_sensor/wrench", "--pose-topic", "/tf",
            "--parent", "base", "--frame", "ft_sensor", "--out", str(out)]
    assert main(args) == 0, capsys.readouterr().err
    log = read_log(out)
    assert log.kind == "spatial" and log.has_pose.sum() == pytest.approx(len(t) / 2, abs=2)
    # the chain by hand at every pose
    rows = np.flatnonzero(log.has_pose)
    k = np.round(log.t[rows] / 0.002).astype(int)
    R = shoulder[k] * elbow[k] * mount
    p = (np.array([0, 0, 0.3]) + shoulder[k].apply(np.column_stack([0.4 + 0.01 * t[k], 0 * k, 0 * k])
                                                    + elbow[k].apply([0.35, 0, 0])
                                                    + (elbow[k] * Rotation.identity()).apply([0, 0, 0.05])))
    for j, row in enumerate(rows[:50]):
        np.testing.assert_allclose(np.asarray(rotation_matrix(log.pose[row, :4])), R[j].as_matrix(), atol=1e-9)
    np.testing.assert_allclose(log.pose[rows, 4:], p, atol=1e-9)
    capsys.readouterr()
    bad = [*args[:-4], "--parent", "world", "--frame", "ft_sensor", "--out", str(tmp_path / "b.csv")]
    assert main(bad) == 2
    err = capsys.readouterr().err
    assert "no chain of transforms from 'world' to 'ft_sensor'" in err and len(err.strip().splitlines()) == 1
