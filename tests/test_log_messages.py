"""A log the reader cannot take is refused in one line that names the real cause (issue 37).

A spatial log missing one of its columns names that column (not the planar format's); a file
separated by semicolons or tabs, or one that opens with a comment line, says so, instead of
listing every column as missing.
"""

import json

import numpy as np
import pandas as pd
import pytest

from fmscal.analysis.cli import main
from fmscal.plant import LogError, SPATIAL_SCENARIOS, read_log


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    """A 2 s spatial log written as ``fmscal simulate`` writes one."""
    folder = tmp_path_factory.mktemp("messages")
    log, _ = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=2.0).generate(0)[:2]
    log.write(folder / "arm.csv")
    return folder, pd.read_csv(folder / "arm.csv")


@pytest.mark.parametrize("dropped", ["fz", "qw", "tz"])
def test_a_missing_spatial_column_is_named(arm, dropped):
    folder, frame = arm
    frame.drop(columns=[dropped]).to_csv(folder / f"no_{dropped}.csv", index=False)
    with pytest.raises(LogError, match=f"^no_{dropped}.csv: missing column\\(s\\) {dropped}; expected the header "
                                       "t,qw,qx,qy,qz,x,y,z,tx,ty,tz,fx,fy,fz "):
        read_log(folder / f"no_{dropped}.csv")


@pytest.mark.parametrize("sep, name", [(";", "semicolons"), ("\t", "tabs")])
def test_a_file_separated_by_semicolons_or_tabs_says_so(arm, sep, name):
    folder, frame = arm
    frame.to_csv(folder / "other.csv", index=False, sep=sep)
    with pytest.raises(LogError, match=f"^other.csv: the columns are separated by {name}; fmscal reads "
                                       "comma-separated files"):
        read_log(folder / "other.csv")


def test_a_comment_line_first_says_so_and_the_cli_answers_in_one_line(arm, capsys):
    folder, _ = arm
    (folder / "commented.csv").write_text("# recorded on the rig\n" + (folder / "arm.csv").read_text())
    with pytest.raises(LogError, match="^commented.csv: line 1 is a comment"):
        read_log(folder / "commented.csv")
    assert main(["identify-payload", str(folder / "commented.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["fmscal identify-payload: error: commented.csv: line 1 is a comment (# recorded on the rig); "
                   "the column header must be the first line: delete the comment lines"]


def test_the_log_itself_still_reads(arm):
    folder, frame = arm
    log = read_log(folder / "arm.csv")
    assert log.kind == "spatial" and len(log) == len(frame)
    np.testing.assert_allclose(log.w_hat[:, 5], frame["fz"].to_numpy())


@pytest.mark.parametrize("method", ["least-squares", "high-gain", "ekf", "adaptive", "max-likelihood"])
def test_readings_that_never_change_are_refused_in_one_line_by_every_method(tmp_path, capsys, method):
    # issue 37: all-zero readings traced back (SVD did not converge) in four methods
    from fmscal.plant import PAPER_PAYLOAD, get_scenario
    log, _, _ = get_scenario("paper").with_(duration=5.0).generate(0)
    log.w_hat[:] = 0.0
    log.write(tmp_path / "zero.csv")
    argv = ["calibrate", str(tmp_path / "zero.csv"), "--mass", "2.5", "--inertia", "0.75", "--rho", "0.2", "0.25",
            "--observer", method]
    assert main(argv) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "fmscal calibrate: error: zero.csv: column(s) M, fx, fy of the reading never change (every row 0): a "
        "channel not connected or a column written empty; check the recording"]
    from fmscal.analysis import calibrate
    from fmscal.plant import FmscalError
    with pytest.raises(FmscalError, match="^zero.csv: column\\(s\\) M, fx, fy of the reading never change"):
        calibrate(read_log(tmp_path / "zero.csv"), PAPER_PAYLOAD, method=method)


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["S"][0].__setitem__(0, "1.0"), "S must be numbers of shape (3, 3); got [['1.0'"),
    (lambda d: d["S"][0].__setitem__(0, True), "S must be numbers of shape (3, 3); got [[True"),
    (lambda d: d.__setitem__("b", ["0", 0, 0]), "b must be numbers of shape (3,); got ['0', 0, 0]"),
    (lambda d: d.__setitem__("payload", None), "payload must be an object with mass, inertia and rho; got None"),
    (lambda d: d.__setitem__("S", [[1.0] * 6] * 5),
     "S must be square, one row per reading component (3 or 6); got shape (5, 6)"),
])
def test_a_calibration_file_takes_json_numbers_only(tmp_path, edit, message):
    # issue 37: "1.0" and true were read as numbers; a null payload gave a raw TypeError text
    import json
    from fmscal.plant import PAPER_PAYLOAD, PAPER_S, Calibration, FmscalError
    Calibration(S=PAPER_S, payload=PAPER_PAYLOAD, method="least-squares", b=np.zeros(3)).save(tmp_path / "c.json")
    data = json.loads((tmp_path / "c.json").read_text())
    Calibration.load(tmp_path / "c.json")                          # the file as written reads
    edit(data)
    (tmp_path / "x.json").write_text(json.dumps(data))
    with pytest.raises(FmscalError) as err:
        Calibration.load(tmp_path / "x.json")
    assert str(err.value).startswith(f"x.json: {message}")


def test_offset_given_as_text_is_refused_on_every_input():
    # a review found offset="False" taken silently on a pose table (it was refused only deep in a method)
    from fmscal.analysis import calibrate
    from fmscal.plant import FmscalError
    from fmscal.plant.io import simulate_table
    from fmscal.plant.scenarios import TOOL
    table = simulate_table(TOOL, n=12, seed=0)
    with pytest.raises(FmscalError, match="^offset must be True or False; got 'False'$"):
        calibrate(table, (TOOL.mass, TOOL.com), offset="False")


@pytest.mark.parametrize("converged", [True, False, None])
def test_apply_warns_on_a_calibration_saved_unconverged_from_python(tmp_path, capsys, converged):
    # Calibration.save refuses one without force=True (and marks it forced with it): a file written otherwise (by
    # hand, or by fmscal before save refused it) is warned on too
    from fmscal.plant import PAPER_PAYLOAD, PAPER_S, Calibration, get_scenario
    log, _, _ = get_scenario("paper").with_(duration=2.0).generate(0)
    log.write(tmp_path / "log.csv")
    cal = Calibration(S=PAPER_S, payload=PAPER_PAYLOAD, method="adaptive", converged=converged)
    if converged is False:
        (tmp_path / "c.json").write_text(json.dumps(cal.to_dict()))
    else:
        cal.save(tmp_path / "c.json")
    assert main(["apply", str(tmp_path / "c.json"), str(tmp_path / "log.csv"), "--out", str(tmp_path / "w.csv")]) == 0
    warned = "records a calibration that did not converge" in capsys.readouterr().err
    assert warned is (converged is False)
