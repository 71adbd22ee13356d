"""Ablation of the adaptive observer: from the paper's law, each documented change in turn (``fmscal ablation``).

Each row is a configuration of a real class: the paper's observer
(:class:`observers.PaperAdaptiveObserver`), then
:class:`observers.AdaptiveObserver` with its settings switched on one at a
time (the numbered changes of its docstring). Each is measured by E (eq. 16,
the median over the last 10 % of the run), against the floor on the same
logs (the maximum-likelihood estimate, :func:`analysis._comparison.floor_error`),
and by its cost per step (compiled, the second run so that compilation is not
counted).
"""

import numpy as np
from tqdm import tqdm

from fmscal.plant.numerics import FmscalError

from fmscal.observers import AdaptiveObserver, PaperAdaptiveObserver

from ._comparison import floor_error, seed_list, simulate_case, tail_error

__all__ = ["ABLATION_STEPS", "QUICK_SETTINGS", "ablation", "ablation_markdown", "tail_error"]

#: ``(label, factory(payload, offset))``, in the order the changes are added.
ABLATION_STEPS = (
    ("adaptive-paper: eqs. (6)-(8), (14), (15) as printed",
     lambda p, offset: PaperAdaptiveObserver(p, offset=offset)),
    ("+ 1, 2: discrete observer, poles at -lam; filtered regressor and position error (gradient gain)",
     lambda p, offset: AdaptiveObserver(p, gain="gradient", track=False, offset=offset)),
    ("+ 3: least-squares gain",
     lambda p, offset: AdaptiveObserver(p, gain="least-squares", track=False, offset=offset)),
    ("+ 4: forgetting on evidence of change (the default)",
     lambda p, offset: AdaptiveObserver(p, offset=offset)),
)


#: Settings of a quick run (``fmscal ablation --quick``): the same rows, one short seed.
QUICK_SETTINGS = {"seeds": 1, "duration": 20.0}


def ablation(scenarios=("paper", "noisy"), seeds=3, duration=100.0, floor=floor_error, progress=False):
    """Each documented change of the adaptive default, added in turn (``fmscal ablation``).

    Parameters
    ----------
    scenarios : sequence of str
        Names from :data:`plant.SCENARIOS`.
    seeds : int or sequence of int
        ``N`` means seeds ``0 .. N-1``.
    duration : float
        Run length, s (:data:`QUICK_SETTINGS`: 20 s and 1 seed give the same rows).
    floor : callable
        ``floor(log, truth, payload) -> float``: the E each
        configuration is divided by (default the maximum-likelihood floor,
        :func:`analysis._comparison.floor_error`).
    progress : bool
        Show a progress bar.

    Returns
    -------
    pandas.DataFrame
        One row per scenario and step: ``scenario``, ``step`` (0 the paper),
        ``configuration``, ``seeds``, ``E_median`` (median over seeds of the
        tail E), ``floor_E_median`` (over the seeds where the floor
        converged), ``ratio`` (their quotient; NaN, printed "n/a", where the
        floor converged on no seed),
        ``diverged_runs`` and ``us_per_step`` (median over seeds).
    """
    if not callable(floor):
        raise FmscalError(f"floor must be callable; got {type(floor).__name__}")
    seeds = seed_list(seeds)
    records = []
    cases = [(s, seed) for s in scenarios for seed in seeds]
    for name, seed in tqdm(cases, desc="ablation", disable=not progress):
        sc, log, truth, told = simulate_case(name, seed, duration=duration)
        E_floor = floor(log, truth, sc.payload)
        offset = truth.offset is not None
        log = log.shift_poses(truth.latency)
        for step, (label, factory) in enumerate(ABLATION_STEPS):
            obs = factory(sc.payload, offset)
            obs.run(log, truth.S0)                            # compiles; the second run is timed
            result = obs.run(log, truth.S0)
            records.append({"scenario": sc.name, "seed": seed, "step": step, "configuration": label,
                            "E": tail_error(result, truth), "E_floor": E_floor,
                            "diverged": bool(result.diverged),
                            "us_per_step": 1e6 * result.wall_time / len(log)})
    import pandas as pd  # heavy (a sixth of the CLI's start): imported where a table is built
    raw = pd.DataFrame(records)
    rows = []
    for (scenario, step), g in raw.groupby(["scenario", "step"], sort=False):
        E_med, F_med = float(g["E"].median()), float(g["E_floor"].median())      # NaN: no floor converged
        rows.append({"scenario": scenario, "step": int(step), "configuration": g["configuration"].iloc[0],
                     "seeds": len(g), "E_median": E_med, "floor_E_median": F_med, "ratio": E_med / F_med,
                     "diverged_runs": int(g["diverged"].sum()), "us_per_step": float(g["us_per_step"].median())})
    return pd.DataFrame(rows)


def ablation_markdown(table, title="Ablation: from the paper's observer to the adaptive default"):
    """The table of :func:`ablation` as Markdown."""
    head = ["scenario", "configuration", "seeds", "median E", "floor median E", "E / floor", "diverged",
            "cost [us/step]"]
    lines = [f"# {title}", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for _, r in table.iterrows():
        lines.append("| " + " | ".join([
            r["scenario"], r["configuration"], str(r["seeds"]), f"{r['E_median']:.3g}",
            _or_na(r["floor_E_median"]), _or_na(r["ratio"]), f"{r['diverged_runs']}/{r['seeds']}",
            f"{r['us_per_step']:.2g}"]) + " |")
    return "\n".join(lines) + "\n"


def _or_na(value):
    """A number for the table; "n/a" where there is none (the floor did not converge)."""
    return "n/a" if np.isnan(value) else f"{value:.3g}"
