"""The floor under the ROS 2 node's delay: a bare rclpy publisher and subscriber, no fmscal between them.
``python benchmarks/ros2_floor.py [--duration 10] [--json]``.

The sender of ``benchmarks/ros2_latency.py`` (``benchmarks/ros2_sender.py``, a process of its own) publishes the
same 1 kHz wrench and pose streams over DDS on loopback, in a ROS domain of its own; this process takes them
(tests/ros2_rig.py's ``Taker``: a blocking wait on the subscriptions, every queued message taken, no executor) and
notes when each wrench arrived. Printed: the delay from a wrench's stamp to its arrival here (p50, p99, the
largest), the same less the sender's lateness against its schedule, and that lateness. The node's delay beyond
its causal filter's (``benchmarks/ros2_latency.py``) is this delivery plus the node's own work: this is what it
cannot go below on the same machine. About ``duration + 5`` s.
"""

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from geometry_msgs.msg import PoseStamped, WrenchStamped  # noqa: E402
from ros2_rig import Taker, domain_id  # noqa: E402

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

SENDER = Path(__file__).resolve().parent / "ros2_sender.py"


def stats(v):
    """p50, p99 and the largest of ``v``, or None where it is empty."""
    v = np.asarray(v, dtype=float)
    return {"p50": float(np.percentile(v, 50)), "p99": float(np.percentile(v, 99)), "max": float(np.max(v))} \
        if len(v) else None


def start_sender(domain, duration, seed=0, qos="reliable", contact=None):
    """The sender's process, started (it waits for its subscribers); ``contact`` ``(start, seconds)``: a push on
    the tool then."""
    extra = [] if not contact else ["--contact", *(str(v) for v in contact)]
    return subprocess.Popen([sys.executable, str(SENDER), "--domain", str(domain), "--duration", str(duration),
                             "--seed", str(seed), "--qos", qos, *extra], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST"))


def sender_result(proc, timeout):
    """The sender's JSON (``epoch``, ``sent``, ``lateness``), once it is done (killed if this process is stopped
    first)."""
    try:
        out, err = proc.communicate(timeout=timeout)
    except BaseException:
        proc.kill()
        raise
    if proc.returncode:
        raise SystemExit(f"the sender failed: {err[-2000:]}")
    return json.loads(out.strip().splitlines()[-1])


def measure(duration=10.0, seed=0, domain=None, qos="reliable"):
    """The bare pair's delivery delay and the sender's lateness (module docstring), as a dict."""
    domain = domain if domain is not None else domain_id(f"floor-{os.getpid()}")
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node("fmscal_floor", context=context)
    profile = QoSProfile(depth=2000, history=HistoryPolicy.KEEP_LAST,
                         reliability=ReliabilityPolicy.RELIABLE if qos == "reliable" else ReliabilityPolicy.BEST_EFFORT)
    wrenches, poses = [], []
    taker = Taker(node, context)
    taker.subscribe(WrenchStamped, "/ft_sensor/wrench", lambda m, at: wrenches.append((m.header.stamp, at)), profile)
    taker.subscribe(PoseStamped, "/ft_sensor/pose", lambda m, at: poses.append(at), profile)
    taker.start()
    try:
        sender = start_sender(domain, duration, seed, qos)
        sent = sender_result(sender, duration + 60)
        time.sleep(0.3)
    finally:
        taker.stop()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    epoch, lateness = sent["epoch"], np.array(sent["lateness"])
    stamps = np.array([s.sec + s.nanosec * 1e-9 for s, _ in wrenches])
    delay = np.array([at for _, at in wrenches]) - stamps
    rows = np.round((stamps - epoch) * 1e3).astype(int)
    return {"duration_s": duration, "qos": qos, "sent": sent["sent"], "received": len(wrenches),
            "poses_received": len(poses), "stamp_to_arrival_s": stats(delay),
            "stamp_to_arrival_less_lateness_s": stats(delay - lateness[np.clip(rows, 0, len(lateness) - 1)]),
            "publisher_lateness_s": stats(lateness)}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=10.0, help="s of 1 kHz streams (default 10)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--qos", default="reliable", choices=("reliable", "sensor_data"))
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args(argv)
    r = measure(args.duration, args.seed, qos=args.qos)
    if args.json:
        print(json.dumps(r))
        return
    print(f"{r['sent']} wrenches and poses at 1 kHz sent ({r['qos']}); received {r['received']} and "
          f"{r['poses_received']} here")
    print("| ms | p50 | p99 | max |")
    print("|---|---|---|---|")
    for key, name in (("stamp_to_arrival_s", "a wrench's stamp to its arrival (bare rclpy pair)"),
                      ("stamp_to_arrival_less_lateness_s", "the same less the sender's lateness"),
                      ("publisher_lateness_s", "the sender's lateness against its 1 kHz schedule")):
        s = r[key]
        print(f"| {name} | {s['p50'] * 1e3:.2f} | {s['p99'] * 1e3:.2f} | {s['max'] * 1e3:.2f} |")


if __name__ == "__main__":
    main()
