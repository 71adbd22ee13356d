"""The ROS 2 node under scripted faults (tests/ros2_rig.py's harness): lost, late, repeated and misstamped messages,
a second publisher, a killed and restarted sender, readings faster than the node follows, a busy process beside
it; over the pose, joint-state and IMU sources.

A sender process (``python tests/ros2_rig.py PLAN.json``) replays the UR5 carrying its tool (tests/robot_rig.py:
the payload's exact wrench plus the noise; the truth of the contact wrench is zero throughout) at 1 kHz over DDS,
with the plan's faults; this process takes the node's outputs, their covariances and flags, and its diagnostics.
Each case asserts:

- the node alive at the end;
- every published output within 5 sigma of the truth (each component, its covariance's sd), or flagged;
- the rms of those z-scores in [0.7, 1.4] over the clean stretches (away from every fault by the window and the
  delay);
- the output resumed within the window plus the delay after the streams return;
- every reading counted: ``received = published + withheld + waiting`` exactly, the outputs this process got
  as many as the node published, and the readings lost on the way (never received) counted as ``lost``;
- the log line and the diagnostics' state the fault calls for.

One run per source mixes the short faults (the fast suite); each long fault runs on its own (slow).
"""

import re
import time
from dataclasses import dataclass, field

import numpy as np
import pytest

from fmscal.analysis import CAUSAL_DELAY, CAUSAL_WINDOW
from ros2_rig import (CpuHog, Listener, domain_id, node_log, running_node, sender_result, source_parameters,
                     start_sender, tool_calibration)

#: s each case's log lasts beyond its last fault, and before its first.
MARGIN = 1.0
#: The output must resume this long after the streams return, s: the window and the delay (and a sample).
RESUME = CAUSAL_WINDOW + CAUSAL_DELAY + 0.002
#: Every unflagged output within this many sd of the truth.
BOUND = 5.0
#: The node's input queues in the harness (``queue_depth``): deep enough that a node behind a loaded machine's
#: other work loses no message (what it drops where they overflow is the overload case's, with the default).
DEPTH = 50000


@dataclass
class Case:
    """A harness run: its faults (tests/ros2_rig.py's ``schedule``), the log lines and diagnostics' states it
    calls for (regular expressions), and what else it needs."""

    faults: list
    logs: tuple = ()
    states: tuple = ()
    duration: float = 4.0
    rate: float = 1000.0
    hog: bool = False
    resumes: bool = True
    node_args: tuple = ()

    def end(self, fault, dt):
        """The stamp (s from the epoch) a fault's effect on the streams ends at."""
        kind = fault["kind"]
        if kind in ("drop", "duplicate", "garbage", "second"):
            return fault["at"] + fault["count"] * dt
        if kind in ("pause", "kill"):
            return fault["at"] + fault["seconds"]
        return fault["at"]


def _mixed(source):
    """The short faults, one after the other, on each stream."""
    bad = {"pose": "a pose whose quaternion is not of unit norm", "joints": "a joint state with a NaN",
           "imu": "an IMU sample with a NaN"}[source]
    return Case(faults=[dict(kind="drop", stream="w", at=1.0, count=1), dict(kind="drop", stream="both", at=1.5,
                                                                               count=2),
                        dict(kind="drop", stream="m", at=2.0, count=10), dict(kind="duplicate", stream="w", at=2.5,
                                                                              count=3),
                        dict(kind="pause", stream="both", at=3.0, seconds=0.05),
                        dict(kind="garbage", stream="m", at=3.5, count=5),
                        dict(kind="drop", stream="both", at=4.0, count=1000)],
                logs=(r"a gap of 0\.00[23] s", r"twice: the second dropped", bad, r"the window restarted"),
                states=(r"^restarting$",), duration=6.5)


SLOW = {
    "drop-1000-readings": Case([dict(kind="drop", stream="w", at=1.5, count=1000)], (r"the window restarted",),
                               (r"^restarting$",)),
    "drop-1000-motion": Case([dict(kind="drop", stream="m", at=1.5, count=1000)], (r"motion stale",),
                             (r"^motion stale$",)),
    "pause-2ms": Case([dict(kind="pause", stream="both", at=1.5, seconds=0.002)]),
    "pause-0.5s": Case([dict(kind="pause", stream="both", at=1.5, seconds=0.5)]),
    "pause-4s": Case([dict(kind="pause", stream="both", at=1.5, seconds=4.0)], duration=7.0),
    "pause-readings": Case([dict(kind="pause", stream="w", at=1.5, seconds=0.5)]),
    "pause-motion": Case([dict(kind="pause", stream="m", at=1.5, seconds=0.5)]),
    "back-both": Case([dict(kind="back", stream="both", at=1.5, seconds=0.5)], (r"stepped back",),
                      (r"^restarting$",)),
    "back-readings": Case([dict(kind="back", stream="w", at=1.5, seconds=1.0)],
                          (r"the streams no longer share a clock",), (r"^streams apart$",), resumes=False),
    "back-motion": Case([dict(kind="back", stream="m", at=1.5, seconds=0.5)], (r"the motion's stamps stepped back",),
                        (r"^motion stale$",), resumes=False),
    "duplicate-motion": Case([dict(kind="duplicate", stream="m", at=1.5, count=5)]),
    "second-readings": Case([dict(kind="second", stream="w", at=1.5, count=800, seconds=0.0)],
                            (r"2 publishers on /ft_sensor/wrench",)),
    "second-motion": Case([dict(kind="second", stream="m", at=1.5, count=800, seconds=3.0)],
                          (r"2 publishers on /motion",)),
    "kill-sender": Case([dict(kind="kill", stream="both", at=1.5, seconds=1.5)], (r"the window restarted",),
                        duration=5.0),
    "5kHz": Case([], (r"1 in 5 compensated",), rate=5000.0, duration=3.0),
    "cpu-hog": Case([dict(kind="drop", stream="both", at=1.5, count=2)], (r"a gap of",), hog=True, duration=5.0),
}


@dataclass
class Run:
    """What a harness run gave: the outputs, the newest diagnostics, the log, what the sender sent."""

    t: np.ndarray
    wrench: np.ndarray
    sd: np.ndarray
    flagged: np.ndarray
    status: dict
    messages: list
    inputs: list
    log: str
    sent: dict
    alive: bool
    fates: dict
    live: list
    epochs: list = field(default_factory=list)


def _run(request, source, case, tmp_path):
    """Start the node, run the case's sender (twice for a kill), take everything; a :class:`Run`."""
    domain = domain_id(request.node.name)
    cal = tool_calibration(tmp_path / "cal.json")
    plan = dict(domain=domain, source=source, rate=case.rate, duration=case.duration, seed=3, faults=case.faults)
    hog = CpuHog() if case.hog else None
    if hog is not None:
        hog.__enter__()
    try:
        depth = () if any(a.startswith("queue_depth") for a in case.node_args) else (f"queue_depth:={DEPTH}",)
        with running_node(domain, f"calibration:={cal}", "qos:=reliable", *source_parameters(source), *depth,
                          *case.node_args) as proc:
            listener = Listener(domain)
            try:
                listener.wait_for_node(proc)
                first = start_sender(plan)
                done = sender_result(first, 120 + case.duration)
                sent = {} if done is None else dict(done["sent"])
                epochs = [] if done is None else [done["epoch"]]
                kill = next((f for f in case.faults if f["kind"] == "kill"), None)
                if kill is not None:                  # the restarted sender: the same clock, the rows due by then
                    epoch = _epoch_of(listener)
                    restart = int(round((kill["at"] + kill["seconds"]) * case.rate))
                    second = start_sender(dict(plan, start=restart, epoch=epoch, name="fmscal_harness_restarted"))
                    done = sender_result(second, 120 + case.duration)
                    sent = {k: sent.get(k, 0) + v for k, v in done["sent"].items()}
                    epochs.append(done["epoch"])
                # every output the node published has come (its diagnostics count them), and nothing more comes
                listener.wait_for(lambda: _done(listener, case), 120)
                alive = proc.poll() is None
                status = listener.status()
                epoch = epochs[0] if epochs else _epoch_of(listener)
                t, wrench, sd, flagged = listener.outputs(epoch)
                fates = listener.fates(epoch)
                messages, inputs, live = listener.messages(0), listener.messages(1), listener.messages(2)
            finally:
                listener.close()
            log = node_log(proc)
    finally:
        if hog is not None:
            hog.__exit__(None, None, None)
    return Run(t, wrench, sd, flagged, status, messages, inputs, log, sent, alive, fates, live, epochs)


def _stamps(case):
    """The readings' stamps a run's log holds (each sent once at least), where the faults keep them countable (no
    second publisher, no step back, no restarted sender); else None."""
    if any(f["kind"] in ("second", "back", "kill") for f in case.faults):
        return None
    return int(round(case.duration * case.rate)) + 1


def _done(listener, case, quiet=3.0):
    """Whether every reading has been taken and every output has come: each of the log's stamps received or
    counted as lost (where countable: :func:`_stamps`; else nothing new for ``quiet`` s), none waiting for the
    motion, every output the node counts here with its covariance."""
    s = listener.status()
    if s is None or "received" not in s or int(s["backlog"]) or not \
            int(s["published"]) == len(listener.contacts) == len(listener.covariances):
        return False
    stamps = _stamps(case)
    if stamps is not None:
        return int(s["lost"]) + int(s["received"]) - int(s["withheld_duplicate"]) >= stamps
    now, seen = time.monotonic(), (s["received"], s["published"])
    if getattr(listener, "_seen", None) != seen:
        listener._seen, listener._since = seen, now
    return now - listener._since > quiet


def _epoch_of(listener):
    """The stamps' epoch of a run whose first sender was killed before it said (its first output's second)."""
    first = listener.contacts[0].header.stamp if listener.contacts else None
    return None if first is None else float(first.sec)


def _check(run, case, source):
    """The case's assertions (module docstring)."""
    dt = 1.0 / case.rate
    where = f"{source}: {run.log[-3000:]}"
    assert run.alive, f"the node died: {where}"
    assert len(run.t), f"no output: {where}"
    z = run.wrench / run.sd
    worst = np.abs(z).max(axis=1)
    bad = (worst > BOUND) & ~run.flagged
    assert not bad.any(), f"{bad.sum()} unflagged outputs beyond {BOUND} sd, at {run.t[bad][:5]}, z {worst[bad][:5]}"
    clean = np.ones(len(run.t), bool)
    for f in case.faults:
        end = case.end(f, dt) if f["kind"] != "back" else np.inf
        clean &= ~((run.t > f["at"] - CAUSAL_WINDOW - CAUSAL_DELAY - 0.01) & (run.t < end + RESUME + 0.05))
    clean &= ~run.flagged
    assert clean.sum() > 500, (clean.sum(), where)
    rms = float(np.sqrt(np.mean(z[clean] ** 2)))
    assert 0.7 <= rms <= 1.4, f"rms z {rms:.3f} over the clean stretches"
    if case.resumes:
        for f in case.faults:
            end = case.end(f, dt)
            if f["kind"] == "back":
                end -= f["seconds"]                    # the stamps return where they stepped back to
            _resumed(run, f, end, dt)
    s = run.status
    withheld = sum(int(v) for k, v in s.items() if k.startswith("withheld_"))
    assert int(s["received"]) == int(s["published"]) + withheld + int(s["waiting"]), s
    assert int(s["published"]) == len(run.t), (s["published"], len(run.t))
    if _stamps(case) is not None:                     # each stamp received once, repeated, or counted as lost
        assert int(s["lost"]) + int(s["received"]) - int(s["withheld_duplicate"]) == _stamps(case), (s, run.sent)
    for line in case.logs:
        assert re.search(line, run.log), f"no log line {line!r}: {where}"
    for state in case.states:
        assert any(re.search(state, m) for m in run.messages), (state, sorted(set(run.messages)))
    if any(f["kind"] == "second" for f in case.faults):
        assert any("publishers" in m for m in run.inputs), sorted(set(run.inputs))


def _resumed(run, fault, end, dt):
    """The output resumed within :data:`RESUME` of the first reading the node took after ``end``: a reading
    published there, or, where none is, another cause the node counted and said for one of them (the motion
    stale, its stamps apart, ...; a loaded machine's late delivery) or readings lost there on the way. The
    window's refilling (``window``, ``restart``, ``gap``) is no excuse."""
    after = sorted(k for k in run.fates if k >= end - 1e-9)
    assert after, f"no reading taken after {fault} ended (at {end:.3f} s)"
    first = after[0]
    near = [k for k in after if k <= first + RESUME + 1e-9]
    published = [k for k in near if not run.fates[k].startswith("withheld")]
    others = {run.fates[k] for k in near if run.fates[k].startswith("withheld")} - \
        {f"withheld: {c}" for c in ("window", "restart", "gap")}
    lost = len(near) < int(round(RESUME / dt))
    assert published or others or lost, \
        f"no output within {RESUME:g} s of {first:.3f} s, after {fault}: {[run.fates[k] for k in near][:5]}"


@pytest.mark.parametrize("source", ["pose", "joints", "imu"])
def test_short_faults(request, source, tmp_path):
    """Lost messages (1, 2, 10 in a row; 1 s of both streams), repeated readings, a 50 ms pause, skipped motion
    messages, one after the other: the node up, every output right within 5 sd, each loss counted and said."""
    case = _mixed(source)
    _check(_run(request, source, case, tmp_path), case, source)


@pytest.mark.slow
@pytest.mark.parametrize("source", ["pose", "joints", "imu"])
@pytest.mark.parametrize("name", sorted(SLOW))
def test_long_faults(request, name, source, tmp_path):
    """Each long fault on its own (module docstring)."""
    case = SLOW[name]
    _check(_run(request, source, case, tmp_path), case, source)
