"""The ROS 2 node's delay and losses: ``python benchmarks/ros2_latency.py [--duration 10]``.

The node (``fmscal ros2``, a subprocess) compensates a ``spatial-arm`` log (a calibration holding the
scenario's truth) fed at 1 kHz by a sender of its own (``benchmarks/ros2_sender.py``, a third process that does
nothing else): a ``WrenchStamped`` and a ``PoseStamped`` each millisecond, stamped with the time they are due,
over DDS on loopback, in a ROS domain of its own. This process takes the node's outputs with a blocking wait and
no executor (tests/ros2_rig.py's ``Taker``), so that neither it nor the sender competes for the node's
cores more than it must. Printed:

- the delay from a reading's stamp to its output's publication, measured by the node itself (``debug_latency``:
  ``~/latency`` carries, per output, the time from the stamp to the publication, and the node's own work: from
  the start of the callback that published it), p50, p99 and the largest, and that delay beyond the causal
  filter's stated delay (the target: p99 under 2 ms beyond it), also without the first second's outputs (the
  start: the first blocks of each size, the machine's caches), and less the lateness of the reading the output
  waited for (the one ``delay`` s after its own);
- the same seen by this process's subscriber (now - stamp on reception: DDS's delivery back included);
- the backlog (the readings waiting for the motion when an output is published), its p99 and largest;
- how late the sender sent each row against its 1 kHz schedule (the stamps are the schedule's times): an
  output needs the reading ``delay`` s after its own, so a stall of the sender shows in the delay too;
- the CPU the node used over the run (s);
- with ``--pin``: the node on a CPU of its own (the last), this process and the sender on the others;
- the messages: readings sent, received by the node, outputs expected (every reading the causal filter covers)
  and received here; dropped = expected - received;
- with ``--identify AT``: ``~/identify_payload`` called once the node has taken ``AT`` s of readings (with
  ``--contact START SECONDS``, a 15 N push on the tool then: the node fits the longest stretch without it), its
  answer, how long it took, and the delay beyond the causal filter's of the outputs published meanwhile (also less
  the sender's lateness, and the node's callback to publication);
- with ``--busy``: a busy loop (a process of pure Python, in the lowest scheduling class, ``SCHED_IDLE``) beside
  the node over the run, and no fit: what any computation beside the node costs its outputs on this machine,
  the yardstick for the fit's process (which runs at ``nice`` 10); with ``--pin``, the loop on the sender's and
  this process's CPUs, not the node's.

The machine's load is not controlled: on a shared machine the tails are the other processes' as much as the
node's. About ``duration + 10`` s. ``--json`` prints the figures as one JSON object instead.
"""

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from fmscal.analysis import compensate  # noqa: E402
from ros2_floor import sender_result, start_sender, stats  # noqa: E402
from ros2_rig import Taker, domain_id, node_log, running_node, truth_calibration  # noqa: E402
from ros2_sender import scenario_log  # noqa: E402
import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from geometry_msgs.msg import WrenchStamped  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

RELIABLE = QoSProfile(depth=2000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)


class Listener:
    """This process's side: the node's contact wrench (its stamp and arrival), its latency and diagnostics,
    taken by tests/ros2_rig.py's ``Taker`` (no executor: this process's own load kept down)."""

    def __init__(self, domain):
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node("fmscal_bench_listener", context=self.context)
        self.stamps, self.received_at, self.latencies, self.latency_at, self.diagnostics = [], [], [], [], []
        self.taker = Taker(self.node, self.context)
        self.contact_sub = self.taker.subscribe(WrenchStamped, "/ft_sensor/contact", self._contact, RELIABLE)
        self.taker.subscribe(Float64MultiArray, "/fmscal_compensator/latency", self._latency, RELIABLE)
        self.taker.subscribe(DiagnosticArray, "/diagnostics", lambda m, at: self.diagnostics.append(m), 10)
        self.taker.start()

    def _latency(self, msg, at):
        self.latencies.append(msg.data.tolist())
        self.latency_at.append(at)

    def received(self):
        """The readings the node has taken, as its newest diagnostics say (0 before)."""
        for d in reversed(self.diagnostics):
            values = {k.key: k.value for k in d.status[0].values}
            if "received" in values:
                return int(values["received"])
        return 0

    def _contact(self, msg, at):
        self.stamps.append(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)
        self.received_at.append(at)

    def wait_for_node(self, proc, timeout=30.0):
        """Until the node takes both inputs, publishes to this process and its diagnostics have come."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if proc.poll() is not None:
                raise SystemExit(f"the node exited ({proc.returncode}): {node_log(proc)[-2000:]}")
            if self.node.count_subscribers("/ft_sensor/wrench") and self.node.count_subscribers("/ft_sensor/pose") \
                    and self.contact_sub.get_publisher_count() and self.diagnostics:
                return
            time.sleep(0.05)
        raise SystemExit(f"the node was not discovered in {timeout} s: {node_log(proc)[-2000:]}")

    def wait_for(self, condition, timeout):
        end = time.monotonic() + timeout
        while time.monotonic() < end and not condition():
            time.sleep(0.02)

    def close(self):
        self.taker.stop()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


class IdentifyCall(threading.Thread):
    """``~/identify_payload`` called once the node has taken ``at`` s of readings (a client of its own context):
    when it went out and came back (``time.time()``), and its answer."""

    def __init__(self, domain, listener, at, rate):
        super().__init__(daemon=True)
        self.domain, self.listener, self.readings = domain, listener, int(at * rate)
        self.start_at = self.end_at = None
        self.answer = None

    def run(self):
        while self.listener.received() < self.readings:
            time.sleep(0.01)
        context = Context()
        rclpy.init(context=context, domain_id=self.domain)
        node = rclpy.create_node("fmscal_bench_identify", context=context)
        try:
            client = node.create_client(Trigger, "/fmscal_compensator/identify_payload")
            if not client.wait_for_service(timeout_sec=30.0):
                self.answer = (False, "~/identify_payload not found")
                return
            self.start_at = time.time()
            future = client.call_async(Trigger.Request())
            executor = SingleThreadedExecutor(context=context)   # of this context (the global one has none)
            executor.add_node(node)
            try:
                executor.spin_until_future_complete(future, timeout_sec=600.0)
            finally:
                executor.shutdown()
            self.end_at = time.time()
            result = future.result()
            self.answer = (False, "no answer in 600 s") if result is None else (result.success, result.message)
        finally:
            node.destroy_node()
            rclpy.try_shutdown(context=context)


def _settled(peer, sent):
    """Whether the node has taken every reading or counted it lost, holds none, and each output it published
    has come."""
    if not peer.diagnostics:
        return False
    s = {k.key: k.value for k in peer.diagnostics[-1].status[0].values}
    if "received" not in s:
        return False
    published = int(s["published"])
    return (int(s["received"]) + int(s["lost"]) >= sent and not int(s["backlog"])
            and len(peer.stamps) >= published and len(peer.latencies) >= published)


#: ``--busy``'s process: pure Python spinning in the lowest scheduling class.
_BUSY = "import os; os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))\nwhile True:\n    pass"


def measure(duration=10.0, seed=0, domain=None, qos="reliable", pin=False, identify=None, contact=None,
            busy=False):
    """Run the node on ``duration`` s of a 1 kHz log; the figures (module docstring) as a dict. ``pin``: the
    node on the last CPU, this process and the sender on the others (where there are two or more). ``identify``:
    ``~/identify_payload`` called once the node has taken that many s of readings; ``contact`` ``(start,
    seconds)``: a 15 N push on the tool then. ``busy``: a ``SCHED_IDLE`` busy loop beside the node over the run."""
    cpus = sorted(os.sched_getaffinity(0))
    pin = pin and len(cpus) >= 2
    scenario, log, truth = scenario_log(duration, seed, contact)
    cal = truth_calibration(scenario, truth)
    domain = domain if domain is not None else domain_id(f"latency-{os.getpid()}")
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "cal.json"
        cal.save(path)
        reference = compensate(cal, log, causal=True)
        if pin:                                     # the node inherits the last CPU; this process, the others
            os.sched_setaffinity(0, cpus[-1:])
        with running_node(domain, f"calibration:={path}", "pose_topic:=/ft_sensor/pose", f"qos:={qos}",
                          "debug_latency:=true") as proc:
            if pin:
                os.sched_setaffinity(0, cpus[:-1])
            peer = Listener(domain)
            try:
                peer.wait_for_node(proc)
                cpu = _cpu(proc.pid)
                call = None
                if identify is not None:
                    call = IdentifyCall(domain, peer, identify, 1.0 / log.dt)
                    call.start()
                hog = subprocess.Popen([sys.executable, "-c", _BUSY]) if busy else None
                try:
                    sent = sender_result(start_sender(domain, duration, seed, qos, contact), duration + 60)
                finally:
                    if hog is not None:
                        hog.kill()
                        hog.wait()
                epoch, lateness = sent["epoch"], np.array(sent["lateness"])
                sent_in = len(lateness) * log.dt + lateness[-1]
                expected = len(reference.t)
                # every output come, or (a loaded machine: the node's queue overflowing, its losses counted) every
                # reading taken or counted lost, nothing waiting, each output published come
                peer.wait_for(lambda: len(peer.stamps) >= expected and len(peer.latencies) >= expected
                              or _settled(peer, len(log.t)), 60)
                node_cpu = _cpu(proc.pid) - cpu
                if call is not None:
                    call.join(timeout=600.0)
                time.sleep(0.3)
                diagnostics = {k.key: k.value for k in peer.diagnostics[-1].status[0].values}
                text = node_log(proc)
            finally:
                peer.close()
    t = np.round(np.array(peer.stamps) - epoch, 6)
    delay = reference.delay
    node = np.array(peer.latencies) if peer.latencies else np.zeros((0, 3))
    seen = np.array(peer.received_at) - np.array(peer.stamps)
    # each output waits for the reading `delay` s after its own: that reading's lateness taken off
    trigger = np.round((t + delay) / log.dt).astype(int)
    net = node[:, 0] - delay - lateness[np.minimum(trigger, len(lateness) - 1)] \
        if len(node) == len(t) else np.zeros(0)
    return {"duration_s": duration, "pinned": pin, "busy": busy, "node_cpu_s": node_cpu, "rate_hz": 1.0 / log.dt,
            "qos": qos, "causal_delay_s": delay,
            "sent": len(log.t), "sent_in_s": sent_in, "received_by_node": int(diagnostics.get("received", -1)),
            "lost_by_node": int(diagnostics.get("lost", -1)),
            "published_by_node": int(diagnostics.get("published", -1)),
            "expected": len(reference.t), "received": len(t), "dropped": len(reference.t) - len(t),
            "in_order": bool(np.all(np.diff(t) > 0)),
            "stamp_to_publication_s": stats(node[:, 0]), "beyond_delay_s": stats(node[:, 0] - delay),
            "beyond_delay_after_1s_s": stats(node[1000:, 0] - delay),
            "beyond_delay_less_lateness_s": stats(net),
            "callback_to_publication_s": stats(node[:, 1]), "backlog": stats(node[:, 2]),
            "stamp_to_subscriber_s": stats(seen), "publisher_lateness_s": stats(lateness),
            "node_counts": diagnostics, **_identify_figures(call, peer, delay, net),
            "warnings": [line for line in text.splitlines() if "WARN" in line][:5]}


def _identify_figures(call, peer, delay, net):
    """The figures of an ``~/identify_payload`` call during the run: its answer, how long it took, and of the
    outputs published meanwhile (p50, p99, the largest) the delay beyond the causal filter's, the same less the
    sender's lateness (``net``), and the node's callback to publication."""
    if call is None:
        return {}
    at = np.array(peer.latency_at)
    node = np.array(peer.latencies) if peer.latencies else np.zeros((0, 3))
    during = (at >= (call.start_at or np.inf)) & (at <= (call.end_at or -np.inf)) if len(at) == len(node) else []
    return {"identify": {"success": None if call.answer is None else call.answer[0],
                         "message": None if call.answer is None else call.answer[1],
                         "took_s": None if call.end_at is None else call.end_at - call.start_at,
                         "outputs_during": int(np.sum(during)),
                         "beyond_delay_during_s": stats(node[during, 0] - delay) if np.any(during) else None,
                         "less_lateness_during_s": stats(net[during]) if np.any(during) and len(net) else None,
                         "callback_during_s": stats(node[during, 1]) if np.any(during) else None}}


def _cpu(pid):
    """s of CPU (user and system) process ``pid`` used so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=10.0, help="s of 1 kHz streams (default 10)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--qos", default="reliable", choices=("reliable", "sensor_data"))
    parser.add_argument("--pin", action="store_true", help="the node on a CPU of its own (the last), this process "
                        "and the sender on the others")
    parser.add_argument("--identify", type=float, metavar="AT", help="call ~/identify_payload once the node has "
                        "taken AT s of readings; its figures printed apart")
    parser.add_argument("--contact", type=float, nargs=2, metavar=("START", "SECONDS"),
                        help="a 15 N push on the tool over [START, START + SECONDS) s of the log")
    parser.add_argument("--busy", action="store_true", help="a busy loop at SCHED_IDLE beside the node (no fit): "
                        "what any computation beside it costs (with --pin, on the CPUs the node is not on)")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args(argv)
    r = measure(args.duration, args.seed, qos=args.qos, pin=args.pin, identify=args.identify, contact=args.contact,
                busy=args.busy)
    if args.json:
        print(json.dumps(r))
        return
    print(f"{r['sent']} readings and poses at {r['rate_hz']:.0f} Hz sent in {r['sent_in_s']:.2f} s ({r['qos']}); "
          f"the node received {r['received_by_node']}; outputs expected {r['expected']}, received {r['received']} "
          f"(dropped {r['dropped']}, in order: {r['in_order']})")
    pinned = "the node pinned to a CPU of its own; " if r["pinned"] else ""
    pinned += "a SCHED_IDLE busy loop beside it; " if r["busy"] else ""
    print(f"causal delay {r['causal_delay_s'] * 1e3:.1f} ms; {pinned}the node used "
          f"{r['node_cpu_s']:.1f} s of CPU over the "
          f"{r['duration_s']:g} s")
    print("| ms | p50 | p99 | max |")
    print("|---|---|---|---|")
    for key, name in (("stamp_to_publication_s", "stamp to publication (node)"),
                      ("beyond_delay_s", "beyond the causal delay"),
                      ("beyond_delay_after_1s_s", "the same after the first second"),
                      ("beyond_delay_less_lateness_s", "the same less the sender's lateness"),
                      ("callback_to_publication_s", "the node's callback to publication"),
                      ("stamp_to_subscriber_s", "stamp to this subscriber"),
                      ("publisher_lateness_s", "this process's lateness against its 1 kHz schedule")):
        s = r[key]
        print(f"| {name} | {s['p50'] * 1e3:.2f} | {s['p99'] * 1e3:.2f} | {s['max'] * 1e3:.2f} |")
    b = r["backlog"]
    print(f"backlog (readings waiting): p50 {b['p50']:.0f}, p99 {b['p99']:.0f}, max {b['max']:.0f}")
    if "identify" in r:
        i = r["identify"]
        print(f"~/identify_payload: {'succeeded' if i['success'] else 'refused or failed'} in "
              f"{i['took_s'] or float('nan'):.2f} s: {i['message']}")
        for key, name in (("beyond_delay_during_s", "beyond the causal delay"),
                          ("less_lateness_during_s", "the same less the sender's lateness"),
                          ("callback_during_s", "the node's callback to publication")):
            d = i[key]
            if d is not None:
                print(f"  the {i['outputs_during']} outputs meanwhile, {name}: p50 {d['p50'] * 1e3:.2f} ms, p99 "
                      f"{d['p99'] * 1e3:.2f} ms, max {d['max'] * 1e3:.2f} ms")
    for line in r["warnings"]:
        print(line)


if __name__ == "__main__":
    # stopped by SIGTERM (a timeout, a job killed): exit as for Ctrl-C, so that running_node stops the node
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))
    main()
