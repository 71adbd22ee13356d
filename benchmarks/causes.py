"""A moving offset and a tilted gravity named in 3D (issue 46 item 6): ``python benchmarks/causes.py [SEEDS]
[DURATION] [--cost] [--clean START STOP [SCENARIO] [DURATION]]``.

For each seed (default 0-4, 20 s) of ``spatial-arm`` and ``spatial-mocap``: the clean log, a ramp of 10 noise
sd on fx over the log, the issue's ramp of 2 noise sd (0.1 N, ``ramp2``), and the base tilted 3 degrees about x,
each through :func:`fmscal.observers.diagnostics.fit_causes` (the mocap log aligned at its known latency).
Printed per log: the offset test's and the tilt test's p-values, the tilt found and its sd, the offset row of the
smallest p-value, its spread over its residual's rms (eq. (C4)), and whether a cause is named.
tests/test_causes.py asserts the naming on ``spatial-arm`` and MuJoCo's logs; this prints the figures the
docs quote (status.md, "Causes named in 3D").

``--clean START STOP [SCENARIO] [DURATION]``: eq. (C4) on clean logs (``spatial-mocap`` and 20 s by default), seeds
``START`` to ``STOP - 1`` (its false-alarm side; on ``spatial-mocap`` the poses' noise makes the test find offsets
moving): per seed and in sum, how many are named by each of (C4)'s arms, how often each of the second arm's
conditions holds alone, and how many are named tilted.

``--cost``: ``calibrate``'s CPU on a 60 s 1 kHz ``spatial-arm`` log with and without the ``"causes"`` check,
after a warm-up, three alternated runs each in one process, and the ratio of the best of each.
"""

import sys
import time

import numpy as np

from fmscal.analysis import calibrate
from fmscal.observers.diagnostics import fit_causes
from fmscal.plant import SPATIAL_SCENARIOS, SpatialModel


def _tilted(degrees):
    a = np.radians(degrees)
    return (0.0, 9.81 * np.sin(a), -9.81 * np.cos(a))


def naming(seeds, duration):
    for name in ("spatial-arm", "spatial-mocap"):
        base = SPATIAL_SCENARIOS[name].with_(duration=duration)
        model = SpatialModel(base.payload)
        for seed in seeds:
            for kind in ("clean", "ramp", "ramp2", "tilt"):
                scenario = base.with_(gravity=_tilted(3.0)) if kind == "tilt" else base
                log, _, _ = scenario.generate(seed)
                if kind.startswith("ramp"):
                    sd = 2 if kind == "ramp2" else 10
                    log.w_hat[:, 3] += sd * scenario.force_sd * (log.t - log.t[0]) / (log.t[-1] - log.t[0])
                c = fit_causes(log.shift_poses(scenario.latency), model)
                print(f"{name:14s} seed {seed} {kind:5s} offset p {c.offset.p_value:8.2g} ({_row(c, model)})  tilt p "
                      f"{c.gravity.p_value:8.2g}  tilt {c.gravity.tilt_deg:5.2f} +- {c.gravity.std_deg:4.2f} deg  "
                      f"named: {bool(c.warnings)}")


def _row(c, model):
    """The offset row of the smallest p-value and its spread (eq. (C4)); "not tested" on a log too short."""
    if c.row_p_values is None:
        return "not tested"
    row = int(np.argmin(c.row_p_values))
    return f"{model.wrench_names[row]}, spread {c.spreads[row]:4.2f}"


def clean(start, stop, name="spatial-mocap", duration=20.0):
    """Eq. (C4) on clean logs (seeds ``start`` to ``stop - 1``, aligned at their latency): per seed the row of the
    smallest p-value, its spread, and whether it is named; then how many are named by each of (C4)'s arms, and how
    often each of the second arm's two conditions holds alone."""
    from fmscal.observers.diagnostics._causes import CAUSE_SIGNIFICANCE, DECISIVE, DECISIVE_SIZE, MOVING_SIZE
    base = SPATIAL_SCENARIOS[name].with_(duration=duration)
    model = SpatialModel(base.payload)
    counts = dict(first=0, second=0, p_alone=0, spread_alone=0, tilted=0, untested=0)
    for seed in range(start, stop):
        log, _, _ = base.generate(seed)
        c = fit_causes(log.shift_poses(base.latency), model)
        if c.row_p_values is None:
            print(f"{name} seed {seed}: not tested")
            counts["untested"] += 1
            continue
        counts["tilted"] += bool(c.gravity.tilted)
        p, spread = c.row_p_values, c.spreads
        significant = p < CAUSE_SIGNIFICANCE / 2
        first = significant & (spread >= MOVING_SIZE)
        second = significant & (p < DECISIVE) & (spread >= DECISIVE_SIZE) & ~first
        counts["first"] += bool(first.any())
        counts["second"] += bool(second.any())
        counts["p_alone"] += bool((significant & (p < DECISIVE) & (spread < DECISIVE_SIZE)).any())
        counts["spread_alone"] += bool((significant & (p >= DECISIVE) & (spread >= DECISIVE_SIZE)).any())
        print(f"{name} seed {seed}: offset p {c.offset.p_value:8.2g} ({_row(c, model)}), largest spread "
              f"{spread.max():4.2f} at p {p[int(np.argmax(spread))]:.2g}, named: {not c.offset.constant}", flush=True)
    print(f"{name}, {duration:g} s, seeds {start}-{stop - 1}: named by (C4)'s first arm {counts['first']}, by its "
          f"second alone {counts['second']}; p below {DECISIVE:g} with a spread under {DECISIVE_SIZE:g} "
          f"{counts['p_alone']}, a significant spread of {DECISIVE_SIZE:g} or more at p above {DECISIVE:g} "
          f"{counts['spread_alone']}; gravity named tilted {counts['tilted']}; too short to test {counts['untested']}")


def cost():
    scenario = SPATIAL_SCENARIOS["spatial-arm"]
    log, _, _ = scenario.generate(0)
    on = SpatialModel.calibration_checks
    off = tuple(c for c in on if c != "causes")
    times = {"on": [], "off": []}
    calibrate(log, scenario.payload)                                    # warm-up, not counted
    try:
        for rep in range(3):
            for name, checks in (("off", off), ("on", on)) if rep % 2 == 0 else (("on", on), ("off", off)):
                SpatialModel.calibration_checks = checks
                t0 = time.process_time()
                calibrate(log, scenario.payload)
                times[name].append(time.process_time() - t0)
                print(f"causes {name:3s}: {times[name][-1]:.2f} s CPU")
    finally:
        SpatialModel.calibration_checks = on
    print(f"ratio on/off (best of 3 each): {min(times['on']) / min(times['off']):.2f}")


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if a != "--cost"]
    if "--cost" in sys.argv[1:]:
        cost()
    elif args and args[0] == "--clean":
        clean(int(args[1]), int(args[2]), *args[3:4], *(float(a) for a in args[4:5]))
    else:
        naming(range(int(args[0]) if args else 5), float(args[1]) if len(args) > 1 else 20.0)
