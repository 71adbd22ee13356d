"""The rclpy node: parameters declared, topics and services wired to :class:`._pipeline.Pipeline`.

rclpy and the message packages are imported by :func:`ros` when the node starts (never when fmscal is
imported): the wheels of the extra ``[ros2]`` (Kilted) or ``[ros2-jazzy]``, or a system ROS 2's rclpy (Humble,
Jazzy) once its setup is sourced.

Threads. The inputs (the wrench, the motion) are subscriptions of a node ``<name>_inputs`` that no executor
spins: a thread of the node's own takes every message queued on both (:meth:`CompensatorNode.poll`, waiting on
rclpy's wait set of the two when both are empty, the interpreter's lock released) and compensates them as one block
(:meth:`fmscal.analysis.Compensator.push_many`). An executor costs a wake-up and a pass of Python per message,
and rclpy's ``MultiThreadedExecutor`` lost 1 kHz messages on a loaded 2-core machine where this way loses none
(docs/guide/robot.md quotes ``benchmarks/ros2_latency.py``). An rclpy without ``take_message`` falls back to its
executor's callbacks. The parameters and the diagnostics' timer are the node's, on a ``SingleThreadedExecutor``
in the main thread. The services live on a node ``<name>_services``, in their own mutually exclusive callback
group on a ``MultiThreadedExecutor`` spun in another thread, and are named under the node's name
(``/fmscal_compensator/tare``): an ``identify_payload`` fit runs beside the inputs, not in front of them; they
share the pipeline through its lock, held for the short steps only (the fit runs outside it).
"""

import array
import gc
import threading
import time
from types import SimpleNamespace

import numpy as np

from fmscal.plant.numerics import FmscalError

from .._motion import ImuMotion, JointMotion, PoseMotion
from ._parameters import NODE_NAME, PARAMETERS, Ros2Error, settings
from ._pipeline import STATES, Pipeline, sensor_pose

__all__ = ["ros", "CompensatorNode", "spin", "INSTALL"]

#: How to get rclpy, as the one-line error says where it is missing.
INSTALL = 'pip install "fmscal[ros2]" (-e ".[ros2]" in a clone), or source a ROS 2 install (Humble, Jazzy)'
#: s between two of one warning in the log.
WARN_EVERY = 2.0
#: The longest wait for an input's message, s (:meth:`CompensatorNode.poll` then sees whether to stop).
WAIT = 0.05
#: s between two looks at the inputs' queues when both were empty, where rclpy has no wait set.
POLL = 0.0003
#: s between two looks at inputs silent for :data:`SILENT` s or more.
IDLE = 0.005
SILENT = 0.1
#: The readings the node's own latency statistic keeps (diagnostics' p50 and p99).
LATENCY_KEPT = 2000


def ros():
    """rclpy and the messages the node uses, imported now; a one-line :class:`Ros2Error` where missing."""
    try:
        import rclpy
        import rclpy.node
        from rclpy.context import Context
        from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
        from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
        from rclpy.parameter import Parameter
        from rclpy.qos import QoSProfile, ReliabilityPolicy, HistoryPolicy, DurabilityPolicy
        from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
        from geometry_msgs.msg import PoseStamped, WrenchStamped
        from sensor_msgs.msg import Imu, JointState
        from std_msgs.msg import Float64MultiArray, MultiArrayDimension
        from std_srvs.srv import Trigger
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    except ImportError as err:
        raise Ros2Error(f"fmscal ros2 needs rclpy and the ROS 2 messages ({err.name or err} not found): "
                        f"{INSTALL}") from None
    try:                                       # rclpy's wait set (private; Humble and later have it)
        from rclpy.impl.implementation_singleton import rclpy_implementation
        WaitSet = rclpy_implementation.WaitSet
    except (ImportError, AttributeError):
        WaitSet = None
    return SimpleNamespace(rclpy=rclpy, Node=rclpy.node.Node, WaitSet=WaitSet, Context=Context,
                           Group=MutuallyExclusiveCallbackGroup,
                           Shutdown=ExternalShutdownException, Executor=MultiThreadedExecutor,
                           Single=SingleThreadedExecutor, Parameter=Parameter,
                           QoSProfile=QoSProfile, Reliability=ReliabilityPolicy, History=HistoryPolicy,
                           Durability=DurabilityPolicy, Descriptor=ParameterDescriptor,
                           SetResult=SetParametersResult, PoseStamped=PoseStamped,
                           WrenchStamped=WrenchStamped, Imu=Imu, JointState=JointState, Array=Float64MultiArray,
                           Dimension=MultiArrayDimension, Trigger=Trigger, DiagnosticArray=DiagnosticArray,
                           DiagnosticStatus=DiagnosticStatus, KeyValue=KeyValue)


_TYPES = {"string": "STRING", "double": "DOUBLE", "integer": "INTEGER", "bool": "BOOL", "double_array": "DOUBLE_ARRAY"}
# a wrench's components by fmscal's names (the planar reading's moment M is about z)
_WRENCH = {"tx": ("torque", "x"), "ty": ("torque", "y"), "tz": ("torque", "z"), "M": ("torque", "z"),
           "fx": ("force", "x"), "fy": ("force", "y"), "fz": ("force", "z")}
# ROS's order of a wrench's covariance: the force first (fx fy fz tx ty tz; planar fx fy tz)
_ROS_ORDER = ("fx", "fy", "fz", "tx", "ty", "tz", "M")


class CompensatorNode:
    """The node ``fmscal_compensator`` (module docstring; the guide, docs/guide/robot.md, lists its topics,
    parameters and services).

    Parameters
    ----------
    r : SimpleNamespace
        :func:`ros`.
    context : rclpy.context.Context
        The context ``rclpy.init`` made of the command line's ``--ros-args``.
    """

    def __init__(self, r, context):
        self.r = r
        self.node = r.Node(NODE_NAME, context=context)
        self.log = self.node.get_logger()
        self.settings = settings(self._declare())
        self.node.add_on_set_parameters_callback(self._refuse_changes)
        motion = self._motion()
        self.pipeline = Pipeline(self.settings, motion)
        model = self.pipeline.model
        self.names = tuple(model.wrench_names)
        self.pose_names = tuple(model.pose_names)
        order = [self.names.index(n) for n in _ROS_ORDER if n in self.names]
        self._cov_index = np.ix_(order, order)
        self._fields = [_WRENCH[n] for n in self.names]
        self._contact_msg = r.WrenchStamped()
        self._cov_msg = r.Array()
        n = len(order)
        self._cov_msg.layout.dim = [r.Dimension(label=" ".join(self.names[i] for i in order), size=n, stride=n * n),
                                    r.Dimension(label="column", size=n, stride=n)]
        self._epoch = None
        self._last_warned = {}
        self._latencies = []
        self._entered = time.monotonic()
        s = self.settings
        services = r.Group()
        depth = int(s.queue_depth)
        qos_in = r.QoSProfile(depth=depth, history=r.History.KEEP_LAST,
                              reliability=r.Reliability.BEST_EFFORT if s.qos == "sensor_data"
                              else r.Reliability.RELIABLE)
        qos_out = r.QoSProfile(depth=depth, history=r.History.KEEP_LAST, reliability=r.Reliability.RELIABLE)
        self.contact_pub = self.node.create_publisher(r.WrenchStamped, s.contact_topic, qos_out)
        self.cov_pub = self.node.create_publisher(r.Array, s.covariance_topic, qos_out)
        self.diag_pub = self.node.create_publisher(r.DiagnosticArray, "/diagnostics", 10)
        self.latency_pub = self.node.create_publisher(r.Array, "~/latency", qos_out) if s.debug_latency else None
        # the inputs on a node of their own, not spun by an executor: a thread takes their messages (poll). The
        # helper nodes take none of the command line's arguments (a node's name remapped would rename them
        # too): their topics are this node's, resolved with its remappings
        helper = dict(namespace=self.node.get_namespace(), context=context, start_parameter_services=False,
                      use_global_arguments=False)
        self.inputs = r.Node(f"{self.node.get_name()}_inputs", **helper)
        self._wrench_sub = self.inputs.create_subscription(r.WrenchStamped, self._resolve(s.wrench_topic),
                                                           self._on_wrench, qos_in)
        message, self._motion_message = {PoseMotion: (r.PoseStamped, self._pose),
                                         JointMotion: (r.JointState, self._joints),
                                         ImuMotion: (r.Imu, self._imu)}[type(motion)]
        self._motion_sub = self.inputs.create_subscription(message, self._resolve(s.topic), self._on_motion, qos_in)
        self.error = None
        # the services on a node of their own, spun by its own executor in another thread, named under this
        # node's name: a fit never waits for the inputs' executor, nor the inputs for it
        self.services = r.Node(f"{self.node.get_name()}_services", **helper)
        base = self.node.get_fully_qualified_name()
        for name, work in (("tare", self.pipeline.tare), ("tare_force", self.pipeline.tare_force),
                           ("identify_payload", self.pipeline.identify), ("save", self.pipeline.save),
                           ("reload", self.pipeline.reload)):
            self.services.create_service(r.Trigger, f"{base}/{name}", self._service(name, work),
                                         callback_group=services)
        self.node.create_timer(s.diagnostics_period, self._diagnose)
        self.log.info(f"compensating {self._wrench_sub.topic_name} with the motion of "
                      f"{self._motion_sub.topic_name} into {self.contact_pub.topic_name} "
                      f"(the wrench {'on the tool' if s.direction == 'on_tool' else 'on the environment'}, "
                      f"{s.output_frame} frame); calibration {s.calibration}")
        for warning in self.pipeline.warnings:
            self.log.warning(warning)

    # --- parameters ------------------------------------------------------------------------------------------
    def _declare(self):
        """Declare every parameter of :data:`PARAMETERS`; their values (None: an optional one unset)."""
        r, values = self.r, {}
        for p in PARAMETERS:
            descriptor = r.Descriptor(description=p.description)
            try:
                if p.default is None:
                    self.node.declare_parameter(p.name, getattr(r.Parameter.Type, _TYPES[p.type]), descriptor)
                else:
                    self.node.declare_parameter(p.name, p.default, descriptor)
                parameter = self.node.get_parameter(p.name)
                values[p.name] = None if parameter.type_ == r.Parameter.Type.NOT_SET else parameter.value
            except FmscalError:
                raise
            except Exception as err:
                if type(err).__name__ == "ParameterUninitializedException":
                    values[p.name] = None
                    continue
                message = str(err).splitlines()[0] if str(err) else type(err).__name__
                raise Ros2Error(f"parameter {p.name} ({p.type}{', e.g. 1.0 not 1' if 'double' in p.type else ''}): "
                                f"{message}") from None
        return values

    def _resolve(self, topic):
        """``topic`` as this node resolves it: its namespace and the command line's remappings applied."""
        resolve = getattr(self.node, "resolve_topic_name", None)
        return topic if resolve is None else resolve(topic)

    def _refuse_changes(self, parameters):
        """Parameters are read once, at start: a change later (``ros2 param set``) is refused, saying so."""
        names = ", ".join(p.name for p in parameters)
        return self.r.SetResult(successful=False, reason=f"{NODE_NAME} reads its parameters at start: restart it "
                                f"to change {names} (~/reload reads the calibration file again)")

    def _motion(self):
        """The motion's source the parameters name (its stamps are aligned by the pipeline: no latency here)."""
        s = self.settings
        if s.source == "pose_topic":
            return PoseMotion()
        if s.source == "joint_states_topic":
            return JointMotion(s.urdf, s.frame)
        return ImuMotion(rotation=s.imu_rotation, lever_arm=s.imu_lever_arm)

    # --- inputs ----------------------------------------------------------------------------------------------
    def _time(self, stamp):
        """A stamp in s from the first stamp's second (a float keeps its nanoseconds)."""
        if self._epoch is None:
            self._epoch = stamp.sec
        return (stamp.sec - self._epoch) + stamp.nanosec * 1e-9

    @staticmethod
    def _queued(sub):
        """The messages waiting on a subscription, taken now (the executor hands one per callback: the rest of a
        backlog is taken in the same callback and compensated as one block)."""
        handle, out = getattr(sub, "handle", None), []
        if handle is None or not hasattr(handle, "take_message"):
            return out
        with handle:
            while (taken := handle.take_message(sub.msg_type, sub.raw)) is not None:
                out.append(taken[0])
        return out

    def pollable(self):
        """Whether this rclpy lets :meth:`poll` take messages (else the inputs' node is spun by an executor)."""
        return hasattr(getattr(self._wrench_sub, "handle", None), "take_message")

    def _waiter(self, context):
        """A function waiting until a message is queued on either input (at most :data:`WAIT` s), the
        interpreter's lock released meanwhile: rclpy's wait set on the two subscriptions; None where this rclpy
        has none (:meth:`poll` then looks again after :data:`POLL` s)."""
        if self.r.WaitSet is None:
            return None
        try:
            wait_set = self.r.WaitSet(2, 0, 0, 0, 0, 0, context.handle)
            handles = (self._motion_sub.handle, self._wrench_sub.handle)
        except Exception:
            return None
        timeout = int(WAIT * 1e9)

        def wait():
            with context.handle:
                wait_set.clear_entities()
                for handle in handles:
                    wait_set.add_subscription(handle)
                wait_set.wait(timeout)
        return wait

    def poll(self, context):
        """Take the inputs' messages as they come, until the context shuts down: all the queued ones of both
        inputs, compensated as one block; where there were none, wait for the next (:meth:`_waiter`; without a
        wait set, look again after :data:`POLL` s, :data:`IDLE` s once the inputs have been silent for
        :data:`SILENT` s). An exception stops the node (:attr:`error`)."""
        last = time.monotonic()
        wait = self._waiter(context)
        try:
            while context.ok():
                motions, readings = self._queued(self._motion_sub), self._queued(self._wrench_sub)
                if not (motions or readings):
                    if wait is not None:
                        wait()
                    else:                                # inputs silent for long: looked at less often
                        time.sleep(POLL if time.monotonic() - last < SILENT else IDLE)
                    continue
                last = time.monotonic()
                self._entered = time.monotonic()
                for m in motions:
                    self._motion_message(m)
                for m in readings:
                    self._reading(m)
                self._process()
        except Exception as err:                     # said by spin, in one line for FmscalError
            if context.ok():
                self.error = err
                self.r.rclpy.try_shutdown(context=context)

    def _on_wrench(self, msg):
        self._entered = time.monotonic()
        for m in self._queued(self._motion_sub):
            self._motion_message(m)
        for m in [msg, *self._queued(self._wrench_sub)]:
            self._reading(m)
        self._process()

    def _on_motion(self, msg):
        self._entered = time.monotonic()
        for m in [msg, *self._queued(self._motion_sub)]:
            self._motion_message(m)
        self._process()

    def _reading(self, msg):
        w = np.array([getattr(getattr(msg.wrench, part), axis) for part, axis in self._fields])
        if not np.isfinite(w).all():
            self._warn("reading", "a wrench with a NaN or infinite component: skipped")
            return
        self.pipeline.add_reading(self._time(msg.header.stamp), w, msg.header.stamp, msg.header.frame_id)

    def _process(self):
        """Compensate what the motion covers; publish it; warn of a stale motion or a saturated reading."""
        for out in self.pipeline.process():
            self._publish(out)
        if self.pipeline.stale:
            self._warn("stale", f"motion stale: {self.settings.topic} has no sample within "
                                f"{self.settings.stale_timeout:g} s of the readings' stamps; no output until it "
                                "covers the filter's window again")
        if self.pipeline.state() == STATES[3]:
            self._warn("saturated", "a reading at or beyond the saturation parameter: its output withheld")

    def _pose(self, msg):
        p, o = msg.pose.position, msg.pose.orientation
        q = np.array([o.w, o.x, o.y, o.z])
        position = np.array([p.x, p.y, p.z])
        q, position = sensor_pose(q, position, self.settings.pose_to_sensor)
        norm = np.linalg.norm(q)
        if not (np.isfinite(norm) and abs(norm - 1) < 1e-3 and np.isfinite(position).all()):
            self._warn("pose", f"a pose whose quaternion is not of unit norm ({norm:.4g}): skipped")
            return
        q = q / norm
        values = {"qw": q[0], "qx": q[1], "qy": q[2], "qz": q[3], "x": position[0], "y": position[1],
                  "z": position[2], "theta": 2 * np.arctan2(q[3], q[0])}
        self.pipeline.add_motion(self._time(msg.header.stamp), np.array([values[n] for n in self.pose_names]),
                                 msg.header.frame_id)

    def _joints(self, msg):
        order = self.pipeline.motion.joints
        where = {name: i for i, name in enumerate(msg.name)}
        missing = [n for n in order if n not in where]
        if missing or len(msg.position) != len(msg.name):
            self._warn("joints", f"a joint state without {', '.join(missing[:3]) or 'a position per name'}: skipped")
            return
        index = [where[n] for n in order]
        q = np.asarray(msg.position, dtype=float)[index]
        if not np.isfinite(q).all():
            self._warn("joints", "a joint state with a NaN or infinite position: skipped")
            return
        dq = np.asarray(msg.velocity, dtype=float)[index] if len(msg.velocity) == len(msg.name) else None
        if dq is not None and not np.isfinite(dq).all():
            dq = None                                  # differentiated from the positions instead
        self.pipeline.add_motion(self._time(msg.header.stamp), (q, dq, None), msg.header.frame_id)

    def _imu(self, msg):
        o, w, a = msg.orientation, msg.angular_velocity, msg.linear_acceleration
        quaternion = None if msg.orientation_covariance[0] == -1 else np.array([o.w, o.x, o.y, o.z])
        rate, force = np.array([w.x, w.y, w.z]), np.array([a.x, a.y, a.z])
        if not (np.isfinite(rate).all() and np.isfinite(force).all()):
            self._warn("imu", "an IMU sample with a NaN or infinite rate or acceleration: skipped")
            return
        if quaternion is not None:
            norm = np.linalg.norm(quaternion)
            quaternion = quaternion / norm if np.isfinite(norm) and abs(norm - 1) < 1e-3 else None
        if quaternion is None and self.settings.output_frame == "base":
            self._warn("imu", "an IMU sample without a unit orientation: skipped (output_frame base needs it)")
            return
        self.pipeline.add_motion(self._time(msg.header.stamp), (quaternion, rate, force),
                                 msg.header.frame_id)

    # --- outputs ---------------------------------------------------------------------------------------------
    def _publish(self, out):
        """The contact wrench (the reading's stamp and frame), its covariance, and the debug latency."""
        msg, sample = self._contact_msg, out.sample
        msg.header.stamp = out.stamp
        msg.header.frame_id = out.frame_id
        for (part, axis), value in zip(self._fields, sample.wrench.tolist()):
            setattr(getattr(msg.wrench, part), axis, value)
        self.contact_pub.publish(msg)
        cov = self._cov_msg
        cov.data = array.array("d", sample.cov[self._cov_index].tobytes())
        self.cov_pub.publish(cov)
        self.pipeline.counts["published"] += 1
        since = time.time() - (out.stamp.sec + out.stamp.nanosec * 1e-9)
        self._latencies.append(since)
        if len(self._latencies) > LATENCY_KEPT:
            del self._latencies[:LATENCY_KEPT // 2]
        if self.latency_pub is not None:
            debug = self.r.Array()
            debug.data = [since, time.monotonic() - self._entered, float(self.pipeline.backlog())]
            self.latency_pub.publish(debug)

    def _warn(self, key, message):
        """A warning in the log, at most one of a kind every :data:`WARN_EVERY` s."""
        now = time.monotonic()
        if now - self._last_warned.get(key, -np.inf) >= WARN_EVERY:
            self._last_warned[key] = now
            self.log.warning(message)

    def _service(self, name, work):
        def serve(request, response):
            try:
                response.success, response.message = work()
            except Exception as err:                   # a bug, said in the answer and the log, the node kept up
                response.success = False
                first = str(err).splitlines()[0] if str(err) else ""
                response.message = f"{name} failed: {type(err).__name__}: {first}"
            if response.success:            # (rclpy refuses two severities from one line)
                self.log.info(f"~/{name}: {response.message}")
            else:
                self.log.warning(f"~/{name}: {response.message}")
            return response
        return serve

    def _diagnose(self):
        """The diagnostics: the state, the offset and its sd, the contact flag, the delays, the counts."""
        r, p = self.r, self.pipeline
        state = p.state()
        status = r.DiagnosticStatus()
        status.level = {STATES[0]: r.DiagnosticStatus.WARN, STATES[1]: r.DiagnosticStatus.OK,
                        STATES[2]: r.DiagnosticStatus.ERROR, STATES[3]: r.DiagnosticStatus.WARN}[state]
        status.name = f"{self.node.get_name()}: contact wrench"
        status.message = state
        status.hardware_id = self.settings.wrench_topic
        sample = p.last_sample
        offset = None if p.compensator is None else p.compensator.offset
        sd = None if sample is None or sample.offset_sd is None else sample.offset_sd
        kept = np.array(self._latencies[-LATENCY_KEPT:]) if self._latencies else None
        values = {"state": state, "contact": str(bool(p.contact)).lower(),
                  "offset": "" if offset is None else " ".join(f"{v:.6g}" for v in offset),
                  "offset_sd": "" if sd is None else " ".join(f"{v:.3g}" for v in sd),
                  "channels": " ".join(self.names),
                  "delay_s": "" if p.delay is None else f"{p.delay:g}", "latency_s": f"{p.latency:g}",
                  "stamp_to_output_p50_s": "" if kept is None else f"{np.percentile(kept, 50):.6f}",
                  "stamp_to_output_p99_s": "" if kept is None else f"{np.percentile(kept, 99):.6f}",
                  "backlog": str(p.backlog()), **{k: str(v) for k, v in p.counts.items()}}
        status.values = [r.KeyValue(key=k, value=v) for k, v in values.items()]
        array = r.DiagnosticArray()
        array.header.stamp = self.node.get_clock().now().to_msg()
        array.status = [status]
        self.diag_pub.publish(array)


def spin(args):
    """Run the node until it is interrupted: ``args`` the ROS arguments (``--ros-args ...``).

    Raises
    ------
    Ros2Error
        rclpy missing, an argument rclpy does not take, a parameter missing or bad (one line naming it).
    """
    r = ros()
    context = r.Context()
    try:
        r.rclpy.init(args=["fmscal", *args], context=context)
    except Exception as err:
        raise Ros2Error(f"the ROS arguments were refused: {str(err).splitlines()[0] if str(err) else err}") from None
    node = None
    try:
        node = CompensatorNode(r, context)
        executor = r.Single(context=context)
        executor.add_node(node.node)
        services = r.Executor(num_threads=2, context=context)
        services.add_node(node.services)
        threads = [threading.Thread(target=_spin_services, args=(r, services), daemon=True)]
        if node.pollable():
            threads.append(threading.Thread(target=node.poll, args=(context,), daemon=True))
        else:                                        # an rclpy without take_message: its executor takes them
            executor.add_node(node.inputs)
        # everything built so far (the imports, the warmed-up compensator) out of the collector's way: a full
        # collection over it would pause the compensation for tens of milliseconds
        gc.collect()
        gc.freeze()
        for thread in threads:
            thread.start()
        try:
            executor.spin()
        except (KeyboardInterrupt, r.Shutdown):
            pass
        # the other threads stopped before their nodes are destroyed (else a C++ abort at exit)
        r.rclpy.try_shutdown(context=context)
        services.shutdown(timeout_sec=2.0)
        for thread in threads:
            thread.join(timeout=2.0)
        if node.error is not None:
            raise node.error
    finally:
        if node is not None:
            for n in (node.services, node.inputs, node.node):
                n.destroy_node()
        r.rclpy.try_shutdown(context=context)


def _spin_services(r, executor):
    """The services' executor, until the context shuts down."""
    try:
        executor.spin()
    except (KeyboardInterrupt, r.Shutdown):
        pass
