"""Compensation's residual and cost: ``python benchmarks/compensation.py``.

A calibration from one 60 s ``spatial-arm`` log (seed 1, the default method), used on other logs of the same
rig with no contact (seed 2: fmscal's simulator 60 s, MuJoCo 20 s, ``tests/mujoco_log.py``; the readings moved
onto the first sensor, ``fmscal.plant.scenarios.same_rig``), prints:

- the residual's rms per channel over the reading's noise times S, offline and causal (issue 38's targets:
  1.3x and 2x with a delay of at most 40 ms);
- the causal residual against the delay (the window twice the delay, read at its centre);
- the same at 200 Hz (``spatial-mocap``: calibrated on its seed 1, compensated on seed 2, 20 s);
- a 15 N contact of 2 s: its estimate and the share of its samples flagged;
- :class:`fmscal.analysis.Compensator`'s cost per sample, p50 and p99;
- the planar model through the same code (``--planar`` alone: this part only; no target): ``paper`` and
  ``real-rig`` (50 Hz poses: offline also with a 0.4 s window, causally a 0.2 s window read at 0.1 s), the
  residual and the share flagged;
- the motion's other sources (``--sources`` alone: this part only): a UR5 carrying the tool for 20 s at 1 kHz
  (``tests/robot_rig.py``: the payload's wrench by pinocchio's rnea, independent of fmscal's dynamics), its
  readings those of the calibrated sensor plus its noise; the residual from the tool frame's poses (with the
  scenario's pose noise), from the joint angles (1e-5 rad of noise; with and without measured joint rates,
  1e-3 rad/s of noise) and from an IMU on the tool (gyroscope 2 mrad/s, accelerometer 0.03 m/s^2, turned and
  7 cm off the sensor's point), offline and causal, the causal residual of the joints and the IMU against
  the delay, and the cost per sample of each;
- ``--blocks`` alone: :meth:`fmscal.analysis.Compensator.push_many`'s cost per row for blocks of 1 to 16 rows,
  every block fitted whole, every row one at a time, and as it is (blocks of fewer than ``BLOCK_MIN`` rows one at
  a time): where the first costs less than the second chooses ``BLOCK_MIN`` (analysis/_compensate.py).

docs/guide/compensation.md quotes it. About a minute on 2 cores (the sources' part about half of it).
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from fmscal.analysis import Compensator, ImuMotion, calibrate, compensate  # noqa: E402
from fmscal.analysis import CAUSAL_WINDOW  # noqa: E402
from fmscal.plant import SCENARIOS, SPATIAL_SCENARIOS, Log  # noqa: E402
from fmscal.plant.io import ImuLog, JointLog  # noqa: E402
from fmscal.plant.scenarios import contact_wrench, same_rig, with_contact  # noqa: E402
from live_rig import noise_rms  # noqa: E402


def ratios(c, ref):
    return np.sqrt(np.mean(c.wrench ** 2, axis=0)) / ref


def row(name, values):
    print(f"| {name} | " + " | ".join(f"{v:.2f}" for v in values) + " |", flush=True)


def cost(stream, samples):
    """p50 and p99 of ``stream.push`` over ``samples`` (keyword arguments per sample), the first 1,000 left out."""
    spent = []
    for t, w, kw in samples:
        start = time.perf_counter()
        stream.push(t, w, **kw)
        spent.append(time.perf_counter() - start)
    spent = np.array(spent[1000:]) * 1e6
    return np.percentile(spent, 50), np.percentile(spent, 99)


def blocks(cal, log, truth, rows=2400, repeats=5):
    """``push_many``'s cost per row (us, the median of ``repeats`` passes of ``rows`` rows each, the three ways
    alternated) for blocks of each size: every block of 2 rows or more fitted whole, every row one at a time
    (:meth:`~fmscal.analysis.Compensator.push`'s path), and as it is (``BLOCK_MIN``)."""
    from fmscal.analysis import _compensate
    chosen = _compensate.BLOCK_MIN
    print(f"\nCompensator.push_many, us per row (blocks of the size given; BLOCK_MIN {chosen})\n")
    print("| rows a block | fitted whole | one at a time | as it is |")
    print("|---|---|---|---|")
    try:
        for size in (1, 2, 3, 4, 6, 8, 16):
            spent = {2: [], 10 ** 9: [], chosen: []}
            for _ in range(repeats):                   # the two ways alternated: a machine's drift shared
                for block_min in spent:
                    _compensate.BLOCK_MIN = block_min
                    stream = Compensator(cal, log.dt, noise=truth.noise)
                    stream.push_many(log.t[:1000], log.w_hat[:1000], log.pose[:1000])       # warm-up
                    start = time.perf_counter()
                    for i in range(1000, 1000 + rows, size):
                        stream.push_many(log.t[i:i + size], log.w_hat[i:i + size], log.pose[i:i + size])
                    spent[block_min].append((time.perf_counter() - start) / rows * 1e6)
            print(f"| {size} | " + " | ".join(f"{np.median(v):.0f}" for v in spent.values()) + " |", flush=True)
    finally:
        _compensate.BLOCK_MIN = chosen


def sources(cal, truth, seed=5, duration=20.0):
    """The residual from poses, joint angles and an IMU on one UR5 log (module docstring)."""
    import robot_rig
    rng = np.random.default_rng(seed)
    run = robot_rig.ur5_run(duration, payload=cal.payload)
    S, b, sd = truth.S_at(0.0), truth.offset, np.asarray(truth.noise.wrench_sd)
    w_hat = np.linalg.solve(S, run["W"].T).T + b + rng.normal(0, 1, run["W"].shape) * sd
    ref = noise_rms(S, sd)
    turn = Rotation.from_quat(run["pose"][:, [1, 2, 3, 0]]) * Rotation.from_rotvec(
        rng.normal(0, truth.noise.angle_sd, (len(run["t"]), 3)))
    pose = np.c_[turn.as_quat(scalar_first=True),
                 run["pose"][:, 4:] + rng.normal(0, truth.noise.position_sd, (len(run["t"]), 3))]
    q = run["q"] + rng.normal(0, 1e-5, run["q"].shape)
    dq = run["dq"] + rng.normal(0, 1e-3, run["q"].shape)
    quaternion, omega_i, f_i, _ = robot_rig.imu_readings(run, rng, 0.002, 0.03)
    imu = ImuMotion(robot_rig.C_IMU, robot_rig.R_IMU)
    paths = {"poses (the scenario's pose noise)": (Log(run["t"], pose, w_hat), None),
             "joint angles": (JointLog(run["t"], q, w_hat), run["motion"]),
             "joint angles and rates": (JointLog(run["t"], q, w_hat, velocities=dq), run["motion"]),
             "IMU": (ImuLog(run["t"], quaternion, omega_i, f_i, w_hat), imu)}
    print(f"\nthe motion's sources: a UR5 for {duration:g} s at 1 kHz (tests/robot_rig.py), no contact; residual rms "
          "/ (reading noise times S)\n")
    print("| source, path | tx | ty | tz | fx | fy | fz |")
    print("|---|---|---|---|---|---|---|")
    for name, (log, motion) in paths.items():
        row(f"{name}, offline", ratios(compensate(cal, log, motion=motion), ref))
        causal = compensate(cal, log, causal=True, motion=motion)
        row(f"{name}, causal ({causal.delay * 1e3:.0f} ms)", ratios(causal, ref))
    k = int(round(8.0 / 1e-3))
    print("\ncausal residual against the delay, the first 8 s (window twice the delay)\n")
    print("| source, delay | tx | ty | tz | fx | fy | fz |")
    print("|---|---|---|---|---|---|---|")
    shorter = {"joint angles": JointLog(run["t"][:k], q[:k], w_hat[:k]),
               "IMU": ImuLog(run["t"][:k], quaternion[:k], omega_i[:k], f_i[:k], w_hat[:k])}
    for name, log in shorter.items():
        for delay in (0.005, 0.01, 0.02):
            c = compensate(cal, log, causal=True, motion=paths[name][1], window=2 * delay, delay=delay)
            row(f"{name}, {delay * 1e3:.0f} ms", ratios(c, ref))
    n = min(len(run["t"]), 6000)
    print(f"\nCompensator.push per sample ({n - 1000} samples after 1,000 of warm-up), p50 and p99, us\n")
    print("| source | p50 | p99 |")
    print("|---|---|---|")
    feeds = {"poses": (None, [dict(pose=p) for p in pose[:n]]),
             "joint angles": (run["motion"], [dict(joints=(v, None, None)) for v in q[:n]]),
             "IMU": (imu, [dict(imu=v) for v in zip(quaternion[:n], omega_i[:n], f_i[:n])])}
    for name, (motion, kws) in feeds.items():
        stream = Compensator(cal, 1e-3, noise=truth.noise, motion=motion)
        p50, p99 = cost(stream, zip(run["t"][:n], w_hat[:n], kws))
        print(f"| {name} | {p50:.0f} | {p99:.0f} |", flush=True)


def planar():
    """The planar model through the same code: ``paper`` (poses at 1 kHz) and ``real-rig`` (50 Hz, 10 % dropped,
    20 ms late), each calibrated on its seed 1 (100 s) and compensating its seed 2 moved onto that sensor: the
    residual over the noise times S per channel, and the share of samples flagged as contact (none is one)."""
    print("\nthe planar model (no target): residual rms / (reading noise times S), no contact; flagged, %\n")
    print("| log, path | M | fx | fy | flagged, % |")
    print("|---|---|---|---|---|")
    paths = {"paper": [("offline", False, {}), ("causal", True, {})],
             "real-rig": [("offline", False, {}), ("offline, window 0.4 s", False, {"window": 0.4}),
                          ("causal, window 0.2 s", True, {"window": 0.2, "delay": 0.1})]}
    for name, settings in paths.items():
        scenario = SCENARIOS[name]
        log, truth, _ = scenario.generate(1)
        cal = calibrate(log, scenario.payload)
        second, truth2, _ = scenario.generate(2)
        offset = lambda b: np.zeros(3) if b is None else b  # noqa: E731 (the paper's sensor has none)
        other = same_rig(second, truth2.S_at(0.0), offset(truth2.offset), truth.S_at(0.0), offset(truth.offset))
        ref = noise_rms(truth2.S_at(0.0), truth.noise.wrench_sd)
        for path, causal, options in settings:
            c = compensate(cal, other, causal=causal, **options)
            path += f" ({c.delay * 1e3:.0f} ms)" if causal else ""
            print(f"| {name}, {path} | " + " | ".join(f"{v:.2f}" for v in ratios(c, ref))
                  + f" | {100 * c.contact.mean():.2f} |", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sources", action="store_true", help="the motion's other sources only")
    parser.add_argument("--planar", action="store_true", help="the planar model only")
    parser.add_argument("--blocks", action="store_true", help="push_many's cost per row by block size only")
    args = parser.parse_args()
    only_sources = args.sources
    if args.planar:
        planar()
        return
    arm = SPATIAL_SCENARIOS["spatial-arm"]
    log, truth, _ = arm.generate(1)
    t0 = time.perf_counter()
    cal = calibrate(log, arm.payload)
    print(f"calibration: {cal.method} on {log.name} ({time.perf_counter() - t0:.0f} s), converged {cal.converged}")
    if only_sources:
        sources(cal, truth)
        return
    if args.blocks:
        second, truth2, _ = arm.generate(2)
        blocks(cal, same_rig(second, truth2.S_at(0.0), truth2.offset, truth.S_at(0.0), truth.offset), truth)
        return
    S, b = truth.S_at(0.0), truth.offset
    logs = {}
    second, truth2, _ = arm.generate(2)
    logs["fmscal 1 kHz"] = (same_rig(second, truth2.S_at(0.0), truth2.offset, S, b), truth2.S_at(0.0))
    try:
        from mujoco_log import mujoco_log
        second, S2, b2 = mujoco_log(arm.with_(duration=20.0), 2)
        logs["MuJoCo 1 kHz"] = (same_rig(second, S2, b2, S, b), S2)
    except ImportError:
        print("(mujoco not installed: its row left out)")
    print("\nresidual rms / (reading noise times S), no contact\n")
    print("| log, path | tx | ty | tz | fx | fy | fz |")
    print("|---|---|---|---|---|---|---|")
    for name, (other, S2) in logs.items():
        ref = noise_rms(S2, truth.noise.wrench_sd)
        row(f"{name}, offline", ratios(compensate(cal, other), ref))
        causal = compensate(cal, other, causal=True)
        row(f"{name}, causal ({causal.delay * 1e3:.0f} ms)", ratios(causal, ref))
    other, S2 = logs["fmscal 1 kHz"]
    ref = noise_rms(S2, truth.noise.wrench_sd)
    print("\ncausal residual against the delay (fmscal 1 kHz; window twice the delay)\n")
    print("| delay, ms | tx | ty | tz | fx | fy | fz |")
    print("|---|---|---|---|---|---|---|")
    for delay in (0.005, 0.01, 0.02, 0.03, 0.04):
        row(f"{delay * 1e3:.0f}", ratios(compensate(cal, other, causal=True, window=2 * delay, delay=delay), ref))

    mocap = SPATIAL_SCENARIOS["spatial-mocap"]
    mlog, mtruth, _ = mocap.generate(1)
    mcal = calibrate(mlog, mocap.payload)
    second, mtruth2, _ = mocap.with_(duration=20.0).generate(2)
    other_m = same_rig(second, mtruth2.S_at(0.0), mtruth2.offset, mtruth.S_at(0.0), mtruth.offset)
    ref_m = noise_rms(mtruth2.S_at(0.0), mtruth.noise.wrench_sd)
    print(f"\n200 Hz poses (spatial-mocap; calibration latency {mcal.latency * 1e3:.1f} ms), no target\n")
    print("| path | tx | ty | tz | fx | fy | fz |")
    print("|---|---|---|---|---|---|---|")
    row("offline", ratios(compensate(mcal, other_m), ref_m))
    for window, delay in ((None, 0.03), (0.12, 0.06)):
        causal = compensate(mcal, other_m, causal=True, window=window, delay=delay)
        row(f"causal ({causal.delay * 1e3:.0f} ms, window {1e3 * (window or CAUSAL_WINDOW):.0f} ms)",
            ratios(causal, ref_m))

    wrench = contact_wrench()
    touched, _ = with_contact(other, S, wrench, 20.0, 2.0)
    print("\na contact of 15 N for 2 s (fmscal 1 kHz), samples 0.1 s inside it\n")
    print("| path | force, N | error, % of the wrench | flagged inside, % | flagged outside, % |")
    print("|---|---|---|---|---|")
    for causal in (False, True):
        c = compensate(cal, touched, causal=causal)
        inside = (c.t >= 20.1) & (c.t < 21.9)
        outside = (c.t < 19.9) | (c.t >= 22.1)
        mean = c.wrench[inside].mean(axis=0)
        print(f"| {'causal' if causal else 'offline'} | {np.linalg.norm(mean[3:]):.2f} | "
              f"{100 * np.linalg.norm(mean - wrench) / np.linalg.norm(wrench):.1f} | "
              f"{100 * c.contact[inside].mean():.1f} | {100 * c.contact[outside].mean():.2f} |")

    stream = Compensator(cal, other.dt, noise=truth.noise)
    cost = []
    for t, w, p in zip(other.t[:20000], other.w_hat, other.pose):
        start = time.perf_counter()
        stream.push(t, w, p)
        cost.append(time.perf_counter() - start)
    cost = np.array(cost[1000:]) * 1e6
    print(f"\nCompensator.push, per sample (19,000 samples after 1,000 of warm-up): "
          f"p50 {np.percentile(cost, 50):.0f} us, p99 {np.percentile(cost, 99):.0f} us")
    planar()
    sources(cal, truth)


if __name__ == "__main__":
    main()
