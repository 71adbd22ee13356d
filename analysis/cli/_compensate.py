"""``fmscal compensate``: the wrench the environment applies to the tool, from a saved calibration and a log."""

import io
import sys
from pathlib import Path

import numpy as np

from fmscal.plant import Calibration, read_log
from fmscal.observers.payload import PayloadEstimate

from .._compensate import (CAUSAL_DELAY, CAUSAL_WINDOW, DIRECTIONS, DRIFT_INTENSITY, OFFLINE_WINDOW, compensate,
                           compensation_model)
from ._common import CliError
from ._files import atomic_write_text, check_outputs


def add_compensate(sub):
    p = sub.add_parser("compensate", help="the contact wrench: the payload's gravity and inertia removed from a log",
                       description="With a calibration saved by fmscal calibrate --save, remove from each reading "
                                   "of LOG.csv the wrench the payload's own motion needs under gravity "
                                   "(Newton-Euler from its poses): w_e = W_p - S (w_hat - b), the wrench the "
                                   "environment applies to the tool, at the sensor point in the sensor frame. "
                                   "Writes t, the reading's columns and contact (1 where the wrench is beyond "
                                   "the noise: a chi-square test of its normalised norm).")
    p.add_argument("calibration", metavar="CAL.json", help="a calibration saved by fmscal calibrate --save")
    p.add_argument("log", metavar="LOG.csv", help="a log of the same sensor (poses and raw readings)")
    p.add_argument("--out", required=True, metavar="CONTACT.csv",
                   help="t, the wrench's columns (t,tx,ty,tz,fx,fy,fz in 3D) and contact (0 or 1)")
    p.add_argument("--causal", action="store_true",
                   help=f"differentiate the poses causally, as on a running robot (a {CAUSAL_WINDOW * 1e3:g} ms "
                        f"window read {CAUSAL_DELAY * 1e3:g} ms back: each row is the reading of its time, "
                        f"available that much later); default both ways ({OFFLINE_WINDOW * 1e3:g} ms window)")
    p.add_argument("--window", type=float, metavar="S",
                   help=f"the smoothing window, s (default {OFFLINE_WINDOW:g} offline, {CAUSAL_WINDOW:g} causal; "
                        "longer for poses at a lower rate)")
    p.add_argument("--delay", type=float, metavar="S", default=CAUSAL_DELAY,
                   help=f"--causal: where the window is read, s before the newest sample (default {CAUSAL_DELAY:g}); "
                        "at least the calibration's latency")
    p.add_argument("--payload", metavar="PAYLOAD.json",
                   help="the tool's mass properties from fmscal identify-payload --save, in place of the "
                        "calibration's (a tool change: S does not depend on the tool)")
    p.add_argument("--on-environment", action="store_true",
                   help="write the wrench the tool applies to the environment (-w_e) instead")
    p.add_argument("--track-offset", action="store_true",
                   help="follow the offset's drift: a random walk updated on the samples with no contact (frozen "
                        "during one); adds the columns b_<channel> and b_sd_<channel>, the offset in the reading's "
                        "units and its sd")
    p.add_argument("--drift-intensity", metavar="Q[,Q...]",
                   help=f"--track-offset: the random walk's intensity, the reading's units per sqrt(s), one value or "
                        f"one per channel (default {DRIFT_INTENSITY:g} x the reading's noise sd)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing CONTACT.csv (never an input)")
    p.set_defaults(func=cmd_compensate)


def _payload(path, calibration):
    """The payload of an identify-payload file, as the calibration's model takes it."""
    estimate = PayloadEstimate.load(path)
    if estimate.inertia is None:
        raise CliError(f"{Path(path).name} holds no inertia (its log did not determine it): the motion's wrench "
                       "needs it; identify the payload from a log with more angular acceleration, or give a "
                       "calibration that holds the tool")
    model = compensation_model(calibration)
    return type(model).payload_from(estimate.mass, estimate.inertia, estimate.com)


def cmd_compensate(args):
    if not args.out.endswith(".csv"):
        raise CliError(f"--out must end in .csv; got {args.out}")
    inputs = [(args.calibration, "the calibration"), (args.log, "the log")]
    if args.payload is not None:
        inputs.append((args.payload, "the --payload file"))
    check_outputs([(args.out, "--out")], inputs, overwrite=args.overwrite)
    calibration = Calibration.load(args.calibration)
    if calibration.forced or calibration.converged is False:
        print(f"fmscal compensate: warning: {args.calibration} records a calibration that did not converge",
              file=sys.stderr)
    payload = None if args.payload is None else _payload(args.payload, calibration)
    log = read_log(args.log)
    if not args.causal and args.delay != CAUSAL_DELAY:
        raise CliError("--delay is the causal path's: add --causal")
    intensity = None
    if args.drift_intensity is not None:
        if not args.track_offset:
            raise CliError("--drift-intensity is the offset tracker's: add --track-offset")
        try:
            intensity = [float(v) for v in args.drift_intensity.split(",")]
        except ValueError:
            raise CliError(f"--drift-intensity takes numbers separated by commas; got {args.drift_intensity}") from None
        intensity = intensity[0] if len(intensity) == 1 else intensity
    result = compensate(calibration, log, causal=args.causal, payload=payload, window=args.window,
                        delay=args.delay, direction=DIRECTIONS[1] if args.on_environment else DIRECTIONS[0],
                        track_offset=args.track_offset, drift_intensity=intensity)
    if not np.isfinite(result.wrench).all():
        raise CliError("the compensated wrench is not finite (overflow): the calibration's S or b is far outside "
                       "any sensor's range: nothing written")
    text = io.StringIO()
    extra = () if result.offset is None else (*(f"b_{n}" for n in result.names),
                                              *(f"b_sd_{n}" for n in result.names))
    text.write(",".join(("t", *result.names, "contact", *extra)) + "\n")
    for i, (t, w, c) in enumerate(zip(result.t, result.wrench, result.contact)):
        tail = "" if not extra else "," + ",".join(repr(float(v)) for v in (*result.offset[i], *result.offset_sd[i]))
        text.write(",".join(repr(float(v)) for v in (t, *w)) + f",{int(c)}{tail}\n")
    atomic_write_text(args.out, text.getvalue())
    for warning in result.warnings:
        print(f"fmscal compensate: warning: {warning}", file=sys.stderr)
    rms = np.sqrt(np.mean(result.wrench ** 2, axis=0))
    what = "the tool on the environment" if args.on_environment else "the environment on the tool"
    print(f"wrote {args.out}: {len(result.t)} wrenches of {what} (sensor frame), "
          f"{'causal, delay ' + format(result.delay * 1e3, '.3g') + ' ms' if args.causal else 'offline'}; "
          f"contact at {int(result.contact.sum())} samples ({100 * result.contact.mean():.2g} %)")
    print("rms " + ", ".join(f"{n} {v:.3g}" for n, v in zip(result.names, rms)))
    if result.offset is not None:
        print("offset at the end " + ", ".join(f"{n} {v:.4g} +- {s:.2g}" for n, v, s in
                                               zip(result.names, result.offset[-1], result.offset_sd[-1])))
