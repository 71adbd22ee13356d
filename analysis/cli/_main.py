"""The ``fmscal`` command line.

Every command answers bad input (a :class:`plant.FmscalError`, or a file that
cannot be read or written) with one line on stderr and exit status 2. Any other
exception is a bug in the toolkit and shows its traceback.
"""

import argparse
import contextlib
import json
import os
import re
import sys
import warnings
from pathlib import Path

import numpy as np

from fmscal.plant import PAPER_PAYLOAD, SCENARIOS, SPATIAL_SCENARIOS, FmscalError, get_scenario
from fmscal.plant.numerics import one_blas_thread
from fmscal.plant.io import write_pose_table

from fmscal.observers import (METHODS, HighGainObserver, PaperAdaptiveObserver, RecursiveObserver, check_gains,
                              get_method, make_observer)

from .._ablation import QUICK_SETTINGS, ablation, ablation_markdown
from .._comparison import case_scenario, compare, summarise, summary_markdown
from .._plots import plot_comparison
from .._reproduce import output_names, reproduce
from ._calibration import add_apply, add_calibrate
from ._compensate import add_compensate
from ._export import add_export
from ._common import (INERTIA_METAVAR, CliError, HelpFormatter, RawDescriptionHelpFormatter, add_jobs,
                      add_scenarios_and_observers, check_jobs, check_seeds, check_sizes, flag_payload, position_flag,
                      position_values, positive, strict)
from ._files import (atomic_write, atomic_write_many, atomic_write_text, check_output_dir, check_outputs, claim_folder,
                     exclusive)
from ._import import add_import
from ._payload import add_identify_payload
from ._ros2 import add_ros2
from ._scale import add_bench, add_sweep

__all__ = ["main", "build_parser", "MAX_LAM"]

#: Longest error message printed, characters (a message echoing a huge input is cut).
MAX_MESSAGE = 400
#: Most characters of one echoed word (a file name, a value the user gave) an error message prints.
MAX_ECHO = 80


def one_line(message):
    """``message`` fit for one line of stderr: control characters escaped, each echoed word (a run
    without spaces, as a path or a value is) cut to its first and last :data:`MAX_ECHO` / 2
    characters, the whole to :data:`MAX_MESSAGE`."""
    if not message.isprintable():
        message = message.encode("unicode_escape").decode("ascii")
    half = MAX_ECHO // 2                 # a path keeps its start and its end, where the file's name is
    message = re.sub(r"\S{%d,}" % (MAX_ECHO + 1), lambda m: m.group()[:half] + "..." + m.group()[-half:], message)
    return message if len(message) <= MAX_MESSAGE else message[:MAX_MESSAGE] + "..."
#: Largest high-gain parameter check-gains accepts, rad/s (a million times the default's 20).
MAX_LAM = 1e7
#: The folder ``fmscal reproduce`` writes without ``--out`` (in the current folder); each run replaces its files.
REPRODUCE_DIR = "reproduce"


def _count(text):
    """argparse type of a count of poses: a whole number, also written as ``1e5``."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number; got {text!r}") from None
    if not (np.isfinite(value) and value == int(value)):
        raise argparse.ArgumentTypeError(f"must be a whole number; got {text!r}")
    return int(value)


def _add_simulate(sub):
    every = {**SCENARIOS, **SPATIAL_SCENARIOS}
    import textwrap
    # the scenarios one per line, each with its own description (the epilog is printed as written)
    width = max(map(len, every)) + 2

    def listed(scenarios):
        return "\n".join(textwrap.fill(sc.description, 79, initial_indent=f"  {name:<{width}}",
                                        subsequent_indent=" " * (width + 2)) for name, sc in scenarios.items())
    p = sub.add_parser("simulate", help="simulate a scenario and write LOG.csv and LOG.truth.json",
                       formatter_class=RawDescriptionHelpFormatter,
                       description=textwrap.fill(
                           "Simulate a named scenario. Writes the log (planar t,theta,x,y,M,fx,fy; spatial "
                           "t,qw,qx,qy,qz,x,y,z,tx,ty,tz,fx,fy,fz), or with --poses N a spatial scenario's pose "
                           "table (qw,qx,qy,qz,tx,ty,tz,fx,fy,fz, one row per held pose), and the sidecar "
                           "LOG.truth.json (the true S, payload, noise and offset).", 79),
                       epilog=f"planar scenarios (a 3-axis reading, the paper's case):\n{listed(SCENARIOS)}\n\n"
                              f"spatial scenarios (a 6-axis reading, a payload moving in 3D under gravity):\n"
                              f"{listed(SPATIAL_SCENARIOS)}")
    p.add_argument("--scenario", default="paper", choices=sorted(every), metavar="NAME",
                   help="the scenario, planar or spatial (listed below; default paper)")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the noise, the initial estimate and any random S (default 0); the same seed "
                        "gives the same log")
    p.add_argument("--duration", type=float, help="run length, s (default: the scenario's)")
    p.add_argument("--dt", type=float, help="sample time, s (default: the scenario's, 0.001)")
    p.add_argument("--noise-free", action="store_true", help="no measurement noise")
    p.add_argument("--pose-rate", type=float, metavar="HZ", help="pose measurements per second")
    p.add_argument("--drop-rate", type=float, metavar="FRAC", help="fraction of pose frames dropped")
    p.add_argument("--mass", type=float, metavar="KG", help="the payload's mass, kg (default: the scenario's)")
    p.add_argument("--inertia", type=float, nargs="+", metavar=INERTIA_METAVAR,
                   help="the payload's inertia about its centre of mass (default: the scenario's): planar I_G, "
                        "kg m^2; spatial IXX IYY IZZ IXY IXZ IYZ, kg m^2, sensor axes")
    p.add_argument("--rho", type=float, **position_values("rho"),
                   help="planar scenarios: rho, from the centre of mass to the sensor, body frame, m (default: "
                        "the scenario's)")
    p.add_argument("--com", type=float, **position_values("com"),
                   help="spatial scenarios: the centre of mass in the sensor frame, m (default: the "
                        "scenario's; the opposite of a planar rho)")
    p.add_argument("--offset", type=float, nargs=3, metavar=("B_M", "B_FX", "B_FY"),
                   help="planar scenarios: sensor offset b in w = S (w_hat - b), N m and N (default: the scenario's; "
                        "a spatial scenario draws its own)")
    p.add_argument("--latency", type=float, metavar="S",
                   help="delay of the pose stream behind the sensor stream, s, any fraction of a sample; negative: the "
                        "wrench stream behind the poses (default: the scenario's)")
    p.add_argument("--poses", type=_count, metavar="N",
                   help="spatial scenarios: write a pose table instead of a log, the tool held at N random attitudes "
                        "(the spatial header without t, one row per held pose; at least 4)")
    p.add_argument("--hold", type=float, metavar="S",
                   help="with --poses: seconds each pose is held, its reading averaged over them (default 1)")
    p.add_argument("--out", required=True, metavar="LOG.csv",
                   help="the log (or table) to write; its sidecar goes beside it as LOG.truth.json")
    p.add_argument("--overwrite", action="store_true", help="replace an existing LOG.csv and LOG.truth.json")
    p.set_defaults(func=cmd_simulate)


def _simulate_payload(args, sc):
    """The payload of ``fmscal simulate``: the scenario's, with what ``--mass``, ``--inertia`` and ``--rho``
    (planar) or ``--com`` (spatial) give in its place; None where none is given."""
    model = type(sc.model())                                   # the scenario's model class declares its flags
    position = position_flag(model, args.rho, args.com, f"{args.scenario} (a {model.name} scenario)")
    if args.mass is None and args.inertia is None and position is None:
        return None
    p = sc.payload
    return flag_payload(model, args.mass if args.mass is not None else p.mass,
                        args.inertia if args.inertia is not None else np.atleast_1d(p.inertia).tolist(),
                        position if position is not None else list(getattr(p, model.payload_position)))


def _simulate_table(args, sc):
    """``fmscal simulate --poses N``: the scenario's pose table (:meth:`plant.scenarios.SpatialScenario.
    generate_table`) and its sidecar."""
    if not hasattr(sc, "generate_table"):
        raise CliError(f"--poses is for the spatial scenarios (a pose table is of a 6-axis reading); {args.scenario} "
                       "is planar")
    timed = [flag for flag, value in (("--duration", args.duration), ("--pose-rate", args.pose_rate),
                                      ("--drop-rate", args.drop_rate), ("--latency", args.latency))
             if value is not None]
    if timed:
        raise CliError(f"{' and '.join(timed)} {'is' if len(timed) == 1 else 'are'} for a log; a pose table "
                       "(--poses) has no time")
    hold = 1.0 if args.hold is None else positive(args.hold, "--hold")
    out = Path(args.out)
    if out.suffix != ".csv":
        raise CliError(f"--out must end in .csv; got {out}")
    truth_path = out.with_suffix(".truth.json")
    check_outputs([(out, "--out"), (truth_path, "--out's sidecar")], overwrite=args.overwrite)
    table, truth = sc.generate_table(args.seed, args.poses, hold=hold, noise_free=args.noise_free)
    atomic_write_many([(truth_path, truth.write), (out, lambda path: write_pose_table(table, path))])
    print(f"wrote {out} ({len(table)} held poses, {hold:g} s each) and {truth_path}")


def cmd_simulate(args):
    check_seeds(seed=args.seed)
    sc = {**SCENARIOS, **SPATIAL_SCENARIOS}[args.scenario]            # --scenario's choices: both tables' names
    if args.offset is not None and "offset" not in sc.payload_settings:      # the scenario's own declaration
        raise CliError(f"--offset is for the planar scenarios; {args.scenario} draws its own offset (the sidecar "
                       "records it)")
    if args.hold is not None and args.poses is None:
        raise CliError("--hold applies to --poses (a pose table); give --poses N too")
    payload = _simulate_payload(args, sc)
    if payload is not None:
        sc = sc.with_(payload=payload)
    if args.poses is not None:
        return _simulate_table(args, sc)
    changes = {}
    if args.duration is not None:
        changes["duration"] = positive(args.duration, "--duration")
    if args.dt is not None:
        changes["dt"] = positive(args.dt, "--dt")
    if args.pose_rate is not None:
        changes["pose_rate"] = positive(args.pose_rate, "--pose-rate")
    if args.drop_rate is not None:
        if not 0 <= args.drop_rate < 1:
            raise CliError(f"--drop-rate must be in [0, 1); got {args.drop_rate}")
        changes["drop_rate"] = args.drop_rate
    if args.offset is not None:
        if not all(np.isfinite(v) for v in args.offset):
            raise CliError(f"--offset must be three finite numbers (N m, N, N); got {args.offset}")
        changes["offset"] = tuple(args.offset)
    if args.latency is not None:
        if not np.isfinite(args.latency):
            raise CliError(f"--latency must be a number of seconds (negative: the wrench behind the poses); got "
                           f"{args.latency}")
        changes["latency"] = args.latency
    sc = sc.with_(**changes)
    if not abs(sc.latency) < sc.duration / 2:
        raise CliError(f"--latency must be less than half the run ({sc.duration / 2:g} s): the poses are shifted "
                       f"by it; got {sc.latency:g} s")
    out = Path(args.out)
    if out.suffix != ".csv":
        raise CliError(f"--out must end in .csv; got {out}")
    truth_path = out.with_suffix(".truth.json")
    check_outputs([(out, "--out"), (truth_path, "--out's sidecar")], overwrite=args.overwrite)
    sc.check_size()
    log, truth, _ = sc.generate(args.seed, noise_free=args.noise_free)
    # the sidecar first, the log last: never a log without its sidecar
    atomic_write_many([(truth_path, truth.write), (out, log.write)])
    print(f"wrote {out} ({len(log)} samples, {log.duration:g} s) and {truth_path}")


def _add_check_gains(sub):
    p = sub.add_parser("check-gains", help="poles, observability and Theorem 1's assumption 2 for the gains",
                       description="Check observer gains with python-control: poles of A - K C, "
                                   "observability of (A, C), the Lyapunov P, and whether assumption 2 "
                                   "of Theorem 1 holds with P = I.")
    configs = [name for name, m in METHODS.items() if issubclass(m.cls, RecursiveObserver)]
    p.add_argument("--config", choices=["paper", *configs], default="paper",
                   help="the gains of one observer: " + ", ".join(configs) + "; paper is adaptive-paper, "
                        "eq. (14) as printed; with --lam, the high-gain observer with poles at -LAM")
    p.add_argument("--lam", type=float, default=None,
                   help="high-gain parameter in rad/s for the high-gain configurations")
    p.add_argument("--json", action="store_true", help="print the report as JSON instead")
    p.set_defaults(func=cmd_check_gains)


def cmd_check_gains(args):
    if args.config == "paper":
        obs = PaperAdaptiveObserver(PAPER_PAYLOAD)
    else:
        obs = make_observer(args.config, PAPER_PAYLOAD)
    if args.lam is not None and not isinstance(obs, HighGainObserver):
        raise CliError(f"--lam applies to the high-gain configurations; got --config {args.config}")
    if args.lam is not None:
        if args.lam > MAX_LAM:
            raise CliError(f"--lam must be at most {MAX_LAM:g} rad/s (the gains grow as lam^2); got {args.lam:g}")
        obs = HighGainObserver(PAPER_PAYLOAD, lam=positive(args.lam, "--lam"))
    report = check_gains(obs.K1, obs.K2)
    if args.json:
        print(json.dumps(report.to_json(), indent=2))
    else:
        print(f"gains of the {obs.name} configuration")
        print(report)


def _add_reproduce(sub):
    p = sub.add_parser("reproduce", help="the paper's section 4: Figs. 2-4 and claimed vs measured E",
                       description="Run the paper, noisy and time-varying scenarios (planar) for every observer; "
                                   "write PNG figures and summary.md to --out, and print the summary.")
    p.add_argument("--out", default=None, metavar="DIR",
                   help=f"the folder to write (default: {REPRODUCE_DIR}/ in the current folder, whose figures and "
                        "summary.md each run replaces; a DIR given here that holds them already is refused "
                        "without --overwrite)")
    p.add_argument("--seed", type=int, default=0, help="seed of every scenario's noise and initial S_hat (default 0)")
    p.add_argument("--quick", type=float, default=1.0, metavar="FRACTION",
                   help="run this fraction of each scenario's length (default 1: the paper's)")
    p.add_argument("--overwrite", action="store_true", help="replace figures and summary.md already in DIR")
    add_jobs(p)
    p.set_defaults(func=cmd_reproduce)


def cmd_reproduce(args):
    if not 0 < args.quick <= 1:
        raise CliError(f"--quick must be in (0, 1]; got {args.quick}")
    check_seeds(seed=args.seed)
    check_jobs(args.jobs)
    # the default folder is the command's own: a second run replaces what the first wrote there (README's quick
    # start runs again); a folder the user named keeps its files unless --overwrite
    own = args.out is None
    out = REPRODUCE_DIR if own else args.out
    check_output_dir(out, output_names(), overwrite=args.overwrite or own)
    with claim_folder(out), exclusive(not (args.overwrite or own)):   # one run's alone: a second one at once is refused
        reproduce(out, seed=args.seed, duration_scale=args.quick, n_jobs=args.jobs)
    print((Path(out) / "summary.md").read_text())


def _add_ablation(sub):
    p = sub.add_parser("ablation", help="the adaptive observer's changes from the paper, added one at a time",
                       description="From the paper's observer as printed, each documented change of the adaptive "
                                   "default added in turn: median E over seeds (E the median over the last 10 % "
                                   "of each run) against the maximum-likelihood floor on the same logs, and the "
                                   "cost per step.")
    p.add_argument("--scenario", nargs="+", default=["paper", "noisy"], metavar="NAME",
                   help="one or more planar scenarios (fmscal simulate --help lists them; default paper noisy)")
    p.add_argument("--seeds", type=int, default=3, metavar="N", help="seeds 0 .. N-1 (default 3)")
    p.add_argument("--duration", type=float, default=100.0, metavar="S", help="run length in s (default 100)")
    p.add_argument("--quick", action="store_true", help="one seed of 20 s: the same rows, for a check")
    p.add_argument("--json", action="store_true", help="print the table as JSON (strict) instead")
    p.set_defaults(func=cmd_ablation)


def cmd_ablation(args):
    for name in args.scenario:
        get_scenario(name)                      # FmscalError naming the choices
    check_seeds(seeds=args.seeds)               # --quick or not: a bad --seeds is not ignored
    seeds, duration = (QUICK_SETTINGS["seeds"], QUICK_SETTINGS["duration"]) if args.quick else \
        (args.seeds, positive(args.duration, "--duration"))
    check_seeds(seeds=seeds)
    check_sizes(args.scenario, duration)
    table = ablation(args.scenario, seeds, duration, progress=not args.json)
    if args.json:
        print(json.dumps(strict(table.to_dict(orient="records")), indent=1, allow_nan=False))
    else:
        print(ablation_markdown(table))


def _add_compare(sub):
    p = sub.add_parser("compare", help="run the observers side by side on identical data",
                       description="Run every observer on the same simulated logs (same data, same "
                                   "initial S_hat) over scenarios and seeds; print the table of E, "
                                   "convergence time and cost. Scenarios: " + ", ".join(SCENARIOS))
    p.epilog = ("The spatial scenarios too: " + ", ".join(SPATIAL_SCENARIOS) + " (a method that does not run in 3D, "
                "as the paper's observer, is reported not applicable there).")
    add_scenarios_and_observers(p, METHODS)
    p.add_argument("--seeds", type=int, default=1, metavar="N", help="seeds 0 .. N-1 (default 1)")
    p.add_argument("--duration", type=float, metavar="S", help="run length in s (default: each scenario's)")
    p.add_argument("--json", action="store_true", help="print a JSON list of rows (strict JSON) instead")
    p.add_argument("--out", metavar="DIR", help="write E-against-time plots, summary.md and runs.csv here")
    p.add_argument("--overwrite", action="store_true", help="replace those files if DIR already holds them")
    p.set_defaults(func=cmd_compare)


def cmd_compare(args):
    for name in args.scenario:
        case_scenario(name)                     # FmscalError naming the choices
    for name in args.observer:
        get_method(name)                        # FmscalError naming the methods
    check_seeds(seeds=args.seeds)
    if args.duration is not None:
        positive(args.duration, "--duration")
    check_sizes(args.scenario, args.duration)
    if args.out:
        scenarios = dict.fromkeys(case_scenario(name).name for name in args.scenario)
        check_output_dir(args.out, [f"E_{sc}.png" for sc in scenarios] + ["summary.md", "runs.csv"],
                         overwrite=args.overwrite)
    with claim_folder(args.out) if args.out else contextlib.nullcontext():
        table, curves = compare(args.scenario, args.seeds, args.observer, args.duration,
                                progress=not args.json, histories=True)
        summary = summarise(table)
        text = summary_markdown(summary, f"Observer comparison ({args.seeds} seed(s), "
                                         f"{'each scenario' if args.duration is None else f'{args.duration:g} s'})")
        if args.out:
            _write_comparison(Path(args.out), args.duration, table, curves, text)
    if args.json:
        print(json.dumps(strict(table.to_dict(orient="records")), indent=1, allow_nan=False))
    else:
        print(text)


def _write_comparison(out, duration, table, curves, text):
    """compare --out: a figure per scenario, summary.md and runs.csv in ``out``."""
    for scenario in dict.fromkeys(table["scenario"]):
        sc = case_scenario(scenario)
        truth = sc.with_(duration=duration or sc.duration).generate(0)[1]     # seed 0's S(t)
        plot_comparison({obs: v for (name, obs), v in curves.items() if name == scenario}, truth,
                        out / f"E_{scenario}.png",
                        f"E against time and the entries of S_hat, scenario '{scenario}' (seed 0)")
    atomic_write_text(out / "summary.md", text)
    atomic_write(out / "runs.csv", lambda tmp: table.to_csv(tmp, index=False))


class _Parser(argparse.ArgumentParser):
    """argparse, with usage errors on one line (exit 2) instead of usage plus error.

    A negative number in scientific notation (``--inertia ... -1e-4``) is a
    value, not an option: argparse alone takes only ``-1`` and ``-0.5``.
    """

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", HelpFormatter)          # a Words metavar printed as written
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {one_line(message)}\n")


def build_parser():
    """The ``fmscal`` argument parser: every subcommand with its options.

    Returns
    -------
    argparse.ArgumentParser
        The parser :func:`main` uses; ``fmscal --help`` prints it.
    """
    from importlib.metadata import PackageNotFoundError, version
    parser = _Parser(
        prog="fmscal",
        description="Calibrate a force-moment sensor from motion, and compare the observers that do it.")
    try:
        installed = version("fmscal")           # the installed distribution's, as pip reports it
    except PackageNotFoundError:                # the folders imported without an installation
        installed = "unknown (not installed)"
    parser.add_argument("--version", action="version", version=f"%(prog)s {installed}",
                        help="print the installed version of fmscal and exit")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in _COMMANDS:
        add(sub)
    return parser


_COMMANDS = [_add_simulate, add_calibrate, add_apply, add_compensate, add_identify_payload, _add_reproduce,
             _add_compare, _add_ablation, add_sweep, add_bench, _add_check_gains, add_import, add_ros2, add_export]


def main(argv=None):
    """Entry point of ``fmscal``; returns the exit status."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as stop:            # --help, or a usage error already printed on one line
        return stop.code
    try:
        # numpy's RuntimeWarnings on degenerate input would break the one-line promise: the
        # commands report such input themselves (warnings, converged flags, refusals)
        # without --overwrite, no output replaces a file, even one that appears while the command works
        with exclusive(not getattr(args, "overwrite", False)), np.errstate(all="ignore"), \
                warnings.catch_warnings(), one_blas_thread():
            warnings.simplefilter("ignore", RuntimeWarning)
            args.func(args)
    except BrokenPipeError:                    # the reader of stdout went away (| head): stop quietly, as cat does
        return _pipe_closed()
    except (FmscalError, OSError) as err:      # the user's input or files; any other error is a bug
        message = str(err).splitlines()[0] if str(err) else type(err).__name__
        print(f"fmscal {args.command}: error: {one_line(message)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("fmscal: interrupted", file=sys.stderr)
        return 130
    return 0


def _pipe_closed():
    """Exit status 141 (128 + SIGPIPE) for output whose reader went away; stdout pointed at the null device, so
    that the interpreter's last flush raises nothing more."""
    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except (OSError, ValueError):
        pass
    return 141


def console():
    """The installed ``fmscal`` script: :func:`main` on the process's arguments, its code as the exit status.
    Output cut short by its reader (``fmscal ... | head``) ends quietly with status 141."""
    try:
        code = main()
        sys.stdout.flush()
    except BrokenPipeError:
        code = _pipe_closed()
    sys.exit(code)
