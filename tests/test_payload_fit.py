"""identify_payload: the practitioners' job (mass, centre of mass, inertia, offset) with S known (issue 22)."""

import re

import numpy as np
import pytest

from fmscal.observers.payload._payload_fit import identify_payload
from fmscal.plant import FmscalError
from fmscal.plant.scenarios._spatial import SPATIAL_SCENARIOS


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_arm_gives_mass_within_1_percent_and_centre_of_mass_within_2_mm(seed):
    log, truth, _ = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=30.0).generate(seed)
    fit = identify_payload(log, S=truth.S_at(0.0))
    p = truth.payload
    assert abs(fit.mass - p.mass) < 0.01 * p.mass
    assert np.abs(fit.com - np.array(p.com)).max() < 2e-3
    assert np.abs(fit.inertia - np.array(p.inertia)).max() < 0.02 * np.mean(p.inertia[:3])      # products too
    assert np.abs(fit.b - truth.offset).max() < 0.02 * np.abs(truth.offset).max()
    # the uncertainties are of the error's size (not a thousand times too small or too large)
    z = np.abs(np.r_[fit.mass - p.mass, fit.com - p.com] / np.r_[fit.mass_std, fit.com_std])
    assert z.max() < 5 and 1e-5 < fit.mass_std / p.mass < 1e-2
    assert np.all((1e-7 < fit.com_std) & (fit.com_std < 1e-4))          # m: neither nil nor above the error allowed
    assert fit.converged and not fit.warnings


@pytest.mark.slow
def test_static_poses_give_mass_and_centre_of_mass_but_not_the_inertia():
    log, truth, _ = SPATIAL_SCENARIOS["spatial-static"].generate(0)
    fit = identify_payload(log, S=truth.S_at(0.0))
    assert abs(fit.mass - truth.payload.mass) < 0.01 * truth.payload.mass
    assert np.abs(fit.com - np.array(truth.payload.com)).max() < 2e-3
    assert fit.inertia is None and fit.inertia_std is None and not fit.converged
    assert any("inertia is not determined" in w and "angular acceleration" in w for w in fit.warnings)
    assert fit.to_dict()["inertia"] is None


@pytest.mark.slow
def test_an_unknown_S_biases_the_mass_and_the_known_one_removes_it():
    """With S = I on a sensor with cross-talk the mass is off by the gains' error; told S, it is not."""
    log, truth, _ = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=20.0, crosstalk=0.1).generate(4)
    told, naive = identify_payload(log, S=truth.S_at(0.0)), identify_payload(log)
    error = lambda fit: abs(fit.mass - truth.payload.mass) / truth.payload.mass
    assert error(told) < 0.002 < error(naive)


def test_a_planar_log_is_refused():
    from fmscal.plant import get_scenario
    log, _, _ = get_scenario("paper").with_(duration=1.0).generate(0)
    with pytest.raises(FmscalError, match="spatial log"):
        identify_payload(log)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_a_tilted_base_with_gravity_along_minus_z_says_to_estimate_it(seed):
    """A base tilted 5 degrees: with gravity along -z the log's fit names --gravity estimate (never --mounting
    estimate: the arm's turns about every axis tell a turn of the world from one on the tool) and is not
    converged; the same log on a level base, and the tilted one with gravity estimated, do not."""
    from fmscal.observers.payload._static_fit import _exp
    tilted = tuple(_exp(np.radians(5.0) * np.array([1.0, 0.0, 0.0])) @ np.array([0.0, 0.0, -9.81]))
    scenario = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=8.0)
    log, truth, _ = scenario.with_(gravity=tilted).generate(seed)
    fit = identify_payload(log, S=truth.S_at(0.0))
    assert not fit.converged and "--gravity estimate" in fit.warnings[0] and "tilted 5 degrees" in fit.warnings[0]
    assert not any("--mounting estimate" in w for w in fit.warnings)
    free = identify_payload(log, S=truth.S_at(0.0), estimate_gravity=True)
    assert not any("--gravity estimate" in w or "--mounting estimate" in w for w in free.warnings)
    level, truth, _ = scenario.generate(seed)
    assert not any("estimate" in w for w in identify_payload(level, S=truth.S_at(0.0)).warnings)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_a_sensor_bolted_askew_names_the_mounting_not_gravity(seed):
    """The sensor turned 7 degrees on the tracked frame, gravity along -z: the log's fit names --mounting estimate
    with the angle found (7 degrees, measured 6.98 to 7.0), not --gravity estimate, and is not converged; with the
    mounting estimated it is silent."""
    from scipy.spatial.transform import Rotation

    from fmscal.observers.payload._static_fit import _exp
    mount = _exp(np.radians(7.0) * np.array([0.3, 1.0, 0.5]) / np.linalg.norm([0.3, 1.0, 0.5]))
    log, truth, _ = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=8.0).generate(seed)
    sensor = Rotation.from_quat(np.roll(log.pose[:, :4], -1, axis=1))          # the poses are the tracked frame's
    log.pose[:, :4] = np.roll((sensor * Rotation.from_matrix(mount.T)).as_quat(), 1, axis=1)
    fit = identify_payload(log, S=truth.S_at(0.0))
    assert not fit.converged and "--mounting estimate" in fit.warnings[0], fit.warnings
    assert float(re.search(r"turned ([\d.]+) degrees", fit.warnings[0]).group(1)) == pytest.approx(7.0, abs=0.2)
    assert not any("--gravity estimate" in w for w in fit.warnings)
    free = identify_payload(log, S=truth.S_at(0.0), estimate_mounting=True)
    assert not any("--mounting estimate" in w or "--gravity estimate" in w for w in free.warnings)


@pytest.mark.slow
def test_a_tilted_base_and_a_sensor_askew_together_name_both_flags():
    """A base tilted 4 degrees and the sensor turned 3 degrees on the tracked frame: neither rotation alone explains
    the residuals (each leaves the other's), both together do: the one line names --gravity estimate --mounting
    estimate with both angles found, and the fit is not converged; with both estimated it is silent."""
    from scipy.spatial.transform import Rotation

    from fmscal.observers.payload._static_fit import _exp
    tilted = tuple(_exp(np.radians(4.0) * np.array([1.0, 0.0, 0.0])) @ np.array([0.0, 0.0, -9.81]))
    mount = _exp(np.radians(3.0) * np.array([0.3, 1.0, 0.5]) / np.linalg.norm([0.3, 1.0, 0.5]))
    log, truth, _ = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=8.0, gravity=tilted).generate(0)
    sensor = Rotation.from_quat(np.roll(log.pose[:, :4], -1, axis=1))
    log.pose[:, :4] = np.roll((sensor * Rotation.from_matrix(mount.T)).as_quat(), 1, axis=1)
    fit = identify_payload(log, S=truth.S_at(0.0))
    assert not fit.converged and "--gravity estimate --mounting estimate" in fit.warnings[0], fit.warnings
    assert float(re.search(r"gravity tilted ([\d.]+) degrees", fit.warnings[0]).group(1)) == pytest.approx(4.0, abs=0.2)
    assert float(re.search(r"turned ([\d.]+) degrees", fit.warnings[0]).group(1)) == pytest.approx(3.0, abs=0.2)
    free = identify_payload(log, S=truth.S_at(0.0), estimate_gravity=True, estimate_mounting=True)
    assert not any("--mounting estimate" in w or "--gravity estimate" in w for w in free.warnings)


def test_where_both_rotations_explain_the_lower_residuals_are_named():
    """rotation_warning's choice: each explains (residuals 10 and 20 times lower, angles far beyond 5 sigmas); the
    better one is named alone, either way round; neither explains: None."""
    from fmscal.observers.payload._static_fit import rotation_warning
    g = [0.0, 0.0, -9.81]
    tilted = np.array([0.0, np.sin(np.radians(4.0)), -np.cos(np.radians(4.0))])
    both = rotation_warning(1.0, g, (0.1, tilted, 0.1), (0.05, 6.0, 0.1))
    assert "--mounting estimate" in both and "turned 6 degrees" in both and "--gravity" not in both
    both = rotation_warning(1.0, g, (0.05, tilted, 0.1), (0.1, 6.0, 0.1))
    assert "--gravity estimate" in both and "tilted 4 degrees" in both and "--mounting" not in both
    assert rotation_warning(1.0, g, (0.5, tilted, 0.1), (0.5, 6.0, 0.1)) is None            # residuals fall 2x
    assert rotation_warning(1.0, g, (0.1, tilted, 1.0), (0.1, 6.0, 2.0)) is None            # angles within 5 sigmas


@pytest.fixture(scope="module")
def twenty_logs():
    """Twenty seeded 20 s spatial-arm logs and their truths; the shorter logs are their first 5 and 10 s."""
    return [SPATIAL_SCENARIOS["spatial-arm"].with_(duration=20.0).generate(seed)[:2] for seed in range(20)]


@pytest.mark.slow
@pytest.mark.parametrize("duration", [5.0, 10.0, 20.0])
def test_the_mass_and_centre_of_mass_uncertainties_of_a_log_hold_over_twenty_seeds(twenty_logs, duration):
    """z-scores of mass and centre of mass on spatial-arm logs (S told), 20 seeds: their rms (not np.std, which
    removes a bias with the mean) within [0.7, 1.4]. Measured 1.13 at 5 s, 1.20 at 10 s and 1.00 at 20 s with the
    blocks of eq. (U2) (0.2 s here: white residuals); with the former fixed 1 s blocks and no small-sample factor
    1.84, 1.48 and 1.11 (few blocks: the sandwich claims too little)."""
    z = []
    for log, truth in twenty_logs:
        fit, p = identify_payload(log.between(0.0, duration), S=truth.S_at(0.0)), truth.payload
        z.append(np.r_[(fit.mass - p.mass) / fit.mass_std, (fit.com - np.array(p.com)) / fit.com_std])
    rms = float(np.sqrt(np.mean(np.square(z))))
    assert 0.7 < rms < 1.4, rms


def test_the_blocks_follow_the_residuals_correlation_time():
    """White residuals get blocks of the smoothing window; residuals of a first-order process with a 50-sample
    time constant (integrated correlation time (1 + a) / (1 - a) = 99 samples, a = exp(-1/50)) get five of it, within
    a fifth (the estimate's noise over 20000 samples); fewer than ten blocks are said."""
    from fmscal.observers.batch._cluster_covariance import block_length, correlation_time, few_blocks, time_blocks
    rng = np.random.default_rng(0)
    white = rng.standard_normal((20000, 6))
    assert 0.9 < correlation_time(white) < 1.2
    assert block_length(white, 1e-3, 0.2) == 0.2
    a = np.exp(-1 / 50)
    slow = np.zeros_like(white)
    for k in range(1, len(white)):
        slow[k] = a * slow[k - 1] + white[k]
    tau = (1 + a) / (1 - a)
    assert 0.8 * tau < correlation_time(slow) < 1.2 * tau
    assert 0.8 * 5 * tau * 1e-3 < block_length(slow, 1e-3, 0.2) < 1.2 * 5 * tau * 1e-3
    blocks, length = time_blocks(slow[:2000], np.arange(2000) * 1e-3, 0.2)
    assert 0.4 < length < 0.6 and "only 4 blocks" in few_blocks(blocks, length)
    assert few_blocks(*time_blocks(white, np.arange(20000) * 1e-3, 0.2)) is None


ROLLS = (0.0, 0.26, -0.26, 0.13)            # rad: attitudes held 3 s, turned about the tracked frame's x alone


def _about_x(*more):
    """spatial-static's held attitudes and moves through ROLLS (yaw and pitch nil), then ``more`` (ZYX angles)."""
    targets = tuple((0.0, 0.0, r) for r in ROLLS) + tuple(tuple(m) for m in more)
    return SPATIAL_SCENARIOS["spatial-static"].with_(targets=targets, duration=8.0 * len(targets) - 5.0,
                                                     crosstalk=0.0)


@pytest.mark.slow
def test_a_log_turned_about_one_axis_names_its_narrow_cone_and_a_pose_that_helps():
    """Held attitudes turned +-15 degrees about x alone: a cone of 16 degrees (measured 16.4), the inertia about
    the other axes named as what the log leaves, the force gains not determined (gravity never along x: what the
    motion tells of the x gain, the smoothed poses bias; measured 1.53 +- 0.08 before issue 44's rule), so the
    payload is not determined; the first suggested pose, recorded in simulation (moved to and held like the
    others), lowers the payload's effect on the compensated wrench to within the tolerance (measured 0.25 N to
    0.001 N) and widens the cone past 30 degrees (measured 41)."""
    from scipy.spatial.transform import Rotation

    from fmscal.observers.payload._coverage import rotation
    from fmscal.plant.physics._rigid_body import rotation_matrix
    log, _, _ = _about_x().generate(0)
    before = identify_payload(log)                              # S = I: no crosstalk simulated
    assert 14.0 < before.cone_deg < 20.0 and not before.converged and not before.payload_determined
    assert len(before.undetermined) == 1 and all(f"I{a}" in before.undetermined[0] for a in ("yy", "zz", "yz"))
    assert "by this log" in before.undetermined[0] and "about more axes" in before.undetermined[0]
    assert any(w.startswith("the force gains are not determined by this log (x +- ") and "along x" in w
               for w in before.warnings), before.warnings
    assert np.all(np.isinf(before.gains_std[3:])) and not np.all(before.effect <= before.tolerance)
    words = before.next_poses[0]
    assert "and hold it 3 s (the payload's largest effect on the compensated wrench falls to" in words, words
    at = float(re.search(r"from the attitude at t = ([\d.]+) s", words).group(1))
    angle = float(re.search(r"turn the tool ([+-][\d.]+) degrees", words).group(1))
    axis = "xyz".index(re.search(r"about its (\w) axis", words).group(1))
    k = int(np.argmin(np.abs(log.t - at)))
    R = np.asarray(rotation_matrix(log.pose[k, :4])) @ rotation(np.radians(angle) * np.eye(3)[axis])
    after = identify_payload(_about_x(Rotation.from_matrix(R).as_euler("ZYX")).generate(0)[0])
    assert after.payload_determined and np.all(after.effect < 0.1 * after.tolerance), (words, after.effect)
    assert after.cone_deg > 30.0 and before.to_dict()["next_poses"] == before.next_poses


@pytest.mark.parametrize("flag", ["estimate_gravity", "estimate_mounting"])
def test_a_flag_given_as_text_is_refused_before_any_work(flag):
    # "no" is a true Python value: refused at the boundary, before any fitting
    log, _ = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=2.0).generate(0)[:2]
    with pytest.raises(FmscalError, match=f"^{flag} must be True or False; got 'no'"):
        identify_payload(log, **{flag: "no"})


def test_zero_gravity_is_refused_in_one_line_as_fit_static_refuses_it():
    # a review found a LinAlgError traceback here, where the command line and fit_static refuse it
    log, _ = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=2.0).generate(0)[:2]
    with pytest.raises(FmscalError, match="^gravity must not be zero$"):
        identify_payload(log, gravity=(0.0, 0.0, 0.0))


def test_force_gains_that_differ_are_estimated_and_named():
    """spatial-weak with S = I assumed, on a sensor with cross-talk (issue 37: 8 sigma off, no warning; then the
    axes' own masses widened the mass, eqs. P1, P2): the force gains are estimated with the payload (issue 44),
    the line says they differ and names S, the gains and the mass (in the gains' mean units) within 4 sigma of
    the truth's (measured 2.3 and 2.1: the cross-talk the gains do not hold), not converged (a cone of 5
    degrees); with the true S given, no such line and the gains within 4 sigma of one."""
    log, truth, _ = SPATIAL_SCENARIOS["spatial-weak"].with_(duration=20.0).generate(0)
    fit = identify_payload(log)
    said = [w for w in fit.warnings if w.startswith("the force gains differ between axes")]
    assert len(said) == 1 and said[0].endswith("S = I may be off: calibrate S for the cross-talk")
    assert not fit.converged and any("cone of only" in w for w in fit.warnings)
    true_gains = np.diag(truth.S_at(0.0))[3:]
    k = true_gains.mean()
    assert np.all(np.abs(fit.gains[3:] - true_gains / k) < 4 * fit.gains_std[3:])
    assert abs(fit.mass - truth.payload.mass / k) < 4 * fit.mass_std
    right = identify_payload(log, S=truth.S_at(0.0))
    assert not any("force gains" in w for w in right.warnings)
    assert np.all(np.abs(right.gains[3:] - 1) < 4 * right.gains_std[3:])
    assert abs(right.mass - truth.payload.mass) < 4 * right.mass_std


def test_the_misfit_line_is_held_back_only_by_a_rotation_named():
    """The force residuals far above the noise are said unless the rotation check named a flag; another warning
    that happens to hold the word "estimate" does not hold it back (it did: the check matched the word)."""
    from types import SimpleNamespace

    from fmscal.observers.payload._payload_fit import _check_misfit
    y = np.random.default_rng(0).normal(0.0, 0.05, (2000, 6))
    for named, said in ((False, True), (True, False)):
        fit = SimpleNamespace(residual_rms=np.full(6, 0.5), warnings=["the gravity direction estimated is rough"],
                              converged=True, cone_deg=90.0)
        _check_misfit(fit, y, True, named)
        assert any("10 times the reading's noise" in w and w.endswith("S = I may be wrong: calibrate S")
                   for w in fit.warnings) is said
        assert fit.converged is not said
