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
    PYTHONPATH=. python benchmarks/adaptive_vs_floor.py --tracking [--seeds 5]

``--tracking``: for each seed, the time after each step of Table 1
(``time-varying``, 300 s) from which E stays below 0.02 until the next step,
and the ``drift`` scenario's E for the old and the new adaptive observer.
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


def markdown(table):
    """A DataFrame as a Markdown table, numbers to 3 significant digits."""
    cells = lambda r: [v if isinstance(v, str) else f"{v:.3g}" for v in r]
    lines = ["| " + " | ".join(table.columns) + " |", "|" + "---|" * len(table.columns)]
    lines += ["| " + " | ".join(cells(r)) + " |" for r in table.itertuples(index=False)]
    return "\n".join(lines)


def recovery_time(t, E, t_step, t_end, threshold=0.02):
    """Seconds after ``t_step`` from which E stays below ``threshold`` until ``t_end`` (inf if never)."""
    seg = (t >= t_step) & (t < t_end)
    above = np.flatnonzero(E[seg] >= threshold)
    if len(above) == 0:
        return 0.0
    if above[-1] == seg.sum() - 1:
        return float("inf")
    return float(t[seg][above[-1] + 1] - t_step)


def tracking(seeds=5):
    """Table 1 steps (``time-varying``, 300 s) and the ``drift`` scenario, old and new adaptive."""
    rows = []
    for seed in range(seeds):
        sc, log, truth, _ = simulate_case("time-varying", seed)
        result = FilteredAdaptiveObserver(sc.payload).run(log, truth.S0)
        E = error_history(result.S_hat_history, truth.S_at(result.t))
        row = {"seed": seed, "recovery after 100 s step [s]": recovery_time(result.t, E, 100.0, 200.0),
               "recovery after 200 s step [s]": recovery_time(result.t, E, 200.0, 300.0 + 1e-9)}
        sc, log, truth, _ = simulate_case("drift", seed, duration=100)
        row["drift E, old adaptive"] = tail_median(AdaptiveObserver(sc.payload).run(log, truth.S0), truth)
        row["drift E, new adaptive"] = tail_median(FilteredAdaptiveObserver(sc.payload).run(log, truth.S0), truth)
        rows.append(row)
        print(pd.DataFrame([row]).to_string(index=False, float_format="%.3g"), flush=True)
    table = pd.DataFrame(rows)
    print("medians:", table.drop(columns="seed").median().to_dict())
    return table


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="*", default=list(SCENARIOS))
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--duration", type=float, default=100.0)
    ap.add_argument("--tracking", action="store_true", help="the Table 1 steps and the drift scenario instead")
    args = ap.parse_args()
    if args.tracking:
        tracking(args.seeds)
        return
    table = run(args.scenarios, args.seeds, args.duration)
    print()
    print(markdown(table))


if __name__ == "__main__":
    main()
