"""``fmscal calibrate`` on pose tables, and the reading's sign through calibrate, the file and apply (issue 28)."""

import json

import numpy as np
import pytest

from fmscal.analysis.cli import main
from fmscal.observers.payload._static_fit import calibrate_table
from fmscal.plant import Calibration, CalibrationFileError, SpatialPayload, read_log
from fmscal.plant.numerics._errors import FmscalError
from fmscal.plant.io._pose_table import simulate_table, write_pose_table
from fmscal.plant.scenarios._spatial import TOOL

OFFSET = np.array([0.01, -0.02, 0.03, 0.5, -0.3, 0.2])
S_TRUE = np.eye(6) + 0.03 * np.random.default_rng(7).normal(size=(6, 6))
PAYLOAD = ["--mass", repr(TOOL.mass), "--com", *map(repr, TOOL.com)]
INERTIA = ["--inertia", "4e-3", "5e-3", "2.5e-3", "2e-4", "-1e-4", "1.5e-4"]
SD = np.array([0.005] * 3 + [0.05] * 3)


def _run(capsys, args):
    code = main(args)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _weight(table):
    """The wrench each held pose needs, ``[com x f; f]`` with ``f = -m R^T g``."""
    from fmscal.plant.physics._rigid_body import GRAVITY, rotation_matrix
    R = np.moveaxis(rotation_matrix(table.q.T), -1, 0)
    f = TOOL.mass * np.einsum("nkj,k->nj", R, -np.asarray(GRAVITY))
    return np.hstack([np.cross(TOOL.com, f), f])


@pytest.fixture(scope="module")
def held(tmp_path_factory):
    """A 16-pose table of a sensor reporting the load (``S`` off the identity, an offset), and its report."""
    folder = tmp_path_factory.mktemp("held")
    table = simulate_table(TOOL, n=16, seed=4, S=S_TRUE, offset=OFFSET, reading="load")
    write_pose_table(table, folder / "held.csv")
    assert main(["calibrate", str(folder / "held.csv"), *PAYLOAD, "--reading", "load", "--json"]) == 0
    return folder, table


def test_a_table_names_what_held_poses_cannot_determine(held, capsys):
    folder, table = held
    code, out, err = _run(capsys, ["calibrate", str(folder / "held.csv"), *PAYLOAD, "--reading", "load", "--json"])
    report = json.loads(out)
    assert code == 0 and report["kind"] == "table" and report["poses"] == 16 and report["reading"] == "load"
    keys = {"S", "S_std", "b", "b_std", "converged", "undetermined", "warnings", "latency", "observer", "saved"}
    assert keys <= set(report) and not report["converged"] and not report["saved"]
    # the weight's wrench spans three of six directions: three directions of the reading are left
    assert len(report["undetermined"]) == 3 and all(len(d) == 7 for d in report["undetermined"])
    assert all("held poses never make more" in w and "record a moving log" in w for w in report["warnings"])
    assert len(err.strip().splitlines()) == 3
    assert all(s is None for row in report["S_std"] for s in row)             # no single entry determined
    b, b_std = np.array(report["b"]), np.array(report["b_std"])
    assert np.all(np.abs(b - OFFSET) < 4 * b_std)
    # each offset's uncertainty is the noise over about the root of the poses, neither far above nor below
    assert np.all(b_std > 0.5 * SD / np.sqrt(16)) and np.all(b_std < 3 * SD / np.sqrt(16))
    # on the poses recorded, S_hat gives the wrench the weight makes, to within the noise
    w = (-table.w_hat - b) @ np.array(report["S"]).T
    assert np.abs(w - _weight(table))[:, 3:].max() < 5 * SD[3] and np.abs(w - _weight(table))[:, :3].max() < 0.03


def test_the_offset_uncertainty_of_a_table_holds_over_twenty_seeds():
    z = []
    for seed in range(20):
        table = simulate_table(TOOL, n=16, seed=100 + seed, S=S_TRUE, offset=OFFSET)
        fit = calibrate_table(table, TOOL.mass, TOOL.com)
        z.append((fit.b - OFFSET) / fit.b_std)
    rms = float(np.sqrt(np.mean(np.square(z))))
    assert 0.7 < rms < 1.4, rms


def test_poses_about_one_axis_leave_a_force_direction_too():
    def turn(angle):
        return np.r_[np.cos(angle / 2), np.sin(angle / 2), 0.0, 0.0]
    table = simulate_table(TOOL, seed=3, offset=OFFSET, q=[turn(a) for a in np.linspace(0, 2 * np.pi, 13)[:-1]])
    fit = calibrate_table(table, TOOL.mass, TOOL.com)
    assert len(fit.undetermined) == 4 and not fit.converged
    force = [w for w in fit.warnings if "the force hardly changes there" in w]
    assert len(force) == 1 and "fx" in force[0] and "tilt it about another axis" in force[0]


def test_the_wrong_sign_on_a_table_names_the_flag(held, capsys):
    folder, _ = held
    code, out, err = _run(capsys, ["calibrate", str(folder / "held.csv"), *PAYLOAD])
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1 and "--reading load" in err


def test_a_table_is_saved_only_forced_with_its_sign_and_applied(held, capsys):
    folder, table = held
    cal = folder / "cal.json"
    args = ["calibrate", str(folder / "held.csv"), *PAYLOAD, "--reading", "load", "--save", str(cal)]
    code, _, err = _run(capsys, args)
    assert code == 2 and "--inertia" in err and not cal.exists()               # the file records the payload
    code, _, err = _run(capsys, [*args, *INERTIA])
    assert code == 2 and "did not save" in err and "--force" in err and not cal.exists()
    code, out, err = _run(capsys, [*args, *INERTIA, "--force"])
    assert code == 0 and f"saved the calibration to {cal}" in out
    saved = json.loads(cal.read_text())
    # format /2: no entry of S determined by held poses (null each), and the directions they leave, named
    assert saved["forced"] and saved["reading"] == "load" and saved["latency"] is None
    assert saved["S_std"] == [[None] * 6] * 6 and saved["converged"] is False and saved["kind"] == "table"
    assert len(saved["undetermined"]) == len(saved["undetermined_directions"]) == 3
    readings = folder / "readings.csv"
    rows = np.column_stack([np.arange(len(table)) * 0.1, table.w_hat])
    np.savetxt(readings, rows, delimiter=",", header="t,tx,ty,tz,fx,fy,fz", comments="", fmt="%.17g")
    code, out, err = _run(capsys, ["apply", str(cal), str(readings), "--out", str(folder / "w.csv")])
    assert code == 0 and "reading load" in out and "--force" in err
    w = np.loadtxt(folder / "w.csv", delimiter=",", skiprows=1)[:, 1:]
    assert np.abs(w - _weight(table))[:, 3:].max() < 5 * SD[3]             # the sign turned: the weight's wrench


@pytest.mark.parametrize("extra, message", [
    (["--observer", "least-squares"], "--observer is not taken on a pose table"),
    (["--latency", "0"], "--latency is not taken on a pose table"),
    (["--no-offset"], "--no-offset is not taken on a pose table"),
])
def test_options_a_table_does_not_take_are_one_line(held, capsys, extra, message):
    folder, _ = held
    code, _, err = _run(capsys, ["calibrate", str(folder / "held.csv"), *PAYLOAD, *extra])
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1


def test_a_table_with_a_planar_centre_of_mass_is_one_line(held, capsys):
    folder, _ = held
    code, _, err = _run(capsys, ["calibrate", str(folder / "held.csv"), "--mass", "1.2", "--com", "0.1", "0.2"])
    assert code == 2 and "a pose table takes --com X Y Z" in err and len(err.strip().splitlines()) == 1
    code, _, err = _run(capsys, ["calibrate", str(folder / "held.csv"), "--mass", "1.2", "--rho", "0.1", "0.2", "0.3"])
    assert code == 2 and "a pose table takes --com X Y Z" in err and "--rho is the planar payload's" in err
    assert len(err.strip().splitlines()) == 1


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    """A 20 s spatial-arm log, the same log as a load sensor reports it, and each one's calibration."""
    folder = tmp_path_factory.mktemp("sign")
    assert main(["simulate", "--scenario", "spatial-arm", "--duration", "20", "--seed", "3",
                 "--out", str(folder / "arm.csv")]) == 0
    log = read_log(folder / "arm.csv")
    log.w_hat = -log.w_hat
    log.write(folder / "load.csv")
    common = [*PAYLOAD, *INERTIA, "--observer", "least-squares", "--latency", "0", "--json"]
    assert main(["calibrate", str(folder / "arm.csv"), *common, "--save", str(folder / "arm.json")]) == 0
    assert main(["calibrate", str(folder / "load.csv"), *common, "--reading", "load",
                 "--save", str(folder / "load.json")]) == 0
    return folder


@pytest.mark.slow
def test_a_load_log_calibrates_as_its_reaction_twin_and_applies_alike(arm, capsys):
    capsys.readouterr()
    a, b = Calibration.load(arm / "arm.json"), Calibration.load(arm / "load.json")
    assert a.reading == "reaction" and b.reading == "load" and not b.forced
    np.testing.assert_allclose(b.S, a.S, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(b.b, a.b, rtol=1e-9, atol=1e-12)
    for cal, log in (("arm.json", "arm.csv"), ("load.json", "load.csv")):
        assert main(["apply", str(arm / cal), str(arm / log), "--out", str(arm / f"w-{cal}.csv")]) == 0
    np.testing.assert_allclose(np.loadtxt(arm / "w-load.json.csv", delimiter=",", skiprows=1),
                               np.loadtxt(arm / "w-arm.json.csv", delimiter=",", skiprows=1), rtol=1e-9, atol=1e-12)


def test_a_load_log_without_the_flag_is_not_saved_and_names_it(arm, capsys):
    code, out, err = _run(capsys, ["calibrate", str(arm / "load.csv"), *PAYLOAD, *INERTIA, "--observer",
                                   "least-squares", "--latency", "0", "--json", "--save", str(arm / "x.json")])
    assert code == 2 and "--reading load" in err and "did not save" in err and not (arm / "x.json").exists()
    assert not json.loads(out)["converged"]


def test_identify_payload_takes_the_sign_the_calibration_recorded(arm, capsys):
    capsys.readouterr()
    code, out, err = _run(capsys, ["identify-payload", str(arm / "load.csv"), "--calibration", str(arm / "load.json"),
                                   "--json"])
    fit = json.loads(out)
    assert code == 0 and fit["reading"] == "load" and abs(fit["mass"] - TOOL.mass) < 0.012
    code, _, err = _run(capsys, ["identify-payload", str(arm / "load.csv"), "--calibration", str(arm / "load.json"),
                                 "--reading", "reaction"])
    assert code == 2 and "contradicts" in err and len(err.strip().splitlines()) == 1


def test_reading_on_a_planar_log_is_one_line(tmp_path, capsys):
    assert main(["simulate", "--duration", "2", "--out", str(tmp_path / "p.csv")]) == 0
    code, _, err = _run(capsys, ["calibrate", str(tmp_path / "p.csv"), "--mass", "2.5", "--rho", "0.2", "0.25",
                                 "--inertia", "0.75", "--reading", "load"])
    assert code == 2 and "--reading is taken on a spatial log" in err and len(err.strip().splitlines()) == 1


def test_the_calibration_file_records_the_sign_and_older_files_read_as_reaction(tmp_path):
    payload = SpatialPayload(TOOL.mass, TOOL.inertia, TOOL.com)
    cal = Calibration(S=S_TRUE, payload=payload, method="least-squares", b=OFFSET, reading="load")
    w_hat = np.array([[0.1, -0.2, 0.3, 1.0, 2.0, -3.0]])
    np.testing.assert_allclose(cal.apply(w_hat), (-w_hat - OFFSET) @ S_TRUE.T, rtol=1e-12)
    cal.save(tmp_path / "c.json")
    assert Calibration.load(tmp_path / "c.json").reading == "load"
    data = json.loads((tmp_path / "c.json").read_text())
    del data["reading"]
    (tmp_path / "old.json").write_text(json.dumps(data))
    old = Calibration.load(tmp_path / "old.json")
    assert old.reading == "reaction"
    np.testing.assert_allclose(old.apply(w_hat), (w_hat - OFFSET) @ S_TRUE.T, rtol=1e-12)
    data["reading"] = "tension"
    (tmp_path / "bad.json").write_text(json.dumps(data))
    with pytest.raises(CalibrationFileError, match="reading must be one of reaction, load; got 'tension'"):
        Calibration.load(tmp_path / "bad.json")
    with pytest.raises(FmscalError, match="reading must be one of"):
        Calibration(S=S_TRUE, payload=payload, method="x", reading="up")


def test_an_attitude_only_log_is_calibrated_on_its_held_segments(tmp_path, capsys):
    from fmscal.plant.io._pose_table import ATTITUDE_COLUMNS, simulate_attitude_log
    log = simulate_attitude_log(TOOL, seed=1, offset=OFFSET)
    path = tmp_path / "imu.csv"
    np.savetxt(path, np.column_stack([log.t, log.q, log.w_hat]), delimiter=",", header=",".join(ATTITUDE_COLUMNS),
               comments="", fmt="%.17g")
    code, out, err = _run(capsys, ["calibrate", str(path), *PAYLOAD, "--json"])
    report = json.loads(out)
    assert code == 0 and report["kind"] == "table" and not report["converged"] and len(report["undetermined"]) == 3
    assert "held segments" in err and np.all(np.abs(np.array(report["b"]) - OFFSET) < 4 * np.array(report["b_std"]))


def test_one_attitude_held_six_times_is_refused_in_one_line(tmp_path, capsys):
    """One attitude, or turns about the vertical only: gravity never tilts in the sensor frame, and the offset
    cannot be told from the weight: one line, exit 2 (a table, and an attitude-only log's held segments)."""
    table = simulate_table(TOOL, n=6, seed=1, offset=OFFSET, q=[[1.0, 0.0, 0.0, 0.0]] * 6)
    with pytest.raises(FmscalError, match="do not tilt gravity in the sensor frame"):
        calibrate_table(table, TOOL.mass, TOOL.com)
    write_pose_table(table, tmp_path / "same.csv")
    write_attitude_log_about_the_vertical(tmp_path / "yaw.csv")
    for name in ("same.csv", "yaw.csv"):
        for command in (["calibrate", str(tmp_path / name), *PAYLOAD], ["identify-payload", str(tmp_path / name)]):
            code, out, err = _run(capsys, command)
            lines = [line for line in err.strip().splitlines() if ": note:" not in line]
            assert code == 2 and out == "" and len(lines) == 1, (command, err)
            assert "do not tilt gravity in the sensor frame (all within 0.0 degrees" in lines[0]
            assert ("S and the offset" if command[0] == "calibrate" else "the mass and the offset") in lines[0]


def write_attitude_log_about_the_vertical(path, holds=6):
    """An attitude-only log: the tool held level at ``holds`` headings, turned about the vertical between them."""
    from fmscal.plant.io._pose_table import ATTITUDE_COLUMNS
    rng = np.random.default_rng(5)
    t = np.arange(0.0, holds * 3.5, 0.01)
    k, u = np.divmod(t, 3.5)
    heading = np.radians(40.0) * (k + np.clip((u - 2.0) / 1.5, 0.0, 1.0))      # 2 s held, 1.5 s turning
    q = np.column_stack([np.cos(heading / 2), 0 * t, 0 * t, np.sin(heading / 2)])
    f = np.array([0.0, 0.0, TOOL.mass * 9.81])
    w = np.r_[np.cross(TOOL.com, f), f] + OFFSET + rng.normal(size=(len(t), 6)) * SD
    np.savetxt(path, np.column_stack([t, q, w]), delimiter=",", header=",".join(ATTITUDE_COLUMNS), comments="",
               fmt="%.17g")
