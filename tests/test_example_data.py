"""The example data in ``examples/`` is what ``examples/make.py`` writes, small, and read by the commands.

The script is run into a temporary folder and each checked-in file compared with its output: the
CSV files and truth sidecars number by number (to the script's rounding, 1e-6, so that a last-digit
difference of another platform's floating point passes and a changed simulation does not), the bags
message by message (topic, stamp and serialized bytes).
"""

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from fmscal.analysis.cli import main

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
#: What the script writes: the text files and the bags.
TEXT = ("arm.csv", "arm.truth.json", "table.csv", "table.truth.json", "joints.csv", "joint_log.csv", "imu_log.csv")
BAGS = ("arm_bag", "run_bag")


def _make_module():
    spec = importlib.util.spec_from_file_location("examples_make", EXAMPLES / "make.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    pytest.importorskip("rosbags")
    pytest.importorskip("pinocchio")
    out = tmp_path_factory.mktemp("examples")
    _make_module().make(out)
    return out


def _csv(path):
    lines = path.read_text().splitlines()
    return lines[0], np.array([[float(v) if v else np.nan for v in line.split(",")] for line in lines[1:]])


def _close(a, b, where):
    """JSON values ``a`` and ``b`` equal, numbers to 1e-9 (relative) or 1e-12."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), where
        for key in a:
            _close(a[key], b[key], f"{where}.{key}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _close(x, y, f"{where}[{i}]")
    elif isinstance(a, float) and not isinstance(b, bool):
        assert np.isclose(a, b, rtol=1e-9, atol=1e-12), f"{where}: {a} != {b}"
    else:
        assert a == b, where


def _messages(bag):
    from rosbags.rosbag2 import Reader
    with Reader(bag) as reader:
        return [(c.topic, c.msgtype, ts, bytes(raw)) for c, ts, raw in reader.messages()]


@pytest.mark.parametrize("name", TEXT)
def test_the_script_reproduces_each_file(made, name):
    ours, theirs = EXAMPLES / name, made / name
    if name.endswith(".csv"):
        (head_a, a), (head_b, b) = _csv(ours), _csv(theirs)
        assert head_a == head_b and a.shape == b.shape
        np.testing.assert_allclose(a, b, rtol=0, atol=1.5e-6, err_msg=name)   # one unit of the rounding at most
    else:
        _close(json.loads(ours.read_text()), json.loads(theirs.read_text()), name)


@pytest.mark.parametrize("name", BAGS)
def test_the_script_reproduces_each_bag(made, name):
    ours, theirs = _messages(EXAMPLES / name), _messages(made / name)
    assert len(ours) > 100 and [m[:3] for m in ours] == [m[:3] for m in theirs]
    assert [m[3] for m in ours] == [m[3] for m in theirs]


def test_the_examples_are_small_and_nothing_else_is_there():
    files = [p for p in EXAMPLES.rglob("*") if p.is_file() and "__pycache__" not in p.parts]
    sizes = {p.relative_to(EXAMPLES).as_posix(): p.stat().st_size for p in files}
    assert sum(sizes.values()) < 450_000 and max(sizes.values()) < 150_000, sizes
    expected = {*TEXT, "make.py", "README.md", "arm6.urdf", "arm_bag/metadata.yaml", "arm_bag/arm_bag.mcap",
                "run_bag/metadata.yaml", "run_bag/run_bag.mcap"}
    assert set(sizes) == expected


def test_the_table_is_what_fmscal_simulate_writes(tmp_path, capsys):
    out = tmp_path / "table.csv"
    assert main(["simulate", "--scenario", "spatial-arm", "--poses", "12", "--seed", "0", "--out", str(out)]) == 0
    (head_a, a), (head_b, b) = _csv(EXAMPLES / "table.csv"), _csv(out)
    assert head_a == head_b
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


def test_the_log_and_the_urdf_read_as_their_guides_say():
    from fmscal.analysis import read_data
    from fmscal.plant.io import PoseTable
    log = read_data(EXAMPLES / "arm.csv")
    assert log.kind == "spatial" and len(log) == 301 and abs(log.duration - 12.0) < 1e-9
    joints = read_data(EXAMPLES / "joints.csv", urdf=EXAMPLES / "arm6.urdf", frame="ft_sensor")
    assert isinstance(joints, PoseTable) and len(joints) == 16


def test_the_runs_compensate_to_the_noise_and_show_the_push():
    # joint_log.csv and imu_log.csv are arm.csv's sensor and tool on arm6.urdf: compensated with the truth (S, offset,
    # payload), what is left away from the push is the reading's noise, and the push is there, all of it.
    from fmscal.analysis import ImuMotion, JointMotion, compensate
    from fmscal.plant import Calibration, read_truth
    from fmscal.plant.io import read_imu_log, read_joint_log
    made = _make_module()
    truth = read_truth(EXAMPLES / "arm.truth.json")
    calibration = Calibration(S=truth.S_at(0.0), payload=truth.payload, method="truth", b=truth.offset,
                              gravity=made.ARM.gravity, latency=0.0, noise=truth.noise)
    arm = JointMotion(EXAMPLES / "arm6.urdf", "ft_sensor")
    imu = ImuMotion(rotation=[[0, -1, 0], [1, 0, 0], [0, 0, 1]], lever_arm=[0.03, -0.04, 0.05])  # arm6.urdf's imu
    sd = np.sqrt(np.diag(truth.S_at(0.0) @ np.diag(np.square(truth.noise.wrench_sd)) @ truth.S_at(0.0).T))
    force = np.linalg.norm(made.PUSH_FORCE)
    for log, motion in ((read_joint_log(EXAMPLES / "joint_log.csv", arm.kinematics), arm),
                        (read_imu_log(EXAMPLES / "imu_log.csv"), imu)):
        assert len(log.t) == 601 and abs(log.dt - 0.01) < 1e-9
        result = compensate(calibration, log, motion=motion)             # offline
        start, end = made.PUSH_TIMES[0], made.PUSH_TIMES[1] + made.PUSH_RAMP
        free = (result.t < start - 0.1) | (result.t > end + 0.1)
        held = (result.t > start + made.PUSH_RAMP) & (result.t < made.PUSH_TIMES[1])
        rms = np.sqrt(np.mean(result.wrench[free] ** 2, axis=0)) / sd
        assert np.all((rms > 0.8) & (rms < 1.6)), (motion.source, rms)
        assert result.contact[free].mean() < 0.01 and result.contact[held].all(), motion.source
        pushed = np.linalg.norm(result.wrench[held, 3:], axis=1)
        assert np.all(np.abs(pushed - force) < 0.05), (motion.source, pushed.min(), pushed.max())
