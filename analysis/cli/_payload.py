"""``fmscal identify-payload``: what practitioners estimate with ``S`` known, from any data: it prints what
:func:`fmscal.observers.payload.identify_payload` returns.

A spatial log (``t,qw,...,fz``) gives the offset, the mass, the centre of
mass, the force gains and, where the motion turns the payload fast enough, the inertia,
with what the log covered and the next poses to record, as for a table. An attitude-only
log (no ``x,y,z``) gives its held segments as a pose table
(:func:`fmscal.plant.io.held_table`). A pose table (the
same header without ``t``: one row per held pose), or joint angles with ``--urdf``, gives the offset, the mass,
the centre of mass and the force gains, and, where asked, gravity's direction in the pose
frame and the sensor's mounting on the tracked frame, with what the poses
covered and the next poses to record. The payload is saved (``--save``) where it is determined by its effect on
the compensated wrench within the cone of attitudes the data span (``--tolerance``); else the line says why.
"""

import json
import sys

import numpy as np

from fmscal.plant import Calibration, Log
from fmscal.plant.io import AttitudeLog
from fmscal.plant.numerics import FmscalError
from fmscal.plant.physics import GRAVITY, INERTIA_NAMES, find_model, inertia_matrix

from fmscal.observers.payload import identify_payload

from .._calibrate import OptionError, read_data
from ._common import CliError, Words, add_max_mass, max_mass, strict
from ._files import check_inputs, check_outputs
from ._spatial import _NAMES, _spatial_truth

__all__ = ["add_identify_payload", "cmd_identify_payload"]


def add_identify_payload(sub):
    """Add ``fmscal identify-payload`` to the subcommands ``sub``."""
    p = sub.add_parser("identify-payload", help="estimate the payload's mass properties and the offset, S known",
                       description="With the calibration S known (the identity, or --calibration CAL.json), "
                                   "estimate the sensor's offset, the payload's mass and centre of mass and the force "
                                   "axes' gains relative to their mean (static poses suffice) and its inertia (motion "
                                   "needed) from a spatial log, an attitude-only log, a pose table (the spatial header "
                                   "without t, one row per held pose) or joint angles with --urdf, with one-sigma "
                                   "uncertainties; the payload counts as determined by what its uncertainty adds "
                                   "to the compensated wrench within the cone of attitudes the data span "
                                   "(--tolerance), and the data's gaps are said.")
    p.add_argument("log", metavar="LOG.csv|TABLE.csv",
                   help="a spatial log, an attitude-only log, or a pose table (the header tells which)")
    p.add_argument("--calibration", metavar="CAL.json", help="a spatial calibration (default: S = I)")
    p.add_argument("--gravity", nargs="+", metavar=Words("GX GY GZ | estimate"),
                   help="gravity in the pose frame, m/s^2 (default 0 0 -9.81); 'estimate': its direction is "
                        "estimated with the payload (a tilted or wall-mounted base)")
    p.add_argument("--mounting", choices=("estimate",),
                   help="estimate the rotation of the sensor's axes on the tracked frame (a sensor bolted at an "
                        "angle), as a matrix and an angle about an axis")
    p.add_argument("--reading", choices=("reaction", "load"), default=None,
                   help="the reading's sign: reaction (the wrench the mount applies to the payload) or load (the "
                        "wrench the tool applies to the sensor, as ATI, Robotiq, Bota and OnRobot report); default: "
                        "the one --calibration recorded, else reaction")
    add_max_mass(p)
    p.add_argument("--urdf", metavar="ROBOT.urdf",
                   help="the pose columns are the robot's joint angles (q1..qn in the URDF's order, or the joints' "
                        "names; rad): poses of --frame by forward kinematics (pinocchio: pip install "
                        "\"fmscal[robot]\")")
    p.add_argument("--frame", metavar="FRAME", help="the sensor's frame in the URDF (with --urdf)")
    p.add_argument("--truth", metavar="TRUTH.json", help="a truth sidecar from fmscal simulate: report the errors")
    p.add_argument("--json", action="store_true", help="print one JSON object (strict JSON)")
    p.add_argument("--tolerance", type=float, nargs=2, metavar=("N", "NM"),
                   help="the largest standard deviation the payload may add to the compensated wrench within the "
                        "cone of attitudes the data span: forces in N, torques in N m (default one standard "
                        "deviation of the reading's noise: a log's sample-to-sample scatter, a table's rows' scatter "
                        "about the fit)")
    p.add_argument("--save", metavar="PAYLOAD.json",
                   help="write the payload (the tracked frame's axes, and gravity where estimated) for fmscal "
                        "calibrate --payload; only where it is determined (within --tolerance)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --save file")
    p.set_defaults(func=cmd_identify_payload)


def _gravity(args):
    """``(gravity, estimate)`` from ``--gravity``: three numbers, or ``estimate`` (the default's size, 9.81)."""
    given = args.gravity
    if given is None:
        return GRAVITY, False
    if given == ["estimate"]:
        return GRAVITY, True
    try:
        g = [float(v) for v in given]
    except ValueError:
        g = []
    if len(g) != 3 or not (all(np.isfinite(g)) and 0 < np.linalg.norm(g) < 1e3):
        raise CliError(f"--gravity takes three finite numbers in m/s^2 (the pose frame's gravity) or 'estimate'; "
                       f"got {' '.join(given)[:80]}")
    return tuple(g), False


def _calibration_S(args):
    """``S`` of the spatial calibration file ``--calibration`` (None without one); sets ``args.reading``.

    The reading's sign is the one the file recorded; ``--reading`` may repeat
    it, not contradict it (the sign is the sensor's, and ``S`` was fitted to it).
    """
    path = args.calibration
    if not path:
        args.reading = args.reading or "reaction"
        return None
    calibration = Calibration.load(path)
    if find_model(n_w=calibration.size, estimates="mass") is None:     # the payload's model: a 6-axis S
        raise CliError(f"{path} is a {calibration.kind} calibration ({calibration.size}x{calibration.size}); "
                       "identify-payload takes a spatial one")
    if calibration.forced:
        print(f"fmscal identify-payload: warning: {path} was saved with --force", file=sys.stderr)
    if args.reading is not None and args.reading != calibration.reading:
        raise CliError(f"--reading {args.reading} contradicts {path}, recorded with the reading "
                       f"{calibration.reading}: drop --reading, or recalibrate with --reading {args.reading}")
    args.reading = calibration.reading
    return calibration.S


def cmd_identify_payload(args):
    """``fmscal identify-payload``: :func:`fmscal.observers.payload.identify_payload` on any data, its report."""
    inputs = [(args.log, "the log"), (args.calibration, "the --calibration file"), (args.truth, "the --truth file"),
              (args.urdf, "the --urdf file")]
    check_inputs(inputs)
    if args.save is not None and not args.save.endswith(".json"):
        raise CliError(f"--save must end in .json; got {args.save}")
    check_outputs([(args.save, "--save")], inputs, overwrite=args.overwrite)
    gravity, estimate_gravity = _gravity(args)
    S = _calibration_S(args)
    try:
        data = read_data(args.log, args.urdf, args.frame)
    except OptionError as err:
        raise CliError(err.template.format("--urdf and --frame")) from None
    if args.truth and not isinstance(data, Log):
        raise CliError("--truth is taken with a simulated log; a pose table has no truth sidecar")
    truth = _spatial_truth(args.truth)
    try:
        fit = identify_payload(data, S=S, gravity=gravity, reading=args.reading, estimate_gravity=estimate_gravity,
                               estimate_mounting=args.mounting == "estimate", max_mass=max_mass(args),
                               tolerance=args.tolerance)
    except FmscalError as err:
        raise CliError(str(err).replace("tolerance must be", "--tolerance must be", 1)) from None
    for note in fit.notes:                # rows dropped, a log's held segments: said, as calibrate says them
        print(f"fmscal identify-payload: note: {note}", file=sys.stderr)
    for warning in fit.warnings:
        print(f"fmscal identify-payload: warning: {warning}", file=sys.stderr)
    out = {**fit.to_dict(), "reading": args.reading}
    if truth is not None:
        p = truth.payload
        out["mass_error"] = fit.mass - p.mass
        out["com_error"] = (fit.com - np.array(p.com)).tolist()
        # the tensor's six entries (URDF order), in the sensor axes as the fit gives them
        out["inertia_error"] = None if fit.inertia is None else (np.asarray(fit.inertia) - np.array(
            [p.I_c[0, 0], p.I_c[1, 1], p.I_c[2, 2], p.I_c[0, 1], p.I_c[0, 2], p.I_c[1, 2]])).tolist()
        if truth.offset is not None:
            out["b_error"] = (fit.b - truth.offset).tolist()
    if args.json:
        print(json.dumps(strict(out), allow_nan=False))
    else:
        _print_report(args, data, fit, out)
    if args.save is not None:
        fit.save(args.save)               # refused in one line where the payload is not determined
        if not args.json:
            print(f"saved the payload to {args.save} (for fmscal compensate, export ros2-control, calibrate --payload)")


def _print_report(args, data, fit, out):
    """The human-readable report of ``identify-payload`` (``out``: its JSON, with the truth's errors if given)."""
    source = "from " + args.calibration if args.calibration else "= I"
    held = not isinstance(data, Log)                     # held poses: a table, joint angles, a log's held segments
    if held:
        what = "its held segments" if isinstance(data, AttitudeLog) else f"{len(data)} held poses"
        print(f"{data.name}: {what}; S {source}; reading {args.reading}")
    else:
        print(f"{data.name}: {len(data)} samples, {data.duration:g} s; S {source}; reading {args.reading}")
    _print_mass(fit)
    if fit.inertia is None:
        print("inertia: " + ("not determined by held poses (it needs angular acceleration)" if held
                             else "not determined by this log"))
    else:
        print("inertia about the centre of mass [kg m^2]: " + "  ".join(
            f"{n} {v:.4g} +- {s:.1g}" for n, v, s in zip(INERTIA_NAMES, fit.inertia, fit.inertia_std)))
    print("offset b [N m, N]: " + "  ".join(f"{n} {v:+.4g} +- {s:.1e}" for n, v, s in zip(_NAMES, fit.b, fit.b_std)))
    _print_gains(fit)
    _print_rotations(fit)
    _print_calibrate_flags(fit, table=held)
    _print_coverage(fit, () if held else fit.undetermined)
    _print_effect(fit)
    print(f"converged: {'yes' if fit.converged else 'no'}")
    if "mass_error" in out:
        print(f"errors against the truth: mass {out['mass_error']:+.3g} kg, centre of mass "
              + " ".join(f"{v * 1e3:+.3f}" for v in out["com_error"]) + " mm"
              + ("" if out["inertia_error"] is None else ", inertia " + " ".join(
                  f"{n} {v:+.2g}" for n, v in zip(INERTIA_NAMES, out["inertia_error"])) + " kg m^2"))


def _print_gains(fit):
    """The channels' gains relative to the force gains' mean, where estimated (eq. P0)."""
    if fit.gains is None:
        print("gains: not estimated (too few poses for them beside the rotations asked); taken as one")
        return
    print("gains (w = diag(gains) S (sigma w_hat - b); forces relative to their mean): " + "  ".join(
        f"{n} {v:.5f} +- {s:.1g}" if np.isfinite(s) else f"{n} not determined"
        for n, v, s in zip(_NAMES, fit.gains, fit.gains_std)))


def _figure(value, unit, what):
    """A figure with its unit, or "not determined" where its sd is infinite (no "inf N" to read)."""
    return f"{value:.2g} {unit}" if np.isfinite(value) else f"not determined ({what})"


def _print_effect(fit):
    """The payload's effect on the compensated wrench against the tolerance, and the verdict (eq. E3)."""
    forces, torques = _figure(fit.effect[0], "N", "forces"), _figure(fit.effect[1], "N m", "torques")
    print(f"the payload's effect on the compensated wrench within the cone (1 sd): {forces}, {torques}; "
          f"tolerance {fit.tolerance[0]:.2g} N, {fit.tolerance[1]:.2g} N m: "
          + ("determined" if fit.payload_determined else "not determined (" + fit.why_undetermined + ")"))


def _print_mass(fit):
    print(f"mass: {fit.mass:.5g} +- {fit.mass_std:.2g} kg")
    print("centre of mass [mm]: " + "  ".join(f"{v * 1e3:+.3f} +- {s * 1e3:.2g}" for v, s in zip(fit.com, fit.com_std)))


def _print_rotations(fit):
    """Gravity's direction and the mounting, where the fit estimated them."""
    if fit.gravity is not None:
        print(f"gravity in the pose frame [m/s^2]: {' '.join(f'{v:+.4f}' for v in fit.gravity)} "
              f"(direction +- {fit.gravity_std_deg:.2g} degrees)")
    if fit.mounting is not None:
        about = " about " + " ".join(f"{v:+.4f}" for v in fit.mounting_axis)
        print(f"mounting (sensor axes on the tracked frame): {fit.mounting_deg:.3f} +- {fit.mounting_std_deg:.2g} "
              f"degrees{about}; matrix rows " + "; ".join(" ".join(f"{v:+.5f}" for v in row) for row in fit.mounting))


def _print_calibrate_flags(fit, table=False):
    """Where gravity or the mounting was estimated, the payload as ``fmscal calibrate`` takes it.

    ``calibrate`` estimates ``S`` in full, which absorbs the mounting, so it
    works in the axes of the frame the poses track: the centre of mass
    ``M com`` and the inertia ``M I M^T`` there (``M`` the mounting, sensor
    axes to the tracked frame's), and the estimated gravity. Given in the
    sensor's own axes they would be wrong by the mounting's turn, and ``S``
    would absorb that too. Only where the fit determined the mass and the
    centre of mass (``payload_determined``, by its own rule); a table's
    ``calibrate`` takes no inertia.
    """
    if fit.gravity is None and fit.mounting is None:
        return
    if not fit.payload_determined:
        print("for fmscal calibrate: no payload to pass on, it is not determined")
        return
    M = np.eye(3) if fit.mounting is None else np.asarray(fit.mounting)
    flags = f"--mass {fit.mass:.6g} --com {' '.join(f'{v:.6g}' for v in M @ np.asarray(fit.com))}"
    known = None if table else fit.inertia                  # held poses never give the inertia
    if known is not None:
        inertia = M @ inertia_matrix(known) @ M.T
        entries = (inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2])
        flags += f" --inertia {' '.join(f'{v:.6g}' for v in entries)}"
    if fit.gravity is not None:
        flags += f" --gravity {' '.join(f'{v:.6g}' for v in fit.gravity)}"
    if known is None and not table:
        flags += " (and --inertia, which this log did not determine, in the same axes)"
    print(f"for fmscal calibrate (the tracked frame's axes): {flags}")


def _print_coverage(fit, undetermined=()):
    """The cone of gravity directions covered, what the data left (a log's; a table's are its warnings), the next
    poses."""
    print(f"gravity directions covered in the sensor frame: a cone of half-angle {fit.cone_deg:.0f} degrees")
    for words in undetermined:
        print(f"left: {words}")
    for words in fit.next_poses:
        print(f"next pose: {words}")
