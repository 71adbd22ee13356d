"""fmscal import --spatial: a 6-axis sensor's bag into a spatial log (issue 22)."""

import json

import numpy as np
import pytest

pytest.importorskip("rosbags")          # the [ros] extra; README's test command installs it (on CI a skip fails)

from fmscal.analysis.cli import main                            # noqa: E402
from fmscal.plant import read_log                               # noqa: E402
from fmscal.plant.io._bag import import_bag                         # noqa: E402
from fmscal.plant.io._bag_write import write_bag                    # noqa: E402
from fmscal.plant.scenarios._spatial import SPATIAL_SCENARIOS   # noqa: E402

OFFSET = (0.01, -0.02, 0.05)            # the tracked frame's origin from the sensor point, sensor axes, m


@pytest.fixture(scope="module")
def mocap(tmp_path_factory):
    log, _, _ = SPATIAL_SCENARIOS["spatial-mocap"].with_(duration=4.0).generate(1)
    folder = tmp_path_factory.mktemp("spatial_bag")
    write_bag(log, folder / "run", pose_type="TransformStamped", pose_offset=OFFSET)
    return log, folder


def test_the_whole_pose_and_six_components_come_back(mocap):
    log, folder = mocap
    back, report = import_bag(folder / "run", "/ft_sensor/wrench", "/mocap/payload/pose", OFFSET, spatial=True)
    assert back.kind == "spatial" and report["spatial"] and not report["rms_ignored"]
    np.testing.assert_array_equal(back.w_hat, log.w_hat)
    np.testing.assert_array_equal(back.has_pose, log.has_pose)
    np.testing.assert_allclose(back.pose[back.has_pose], log.pose[log.has_pose], rtol=0, atol=1e-12)


def test_without_the_offset_the_position_is_the_tracked_frames(mocap):
    log, folder = mocap
    back, _ = import_bag(folder / "run", "/ft_sensor/wrench", "/mocap/payload/pose", (0, 0, 0), spatial=True)
    moved = np.linalg.norm(back.pose[back.has_pose, 4:] - log.pose[log.has_pose, 4:], axis=1)
    np.testing.assert_allclose(moved, np.linalg.norm(OFFSET), rtol=1e-9)       # the offset, turned with the body


def test_the_command_writes_a_spatial_log(mocap, tmp_path, capsys):
    _, folder = mocap
    args = ["import", str(folder / "run"), "--wrench-topic", "/ft_sensor/wrench", "--pose-topic",
            "/mocap/payload/pose", "--spatial", "--out", str(tmp_path / "log.csv")]
    assert main([*args, "--pose-offset", *map(str, OFFSET)]) == 0
    assert read_log(tmp_path / "log.csv").kind == "spatial"
    assert main([*args[:-1], str(tmp_path / "two.csv"), "--pose-offset", "0", "0.1"]) == 2
    assert "--pose-offset must be 3 finite numbers in m with --spatial" in capsys.readouterr().err


def test_the_wrench_frame_id_is_recorded(mocap, tmp_path, capsys):
    """The wrench's header.frame_id in the report, the sidecar and the printed report (for the node's
    sensor_frame); several frames among the messages: a warning naming each with its count, the most common kept."""
    log, _ = mocap
    write_bag(log, tmp_path / "one", wrench_frame_id="ft_sensor")
    frames = ["ft_sensor"] * len(log.t)
    frames[10:13] = ["tool0"] * 3
    write_bag(log, tmp_path / "two", wrench_frame_id=frames)
    _, report = import_bag(tmp_path / "one", "/ft_sensor/wrench", "/mocap/payload/pose", (0, 0, 0), spatial=True)
    assert report["wrench"]["frame_id"] == "ft_sensor" and report["wrench"]["frame_ids"] == {"ft_sensor": len(log.t)}
    assert not report["warnings"]
    _, mixed = import_bag(tmp_path / "two", "/ft_sensor/wrench", "/mocap/payload/pose", (0, 0, 0), spatial=True)
    assert mixed["wrench"]["frame_id"] == "ft_sensor"
    assert mixed["warnings"] == [f"the wrench messages name 2 frames: ft_sensor ({len(log.t) - 3}), tool0 (3); the "
                                 "most common, ft_sensor, is recorded as the sensor's"]
    out = tmp_path / "log.csv"
    assert main(["import", str(tmp_path / "one"), "--wrench-topic", "/ft_sensor/wrench", "--pose-topic",
                 "/mocap/payload/pose", "--spatial", "--out", str(out)]) == 0
    assert "frame_id 'ft_sensor' (the node's sensor_frame)" in capsys.readouterr().out
    assert json.loads(out.with_suffix(".import.json").read_text())["wrench"]["frame_id"] == "ft_sensor"
