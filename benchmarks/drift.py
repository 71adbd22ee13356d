"""The offset's drift followed without eating a contact: ``python benchmarks/drift.py [SEEDS]``.

A calibration from one 60 s ``spatial-arm`` log (seed 1, the default method) is used on ten other 60 s logs of
the same rig (seeds 2-11, the readings moved onto the first sensor, ``tests/live_rig.py``), each given a
temperature-like offset drift (``d (1 - exp(-t / 15 s))``, 2 N and 0.05 N m per channel, seeded signs) and:

- a 15 N contact of 2 s from 30 s: issue 38's targets, offline and causal, at the default intensity
  (:data:`fmscal.analysis._compensate.DRIFT_INTENSITY` times the reading's noise sd, per sqrt(s)): the residual
  after the first 5 s (outside the contact) within 2x the noise times S; the offset's 95 % intervals covering
  93-97 % of samples; the contact within 10 %;
- a slow push, 10 N over 10 s from 40 s, instead of the contact: the share of it the offset has taken for
  drift at its end, and the share of its samples flagged;

then the trade-off the drift's intensity sets (causal): the residual, coverage and push taken at several
intensities. docs/guide/compensation.md quotes it. A few minutes on 2 cores.
"""

import sys
import time
from functools import partial
from multiprocessing import Pool
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from fmscal.analysis import calibrate  # noqa: E402
from fmscal.analysis._compensate import DRIFT_INTENSITY  # noqa: E402
from fmscal.plant import SPATIAL_SCENARIOS  # noqa: E402
from live_rig import drift_run  # noqa: E402

ARM = SPATIAL_SCENARIOS["spatial-arm"]
MULTIPLES = (0.25, 0.5, 1.0, 2.0, 4.0)


def one(seed, cal, S, b, jobs):
    """Every (multiple, causal) of ``jobs`` on the log of ``seed``."""
    log, truth, _ = ARM.generate(seed)
    sd = np.asarray(truth.noise.wrench_sd, dtype=float)
    return {(m, causal): drift_run(cal, S, b, log, truth.S_at(0.0), truth.offset, sd, seed, m * sd, causal)
            for m, causal in jobs}


def summary(runs):
    keys = runs[0].keys()
    return {k: np.array([r[k] for r in runs]) for k in keys}


def main():
    seeds = range(2, 2 + (int(sys.argv[1]) if len(sys.argv) > 1 else 10))
    log, truth, _ = ARM.generate(1)
    t0 = time.perf_counter()
    cal = calibrate(log, ARM.payload)
    print(f"calibration: {cal.method} on {log.name} ({time.perf_counter() - t0:.0f} s), converged {cal.converged}; "
          f"{len(seeds)} seeds ({seeds.start}-{seeds.stop - 1})")
    jobs = [(DRIFT_INTENSITY, False)] + [(m, True) for m in MULTIPLES]
    with Pool(2) as pool:
        results = pool.map(partial(one, cal=cal, S=truth.S_at(0.0), b=truth.offset, jobs=jobs), seeds)
    print(f"\ndefault intensity ({DRIFT_INTENSITY:g} x the noise sd per sqrt(s)); worst seed and channel, and the "
          "mean over seeds\n")
    print("| path | residual / noise after 5 s, worst | coverage of the 95 % intervals, min-max (mean) | "
          "15 N contact error, worst, % | contact flagged, % | false alarms, % |")
    print("|---|---|---|---|---|---|")
    for causal in (False, True):
        s = summary([r[(DRIFT_INTENSITY, causal)] for r in results])
        cover = s["coverage"].mean(axis=1)                     # each seed's share over the channels
        print(f"| {'causal' if causal else 'offline'} | {s['residual'].max():.2f} | "
              f"{100 * cover.min():.1f}-{100 * cover.max():.1f} ({100 * cover.mean():.1f}) | "
              f"{100 * s['contact_error'].max():.1f} | {100 * s['contact_flagged'].mean():.1f} | "
              f"{100 * s['false_alarm'].mean():.2f} |")
    print("\nper channel coverage at the default intensity, causal, mean over seeds: "
          + ", ".join(f"{100 * v:.1f} %" for v in summary([r[(DRIFT_INTENSITY, True)] for r in results])
                      ["coverage"].mean(axis=0)))
    print("\nthe drift's intensity (causal): following a drift against taking a slow push (10 N over 10 s) for it\n")
    print("| intensity, x noise sd / sqrt(s) | residual / noise after 5 s, worst | coverage, mean (min) | "
          "push taken for drift at its end, mean (max), % | push flagged, % |")
    print("|---|---|---|---|---|")
    for m in MULTIPLES:
        s = summary([r[(m, True)] for r in results])
        cover = s["coverage"].mean(axis=1)
        print(f"| {m:g} | {s['residual'].max():.2f} | {100 * cover.mean():.1f} ({100 * cover.min():.1f}) | "
              f"{100 * s['push_taken'].mean():.0f} ({100 * s['push_taken'].max():.0f}) | "
              f"{100 * s['push_flagged'].mean():.0f} |", flush=True)


if __name__ == "__main__":
    main()
