"""The ``fmscal`` command line.

Every command answers bad input with one line on stderr and exit status 2,
never a traceback.
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np

__all__ = ["main"]


class CliError(Exception):
    """A user error: printed as one line, exit status 2."""


def _add_simulate(sub):
    from plant import SCENARIOS
    p = sub.add_parser("simulate", help="simulate a scenario and write LOG.csv and LOG.truth.json",
                       description="Simulate a named scenario. Writes the log (t,theta,x,y,M,fx,fy) "
                                   "and the sidecar LOG.truth.json. Scenarios: " +
                                   "; ".join(f"{k}: {v.description}" for k, v in SCENARIOS.items()))
    p.add_argument("--scenario", default="paper", choices=sorted(SCENARIOS), metavar="NAME",
                   help="one of: " + ", ".join(SCENARIOS))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--duration", type=float, help="s (default: the scenario's)")
    p.add_argument("--dt", type=float, help="sample time, s (default: the scenario's, 0.001)")
    p.add_argument("--noise-free", action="store_true", help="no measurement noise")
    p.add_argument("--pose-rate", type=float, metavar="HZ", help="pose measurements per second")
    p.add_argument("--drop-rate", type=float, metavar="FRAC", help="fraction of pose frames dropped")
    p.add_argument("--mass", type=float, metavar="KG", help="payload mass (default: the scenario's)")
    p.add_argument("--inertia", type=float, metavar="KGM2", help="payload I_G (default: the scenario's)")
    p.add_argument("--rho", type=float, nargs=2, metavar=("RX", "RY"), help="offset, m (default: the scenario's)")
    p.add_argument("--offset", type=float, nargs=3, metavar=("B_M", "B_FX", "B_FY"),
                   help="sensor offset b in w = S (w_hat - b), N m and N (default: the scenario's)")
    p.add_argument("--latency", type=float, metavar="S",
                   help="delay of the pose stream behind the sensor stream, s (default: the scenario's)")
    p.add_argument("--out", required=True, metavar="LOG.csv")
    p.set_defaults(func=cmd_simulate)


def cmd_simulate(args):
    from plant import get_scenario
    sc = get_scenario(args.scenario)
    changes = {}
    if args.duration is not None:
        changes["duration"] = _positive(args.duration, "--duration")
    if args.dt is not None:
        changes["dt"] = _positive(args.dt, "--dt")
    if args.pose_rate is not None:
        changes["pose_rate"] = _positive(args.pose_rate, "--pose-rate")
    if args.drop_rate is not None:
        if not 0 <= args.drop_rate < 1:
            raise CliError(f"--drop-rate must be in [0, 1); got {args.drop_rate}")
        changes["drop_rate"] = args.drop_rate
    if args.offset is not None:
        if not all(np.isfinite(v) for v in args.offset):
            raise CliError(f"--offset must be three finite numbers (N m, N, N); got {args.offset}")
        changes["offset"] = tuple(args.offset)
    if args.latency is not None:
        if not (np.isfinite(args.latency) and args.latency >= 0):
            raise CliError(f"--latency must be a non-negative number of seconds; got {args.latency}")
        changes["latency"] = args.latency
    if args.mass is not None or args.inertia is not None or args.rho is not None:
        from plant import Payload
        p = sc.payload
        changes["payload"] = Payload(_positive(args.mass, "--mass") if args.mass is not None else p.mass,
                                     _positive(args.inertia, "--inertia") if args.inertia is not None else p.inertia,
                                     tuple(args.rho) if args.rho is not None else p.rho)
    sc = sc.with_(**changes)
    log, truth, _ = sc.generate(args.seed, noise_free=args.noise_free)
    out = Path(args.out)
    if out.suffix != ".csv":
        raise CliError(f"--out must end in .csv; got {out}")
    out.parent.mkdir(parents=True, exist_ok=True)
    log.write(out)
    truth_path = out.with_suffix(".truth.json")
    truth.write(truth_path)
    print(f"wrote {out} ({len(log)} samples, {log.duration:g} s) and {truth_path}")


def _add_check_gains(sub):
    p = sub.add_parser("check-gains", help="poles, observability and Theorem 1's assumption 2 for the gains",
                       description="Check observer gains with python-control: poles of A - K C, "
                                   "observability of (A, C), the Lyapunov P, and whether assumption 2 "
                                   "of Theorem 1 holds with P = I.")
    p.add_argument("--config", choices=["paper", "adaptive", "high-gain", "high-gain-ref4"], default="paper",
                   help="paper: eq. (14) as printed; adaptive: the default configuration's gains; "
                        "high-gain, high-gain-ref4: the reconstruction of [4] (poles at -LAM)")
    p.add_argument("--lam", type=float, default=None,
                   help="high-gain parameter in rad/s for the high-gain configurations")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_check_gains)


def cmd_check_gains(args):
    from observers import AdaptiveObserver, HighGainObserver, check_gains
    from plant import PAPER_PAYLOAD
    if args.lam is not None and not args.config.startswith("high-gain"):
        raise CliError(f"--lam applies to the high-gain configurations; got --config {args.config}")
    if args.lam is not None:
        _positive(args.lam, "--lam")
    obs = {"paper": lambda: AdaptiveObserver.paper(PAPER_PAYLOAD),
           "adaptive": lambda: AdaptiveObserver(PAPER_PAYLOAD),
           "high-gain": lambda: HighGainObserver(PAPER_PAYLOAD),
           "high-gain-ref4": lambda: HighGainObserver.ref4(PAPER_PAYLOAD)}[args.config]()
    if args.lam is not None:
        obs = HighGainObserver(PAPER_PAYLOAD, lam=args.lam)
    report = check_gains(obs.K1, obs.K2)
    if args.json:
        print(json.dumps({k: {"poles": [[complex(p).real, complex(p).imag] for p in v["poles"]],
                              "observable": v["observable"], "stable": v["stable"],
                              "sym_eigs": v["sym_eigs"].tolist(),
                              "assumption_2_holds": v["assumption_2_holds"]}
                          for k, v in report.items()}, indent=2))
    else:
        print(f"gains of the {obs.name} configuration")
        print(report)


def _add_reproduce(sub):
    p = sub.add_parser("reproduce", help="the paper's section 4: Figs. 2-4 and claimed vs measured E",
                       description="Run the paper, noisy and time-varying scenarios for every observer; "
                                   "write PNG figures and summary.md to --out.")
    p.add_argument("--out", default="reproduce", metavar="DIR")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quick", type=float, default=1.0, metavar="FRACTION",
                   help="run this fraction of each scenario's length (default 1: the paper's)")
    p.set_defaults(func=cmd_reproduce)


def cmd_reproduce(args):
    from .reproduce import reproduce
    if not 0 < args.quick <= 1:
        raise CliError(f"--quick must be in (0, 1]; got {args.quick}")
    reproduce(args.out, seed=args.seed, duration_scale=args.quick)
    print((Path(args.out) / "summary.md").read_text())


def _add_scenarios_and_observers(p, default_observers):
    from plant import SCENARIOS
    from .comparison import OBSERVER_NAMES
    p.add_argument("--scenario", nargs="+", default=["paper"], metavar="NAME",
                   help="one or more of: " + ", ".join(SCENARIOS))
    p.add_argument("--observer", nargs="+", default=list(default_observers), metavar="NAME",
                   help="one or more of: " + ", ".join(OBSERVER_NAMES) + f" (default: {' '.join(default_observers)})")


def _add_compare(sub):
    from plant import SCENARIOS
    from .comparison import OBSERVER_NAMES
    p = sub.add_parser("compare", help="run the observers side by side on identical data",
                       description="Run every observer on the same simulated logs (same data, same "
                                   "initial S_hat) over scenarios and seeds; print the table of E, "
                                   "convergence time and cost. Scenarios: " + ", ".join(SCENARIOS))
    _add_scenarios_and_observers(p, OBSERVER_NAMES)
    p.add_argument("--seeds", type=int, default=1, metavar="N", help="seeds 0 .. N-1 (default 1)")
    p.add_argument("--duration", type=float, metavar="S", help="run length in s (default: each scenario's)")
    p.add_argument("--json", action="store_true", help="print a JSON list of rows (strict JSON) instead")
    p.add_argument("--out", metavar="DIR", help="write E-against-time plots and summary.md here")
    p.set_defaults(func=cmd_compare)


def cmd_compare(args):
    from plant import get_scenario
    from .comparison import OBSERVER_NAMES, compare, summarise, summary_markdown
    from .plots import plot_error_histories
    for name in args.scenario:
        get_scenario(name)                      # ValueError naming the choices
    for name in args.observer:
        if name not in OBSERVER_NAMES:
            raise CliError(f"unknown observer {name!r}; expected one of {', '.join(OBSERVER_NAMES)}")
    if args.seeds < 1:
        raise CliError(f"--seeds must be at least 1; got {args.seeds}")
    if args.duration is not None:
        _positive(args.duration, "--duration")
    table, curves = compare(args.scenario, args.seeds, args.observer, args.duration,
                            progress=not args.json, histories=True)
    summary = summarise(table)
    text = summary_markdown(summary, f"Observer comparison ({args.seeds} seed(s), "
                                     f"{'each scenario' if args.duration is None else f'{args.duration:g} s'})")
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        for scenario in dict.fromkeys(table["scenario"]):
            plot_error_histories({obs: v for (sc, obs), v in curves.items() if sc == scenario},
                                 out / f"E_{scenario}.png", f"E against time, scenario '{scenario}' (seed 0)")
        (out / "summary.md").write_text(text)
        table.to_csv(out / "runs.csv", index=False)
    if args.json:
        print(json.dumps(_strict(table.to_dict(orient="records")), indent=1, allow_nan=False))
    else:
        print(text)


def _add_calibrate(sub):
    from .calibrate import CALIBRATION_METHODS, DEFAULT_MAX_LATENCY, DEFAULT_METHOD
    p = sub.add_parser("calibrate", help="estimate S from a recorded log",
                       description="Estimate the calibration matrix S from a log (t,theta,x,y,M,fx,fy; "
                                   "rad, m, N m, N) and the payload's mass properties. Prints S_hat with "
                                   "its one-sigma uncertainty, whether the run converged, warnings about "
                                   "excitation and model consistency, and E with --truth.")
    p.add_argument("log", metavar="LOG.csv")
    p.add_argument("--mass", type=float, required=True, metavar="KG")
    p.add_argument("--inertia", type=float, required=True, metavar="KGM2", help="I_G about the centre of mass")
    p.add_argument("--rho", type=float, nargs=2, required=True, metavar=("RX", "RY"),
                   help="offset of the centre of mass from the sensor, body frame, m (negative values as written)")
    p.add_argument("--observer", choices=CALIBRATION_METHODS, default=DEFAULT_METHOD,
                   help=f"method (default {DEFAULT_METHOD}: the most accurate one that is robust)")
    p.add_argument("--pose-noise", type=float, nargs=2, metavar=("SD_RAD", "SD_M"),
                   help="pose noise standard deviations (default: estimated from the log)")
    p.add_argument("--wrench-noise", type=float, nargs=3, metavar=("SD_M", "SD_FX", "SD_FY"),
                   help="raw-reading noise standard deviations, N m and N (default: estimated from the log)")
    p.add_argument("--offset", action=argparse.BooleanOptionalAction, default=True,
                   help="estimate the sensor's offset b in w = S (w_hat - b) with S (default: yes; "
                        "--no-offset for an offset-free sensor, as in the paper)")
    p.add_argument("--latency", type=float, metavar="S",
                   help="delay of the pose stream behind the sensor stream, s (default: estimated)")
    p.add_argument("--max-latency", type=float, default=DEFAULT_MAX_LATENCY, metavar="S",
                   help=f"largest delay searched when estimating it (default {DEFAULT_MAX_LATENCY:g} s)")
    p.add_argument("--truth", metavar="TRUTH.json", help="a truth sidecar from fmscal simulate: report E")
    p.add_argument("--json", action="store_true", help="print one JSON object (strict JSON)")
    p.add_argument("--plot", metavar="FILE.png", help="draw the entries of S_hat against time")
    p.add_argument("--save", metavar="CAL.json", help="write the calibration here (for fmscal apply)")
    p.set_defaults(func=cmd_calibrate)


def cmd_calibrate(args):
    from plant import Calibration, Payload, file_sha256, read_log, read_truth
    from .calibrate import calibrate
    from .plots import plot_S_entries
    for name, value in (("--mass", args.mass), ("--inertia", args.inertia)):
        _positive(value, name)
    for value in args.rho:
        if not np.isfinite(value):
            raise CliError(f"--rho must be two finite numbers in m; got {args.rho}")
    for option, values in (("--pose-noise", args.pose_noise), ("--wrench-noise", args.wrench_noise)):
        if values is not None and not all(np.isfinite(v) and v >= 0 for v in values):
            raise CliError(f"{option} must be non-negative standard deviations; got {values}")
    if args.latency is not None and not (np.isfinite(args.latency) and args.latency >= 0):
        raise CliError(f"--latency must be a non-negative number of seconds; got {args.latency}")
    _positive(args.max_latency, "--max-latency")
    if args.save and not args.save.endswith(".json"):
        raise CliError(f"--save must end in .json; got {args.save}")
    payload = Payload(args.mass, args.inertia, tuple(args.rho))
    log = read_log(args.log)
    truth = read_truth(args.truth) if args.truth else None
    out = calibrate(log, payload, args.observer, args.pose_noise, args.wrench_noise, truth,
                    offset=args.offset, latency=args.latency, max_latency=args.max_latency)
    if args.save:
        Calibration(S=out["S"], payload=payload, method=out["observer"], S_std=out["S_std"], b=out["b"],
                    b_std=out["b_std"], log_name=Path(args.log).name, log_sha256=file_sha256(args.log),
                    latency=out["latency"]).save(args.save)
    for warning in out["warnings"]:
        print(f"fmscal calibrate: warning: {warning}", file=sys.stderr)
    if args.plot:
        plot_S_entries([out["result"]], truth, args.plot, f"{Path(args.log).name}: entries of S_hat")
    result = out.pop("result")
    if args.json:
        print(json.dumps(_strict(out), allow_nan=False))
        return
    print(f"{Path(args.log).name}: {len(log)} samples, {log.duration:g} s, "
          f"{int(log.has_pose.sum())} pose measurements; method {out['observer']}")
    if out["noise_estimated"]:
        n = out["noise"]
        print(f"noise estimated from the log ({' and '.join(out['noise_estimated'])}): wrench sd "
              f"{', '.join(f'{v:.3g}' for v in n['wrench_sd'])}; angle sd {n['angle_sd']:.3g} rad; "
              f"position sd {n['position_sd']:.3g} m")
    S, S_std = np.array(out["S"]), out["S_std"]
    print("S_hat" + (" +- one sigma:" if S_std is not None else " (this method gives no uncertainty):"))
    for i in range(3):
        cells = [f"{S[i, j]:+.5f}" + (f" +- {S_std[i][j]:.1e}" if S_std is not None else "") for j in range(3)]
        print("  " + "   ".join(cells))
    if out["b"] is not None:
        b, b_std = out["b"], out["b_std"]
        cells = [f"{b[j]:+.5g}" + (f" +- {b_std[j]:.1e}" if b_std is not None else "") for j in range(3)]
        print("offset b [N m, N, N]: " + "   ".join(cells))
    print(f"pose latency: {out['latency'] * 1e3:.3g} ms ({'estimated' if out['latency_estimated'] else 'given'})")
    print(f"converged: {'yes' if out['converged'] else 'no'} (at t = {result.t[-1]:g} s)")
    if "E" in out:
        print(f"E = ||I - S_hat S^-1||_2 = {out['E']:.4g}")
    if args.save:
        print(f"saved the calibration to {args.save}")


def _add_sweep(sub):
    from .sweep import SWEEP_OBSERVERS
    p = sub.add_parser("sweep", help="Monte Carlo: seeds x scenarios x noise levels x observer settings",
                       description="Run observers over the product of scenarios, seeds, noise levels and "
                                   "settings, on local cores (joblib) or a Dask cluster (--scheduler); "
                                   "print medians over seeds. The table is the same whichever runs it, "
                                   "timing columns aside.")
    _add_scenarios_and_observers(p, SWEEP_OBSERVERS)
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
        _positive(args.duration, "--duration")
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
        print(json.dumps(_strict(summary.to_dict(orient="records")), indent=1, allow_nan=False))
    else:
        print(summary_markdown(summary, f"Sweep ({args.seeds} seed(s), "
                                        f"{'each scenario' if args.duration is None else f'{args.duration:g} s'})"))


def _add_bench(sub):
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
    print(json.dumps(_strict(report), indent=1, allow_nan=False) if args.json else text)


def _add_apply(sub):
    p = sub.add_parser("apply", help="turn raw readings into calibrated wrenches with a saved calibration",
                       description="Apply a calibration saved by fmscal calibrate --save: w = S (w_hat - b) "
                                   "for every row of READINGS.csv (columns t,M,fx,fy, or a full log); "
                                   "writes t,M,fx,fy.")
    p.add_argument("calibration", metavar="CAL.json")
    p.add_argument("readings", metavar="READINGS.csv")
    p.add_argument("--out", required=True, metavar="WRENCH.csv")
    p.add_argument("--mass", type=float, metavar="KG", help="refuse a calibration made for another payload")
    p.add_argument("--inertia", type=float, metavar="KGM2")
    p.add_argument("--rho", type=float, nargs=2, metavar=("RX", "RY"))
    p.set_defaults(func=cmd_apply)


def cmd_apply(args):
    from plant import Calibration, Payload, read_readings
    given = [v is not None for v in (args.mass, args.inertia, args.rho)]
    if any(given) and not all(given):
        raise CliError("give all of --mass, --inertia and --rho to check the payload, or none")
    payload = None
    if all(given):
        payload = Payload(_positive(args.mass, "--mass"), _positive(args.inertia, "--inertia"), tuple(args.rho))
    if not args.out.endswith(".csv"):
        raise CliError(f"--out must end in .csv; got {args.out}")
    calibration = Calibration.load(args.calibration, payload)
    t, w_hat = read_readings(args.readings)
    w = calibration.apply(w_hat)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    lines = ["t,M,fx,fy"] + [",".join(repr(float(v)) for v in (ti, *wi)) for ti, wi in zip(t, w)]
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}: {len(t)} calibrated wrenches (calibration of {calibration.log_name or 'unknown log'}, "
          f"{calibration.method}, {calibration.date})")


def _strict(value):
    """A JSON-ready copy: NaN and infinity become None, numpy scalars plain."""
    if isinstance(value, dict):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    return value


def _positive(value, name):
    if not np.isfinite(value) or value <= 0:
        raise CliError(f"{name} must be positive; got {value}")
    return value


class _Parser(argparse.ArgumentParser):
    """argparse, with usage errors on one line (exit 2) instead of usage plus error."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser():
    parser = _Parser(
        prog="fmscal",
        description="Calibrate a force-moment sensor from motion, and compare the observers that do it.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in _COMMANDS:
        add(sub)
    return parser


_COMMANDS = [_add_simulate, _add_calibrate, _add_apply, _add_reproduce, _add_compare, _add_sweep, _add_bench, _add_check_gains]


def main(argv=None):
    """Entry point of ``fmscal``; returns the exit status."""
    from plant import LogError, SingularCalibrationError
    from .calibrate import DivergedError
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as stop:            # --help, or a usage error already printed on one line
        return stop.code
    try:
        args.func(args)
    except (CliError, LogError, SingularCalibrationError, DivergedError, ValueError, OSError) as err:
        message = str(err).splitlines()[0] if str(err) else type(err).__name__
        print(f"fmscal {args.command}: error: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("fmscal: interrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())


def _console():
    sys.exit(main())
