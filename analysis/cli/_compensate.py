"""``fmscal compensate``: the wrench the environment applies to the tool, from a saved calibration and a log."""

import io
import re
import sys
from pathlib import Path

import numpy as np

from fmscal.plant import Calibration, read_log
from fmscal.plant.io import IMU_COLUMNS, csv_header, read_imu_log, read_joint_log
from fmscal.observers.payload import PayloadEstimate

from .._compensate import (CAUSAL_DELAY, CAUSAL_WINDOW, DIRECTIONS, DRIFT_INTENSITY, FRAMES, OFFLINE_WINDOW,
                           CompensationError, compensate)
from .._motion import ImuMotion, JointMotion, quaternion_to_matrix
from .._calibrate import read_data
from .._setup import load_setup
from .._tool_change import TOOL_CHANGE
from ._common import CliError, Words
from ._files import atomic_write_text, check_inputs, check_outputs


def add_compensate(sub):
    p = sub.add_parser("compensate", help="the contact wrench: the payload's gravity and inertia removed from a log",
                       description="With a calibration saved by fmscal calibrate --save, or a payload file saved by "
                                   "fmscal identify-payload --save (the sensor's own S: the identity, or "
                                   "--calibration's), remove from each reading "
                                   "of LOG.csv the wrench the payload's own motion needs under gravity "
                                   "(Newton-Euler from its poses, from its joint angles with --urdf, or from an "
                                   "IMU on the tool): w_e = W_p - S (w_hat - b), the wrench the "
                                   "environment applies to the tool, at the sensor point in the sensor frame "
                                   "(or as --output-frame and --point say). "
                                   "Writes t, the reading's columns and contact (1 where the wrench is beyond "
                                   "the noise: a chi-square test of its normalised norm).")
    p.add_argument("setup", metavar="CAL.json|PAYLOAD.json",
                   help="a calibration saved by fmscal calibrate --save, or a payload file saved by fmscal "
                        "identify-payload --save (its format tells which): the tool, the offset, gravity, the "
                        "mounting, the reading's sign and their uncertainties")
    p.add_argument("log", metavar="LOG.csv",
                   help="a log of the same sensor: poses and raw readings; with --urdf, t, the joint angles (q1..qn "
                        "or the joints' names, rad) and the readings; or an IMU log: t," + ",".join(IMU_COLUMNS)
                        + ", the readings (the IMU's orientation scalar first in its world, its rate in rad/s and "
                        "specific force in m/s^2 in its axes)")
    p.add_argument("--urdf", metavar="ROBOT.urdf", help="the log's joint angles are this robot's (pinocchio): the "
                                                          "motion from its forward kinematics")
    p.add_argument("--frame", metavar="FRAME", help="the sensor's frame in the URDF (with --urdf)")
    p.add_argument("--imu-rotation", type=float, nargs="+", metavar=Words("QW QX QY QZ | R11 R12 ... R33"),
                   help="an IMU log: the IMU's axes in the sensor's, as a unit quaternion QW QX QY QZ or a rotation "
                        "matrix of 9 numbers by rows (v_sensor = C v_imu); default identity")
    p.add_argument("--imu-lever-arm", type=float, nargs=3, metavar=("X", "Y", "Z"),
                   help="an IMU log: the IMU's point from the sensor's point, sensor axes, m; default 0 0 0")
    p.add_argument("--motion-latency", type=float, metavar="S",
                   help="a joint-state (--urdf) or IMU log: how late its stream is behind the readings, s, either "
                        "sign (a sample in the row of time t is as of t - S); default 0. A pose log's latency is the "
                        "calibration's")
    p.add_argument("--output-frame", choices=FRAMES, default=FRAMES[0],
                   help="the written wrench's axes: the sensor's (default) or the base's (the poses' world, the "
                        "URDF's base, the IMU's world)")
    p.add_argument("--point", type=float, nargs=3, metavar=("X", "Y", "Z"),
                   help="the tool point the torque is taken about, sensor axes from the sensor's point, m "
                        "(default the sensor's point)")
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
                   help="with a calibration: the tool's mass properties from fmscal identify-payload --save, in "
                        "place of the calibration's (a tool change: S does not depend on the tool)")
    p.add_argument("--calibration", metavar="CAL.json",
                   help="with a payload file: the sensor's calibrated S (fmscal calibrate --save, or a maker's "
                        "matrix saved so); default the identity, a factory-calibrated sensor")
    p.add_argument("--tool-radius", type=float, metavar="M",
                   help="with a payload file whose inertia its poses did not determine: the tool's radius about its "
                        "centre of mass, m, which bounds the inertia (default twice the centre of mass's distance, "
                        "at least 0.05)")
    p.add_argument("--on-environment", action="store_true",
                   help="write the wrench the tool applies to the environment (-w_e) instead")
    p.add_argument("--track-offset", action="store_true",
                   help="follow the offset's drift: a random walk updated on the samples with no contact (frozen "
                        "during one); adds the columns b_<channel> and b_sd_<channel>, the offset in the reading's "
                        "units and its sd")
    p.add_argument("--drift-intensity", metavar="Q[,Q...]|fit",
                   help=f"--track-offset: the random walk's intensity, the reading's units per sqrt(s), one value or "
                        f"one per channel (--causal default {DRIFT_INTENSITY:g} x the reading's noise sd); 'fit', "
                        "offline only and its default: that scaled to the maximum of the innovations' likelihood, "
                        "printed")
    p.add_argument("--sd", action="store_true",
                   help="add the columns sd_<channel>: each component's one-sigma uncertainty (the covariance's "
                        "diagonal: the reading's noise, the motion's, the calibration's or the payload's)")
    p.add_argument("--tool-change", choices=TOOL_CHANGE,
                   help="a change of the payload (a part grasped): detect and report it, one line each and the column "
                        "tool_change (the changes declared by each row), the default on a 6-axis log; 'reidentify' "
                        "(--causal) goes on with the payload fitted to the held attitudes after each; 'off'")
    p.add_argument("--overwrite", action="store_true", help="replace an existing CONTACT.csv (never an input)")
    p.set_defaults(func=cmd_compensate)


def _motion_log(args):
    """The log and the motion's source the options and the log's header give: ``(log, motion or None)``."""
    if (args.urdf is None) != (args.frame is None):
        raise CliError("--urdf and --frame go together: the robot's URDF and the sensor's frame in it")
    try:
        header = csv_header(args.log)
    except OSError:
        header = []                                  # the reader below says what is wrong with the file
    imu = "iwx" in header
    if not imu and (args.imu_rotation is not None or args.imu_lever_arm is not None):
        raise CliError(f"--imu-rotation and --imu-lever-arm are an IMU log's; {Path(args.log).name} has no IMU columns "
                       f"({','.join(IMU_COLUMNS)})")
    latency = 0.0 if args.motion_latency is None else args.motion_latency
    if not np.isfinite(latency):
        raise CliError(f"--motion-latency must be a finite number of seconds (either sign); got {latency}")
    if args.motion_latency is not None and args.urdf is None and not imu:
        raise CliError("--motion-latency is a joint-state (--urdf) or IMU log's stream's; a pose log's latency is the "
                       "calibration's (fmscal calibrate --latency)")
    if args.urdf is not None:
        if imu:
            raise CliError("--urdf takes a log of joint angles; this one has an IMU's columns: give one source")
        if header and "t" not in header:             # held poses by their joint angles: a pose table
            return read_data(args.log, urdf=args.urdf, frame=args.frame), None
        motion = JointMotion(args.urdf, args.frame, latency=latency)
        return read_joint_log(args.log, motion.kinematics), motion
    if imu:
        rotation = None
        if args.imu_rotation is not None:
            values = np.asarray(args.imu_rotation, dtype=float)
            if len(values) == 4:
                if abs(np.linalg.norm(values) - 1) > 1e-3:
                    raise CliError(f"--imu-rotation: a quaternion QW QX QY QZ must be a unit one; got norm "
                                   f"{np.linalg.norm(values):.4g}")
                rotation = quaternion_to_matrix(values)
            elif len(values) == 9:
                rotation = values.reshape(3, 3)
            else:
                raise CliError(f"--imu-rotation takes 4 numbers (a unit quaternion QW QX QY QZ) or 9 (a rotation "
                               f"matrix by rows); got {len(values)}")
        return read_imu_log(args.log), ImuMotion(rotation, args.imu_lever_arm, latency=latency)
    if header and "t" not in header:                 # held poses (a pose table): one output per row
        return read_data(args.log), None
    return read_log(args.log), None


def _as_flags(message, args):
    """The library's message about its ``window`` or ``delay`` keyword, naming this command's flag instead.

    ``window 0.06 s is 1 samples at dt = 0.04 s; ...`` becomes ``--window 0.06 s (the default with --causal) is 1
    samples ...``, and ``give a window of at least ...`` ``give --window of at least ...``: the user of the command
    line is told which flag to change (a 25 Hz log needs a longer ``--window`` than the causal default). Any other
    message is returned as it is.
    """
    match = re.match(r"(window|delay) ", message)
    if match is None:
        return message
    keyword = match.group(1)
    given = args.window is not None if keyword == "window" else args.delay != CAUSAL_DELAY
    message = re.sub(r"\b(?:a |the )?(window|delay)\b", r"--\1", message)
    if not given:
        mode = "with --causal" if args.causal else "offline"
        message = re.sub(r"^(--\w+ \S+ s)", rf"\1 (the default {mode})", message)
    return message


def cmd_compensate(args):
    inputs = [(args.setup, "the calibration or payload file"), (args.log, "the log"),
              (args.payload, "the --payload file"), (args.calibration, "the --calibration file"),
              (args.urdf, "the --urdf file")]
    check_inputs(inputs)
    if not args.out.endswith(".csv"):
        raise CliError(f"--out must end in .csv; got {args.out}")
    check_outputs([(args.out, "--out")], inputs, overwrite=args.overwrite)
    setup = load_setup(args.setup)
    payload_file = isinstance(setup, PayloadEstimate)
    if payload_file and args.payload is not None:
        raise CliError(f"{args.setup} is a payload file: --payload replaces a calibration's payload (give the "
                       "calibration first, or the payload file alone)")
    if not payload_file and (args.calibration is not None or args.tool_radius is not None):
        raise CliError(f"--calibration and --tool-radius go with a payload file; {args.setup} is a calibration")
    calibration = None if args.calibration is None else Calibration.load(args.calibration)
    for cal, path in ((setup, args.setup), (calibration, args.calibration)):
        if isinstance(cal, Calibration) and (cal.forced or cal.converged is False):
            print(f"fmscal compensate: warning: {path} records a calibration that did not converge", file=sys.stderr)
    if payload_file and not setup.converged:
        print(f"fmscal compensate: warning: {args.setup} records a payload that did not converge", file=sys.stderr)
    payload = None if args.payload is None else PayloadEstimate.load(args.payload)
    log, motion = _motion_log(args)
    if not args.causal and args.delay != CAUSAL_DELAY:
        raise CliError("--delay is the causal path's: add --causal")
    intensity = None
    if args.drift_intensity is not None:
        if not args.track_offset:
            raise CliError("--drift-intensity is the offset tracker's: add --track-offset")
        if args.drift_intensity.strip() == "fit":
            if args.causal:
                raise CliError("--drift-intensity fit is fitted over the whole log: offline only (leave out --causal)")
            intensity = "fit"
        else:
            try:
                intensity = [float(v) for v in args.drift_intensity.split(",")]
            except ValueError:
                raise CliError(f"--drift-intensity takes numbers separated by commas, or fit; got "
                               f"{args.drift_intensity}") from None
            intensity = intensity[0] if len(intensity) == 1 else intensity
    try:
        result = compensate(setup, log, causal=args.causal, payload=payload, calibration=calibration,
                            tool_radius=args.tool_radius, window=args.window, delay=args.delay,
                            direction=DIRECTIONS[1] if args.on_environment else DIRECTIONS[0],
                            track_offset=args.track_offset, drift_intensity=intensity, motion=motion,
                            frame=args.output_frame, point=args.point, tool_change=args.tool_change)
    except CompensationError as err:
        raise CliError(_as_flags(str(err), args)) from None
    if not np.isfinite(result.wrench).all():
        raise CliError("the compensated wrench is not finite (overflow): the calibration's S or b is far outside "
                       "any sensor's range: nothing written")
    text = io.StringIO()
    sd = result.sd if args.sd else None
    extra = (() if sd is None else tuple(f"sd_{n}" for n in result.names)) + (
        () if result.offset is None else (*(f"b_{n}" for n in result.names), *(f"b_sd_{n}" for n in result.names)))
    changes = () if result.tool_change is None else ("tool_change",)
    text.write(",".join(("t", *result.names, "contact", *extra, *changes)) + "\n")
    for i, (t, w, c) in enumerate(zip(result.t, result.wrench, result.contact)):
        more = (() if sd is None else tuple(sd[i])) + (() if result.offset is None else
                                                       (*result.offset[i], *result.offset_sd[i]))
        tail = "" if not more else "," + ",".join(repr(float(v)) for v in more)
        tail += "" if not changes else f",{int(result.tool_change[i])}"
        text.write(",".join(repr(float(v)) for v in (t, *w)) + f",{int(c)}{tail}\n")
    atomic_write_text(args.out, text.getvalue())
    for warning in result.warnings:
        print(f"fmscal compensate: warning: {warning}", file=sys.stderr)
    rms = np.sqrt(np.mean(result.wrench ** 2, axis=0))
    what = "the tool on the environment" if args.on_environment else "the environment on the tool"
    where = f"{args.output_frame} frame" + ("" if args.point is None else
                                            ", torque about the tool point " + " ".join(f"{v:g}" for v in args.point))
    source = "" if motion is None else f", motion from {motion.source}"
    print(f"wrote {args.out}: {len(result.t)} wrenches of {what} ({where}{source}), "
          f"{'causal, delay ' + format(result.delay * 1e3, '.3g') + ' ms' if args.causal else 'offline'}; "
          f"contact at {int(result.contact.sum())} samples ({100 * result.contact.mean():.2g} %)")
    print("rms " + ", ".join(f"{n} {v:.3g}" for n, v in zip(result.names, rms)))
    if args.track_offset and not args.causal and intensity in (None, "fit"):
        print("drift intensity fitted (per sqrt(s)) " + ", ".join(f"{n} {v:.3g}" for n, v in
                                                                  zip(result.names, result.drift_intensity)))
    for change in result.tool_changes:
        print(change.describe())
    if result.tool_change is not None and not result.tool_changes:
        print("no tool change detected")
    if result.offset is not None:
        print("offset at the end " + ", ".join(f"{n} {v:.4g} +- {s:.2g}" for n, v, s in
                                               zip(result.names, result.offset[-1], result.offset_sd[-1])))
