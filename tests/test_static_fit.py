"""Pose tables and their static fit: the sensor's sign, gravity's direction, the mounting, coverage (issue 28)."""

import re

import numpy as np
import pytest

from fmscal.observers.payload._static_fit import _exp, fit_static
from fmscal.plant import FmscalError
from fmscal.plant.io._log import LogError
from fmscal.plant.io._pose_table import is_pose_table, read_pose_table, simulate_table, write_pose_table
from fmscal.plant.scenarios._spatial import TOOL

OFFSET = np.array([0.01, -0.02, 0.03, 0.5, -0.3, 0.2])       # N m, N
TILT = _exp(np.radians(10.0) * np.array([1.0, 0.3, 0.0]) / np.linalg.norm([1.0, 0.3, 0.0]))   # a tilted base
MOUNT = _exp(np.radians(7.0) * np.array([0.3, 1.0, 0.5]) / np.linalg.norm([0.3, 1.0, 0.5]))    # a sensor bolted askew
G = np.array([0.0, 0.0, -9.81])


def _angle(R):
    return np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)))


@pytest.fixture(scope="module")
def twenty_seeds():
    """Twelve poses each, gravity along -z: the fits of 20 seeded tables."""
    return [fit_static(simulate_table(TOOL, n=12, seed=seed, offset=OFFSET)) for seed in range(20)]


@pytest.mark.slow
def test_mass_centre_of_mass_and_offset_with_honest_uncertainties(twenty_seeds):
    """Twelve poses, S = I: the z-scores' rms two-sided (the gains estimated with the payload since issue 44);
    converged where the payload's effect is within the rows' scatter (its default tolerance, issue 44: 18 of the
    20 measured, the other two at 1.0 and 1.04 of it, "the cone is covered thinly")."""
    z = []
    for fit in twenty_seeds:
        assert abs(fit.mass - TOOL.mass) < 0.01 * TOOL.mass
        assert np.abs(fit.com - TOOL.com).max() < 2e-3
        assert fit.converged is fit.payload_determined and fit.gravity is None and fit.mounting is None
        assert fit.payload_determined or "the cone is covered thinly" in fit.why_undetermined
        z.append(np.r_[(fit.mass - TOOL.mass) / fit.mass_std, (fit.com - TOOL.com) / fit.com_std,
                       (fit.b - OFFSET) / fit.b_std, (fit.gains[3:] - 1) / fit.gains_std[3:]])
    rms = float(np.sqrt(np.mean(np.square(z))))            # not np.std: a bias would hide in the mean it removes
    assert 0.7 < rms < 1.4, rms                             # 1.13 measured
    assert sum(fit.payload_determined for fit in twenty_seeds) >= 16


def test_the_load_convention_is_named_never_a_negative_mass():
    table = simulate_table(TOOL, n=12, seed=3, offset=OFFSET, reading="load")
    with pytest.raises(FmscalError,
                       match="mass comes out negative .* pass reading=\"load\" \\(on the command line --reading load"):
        fit_static(table)
    fit = fit_static(table, reading="load")
    assert abs(fit.mass - TOOL.mass) < 0.01 * TOOL.mass and fit.reading == "load"
    np.testing.assert_allclose(fit.b, OFFSET, atol=5 * fit.b_std.max())     # of the reading negated, as simulated


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(3))
def test_a_tilted_base_gravity_is_recovered_within_a_fifth_of_a_degree(seed):
    table = simulate_table(TOOL, n=24, seed=seed, gravity=TILT @ G, offset=OFFSET)
    fixed = fit_static(table)                                      # gravity along -z: the data disagree
    fit = fit_static(table, estimate_gravity=True)
    error = np.degrees(np.arccos(np.clip(fit.gravity @ (TILT @ G) / 9.81 ** 2, -1, 1)))
    assert error < 0.2 and 0 < fit.gravity_std_deg < 0.2
    assert np.linalg.norm(fit.gravity) == pytest.approx(9.81)
    assert abs(fit.mass - TOOL.mass) < 0.01 * TOOL.mass
    assert fixed.residual_rms[3:].max() > 10 * fit.residual_rms[3:].max()


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(3))
def test_a_mounting_rotation_is_recovered_within_a_fifth_of_a_degree(seed):
    """... and without --mounting estimate the fit names it with the angle found (7 degrees, measured 6.9 to 7.0),
    never --gravity estimate, and is not converged."""
    table = simulate_table(TOOL, n=24, seed=seed, mounting=MOUNT, offset=OFFSET)
    fit = fit_static(table, estimate_mounting=True)
    assert _angle(fit.mounting.T @ MOUNT) < 0.2
    assert fit.mounting_deg == pytest.approx(7.0, abs=0.2) and 0 < fit.mounting_std_deg < 0.2
    assert np.abs(fit.com - TOOL.com).max() < 2e-3
    assert not any("estimate" in w for w in fit.warnings)
    square = fit_static(table)
    told = [w for w in square.warnings if "--mounting estimate" in w]
    assert not square.converged and len(told) == 1, square.warnings
    assert float(re.search(r"turned ([\d.]+) degrees", told[0]).group(1)) == pytest.approx(7.0, abs=0.2)
    assert not any("--gravity estimate" in w for w in square.warnings)


def test_poses_about_one_axis_leave_gravity_and_the_offset_unseparated():
    """Turns about one sensor axis keep gravity's component along it: with gravity's direction unknown, the
    offset along that axis and the tilt do not separate; the fit says so and is not converged."""
    angles = np.radians(np.linspace(0.0, 330.0, 12))
    q = np.column_stack([np.cos(angles / 2), np.zeros(12), np.sin(angles / 2), np.zeros(12)])    # about y
    tilt = _exp(np.radians(20.0) * np.array([1.0, 0.0, 0.0]))
    table = simulate_table(TOOL, q=q, n=12, seed=0, gravity=tilt @ G, offset=OFFSET)
    fit = fit_static(table, estimate_gravity=True)
    assert not fit.converged and fit.undetermined
    assert any("offset's fy" in words for words in fit.undetermined), fit.undetermined
    assert fit.next_poses and "about its" in fit.next_poses[0]


def test_the_first_suggested_pose_reduces_the_largest_uncertainty():
    """A table of small tilts: the suggestion, recorded in simulation, lowers the payload's largest effect on the
    compensated wrench over the noise, as it said (measured to 61 %, predicted 62 %)."""
    table = simulate_table(TOOL, n=6, seed=4, offset=OFFSET, spread=np.radians(25.0))
    before = fit_static(table)
    words = before.next_poses[0]
    k, axis, angle = _parse(words)
    R = _exp(np.radians(angle) * np.eye(3)["xyz".index(axis)])
    q_new = _quaternion(_rotation(table.q[k - 1]) @ R)
    after = fit_static(simulate_table(TOOL, n=7, seed=4, offset=OFFSET, q=np.vstack([table.q, q_new])))
    worst = lambda f: np.max(f.effect / f.tolerance)                                  # noqa: E731
    predicted = float(words.split("compensated wrench falls to ")[1].split("%")[0]) / 100
    assert worst(after) < 0.8 * worst(before), (words, worst(before), worst(after))
    assert worst(after) / worst(before) == pytest.approx(predicted, abs=0.1)


def _parse(words):
    """``(pose, axis, degrees)`` of "from pose K, turn the tool A degrees about its X axis (...)"."""
    pose = int(words.split("from pose ")[1].split(",")[0])
    angle = float(words.split("turn the tool ")[1].split()[0])
    return pose, words.split("about its ")[1][0], angle


def _rotation(q):
    from fmscal.plant.physics._rigid_body import rotation_matrix
    return np.asarray(rotation_matrix(q))


def _quaternion(R):
    from scipy.spatial.transform import Rotation
    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return np.array([w, x, y, z])


def test_a_table_round_trips_and_bad_tables_are_one_line(tmp_path):
    table = simulate_table(TOOL, n=8, seed=1, offset=OFFSET)
    path = tmp_path / "table.csv"
    write_pose_table(table, path)
    assert is_pose_table(path)
    back = read_pose_table(path)
    np.testing.assert_allclose(back.q, table.q, rtol=1e-15)
    np.testing.assert_allclose(back.w_hat, table.w_hat, rtol=1e-15)
    short = tmp_path / "short.csv"
    short.write_text("\n".join(path.read_text().splitlines()[:4]) + "\n")
    with pytest.raises(LogError, match="at least 4 poses .* got 3"):
        read_pose_table(short)
    bad = tmp_path / "bad.csv"
    lines = path.read_text().splitlines()
    lines[2] = "0.5,0.5,0.5,0.9," + lines[2].split(",", 4)[4]
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(LogError, match="row 2 has norm"):
        read_pose_table(bad)
    lines = path.read_text().splitlines()                 # one cell 1e300 (a hostile review's: an SVD's traceback)
    cells = lines[3].split(",")
    cells[8] = "1e300"
    lines[3] = ",".join(cells)
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(LogError, match=r"^bad.csv: column fy holds 1e\+300 at row 3; values beyond 1e\+09 are not"):
        read_pose_table(bad)


@pytest.mark.slow
def test_an_attitude_only_log_uses_its_held_segments_and_its_uncertainty_covers_a_drift():
    """No positions: only the held segments are used (and said so); with the offset drifting slowly the
    residual-based uncertainty still covers the truth (over 6 seeds, every mass within 3 sigma)."""
    from fmscal.plant.io._pose_table import held_table, simulate_attitude_log
    for seed in range(6):
        log = simulate_attitude_log(TOOL, seed=seed, offset=OFFSET, drift=[0, 0, 0, 0.004, 0.002, -0.004])
        table, used, why = held_table(log)
        assert 10 <= len(table) <= 14 and 0.3 < used < 0.5 and "held segments" in why
        fit = fit_static(table)
        assert abs(fit.mass - TOOL.mass) < 3 * fit.mass_std and fit.mass_std < 0.01 * TOOL.mass
        assert np.abs(fit.com - TOOL.com).max() < 2e-3


def test_an_attitude_log_without_enough_holds_is_one_line():
    from fmscal.plant.io._pose_table import held_table, simulate_attitude_log
    log = simulate_attitude_log(TOOL, poses=3, seed=0)
    with pytest.raises(LogError, match="needs at least 4 held poses"):
        held_table(log)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(3))
def test_a_tilted_base_fitted_with_gravity_along_minus_z_says_to_estimate_it(seed, twenty_seeds):
    """Gravity fixed along -z on a base tilted 10 degrees: the fit names --gravity estimate and is not converged;
    on the untilted tables (twenty seeds) and with gravity estimated it stays silent."""
    table = simulate_table(TOOL, n=24, seed=seed, gravity=TILT @ G, offset=OFFSET)
    fixed = fit_static(table)
    told = [w for w in fixed.warnings if "--gravity estimate" in w]
    assert not fixed.converged and len(told) == 1, fixed.warnings
    assert "times the noise with gravity along -z" in told[0] and "tilted 10 degrees" in told[0]
    assert not any("record more poses" in w or "--mounting estimate" in w for w in fixed.warnings)
    assert not any("--gravity estimate" in w for w in fit_static(table, estimate_gravity=True).warnings)
    assert not any("estimate" in w for fit in twenty_seeds for w in fit.warnings)


@pytest.mark.slow
def test_a_sensor_two_degrees_askew_is_named_on_every_seed(twenty_seeds):
    """Twelve poses, the sensor turned 2 degrees on the tracked frame: --mounting estimate named on each of 20 seeds
    with the angle found (measured 1.9 to 2.2 degrees), --gravity estimate never; on the square sensor's twenty
    tables (the fixture) neither is (measured over 6, 12 and 24 poses: named at 1 degree on 4, 1 and 0 of 20)."""
    axis = np.array([0.3, 1.0, 0.5]) / np.linalg.norm([0.3, 1.0, 0.5])
    for seed in range(20):
        fit = fit_static(simulate_table(TOOL, n=12, seed=seed, mounting=_exp(np.radians(2.0) * axis), offset=OFFSET))
        told = [w for w in fit.warnings if "--mounting estimate" in w]
        assert len(told) == 1 and not any("--gravity estimate" in w for w in fit.warnings), (seed, fit.warnings)
        assert 1.7 < float(re.search(r"turned ([\d.]+) degrees", told[0]).group(1)) < 2.3
    assert not any("estimate" in w for fit in twenty_seeds for w in fit.warnings)


def test_a_tilted_base_and_a_sensor_askew_together_name_both_flags():
    """Twenty-four poses on a base tilted 4 degrees, the sensor turned 3 degrees on the tracked frame: the one line
    names --gravity estimate --mounting estimate with both angles, and with both estimated the fit is silent."""
    tilt = _exp(np.radians(4.0) * np.array([1.0, 0.3, 0.0]) / np.linalg.norm([1.0, 0.3, 0.0]))
    mount = _exp(np.radians(3.0) * np.array([0.3, 1.0, 0.5]) / np.linalg.norm([0.3, 1.0, 0.5]))
    table = simulate_table(TOOL, n=24, seed=0, gravity=tilt @ G, mounting=mount, offset=OFFSET)
    fit = fit_static(table)
    told = [w for w in fit.warnings if "estimate" in w]
    assert not fit.converged and len(told) == 1 and "--gravity estimate --mounting estimate" in told[0], fit.warnings
    assert float(re.search(r"gravity tilted ([\d.]+) degrees", told[0]).group(1)) == pytest.approx(4.0, abs=0.2)
    assert float(re.search(r"turned ([\d.]+) degrees", told[0]).group(1)) == pytest.approx(3.0, abs=0.2)
    free = fit_static(table, estimate_gravity=True, estimate_mounting=True)
    assert not any("estimate" in w for w in free.warnings)


def test_gravity_up_names_the_reading_and_a_base_upside_down():
    """A robot hung from a ceiling (gravity along +z of its base): with gravity estimated the fit cannot tell it
    from a reading of the other sign, and says both, with each flag; told the gravity, it fits the payload."""
    table = simulate_table(TOOL, n=12, seed=0, gravity=-G, offset=OFFSET)
    with pytest.raises(FmscalError, match=r"pointing up .*--reading load.*--gravity 0 0 9.81"):
        fit_static(table, estimate_gravity=True)
    fit = fit_static(table, gravity=-G)
    assert fit.mass == pytest.approx(TOOL.mass, rel=0.01) and not any("estimate" in w for w in fit.warnings)


def _about(axis, degrees):
    """Unit quaternions (scalar first) of turns by ``degrees`` about ``axis``."""
    half = np.radians(np.asarray(degrees, dtype=float)) / 2
    return np.column_stack([np.cos(half), *(np.sin(half) * a for a in axis)])


@pytest.mark.parametrize("q", [_about((0, 0, 0), [0.0] * 8), _about((0, 0, 1), np.arange(0, 360, 30)),
                               _about((0, 0, 1), np.arange(0, 360, 30)) + [0, 1e-3, 0, 0]],
                         ids=["one attitude", "turns about the vertical", "within a tenth of a degree"])
def test_poses_that_do_not_tilt_gravity_are_refused_in_one_line(q):
    from fmscal.observers.payload._static_fit import calibrate_table
    q = q / np.linalg.norm(q, axis=1)[:, None]
    table = simulate_table(TOOL, q=q, n=len(q), seed=1, offset=OFFSET)
    for fit in (fit_static, lambda t: fit_static(t, estimate_mounting=True),
                lambda t: calibrate_table(t, TOOL.mass, TOOL.com)):
        with pytest.raises(FmscalError, match=r"do not tilt gravity in the sensor frame \(all within 0\.\d degrees.*"
                                              "cannot be separated; hold the tool in at least four attitudes"):
            fit(table)
    # held at one attitude, gravity's direction unknown too: still refused
    if np.ptp(q, axis=0).max() == 0:
        with pytest.raises(FmscalError, match="do not tilt gravity"):
            fit_static(table, estimate_gravity=True)


@pytest.mark.slow
def test_poses_tilted_two_degrees_are_fitted_not_refused():
    """Just above the threshold (a cone of 2 degrees): a fit, with its weak directions named in words."""
    q = np.vstack([_about((1, 0, 0), [0.0, 2.0, -2.0]), _about((0, 1, 0), [2.0, -2.0])])
    fit = fit_static(simulate_table(TOOL, q=q, n=len(q), seed=1, offset=OFFSET))
    assert 1.0 < fit.cone_deg < 3.0 and not fit.converged


def test_a_weak_direction_of_one_parameter_reads_in_the_singular():
    from fmscal.observers.payload._coverage import describe
    names = ("m", "com_x", "com_y", "com_z")
    assert describe(names, np.array([0.0, 0.0, 0.0, 1.0])).startswith("the centre of mass along z is not determined")
    assert describe(names, np.array([0.7, 0.0, 0.7, 0.0])).startswith(
        "the mass and the centre of mass along y are not separated")


@pytest.mark.slow
@pytest.mark.parametrize("flag", ["estimate_gravity", "estimate_mounting"])
@pytest.mark.parametrize("text", ["False", "no", 0])
def test_a_flag_given_as_text_or_a_number_is_refused_not_taken_as_true(flag, text):
    # "False" is a true Python value: taken as given, it would fit gravity or the mounting unasked
    table = simulate_table(TOOL, n=12, seed=0, offset=OFFSET)
    with pytest.raises(FmscalError, match=f"^{flag} must be True or False; got"):
        fit_static(table, **{flag: text})
    assert fit_static(table, **{flag: False}).converged         # a boolean is taken


def test_a_row_copied_counts_once():
    """Rows that repeat earlier rows to the last digit (a table pasted twice) are copies, not poses: the fit is
    the distinct rows', said in a warning (it was a mass's sd smaller by sqrt(2)); too few distinct rows are
    refused, naming the copies. A hostile review's case."""
    from fmscal.plant.io import PoseTable

    table = simulate_table(TOOL, n=8, seed=3, offset=OFFSET)
    once = fit_static(table)
    twice = fit_static(PoseTable(np.r_[table.q, table.q[:5]], np.r_[table.w_hat, table.w_hat[:5]], name="pasted"))
    assert twice.mass == once.mass and twice.mass_std == once.mass_std
    np.testing.assert_array_equal(twice.com_std, once.com_std)
    assert [w for w in twice.warnings if "rows 9, 10, 11, 12, 13 repeat earlier rows" in w]
    assert not [w for w in once.warnings if "repeat" in w]
    three = PoseTable(np.r_[table.q[:3], table.q[:3]], np.r_[table.w_hat[:3], table.w_hat[:3]], name="three")
    with pytest.raises(FmscalError, match=r"three: 3 distinct poses \(rows 4, 5, 6 the same as earlier rows"):
        fit_static(three)
