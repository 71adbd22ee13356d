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
    p.add_argument("--config", choices=["paper", "adaptive"], default="paper",
                   help="paper: eq. (14) as printed; adaptive: the default configuration's gains")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_check_gains)


def cmd_check_gains(args):
    from observers import AdaptiveObserver, check_gains
    from plant import PAPER_PAYLOAD
    obs = AdaptiveObserver.paper(PAPER_PAYLOAD) if args.config == "paper" else AdaptiveObserver(PAPER_PAYLOAD)
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


def _positive(value, name):
    if not np.isfinite(value) or value <= 0:
        raise CliError(f"{name} must be positive; got {value}")
    return value


def build_parser():
    parser = argparse.ArgumentParser(
        prog="fmscal",
        description="Calibrate a force-moment sensor from motion, and compare the observers that do it.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in _COMMANDS:
        add(sub)
    return parser


_COMMANDS = [_add_simulate, _add_reproduce, _add_check_gains]


def main(argv=None):
    """Entry point of ``fmscal``; returns the exit status."""
    from plant import LogError, SingularCalibrationError
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        args.func(args)
    except (CliError, LogError, SingularCalibrationError, ValueError, OSError) as err:
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
