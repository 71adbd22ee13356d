"""A 1 kHz sender of a ``spatial-arm`` log for the ROS 2 benchmarks (``benchmarks/ros2_latency.py``,
``benchmarks/ros2_floor.py``), run as a process of its own:
``python benchmarks/ros2_sender.py --domain D [--duration 10] [--seed 0] [--qos reliable] [--contact START SECONDS]``.

It publishes a ``WrenchStamped`` on ``/ft_sensor/wrench`` and a ``PoseStamped`` on ``/ft_sensor/pose`` for each
row of the log, stamped ``epoch + t`` (the rows' 1 kHz schedule, in wall-clock time), each when the wall clock
reaches its stamp. The process does nothing else: it subscribes to nothing (a subscriber's executor in the same
process took the interpreter's lock from the sender, making it late), builds every message before the first
is sent and runs with the garbage collector off, so that what it adds to a delay measured from the stamps is
its own lateness, measured and printed apart. It waits for a subscriber on both topics (and ``--settle`` s
more, for the subscribers to hear it) before it starts. Printed, as one JSON object on the last line: the
epoch, the rows sent and how late each went out (s after its stamp).
"""

import argparse
import gc
import json
import math
import os
import sys
import time

import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from geometry_msgs.msg import PoseStamped, WrenchStamped

from fmscal.plant import SPATIAL_SCENARIOS
from fmscal.plant.scenarios import contact_wrench, with_contact


def scenario_log(duration, seed, contact=None):
    """The benchmarks' log: ``spatial-arm`` for ``duration`` s (one row more: the last output's reading), its
    scenario and truth; ``contact`` ``(start, seconds)``: a 15 N push on the tool then
    (:func:`fmscal.plant.scenarios.with_contact`)."""
    scenario = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=duration + 0.001)
    log, truth, _ = scenario.generate(seed)
    if contact:
        log, _ = with_contact(log, truth.S_at(0.0), contact_wrench(), *contact)
    return scenario, log, truth


def messages(log):
    """A ``(WrenchStamped, PoseStamped)`` per row of ``log``, stamps unset."""
    out = []
    for w, pose in zip(log.w_hat.tolist(), log.pose.tolist()):
        wrench = WrenchStamped()
        wrench.header.frame_id = "ft_sensor"
        f, m = wrench.wrench.force, wrench.wrench.torque
        m.x, m.y, m.z, f.x, f.y, f.z = w
        msg = PoseStamped()
        msg.header.frame_id = "world"
        o, p = msg.pose.orientation, msg.pose.position
        o.w, o.x, o.y, o.z, p.x, p.y, p.z = pose
        out.append((wrench, msg))
    return out


def send(domain, duration=10.0, seed=0, qos="reliable", settle=0.5, timeout=30.0, contact=None):
    """Publish the log at 1 kHz once both topics have a subscriber; ``{"epoch", "sent", "lateness"}``."""
    _, log, _ = scenario_log(duration, seed, contact)
    rows = messages(log)
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node("fmscal_bench_sender", context=context)
    profile = QoSProfile(depth=2000, history=HistoryPolicy.KEEP_LAST,
                         reliability=ReliabilityPolicy.RELIABLE if qos == "reliable" else ReliabilityPolicy.BEST_EFFORT)
    wrench_pub = node.create_publisher(WrenchStamped, "/ft_sensor/wrench", profile)
    pose_pub = node.create_publisher(PoseStamped, "/ft_sensor/pose", profile)
    try:
        end = time.monotonic() + timeout
        while not (wrench_pub.get_subscription_count() and pose_pub.get_subscription_count()):
            if time.monotonic() > end:
                raise SystemExit("ros2_sender: no subscriber on /ft_sensor/wrench and /ft_sensor/pose")
            time.sleep(0.05)
        time.sleep(settle)
        # the stamps: a whole millisecond of the wall clock, a little ahead, plus the rows' times (exact ns)
        epoch_ms = math.ceil(time.time() * 1e3) + 50
        due = [(epoch_ms * 1_000_000 + int(round(t * 1e9))) for t in log.t.tolist()]
        for (wrench, pose), ns in zip(rows, due):
            sec, nanosec = divmod(ns, 1_000_000_000)
            wrench.header.stamp.sec = pose.header.stamp.sec = sec
            wrench.header.stamp.nanosec = pose.header.stamp.nanosec = nanosec
        lateness = []
        gc.disable()
        clock, sleep, publish_pose, publish_wrench = time.time_ns, time.sleep, pose_pub.publish, wrench_pub.publish
        for (wrench, pose), ns in zip(rows, due):
            while (wait := ns - clock()) > 0:
                sleep(min(wait, 500_000) * 1e-9)
            lateness.append(-wait)
            publish_pose(pose)
            publish_wrench(wrench)
        gc.enable()
        time.sleep(0.2)                         # the last messages delivered before the publishers go
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    return {"epoch": epoch_ms / 1e3, "sent": len(rows), "lateness": (np.array(lateness) * 1e-9).tolist()}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", 0)))
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--qos", default="reliable", choices=("reliable", "sensor_data"))
    parser.add_argument("--settle", type=float, default=0.5)
    parser.add_argument("--contact", type=float, nargs=2, metavar=("START", "SECONDS"),
                        help="a 15 N push on the tool over [START, START + SECONDS) s of the log")
    args = parser.parse_args(argv)
    result = send(args.domain, args.duration, args.seed, args.qos, args.settle, contact=args.contact)
    sys.stdout.write(json.dumps(result) + "\n")


if __name__ == "__main__":
    main()
