"""Poses from joint angles by pinocchio's forward kinematics, on a real robot's URDF (issue 28)."""

import json
import os

import numpy as np
import pytest

from fmscal.analysis.cli import main
from fmscal.plant import FmscalError
from fmscal.plant.io._kinematics import RobotKinematics, joint_columns
from fmscal.plant.io._pose_table import simulate_table
from fmscal.plant.physics._rigid_body import rotation_matrix
from fmscal.plant.scenarios._spatial import TOOL
from robot_rig import ur5_urdf

OFFSET = np.array([0.01, -0.02, 0.03, 0.5, -0.3, 0.2])


@pytest.fixture(scope="module")
def ur5():
    return RobotKinematics(ur5_urdf(), "tool0")


def test_the_pose_is_pinocchios_frame_placement_in_the_logs_order(ur5):
    """The quaternion (scalar first) turns the same way as pinocchio's rotation; the position is its translation."""
    import pinocchio as pin
    rng = np.random.default_rng(0)
    joints = rng.uniform(-np.pi, np.pi, (5, 6))
    poses = ur5.poses(joints)
    data = ur5.model.createData()
    for q, pose in zip(joints, poses):
        pin.framesForwardKinematics(ur5.model, data, q)
        placement = data.oMf[ur5.frame_id]
        np.testing.assert_allclose(np.asarray(rotation_matrix(pose[:4])), placement.rotation, atol=1e-12)
        np.testing.assert_allclose(pose[4:], placement.translation, atol=1e-12)
        assert abs(np.linalg.norm(pose[:4]) - 1) < 1e-12
    assert ur5.joint_names[0] == "shoulder_pan_joint" and len(ur5.joint_names) == 6


def test_a_table_of_joint_angles_gives_the_payload(ur5, tmp_path, capsys):
    rng = np.random.default_rng(1)
    joints = rng.uniform(-np.pi, np.pi, (16, 6))
    table = simulate_table(TOOL, n=16, seed=1, offset=OFFSET, q=ur5.poses(joints)[:, :4])
    for names in ([f"q{i + 1}" for i in range(6)], list(ur5.joint_names)):
        path = tmp_path / "joints.csv"
        rows = np.hstack([joints, table.w_hat])
        path.write_text(",".join([*names, "tx", "ty", "tz", "fx", "fy", "fz"]) + "\n"
                        + "\n".join(",".join(f"{v:.17g}" for v in row) for row in rows) + "\n")
        assert main(["identify-payload", str(path), "--urdf", str(ur5_urdf()), "--frame", "tool0", "--json"]) == 0
        fit = json.loads(capsys.readouterr().out)
        assert abs(fit["mass"] - TOOL.mass) < 0.01 * TOOL.mass
        assert np.abs(np.array(fit["com"]) - TOOL.com).max() < 2e-3 and fit["converged"]


def test_a_frame_the_urdf_lacks_and_joints_that_do_not_match_are_one_line(tmp_path, capsys):
    with pytest.raises(FmscalError, match="has no frame 'sensor'"):
        RobotKinematics(ur5_urdf(), "sensor")
    with pytest.raises(FmscalError, match="do not match the URDF's 6 joints: name them q1,q2"):
        joint_columns(["t", "a", "b", "tx", "ty", "tz", "fx", "fy", "fz"], [f"j{i}" for i in range(6)])
    path = tmp_path / "five.csv"
    path.write_text("q1,q2,q3,q4,q5,tx,ty,tz,fx,fy,fz\n" + "0,0,0,0,0,0,0,0,0,0,1\n" * 5)
    assert main(["identify-payload", str(path), "--urdf", str(ur5_urdf()), "--frame", "tool0"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "do not match the URDF's 6 joints" in err
    assert main(["identify-payload", str(path), "--urdf", str(ur5_urdf())]) == 2
    assert "--urdf and --frame go together" in capsys.readouterr().err


def test_a_bag_of_joint_states_imports_as_a_spatial_log(ur5, tmp_path, capsys):
    """An arm's bag: WrenchStamped and sensor_msgs/JointState; with the URDF the import writes the sensor frame's
    poses (pinocchio's forward kinematics of the joints, by name, in any order in the message)."""
    from fmscal.plant import Log, read_log
    from fmscal.plant.io._bag_write import write_bag
    t = np.arange(0.0, 2.0, 0.005)
    joints = 0.5 * np.sin(np.outer(t, [0.7, 1.1, 0.9, 1.3, 0.5, 1.7]) + np.arange(6))
    poses = ur5.poses(joints)
    log = Log(t, poses, np.tile(OFFSET, (len(t), 1)), name="arm")
    order = [5, 0, 3, 1, 4, 2]                                  # the message names the joints in its own order
    bag = write_bag(log, tmp_path / "arm_bag", pose_type="JointState", pose_topic="/joint_states",
                    joints=joints[:, order], joint_names=[ur5.joint_names[i] for i in order])
    out = tmp_path / "arm.csv"
    assert main(["import", str(bag), "--wrench-topic", "/ft_sensor/wrench", "--pose-topic", "/joint_states",
                 "--urdf", str(ur5_urdf()), "--frame", "tool0", "--out", str(out)]) == 0
    back = read_log(out)
    assert back.kind == "spatial" and len(back) == len(t)
    np.testing.assert_allclose(back.pose, poses, atol=1e-9)
    np.testing.assert_allclose(back.w_hat, log.w_hat, atol=1e-12)
    capsys.readouterr()
    assert main(["import", str(bag), "--wrench-topic", "/ft_sensor/wrench", "--pose-topic", "/joint_states",
                 "--urdf", str(ur5_urdf()), "--frame", "tool0", "--out", str(tmp_path / "again.csv"),
                 "--pose-offset", "0", "0", "0"]) == 2
    assert "--pose-offset is not taken with --urdf" in capsys.readouterr().err


def test_joint_columns_beyond_the_urdfs_and_a_missing_urdf_are_one_line(tmp_path, capsys):
    """q1..q7 against the UR5's six joints: refused (never q7 dropped); a URDF that is not there: said so."""
    with pytest.raises(FmscalError, match=r"7 joint columns \(q7 beyond q1\.\.q6\); the URDF has 6 joints"):
        joint_columns(["q1", "q2", "q3", "q4", "q5", "q6", "q7", "tx", "ty", "tz", "fx", "fy", "fz"],
                      [f"j{i}" for i in range(6)])
    assert joint_columns(["t", *(f"q{i}" for i in range(1, 7)), "tx", "ty", "tz", "fx", "fy", "fz"],
                         [f"j{i}" for i in range(6)]) == [f"q{i}" for i in range(1, 7)]
    path = tmp_path / "seven.csv"
    path.write_text("q1,q2,q3,q4,q5,q6,q7,tx,ty,tz,fx,fy,fz\n" + "0.1,0.2,0.3,0.4,0.5,0.6,0,0,0,0,0,0,1\n" * 5)
    for command in ("identify-payload", "calibrate"):
        extra = ["--mass", "1.2", "--com", "0", "0", "0.05"] if command == "calibrate" else []
        assert main([command, str(path), "--urdf", str(ur5_urdf()), "--frame", "tool0", *extra]) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and "7 joint columns" in err and "6 joints" in err, err
    assert main(["identify-payload", str(path), "--urdf", str(tmp_path / "robot.urdf"), "--frame", "tool0"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "robot.urdf" in err and ": no such file" in err
    assert "not a URDF" not in err


def test_calibrate_takes_a_table_of_joint_angles(ur5, tmp_path, capsys):
    """The poses from the joints as identify-payload takes them: calibrate reports the table's offset, and
    --urdf without --frame is one line."""
    rng = np.random.default_rng(2)
    joints = rng.uniform(-np.pi, np.pi, (16, 6))
    table = simulate_table(TOOL, n=16, seed=2, offset=OFFSET, q=ur5.poses(joints)[:, :4])
    path = tmp_path / "joints.csv"
    path.write_text("q1,q2,q3,q4,q5,q6,tx,ty,tz,fx,fy,fz\n"
                    + "\n".join(",".join(f"{v:.17g}" for v in row) for row in np.hstack([joints, table.w_hat])) + "\n")
    payload = ["--mass", repr(TOOL.mass), "--com", *map(repr, TOOL.com)]
    assert main(["calibrate", str(path), "--urdf", str(ur5_urdf()), "--frame", "tool0", *payload, "--json"]) == 0
    captured = capsys.readouterr()
    report = json.loads(captured.out)
    assert report["kind"] == "table" and report["poses"] == 16 and not report["converged"]
    b, b_std = np.array(report["b"]), np.array(report["b_std"])
    assert np.all(np.abs(b - OFFSET) < 4 * b_std) and np.all(b_std < 0.05)
    assert main(["calibrate", str(path), "--urdf", str(ur5_urdf()), *payload]) == 2
    assert "--urdf and --frame go together" in capsys.readouterr().err


def test_a_malformed_urdf_is_our_one_line_and_nothing_from_urdfdom(tmp_path, capfd):
    """urdfdom prints two C-level lines to file descriptor 2 on a malformed URDF; the command's stderr holds only its
    own line, and file descriptor 2 works after it."""
    bad = tmp_path / "bad.urdf"
    bad.write_text('<robot name="x"><link name="a"></robot>\n')
    path = tmp_path / "joints.csv"
    path.write_text("q1,q2,tx,ty,tz,fx,fy,fz\n" + "0.1,0.2,0,0,0,0,0,1\n" * 5)
    capfd.readouterr()
    assert main(["identify-payload", str(path), "--urdf", str(bad), "--frame", "tool0"]) == 2
    err = capfd.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "not a URDF pinocchio can read" in err, err
    assert "XML_ERROR" not in err and "model.cpp" not in err
    os.write(2, b"after\n")
    assert capfd.readouterr().err == "after\n"
