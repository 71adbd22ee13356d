"""The pose stream's latency as a parameter with an uncertainty (issue 37, "Timing"): fractional shifts of either
sign, SLERP, the estimate and its std, a latency that steps mid-log, and calibrate's use of them."""

import numpy as np
import pytest

from fmscal.analysis import calibrate
from fmscal.observers.batch import estimate_latency
from fmscal.plant import SPATIAL_SCENARIOS, Log, SpatialModel, get_scenario


def _turn_about_z(angle):
    return np.c_[np.cos(angle / 2), np.zeros_like(angle), np.zeros_like(angle), np.sin(angle / 2)]


def test_slerp_turns_at_a_constant_rate_between_measurements():
    """Half-way between two attitudes 1.2 rad apart about z, SLERP gives the turn of 0.6 rad (to rounding); the
    position is linear."""
    times = np.array([0.0, 1.0])
    poses = np.c_[_turn_about_z(np.array([0.3, 1.5])), [[0.0, 0, 0], [1.0, 2.0, -4.0]]]
    out = SpatialModel.interpolate_pose(np.array([0.25, 0.5]), times, poses)
    np.testing.assert_allclose(out[:, :4], _turn_about_z(np.array([0.6, 0.9])), atol=1e-15)
    np.testing.assert_allclose(out[:, 4:], [[0.25, 0.5, -1.0], [0.5, 1.0, -2.0]], atol=1e-15)


def test_a_fractional_shift_of_either_sign_lines_the_streams_up():
    """A spatial log whose poses turn about z at a constant rate, shifted by +2.4 and -1.6 samples, shows at
    every row the attitude of that row's time (to rounding); rows the shift leaves without a pose are dropped."""
    t = np.arange(200) * 1e-3
    rate, lag = 3.0, 2.4e-3

    def poses(at):
        return np.c_[_turn_about_z(rate * at), np.c_[at, 2 * at, 0 * at]]

    for latency in (lag, -1.6e-3):
        log = Log(t, poses(t - latency), np.random.default_rng(0).normal(size=(200, 6)))
        aligned = log.shift_poses(latency)
        np.testing.assert_allclose(aligned.pose, poses(aligned.t), atol=1e-12)
        assert len(aligned) == 200 - int(np.ceil(abs(latency) / 1e-3))


def test_a_multi_rate_log_keeps_its_pattern_of_pose_rows():
    """200 Hz poses in a 1 kHz log with frames dropped: the measurements move by the nearest whole samples and
    keep their number (less those the shift leaves outside the stream)."""
    log, _, _ = SPATIAL_SCENARIOS["spatial-mocap"].with_(duration=2.0, latency=0.0).generate(0)
    aligned = log.shift_poses(2.4e-3)
    assert log.has_pose.sum() - aligned.has_pose.sum() == 2          # the first and the last measurement
    np.testing.assert_array_equal(np.diff(np.flatnonzero(aligned.has_pose)),
                                  np.diff(np.flatnonzero(log.has_pose))[1:-1])


def test_a_5_ms_late_mocap_stream_is_found_within_its_std():
    """The issue's case (spatial-mocap, seed 1, 10 s): found at 4 ms before; now within two of its std of 5 ms,
    the std under a sample, and the calibration's E close to the one at the known latency."""
    sc = SPATIAL_SCENARIOS["spatial-mocap"].with_(duration=10.0)
    log, truth, _ = sc.generate(1)
    found = estimate_latency(log, sc.model())
    assert found.determined and 0 < found.std < 1e-3
    assert abs(found.latency - 0.005) < 2 * found.std


def test_a_wrench_behind_the_poses_is_a_negative_latency():
    """The wrench 1 ms behind the poses (a sensor's filter): the search covers negative delays."""
    sc = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=10.0, latency=-0.001)
    log, _, _ = sc.generate(2)
    found = estimate_latency(log, sc.model())
    assert found.determined and 0 < found.std < 1e-3 and abs(found.latency + 0.001) < max(4 * found.std, 1e-4)


def test_a_dropped_wrench_sample_is_found_and_placed():
    """One wrench sample dropped at t = 6.667 s while the stamps stay regular: the latency steps by about a
    sample there; calibrate says where and leaves converged False."""
    sc = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=10.0, latency=0.002)
    log, truth, _ = sc.generate(0)
    j = 2 * len(log) // 3
    # the log one sample shorter (its last pose left out), not its last reading repeated: a repeat at the end is a
    # frozen reading (observers.core._frozen), another cause
    dropped = Log(log.t[:-1], log.pose[:-1], np.r_[log.w_hat[:j], log.w_hat[j + 1:]], name="dropped")
    found = estimate_latency(dropped, sc.model())
    assert found.step is not None and not found.determined
    assert abs(found.step["t"] - log.t[j]) < 1.0 and 0.4e-3 < found.step["size"] < 1.6e-3
    cal = calibrate(dropped, truth.payload)
    assert not cal.converged and any("latency changes along the log" in w for w in cal.warnings)
    assert cal.why_unconverged == "the latency changes along the log"


@pytest.mark.slow
def test_the_latency_std_widens_S_std():
    """Estimated, the latency's variance enters S_std (never narrower than with the latency given)."""
    sc = SPATIAL_SCENARIOS["spatial-mocap"].with_(duration=10.0)
    log, truth, _ = sc.generate(3)
    estimated = calibrate(log, truth.payload)
    given = calibrate(log, truth.payload, latency=estimated.latency)
    assert estimated.latency_std > 0 and given.latency_std is None
    assert np.all(np.asarray(estimated.S_std) >= np.asarray(given.S_std) - 1e-15)
    assert np.any(np.asarray(estimated.S_std) > 1.01 * np.asarray(given.S_std))
    # by exactly the latency's share, no more: S_std^2 = S_std_given^2 + (dS/dlatency std)^2 (eq. L4)
    found = estimate_latency(log, sc.model())
    expected = np.sqrt(np.square(given.S_std) + np.square(found.dS_dlatency[:, :6] * found.std))
    np.testing.assert_allclose(estimated.S_std, expected, rtol=1e-6)


def test_a_planar_log_gets_a_fractional_latency_too():
    """The planar case through the same search (its dynamics inverted): 35.4 ms on a 1 kHz log, to a sample
    (the std on planar logs is not held to a z-score here)."""
    sc = get_scenario("real-rig").with_(latency=0.0354, pose_rate=None, duration=20)
    log, _, _ = sc.generate(1)
    found = estimate_latency(log, sc.payload)
    assert found.determined and abs(found.latency - 0.0354) < log.dt


@pytest.mark.parametrize("latency", [-0.0015, 0.0004])
def test_simulate_takes_a_negative_and_fractional_latency(tmp_path, latency):
    from fmscal.analysis.cli import main
    from fmscal.plant import read_truth
    out = tmp_path / "late.csv"
    assert main(["simulate", "--scenario", "spatial-arm", "--duration", "2", "--latency", repr(latency),
                 "--out", str(out)]) == 0
    assert read_truth(out.with_suffix(".truth.json")).latency == latency


def test_a_log_that_cannot_tell_the_delays_apart_is_not_converged():
    """Held attitudes joined by slow moves (spatial-static, 20 s): the cost barely changes with the delay. Seed 1:
    the latency's std is above three samples, it is not determined, and the warning (calibrate's "latency" check
    passes it on, with converged False, as for the step above) says why and suggests --latency. Seed 0 (this
    test's log before eqs. L2, L6 and L7): 3.25 ms off, it was undetermined only because the half window's search
    jumped 10 ms (eq. L5); its std now covers its error."""
    sc = SPATIAL_SCENARIOS["spatial-static"].with_(duration=20.0)
    log, truth, _ = sc.generate(1)
    found = estimate_latency(log, sc.model())
    assert not found.determined and found.std > 3 * log.dt and found.step is None
    (said,) = found.warnings
    assert "latency is not determined" in said and "cannot tell the candidate delays apart" in said \
        and "--latency" in said
    assert found.unresolved == [said]                 # the data's: a cause named elsewhere may explain it
    log, truth, _ = sc.generate(0)
    found = estimate_latency(log, sc.model())
    assert not found.determined or abs(found.latency - truth.latency) < 3 * found.std


def test_a_planar_log_with_30_times_the_noise_gets_no_confident_latency():
    """Issue 46's review: a 20 s paper log with 30x the noise (seed 0) was given 42 +- 0.7 ms for a true 0. The
    cost's curvature there is the noise's (Gauss-Newton's counted the poses' differentiated noise as information,
    eq. L2, and the curvature at the lowest point is within its own noise, eq. L6): not determined, the warning
    says so, and the calibration is not converged for it. The same log at the scenario's own noise keeps its
    latency, within 3 of its std."""
    from fmscal.plant import SCENARIOS
    scenario = SCENARIOS["paper"].with_(duration=20.0)
    log, truth, _ = scenario.generate(0)
    found = estimate_latency(log, scenario.model())
    assert found.determined and abs(found.latency - truth.latency) < 3 * found.std < 3 * log.dt
    log, truth, _ = scenario.with_noise_scaled(30).generate(0)
    found = estimate_latency(log, scenario.model())
    assert not found.determined and found.std == np.inf and found.curvature[0] < 3 * found.curvature[1]
    cal = calibrate(log, truth.payload)
    assert not cal.converged and cal.latency_std is None
    assert cal.why_unconverged == "the log does not determine the pose stream's latency"
    (said,) = [w for w in cal.warnings if "latency" in w]
    assert said.startswith("the pose stream's latency is not determined: the cost's curvature in the delay") \
        and "--latency" in said


def test_a_search_under_two_samples_says_so():
    """A max_latency under two samples leaves rule 2's parabola nothing to stand on: the latency is undetermined
    and the warning says the range searched is too short (not 'no clear minimum')."""
    sc = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=4.0)
    log, _, _ = sc.generate(0)
    found = estimate_latency(log, sc.model(), max_latency=1.4 * log.dt)
    assert not found.determined and any("span under two samples" in w for w in found.warnings)
    assert found.unresolved == []                     # the search's, not the data's
    assert estimate_latency(log, sc.model(), max_latency=10 * log.dt).determined
