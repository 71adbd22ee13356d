"""Real rigs: sensor offsets, mass-property errors, multi-rate logs, latency, saving and applying."""

import json

import numpy as np
import pytest

from fmscal import plant
from fmscal.analysis import calibration_error
from fmscal.analysis._calibrate import calibrate
from fmscal.analysis.cli import main
from fmscal.observers import make_observer
from fmscal.analysis._sensitivity import derived_error, distortion, perturbed, sensitivity, tolerable_error
from fmscal.observers import LeastSquares
from fmscal.observers.batch._latency import estimate_latency
from fmscal.plant import Calibration, CalibrationFileError, PAPER_PAYLOAD

B_TRUE = np.array([0.3, 2.0, -1.5])
#: E bound after 60 s with the offset estimated, per method (measured 2.4e-3, 3.8e-3, 2.8e-2, 4.3e-3)
OFFSET_E_BOUND = {"least-squares": 0.01, "ekf": 0.015, "adaptive": 0.06, "high-gain": 0.015}


def _assert_calibrated_sigma(error, sigma):
    """The stated one-sigma uncertainty fits the actual error, both ways.

    No entry beyond 4 sigma (sigma too small), and the RMS of the normalised
    errors above 0.2 (sigma too large: with sigma 10 times too large it is
    about 0.07; measured 0.65 to 0.8 on these logs).
    """
    z = np.asarray(error) / np.asarray(sigma)
    assert np.all(np.abs(z) < 4), f"errors of {z} sigma: the uncertainty is too small"
    assert np.sqrt(np.mean(z ** 2)) > 0.2, f"errors of only {z} sigma: the uncertainty is too large"


@pytest.fixture(scope="module")
def offset_log():
    sc = plant.get_scenario("paper").with_(offset=tuple(B_TRUE), duration=60)
    log, truth, _ = sc.generate(0)
    return sc, log, truth


@pytest.mark.slow
@pytest.mark.parametrize("method", sorted(OFFSET_E_BOUND))
def test_every_method_recovers_the_offset_with_S(offset_log, method):
    sc, log, truth = offset_log
    obs = make_observer(method, sc.payload, truth.noise, {"offset": True})
    result = obs.run(log, truth.S0 if obs.online else None)
    assert not result.diverged
    assert calibration_error(result.S_hat, truth.S_at(60)) < OFFSET_E_BOUND[method]
    assert np.max(np.abs(result.b - B_TRUE)) < 0.05
    if result.b_std is not None:                  # least squares and the EKF say how sure they are
        _assert_calibrated_sigma(result.b - B_TRUE, result.b_std)


def test_ignoring_the_offset_biases_S_as_predicted():
    sc = plant.get_scenario("paper").with_(offset=tuple(B_TRUE), duration=30)
    log, truth, _ = sc.generate(0, noise_free=True)
    S = truth.S_at(0.0)
    fit = LeastSquares(sc.payload)                # offset left out
    biased = fit.run(log).S_hat
    predicted = fit.offset_bias(log, S, B_TRUE)
    assert calibration_error(biased, S) > 0.5     # the bias is large ...
    np.testing.assert_allclose(biased - S, predicted, atol=1e-5)   # ... and it is the predicted one


def test_estimating_an_offset_that_is_not_there_costs_nothing_measurable():
    log, truth, _ = plant.get_scenario("paper").with_(duration=40).generate(1)
    without, with_ = (LeastSquares(PAPER_PAYLOAD, offset=o).run(log) for o in (False, True))
    E = [calibration_error(r.S_hat, truth.S_at(40)) for r in (without, with_)]
    assert E[1] < 1.2 * E[0]
    _assert_calibrated_sigma(with_.b, with_.b_std)


@pytest.mark.parametrize("parameter", ["mass", "inertia", "rho"])
def test_sensitivity_matches_the_derivation(parameter):
    table = sensitivity(errors=(-0.05, 0.1), parameters=[parameter], duration=10)
    np.testing.assert_allclose(table["E_measured"], table["E_derived"], rtol=1e-3)
    assert np.all(table["E_exact_payload"] < 1e-4)
    # E is linear in the error: the tolerance inverts it
    e = tolerable_error(parameter, 0.02, PAPER_PAYLOAD)
    assert derived_error(parameter, e, PAPER_PAYLOAD) == pytest.approx(0.02)


def test_mass_and_S_scale_together_unseen():
    """A 10 % mass error changes S_hat by the distortion T and leaves the fit's residual as it was."""
    log, truth, _ = plant.get_scenario("paper").with_(duration=20).generate(2)
    right = LeastSquares(PAPER_PAYLOAD)
    wrong = LeastSquares(perturbed(PAPER_PAYLOAD, "mass", 0.1))
    S_right, S_wrong = right.run(log).S_hat, wrong.run(log).S_hat
    np.testing.assert_allclose(S_wrong, distortion("mass", 0.1, PAPER_PAYLOAD) @ S_right, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(wrong.report.residual_rms, right.report.residual_rms, rtol=1e-9)
    assert not wrong.report.warnings           # nothing in the data says the mass is wrong


@pytest.mark.slow
def test_a_50_hz_log_with_dropped_frames_calibrates_close_to_full_rate():
    full, truth, _ = plant.get_scenario("paper").with_(duration=60).generate(3)
    slow, _, _ = plant.get_scenario("vision-50hz").with_(duration=60).generate(3)
    assert slow.pose_rate() < 50
    S_full = calibrate(full, PAPER_PAYLOAD, latency=0.0).S
    S_slow = calibrate(slow, PAPER_PAYLOAD, latency=0.0).S
    assert calibration_error(np.array(S_slow), truth.S_at(60)) < 0.02
    assert calibration_error(np.array(S_slow), np.array(S_full)) < 0.02


@pytest.mark.slow
@pytest.mark.parametrize("method", ["ekf", "high-gain", "adaptive"])
def test_every_observer_takes_empty_pose_cells(method):
    sc = plant.get_scenario("vision-50hz").with_(duration=30)
    log, truth, _ = sc.generate(0, noise_free=True)
    result = make_observer(method, sc.payload, truth.noise).run(log, truth.S0)
    assert not result.diverged
    assert calibration_error(result.S_hat, truth.S_at(30)) < 0.05


def test_noise_is_estimated_from_a_multi_rate_log():
    log, truth, _ = plant.get_scenario("vision-50hz").generate(0)
    estimate = plant.estimate_noise(log)
    assert estimate.angle_sd == pytest.approx(truth.noise.angle_sd, rel=0.1)
    assert estimate.position_sd == pytest.approx(truth.noise.position_sd, rel=0.1)


@pytest.mark.parametrize("latency, pose_rate", [(0.02, 50.0), (0.035, None), (0.0, 50.0)])
def test_a_known_latency_is_recovered(latency, pose_rate):
    sc = plant.get_scenario("real-rig").with_(latency=latency, pose_rate=pose_rate, duration=30)
    log, _, _ = sc.generate(1)
    found = estimate_latency(log, sc.payload, offset=True)
    assert abs(found.latency - latency) <= max(1.5 * log.dt, 4 * found.std)
    assert abs(min(found.costs, key=found.costs.get) - found.latency) <= log.dt


def test_shift_poses_lines_the_streams_up():
    sc = plant.get_scenario("paper").with_(duration=2, latency=0.01)
    late, _, x_true = sc.generate(0, noise_free=True)
    aligned = late.shift_poses(0.01)
    k = 10                                         # 10 samples of 1 ms
    np.testing.assert_allclose(aligned.pose, x_true[:-k][:, [0, 2, 4]], atol=1e-12)
    assert len(aligned) == len(late) - k                 # the rows after the last pose are dropped
    with pytest.raises(ValueError, match="latency must be"):
        late.shift_poses(late.duration)


# --- saving and applying ------------------------------------------------------------------

def _calibration():
    return Calibration(S=[[0.61, -0.04, -0.14], [-0.34, 1.0, -0.14], [-0.11, 0.17, 0.96]], payload=PAPER_PAYLOAD,
                       method="least-squares", S_std=np.full((3, 3), 1e-3), b=B_TRUE, b_std=[1e-3, 2e-3, 3e-3],
                       log_name="run.csv", log_sha256="ab" * 32, latency=0.02)


def test_save_load_apply_round_trip_exactly(tmp_path):
    cal = _calibration()
    cal.save(tmp_path / "cal.json")
    back = Calibration.load(tmp_path / "cal.json", PAPER_PAYLOAD)
    for name in ("S", "S_std", "b", "b_std"):
        np.testing.assert_array_equal(getattr(back, name), getattr(cal, name))
    assert (back.method, back.log_name, back.log_sha256, back.latency, back.date) == \
        (cal.method, cal.log_name, cal.log_sha256, cal.latency, cal.date)
    w_hat = np.random.default_rng(0).normal(size=(5, 3))
    np.testing.assert_array_equal(back.apply(w_hat), (w_hat - B_TRUE) @ cal.S.T)
    np.testing.assert_array_equal(back.apply(w_hat[0]), cal.S @ (w_hat[0] - B_TRUE))


def test_apply_command_writes_what_python_computes(tmp_path, capsys):
    cal = _calibration()
    cal.save(tmp_path / "cal.json")
    log, _, _ = plant.get_scenario("paper").with_(duration=0.05).generate(0)
    log.write(tmp_path / "log.csv")                       # a full log will do
    assert main(["apply", str(tmp_path / "cal.json"), str(tmp_path / "log.csv"), "--out",
                 str(tmp_path / "w.csv")]) == 0
    lines = (tmp_path / "w.csv").read_text().splitlines()
    assert lines[0] == "t,M,fx,fy"
    written = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    np.testing.assert_array_equal(written[:, 0], log.t)
    np.testing.assert_array_equal(written[:, 1:], cal.apply(log.w_hat))
    (tmp_path / "readings.csv").write_text("t,M,fx,fy\n0.0,1.0,2.0,3.0\n0.5,0.0,0.0,0.0\n")
    assert main(["apply", str(tmp_path / "cal.json"), str(tmp_path / "readings.csv"), "--out",
                 str(tmp_path / "w2.csv")]) == 0
    capsys.readouterr()


def _broken(data, **changes):
    data = dict(data)
    for key, value in changes.items():
        if value is KeyError:
            del data[key]
        else:
            data[key] = value
    return data


@pytest.mark.parametrize("change, message", [
    ("not json", "not a JSON calibration file"),
    ({"format": "something-else"}, "not an fmscal calibration"),
    ({"S": KeyError}, "missing key"),
    ({"S": [[1, 0], [0, 1]]}, "S must be square, one row per reading component (3 or 6); got shape (2, 2)"),
    ({"S": [[1, 0, 0], [0, 1, 0], [0, 0, float("nan")]]}, "S must be finite numbers"),
    ({"S": [[1, 0, 0], [0, 1, 0], [0, 0, 0]]}, "singular"),
    ({"b": [1, 2]}, "b must be finite numbers of shape (3,)"),
    ({"payload": {"mass": 2.5}}, "payload must hold mass, inertia and rho"),
    ({"payload": {"mass": 3.0, "inertia": 0.75, "rho": [0.2, 0.25]}}, "made for another payload"),
    ({"latency": "20 ms"}, "latency must be a number"),
])
def test_malformed_calibration_files_are_refused(tmp_path, capsys, change, message):
    path = tmp_path / "cal.json"
    if change == "not json":
        path.write_text("{ S: [1, 2, 3] ")
    else:
        path.write_text(json.dumps(_broken(_calibration().to_dict(), **change)))
    with pytest.raises(CalibrationFileError, match=message.replace("(", r"\(").replace(")", r"\)")):
        Calibration.load(path, PAPER_PAYLOAD)
    readings = tmp_path / "readings.csv"
    readings.write_text("t,M,fx,fy\n0.0,1.0,2.0,3.0\n")
    code = main(["apply", str(path), str(readings), "--out", str(tmp_path / "w.csv"),
                 "--mass", "2.5", "--inertia", "0.75", "--rho", "0.2", "0.25"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and message.split(" (")[0] in err


@pytest.mark.slow
def test_simulate_calibrate_save_apply_on_a_multi_rate_log_with_an_offset(tmp_path, capsys):
    log_path, cal_path = tmp_path / "rig.csv", tmp_path / "cal.json"
    assert main(["simulate", "--scenario", "paper", "--duration", "40", "--pose-rate", "50", "--drop-rate", "0.1",
                 "--offset", "0.3", "2", "-1.5", "--latency", "0.02", "--out", str(log_path)]) == 0
    capsys.readouterr()
    assert main(["calibrate", str(log_path), "--mass", "2.5", "--inertia", "0.75", "--rho", "0.2", "0.25",
                 "--truth", str(tmp_path / "rig.truth.json"), "--save", str(cal_path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["E"] < 0.02 and out["latency"] == pytest.approx(0.02, abs=2e-3) and out["latency_estimated"]
    np.testing.assert_allclose(out["b"], B_TRUE, atol=0.05)
    cal = Calibration.load(cal_path, PAPER_PAYLOAD)
    assert cal.log_name == "rig.csv" and cal.log_sha256 == plant.file_sha256(log_path)
    np.testing.assert_array_equal(cal.S, out["S"])
    assert main(["apply", str(cal_path), str(log_path), "--out", str(tmp_path / "w.csv")]) == 0
    # the calibrated wrench is the true one to within the noise and E
    truth = plant.read_truth(tmp_path / "rig.truth.json")
    log = plant.read_log(log_path)
    w_true = (log.w_hat - B_TRUE) @ truth.S_at(0.0).T
    w = np.loadtxt(tmp_path / "w.csv", delimiter=",", skiprows=1)[:, 1:]
    assert np.max(np.abs(w - w_true)) < 0.05 * np.max(np.abs(w_true))


def test_the_offset_of_a_singular_estimate_is_nan_not_an_exception():
    from fmscal.observers.core._result import offset_from_c, offset_std
    S = np.array([[1.0, 2.0, 0.0], [2.0, 4.0, 0.0], [0.0, 0.0, 1.0]])
    b = offset_from_c(S, np.ones(3))
    assert np.all(np.isnan(b)) and np.all(np.isnan(offset_std(S, b, np.eye(12))))
