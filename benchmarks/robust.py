"""Glitches and misfit over seeds (issue 37): ``python benchmarks/robust.py [SEEDS] [DURATION]``.

For each seed of a ``spatial-arm`` log (default seeds 0-9, 10 s), the floor (calibrate's default, latency
given) on the clean log, on the log with the issue's 20 spikes of +5 N on ``fz``, and with spikes of 5, 20
and 50 times the reading's noise on 1 % of the samples (random channels and signs); then the payload given
in axes turned 1, 3 and 10 degrees from the poses' frame, and the poses 8 ms late taken as aligned.
Printed: E over the clean log's E, the largest ``|z|`` (error over ``S_std``) and the z-scores' rms over
the seeds (every entry of ``S``), the share of seeds converged, and for the misfit logs the z-scores' rms
before and after the misfit check widens ``S_std`` (eq. (M3) of :mod:`fmscal.observers.diagnostics._misfit`).
The payload is the simulator's, taken as exact (``PayloadStd.exact()``): ``S_std``'s statistical part is what is
measured. tests/test_robust_slow.py asserts the bounds; this prints the figures. A few minutes on 2 cores.
"""

import copy
import sys

import numpy as np
from scipy.spatial.transform import Rotation

from fmscal.analysis import calibrate
from fmscal.observers import make_observer
from fmscal.observers.core import reading_noise
from fmscal.plant import SPATIAL_SCENARIOS, PayloadStd, SpatialModel


def spikes(log, rows, channels, sizes):
    out = copy.copy(log)
    out.w_hat = log.w_hat.copy()
    out.w_hat[rows, channels] += sizes
    return out


def turned(log, degrees):
    out = copy.copy(log)
    out.pose = log.pose.copy()
    turn = Rotation.from_quat(log.pose[:, [1, 2, 3, 0]]) * Rotation.from_rotvec([0, np.radians(degrees), 0])
    out.pose[:, :4] = turn.as_quat()[:, [3, 0, 1, 2]]
    return out


def main(seeds, duration):
    scenario = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=duration)
    model = SpatialModel(scenario.payload)
    cases = ["clean", "20 x +5 N on fz", "1 % at 5 sigma", "1 % at 20 sigma", "1 % at 50 sigma",
             "turned 1 deg", "turned 3 deg", "turned 10 deg", "poses 8 ms late"]
    rows = {case: [] for case in cases}
    for seed in seeds:
        log, truth, _ = scenario.generate(seed)
        S = truth.S_at(log.t[-1])
        rng = np.random.default_rng(seed)
        noise = reading_noise(log.w_hat)
        logs = {"clean": log}
        picked = rng.choice(len(log), 20, replace=False)
        logs["20 x +5 N on fz"] = spikes(log, picked, 5, 5.0)
        for size in (5, 20, 50):
            picked = rng.choice(len(log), len(log) // 100, replace=False)
            channels = rng.integers(0, 6, len(picked))
            logs[f"1 % at {size} sigma"] = spikes(log, picked, channels,
                                                 rng.choice([-1.0, 1.0], len(picked)) * size * noise[channels])
        for degrees in (1, 3, 10):
            logs[f"turned {degrees} deg"] = turned(log, degrees)
        logs["poses 8 ms late"] = log.shift_poses(0.008)          # taken as aligned: a misfit of the timing
        for case, data in logs.items():
            cal = calibrate(data, scenario.payload, latency=0.0, truth=truth, payload_std=PayloadStd.exact())
            bare = make_observer("max-likelihood", model, settings={"offset": True}).run(data).S_std
            rows[case].append((cal.E, (cal.S_hat - S) / cal.S_std, (cal.S_hat - S) / bare, cal.converged))
    clean_E = np.array([r[0] for r in rows["clean"]])
    print(f"spatial-arm, {duration:g} s, seeds {seeds[0]}-{seeds[-1]}, the floor with the latency given")
    print("| case | E / clean E (median, max) | max abs z | rms z | rms z before widening | converged |")
    print("|---|---|---|---|---|---|")
    for case in cases:
        E = np.array([r[0] for r in rows[case]]) / clean_E
        z = np.array([r[1] for r in rows[case]])
        bare = np.array([r[2] for r in rows[case]])
        converged = np.mean([r[3] for r in rows[case]])
        print(f"| {case} | {np.median(E):.3f}, {E.max():.3f} | {np.abs(z).max():.1f} | "
              f"{np.sqrt(np.mean(z ** 2)):.2f} | {np.sqrt(np.mean(bare ** 2)):.2f} | {converged:.0%} |")


if __name__ == "__main__":
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    main(list(range(count)), float(sys.argv[2]) if len(sys.argv) > 2 else 10.0)
