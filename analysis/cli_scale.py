"""``fmscal sweep`` and ``fmscal bench``: Monte Carlo sweeps and the speed benchmark."""

import json
from pathlib import Path

from .cli_common import CliError, add_scenarios_and_observers, positive, strict


def add_sweep(sub):
    from .sweep import SWEEP_OBSERVERS
    p = sub.add_parser("sweep", help="Monte Carlo: seeds x scenarios x noise levels x observer settings",
                       description="Run observers over the product of scenarios, seeds, noise levels and "
                                   "settings, on local cores (joblib) or a Dask cluster (--scheduler); "
                                   "print medians over seeds. The table is the same whichever runs it, "
                                   "timing columns aside.")
    add_scenarios_and_observers(p, SWEEP_OBSERVERS)
    p.add_argument("--seeds", type=int, default=10, metavar="N", help="seeds 0 .. N-1 (default 10)")
    p.add_argument("--noise-scale", type=float, nargs="+", default=[1.0], metavar="F",
                   help="multiply every noise standard deviation by each F (default 1)")
    p.add_argument("--set", action="append", default=[], metavar="OBSERVER:PARAM=V1,V2",
                   help="a grid of constructor settings, e.g. high-gain:lam=10,20,40 (repeatable)")
    p.add_argument("--duration", type=float, metavar="S", help="run length in s (default: each scenario's)")
    p.add_argument("--jobs", type=int, default=-1, metavar="N", help="local worker processes (default -1: every core)")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="run on this Dask scheduler instead")
    p.add_argument("--out", metavar="RUNS.csv", help="write every run (one row per case and observer)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON (strict) instead")
    p.set_defaults(func=cmd_sweep)


def _parse_value(text):
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text.strip()


def parse_settings(items):
    """``["high-gain:lam=10,20"]`` as ``{"high-gain": {"lam": [10, 20]}}``."""
    grid = {}
    for item in items:
        observer, sep, rest = item.partition(":")
        param, eq, values = rest.partition("=")
        if not (sep and eq and observer and param and values):
            raise CliError(f"--set must read OBSERVER:PARAM=V1,V2,...; got {item!r}")
        grid.setdefault(observer, {})[param.strip()] = [_parse_value(v) for v in values.split(",")]
    return grid


def cmd_sweep(args):
    from .comparison import summarise, summary_markdown
    from .sweep import sweep
    if args.seeds < 1:
        raise CliError(f"--seeds must be at least 1; got {args.seeds}")
    if args.jobs == 0:
        raise CliError("--jobs must be a positive number of processes or -1 (every core); got 0")
    if args.duration is not None:
        positive(args.duration, "--duration")
    if args.out and not args.out.endswith(".csv"):
        raise CliError(f"--out must end in .csv; got {args.out}")
    grid = parse_settings(args.set)
    table = sweep(args.scenario, args.seeds, args.noise_scale, args.observer, grid, args.duration,
                  n_jobs=args.jobs, scheduler=args.scheduler, progress=not args.json)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        table.to_csv(args.out, index=False)
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
    p.set_defaults(func=cmd_bench)


def cmd_bench(args):
    from .bench import BenchSettings, bench_markdown, run_bench
    report = run_bench(BenchSettings.quick() if args.quick else BenchSettings(), progress=not args.json)
    text = bench_markdown(report)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(text)
    print(json.dumps(strict(report), indent=1, allow_nan=False) if args.json else text)
