"""The payload's uncertainty in ``S_std`` (issue 46): its targets over seeds, and its cost in ``fmscal calibrate``.

Usage (from the repository's root)::

    python benchmarks/payload_std.py                       # the targets' table: 20 seeds of 10 s, each setting
    python benchmarks/payload_std.py --seeds 40 --duration 20 --sources spatial-arm spatial-mocap paper
    python benchmarks/payload_std.py --timing              # the cost, on a 60 s spatial-arm log at 1 kHz
    python benchmarks/payload_std.py --cases               # the issue's cases, one log: max |z| before and after

The table. For each source of logs (``simulate``'s ``spatial-arm``,
``spatial-mocap``, and the planar ``paper``) and each setting of the
payload's standard deviations (:data:`SETTINGS`: the defaults of
:mod:`fmscal.plant.physics._payload_std`, and a tool known from CAD alone), over
the seeds: the payload given to ``calibrate`` is the true one plus an error
drawn from the covariance those standard deviations make
(:meth:`fmscal.plant.PayloadStd.covariance` at the true payload; a draw that is
no valid payload, an inertia breaking the triangle inequality, is drawn
again), and ``calibrate`` is told the same standard deviations. Printed: the
z-scores' rms ``(S_hat - S) / S_std`` over every entry and seed (target:
within [0.7, 1.4]), and on the torque and the force rows; the same with the
payload taken as exact (what ``fmscal calibrate`` did before); the share of
seeds converged; and how many named the inertia beyond its stated
uncertainty (eq. (M4) of :mod:`fmscal.observers.diagnostics._misfit`).

The cases: the issue's payload errors on one log (seed 1, 10 s ``spatial-arm``):
the largest ``|z|`` with the payload taken as exact (as before), with the
default standard deviations, and with each error's own size stated as its
standard deviation (:data:`CASES`).

The timing: the CPU seconds of ``fmscal calibrate`` on a 60 s ``spatial-arm``
log (the child's user and system time, least of three), and of the payload's
sensitivity alone (:func:`fmscal.observers.batch.payload_sensitivity`, in this
process) on the same log: the share of the command the payload's uncertainty
costs. On a shared machine, compare ratios measured in one run.
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: The payload's standard deviations of each setting (:class:`fmscal.plant.PayloadStd`'s fields; None: the default).
SETTINGS = {"defaults": {},
            "cad": {"mass_rel": 0.03, "com": 0.002, "inertia": 0.2, "gravity": 0.02}}
TOOL = ["--mass", "1.2", "--com", "0.01", "-0.005", "0.06", "--inertia", "4e-3", "5e-3", "2.5e-3", "2e-4", "-1e-4",
        "1.5e-4"]


def payload_std(setting, model):
    """The :class:`fmscal.plant.PayloadStd` of a setting for a payload (its mass's sd relative in ``mass_rel``)."""
    from fmscal.plant import PayloadStd
    fields = dict(SETTINGS[setting])
    if "mass_rel" in fields:
        fields["mass"] = fields.pop("mass_rel") * model.payload.mass
    if not model.under_gravity:
        fields.pop("gravity", None)
    return PayloadStd(**fields)


def draw_model(model, cov, rng):
    """The model with its payload moved by a draw of ``N(0, cov)``; drawn again until it is a valid payload."""
    from fmscal.plant import FmscalError
    theta = model.payload_parameters()
    root = np.linalg.cholesky(cov + 1e-30 * np.eye(len(cov)))
    for _ in range(1000):
        try:
            return model.with_payload_parameters(theta + root @ rng.standard_normal(len(theta)))
        except FmscalError:
            continue
    raise RuntimeError("no valid payload in 1000 draws")


def _source(name, duration):
    """``seed -> (log, S, model)`` of a source of logs."""
    from fmscal.plant import SPATIAL_SCENARIOS, PlanarModel, get_scenario
    if name in SPATIAL_SCENARIOS:
        scenario = SPATIAL_SCENARIOS[name].with_(duration=duration)
        model = scenario.model()
    else:
        scenario = get_scenario(name).with_(duration=duration)
        model = PlanarModel(scenario.payload)

    def make(seed):
        log, truth, _ = scenario.generate(seed)
        return log, truth.S_at(log.t[-1]), model
    return make


def targets(seeds, duration, sources=("spatial-arm", "spatial-mocap"), settings=tuple(SETTINGS), per_seed=False):
    """Rows of the targets' table (module docstring), one per source and setting."""
    from fmscal.analysis import calibrate
    from fmscal.plant import PayloadStd
    rows = []
    for name in sources:
        make = _source(name, duration)
        for setting in settings:
            rng = np.random.default_rng(20261128)
            z, z_exact, converged, beyond = [], [], [], 0
            for seed in range(seeds):
                log, S, model = make(seed)
                std = payload_std(setting, model)
                given = draw_model(model, std.covariance(model), rng)
                cal = calibrate(log, given, payload_std=std)
                exact = calibrate(log, given, payload_std=PayloadStd.exact())
                z.append(((np.asarray(cal.S) - S) / np.asarray(cal.S_std)))
                z_exact.append(((np.asarray(exact.S) - S) / np.asarray(exact.S_std)))
                converged.append(cal.converged)
                beyond += any("inertia does not fit" in w for w in cal.warnings)
                if per_seed:
                    print(f"{name:>14} {setting:>8} seed {seed:2d}  z rms {np.sqrt(np.mean(z[-1] ** 2)):.2f} "
                          f"(exact {np.sqrt(np.mean(z_exact[-1] ** 2)):.2f}) max {np.abs(z[-1]).max():.2f}  "
                          f"converged {cal.converged}  {cal.why_unconverged or ''}", flush=True)
            z, z_exact = np.array(z), np.array(z_exact)
            n = z.shape[1]
            blocks = {"torque": slice(0, n // 2), "force": slice(n // 2, n)} if n == 6 else {"all": slice(0, n)}
            rows.append({"source": name, "setting": setting, "seeds": seeds, "z_rms": _rms(z),
                         "z_rms_exact": _rms(z_exact),
                         "z_rms_blocks": {k: _rms(z[:, rows_]) for k, rows_ in blocks.items()},
                         "converged": float(np.mean(converged)), "inertia_beyond": int(beyond)})
            print(_line(rows[-1]), flush=True)
    return rows


def _rms(z):
    return float(np.sqrt(np.mean(np.square(z))))


def _line(row):
    blocks = ", ".join(f"{k} rows {v:.2f}" for k, v in row["z_rms_blocks"].items())
    return (f"{row['source']:>14} {row['setting']:>8}: z rms {row['z_rms']:.2f} ({blocks}); payload taken as exact "
            f"{row['z_rms_exact']:.2f}; converged {100 * row['converged']:.0f} %; inertia beyond its stated "
            f"uncertainty {row['inertia_beyond']} of {row['seeds']}")


#: The issue's cases (seed 1, 10 s spatial-arm): a name, the payload's numbers moved (index: factor, or a shift
#: in m), and the standard deviations that state the error's own size.
CASES = (("mass 1 % high", {0: 1.01}, {"mass": 0.012}),
         ("mass 5 % high", {0: 1.05}, {"mass": 0.06}),
         ("inertia 1.2x (all entries)", {i: 1.2 for i in range(4, 10)}, {"inertia": 0.2}),
         ("IXX 1.3x (the shape)", {4: 1.3}, {"inertia": 0.3}),
         ("gravity 9.7 for 9.81", {10: 9.7 / 9.81}, {"gravity": 0.11}),
         ("com x 3 mm off", {1: ("shift", 0.003)}, {"com": 0.003}))


def cases(seed=1, duration=10.0):
    """The issue's cases (:data:`CASES`): the largest ``|z|`` with the payload taken as exact, with the default
    standard deviations, and with the error's own size stated as its standard deviation; converged, and whether
    the inertia was named."""
    from fmscal.analysis import calibrate
    from fmscal.plant import PayloadStd
    log, S, model = _source("spatial-arm", duration)(seed)
    print(f"spatial-arm, seed {seed}, {duration:g} s, the latency estimated; max |z| over S's 36 entries\n")
    print("| case | payload exact | defaults | its own size stated | converged (stated) | inertia named |")
    print("|---|---|---|---|---|---|")
    for name, moves, stated in CASES:
        theta = model.payload_parameters()
        for index, move in moves.items():
            theta[index] = theta[index] + move[1] if isinstance(move, tuple) else theta[index] * move
        given = model.with_payload_parameters(theta)
        out = []
        for std in (PayloadStd.exact(), PayloadStd(), PayloadStd(**stated)):
            cal = calibrate(log, given, payload_std=std)
            out.append((np.abs((np.asarray(cal.S) - S) / np.asarray(cal.S_std)).max(), cal))
        named = any("inertia" in w for w in out[2][1].warnings + out[2][1].notes)
        print(f"| {name} | {out[0][0]:.1f} | {out[1][0]:.1f} | {out[2][0]:.1f} | "
              f"{'yes' if out[2][1].converged else 'no'} | {'yes' if named else 'no'} |", flush=True)


def timing(repeat=3):
    """CPU seconds of ``fmscal calibrate`` of a 60 s spatial-arm log at 1 kHz (least of ``repeat``), and of the
    payload's sensitivity alone on that log (least of ``repeat``, this process)."""
    from fmscal.analysis import read_data
    from fmscal.observers.batch import payload_sensitivity
    from fmscal.plant import SPATIAL_SCENARIOS
    with tempfile.TemporaryDirectory() as folder:
        log = Path(folder) / "arm.csv"
        subprocess.run([sys.executable, "-m", "fmscal.analysis.cli", "simulate", "--scenario", "spatial-arm",
                        "--duration", "60", "--seed", "1", "--out", str(log)], check=True, capture_output=True)
        times = []
        for _ in range(repeat):
            start = os.times()
            subprocess.run([sys.executable, "-m", "fmscal.analysis.cli", "calibrate", str(log), *TOOL], check=True,
                           capture_output=True)
            end = os.times()
            times.append(end.children_user + end.children_system - start.children_user - start.children_system)
        data, model = read_data(log), SPATIAL_SCENARIOS["spatial-arm"].model()
        own = []
        for _ in range(repeat):
            start = time.process_time()
            payload_sensitivity(data, model)
            own.append(time.process_time() - start)
    return min(times), min(own)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timing", action="store_true", help="only the cost")
    parser.add_argument("--cases", action="store_true", help="only the issue's cases (seed 1, 10 s spatial-arm)")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--duration", type=float, default=10.0, help="s of each log of the table")
    parser.add_argument("--sources", nargs="+", default=["spatial-arm", "spatial-mocap"])
    parser.add_argument("--settings", nargs="+", default=list(SETTINGS), choices=list(SETTINGS))
    parser.add_argument("--per-seed", action="store_true", help="print each seed")
    args = parser.parse_args(argv)
    if args.timing:
        total, own = timing()
        print(f"fmscal calibrate, 60 s spatial-arm at 1 kHz: {total:.2f} CPU s, of which the payload's sensitivity "
              f"{own:.2f} s ({100 * own / total:.0f} %)")
        return
    if args.cases:
        cases()
        return
    print(f"{args.seeds} seeds of {args.duration:g} s; target: z rms in [0.7, 1.4]")
    targets(args.seeds, args.duration, args.sources, args.settings, args.per_seed)


if __name__ == "__main__":
    main()
