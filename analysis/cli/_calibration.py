"""``fmscal calibrate`` and ``fmscal apply``: a calibration from a log, and applied to readings."""

import argparse
import copy
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from fmscal.plant import (Calibration, PayloadStd, SPATIAL_SCENARIOS, SpatialModel, file_sha256, read_readings,
                          read_truth)
from fmscal.plant.io import AttitudeLog, NotSavedError, PoseTable, reading_sign
from fmscal.plant.physics import (DEFAULT_COM_STD, DEFAULT_GRAVITY_STD, DEFAULT_INERTIA_STD, DEFAULT_MASS_STD,
                                  PayloadStdError, find_model)

from fmscal.observers import method_names
from fmscal.observers.payload import PayloadEstimate

from .. import _plots
from .._calibrate import DEFAULT_MAX_LATENCY, DEFAULT_METHOD, OptionError, calibrate, log_model_class, read_data
from ._common import (INERTIA_METAVAR, CliError, Words, add_max_mass, flag_payload, max_mass, position_flag,
                      position_values, positive)
from ._files import atomic_write_text, check_inputs, check_outputs
from ._spatial import latency_line, print_spatial, print_std_parts


def add_calibrate(sub):
    p = sub.add_parser("calibrate", help="estimate S from a recorded log",
                       description="Estimate the calibration matrix S from a log and the payload's mass "
                                   "properties: planar (t,theta,x,y,M,fx,fy; rad, m, N m, N) or spatial "
                                   "(t,qw,qx,qy,qz,x,y,z,tx,ty,tz,fx,fy,fz: a 6-axis sensor; the header tells), "
                                   "or a pose table (the spatial header without t, one row per held pose: "
                                   "reports the directions of S held poses cannot determine, never converged). "
                                   "Prints S_hat with its one-sigma uncertainty, whether the run converged, "
                                   "warnings about excitation and model consistency, and E with --truth.")
    p.add_argument("log", metavar="LOG.csv|TABLE.csv",
                   help="a planar or spatial log, or a pose table (the header tells which)")
    p.add_argument("--payload", metavar="PAYLOAD.json",
                   help="the payload as fmscal identify-payload --save wrote it (the tracked frame's axes, and the "
                        "gravity it estimated), instead of --mass, --com and --inertia")
    p.add_argument("--mass", type=float, metavar="KG", help="the payload's mass, kg (or --payload)")
    p.add_argument("--inertia", type=float, nargs="+", metavar=INERTIA_METAVAR,
                   help="planar: I_G about the centre of mass (kg m^2); spatial: IXX IYY IZZ IXY IXZ IYZ, the "
                        "tensor about the centre of mass in sensor axes (a pose table needs it only with --save)")
    p.add_argument("--rho", type=float, **position_values("rho"),
                   help="planar logs: the paper's rho: the sensor's position from the centre of mass G, "
                        "body frame, m; negative values as written")
    p.add_argument("--com", type=float, **position_values("com"),
                   help="spatial logs and pose tables: the centre of mass in the sensor frame, m (seen "
                        "from the sensor: the opposite of a planar rho); negative values as written")
    p.add_argument("--gravity", type=float, nargs=3, metavar=("GX", "GY", "GZ"),
                   help="spatial logs: gravity in the pose frame, m/s^2 (default 0 0 -9.81)")
    p.add_argument("--mass-std", type=float, metavar="KG",
                   help=f"logs: the mass's standard deviation, kg (default {100 * DEFAULT_MASS_STD:g} %% of the "
                        "mass: a weighed tool; a CAD mass is off by a few %%); carried into S_std, as the three below")
    p.add_argument("--com-std", type=float, nargs="+", metavar=Words("M | MX MY MZ"),
                   help=f"logs: the centre of mass's standard deviation, m, one for each axis or one per axis (the "
                        f"planar rho's alike; default {DEFAULT_COM_STD:g} m, CAD's)")
    p.add_argument("--inertia-std", type=float, nargs="+", metavar=Words("REL | REL x 6"),
                   help=f"logs: each inertia entry's standard deviation relative to its scale (I_ii; sqrt(I_ii I_jj) "
                        f"for a product), one for every entry or one per entry (default {DEFAULT_INERTIA_STD:g}, "
                        "CAD's)")
    p.add_argument("--gravity-std", type=float, metavar="M/S2",
                   help=f"spatial logs: gravity's size's standard deviation, m/s^2 (default {DEFAULT_GRAVITY_STD:g}: "
                        "9.81 taken for the local value; 0 for a measured one)")
    p.add_argument("--reading", choices=("reaction", "load"), default=None,
                   help="spatial logs and tables: the reading's sign, reaction (default, the wrench the mount "
                        "applies to the payload) or load (the wrench the tool applies to the sensor, as ATI, "
                        "Robotiq, Bota and OnRobot report); recorded in the saved calibration")
    spatial_methods = method_names(calibrates=True, model=next(iter(SPATIAL_SCENARIOS.values())).payload)
    add_max_mass(p, "spatial logs and tables: ")
    p.add_argument("--observer", choices=method_names(calibrates=True), default=None,
                   help=f"the method (default {DEFAULT_METHOD}: the maximum-likelihood estimate, at the information "
                        "floor; its noise model is estimated from the log unless given). A planar log takes every "
                        "one; a spatial log takes " + ", ".join(spatial_methods) + "; a pose table none (held "
                        "poses have one fit, least squares)")
    p.add_argument("--pose-noise", type=float, nargs=2, metavar=("SD_RAD", "SD_M"),
                   help="planar logs only: pose noise standard deviations, rad and m (default: estimated from "
                        "the log; a spatial log's is always estimated)")
    p.add_argument("--wrench-noise", type=float, nargs=3, metavar=("SD_M", "SD_FX", "SD_FY"),
                   help="planar logs only: raw-reading noise standard deviations, N m and N (default: estimated "
                        "from the log; a spatial log's is always estimated)")
    p.add_argument("--offset", action=argparse.BooleanOptionalAction, default=True,
                   help="estimate the sensor's offset b in w = S (w_hat - b) with S (default: yes; "
                        "--no-offset for an offset-free sensor, as in the paper)")
    p.add_argument("--latency", type=float, metavar="S",
                   help="delay of the pose stream behind the sensor stream, s, any fraction of a sample; negative: the "
                        "wrench stream behind the poses (default: estimated, with its uncertainty; a latency given is "
                        "checked against the log's own)")
    p.add_argument("--max-latency", type=float, default=None, metavar="S",
                   help=f"largest magnitude of the delay searched when estimating it, either sign (default "
                        f"{DEFAULT_MAX_LATENCY:g} s)")
    p.add_argument("--urdf", metavar="ROBOT.urdf",
                   help="the pose columns are the robot's joint angles (q1..qn in the URDF's order, or the joints' "
                        "names; rad), in a spatial log or a table: poses of --frame by forward kinematics "
                        "(pinocchio: pip install \"fmscal[robot]\")")
    p.add_argument("--frame", metavar="FRAME", help="the sensor's frame in the URDF (with --urdf)")
    p.add_argument("--truth", metavar="TRUTH.json", help="a truth sidecar from fmscal simulate: report E")
    p.add_argument("--json", action="store_true", help="print one JSON object (strict JSON)")
    p.add_argument("--plot", metavar="FILE.png",
                   help="draw each entry of S_hat against time with its one-sigma band, and the pose residual")
    p.add_argument("--save", metavar="CAL.json",
                   help="write the calibration here (for fmscal apply), only if the run converged and the "
                        "log's units look right; written atomically, never onto the log or --truth")
    p.add_argument("--force", action="store_true",
                   help="save even a calibration that did not converge; the file records \"forced\": true")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --save or --plot file")
    p.set_defaults(func=cmd_calibrate)


def cmd_calibrate(args):
    """``fmscal calibrate``: :func:`fmscal.analysis.calibrate` on the file, its report printed, saved on request."""
    inputs = [(args.log, "the log"), (args.truth, "the --truth file"), (args.payload, "the --payload file"),
              (args.urdf, "the --urdf file")]
    check_inputs(inputs)
    if args.save and not args.save.endswith(".json"):
        raise CliError(f"--save must end in .json; got {args.save}")
    if args.plot and not args.plot.endswith(".png"):
        raise CliError(f"--plot must end in .png; got {args.plot}")
    if args.force and not args.save:
        raise CliError("--force applies to --save; give --save CAL.json too")
    check_outputs([(args.save, "--save"), (args.plot, "--plot")], inputs, overwrite=args.overwrite)
    try:
        data = read_data(args.log, args.urdf, args.frame)
        table = isinstance(data, (PoseTable, AttitudeLog))
        if table and args.plot is not None:
            raise CliError("--plot is not taken on a pose table (a figure of S against time needs a log)")
        payload = _payload(args, data, table)
        truth = read_truth(args.truth) if args.truth and not table else args.truth
        cal = calibrate(data, payload, observer=args.observer, reading=args.reading, gravity=args.gravity,
                        latency=args.latency, max_latency=args.max_latency, offset=args.offset,
                        pose_noise=args.pose_noise, wrench_noise=args.wrench_noise, truth=truth,
                        max_mass=max_mass(args), payload_std=_payload_std(args))
    except OptionError as err:                    # the library's keyword, as this command's flag
        raise CliError(err.template.format(_FLAGS.get(err.option, err.option))) from None
    for note in cal.notes:
        print(f"fmscal calibrate: note: {note}", file=sys.stderr)
    for warning in cal.warnings:
        print(f"fmscal calibrate: warning: {warning}", file=sys.stderr)
    if args.plot:                 # before saving: a failing plot leaves no calibration behind
        _plot(args, data, cal, truth)
    saved, refused = False, None
    if args.save:                 # the library refuses an unconverged calibration and an existing file: our flags
        try:
            replace(cal, log_name=Path(args.log).name, log_sha256=file_sha256(args.log)).save(
                args.save, force=args.force, overwrite=args.overwrite)
            saved = True
        except NotSavedError as err:
            refused = CliError(err.template.format(_FLAGS[err.option]))
    if args.json:
        print(cal.to_json(saved=saved))
    else:
        _print_calibration(args, data, cal, saved)
    if refused is not None:
        raise refused


#: The command line's flag for each keyword of :func:`fmscal.analysis.calibrate` it refuses.
_FLAGS = {"observer": "--observer", "offset=False": "--no-offset", "pose_noise": "--pose-noise",
          "wrench_noise": "--wrench-noise", "latency": "--latency", "max_latency": "--max-latency", "truth": "--truth",
          "gravity": "--gravity", "reading": "--reading", "urdf and frame": "--urdf and --frame",
          "max_mass": "--max-mass", "force=True": "--force", "overwrite=True": "--overwrite",
          "payload_std": "--mass-std, --com-std, --inertia-std and --gravity-std",
          "payload_std.mass": "--mass-std", "payload_std.com": "--com-std", "payload_std.inertia": "--inertia-std",
          "payload_std.gravity": "--gravity-std"}


def _payload_std(args):
    """``--mass-std``, ``--com-std``, ``--inertia-std`` and ``--gravity-std`` as a :class:`fmscal.plant.PayloadStd`;
    None where none is given (the defaults, or a payload file's own)."""
    fields = {"mass": args.mass_std, "com": args.com_std, "inertia": args.inertia_std, "gravity": args.gravity_std}
    if all(v is None for v in fields.values()):
        return None
    try:
        return PayloadStd(**fields)
    except PayloadStdError as err:
        raise CliError(f"{_FLAGS['payload_std.' + err.field]} {err.message}") from None


def _payload(args, data, table):
    """The payload: ``--payload PAYLOAD.json``, or ``--mass``, ``--inertia`` and ``--rho`` (planar) or ``--com``
    (spatial, tables) in ``data``'s case."""
    flags = [name for name, value in (("--mass", args.mass), ("--rho", args.rho), ("--com", args.com),
                                      ("--inertia", args.inertia)) if value is not None]
    if args.payload is not None:
        if flags:
            raise CliError(f"--payload takes the place of --mass, --com and --inertia; got {' and '.join(flags)} "
                           "too: give one or the other")
        estimate = PayloadEstimate.load(args.payload)
        if args.save and table and estimate.inertia is None:
            raise CliError(f"--save records the payload in the calibration file: {args.payload} holds no inertia "
                           "(held poses do not give it); give --mass, --com and --inertia instead")
        return estimate
    model = SpatialModel if table else log_model_class(data)          # held poses: a 3D payload
    position = position_flag(model, args.rho, args.com, "a pose table" if table else None)
    flag = f"--{model.payload_position}"
    if args.mass is None or position is None:
        raise CliError(f"give the payload: --mass and {flag} (and --inertia), or --payload PAYLOAD.json")
    positive(args.mass, "--mass")
    for value in position:
        if not np.isfinite(value):
            raise CliError(f"{flag} must be finite numbers in m; got {position}")
    if table:
        if len(position) != 3:
            raise CliError(f"a pose table takes --com X Y Z (3 numbers, m, the centre of mass in the sensor frame); "
                           f"got {len(position)}")
        if args.inertia is None:
            if args.save:
                raise CliError("--save records the payload in the calibration file: give --inertia IXX IYY IZZ IXY "
                               "IXZ IYZ too (held poses do not use it)")
            return args.mass, tuple(position)
    return flag_payload(model, args.mass, args.inertia, position)


def _plot(args, log, cal, truth):
    """``--plot``: each entry of ``S_hat`` against time with its band, and the pose residual, on the aligned log."""
    title = f"{Path(args.log).name}: entries of S_hat ({cal.method}) and the pose residual"
    signed = copy.copy(log)                       # the reading in the toolkit's sign, as it was calibrated
    signed.w_hat = reading_sign(cal.reading) * log.w_hat
    cls = log_model_class(log)
    model = cls(cal.payload, cal.gravity) if cls.under_gravity else cls(cal.payload)
    _plots.plot_calibration(cal.run, signed.shift_poses(cal.latency), args.plot, title, truth, model)


def _print_calibration(args, data, cal, saved):
    """The human-readable report of ``fmscal calibrate``."""
    out = json.loads(cal.to_json(saved=saved))
    for key in ("S_std", "b_std"):                # infinite (not determined) as inf, not JSON's null
        out[key] = None if getattr(cal, key) is None else getattr(cal, key).tolist()
    name = Path(args.log).name
    if isinstance(data, (PoseTable, AttitudeLog)):
        what = ("attitude-only log, its held segments" if isinstance(data, AttitudeLog)
                else "table of joint angles" if args.urdf else "pose table")
        print_spatial(args, f"{name}: {what}, {cal.poses} held poses; method {cal.method} (S = I where the poses "
                      "say nothing)", out)
        return
    if "noise" not in out:            # a log whose method estimated its own noise model: the report by channel
        print_spatial(args, f"{name}: {cal.kind}, {len(data)} samples, {data.duration:g} s, "
                      f"{int(data.has_pose.sum())} pose measurements; method {cal.method}", out)
        return
    print(f"{name}: {len(data)} samples, {data.duration:g} s, "
          f"{int(data.has_pose.sum())} pose measurements; method {out['observer']}")
    if out["noise_estimated"]:
        n = out["noise"]
        print(f"noise estimated from the log ({' and '.join(out['noise_estimated'])}): wrench sd "
              f"{', '.join(f'{v:.3g}' for v in n['wrench_sd'])}; angle sd {n['angle_sd']:.3g} rad; "
              f"position sd {n['position_sd']:.3g} m")
    S, S_std = np.array(out["S"]), out["S_std"]
    print("S_hat" + (" +- one sigma:" if S_std is not None else " (this method gives no uncertainty):"))
    for i in range(len(S)):
        cells = [f"{S[i, j]:+.5f}" + (f" +- {S_std[i][j]:.1e}" if S_std is not None else "") for j in range(len(S))]
        print("  " + "   ".join(cells))
    print_std_parts(out, cal.kind)
    if out["b"] is not None:
        b, b_std = out["b"], out["b_std"]
        cells = [f"{b[j]:+.5g}" + (f" +- {b_std[j]:.1e}" if b_std is not None else "") for j in range(len(b))]
        print("offset b [N m, N, N]: " + "   ".join(cells))
    print(latency_line(out))
    print(f"converged: {'yes' if out['converged'] else 'no'} (at t = {cal.run.t[-1]:g} s)")
    if "E" in out:
        print(f"E = ||I - S_hat S^-1||_2 = {out['E']:.4g}")
    if out["saved"]:
        print(f"saved the calibration to {args.save}")


def add_apply(sub):
    p = sub.add_parser("apply", help="turn raw readings into calibrated wrenches with a saved calibration",
                       description="Apply a calibration saved by fmscal calibrate --save: w = S (w_hat - b), or "
                                   "w = S (-w_hat - b) for a calibration recorded with --reading load, "
                                   "for every row of READINGS.csv (columns t,M,fx,fy, or t,tx,ty,tz,fx,fy,fz "
                                   "for a spatial calibration, or a full log); writes the same columns.")
    p.add_argument("calibration", metavar="CAL.json", help="a calibration saved by fmscal calibrate --save")
    p.add_argument("readings", metavar="READINGS.csv",
                   help="the raw readings: t,M,fx,fy (planar), t,tx,ty,tz,fx,fy,fz (spatial), or a full log")
    p.add_argument("--out", required=True, metavar="WRENCH.csv",
                   help="the calibrated wrenches, the same columns as the readings")
    p.add_argument("--overwrite", action="store_true", help="replace an existing WRENCH.csv (never an input)")
    p.add_argument("--mass", type=float, metavar="KG", help="refuse a calibration made for another payload")
    p.add_argument("--inertia", type=float, nargs="+", metavar=INERTIA_METAVAR,
                   help="planar I_G, or the six spatial entries")
    p.add_argument("--rho", type=float, **position_values("rho"),
                   help="planar: the sensor's position from the centre of mass (body frame, m)")
    p.add_argument("--com", type=float, **position_values("com"),
                   help="spatial: the centre of mass in the sensor frame (m)")
    p.set_defaults(func=cmd_apply)


def cmd_apply(args):
    inputs = [(args.calibration, "the calibration"), (args.readings, "the readings")]
    check_inputs(inputs)
    if args.rho is not None and args.com is not None:
        raise CliError("give --rho (a planar payload) or --com (a spatial one), not both")
    position = args.rho if args.com is None else args.com
    given = [v is not None for v in (args.mass, args.inertia, position)]
    if any(given) and not all(given):
        raise CliError("give all of --mass, --inertia and --rho (planar) or --com (spatial) to check the payload, "
                       "or none")
    payload = None
    if all(given):
        name = "rho" if args.com is None else "com"
        cls = find_model(position=name)
        payload = flag_payload(cls, args.mass, args.inertia, position)
    if not args.out.endswith(".csv"):
        raise CliError(f"--out must end in .csv; got {args.out}")
    check_outputs([(args.out, "--out")], inputs, overwrite=args.overwrite)
    calibration = Calibration.load(args.calibration, payload)
    if calibration.forced:
        print(f"fmscal apply: warning: {args.calibration} was saved with --force (force=True): its run had not "
              "converged",
              file=sys.stderr)
    elif calibration.converged is False:          # a file written by hand, or by fmscal before save refused it
        print(f"fmscal apply: warning: {args.calibration} records a calibration that did not converge",
              file=sys.stderr)
    t, w_hat = read_readings(args.readings)
    model = find_model(n_w=calibration.size)      # a calibration is of one
    if w_hat.shape[1] != calibration.size:
        raise CliError(f"{Path(args.readings).name} holds {w_hat.shape[1]} reading columns; the calibration is "
                       f"{calibration.size}x{calibration.size} ({model.name})")
    w = calibration.apply(w_hat)                            # the sign of a load reading turned first
    bad = ~np.isfinite(w).all(axis=1)
    if bad.any():
        raise CliError(f"the calibration gives a wrench that is not finite (overflow) at row {np.argmax(bad) + 1} of "
                       f"{Path(args.readings).name}; its S or b is far outside any sensor's range: nothing written")
    header = ",".join(("t", *model.wrench_names))
    lines = [header] + [",".join(repr(float(v)) for v in (ti, *wi)) for ti, wi in zip(t, w)]
    atomic_write_text(args.out, "\n".join(lines) + "\n")
    print(f"wrote {args.out}: {len(t)} calibrated wrenches (calibration of {calibration.log_name or 'unknown log'}, "
          f"{calibration.method}, {calibration.date}; reading {calibration.reading})")
