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
TEXT = ("arm.csv", "arm.truth.json", "table.csv", "table.truth.json", "joints.csv")
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
    assert sum(sizes.values()) < 400_000 and max(sizes.values()) < 150_000, sizes
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
