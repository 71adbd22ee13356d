"""The ROS 2 node (``fmscal ros2``, fmscal.analysis.ros2) on real ROS 2: the node in a subprocess, a publisher
and a subscriber in this process, over DDS on loopback (tests/ros2_rig.py: a ROS domain per test, discovery on
this machine only, every wait bounded, the node stopped in a ``finally``).

The replayed logs are spatial-arm's at 1 kHz, compensated with a calibration holding the scenario's truth: the
node's output is compared with ``compensate(..., causal=True)`` on the same log.
"""

import json
import subprocess
import sys
import time
import types
from pathlib import Path

import numpy as np
import pytest

from fmscal.analysis import Compensator, ImuMotion, calibrate, compensate
from fmscal.analysis.cli import main
from fmscal.analysis.ros2 import PARAMETERS, Pipeline, Ros2Error, sensor_pose, settings
from fmscal.plant.physics import rotation_matrix
from fmscal.plant import SCENARIOS, SPATIAL_SCENARIOS, Calibration, Log, SpatialModel
from fmscal.plant import NoiseSpec
from fmscal.plant.io import simulate_attitude_log
from fmscal.plant.scenarios._spatial import TOOL
from live_rig import contact_wrench, noise_rms, with_contact
from geometry_msgs.msg import PoseStamped
from ros2_rig import (HARNESS_NOISE, WAIT, Peer, contact_array, domain_id, imu_message, joint_state,
                      node_command, node_log, running_node, seconds, tool_calibration, truth_calibration,
                      wait_until)
import robot_rig
from sensor_msgs.msg import Imu, JointState

ARM = SPATIAL_SCENARIOS["spatial-arm"]
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def arm():
    scenario = ARM.with_(duration=2.0)
    log, truth, _ = scenario.generate(5)
    return scenario, log, truth, truth_calibration(scenario, truth)


@pytest.fixture
def cal_file(arm, tmp_path):
    path = tmp_path / "cal.json"
    arm[3].save(path)
    return path


def _node(request, cal, *extra, domain=None):
    """The node of this test's domain (or ``domain``), with the pose source and reliable inputs."""
    return running_node(domain_id(request.node.name) if domain is None else domain, f"calibration:={cal}",
                        "pose_topic:=/ft_sensor/pose", "qos:=reliable", *extra)


def _expected_count(reference, log, last):
    """The outputs of the readings up to row ``last``: those compensate(causal) gives whose reading is out
    (the causal filter's delay behind row ``last``)."""
    return int(np.sum(reference.t <= log.t[last] - reference.delay + 1e-9))


# --- without ROS: the pieces the node runs ----------------------------------------------------------------------
@pytest.mark.parametrize("frame, point", [("sensor", None), ("base", (0.0, 0.02, 0.1))])
def test_push_many_is_push_row_by_row(arm, frame, point):
    """Compensator.push_many (the node's backlog as one block) gives push's samples, with missing poses and the
    offset tracker in play, in the sensor's frame or the base's at a tool point; the tare after them the same."""
    scenario, log, truth, _ = arm
    cal = truth_calibration(scenario, truth, cov=np.eye(42) * 1e-6)
    log = log.head(700)
    pose = log.pose.copy()
    pose[300:304] = np.nan
    one, block = (Compensator(cal, log.dt, track_offset=True, frame=frame, point=point) for _ in range(2))
    ref = [o for o in (one.push(t, w, None if np.isnan(p).any() else p)
                       for t, w, p in zip(log.t, log.w_hat, pose)) if o is not None]
    out, sizes = [], np.random.default_rng(0).integers(1, 40, size=100)
    for start, stop in zip(np.r_[0, np.cumsum(sizes)], np.cumsum(sizes)):
        out += block.push_many(log.t[start:stop], log.w_hat[start:stop], pose[start:stop])
    assert len(out) == len(ref) > 600
    assert [o.t for o in out] == [o.t for o in ref]
    np.testing.assert_allclose([o.wrench for o in out], [o.wrench for o in ref], atol=1e-10)
    np.testing.assert_allclose([o.cov for o in out], [o.cov for o in ref], rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose([o.offset for o in out], [o.offset for o in ref], atol=1e-12)
    np.testing.assert_allclose(block.tare(), one.tare(), atol=1e-12)


def _settings(cal_file, **values):
    v = {p.name: p.default for p in PARAMETERS}
    v.update(calibration=str(cal_file), pose_topic="/p", **values)
    return settings(v)


def test_pipeline_interpolates_poses_at_the_readings_stamps(arm, cal_file):
    """Poses at 500 Hz, stamped 0.4 ms off the readings' grid, SLERPed at each reading's stamp: the output is
    the causal compensation of the log (all poses) within a fraction of the noise (rms); readings wait for the
    poses."""
    scenario, log, truth, cal = arm
    log = log.head(800)
    pipeline = Pipeline(_settings(cal_file))
    out = []
    for i, (t, w) in enumerate(zip(log.t, log.w_hat)):
        if i % 2 == 0 and i >= 2:                      # the pose of row i - 2, stamped 0.4 ms after it: late
            pipeline.add_motion(log.t[i - 2] + 0.0004, SpatialModel.interpolate_pose(
                np.array([log.t[i - 2] + 0.0004]), log.t, log.pose)[0])
        pipeline.add_reading(t, w)
        out += pipeline.process()
    reference = compensate(cal, log, causal=True)
    t = np.array([o.sample.t for o in out])
    common, i, j = np.intersect1d(np.round(reference.t, 9), np.round(t, 9), return_indices=True)
    assert len(common) > 0.95 * len(reference.t)
    difference = np.array([o.sample.wrench for o in out])[j] - reference.wrench[i]
    error = np.sqrt(np.mean(difference ** 2, axis=0)) / noise_rms(truth.S_at(0.0), truth.noise.wrench_sd)
    assert np.all(error < 0.3) and np.all(error > 0.01), error        # half the poses, interpolated: not equal
    assert pipeline.backlog() <= 3


@pytest.fixture(scope="module")
def grasped_held(tmp_path_factory):
    """Held attitudes as tests/test_tool_change.py's: 50 s of spatial-static's motion at eight attitudes, a 200 g
    part grasped in the first at 1.3 s; the truth's calibration file; the tool holding the part."""
    from tool_change_rig import PART
    from fmscal.plant.scenarios import with_grasp
    held = ((0.0, 0.0, 0.0), (0.6, -0.5, 0.3), (-0.4, 0.5, -0.6), (0.8, 0.2, 0.7), (-0.7, -0.6, 0.1),
            (0.3, 0.7, -0.2), (-0.8, 0.1, 0.5), (0.1, -0.7, -0.4))
    scenario = SPATIAL_SCENARIOS["spatial-static"].with_(duration=50.0, targets=held)
    log, truth, total = with_grasp(scenario, 5, PART, 1.3)
    path = tmp_path_factory.mktemp("grasp") / "cal.json"
    truth_calibration(scenario, truth).save(path)
    return log, path, total


def _through(pipeline, log, start, stop, every=50):
    """Rows ``[start, stop)`` of ``log`` through ``pipeline`` (each pose with its reading) in passes of ``every``;
    the outputs."""
    out = []
    for i in range(start, stop, every):
        for t, w, pose in zip(log.t[i:min(i + every, stop)], log.w_hat[i:min(i + every, stop)],
                              log.pose[i:min(i + every, stop)]):
            pipeline.add_motion(t, pose)
            pipeline.add_reading(t, w)
        out += pipeline.process()
    return out


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["detect", "reidentify"])
def test_a_tool_change_is_said_flagged_and_reidentified(grasped_held, mode):
    """The node's pipeline with tool_change detect: the grasp counted once, its line said (the time named), every
    output after the declaration flagged tool_change until ~/reidentify (refused while no attitude is held), then
    the new total in use (within 4 g and 5 mm) and the outputs unflagged at the noise; with reidentify the same
    without the call, from the held attitudes. The flags' onset: none before the grasp."""
    from tool_change_rig import COM_WITHIN, MASS_WITHIN, PART
    log, path, total = grasped_held
    pipeline = Pipeline(_settings(path, sample_time=float(log.dt), tool_change=mode))
    cut = int(np.searchsorted(log.t, 30.0 if mode == "detect" else 45.0))
    out = _through(pipeline, log, 0, int(np.searchsorted(log.t, 2.0)))
    early = pipeline.reidentify()
    out += _through(pipeline, log, int(np.searchsorted(log.t, 2.0)), cut)
    assert pipeline.counts["tool_changes"] == 1
    said = [m for k, m in pipeline.notices if k == "tool_change"]
    assert said and said[0].startswith("tool change at 1."), said
    assert abs(float(said[0].split(": mass ")[1].split()[0]) - PART.mass) < 0.01, said
    t = np.array([o.sample.t for o in out])
    flagged = np.array(["tool_change" in o.flags for o in out])
    assert not flagged[t < 1.3].any()
    if mode == "detect":
        assert not early[0] and early[1].startswith("reidentify refused: ") and "held" in early[1], early
        assert flagged[t > 4.0].all() and "tool_change" in pipeline.snapshot.conditions
        ok, message = pipeline.reidentify()
        assert ok and message.startswith("re-identified: mass "), message
    else:
        assert flagged[(t > 4.0) & (t < 20.0)].all()
        assert not flagged[t > 44.0].any()
    assert "tool_change" not in pipeline.conditions
    mass, com = pipeline.payload.mass, np.asarray(pipeline.payload.com)
    assert abs(mass - total.mass) < MASS_WITHIN and np.linalg.norm(com - np.asarray(total.com)) < COM_WITHIN
    assert "re-identified from" in pipeline.snapshot.tool_change
    after = _through(pipeline, log, cut, len(log))
    flags = sorted({f for o in after for f in o.flags})
    assert len(after) > 3000 and not flags, (flags, [o.sample.t for o in after if o.flags][:5])
    assert np.mean([o.sample.contact for o in after]) < 0.01
    assert pipeline.counts["tool_changes"] == 1


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["detect", "reidentify"])
def test_a_tool_change_flags_from_its_declaration_in_long_passes(grasped_held, mode):
    """A node behind its inputs pushes long runs (here 1.5 s of readings in one pass): the outputs of a pass that
    declares the grasp are flagged tool_change from the one that declared it on (within 0.15 s of the one in
    passes of 50: the detector's blocks fall alike), not before; with
    reidentify, the pass that re-identifies keeps each of its outputs flagged, and the outputs after it are
    unflagged."""
    log, path, _ = grasped_held
    onsets = []
    for every in (50, 1500):
        pipeline = Pipeline(_settings(path, sample_time=float(log.dt), tool_change=mode))
        out = _through(pipeline, log, 0, int(np.searchsorted(log.t, 47.0)), every=every)
        t = np.array([o.sample.t for o in out])
        flagged = np.array(["tool_change" in o.flags for o in out])
        assert pipeline.counts["tool_changes"] == 1 and t[0] < 1.0
        onsets.append(t[flagged][0])
    onset = onsets[1]
    assert abs(onsets[0] - onset) < 0.15 and 1.3 < onset < 4.0 and not flagged[t < onset].any(), onsets
    if mode == "detect":
        assert flagged[t >= onset].all()
    else:
        assert flagged[(t >= onset) & (t < 20.0)].all() and not flagged[t > 45.0].any()


def test_the_tool_change_parameter_is_checked(cal_file, tmp_path):
    """tool_change: one of its options; detection on a planar calibration refused at start, naming the parameter."""
    with pytest.raises(Ros2Error, match="^parameter tool_change must be one of off, detect, reidentify; got 'on'$"):
        Pipeline(_settings(cal_file, tool_change="on"))
    scenario = SCENARIOS["paper"]
    log, truth, _ = scenario.with_(duration=1.0).generate(0)
    planar = tmp_path / "planar.json"
    Calibration(S=truth.S_at(0.0), payload=scenario.payload, method="truth", b=truth.offset, latency=0.0,
                noise=truth.noise).save(planar)
    assert Pipeline(_settings(planar)).compensator is None           # the default: off on a planar reading
    with pytest.raises(Ros2Error, match="^parameter tool_change: a tool change is detected on a 6-axis reading "
                                        "in 3D.*: leave it empty or off$"):
        Pipeline(_settings(planar, tool_change="detect"))


def test_a_payload_file_of_held_poses_learns_the_noise_once(tmp_path):
    """A payload file from a table of held poses (its noise a held pose's, not a sample's): the pipeline's
    compensator learns the readings' noise from its first 4 s (no output before), as a log's noise model is measured;
    ``~/reload`` goes on with the noise learned, its outputs without a second wait."""
    from fmscal.observers.payload import fit_static
    from fmscal.plant.io import simulate_table, wrench_noise
    scenario = ARM.with_(crosstalk=0.0, duration=5.0)                    # S = I, as a payload file takes it
    log, truth, _ = scenario.generate(1)
    sd = np.asarray(truth.noise.wrench_sd)
    path = tmp_path / "tool.json"
    fit_static(simulate_table(scenario.payload, n=8, seed=101, S=truth.S_at(0.0), offset=truth.offset,
                              wrench_sd=sd / np.sqrt(500))).save(path)
    values = {p.name: p.default for p in PARAMETERS}
    values.update(payload=str(path), pose_topic="/p", sample_time=float(log.dt))
    pipeline = Pipeline(settings(values))
    out = _through(pipeline, log, 0, 4500)
    t = np.array([o.sample.t for o in out])
    assert len(t) and abs(t[0] - (log.t[4001] - pipeline.delay)) < 1e-9       # colour_samples(1 ms): 4002
    learned = pipeline.compensator.noise
    assert (learned.wrench_sd, learned.wrench_tau) == wrench_noise(log.w_hat[:4002], log.dt)
    ok, said = pipeline.reload()
    assert ok, said
    after = _through(pipeline, log, 4500, len(log))
    assert len(after) > 400 and pipeline.compensator.noise.wrench_sd == learned.wrench_sd
    z = np.array([o.sample.wrench / np.sqrt(np.diag(o.sample.cov)) for o in out + after])
    assert 0.7 < np.sqrt(np.mean(z ** 2)) < 1.4


def test_a_slower_motion_is_given_to_the_nearest_reading_only(arm, cal_file):
    """Poses at 200 Hz, on every fifth reading's stamp: each goes to that reading only, the readings between get
    none, so the node's wrench and covariance are the Compensator's fed the sparse stream, exactly; poses
    interpolated at every reading would count as independent samples (a covariance too small)."""
    scenario, log, truth, cal = arm
    log = log.head(600)
    pipeline = Pipeline(_settings(cal_file, sample_time=float(log.dt)))
    reference = Compensator(cal.__class__(**{**cal.__dict__, "latency": 0.0}), log.dt)
    out, expected = [], []
    for i, (t, w, pose) in enumerate(zip(log.t, log.w_hat, log.pose)):
        if i % 5 == 0:
            pipeline.add_motion(t, pose)
        pipeline.add_reading(t, w)
        out += pipeline.process()
        if (e := reference.push(t, w, pose if i % 5 == 0 else None)) is not None:
            expected.append(e)
    got = {round(o.sample.t, 9): o.sample for o in out}
    pairs = [(got[round(e.t, 9)], e) for e in expected if round(e.t, 9) in got]
    assert len(pairs) > 0.9 * len(expected)
    for g, e in pairs:
        np.testing.assert_allclose(g.wrench, e.wrench, rtol=0, atol=1e-9)
        np.testing.assert_allclose(g.cov, e.cov, rtol=1e-9, atol=0)


def test_sensor_pose_from_a_tracked_frame():
    """(R1): the sensor's axes R(q_M) R and its point p_M + R(q_M) t, against rotation matrices composed."""
    rng = np.random.default_rng(3)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    R = robot_rig.Rotation.from_euler("xyz", [0.4, -0.2, 1.3]).as_matrix()
    t, p = np.array([0.01, -0.02, 0.15]), np.array([0.5, 0.1, 0.3])
    q_s, p_s = sensor_pose(q, p, (R, t))
    np.testing.assert_allclose(rotation_matrix(q_s), rotation_matrix(q) @ R, atol=1e-12)
    np.testing.assert_allclose(p_s, p + rotation_matrix(q) @ t, atol=1e-12)
    assert sensor_pose(q, p) == (q, p)


def test_saturated_readings_are_withheld(arm, cal_file):
    """A reading at the saturation parameter's range: its output withheld and counted, the state "saturated";
    the other readings' outputs as they were."""
    scenario, log, truth, cal = arm
    log = log.head(400)
    limit = np.abs(log.w_hat).max(axis=0) * 1.01
    w_hat = log.w_hat.copy()
    w_hat[200, 3] = limit[3]
    pipelines = [Pipeline(_settings(cal_file, saturation=s)) for s in (None, list(limit))]
    outputs, states = [], []
    for pipeline in pipelines:
        out = []
        for t, w, p in zip(log.t, w_hat, log.pose):
            pipeline.add_motion(t, p)
            pipeline.add_reading(t, w)
            out += pipeline.process()
        states.append(pipeline.state())       # at once: "not ready" once the readings are silent (wall time)
        outputs.append({round(o.sample.t, 9): o.sample.wrench for o in out})
    assert set(outputs[0]) - set(outputs[1]) == {round(log.t[200], 9)}
    assert pipelines[1].withheld["saturated"] == 1 and states[1] == "saturated"
    assert states[0] == "running"
    assert all(np.array_equal(outputs[0][k], v) for k, v in outputs[1].items())


def test_parameters_refused_in_one_line(cal_file):
    """Not exactly one motion source, an option not among its choices: one line naming the parameter."""
    with pytest.raises(Exception, match="exactly one motion source"):
        _settings(cal_file, imu_topic="/imu")
    with pytest.raises(Exception, match="parameter qos must be one of sensor_data, reliable"):
        _settings(cal_file, qos="best")
    with pytest.raises(Exception, match="drift_intensity is the offset tracker's"):
        _settings(cal_file, drift_intensity=[0.1])


def test_the_inputs_events_are_in_no_executors_wait_set(request, cal_file):
    """The inputs' QoS event handlers (incompatible, matched, lost) are taken by a timer's look
    (``take_events``), not waited on by the node's executor. Fast DDS wakes a wait set holding a subscription's
    events at each of its messages; the executor then rebuilt its wait set in Python at each input message, and
    the compensation, waiting for the interpreter's lock, fell behind its 1 kHz inputs
    (benchmarks/ros2_latency.py). Fails where the handlers are added to the node's executor."""
    from fmscal.analysis.ros2._node import CompensatorNode
    from fmscal.analysis.ros2._rclpy import ros
    r = ros()
    context = r.Context()
    args = ["--ros-args", "-p", f"calibration:={cal_file}", "-p", "pose_topic:=/ft_sensor/pose"]
    r.rclpy.init(args=["fmscal", *args], context=context, domain_id=domain_id(request.node.name))
    node = None
    try:
        node = CompensatorNode(r, context, args)
        assert node.pollable()
        handlers = [*node._wrench_sub.event_handlers, *node._motion_sub.event_handlers]
        timers = len(list(node.node.timers))
        node.take_events(context)
        # incompatible QoS, matched, lost: on each input
        assert len(node._wrench_sub.event_handlers) >= 3 and len(node._motion_sub.event_handlers) >= 3
        assert not set(map(id, handlers)) & {id(w) for n in (node.node, node.services) for w in n.waitables}
        assert len(list(node.node.timers)) == timers + 1
    finally:
        if node is not None:
            node.destroy()
        r.rclpy.try_shutdown(context=context)


def _random_input(kind, rng, frame_id):
    """A message of ``kind`` (rclpy's), random numbers, ``frame_id`` (its length moves the fields' alignment)."""
    from geometry_msgs.msg import WrenchStamped
    msg = {"wrench": WrenchStamped, "pose": PoseStamped, "imu": Imu, "joints": JointState}[kind]()
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(rng.integers(-2 ** 31, 2 ** 31)), int(rng.integers(0, 10 ** 9))
    msg.header.frame_id = frame_id
    v = rng.normal(size=40).tolist()
    if kind == "wrench":
        f, t = msg.wrench.force, msg.wrench.torque
        f.x, f.y, f.z, t.x, t.y, t.z = v[:6]
    elif kind == "pose":
        p, o = msg.pose.position, msg.pose.orientation
        p.x, p.y, p.z, o.x, o.y, o.z, o.w = v[:7]
    elif kind == "imu":
        o, w, a = msg.orientation, msg.angular_velocity, msg.linear_acceleration
        o.x, o.y, o.z, o.w = v[:4]
        w.x, w.y, w.z, a.x, a.y, a.z = v[4:10]
        msg.orientation_covariance = v[10:19]
        msg.angular_velocity_covariance = v[19:28]
        msg.linear_acceleration_covariance = v[28:37]
    else:
        n = int(rng.integers(0, 8))
        msg.name = ["j" * int(rng.integers(1, 9)) + str(i) for i in range(n)]
        msg.position = v[:n] if rng.random() < 0.8 else []
        msg.velocity = v[10:10 + n] if rng.random() < 0.6 else []
        msg.effort = v[20:20 + n] if rng.random() < 0.3 else []
    return msg


def _same_values(got, want):
    """Two plain values (analysis/ros2/_cdr.py's ``plain``) alike: the stamp, the frame, every number."""
    assert got[:2] == want[:2]
    a, b = got[2], want[2]
    if isinstance(a[0], list):                               # a joint state: the names, then the sequences
        assert a[0] == b[0]
        a, b = a[1:], b[1:]
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    assert len(a) == len(b)


@pytest.mark.parametrize("kind", ["wrench", "pose", "imu", "joints"])
def test_the_inputs_bytes_are_decoded_as_rclpy_decodes_them(kind):
    """The node takes its inputs as bytes (analysis/ros2/_cdr.py): each decoded as rclpy's own
    deserialization gives its values, over frames of every length mod 8 (the fields' alignment) and random
    numbers; strings read as rclpy reads them (up to the first NUL, with none, or empty); bytes cut short, or that
    rclpy cannot read in another encapsulation, are a ValueError, never a wrong value nor another exception."""
    from rclpy.serialization import deserialize_message, serialize_message
    from fmscal.analysis.ros2._cdr import decoder, plain
    rng = np.random.default_rng(7)
    for i in range(48):
        msg = _random_input(kind, rng, "f" * (i % 17))
        data = bytes(serialize_message(msg))
        assert data[:2] == b"\x00\x01"
        stamp, frame_id, values = decoder(kind, type(msg), deserialize_message)(data)
        want = plain(kind, deserialize_message(data, type(msg)))
        assert (stamp, frame_id) == want[:2] == ((msg.header.stamp.sec, msg.header.stamp.nanosec), msg.header.frame_id)
        if kind == "joints":
            assert values[0] == want[2][0] == list(msg.name)
            for got, expected in zip(values[1:], want[2][1:]):
                np.testing.assert_array_equal(got, expected)
        else:
            assert tuple(values) == tuple(want[2])
    # another encapsulation (here XCDR2's, 00 07) goes to the deserializer given (rclpy's, told it is plain CDR)
    given = []
    other = decoder(kind, type(msg), lambda b, t: given.append(b) or deserialize_message(b"\x00\x01" + b[2:], t))
    _same_values(other(b"\x00\x07" + data[2:]), plain(kind, msg))
    assert len(given) == 1
    decode = decoder(kind, type(msg), deserialize_message)
    with pytest.raises(ValueError):
        decode(data[:14])
    with pytest.raises(ValueError):                          # big endian, cut short: rclpy cannot read it either
        decode(b"\x00\x00" + data[2:10])
    # strings as rclpy reads them: up to the first NUL, with or without one, or empty (length 0)
    sent = bytes(serialize_message(_random_input(kind, rng, "abcdefg")))
    for frame_bytes in (b"ab\0d\0\0\0\0", b"abcdefgh", b""):
        crafted = sent[:12] + len(frame_bytes).to_bytes(4, "little") + frame_bytes + sent[24:]
        if frame_bytes == b"":                               # (the fields after it where alignment puts them)
            crafted = sent[:12] + b"\0\0\0\0" + sent[24:]
        _same_values(decode(crafted), plain(kind, deserialize_message(crafted, type(msg))))
    if kind == "joints":                                     # cut inside the efforts: rclpy refuses it, and so here
        full = _random_input(kind, rng, "")
        full.name, full.position, full.velocity, full.effort = ["a", "b"], [1.0, 2.0], [], [3.0, 4.0]
        whole = bytes(serialize_message(full))
        with pytest.raises(Exception):
            deserialize_message(whole[:-12], JointState)
        with pytest.raises(ValueError):
            decode(whole[:-12])


def test_the_outputs_bytes_are_the_messages_rclpy_makes(request, cal_file):
    """The node publishes its outputs as bytes (analysis/ros2/_cdr.py's templates, their stamp and numbers
    written in place): read back by rclpy, each is the message the node means, for a template reused with
    another stamp and numbers, for frames and flags of several lengths, and beyond the templates kept."""
    from rclpy.serialization import deserialize_message
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from geometry_msgs.msg import WrenchStamped
    from std_msgs.msg import Float64MultiArray
    from fmscal.analysis.ros2._node import CompensatorNode
    from fmscal.analysis.ros2._rclpy import ros
    r = ros()
    context = r.Context()
    args = ["--ros-args", "-p", f"calibration:={cal_file}", "-p", "pose_topic:=/ft_sensor/pose"]
    r.rclpy.init(args=["fmscal", *args], context=context, domain_id=domain_id(request.node.name))
    node = None
    rng = np.random.default_rng(3)
    try:
        node = CompensatorNode(r, context, args)
        encode = node._encode
        encode.flags.kept = 3
        for i in range(12):
            stamp = (int(rng.integers(0, 2 ** 31)), int(rng.integers(0, 10 ** 9)))
            frame, numbers = "tool" * (i % 4), rng.normal(size=6)
            msg = deserialize_message(encode.contact(stamp, numbers, frame), WrenchStamped)
            f, t = msg.wrench.force, msg.wrench.torque
            assert ((msg.header.stamp.sec, msg.header.stamp.nanosec), msg.header.frame_id) == (stamp, frame)
            assert [f.x, f.y, f.z, t.x, t.y, t.z] == numbers.tolist()
            cov = rng.normal(size=36)
            array_ = deserialize_message(encode.cov(None, cov), Float64MultiArray)
            assert list(array_.data) == cov.tolist()
            assert [(d.label, d.size, d.stride) for d in array_.layout.dim] == \
                [("fx fy fz tx ty tz", 6, 36), ("column", 6, 6)]
            level = [DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR][i % 3]
            message, contact = "stale " * (i % 5), ["true", "false"][i % 2]
            flags = deserialize_message(encode.flags(stamp, (), frame, level, message, contact), DiagnosticArray)
            status = flags.status[0]
            assert ((flags.header.stamp.sec, flags.header.stamp.nanosec), flags.header.frame_id) == (stamp, frame)
            assert (status.level, status.message, status.hardware_id) == (level, message, "/ft_sensor/wrench")
            assert status.name == "fmscal_compensator: contact wrench"
            assert [(kv.key, kv.value) for kv in status.values] == [("contact", contact)]
        assert len(encode.flags._layouts) == 3 and all(v is not None for v in encode.contact._layouts.values())
    finally:
        if node is not None:
            node.destroy()
        r.rclpy.try_shutdown(context=context)


def test_an_input_whose_bytes_do_not_decode_is_counted_and_taken_by_rclpy_after(request, cal_file):
    """A wrench message whose bytes do not decode (here cut short, published as bytes) is skipped, said (its length
    and first bytes) and counted as an invalid reading; the wrench's messages are then taken through rclpy's own
    conversion, and the next is read as it was sent. Real DDS in this process: the node's own take."""
    from rclpy.serialization import serialize_message
    from geometry_msgs.msg import WrenchStamped
    from fmscal.analysis.ros2._node import CompensatorNode
    from fmscal.analysis.ros2._rclpy import ros
    r = ros()
    context = r.Context()
    args = ["--ros-args", "-p", f"calibration:={cal_file}", "-p", "pose_topic:=/ft_sensor/pose", "-p",
            "qos:=reliable"]
    r.rclpy.init(args=["fmscal", *args], context=context, domain_id=domain_id(request.node.name))
    node = peer = None
    try:
        node = CompensatorNode(r, context, args)
        peer = r.Node("bad_sender", context=context)
        pub = peer.create_publisher(WrenchStamped, "/ft_sensor/wrench", r.QoSProfile(depth=10))
        wait_until(lambda: pub.get_subscription_count() > 0, 10.0)
        good = WrenchStamped()
        good.header.stamp.sec, good.header.frame_id = 5, "ft"
        good.wrench.force.x, good.wrench.torque.z = 1.5, -0.25
        pub.publish(bytes(serialize_message(good))[:40])
        pub.publish(good)
        taken = []
        wait_until(lambda: taken.extend(node._taken(node._wrench_sub, 1)) or len(taken) >= 1, 10.0)
        assert [values for _, _, values in taken] == [((5, 0), "ft", (1.5, 0.0, 0.0, 0.0, 0.0, -0.25))]
        assert node.pipeline.withheld["invalid"] == 1 and node._raw == [True, False]
    finally:
        for n in (peer, node):
            if n is not None:
                n.destroy() if n is node else n.destroy_node()
        r.rclpy.try_shutdown(context=context)


def test_the_diagnostics_never_wait_on_a_running_compensation(request, cal_file):
    """A compensation pass holding the pipeline's lock for 1 s (a stalled pass): the diagnostics and the inputs'
    QoS events (taken in the same thread) go on, at once, with the liveness an ERROR naming the pass; another node
    of the same name and an incompatible publisher are set as conditions once the lock is free (kept, not waited
    for)."""
    import threading
    from fmscal.analysis.ros2._node import CompensatorNode
    from fmscal.analysis.ros2._rclpy import ros
    r = ros()
    context = r.Context()
    args = ["--ros-args", "-p", f"calibration:={cal_file}", "-p", "pose_topic:=/ft_sensor/pose"]
    r.rclpy.init(args=["fmscal", *args], context=context, domain_id=domain_id(request.node.name))
    node = twin = None
    try:
        node = CompensatorNode(r, context, args)
        sent = []
        node.diag_pub.publish = sent.append          # the array as built, before the middleware
        node._diagnose()
        assert sent[-1].status[2].level == r.DiagnosticStatus.OK
        twin = r.rclpy.create_node(node.node.get_name(), context=context)
        deadline = time.monotonic() + 10
        while sum(n == node.node.get_fully_qualified_name() for n in node.node.get_fully_qualified_node_names()) < 2:
            assert time.monotonic() < deadline, "the twin never seen in the graph"
            time.sleep(0.05)
        held, release = threading.Event(), threading.Event()
        event = types.SimpleNamespace(last_policy_kind=None, current_count=2)

        def stalled_pass():
            with node.pipeline.lock:
                held.set()
                release.wait(5)
        thread = threading.Thread(target=stalled_pass)
        thread.start()
        try:
            held.wait(5)
            node._pass_start, node._pass_size = time.monotonic() - 1.0, 40
            start = time.monotonic()
            node._diagnose()
            node._incompatible("/ft_sensor/wrench", event)         # the QoS events, taken in the same thread
            node._matched("/ft_sensor/wrench", event)
            took = time.monotonic() - start
        finally:
            release.set()
            thread.join()
        assert took < 0.5, took
        live = sent[-1].status[2]
        assert live.level == r.DiagnosticStatus.ERROR and live.message.startswith("behind: a compensation pass has run")
        assert not {"name", "qos /ft_sensor/wrench"} & set(node.pipeline.conditions)   # not while the lock was held
        node._pass_start = None
        node._diagnose()
        assert "2 nodes named" in node.pipeline.conditions["name"]
        assert "none of its messages arrive" in node.pipeline.conditions["qos /ft_sensor/wrench"]
        assert "2 nodes named" in sent[-1].status[1].message
    finally:
        if twin is not None:
            twin.destroy_node()
        if node is not None:
            node.destroy()
        r.rclpy.try_shutdown(context=context)


def test_the_liveness_is_behind_before_the_input_queue_fills(request, cal_file):
    """The liveness says "behind" where an output came later than its reading and the causal delay by 0.25 s, or by
    half the input queue's span where that is shorter (``queue_depth`` readings: at 5 kHz, 1000 hold 0.2 s, and a
    burst fills them before 0.25 s); the longest lateness since its last look counts, once (a burst between two
    looks is said)."""
    import dataclasses
    from fmscal.analysis.ros2._node import CompensatorNode
    from fmscal.analysis.ros2._rclpy import ros
    r = ros()
    context = r.Context()
    args = ["--ros-args", "-p", f"calibration:={cal_file}", "-p", "pose_topic:=/ft_sensor/pose", "-p",
            "queue_depth:=1000"]
    r.rclpy.init(args=["fmscal", *args], context=context, domain_id=domain_id(request.node.name))
    node = None
    try:
        node = CompensatorNode(r, context, args)
        node.pipeline.snapshot = dataclasses.replace(node.pipeline.snapshot, delay=0.03)
        now = time.time()

        def behind(period, newest, longest=0.0):
            node.pipeline.dt_in, node._held_for, node._late_most = period, (0.03 + newest, now), 0.03 + longest
            return node._behind(time.monotonic())

        assert behind(0.0002, 0.15).startswith("behind: the outputs come 0.15 s")        # 5 kHz: 0.1 s the bound
        assert behind(0.0002, 0.09) is None
        assert behind(0.001, 0.15) is None and behind(0.001, 0.26).startswith("behind")    # 1 kHz: 0.25 s
        assert behind(None, 0.26).startswith("behind") and behind(None, 0.2) is None
        assert behind(0.0002, 0.01, longest=0.3).startswith("behind: the outputs come 0.3 s")
        node._held_for = (0.03 + 0.01, now)
        assert node._behind(time.monotonic()) is None                                      # said once
    finally:
        if node is not None:
            node.destroy()
        r.rclpy.try_shutdown(context=context)


def test_the_guide_lists_every_parameter_with_its_type_and_default():
    """docs/guide/robot.md's table: the node's parameters, in its order, each with its type and default."""
    text = (ROOT / "docs" / "guide" / "robot.md").read_text()
    table = text.split("| parameter | type | default | meaning |")[1].split("\n\n")[0]
    rows = [[cell.strip().strip("`") for cell in line.strip("|").split("|")] for line in table.strip().splitlines()[1:]]
    types = {"string": "string", "double": "double", "integer": "integer", "bool": "bool", "double_array": "double[]"}
    expected = [[p.name, types[p.type], "unset" if p.default is None else '""' if p.default == "" else
                 str(p.default).lower() if isinstance(p.default, bool) else str(p.default)] for p in PARAMETERS]
    assert [row[:3] for row in rows] == expected


# --- the node, on ROS 2 -----------------------------------------------------------------------------------------
def _run(*args, **kw):
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=60, **kw)


@pytest.mark.slow
def test_a_missing_calibration_exits_with_one_line():
    """``fmscal ros2`` without a calibration: exit status 2 and one line on stderr, no traceback."""
    done = _run(*node_command("pose_topic:=/ft_sensor/pose")[1:])
    assert done.returncode == 2
    assert done.stderr.strip() == ("fmscal ros2: error: parameter calibration or payload is required: a file saved "
                                   "by fmscal calibrate --save (--ros-args -p calibration:=CAL.json), or by fmscal "
                                   "identify-payload --save (-p payload:=tool.json)")


@pytest.mark.slow
@pytest.mark.parametrize("name", ["SIGINT", "SIGTERM"])
def test_a_ctrl_c_stops_the_node_without_a_traceback(request, cal_file, name):
    """One SIGINT (Ctrl-C), or one SIGTERM (a launch system's stop), to a running node: it logs "stopping" and
    exits with status 0 within a second or two, with no traceback on its stderr (the inputs' subscriptions and
    their QoS event handlers destroyed with their node); the former code died at once on a SIGTERM."""
    import signal as signals
    with _node(request, cal_file) as proc:
        started = wait_until(lambda: "compensating" in node_log(proc) or proc.poll() is not None)
        sent = time.monotonic()
        proc.send_signal(getattr(signals, name))
        try:
            proc.wait(timeout=WAIT)
        except subprocess.TimeoutExpired:               # every thread's stack on its stderr (the node registers it)
            masks = [line for line in Path(f"/proc/{proc.pid}/status").read_text().splitlines()
                     if line.startswith(("SigPnd", "ShdPnd", "SigBlk", "SigIgn", "SigCgt"))]   # SIGINT: bit 2
            proc.send_signal(signals.SIGUSR1)
            time.sleep(2.0)
            pytest.fail(f"the node still runs {WAIT:g} s after one {name} (its signal masks {masks}): "
                        f"{node_log(proc)[-12000:]}")
        took = time.monotonic() - sent
        log = node_log(proc)
    assert started, log
    assert proc.returncode == 0 and "stopping (a SIGINT or SIGTERM)" in log, (proc.returncode, log)
    assert "Traceback" not in log and "ValueError" not in log, log
    assert took < 10.0, f"the node took {took:.2f} s to stop after one {name}"


_SIGNALS = """
import os, signal, threading, time
from fmscal.analysis.ros2._node import _stop_on_signals
former = signal.getsignal(signal.SIGINT)     # SIG_IGN where the process started with SIGINT ignored
stopping = threading.Event()
restore = _stop_on_signals(stopping)
if {quiet}:                  # the Python handler made to do nothing: only the wakeup fd's watcher can see the signal
    signal.signal(signal.SIGINT, lambda *a: None)
os.kill(os.getpid(), signal.{name})
print(stopping.wait(5.0))
restore()
print(signal.getsignal(signal.SIGINT) == former, signal.set_wakeup_fd(-1), former == signal.SIG_IGN)
"""


def _sigint(disposition):
    """A child's SIGINT as it starts: ignored or default, whatever this process's is (a background job ignores
    it)."""
    import signal as signals
    return lambda: signals.signal(signals.SIGINT, getattr(signals, disposition))


@pytest.mark.parametrize("name, quiet, ignored", [("SIGINT", False, False), ("SIGTERM", False, False),
                                                  ("SIGINT", True, False), ("SIGINT", False, True)])
def test_a_stop_signal_is_seen_without_the_main_threads_handler(name, quiet, ignored):
    """SIGINT and SIGTERM set the node's stop event and raise nothing; the event is set even where the main
    thread's Python handler does nothing (a KeyboardInterrupt a finalizer swallowed), through the thread that
    watches the interpreter's wakeup fd, and where the process started with SIGINT ignored (a background job's
    children, as CI's node tests ran: Python then sets no handler of its own, and the node ignored the Ctrl-C
    for good); the former handlers and wakeup fd restored after."""
    run = subprocess.run([sys.executable, "-c", _SIGNALS.format(quiet=quiet, name=name)], capture_output=True,
                         text=True, timeout=60, preexec_fn=_sigint("SIG_IGN" if ignored else "SIG_DFL"))
    assert run.returncode == 0 and "Traceback" not in run.stderr, run.stderr
    assert run.stdout.split() == ["True", "True", "-1", str(ignored)], (run.stdout, run.stderr)


def test_without_rclpy_one_line_names_the_install(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "rclpy", None)              # import rclpy now fails, as where it is missing
    assert main(["ros2", "--ros-args", "-p", "calibration:=x.json"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert 'pip install "fmscal[ros2]"' in err and "source a ROS 2 install" in err


@pytest.mark.slow
def test_replay_every_reading_out(request, arm, tmp_path):
    """1.5 s of the log at 1 kHz with a 15 N contact: every reading the causal filter covers comes out, with
    its stamp and frame, as compensate(causal=True) gives it (the same numbers: the poses share the readings'
    stamps), the contact flagged where it is; the covariance topic carries each output's, force first."""
    scenario, log, truth, cal = arm
    log = log.head(1500)
    touched, on = with_contact(log, truth.S_at(0.0), contact_wrench(), 0.8, 0.4)
    cal.save(tmp_path / "cal.json")
    reference = compensate(cal, touched, causal=True)
    with _node(request, tmp_path / "cal.json") as proc:
        peer = Peer(domain_id(request.node.name))
        try:
            peer.wait_for_node(proc)
            epoch = peer.replay(touched)
            n = _expected_count(reference, touched, len(touched) - 1)
            assert peer.wait_for(lambda: len(peer.contacts) >= n and len(peer.covariances) >= n, 10), \
                (len(peer.contacts), n, node_log(proc)[-1000:])
            time.sleep(0.1)
        finally:
            peer.close()
    t, wrench = contact_array(peer.contacts, epoch)
    assert len(t) == n and np.all(np.diff(t) > 0)
    np.testing.assert_allclose(t, np.round(reference.t[:n], 6), atol=1e-9)
    np.testing.assert_allclose(wrench, reference.wrench[:n], atol=1e-7)
    assert {m.header.frame_id for m in peer.contacts} == {"ft_sensor"}
    inside = (t > 0.85) & (t < 1.15)
    assert np.linalg.norm(wrench[inside].mean(axis=0)[3:]) == pytest.approx(15.0, rel=0.1)
    force_first = [3, 4, 5, 0, 1, 2]
    cov = np.array([m.data for m in peer.covariances]).reshape(-1, 6, 6)
    np.testing.assert_allclose(cov, reference.cov[:n][:, force_first][:, :, force_first], rtol=1e-6)
    assert peer.covariances[0].layout.dim[0].label == "fx fy fz tx ty tz"


def _offset_off(cal, truth, path):
    """Save ``cal`` with its offset off by one noise sd per channel at ``path``; return that error."""
    delta = 1.0 * np.asarray(truth.noise.wrench_sd)
    fields = {k: getattr(cal, k) for k in ("S", "payload", "method", "gravity", "latency", "noise")}
    Calibration(**fields, b=cal.b + delta).save(path)
    return delta


@pytest.mark.slow
def test_tare(request, arm, tmp_path):
    """A calibration whose offset is off by 1 sd per channel: the output's mean sits at S delta; ~/tare
    re-biases, and from then on the mean is zero within the noise (a contact threshold of 1e-6: no sample of
    the tare's window is taken for a contact)."""
    scenario, log, truth, cal = arm
    S = truth.S_at(0.0)
    delta = _offset_off(cal, truth, tmp_path / "cal.json")
    noise = noise_rms(S, truth.noise.wrench_sd)
    with _node(request, tmp_path / "cal.json", "contact_threshold:=1e-6") as proc:
        peer = Peer(domain_id(request.node.name))
        try:
            peer.wait_for_node(proc)
            epoch = peer.replay(log.head(700))
            assert peer.wait_for(lambda: len(peer.contacts) >= 640, 10)
            before = len(peer.contacts)
            ok, message = peer.call("tare")
            assert ok and message.startswith("tared: offset "), message
            peer.replay(log.head(1400), start=700, epoch=epoch)
            assert peer.wait_for(lambda: len(peer.contacts) >= 1340, 10)
        finally:
            peer.close()
    t, wrench = contact_array(peer.contacts, epoch)
    shift = S @ delta
    assert np.all(np.abs(wrench[100:before].mean(axis=0) - shift) < 0.25 * noise), (wrench[:before].mean(0), shift)
    after = t > 0.8
    assert np.all(np.abs(wrench[after].mean(axis=0)) < 0.25 * noise), wrench[after].mean(axis=0) / noise


@pytest.mark.slow
def test_tare_refused_during_a_contact(request, arm, cal_file):
    """A contact at the end of the replay: ~/tare refuses, and says why; ~/tare_force tares."""
    scenario, log, truth, cal = arm
    touched, _ = with_contact(log.head(600), truth.S_at(0.0), contact_wrench(), 0.3, 1.0)
    with _node(request, cal_file) as proc:
        peer = Peer(domain_id(request.node.name))
        try:
            peer.wait_for_node(proc)
            peer.replay(touched)
            assert peer.wait_for(lambda: len(peer.contacts) >= 541, 10), (len(peer.contacts), node_log(proc)[-1500:])
            ok, message = peer.call("tare")
            forced, forced_message = peer.call("tare_force")
        finally:
            peer.close()
    assert not ok
    assert message.startswith("tare refused: a contact is detected (") and "\n" not in message, message
    assert message.endswith("; tare with the tool free, or call ~/tare_force where the offset itself is off (a "
                            "sensor zeroed by its hardware, a drift without track_offset); ~/reload undoes a wrong "
                            "~/tare_force"), message
    assert forced and forced_message.startswith("tared: offset "), forced_message
    absorbed = float(forced_message.split("; absorbed ")[1].split(" N")[0])
    assert absorbed == pytest.approx(np.linalg.norm(contact_wrench()[3:]), rel=0.2), forced_message


@pytest.mark.slow
def test_stale_motion_stops_the_output(request, arm, cal_file):
    """The poses stop at row 500 of 900: the outputs stop at the last reading the poses reach, the diagnostics
    say "motion stale" and the log warns."""
    scenario, log, truth, cal = arm
    log = log.head(900)
    with _node(request, cal_file, "stale_timeout:=0.05") as proc:
        peer = Peer(domain_id(request.node.name))
        try:
            peer.wait_for_node(proc)
            epoch = peer.replay(log, poses=np.arange(len(log)) < 500)
            assert peer.wait_for(lambda: any(s.message == "motion stale" for d in peer.diagnostics
                                             for s in d.status), 10), [d.status[0].message for d in peer.diagnostics]
            peer.wait_for(lambda: len(peer.contacts) >= 500 - 29, 10)        # a busy machine: later, not fewer
            time.sleep(0.2)                                                    # none more comes
            text = node_log(proc)
        finally:
            peer.close()
    t, _ = contact_array(peer.contacts, epoch)
    # the last reading the poses reach is 499; a busy machine may deliver the poses late against the readings, and
    # a reading the poses have not reached when one stale_timeout newer is there is stale by the rule: the output
    # stops within stale_timeout of it, never after, and none is missing before
    assert log.t[499] - 0.05 - 1e-9 <= t[-1] <= log.t[499] + 1e-9, (t[-1], len(t), t[:3])
    assert np.diff(t).max() < 1.5 * log.dt and len(t) == np.sum(log.t <= t[-1] + 1e-9) - 29, (len(t), t[-1])
    assert "motion stale: /ft_sensor/pose has no sample within 0.05 s" in text


# --- the planar model through the node --------------------------------------------------------------------------
@pytest.mark.slow
def test_planar_replay(request, tmp_path):
    """A planar calibration (calibrate on 10 s of paper) and 1.5 s of another paper log replayed as PoseStamped
    (yaw wrapped into (-pi, pi], as a quaternion about z with q_w >= 0) and WrenchStamped (M as torque z): theta
    crosses pi, and the node unwraps it (U1), so every output is compensate(causal=True)'s of the log; the
    covariance topic carries 3x3 (fx fy M), the diagnostics three channels, and ~/identify_payload refuses in
    one line."""
    scenario = SCENARIOS["paper"].with_(duration=10.0)
    cal = calibrate(scenario.generate(1)[0], scenario.payload, latency=0.0)
    assert cal.converged
    cal.save(tmp_path / "cal.json")
    other = scenario.generate(2)[0]
    a = int(np.argmax(other.pose[:, 0] > np.pi)) - 700
    log = Log(other.t[a:a + 1500] - other.t[a], other.pose[a:a + 1500], other.w_hat[a:a + 1500], name="planar")
    assert log.pose[0, 0] < np.pi < log.pose[-1, 0]
    reference = compensate(cal, log, causal=True)
    yaw = np.angle(np.exp(1j * log.pose[:, 0]))                # (-pi, pi]: q_w = cos(yaw / 2) >= 0

    def pose(i, stamp):
        msg = PoseStamped()
        msg.header.stamp, msg.header.frame_id = stamp, "world"
        msg.pose.orientation.w, msg.pose.orientation.z = float(np.cos(yaw[i] / 2)), float(np.sin(yaw[i] / 2))
        msg.pose.position.x, msg.pose.position.y = float(log.pose[i, 1]), float(log.pose[i, 2])
        return msg
    w_hat = np.zeros((len(log.t), 6))
    w_hat[:, 2:5] = log.w_hat                                   # M fx fy: torque z, force x, force y
    with _node(request, tmp_path / "cal.json") as proc:
        peer = Peer(domain_id(request.node.name))
        try:
            peer.wait_for_node(proc)
            epoch = peer.replay_rows(log.t, w_hat, pose)
            n = _expected_count(reference, log, len(log.t) - 1)
            assert peer.wait_for(lambda: len(peer.contacts) >= n and len(peer.covariances) >= n, 10), \
                (len(peer.contacts), n, node_log(proc)[-1000:])
            ok, message = peer.call("identify_payload")
            # the diagnostics while the readings came (after them the state is "not ready": silent inputs)
            status = next((s for d in reversed(peer.diagnostics) for s in d.status if s.message == "running"), None)
        finally:
            peer.close()
    t, wrench = contact_array(peer.contacts, epoch)
    assert len(t) == n
    np.testing.assert_allclose(t, np.round(reference.t[:n], 6), atol=1e-9)
    np.testing.assert_allclose(wrench[:, 2:5], reference.wrench[:n], atol=1e-6)
    assert np.all(wrench[:, [0, 1, 5]] == 0)
    cov = np.array([m.data for m in peer.covariances]).reshape(-1, 3, 3)
    np.testing.assert_allclose(cov, reference.cov[:n][:, [1, 2, 0]][:, :, [1, 2, 0]], rtol=1e-6)
    assert peer.covariances[0].layout.dim[0].label == "fx fy M"
    assert status is not None, [d.status[0].message for d in peer.diagnostics]
    values = {k.key: k.value for k in status.values}
    assert values["channels"] == "M fx fy" and len(values["offset"].split()) == 3
    assert not ok and message == ("identify_payload refused: fmscal's payload fits are a 6-axis sensor's, and this "
                                  "calibration is of a planar reading (M fx fy); the payload in use is the "
                                  "calibration's")


# --- the other motion sources: joint states with a URDF, an IMU --------------------------------------------------
#: The motion sources' tests' noise model (tests/test_motion_sources.py's; the harness's calibration's).
NOISE = NoiseSpec(*HARNESS_NOISE)


@pytest.fixture(scope="module")
def ur5():
    """1 s at 1 kHz of a UR5 moving every joint, its readings the payload's exact wrench (tests/robot_rig.py)."""
    return robot_rig.ur5_run(1.0)


def _source_calibration(tmp_path):
    return tool_calibration(tmp_path / "cal.json")


def _replay_source(request, node_args, message, build, t, w_hat):
    """The node on a joint-state or IMU topic, fed ``w_hat`` and ``build``'s messages; the contact messages and
    the stamps' epoch."""
    domain = domain_id(request.node.name)
    with running_node(domain, *node_args) as proc:
        peer = Peer(domain, pose_topic="/motion", motion=message)
        try:
            peer.wait_for_node(proc)
            epoch = peer.replay_rows(t, w_hat, build)
            assert peer.wait_for(lambda: len(peer.contacts) >= len(t) - 59, 10), \
                (len(peer.contacts), node_log(proc)[-1500:])
        finally:
            peer.close()
    return peer.contacts, epoch


@pytest.mark.slow
def test_joint_states(request, ur5, tmp_path):
    """JointState (names in reverse order, positions only; one with a NaN position, skipped) with the UR5's URDF:
    every reading out, as Compensator(motion=JointMotion) gives it pushed the same joints (none at that row);
    the readings being the payload's wrench alone, the contact wrench within 2e-3 of zero (the classical
    acceleration)."""
    run = ur5
    names = run["motion"].joints[::-1]
    good, bad = joint_state(names, run["q"][:, ::-1]), 300

    def build(i, stamp):                      # one message with a NaN position: skipped (a warning), not fatal
        msg = good(i, stamp)
        if i == bad:
            msg.position = [float("nan")] + list(msg.position[1:])
        return msg

    contacts, epoch = _replay_source(
        request, (f"calibration:={_source_calibration(tmp_path)}", "joint_states_topic:=/motion",
                  f"urdf:={robot_rig.ur5_urdf()}", "frame:=tool0", "qos:=reliable"),
        JointState, build, run["t"], run["W"])
    stream = Compensator(Calibration.load(tmp_path / "cal.json"), 1e-3, motion=run["motion"])
    expected = [o for o in (stream.push(t, w, joints=None if i == bad else (q, None, None))
                            for i, (t, w, q) in enumerate(zip(run["t"], run["W"], run["q"]))) if o is not None]
    t, wrench = contact_array(contacts, epoch)
    assert len(t) == len(expected) == len(run["t"]) - 59
    np.testing.assert_allclose(t, [round(o.t, 6) for o in expected], atol=1e-9)
    np.testing.assert_allclose(wrench, [o.wrench for o in expected], atol=1e-7)
    assert np.abs(wrench).max() < 2e-3


def _joints_at_5_khz(tmp_path, seed):
    """1 s of the UR5 (tests/robot_rig.py) at 5 kHz: the run, its readings with the harness's noise, and a
    pipeline of its joint states (the harness's calibration; 1 in 5 compensated)."""
    run = robot_rig.ur5_run(1.0, 2e-4)
    w_hat = run["W"] + np.random.default_rng(seed).normal(0.0, 1.0, run["W"].shape) * np.asarray(HARNESS_NOISE[0])
    values = {p.name: p.default for p in PARAMETERS}
    values.update(calibration=str(tool_calibration(tmp_path / "cal.json")), joint_states_topic="/j",
                  urdf=str(robot_rig.ur5_urdf()), frame="tool0", sample_time=2e-4)
    return run, w_hat, Pipeline(settings(values), motion=run["motion"])


def test_no_reading_takes_its_motion_across_a_hole_in_it(tmp_path):
    """Joint states and readings at 5 kHz (1 in 5 compensated), 71 ms of readings lost and then, 6 ms later, 59 ms
    of joint states (a node behind its inputs, its queues overflowing: tests/test_ros2_faults.py's 5 kHz case):
    the reading just before the motion's hole is not given a motion drawn straight across it. Drawn so, its
    error put outputs up to 15 sd off, unflagged, where the filter's window held the few samples after the
    readings' gap; here every output is within 5 sd (the largest of six channels' |z|), as without the holes."""
    run, w_hat, pipeline = _joints_at_5_khz(tmp_path, 3)
    out = []
    for i, t in enumerate(run["t"]):
        if not 0.7208 < t < 0.78:
            pipeline.add_motion(t, (run["q"][i], None, None))
        if not 0.644 < t < 0.715:
            pipeline.add_reading(t, w_hat[i])
        if i % 20 == 0:
            out += pipeline.process()
    t = np.array([o.sample.t for o in out])
    z = np.array([np.abs(o.sample.wrench) / np.sqrt(np.diag(o.sample.cov)) for o in out]).max(axis=1)
    assert pipeline.decimation == 5 and np.any((t > 0.715) & (t < 0.722)), t[(t > 0.7) & (t < 0.8)]
    assert z.max() < 5.0, (t[z.argmax()], z.max())


def test_the_decimation_grid_goes_on_through_a_restart(tmp_path):
    """Readings and joint states at 5 kHz (1 in 5 compensated) with 0.12 s of readings lost (a restart of the
    window), taken in passes of 37 readings (a node behind its inputs): the kept stamps stay on one grid, whole
    milliseconds apart, so the compensator restarts once (the gap) and never for a stamp off its grid. A grid
    started again at the next pass's first reading kept stamps 0.8 ms apart, with no gap."""
    run, w_hat, pipeline = _joints_at_5_khz(tmp_path, 4)
    out = []
    for i, t in enumerate(run["t"]):
        pipeline.add_motion(t, (run["q"][i], None, None))
        if not 0.4 < t < 0.52:
            pipeline.add_reading(t, w_hat[i])
        if i % 37 == 0:
            out += pipeline.process()
    t = np.array([o.sample.t for o in out])
    steps = np.diff(t) / 1e-3
    assert pipeline.decimation == 5 and dict(pipeline.compensator.events) == {"restart": 1}, \
        (pipeline.compensator.events, pipeline.compensator.warnings)
    assert np.abs(steps - np.round(steps)).max() < 1e-6 and len(t) > 700, (len(t), steps[steps % 1 > 1e-6])


@pytest.mark.slow
def test_identify_payload_from_joint_states(tmp_path):
    """identify_payload on joint states: the held joint angles' poses by the URDF's forward kinematics, the
    payload fitted to them and the readings, with a sensor's noise (the truth's mass and centre of mass within 4 of
    their sd; a noise-free reading has no noise to hold the payload's effect to); an IMU source is refused."""
    run = robot_rig.ur5_run(2.0)
    sd = np.array([2e-3] * 3 + [5e-2] * 3)                   # spatial-arm's sensor: N m, N
    noisy = run["W"] + np.random.default_rng(5).normal(0.0, sd, np.shape(run["W"]))
    values = {p.name: p.default for p in PARAMETERS}
    values.update(calibration=str(_source_calibration(tmp_path)), joint_states_topic="/j",
                  urdf=str(robot_rig.ur5_urdf()), frame="tool0", sample_time=1e-3)
    pipeline = Pipeline(settings(values), motion=run["motion"])
    for t, q, w in zip(run["t"], run["q"], noisy):
        pipeline.add_motion(t, (q, None, None))
        pipeline.add_reading(t, w)
        pipeline.process()
    ok, message = pipeline.identify()
    assert ok, message
    mass = float(message.split("mass ")[1].split(" ")[0])
    mass_sd = float(message.split("mass ")[1].split(" ")[2])
    com = np.array(message.split("com ")[1].split(" m")[0].split(), dtype=float)
    assert abs(mass - TOOL.mass) < 4 * mass_sd + 1e-4 * TOOL.mass, message      # the message's 4 digits
    assert np.all(np.abs(com - np.asarray(TOOL.com)) < 2e-3), com
    imu = Pipeline(settings({**values, "joint_states_topic": "", "urdf": "", "frame": "", "imu_topic": "/i"}),
                   motion=ImuMotion())
    ok, message = imu.identify()
    assert not ok and message.startswith("identify_payload refused: 0 samples held since the last call"), message


def _held_imu(seconds_held=1.2, poses=6, dt=0.004, seed=4):
    """An IMU (axes C_IMU in the sensor's) on a tool held at ``poses`` attitudes and turned between them
    (simulate_attitude_log): its orientation, body rate and specific force (no linear acceleration), the
    sensor's readings, and their times."""
    log = simulate_attitude_log(TOOL, poses=poses, hold=seconds_held, move=0.6, dt=dt, seed=seed,
                                gravity=(0.0, 0.0, -9.81), wrench_sd=NOISE.wrench_sd)
    R_s = robot_rig.Rotation.from_quat(log.q[:, [1, 2, 3, 0]])
    R_i = R_s * robot_rig.Rotation.from_matrix(robot_rig.C_IMU)             # R_IMU = R_S C
    omega = np.vstack([(R_i[:-1].inv() * R_i[1:]).as_rotvec() / dt, np.zeros((1, 3))])
    force = R_i.inv().apply([0.0, 0.0, 9.81])
    return log.t, R_i.as_quat()[:, [3, 0, 1, 2]], omega, force, log.w_hat


def _imu_settings(tmp_path, **values):
    v = {p.name: p.default for p in PARAMETERS}
    xyzw = robot_rig.Rotation.from_matrix(robot_rig.C_IMU).as_quat()
    v.update(calibration=str(_source_calibration(tmp_path)), imu_topic="/i", sample_time=4e-3,
             imu_rotation=list(xyzw), **values)
    return settings(v)


@pytest.mark.slow
def test_identify_payload_from_an_imu(tmp_path):
    """identify_payload on an IMU: its orientation through imu_rotation gives the sensor's attitude, the held
    segments are fitted statically: the truth's mass and centre of mass (the inertia kept); an IMU without
    orientation is refused, saying why."""
    t, quaternion, omega, force, w_hat = _held_imu()
    runs = {}
    for oriented in (True, False):
        pipeline = Pipeline(_imu_settings(tmp_path), motion=ImuMotion(robot_rig.C_IMU))
        for row in zip(t, quaternion, omega, force, w_hat):
            pipeline.add_motion(row[0], (row[1] if oriented else None, row[2], row[3]))
            pipeline.add_reading(row[0], row[4])
            pipeline.process()
        runs[oriented] = pipeline.identify(), pipeline
    (ok, message), pipeline = runs[True]
    assert ok, message
    assert int(message.split("from ")[1].split(" held poses")[0]) >= 5 and "the inertia kept" in message, message
    mass = float(message.split("mass ")[1].split(" ")[0])
    com = np.array(message.split("com ")[1].split(" m")[0].split(), dtype=float)
    assert abs(mass - TOOL.mass) < 0.01 * TOOL.mass, mass
    assert np.all(np.abs(com - np.asarray(TOOL.com)) < 2e-3), com
    assert pipeline.payload.inertia == TOOL.inertia and pipeline.payload.mass == pytest.approx(mass, rel=1e-3)
    (ok, message), _ = runs[False]
    assert not ok and message.startswith("identify_payload refused: the IMU gave no orientation ("), message


@pytest.mark.slow
def test_imu(request, ur5, tmp_path):
    """sensor_msgs/Imu (orientation scalar last) of an IMU turned and 7 cm off the sensor's point, imu_rotation
    and imu_lever_arm given, the output in the base frame at a tool point: as Compensator(motion=ImuMotion,
    frame="base", point=...) gives it; the readings being the payload's wrench alone, the contact wrench is
    within 1e-3 of zero."""
    run = ur5
    quaternion, omega, force, _ = robot_rig.imu_readings(run)
    xyzw = np.r_[robot_rig.Rotation.from_matrix(robot_rig.C_IMU).as_quat()]
    point = [0.0, 0.02, 0.1]
    args = (f"calibration:={_source_calibration(tmp_path)}", "imu_topic:=/motion", "qos:=reliable",
            "imu_rotation:=[" + ",".join(repr(float(v)) for v in xyzw) + "]",
            "imu_lever_arm:=[" + ",".join(repr(float(v)) for v in robot_rig.R_IMU) + "]",
            "output_frame:=base", "base_frame:=world", "tool_point:=[" + ",".join(map(repr, point)) + "]")
    contacts, epoch = _replay_source(request, args, Imu, imu_message(quaternion, omega, force), run["t"], run["W"])
    stream = Compensator(Calibration.load(tmp_path / "cal.json"), 1e-3, motion=ImuMotion(robot_rig.C_IMU,
                                                                                          robot_rig.R_IMU),
                         frame="base", point=point)
    expected = [o for o in (stream.push(t, w, imu=(q, om, f)) for t, w, q, om, f in
                            zip(run["t"], run["W"], quaternion, omega, force)) if o is not None]
    t, wrench = contact_array(contacts, epoch)
    assert len(t) == len(expected) == len(run["t"]) - 59
    assert {m.header.frame_id for m in contacts} == {"world"}
    np.testing.assert_allclose(wrench, [o.wrench for o in expected], atol=1e-6)
    assert np.abs(wrench).max() < 1e-3


def _taken(peer):
    """The readings the node has taken or counted as lost, none waiting for the motion (its newest diagnostics;
    -1 before any): what a loaded machine's late or lost delivery cannot hold up."""
    if not peer.diagnostics:
        return -1
    values = {v.key: v.value for v in peer.diagnostics[-1].status[0].values}
    if "received" not in values or int(values["backlog"]):
        return -1
    return int(values["received"]) + int(values["lost"])


@pytest.mark.slow
def test_identify_payload_from_an_imu_over_ros(request, tmp_path):
    """~/identify_payload on an imu_topic node (imu_rotation given), fed 10 s of a tool held at six attitudes
    (four times faster than their stamps): the truth's mass and centre of mass; then 1 s of an IMU publishing no
    orientation (orientation_covariance[0] == -1): refused, saying why."""
    t, quaternion, omega, force, w_hat = _held_imu()
    xyzw = robot_rig.Rotation.from_matrix(robot_rig.C_IMU).as_quat()
    # stale_timeout 2 s of the stamps: 0.5 s of wall time at four times their pace (the default 0.5 s, 125 ms of
    # wall time, is a busy machine's delay between the two subscriptions: the readings withheld as stale, none held)
    args = (f"calibration:={_source_calibration(tmp_path)}", "imu_topic:=/motion", "qos:=reliable",
            "stale_timeout:=2.0", "imu_rotation:=[" + ",".join(repr(float(v)) for v in xyzw) + "]")
    oriented = imu_message(quaternion, omega, force)

    def unoriented(i, stamp):
        msg = oriented(i, stamp)
        msg.orientation_covariance[0] = -1.0
        return msg
    domain = domain_id(request.node.name)
    with running_node(domain, *args) as proc:
        peer = Peer(domain, pose_topic="/motion", motion=Imu)
        try:
            peer.wait_for_node(proc)
            epoch = peer.replay_rows(t, w_hat, oriented, rate=4.0)
            assert peer.wait_for(lambda: _taken(peer) >= len(t) - 20, 120), _taken(peer)    # lost ones counted too
            ledger = {v.key: v.value for v in peer.diagnostics[-1].status[0].values}      # (said where it fails)
            ok, message = peer.call("identify_payload", proc=proc)
            more = t[-1] + 0.004 + np.arange(250) * 0.004
            peer.replay_rows(more, w_hat[:250], unoriented, epoch=epoch)
            assert peer.wait_for(lambda: _taken(peer) >= len(t) + 250 - 20, 120), _taken(peer)
            refused, why = peer.call("identify_payload", proc=proc)
        finally:
            peer.close()
    assert ok, (message, {k: v for k, v in ledger.items() if v not in ("0", "")})
    mass = float(message.split("mass ")[1].split(" ")[0])
    com = np.array(message.split("com ")[1].split(" m")[0].split(), dtype=float)
    assert abs(mass - TOOL.mass) < 0.01 * TOOL.mass, mass
    assert np.all(np.abs(com - np.asarray(TOOL.com)) < 2e-3), com
    assert not refused and why.startswith("identify_payload refused: the IMU gave no orientation ("), why


# --- slow: the other services, and the latency benchmark ----------------------------------------------------------
@pytest.mark.slow
def test_identify_payload(request, arm, cal_file):
    """~/identify_payload fits the payload to the 1.6 s replayed (the truth's mass and centre of mass); a second
    call at once has nothing held and refuses; the output goes on with no gap, at the noise with the identified
    payload."""
    scenario, log, truth, cal = arm
    with _node(request, cal_file) as proc:
        peer = Peer(domain_id(request.node.name))
        try:
            peer.wait_for_node(proc)
            epoch = peer.replay(log.head(1600))
            assert peer.wait_for(lambda: len(peer.contacts) >= 1541, 10)
            ok, message = peer.call("identify_payload")
            again, refusal = peer.call("identify_payload")
            peer.replay(log, start=1600, epoch=epoch)
            assert peer.wait_for(lambda: len(peer.contacts) >= len(log) - 59, 10)
        finally:
            peer.close()
    assert ok, message
    mass = float(message.split("mass ")[1].split(" ")[0])
    com = np.array(message.split("com ")[1].split(" m")[0].split(), dtype=float)
    assert mass == pytest.approx(scenario.payload.mass, rel=0.01)
    assert np.all(np.abs(com - scenario.payload.com) < 1e-3), com
    assert not again and refusal.startswith("identify_payload refused: 0 samples held since the last call")
    t, wrench = contact_array(peer.contacts, epoch)
    assert len(t) == len(log) - 59
    after = wrench[t > 1.65]
    assert len(after) > 250
    rms = np.sqrt(np.mean(after ** 2, axis=0)) / noise_rms(truth.S_at(0.0), truth.noise.wrench_sd)
    assert np.all((rms > 0.7) & (rms < 1.5)), rms


@pytest.mark.slow
def test_a_tool_change_on_the_node(request, tmp_path):
    """A 200 g part grasped while the arm moves (tests/test_tool_change.py's log, 6 s of it replayed around the
    grasp): the node's log names the change and its time, the diagnostics count it and carry its line, the flags of
    the outputs after it say tool_change (none before the grasp); ~/reidentify, with no attitude held, refuses in
    one line and the flag stays."""
    from tool_change_rig import PART
    from fmscal.plant.scenarios import with_grasp
    scenario = ARM.with_(duration=12.0)
    log, truth, _ = with_grasp(scenario, 4, PART, 6.0)
    path = tmp_path / "cal.json"
    truth_calibration(scenario, truth).save(path)
    first, last = (int(np.searchsorted(log.t, at)) for at in (4.0, 10.0))
    with _node(request, path) as proc:
        peer = Peer(domain_id(request.node.name), flags=True)
        try:
            peer.wait_for_node(proc)
            epoch = peer.replay(log.head(last), start=first)
            end = epoch + log.t[last - 1] - 0.1          # the newest outputs (under load, some may be withheld)
            assert peer.wait_for(lambda: peer.contacts and seconds(peer.contacts[-1].header.stamp) > end, 30)
            refused = peer.call("reidentify")
            assert peer.wait_for(lambda: any(v.key == "tool_changes" and v.value == "1"
                                             for d in peer.diagnostics for v in d.status[0].values), 5)
            values = {v.key: v.value for v in peer.diagnostics[-1].status[0].values}
            said = node_log(proc)
        finally:
            peer.close()
    assert values["tool_changes"] == "1" and values["tool_change"].startswith("tool change at "), values
    at = float(values["tool_change"].split()[3])
    assert abs(at - epoch - 6.0) < 0.3 and "tool_change" in values["flags"], values
    assert f"tool change at {at:.3f} s" in said and "then ~/reidentify" in said, said[-2000:]
    flags = {m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 - epoch: m.status[0].message for m in peer.flags}
    before = [m for t, m in flags.items() if t < 6.0]            # (a loaded machine may lose some of the flags:
    after = [m for t, m in flags.items() if t > 8.5 and not m.startswith("withheld")]     # those that came count)
    assert len(before) > 500 and len(after) > 500, (len(before), len(after))
    assert not any("tool_change" in m for m in before)
    assert all("tool_change" in m for m in after)
    assert not refused[0] and refused[1].startswith("reidentify refused: ") and "\n" not in refused[1], refused


@pytest.mark.slow
def test_save(request, arm, cal_file, tmp_path):
    """~/save refuses without save_path, which cannot be set on the running node (parameters are read at
    start: the change refused, saying so); started with it, writes the calibration with the tracked offset in
    use: S, the payload and gravity as loaded, b the offset the diagnostics report."""
    scenario, log, truth, cal = arm
    saved = tmp_path / "saved.json"
    with _node(request, cal_file, "track_offset:=true") as proc:
        peer = Peer(domain_id(request.node.name))
        try:
            peer.wait_for_node(proc)
            refused = peer.call("save")
            changed = peer.set_parameter("save_path", str(saved))
        finally:
            peer.close()
    assert refused == (False, "save refused: set the parameter save_path")
    assert not changed.successful
    assert changed.reason == ("fmscal_compensator reads its parameters at start: restart it to change save_path "
                              "(~/reload reads the calibration file again)")
    second = domain_id(request.node.name + "/second")
    with _node(request, cal_file, "track_offset:=true", f"save_path:={saved}", domain=second) as proc:
        peer = Peer(second)
        try:
            peer.wait_for_node(proc)
            peer.replay(log.head(600))
            assert peer.wait_for(lambda: len(peer.contacts) >= 541, 10)
            ok, message = peer.call("save")
            time.sleep(0.3)
            offset = [d.status[0] for d in peer.diagnostics][-1]
        finally:
            peer.close()
    assert ok and message.startswith(f"saved {saved}: offset "), message
    loaded = Calibration.load(saved)
    np.testing.assert_allclose(loaded.S, cal.S)
    assert loaded.payload == cal.payload and np.allclose(loaded.gravity, cal.gravity)
    b = np.array(message.split("offset ")[1].split(), dtype=float)
    np.testing.assert_allclose(loaded.b, b, rtol=1e-5, atol=1e-9)
    reported = np.array({k.key: k.value for k in offset.values}["offset"].split(), dtype=float)
    np.testing.assert_allclose(loaded.b, reported, rtol=1e-5, atol=1e-9)
    sd = np.asarray(truth.noise.wrench_sd)
    assert np.all(np.abs(loaded.b - cal.b) < 3 * sd) and not np.allclose(loaded.b, cal.b)


@pytest.mark.slow
def test_reload(request, arm, tmp_path):
    """The calibration file corrected while the node runs: ~/reload reads it, the output goes on with no gap
    (every reading out), and its offset error (S delta before) is gone after it; a file made unreadable is
    refused and the one in use kept."""
    scenario, log, truth, cal = arm
    S = truth.S_at(0.0)
    path = tmp_path / "cal.json"
    delta = _offset_off(cal, truth, path)
    noise = noise_rms(S, truth.noise.wrench_sd)
    with _node(request, path) as proc:
        peer = Peer(domain_id(request.node.name))
        try:
            peer.wait_for_node(proc)
            epoch = peer.replay(log.head(700))
            assert peer.wait_for(lambda: len(peer.contacts) >= 641, 10)
            before = len(peer.contacts)
            cal.save(path, overwrite=True)
            ok, message = peer.call("reload", proc=proc)
            peer.replay(log.head(1500), start=700, epoch=epoch)
            path.write_text("{")
            bad, refusal = peer.call("reload", proc=proc)
            peer.replay(log, start=1500, epoch=epoch)
            assert peer.wait_for(lambda: len(peer.contacts) >= len(log) - 59, 10)
        finally:
            peer.close()
    assert ok and message.startswith(f"reloaded {path}: offset "), message
    assert not bad and refusal.startswith("reload refused, the calibration in use kept: cal.json: not a JSON")
    t, wrench = contact_array(peer.contacts, epoch)
    assert len(t) == len(log) - 59 and np.all(np.diff(t) > 0)
    assert np.all(np.abs(wrench[100:before].mean(axis=0) - S @ delta) < 0.25 * noise)
    after = t > 0.8
    assert np.all(np.abs(wrench[after].mean(axis=0)) < 0.25 * noise), wrench[after].mean(axis=0) / noise


@pytest.mark.slow
def test_latency_benchmark_short():
    """benchmarks/ros2_latency.py on 3 s: every output comes, in order, none dropped (or the readings a loaded
    machine's node lost from its queue counted, and every output it published come), and the delays it reports
    are ordered (0 < p50 <= p99 <= largest). The delay's target lives in the benchmark and docs/speed.md, not
    here: the suite runs beside other tests, where the tail is the wait for a core."""
    done = _run(str(ROOT / "benchmarks" / "ros2_latency.py"), "--duration", "3", "--json")
    assert done.returncode == 0, done.stderr[-2000:]
    r = json.loads(done.stdout.strip().splitlines()[-1])
    # a loaded machine may overflow the node's 1 s queue: each reading then taken or counted lost, each output
    # the node published come
    assert r["sent"] == 3002 and r["received_by_node"] + r["lost_by_node"] == 3002, r
    assert r["received"] == r["published_by_node"] and r["in_order"], r
    if r["lost_by_node"] == 0:
        assert r["received"] == r["expected"] == 3002 - 59 and r["dropped"] == 0, r
    d = r["beyond_delay_s"]
    assert 0 < d["p50"] <= d["p99"] <= d["max"] and np.isfinite(d["max"]), d


@pytest.mark.slow
def test_remapped_names(request, arm, cal_file):
    """-r remappings: the node renamed (its services under the new name, its two helper nodes named after it)
    and its topics remapped, a relative pose topic among them."""
    scenario, log, truth, cal = arm
    domain = domain_id(request.node.name)
    remaps = ["-r", "__node:=comp", "-r", "/ft_sensor/wrench:=/ati/raw", "-r", "pose_in:=/mocap/tool"]
    with running_node(domain, f"calibration:={cal_file}", "pose_topic:=pose_in", "qos:=reliable",
                      ros_args=remaps):
        peer = Peer(domain, wrench_topic="/ati/raw", pose_topic="/mocap/tool", node_name="comp")
        try:
            assert peer.wait_for(lambda: peer.wrench_pub.get_subscription_count() and peer.diagnostics
                                 and peer.pose_pub.get_subscription_count(), 30)
            peer.replay(log.head(300))
            assert peer.wait_for(lambda: len(peer.contacts) >= 241, 10)
            ok, message = peer.call("tare")
            names = peer.node.get_node_names()
        finally:
            peer.close()
    assert ok, message
    assert {"comp", "comp_inputs", "comp_services"} <= set(names) and "fmscal_compensator" not in names
