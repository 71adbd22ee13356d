"""The plant: eq. (1) against known answers, the integrator, the sensor, logs."""

import numpy as np
import pytest

from fmscal import plant
from fmscal.plant import (PAPER_PAYLOAD, PAPER_S, CalibrationSchedule, Log, LogError, Payload,
                   PaperWrench, SampledWrench, acceleration, get_scenario, integrate)


def _constant(w):
    return lambda t: np.broadcast_to(np.asarray(w, float), np.shape(t) + (3,)).copy()


def test_no_force_keeps_constant_velocity():
    t = np.linspace(0, 5, 501)
    x = integrate(PAPER_PAYLOAD, _constant([0, 0, 0]), t, x0=[0.3, 0.2, 1.0, -0.5, 2.0, 0.25])
    np.testing.assert_allclose(x[-1], [0.3 + 0.2 * 5, 0.2, 1.0 - 2.5, -0.5, 2.0 + 1.25, 0.25], atol=1e-12)


def test_pure_moment_gives_theta_ddot_M_over_I():
    a = acceleration(0.7, [1.5, 0.0, 0.0], PAPER_PAYLOAD)
    np.testing.assert_allclose(a, [1.5 / 0.75, 0.0, 0.0])


def test_force_through_centre_of_mass_does_not_rotate():
    body = Payload(2.0, 0.5, [0.0, 0.0])
    t = np.linspace(0, 3, 301)
    x = integrate(body, _constant([0.0, 1.0, -2.0]), t)
    np.testing.assert_allclose(x[:, 0], 0.0, atol=1e-15)
    np.testing.assert_allclose(x[-1, [2, 4]], [0.5 * 0.5 * 9, -1.0 * 0.5 * 9], rtol=1e-12)


@pytest.mark.parametrize("rho, f, expected_moment", [
    ([0.2, 0.0], [0.0, 0.0, 1.0], +0.2),    # rho_x f_y: counter-clockwise
    ([0.0, 0.2], [0.0, 1.0, 0.0], -0.2),    # -rho_y f_x: clockwise
])
def test_moment_arm_sign_of_rho(rho, f, expected_moment):
    body = Payload(1.0, 1.0, rho)
    assert acceleration(0.0, f, body)[0] == pytest.approx(expected_moment)


def test_force_is_rotated_into_the_inertial_frame():
    a = acceleration(np.pi / 2, [0.0, 1.0, 0.0], Payload(2.0, 1.0, [0, 0]))
    np.testing.assert_allclose(a, [0.0, 0.0, 0.5], atol=1e-15)


def test_rk4_error_against_a_much_finer_reference():
    coarse = np.arange(0, 5.0 + 1e-9, 1e-2)
    fine = np.arange(0, 5.0 + 1e-9, 1e-2 / 16)
    xc = integrate(PAPER_PAYLOAD, PaperWrench(), coarse)
    xf = integrate(PAPER_PAYLOAD, PaperWrench(), fine)[::16]
    err = np.max(np.abs(xc - xf))
    assert err < 1e-6
    # fourth order: halving the step cuts the error about 16 times
    half = integrate(PAPER_PAYLOAD, PaperWrench(), np.arange(0, 5.0 + 1e-9, 5e-3))[::2]
    assert np.max(np.abs(half - xf)) < err / 8


def test_compiled_and_numpy_integrators_agree():
    t = np.arange(0, 2.0, 1e-3)
    a = integrate(PAPER_PAYLOAD, PaperWrench(), t)
    b = integrate(PAPER_PAYLOAD, PaperWrench(), t, compiled=False)
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)


def test_agrees_with_an_independent_physics_engine():
    """pymunk (Chipmunk2D) fed the logged samples agrees to 1e-4 over 20 s.

    Chipmunk integrates positions, then velocities (semi-implicit Euler).
    Each logged wrench sample is applied in the body's ``velocity_func``,
    after the position update, so it acts at the middle of the engine's
    velocity step (Stormer-Verlet, second order): the engine's velocity lives
    at half steps and starts at ``v(dt/2)``.
    """
    import pymunk                                # the [test] extra: a missing package fails here, never skips
    log, truth, x = get_scenario("paper").with_(duration=20.0).generate(0, noise_free=True)
    w = log.w_hat @ truth.S_at(0.0).T            # what the body feels: S w_hat
    p, dt = PAPER_PAYLOAD, log.dt
    space = pymunk.Space()
    body = pymunk.Body(p.mass, p.inertia)
    space.add(body)
    k = [0]

    def velocity_func(b, gravity, damping, step):
        k[0] += 1
        b.apply_force_at_local_point(tuple(w[k[0], 1:]), tuple(p.rho))
        b.torque += w[k[0], 0]
        pymunk.Body.update_velocity(b, gravity, damping, step)

    body.velocity_func = velocity_func
    M, fx, fy = w[0]
    body.angular_velocity = (M + p.rho[0] * fy - p.rho[1] * fx) / p.inertia * dt / 2
    body.velocity = (fx / p.mass * dt / 2, fy / p.mass * dt / 2)
    poses = np.empty((len(log), 3))
    for i in range(len(log)):
        poses[i] = (body.angle, body.position.x, body.position.y)
        if i < len(log) - 1:
            space.step(dt)
    assert np.max(np.abs(x[:, 0])) > 3.0 and np.max(np.abs(x[:, 2])) > 3.0   # it moves and turns
    np.testing.assert_array_less(np.max(np.abs(poses - log.pose), axis=0), 1e-4)


def test_S_and_its_inverse_round_trip():
    sched = CalibrationSchedule(PAPER_S)
    t = np.linspace(0, 1, 11)
    w = PaperWrench()(t)
    w_hat = sched.raw_reading(t, w)
    np.testing.assert_allclose(w_hat @ PAPER_S.T, w, atol=1e-12)


def test_singular_S_is_refused():
    with pytest.raises(plant.SingularCalibrationError, match="singular"):
        CalibrationSchedule(np.ones((3, 3)))


def test_paper_scenario_matches_section_4():
    sc = get_scenario("paper")
    assert (sc.payload.mass, sc.payload.inertia, sc.payload.rho) == (2.5, 0.75, (0.2, 0.25))
    assert (sc.duration, sc.dt, sc.wrench_noise) == (100.0, 1e-3, 0.05)
    assert sc.angle_sd == pytest.approx(np.deg2rad(0.1)) and sc.position_sd == 1e-4
    np.testing.assert_array_equal(PAPER_S[0], [0.6110, -0.0372, -0.1445])
    log, truth, _ = sc.with_(duration=1.0).generate(3)
    assert np.all((truth.S0 >= 0) & (truth.S0 <= 3))
    peak = np.max(np.abs(PAPER_S_inv_w(sc)), axis=0)
    np.testing.assert_allclose(truth.noise.wrench_sd, 0.05 * peak, rtol=0.02)


def PAPER_S_inv_w(sc):
    t = np.arange(0, 1.0 + 1e-9, 1e-3)
    return sc.excitation(t) @ np.linalg.inv(PAPER_S).T


def test_noisy_scenario_draws_well_conditioned_S():
    sc = get_scenario("noisy")
    assert (sc.wrench_noise, sc.position_sd) == (0.10, 2e-4)
    assert sc.angle_sd == pytest.approx(np.deg2rad(1.0))
    for seed in range(5):
        _, truth, _ = sc.with_(duration=0.1).generate(seed)
        S = truth.S_at(0.0)
        assert np.all(np.abs(S) <= 3) and np.linalg.cond(S) <= 20


def test_time_varying_scenario_follows_table_1():
    _, truth, _ = get_scenario("time-varying").with_(duration=0.1).generate(0)
    for t, k in [(50.0, 0), (150.0, 1), (250.0, 2)]:
        S = truth.S_at(t)
        assert (S[0, 0], S[1, 1], S[2, 2]) == (plant.TABLE_1["s11"][k], plant.TABLE_1["s22"][k],
                                               plant.TABLE_1["s33"][k])


def test_log_round_trip_keeps_missing_poses(tmp_path):
    log, truth, _ = get_scenario("vision-50hz").with_(duration=2.0).generate(1)
    assert 0 < log.has_pose.sum() < len(log)
    log.write(tmp_path / "log.csv")
    truth.write(tmp_path / "log.truth.json")
    back = plant.read_log(tmp_path / "log.csv")
    np.testing.assert_array_equal(back.t, log.t)
    np.testing.assert_array_equal(back.w_hat, log.w_hat)
    np.testing.assert_array_equal(back.has_pose, log.has_pose)
    np.testing.assert_array_equal(back.pose[log.has_pose], log.pose[log.has_pose])
    t2 = plant.read_truth(tmp_path / "log.truth.json")
    np.testing.assert_array_equal(t2.S_at(0.0), truth.S_at(0.0))
    np.testing.assert_array_equal(t2.S0, truth.S0)
    assert t2.payload == truth.payload and t2.noise == truth.noise


@pytest.mark.parametrize("kwargs, match", [
    (dict(mass=0.0), "mass must be positive"),
    (dict(mass=-1.0), "mass must be positive"),
    (dict(inertia=float("nan")), "inertia must be positive and finite"),
    (dict(rho=[0.1]), "rho has the wrong shape; expected 2 instead of 1"),
    (dict(rho=[0.1, float("inf")]), "rho must be finite"),
    (dict(mass="heavy"), "mass must be a number"),
])
def test_bad_payload_values_are_refused(kwargs, match):
    args = dict(mass=2.5, inertia=0.75, rho=[0.2, 0.25])
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        Payload(**args)


def _write(tmp_path, text):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    return path


def _good_rows(n=12, dt=0.01):
    return [f"{k * dt},0.0,0.0,0.0,1.0,0.5,0.2" for k in range(n)]


@pytest.mark.parametrize("header, rows, match", [
    ("t,theta,x,y,M,fx", None, "missing column"),
    ("t,angle,x,y,M,fx,fy", None, "missing column.*theta"),
    (None, lambda r: r[:5] + ["0.05,0.0,0.0,0.0,nan,0.5,0.2"] + r[6:], "NaN or infinite"),
    (None, lambda r: r[:5] + ["0.05,0.0,0.0,0.0,inf,0.5,0.2"] + r[6:], "NaN or infinite"),
    (None, lambda r: r[:5] + ["0.05,0.0,0.0,0.0,,0.5,0.2"] + r[6:], "column M has a missing"),
    (None, lambda r: r[:5] + [r[3]] + r[6:], "not strictly increasing"),
    (None, lambda r: r[:5] + ["0.052,0.0,0.0,0.0,1.0,0.5,0.2"] + r[6:], "not evenly sampled"),
    (None, lambda r: r[:4], "too few rows"),
    (None, lambda r: [s if k % 4 == 0 else s.split(",")[0] + ",,,,1.0,0.5,0.2"
                      for k, s in enumerate(r)], "too few pose measurements"),
    (None, lambda r: r[:5] + ["0.05,0.0,,0.0,1.0,0.5,0.2"] + r[6:], "some but not all"),
    (None, lambda r: r[:5] + ["0.05,0.0,abc,0.0,1.0,0.5,0.2"] + r[6:], "not a number"),
])
def test_bad_logs_are_refused_with_a_message(tmp_path, header, rows, match):
    body = _good_rows() if rows is None else rows(_good_rows())
    path = _write(tmp_path, "\n".join([header or ",".join(plant.COLUMNS)] + body) + "\n")
    with pytest.raises(LogError, match=match):
        plant.read_log(path)


def test_missing_log_file_is_refused(tmp_path):
    with pytest.raises(LogError, match="no such file"):
        plant.read_log(tmp_path / "nope.csv")


def test_sampled_wrench_interpolates():
    w = SampledWrench([0.0, 1.0], [[0, 0, 0], [2, 4, 6]])
    np.testing.assert_allclose(w(0.5), [1, 2, 3])


def test_log_rejects_wrong_shapes():
    with pytest.raises(LogError, match="expected t"):
        Log(np.arange(20.0), np.zeros((20, 2)), np.zeros((20, 3)))


def test_rows_before_the_first_pose_are_dropped_with_a_note():
    # a recording starts with readings before the tracker's first pose: the log starts at that pose
    log, _, _ = get_scenario("paper").with_(duration=2.0).generate(0)
    pose = log.pose.copy()
    pose[:5] = np.nan
    trimmed = Log(log.t, pose, log.w_hat, name="late.csv")
    assert len(trimmed) == len(log) - 5 and trimmed.t[0] == log.t[5] and trimmed.has_pose[0]
    np.testing.assert_array_equal(trimmed.w_hat, log.w_hat[5:])
    assert trimmed.notes == [f"late.csv: the first 5 row(s) come before the first pose (at t = {log.t[5]:g} s) "
                             "and were dropped: the log starts at its first pose"]
    assert Log(log.t, log.pose, log.w_hat).notes == []          # a log that starts with a pose keeps every row
