"""The force-moment sensor: calibration matrix ``S`` (eq. 3) and noise."""

from dataclasses import dataclass

import numpy as np

from fmscal.plant.numerics import FmscalError, as_finite_array, as_positive_scalar

__all__ = ["CalibrationSchedule", "NoiseSpec", "SingularCalibrationError", "check_calibration"]


class SingularCalibrationError(FmscalError):
    """A calibration matrix that cannot be inverted."""


def check_calibration(S, name="S", max_cond=1e8, size=3):
    """Return ``S`` as a finite, invertible ``size x size`` float array, or raise.

    Parameters
    ----------
    S : array_like
    name : str
        Named in the message.
    max_cond : float
        Largest condition number taken for invertible.
    size : int
        ``n_w`` of the model: 3 (planar) or 6 (spatial).

    Raises
    ------
    ValueError
        Wrong shape or non-finite entries.
    SingularCalibrationError
        Condition number above ``max_cond``.
    """
    S = as_finite_array(S, (size, size), name)
    cond = np.linalg.cond(S)
    if not np.isfinite(cond) or cond > max_cond:
        raise SingularCalibrationError(
            f"{name} is singular (condition number {cond:.3g}); a calibration matrix must be invertible")
    return S


class CalibrationSchedule:
    """The true calibration matrix ``S(t)``: constant or piecewise constant.

    Eq. (3): ``w = S w_hat``, so the raw reading is ``w_hat = S^-1 w``.

    Parameters
    ----------
    steps : list of (t_start, S)
        Times in s, strictly increasing, the first 0; each ``S`` square
        (3x3 planar, 6x6 spatial; all of one size) and invertible. A single
        matrix may be given instead of a list.

    Examples
    --------
    >>> sched = CalibrationSchedule(np.eye(3))
    >>> sched.at(5.0).shape
    (3, 3)
    """

    def __init__(self, steps):
        arr = np.asarray(steps, dtype=object)
        if not isinstance(steps, list) or (arr.ndim == 2 and arr.shape[0] == arr.shape[1] and arr.shape[0] in (3, 6)):
            steps = [(0.0, steps)]
        if not steps:
            raise FmscalError("a calibration schedule needs at least one matrix")
        self.starts = np.array([float(t0) for t0, _ in steps])
        size = 6 if np.shape(steps[0][1]) == (6, 6) else 3
        self.matrices = np.array([check_calibration(S, f"S at t={t0}", size=size) for t0, S in steps])
        if self.starts[0] != 0.0 or np.any(np.diff(self.starts) <= 0):
            raise FmscalError(f"schedule start times must begin at 0 and increase; got {list(self.starts)}")

    @property
    def is_constant(self):
        return len(self.starts) == 1

    @property
    def size(self):
        """``n_w``: 3 (planar) or 6 (spatial)."""
        return self.matrices.shape[1]

    def at(self, t):
        """``S(t)``, shape (n_w, n_w) for a scalar ``t`` or (N, n_w, n_w) for an array."""
        idx = np.searchsorted(self.starts, np.asarray(t, dtype=float), side="right") - 1
        return self.matrices[np.clip(idx, 0, None)]

    def to_json(self):
        """``{"S": ...}`` for a constant matrix, else ``{"S_schedule": [[t, S], ...]}``."""
        if self.is_constant:
            return {"S": self.matrices[0].tolist()}
        return {"S_schedule": [[float(t0), S.tolist()] for t0, S in zip(self.starts, self.matrices)]}

    def raw_reading(self, t, w):
        """Noise-free raw reading ``w_hat = S(t)^-1 w``, eq. (3).

        Parameters
        ----------
        t : ndarray, shape (N,)
        w : ndarray, shape (N, n_w)

        Returns
        -------
        ndarray, shape (N, n_w)
        """
        S_inv = np.linalg.inv(self.matrices)[np.clip(
            np.searchsorted(self.starts, t, side="right") - 1, 0, None)]
        return np.einsum("nij,nj->ni", S_inv, w)


@dataclass(frozen=True)
class NoiseSpec:
    """Measurement noise standard deviations, in the units of the log.

    Parameters
    ----------
    wrench_sd : tuple of float
        Standard deviation of each component of the raw reading, planar
        ``[M, f_x, f_y]`` or spatial ``[tx, ty, tz, fx, fy, fz]``, in N m and N
        (as many as the model's reading has: :meth:`fmscal.plant.Model.check_noise`).
    angle_sd : float
        Standard deviation of the measured angle, in rad (spatial: of the
        attitude about each axis).
    position_sd : float
        Standard deviation of each measured position coordinate, in m.
    wrench_tau : tuple of float, optional
        Each reading component's integrated correlation time, in samples
        (``tau = 1 + 2 sum_k rho_k``, ``rho_k`` the noise's autocorrelation at
        lag ``k``): 1 for white noise, about 2 for readings averaged over 2
        samples, ``(1 + a) / (1 - a)`` for a first-order filter of pole ``a``
        (:func:`fmscal.plant.io.estimate_noise`, eq. (N2)). None (the
        default): white. ``wrench_sd`` is then the noise's standard deviation
        sample by sample, and ``wrench_sd * sqrt(wrench_tau)``
        (:attr:`long_run_wrench_sd`) the white noise of the same power at low
        frequencies, which is what a fit over many samples sees.
    """

    wrench_sd: tuple = (0.0, 0.0, 0.0)
    angle_sd: float = 0.0
    position_sd: float = 0.0
    wrench_tau: tuple = None

    def __post_init__(self):
        sd = as_finite_array(self.wrench_sd, (-1,), "wrench_sd")
        if len(sd) < 1:
            raise FmscalError("wrench_sd is empty; expected one standard deviation per reading component")
        if np.any(sd < 0):
            raise FmscalError(f"noise standard deviations must be >= 0; got wrench_sd {tuple(sd.tolist())}")
        object.__setattr__(self, "wrench_sd", tuple(float(v) for v in sd))
        object.__setattr__(self, "angle_sd", as_positive_scalar(self.angle_sd, "angle_sd", allow_zero=True))
        object.__setattr__(self, "position_sd", as_positive_scalar(self.position_sd, "position_sd", allow_zero=True))
        if self.wrench_tau is not None:
            tau = as_finite_array(self.wrench_tau, (len(sd),), "wrench_tau")
            if np.any(tau < 1.0):
                raise FmscalError(f"wrench_tau is a correlation time in samples, at least 1; got {tuple(tau.tolist())}")
            object.__setattr__(self, "wrench_tau", tuple(float(v) for v in tau))

    @property
    def pose_sd(self):
        """``[angle_sd, position_sd, position_sd]``, shape (3,)."""
        return np.array([self.angle_sd, self.position_sd, self.position_sd])

    @property
    def white(self):
        """True where the reading's noise is white (no :attr:`wrench_tau`)."""
        return self.wrench_tau is None

    @property
    def long_run_wrench_sd(self):
        """``wrench_sd * sqrt(wrench_tau)``, shape (n_w,): the white noise whose power at low frequencies is the
        reading noise's (eq. (N2) of :func:`fmscal.plant.io.estimate_noise`); ``wrench_sd`` where it is white."""
        sd = np.asarray(self.wrench_sd, dtype=float)
        return sd if self.white else sd * np.sqrt(np.asarray(self.wrench_tau))

    def to_dict(self):
        out = {"wrench_sd": list(self.wrench_sd), "angle_sd": self.angle_sd, "position_sd": self.position_sd}
        if not self.white:
            out["wrench_tau"] = list(self.wrench_tau)
        return out

    @classmethod
    def from_dict(cls, d):
        return cls(tuple(d["wrench_sd"]), d["angle_sd"], d["position_sd"], d.get("wrench_tau"))

    def scaled(self, factor):
        """The same noise with every standard deviation times ``factor`` (the correlation kept)."""
        return NoiseSpec(tuple(factor * v for v in self.wrench_sd),
                         factor * self.angle_sd, factor * self.position_sd, self.wrench_tau)
