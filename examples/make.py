"""Write the example data the guides' commands read (seeded: the same files at every run).

    python examples/make.py              # rewrite the files in examples/
    python examples/make.py --out DIR    # write them into DIR instead (tests/test_example_data.py compares)

What it writes (examples/README.md says what each is for):

- ``arm.csv`` and ``arm.truth.json``: a spatial log of the ``spatial-arm`` scenario (seed 0), 12 s read at
  25 Hz, each reading the mean of the 40 samples at 1 kHz (the noise's standard deviations over
  sqrt(40)), every number rounded to 1e-6 (below a tenth of the noise);
- ``table.csv`` and ``table.truth.json``: a pose table, 12 held poses of the same tool and sensor, exactly
  what ``fmscal simulate --scenario spatial-arm --poses 12 --seed 0 --out table.csv`` writes;
- ``joints.csv``: a table of held poses whose pose columns are the joint angles of the 6-joint arm
  ``arm6.urdf`` (written by hand, not by this script), its sensor frame ``ft_sensor``; the tool of
  ``spatial-arm``, ``S = I``;
- ``joint_log.csv`` and ``imu_log.csv``: a run of ``arm6.urdf`` (6 s at 100 Hz, every joint moving) carrying the
  tool on ``arm.csv``'s sensor (its ``S``, offset and reading noise), pushed once at the tool point: its joint
  angles, and what an IMU on the tool (the URDF's frame ``imu``) measured, each with the raw readings;
- ``arm_bag/``: a ROS 2 bag (mcap) as a wrist rig records it, the walkthrough's rig
  (``notebooks/07_wrist_walkthrough.ipynb``): the arm's transform tree on ``/tf`` and ``/tf_static``, the
  sensor's ``WrenchStamped`` on ``/ft_sensor/wrench`` at 25 Hz for 12 s (as ``arm.csv``'s); the sensor reports the load
  (the negative of fmscal's reading), the base is tilted 4 degrees and the sensor turned 3 degrees on
  the flange;
- ``tool_poses.csv``, ``tool_check.csv`` and ``tool_run.csv``: the everyday job's rig, a sensor calibrated by its
  maker (``S = I``) on ``arm6.urdf`` with a new tool (:data:`GRIPPER`): 8 held poses to identify it, 4 other held
  poses to check it, and a joint-state run of 5 s at 100 Hz pushed once (as ``joint_log.csv``'s), the same
  sensor's offset throughout;
- ``run_bag/``: a ROS 2 bag (mcap) of ``arm.csv``'s first 4 s: ``PoseStamped`` on ``/tool``, ``WrenchStamped`` on
  ``/ft``.
"""

import argparse
import dataclasses
import shutil
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from fmscal.plant import SPATIAL_SCENARIOS, Log
from fmscal.plant.io import IMU_COLUMNS, RobotKinematics, simulate_table, write_bag, write_pose_table, write_tf_bag
from fmscal.plant.physics import SpatialPayload, rotation_matrices, sensor_wrench
from fmscal.plant.scenarios import TOOL

HERE = Path(__file__).resolve().parent
#: The scenario every example's tool and motion come from.
ARM = SPATIAL_SCENARIOS["spatial-arm"]
#: Decimals kept in arm.csv (the noise is 4e-4 N m and 1e-2 N at its smallest: rounding adds 3e-7).
DECIMALS = 6


#: The examples' sample time, s, and the readings averaged into each (the noise over their square root).
DT, AVERAGED = 0.04, 40


def _write_csv(path, names, rows):
    """A CSV of ``rows`` under the header ``names``, every number rounded to :data:`DECIMALS`."""
    text = "\n".join(",".join(repr(float(v)) for v in np.round(row, DECIMALS)) for row in rows)
    Path(path).write_text(",".join(names) + "\n" + text + "\n")


def spatial_log(out):
    """``arm.csv`` and ``arm.truth.json``; returns the log and its truth."""
    scenario = ARM.with_(duration=12.0, dt=DT).with_noise_scaled(1 / np.sqrt(AVERAGED))
    log, truth, _ = scenario.generate(seed=0)
    _write_csv(out / "arm.csv", log.columns, np.column_stack([log.t, log.pose, log.w_hat]))
    truth.write(out / "arm.truth.json")
    return log, truth


#: The run of the arm ``arm6.urdf`` (joint_log.csv, imu_log.csv): its sample time and length, s.
RUN_DT, RUN_DURATION = 0.01, 6.0
#: The push on the tool during the run: the force in the base's axes (N) at the tool point (sensor axes from the
#: sensor's point, m), held from ``PUSH_TIMES[0]`` to ``PUSH_TIMES[1]`` s, ramped up and down over ``PUSH_RAMP`` s.
PUSH_FORCE, PUSH_POINT, PUSH_TIMES, PUSH_RAMP = (4.0, -3.0, -6.0), (0.0, 0.0, 0.12), (3.0, 4.0), 0.3
#: The joint angles' noise (encoders, rad), and the IMU's: its rate's (rad/s) and its specific force's (m/s^2).
JOINT_SD, GYRO_SD, ACCEL_SD = 2e-6, 1e-3, 0.01


def arm_run(truth, urdf=HERE / "arm6.urdf", tool=TOOL, seed=11, duration=RUN_DURATION):
    """The arm's run: every joint moving, the tool of ``spatial-arm`` on arm.csv's sensor (its ``S``, offset and
    noise, ``truth``), pushed once.

    Returns ``t``, the joints' ``q``, ``dq``, ``ddq`` (exact; their noise is added where they are written), the
    raw reading ``w_hat`` and the push's force ``push`` (N, 3, base axes). The reading is ``S^-1 (W_p - w_e) +
    b + noise``: ``W_p`` the wrench the tool's motion needs (Newton-Euler, :func:`fmscal.plant.physics.
    sensor_wrench`, from the sensor frame's motion by pinocchio), ``w_e`` the push's wrench on the tool at the
    sensor's point.
    """
    t = np.arange(int(round(duration / RUN_DT)) + 1) * RUN_DT
    q0 = np.array([0.2, -1.2, 1.0, -0.6, 0.8, 0.3])
    amplitude = np.array([0.6, 0.3, 0.4, 0.9, 0.8, 1.2])
    omega = 2 * np.pi * np.array([0.21, 0.17, 0.25, 0.31, 0.27, 0.23])
    phase = omega * t[:, None] + np.arange(6)
    q = q0 + amplitude * np.sin(phase)
    dq, ddq = amplitude * omega * np.cos(phase), -amplitude * omega ** 2 * np.sin(phase)
    pose, _, w, a, alpha = RobotKinematics(urdf, "ft_sensor").motion(q, dq, ddq)
    R = rotation_matrices(pose[:, :4])
    p_ddot = np.einsum("nij,nj->ni", R, a)                          # the classical acceleration, in the base's axes
    W = np.array([sensor_wrench(pose[k, :4], w[k], alpha[k], p_ddot[k], tool, ARM.gravity) for k in range(len(t))])
    up = np.clip((t - PUSH_TIMES[0]) / PUSH_RAMP, 0, 1)
    down = np.clip((PUSH_TIMES[1] + PUSH_RAMP - t) / PUSH_RAMP, 0, 1)
    push = np.outer(np.minimum(up, down) ** 2 * (3 - 2 * np.minimum(up, down)), PUSH_FORCE)     # a smoothstep
    f_e = np.einsum("nji,nj->ni", R, push)                           # in the sensor's axes
    w_e = np.c_[np.cross(PUSH_POINT, f_e), f_e]
    rng = np.random.default_rng(seed)
    w_hat = (truth.schedule.raw_reading(t, W - w_e) + truth.offset
             + rng.standard_normal(W.shape) * np.array(truth.noise.wrench_sd))
    return dict(t=t, q=q, dq=dq, ddq=ddq, w_hat=w_hat, push=push)


def joint_log(out, run):
    """``joint_log.csv``: the run's time, joint angles (``JOINT_SD`` of noise) and raw readings."""
    rng = np.random.default_rng(12)
    names = ["t", *(f"q{i + 1}" for i in range(6)), "tx", "ty", "tz", "fx", "fy", "fz"]
    joints = run["q"] + rng.normal(0, JOINT_SD, run["q"].shape)
    _write_csv(out / "joint_log.csv", names, np.column_stack([run["t"], joints, run["w_hat"]]))


def imu_log(out, run, urdf=HERE / "arm6.urdf"):
    """``imu_log.csv``: the run as an IMU on the tool saw it (arm6.urdf's frame ``imu``), with the raw readings.

    The IMU's orientation is its frame's in the base; its rate and specific force ``R_i^T (p_ddot_i - g)`` are
    its frame's angular velocity and classical acceleration less gravity, in its axes (pinocchio), plus white
    noise (``GYRO_SD``, ``ACCEL_SD``).
    """
    rng = np.random.default_rng(13)
    pose, _, w, a, _ = RobotKinematics(urdf, "imu").motion(run["q"], run["dq"], run["ddq"])
    R = rotation_matrices(pose[:, :4])
    f = a - np.einsum("nji,j->ni", R, ARM.gravity)
    w = w + rng.normal(0, GYRO_SD, w.shape)
    f = f + rng.normal(0, ACCEL_SD, f.shape)
    names = ["t", *IMU_COLUMNS, "tx", "ty", "tz", "fx", "fy", "fz"]
    _write_csv(out / "imu_log.csv", names, np.column_stack([run["t"], pose[:, :4], w, f, run["w_hat"]]))


def pose_table(out):
    """``table.csv`` and ``table.truth.json``: ``fmscal simulate --scenario spatial-arm --poses 12 --seed 0``."""
    table, truth = ARM.generate_table(seed=0, poses=12)
    write_pose_table(table, out / "table.csv")
    truth.write(out / "table.truth.json")


def joint_table(out, urdf=HERE / "arm6.urdf"):
    """``joints.csv``: 16 held poses of the arm, the joint angles and the averaged reading."""
    rng = np.random.default_rng(7)
    joints = rng.uniform(-np.pi, np.pi, (16, 6))
    joints[:, 1] = rng.uniform(-2.0, -0.5, 16)                  # the arm up, the tool turned every way
    kinematics = RobotKinematics(urdf, "ft_sensor")
    q = kinematics.poses(joints)[:, :4]
    offset = np.r_[rng.normal(0, ARM.offset_sd[0], 3), rng.normal(0, ARM.offset_sd[1], 3)]
    table = simulate_table(TOOL, n=len(q), seed=8, gravity=ARM.gravity, offset=offset, q=q)
    names = [f"q{i + 1}" for i in range(6)] + ["tx", "ty", "tz", "fx", "fy", "fz"]
    _write_csv(out / "joints.csv", names, np.hstack([joints, table.w_hat]))


#: The everyday job's tool: a gripper of 0.8 kg (mass, inertia about its centre of mass in kg m^2, centre of mass
#: in the sensor frame in m).
GRIPPER = SpatialPayload(0.8, (2.2e-3, 2.6e-3, 1.1e-3, 1e-4, 0.0, -5e-5), (0.004, 0.002, 0.045))
#: Its held poses' noise (each the mean of 0.5 s at 1 kHz of spatial-arm's sensor), N m and N; the run's readings
#: are 100 Hz, each the mean of 10 samples at 1 kHz.
HELD_AVERAGED, RUN_AVERAGED = 500, 10
#: The everyday run's length, s (the push at 3-4.3 s within it; the folder kept small).
EVERYDAY_DURATION = 5.0


def everyday(out, urdf=HERE / "arm6.urdf"):
    """``tool_poses.csv``, ``tool_check.csv``, ``tool_run.csv``: the sensor as its maker calibrated it (``S = I``,
    an offset drawn as spatial-arm's), :data:`GRIPPER` held at 8 and then at 4 other joint angles, and moved in the
    run of :func:`arm_run`, pushed once."""
    rng = np.random.default_rng(21)
    offset = np.r_[rng.normal(0, ARM.offset_sd[0], 3), rng.normal(0, ARM.offset_sd[1], 3)]
    held_sd = np.r_[(ARM.torque_sd,) * 3, (ARM.force_sd,) * 3] / np.sqrt(HELD_AVERAGED)
    kinematics = RobotKinematics(urdf, "ft_sensor")
    names = [f"q{i + 1}" for i in range(6)] + ["tx", "ty", "tz", "fx", "fy", "fz"]
    for name, n, seed in (("tool_poses.csv", 8, 22), ("tool_check.csv", 4, 23)):
        joints = rng.uniform(-np.pi, np.pi, (n, 6))
        joints[:, 1] = rng.uniform(-2.0, -0.5, n)              # the arm up, the tool turned every way
        q = kinematics.poses(joints)[:, :4]
        table = simulate_table(GRIPPER, n=n, seed=seed, gravity=ARM.gravity, offset=offset, q=q, wrench_sd=held_sd)
        _write_csv(out / name, names, np.hstack([joints, table.w_hat]))
    scenario = ARM.with_(crosstalk=0.0).with_noise_scaled(1 / np.sqrt(RUN_AVERAGED))
    _, truth, _ = scenario.generate(seed=0)
    truth = dataclasses.replace(truth, offset=offset)
    run = arm_run(truth, urdf, tool=GRIPPER, seed=24, duration=EVERYDAY_DURATION)
    rng = np.random.default_rng(25)
    names = ["t", *(f"q{i + 1}" for i in range(6)), "tx", "ty", "tz", "fx", "fy", "fz"]
    joints = run["q"] + rng.normal(0, JOINT_SD, run["q"].shape)
    _write_csv(out / "tool_run.csv", names, np.column_stack([run["t"], joints, run["w_hat"]]))


def wrist_bag(out, duration=12.0, dt=DT):
    """``arm_bag/``: the walkthrough's rig (notebooks/07_wrist_walkthrough.ipynb) at 25 Hz."""
    tilt = Rotation.from_rotvec(np.radians(4.0) * np.array([0.8, -0.6, 0.0]))      # the base, 4 degrees
    axis = np.array([0.2, 0.4, 0.9]) / np.linalg.norm([0.2, 0.4, 0.9])
    mount = Rotation.from_rotvec(np.radians(3.0) * axis)        # the sensor's axes on ft_sensor, 3 degrees
    scenario = ARM.with_(duration=duration, dt=dt, gravity=tuple(tilt.apply([0.0, 0.0, -9.81])),
                         crosstalk=0.0).with_noise_scaled(1 / np.sqrt(AVERAGED))
    log, _, _ = scenario.generate(seed=3)
    t = log.t
    sensor = Rotation.from_quat(np.roll(log.pose[:, :4], -1, axis=1))     # the sensor's attitude in base_link
    nominal = sensor * mount.inv()                                        # the ft_sensor frame /tf_static says
    yaw = Rotation.from_rotvec(np.outer(0.6 * np.sin(0.3 * t), [0.0, 0.0, 1.0]))
    shoulder, to_sensor = np.array([0.0, 0.0, 0.3]), np.array([0.0, 0.0, 0.10])
    wrist = yaw.inv() * nominal
    wrist_p = yaw.inv().apply(log.pose[:, 4:] - nominal.apply(to_sensor) - shoulder)
    links = [("base_link", "shoulder", yaw, np.tile(shoulder, (len(t), 1))), ("shoulder", "wrist", wrist, wrist_p)]
    static = [("wrist", "flange", Rotation.identity(), [0.0, 0.0, 0.08]),
              ("flange", "ft_sensor", Rotation.identity(), [0.0, 0.0, 0.02])]
    write_tf_bag(out / "arm_bag", t, np.round(-log.w_hat, DECIMALS), links, static,
                 wrench_topic="/ft_sensor/wrench", storage="mcap")        # the load convention


def pose_bag(out, log):
    """``run_bag/``: ``log`` as a ROS 2 bag (mcap), ``PoseStamped`` on ``/tool`` and ``WrenchStamped`` on ``/ft``."""
    first = log.t <= 4.0                                                  # its first 4 s: a bag to import
    short = Log(log.t[first], log.pose[first], log.w_hat[first], name=log.name)
    write_bag(short, out / "run_bag", storage="mcap", wrench_topic="/ft", pose_topic="/tool")


def make(out):
    """Write every example into the folder ``out`` (created; its bags replaced)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for bag in ("arm_bag", "run_bag"):
        shutil.rmtree(out / bag, ignore_errors=True)
    log, truth = spatial_log(out)
    pose_table(out)
    joint_table(out)
    run = arm_run(truth)
    joint_log(out, run)
    imu_log(out, run)
    everyday(out)
    wrist_bag(out)
    pose_bag(out, log)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(HERE), help="the folder to write (default: examples/)")
    make(parser.parse_args(argv).out)


if __name__ == "__main__":
    sys.exit(main())
