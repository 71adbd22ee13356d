"""``fmscal import --parent FRAME --frame FRAME``: the sensor's pose from a bag's /tf and /tf_static (issue 28)."""

import numpy as np
import pytest

from fmscal.analysis.cli import main
from fmscal.plant import read_log
from fmscal.plant.io._bag_write import write_tf_bag
from fmscal.plant.physics._rigid_body import rotation_matrix
from scipy.spatial.transform import Rotation

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
    write_tf_bag(tmp_path / "arm_bag", t, wrench, links, static, tf_every=2)
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
