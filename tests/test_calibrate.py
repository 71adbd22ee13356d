"""fmscal calibrate and the least-squares reference: recovery, warnings, and bad input."""

import contextlib
import io
import json
import subprocess
import sys

import numpy as np
import pytest

from fmscal import plant
from fmscal.analysis.cli import main
from fmscal.analysis._metrics import calibration_error
from fmscal.observers import AugmentedEKF, LeastSquares
from fmscal.observers.core._base import ObserverResult

OTHER = plant.Payload(6.0, 0.3, (-0.15, 0.4))
PAYLOAD_ARGS = ["--mass", "6", "--inertia", "0.3", "--rho", "-0.15", "0.4"]


@pytest.fixture(scope="module")
def other_log(tmp_path_factory):
    """A log of another payload and a random S, made by fmscal simulate."""
    out = tmp_path_factory.mktemp("logs") / "other.csv"
    assert main(["simulate", "--scenario", "random-S", "--seed", "4", "--duration", "40", *PAYLOAD_ARGS,
                 "--out", str(out)]) == 0
    truth = plant.read_truth(out.with_suffix(".truth.json"))
    assert truth.payload == OTHER
    return out, truth


@pytest.fixture(scope="module")
def calibrated(other_log):
    """``fmscal calibrate --json`` of the other payload's log by a method (None: the default), each run once."""
    path, _ = other_log
    done = {}

    def by(method=None):
        if method not in done:
            done[method] = _calibrate_json(path, *(["--observer", method] if method else []))
        return done[method]
    return by


def _calibrate_json(path, *extra):
    """``fmscal calibrate --json`` in this process (the command line's own entry, ``main``): its JSON, strict."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["calibrate", str(path), *PAYLOAD_ARGS, "--truth", str(path.with_suffix(".truth.json")),
                     "--json", *extra])
    assert code == 0, err.getvalue()
    return json.loads(out.getvalue(), parse_constant=lambda c: pytest.fail(f"non-strict JSON {c}"))


@pytest.mark.parametrize("method, tolerance", [("max-likelihood", 0.01), ("least-squares", 0.01), ("ekf", 0.02),
                                               ("high-gain", 0.02), ("adaptive", 0.01)])
@pytest.mark.slow
def test_every_method_recovers_S_of_another_payload(other_log, calibrated, method, tolerance):
    _, truth = other_log
    out = calibrated(method)
    assert out["observer"] == method
    assert out["converged"] is True
    assert calibration_error(truth.S0, truth.S_at(0)) > 1.0
    assert out["E"] < tolerance
    assert (out["S_std"] is None) == (method in ("high-gain", "adaptive"))


@pytest.mark.slow
def test_least_squares_and_ekf_agree(calibrated):
    ls, ekf = calibrated("least-squares"), calibrated("ekf")
    assert calibrated()["observer"] == "max-likelihood"            # the default: the floor
    diff = np.abs(np.array(ls["S"]) - np.array(ekf["S"]))
    assert np.all(diff < 3 * np.hypot(np.array(ls["S_std"]), np.array(ekf["S_std"])) + 1e-3)
    assert not any("random walk" in w for w in ekf["warnings"])        # a constant S: nothing moved


@pytest.mark.slow
def test_ekf_warns_when_the_calibration_steps_during_the_log(tmp_path, capsys):
    """A Table 1 step at 100 s: the EKF raises its random walk there, and calibrate says so."""
    path = tmp_path / "step.csv"
    assert main(["simulate", "--scenario", "time-varying", "--duration", "110", "--out", str(path)]) == 0
    assert main(["calibrate", str(path), "--mass", "2.5", "--inertia", "0.75", "--rho", "0.2", "0.25",
                 "--observer", "ekf", "--latency", "0"]) == 0
    err = capsys.readouterr().err
    assert "the EKF raised its random walk on S" in err and "first at t = 100." in err


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["random-S", "real-rig"])
def test_least_squares_uncertainty_is_honest(scenario):
    """Issue 15: over 20 seeds the z-scores ``(S_hat - S) / S_std`` (and of ``b`` on the rig, with its offset,
    50 Hz poses and latency) have a spread between 0.8 and 1.25 and a mean near 0: neither overconfident
    nor needlessly cautious."""
    from fmscal.analysis._comparison import simulate_case
    z_S, z_b = [], []
    for seed in range(20):
        sc, log, truth, _ = simulate_case(scenario, seed, 30.0)
        offset = truth.offset is not None
        result = LeastSquares(sc.payload, offset=offset).run(log.shift_poses(truth.latency))
        z_S.append(((result.S_hat - truth.S_at(log.t[-1])) / result.S_std).ravel())
        if offset:
            z_b.append((result.b - truth.offset) / result.b_std)
    z_S = np.concatenate(z_S)
    assert 0.8 < z_S.std() < 1.25 and abs(z_S.mean()) < 0.3
    if z_b:
        z_b = np.concatenate(z_b)
        assert 0.8 < z_b.std() < 1.25 and abs(z_b.mean()) < 0.3


@pytest.mark.slow
def test_noise_is_estimated_and_said(other_log, capsys):
    path, truth = other_log
    assert main(["calibrate", str(path), *PAYLOAD_ARGS]) == 0
    text = capsys.readouterr().out
    assert "noise estimated from the log (wrench and pose)" in text and "S_hat +- one sigma" in text
    assert main(["calibrate", str(path), *PAYLOAD_ARGS, "--pose-noise", "0.0017", "1e-4", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["noise_estimated"] == ["wrench"] and out["noise"]["position_sd"] == 1e-4


@pytest.mark.slow
def test_plot_draws_S_hat(other_log, tmp_path):
    path, _ = other_log
    assert main(["calibrate", str(path), *PAYLOAD_ARGS, "--observer", "high-gain",
                 "--plot", str(tmp_path / "s.png")]) == 0
    assert (tmp_path / "s.png").stat().st_size > 0


def test_excitation_warning_when_one_wrench_component_is_driven(tmp_path, capsys):
    only_moment = plant.Multisine([[(1.0, 2.0, 0.0), (0.5, 5.0, 0.3)], [(0.0, 1.0, 0.0)], [(0.0, 1.0, 0.0)]])
    log, truth, _ = plant.get_scenario("paper").with_(excitation=only_moment, duration=20).generate(0)
    log.write(tmp_path / "moment.csv")
    assert main(["calibrate", str(tmp_path / "moment.csv"), "--mass", "2.5", "--inertia", "0.75",
                 "--rho", "0.2", "0.25"]) == 0
    err = capsys.readouterr().err
    assert "does not excite all nine entries of S" in err


@pytest.mark.slow
def test_consistency_warning_when_angles_are_in_degrees(tmp_path, capsys):
    log, _, _ = plant.get_scenario("paper").with_(duration=20).generate(0)
    pose = log.pose.copy()
    pose[:, 0] = np.rad2deg(pose[:, 0])
    plant.Log(log.t, pose, log.w_hat).write(tmp_path / "degrees.csv")
    assert main(["calibrate", str(tmp_path / "degrees.csv"), "--mass", "2.5", "--inertia", "0.75",
                 "--rho", "0.2", "0.25"]) == 0
    err = capsys.readouterr().err
    assert "does not match the model" in err and "angles in rad" in err
    # the same log in radians draws no warning
    log.write(tmp_path / "radians.csv")
    assert main(["calibrate", str(tmp_path / "radians.csv"), "--mass", "2.5", "--inertia", "0.75",
                 "--rho", "0.2", "0.25"]) == 0
    assert "warning" not in capsys.readouterr().err


def test_a_diverged_run_is_an_error_not_an_answer(other_log, monkeypatch, capsys):
    path, _ = other_log

    def diverging(self, log, S0=None, **kwargs):
        return ObserverResult("ekf", log.t[:5], np.eye(3), np.tile(np.eye(3), (5, 1, 1)), np.zeros((5, 6)),
                              diverged=True)

    monkeypatch.setattr(AugmentedEKF, "run", diverging)
    assert main(["calibrate", str(path), *PAYLOAD_ARGS, "--observer", "ekf"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "diverged" in err[0]


def _write(path, text):
    path.write_text(text)
    return str(path)


GOOD_ROWS = "".join(f"{0.001 * k},{0.0},{0.0},{0.0},1,1,1\n" for k in range(20))


@pytest.mark.parametrize("make, message", [
    (lambda d: str(d / "absent.csv"), "no such file"),
    (lambda d: _write(d / "cols.csv", "t,theta,x,y,M,fx,fz\n" + GOOD_ROWS), "missing column(s) fy"),
    (lambda d: _write(d / "nan.csv", "t,theta,x,y,M,fx,fy\n" + GOOD_ROWS.replace("1,1,1\n", "nan,1,1\n", 1)),
     "NaN or infinite"),
    (lambda d: _write(d / "order.csv", "t,theta,x,y,M,fx,fy\n" + GOOD_ROWS.replace("0.002,", "0.0005,", 1)),
     "not strictly increasing"),
    (lambda d: _write(d / "uneven.csv", "t,theta,x,y,M,fx,fy\n" + GOOD_ROWS.replace("0.002,", "0.0021,", 1)),
     "not evenly sampled"),
    (lambda d: _write(d / "short.csv", "t,theta,x,y,M,fx,fy\n" + "".join(GOOD_ROWS.splitlines(True)[:3])),
     "too few rows"),
    (lambda d: _write(d / "cut.csv", "t,theta,x,y,M,fx,fy\n" + GOOD_ROWS[:60]),
     "line 4 has 4 fields (row 3); the header has 7"),
    (lambda d: _write(d / "nopose.csv", "t,theta,x,y,M,fx,fy\n" + "".join(
        f"{0.001 * k},{'0,0,0' if k < 3 else ',,'},1,1,1\n" for k in range(20))), "too few pose measurements"),
])
def test_bad_logs_are_refused_with_one_line(tmp_path, make, message, capsys):
    assert main(["calibrate", make(tmp_path), *PAYLOAD_ARGS]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], lines


def test_the_installed_command_refuses_a_bad_log_in_one_line(tmp_path):
    """The same through a new process, as a user's shell runs it: exit 2, one line, no traceback."""
    proc = subprocess.run([sys.executable, "-m", "fmscal.analysis.cli", "calibrate", str(tmp_path / "absent.csv"),
                           *PAYLOAD_ARGS], capture_output=True, text=True)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "no such file" in lines[0], proc.stderr


@pytest.mark.parametrize("args, message", [
    (["--mass", "0", "--inertia", "0.3", "--rho", "0", "0"], "--mass must be positive"),
    (["--mass", "6", "--inertia", "-1", "--rho", "0", "0"], "--inertia must be positive"),
    (["--mass", "6", "--inertia", "0.3", "--rho", "0.1"], "a planar log takes --rho RX RY (2 numbers, m)"),
    (["--mass", "6", "--inertia", "0.3", "--rho", "0.1", "x"], "invalid float value: 'x'"),
    (["--mass", "6", "--inertia", "0.3", "--rho", "0", "0", "--pose-noise", "-1", "0"], "--pose-noise must be"),
])
def test_bad_payload_arguments_are_refused_with_one_line(other_log, args, message, capsys):
    path, _ = other_log
    assert main(["calibrate", str(path), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_readings_in_counts_are_named_and_fail_only_the_methods_that_start_from_S0():
    """A reading in sensor counts makes S's entries tiny: every method warns, the offline fit absorbs it (its units
    check passes), an online method starting from S0 of order one does not (its units check fails)."""
    from fmscal.analysis._calibrate import calibrate
    sc = plant.get_scenario("paper").with_(duration=20.0)
    log, truth, _ = sc.generate(0)
    counts = plant.Log(log.t, log.pose, log.w_hat * 1e4)
    offline = calibrate(counts, sc.payload, method="least-squares", offset=False, latency=0.0)
    online = calibrate(counts, sc.payload, method="adaptive", offset=False, latency=0.0)
    for report in (offline, online):
        assert any("sensor counts" in w for w in report.warnings)
    assert offline.units == [] and len(online.units) == 1 and "sensor counts" in online.units[0]
