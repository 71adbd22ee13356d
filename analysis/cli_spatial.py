"""The commands on spatial logs: ``calibrate`` of a 6-axis sensor, and ``identify-payload``.

A spatial log (header ``t,qw,qx,qy,qz,x,y,z,tx,ty,tz,fx,fy,fz``) goes where a
planar one goes: ``fmscal calibrate`` picks the case from the header. In 3D
the calibration is the maximum-likelihood floor, linearised about the
smoothed motion (:mod:`fmscal.observers.linearised_floor`), or the reference
fit (``--observer least-squares``: smoothed inverse dynamics and least
squares, :func:`fmscal.observers.inverse_dynamics_fit.fit_inverse_dynamics`),
both through the one registry; the pose stream's latency is estimated as in
the plane. The online observers are not there yet in 3D, and the options
that only they use are refused in one line.
"""

import json
import sys
from pathlib import Path

import numpy as np

from .cli_common import CliError, positive, strict

__all__ = ["calibrate_spatial", "spatial_payload", "gravity_of"]
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
    from fmscal.plant.rigid_body import GRAVITY
    g = args.gravity if getattr(args, "gravity", None) is not None else GRAVITY
    if not (all(np.isfinite(v) for v in g) and 0 < np.linalg.norm(g) < 1e3):
        raise CliError(f"--gravity must be three finite numbers in m/s^2 (the pose frame's gravity); got {list(g)}")
    return tuple(float(v) for v in g)


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


def calibrate_spatial(args):
    """``fmscal calibrate`` on a spatial log: ``S`` (6x6) and the offset, with what the log did not determine."""
    from fmscal.observers import make_observer
    from fmscal.observers.faults import saturation
    from fmscal.observers.latency import estimate_latency
    from fmscal.plant import Calibration, SpatialModel, file_sha256, read_log
    from .calibrate import DEFAULT_MAX_LATENCY
    from .metrics import block_errors
    from .plots import plot_calibration
    from fmscal.observers import FLOOR_METHOD
    payload = spatial_payload(args.mass, args.rho, args.inertia)
    model = SpatialModel(payload, gravity_of(args))
    _refuse_planar_options(args, model)
    name = args.observer or FLOOR_METHOD
    log = read_log(args.log)
    for note in log.notes:
        print(f"fmscal calibrate: note: {note}", file=sys.stderr)
    truth = _spatial_truth(args.truth)
    latency_estimated = args.latency is None
    latency = args.latency
    if latency_estimated:
        latency, _ = estimate_latency(log, model, args.max_latency or DEFAULT_MAX_LATENCY, offset=True)
    aligned = log.shift_poses(latency)
    result = make_observer(name, model, settings={"offset": True}).run(aligned)
    saturated = saturation(log)
    warnings = [*saturated, *result.warnings]
    if not result.converged and not result.warnings:
        warnings.append(_not_settled(result.observer))
    for warning in warnings:
        print(f"fmscal calibrate: warning: {warning}", file=sys.stderr)
    converged = bool(result.converged and not saturated)
    out = {"observer": name, "kind": "spatial", "S": result.S_hat.tolist(), "S_std": result.S_std.tolist(),
           "b": result.b.tolist(), "b_std": result.b_std.tolist(), "latency": float(latency),
           "latency_estimated": latency_estimated, "converged": converged,
           "undetermined": result.info.get("undetermined", []), "warnings": warnings}
    if truth is not None:
        out["E"], out["E_torque"], out["E_force"] = block_errors(result.S_hat, truth.S_at(aligned.t[-1]))
    if args.plot:                 # before saving: a failing plot leaves no calibration behind
        plot_calibration(result, aligned, args.plot, f"{Path(args.log).name}: entries of S_hat ({name}) and the "
                         "pose residual", truth, model)
    saved = bool(args.save) and (converged or args.force)
    if saved:
        Calibration(S=result.S_hat, payload=payload, method=name, S_std=result.S_std, b=result.b,
                    b_std=result.b_std, latency=float(latency), log_name=Path(args.log).name,
                    log_sha256=file_sha256(args.log), forced=not converged).save(args.save)
    out["saved"] = saved
    if args.json:
        print(json.dumps(strict(out), allow_nan=False))
    else:
        _print(args, log, out)
    if args.save and not saved:
        why = "the reading saturates" if saturated else "the run did not converge (see the warnings)"
        raise CliError(f"did not save {args.save}: {why}; add --force to save it anyway (marked as forced)")


def _not_settled(method):
    """Why a run with every direction determined did not converge: the log was too short to pin ``S`` down."""
    from fmscal.observers.convergence import EVIDENCE_TOLERANCE, SETTLE_FRACTION, SETTLE_TOLERANCE
    return (f"{method}: S_hat did not settle within {SETTLE_TOLERANCE:.0%} over the last {SETTLE_FRACTION:.0%} of "
            f"the log, or its uncertainty is above {EVIDENCE_TOLERANCE:.0%} of it (each reading component in its "
            f"own scale): record a longer log, or one that turns the payload faster")


def _print(args, log, out):
    print(f"{Path(args.log).name}: spatial, {len(log)} samples, {log.duration:g} s, "
          f"{int(log.has_pose.sum())} pose measurements; method {out['observer']}")
    S, S_std = np.array(out["S"]), np.array(out["S_std"])
    print("S_hat +- one sigma (rows and columns tx ty tz fx fy fz):")
    for i in range(6):
        print("  " + "  ".join(f"{S[i, j]:+.4f}+-{S_std[i, j]:.0e}" for j in range(6)))
    print("offset b [N m, N]: " + "  ".join(f"{n} {b:+.4g} +- {s:.1e}" for n, b, s in
                                            zip(_NAMES, out["b"], out["b_std"])))
    print(f"pose latency: {out['latency'] * 1e3:.3g} ms ({'estimated' if out['latency_estimated'] else 'given'})")
    undetermined = len(out["undetermined"])
    print(f"converged: {'yes' if out['converged'] else 'no'}"
          + (f" ({undetermined} direction(s) of the reading not determined)" if undetermined else ""))
    if "E" in out:
        print(f"E = ||I - S_hat S^-1||_2 = {out['E']:.4g} (SI units); torque block {out['E_torque']:.4g}, "
              f"force block {out['E_force']:.4g}")
    if out["saved"]:
        print(f"saved the calibration to {args.save}")
