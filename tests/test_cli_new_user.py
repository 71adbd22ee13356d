"""What a new user of the command line meets first: a missing file named as missing, the counts of a flag's values
in its help, and a refusal that names the flag to change.

- Every command that reads files names a missing one (and what it is) before any other check, whatever else is wrong
  with the command: each case below also carries an option that another check would refuse.
- A flag that takes a fixed count of values shows them (``--com X Y Z``, ``--inertia I_G | IXX IYY IZZ IXY IXZ
  IYZ``), never ``C [C ...]``; only flags that take any number of values show that.
- ``fmscal compensate --causal`` on a log whose rate the default window does not fit names ``--window``.
"""

import argparse
import shutil
from pathlib import Path

import numpy as np
import pytest

from fmscal.analysis.cli import main
from fmscal.analysis.cli._common import Words
from fmscal.analysis.cli._main import build_parser
from fmscal.plant import Calibration, read_truth

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
TOOL = ["--mass", "1.2", "--com", "0.01", "-0.005", "0.06", "--inertia", "4e-3", "5e-3", "2.5e-3", "2e-4", "-1e-4",
        "1.5e-4"]


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """The example log and URDF, a calibration of the example log's sensor (its truth), an existing output."""
    d = tmp_path_factory.mktemp("new_user")
    for name in ("arm.csv", "arm.truth.json", "arm6.urdf", "joint_log.csv"):
        shutil.copy(EXAMPLES / name, d / name)
    truth = read_truth(d / "arm.truth.json")
    Calibration(S=truth.S_at(0.0), payload=truth.payload, method="truth", b=truth.offset, gravity=(0.0, 0.0, -9.81),
                latency=0.0, noise=truth.noise).save(d / "cal.json")
    (d / "exists.csv").write_text("a\n")
    return d


#: (argv with {d} for the folder, the missing file, what it is): each with another fault a later check refuses.
MISSING = [
    (["calibrate", "{d}/none.csv", *TOOL, "--save", "{d}/x.txt"], "none.csv", "the log"),
    (["calibrate", "{d}/arm.csv", *TOOL, "--truth", "{d}/none.json", "--save", "{d}/x.txt"], "none.json",
     "the --truth file"),
    (["calibrate", "{d}/arm.csv", "--payload", "{d}/none.json", "--mass", "1", "--save", "{d}/x.txt"], "none.json",
     "the --payload file"),
    (["calibrate", "{d}/arm.csv", *TOOL, "--urdf", "{d}/none.urdf", "--save", "{d}/x.txt"], "none.urdf",
     "the --urdf file"),
    (["apply", "{d}/none.json", "{d}/arm.csv", "--out", "{d}/w.csv", "--mass", "1"], "none.json", "the calibration"),
    (["apply", "{d}/cal.json", "{d}/none.csv", "--out", "{d}/exists.csv", "--mass", "1"], "none.csv", "the readings"),
    (["compensate", "{d}/cal.json", "{d}/imu.csv", "--out", "{d}/c.txt", "--imu-rotation", "1", "0", "0", "0"],
     "imu.csv", "the log"),
    (["compensate", "{d}/none.json", "{d}/arm.csv", "--out", "{d}/exists.csv"], "none.json",
     "the calibration or payload file"),
    (["compensate", "{d}/cal.json", "{d}/arm.csv", "--out", "{d}/c.txt", "--payload", "{d}/none.json"], "none.json",
     "the --payload file"),
    (["compensate", "{d}/cal.json", "{d}/joint_log.csv", "--out", "{d}/c.txt", "--urdf", "{d}/none.urdf"],
     "none.urdf", "the --urdf file"),
    (["identify-payload", "{d}/none.csv", "--save", "{d}/x.txt"], "none.csv", "the log"),
    (["identify-payload", "{d}/arm.csv", "--calibration", "{d}/none.json", "--save", "{d}/x.txt"], "none.json",
     "the --calibration file"),
    (["identify-payload", "{d}/arm.csv", "--truth", "{d}/none.json", "--save", "{d}/x.txt"], "none.json",
     "the --truth file"),
    (["identify-payload", "{d}/arm.csv", "--urdf", "{d}/none.urdf", "--save", "{d}/x.txt"], "none.urdf",
     "the --urdf file"),
    (["import", "{d}/none_bag", "--wrench-topic", "/ft", "--pose-topic", "/tool", "--out", "{d}/x.txt"], "none_bag",
     "the bag"),
    (["import", "{d}", "--wrench-topic", "/ft", "--pose-topic", "/q", "--urdf", "{d}/none.urdf", "--frame", "f",
      "--out", "{d}/x.txt"], "none.urdf", "the --urdf file"),
    (["ros2", "--params-file", "{d}/none.yaml"], "none.yaml", "the params file"),
    (["ros2", "--ros-args", "--params-file", "{d}/none.yaml"], "none.yaml", "the params file"),
]


@pytest.mark.parametrize("argv, missing, what", MISSING, ids=[f"{a[0]}-{w}" for a, _, w in MISSING])
def test_a_missing_file_is_named_before_any_other_check(argv, missing, what, folder, capsys):
    before = sorted(p.name for p in folder.iterdir())
    assert main([a.format(d=folder) for a in argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{missing}: no such file" in err[0] and f"({what})" in err[0], err
    assert sorted(p.name for p in folder.iterdir()) == before


def test_without_the_missing_file_the_other_fault_is_the_one_named(folder, capsys):
    # The cases' other faults are real: with the file there, a later check refuses them.
    assert main(["compensate", str(folder / "cal.json"), str(folder / "arm.csv"), "--out", str(folder / "c.csv"),
                 "--imu-rotation", "1", "0", "0", "0"]) == 2
    assert "has no IMU columns" in capsys.readouterr().err
    assert main(["calibrate", str(folder / "arm.csv"), *TOOL, "--save", str(folder / "x.txt")]) == 2
    assert "--save must end in .json" in capsys.readouterr().err


#: The flags that take any number of values: the only ones whose help may print ``V [V ...]``.
OPEN_COUNTS = {"scenario", "observer", "noise_scale"}


def _subparsers():
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices


def test_a_flag_of_a_fixed_count_shows_its_values():
    for name, parser in _subparsers().items():
        for action in parser._actions:
            if action.nargs in ("+", "*"):
                assert isinstance(action.metavar, Words) or action.dest in OPEN_COUNTS, (name, action.option_strings)
    usage = {name: " ".join(p.format_usage().split()) for name, p in _subparsers().items()}
    for command in ("calibrate", "apply", "simulate"):
        assert "--inertia I_G | IXX IYY IZZ IXY IXZ IYZ" in usage[command] and "--com X Y Z" in usage[command]
        assert "--rho RX RY" in usage[command] and "..." not in usage[command], usage[command]
    assert "--imu-rotation QW QX QY QZ | R11 R12 ... R33" in usage["compensate"]
    assert "--imu-lever-arm X Y Z" in usage["compensate"] and "--point X Y Z" in usage["compensate"]
    assert "--gravity GX GY GZ | estimate" in usage["identify-payload"]
    assert "--pose-offset DX DY | DX DY DZ" in usage["import"]


def test_a_fixed_count_is_held_and_the_counted_flags_still_read(folder, capsys):
    assert main(["calibrate", str(folder / "arm.csv"), *TOOL[:5], *TOOL[6:]]) == 2      # --com of two numbers
    assert "a spatial log takes --com X Y Z (3 numbers, m)" in capsys.readouterr().err
    # --inertia keeps both of its counts: six for a spatial log, one for a planar (refused on a spatial log by name)
    assert main(["calibrate", str(folder / "arm.csv"), "--mass", "1.2", "--com", "0.01", "-0.005", "0.06",
                 "--inertia", "0.75"]) == 2
    assert "IXX IYY IZZ IXY IXZ IYZ (6 numbers" in capsys.readouterr().err


def test_causal_on_a_sparse_log_names_the_window_flag(folder, capsys):
    argv = ["compensate", str(folder / "cal.json"), str(folder / "arm.csv"), "--out", str(folder / "c.csv"),
            "--causal"]
    assert main(argv) == 2                                         # arm.csv is 25 Hz: 60 ms holds too few poses
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fmscal compensate: error: --window 0.06 s (the default with "
                                               "--causal) is"), err
    assert main(argv + ["--window", "0.24", "--delay", "0.4"]) == 2
    err = capsys.readouterr().err
    assert "--delay 0.4 s reaches past --window 0.24 s: give --window of at least" in err, err
    assert main(argv + ["--window", "0.24"]) == 0                  # the six poses the cubic needs
    rows = np.loadtxt(folder / "c.csv", delimiter=",", skiprows=1)
    assert rows.shape[1] == 9 and len(rows) > 250                  # t, the wrench, contact, tool_change
