"""The rclpy node: parameters declared, topics and services wired to :class:`._pipeline.Pipeline`.

rclpy and the message packages are imported by :func:`ros` when the node starts (never when fmscal is
imported): the wheels of the extra ``[ros2]`` (Kilted) or ``[ros2-jazzy]``, or a system ROS 2's rclpy (Humble,
Jazzy) once its setup is sourced.

Threads. The inputs (the wrench, the motion) are subscriptions of a node ``<name>_inputs`` that no executor
spins: a thread of the node's own takes every message queued on both (:meth:`CompensatorNode.poll`, waiting on
rclpy's wait set of the two when both are empty, the interpreter's lock released), hands them to the pipeline in
the order the middleware received them (each reading after the motion received before it, however long the take
of either queue took) and compensates them as one block (:meth:`fmscal.analysis.Compensator.push_many`). An
executor costs a wake-up and a pass of Python per message, and rclpy's ``MultiThreadedExecutor`` lost 1 kHz
messages on a loaded 2-core machine where this way loses none (docs/guide/robot.md quotes
``benchmarks/ros2_latency.py``). An rclpy without ``take_message`` falls back to its executor's callbacks. The
parameters, the diagnostics' timer and a timer looking at the inputs' QoS events (their handlers stay with the
inputs' node, which is not spun: :meth:`CompensatorNode.take_events`) are the node's, on a
``SingleThreadedExecutor`` in the main thread; the diagnostics read the
pipeline's snapshot, never its lock, so that a compensation that stalls is said, not silenced. The services live
on a node ``<name>_services``, on a ``MultiThreadedExecutor`` spun in another thread, and are named under the
node's name (``/fmscal_compensator/tare``); ``~/identify_payload``'s fit runs in a process of its own
(:mod:`._worker`), which ``~/cancel`` or the node's stopping kills.

Never a crash on an input. Whatever the messages (any order, loss, pause, duplicate, jump or restart of either
stream), the poll thread goes on: an exception while compensating is logged with its traceback once, the
pipeline's window restarted (the readings it held counted as ``error``), and the node keeps running.
"""

import contextlib
import difflib
import faulthandler
import fnmatch
import gc
import heapq
import math
import signal
import socket
import threading
import time
import traceback
from collections import deque
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from fmscal.plant.numerics import FmscalError

from .._export import ros2_control_parameters
from .._motion import ImuMotion, JointMotion, PoseMotion
from ._parameters import NODE_NAME, PARAMETERS, Ros2Error, settings
from ._cdr import Template, decoder, plain
from ._rclpy import ros
from ._pipeline import FLAGS, LEVELS, Pipeline, motion_source, sensor_pose, state_of
from ._push import push_parameters, pushed_line
from ._worker import Cancelled, Worker

__all__ = ["CompensatorNode", "spin", "unknown_parameters"]

#: s between two of one warning in the log.
WARN_EVERY = 2.0
#: The longest wait for an input's message, s (:meth:`CompensatorNode.poll` then sees whether to stop).
WAIT = 0.05
#: s: the longest the main executor waits before it looks whether a SIGINT or SIGTERM asked the node to stop
STOP_LOOK = 0.1
#: s between two looks at the inputs' queues when both were empty, where rclpy has no wait set.
POLL = 0.0003
#: s between two looks at inputs silent for :data:`SILENT` s or more.
IDLE = 0.005
SILENT = 0.1
#: s between two looks at the inputs' QoS events (:meth:`CompensatorNode.take_events`).
EVENTS = 0.1
#: The readings the node's own latency statistic keeps (diagnostics' p50 and p99).
LATENCY_KEPT = 2000
#: s beyond its usual lag an output may come (or a compensation pass may run) before the node is "behind".
BEHIND = 0.25
#: The parameters rclpy declares on every node (not the node's to refuse).
RCLPY_PARAMETERS = ("use_sim_time", "start_type_description_service")


_TYPES = {"string": "STRING", "double": "DOUBLE", "integer": "INTEGER", "bool": "BOOL", "double_array": "DOUBLE_ARRAY"}
# ROS's order of a wrench's covariance: the force first (fx fy fz tx ty tz; planar fx fy tz)
_ROS_ORDER = ("fx", "fy", "fz", "tx", "ty", "tz", "M")
# a pose's values as the node makes them from a PoseStamped, which the model's pose names pick from
_POSE_ORDER = ("qw", "qx", "qy", "qz", "x", "y", "z", "theta")
# a wrench component's place among a WrenchStamped's six numbers (force x y z, torque x y z; the planar reading's
# moment M is about z)
_ROS_PLACE = {"fx": 0, "fy": 1, "fz": 2, "tx": 3, "ty": 4, "tz": 5, "M": 5}


def _flat(section, prefix=""):
    """A params file's ``ros__parameters`` as dotted names (nested maps are dotted, as rclpy reads them)."""
    out = []
    for key, value in (section or {}).items():
        name = f"{prefix}{key}"
        out += _flat(value, name + ".") if isinstance(value, dict) else [name]
    return out


def unknown_parameters(args, node_name, known):
    """The parameters given to this node that it does not have: ``(errors, warnings)``, one line each naming the
    closest known name.

    ``args`` the ROS arguments (``-p``/``--param name:=value``, ``--params-file FILE``); ``node_name`` the node's
    fully qualified name. A ``-p`` is this node's (its helpers take no command-line arguments), as is a params
    file's section whose key is its name; a section whose key is a wildcard (``/**``, ``/**/fmscal_*``) holds other
    nodes' parameters too: a warning there.
    """
    import yaml
    known = set(known)
    errors, warnings = [], []

    def closest(name):
        match = difflib.get_close_matches(name, sorted(known), n=1, cutoff=0.6)
        return f": did you mean {match[0]}?" if match else f" (docs/guide/robot.md lists {node_name}'s parameters)"
    short = node_name.rsplit("/", 1)[-1]
    args = list(args)
    for i, arg in enumerate(args[:-1]):
        if arg in ("-p", "--param"):
            name = args[i + 1].split(":=", 1)[0]
            if name not in known:
                errors.append(f"parameter {name} (-p on the command line) is not one of {short}'s{closest(name)}")
        elif arg == "--params-file":
            path = Path(args[i + 1])
            try:
                content = yaml.safe_load(path.read_text()) or {}
            except (OSError, yaml.YAMLError):
                continue                               # rclpy says what is wrong with the file itself
            for key, section in (content.items() if isinstance(content, dict) else ()):
                if not isinstance(section, dict):
                    continue
                key = str(key)
                full = key if key.startswith("/") else "/" + key
                wildcard = "*" in key
                if not (full == node_name or key == short or
                        wildcard and fnmatch.fnmatch(node_name, full.replace("/**", "*"))):
                    continue
                for name in _flat(section.get("ros__parameters")):
                    if name in known:
                        continue
                    line = f"parameter {name} ({path.name}, section {key}) is not one of {short}'s{closest(name)}"
                    (warnings if wildcard else errors).append(line)
    return errors, warnings


class CompensatorNode:
    """The node ``fmscal_compensator`` (module docstring; the guide, docs/guide/robot.md, lists its topics,
    parameters and services).

    Parameters
    ----------
    r : SimpleNamespace
        :func:`ros`.
    context : rclpy.context.Context
        The context ``rclpy.init`` made of the command line's ``--ros-args``.
    args : sequence of str
        Those arguments (the parameters given are checked against the node's: :func:`unknown_parameters`).
    """

    def __init__(self, r, context, args=()):
        self.r = r
        self.node = r.Node(NODE_NAME, context=context)
        self.log = self.node.get_logger()
        self._last_warned, self._warned_count = {}, {}
        builtin = set(self.node._parameters) if hasattr(self.node, "_parameters") else set(RCLPY_PARAMETERS)
        errors, warnings = unknown_parameters(args, self.node.get_fully_qualified_name(),
                                              {p.name for p in PARAMETERS} | builtin | set(RCLPY_PARAMETERS))
        if errors:
            raise Ros2Error(errors[0] + (f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""))
        for line in warnings:
            self.log.warning(line + " (a wildcard section: left alone)")
        self.settings = settings(self._declare())
        self.node.add_on_set_parameters_callback(self._refuse_changes)
        motion = motion_source(self.settings)
        self.pipeline = Pipeline(self.settings, motion)
        model = self.pipeline.model
        self.names = tuple(model.wrench_names)
        self.pose_names = tuple(model.pose_names)
        self._pose_index = np.array([_POSE_ORDER.index(n) for n in self.pose_names])
        order = [self.names.index(n) for n in _ROS_ORDER if n in self.names]
        self._cov_index = np.ix_(order, order)
        # a reading's values (a wrench's six, force then torque) in the model's order, and back
        self._from_ros = np.array([_ROS_PLACE[n] for n in self.names])
        n = len(order)
        self._encode = self._templates(r, n, " ".join(self.names[i] for i in order))
        self._epoch = None
        self._latencies = deque(maxlen=LATENCY_KEPT)
        self._held_for = None                         # (s from the newest output's reading's reception, when)
        self._late_most = 0.0                         # the longest such since the diagnostics last looked
        self._pass_start, self._pass_size = None, 0
        self._seen, self._latched = None, []           # the transient states' counts, those not said yet
        self._name_said = None                         # the name clash seen in the graph, said in the log
        self._pending = {}                             # conditions set from the main thread, the lock then held
        self._entered = time.monotonic()
        self.error = None
        self.stopping = threading.Event()
        self.worker = Worker()
        s = self.settings
        depth = int(s.queue_depth)
        self._reliable = s.qos != "sensor_data"
        qos_in = r.QoSProfile(depth=depth, history=r.History.KEEP_LAST,
                              reliability=r.Reliability.RELIABLE if self._reliable else r.Reliability.BEST_EFFORT)
        qos_out = r.QoSProfile(depth=depth, history=r.History.KEEP_LAST, reliability=r.Reliability.RELIABLE)
        self.contact_pub = self.node.create_publisher(r.WrenchStamped, s.contact_topic, qos_out)
        self.cov_pub = self.node.create_publisher(r.Array, s.covariance_topic, qos_out)
        self.flag_pub = self.node.create_publisher(r.DiagnosticArray, s.flags_topic, qos_out)
        self.diag_pub = self.node.create_publisher(r.DiagnosticArray, "/diagnostics", 10)
        self.latency_pub = self.node.create_publisher(r.Array, "~/latency", qos_out) if s.debug_latency else None
        # the inputs on a node of their own, not spun by an executor: a thread takes their messages (poll). The
        # helper nodes take none of the command line's arguments (a node's name remapped would rename them
        # too): their topics are this node's, resolved with its remappings
        helper = dict(namespace=self.node.get_namespace(), context=context, start_parameter_services=False,
                      use_global_arguments=False)
        self.inputs = r.Node(f"{self.node.get_name()}_inputs", **helper)
        message, self._motion_kind, self._motion_values = {
            PoseMotion: (r.PoseStamped, "pose", self._pose), JointMotion: (r.JointState, "joints", self._joints),
            ImuMotion: (r.Imu, "imu", self._imu)}[type(motion)]
        self._decode = (decoder(self._motion_kind, message, r.deserialize),
                        decoder("wrench", r.WrenchStamped, r.deserialize))
        self._kinds, self._raw = (self._motion_kind, "wrench"), [True, True]    # motion, wrench: taken as bytes?
        self._events = []                              # the inputs' QoS event handlers (take_events)
        self._wrench_sub = self._subscribe(r.WrenchStamped, s.wrench_topic, self._on_wrench, qos_in)
        self._motion_sub = self._subscribe(message, s.topic, self._on_motion, qos_in)
        # the services on a node of their own, spun by its own executor in another thread, named under this
        # node's name: a fit never waits for the inputs, nor the inputs for it; ~/cancel in a group of its own
        self.services = r.Node(f"{self.node.get_name()}_services", **helper)
        base = self.node.get_fully_qualified_name()
        work, cancel = r.Group(), r.Group()
        for name, call in (("tare", self.pipeline.tare), ("tare_force", self.pipeline.tare_force),
                           ("identify_payload", self._identify), ("reidentify", self._reidentify),
                           ("save", self.pipeline.save), ("push", self._push),
                           ("reload", self.pipeline.reload)):
            self.services.create_service(r.Trigger, f"{base}/{name}", self._service(name, call), callback_group=work)
        self.services.create_service(r.Trigger, f"{base}/cancel", self._service("cancel", self._cancel),
                                     callback_group=cancel)
        self.node.create_timer(s.diagnostics_period, self._diagnose)
        self.log.info(f"compensating {self._wrench_sub.topic_name} with the motion of "
                      f"{self._motion_sub.topic_name} into {self.contact_pub.topic_name} "
                      f"(the wrench {'on the tool' if s.direction == 'on_tool' else 'on the environment'}, "
                      f"{s.output_frame} frame; flags on {self.flag_pub.topic_name}); {self.pipeline.source}")
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

    # --- the inputs' subscriptions and their events -------------------------------------------------------------
    def _subscribe(self, message, topic, callback, qos):
        """A subscription of the inputs' node, its QoS events (an incompatible publisher, the publishers matched,
        messages lost) kept for :meth:`take_events` (the inputs' node is not spun where :meth:`poll` takes the
        messages)."""
        r, topic = self.r, self._resolve(topic)
        events = None
        if r.Events is not None:
            events = r.Events(incompatible_qos=lambda info: self._incompatible(topic, info),
                              matched=lambda info: self._matched(topic, info),
                              message_lost=lambda info: self._message_lost(topic, info))
        try:
            sub = self.inputs.create_subscription(message, topic, callback, qos, event_callbacks=events)
        except Exception:                          # an rmw without one of these events
            sub = self.inputs.create_subscription(message, topic, callback, qos)
        self._events.extend(getattr(sub, "event_handlers", ()))
        return sub

    def take_events(self, context):
        """The inputs' QoS events taken and handled, each :data:`EVENTS` s (a timer of this node's executor): a
        wait set looked at without waiting, not an executor waiting on the events. A middleware may wake a wait
        set holding a subscription's events at each of its messages (Fast DDS does): an executor would then
        rebuild its wait set in Python at each message, holding the interpreter's lock the compensation needs.
        An error while taking them is said, never fatal. Where this rclpy has no wait set, they are not taken,
        said at start."""
        if not self._events:
            return
        if self.r.WaitSet is None:
            self.log.warning("this rclpy has no wait set: the inputs' QoS events (an incompatible publisher, "
                             "messages lost) are not watched")
            return
        wait_set = self.r.WaitSet(0, 0, 0, 0, 0, len(self._events), context.handle)

        def take():
            try:
                with contextlib.ExitStack() as held:
                    held.enter_context(context.handle)
                    for handler in self._events:
                        held.enter_context(handler)
                    wait_set.clear_entities()
                    for handler in self._events:
                        handler.add_to_wait_set(wait_set)
                    wait_set.wait(0)
                    taken = [(h, h.take_data()) for h in self._events if h.is_ready(wait_set)]
                for handler, data in taken:
                    if data:
                        handler.callback(data)
                self._set_pending()
            except Exception as err:                   # said, never fatal
                self._warn("event", f"the inputs' QoS events not taken ({type(err).__name__}: {err})")
        self.node.create_timer(EVENTS, take)

    def _incompatible(self, topic, info):
        policy = getattr(info, "last_policy_kind", None)
        name = self.r.policy_name(policy) if self.r.policy_name is not None and policy is not None else "a policy"
        want = "reliable" if self._reliable else "sensor_data (best effort)"
        hint = " (a best-effort publisher: set qos: sensor_data)" if "RELIAB" in str(name).upper() and \
            self._reliable else ""
        message = (f"a publisher of {topic} offers a QoS this node's subscription ({want}) cannot take: {name} "
                   f"incompatible{hint}; none of its messages arrive")
        self._set_condition(f"qos {topic}", message)           # an event, taken in the main thread
        self._warn(f"qos {topic}", message)

    def _matched(self, topic, info):
        count = getattr(info, "current_count", None)
        if count is not None and count > 1:            # an event, in the main thread: the poll thread's next
            self._publishers(topic, count, wait=False)  # pass counts them where a pass holds the lock now

    def _message_lost(self, topic, info):
        self._warn(f"lost {topic}", f"{topic}: {getattr(info, 'total_count_change', '?')} messages lost on the way "
                                    f"(DDS; {getattr(info, 'total_count', '?')} so far)")

    def _publishers(self, topic, count, wait=True):
        """More than one publisher on an input topic: the condition ``publishers`` (outputs flagged); with ``wait``
        False, nothing where the compensation's lock is held."""
        hold = self.settings.window + self.settings.delay + self.settings.stale_timeout
        if count > 1:
            message = (f"{count} publishers on {topic}: their messages interleave (a driver restarted beside the "
                       "old one?); the outputs flagged")
            if self.pipeline.condition("publishers", message, wait=wait):
                self.log.warning(message)
        elif self.pipeline.condition("publishers", None, hold, wait=wait):
            self.log.info(f"one publisher on each input again: outputs unflagged after {hold:g} s")

    def _check_graph(self):
        """The input topics' publishers counted, each pass of the poll thread after its messages are taken and
        before they are compensated (a message taken from a second publisher: it had matched, and is counted)."""
        counts = {}
        for sub in (self._wrench_sub, self._motion_sub):
            try:
                counts[sub.topic_name] = sub.get_publisher_count()
            except Exception:
                return
        topic, most = max(counts.items(), key=lambda kv: kv[1])
        self._publishers(topic, most)

    # --- inputs ----------------------------------------------------------------------------------------------
    def _time(self, stamp):
        """A stamp ``(sec, nanosec)`` in s from the first stamp's second (a float keeps its nanoseconds)."""
        if self._epoch is None:
            self._epoch = stamp[0]
            self.pipeline.time_origin = float(stamp[0])
        return (stamp[0] - self._epoch) + stamp[1] * 1e-9

    def _queued(self, sub, kind):
        """The plain values of the messages waiting on a subscription, taken now (the executor hands one per
        callback: the rest of a backlog is taken in the same callback and compensated as one block)."""
        return [m for _, _, m in self._taken(sub, kind)]

    def _taken(self, sub, kind):
        """The messages waiting on a subscription, taken now as bytes and decoded (:mod:`._cdr`): ``(received,
        kind, values)``, ``kind`` 1 for the wrench, 0 for the motion, ``received`` the middleware's reception time
        (ns; its order where it has none). A message whose bytes cannot be decoded is skipped, said and counted,
        and that input's messages are taken through rclpy's own conversion from then on."""
        handle, out = getattr(sub, "handle", None), []
        if handle is None or not hasattr(handle, "take_message"):
            return out
        raw, decode = self._raw[kind], self._decode[kind]
        with handle:
            while (taken := handle.take_message(sub.msg_type, raw)) is not None:
                info = taken[1] if len(taken) > 1 and isinstance(taken[1], dict) else {}
                try:
                    values = decode(taken[0]) if raw else plain(self._kinds[kind], taken[0])
                except Exception as err:               # counted as a reading invalid, or a motion sample skipped
                    data = bytes(taken[0])
                    line = (f"a message on {sub.topic_name} not decoded ({err}; {len(data)} bytes, "
                            f"{data[:24].hex(' ')}): skipped")
                    if kind:
                        self.pipeline.add_reading(np.nan, np.full(len(self.names), np.nan))
                        self._warn("decode", line + " (counted as invalid)")
                    else:
                        self._skip_motion("decode", line)
                    self._raw[kind] = raw = False
                    self.log.warning(f"{sub.topic_name}: its messages taken through rclpy's conversion from now on")
                    continue
                out.append((info.get("received_timestamp") or len(out), kind, values))
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
        :data:`SILENT` s). An exception while compensating never stops it (:meth:`_failed`); one outside that (the
        middleware gone) stops the node (:attr:`error`)."""
        last = time.monotonic()
        wait = self._waiter(context)
        idle = True
        try:
            while context.ok():
                readings, motions = self._taken(self._wrench_sub, 1), self._taken(self._motion_sub, 0)
                if not (motions or readings):
                    if not idle:                         # the inputs fell silent: the diagnostics' numbers final
                        self.pipeline.snap()
                        idle = True
                    if wait is not None:
                        wait()
                    else:                                # inputs silent for long: looked at less often
                        time.sleep(POLL if time.monotonic() - last < SILENT else IDLE)
                    continue
                idle = False
                last = self._entered = self._pass_start = time.monotonic()
                self._pass_size = len(readings)
                try:
                    self._check_graph()
                    # in the order the middleware received them: each reading after the motion that came before it
                    for received, kind, m in heapq.merge(motions, readings, key=lambda e: (e[0], e[1])):
                        if kind:
                            self._reading(*m, received * 1e-9 if received > 1e18 else None)
                        else:
                            self._motion_values(*m)
                    self._process()
                except Exception as err:
                    self._failed(err)
                finally:
                    self._pass_start = None
        except Exception as err:                     # said by spin, in one line for FmscalError
            if context.ok():
                self.error = err
                self.r.rclpy.try_shutdown(context=context)

    def _failed(self, err):
        """An exception while compensating: logged (its traceback the first time), the pipeline restarted."""
        key = f"error {type(err).__name__}"
        first = key not in self._last_warned
        self._warn(key, f"compensation failed ({type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''})"
                        "; the window restarted" + (":\n" + traceback.format_exc() if first else ""))
        self.pipeline.reset(f"{type(err).__name__}")

    def _on_wrench(self, msg):
        self._entered = time.monotonic()
        for m in self._queued(self._motion_sub, 0):
            self._motion_values(*m)
        for m in [plain("wrench", msg), *self._queued(self._wrench_sub, 1)]:
            self._reading(*m)
        self._process()

    def _on_motion(self, msg):
        self._entered = time.monotonic()
        for m in [plain(self._motion_kind, msg), *self._queued(self._motion_sub, 0)]:
            self._motion_values(*m)
        self._process()

    def _reading(self, stamp, frame_id, values, received=None):
        """A wrench reading's plain values (:func:`._cdr.plain`) to the pipeline."""
        w = np.array(values)[self._from_ros]
        if not self.pipeline.add_reading(self._time(stamp), w, stamp, frame_id, received):
            self._warn("reading", "a wrench with a NaN or infinite component: skipped (counted as invalid)")

    def _process(self):
        """Compensate what the motion covers; publish it; say what the pipeline noticed."""
        outputs = self.pipeline.process()
        failed = []
        for out in outputs:
            try:
                self._publish(out)
            except Exception as err:                 # the middleware refused it: said, counted, never fatal
                failed.append(out)
                self._warn("publish", f"an output not published ({type(err).__name__}: {err})")
        if failed:
            self.pipeline.unpublished(failed)
        dropped = self.pipeline.dropped
        while dropped:
            self._publish_withheld(*dropped.popleft())
        notices = self.pipeline.notices
        while notices:
            key, message = notices.popleft()
            self._warn(key, message)

    def _skip_motion(self, key, message):
        self.pipeline.skip_motion()
        self._warn(key, message + " (counted in motion_skipped; the readings near it take the samples around it)")

    def _pose(self, stamp, frame_id, values):
        """A pose's plain values (position, orientation x y z w) to the pipeline, the sensor's pose in the model's
        order."""
        q = np.array([values[6], values[3], values[4], values[5]])
        position = np.array(values[:3])
        q, position = sensor_pose(q, position, self.settings.pose_to_sensor)
        norm = math.sqrt(float(q @ q))
        if not (math.isfinite(norm) and abs(norm - 1) < 1e-3 and np.isfinite(position).all()):
            self._skip_motion("pose", f"a pose whose quaternion is not of unit norm ({norm:.4g}): skipped")
            return
        q = q / norm
        full = np.concatenate([q, position, [2 * math.atan2(q[3], q[0])]])        # _POSE_ORDER
        self.pipeline.add_motion(self._time(stamp), full[self._pose_index], frame_id)

    def _joints(self, stamp, frame_id, values):
        """A joint state's plain values (names, positions, velocities) to the pipeline, in the model's order."""
        names, position, velocity = values
        order = self.pipeline.motion.joints
        where = {name: i for i, name in enumerate(names)}
        missing = [n for n in order if n not in where]
        if missing or len(position) != len(names):
            self._skip_motion("joints", f"a joint state without {', '.join(missing[:3]) or 'a position per name'}: "
                                        "skipped")
            return
        index = [where[n] for n in order]
        q = np.asarray(position, dtype=float)[index]
        if not np.isfinite(q).all():
            self._skip_motion("joints", "a joint state with a NaN or infinite position: skipped")
            return
        dq = np.asarray(velocity, dtype=float)[index] if len(velocity) == len(names) else None
        if dq is not None and not np.isfinite(dq).all():
            dq = None                                  # differentiated from the positions instead
        self.pipeline.add_motion(self._time(stamp), (q, dq, None), frame_id)

    def _imu(self, stamp, frame_id, values):
        """An IMU sample's plain values (:func:`._cdr.plain`) to the pipeline; an orientation whose covariance
        begins with -1 is none (sensor_msgs/Imu's convention)."""
        v = values
        quaternion = None if v[4] == -1 else np.array([v[3], v[0], v[1], v[2]])
        rate, force = np.array(v[13:16]), np.array(v[25:28])
        if not (np.isfinite(rate).all() and np.isfinite(force).all()):
            self._skip_motion("imu", "an IMU sample with a NaN or infinite rate or acceleration: skipped")
            return
        if quaternion is not None:
            norm = np.linalg.norm(quaternion)
            quaternion = quaternion / norm if np.isfinite(norm) and abs(norm - 1) < 1e-3 else None
        if quaternion is None and self.settings.output_frame == "base":
            self._skip_motion("imu", "an IMU sample without a unit orientation: skipped (output_frame base needs it)")
            return
        self.pipeline.add_motion(self._time(stamp), (quaternion, rate, force), frame_id)

    # --- outputs ---------------------------------------------------------------------------------------------
    def _templates(self, r, n, label):
        """The outputs' bytes (:class:`._cdr.Template`): the contact wrench, its covariance (``n`` by ``n``, the
        axes ``label``), its flags, the debug latency."""
        status_name = f"{self.node.get_name()}: contact wrench"
        hardware_id = self.settings.wrench_topic

        def header(msg, stamp, frame_id):
            msg.header.stamp = r.Time(sec=stamp[0], nanosec=stamp[1])
            msg.header.frame_id = frame_id
            return msg

        def wrench(stamp, numbers, frame_id):
            msg = header(r.WrenchStamped(), stamp, frame_id)
            f, t = msg.wrench.force, msg.wrench.torque
            f.x, f.y, f.z, t.x, t.y, t.z = (float(v) for v in numbers)
            return msg

        def array_(numbers, dims=()):
            msg = r.Array()
            msg.layout.dim = list(dims)
            msg.data = [float(v) for v in numbers]
            return msg

        dims = [r.Dimension(label=label, size=n, stride=n * n), r.Dimension(label="column", size=n, stride=n)]

        def flags(stamp, numbers, frame_id, level, message, contact):
            msg = header(r.DiagnosticArray(), stamp, frame_id)
            msg.status = [r.DiagnosticStatus(level=level, name=status_name, message=message, hardware_id=hardware_id,
                                             values=[r.KeyValue(key="contact", value=contact)])]
            return msg

        return SimpleNamespace(
            contact=Template(wrench, 6, r.serialize),
            cov=Template(lambda stamp, numbers: array_(numbers, dims), n * n, r.serialize, stamped=False),
            flags=Template(flags, 0, r.serialize),
            latency=Template(lambda stamp, numbers: array_(numbers), 3, r.serialize, stamped=False))

    def _publish(self, out):
        """The contact wrench (the reading's stamp and frame), its covariance, its flags, the debug latency: as
        bytes (:mod:`._cdr`)."""
        encode, sample, stamp = self._encode, out.sample, out.stamp
        six = np.zeros(6)
        six[self._from_ros] = sample.wrench
        self.contact_pub.publish(encode.contact(stamp, six, out.frame_id))
        self.cov_pub.publish(encode.cov(None, sample.cov[self._cov_index].ravel()))
        level = self.r.DiagnosticStatus.WARN if out.flags else self.r.DiagnosticStatus.OK
        self.flag_pub.publish(encode.flags(stamp, (), out.frame_id, level, " ".join(out.flags),
                                           "true" if sample.contact else "false"))
        now = time.time()
        since = now - (stamp[0] + stamp[1] * 1e-9)
        self._latencies.append(since)
        self._held_for = (now - out.arrival, now)          # from the reading's reception to its output
        if now - out.arrival > self._late_most:
            self._late_most = now - out.arrival
        if self.latency_pub is not None:
            self.latency_pub.publish(encode.latency(None, (since, time.monotonic() - self._entered,
                                                           float(self.pipeline.backlog()))))

    def _publish_withheld(self, stamp, frame_id, cause):
        """The flags of a reading given no output: level ERROR, ``withheld: <cause>``."""
        try:
            self.flag_pub.publish(self._encode.flags(stamp, (), frame_id, self.r.DiagnosticStatus.ERROR,
                                                     f"withheld: {cause}", "false"))
        except Exception as err:
            self._warn("publish", f"a flag not published ({type(err).__name__}: {err})")

    def _warn(self, key, message):
        """A warning in the log, at most one of a kind every :data:`WARN_EVERY` s (the ones held back counted in
        the next)."""
        now = time.monotonic()
        if now - self._last_warned.get(key, -np.inf) >= WARN_EVERY:
            held = self._warned_count.pop(key, 0)
            self._last_warned[key] = now
            self.log.warning(message + (f" ({held} more since the last such line)" if held else ""))
        else:
            self._warned_count[key] = self._warned_count.get(key, 0) + 1

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

    def _identify(self):
        """``~/identify_payload``: the held samples fitted in the worker process (:mod:`._worker`); cancelled by
        ``~/cancel`` or the node stopping."""
        job = self.pipeline.identify_job()
        if isinstance(job, tuple):
            return job
        if self.stopping.is_set():
            return False, "identify_payload refused: the node is stopping"
        t = job["held"][0]
        self.log.info(f"~/identify_payload: fitting {len(t)} samples ({t[-1] - t[0]:.3g} s) in a process of its own; "
                      "~/cancel stops it")
        try:
            result = self.worker.run(self.settings, job)
        except Cancelled:
            return False, ("identify_payload interrupted: the node is stopping" if self.stopping.is_set() else
                           "identify_payload cancelled (~/cancel); the payload in use kept")
        except RuntimeError as err:
            return False, f"identify_payload failed: {err}"
        return self._then_push(*self.pipeline.identified_by(result))

    def _reidentify(self):
        """``~/reidentify``: :meth:`._pipeline.Pipeline.reidentify`, then the push where ``push_controller`` is set."""
        return self._then_push(*self.pipeline.reidentify())

    def _then_push(self, ok, message):
        """A service's answer, with the new payload pushed (:meth:`_push`) where it succeeded and
        ``push_controller`` is set; a failed push said, the payload in use kept."""
        if not (ok and self.settings.push_controller):
            return ok, message
        _, line = self._push()
        return ok, message + "; " + line

    def _push(self):
        """``~/push``: the payload and offset in use set on the broadcaster ``push_controller`` (its run-time
        parameters, :func:`._push.push_parameters`), as ``fmscal export ros2-control --push`` does."""
        node = self.settings.push_controller
        if not node:
            return False, "push refused: set the parameter push_controller (with a payload file alone)"
        node = "/" + node.lstrip("/")
        with self.pipeline.lock:
            document = self.pipeline.payload_document()
        try:
            exported = ros2_control_parameters(document, self.settings.sensor_frame or "ft_sensor", "world",
                                               controller=node.rsplit("/", 1)[-1])
            return True, pushed_line(node, push_parameters(exported, node=node))
        except FmscalError as err:
            return False, "push failed: " + (str(err).splitlines()[0] or repr(err))

    def _cancel(self):
        """``~/cancel``: a running ``~/identify_payload`` stopped."""
        if self.worker.cancel():
            return True, "cancelled the running identify_payload; the payload in use kept"
        return False, "cancel: no identify_payload is running"

    def _behind(self, now):
        """Why the compensation is behind the clock, or None: a pass running for :data:`BEHIND` s, or an output since
        the last look (the newest within the last 2 s) published that much later than its reading's reception and
        the causal delay (the middleware's reception time: the wait in the input queue counted), or half the input
        queue's span (``queue_depth`` readings) where that is shorter: beyond it, a burst fills the queue and
        readings are lost."""
        started = self._pass_start
        snapshot = self.pipeline.snapshot
        waiting = snapshot.backlog + (self._pass_size if started is not None else 0)
        if started is not None and now - started > BEHIND:
            return (f"behind: a compensation pass has run {now - started:.3g} s over {self._pass_size} readings; "
                    f"{waiting} readings waiting, {snapshot.counts.get('lost', 0)} lost so far")
        held, most = self._held_for, self._late_most
        self._late_most = 0.0                        # the longest since the last look
        period = self.pipeline.dt_in
        bound = BEHIND if not period else min(BEHIND, 0.5 * self.settings.queue_depth * period)
        if held is not None and snapshot.delay is not None and time.time() - held[1] < 2.0:
            late = max(held[0], most) - snapshot.delay
            if late > bound:
                return (f"behind: the outputs come {late:.3g} s after their readings and the causal delay; "
                        f"{waiting} readings waiting, {snapshot.counts.get('lost', 0)} lost so far")
        return None

    def _check_name(self):
        """Another node of this name in the graph: its outputs and services mix with this one's. Said where it
        changed; set in the pipeline's conditions without waiting on the compensation's lock (this runs in the
        diagnostics: :meth:`_set_condition`)."""
        try:
            names = self.node.get_fully_qualified_node_names()
        except Exception:
            return
        me = self.node.get_fully_qualified_name()
        count = sum(1 for n in names if n == me)
        message = None if count < 2 else (
            f"{count} nodes named {me}: their outputs mix on the same topics and one service call reaches either; "
            "stop one, or rename it (-r __node:=other_name)")
        if message == self._name_said:
            return
        if message is not None:
            self.log.warning(message)
        elif self._name_said is not None:
            self.log.info(f"one node named {me} again")
        self._name_said = message
        self._set_condition("name", message)

    def _set_condition(self, name, message, hold=0.0):
        """A condition set from the main executor's thread (the diagnostics, the QoS events): never waiting on the
        compensation's lock; where a pass holds it, kept and set at a later look (:meth:`_set_pending`)."""
        self._pending[name] = (message, hold)
        self._set_pending()

    def _set_pending(self):
        """The conditions :meth:`_set_condition` kept, set in the pipeline where its lock is free now."""
        for name, (message, hold) in list(self._pending.items()):
            if self.pipeline.condition(name, message, hold, wait=False) is None:
                return
            del self._pending[name]

    def _state(self, snapshot, now):
        """The outputs' state (:data:`._pipeline.STATES`) of a snapshot; a restart, a stale motion or readings
        apart from the motion since the last diagnostics said even where it is over by now, one per diagnostics
        (a state that lasts less than a diagnostics period is not missed)."""
        state = state_of(snapshot, now, self.settings.stale_timeout)
        seen = {"motion stale": snapshot.withheld.get("stale", 0), "streams apart": snapshot.withheld.get("apart", 0),
                "restarting": snapshot.events.get("restart", 0)}
        last, self._seen = self._seen or seen, seen
        for name, count in seen.items():
            if count > last[name] and name != state and name not in self._latched:
                self._latched.append(name)
        if self._latched and LEVELS[state] < 2 and (state != "saturated" or LEVELS[self._latched[0]] == 2):
            shown = self._latched.pop(0)
            if state in seen and state != shown and state not in self._latched:
                self._latched.append(state)          # this one not said now either: said in turn
            return shown
        return state

    def _diagnose(self):
        """The diagnostics, from the pipeline's snapshot (no lock): the outputs' state with the offset and its sd,
        the contact flag, the delays, the ledger; the inputs' conditions; the compensation's liveness."""
        r = self.r
        now = time.monotonic()
        self._check_name()
        self._set_pending()
        p, snapshot = self.pipeline, self.pipeline.snapshot
        levels = (r.DiagnosticStatus.OK, r.DiagnosticStatus.WARN, r.DiagnosticStatus.ERROR)
        state = self._state(snapshot, now)
        status = r.DiagnosticStatus()
        status.level = levels[LEVELS[state]]
        status.name = f"{self.node.get_name()}: contact wrench"
        status.message = state
        status.hardware_id = self.settings.wrench_topic
        kept = np.percentile(np.array(self._latencies), (50, 99)) if self._latencies else None
        offset, sd = snapshot.offset, snapshot.offset_sd
        values = {"state": state, "contact": str(bool(snapshot.contact)).lower(),
                  "offset": "" if offset is None else " ".join(f"{v:.6g}" for v in offset),
                  "offset_sd": "" if sd is None else " ".join(f"{v:.3g}" for v in sd),
                  "channels": " ".join(self.names),
                  "delay_s": "" if snapshot.delay is None else f"{snapshot.delay:g}", "latency_s": f"{p.latency:g}",
                  "sample_time_s": "" if snapshot.dt is None else f"{snapshot.dt:g}",
                  "decimation": str(snapshot.decimation),
                  "stamp_to_output_p50_s": "" if kept is None else f"{kept[0]:.6f}",
                  "stamp_to_output_p99_s": "" if kept is None else f"{kept[1]:.6f}",
                  "backlog": str(snapshot.backlog), "waiting": str(snapshot.waiting),
                  "motion_lag_s": "" if snapshot.motion_lag is None else f"{snapshot.motion_lag:.4f}",
                  **{k: str(v) for k, v in snapshot.counts.items()},
                  **{f"withheld_{k}": str(v) for k, v in snapshot.withheld.items()},
                  **{f"events_{k}": str(v) for k, v in snapshot.events.items()},
                  "flags": " ".join(f for f in FLAGS if f in snapshot.conditions),
                  "tool_change": snapshot.tool_change}
        status.values = [r.KeyValue(key=k, value=v) for k, v in values.items()]
        inputs = r.DiagnosticStatus()
        inputs.name = f"{self.node.get_name()}: inputs"
        inputs.hardware_id = self.settings.topic
        conditions = {k: v for k, v in snapshot.conditions.items() if k not in ("frame", "apart")}
        inputs.level = r.DiagnosticStatus.WARN if conditions else r.DiagnosticStatus.OK
        inputs.message = "; ".join(sorted(set(conditions.values()))) if conditions else "ok"
        inputs.values = [r.KeyValue(key=k, value=v) for k, v in sorted(conditions.items())]
        behind = self._behind(now)
        if behind:
            self._warn("behind", behind)
        live = r.DiagnosticStatus()
        live.name = f"{self.node.get_name()}: compensation"
        live.hardware_id = self.settings.wrench_topic
        live.level = r.DiagnosticStatus.ERROR if behind else r.DiagnosticStatus.OK
        live.message = behind or "keeping up"
        pass_s = 0.0 if self._pass_start is None else now - self._pass_start
        live.values = [r.KeyValue(key="pass_s", value=f"{pass_s:.3f}"),
                       r.KeyValue(key="backlog", value=str(snapshot.backlog + (self._pass_size if pass_s else 0))),
                       r.KeyValue(key="lost", value=str(snapshot.counts.get("lost", 0)))]
        array_ = r.DiagnosticArray()
        array_.header.stamp = self.node.get_clock().now().to_msg()
        array_.status = [status, inputs, live]
        self.diag_pub.publish(array_)

    def stop(self):
        """The node stopping: a running fit killed (its call answers at once)."""
        self.stopping.set()
        self.worker.close()

    def destroy(self):
        """The nodes destroyed (each with its own waitables: the inputs' node with its subscriptions' QoS event
        handlers)."""
        for n in (self.services, self.inputs, self.node):
            n.destroy_node()


def spin(args):
    """Run the node until it is interrupted: ``args`` the ROS arguments (``--ros-args ...``). One Ctrl-C (or
    SIGTERM) stops it within a second, a running ``~/identify_payload`` killed.

    Raises
    ------
    Ros2Error
        rclpy missing, an argument rclpy does not take, a parameter missing, bad or unknown (one line naming it).
    """
    r = ros()
    context = r.Context()
    try:
        r.rclpy.init(args=["fmscal", *args], context=context)
    except Exception as err:
        raise Ros2Error(f"the ROS arguments were refused: {str(err).splitlines()[0] if str(err) else err}") from None
    if hasattr(signal, "SIGUSR1"):                   # kill -USR1 <pid>: every thread's stack on stderr
        faulthandler.register(signal.SIGUSR1, all_threads=True)
    stopping = threading.Event()                     # set by a SIGINT or SIGTERM from here on, even mid-start
    restore = _stop_on_signals(stopping)
    node = None
    try:
        node = CompensatorNode(r, context, args)
        executor = r.Single(context=context)
        executor.add_node(node.node)
        services = r.Executor(num_threads=3, context=context)
        services.add_node(node.services)
        threads = [threading.Thread(target=_spin_services, args=(r, services), daemon=True)]
        if node.pollable():
            threads.append(threading.Thread(target=node.poll, args=(context,), daemon=True))
            node.take_events(context)
        else:                                        # an rclpy without take_message: its executor takes them
            executor.add_node(node.inputs)
        # everything built so far (the imports, the warmed-up compensator) out of the collector's way: a full
        # collection over it would pause the compensation for tens of milliseconds
        gc.collect()
        gc.freeze()
        try:
            node.worker.start()                 # the fit's process, its imports done before any call needs it
        except OSError as err:                  # not started: the first ~/identify_payload tries again, and says
            node.node.get_logger().warning(f"the fit's process did not start ({err}): ~/identify_payload will "
                                           "try again when called")
        for thread in threads:
            thread.start()
        try:
            while not stopping.is_set():
                executor.spin_once(timeout_sec=STOP_LOOK)
        except (KeyboardInterrupt, r.Shutdown):
            pass
        if stopping.is_set():
            node.node.get_logger().info("stopping (a SIGINT or SIGTERM)")
        # the other threads stopped before their nodes are destroyed (else a C++ abort at exit); a running fit
        # killed first, so that its service call returns and the services' threads end
        node.stop()
        r.rclpy.try_shutdown(context=context)
        services.shutdown(timeout_sec=0.5)
        for thread in threads:
            thread.join(timeout=0.5)
        if node.error is not None:
            raise node.error
    finally:
        if node is not None:
            node.stop()
            node.destroy()
        r.rclpy.try_shutdown(context=context)
        restore()


def _stop_on_signals(stopping):
    """SIGINT (Ctrl-C) and SIGTERM set ``stopping`` instead of raising; returns what restores the former handlers.

    The handlers are set whatever the process inherited: a child of a background job (CI's commands, a node
    started with ``&``) starts with SIGINT ignored, Python then sets no handler of its own, and the node ran on
    after every Ctrl-C. They raise nothing (a ``KeyboardInterrupt`` can land in a finalizer, which swallows it),
    and a thread of its own also reads the signal's number from Python's wakeup fd, which the interpreter's
    C-level handler writes in whichever thread the signal lands: ``stopping`` is set whatever the main thread
    does. Outside the main thread (no handler can be set there): nothing done.
    """
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    read, write = socket.socketpair()
    write.setblocking(False)
    stops = (int(signal.SIGINT), int(signal.SIGTERM))

    def handler(signum, frame):
        stopping.set()

    def watch():
        while not stopping.is_set():
            try:
                data = read.recv(64)
            except OSError:
                return
            if not data:
                return
            if any(b in stops for b in data):
                stopping.set()

    former = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    former_fd = signal.set_wakeup_fd(write.fileno(), warn_on_full_buffer=False)
    watcher = threading.Thread(target=watch, name="fmscal-signals", daemon=True)
    watcher.start()

    def restore():
        signal.set_wakeup_fd(former_fd)
        for s, h in former.items():
            signal.signal(s, h)
        with contextlib.suppress(OSError):
            read.shutdown(socket.SHUT_RDWR)              # the watcher's recv returns
        watcher.join(timeout=0.5)
        read.close()
        write.close()

    return restore


def _spin_services(r, executor):
    """The services' executor, until the context shuts down."""
    try:
        executor.spin()
    except (KeyboardInterrupt, r.Shutdown):
        pass
