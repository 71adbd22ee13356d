"""The filtered adaptive observer against the floor: median E over seeds, per scenario.

For each scenario and seed (100 s logs, ``analysis.comparison.simulate_case``)
this runs the floor proxy (the EKF told the noise, with no random walk on
``S``: ``q_S=0, adapt_q=False``), the offline least squares, the current
default ``adaptive`` and :class:`observers.adaptive_filtered.FilteredAdaptiveObserver`,
and prints the median over seeds of each one's E (the median over the last
10 % of the run) and the ratio to the floor proxy's, with the filtered
observer's cost per step (compiled, second run). Where the scenario has an
offset every method estimates it; where it has a latency every method runs on
the log with its poses moved back by it.

Usage::

    PYTHONPATH=. python benchmarks/adaptive_vs_floor.py [--seeds 5] [--duration 100] [scenario ...]
"""

import argparse

import numpy as np
import pandas as pd

from analysis.comparison import simulate_case
from analysis.metrics import error_history
from observers import AdaptiveObserver, AugmentedEKF, LeastSquares
from observers.adaptive_filtered import FilteredAdaptiveObserver

SCENARIOS = ("paper", "other-payload", "random-S", "weak-excitation", "noisy", "vision-50hz", "real-rig")


def tail_median(result, truth):
    """E of eq. (16), its median over the last 10 % of the run."""
    E = error_history(result.S_hat_history, truth.S_at(result.t))
    return float(np.median(E[int(0.9 * len(E)):]))


def run(scenarios=SCENARIOS, seeds=5, duration=100.0):
    """One row per scenario: median E of each method over seeds, ratios and cost."""
    rows = []
    for name in scenarios:
        per = {k: [] for k in ("floor proxy", "least squares", "old adaptive", "new adaptive")}
        cost = []
        for seed in range(seeds):
            sc, log, truth, told = simulate_case(name, seed, duration=duration)
            offset = truth.extra.get("offset") is not None
            log = log.shift_poses(truth.extra.get("latency") or 0.0)
            p = sc.payload
            per["floor proxy"].append(tail_median(
                AugmentedEKF(p, noise=told, q_S=0, adapt_q=False, offset=offset).run(log, truth.S0), truth))
            ls = LeastSquares(p, offset=offset).run(log)
            per["least squares"].append(float(error_history(ls.S_hat[None], truth.S_at(log.t[-1]))[0]))
            per["old adaptive"].append(tail_median(AdaptiveObserver(p, offset=offset).run(log, truth.S0), truth))
            new = FilteredAdaptiveObserver(p, offset=offset)
            new.run(log, truth.S0)                              # compile once
            result = new.run(log, truth.S0)
            per["new adaptive"].append(tail_median(result, truth))
            cost.append(1e6 * result.wall_time / len(log))
        row = {"scenario": name, **{k: float(np.median(v)) for k, v in per.items()}}
        row["new / floor"] = row["new adaptive"] / row["floor proxy"]
        row["worst seed new / floor"] = float(np.max(np.array(per["new adaptive"]) / np.array(per["floor proxy"])))
        row["new us/step"] = float(np.median(cost))
        rows.append(row)
        print(pd.DataFrame([row]).to_string(index=False, float_format="%.3g"), flush=True)
    return pd.DataFrame(rows)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="*", default=list(SCENARIOS))
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--duration", type=float, default=100.0)
    args = ap.parse_args()
    table = run(args.scenarios, args.seeds, args.duration)
    print()
    print(table.to_markdown(index=False, floatfmt=".3g") if hasattr(table, "to_markdown") else table)


if __name__ == "__main__":
    main()
