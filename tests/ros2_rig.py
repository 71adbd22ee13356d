"""The ROS 2 tests' and benchmark's rig: the node started as a subprocess (``python -m fmscal.analysis.cli ros2``)
and a publisher and subscriber in this process, over real DDS on loopback.

Each test runs in its own ROS domain (:func:`domain_id`: from the xdist worker and the test's name) with
discovery kept to this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``), so that no two tests hear each
other. Every wait is bounded, and the node is stopped by its process id in a ``finally``.
"""

import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
import zlib
from contextlib import contextmanager

import numpy as np
import rclpy
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


def domain_id(name):
    """A ROS domain for one test: from the xdist worker (gw0, gw1, ...) and the test's name, in 1-100."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    w = int("".join(c for c in worker if c.isdigit()) or 0)
    return 1 + (w * 29 + zlib.crc32(name.encode())) % 100


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
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5)
        if log is not None:
            log.close()


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
                 node_name="fmscal_compensator", motion=PoseStamped, covariance=True):
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
        self.node.create_subscription(Float64MultiArray, f"/{node_name}/latency",
                                      lambda m: self.latencies.append(list(m.data)), RELIABLE)
        self.clients = {s: self.node.create_client(Trigger, f"/{node_name}/{s}")
                        for s in ("tare", "tare_force", "identify_payload", "save", "reload")}
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
        """Until ``condition()`` holds; its last value."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if condition():
                return True
            time.sleep(0.02)
        return False

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
