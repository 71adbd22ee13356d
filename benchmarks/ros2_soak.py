"""The ROS 2 node's soak under random faults: ``python benchmarks/ros2_soak.py [--minutes 10] [--sources pose
joints imu] [--seed 0]``.

For each motion source, the node (``fmscal ros2``, a subprocess) compensates the fault harness's replay of the UR5
carrying its tool (tests/ros2_rig.py: a sender process at 1 kHz over DDS, the truth of the contact wrench zero
throughout) for ``--minutes``, with faults drawn at random, one every 2-8 s: drops of 1, 2, 10 or 1000 messages on
either stream or both, pauses of both of 2 ms to 0.5 s, repeated readings, motion messages the node skips, one or two
motion messages off the motion (a glitch: a pose turned by a degree, its norm kept; a joint angle 0.01 rad off; an
IMU's rate 0.5 rad/s off). This process takes every output, its covariance and flag, and the node's diagnostics, and
samples the node's resident memory (``/proc/PID/status``, VmRSS) every 5 s. Printed per source:

- whether the node was alive at the end;
- the outputs, and those beyond 5 sd of the truth with no flag, a condition's or the contact's (the target: none),
  beside the count Gaussian noise at the stated sd gives on average (each output's channels, two-sided:
  ``2 Phi(-5)`` each; about 2 in ten minutes of six channels at 1 kHz, so a rare one is the noise's, not the
  node's), and the largest unflagged ``|z|``;
- the rms z-score over the outputs away from every fault (the window and the delay either side);
- the ledger: ``received = published + withheld + waiting`` (exact), and the readings lost; the withheld by cause;
- the outputs flagged as contact (the truth has none: the contact test's false alarms, or a fault's), and those
  beyond 5 sd;
- the unflagged outputs beyond 5 sd, and apart those flagged as contact, in runs (0.1 s apart or more): the first
  eight, each with its first stamp, its size and the last fault that reaches it;
- the resident memory at minute 2 and at the end, and its growth (the target: under 20 MB; with ``--minutes``
  under 2, minute 2 falls after the replay, in the wait for its last outputs); and its sample each minute (a
  leak grows steadily; a queue's or buffer's high-water mark steps up and stays).

The machine's load is not controlled. About ``--minutes`` plus a minute of setup per source. ``--json`` prints
the figures as one JSON object instead. ``--depth`` sets the node's ``queue_depth`` (default :data:`DEPTH`).

``--stalls S1 S2 ...`` measures what a stalled node costs in memory instead: for each source, the node is fed the
clean replay and stopped (SIGSTOP) for each ``S`` seconds in turn, 10 s apart, its resident memory printed before
each stop and 10 s after it resumes (the readings queued meanwhile taken and compensated). The stops share one
node: the memory is a high-water mark, so each figure is what the stop added beyond the marks before it.
"""

import argparse
import json
import os
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from scipy.stats import norm

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from fmscal.analysis import CAUSAL_DELAY, CAUSAL_WINDOW  # noqa: E402
from ros2_rig import (Listener, domain_id, node_log, running_node, sender_result, source_parameters,  # noqa: E402
                      start_sender, tool_calibration)

#: Every unflagged output within this many sd of the truth.
BOUND = 5.0
#: The resident memory's rise between two samples (5 s apart) printed as a step, MB.
MEMORY_STEP = 2.0
#: The node's input queues (deep: a loaded machine's pauses lose nothing; the overload is a test's).
DEPTH = 50000


def faults(duration, rng):
    """Random faults, one every 2-8 s from 1 s to the last second (the harness's ``schedule`` dicts)."""
    out, at = [], 1.0
    while True:
        at += float(rng.uniform(2.0, 8.0))
        if at > duration - 2.0:
            return out
        kind = rng.choice(["drop", "drop", "pause", "duplicate", "garbage", "glitch"])
        stream = str(rng.choice(["w", "m", "both"]))
        if kind == "drop":
            out.append(dict(kind="drop", stream=stream, at=round(at, 3), count=int(rng.choice([1, 2, 10, 1000]))))
        elif kind == "pause":
            out.append(dict(kind="pause", stream="both", at=round(at, 3),
                            seconds=float(rng.choice([0.002, 0.05, 0.5]))))
        elif kind == "duplicate":
            out.append(dict(kind="duplicate", stream="w", at=round(at, 3), count=int(rng.integers(1, 6))))
        elif kind == "glitch":
            out.append(dict(kind="glitch", stream="m", at=round(at, 3), count=int(rng.integers(1, 3))))
        else:
            out.append(dict(kind="garbage", stream="m", at=round(at, 3), count=int(rng.integers(1, 6))))
        at += 0.0 if kind != "drop" else out[-1]["count"] * 1e-3


def rss_mb(pid):
    """The resident memory of process ``pid``, MB (None once it is gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except FileNotFoundError:
        return None
    return None


def stalls(source, seconds, depth=DEPTH, seed=0):
    """The node's resident memory around stops of ``seconds`` (each in turn, SIGSTOP then SIGCONT, 10 s apart) on the
    clean replay of ``source``: a list of ``(stop s, MB before, MB 10 s after)``."""
    domain = domain_id(f"stalls-{source}-{seed}")
    duration = 20.0 + sum(s + 12.0 for s in seconds)
    plan = dict(domain=domain, source=source, rate=1000.0, duration=duration, seed=seed, faults=[])
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        cal = tool_calibration(Path(tmp) / "cal.json")
        with running_node(domain, f"calibration:={cal}", "qos:=reliable", f"queue_depth:={depth}",
                          *source_parameters(source)) as proc:
            listener = Listener(domain)
            try:
                listener.wait_for_node(proc)
                sender = start_sender(plan)
                time.sleep(10.0)
                for s in seconds:
                    before = rss_mb(proc.pid)
                    os.kill(proc.pid, signal.SIGSTOP)
                    try:
                        time.sleep(s)
                    finally:
                        os.kill(proc.pid, signal.SIGCONT)
                    time.sleep(10.0)
                    out.append((s, before, rss_mb(proc.pid)))
                sender_result(sender, duration + 120)
            finally:
                listener.close()
    return out


def soak(source, minutes, seed, depth=DEPTH):
    """One source's soak; a dict of its figures."""
    duration = 60.0 * minutes
    plan_faults = faults(duration, np.random.default_rng(seed))
    domain = domain_id(f"soak-{source}-{seed}")
    with tempfile.TemporaryDirectory() as tmp:
        cal = tool_calibration(Path(tmp) / "cal.json")
        plan = dict(domain=domain, source=source, rate=1000.0, duration=duration, seed=seed, faults=plan_faults)
        with running_node(domain, f"calibration:={cal}", "qos:=reliable", f"queue_depth:={depth}",
                          *source_parameters(source)) as proc:
            listener = Listener(domain)
            memory, stop = [], threading.Event()

            begun_wall = [None]

            def sample():
                begun, begun_wall[0] = time.monotonic(), time.time()
                while not stop.wait(5.0):
                    memory.append((time.monotonic() - begun, rss_mb(proc.pid)))
            try:
                listener.wait_for_node(proc)
                sampler = threading.Thread(target=sample, daemon=True)
                sampler.start()
                done = sender_result(start_sender(plan), duration + 600)
                epoch = done["epoch"]
                stamps = int(round(duration * 1000.0)) + 1
                quiet, seen, since = 60.0, None, time.monotonic()
                while time.monotonic() - since < quiet:          # every stamp taken or lost, or nothing new for 60 s
                    s = listener.status()
                    if s is not None and "received" in s and not int(s["backlog"]) and \
                            int(s["received"]) + int(s["lost"]) - int(s["withheld_duplicate"]) >= stamps and \
                            int(s["published"]) <= len(listener.contacts):
                        break
                    now_seen = None if s is None else (s.get("received"), s.get("published"), len(listener.contacts))
                    if now_seen != seen:
                        seen, since = now_seen, time.monotonic()
                    time.sleep(0.2)
                stop.set()
                alive = proc.poll() is None
                status = listener.status()
                t, wrench, sd, flagged = listener.outputs(epoch)
                contact = listener.contact_flags()
                behind = _behind_said(listener, begun_wall[0])
            finally:
                stop.set()
                listener.close()
            log = node_log(proc)
    z = wrench / sd
    worst = np.abs(z).max(axis=1)
    clean = ~flagged
    beyond = (worst > BOUND) & ~flagged & ~contact
    for f in plan_faults:
        length = f.get("count", 0) * 1e-3 + f.get("seconds", 0.0)
        clean &= ~((t > f["at"] - CAUSAL_WINDOW - CAUSAL_DELAY - 0.01) &
                   (t < f["at"] + length + CAUSAL_WINDOW + CAUSAL_DELAY + 0.05))
    withheld = sum(int(v) for k, v in status.items() if k.startswith("withheld_"))
    at2 = [m for s, m in memory if s >= 120.0 and m is not None]             # the sampler starts with the sender
    last = [m for _, m in memory if m is not None]
    return dict(source=source, minutes=minutes, faults=len(plan_faults), alive=alive, outputs=int(len(t)),
                unflagged_beyond=int(beyond.sum()), flagged=int(flagged.sum()), contact=int(contact.sum()),
                contact_beyond=int(((worst > BOUND) & ~flagged & contact).sum()),
                expected_beyond=float(z.size * 2 * norm.sf(BOUND)),
                largest_unflagged_z=float(worst[~flagged & ~contact].max()) if (~flagged & ~contact).any() else None,
                rms_z_clean=float(np.sqrt(np.mean(z[clean] ** 2))) if clean.any() else None,
                received=int(status["received"]), published=int(status["published"]), withheld=withheld,
                waiting=int(status["waiting"]), lost=int(status["lost"]),
                ledger_exact=int(status["received"]) == int(status["published"]) + withheld + int(status["waiting"]),
                rss_minute2_mb=at2[0] if at2 else None, rss_end_mb=last[-1] if last else None,
                rss_growth_mb=(last[-1] - at2[0]) if at2 and last else None,
                rss_by_minute_mb=[round(m, 1) for s, m in memory if m is not None and int(s) % 60 < 5],
                withheld_by_cause={k[len("withheld_"):]: int(v) for k, v in status.items()
                                   if k.startswith("withheld_") and int(v)},
                beyond=_beyond(t[beyond], plan_faults),
                memory_steps=[dict(t=round(s1, 1), mb=round(m1 - m0, 1))
                              for (_, m0), (s1, m1) in zip(memory, memory[1:])
                              if m0 is not None and m1 is not None and m1 - m0 > MEMORY_STEP],
                behind=behind,
                contact_runs=_beyond(t[(worst > BOUND) & ~flagged & contact], plan_faults),
                log_tail=None if alive else log[-2000:])


def _behind_said(listener, begun, most=8):
    """The node's liveness diagnostics that said "behind" (its compensation late; the first ``most`` in runs 1 s
    apart): their time, s from the memory sampler's start, the backlog and the message."""
    out = []
    for d in listener.diagnostics:
        live = [s for s in d.status if s.name.endswith(": compensation")]
        if not live or not live[0].message.startswith("behind"):
            continue
        at = d.header.stamp.sec + 1e-9 * d.header.stamp.nanosec - (begun or 0.0)
        if out and at - out[-1]["t_last"] < 1.5:
            out[-1]["t_last"] = at
            continue
        if len(out) == most:
            break
        values = {v.key: v.value for v in live[0].values}
        out.append(dict(t=round(at, 1), t_last=at, backlog=values.get("backlog"), message=live[0].message[:160]))
    for o in out:
        o["t_last"] = round(o["t_last"], 1)
    return out


def _beyond(times, plan_faults, most=8):
    """Outputs beyond the bound, in runs 0.1 s apart or more: for the first ``most`` runs, their first stamp, size,
    and the last fault that reaches it (begun before the stamp plus the causal delay: an output waits for the
    readings that long after it; its kind, stream and how long before the stamp, s, negative where after)."""
    out = []
    for k, at in enumerate(times):
        if k and at - times[k - 1] < 0.1:
            out[-1]["outputs"] += 1
            continue
        if len(out) == most:
            break
        before = [f for f in plan_faults if f["at"] <= at + CAUSAL_DELAY + 0.01]
        f = before[-1] if before else None
        out.append(dict(t=round(float(at), 3), outputs=1,
                        fault=None if f is None else f"{f['kind']} {f['stream']} {f.get('count', f.get('seconds'))}",
                        after_s=None if f is None else round(float(at - f["at"]), 3)))
    return out


def _mb(v):
    return "n/a" if v is None else f"{v:.1f} MB"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--sources", nargs="+", default=["pose", "joints", "imu"], choices=["pose", "joints", "imu"])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--depth", type=int, default=DEPTH, help=f"the node's queue_depth (default {DEPTH})")
    parser.add_argument("--stalls", type=float, nargs="+", metavar="S",
                        help="instead of the soak: the node stopped for each S seconds, its memory around each stop")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.stalls:
        for k, source in enumerate(args.sources):
            for s, before, after in stalls(source, args.stalls, args.depth, args.seed + k):
                print(f"{source}, queue_depth {args.depth}: stopped {s:g} s, resident memory {_mb(before)} before, "
                      f"{_mb(after)} 10 s after ({_mb(after - before)} more)")
        return
    results = [soak(source, args.minutes, args.seed + k, args.depth) for k, source in enumerate(args.sources)]
    if args.json:
        print(json.dumps(results))
        return
    for r in results:
        growth = _mb(r["rss_growth_mb"])
        print(f"{r['source']}: {r['minutes']:g} min, {r['faults']} faults; alive {r['alive']}; {r['outputs']} "
              f"outputs, {r['unflagged_beyond']} unflagged beyond {BOUND:g} sd (Gaussian noise at its stated sd "
              f"gives {r['expected_beyond']:.2g} on average; the largest unflagged |z| "
              f"{r['largest_unflagged_z']:.2f}), {r['flagged']} flagged; rms z "
              f"(clean) {r['rms_z_clean']:.3f}; received {r['received']} = published {r['published']} + withheld "
              f"{r['withheld']} + waiting {r['waiting']} ({'exact' if r['ledger_exact'] else 'NOT exact'}), lost "
              f"{r['lost']}; resident memory {_mb(r['rss_minute2_mb'])} at minute 2, {_mb(r['rss_end_mb'])} at the "
              f"end (growth {growth})")
        print(f"  resident memory each minute, MB: {r['rss_by_minute_mb']}")
        print(f"  its steps beyond {MEMORY_STEP:g} MB in 5 s: " + (", ".join(f"{m['mb']} MB by {m['t']} s"
                                                                   for m in r["memory_steps"]) or "none"))
        for b in r["behind"]:
            print(f"  behind from {b['t']} to {b['t_last']} s (backlog {b['backlog']}): {b['message']}")
        print(f"  withheld by cause: {r['withheld_by_cause']}; flagged contact {r['contact']} (the contact "
              f"test's false alarms; {r['contact_beyond']} of them beyond {BOUND:g} sd)")
        for b in r["beyond"]:
            print(f"  unflagged beyond {BOUND:g} sd from t = {b['t']} s ({b['outputs']} outputs), {b['after_s']} s "
                  f"after the fault {b['fault']}")
        for b in r["contact_runs"]:
            print(f"  flagged contact beyond {BOUND:g} sd from t = {b['t']} s ({b['outputs']} outputs), "
                  f"{b['after_s']} s after the fault {b['fault']}")
        if r["log_tail"]:
            print(r["log_tail"])


if __name__ == "__main__":
    main()
