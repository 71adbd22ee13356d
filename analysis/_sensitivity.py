"""How errors in the assumed mass properties pass into ``S_hat``: measured and derived.

Every method assumes ``m``, ``I_G`` and ``rho`` known. Written as eqs. (4),
(5), the data fix ``phi_1 = [1, -rho_y, rho_x] S`` through ``theta'' = w_hat .
phi_1 / I_G`` and ``phi_2`` (rows 2, 3 of ``S``) through ``[X'', Y''] =
R(theta) [s_2; s_3] w_hat / m``; ``S`` then follows from ``phi_1, phi_2`` and
the assumed ``rho``. So a wrong property gives ``S_hat = T S`` exactly, with

- mass ``m (1 + e)``: rows 2, 3 scale by ``1 + e``, and row 1 moves by
  ``e (rho_y s_2 - rho_x s_3)``: ``T = [[1, e rho_y, -e rho_x], [0, 1 + e, 0],
  [0, 0, 1 + e]]``. ``m`` and ``S`` scale together with no measurable change:
  they cannot be estimated jointly;
- inertia ``I_G (1 + e)``: ``phi_1`` scales by ``1 + e``:
  ``T = [[1 + e, -e rho_y, e rho_x], [0, 1, 0], [0, 0, 1]]``, so
  ``E = |e| sqrt(1 + rho_x^2 + rho_y^2)``;
- offset ``rho + d`` (m): ``s_1`` moves by ``d_y s_2 - d_x s_3``:
  ``T = [[1, d_y, -d_x], [0, 1, 0], [0, 0, 1]]``, ``E = |d|``.

and ``E = ||I - S_hat S^-1||_2 = ||I - T||_2``, whatever ``S``.
:func:`derived_error` gives it; :func:`sensitivity` measures it by running a
method on a log with the payload's property perturbed.
"""

import numpy as np
import pandas as pd

from fmscal.plant import Payload, get_scenario
from fmscal.plant.numerics import FmscalError

from fmscal.observers import make_observer

from ._metrics import calibration_error

__all__ = ["PARAMETERS", "perturbed", "distortion", "derived_error", "sensitivity", "tolerable_error"]

#: The mass properties whose errors are studied; ``rho`` is perturbed along itself.
PARAMETERS = ("mass", "inertia", "rho")


def perturbed(payload, parameter, relative_error):
    """The payload as a user with a wrong ``parameter`` believes it to be.

    ``rho`` is scaled along itself: ``rho (1 + e)``, an error of ``e |rho|`` m.
    """
    e = float(relative_error)
    if parameter == "mass":
        return Payload(payload.mass * (1 + e), payload.inertia, payload.rho)
    if parameter == "inertia":
        return Payload(payload.mass, payload.inertia * (1 + e), payload.rho)
    if parameter == "rho":
        return Payload(payload.mass, payload.inertia, tuple(r * (1 + e) for r in payload.rho))
    raise FmscalError(f"unknown parameter {parameter!r}; expected one of {', '.join(PARAMETERS)}")


def distortion(parameter, relative_error, payload):
    """``T`` in ``S_hat = T S`` for one wrong mass property (module docstring).

    Parameters
    ----------
    parameter : {"mass", "inertia", "rho"}
    relative_error : float
        ``e``: the assumed value is ``(1 + e)`` times the true one (for
        ``rho``, ``rho (1 + e)``).
    payload : plant.Payload
        The true mass properties.

    Returns
    -------
    ndarray, shape (3, 3)
    """
    e = float(relative_error)
    rho_x, rho_y = payload.rho
    if parameter == "mass":
        return np.array([[1.0, e * rho_y, -e * rho_x], [0.0, 1 + e, 0.0], [0.0, 0.0, 1 + e]])
    if parameter == "inertia":
        return np.array([[1 + e, -e * rho_y, e * rho_x], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    if parameter == "rho":
        d_x, d_y = e * rho_x, e * rho_y
        return np.array([[1.0, d_y, -d_x], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    raise FmscalError(f"unknown parameter {parameter!r}; expected one of {', '.join(PARAMETERS)}")


def derived_error(parameter, relative_error, payload):
    """E of eq. (16) that a wrong mass property alone causes: ``||I - T||_2``."""
    return float(np.linalg.norm(np.eye(3) - distortion(parameter, relative_error, payload), 2))


def tolerable_error(parameter, E, payload):
    """The largest relative error in ``parameter`` that keeps E from it alone at or below ``E``.

    E grows linearly with the error (``T - I`` is linear in ``e``), so this is
    ``E / derived_error(parameter, 1, payload)``.
    """
    return float(E) / derived_error(parameter, 1.0, payload)


def sensitivity(scenario="paper", errors=(-0.1, -0.05, -0.01, 0.01, 0.05, 0.1), parameters=PARAMETERS,
                method="least-squares", seed=0, duration=30.0, noise_free=True):
    """E against the error in each mass property: measured beside derived.

    Parameters
    ----------
    scenario : str
        The log (its payload is the truth).
    errors : sequence of float
        Relative errors ``e`` (the assumed property is ``1 + e`` times the
        true one).
    parameters : sequence of str
        From :data:`PARAMETERS`.
    method : str
        The estimator run with the wrong payload
        (:data:`observers.METHODS`).
    seed : int
    duration : float
        Length of the log, s.
    noise_free : bool
        Leave the noise out, so that the measured E is the mass property's
        alone (with noise, E also holds the method's own error).

    Returns
    -------
    pandas.DataFrame
        ``parameter``, ``relative_error``, ``absolute_error`` (kg, kg m^2 or
        m), ``E_measured``, ``E_derived``, and ``E_exact_payload`` (the
        method's E with the right payload, the floor).
    """
    sc = get_scenario(scenario).with_(duration=duration)
    log, truth, _ = sc.generate(seed, noise_free=noise_free)
    S_true = truth.S_at(log.t[-1])

    def measured(payload):
        obs = make_observer(method, payload, truth.noise)
        result = obs.run(log, truth.S0 if obs.online else None)     # an offline fit takes no start
        return np.nan if result.diverged else calibration_error(result.S_hat, S_true)

    floor = measured(sc.payload)
    rows = []
    for parameter in parameters:
        for e in errors:
            size = {"mass": sc.payload.mass, "inertia": sc.payload.inertia,
                    "rho": float(np.hypot(*sc.payload.rho))}[parameter]
            rows.append({"parameter": parameter, "relative_error": float(e), "absolute_error": abs(e) * size,
                         "E_measured": measured(perturbed(sc.payload, parameter, e)),
                         "E_derived": derived_error(parameter, e, sc.payload), "E_exact_payload": floor})
    return pd.DataFrame(rows)
