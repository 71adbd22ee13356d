"""The held-out check on every shipped table and log: ``python benchmarks/held_out.py``.

The everyday job's rig first (examples/tool_poses.csv and its check poses and run, :func:`tool_rig`); then, for
each other example table and pose log (examples/README.md): the payload identified on half of it (a table's even
rows, a log's first half) with the sensor's own ``S`` (the identity), then the other half compensated with that
estimate alone (``fmscal.analysis.compensate``), and the residual's rms per channel printed against the noise (a
table's: the identification's own per-pose noise; a log's: its readings' noise estimated from the log), with the
share of rows flagged. docs/status.md quotes it. Seconds.
"""

import sys
from pathlib import Path

import numpy as np

from fmscal.analysis import compensate, read_data
from fmscal.observers.payload import fit_static, identify_payload
from fmscal.plant import Log, NoiseSpec
from fmscal.plant.io import PoseTable, estimate_noise

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def halves(data):
    """The data's two halves: a table's even and odd rows, a log's first and second half."""
    if isinstance(data, PoseTable):
        pick = [np.arange(len(data))[k::2] for k in (0, 1)]
        return [PoseTable(data.q[i], data.w_hat[i], f"{data.name} rows {k}::2",
                          None if data.noise is None else data.noise[i]) for k, i in enumerate(pick)]
    n = len(data.t) // 2
    return [Log(data.t[:n], data.pose[:n], data.w_hat[:n], name=f"{data.name} first half"),
            Log(data.t[n:] - data.t[n], data.pose[n:], data.w_hat[n:], name=f"{data.name} second half")]


def check(name, data):
    """Identify on one half, compensate the other: a row of the table."""
    first, second = halves(data)
    estimate = fit_static(first) if isinstance(first, PoseTable) else identify_payload(first)
    if isinstance(second, PoseTable):
        per_pose = getattr(estimate, "noise_sd", None)
        sd = np.asarray(per_pose if per_pose is not None else estimate.residual_rms, dtype=float)
        noise = NoiseSpec(tuple(sd))
    else:
        noise = estimate_noise(second)
        sd = np.asarray(noise.wrench_sd)
    c = compensate(estimate, second, noise=noise)
    ratio = np.sqrt(np.mean(c.wrench ** 2, axis=0)) / sd
    print(f"| {name} | {len(first.w_hat)} / {len(second.w_hat)} | " + " | ".join(f"{v:.2f}" for v in ratio)
          + f" | {100 * c.contact.mean():.1f} |", flush=True)


def tool_rig():
    """The everyday job's rig: the gripper identified on all of tool_poses.csv, then checked on the other poses
    (tool_check.csv, against the identification's per-pose noise) and compensated on the pushed joint-state run
    (tool_run.csv, its contact-free rows, against the readings' noise: their second differences' sd over
    sqrt 6): two rows."""
    where = dict(urdf=EXAMPLES / "arm6.urdf", frame="ft_sensor")
    estimate = fit_static(read_data(EXAMPLES / "tool_poses.csv", **where))
    check_ = read_data(EXAMPLES / "tool_check.csv", **where)
    c = compensate(estimate, check_)
    ratio = np.sqrt(np.mean(c.wrench ** 2, axis=0)) / np.asarray(estimate.noise_sd)
    print("| examples/tool_poses.csv, checked on tool_check.csv | 8 / 4 | " + " | ".join(f"{v:.2f}" for v in ratio)
          + f" | {100 * c.contact.mean():.1f} |", flush=True)
    from fmscal.analysis import JointMotion
    from fmscal.plant.io import read_joint_log
    motion = JointMotion(where["urdf"], where["frame"])
    run = read_joint_log(EXAMPLES / "tool_run.csv", motion.kinematics)
    c = compensate(estimate, run, motion=motion)
    free = (c.t < 2.8) | (c.t > 4.8)                    # the push: 3 s to 4.3 s, ramped over 0.3 s
    sd = np.std(np.diff(run.w_hat, n=2, axis=0), axis=0) / np.sqrt(6)     # white noise's second differences
    ratio = np.sqrt(np.mean(c.wrench[free] ** 2, axis=0)) / sd
    print("| examples/tool_poses.csv, compensated on tool_run.csv (contact-free rows) | 8 / "
          f"{int(free.sum())} | " + " | ".join(f"{v:.2f}" for v in ratio) + f" | {100 * c.contact[free].mean():.1f} |",
          flush=True)


def main():
    print("| data | rows identified / checked | tx | ty | tz | fx | fy | fz | flagged % |")
    print("|---|---|---|---|---|---|---|---|---|")
    tool_rig()
    check("examples/table.csv", read_data(EXAMPLES / "table.csv"))
    check("examples/joints.csv (arm6.urdf)", read_data(EXAMPLES / "joints.csv", urdf=EXAMPLES / "arm6.urdf",
                                                       frame="ft_sensor"))
    check("examples/arm.csv", read_data(EXAMPLES / "arm.csv"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
