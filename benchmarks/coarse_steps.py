"""The step every method takes, at a log's rate: ``python benchmarks/coarse_steps.py [--rates HZ ...] [--seeds N]``.

Every method steps the motion with the acceleration linear over a sample (:func:`fmscal.observers.core.move`).
That step misses a smooth motion by about ``h^4 a'' / 24`` (``h`` the step, ``a''`` the acceleration's second
derivative): nothing at 1 kHz, but ``examples/arm.csv`` (``spatial-arm`` read at 25 Hz for 12 s, its noise over
sqrt(40): poses to 1.6e-5 rad and 3e-6 m) misses the attitude by about twice its noise a step. For each rate and
seed this runs ``fmscal.analysis.calibrate`` (the latency given, 0) with the floor (``max-likelihood``) and the
EKF on that scenario, and prints E, whether it converged and the z-scores ``(S_hat - S) / S_std`` over the 36
entries of ``S`` (their rms, 1 where ``S_std`` is honest, and the largest), each rate's median and range over the
seeds. The first column of the first rate includes the EKF's compiled step's build (about a minute, once a
process). Defaults: 25 and 50 Hz, 5 seeds (about 3 min on 2 cores).
"""

import argparse

import numpy as np

from fmscal.analysis import calibrate
from fmscal.plant.scenarios import SPATIAL_SCENARIOS, TOOL

#: The example's settings (examples/make.py): 12 s, each reading's noise over sqrt(40).
DURATION, AVERAGED = 12.0, 40


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rates", type=float, nargs="+", default=[25.0, 50.0], metavar="HZ")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--methods", nargs="+", default=["max-likelihood", "ekf"])
    args = parser.parse_args(argv)
    print("| rate [Hz] | method | E median | rms z median (range) | max abs z (range) | converged |")
    print("|---|---|---|---|---|---|")
    for rate in args.rates:
        scenario = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=DURATION, dt=1 / rate) \
            .with_noise_scaled(1 / np.sqrt(AVERAGED))
        rows = {m: [] for m in args.methods}
        for seed in range(args.seeds):
            log, truth, _ = scenario.generate(seed=seed)
            for method in args.methods:
                cal = calibrate(log, TOOL, method=method, truth=truth, latency=0.0)
                z = (cal.S_hat - truth.S_at(0)) / cal.S_std
                rows[method].append((cal.E, np.sqrt(np.mean(z ** 2)), np.max(np.abs(z)), cal.converged))
        for method, values in rows.items():
            E, rms, top, converged = (np.array(v) for v in zip(*values))
            print(f"| {rate:g} | {method} | {np.median(E):.3g} | {np.median(rms):.2f} "
                  f"({rms.min():.2f}-{rms.max():.2f}) | {np.median(top):.2f} ({top.min():.2f}-{top.max():.2f}) "
                  f"| {int(converged.sum())} of {len(E)} |", flush=True)


if __name__ == "__main__":
    main()
