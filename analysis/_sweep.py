"""Monte Carlo sweeps: seeds x scenarios x noise levels x observer settings, in parallel.

The unit of work is a *case*: one scenario, one seed and one noise level,
simulated once, on which every observer variant runs (same data, same
``S0``). Cases run on local cores through joblib, or on a Dask cluster; the
table is the same either way, timing columns aside (:data:`TIMING_COLUMNS`).
"""

import itertools

import numpy as np
from tqdm import tqdm

from fmscal.plant.numerics import FmscalError

from fmscal.observers import get_method, make_observer, method_names

from ._comparison import case_model, case_scenario, floor_error, run_observer, seed_list, simulate_case

__all__ = ["sweep", "run_local", "worker_count", "expand_settings", "settings_label", "TIMING_COLUMNS",
           "SWEEP_OBSERVERS",
           "DEFAULT_SCHEDULER_TIMEOUT"]

#: Columns that depend on the machine and the moment, not on the data.
TIMING_COLUMNS = ("wall_time", "wall_per_sim_s", "us_per_step")
#: Seconds to wait for a Dask scheduler to answer.
DEFAULT_SCHEDULER_TIMEOUT = 10.0
#: The three observers the toolkit compares, swept by default (the registry's ``design`` role).
SWEEP_OBSERVERS = method_names(role="design")


def settings_label(settings):
    """``{"lam": 10, "gamma": 2}`` as ``"gamma=2, lam=10"``; ``{}`` as ``"default"``."""
    if not settings:
        return "default"
    return ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in sorted(settings.items()))


def expand_settings(observers, grid=None):
    """Every observer variant of a settings grid.

    Parameters
    ----------
    observers : sequence of str
        Names from :data:`observers.METHODS`.
    grid : dict, optional
        ``{observer: {parameter: [values]}}``; the product of each
        observer's value lists gives its variants. Observers absent from
        the grid run once with their defaults.

    Returns
    -------
    list of (str, dict)
        ``(observer, constructor keyword arguments)``.
    """
    grid = dict(grid or {})
    for name in grid:
        if name not in observers:
            raise FmscalError(f"settings given for {name!r}, which is not swept; observers: {', '.join(observers)}")
    variants = []
    for name in observers:
        get_method(name)                  # FmscalError naming the methods
        params = grid.get(name) or {}
        keys = sorted(params)
        values = [list(params[k]) if np.ndim(params[k]) else [params[k]] for k in keys]
        for k, v in zip(keys, values):
            if not v:
                raise FmscalError(f"settings for {name}: {k} needs at least one value; got none")
        for combo in itertools.product(*values):
            variants.append((name, dict(zip(keys, combo))))
    return variants


def _check_variants(variants, model):
    """Build each variant once here, so that a misspelt setting fails before any work is sent (the methods
    that do not run on ``model`` are shown as not applicable, unbuilt)."""
    for name, settings in variants:
        if not get_method(name).cls.runs_on(model):
            continue
        try:
            make_observer(name, model, None, {"offset": True, **settings})    # as on a rig with an offset
        except TypeError as err:
            raise FmscalError(f"{name}: {err}") from err


def _run_case(case):
    """One case: simulate once, run every variant. Module-level so that it pickles."""
    index, scenario, seed, noise_scale, duration, variants = case
    sc, log, truth, told = simulate_case(scenario, seed, duration, noise_scale)
    model = case_model(sc)
    floor = floor_error(log, truth, model)
    rows = []
    for name, settings in variants:
        row = run_observer(name, log, truth, model, told, settings, floor=floor)
        rows.append({"case": index, "scenario": sc.name, "seed": int(seed), "noise_scale": float(noise_scale),
                     "settings": settings_label(settings), **row})
    return index, rows


def worker_count(n_jobs, n_items):
    """How many worker processes serve ``n_items`` items: ``n_jobs``, at most one per item and per core.

    Parameters
    ----------
    n_jobs : int
        A positive count, or -1 for every core.
    n_items : int

    Returns
    -------
    int
        At least 1.

    Raises
    ------
    FmscalError
        ``n_jobs`` neither a positive integer nor -1.
    """
    import numbers
    import os
    if not isinstance(n_jobs, numbers.Integral) or isinstance(n_jobs, bool) or not (n_jobs >= 1 or n_jobs == -1):
        raise FmscalError(f"n_jobs must be a positive number of processes or -1 (every core); got {n_jobs!r}")
    cores = os.cpu_count() or 1
    return max(1, min(cores, n_items, cores if n_jobs == -1 else int(n_jobs)))


def run_local(func, items, n_jobs, bar):
    """``func(item)`` for every item on local worker processes (joblib), yielded as each finishes.

    ``n_jobs=1`` runs them in this process, in order (simplest to debug);
    ``-1`` on every core; never more workers than items or cores
    (:func:`worker_count`). ``bar`` (a tqdm bar) advances by one per item.
    ``func`` must be a module-level function, so that it pickles.
    """
    from joblib import Parallel, delayed          # only a sweep on local cores needs it
    items = list(items)
    n_jobs = worker_count(n_jobs, len(items))
    if n_jobs == 1:                     # no worker processes: simplest to debug
        for item in items:
            yield func(item)
            bar.update()
        return
    for out in Parallel(n_jobs=n_jobs, return_as="generator_unordered")(delayed(func)(item) for item in items):
        bar.update()
        yield out


def _run_dask(cases, client, bar):
    from dask.distributed import as_completed     # optional (the distributed extra)
    futures = client.map(_run_case, cases, pure=False)
    for future in as_completed(futures):
        bar.update()
        yield future.result()


def _probe(address, timeout):
    """Refuse a ``tcp://`` address where nothing listens, or where the listener says nothing.

    A Dask scheduler sends its handshake as soon as it accepts a connection;
    a listener that accepts and stays silent would make the Dask client wait
    for ever, so this waits at most ``timeout`` s for the first byte.
    Addresses of other schemes are left to Dask.
    """
    import socket
    from urllib.parse import urlsplit
    parts = urlsplit(address)
    if parts.scheme != "tcp":
        return
    try:
        host, port = parts.hostname, parts.port
    except ValueError:
        host = port = None
    if not host or port is None:
        raise FmscalError(f"a scheduler address reads tcp://HOST:PORT; got {address!r}")
    try:
        sock = socket.create_connection((host, port), timeout=timeout)
    except socket.timeout:
        raise FmscalError(f"no answer from {address} within {timeout:g} s (nothing accepted the connection: "
                          "is the address right, and is the scheduler running?)") from None
    except OSError as err:
        raise FmscalError(f"cannot reach the Dask scheduler at {address} ({err.strerror or err})") from None
    try:
        with sock:
            sock.settimeout(timeout)
            first = sock.recv(1)
    except socket.timeout:
        raise FmscalError(f"no answer from the Dask scheduler at {address} within {timeout:g} s "
                          "(something accepts connections there but says nothing)") from None
    except OSError as err:
        raise FmscalError(f"cannot reach the Dask scheduler at {address} ({err.strerror or err})") from None
    if not first:
        raise FmscalError(f"the listener at {address} closed the connection without a Dask handshake")


def _client(scheduler, timeout=DEFAULT_SCHEDULER_TIMEOUT):
    if isinstance(scheduler, str):
        try:
            from dask.distributed import Client   # optional (the distributed extra)
        except ImportError:
            raise FmscalError('a Dask scheduler needs the distributed extra: pip install "fmscal[distributed]"') \
                from None
        _probe(scheduler, timeout)
        try:
            return Client(scheduler, timeout=timeout), True
        except (OSError, TimeoutError) as err:
            raise FmscalError(f"no answer from the Dask scheduler at {scheduler} within {timeout:g} s "
                              f"({type(err).__name__}); is it running, and is the address right?") from None
        except ValueError as err:
            raise FmscalError(f"cannot use the Dask scheduler address {scheduler!r} ({str(err).splitlines()[0]})") \
                from None
    if not (hasattr(scheduler, "map") and hasattr(scheduler, "gather")):
        raise TypeError(f"scheduler must be an address like 'tcp://HOST:PORT' or a dask.distributed.Client; "
                        f"got {type(scheduler).__name__}")
    return scheduler, False


def sweep(scenarios=("paper",), seeds=1, noise_scales=(1.0,), observers=SWEEP_OBSERVERS, settings=None,
          duration=None, n_jobs=-1, scheduler=None, progress=True, scheduler_timeout=DEFAULT_SCHEDULER_TIMEOUT):
    """Run observers over the product of scenarios, seeds, noise levels and settings.

    Parameters
    ----------
    scenarios : sequence of str
        Names from :data:`plant.SCENARIOS` or :data:`plant.SPATIAL_SCENARIOS`
        (a method that does not run on a scenario's model gets a row marked
        ``applicable`` False, without figures).
    seeds : int or sequence of int
        ``N`` means seeds ``0 .. N-1``.
    noise_scales : sequence of float
        Each multiplies every noise standard deviation of the scenario.
    observers : sequence of str
        Names from :data:`observers.METHODS`.
    settings : dict, optional
        ``{observer: {parameter: [values]}}``: a grid of constructor
        arguments (:func:`expand_settings`).
    duration : float, optional
        Run length in s; default each scenario's.
    n_jobs : int
        Local worker processes (joblib; -1: every core, 1: this process).
    scheduler : str or dask.distributed.Client, optional
        Run on a Dask cluster instead: a scheduler address
        (``"tcp://HOST:PORT"``) or a connected client.
    progress : bool
        Show a progress bar (one tick per case).
    scheduler_timeout : float
        Seconds to wait for a scheduler given by address to answer before
        giving up with :class:`plant.FmscalError`.

    Returns
    -------
    pandas.DataFrame
        One row per case and observer variant, in case order whatever ran
        it: ``case``, ``scenario``, ``seed``, ``noise_scale``, ``settings``
        (a label, ``"default"`` or ``"lam=10"``) and the columns of
        :func:`analysis.compare`.
    """
    seeds = seed_list(seeds)
    scenarios = [case_scenario(s).name for s in scenarios]
    noise_scales = [float(f) for f in np.atleast_1d(noise_scales)]
    for f in noise_scales:
        if not (np.isfinite(f) and f >= 0):
            raise FmscalError(f"noise scales must be non-negative numbers; got {f}")
    variants = expand_settings(observers, settings)
    for name in dict.fromkeys(scenarios):
        _check_variants(variants, case_model(case_scenario(name)))
    cases = [(i, sc, seed, f, duration, variants)
             for i, (sc, f, seed) in enumerate(itertools.product(scenarios, noise_scales, seeds))]
    client, owned = _client(scheduler, scheduler_timeout) if scheduler is not None else (None, False)
    results = {}
    try:
        with tqdm(total=len(cases), desc="sweep", unit="case", disable=not progress) as bar:
            runs = run_local(_run_case, cases, n_jobs, bar) if client is None else _run_dask(cases, client, bar)
            for index, rows in runs:
                results[index] = rows
    finally:
        if owned:
            client.close()
    import pandas as pd  # heavy (a sixth of the CLI's start): imported where a table is built
    return pd.DataFrame([row for i in sorted(results) for row in results[i]])
