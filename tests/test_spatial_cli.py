"""The commands on spatial logs: simulate, calibrate, apply, identify-payload (issue 22)."""

import json

import numpy as np
import pytest

from fmscal.analysis.cli import main
from fmscal.plant import read_truth

TOOL = ["--mass", "1.2", "--com", "0.01", "-0.005", "0.06", "--inertia", "4e-3", "5e-3", "2.5e-3", "2e-4", "-1e-4",
        "1.5e-4"]


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    """A 20 s spatial-arm log, its sidecar, and a calibration saved from it (``cal0.json``)."""
    folder = tmp_path_factory.mktemp("spatial")
    assert main(["simulate", "--scenario", "spatial-arm", "--duration", "20", "--seed", "2",
                 "--out", str(folder / "arm.csv")]) == 0
    assert main(["calibrate", str(folder / "arm.csv"), *TOOL, "--save", str(folder / "cal0.json")]) == 0
    return folder


def _json(capsys):
    return json.loads(capsys.readouterr().out)


@pytest.mark.slow
def test_calibrate_a_spatial_log_saves_and_applies(arm, capsys):
    assert main(["calibrate", str(arm / "arm.csv"), *TOOL, "--truth", str(arm / "arm.truth.json"), "--json",
                 "--save", str(arm / "cal.json")]) == 0
    out = _json(capsys)
    assert out["kind"] == "spatial" and out["converged"] and out["saved"] and out["observer"] == "max-likelihood"
    assert out["latency_estimated"] and abs(out["latency"]) < max(4 * out["latency_std"], 1e-5) \
        and 0 < out["latency_std"] < 2e-4 and out["undetermined"] == []
    assert np.shape(out["S"]) == (6, 6) and np.shape(out["S_std"]) == (6, 6) and len(out["b"]) == len(out["b_std"]) == 6
    assert out["E_torque"] < 0.02 and out["E_force"] < 0.02
    truth = read_truth(arm / "arm.truth.json")
    assert np.abs(np.array(out["b"]) - truth.offset).max() < 0.02 * np.abs(truth.offset).max()
    assert main(["apply", str(arm / "cal.json"), str(arm / "arm.csv"), "--out", str(arm / "w.csv"), *TOOL]) == 0
    header = (arm / "w.csv").read_text().splitlines()[0]
    assert header == "t,tx,ty,tz,fx,fy,fz"
    # the saved payload holds the centre of mass as com; apply checks it with --com, and a --rho names --com
    assert json.loads((arm / "cal.json").read_text())["payload"]["com"] == [0.01, -0.005, 0.06]
    as_rho = ["--rho" if a == "--com" else a for a in TOOL]
    assert main(["apply", str(arm / "cal.json"), str(arm / "arm.csv"), "--out", str(arm / "w2.csv"), *as_rho]) == 2
    err = capsys.readouterr().err.strip()
    assert "--com X Y Z and --inertia IXX IYY IZZ IXY IXZ IYZ are for a spatial log" in err
    assert len(err.splitlines()) == 1 and not (arm / "w2.csv").exists()


@pytest.mark.slow
def test_the_reference_fit_and_a_figure_of_a_spatial_calibration(arm, capsys):
    capsys.readouterr()
    assert main(["calibrate", str(arm / "arm.csv"), *TOOL, "--observer", "least-squares", "--latency", "0",
                 "--truth", str(arm / "arm.truth.json"), "--json", "--plot", str(arm / "ls.png")]) == 0
    out = _json(capsys)
    assert out["observer"] == "least-squares" and out["converged"] and not out["latency_estimated"]
    assert out["E_torque"] < 0.03 and out["E_force"] < 0.03
    assert (arm / "ls.png").read_bytes()[:4] == b"\x89PNG"


def test_identify_payload_with_the_saved_calibration(arm, capsys):
    capsys.readouterr()
    assert main(["identify-payload", str(arm / "arm.csv"), "--calibration", str(arm / "cal0.json"), "--json"]) == 0
    out = _json(capsys)
    assert abs(out["mass"] - 1.2) < 0.012
    assert np.abs(np.array(out["com"]) - [0.01, -0.005, 0.06]).max() < 2e-3
    assert out["inertia"] is not None and out["converged"]
    # with the truth: the errors of every group, the inertia's six entries among them (URDF order)
    assert main(["identify-payload", str(arm / "arm.csv"), "--calibration", str(arm / "cal0.json"), "--json",
                 "--truth", str(arm / "arm.truth.json")]) == 0
    errors = _json(capsys)
    truth = read_truth(arm / "arm.truth.json").payload
    I_true = [truth.I_c[0, 0], truth.I_c[1, 1], truth.I_c[2, 2], truth.I_c[0, 1], truth.I_c[0, 2], truth.I_c[1, 2]]
    np.testing.assert_allclose(errors["inertia_error"], np.array(out["inertia"]) - I_true, rtol=1e-12, atol=1e-15)
    assert np.all(np.abs(errors["inertia_error"]) < 4 * np.array(out["inertia_std"]) + 1e-6)
    assert abs(errors["mass_error"]) < 0.012 and len(errors["com_error"]) == 3


@pytest.mark.slow
def test_static_poses_are_not_saved_as_a_calibration(tmp_path, capsys):
    log = tmp_path / "static.csv"
    assert main(["simulate", "--scenario", "spatial-static", "--duration", "40", "--out", str(log)]) == 0
    assert main(["calibrate", str(log), *TOOL, "--save", str(tmp_path / "cal.json")]) == 2
    err = capsys.readouterr().err
    assert "angular acceleration" in err and "did not save" in err and not (tmp_path / "cal.json").exists()


@pytest.mark.parametrize("args, message", [
    (["--mass", "1.2", "--com", "0.2", "0.25", "--inertia", "0.75"], "a spatial log takes --com X Y Z (3 numbers"),
    (["--mass", "1.2", "--rho", "0.01", "-0.005", "0.06", "--inertia", "4e-3", "5e-3", "2.5e-3", "0", "0", "0"],
     "a spatial log takes --com X Y Z (m, the centre of mass in the sensor frame); --rho is the planar payload's"),
    ([*TOOL, "--observer", "high-gain"], "--observer high-gain does not run on a spatial log yet"),
    ([*TOOL, "--no-offset"], "--no-offset is not taken on a spatial log"),
    ([*TOOL, "--gravity", "0", "0", "inf"], "--gravity must be three finite numbers"),
    (["--mass", "1.2", "--com", "0", "0", "0.06", "--inertia", "1", "1", "3", "0", "0", "0"], "triangle inequality"),
])
def test_a_wrong_flag_on_a_spatial_log_is_one_line(arm, capsys, args, message):
    assert main(["calibrate", str(arm / "arm.csv"), *[a.format(d=arm) for a in args]]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_spatial_flags_on_a_planar_log_are_one_line(tmp_path, capsys):
    log = tmp_path / "paper.csv"
    assert main(["simulate", "--duration", "2", "--out", str(log)]) == 0
    assert main(["calibrate", str(log), *TOOL]) == 2
    err = capsys.readouterr().err.strip()
    assert "a planar log takes --rho RX RY (m, the sensor's position from the centre of mass" in err
    assert "--com is the spatial payload's" in err and len(err.splitlines()) == 1
    assert main(["identify-payload", str(log)]) == 2
    err = capsys.readouterr().err.strip()
    assert "a planar log weighs no payload under gravity; identify_payload takes a spatial log" in err
    assert len(err.splitlines()) == 1


def test_a_quaternion_off_unit_norm_is_one_line(arm, tmp_path, capsys):
    lines = (arm / "arm.csv").read_text().splitlines()
    cells = lines[5].split(",")
    cells[1] = repr(float(cells[1]) * 1.1)
    lines[5] = ",".join(cells)
    (tmp_path / "bad.csv").write_text("\n".join(lines) + "\n")
    assert main(["calibrate", str(tmp_path / "bad.csv"), *TOOL]) == 2
    assert "expected a unit quaternion" in capsys.readouterr().err


@pytest.mark.slow
def test_a_saturating_channel_is_not_saved(arm, tmp_path, capsys):
    lines = (arm / "arm.csv").read_text().splitlines()
    fz = np.array([float(line.split(",")[-1]) for line in lines[1:]])
    top = np.percentile(fz, 80)
    clipped = [lines[0]] + [",".join([*line.split(",")[:-1], repr(float(min(v, top)))])
                            for line, v in zip(lines[1:], fz)]
    (tmp_path / "clip.csv").write_text("\n".join(clipped) + "\n")
    assert main(["calibrate", str(tmp_path / "clip.csv"), *TOOL, "--save", str(tmp_path / "cal.json")]) == 2
    err = capsys.readouterr().err
    assert "the reading fz is pinned at" in err and "did not save" in err and not (tmp_path / "cal.json").exists()


def test_a_truth_of_the_other_case_is_one_line(arm, tmp_path, capsys):
    assert main(["simulate", "--duration", "2", "--out", str(tmp_path / "p.csv")]) == 0
    assert main(["identify-payload", str(arm / "arm.csv"), "--truth", str(tmp_path / "p.truth.json")]) == 2
    assert "is the truth of a planar log" in capsys.readouterr().err
    assert main(["calibrate", str(tmp_path / "p.csv"), "--mass", "2.5", "--rho", "0.2", "0.25", "--inertia", "0.75",
                 "--truth", str(arm / "arm.truth.json")]) == 2
    assert "is the truth of a spatial log" in capsys.readouterr().err


def test_planar_scenario_options_are_refused_for_a_spatial_scenario(tmp_path, capsys):
    out = str(tmp_path / "x.csv")
    assert main(["simulate", "--scenario", "spatial-weak", "--rho", "0.1", "0.2", "--out", out]) == 2
    assert "takes --com X Y Z" in capsys.readouterr().err


@pytest.mark.slow
def test_compare_takes_a_spatial_scenario_and_writes_its_figure(tmp_path, capsys):
    out = tmp_path / "cmp"
    assert main(["compare", "--scenario", "spatial-arm", "--seeds", "1", "--duration", "3", "--observer",
                 "least-squares", "max-likelihood", "high-gain", "--out", str(out)]) == 0
    text = (out / "summary.md").read_text()
    assert "| spatial-arm | high-gain (reconstruction of [4]) | 1 | not applicable |" in text
    assert "HighGainObserver is defined for planar models" in text
    assert (out / "E_spatial-arm.png").read_bytes()[:4] == b"\x89PNG"
    assert main(["compare", "--scenario", "spatial-nowhere"]) == 2
    assert "spatial-arm" in capsys.readouterr().err                    # the message lists both cases' scenarios


@pytest.mark.slow
def test_the_online_methods_calibrate_a_spatial_log(arm, capsys):
    """The adaptive observer (no uncertainty of its own) and the EKF through calibrate: S near the floor's, printed
    and in JSON, no uncertainty claimed where the method gives none. The latency is told (the log has none):
    its search, the same for every method, is tested with the floor above."""
    log, sidecar = str(arm / "arm.csv"), str(arm / "arm.truth.json")
    capsys.readouterr()
    E = {}
    for name in ("max-likelihood", "adaptive", "ekf"):
        assert main(["calibrate", log, *TOOL, "--observer", name, "--latency", "0", "--truth", sidecar, "--json"]) == 0
        out = json.loads(capsys.readouterr().out)
        assert out["observer"] == name and np.array(out["S"]).shape == (6, 6) and len(out["b"]) == 6
        assert (out["S_std"] is None) == (name == "adaptive") and (out["b_std"] is None) == (name == "adaptive")
        E[name] = out["E"]
    assert 0.5 < E["adaptive"] / E["max-likelihood"] < 2.0 and 0.5 < E["ekf"] / E["max-likelihood"] < 2.0, E
    assert main(["calibrate", log, *TOOL, "--observer", "adaptive", "--latency", "0"]) == 0
    text = capsys.readouterr().out
    assert "adaptive reports no uncertainty" in text and "+-" in text.split("offset b")[1]
