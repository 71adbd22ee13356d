"""ROS bags in: plant.io._bag and fmscal import (bags written here with rosbags' own writers)."""

import json

import numpy as np
import pytest

from fmscal.analysis._calibrate import calibrate
from fmscal.analysis.cli import main
from fmscal.plant import FmscalError, get_scenario, read_log, read_truth
from fmscal.plant.io._bag import BagError, import_bag, read_bag
from fmscal.plant.io._bag_write import write_bag

WRENCH, POSE = "/ft_sensor/wrench", "/mocap/payload/pose"
OFFSET = (0.05, -0.02)          # marker origin from the centre of mass, body frame, m


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """A 15 s real-rig run (offset, 20 ms latency, poses at 50 Hz with 10 % dropped), as CSV and truth."""
    folder = tmp_path_factory.mktemp("rig")
    log, truth, x_true = get_scenario("real-rig").with_(duration=15.0).generate(3)
    log.write(folder / "rig.csv")
    truth.write(folder / "rig.truth.json")
    return folder, log, truth, x_true


@pytest.fixture(scope="module")
def E_csv(rig):
    """E of the least-squares calibration of the CSV log (the pose latency given)."""
    folder, _, truth, _ = rig
    return calibrate(read_log(folder / "rig.csv"), truth.payload, method="least-squares", truth=truth, latency=0.02).E


def _bag(folder, storage, pose_type, log, **kw):
    path = folder / (f"{storage}-{pose_type}" + (".bag" if storage == "ros1" else ""))
    if not path.exists():
        write_bag(log, path, storage, WRENCH, POSE, pose_type, receive_jitter=0.004, pose_offset=OFFSET,
                  seed=1, **kw)
    return path


@pytest.mark.parametrize("storage, pose_type", [("mcap", "PoseStamped"), ("sqlite3", "TransformStamped"),
                                                ("ros1", "Odometry")])
@pytest.mark.slow
def test_bag_calibrates_as_its_csv(rig, E_csv, storage, pose_type):
    folder, log, truth, _ = rig
    bag = _bag(folder, storage, pose_type, log)
    imported = read_bag(bag, WRENCH, POSE, pose_offset=OFFSET)
    csv = read_log(folder / "rig.csv")
    assert len(imported) == len(csv) and imported.has_pose.sum() == csv.has_pose.sum()
    np.testing.assert_allclose(imported.w_hat, csv.w_hat, rtol=0, atol=1e-12)
    E_bag = calibrate(imported, truth.payload, method="least-squares", truth=truth, latency=0.02).E
    assert 1e-4 < E_csv < 0.05                       # the CSV calibrates at all (and not suspiciously well)
    assert abs(E_bag - E_csv) <= 1e-3 * E_csv


def test_yaw_unwrapped_against_the_simulated_angle(rig):
    folder, log, _, x_true = rig
    bag = _bag(folder, "mcap", "PoseStamped", log)
    imported, report = import_bag(bag, WRENCH, POSE, pose_offset=OFFSET)
    rows = imported.has_pose
    wrapped = np.angle(np.exp(1j * log.pose[rows, 0]))
    assert np.sum(np.abs(np.diff(wrapped)) > np.pi) >= 2          # the quaternions' yaw wraps at least twice
    diff = imported.pose[rows, 0] - log.pose[rows, 0]
    turns = diff / (2 * np.pi)
    assert np.ptp(diff) < 1e-9 and abs(turns[0] - np.round(turns[0])) < 1e-9    # continuous, to whole turns
    np.testing.assert_allclose(imported.pose[rows, 1:], log.pose[rows, 1:], atol=1e-9)   # offset undone
    late = np.interp(log.t - 0.02, log.t, x_true[:, 0])[rows]                 # the rig's 20 ms pose latency
    assert np.max(np.abs(imported.pose[rows, 0] - diff[0] - late)) < 0.01    # 0.1 deg noise; wrapped: ~6
    assert report["pose"]["rate_hz"] == pytest.approx(50.0, rel=1e-6)
    assert report["wrench"]["rate_hz"] == pytest.approx(1000.0, rel=1e-6)
    expected_drops = int(np.sum(np.round(np.diff(log.t[rows]) / 0.02) - 1))
    assert report["pose"]["dropped"] == expected_drops > 0
    assert report["start_time_ns"] == 1_700_000_000_000_000_000 and report["warnings"] == []


def test_without_the_offset_the_position_is_the_marker(rig):
    folder, log, _, _ = rig
    imported = read_bag(_bag(folder, "mcap", "PoseStamped", log), WRENCH, POSE)
    rows = imported.has_pose
    shift = np.linalg.norm(imported.pose[rows, 1:] - log.pose[rows, 1:], axis=1)
    np.testing.assert_allclose(shift, np.hypot(*OFFSET), rtol=1e-9)


def test_pose_stamps_off_the_grid_are_snapped_and_reported(rig, tmp_path):
    _, log, _, _ = rig
    bag = write_bag(log.head(5000), tmp_path / "jitter", "mcap", WRENCH, POSE, pose_stamp_jitter=4e-4, seed=2)
    imported, report = import_bag(bag, WRENCH, POSE)
    assert 3e-4 < report["snap_error_max_s"] <= 4e-4 + 1e-9
    assert imported.has_pose.sum() == log.head(5000).has_pose.sum()


def test_dropped_wrench_messages_resampled_with_a_warning(rig, E_csv, tmp_path):
    folder, log, truth, _ = rig
    bag = write_bag(log, tmp_path / "drops", "sqlite3", WRENCH, POSE, wrench_drop_rate=0.01, seed=4)
    imported, report = import_bag(bag, WRENCH, POSE)
    missing = len(log) - report["wrench"]["messages"]
    assert 75 < missing < 225 and report["wrench"]["dropped"] == missing
    assert report["resampled"] is not None and any("resampled" in w for w in report["warnings"])
    assert len(imported) == len(log)
    E_bag = calibrate(imported, truth.payload, method="least-squares", truth=truth, latency=0.02).E
    assert 0.5 * E_csv < E_bag < 1.25 * E_csv                # resampling over 1 % of samples costs little


def test_window_cuts_the_log_and_moves_t0(rig):
    folder, log, _, _ = rig
    imported, report = import_bag(_bag(folder, "mcap", "PoseStamped", log), WRENCH, POSE, OFFSET, start=5.0, end=12.0)
    assert imported.t[0] == 0.0 and 6.9 < imported.duration <= 7.0
    assert 5.0 <= report["span_s"][0] < 5.1
    assert report["start_time_ns"] == 1_700_000_000_000_000_000 + round(report["span_s"][0] * 1e9)
    k = int(round(report["span_s"][0] / log.dt))
    np.testing.assert_allclose(imported.w_hat[:100], log.w_hat[k:k + 100], atol=1e-12)


def test_uneven_wrench_stamps_resampled_and_a_hole_refused():
    from fmscal.plant.io._bag import _even_grid
    rng = np.random.default_rng(0)
    t = np.arange(2000) * 1e-3 + rng.uniform(-5e-5, 5e-5, 2000)          # 5 % jitter
    w = np.column_stack([np.sin(t), np.cos(t), t])
    grid, w_grid, info = _even_grid(t, w, "x")
    assert info is not None and 0.05 < info["spread"] < 0.11
    assert np.ptp(np.diff(grid)) < 1e-12
    np.testing.assert_allclose(w_grid[:, 0], np.sin(grid), atol=1e-6)
    even, _, none = _even_grid(np.arange(100) * 1e-3, w[:100], "x")
    assert none is None
    with pytest.raises(BagError, match="hole"):
        _even_grid(np.delete(t, np.arange(500, 520)), np.delete(w, np.arange(500, 520), axis=0), "x")


def test_tilt_and_out_of_plane_travel_warned(rig, tmp_path):
    from fmscal.plant.io._bag import _planar_pose, _warnings
    n = 50
    tilt = np.deg2rad(5.0)                                  # about x
    q = np.tile([np.sin(tilt / 2), 0.0, 0.0, np.cos(tilt / 2)], (n, 1))
    p = np.column_stack([np.zeros(n), np.zeros(n), np.linspace(0, 0.03, n), q])
    _, _, tilt_out, z = _planar_pose(p, (0.0, 0.0))
    assert np.degrees(tilt_out.max()) == pytest.approx(5.0, rel=1e-9)
    report = {"tilt_max_deg": 5.0, "out_of_plane_m": float(np.ptp(z)), "resampled": None, "poses_merged": 0}
    assert len(_warnings(report)) == 2
    report.update(tilt_max_deg=1.0, out_of_plane_m=0.001)
    assert _warnings(report) == []


@pytest.mark.slow
def test_import_and_calibrate_on_the_command_line(rig, tmp_path, capsys):
    folder, log, _, _ = rig
    bag = _bag(folder, "mcap", "PoseStamped", log)
    out = tmp_path / "imported.csv"
    args = ["import", str(bag), "--wrench-topic", WRENCH, "--pose-topic", POSE, "--out", str(out),
            "--pose-offset", *map(str, OFFSET)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "50 Hz" in printed and "1000 Hz" in printed and "dropped" in printed
    sidecar = json.loads(out.with_suffix(".import.json").read_text())
    assert sidecar["pose_offset"] == list(OFFSET) and sidecar["samples"] == len(log)
    assert main(args) == 2                                       # never overwritten silently
    assert "--overwrite" in capsys.readouterr().err
    assert main(args + ["--overwrite"]) == 0
    capsys.readouterr()
    E = {}
    for name, path in (("bag", out), ("csv", folder / "rig.csv")):
        p = read_truth(folder / "rig.truth.json").payload
        assert main(["calibrate", str(path), "--mass", str(p.mass), "--inertia", str(p.inertia),
                     "--rho", *map(str, p.rho), "--truth", str(folder / "rig.truth.json"), "--latency", "0.02",
                     "--json"]) == 0
        E[name] = json.loads(capsys.readouterr().out)["E"]
    assert 0 < E["csv"] < 0.05 and E["bag"] == pytest.approx(E["csv"], rel=1e-3)


def _refused(args, capsys):
    assert main(args) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in captured.err and lines[0].startswith("fmscal import: error:")
    return lines[0]


def test_missing_topic_wrong_type_and_not_a_bag_refused(rig, tmp_path, capsys):
    folder, log, _, _ = rig
    bag = str(_bag(folder, "ros1", "Odometry", log))
    out = str(tmp_path / "x.csv")
    line = _refused(["import", bag, "--wrench-topic", "/wrench", "--pose-topic", POSE, "--out", out], capsys)
    assert "'/wrench'" in line and WRENCH in line and POSE in line              # the topics present
    line = _refused(["import", bag, "--wrench-topic", POSE, "--pose-topic", WRENCH, "--out", out], capsys)
    assert "nav_msgs/msg/Odometry" in line and "expected geometry_msgs/msg/WrenchStamped" in line
    line = _refused(["import", bag, "--wrench-topic", WRENCH, "--pose-topic", WRENCH, "--out", out], capsys)
    assert "WrenchStamped" in line and "PoseStamped" in line
    whole = next(_bag(folder, "mcap", "PoseStamped", log).glob("*.mcap")).read_bytes()
    for name, content in (("fake.bag", b"not a bag\n"), ("fake.mcap", b"\x00" * 64), ("fake.db3", b"hello"),
                          ("fake.txt", b"t,theta\n"), ("cut.mcap", whole[:len(whole) // 2])):
        (tmp_path / name).write_bytes(content)
        line = _refused(["import", str(tmp_path / name), "--wrench-topic", WRENCH, "--pose-topic", POSE,
                         "--out", out], capsys)
        assert "not a" in line and "ROS" in line and name in line
    (tmp_path / "folder").mkdir()
    assert "not a ROS 2 bag folder" in _refused(["import", str(tmp_path / "folder"), "--wrench-topic", WRENCH,
                                                 "--pose-topic", POSE, "--out", out], capsys)
    assert not (tmp_path / "x.csv").exists()


def test_never_writes_into_the_bag(rig, capsys):
    folder, log, _, _ = rig
    bag = _bag(folder, "mcap", "PoseStamped", log)
    _refused(["import", str(bag), "--wrench-topic", WRENCH, "--pose-topic", POSE, "--out", str(bag / "x.csv")],
             capsys)


def test_bad_arguments_are_fmscal_errors(rig):
    folder, log, _, _ = rig
    bag = _bag(folder, "mcap", "PoseStamped", log)
    with pytest.raises(FmscalError, match="pose_offset"):
        read_bag(bag, WRENCH, POSE, pose_offset=(0.1,))
    with pytest.raises(FmscalError, match="end must be after start"):
        read_bag(bag, WRENCH, POSE, start=5, end=2)
    with pytest.raises(FmscalError, match="window"):
        read_bag(bag, WRENCH, POSE, start=50, end=60)


@pytest.mark.parametrize("back_ms", [1, 5, 9])
def test_a_clock_that_steps_back_a_few_ms_is_counted_and_warned(back_ms):
    # issue 37: a wrench clock stepping back 1-9 ms sorted silently into "1 duplicate stamps"
    from fmscal.plant.io._bag import _stream, _warnings
    step = 1_000_000                                            # 1 kHz, in ns
    t0 = 1_700_000_000_000_000_000
    stamps = [t0 + k * step for k in range(1000)]
    stamps = stamps[:500] + [s - back_ms * step for s in stamps[500:]]     # the clock steps back at message 501
    messages = [(s, [0.0] * 6) for s in stamps]
    _, _, _, info = _stream(messages, "wrench", "rig.bag")
    assert info["overlapping_stamps"] == back_ms and info["first_overlap_ns"] == t0 + 500 * step - back_ms * step
    reordered = stamps[:500] + [stamps[501], stamps[500]] + stamps[502:]    # transport reordering alone: no overlap
    assert _stream([(s, [0.0] * 6) for s in sorted(set(reordered))], "wrench", "rig.bag")[3]["overlapping_stamps"] == 0
    report = {"spatial": True, "resampled": None, "poses_merged": 0, "wrench": info,
              "pose": {"overlapping_stamps": 0}}
    (warning,) = _warnings(report)
    assert warning.startswith(f"the wrench stamps overlap: {back_ms} fall within half a step of another")
    assert info["step_back_ns"] == back_ms * step and info["step_back_at_ns"] == t0 + (500 - back_ms) * step
    assert f"the clock steps back by {back_ms:g} ms at" in warning
