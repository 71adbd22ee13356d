"""Calibrate a recorded log: one method, the fit diagnostics, and how far to trust the answer."""

from dataclasses import dataclass, field

import numpy as np

from fmscal.observers import FLOOR_METHOD, LeastSquares, ObserverResult, get_method, method_names
from fmscal.observers.diagnostics._faults import offset_drift, saturation
from fmscal.observers.diagnostics._health import consistency_check
from fmscal.observers.batch._latency import estimate_latency
from fmscal.plant import Calibration, NoiseSpec, SingularCalibrationError, estimate_noise
from fmscal.plant.numerics._errors import FmscalError
from fmscal.plant.io._units import COUNTS, diagnose_units

from fmscal.analysis._metrics import calibration_error

__all__ = ["DEFAULT_METHOD", "DEFAULT_MAX_LATENCY", "CalibrationReport", "calibrate",
           "DivergedError"]

#: The default: the maximum-likelihood estimate, at the information floor by construction, on
#: full-rate and multi-rate logs, with offset and latency; its noise model is estimated from the
#: log when not given (docs/comparison.md, "Which observer to trust").
DEFAULT_METHOD = FLOOR_METHOD
#: Largest pose-stream delay searched when the latency is estimated, s.
DEFAULT_MAX_LATENCY = 0.1
#: A method's estimate disagrees with the least-squares fit of the same log when an entry differs by more
#: than this many (combined) standard deviations ...
AGREEMENT_SIGMAS = 6.0
#: ... and the two calibrations differ by more than this E (eq. 16, one against the other).
AGREEMENT_E = 0.01


class DivergedError(FmscalError):
    """The estimate diverged: there is no calibration to report."""


@dataclass
class CalibrationReport:
    """What :func:`calibrate` returns: the calibration, and how far to trust it.

    Attributes
    ----------
    calibration : plant.Calibration
        ``S``, its one-sigma ``S_std`` (None where the method gives none),
        the offset ``b`` and ``b_std`` (None without the offset), the
        method, the payload and the latency; ready to ``save``.
    result : observers.ObserverResult
        The method's full run (histories, info).
    converged : bool
        The method's ``converged`` flag (:class:`observers.ObserverResult`),
        and: the log's units look right, a least-squares fit of it finds it
        exciting every entry and matching the model, the log is consistent with one
        constant ``S`` (:func:`observers.diagnostics.consistency_check`), no channel of the
        reading saturates (:func:`observers.diagnostics.saturation`), the offset keeps one
        level (:func:`observers.diagnostics.offset_drift`), and the
        method's estimate agrees with a least-squares fit of the same log
        (within :data:`AGREEMENT_SIGMAS` standard deviations or an E of
        :data:`AGREEMENT_E`). Each failure adds a warning that names it.
    noise : plant.NoiseSpec
        The noise model used.
    noise_estimated : list of str
        Which parts of it came from the log (``"wrench"``, ``"pose"``).
    latency_estimated : bool
        The latency was estimated (True) or given.
    warnings : list of str
        The units diagnosis, excitation and model consistency (from a
        least-squares fit of the same log), saturation and a moving offset,
        and the method's own warnings, one line each.
    units : list of str
        What :func:`plant.io.diagnose_units` found wrong with the log's
        units (degrees, millimetres, counts) that this method cannot absorb
        (an offline fit is linear in ``S`` and takes readings in counts);
        empty when they look right. Any of them makes ``converged`` false.
    fit : dict
        The least-squares fit's diagnostics (:class:`observers.batch.FitReport`
        without its warnings).
    E : float or None
        E of eq. (16) against a known truth, where one was given.
    """

    calibration: Calibration
    result: ObserverResult
    converged: bool
    noise: NoiseSpec
    noise_estimated: list
    latency_estimated: bool
    warnings: list = field(default_factory=list)
    units: list = field(default_factory=list)
    fit: dict = field(default_factory=dict)
    E: float = None

    def to_dict(self):
        """The report as plain JSON-ready values (``fmscal calibrate --json``).

        Returns
        -------
        dict
            ``observer``, ``S``, ``S_std``, ``b``, ``b_std``, ``latency``,
            ``latency_estimated``, ``converged``, ``noise``,
            ``noise_estimated``, ``warnings``, ``fit`` and, with a truth, ``E``.
        """
        cal = self.calibration.to_dict()
        out = {"observer": self.calibration.method, "S": cal["S"], "S_std": cal["S_std"], "b": cal["b"],
               "b_std": cal["b_std"], "latency": float(self.calibration.latency),
               "latency_estimated": self.latency_estimated, "converged": bool(self.converged),
               "noise": self.noise.to_dict(), "noise_estimated": list(self.noise_estimated),
               "warnings": list(self.warnings), "fit": self.fit}
        if self.E is not None:
            out["E"] = float(self.E)
        return out


def calibrate(log, payload, method=DEFAULT_METHOD, pose_noise=None, wrench_noise=None, truth=None,
              offset=True, latency=None, max_latency=DEFAULT_MAX_LATENCY):
    """Estimate ``S`` (and the sensor's offset) from a log, with diagnostics.

    Every method runs on the log with its pose stream moved back by the
    latency (given, or estimated by least squares over candidate delays,
    :func:`observers.batch.estimate_latency`).

    Parameters
    ----------
    log : plant.Log
    payload : plant.Payload
    method : str
        A method the registry offers for calibration
        (``observers.method_names(calibrates=True)``).
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
    CalibrationReport

    Raises
    ------
    DivergedError
        The method's estimate diverged.
    """
    offered = method_names(calibrates=True)
    if method not in offered:
        raise FmscalError(f"unknown method {method!r}; expected one of {', '.join(offered)}")
    estimated = estimate_noise(log)
    noise = NoiseSpec(tuple(wrench_noise) if wrench_noise is not None else estimated.wrench_sd,
                      pose_noise[0] if pose_noise is not None else estimated.angle_sd,
                      pose_noise[1] if pose_noise is not None else estimated.position_sd)
    noise_estimated = [name for name, given in (("wrench", wrench_noise), ("pose", pose_noise)) if given is None]
    spread = np.ptp(log.pose[log.has_pose], axis=0)
    if np.all(spread <= 10 * np.array([noise.angle_sd, noise.position_sd, noise.position_sd])):
        raise FmscalError(f"{log.name}: the pose does not move (theta, x and y each stay within 10 noise standard "
                          "deviations): a payload at rest does not excite S; record it moving")
    latency_estimated = latency is None
    if latency_estimated:
        latency, _ = estimate_latency(log, payload, max_latency, offset=offset)
    aligned = log.shift_poses(latency)
    reference = LeastSquares(payload, offset=offset)
    ls_result = reference.run(aligned)
    if method == reference.name:
        result = ls_result
    else:
        result = get_method(method).build(payload, noise, {"offset": offset}).run(aligned)
    if result.diverged:
        raise DivergedError(f"the {method} estimate diverged at t = {result.t[-1]:.3f} s; "
                            "no calibration (check the mass properties, units and excitation)")
    findings = diagnose_units(log, payload)
    diagnosed = [f.message for f in findings]
    units = [f.message for f in findings if f.kind != COUNTS or get_method(method).online]
    warnings = diagnosed + list(ls_result.warnings)
    warnings += [w for w in result.warnings if w not in warnings]
    try:
        consistency = consistency_check(aligned, payload, offset=offset)
        consistent = consistency.consistent
        if not consistent:
            warnings.append(consistency.warning)
    except FmscalError as err:            # a half too short to fit: nothing says S stayed constant
        consistent = False
        warnings.append(f"the log is too short to check that one constant S explains it ({err})")
    faults = saturation(log)
    drift = offset_drift(aligned, payload, ls_result.S_hat, ls_result.b)
    if drift.warning:
        faults.append(drift.warning)
    warnings += faults
    disagreement = _disagreement(result, ls_result)
    if disagreement:
        warnings.append(disagreement)
    try:
        calibration = Calibration(S=result.S_hat, payload=payload, method=result.observer, S_std=result.S_std,
                                  b=result.b, b_std=result.b_std, latency=float(latency))
    except SingularCalibrationError as err:
        raise FmscalError(f"the {method} estimate of S is singular ({str(err).split('(')[-1].split(')')[0]}): the "
                          "log does not excite every entry of S, or holds an outlier (a reading far from the "
                          "rest)") from None
    E = calibration_error(result.S_hat, truth.S_at(log.t[-1])) if truth is not None else None
    converged = (bool(result.converged) and not units and not ls_result.warnings and consistent
                 and not faults and not disagreement)
    return CalibrationReport(calibration=calibration, result=result, converged=converged,
                             noise=noise, noise_estimated=noise_estimated, latency_estimated=latency_estimated,
                             warnings=warnings, units=units,
                             fit={k: v for k, v in reference.report.items() if k != "warnings"},
                             E=E)


def _disagreement(result, reference):
    """A warning when ``result``'s estimate is far from the least-squares fit ``reference``; else None."""
    if result is reference:
        return None
    var = np.square(reference.S_std) + (0.0 if result.S_std is None else np.square(result.S_std))
    with np.errstate(divide="ignore", invalid="ignore"):
        z = float(np.nanmax(np.abs(result.S_hat - reference.S_hat) / np.sqrt(var)))
    try:
        E = calibration_error(result.S_hat, reference.S_hat)
    except (np.linalg.LinAlgError, FmscalError):
        E = float("inf")
    if z > AGREEMENT_SIGMAS and E > AGREEMENT_E:
        return (f"the {result.observer} estimate is far from a least-squares fit of the same log (E between "
                f"them {E:.3g}, an entry {z:.3g} sigma off): it has not converged to what the data say "
                "(a gain too small, or a run too short)")
    return None
