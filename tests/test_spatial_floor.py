"""The maximum-likelihood floor of a spatial log (issue 22): honest, at least as good as the reference, cheap.

The twenty seeds are simulated and fitted once (a module fixture, marked
slow with the tests that read it); the shorter checks run on their own logs.
"""

import numpy as np
import pytest

from fmscal.observers import make_observer
from fmscal.observers.batch._inverse_dynamics import fit_inverse_dynamics
from fmscal.observers.batch._max_likelihood import fit_max_likelihood
from fmscal.plant import SpatialModel
from fmscal.plant.scenarios._spatial import SPATIAL_SCENARIOS

ARM = SPATIAL_SCENARIOS["spatial-arm"]
SEEDS = range(20)


def _E(S_hat, S, scale=None):
    """E of eq. (16) in SI units; with ``scale`` (each reading component's spread), unit-free: ``D^-1 (I - S_hat
    S^-1) D``, each component in its own scale."""
    D = np.ones(6) if scale is None else np.asarray(scale)
    return float(np.linalg.norm((np.eye(6) - S_hat @ np.linalg.inv(S)) * D[None, :] / D[:, None], 2))


@pytest.fixture(scope="module")
def twenty_arms():
    """The floor and the reference fit on 20 seeds of a 20 s ``spatial-arm``: z-scores and E."""
    scenario = ARM.with_(duration=20.0)
    model = SpatialModel(scenario.payload, scenario.gravity)
    z_S, z_b, E_floor, E_ref, z_ref = [], [], [], [], []
    for seed in SEEDS:
        log, truth, _ = scenario.generate(seed)
        S = truth.S_at(log.t[-1])
        fit = fit_max_likelihood(log, model, offset=True)
        ref = fit_inverse_dynamics(log, scenario.payload, scenario.gravity)
        z_S.append(((fit.S_hat - S) / fit.S_std).ravel())
        z_b.append((fit.b - truth.offset) / fit.b_std)
        scale = np.std(log.w_hat, axis=0)
        E_floor.append([_E(fit.S_hat, S), _E(fit.S_hat, S, scale)])
        E_ref.append([_E(ref.S_hat, S), _E(ref.S_hat, S, scale)])
        z_ref.append(np.r_[((ref.S_hat - S) / ref.S_std).ravel(), (ref.b - truth.offset) / ref.b_std])
    return np.array(z_S), np.array(z_b), np.array(E_floor), np.array(E_ref), np.array(z_ref)


@pytest.mark.slow
def test_the_floor_uncertainty_is_honest_over_20_seeds(twenty_arms):
    z_S, z_b, _, _, _ = twenty_arms
    # measured: 1.01 for S, 1.12 for the offset
    assert 0.8 <= z_S.std() <= 1.25 and abs(z_S.mean()) < 0.15
    assert 0.8 <= z_b.std() <= 1.25 and abs(z_b.mean()) < 0.4


@pytest.mark.slow
def test_the_floor_uncertainty_is_honest_on_noisy_attitudes():
    """spatial-mocap (0.1 degree attitudes at 200 Hz, 2 % of frames dropped; no latency), 8 seeds of 20 s: the
    z-scores' rms of S measured 1.01 (1.19 while the step's end took its acceleration at the nominal motion, which
    left half of the attitude error's coupling into the acceleration out of the linearisation)."""
    scenario = SPATIAL_SCENARIOS["spatial-mocap"].with_(duration=20.0, latency=0.0)
    model = SpatialModel(scenario.payload, scenario.gravity)
    z = []
    for seed in range(8):
        log, truth, _ = scenario.generate(seed)
        fit = fit_max_likelihood(log, model, offset=True)
        z.append(((fit.S_hat - truth.S_at(log.t[-1])) / fit.S_std).ravel())
    rms = float(np.sqrt(np.mean(np.square(z))))
    assert 0.8 <= rms <= 1.12, rms


@pytest.mark.slow
def test_the_reference_fits_uncertainty_is_honest_over_20_seeds(twenty_arms):
    """Least squares' S_std and b_std (cluster-robust over blocks of five correlation times of its residuals, with
    the small-sample factor): the z-scores' rms measured 1.09 for S and 1.18 for b (1.18 and 1.45 with fixed 1 s
    blocks and no small-sample factor)."""
    z_ref = twenty_arms[4]
    rms_S, rms_b = np.sqrt(np.mean(z_ref[:, :36] ** 2)), np.sqrt(np.mean(z_ref[:, 36:] ** 2))
    assert 0.8 <= rms_S <= 1.25 and 0.8 <= rms_b <= 1.4, (rms_S, rms_b)


@pytest.mark.slow
def test_the_floor_is_not_beaten_by_the_reference_fit(twenty_arms):
    """Median over 20 seeds: the floor ahead, in SI units (measured 0.93x) and each reading component in its
    own scale (0.71x); seed by seed the reference is luckier on a few, by at most 1.17x (measured)."""
    _, _, E_floor, E_ref, _ = twenty_arms
    ratio = np.median(E_floor, axis=0) / np.median(E_ref, axis=0)
    assert 0.3 < ratio[0] <= 1.0 and 0.3 < ratio[1] <= 0.85, ratio
    assert np.all(E_floor <= 1.2 * E_ref), np.c_[E_floor, E_ref]
    # the check: over 3 seeds, the floor and least squares (the reference fit) within 1.3x of each other
    three = np.median(E_floor[:3, 0]) / np.median(E_ref[:3, 0])
    assert 1 / 1.3 <= three <= 1.3, three


@pytest.fixture(scope="module")
def arm_log():
    log, truth, _ = ARM.with_(duration=20.0).generate(3)
    return log, truth, SpatialModel(ARM.payload, ARM.gravity)


def test_the_floor_runs_behind_the_observer_contract(arm_log):
    log, truth, model = arm_log
    result = make_observer("max-likelihood", model, settings={"offset": True}).run(log)
    assert result.S_hat.shape == result.S_std.shape == (6, 6) and result.b.shape == result.b_std.shape == (6,)
    assert result.S_hat_history.shape == (len(log), 6, 6) and result.x_hat_history.shape == (len(log), 13)
    assert result.converged and result.warnings == [] and result.info["undetermined"] == []
    z = (result.S_hat - truth.S_at(log.t[-1])) / result.S_std
    assert np.abs(z).max() < 5
    # the motion the fit shows follows the poses to about their noise
    from fmscal.observers.batch._linearised_floor import configuration_residuals
    residual = configuration_residuals(model, result.x_hat_history, log.pose)
    assert 0.5 * ARM.position_sd < np.sqrt(np.mean(residual[:, :3] ** 2)) < 1.5 * ARM.position_sd
    assert 0.5 * ARM.angle_sd < np.sqrt(np.mean(residual[:, 3:] ** 2)) < 1.5 * ARM.angle_sd


def test_the_compiled_floor_matches_casadis_virtual_machine():
    """The same step (the payload and the gravity read at run time), compiled and on casadi's virtual machine;
    that step's dynamics are the numbers' own (``tests/test_model.py``)."""
    log, _, _ = ARM.with_(duration=0.6).generate(1)
    model = SpatialModel(ARM.payload, ARM.gravity)
    fast = fit_max_likelihood(log, model, offset=True)
    slow = fit_max_likelihood(log, model, offset=True, compiled=False)
    np.testing.assert_allclose(slow.information, fast.information, rtol=1e-9, atol=0)
    np.testing.assert_allclose(slow.x_history, fast.x_history, rtol=0, atol=1e-9)
    np.testing.assert_allclose(slow.S_aug, fast.S_aug, rtol=1e-6, atol=1e-9)


@pytest.mark.slow
def test_static_poses_leave_directions_undetermined_and_not_converged():
    scenario = SPATIAL_SCENARIOS["spatial-static"].with_(duration=40.0)
    log, _, _ = scenario.generate(0)
    result = make_observer("max-likelihood", SpatialModel(scenario.payload, scenario.gravity),
                           settings={"offset": True}).run(log)
    assert not result.converged and len(result.info["undetermined"]) >= 2
    assert any("angular acceleration" in w for w in result.warnings)
    assert all(np.isclose(np.linalg.norm(d), 1.0) for d in result.info["undetermined"])


def test_the_planar_only_observer_refuses_a_spatial_model_in_one_line():
    """The high-gain reconstruction is planar; the adaptive default runs in 3D (tests/test_spatial_adaptive.py)."""
    from fmscal.plant.numerics._errors import FmscalError
    model = SpatialModel(ARM.payload)
    with pytest.raises(FmscalError, match="spatial"):
        make_observer("high-gain", model)


@pytest.fixture(scope="module")
def mujoco_arm():
    """20 s of ``spatial-arm`` integrated by MuJoCo (tests/mujoco_log.py), and fmscal's own log of the same draw."""
    pytest.importorskip("mujoco")                 # the [test] extra installs it; on CI a skip fails
    from mujoco_log import mujoco_log
    scenario = ARM.with_(duration=20.0)
    log, S, b = mujoco_log(scenario, seed=4)
    own, truth, _ = scenario.generate(4)
    return scenario, log, S, b, own, truth


@pytest.mark.slow
def test_a_log_written_by_mujoco_calibrates_at_the_floor(mujoco_arm, tmp_path, capsys):
    """Another engine's log: ``fmscal calibrate`` gives the floor's E of fmscal's own log of the same draw."""
    from fmscal.analysis.cli import main
    from fmscal.analysis._metrics import block_errors
    scenario, log, S, b, own, truth = mujoco_arm
    np.testing.assert_allclose(truth.S_at(0.0), S, rtol=0, atol=0)      # the same draw: only the engine differs
    # MuJoCo integrates the wrench open loop: its path drifts from the imposed one (measured 8.6e-5 m over 20 s,
    # four times the pose noise): the log is its own, of the same motion
    drift = np.abs(log.pose[:, 4:] - own.pose[:, 4:]).max()
    assert scenario.position_sd < drift < 1e-3
    log.write(tmp_path / "mujoco.csv")
    p = scenario.payload
    args = ["calibrate", str(tmp_path / "mujoco.csv"), "--mass", str(p.mass), "--com", *map(str, p.com),
            "--inertia", *map(str, p.inertia), "--json",
            "--mass-std", "0", "--com-std", "0", "--inertia-std", "0", "--gravity-std", "0"]   # the engine's payload
    capsys.readouterr()
    assert main(args) == 0
    import json
    out = json.loads(capsys.readouterr().out)
    assert out["converged"] and out["observer"] == "max-likelihood" and out["undetermined"] == []
    # no latency in the log: the estimate (a fraction of a sample, of either sign) within 3 of its std of 0,
    # and that std well under a sample
    assert abs(out["latency"]) < 3 * out["latency_std"] and 0 < out["latency_std"] < 0.5 * log.dt
    S_hat, S_std = np.array(out["S"]), np.array(out["S_std"])
    z = np.r_[((S_hat - S) / S_std).ravel(), (np.array(out["b"]) - b) / np.array(out["b_std"])]
    assert 0.6 < z.std() < 1.5 and np.abs(z).max() < 4.5
    own_fit = fit_max_likelihood(own, SpatialModel(p, scenario.gravity), offset=True)
    E_mujoco, E_own = np.array(block_errors(S_hat, S)), np.array(block_errors(own_fit.S_hat, S))
    # the latency estimated (a fraction of a sample, the poses interpolated): within the 1.15x of the E
    # at the known latency either way (measured 0.98 on this draw) ...
    assert np.all((0.85 < E_mujoco / E_own) & (E_mujoco / E_own < 1.15))
    # ... and with the latency given, the same E as fmscal's own log to 1 % (whole, torque and force blocks)
    assert main([*args, "--latency", "0"]) == 0
    given = np.array(json.loads(capsys.readouterr().out)["S"])
    np.testing.assert_allclose(np.array(block_errors(given, S)), E_own, rtol=0.01)
