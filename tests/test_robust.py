"""Glitches in the reading (found, bridged, reported) and the misfit of a log measured (issue 37).

Fast cases; the statistics over seeds are in tests/test_robust_slow.py.
"""

import copy
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fmscal.analysis import calibrate
from fmscal.analysis.cli import main
from fmscal.observers import make_observer
from fmscal.observers.core import calibration_uncertainty, find_glitches, glitch_threshold, reading_noise
from fmscal.observers.diagnostics import misfit
from fmscal.plant import SPATIAL_SCENARIOS, PayloadStd, SpatialModel, get_scenario

ARM = SPATIAL_SCENARIOS["spatial-arm"]
#: The simulator's payload is the one the logs were made with: exact (S_std its statistical part alone).
EXACT = PayloadStd.exact()


@pytest.fixture(scope="module")
def arm():
    """A 10 s spatial-arm log (1 kHz) and its truth."""
    log, truth, _ = ARM.with_(duration=10.0).generate(0)
    return log, truth


def spiked(log, count, size, channel, seed=1):
    """``log`` with ``count`` single-sample spikes of ``size`` on ``channel`` (a copy), and their rows."""
    rows = np.sort(np.random.default_rng(seed).choice(np.arange(20, len(log) - 20), count, replace=False))
    out = copy.copy(log)
    out.w_hat = log.w_hat.copy()
    out.w_hat[rows, channel] += size
    return out, rows


def turned(log, degrees):
    """``log`` with its poses those of a frame turned ``degrees`` about y from the sensor's."""
    rows = np.flatnonzero(log.has_pose)
    out = copy.copy(log)
    out.pose = log.pose.copy()
    turn = Rotation.from_quat(log.pose[rows][:, [1, 2, 3, 0]]) * Rotation.from_rotvec([0, np.radians(degrees), 0])
    out.pose[rows, :4] = turn.as_quat()[:, [3, 0, 1, 2]]
    return out


def test_the_rule_finds_exactly_the_spikes_and_nothing_on_a_clean_reading():
    rng = np.random.default_rng(3)
    t = np.arange(20000) * 1e-3
    clean = np.column_stack([np.sin(2 * np.pi * 0.7 * t), np.cos(2 * np.pi * 1.3 * t)]) + 0.01 * rng.normal(
        size=(len(t), 2))
    glitches, bridged = find_glitches(t, clean)
    assert glitches.count == 0 and bridged is clean                     # nothing rejected: the same array
    w = clean.copy()
    rows = np.array([0, 500, 501, 9000, 19999])                         # the ends and two side by side
    w[rows, 1] += [0.2, -0.3, 0.3, 0.1, -0.5]                           # 10 to 50 noise standard deviations
    glitches, bridged = find_glitches(t, w, ["a", "b"])
    np.testing.assert_array_equal(glitches.indices, rows)
    assert all(c == ["b"] for c in glitches.channels)
    assert np.abs(bridged - clean)[rows].max() < 0.05                   # bridged from the neighbours
    np.testing.assert_array_equal(np.delete(bridged, rows, 0), np.delete(w, rows, 0))
    assert 0.009 < reading_noise(w)[1] < 0.011
    stepped = clean.copy()
    stepped[7000:, 0] += 0.5                                            # a true change of the wrench: no glitch
    assert find_glitches(t, stepped)[0].count == 0


def test_the_threshold_is_the_bonferroni_bound_of_the_logs_size():
    assert glitch_threshold(5000, 6) == pytest.approx(5.52, abs=0.01)
    assert glitch_threshold(60001, 6) == pytest.approx(5.94, abs=0.01)


def test_spikes_in_a_spatial_log_no_longer_steer_least_squares(arm):
    """Issue 37: 20 single-sample spikes of +5 N on fz (100 noise standard deviations)."""
    log, truth = arm
    S = truth.S_at(log.t[-1])
    clean = calibrate(log, ARM.payload, method="least-squares", latency=0.0, truth=truth, payload_std=EXACT)
    bad, rows = spiked(log, 20, 5.0, 5)
    cal = calibrate(bad, ARM.payload, method="least-squares", latency=0.0, truth=truth, payload_std=EXACT)
    assert clean.glitches is None and "glitches" not in json.loads(clean.to_json())
    assert cal.glitches["count"] == 20 and cal.glitches["indices"] == rows.tolist()
    assert json.loads(cal.to_json())["glitches"]["times"] == pytest.approx(log.t[rows].tolist())
    assert any("20 sample(s) of the reading rejected as glitches" in note for note in cal.notes)
    assert cal.run.info["glitches"]["indices"] == rows.tolist()        # the run reports what calibrate bridged
    assert 0.9 * clean.E < cal.E < 1.1 * clean.E
    assert np.abs((cal.S_hat - S) / cal.S_std).max() < 5
    assert cal.converged


def test_every_batch_method_bridges_the_glitches_itself(arm):
    """Observer.run of an offline method, outside calibrate: the same rule, the rows in result.info."""
    log, _ = arm
    bad, rows = spiked(log, 10, 2.0, 3, seed=2)
    model = SpatialModel(ARM.payload)
    result = make_observer("least-squares", model, None, {"offset": True}).run(bad)
    clean = make_observer("least-squares", model, None, {"offset": True}).run(log)
    assert result.info["glitches"]["indices"] == rows.tolist() and clean.info["glitches"]["count"] == 0
    assert np.abs(result.S_hat - clean.S_hat).max() < 0.5 * clean.S_std.max()


def test_a_run_given_the_glitches_does_not_search_again(arm):
    """calibrate bridges once and hands the glitches to the run: the run takes them as found, not searching."""
    log, _ = arm
    bad, rows = spiked(log, 10, 2.0, 3, seed=2)
    model = SpatialModel(ARM.payload)
    glitches, _ = find_glitches(log.t, log.w_hat)                      # none on the clean reading
    kept = make_observer("least-squares", model, None, {"offset": True}).run(bad, glitches=glitches)
    searched = make_observer("least-squares", model, None, {"offset": True}).run(bad)
    assert kept.info["glitches"]["count"] == 0 and searched.info["glitches"]["indices"] == rows.tolist()
    assert np.abs(kept.S_hat - searched.S_hat).max() > 0.1 * searched.S_std.max()     # the spikes left in
    with pytest.raises(TypeError, match="glitches must be a Glitches"):
        make_observer("least-squares", model, None, {"offset": True}).run(log, glitches={"count": 0})


def test_the_command_line_prints_the_glitches(tmp_path, capsys):
    log, truth, _ = get_scenario("paper").with_(duration=10.0).generate(0)
    bad, rows = spiked(log, 5, 20 * reading_noise(log.w_hat)[1], 1)
    bad.write(tmp_path / "spiked.csv")
    payload = get_scenario("paper").payload
    args = ["calibrate", str(tmp_path / "spiked.csv"), "--mass", repr(payload.mass), "--inertia",
            repr(payload.inertia), "--rho", *map(repr, payload.rho), "--observer", "least-squares", "--latency",
            "0", "--json"]
    assert main(args) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["glitches"]["indices"] == rows.tolist()
    assert "note: " in err and "5 sample(s) of the reading rejected as glitches" in err


def test_a_payload_in_axes_turned_from_the_poses_frame_is_not_converged(arm):
    """Issue 37: the payload in the sensor's axes, the poses of a frame turned 10 degrees from it."""
    log, truth = arm
    cal = calibrate(turned(log, 10.0), ARM.payload, method="least-squares", latency=0.0, truth=truth)
    assert cal.E > 1.0                                                  # S absorbs the turn: far off
    assert not cal.converged
    assert any("the model does not fit the log: the residual is" in w and "slow half" in w for w in cal.warnings)
    # the widened uncertainty is one claim: S_std and b_std are what cov says, the offset's column widened with
    # its row; the method's own run keeps its own (narrower) S_std
    S_std, _, b_std = calibration_uncertainty(np.c_[cal.S_hat, -cal.S_hat @ cal.b], cal.cov, True)
    np.testing.assert_allclose(S_std, cal.S_std, rtol=1e-12)
    np.testing.assert_allclose(b_std, cal.b_std, rtol=1e-12)
    assert np.all(cal.run.S_std <= cal.S_std) and np.any(cal.run.S_std < cal.S_std)
    right = calibrate(log, ARM.payload, method="least-squares", latency=0.0, truth=truth)
    assert right.converged and not any("does not fit" in w for w in right.warnings)


def test_the_misfit_says_how_far_the_residual_is_above_the_noise(arm):
    """Poses 20 ms behind the reading, taken as aligned: the residual is several times the noise, in words."""
    log, _ = arm
    model = SpatialModel(ARM.payload)
    found = misfit(log.shift_poses(0.02), model)
    fits = misfit(log, model)
    assert fits.fits and not fits.gross and 0.9 < fits.ratio.min() and fits.ratio.max() < 1.2 and fits.p_value > 0.01
    assert found.gross and 3 < found.ratio.max() < 10
    assert f"the residual is {found.ratio.max():.2g} times the noise" in found.warning


def test_an_online_method_is_warned_of_the_glitches():
    log, truth, _ = get_scenario("paper").with_(duration=5.0).generate(0)
    bad, rows = spiked(log, 5, 30 * reading_noise(log.w_hat)[2], 2)
    cal = calibrate(bad, get_scenario("paper").payload, method="ekf", latency=0.0, truth=truth)
    clean = calibrate(log, get_scenario("paper").payload, method="ekf", latency=0.0, truth=truth)
    assert cal.glitches["indices"] == rows.tolist()
    assert any("rejected as glitches" in w and "a live run" in w for w in cal.warnings)
    assert cal.E < 1.2 * clean.E


def test_held_poses_and_slow_moves_are_not_taken_for_a_misfit():
    """spatial-static: its slow half leaves directions of the reading undetermined, so the halves are not compared
    (their near-degenerate fits differ by far more than their covariances say); the residual is the noise."""
    static = SPATIAL_SCENARIOS["spatial-static"].with_(duration=16.0)
    found = misfit(static.generate(0)[0], SpatialModel(static.payload))
    assert found.fits and found.p_value == 1.0 and found.ratio.max() < 1.2
