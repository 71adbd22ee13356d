"""A moving offset and a tilted gravity named in 3D (issue 46 item 6): ``python benchmarks/causes.py [SEEDS]
[DURATION] [--cost] [--clean START STOP [SCENARIO] [DURATION]] [--zscores START STOP [SCENARIO] [DURATION]]
[--payload [SEEDS] [DURATION]] [--calibrate START STOP [DURATION]] [--gain START STOP [DURATION]]``.

For each seed (default 0-4, 20 s) of ``spatial-arm`` and ``spatial-mocap``: the clean log, a ramp of 10 noise
sd on fx over the log, the issue's ramp of 2 noise sd (0.1 N, ``ramp2``), and the base tilted 3 degrees about x,
each through :func:`fmscal.observers.diagnostics.fit_causes` (the mocap log aligned at its known latency).
Printed per log: the offset test's and the tilt test's p-values, the tilt found and its sd, the offset row of the
smallest p-value, its spread over its residual's rms (eq. (C4)), and whether a cause is named; per scenario, how many
logs of each kind are named moving, tilted, and tilted beside an offset (ambiguous), and how many are named
nothing but a cause suggested (:attr:`fmscal.observers.diagnostics.Causes.suggestion`).
tests/test_causes.py asserts the naming on ``spatial-arm`` and MuJoCo's logs; this prints the figures the
docs quote (status.md, "Causes named in 3D").

``--clean START STOP [SCENARIO] [DURATION]``: eq. (C4) on clean logs (``spatial-mocap`` and 20 s by default), seeds
``START`` to ``STOP - 1`` (its false-alarm side, on the noisiest poses): per seed and in sum, how many are named
moving, how often each of (C4)'s two conditions holds alone, how many are named tilted, and how many suggest a
cause.

``--zscores START STOP [SCENARIO] [DURATION]``: on clean logs (``spatial-mocap`` and 10 s by default), the
offset's levels over their sd and the two tests' small p-values, with eq. (C1)'s payload columns from the motion
smoothed over the reference fit's window and over ``PAYLOAD_WINDOW``: the poses' noise in those columns.

``--payload [SEEDS] [DURATION]``: clean logs (seeds 0-9, 10 s by default) fitted with the payload given wrong
(the mass 3 % high, the centre of mass 1 cm along x or 3 cm along z off, IXX 1.5 times, the inertia 1.3 times),
which eq. (C1)'s payload columns and ``S`` take up: how many are named moving or tilted, or suggest a cause.

``--calibrate START STOP [DURATION]``: the same kinds (10 s by default) through ``calibrate`` as a user runs it,
at the latency it estimates: per kind, how many runs are converged outside 4 of their sds, and of those not
converged how many name a cause, suggest one (:attr:`fmscal.observers.diagnostics.Causes.suggestion`), or
neither.

``--gain START STOP [DURATION]``: logs whose offset moves (the ramp on fx, a ramp and a step on fz) or whose gain
does (fz's alone, every channel's as ``spatial-drift``), 20 s by default: how many are named a moving offset, a
moving gain, both, or with a row the log cannot tell (eq. (C5) of ``fmscal.observers.diagnostics._causes``).

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


def _case(base, kind, seed):
    """The scenario, log and truth of ``kind``: "clean", "ramp" (10 noise sd on fx over the log), "ramp2" (2 sd,
    the issue's 0.1 N), "tilt" (the base tilted 3 degrees about x), "rampz" (10 sd on fz), "stepz" (a step of 10 sd
    on fz a third into the log), "gainz" (the reading's gain on fz falling 5 % over the log about its offset: ``S``'s
    gain rising 5.3 %) or "drift" (every channel's gain drifting 5 %, as ``spatial-drift``)."""
    scenario = base.with_(gravity=_tilted(3.0)) if kind == "tilt" else \
        base.with_(drift=0.05) if kind == "drift" else base
    log, truth, _ = scenario.generate(seed)
    u = (log.t - log.t[0]) / (log.t[-1] - log.t[0])
    if kind in ("ramp", "ramp2"):
        log.w_hat[:, 3] += (2 if kind == "ramp2" else 10) * scenario.force_sd * u
    elif kind == "rampz":
        log.w_hat[:, 5] += 10 * scenario.force_sd * u
    elif kind == "stepz":
        log.w_hat[:, 5] += 10 * scenario.force_sd * (u > 1 / 3)
    elif kind == "gainz":
        log.w_hat[:, 5] = truth.offset[5] + (log.w_hat[:, 5] - truth.offset[5]) * (1 - 0.05 * u)
    return scenario, log, truth


def naming(seeds, duration):
    for name in ("spatial-arm", "spatial-mocap"):
        base = SPATIAL_SCENARIOS[name].with_(duration=duration)
        model = SpatialModel(base.payload)
        counts = {kind: [0, 0, 0, 0] for kind in ("clean", "ramp", "ramp2", "tilt")}
        for seed in seeds:
            for kind in ("clean", "ramp", "ramp2", "tilt"):
                scenario, log, _ = _case(base, kind, seed)
                c = fit_causes(log.shift_poses(scenario.latency), model)
                counts[kind][0] += not c.offset.constant
                counts[kind][1] += bool(c.gravity.tilted)
                counts[kind][2] += bool(c.gravity.ambiguous)
                counts[kind][3] += bool(c.suggestion) and not c.warnings
                print(f"{name:14s} seed {seed} {kind:5s} offset p {c.offset.p_value:8.2g} ({_row(c, model)})  tilt p "
                      f"{c.gravity.p_value:8.2g}  tilt {c.gravity.tilt_deg:5.2f} +- {c.gravity.std_deg:4.2f} deg  "
                      f"named: {bool(c.warnings)}{', suggested' if c.suggestion and not c.warnings else ''}")
        print(f"{name}, {duration:g} s, {len(seeds)} seeds, named moving / tilted (of which beside an offset, "
              "ambiguous) / not named but suggested: " + ", ".join(
                  f"{kind} {moving} / {tilted} ({ambiguous}) / {suggested}"
                  for kind, (moving, tilted, ambiguous, suggested) in counts.items()), flush=True)


def _row(c, model):
    """The offset row of the smallest p-value and its spread (eq. (C4)); "not tested" on a log too short."""
    if c.row_p_values is None:
        return "not tested"
    row = int(np.argmin(c.row_p_values))
    return f"{model.wrench_names[row]}, spread {c.spreads[row]:4.2f}"


def clean(start, stop, name="spatial-mocap", duration=20.0):
    """Eq. (C4) on clean logs (seeds ``start`` to ``stop - 1``, aligned at their latency): per seed the row of the
    smallest p-value, its spread, and whether it is named; then how many are named, how often each of (C4)'s two
    conditions holds alone, and how many are named tilted."""
    from fmscal.observers.diagnostics._causes import CAUSE_SIGNIFICANCE, MOVING_SIZE
    base = SPATIAL_SCENARIOS[name].with_(duration=duration)
    model = SpatialModel(base.payload)
    counts = dict(named=0, p_alone=0, spread_alone=0, tilted=0, untested=0, suggested=0)
    for seed in range(start, stop):
        log, _, _ = base.generate(seed)
        c = fit_causes(log.shift_poses(base.latency), model)
        if c.row_p_values is None:
            print(f"{name} seed {seed}: not tested")
            counts["untested"] += 1
            continue
        counts["tilted"] += bool(c.gravity.tilted)
        counts["suggested"] += bool(c.suggestion) and not c.warnings
        p, spread = c.row_p_values, c.spreads
        significant, large = p < CAUSE_SIGNIFICANCE / 2, spread >= MOVING_SIZE
        counts["named"] += bool((significant & large).any())
        counts["p_alone"] += bool((significant & ~large).any())
        counts["spread_alone"] += bool((~significant & large).any())
        print(f"{name} seed {seed}: offset p {c.offset.p_value:8.2g} ({_row(c, model)}), largest spread "
              f"{spread.max():4.2f} at p {p[int(np.argmax(spread))]:.2g}, tilt p {c.gravity.p_value:8.2g}, "
              f"named: {not c.offset.constant}", flush=True)
    print(f"{name}, {duration:g} s, seeds {start}-{stop - 1}: offset named moving {counts['named']}; a row "
          f"significant with a spread under {MOVING_SIZE:g} {counts['p_alone']}, a spread of {MOVING_SIZE:g} or more "
          f"not significant {counts['spread_alone']}; gravity named tilted {counts['tilted']}; nothing named but a "
          f"cause suggested {counts['suggested']}; too short to test {counts['untested']}")


def zscores(start, stop, name="spatial-mocap", duration=10.0):
    """The tests' calibration on clean logs (seeds ``start`` to ``stop - 1``), with eq. (C1)'s payload columns from
    the motion smoothed over the reference fit's window (0.2 s) and over ``PAYLOAD_WINDOW``: the rms over seeds and
    entries of the offset's levels over their sd (1 where the covariance holds them), and how many logs' gravity and
    offset tests fall below 0.05 and 0.01 (about 5 % and 1 % where calibrated, fewer where conservative)."""
    from fmscal.observers.diagnostics import _causes
    base = SPATIAL_SCENARIOS[name].with_(duration=duration)
    model = SpatialModel(base.payload)
    kept = _causes.PAYLOAD_WINDOW
    try:
        for window in (0.2, kept):
            _causes.PAYLOAD_WINDOW = window
            z, gravity_p, offset_p, named = [], [], [], 0
            for seed in range(start, stop):
                c = fit_causes(base.generate(seed)[0].shift_poses(base.latency), model)
                if c.levels is None:
                    continue
                z.append((c.levels / c.levels_std).ravel())
                gravity_p.append(c.gravity.p_value)
                offset_p.append(c.offset.p_value)
                named += bool(c.warnings)
            gravity_p, offset_p = np.array(gravity_p), np.array(offset_p)
            below = [int((p < level).sum()) for p in (gravity_p, offset_p) for level in (0.05, 0.01)]
            print(f"{name}, {duration:g} s, seeds {start}-{stop - 1}, payload columns over {window:g} s: offset "
                  f"levels' rms z {np.sqrt(np.mean(np.square(z))):.2f}; gravity p below 0.05 / 0.01: {below[0]} / "
                  f"{below[1]}, offset p {below[2]} / {below[3]}, of {len(offset_p)}; named {named}", flush=True)
    finally:
        _causes.PAYLOAD_WINDOW = kept


def payload_given_wrong(seeds, duration):
    """The payload given wrong, which eq. (C1)'s payload columns take up (or ``S`` absorbs): named neither moving nor
    tilted. Per scenario and error, over ``seeds`` of clean logs of ``duration`` s, how many are named each."""
    import dataclasses
    for name in ("spatial-arm", "spatial-mocap"):
        base = SPATIAL_SCENARIOS[name].with_(duration=duration)
        payload = base.payload
        inertia = np.asarray(payload.inertia, dtype=float)
        wrong = {"mass +3 %": dataclasses.replace(payload, mass=payload.mass * 1.03),
                 "com +1 cm x": dataclasses.replace(payload, com=tuple(np.add(payload.com, (0.01, 0.0, 0.0)))),
                 "com +3 cm z": dataclasses.replace(payload, com=tuple(np.add(payload.com, (0.0, 0.0, 0.03)))),
                 "IXX x1.5": dataclasses.replace(payload, inertia=tuple(inertia * np.r_[1.5, 1, 1, 1, 1, 1])),
                 "inertia x1.3": dataclasses.replace(payload, inertia=tuple(inertia * 1.3))}
        logs = [base.generate(seed)[0].shift_poses(base.latency) for seed in seeds]
        counts = []
        for label, given in wrong.items():
            found = [fit_causes(log, SpatialModel(given)) for log in logs]
            counts.append(f"{label} {sum(not c.offset.constant for c in found)} / "
                          f"{sum(bool(c.gravity.tilted) for c in found)} / "
                          f"{sum(bool(c.suggestion) and not c.warnings for c in found)}")
        print(f"{name}, {duration:g} s, {len(logs)} seeds, the payload given wrong, named moving / tilted / "
              "suggested: "
              + ", ".join(counts), flush=True)


def through_calibrate(start, stop, duration=10.0):
    """The issue's kinds (clean, the ramps of 10 and 2 noise sd on fx, the base tilted 3 degrees) through
    ``calibrate`` as a user runs it (its own latency estimate; seeds ``start`` to ``stop - 1``, both scenarios): per
    run converged or not, the largest ``|S_hat - S| / S_std`` and why; per kind, how many are converged outside 4 of
    their sds (confident and wrong), named, suggested, or neither (said only as not settling or a misfit)."""
    import warnings
    for name in ("spatial-arm", "spatial-mocap"):
        base = SPATIAL_SCENARIOS[name].with_(duration=duration)
        for kind in ("clean", "ramp", "ramp2", "tilt"):
            counts = dict(wrong=0, converged=0, named=0, suggested=0, neither=0)
            for seed in range(start, stop):
                scenario, log, truth = _case(base, kind, seed)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    cal = calibrate(log, scenario.payload)
                z = float(np.max(np.abs((np.asarray(cal.S) - truth.S_at(log.t[-1])) / np.asarray(cal.S_std))))
                why = cal.why_unconverged or ""
                counts["converged"] += bool(cal.converged)
                counts["wrong"] += bool(cal.converged and z > 4)
                first = cal.warnings[0] if cal.warnings else ""       # a tilt alone keeps a misfit's why
                suggested = "may move" in why or "may not be" in why or "poses give, gravity" in why or \
                    "poses give, or gravity" in why or first.startswith(("the sensor's offset may move",
                                                                         "gravity's direction may not be"))
                named = not cal.converged and not suggested and \
                    any(cause in why for cause in ("offset moves", "gain move", "gravity's"))
                counts["named"] += named
                counts["suggested"] += suggested
                counts["neither"] += not cal.converged and not named and not suggested
                print(f"{name:14s} seed {seed} {kind:5s} converged {str(cal.converged):5s} max |z| {z:5.1f}  "
                      f"{why}", flush=True)
            print(f"{name}, {duration:g} s, seeds {start}-{stop - 1}, {kind}: converged {counts['converged']} "
                  f"(outside 4 sds {counts['wrong']}); not converged: a cause named {counts['named']}, suggested "
                  f"{counts['suggested']}, neither {counts['neither']}", flush=True)


def gain_or_offset(start, stop, duration=20.0):
    """Eq. (C5) on logs whose offset or gain moves (seeds ``start`` to ``stop - 1``, both scenarios, aligned at their
    latency): per kind ("ramp" and "rampz", "stepz": the offset; "gainz", "drift": the gain), how many logs are named
    a moving offset, a moving gain, both, with a row the log cannot tell (the offset's line naming the gain too),
    with eq. (C5) not fitted (too few blocks of time for it), or nothing;
    and how many had too few blocks of time to test at all (eq. (C2)); per log, its blocks of time and the blocks
    the test asks for."""
    for name in ("spatial-arm", "spatial-mocap"):
        base = SPATIAL_SCENARIOS[name].with_(duration=duration)
        model = SpatialModel(base.payload)
        for kind in ("ramp", "rampz", "stepz", "gainz", "drift"):
            counts = dict(offset=0, gain=0, both=0, unresolved=0, untested=0, nothing=0, short=0)
            for seed in range(start, stop):
                scenario, log, _ = _case(base, kind, seed)
                c = fit_causes(log.shift_poses(scenario.latency), model)
                gain = c.gain is not None and bool(c.gain.rows)
                offset = not c.offset.constant
                counts["both" if gain and offset else "gain" if gain else "offset" if offset else "nothing"] += 1
                counts["unresolved"] += c.gain is not None and bool(c.gain.unresolved)
                counts["untested"] += c.gain is not None and not c.gain.tested
                counts["short"] += not c.tested
                rows = "" if c.gain is None else (
                    f" gain {[model.wrench_names[i] for i in c.gain.rows]} "
                    f"{[f'{100 * x:+.1f} %' for x in c.gain.changes]}, unresolved "
                    f"{[model.wrench_names[i] for i in c.gain.unresolved]}, (C5) fitted {c.gain.tested}")
                which = c.offset.warning.split("the offset of ")[1].split(" ")[0] if offset else "-"
                print(f"{name:14s} seed {seed} {kind:5s} blocks {c.blocks} of {c.needed} asked, offset named "
                      f"{offset} ({which}){rows}", flush=True)
            print(f"{name}, {duration:g} s, seeds {start}-{stop - 1}, {kind}: named an offset {counts['offset']}, a "
                  f"gain {counts['gain']}, both {counts['both']}, nothing {counts['nothing']}; a row not told "
                  f"{counts['unresolved']}; eq. (C5) not fitted {counts['untested']}; too few blocks of time to test "
                  f"{counts['short']}", flush=True)


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
    elif args and args[0] == "--payload":
        payload_given_wrong(range(int(args[1]) if len(args) > 1 else 10), float(args[2]) if len(args) > 2 else 10.0)
    elif args and args[0] == "--zscores":
        zscores(int(args[1]), int(args[2]), *args[3:4], *(float(a) for a in args[4:5]))
    elif args and args[0] == "--calibrate":
        through_calibrate(int(args[1]), int(args[2]), *(float(a) for a in args[3:4]))
    elif args and args[0] == "--gain":
        gain_or_offset(int(args[1]), int(args[2]), *(float(a) for a in args[3:4]))
    elif args and args[0] == "--clean":
        clean(int(args[1]), int(args[2]), *args[3:4], *(float(a) for a in args[4:5]))
    else:
        naming(range(int(args[0]) if args else 5), float(args[1]) if len(args) > 1 else 20.0)
