"""Issue 37, "Messages": each case on the command line (one line, a non-zero exit) and in Python, on a spatial log,
where the earlier tests (test_log_messages.py, test_bad_input*.py) hold the Python call or the planar case only."""

import json

import numpy as np
import pandas as pd
import pytest

from fmscal.analysis import calibrate
from fmscal.analysis.cli import main
from fmscal.observers.payload import identify_payload
from fmscal.plant import Calibration, FmscalError, SPATIAL_SCENARIOS, read_log
from fmscal.plant.scenarios import TOOL

FLAGS = ["--mass", "1.2", "--com", "0.01", "-0.005", "0.06", "--inertia", "4e-3", "5e-3", "2.5e-3", "2e-4", "-1e-4",
         "1.5e-4"]


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    folder = tmp_path_factory.mktemp("messages3d")
    SPATIAL_SCENARIOS["spatial-arm"].with_(duration=2.0).generate(0)[0].write(folder / "arm.csv")
    return folder, pd.read_csv(folder / "arm.csv")


def _one_line(capsys, argv, words):
    code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and words in err[0] and "Traceback" not in err[0], err
    return err[0]


@pytest.mark.parametrize("command", ["calibrate", "identify-payload"])
def test_a_missing_spatial_column_and_semicolons_are_named_by_both_commands(arm, capsys, command):
    folder, frame = arm
    frame.drop(columns=["fz"]).to_csv(folder / "no_fz.csv", index=False)
    frame.to_csv(folder / "semi.csv", index=False, sep=";")
    flags = FLAGS if command == "calibrate" else []
    line = _one_line(capsys, [command, str(folder / "no_fz.csv"), *flags], "missing column(s) fz;")
    assert "theta" not in line and "--rho" not in line
    _one_line(capsys, [command, str(folder / "semi.csv"), *flags], "separated by semicolons")


def test_all_zero_spatial_readings_are_named_by_both_commands_and_in_python(arm, capsys):
    folder, frame = arm
    zero = frame.copy()
    zero[["tx", "ty", "tz", "fx", "fy", "fz"]] = 0.0
    zero.to_csv(folder / "zero.csv", index=False)
    words = "column(s) tx, ty, tz, fx, fy, fz of the reading never change"
    _one_line(capsys, ["calibrate", str(folder / "zero.csv"), *FLAGS], words)
    _one_line(capsys, ["identify-payload", str(folder / "zero.csv")], words)
    log = read_log(folder / "zero.csv")
    for call in (lambda: calibrate(log, TOOL), lambda: identify_payload(log)):
        with pytest.raises(FmscalError, match="never change"):
            call()


@pytest.mark.parametrize("edit, words", [
    (lambda d: d.__setitem__("S", d["S"][:5]), "S must be square, one row per reading component (3 or 6); got "
                                               "shape (5, 6)"),
    (lambda d: d.__setitem__("payload", None), "payload must be an object with mass, inertia and com; got None"),
])
def test_a_bad_spatial_calibration_file_is_one_line_on_the_command_line(arm, tmp_path, capsys, edit, words):
    folder, _ = arm
    S = np.eye(6)
    Calibration(S=S, payload=TOOL, method="least-squares", b=np.zeros(6), gravity=(0, 0, -9.81),
                reading="reaction").save(tmp_path / "c.json")
    data = json.loads((tmp_path / "c.json").read_text())
    edit(data)
    (tmp_path / "x.json").write_text(json.dumps(data))
    _one_line(capsys, ["identify-payload", str(folder / "arm.csv"), "--calibration", str(tmp_path / "x.json")],
              words)
    _one_line(capsys, ["apply", str(tmp_path / "x.json"), str(folder / "arm.csv"), "--out", str(tmp_path / "w.csv")],
              words)
    with pytest.raises(FmscalError, match=words.replace("(", "\\(").replace(")", "\\)")):
        Calibration.load(tmp_path / "x.json")


def test_rows_before_the_first_pose_are_noted_by_both_commands(arm, capsys):
    folder, frame = arm
    late = frame.copy()
    late.loc[:4, ["qw", "qx", "qy", "qz", "x", "y", "z"]] = np.nan
    late.to_csv(folder / "late.csv", index=False)
    note = "late.csv: the first 5 row(s) come before the first pose"
    assert main(["identify-payload", str(folder / "late.csv")]) == 0
    assert f"fmscal identify-payload: note: {note}" in capsys.readouterr().err
    assert main(["calibrate", str(folder / "late.csv"), *FLAGS, "--observer", "least-squares", "--latency", "0"]) == 0
    assert f"fmscal calibrate: note: {note}" in capsys.readouterr().err
    assert read_log(folder / "late.csv").notes[0].startswith(note)
