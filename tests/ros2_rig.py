"""The ROS 2 tests' and benchmark's rig: the node started as a subprocess (``python -m fmscal.analysis.cli ros2``)
and a publisher and subscriber in this process, over real DDS on loopback.

Each test runs in its own ROS domain (:func:`domain_id`: one no other process on this machine holds) with
discovery kept to this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``), so that no two tests hear each
other. Every wait is bounded, and the node is stopped by its process id in a ``finally``.

The fault-injection harness (tests/test_ros2_faults.py): a sender of its own process (``python tests/ros2_rig.py
PLAN.json``, :func:`send_plan`) replays the UR5 carrying its tool (tests/robot_rig.py) as a pose, joint-state or
IMU stream with the readings, the faults :func:`schedule` scripts (messages dropped, paused, repeated, stamped back,
a second publisher, the sender killed and restarted, garbage); :class:`Listener` takes the node's outputs, their
covariances and flags and its diagnostics without an executor (:class:`Taker`); :class:`CpuHog` is a busy process
beside the node.
"""

import fcntl
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
import zlib
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import rclpy
from scipy.spatial.transform import Rotation
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from geometry_msgs.msg import PoseStamped, WrenchStamped
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters

from fmscal.plant import Calibration

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"

#: The longest any one wait may take, s (discovery, a service's answer, the last output).
WAIT = 30.0


#: The ROS domains the tests use, 1 to this (Fast DDS's ports reach to 232).
DOMAINS = 200


#: Where the domains' locks are (one file each): every process on this machine that runs these tests claims its
#: domains there, xdist's workers and a second test run or the soak alike.
DOMAIN_LOCKS = Path(tempfile.gettempdir()) / "fmscal-ros-domains"

#: How many of this process's newest names keep their domain (a test asks for one or two; the older are let go).
KEPT = 4

_claimed = {}                                          # name -> (domain, the open lock file), newest last


def domain_id(name):
    """A ROS domain for one test, in 1-:data:`DOMAINS`, that no other process on this machine holds: the first free
    one from a hash of the name, claimed by an exclusive lock on its file in :data:`DOMAIN_LOCKS` and kept while
    this process asks for at most :data:`KEPT` newer names (the same name gives the same domain). A hash alone let
    two tests running at once on two xdist workers share a domain now and then; each then heard the other's node
    (its outputs, its diagnostics, its answers)."""
    if name in _claimed:
        return _claimed[name][0]
    DOMAIN_LOCKS.mkdir(exist_ok=True)
    start = zlib.crc32(name.encode())
    for k in range(DOMAINS):
        domain = 1 + (start + k) % DOMAINS
        if any(d == domain for d, _ in _claimed.values()):
            continue
        lock = open(DOMAIN_LOCKS / f"{domain}.lock", "a")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        _claimed[name] = (domain, lock)
        while len(_claimed) > KEPT:
            _claimed.pop(next(iter(_claimed)))[1].close()
        return domain
    raise RuntimeError(f"all {DOMAINS} ROS domains are held by other processes ({DOMAIN_LOCKS})")


def truth_calibration(scenario, truth, **kw):
    """A calibration holding the scenario's truth (S, b, payload, gravity, noise): the compensation alone under
    test."""
    return Calibration(S=truth.S_at(0.0), payload=scenario.payload, method="truth", b=truth.offset,
                       gravity=scenario.gravity, latency=0.0, noise=truth.noise, **kw)


def node_command(*parameters, params_file=None):
    """``python -m fmscal.analysis.cli ros2`` with ``--ros-args -p`` of each ``name:=value``."""
    cmd = [sys.executable, "-m", "fmscal.analysis.cli", "ros2"]
    if params_file is not None:
        cmd += ["--params-file", str(params_file)]
    if parameters:
        cmd += ["--ros-args"] + [a for p in parameters for a in ("-p", p)]
    return cmd


@contextmanager
def running_node(domain, *parameters, params_file=None, ros_args=()):
    """The node in a subprocess of domain ``domain``; stopped (SIGINT, then SIGKILL) on leaving. Yields the
    :class:`subprocess.Popen` (its stderr piped to a file, read by :func:`node_log`). ``ros_args``: more ROS
    arguments after the parameters (``-r`` remappings)."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               PYTHONUNBUFFERED="1")
    parameters = ("diagnostics_period:=0.1", *parameters)
    log = open(os.devnull, "w") if os.environ.get("FMSCAL_ROS_QUIET") else None
    err = tempfile.TemporaryFile(mode="w+")
    proc = subprocess.Popen(node_command(*parameters, params_file=params_file) + list(ros_args), env=env,
                            stdout=log or err,
                            stderr=err, text=True)
    proc.log_file = err
    try:
        yield proc
    finally:
        stop(proc)
        if log is not None:
            log.close()


def stop(proc):
    """A process of the tests stopped as Ctrl-C does (SIGINT), killed after 5 s."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)


def wait_until(condition, timeout=WAIT):
    """Whether ``condition()`` held within ``timeout`` s (looked at every 20 ms)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.02)
    return False


def node_log(proc):
    """What the node wrote to stderr so far."""
    proc.log_file.flush()
    proc.log_file.seek(0)
    return proc.log_file.read()


RELIABLE = QoSProfile(depth=2000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)


class Peer:
    """This process's side: publishers of the readings and poses, subscribers of the contact wrench, its
    covariance (``covariance``), the diagnostics and the node's latency, service clients; spun in a thread."""

    def __init__(self, domain, wrench_topic="/ft_sensor/wrench", pose_topic="/ft_sensor/pose",
                 contact_topic="/ft_sensor/contact", covariance_topic="/ft_sensor/contact_covariance",
                 node_name="fmscal_compensator", motion=PoseStamped, covariance=True, flags=False):
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node("fmscal_test_peer", context=self.context)
        self.node_name = node_name
        self.wrench_pub = self.node.create_publisher(WrenchStamped, wrench_topic, RELIABLE)
        self.pose_pub = self.node.create_publisher(motion, pose_topic, RELIABLE)
        self.contacts, self.covariances, self.diagnostics, self.latencies = [], [], [], []
        self.contact_sub = self.node.create_subscription(WrenchStamped, contact_topic, self.contacts.append, RELIABLE)
        if covariance:
            self.node.create_subscription(Float64MultiArray, covariance_topic, self.covariances.append, RELIABLE)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self.diagnostics.append, 10)
        self.flags = []                          # with flags: the outputs' flags (the node's flags_topic)
        if flags:
            self.node.create_subscription(DiagnosticArray, "/ft_sensor/contact_flags", self.flags.append, RELIABLE)
        self.node.create_subscription(Float64MultiArray, f"/{node_name}/latency",
                                      lambda m: self.latencies.append(list(m.data)), RELIABLE)
        self.clients = {s: self.node.create_client(Trigger, f"/{node_name}/{s}")
                        for s in ("tare", "tare_force", "identify_payload", "reidentify", "save", "reload", "push")}
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self):
        try:
            while self.context.ok():
                self.executor.spin_once(timeout_sec=0.05)
        except Exception:                   # the context shut down under the loop
            pass

    def close(self):
        self.executor.shutdown(timeout_sec=1.0)
        rclpy.try_shutdown(context=self.context)
        self._thread.join(timeout=5)
        self.node.destroy_node()

    def wait_for_node(self, proc, timeout=WAIT):
        """Until the node subscribes to both inputs, publishes the contact wrench and its diagnostics have come
        (it has matched this process's subscribers: its first outputs are not lost), or it exits."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if proc.poll() is not None:
                raise AssertionError(f"the node exited ({proc.returncode}): {node_log(proc)[-2000:]}")
            if self.wrench_pub.get_subscription_count() and self.pose_pub.get_subscription_count() \
                    and self.contact_sub.get_publisher_count() and self.diagnostics:
                return
            time.sleep(0.05)
        raise AssertionError(f"the node was not discovered in {timeout} s: {node_log(proc)[-2000:]}")

    def replay(self, log, start=None, rate=1.0, poses=True, epoch=None):
        """Publish each row of ``log`` (a reading and its pose, both stamped ``epoch + t``) at the log's pace
        times ``rate``; ``poses``: a boolean per row (or all). Returns the stamps' epoch (s, now by default,
        a whole millisecond: the stamps are exact nanoseconds)."""
        send = np.ones(len(log.t), bool) if poses is True else np.asarray(poses, bool)

        def pose(i, stamp):
            if not send[i]:
                return None
            msg = PoseStamped()
            msg.header.stamp = stamp
            msg.header.frame_id = "world"
            qw, qx, qy, qz, x, y, z = (float(v) for v in log.pose[i])
            o, p = msg.pose.orientation, msg.pose.position
            o.w, o.x, o.y, o.z, p.x, p.y, p.z = qw, qx, qy, qz, x, y, z
            return msg
        return self.replay_rows(log.t, log.w_hat, pose, start, rate, epoch)

    def replay_rows(self, t, w_hat, motion, start=None, rate=1.0, epoch=None):
        """Publish a reading of each row of ``w_hat`` and the motion message ``motion(i, stamp)`` (None: no
        motion with this reading), both stamped ``epoch + t[i]``, at the pace of ``t`` times ``rate``; the
        stamps are the rows' times (their schedule), and :attr:`lateness` how late each row went out."""
        epoch = round(time.time(), 3) if epoch is None else epoch
        begin = time.perf_counter()
        first = start or 0
        self.lateness = []                       # s each row went out after its time (this process's stalls)
        for i in range(first, len(t)):
            due = begin + (t[i] - t[first]) / rate
            while (wait := due - time.perf_counter()) > 0:
                time.sleep(min(wait, 0.0005))
            self.lateness.append(-wait)
            sec, nanosec = divmod(int(round(epoch * 1e3)) * 1_000_000 + int(round(t[i] * 1e9)), 1_000_000_000)
            wrench = WrenchStamped()
            wrench.header.stamp.sec, wrench.header.stamp.nanosec = sec, nanosec
            message = motion(i, wrench.header.stamp)
            if message is not None:
                self.pose_pub.publish(message)
            wrench.header.frame_id = "ft_sensor"
            tx, ty, tz, fx, fy, fz = (float(v) for v in w_hat[i])
            wrench.wrench.torque.x, wrench.wrench.torque.y, wrench.wrench.torque.z = tx, ty, tz
            wrench.wrench.force.x, wrench.wrench.force.y, wrench.wrench.force.z = fx, fy, fz
            self.wrench_pub.publish(wrench)
        return epoch

    def wait_for(self, condition, timeout=WAIT):
        """Until ``condition()`` holds (:func:`wait_until`)."""
        return wait_until(condition, timeout)

    def set_parameter(self, name, value, timeout=WAIT):
        """Set one of the node's parameters (a string) by its ``set_parameters`` service; the result."""
        client = self.node.create_client(SetParameters, f"/{self.node_name}/set_parameters")
        assert client.wait_for_service(timeout_sec=timeout), "set_parameters not found"
        request = SetParameters.Request()
        request.parameters = [Parameter(name=name, value=ParameterValue(type=ParameterType.PARAMETER_STRING,
                                                                        string_value=value))]
        future = client.call_async(request)
        assert self.wait_for(future.done, timeout), "set_parameters: no answer"
        return future.result().results[0]

    def call(self, service, timeout=WAIT, proc=None):
        """Call a Trigger service of the node; ``(success, message)``."""
        client = self.clients[service]
        assert client.wait_for_service(timeout_sec=timeout), f"~/{service} not found"
        future = client.call_async(Trigger.Request())
        assert self.wait_for(future.done, timeout), \
            f"~/{service}: no answer in {timeout} s{'' if proc is None else ': ' + node_log(proc)[-1500:]}"
        result = future.result()
        return result.success, result.message


def stamp_of(t):
    """``(sec, nanosec)`` of a time in s (``epoch + t``: each rounded to the nanosecond, then added exactly)."""
    return divmod(int(round(t * 1e9)), 1_000_000_000)


def seconds(stamp):
    return stamp.sec + stamp.nanosec * 1e-9


def contact_array(msgs, epoch):
    """The contact messages as ``(t, wrench)``: ``t`` from the epoch (s, rounded to the microsecond), ``wrench``
    in fmscal's order (tx ty tz fx fy fz)."""
    t = np.array([round(seconds(m.header.stamp) - epoch, 6) for m in msgs])
    w = np.array([[m.wrench.torque.x, m.wrench.torque.y, m.wrench.torque.z, m.wrench.force.x, m.wrench.force.y,
                   m.wrench.force.z] for m in msgs])
    return t, w


def joint_state(names, q, dq=None):
    """A motion builder for :meth:`Peer.replay_rows`: JointState of ``names`` (in that order) at row ``i``."""
    def build(i, stamp):
        msg = JointState()
        msg.header.stamp = stamp
        msg.name = list(names)
        msg.position = [float(v) for v in q[i]]
        if dq is not None:
            msg.velocity = [float(v) for v in dq[i]]
        return msg
    return build


def imu_message(quaternion, omega, force):
    """A motion builder for :meth:`Peer.replay_rows`: sensor_msgs/Imu (orientation scalar last, as ROS has it)."""
    def build(i, stamp):
        msg = Imu()
        msg.header.stamp = stamp
        msg.header.frame_id = "imu"
        w, x, y, z = (float(v) for v in quaternion[i])
        msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = x, y, z, w
        msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = (float(v) for v in omega[i])
        a = msg.linear_acceleration
        a.x, a.y, a.z = (float(v) for v in force[i])
        return msg
    return build


# --- the fault-injection harness --------------------------------------------------------------------------------
class Taker:
    """Subscriptions taken by a thread of their own: it waits on them (rclpy's wait set, the interpreter's lock
    released while it waits), takes every queued message and hands each with its arrival (``time.time()``) to
    its subscription's callback. Much less Python per message than an executor's spin: a listener that keeps
    up with 1 kHz outputs on a loaded machine."""

    def __init__(self, node, context):
        self.node, self.context, self.subs = node, context, []
        self._thread, self._running = None, False

    def subscribe(self, msg_type, topic, callback, qos):
        sub = self.node.create_subscription(msg_type, topic, lambda m: None, qos)
        self.subs.append((sub, callback))
        return sub

    def start(self):
        self._running = True
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
        try:
            with self.context.handle:
                wait_set = _rclpy.WaitSet(len(self.subs), 0, 0, 0, 0, 0, self.context.handle)
                while self._running and self.context.ok():
                    wait_set.clear_entities()
                    for sub, _ in self.subs:
                        wait_set.add_subscription(sub.handle)
                    wait_set.wait(50_000_000)
                    for sub, callback in self.subs:
                        with sub.handle:
                            while (taken := sub.handle.take_message(sub.msg_type, sub.raw)) is not None:
                                callback(taken[0], time.time())
        except Exception:                             # the context shut down under the loop
            pass

    def stop(self):
        """Stop the thread (within the wait's 50 ms), before the context shuts down."""
        self._running = False
        if self._thread is not None:
            self._thread.join(timeout=5)


#: The harness's motion sources: the node's parameter and the message of each.
SOURCES = {"pose": ("pose_topic", PoseStamped), "joints": ("joint_states_topic", JointState),
           "imu": ("imu_topic", Imu)}
#: The harness's noise model: the readings' sd (N m, N), the poses' (rad, m); the calibration's.
HARNESS_NOISE = ((0.005,) * 3 + (0.1,) * 3, 1e-4, 1e-4)
#: The faults :func:`schedule` scripts (module docstring of tests/test_ros2_faults.py).
FAULTS = ("drop", "pause", "back", "duplicate", "second", "kill", "garbage", "glitch")
#: The streams a fault acts on: the readings, the motion, both.
STREAMS = ("w", "m", "both")
#: The relay topics of the harness's motion (any source).
MOTION_TOPIC = "/motion"


def tool_calibration(path):
    """The harness's calibration, saved at ``path``: the UR5's tool (``TOOL``) on a sensor with ``S = I``, no
    offset, gravity down the URDF's base z, the harness's noise."""
    from fmscal.plant import NoiseSpec
    from fmscal.plant.scenarios._spatial import TOOL
    wrench_sd, angle_sd, position_sd = HARNESS_NOISE
    Calibration(S=np.eye(6), payload=TOOL, method="truth", b=np.zeros(6), gravity=(0.0, 0.0, -9.81), latency=0.0,
                noise=NoiseSpec(wrench_sd, angle_sd, position_sd)).save(path, overwrite=True)     # asked twice
    return path


def tool_payload(path):
    """The harness's tool as ``fmscal identify-payload --save`` writes it (``fmscal-payload``), saved at ``path``: the
    UR5's tool (``TOOL``) on a sensor with ``S = I``, no offset, gravity down the URDF's base z, the harness's noise
    of a sample; its mass and centre of mass with the sds a few held poses give, the inertia undetermined (held
    poses never show it)."""
    from fmscal.observers.payload import PayloadEstimate
    from fmscal.plant.scenarios._spatial import TOOL
    sd = np.asarray(HARNESS_NOISE[0], dtype=float)
    PayloadEstimate(mass=TOOL.mass, mass_std=2e-3, com=np.array(TOOL.com), com_std=np.full(3, 3e-4), inertia=None,
                    inertia_std=None, b=np.zeros(6), b_std=sd / 10, residual_rms=sd, converged=True,
                    payload_determined=True, gravity_given=np.array([0.0, 0.0, -9.81]), reading="reaction",
                    noise_sd=sd, noise_of="sample", inertia_reason="held poses do not show the inertia").save(path)
    return path


def source_parameters(source):
    """The node's parameters for a motion source of the harness (besides the calibration)."""
    import robot_rig
    from scipy.spatial.transform import Rotation
    topic = f"{SOURCES[source][0]}:={MOTION_TOPIC}"
    if source == "joints":
        return (topic, f"urdf:={robot_rig.ur5_urdf()}", "frame:=tool0")
    if source == "imu":
        xyzw = Rotation.from_matrix(robot_rig.C_IMU).as_quat()
        return (topic, "imu_rotation:=[" + ",".join(repr(float(v)) for v in xyzw) + "]",
                "imu_lever_arm:=[" + ",".join(repr(float(v)) for v in robot_rig.R_IMU) + "]")
    return (topic,)


def harness_rows(source, duration, dt, seed, start=0.0):
    """The harness's data: the UR5 moving every joint (tests/robot_rig.py), ``duration`` s from ``start`` at
    ``dt``: its times, the readings (the payload's exact wrench plus the noise), and a builder of each row's
    motion message for ``source`` (the poses with the noise; joint angles and an IMU's rate and specific force
    exact: their noise is estimated by the node). The contact wrench's truth is zero throughout."""
    import robot_rig
    run = robot_rig.ur5_run(duration, dt, start=start)
    rng = np.random.default_rng(seed)
    wrench_sd, angle_sd, position_sd = HARNESS_NOISE
    w_hat = run["W"] + rng.normal(0.0, 1.0, run["W"].shape) * np.asarray(wrench_sd)
    if source == "joints":
        return run["t"], w_hat, joint_state(run["motion"].joints, run["q"])
    if source == "imu":
        quaternion, omega, force, _ = robot_rig.imu_readings(run)
        return run["t"], w_hat, imu_message(quaternion, omega, force)
    pose = run["pose"].copy()
    turn = robot_rig.Rotation.from_rotvec(rng.normal(0.0, angle_sd, (len(pose), 3)))
    q = (robot_rig.Rotation.from_quat(pose[:, [1, 2, 3, 0]]) * turn).as_quat()
    pose[:, :4] = q[:, [3, 0, 1, 2]]
    pose[:, 4:] += rng.normal(0.0, position_sd, (len(pose), 3))

    def build(i, stamp):
        msg = PoseStamped()
        msg.header.stamp = stamp
        msg.header.frame_id = "world"
        o, p = msg.pose.orientation, msg.pose.position
        o.w, o.x, o.y, o.z, p.x, p.y, p.z = (float(v) for v in pose[i])
        return msg
    return run["t"], w_hat, build


def schedule(n, dt, faults, start=0):
    """The emissions of a harness run of rows ``start..n-1`` at ``dt``, with ``faults`` scripted: a list of
    ``(due, stream, row, stamp, publisher)``, in the order they go out (``due`` and ``stamp`` s from the epoch;
    ``stream`` "w" or "m"; ``publisher`` 0, or 1 for a second publisher's).

    Each fault is a dict: ``kind`` (:data:`FAULTS`), ``stream`` (:data:`STREAMS`), ``at`` (s) and as it needs
    ``count`` (rows) or ``seconds``:

    - ``drop``: ``count`` rows not sent;
    - ``pause``: the rows due in ``[at, at + seconds)`` sent at ``at + seconds``, all at once (a stalled network or
      driver that then flushes its queue);
    - ``back``: from ``at`` on, the stamps ``seconds`` earlier (a clock stepped back);
    - ``duplicate``: ``count`` rows sent twice;
    - ``second``: a second publisher sends the log's rows from its start, stamped with its own clock ``seconds``
      behind, for ``count`` rows from ``at`` (a restarted driver beside the old one);
    - ``kill``: the sender killed at ``at`` (a restarted sender, :func:`send_plan` with ``start``, sends the rows
      from ``at + seconds`` on, stamped from when it is up: the stamps jump forward, as a restarted driver's);
    - ``garbage``: ``count`` motion messages the node skips (a pose's quaternion not of unit norm, a NaN joint
      angle or IMU rate);
    - ``glitch``: ``count`` motion messages of their form but off the motion (:func:`glitched`).
    """
    rows = np.arange(start, n)
    base = [(float(i * dt), s, int(i), float(i * dt), 0) for i in rows for s in ("m", "w")]
    out = base
    for f in faults:
        streams = ("w", "m") if f.get("stream", "both") == "both" else (f["stream"],)
        at = int(round(f["at"] / dt))
        kind = f["kind"]
        if kind == "drop":
            out = [e for e in out if not (e[1] in streams and e[4] == 0 and at <= e[2] < at + f["count"])]
        elif kind == "pause":
            end = f["at"] + f["seconds"]
            out = [(end, *e[1:]) if e[1] in streams and f["at"] <= e[0] < end else e for e in out]
        elif kind == "back":
            out = [(e[0], e[1], e[2], e[3] - f["seconds"], e[4]) if e[1] in streams and e[2] >= at and e[4] == 0
                   else e for e in out]
        elif kind == "duplicate":
            out = out + [e for e in out if e[1] in streams and e[4] == 0 and at <= e[2] < at + f["count"]]
        elif kind == "second":
            out = out + [(float((at + j) * dt + 0.3 * dt), s, j, float((at + j) * dt + 0.3 * dt) - f["seconds"], 1)
                         for j in range(f["count"]) for s in streams if at + j < n]
        elif kind in ("garbage", "glitch"):
            mark = "g" if kind == "garbage" else "j"
            out = [(e[0], mark, *e[2:]) if e[1] == "m" and e[4] == 0 and at <= e[2] < at + f["count"] else e
                   for e in out]
    return sorted(out, key=lambda e: (e[0], e[4], e[1] != "m"))


def _publish(pub, msg, tries=20):
    """Publish ``msg``; a publish the middleware refuses (its writer's history full on a loaded machine: rclpy's
    RCLError "cannot publish data") tried again every 5 ms, ``tries`` times; whether it went out. A message that
    never does is a lost one, which the node counts as such."""
    from rclpy.impl.implementation_singleton import rclpy_implementation
    for _ in range(tries):
        try:
            pub.publish(msg)
            return True
        except rclpy_implementation.RCLError:
            time.sleep(0.005)
    return False


def garbled(msg, source):
    """``msg``, a motion message of ``source``, made one the node must skip (a fault ``garbage``): a pose's
    quaternion scaled to norm 1.5 (scaling one component alone leaves the norm within the node's tolerance where
    that component is near zero: a pose turned by up to a degree, not a skipped one), a NaN in an IMU's rate or the
    first joint angle."""
    if source == "pose":
        o = msg.pose.orientation
        o.w, o.x, o.y, o.z = 1.5 * o.w, 1.5 * o.x, 1.5 * o.y, 1.5 * o.z
    elif source == "imu":
        msg.angular_velocity.x = float("nan")
    else:
        msg.position = [float("nan")] + list(msg.position[1:])
    return msg


def glitched(msg, source):
    """``msg``, a motion message of ``source``, made a glitch (a fault ``glitch``): of its form, but off the motion
    (eq. G1 of ``analysis/_compensate.py``): a pose turned by a degree about its x axis (the quaternion's norm kept),
    the first joint angle 0.01 rad off, an IMU's rate 0.5 rad/s off on x."""
    if source == "pose":
        o = msg.pose.orientation
        turned = (Rotation.from_quat([o.x, o.y, o.z, o.w]) * Rotation.from_rotvec([np.radians(1.0), 0, 0])).as_quat()
        o.x, o.y, o.z, o.w = (float(v) for v in turned)
    elif source == "imu":
        msg.angular_velocity.x += 0.5
    else:
        msg.position = [msg.position[0] + 0.01] + list(msg.position[1:])
    return msg


def send_plan(plan):
    """Publish a harness run (``plan``: a dict, :func:`start_sender`'s); returns what was sent, as a dict."""
    import gc
    domain, source = plan["domain"], plan["source"]
    dt = 1.0 / plan["rate"]
    n = int(round(plan["duration"] / dt)) + 1
    start = plan.get("start", 0)
    t, w_hat, build = harness_rows(source, n * dt, dt, plan.get("seed", 0))
    kill = next((f for f in plan.get("faults", ()) if f["kind"] == "kill"), None)
    emissions = schedule(n, dt, plan.get("faults", ()), start)
    if kill is not None and not start:
        emissions = [e for e in emissions if e[0] < kill["at"]]
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node(plan.get("name", "fmscal_harness_sender"), context=context)
    profile = QoSProfile(depth=plan.get("depth", 50000), history=HistoryPolicy.KEEP_LAST,
                         reliability=ReliabilityPolicy.RELIABLE if plan.get("qos", "reliable") == "reliable"
                         else ReliabilityPolicy.BEST_EFFORT)
    message = SOURCES[source][1]
    last_second = {s: max((e[0] for e in emissions if e[4] == 1 and e[1] == s), default=None) for s in ("w", "m")}

    def make_publisher(stream):
        return node.create_publisher(WrenchStamped if stream == "w" else message,
                                     plan.get("wrench_topic", "/ft_sensor/wrench") if stream == "w" else MOTION_TOPIC,
                                     profile)
    pubs = {(s, 0): make_publisher(s) for s in ("w", "m")}
    try:
        end = time.monotonic() + 60
        while not all(p.get_subscription_count() for p in pubs.values()):
            if time.monotonic() > end:
                raise SystemExit("harness sender: no subscriber")
            time.sleep(0.05)
        time.sleep(plan.get("settle", 0.5))
        epoch = round(time.time() + 0.05, 3)
        if start:                                              # a restarted sender: its rows from now on
            emissions = [(e[0] - start * dt, e[1], e[2], e[3] - start * dt, e[4]) for e in emissions]
        begin = epoch - time.time()                           # the schedule's times are the epoch's
        sys.stdout.write(json.dumps({"epoch": epoch}) + "\n")   # said before it may be killed
        sys.stdout.flush()
        sent = {"w": 0, "m": 0, "g": 0, "j": 0}
        failed = 0                                             # publishes the middleware refused (a loaded machine)
        first = emissions[0][2] if emissions else None
        gc.disable()
        lateness = []
        wrench = WrenchStamped()
        wrench.header.frame_id = plan.get("frame_id", "ft_sensor")
        speed = plan.get("speed", 1.0)
        for due, stream, row, stamp_t, publisher in emissions:
            while (wait := epoch + due / speed - time.time()) > 0:
                time.sleep(min(wait, 0.0005))
            lateness.append(-wait)
            kind = "m" if stream in ("g", "j") else stream
            if publisher == 1 and (kind, 1) not in pubs:     # a second driver starts: its publisher discovered
                pubs[kind, 1] = make_publisher(kind)
                while not pubs[kind, 1].get_subscription_count():
                    time.sleep(0.001)
            sec, nanosec = divmod(int(round(epoch * 1e3)) * 1_000_000 + int(round(stamp_t * 1e9)), 1_000_000_000)
            if stream == "w":
                wrench.header.stamp.sec, wrench.header.stamp.nanosec = sec, nanosec
                w = w_hat[row]
                wrench.wrench.torque.x, wrench.wrench.torque.y, wrench.wrench.torque.z = (float(v) for v in w[:3])
                wrench.wrench.force.x, wrench.wrench.force.y, wrench.wrench.force.z = (float(v) for v in w[3:])
                published = _publish(pubs["w", publisher], wrench)
            else:
                stamp = WrenchStamped().header.stamp
                stamp.sec, stamp.nanosec = sec, nanosec
                msg = build(row, stamp)
                if stream == "g":                               # a message the node must skip
                    garbled(msg, source)
                elif stream == "j":                             # a glitch: of its form, off the motion
                    glitched(msg, source)
                published = _publish(pubs["m", publisher], msg)
            if published:
                sent[stream] += 1
            else:
                failed += 1
            if publisher == 1 and due == last_second[kind]:
                node.destroy_publisher(pubs.pop((kind, 1)))     # the second driver gone
            if kill is not None and not start and due >= kill["at"] - dt:
                os.kill(os.getpid(), signal.SIGKILL)           # killed, as a crashing driver is
        gc.enable()
        from rclpy.duration import Duration                     # the last messages delivered before it exits (a
        for pub in pubs.values():                               # loaded node may be seconds behind)
            pub.wait_for_all_acked(Duration(seconds=120))
        time.sleep(0.3)                                         # best effort: no acknowledgement to wait for
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    return {"epoch": epoch, "first_row": first, "sent": sent, "publish_failed": failed, "begin": begin,
            "lateness_p99": float(np.percentile(lateness, 99)) if lateness else 0.0}


def start_sender(plan):
    """The harness's sender (:func:`send_plan`) as a process of its own (``python tests/ros2_rig.py PLAN.json``)."""
    path = tempfile.NamedTemporaryFile("w", suffix=".json", delete=False)
    json.dump(plan, path)
    path.close()
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONPATH=os.pathsep.join(
        [str(Path(__file__).parent), os.environ.get("PYTHONPATH", "")]))
    return subprocess.Popen([sys.executable, __file__, path.name], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)


def sender_result(proc, timeout):
    """The sender's JSON once it is done (where its plan killed it: its epoch, and ``killed``); killed if this
    process is stopped first."""
    try:
        out, err = proc.communicate(timeout=timeout)
    except BaseException:
        proc.kill()
        raise
    lines = [json.loads(line) for line in out.strip().splitlines() if line.startswith("{")]
    if proc.returncode == -signal.SIGKILL:            # killed by its plan: what it said before
        return {**lines[0], "killed": True} if lines else None
    if proc.returncode:
        raise AssertionError(f"the harness sender failed: {err[-2000:]}")
    return lines[-1]


class CpuHog:
    """A busy process beside the node (``while True: pass``), for as long as the ``with`` lasts."""

    def __enter__(self):
        self.proc = subprocess.Popen([sys.executable, "-c", "while True: pass"])
        return self

    def __exit__(self, *exc):
        self.proc.kill()
        self.proc.wait(timeout=5)


def _key(msg):
    """A message's stamp as a key, ``(sec, nanosec)``."""
    return msg.header.stamp.sec, msg.header.stamp.nanosec


def _level(status):
    """A DiagnosticStatus's level as an int (rclpy gives a byte)."""
    return int.from_bytes(status.level, "little") if isinstance(status.level, bytes) else int(status.level)


class Listener:
    """The node's outputs taken by a :class:`Taker` (no executor): the contact wrenches, their covariances and
    flags, the diagnostics."""

    def __init__(self, domain, contact_topic="/ft_sensor/contact", covariance_topic="/ft_sensor/contact_covariance",
                 flags_topic="/ft_sensor/contact_flags", node_name="fmscal_compensator"):
        from diagnostic_msgs.msg import DiagnosticArray as Diagnostics
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node("fmscal_harness_listener", context=self.context)
        self.node_name = node_name
        self.contacts, self.covariances, self.flags, self.diagnostics = [], [], [], []
        deep = QoSProfile(depth=100000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
        self.taker = Taker(self.node, self.context)
        self.contact_sub = self.taker.subscribe(WrenchStamped, contact_topic, lambda m, at: self.contacts.append(m),
                                                deep)
        self.taker.subscribe(Float64MultiArray, covariance_topic, lambda m, at: self.covariances.append(m.data),
                             deep)
        self.taker.subscribe(Diagnostics, flags_topic, lambda m, at: self.flags.append(m), deep)
        self.taker.subscribe(Diagnostics, "/diagnostics", lambda m, at: self.diagnostics.append(m), 1000)
        self.clients = {s: self.node.create_client(Trigger, f"/{node_name}/{s}")
                        for s in ("tare", "tare_force", "identify_payload", "save", "reload", "cancel")}
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.taker.start()

    def wait_for_node(self, proc, timeout=WAIT):
        """Until the node publishes to this process and its diagnostics have come, or it exits."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if proc.poll() is not None:
                raise AssertionError(f"the node exited ({proc.returncode}): {node_log(proc)[-2000:]}")
            if self.contact_sub.get_publisher_count() and self.diagnostics:
                return
            time.sleep(0.05)
        raise AssertionError(f"the node was not discovered in {timeout} s: {node_log(proc)[-2000:]}")

    def wait_for(self, condition, timeout=WAIT):
        """Until ``condition()`` holds (:func:`wait_until`)."""
        return wait_until(condition, timeout)

    def call(self, service, timeout=WAIT):
        """Call a Trigger service of the node; ``(success, message)`` (None where no answer came in time)."""
        return self.answer(self.call_async(service, timeout), timeout)

    def call_async(self, service, timeout=WAIT):
        """A Trigger service of the node called; the future (:meth:`answer` waits for it)."""
        client = self.clients[service]
        assert client.wait_for_service(timeout_sec=timeout), f"~/{service} not found"
        return client.call_async(Trigger.Request())

    def answer(self, future, timeout=WAIT):
        """``(success, message)`` of a call (None where no answer came within ``timeout`` s)."""
        end = time.monotonic() + timeout
        while not future.done() and time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.05)
        if not future.done():
            return None
        return future.result().success, future.result().message

    def status(self, which=0):
        """The newest diagnostics of the node (``which`` 0: its outputs, 1: its inputs) as a dict of values, with
        ``message`` and ``level``."""
        for d in reversed(self.diagnostics):
            if len(d.status) > which and d.status[which].name.startswith(self.node_name + ":"):
                s = d.status[which]
                return {**{k.key: k.value for k in s.values}, "message": s.message, "level": _level(s)}
        return None

    def messages(self, which=0):
        """Every diagnostics message of the node seen so far (``which`` as :meth:`status`)."""
        return [d.status[which].message for d in self.diagnostics
                if len(d.status) > which and d.status[which].name.startswith(self.node_name + ":")]

    def outputs(self, epoch):
        """The outputs so far: ``t`` (s from the epoch), ``wrench`` (fmscal's order), ``sd`` (the covariance's
        diagonal's root, fmscal's order; paired by order, as the node publishes them), ``flagged`` (by stamp)."""
        n = min(len(self.contacts), len(self.covariances))
        t, wrench = contact_array(self.contacts[:n], epoch)
        cov = np.array([np.asarray(c) for c in self.covariances[:n]]).reshape(n, 6, 6)
        sd = np.sqrt(np.diagonal(cov, axis1=1, axis2=2))[:, [3, 4, 5, 0, 1, 2]]      # ROS's force first back
        flagged = self._at_outputs(n, {_key(m): True for m in self.flags if _level(m.status[0]) == 1})
        return t, wrench, sd, flagged

    def contact_flags(self):
        """Whether each output (:meth:`outputs`' order) carried the contact flag (its flags message's ``contact``
        key ``true``; a later message of one stamp wins)."""
        n = min(len(self.contacts), len(self.covariances))
        return self._at_outputs(n, {_key(m): any(v.key == "contact" and v.value == "true" for v in m.status[0].values)
                                    for m in self.flags})

    def _at_outputs(self, n, by_stamp):
        """``by_stamp`` (a flags message's stamp key: bool) read at each of the first ``n`` outputs' stamps (False
        where it has none)."""
        return np.array([by_stamp.get(_key(m), False) for m in self.contacts[:n]], dtype=bool)

    def fates(self, epoch):
        """Each reading's fate by its stamp (s from the epoch, rounded to the microsecond), from the node's flags:
        "" (published), the flags (published, flagged), "withheld: <cause>"; a later message of one stamp wins."""
        return {round(seconds(m.header.stamp) - epoch, 6): m.status[0].message for m in self.flags}

    def close(self):
        self.taker.stop()
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


if __name__ == "__main__":                       # the harness's sender: python tests/ros2_rig.py PLAN.json
    sys.path.insert(0, str(Path(__file__).parent))
    result = send_plan(json.loads(Path(sys.argv[1]).read_text()))
    sys.stdout.write(json.dumps(result) + "\n")
