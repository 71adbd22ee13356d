"""Calibrate a recorded log: one method, the fit diagnostics, and how far to trust the answer."""

import numpy as np

from observers import LeastSquares
from observers.latency import estimate_latency
from observers.noise_level import DEFAULT_TOLERANCE
from plant import NoiseSpec, estimate_noise

from .comparison import make_observer
from .metrics import calibration_error
from plant.errors import FmscalError

__all__ = ["CALIBRATION_METHODS", "DEFAULT_METHOD", "DEFAULT_MAX_LATENCY", "calibrate", "DivergedError"]

#: Methods ``fmscal calibrate`` offers.
CALIBRATION_METHODS = ("least-squares", "ekf", "high-gain", "adaptive")
#: The default: it never diverges, needs no noise model, and is within 1.5x of the most
#: accurate method on full-rate logs; with poses at 50 Hz the EKF is more accurate
#: (README, "Which observer to trust").
DEFAULT_METHOD = "least-squares"
#: Largest pose-stream delay searched when the latency is estimated, s.
DEFAULT_MAX_LATENCY = 0.1


class DivergedError(FmscalError):
    """The estimate diverged: there is no calibration to report."""


def calibrate(log, payload, method=DEFAULT_METHOD, pose_noise=None, wrench_noise=None, truth=None,
              offset=True, latency=None, max_latency=DEFAULT_MAX_LATENCY):
    """Estimate ``S`` (and the sensor's offset) from a log, with diagnostics.

    Every method runs on the log with its pose stream moved back by the
    latency (given, or estimated by least squares over candidate delays,
    :func:`observers.latency.estimate_latency`).

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
    offset : bool
        Estimate the sensor's offset ``b`` in ``w = S (w_hat - b)`` with
        ``S`` (the default: a real sensor reads non-zero under no load, and
        an offset left out biases ``S_hat`` far more than estimating three
        more numbers costs).
    latency : float, optional
        Delay of the pose stream behind the sensor stream, s. None: estimated.
    max_latency : float
        Largest delay searched when it is estimated, s.

    Returns
    -------
    dict
        ``observer``, ``S`` (3x3 list), ``S_std`` (3x3 list or None),
        ``b``, ``b_std`` (3 lists, or None without the offset),
        ``latency`` (s), ``latency_estimated`` (bool), ``converged``, ``E`` (with ``truth``, else absent), ``noise`` (what
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
        raise FmscalError(f"unknown method {method!r}; expected one of {', '.join(CALIBRATION_METHODS)}")
    estimated = estimate_noise(log)
    noise = NoiseSpec(tuple(wrench_noise) if wrench_noise is not None else estimated.wrench_sd,
                      pose_noise[0] if pose_noise is not None else estimated.angle_sd,
                      pose_noise[1] if pose_noise is not None else estimated.position_sd)
    noise_estimated = [name for name, given in (("wrench", wrench_noise), ("pose", pose_noise)) if given is None]
    latency_estimated = latency is None
    if latency_estimated:
        latency, _ = estimate_latency(log, payload, max_latency, offset=offset)
    aligned = log.shift_poses(latency)
    reference = LeastSquares(payload, offset=offset)
    ls_result = reference.run(aligned)
    if method == "least-squares":
        result = ls_result
    else:
        result = make_observer(method, payload, told_noise=noise, settings={"offset": offset}).run(aligned)
    if result.diverged:
        raise DivergedError(f"the {method} estimate diverged at t = {result.t[-1]:.3f} s; "
                            "no calibration (check the mass properties, units and excitation)")
    warnings = list(reference.report["warnings"])
    if "q_S_history" in result.info:
        warnings += _random_walk_warning(result.t, result.info["q_S_history"])

    def listed(a):
        return None if a is None else np.asarray(a).tolist()

    out = {"observer": result.observer, "S": result.S_hat.tolist(), "S_std": listed(result.S_std),
           "b": listed(result.b), "b_std": listed(result.b_std), "latency": float(latency),
           "latency_estimated": latency_estimated,
           "converged": bool(result.converged), "noise": noise.to_dict(),
           "noise_estimated": noise_estimated, "warnings": warnings,
           "fit": {k: v for k, v in reference.report.items() if k != "warnings"}, "result": result}
    if truth is not None:
        out["E"] = calibration_error(result.S_hat, truth.S_at(log.t[-1]))
    return out


def _random_walk_warning(t, q_history):
    """A warning if the EKF raised its random walk on S (its innovations said S moved)."""
    raised = q_history > 1.01 * q_history.min()
    if not raised.any():
        return []
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.0
    return [f"the EKF raised its random walk on S for {raised.sum() * dt:.1f} s (first at t = "
            f"{t[np.argmax(raised)]:.1f} s): S may have changed during the log, or the noise model is "
            f"more than {DEFAULT_TOLERANCE * 100:g} % off"]
