"""Run observers side by side on identical data and tabulate E, convergence and cost."""

import numpy as np
from tqdm import tqdm

from fmscal.plant import SCENARIOS, SPATIAL_SCENARIOS
from fmscal.plant.numerics import FmscalError, as_positive_scalar

from fmscal.observers import FLOOR_METHOD, METHODS, get_method, method_label
from fmscal.observers.diagnostics import has_evidence

from ._metrics import TAIL_FRACTION, convergence_time, error_history, tail_median

__all__ = ["case_scenario", "case_model",
           "simulate_case", "tail_error", "floor_error", "run_observer", "run_case", "seed_list", "compare",
           "summarise", "summary_markdown", "CHECKPOINTS"]

#: Columns of a sweep's table that tell its rows apart besides scenario and observer.
_SWEEP_KEYS = ("noise_scale", "settings")
#: Times (s) at which E is reported, where the run is that long.
CHECKPOINTS = (10.0, 30.0, 100.0)
#: A run reports a checkpoint it falls short of by at most this share of it (a latency's last rows dropped).
CHECKPOINT_SLACK = 0.01


def _checkpoint_column(t_check):
    return f"E_{t_check:g}s"


def simulate_case(scenario, seed, duration=None, noise_scale=1.0):
    """The log a case runs on: one scenario, one seed, its noise scaled.

    Parameters
    ----------
    scenario : str or plant.Scenario
    seed : int
        Seeds the log (noise, ``S``, ``S0``).
    duration : float, optional
        Run length in s; default the scenario's.
    noise_scale : float
        Multiplies every noise standard deviation of the scenario (wrench,
        angle, position); 1 is the scenario as defined.

    Returns
    -------
    scenario : plant.Scenario
        As run (duration and noise applied).
    log : plant.Log
    truth : plant.Truth
    told_noise : plant.NoiseSpec
        What an observer with a noise model is told (the scenario may tell
        it a wrong figure on purpose).
    """
    sc = case_scenario(scenario) if isinstance(scenario, str) else scenario
    if duration is not None:
        sc = sc.with_(duration=as_positive_scalar(duration, "duration"))
    noise_scale = float(noise_scale)
    if not (np.isfinite(noise_scale) and noise_scale >= 0):
        raise FmscalError(f"noise_scale must be a non-negative number; got {noise_scale}")
    if noise_scale != 1.0:
        sc = sc.with_noise_scaled(noise_scale)
    log, truth, _ = sc.generate(int(seed))
    return sc, log, truth, truth.told_noise_spec()


def case_scenario(name):
    """The scenario called ``name``: planar (:data:`plant.SCENARIOS`) or spatial (:data:`plant.SPATIAL_SCENARIOS`).

    Raises
    ------
    FmscalError
        No such scenario; the message lists both cases' names.
    """
    try:
        return {**SCENARIOS, **SPATIAL_SCENARIOS}[name]
    except KeyError:
        raise FmscalError(f"unknown scenario {name!r}; expected one of {', '.join([*SCENARIOS, *SPATIAL_SCENARIOS])}"
                          ) from None


def case_model(scenario):
    """The model the methods run on for a scenario: its payload's, with its gravity in 3D (``scenario.model()``)."""
    return scenario.model()


def _aligned(log, truth, settings):
    """The log as every method sees it, and its settings: poses lined up, offset estimated where there is one."""
    settings = dict(settings or {})
    if truth.offset is not None:                  # a rig with an offset: every method estimates it
        settings.setdefault("offset", True)
    return log.shift_poses(truth.latency), settings


def tail_error(result, truth):
    """E of eq. (16) of a result, its median over the last 10 % of the run (NaN if the run diverged).

    Parameters
    ----------
    result : observers.ObserverResult
    truth : plant.Truth

    Returns
    -------
    float
    """
    if result.diverged:
        return float("nan")
    return tail_median(error_history(result.S_hat_history, truth.S_at(result.t)))


def floor_error(log, truth, payload):
    """The information floor of a log: E of the maximum-likelihood estimate on it.

    The registry's floor method (:data:`observers.FLOOR_METHOD`) runs on the
    log as every method sees it (:func:`run_observer`), with the log's own
    noise (``truth.noise``; not what a scenario tells a method on purpose,
    ``ekf-noise-low``); its E is taken as every method's is
    (:func:`analysis.tail_median`).

    Parameters
    ----------
    log : plant.Log
    truth : plant.Truth
    payload : plant.Model or plant.Payload
        The problem (a payload stands for its case's model).

    Returns
    -------
    float
        NaN where the floor did not converge (:class:`observers.ObserverResult`:
        a log too short to pin ``S`` down, or an ``S`` that is not constant):
        there is then no floor, and every table leaves ``E / floor`` out
        ("-").
    """
    log, settings = _aligned(log, truth, None)
    result = get_method(FLOOR_METHOD).build(payload, truth.noise, settings).run(log)
    return tail_error(result, truth) if result.converged else float("nan")


def run_observer(name, log, truth, payload, told_noise=None, settings=None, history=False, floor=None):
    """Run one observer on a simulated log and measure it against the truth.

    Parameters
    ----------
    name : str
        A method of :data:`observers.METHODS`.
    log : plant.Log
    truth : plant.Truth
        ``S`` against time, and ``S0`` (every online method starts from it).
    payload : plant.Model or plant.Payload
        The problem (a payload stands for its case's model).
    told_noise : plant.NoiseSpec, optional
    settings : dict, optional
        Constructor keyword arguments. Where the scenario has a sensor
        offset, ``offset=True`` unless given; where it has a latency, the
        observer runs on the log with its poses moved back by it (the
        latency is known here; ``fmscal calibrate`` estimates it).
    history : bool
        Also return ``(t, E, S_hat_history)``, decimated to at most 2000 points.
    floor : float, optional
        The floor's E on this log (:func:`floor_error`), for ``E_over_floor``.

    Returns
    -------
    row : dict
        The columns of :func:`compare` other than ``scenario`` and ``seed``.
    (t, E, S_hat_history) : tuple of ndarray, only with ``history=True``
        Shapes (M,), (M,), (M, 3, 3).
    """
    method = get_method(name)
    if not method.cls.runs_on(payload):
        return _row_without_figures(name, log, floor, history)
    log, settings = _aligned(log, truth, settings)
    observer = method.build(payload, told_noise, settings)      # a wrong setting is an error, not a row
    try:
        result = observer.run(log, truth.S0 if method.online else None)
    except FmscalError as err:     # the method refuses this log (a reading that never moves, ...): a row, said why
        reason = str(err).removeprefix(f"{log.name}: ")
        return _row_without_figures(name, log, floor, history, refused=reason or str(err))
    E = error_history(result.S_hat_history, truth.S_at(result.t))
    bad = result.diverged
    # the run settled (result.converged); the log must also have pinned S down (Observer, Notes)
    converged = bool(result.converged) and has_evidence(result, log, observer.model, observer.offset)
    row = {"observer": name, "duration": float(log.duration),
           "E": np.nan if bad else tail_median(E), "E_end": np.nan if bad else float(E[-1]),
           "E_over_floor": np.nan, "floor_E": np.nan if floor is None else float(floor),
           "convergence_time": np.nan, "diverged": bool(bad), "converged": converged,
           "applicable": True, "refused": ""}
    if floor is not None and not bad:
        row["E_over_floor"] = row["E"] / floor if floor > 0 else np.nan        # NaN > 0 is False
    if not bad:
        ct = convergence_time(result.t, E)
        row["convergence_time"] = np.nan if ct is None else float(ct)
    for t_check in CHECKPOINTS:
        # a run a few samples short of a checkpoint still reports it: poses moved back by a latency end
        # that much before the log does (Log.shift_poses drops the rows after the last pose)
        if t_check <= log.duration + CHECKPOINT_SLACK * t_check:
            k = min(len(E), int(round(t_check / log.dt)))          # samples before t_check
            window = E[int((1 - TAIL_FRACTION) * k):k]               # the last 10 % before it
            row[_checkpoint_column(t_check)] = np.nan if bad or len(window) == 0 else float(np.median(window))
    row.update({"wall_time": result.wall_time, "wall_per_sim_s": result.wall_time / log.duration,
                "us_per_step": 1e6 * result.wall_time / len(log)})
    if not history:
        return row
    step = max(1, len(E) // 2000)
    return row, (result.t[::step], E[::step], result.S_hat_history[::step])


def _row_without_figures(name, log, floor, history, refused=""):
    """The row of a method that does not run on the scenario's model (a planar-only observer in 3D), or that
    refused this log (``refused``, its one-line reason; the method runs on the model): no figures."""
    row = {"observer": name, "duration": float(log.duration), "E": np.nan, "E_end": np.nan, "E_over_floor": np.nan,
           "floor_E": np.nan if floor is None else float(floor), "convergence_time": np.nan, "diverged": False,
           "converged": False, "applicable": bool(refused), "refused": refused, "wall_time": np.nan,
           "wall_per_sim_s": np.nan, "us_per_step": np.nan}
    return (row, None) if history else row


def run_case(scenario, seed, observers=tuple(METHODS), duration=None, settings=None, histories=False):
    """Run several observers on one simulated log: same data, same ``S0``.

    Parameters
    ----------
    scenario : str or plant.Scenario
    seed : int
        Seeds the log (noise, ``S``, ``S0``).
    observers : sequence of str
        Names from :data:`observers.METHODS`.
    duration : float, optional
        Run length in s; default the scenario's.
    settings : dict, optional
        ``{observer name: constructor keyword arguments}``.
    histories : bool
        Also return E against time for each observer.

    Returns
    -------
    rows : list of dict
        One per observer; the columns of :func:`compare`, ``E_over_floor``
        against the floor of this log (:func:`floor_error`).
    histories : dict, only with ``histories=True``
        ``{observer: (t, E, S_hat_history)}``, decimated to at most 2000 points.
    """
    sc, log, truth, told = simulate_case(scenario, seed, duration)
    model = case_model(sc)
    floor = floor_error(log, truth, model)
    rows, curves = [], {}
    for name in observers:
        out = run_observer(name, log, truth, model, told, (settings or {}).get(name), histories, floor)
        row, curve = out if histories else (out, None)
        if curve is not None:                   # a method not applicable to the model has no curve
            curves[name] = curve
        rows.append({"scenario": sc.name, "seed": int(seed), **row})
    return (rows, curves) if histories else rows


def seed_list(seeds):
    """``N`` as seeds ``[0, 1, ..., N-1]``; a sequence as a list of ints. At least one seed."""
    seeds = list(range(int(seeds))) if np.isscalar(seeds) else [int(s) for s in seeds]
    if not seeds:
        raise FmscalError("seeds must be at least 1; got 0")
    return seeds


def compare(scenarios=("paper",), seeds=1, observers=tuple(METHODS), duration=None, settings=None,
            progress=True, histories=False):
    """Run observers over scenarios and seeds on identical data.

    For each scenario and seed one log is simulated, and every observer runs
    on it from the same initial ``S_hat`` (drawn from the seed).

    Parameters
    ----------
    scenarios : sequence of str
        Names from :data:`plant.SCENARIOS` or :data:`plant.SPATIAL_SCENARIOS`
        (a spatial scenario runs the methods that take a spatial model:
        ``max-likelihood`` and ``least-squares``).
    seeds : int or sequence of int
        ``N`` means seeds ``0 .. N-1``.
    observers : sequence of str
        Names from :data:`observers.METHODS`.
    duration : float, optional
        Run length in s; default each scenario's.
    settings : dict, optional
        ``{observer name: constructor keyword arguments}``.
    progress : bool
        Show a progress bar.
    histories : bool
        Also return E against time for seed ``seeds[0]``.

    Returns
    -------
    pandas.DataFrame
        One row per observer, scenario and seed: ``observer``, ``scenario``,
        ``seed``, ``duration``, ``E`` (the median over the last 10 % of
        the run, :func:`analysis.tail_median`), ``E_end`` (the last
        sample), ``floor_E`` (the floor's E on the same log,
        :func:`floor_error`; NaN where the floor did not converge), ``E_over_floor`` (``E / floor_E``: how much
        accuracy the method leaves on the table), ``E_10s``, ``E_30s``,
        ``E_100s`` (the median over the 10 % of the run before each
        checkpoint, where the run is that long), ``convergence_time`` (s,
        :func:`analysis.convergence_time`; NaN where E never holds
        below the threshold), ``diverged``, ``converged``, ``wall_time``
        (s), ``wall_per_sim_s`` (wall seconds per simulated second) and
        ``us_per_step``. E is NaN for a diverged run.
    dict, only with ``histories=True``
        ``{(scenario, observer): (t, E, S_hat_history)}``.
    """
    seeds = seed_list(seeds)
    for name in observers:
        get_method(name)                        # FmscalError naming the methods
    scenarios = [case_scenario(s).name for s in scenarios]
    rows, curves = [], {}
    cases = [(s, seed) for s in scenarios for seed in seeds]
    for scenario, seed in tqdm(cases, desc="compare", disable=not progress):
        keep = histories and seed == seeds[0]
        out = run_case(scenario, seed, observers, duration, settings, histories=keep)
        if keep:
            out, h = out
            curves.update({(scenario, name): v for name, v in h.items()})
        rows += out
    import pandas as pd  # heavy (a sixth of the CLI's start): imported where a table is built
    table = pd.DataFrame(rows)
    return (table, curves) if histories else table


def summarise(table):
    """Medians and spread over seeds, one row per scenario and observer.

    Parameters
    ----------
    table : pandas.DataFrame
        From :func:`compare` or :func:`analysis._sweep`.

    Returns
    -------
    pandas.DataFrame
        ``scenario``, (``noise_scale``, ``settings``: from a sweep),
        ``observer``, ``seeds``, ``E_median``, ``E_q25``,
        ``E_q75`` (quartiles over seeds), ``floor_E_median``,
        ``E_over_floor_median`` and ``E_over_floor_max`` (over seeds), the medians of each checkpoint
        column and of ``convergence_time`` (over the runs that converged),
        ``converged_runs``, ``diverged_runs`` and ``us_per_step_median``.
    """
    checkpoints = [c for c in table.columns if c.startswith("E_") and c.endswith("s") and c[2].isdigit()]
    keys = ["scenario"] + [k for k in _SWEEP_KEYS if k in table.columns] + ["observer"]
    out = []
    for values, g in table.groupby(keys, sort=False):
        row = {**dict(zip(keys, values)), "seeds": len(g),
               "E_median": g["E"].median(), "E_q25": g["E"].quantile(0.25), "E_q75": g["E"].quantile(0.75),
               "floor_E_median": g["floor_E"].median(), "E_over_floor_median": g["E_over_floor"].median(),
               "E_over_floor_max": g["E_over_floor"].max()}
        for c in checkpoints:
            row[c + "_median"] = g[c].median()
        row["convergence_time_median"] = g["convergence_time"].median()
        row["converged_runs"] = int(g["converged"].sum())
        row["diverged_runs"] = int(g["diverged"].sum())
        row["us_per_step_median"] = g["us_per_step"].median()
        row["applicable"] = bool(g["applicable"].all()) if "applicable" in g else True
        reasons = [r for r in g["refused"] if isinstance(r, str) and r] if "refused" in g else []
        row["refused_runs"], row["refused"] = len(reasons), (reasons[0] if reasons else "")
        out.append(row)
    import pandas as pd  # heavy (a sixth of the CLI's start): imported where a table is built
    return pd.DataFrame(out)


def _fmt(v, spec=".3g"):
    if isinstance(v, str):
        return v
    return "-" if v is None or (isinstance(v, float) and np.isnan(v)) else format(v, spec)


def summary_markdown(summary, title="Observer comparison"):
    """The summary of :func:`summarise` as a Markdown table."""
    checkpoints = [c for c in summary.columns if c.startswith("E_") and c.endswith("s_median")]
    keys = [k for k in _SWEEP_KEYS if k in summary.columns]
    head = ["scenario", *keys, "observer", "seeds", "median E, last 10 % [IQR]", "E / floor, median [max]"]
    head += [f"median {c[:-len('_median')].replace('E_', 'E at ')}" for c in checkpoints]
    head += ["median convergence time [s]", "converged", "diverged", "cost [us/step]"]
    lines = [f"# {title}", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    refused, refusals = {}, {}
    for _, r in summary.iterrows():
        if isinstance(r.get("refused"), str) and r["refused"]:
            refusals.setdefault((r["observer"], r["refused"]), []).append(
                f"{r['scenario']} ({r['refused_runs']} of {r['seeds']} seeds)")
        if r.get("refused_runs", 0) == r["seeds"]:
            cells = [r["scenario"], *[_fmt(r[k], "g") for k in keys], method_label(r["observer"]), str(r["seeds"]),
                     "refused the log"] + ["-"] * (len(head) - len(keys) - 4)
            lines.append("| " + " | ".join(cells) + " |")
            continue
        if not r.get("applicable", True):
            refused.setdefault(r["observer"], []).append(r["scenario"])
            cells = [r["scenario"], *[_fmt(r[k], "g") for k in keys], method_label(r["observer"]), str(r["seeds"]),
                     "not applicable"] + ["-"] * (len(head) - len(keys) - 4)
            lines.append("| " + " | ".join(cells) + " |")
            continue
        cells = [r["scenario"], *[_fmt(r[k], "g") for k in keys], method_label(r["observer"]), str(r["seeds"]),
                 f"{_fmt(r['E_median'])} [{_fmt(r['E_q25'])}, {_fmt(r['E_q75'])}]",
                 f"{_fmt(r['E_over_floor_median'], '.2f')} [{_fmt(r['E_over_floor_max'], '.2f')}]"]
        cells += [_fmt(r[c]) for c in checkpoints]
        cells += [_fmt(r["convergence_time_median"], ".1f"), f"{r['converged_runs']}/{r['seeds']}",
                  f"{r['diverged_runs']}/{r['seeds']}", _fmt(r["us_per_step_median"], ".1f")]
        lines.append("| " + " | ".join(cells) + " |")
    if refused:
        lines += ["", "Not applicable: " + "; ".join(
            f"{name} on {', '.join(dict.fromkeys(scenarios))} ({_refusal(name, scenarios[0])})"
            for name, scenarios in refused.items()) + "."]
    if refusals:
        lines += ["", "Refused the log: " + "; ".join(
            f"{name} on {', '.join(dict.fromkeys(scenarios))} ({why})" for (name, why), scenarios in refusals.items())
            + "."]
    return "\n".join(lines) + "\n"


def _refusal(name, scenario):
    """Why method ``name`` does not run on ``scenario``'s model, in the method's own words."""
    return get_method(name).cls.refusal(case_model(case_scenario(scenario)))
