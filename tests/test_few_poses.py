"""Few held poses (issue 37): Student-t sigmas, the fit with gravity fixed deciding the reading's sign, the sign told
from a mounting turned half a turn, and the fewest poses each estimated rotation needs."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fmscal.observers.payload import fit_static, min_poses, rotations_unresolved
from fmscal.observers.payload._static_fit import _exp
from fmscal.plant import FmscalError
from fmscal.plant.io._pose_table import simulate_table
from fmscal.plant.scenarios._spatial import TOOL

OFFSET = np.array([0.01, -0.02, 0.03, 0.5, -0.3, 0.2])       # N m, N
G = np.array([0.0, 0.0, -9.81])


def _askew_table(n, seed, reading="reaction"):
    """``n`` poses on a base tilted 10 degrees (rms) with the sensor turned 10 degrees (rms) on the tracked frame."""
    rng = np.random.default_rng(1000 + seed)
    tilt = _exp(np.radians(10.0) * rng.normal(size=3) / np.sqrt(3))
    mount = _exp(np.radians(10.0) * rng.normal(size=3) / np.sqrt(3))
    return simulate_table(TOOL, n=n, seed=seed, offset=OFFSET, gravity=tilt @ G, mounting=mount,
                          reading=reading), tilt @ G, mount


def _z(fit, gravity, mount):
    """The z-scores of the mass, the centre of mass, the mounting's three angles and gravity's two."""
    k = list(fit.names).index("mount_x")
    error = Rotation.from_matrix(mount.T @ fit.mounting).as_rotvec()        # M_hat = M exp(error)
    z_mount = error / np.sqrt(np.diag(fit.cov)[k:k + 3])
    tilt = np.arccos(np.clip(fit.gravity @ gravity / np.linalg.norm(gravity) ** 2, -1.0, 1.0))
    z_gravity = tilt / np.radians(fit.gravity_std_deg) / np.sqrt(2)        # the rms of the two angles' z-scores
    return np.r_[(fit.mass - TOOL.mass) / fit.mass_std, (fit.com - TOOL.com) / fit.com_std, z_mount,
                 z_gravity, z_gravity]


def test_the_fewest_poses_each_rotation_needs():
    """Eq. N4: three forces a pose, their noise measured beyond two degrees of freedom."""
    assert min_poses() == 3 and min_poses(estimate_gravity=True) == 3
    assert min_poses(estimate_mounting=True) == 4 and min_poses(estimate_gravity=True, estimate_mounting=True) == 4
    for gravity in (False, True):          # the count is the fewest N with 3 N - p_f > 2 (eq. N4), both ways
        for mounting in (False, True):
            p_f, n = 4 + 2 * gravity + 3 * mounting, min_poses(gravity, mounting)
            assert 3 * n - p_f > 2 >= 3 * (n - 1) - p_f


@pytest.mark.parametrize("seed", [6, 11, 17, 28])
def test_four_poses_whose_first_start_found_gravity_up_are_fitted_not_sent_to_the_load_convention(seed):
    """Four reaction-convention poses on which the linear start put gravity up (refused before with 'pass --reading
    load'): the fit from gravity's given direction is kept, and no line names the load convention."""
    table, gravity, mount = _askew_table(4, seed)
    fit = fit_static(table, estimate_gravity=True, estimate_mounting=True)
    assert fit.gravity @ gravity > 0 and fit.mounting_deg < 45
    assert not any("--reading" in w or "reading=" in w for w in fit.warnings)
    assert np.all(np.abs(_z(fit, gravity, mount)) < 5)


@pytest.mark.parametrize("seed", [11, 28])
def test_four_load_poses_near_one_plane_are_not_a_converged_half_turn(seed):
    """Load-convention poses fitted as reaction, the mounting estimated: before, a mounting of 175 and 167 degrees,
    converged. Their gravity directions lie near one plane, where a reflection is a half turn: refused, or not
    converged with the line that says so."""
    table, _, _ = _askew_table(4, seed, reading="load")
    try:
        fit = fit_static(table, estimate_gravity=True, estimate_mounting=True)
    except FmscalError as err:
        assert "--reading load" in str(err)
        return
    assert not fit.converged
    assert any("half a turn" in w for w in fit.warnings), fit.warnings


def test_the_unresolved_rotations_line_never_names_the_other_convention():
    line = rotations_unresolved("t.csv", 4, 1.2)
    assert "1.2 kg" in line and "load" not in line and "reading" in line


@pytest.mark.slow
def test_six_poses_sigmas_cover_their_errors():
    """Twelve seeds of six poses, gravity and the mounting estimated: the z-scores' rms two-sided (1.10 measured;
    the statistics over 200 seeds are the slow test's)."""
    z = [_z(fit_static(table, estimate_gravity=True, estimate_mounting=True), gravity, mount)
         for table, gravity, mount in (_askew_table(6, seed) for seed in range(12))]
    rms = float(np.sqrt(np.mean(np.square(z))))
    assert 0.7 < rms < 1.35, rms


@pytest.mark.slow
def test_four_to_eight_poses_z_scores_and_how_many_are_left_unconverged():
    """200 tables, 40 each of 4 to 8 poses, gravity and the mounting estimated: the z-scores' rms (mass, centre of
    mass, mounting, gravity) within [0.8, 1.25] at each count and over all; at 8 poses at most 10 % refused or not
    converged, fewer poses leaving more (converged asks the payload determined, issue 44's effect rule; left 34,
    35, 22, 6, 2 of 40 at 4 to 8 poses when it came). Before issue 37: the mass's rms 1.9 at 4 and 5 poses, 5 % of
    reaction tables sent to --reading load."""
    z, left = {}, {}
    for n in range(4, 9):
        z[n], left[n] = [], 0
        for seed in range(40):
            table, gravity, mount = _askew_table(n, seed)
            try:
                fit = fit_static(table, estimate_gravity=True, estimate_mounting=True)
            except FmscalError:
                left[n] += 1
                continue
            left[n] += not fit.converged
            z[n].append(_z(fit, gravity, mount))
    every = np.concatenate([np.ravel(v) for v in z.values()])
    rms = {n: float(np.sqrt(np.mean(np.square(v)))) for n, v in z.items()}
    assert 0.8 < float(np.sqrt(np.mean(every ** 2))) < 1.25, rms
    assert all(0.8 < r < 1.25 for r in rms.values()), rms
    # converged needs the payload determined too (its effect on the compensated wrench within the tolerance, issue
    # 44): with gravity and the mounting estimated, few poses leave it beyond at 4-7 poses; at 8, the most
    assert left[8] <= 4 and all(left[n] >= left[n + 1] - 4 for n in range(4, 8)), left
