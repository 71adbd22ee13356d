"""A tool change, noticed: ``python benchmarks/tool_change.py [SEEDS] [--cost] [--noise]``.

Issue 44's targets (analysis/_tool_change.py; docs/guide/compensation.md, "A tool change" quotes this), each over
SEEDS logs (default 10, seeds 2 on), every log moved onto the sensor calibrated on one 60 s ``spatial-arm`` log
(seed 1, the default method; ``fmscal.plant.scenarios.same_rig``), as ``benchmarks/drift.py`` does:

- **a grasp**: a 200 g part (:data:`PART`, 15 cm out) grasped at a time drawn from the seed (uniform in 8-20 s) on a
  30 s ``spatial-arm`` log (``fmscal.plant.scenarios.with_grasp``), compensated causally (the stream) and offline.
  Target: declared within 2 s of the grasp on every log whose attitude turned gravity by 30 degrees or more in the
  sensor's axes within those 2 s. Printed: the delay, the angle gravity had turned by then, the change's mass
  against the part's; a declaration before the grasp counts as a false alarm;
- **no false alarm**: ``benchmarks/drift.py``'s logs, 60 s each (a temperature-like drift and a 15 N contact of
  2 s), compensated with ``track_offset`` at each path's default.
  Target: no change declared in the ten minutes of these logs, causally and offline;
- **re-identified**: a grasp at a time drawn in the first held attitude of a 60 s ``spatial-static`` log (held
  3 s, moved 5 s), compensated causally with ``tool_change="reidentify"``. Target: after 6 held attitudes the new
  total's mass within 2 % of the part's (4 g) and its centre of mass within 5 mm.

``--cost``: ``Compensator.push`` per sample with detection off and on, the two streams pushed in turn, sample by
sample, in one run (the machine's load cancels in their ratio): the median, the mean (a block's evaluation spread
over its samples) and the 99th percentile. ``--noise``: the blocks' scatter against their stated sd (T2), the
z-scores' rms per channel, on seeds of free motion compensated with the truth's calibration.
"""

import argparse
import sys
import time
from functools import partial
from multiprocessing import Pool
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from fmscal.analysis import Compensator, calibrate, compensate  # noqa: E402
from fmscal.analysis._tool_change import BLOCK  # noqa: E402
from fmscal.plant import Calibration  # noqa: E402
from tool_change_rig import (ARM, COM_WITHIN, GRASP_WITHIN, MASS_WITHIN, PART, TURN_DEG, false_alarms,  # noqa: E402
                             grasp, reidentified)

def cost(n=6000):
    """``Compensator.push`` per sample, detection off and on, pushed in turn (one run): us."""
    log, truth, _ = ARM.with_(duration=n * ARM.dt + 0.1).generate(3)
    cal = Calibration(S=truth.S_at(0.0), payload=ARM.payload, method="truth", b=truth.offset,
                      gravity=ARM.gravity, latency=0.0)
    streams = {m: Compensator(cal, log.dt, noise=truth.noise, tool_change=m) for m in ("off", "detect")}
    spent = {m: [] for m in streams}
    detector, blocks = streams["detect"]._detector, []
    close = detector._close

    def timed():                                     # a block's means and its evaluation, (T2)-(T8)
        start = time.perf_counter()
        close()
        blocks.append(time.perf_counter() - start)
    detector._close = timed
    for t, w, p in zip(log.t[:n], log.w_hat[:n], log.pose[:n]):
        for m, stream in streams.items():
            start = time.perf_counter()
            stream.push(t, w, p)
            spent[m].append(time.perf_counter() - start)
    print(f"\nCompensator.push per sample ({n - 1000} samples after 1,000 of warm-up, the two streams in turn), us\n")
    print("| detection | median | mean | p99 |\n|---|---|---|---|")
    for m, v in spent.items():
        v = 1e6 * np.array(v[1000:])
        print(f"| {m} | {np.median(v):.0f} | {v.mean():.0f} | {np.percentile(v, 99):.0f} |")
    blocks = 1e6 * np.array(blocks[10:])
    print(f"\na block's means and evaluation (every {detector.n} samples): median {np.median(blocks):.0f} us, "
          f"{np.median(blocks) / np.median(1e6 * np.array(spent['off'][1000:])):.1f} times a push's median without "
          "detection")
    ratio = np.mean(spent["detect"][1000:]) / np.mean(spent["off"][1000:])
    print(f"\nmean with detection / without: {ratio:.2f}; the ratio's threshold h of (T5): "
          f"{streams['detect']._detector.h:.1f}")


def noise(seeds):
    """The blocks' z-scores' rms per channel (T2) on free motion, causal, the truth's calibration."""
    z = []
    for seed in seeds:
        log, truth, _ = ARM.with_(duration=20.0).generate(seed)
        cal = Calibration(S=truth.S_at(0.0), payload=ARM.payload, method="truth", b=truth.offset,
                          gravity=ARM.gravity, latency=0.0)
        c = compensate(cal, log, causal=True, noise=truth.noise, tool_change="off")   # (C3): the noise alone
        n = int(round(BLOCK / log.dt))
        m = len(c.t) // n
        mean = c.wrench[:m * n].reshape(m, n, 6).mean(axis=1)
        sd = np.sqrt(np.einsum("nii->ni", c.cov[:m * n].reshape(m, n, 6, 6).mean(axis=1)) / n)
        z.append(mean / sd)
    z = np.concatenate(z)
    print(f"\nblocks of {BLOCK:g} s, their mean's z-score rms per channel (stated sd: the samples' (C3) over n), "
          f"{len(z)} blocks: " + ", ".join(f"{v:.2f}" for v in np.sqrt(np.mean(z ** 2, axis=0))))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("seeds", nargs="?", type=int, default=10, help="how many logs (seeds 2 on); default 10")
    parser.add_argument("--cost", action="store_true", help="only the cost of detection in Compensator.push")
    parser.add_argument("--noise", action="store_true", help="only the blocks' scatter against their sd")
    args = parser.parse_args()
    seeds = range(2, 2 + args.seeds)
    if args.cost:
        cost()
        return
    if args.noise:
        noise(seeds)
        return
    log, truth, _ = ARM.generate(1)
    t0 = time.perf_counter()
    cal = calibrate(log, ARM.payload)
    S, b = truth.S_at(0.0), truth.offset
    print(f"calibration: {cal.method} on {log.name} ({time.perf_counter() - t0:.0f} s), converged {cal.converged}; "
          f"{len(seeds)} seeds ({seeds.start}-{seeds.stop - 1}); the part {PART.mass * 1e3:.0f} g at "
          + " ".join(f"{v:g}" for v in PART.com) + " m", flush=True)
    pool = Pool(2)
    grasps = pool.map(partial(grasp, cal=cal, S=S, b=b), seeds)
    print(f"\n### A grasp ({PART.mass * 1e3:.0f} g) on 30 s of spatial-arm\n")
    print("| seed | grasp, s | gravity turned in 2 s, deg | path | declared after, s | change's time - grasp, s | "
          "turned by then, deg | mass change, g | before the grasp | more |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    met = {True: 0, False: 0}
    eligible = 0
    for seed, g in zip(seeds, grasps):
        eligible += g["turn"] >= TURN_DEG
        for path in ("causal", "offline"):
            r = g[path]
            found = r["declared"] is not None
            if g["turn"] >= TURN_DEG and found and r["declared"] <= GRASP_WITHIN and not r["early"]:
                met[path == "causal"] += 1
            print(f"| {seed} | {g['at']:.2f} | {g['turn']:.0f} | {path} | "
                  + (f"{r['declared']:.2f} | {r['tau']:+.2f} | {r['turned']:.0f} | {r['mass'] * 1e3:.1f}"
                     if found else "none | | |") + f" | {r['early']} | {r['more']} |")
    print(f"\ntarget, declared within {GRASP_WITHIN:g} s where gravity turned {TURN_DEG:g} deg or more in them: "
          f"{eligible} of {len(seeds)} logs eligible; causal {met[True]}/{eligible}, offline {met[False]}/{eligible}",
          flush=True)
    alarms = pool.map(partial(false_alarms, cal=cal, S=S, b=b, logs=("contact",)), seeds)
    print("\n### No false alarm: benchmarks/drift.py's logs (60 s each, a drift and a 15 N contact, track_offset)\n")
    print("| log | path | changes declared (their times, s) |\n|---|---|---|")
    total = {}
    for name in ("contact",):
        for causal in (True, False):
            found = [(seed, t) for seed, a in zip(seeds, alarms) for t in a[(name, causal)]]
            total[(name, causal)] = len(found)
            print(f"| {name} | {'causal' if causal else 'offline'} | {len(found)}"
                  + ("" if not found else " (" + ", ".join(f"seed {s} at {t:.1f}" for s, t in found) + ")") + " |")
    minutes = len(seeds) * ARM.duration / 60
    print(f"\ntarget, none in {minutes:g} minutes of these logs: causal {total[('contact', True)]}, offline "
          f"{total[('contact', False)]}", flush=True)
    again = pool.map(partial(reidentified, cal=cal, S=S, b=b), seeds)
    pool.close()
    print("\n### Re-identified after 6 held attitudes (60 s of spatial-static, tool_change='reidentify', causal)\n")
    print("| seed | grasp, s | declared after, s | its mass change, g | changes declared | held attitudes | "
          "re-identified at, s | mass error, g | mass sd, g | centre of mass error, mm | flagged after, % |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    good = 0
    for seed, r in zip(seeds, again):
        if "mass" not in r:
            found = r["declared"] is not None
            print(f"| {seed} | {r['at']:.2f} | {format(r['declared'], '.2f') if found else 'none'} | "
                  f"{format(r['declared_mass'] * 1e3, '.1f') if found else ''} | {r['changes']} | | not re-identified "
                  "| | | | |")
            continue
        good += abs(r["mass"]) <= MASS_WITHIN and r["com"] <= COM_WITHIN
        print(f"| {seed} | {r['at']:.2f} | {r['declared']:.2f} | {r['declared_mass'] * 1e3:.1f} | {r['changes']} | "
              f"{r['poses']} | {r['when']:.1f} | "
              f"{r['mass'] * 1e3:+.2f} | {r['mass_sd'] * 1e3:.2f} | {r['com'] * 1e3:.2f} | "
              f"{100 * r['contact_after']:.2f} |")
    print(f"\ntarget, mass within {MASS_WITHIN * 1e3:g} g and centre of mass within {COM_WITHIN * 1e3:g} mm: "
          f"{good}/{len(seeds)}", flush=True)


if __name__ == "__main__":
    main()
