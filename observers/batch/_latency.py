"""The delay of the pose stream behind the sensor stream, by least squares over candidate delays.

A vision system delivers each pose a roughly constant time after it was
taken. Shifted back by the right delay, the log fits its dynamics best: the
fit's residual is smallest there. In the plane the fit is least squares
(eq. 1) and the residual is in units of the pose noise; in space it is the
reference fit of smoothed inverse dynamics
(:func:`fmscal.observers.batch.fit_inverse_dynamics`) and the
residual is the share of each wrench component the fit leaves unexplained.
The search is a coarse grid over ``[0, max_latency]`` followed by a
golden-section search on whole samples around the best grid point.
"""

import numpy as np

from fmscal.plant import Log
from fmscal.plant.numerics import FmscalError, as_positive_scalar
from fmscal.plant.physics import as_model

from ._least_squares import LeastSquares

__all__ = ["estimate_latency"]

_GRID = 11          # coarse candidates over [0, max_latency]
_SEARCH_SPAN = 20.0  # s of log searched (the start); the fit at the answer uses all of it


def _cost(log, model, samples, offset, window):
    """The fit's residual on the log with its poses shifted back by ``samples``: in the plane the sum over
    the pose channels of (residual rms / pose noise)^2 after least squares; in space the sum over the
    wrench components of the share the inverse-dynamics fit leaves unexplained."""
    shifted = log.shift_poses(samples * log.dt)
    engine = LeastSquares.engine(model)                  # the spatial fit always estimates the offset
    return engine(model, window=window, offset=offset or engine.offset_required).latency_cost(shifted)


def estimate_latency(log, model, max_latency=0.1, offset=False, window=0.5):
    """Delay of the pose stream behind the sensor stream.

    Parameters
    ----------
    log : plant.Log
        A log of the model's case.
    model : plant.Model, plant.Payload or plant.SpatialPayload
        The problem (a payload stands for its case's model; a spatial
        model carries the gravity).
    max_latency : float
        Largest delay considered, s.
    offset : bool
        Fit the sensor's offset too (as the calibration will; the spatial
        fit always does).
    window : float
        Least-squares window, s (planar).

    Returns
    -------
    latency : float
        s, a whole number of samples.
    costs : dict
        ``{latency_s: cost}`` for every delay tried (module docstring).

    Raises
    ------
    TypeError
        ``log`` is not a :class:`plant.Log`.
    FmscalError
        No model, a log of another case, or a ``max_latency`` too long for the log.
    """
    model = as_model(model, "estimate_latency")
    if not isinstance(log, Log):
        raise TypeError(f"log must be a plant.Log; got {type(log).__name__}")
    model.check_log(log, "the latency search")
    max_latency = as_positive_scalar(max_latency, "max_latency")
    n_search = min(len(log), int(round(_SEARCH_SPAN / log.dt)) + 1)
    part = log.head(n_search)
    k_max = int(round(max_latency / log.dt))
    if k_max * log.dt >= part.duration / 4:
        raise FmscalError(f"max_latency {max_latency:g} s is too long for a {part.duration:g} s log")
    seen = {}

    def cost(k):
        if k not in seen:
            seen[k] = _cost(part, model, k, offset, window)
        return seen[k]

    grid = np.unique(np.round(np.linspace(0, k_max, _GRID)).astype(int))
    best = min(grid, key=cost)
    i = int(np.searchsorted(grid, best))
    lo, hi = int(grid[max(i - 1, 0)]), int(grid[min(i + 1, len(grid) - 1)])
    # golden-section search on whole samples in [lo, hi]
    ratio = (np.sqrt(5) - 1) / 2
    while hi - lo > 2:
        a = int(round(hi - ratio * (hi - lo)))
        b = int(round(lo + ratio * (hi - lo)))
        if a == b:
            b = a + 1
        if cost(a) <= cost(b):
            hi = b
        else:
            lo = a
    best = min(range(lo, hi + 1), key=cost)
    return best * log.dt, {k * log.dt: c for k, c in sorted(seen.items())}
