"""The commands on spatial logs: ``calibrate`` of a 6-axis sensor, and ``identify-payload``.

A spatial log (header ``t,qw,qx,qy,qz,x,y,z,tx,ty,tz,fx,fy,fz``) goes where a
planar one goes: ``fmscal calibrate`` picks the case from the header. In 3D
the calibration is the maximum-likelihood floor, linearised about the
smoothed motion (:mod:`fmscal.observers.batch._linearised_floor`), or the reference
fit (``--observer least-squares``: smoothed inverse dynamics and least
squares, :func:`fmscal.observers.batch.fit_inverse_dynamics`),
both through the one registry, as are the online methods that run in 3D
(``--observer adaptive``, which reports no uncertainty, or ``ekf``); the pose
stream's latency is estimated as in the plane, and the options that only the
planar methods use are refused in one line.

A pose table (the same header without ``t``, one row per held pose; or an
attitude-only log, its held segments) goes to ``fmscal calibrate`` too
(:func:`calibrate_table`): held poses never determine ``S`` in full, so the
report names the directions of the reading they leave undetermined and is
never converged. ``--reading load`` turns the reading's sign first (a sensor
that reports the wrench the tool applies to it) and is recorded in the
saved calibration.
"""

import json
import sys
from pathlib import Path

import numpy as np

from fmscal.analysis.cli._common import CliError, positive, strict

__all__ = ["calibrate_spatial", "calibrate_table", "spatial_payload", "gravity_of", "joint_data"]
_NAMES = ("tx", "ty", "tz", "fx", "fy", "fz")


def spatial_payload(mass, rho, inertia):
    """The payload from ``--mass``, ``--rho X Y Z`` and ``--inertia IXX IYY IZZ IXY IXZ IYZ``, or a one-line error."""
    from fmscal.plant import SpatialPayload
    if rho is None or inertia is None or len(rho) != 3 or len(inertia) != 6:
        raise CliError(f"a spatial log takes --rho X Y Z (3 numbers, m) and --inertia IXX IYY IZZ IXY IXZ IYZ "
                       f"(6 numbers, kg m^2, about the centre of mass, sensor axes); got {len(rho or ())} and "
                       f"{len(inertia or ())}")
    return SpatialPayload(positive(mass, "--mass"), tuple(rho), tuple(inertia))


def gravity_of(args):
    """``--gravity GX GY GZ`` (m/s^2, pose frame) or the default, checked."""
    from fmscal.plant.physics._rigid_body import GRAVITY
    g = args.gravity if getattr(args, "gravity", None) is not None else GRAVITY
    if not (all(np.isfinite(v) for v in g) and 0 < np.linalg.norm(g) < 1e3):
        raise CliError(f"--gravity must be three finite numbers in m/s^2 (the pose frame's gravity); got {list(g)}")
    return tuple(float(v) for v in g)


def joint_data(args, path):
    """The log or table ``path`` whose pose columns are joint angles, as poses of ``--frame`` (``--urdf``).

    Parameters
    ----------
    args : argparse.Namespace
        With ``urdf`` and ``frame`` (both None, or both given).
    path : Path

    Returns
    -------
    plant.Log or plant.PoseTable or None
        None without ``--urdf``: the file holds poses.

    Raises
    ------
    CliError
        One of ``--urdf`` and ``--frame`` without the other.
    """
    if (args.urdf is None) != (args.frame is None):
        raise CliError("--urdf and --frame go together: the robot's URDF and the sensor's frame in it")
    if args.urdf is None:
        return None
    from fmscal.plant.io._kinematics import RobotKinematics, read_joint_data
    return read_joint_data(path, RobotKinematics(args.urdf, args.frame))


def _spatial_truth(path):
    """The truth sidecar at ``path`` (None without one), refused if it is a planar log's."""
    from fmscal.plant import read_truth
    truth = read_truth(path) if path else None
    if truth is not None and truth.schedule.size != 6:
        raise CliError(f"{path} is the truth of a planar log; this log is spatial")
    return truth


def _refuse_planar_options(args, model):
    """One line for an option the spatial calibration does not take (yet), or a method that does not run in 3D."""
    from fmscal.observers import FLOOR_METHOD, get_method, method_names
    if args.observer is not None:
        get_method(args.observer)                              # an unknown name: FmscalError naming the methods
        offered = method_names(calibrates=True, model=model)
        if args.observer not in offered:
            raise CliError(f"--observer {args.observer} does not run on a spatial log yet; a spatial log takes "
                           f"{', '.join(offered)} (default {FLOOR_METHOD})")
    given = [(args.pose_noise is not None, "--pose-noise", "the noise is estimated from the log"),
             (args.wrench_noise is not None, "--wrench-noise", "the noise is estimated from the log"),
             (not args.offset, "--no-offset", "the offset is always estimated in 3D")]
    for present, option, why in given:
        if present:
            raise CliError(f"{option} is not taken on a spatial log ({why})")


def calibrate_spatial(args, log=None):
    """``fmscal calibrate`` on a spatial log: ``S`` (6x6) and the offset, with what the log did not determine.

    Parameters
    ----------
    args : argparse.Namespace
        ``fmscal calibrate``'s options.
    log : plant.Log, optional
        The log (from joint angles, :func:`joint_data`); default: read from ``args.log``.
    """
    from fmscal.observers import make_observer
    from fmscal.observers.diagnostics._faults import saturation
    from fmscal.observers.batch._latency import estimate_latency
    from fmscal.plant import SpatialModel, read_log
    from fmscal.plant.io._calibration import reading_sign
    from fmscal.analysis._calibrate import DEFAULT_MAX_LATENCY
    from fmscal.analysis._metrics import block_errors
    from fmscal.analysis._plots import plot_calibration
    from fmscal.observers import FLOOR_METHOD
    payload = spatial_payload(args.mass, args.rho, args.inertia)
    model = SpatialModel(payload, gravity_of(args))
    _refuse_planar_options(args, model)
    name = args.observer or FLOOR_METHOD
    log = read_log(args.log) if log is None else log
    for note in log.notes:
        print(f"fmscal calibrate: note: {note}", file=sys.stderr)
    reading = args.reading or "reaction"
    log.w_hat = reading_sign(reading) * log.w_hat             # the toolkit's sign: S and b are of sigma w_hat
    truth = _spatial_truth(args.truth)
    latency_estimated = args.latency is None
    latency = args.latency
    if latency_estimated:
        latency, _ = estimate_latency(log, model, args.max_latency or DEFAULT_MAX_LATENCY, offset=True)
    aligned = log.shift_poses(latency)
    result = make_observer(name, model, settings={"offset": True}).run(aligned)
    if result.diverged:                  # a diverging estimate is an error, never an answer
        raise CliError(f"{name} diverged on {Path(args.log).name}"
                       + (f": {result.warnings[-1]}" if result.warnings else "") + "; no calibration")
    saturated = saturation(log)
    warnings = [*saturated, *result.warnings]
    if not result.converged and not result.warnings:
        warnings.append(_not_settled(result.observer))
    flipped = bool(np.trace(result.S_hat[3:, 3:]) < 0)      # a negative force gain: the other sign convention
    if flipped:
        from fmscal.observers.payload._static_fit import other_convention
        warnings.append(other_convention(Path(args.log).name, None, reading))
    converged = bool(result.converged and not saturated and not flipped)
    listed = lambda v: None if v is None else v.tolist()          # the adaptive observer reports no uncertainty
    out = {"observer": name, "kind": "spatial", "S": result.S_hat.tolist(), "S_std": listed(result.S_std),
           "b": result.b.tolist(), "b_std": listed(result.b_std), "latency": float(latency),
           "latency_estimated": latency_estimated, "converged": converged,
           "undetermined": result.info.get("undetermined", []), "warnings": warnings, "reading": reading}
    if truth is not None:
        out["E"], out["E_torque"], out["E_force"] = block_errors(result.S_hat, truth.S_at(aligned.t[-1]))
    if args.plot:                 # before saving: a failing plot leaves no calibration behind
        plot_calibration(result, aligned, args.plot, f"{Path(args.log).name}: entries of S_hat ({name}) and the "
                         "pose residual", truth, model)
    why = ("the reading saturates" if saturated else "the reading follows the other sign convention" if flipped
           else "the run did not converge (see the warnings)")
    summary = (f"{Path(args.log).name}: spatial, {len(log)} samples, {log.duration:g} s, "
               f"{int(log.has_pose.sum())} pose measurements; method {name}")
    _report(args, out, payload, summary, why)


def calibrate_table(args, path, table=None):
    """``fmscal calibrate`` on a pose table (or an attitude-only log's held segments): what held poses determine.

    ``S`` is never determined in full from held poses
    (:func:`fmscal.observers.payload.calibrate_table`): the report names
    the directions of the reading it is not determined along, ``converged``
    is false, and ``--save`` needs ``--force``.

    Parameters
    ----------
    args : argparse.Namespace
        ``fmscal calibrate``'s options (``--mass``, ``--rho X Y Z``,
        ``--gravity``, ``--reading``, ``--inertia`` only to save, ``--save``,
        ``--force``, ``--json``).
    path : Path
        The pose table, or the attitude-only log.
    table : plant.PoseTable, optional
        The table (from joint angles, :func:`joint_data`); default: read from ``path``.

    Raises
    ------
    CliError
        An option a table does not take, a planar ``--rho``, ``--save``
        without ``--inertia`` or without ``--force``.
    """
    from fmscal.observers.payload._static_fit import calibrate_table as fit_table
    from fmscal.plant.io._pose_table import held_table, is_pose_table, read_attitude_log, read_pose_table
    rho = args.rho
    if len(rho) != 3:
        raise CliError(f"a pose table takes --rho X Y Z (3 numbers, m, the centre of mass in the sensor frame); "
                       f"got {len(rho)}")
    mass = positive(args.mass, "--mass")
    given = [(args.observer is not None, "--observer", "held poses have one fit, least squares"),
             (args.latency is not None, "--latency", "held poses have no time"),
             (args.max_latency is not None, "--max-latency", "held poses have no time"),
             (args.plot is not None, "--plot", "a figure of S against time needs a log"),
             (args.truth is not None, "--truth", "a pose table has no truth sidecar"),
             (args.pose_noise is not None, "--pose-noise", "held poses are taken as exact"),
             (args.wrench_noise is not None, "--wrench-noise", "the noise is estimated from the residuals"),
             (not args.offset, "--no-offset", "the offset is always estimated in 3D")]
    for present, option, why in given:
        if present:
            raise CliError(f"{option} is not taken on a pose table ({why})")
    payload = None
    if args.inertia is not None:
        payload = spatial_payload(mass, rho, args.inertia)
    elif args.save:
        raise CliError("--save records the payload in the calibration file: give --inertia IXX IYY IZZ IXY IXZ IYZ "
                       "too (held poses do not use it)")
    if table is not None:
        what = "table of joint angles"
    elif is_pose_table(path):
        table, what = read_pose_table(path), "pose table"
    else:
        table, _, note = held_table(read_attitude_log(path))
        print(f"fmscal calibrate: note: {note}", file=sys.stderr)
        what = "attitude-only log, its held segments"
    reading = args.reading or "reaction"
    fit = fit_table(table, mass, rho, gravity_of(args), reading)
    name = "static-least-squares"
    out = {"observer": name, "kind": "table", "poses": len(table), "S": fit.S_hat.tolist(),
           "S_std": fit.S_std.tolist(), "b": fit.b.tolist(), "b_std": fit.b_std.tolist(), "latency": None,
           "latency_estimated": False, "converged": False,
           "undetermined": [d.tolist() for d in fit.undetermined], "warnings": list(fit.warnings),
           "reading": reading}
    summary = f"{path.name}: {what}, {len(table)} held poses; method {name} (S = I where the poses say nothing)"
    _report(args, out, payload, summary, "held poses never determine S in full (see the warnings)")


def _report(args, out, payload, summary, why):
    """Warnings on stderr, the calibration saved if it converged (or ``--force``), the report, the refusal."""
    from fmscal.plant import Calibration, file_sha256
    for warning in out["warnings"]:
        print(f"fmscal calibrate: warning: {warning}", file=sys.stderr)
    converged = out["converged"]
    saved = bool(args.save) and (converged or args.force)
    if saved:
        def finite(key):
            value = np.asarray(out[key], dtype=float)
            return value if np.all(np.isfinite(value)) else None
        Calibration(S=np.array(out["S"]), payload=payload, method=out["observer"], S_std=finite("S_std"),
                    b=np.array(out["b"]), b_std=finite("b_std"), latency=out["latency"],
                    log_name=Path(args.log).name, log_sha256=file_sha256(args.log), forced=not converged,
                    reading=out["reading"]).save(args.save)
    out["saved"] = saved
    if args.json:
        print(json.dumps(strict(out), allow_nan=False))
    else:
        _print(args, summary, out)
    if args.save and not saved:
        raise CliError(f"did not save {args.save}: {why}; add --force to save it anyway (marked as forced)")


def _not_settled(method):
    """Why a run with every direction determined did not converge: the log was too short to pin ``S`` down."""
    from fmscal.observers.core._convergence import EVIDENCE_TOLERANCE, SETTLE_FRACTION, SETTLE_TOLERANCE
    return (f"{method}: S_hat did not settle within {SETTLE_TOLERANCE:.0%} over the last {SETTLE_FRACTION:.0%} of "
            f"the log, or its uncertainty is above {EVIDENCE_TOLERANCE:.0%} of it (each reading component in its "
            f"own scale): record a longer log, or one that turns the payload faster")


def _print(args, summary, out):
    print(summary)
    S = np.array(out["S"])
    if out["S_std"] is None:
        print(f"S_hat (rows and columns tx ty tz fx fy fz; {out['observer']} reports no uncertainty):")
        for i in range(6):
            print("  " + "  ".join(f"{S[i, j]:+.4f}" for j in range(6)))
    else:
        S_std = np.array(out["S_std"])
        print("S_hat +- one sigma (rows and columns tx ty tz fx fy fz; inf: not determined):")
        for i in range(6):
            print("  " + "  ".join(f"{S[i, j]:+.4f}+-{S_std[i, j]:.0e}" for j in range(6)))
    b_std = out["b_std"] if out["b_std"] is not None else [np.nan] * 6
    print("offset b [N m, N]: " + "  ".join(f"{n} {b:+.4g} +- {s:.1e}" for n, b, s in zip(_NAMES, out["b"], b_std)))
    print(f"reading: {out['reading']}")
    if out["latency"] is not None:
        print(f"pose latency: {out['latency'] * 1e3:.3g} ms ({'estimated' if out['latency_estimated'] else 'given'})")
    undetermined = len(out["undetermined"])
    print(f"converged: {'yes' if out['converged'] else 'no'}"
          + (f" ({undetermined} direction(s) of the reading not determined)" if undetermined else ""))
    if "E" in out:
        print(f"E = ||I - S_hat S^-1||_2 = {out['E']:.4g} (SI units); torque block {out['E_torque']:.4g}, "
              f"force block {out['E_force']:.4g}")
    if out["saved"]:
        print(f"saved the calibration to {args.save}")
