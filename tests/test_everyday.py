"""The everyday job (issue 44): a factory-calibrated sensor (S = I) and a new tool identified from a few held poses,
then compensated with the payload estimate alone: compensate(PayloadEstimate or StaticFit, log), Compensator, a
pose table checked row by row (analysis/_setup.py: K1-K3; analysis/_compensate.py: L1).

The statistics over seeds are benchmarks/everyday.py's; these hold the behaviours on one seed each.
"""

from dataclasses import replace

import numpy as np
import pytest

from fmscal.analysis import FALSE_ALARM, Compensator, ImuMotion, compensate
from fmscal.observers.payload import fit_static
from fmscal.plant import SPATIAL_SCENARIOS, Calibration, FmscalError, Log, NoiseSpec
from fmscal.plant.io import ImuLog, estimate_noise, simulate_table
from fmscal.plant.physics import quaternion_multiply, rotation_matrix
from fmscal.plant.scenarios import contact_wrench, with_contact
from fmscal.analysis._motion import quaternion_from_matrix

ARM = SPATIAL_SCENARIOS["spatial-arm"].with_(crosstalk=0.0, duration=8.0)


@pytest.fixture(scope="module")
def rig():
    """An 8 s spatial-arm log of a sensor with S = I and an offset, and 8 held poses of the same tool (each row the
    mean of 500 readings)."""
    log, truth, _ = ARM.generate(2)
    S, b = truth.S_at(0.0), truth.offset
    sd = np.asarray(truth.noise.wrench_sd)
    table = simulate_table(ARM.payload, n=8, seed=102, S=S, offset=b, wrench_sd=sd / np.sqrt(500))
    return log, truth, table, fit_static(table), np.sqrt(np.diag(S @ np.diag(sd ** 2) @ S.T))


def _rms(c):
    return np.sqrt(np.mean(c.wrench ** 2, axis=0))


@pytest.mark.slow
@pytest.mark.parametrize("causal, ratio", [(False, 1.3), (True, 2.0)])
def test_a_payload_from_held_poses_compensates_a_log(rig, causal, ratio):
    """The table's fit alone (S the identity; the offset the fit's; the inertia, which held poses never give,
    bounded by the tool's size and learned from the motion, L1): the residual within 1.3x the noise offline and
    2x causal, rms z in [0.7, 1.4], false alarms at most twice the stated rate; the bound said."""
    log, truth, table, fit, noise = rig
    c = compensate(fit, log, causal)
    r = _rms(c) / noise
    assert np.all(r > 0.9) and np.all(r < ratio), r
    z = np.sqrt(np.mean((c.wrench / c.sd) ** 2, axis=0))
    assert np.all(z > 0.7) and np.all(z < 1.4), z
    assert c.contact.mean() <= 2 * 1e-3 + 3 * np.sqrt(1e-3 / len(c.t)), c.contact.mean()
    assert any("inertia was not determined" in w for w in c.warnings), c.warnings


def test_without_learning_the_bound_alone_covers_the_inertia(rig):
    """The inertia's bound (K3) alone, carried in the covariance (K2): where it is not learned the torque's residual
    is above the noise (the tool's unknown inertia), and the covariance covers it (rms z below 1, not above)."""
    log, truth, table, fit, noise = rig
    from fmscal.analysis._setup import setup
    st = setup(fit)
    st.inertia_bounded = False                     # the bound carried, not learned
    stream = Compensator(st, log.dt, noise=replace(truth.noise))
    out = stream.push_many(log.t, log.w_hat, log.pose)
    w = np.array([o.wrench for o in out])
    sd = np.sqrt(np.array([np.diag(o.cov) for o in out]))
    r = np.sqrt(np.mean(w ** 2, axis=0)) / noise
    assert np.all(r[:3] > 1.5), r
    assert np.all(np.sqrt(np.mean((w / sd) ** 2, axis=0)) < 1.2)


def test_a_contact_of_one_newton_is_flagged(rig):
    """1 N pushed on the tool for 1 s: flagged at 90 % of its samples or more, offline and causal."""
    log, truth, table, fit, noise = rig
    touched, on = with_contact(log, truth.S_at(0.0), contact_wrench(1.0), 3.0, 1.0)
    for causal in (False, True):
        c = compensate(fit, touched, causal)
        inside = (c.t > 3.05) & (c.t < 3.95)
        assert c.contact[inside].mean() >= 0.9, (causal, c.contact[inside].mean())


@pytest.mark.slow
def test_the_stream_is_the_causal_log(rig):
    """Compensator with the estimate, fed the log with the log's noise model, gives compensate(..., causal=True)'s
    numbers. Given none, it estimates the readings' noise from its first 4002 readings (4 s at 1 kHz: a table's fit
    holds its rows' noise, not a sample's; the readings' correlation in time measured, tests/test_coloured_noise.py),
    with no output before, and the poses' as they come: its outputs then at the noise in z."""
    log, truth, table, fit, noise = rig
    short = log.head(2500)
    reference = compensate(fit, short, True)
    model_noise = estimate_noise(short)
    stream = Compensator(fit, log.dt, noise=model_noise)
    out = [o for o in (stream.push(t, w, p) for t, w, p in zip(short.t, short.w_hat, short.pose)) if o is not None]
    assert len(out) == len(reference.t)
    np.testing.assert_allclose([o.wrench for o in out], reference.wrench, atol=1e-9)
    learning = Compensator(fit, log.dt)
    out = learning.push_many(log.t, log.w_hat, log.pose)
    assert out[0].t >= log.t[4001] - 0.03 - 1e-9 and len(out) > 3900
    assert any("readings' noise estimated from the first 4002 readings" in w for w in learning.warnings)
    z = np.array([o.wrench / np.sqrt(np.diag(o.cov)) for o in out])
    assert np.all(np.sqrt(np.mean(z ** 2, axis=0)) < 1.4) and np.all(np.sqrt(np.mean(z ** 2, axis=0)) > 0.7)


def test_a_pose_table_is_checked_row_by_row(rig):
    """Six new held poses of the same tool: each row's residual at the noise, none flagged, with the noise given or
    the fit's own of a row; with another tool (200 g more) the rows are flagged."""
    log, truth, table, fit, noise = rig
    sd = np.asarray(truth.noise.wrench_sd) / np.sqrt(500)
    check = simulate_table(ARM.payload, n=6, seed=7, S=truth.S_at(0.0), offset=truth.offset, wrench_sd=sd)
    c = compensate(fit, check, noise=NoiseSpec(tuple(sd)))
    assert len(c.t) == 6 and not c.contact.any()
    z = c.wrench / c.sd
    assert np.sqrt(np.mean(z ** 2)) < 2.0
    heavier = replace(ARM.payload, mass=ARM.payload.mass + 0.2)
    other = simulate_table(heavier, n=6, seed=7, S=truth.S_at(0.0), offset=truth.offset, wrench_sd=sd)
    assert compensate(fit, other, noise=NoiseSpec(tuple(sd))).contact.mean() > 0.8
    with pytest.raises(FmscalError, match="held poses, not a stream"):
        compensate(fit, check, True, noise=NoiseSpec(tuple(sd)))
    own = compensate(fit, check)                # the noise of a row the fit measured (Setup.held_noise)
    assert not own.contact.any() and np.sqrt(np.mean((own.wrench / own.sd) ** 2)) < 2.0


def test_a_sensor_turned_on_the_tracked_frame(rig):
    """A sensor mounted turned on the tracked frame (its axes M): the poses the tracked frame's, the payload fitted
    with the mounting estimated; the output, in the sensor's own axes, is the compensation of the sensor's poses
    (K1); an IMU source with such a payload is refused."""
    log, truth, table, fit, noise = rig
    M = rotation_matrix(np.array([np.cos(0.2), 0.0, np.sin(0.2), 0.0]))          # 23 degrees about y
    M = np.asarray(M, dtype=float)
    qM = quaternion_from_matrix(M[None])[0]
    # the tracked frame's attitude R_T = R_S M^T: q_T = q_S (x) q(M)^*
    conj = qM * np.array([1.0, -1.0, -1.0, -1.0])
    q_T = quaternion_multiply(log.pose[:, :4].T, np.tile(conj, (len(log.t), 1)).T).T
    tracked = Log(log.t, np.c_[q_T, log.pose[:, 4:]], log.w_hat)
    sd = np.asarray(truth.noise.wrench_sd) / np.sqrt(500)
    table_T = simulate_table(ARM.payload, n=10, seed=3, S=truth.S_at(0.0), offset=truth.offset, wrench_sd=sd,
                             mounting=M)
    turned = fit_static(table_T, estimate_mounting=True)
    assert turned.mounting is not None
    c = compensate(turned, tracked)
    r = _rms(c) / noise
    assert np.all(r < 1.3), r
    with pytest.raises(FmscalError, match="mounted turned"):
        compensate(turned, ImuLog(log.t, None, np.zeros((len(log.t), 3)), np.tile([0, 0, 9.81], (len(log.t), 1)),
                                  log.w_hat), motion=ImuMotion(), noise=truth.noise)


def test_refusals(rig):
    """What a payload estimate does not take, in one line each."""
    log, truth, table, fit, noise = rig
    cal = Calibration(S=np.eye(6), payload=ARM.payload, method="truth", b=truth.offset, gravity=ARM.gravity,
                      latency=0.0)
    with pytest.raises(FmscalError, match="payload= replaces a calibration's payload"):
        compensate(fit, log, payload=ARM.payload)
    with pytest.raises(FmscalError, match="calibration= gives a payload estimate its sensor's S"):
        compensate(cal, log, calibration=cal)
    with pytest.raises(FmscalError, match="tool_radius must be a positive number"):
        compensate(fit, log, tool_radius=-1.0)
    with pytest.raises(FmscalError, match="holds no offset"):
        compensate(replace(fit, b=None), log)
    with pytest.raises(FmscalError, match="compensate takes a plant.Calibration or a payload estimate"):
        compensate("tool.json", log)


def test_the_example_rig_end_to_end(tmp_path):
    """examples/tool_*.csv through the command line, as the guides run them: the gripper identified from 8 held
    poses (within 4 sd of examples/make.py's GRIPPER), the 4 check poses at the noise and unflagged, the run's
    contact-free rows at the noise (1.3x either way) and its push flagged throughout."""
    import importlib.util
    import json
    from pathlib import Path

    from fmscal.analysis.cli import main

    examples = Path(__file__).resolve().parents[1] / "examples"
    spec = importlib.util.spec_from_file_location("make_examples", examples / "make.py")
    make = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make)
    where = ["--urdf", str(examples / "arm6.urdf"), "--frame", "ft_sensor"]
    tool = tmp_path / "gripper.json"
    assert main(["identify-payload", str(examples / "tool_poses.csv"), *where, "--save", str(tool)]) in (0, None)
    saved = json.loads(tool.read_text())
    truth = make.GRIPPER
    assert abs(saved["mass"] - truth.mass) < 4 * saved["mass_std"]
    assert np.all(np.abs(np.subtract(saved["com"], truth.com)) < 4 * np.asarray(saved["com_std"]))
    names = ["tx", "ty", "tz", "fx", "fy", "fz"]
    held = np.r_[(make.ARM.torque_sd,) * 3, (make.ARM.force_sd,) * 3] / np.sqrt(make.HELD_AVERAGED)
    run_sd = np.r_[(make.ARM.torque_sd,) * 3, (make.ARM.force_sd,) * 3] / np.sqrt(make.RUN_AVERAGED)
    for name, out in (("tool_check.csv", "check.csv"), ("tool_run.csv", "run.csv")):
        assert main(["compensate", str(tool), str(examples / name), *where, "--out", str(tmp_path / out)]) in (0, None)
    check = np.genfromtxt(tmp_path / "check.csv", delimiter=",", names=True)
    assert not check["contact"].any()
    assert np.all(np.abs([check[n] for n in names]).T < 4 * np.sqrt(2) * held)      # a pose's and the fit's noise
    run = np.genfromtxt(tmp_path / "run.csv", delimiter=",", names=True)
    t = run["t"]
    lo, hi = make.PUSH_TIMES[0] - 0.2, make.PUSH_TIMES[1] + make.PUSH_RAMP + 0.2
    free, pushed = (t < lo) | (t > hi), (t > make.PUSH_TIMES[0] + make.PUSH_RAMP) & (t < make.PUSH_TIMES[1])
    rms = np.sqrt(np.mean(np.square([run[n][free] for n in names]), axis=1))
    assert np.all((rms / run_sd > 1 / 1.3) & (rms / run_sd < 1.3)), rms / run_sd
    assert run["contact"][free].mean() < 0.01
    assert run["contact"][pushed].mean() > 0.9


@pytest.mark.slow
def test_everyday_targets(tmp_path):
    """Issue 44's targets on 3 seeds of the harder sensor, force gains off by up to 5 % (benchmarks/everyday.py
    runs 10 seeds of each sensor and prints the table docs/status.md quotes): 8 held attitudes, identify-payload
    --save, compensate on a 20 s log with a 1 N push. Medians over the seeds: the contact-free residual within 1.3x
    the noise offline and 2x causal (and above 1/1.3: not a wrench left out), rms z in [0.7, 1.4], false alarms at
    most twice the stated rate; the push flagged in at least 90 % of its samples on every seed."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "everyday.py"
    spec = importlib.util.spec_from_file_location("everyday_benchmark", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    results = [bench.run(seed, True, tmp_path) for seed in range(3)]
    for k, ratio in ((0, 1.3), (1, 2.0)):
        rs = [r[k] for r in results]
        median_ratio = np.median([r["ratio"] for r in rs], axis=0)
        assert np.all((median_ratio > 1 / 1.3) & (median_ratio < ratio)), median_ratio
        z = np.median([r["z"] for r in rs], axis=0)
        assert np.all((z > 0.7) & (z < 1.4)), z
        assert np.median([r["false"] for r in rs]) <= 2 * FALSE_ALARM
        assert min(r["found"] for r in rs) >= 0.9
