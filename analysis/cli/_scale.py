"""``fmscal sweep`` and ``fmscal bench``: Monte Carlo sweeps and the speed benchmark."""

import json

from fmscal.plant import PAPER_PAYLOAD
from fmscal.plant.numerics import FmscalError

from fmscal.observers import make_observer, method_names

from .._bench import BenchSettings, bench_markdown, run_bench
from .._comparison import summarise, summary_markdown
from .._sweep import DEFAULT_SCHEDULER_TIMEOUT, sweep
from ._common import (CliError, add_jobs, add_scenarios_and_observers, check_jobs, check_seeds, check_sizes, positive,
                      strict)
from ._files import atomic_write, atomic_write_text, check_outputs


def add_sweep(sub):
    p = sub.add_parser("sweep", help="Monte Carlo: seeds x scenarios x noise levels x observer settings",
                       description="Run observers over the product of scenarios, seeds, noise levels and "
                                   "settings, on local cores (joblib) or a Dask cluster (--scheduler); "
                                   "print medians over seeds. The table is the same whichever runs it, "
                                   "timing columns aside.")
    add_scenarios_and_observers(p, method_names(role="design"))     # the registry as it is now (SWEEP_OBSERVERS)
    p.add_argument("--seeds", type=int, default=10, metavar="N", help="seeds 0 .. N-1 (default 10)")
    p.add_argument("--noise-scale", type=float, nargs="+", default=[1.0], metavar="F",
                   help="multiply every noise standard deviation by each F (default 1)")
    p.add_argument("--set", action="append", default=[], metavar="OBSERVER:PARAM=V1,V2",
                   help="a grid of constructor settings, e.g. high-gain:lam=10,20,40 (repeatable, once per "
                        "parameter; booleans: true/false/yes/no/1/0)")
    p.add_argument("--duration", type=float, metavar="S", help="run length in s (default: each scenario's)")
    add_jobs(p)
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="run on this Dask scheduler instead")
    p.add_argument("--scheduler-timeout", type=float, default=DEFAULT_SCHEDULER_TIMEOUT, metavar="S",
                   help=f"give up on a scheduler that does not answer within this many seconds "
                        f"(default {DEFAULT_SCHEDULER_TIMEOUT:g})")
    p.add_argument("--out", metavar="RUNS.csv", help="write every run (one row per case and observer)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing RUNS.csv")
    p.add_argument("--json", action="store_true", help="print the summary as JSON (strict) instead")
    p.set_defaults(func=cmd_sweep)


#: How ``--set`` reads a boolean setting; anything else is refused.
BOOLEANS = {"true": True, "yes": True, "1": True, "false": False, "no": False, "0": False}


def _parse_value(text):
    """A number if ``text`` reads as one, a boolean for true/false/yes/no, None for none, else the stripped text."""
    low = text.strip().lower()
    if low in ("true", "false", "yes", "no"):
        return BOOLEANS[low]
    if low == "none":                    # e.g. high-gain:t_decay=none, a constant gain
        return None
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text.strip()


def _defaults(observer):
    """The constructor's default of each parameter of ``observer`` (empty for an unknown name)."""
    import inspect
    try:
        obs = make_observer(observer, PAPER_PAYLOAD)
    except FmscalError:       # an unknown observer: sweep names it
        return {}
    return {k: v.default for k, v in inspect.signature(type(obs).__init__).parameters.items()}


def parse_settings(items):
    """``["high-gain:lam=10,20"]`` as ``{"high-gain": {"lam": [10, 20]}}``.

    A parameter whose default is a boolean reads only true/false/yes/no/1/0
    (any case); a parameter given in two ``--set`` options is refused (give
    every value in one).
    """
    grid = {}
    for item in items:
        observer, sep, rest = item.partition(":")
        param, eq, values = rest.partition("=")
        observer, param = observer.strip(), param.strip()
        if not (sep and eq and observer and param and values):
            raise CliError(f"--set must read OBSERVER:PARAM=V1,V2,...; got {item!r}")
        if param in grid.get(observer, {}):
            raise CliError(f"--set gives {observer}:{param} twice; give all its values in one "
                           f"--set {observer}:{param}=V1,V2,...")
        texts = values.split(",")
        if isinstance(_defaults(observer).get(param), bool):
            bad = [v for v in texts if v.strip().lower() not in BOOLEANS]
            if bad:
                raise CliError(f"--set {observer}:{param} is true or false (true/false/yes/no/1/0); got {bad[0]!r}")
            parsed = [BOOLEANS[v.strip().lower()] for v in texts]
        else:
            parsed = [_parse_value(v) for v in texts]
        grid.setdefault(observer, {})[param] = parsed
    return grid


def cmd_sweep(args):
    check_seeds(seeds=args.seeds)
    check_jobs(args.jobs)
    if args.duration is not None:
        positive(args.duration, "--duration")
    if args.out and not args.out.endswith(".csv"):
        raise CliError(f"--out must end in .csv; got {args.out}")
    positive(args.scheduler_timeout, "--scheduler-timeout")
    check_outputs([(args.out, "--out")], overwrite=args.overwrite)
    check_sizes(args.scenario, args.duration)
    grid = parse_settings(args.set)
    table = sweep(args.scenario, args.seeds, args.noise_scale, args.observer, grid, args.duration,
                  n_jobs=args.jobs, scheduler=args.scheduler, progress=not args.json,
                  scheduler_timeout=args.scheduler_timeout)
    if args.out:
        atomic_write(args.out, lambda tmp: table.to_csv(tmp, index=False))
    summary = summarise(table)
    if args.json:
        print(json.dumps(strict(summary.to_dict(orient="records")), indent=1, allow_nan=False))
    else:
        print(summary_markdown(summary, f"Sweep ({args.seeds} seed(s), "
                                        f"{'each scenario' if args.duration is None else f'{args.duration:g} s'})"))


def add_bench(sub):
    p = sub.add_parser("bench", help="speed: compiled paths against plain numpy, reproduce and a sweep",
                       description="Measure observer steps per second against the plain numpy loop of the "
                                   "same equations, the EKF against filterpy's bare predict + update, the "
                                   "wall time of reproduce and of a 100-seed sweep; print ratios and the "
                                   "targets (about 5 minutes on 2 cores; --quick: seconds).")
    p.add_argument("--quick", action="store_true", help="short runs that exercise every measurement")
    p.add_argument("--json", action="store_true", help="print the measurements as JSON (strict) instead")
    p.add_argument("--out", metavar="FILE.md", help="also write the Markdown report here")
    p.add_argument("--overwrite", action="store_true", help="replace an existing FILE.md")
    p.set_defaults(func=cmd_bench)


def cmd_bench(args):
    check_outputs([(args.out, "--out")], overwrite=args.overwrite)
    report = run_bench(BenchSettings.quick() if args.quick else BenchSettings(), progress=not args.json)
    text = bench_markdown(report)
    if args.out:
        atomic_write_text(args.out, text)
    print(json.dumps(strict(report), indent=1, allow_nan=False) if args.json else text)
