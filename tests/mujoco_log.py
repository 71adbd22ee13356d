"""A spatial log written by MuJoCo, an engine independent of fmscal's simulator.

The payload is a MuJoCo free body with the tool's mass, centre of mass and
full inertia tensor, driven by six motors on a site at the sensor point
(force along and torque about the sensor's axes) with the wrench a scenario's
motion needs. MuJoCo integrates at a tenth of the log's sample time (RK4),
the wrench held at its mid-step value over each sub-step, so that its
trajectory is the continuous one to well below the pose noise; the log
samples it at the scenario's rate. The reading and the poses are then made
as a scenario makes them (``w_hat = S^-1 w + b + n``, a turn of white noise
about the sensor's axes, white position noise), with the random draws in the
scenario's order, so that the same seed gives fmscal's own simulation of the
same motion, noise and sensor: the two logs differ only by the engine.

With ``hold=True`` the log is written as an engine steps and logs a
controller: MuJoCo steps at the log's sample time (RK4), each step's wrench
held over it (a zero-order hold) and recorded with the pose at the step's
start. The wrench held is the motion's at the step's middle, so that the
payload keeps to the scenario's motion (the step's mean wrench to second
order); the reading recorded is the wrench held. The wrench then drives the
motion as the continuous one half a step later would: the log's poses are,
to fmscal's models, half a sample late (``dt / 2``: the cross-correlation
and the floor's own likelihood both find it,
:mod:`fmscal.observers.batch._latency`).
"""

import numpy as np
from scipy.spatial.transform import Rotation

from fmscal.plant import Log, SpatialModel
from fmscal.plant.scenarios._spatial import draw_spatial_S

SUBSTEPS = 10


def mujoco_model(payload, gravity, dt):
    """A MuJoCo model of ``payload`` on a free joint, six motors at the sensor point ``O``."""
    import mujoco
    inertial = (f'<inertial pos="{" ".join(map(str, payload.com))}" mass="{payload.mass}" '
                f'fullinertia="{" ".join(map(str, payload.inertia))}"/>')
    motors = "".join(f'<motor site="O" ctrllimited="false" gear="{" ".join(str(int(i == j)) for i in range(6))}"/>'
                     for j in range(6))
    return mujoco.MjModel.from_xml_string(
        f'<mujoco><option timestep="{dt}" integrator="RK4" gravity="{" ".join(map(str, gravity))}"/>'
        f'<worldbody><body name="payload"><freejoint/>{inertial}<site name="O"/></body></worldbody>'
        f'<actuator>{motors}</actuator></mujoco>')


def mujoco_log(scenario, seed, latency=0.0, hold=False):
    """A log of ``scenario``'s motion as MuJoCo integrates it; ``(log, S, b)``.

    Parameters
    ----------
    scenario : plant.SpatialScenario
        A scenario with a pose at every sample, no latency and no dropped frames.
    seed : int
    latency : float
        s, of either sign: the pose stream this late, each pose that of ``t - latency`` interpolated
        (:meth:`fmscal.plant.SpatialModel.interpolate_pose`) before its noise is drawn, as a late pose stream
        is measured; the rows with no pose of their own dropped.
    hold : bool
        MuJoCo steps at the log's sample time instead, each step's wrench held over it and recorded with the pose
        at its start: a zero-order hold, as a controller's command is applied and an engine's log is written
        (module docstring).

    Returns
    -------
    log : plant.Log
    S : ndarray, shape (6, 6)
    b : ndarray, shape (6,)
    """
    import mujoco
    dt, n = scenario.dt, int(round(scenario.duration / scenario.dt)) + 1
    rng = np.random.default_rng(seed)
    motion = scenario.motion_function(rng)
    x0 = np.array(motion(0.0)[0]).ravel()
    # what the sensor reads, at the samples; held, the wrench of the step that starts there (its middle's)
    wrench = np.array(motion.map(n)((np.arange(n) + 0.5 * hold) * dt)[1]).T
    substeps = 1 if hold else SUBSTEPS
    fine = wrench[:-1] if hold else np.array(
        motion.map((n - 1) * SUBSTEPS)((np.arange((n - 1) * SUBSTEPS) + 0.5) * dt / SUBSTEPS)[1]).T
    model = mujoco_model(scenario.payload, scenario.gravity, dt / substeps)
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = x0[:7], x0[7:13]                           # free joint: v in W, omega in B
    qpos = np.empty((n, 7))
    qpos[0] = data.qpos
    ctrl = np.c_[fine[:, 3:], fine[:, :3]]                                  # motors: force first
    for k in range(n - 1):
        for j in range(substeps):
            data.ctrl[:] = ctrl[k * substeps + j]
            mujoco.mj_step(model, data)
        qpos[k + 1] = data.qpos
    S = draw_spatial_S(rng, scenario.crosstalk)
    b = np.r_[rng.normal(0, scenario.offset_sd[0], 3), rng.normal(0, scenario.offset_sd[1], 3)]
    sd = np.r_[[scenario.torque_sd] * 3, [scenario.force_sd] * 3]
    w_hat = np.linalg.solve(S, wrench.T).T + b + rng.standard_normal((n, 6)) * sd
    pose = np.c_[qpos[:, 3:7], qpos[:, 0:3]]                                # log order: q, p
    t = np.arange(n) * dt
    if latency:
        rows = np.flatnonzero((t - latency >= t[0]) & (t - latency <= t[-1]))
        pose = SpatialModel.interpolate_pose(t[rows] - latency, t, pose)
        t, w_hat, n = t[rows], w_hat[rows], len(rows)
    turn = Rotation.from_rotvec(rng.standard_normal((n, 3)) * scenario.angle_sd)
    pose[:, :4] = np.roll((Rotation.from_quat(np.roll(pose[:, :4], -1, axis=1)) * turn).as_quat(), 1, axis=1)
    pose[:, 4:] += rng.standard_normal((n, 3)) * scenario.position_sd
    return Log(t, pose, w_hat, name=f"mujoco-{scenario.name}{'-held' if hold else ''}-seed{seed}"), S, b
