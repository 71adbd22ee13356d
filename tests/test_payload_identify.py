"""Identification that ends in a payload (issue 44, item 2): ``identify_payload`` on every shape ``read_data``
returns, the force gains estimated with the payload, and "determined" judged by what the payload's uncertainty
does to the compensated wrench within the cone of attitudes the data span."""

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fmscal.analysis import read_data
from fmscal.analysis.cli import main
from fmscal.observers import make_observer, method_names
from fmscal.observers.payload import PayloadEstimate, identify_payload
from fmscal.plant import SPATIAL_SCENARIOS, FmscalError, Log, PayloadModel, SpatialModel, get_scenario
from fmscal.plant.io import simulate_table, write_pose_table
from fmscal.plant.io._pose_table import ATTITUDE_COLUMNS, simulate_attitude_log
from fmscal.plant.physics import find_model, rotation_matrix
from fmscal.plant.scenarios import TOOL

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
OFFSET = np.array([0.01, -0.02, 0.03, 0.5, -0.3, 0.2])       # N m, N
G = np.array([0.0, 0.0, -9.81])
ARM = SPATIAL_SCENARIOS["spatial-arm"]
#: spatial-arm's reading noise averaged over a 1 s hold at 1 kHz: a table's rows (N m, N).
HELD_SD = np.r_[np.full(3, ARM.torque_sd), np.full(3, ARM.force_sd)] / np.sqrt(1000.0)


def _quaternions(rotations):
    """Scalar-first unit quaternions of scipy rotations."""
    return np.roll(rotations.as_quat(), 1, axis=1)


def _attitude_csv(path):
    """An attitude-only log of the tool held at ten attitudes, written as ``t,qw,qx,qy,qz,tx,..,fz``."""
    log = simulate_attitude_log(TOOL, seed=3, offset=OFFSET)
    rows = np.column_stack([log.t, log.q, log.w_hat])
    np.savetxt(path, rows, delimiter=",", header=",".join(ATTITUDE_COLUMNS), comments="", fmt="%.10g")
    return path


@pytest.mark.parametrize("shape", ["log", "table", "joints", "attitude"])
def test_identify_payload_takes_every_shape_read_data_returns(shape, tmp_path):
    """One call for a spatial log, a pose table, joint angles with a URDF (a table: it raised AttributeError
    before) and an attitude-only log (its held segments, said in the notes): each a PayloadEstimate with its
    gains (forces' mean one), the payload's effect and the tolerance it was held to."""
    data = {"log": lambda: read_data(EXAMPLES / "arm.csv"), "table": lambda: read_data(EXAMPLES / "table.csv"),
            "joints": lambda: read_data(EXAMPLES / "joints.csv", urdf=EXAMPLES / "arm6.urdf", frame="ft_sensor"),
            "attitude": lambda: read_data(_attitude_csv(tmp_path / "held.csv"))}[shape]()
    fit = identify_payload(data)
    assert isinstance(fit, PayloadEstimate) and fit.gains.shape == fit.gains_std.shape == (6,)
    assert np.mean(fit.gains[3:]) == pytest.approx(1.0, abs=1e-12)
    assert abs(fit.mass - TOOL.mass) < 0.05 * TOOL.mass             # the examples' S has 2 % cross-talk
    assert fit.effect.shape == fit.tolerance.shape == (2,) and np.all(fit.tolerance > 0)
    assert shape == "log" or fit.inertia is None                   # held poses never give it (nor this short log)
    assert any("held segments" in note for note in fit.notes) is (shape == "attitude")
    assert json.loads(json.dumps(fit.to_dict(), allow_nan=True))["gains"] == pytest.approx(fit.gains.tolist())


def test_a_planar_log_is_refused_in_one_line(tmp_path, capsys):
    log, _, _ = get_scenario("paper").with_(duration=1.0).generate(0)
    with pytest.raises(FmscalError) as err:
        identify_payload(log)
    assert "\n" not in str(err.value) and "a planar log weighs no payload under gravity" in str(err.value)
    log.write(tmp_path / "planar.csv")
    assert main(["identify-payload", str(tmp_path / "planar.csv")]) == 2
    said = capsys.readouterr().err.strip().splitlines()
    assert len(said) == 1 and "planar log weighs no payload" in said[0]
    with pytest.raises(FmscalError, match="^data must be what fmscal.analysis.read_data returns"):
        identify_payload(np.zeros((10, 13)))


def _one_axis_table(n=13, spread=np.pi / 2):
    """``n`` poses turned about the sensor's x axis only, -spread .. spread: gravity's directions on one circle."""
    q = _quaternions(Rotation.from_rotvec(np.linspace(-spread, spread, n)[:, None] * np.array([1.0, 0.0, 0.0])))
    return simulate_table(TOOL, n=n, seed=4, offset=OFFSET, q=q, wrench_sd=HELD_SD)


def test_poses_turned_about_one_axis_are_refused_naming_the_cone(tmp_path, capsys):
    """Gravity on one circle in the sensor frame: a force gain, and with it the mass, is not determined off it;
    the payload is not determined and the line names the circle's axis and the cone (90 degrees); it is not
    saved (the same line, on the command line too), and the next poses turn the tool about another axis."""
    fit = identify_payload(_one_axis_table())
    assert not fit.payload_determined and not fit.converged
    why = fit.why_undetermined
    assert "about one axis only" in why and "+1.00 +0.00 +0.00" in why and "cone of 90 degrees" in why, why
    assert why in fit.warnings and fit.next_poses
    assert all(" about its y axis" in w or " about its z axis" in w for w in fit.next_poses), fit.next_poses
    with pytest.raises(FmscalError, match="about one axis only"):
        fit.save(tmp_path / "p.json")
    write_pose_table(_one_axis_table(), tmp_path / "one.csv")
    code = main(["identify-payload", str(tmp_path / "one.csv"), "--save", str(tmp_path / "p.json")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and "about one axis only" in err[-1] and "cone of 90 degrees" in err[-1]
    assert not (tmp_path / "p.json").exists()


def test_a_pose_off_the_circle_makes_it_determined():
    """The first suggested pose, and a second from the list a refit gives, recorded: the payload determined."""
    table = _one_axis_table()
    for _ in range(2):
        fit = identify_payload(table)
        words = fit.next_poses[0]
        k = int(words.split("from pose ")[1].split(",")[0]) - 1
        angle = float(words.split("turn the tool ")[1].split(" degrees")[0])
        axis = "xyz".index(words.split("about its ")[1][0])
        turn = Rotation.from_matrix(rotation_matrix(table.q[k])) * Rotation.from_rotvec(
            np.radians(angle) * np.eye(3)[axis])
        table = simulate_table(TOOL, n=len(table) + 1, seed=4, offset=OFFSET, wrench_sd=HELD_SD,
                               q=np.vstack([table.q, np.roll(turn.as_quat(), 1)]))
    fit = identify_payload(table)
    assert fit.payload_determined and fit.why_undetermined is None, fit.why_undetermined


def _gain_table(n, seed, gains, wrench_sd=HELD_SD):
    """``n`` held poses read by a sensor whose force axes read ``1 / gains`` of the force (``S = I`` assumed)."""
    S = np.eye(6)
    S[3:, 3:] = np.diag(gains)                                           # w = S (w_hat - b)
    return simulate_table(TOOL, n=n, seed=seed, offset=OFFSET, S=S, wrench_sd=wrench_sd)


def test_force_gains_that_disagree_are_estimated_and_the_payload_saved(tmp_path):
    """fy read 5 % high, S = I taken (before: the gains' spread widened the mass, not converged, nothing saved):
    the gains relative to their mean come back within 4 sigma, the line says they differ, the payload is
    determined and saved with them, and its compensated wrench at the poses is at the rows' noise."""
    gains = np.array([1.0, 1 / 1.05, 1.0])
    table = _gain_table(24, 3, gains)
    fit = identify_payload(table)
    k = gains.mean()
    assert np.all(np.abs(fit.gains[3:] - gains / k) < 4 * fit.gains_std[3:]), (fit.gains, fit.gains_std)
    assert np.all(fit.gains[:3] == 1.0) and np.all(fit.gains_std[:3] == 0.0)
    assert abs(fit.mass - TOOL.mass / k) < 4 * fit.mass_std
    assert fit.payload_determined and fit.converged
    assert any(w.startswith("the force gains differ between axes") for w in fit.warnings), fit.warnings
    fit.save(tmp_path / "p.json")
    a = np.einsum("nkj,k->nj", rotation_matrix(table.q.T).transpose(2, 0, 1), -G)
    f = fit.mass * a
    compensated = fit.gains * (table.w_hat - fit.b) - np.hstack([np.cross(fit.com, f), f])
    rms = np.sqrt(np.mean(compensated ** 2, axis=0))
    assert np.all(rms < 2 * HELD_SD) and np.all(rms > 0.3 * HELD_SD), rms / HELD_SD


def test_the_tolerance_decides_and_names_the_noise(tmp_path, capsys):
    """A tolerance far below the effect: not determined, the line names the noise and the next poses help; a
    loose one: determined, and kept as given; a tolerance that is not two positive numbers: one line."""
    table = simulate_table(TOOL, n=12, seed=1, offset=OFFSET, wrench_sd=HELD_SD)
    tight = identify_payload(table, tolerance=(1e-6, 1e-8))
    assert not tight.payload_determined and "the noise" in tight.why_undetermined and tight.next_poses
    loose = identify_payload(table, tolerance=(1.0, 0.1))
    assert loose.payload_determined and loose.tolerance.tolist() == [1.0, 0.1]
    assert loose.effect.tolist() == tight.effect.tolist()
    for bad in [(1.0,), (0.0, 1.0), "1 1", (1.0, np.nan)]:
        with pytest.raises(FmscalError, match="^tolerance must be two positive numbers, N and N m"):
            identify_payload(table, tolerance=bad)
    write_pose_table(table, tmp_path / "t.csv")
    assert main(["identify-payload", str(tmp_path / "t.csv"), "--tolerance", "0", "1"]) == 2
    assert capsys.readouterr().err.strip().endswith("--tolerance must be two positive numbers, N and N m (the "
                                                    "forces' and the torques' largest standard deviation the "
                                                    "payload may add); got [0.0, 1.0]")
    assert main(["identify-payload", str(tmp_path / "t.csv"), "--tolerance", "1", "0.1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["tolerance"] == [1.0, 0.1] and out["payload_determined"] and out["why_undetermined"] is None


def test_the_default_tolerance_is_one_sd_of_the_readings_noise():
    """A table's: TABLE_TOLERANCE times its rows' scatter (here the rows' simulated noise, within a third: 12
    poses; a row averages readings, so that this is at most one sd of a reading); a log's: the reading's
    sample-to-sample scatter (spatial-arm's 0.05 N and 0.002 N m, within a tenth)."""
    from fmscal.observers.payload import TABLE_TOLERANCE
    fit = identify_payload(simulate_table(TOOL, n=12, seed=1, offset=OFFSET, wrench_sd=HELD_SD))
    assert fit.tolerance / HELD_SD[[3, 0]] == pytest.approx([TABLE_TOLERANCE] * 2, rel=0.35)
    log, _, _ = ARM.with_(duration=5.0, crosstalk=0.0).generate(1)
    fit = identify_payload(log)
    assert fit.tolerance == pytest.approx([ARM.force_sd, ARM.torque_sd], rel=0.1)
    assert fit.payload_determined and np.all(fit.effect < 0.2 * fit.tolerance)



def test_an_attitude_only_logs_default_tolerance_is_its_readings_noise():
    """The held segments of an attitude-only log are rows of averages, but its raw readings are at hand: the
    default tolerance is their noise, the scatter within the held segments (0.05 N and 0.005 N m simulated, within
    a tenth; no attitude jitter, which would add to it), not the rows' scatter (a tenth of it: 100 samples a
    segment), and ten held attitudes determine the payload against it (the node's ~/identify_payload on an IMU
    goes the same way); a table of the same rows holds to its rows' scatter."""
    from fmscal.observers.payload import fit_static
    from fmscal.plant.io import held_table
    log = simulate_attitude_log(TOOL, seed=3, offset=OFFSET, angle_sd=0.0)
    fit = identify_payload(log)
    assert fit.tolerance == pytest.approx([0.05, 0.005], rel=0.1), fit.tolerance
    assert fit.payload_determined and fit.why_undetermined is None
    rows = fit_static(held_table(log)[0])
    assert np.all(rows.tolerance < 0.3 * fit.tolerance) and np.all(rows.tolerance > 0.03 * fit.tolerance)

def _gain_log(seed, gains, duration):
    """A spatial-arm log (no cross-talk) read by force axes of ``gains``, its noise added after: ``w_hat = diag(1,
    1, 1, 1 / gains) w + b + n``; and its truth."""
    log, truth, _ = ARM.with_(crosstalk=0.0, duration=duration).generate(seed, noise_free=True)
    rng = np.random.default_rng(1000 + seed)
    w = log.w_hat - truth.offset
    w[:, 3:] /= gains
    noise = rng.standard_normal(w.shape) * np.r_[np.full(3, ARM.torque_sd), np.full(3, ARM.force_sd)]
    return Log(log.t, log.pose, w + truth.offset + noise, name=f"gains-seed{seed}"), truth


def test_a_log_estimates_the_force_gains_and_the_torques_common_gain():
    """Force gains 5 % apart and their mean 1.01 of the torques': the log's motion ties the torques' scale to the
    forces' (alpha x h in the forces, h x a_g in the torques), so the force gains relative to their mean and the
    torques' common gain (1 / 1.01, told from one) come back within 4 sigma, with the mass in the forces' mean
    units; a log whose torques read as its forces takes that gain as one."""
    gains = np.array([1.04, 1.0, 0.99])
    log, truth = _gain_log(0, gains, 10.0)
    fit = identify_payload(log)
    k = gains.mean()
    expected = np.r_[np.full(3, 1 / k), gains / k]
    assert np.all(np.abs(fit.gains - expected) < 4 * fit.gains_std), ((fit.gains - expected) / fit.gains_std)
    assert abs(fit.mass - TOOL.mass / k) < 4 * fit.mass_std
    assert np.all(np.abs(fit.com - TOOL.com) < 4 * fit.com_std)
    assert fit.payload_determined and fit.inertia is not None
    same, _ = _gain_log(0, np.ones(3), 10.0)
    assert identify_payload(same).gains_std[0] == 0.0


def test_the_payload_model_is_found_in_one_place():
    """The payload with S known is a third model beside the planar and spatial ones: the spatial log's columns
    and reading, estimating the payload, the offset and the force gains (no S); find_model picks it by what it
    estimates, and no method of the registry runs on it."""
    model = PayloadModel()
    assert model.wrench_names == SpatialModel.wrench_names and "S" not in model.estimates
    assert find_model(columns=("t", *SpatialModel.pose_names, *SpatialModel.wrench_names)) is SpatialModel
    assert find_model(columns=("t", *SpatialModel.pose_names, *SpatialModel.wrench_names),
                      estimates="mass") is PayloadModel
    assert find_model(n_w=3).name == "planar" and find_model(position="com") is SpatialModel
    assert find_model(payload=TOOL, estimates="mass") is PayloadModel and find_model(n_w=5) is None
    assert method_names(calibrates=True, model=model) == ()
    with pytest.raises(FmscalError, match="MaximumLikelihood estimates S; the payload model takes S as known"):
        make_observer("max-likelihood", model)


def _cone_attitudes(u, cone, count, rng):
    """``count`` random sensor attitudes whose gravity direction (``R^T (-g)``, unit) lies within ``cone`` degrees
    of the mean of the directions ``u``."""
    mean = u.mean(axis=0) / np.linalg.norm(u.mean(axis=0))
    out = []
    while len(out) < count:
        R = Rotation.random(random_state=rng).as_matrix()
        if np.degrees(np.arccos(np.clip(R.T @ -G / 9.81 @ mean, -1, 1))) <= cone:
            out.append(R)
    return np.array(out)


def _static_error(fit, S, b, attitudes):
    """The compensated wrench's error at held attitudes, no contact, noise-free readings: ``diag(gains) (w_hat -
    b_hat) - W_p`` with ``W_p = [com x m a; m a]``, ``a = R^T (-g)`` (``S = I`` taken), shape (K, 6)."""
    a = np.einsum("nkj,k->nj", attitudes, -G)
    f_true = TOOL.mass * a
    w_hat = np.linalg.solve(S, np.hstack([np.cross(TOOL.com, f_true), f_true]).T).T + b
    f = fit.mass * a
    return fit.gains * (w_hat - fit.b) - np.hstack([np.cross(fit.com, f), f])


def _scored(fit, q, gains, b, rng):
    """A fit of data read by force axes of ``gains`` (``S = I`` taken) with offset ``b``, its attitudes ``q``:
    the gains' z-scores against the truth relative to the force gains' mean (the torques' common gain too, where
    the fit tells it from one), and the compensated wrench's error rms at 50 held attitudes within the fit's
    cone, forces and torques, over the tolerance and over the stated effect."""
    k = gains.mean()
    zs = (fit.gains - np.r_[np.full(3, 1 / k), gains / k]) / np.where(fit.gains_std > 0, fit.gains_std, np.inf)
    u = np.einsum("nkj,k->nj", rotation_matrix(q.T).transpose(2, 0, 1), -G) / 9.81
    S = np.eye(6)
    S[3:, 3:] = np.diag(gains)
    error = _static_error(fit, S, b, _cone_attitudes(u, fit.cone_deg, 50, rng))
    rms = np.sqrt(np.mean(error ** 2, axis=0))
    group = np.array([np.sqrt(np.mean(rms[3:] ** 2)), np.sqrt(np.mean(rms[:3] ** 2))])
    return (zs[[0, 3, 4, 5]] if fit.gains_std[0] > 0 else zs[3:]), group / fit.tolerance, group / fit.effect


@pytest.mark.slow
def test_ten_seeds_of_tables_and_logs_gains_recovered_and_the_tolerance_kept(tmp_path):
    """Ten seeds each of 16-pose tables (rows of a 1 s hold) and 20 s spatial-arm logs, with S = I and with force
    gains off by up to 5 %: the gains' z-scores' rms within [0.7, 1.4] (the forces' relative gains; the logs'
    torque gain too), every log's payload determined and saved and at least 18 of the 20 tables' (a table's default
    tolerance, its rows' scatter, is strict: benchmarks/identify.py), and the compensated wrench's error at held
    attitudes within the cone, over the tolerance, an rms at most 1 (what the tolerance promises: the payload adds at
    most one sd of the noise) and, over the stated effect, an rms within [0.1, 1] (the effect is the cone's largest
    sd)."""
    rng = np.random.default_rng(44)
    z, over_tolerance, over_effect, saved = [], [], [], {"table": 0, "log": 0}
    for off in (0.0, 0.05):
        for seed in range(10):
            gains = 1.0 + rng.uniform(-off, off, 3)
            for shape in ("table", "log"):
                if shape == "table":
                    data = _gain_table(16, seed, gains)
                    b, q = OFFSET, data.q
                else:
                    data, truth = _gain_log(seed, gains, 20.0)
                    b, q = truth.offset, data.pose[::50, :4]
                fit = identify_payload(data)
                zs, tol, eff = _scored(fit, q, gains, b, rng)
                z.extend(zs)
                if fit.payload_determined:
                    fit.save(tmp_path / f"{shape}-{off}-{seed}.json")
                    saved[shape] += 1
                over_tolerance.append(tol)
                over_effect.append(eff)
    z_rms = float(np.sqrt(np.mean(np.square(z))))
    assert 0.7 < z_rms < 1.4, z_rms
    assert saved["log"] == 20 and saved["table"] >= 18, saved       # a table's strict default: 16 poses, 90-100 %
    tolerance_rms = np.sqrt(np.mean(np.square(over_tolerance), axis=0))
    effect_rms = np.sqrt(np.mean(np.square(over_effect), axis=0))
    assert np.all(tolerance_rms < 1.0), tolerance_rms
    assert np.all((0.1 < effect_rms) & (effect_rms < 1.0)), effect_rms
