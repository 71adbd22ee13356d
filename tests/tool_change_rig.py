"""A tool change's scenarios, for its tests and benchmark (benchmarks/tool_change.py): a grasp on ``spatial-arm``,
benchmarks/drift.py's logs for the false alarms, a grasp at a held attitude of ``spatial-static`` re-identified.

Every log is moved onto the sensor ``(S, b)`` a calibration ``cal`` is of (``fmscal.plant.scenarios.same_rig``).
"""

import numpy as np

from fmscal.analysis import compensate
from fmscal.plant import SPATIAL_SCENARIOS, SpatialPayload
from fmscal.plant.physics import rotation_matrices
from fmscal.plant.scenarios import contact_wrench, drift_contact_log, same_rig, with_grasp
from live_rig import DRIFT_CONTACT, DRIFT_PUSH

ARM = SPATIAL_SCENARIOS["spatial-arm"]
STATIC = SPATIAL_SCENARIOS["spatial-static"].with_(duration=60.0)
#: The part: 200 g, its centre of mass 15 cm out (sensor axes), a 5 cm cube's inertia.
PART = SpatialPayload(0.2, (8.3e-5, 8.3e-5, 8.3e-5, 0.0, 0.0, 0.0), (0.0, 0.03, 0.15))
GRASP_WITHIN, TURN_DEG = 2.0, 30.0
MASS_WITHIN, COM_WITHIN = 0.02 * PART.mass, 0.005


def gravity_turn(log, start, stop):
    """The largest angle gravity's direction turned in the sensor's axes over ``[start, stop]`` from its direction at
    ``start``, degrees (the log's poses)."""
    rows = (log.t >= start) & (log.t <= stop) & log.has_pose
    down = np.einsum("nji,j->ni", rotation_matrices(log.pose[rows, :4], normalise=True), [0.0, 0.0, -1.0])
    return float(np.degrees(np.arccos(np.clip(down @ down[0], -1.0, 1.0)).max()))


def grasp(seed, cal, S, b, paths=(True, False)):
    """The grasp on ``seed``'s 30 s log: per path (causal True, offline False), the first change declared after the
    grasp and what it says, and the changes declared before it."""
    at = float(np.random.default_rng(seed).uniform(8.0, 20.0))
    log, truth, total = with_grasp(ARM.with_(duration=30.0), seed, PART, at)
    log = same_rig(log, truth.S_at(0.0), truth.offset, S, b)
    out = {"at": at, "turn": gravity_turn(log, at, at + GRASP_WITHIN)}
    for causal in paths:
        c = compensate(cal, log, causal=causal)
        before = [e for e in c.tool_changes if e.declared < at]
        after = [e for e in c.tool_changes if e.declared >= at]
        first = after[0] if after else None
        out["causal" if causal else "offline"] = dict(
            early=len(before), declared=None if first is None else first.declared - at,
            tau=None if first is None else first.t - at, mass=None if first is None else first.mass_change,
            turned=None if first is None else gravity_turn(log, at, first.declared), more=max(len(after) - 1, 0))
    return out


def false_alarms(seed, cal, S, b, logs=("contact", "push"), paths=(True, False)):
    """The times of the changes declared on ``seed``'s drift logs (benchmarks/drift.py's), per log and path."""
    log, truth, _ = ARM.generate(seed)
    base = same_rig(log, truth.S_at(0.0), truth.offset, S, b)
    touched, _, _ = drift_contact_log(base, S, contact=contact_wrench(15.0), contact_at=DRIFT_CONTACT, seed=seed)
    pushed, _, _ = drift_contact_log(base, S, push=contact_wrench(10.0, direction=(0.0, 0.6, -0.8)),
                                     push_at=DRIFT_PUSH, seed=seed)
    out = {}
    for name, data in (("contact", touched), ("push", pushed)):
        if name not in logs:
            continue
        for causal in paths:
            c = compensate(cal, data, causal=causal, track_offset=True)
            out[(name, causal)] = [e.t for e in c.tool_changes]
    return out


def reidentified(seed, cal, S, b):
    """The grasp in the first held attitude of ``seed``'s 60 s static log, re-identified as the stream goes."""
    at = float(np.random.default_rng(seed).uniform(0.5, 2.0))
    log, truth, total = with_grasp(STATIC, seed, PART, at)
    log = same_rig(log, truth.S_at(0.0), truth.offset, S, b)
    c = compensate(cal, log, causal=True, track_offset=True, tool_change="reidentify")
    first = next((e for e in c.tool_changes if e.declared >= at), None)
    fit = None if first is None else first.reidentified
    out = {"at": at, "changes": len(c.tool_changes), "declared": None if first is None else first.declared - at,
           "declared_mass": None if first is None else first.mass_change}
    if fit is not None:
        out.update(mass=fit.mass - total.mass, com=float(np.linalg.norm(np.asarray(fit.com) - total.com)),
                   poses=first.poses, when=first.reidentified_at, mass_sd=fit.mass_std)
        after = c.t > first.reidentified_at + 1.0
        out["contact_after"] = float(c.contact[after].mean())
    return out
