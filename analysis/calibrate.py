"""Calibrate a recorded log: one method, the fit diagnostics, and how far to trust the answer."""

import numpy as np

from observers import LeastSquares
from plant import NoiseSpec, estimate_noise

from .comparison import make_observer
from .metrics import calibration_error

__all__ = ["CALIBRATION_METHODS", "DEFAULT_METHOD", "calibrate", "DivergedError"]

#: Methods ``fmscal calibrate`` offers.
CALIBRATION_METHODS = ("least-squares", "ekf", "high-gain", "adaptive")
#: The default: the most accurate method that is robust on logs unlike the paper's
#: (README, "Which observer to trust").
DEFAULT_METHOD = "least-squares"


class DivergedError(RuntimeError):
    """The estimate diverged: there is no calibration to report."""


def calibrate(log, payload, method=DEFAULT_METHOD, pose_noise=None, wrench_noise=None, truth=None):
    """Estimate ``S`` from a log, with diagnostics.

    Parameters
    ----------
    log : plant.Log
    payload : plant.Payload
    method : str
        One of :data:`CALIBRATION_METHODS`.
    pose_noise : (float, float), optional
        Standard deviations of the angle (rad) and of the positions (m).
    wrench_noise : (float, float, float), optional
        Standard deviations of the raw reading ``[M, f_x, f_y]`` (N m, N).
        Noise not given is estimated from the log and reported.
    truth : plant.Truth, optional
        For E of eq. (16).

    Returns
    -------
    dict
        ``observer``, ``S`` (3x3 list), ``S_std`` (3x3 list or None),
        ``converged``, ``E`` (with ``truth``, else absent), ``noise`` (what
        was used), ``noise_estimated`` (which parts came from the log),
        ``warnings`` (excitation and model consistency, from a
        least-squares fit of the same log), ``fit`` (its diagnostics) and
        ``result`` (the :class:`observers.ObserverResult`).

    Raises
    ------
    DivergedError
        The method's estimate diverged.
    """
    if method not in CALIBRATION_METHODS:
        raise ValueError(f"unknown method {method!r}; expected one of {', '.join(CALIBRATION_METHODS)}")
    estimated = estimate_noise(log)
    noise = NoiseSpec(tuple(wrench_noise) if wrench_noise is not None else estimated.wrench_sd,
                      pose_noise[0] if pose_noise is not None else estimated.angle_sd,
                      pose_noise[1] if pose_noise is not None else estimated.position_sd)
    noise_estimated = [name for name, given in (("wrench", wrench_noise), ("pose", pose_noise)) if given is None]
    reference = LeastSquares(payload)
    ls_result = reference.run(log)
    if method == "least-squares":
        result = ls_result
    else:
        result = make_observer(method, payload, told_noise=noise).run(log)
    if result.diverged:
        raise DivergedError(f"the {method} estimate diverged at t = {result.t[-1]:.3f} s; "
                            "no calibration (check the mass properties, units and excitation)")
    out = {"observer": result.observer, "S": result.S_hat.tolist(),
           "S_std": None if result.S_std is None else result.S_std.tolist(),
           "converged": bool(result.converged), "noise": noise.to_dict(),
           "noise_estimated": noise_estimated, "warnings": list(reference.report["warnings"]),
           "fit": {k: v for k, v in reference.report.items() if k != "warnings"}, "result": result}
    if truth is not None:
        out["E"] = calibration_error(result.S_hat, truth.S_at(log.t[-1]))
    return out
