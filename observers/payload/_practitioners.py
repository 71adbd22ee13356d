"""The practitioners' static estimators, reimplemented to compare with fmscal on the same data.

Two estimators that the tools used on robot wrists publish, written here
from their published equations (their own code, in ROS C++ and Julia, is
not run):

- :func:`plain_fit`: the static least squares of KTH's
  ``force_torque_sensor_calib`` and of the scripts labs write. With gravity
  along -z of the pose frame and the sensor square on the tracked frame,
  the force is ``f = m R^T (-g) + c_f`` (eq. (P1)), linear in the mass and
  the force offset, and then the torque is ``tau = com x f + c_tau``
  (eq. (P2)), linear in the centre of mass and the torque offset, with
  ``f`` the fitted weight.
- :func:`calib_force`: ``calibForce`` of Robotlib.jl (``src/calibForce.jl``,
  F. Bagge Carlson): the forces only. It solves
  ``Rf F_i + o = R_i^T [0, 0, -m g]`` (eq. (P3)) by linear least squares for
  the nine entries of ``Rf`` and the offset, with a guess ``m0`` of the
  mass; takes the rotation nearest ``Rf`` (orthonormalised); then solves
  the mass and the offset again with ``Rf`` fixed (the published code
  repeats that solve twice, with the same result). Gravity is 9.82 m/s^2
  along -z, as there.

Neither gives an uncertainty, nor says whether gravity was along -z. Both
take every row as a held pose: on a moving log the accelerations are
left in the residual. fmscal's own fits are :func:`fmscal.observers.
static_fit.fit_static` (tables) and :func:`fmscal.observers.payload._payload_fit.
identify_payload` (logs).
"""

from dataclasses import dataclass

import numpy as np

from fmscal.plant.io import reading_sign
from fmscal.plant.numerics import FmscalError, as_finite_array, as_positive_scalar
from fmscal.plant.physics import rotation_matrix, skew

__all__ = ["ReferenceFit", "plain_fit", "calib_force", "CALIB_FORCE_G"]

#: The gravity calibForce takes, m/s^2 (``g = 9.82`` in ``src/calibForce.jl``).
CALIB_FORCE_G = 9.82


@dataclass
class ReferenceFit:
    """What a practitioners' estimator returns: point estimates, no uncertainty.

    Attributes
    ----------
    mass : float
        kg.
    com : ndarray, shape (3,), or None
        Centre of mass in the sensor frame, m (None: not estimated).
    b : ndarray, shape (6,)
        The offset in fmscal's convention (``w = S (sigma w_hat - b)``,
        reading order, sensor axes), N m and N; the torque part NaN where not
        estimated.
    mounting : ndarray, shape (3, 3), or None
        The sensor's axes on the tracked frame (sensor vectors to tracked-frame
        vectors), where estimated.
    force_rms : float
        rms of the force residual, N.
    """

    mass: float
    com: np.ndarray
    b: np.ndarray
    mounting: np.ndarray
    force_rms: float


def _rows(q, w_hat, reading):
    """``(R (N, 3, 3), sigma w_hat (N, 6))``, checked: the attitudes and the reading in fmscal's sign."""
    q = as_finite_array(q, (-1, 4), "q")
    w_hat = as_finite_array(w_hat, (len(q), 6), "w_hat")
    if len(q) < 4:
        raise FmscalError(f"a static fit needs at least 4 poses; got {len(q)}")
    q = q / np.linalg.norm(q, axis=1)[:, None]
    return np.moveaxis(rotation_matrix(q.T), -1, 0), reading_sign(reading) * w_hat


def plain_fit(q, w_hat, reading="reaction", g=9.81):
    """The practitioners' plain static fit: eqs. (P1) and (P2) by linear least squares (module docstring).

    Parameters
    ----------
    q : array_like, shape (N, 4)
        Attitudes of the tracked frame (sensor frame taken as square on it),
        unit quaternions, scalar first.
    w_hat : array_like, shape (N, 6)
        The reading ``(tx, ty, tz, fx, fy, fz)``, N m and N.
    reading : {"reaction", "load"}
        The reading's sign convention (fmscal's, or the tool's load on the sensor).
    g : float
        Gravity's size, along -z of the pose frame, m/s^2.

    Returns
    -------
    ReferenceFit
        Mass, centre of mass, the six offsets; no mounting.
    """
    R, y = _rows(q, w_hat, reading)
    a = np.einsum("nkj,k->nj", R, [0.0, 0.0, as_positive_scalar(g, "g")])      # R^T (-g): the weight per kg
    n = len(a)
    X = np.concatenate([a[:, :, None], np.broadcast_to(np.eye(3), (n, 3, 3))], axis=2).reshape(3 * n, 4)
    m, *c_f = np.linalg.lstsq(X, y[:, 3:].ravel(), rcond=None)[0]                # eq. (P1)
    X = np.concatenate([-skew(m * a), np.broadcast_to(np.eye(3), (n, 3, 3))], axis=2).reshape(3 * n, 6)
    sol = np.linalg.lstsq(X, y[:, :3].ravel(), rcond=None)[0]                    # eq. (P2): com x f = -f x com
    force_rms = float(np.sqrt(np.mean((y[:, 3:] - m * a - c_f) ** 2)))
    return ReferenceFit(mass=float(m), com=sol[:3], b=np.r_[sol[3:], c_f], mounting=None, force_rms=force_rms)


def _nearest_rotation(A):
    """The rotation nearest ``A`` in the Frobenius norm: ``U diag(1, 1, det(U V^T)) V^T`` from the SVD."""
    u, _, vt = np.linalg.svd(A)
    return u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt


def calib_force(q, w_hat, reading="load", m0=0.3):
    """``calibForce`` of Robotlib.jl: eq. (P3), the forces only (module docstring).

    Parameters
    ----------
    q : array_like, shape (N, 4)
        Attitudes of the tool frame from the robot's kinematics, unit
        quaternions, scalar first.
    w_hat : array_like, shape (N, 6)
        The reading ``(tx, ty, tz, fx, fy, fz)``; only the forces are used.
    reading : {"load", "reaction"}
        The reading's sign convention. calibForce's equation is the load's
        (the tool's weight on the sensor); a reaction reading is negated
        first.
    m0 : float
        The guess of the mass the first solve scales by, kg (calibForce's
        default 0.3).

    Returns
    -------
    ReferenceFit
        The mass, the rotation ``Rf`` (as ``mounting``), the force offset
        (turned into the sensor's axes and fmscal's sign, ``b[3:]``); no
        centre of mass, no torque offset.
    """
    R, y = _rows(q, w_hat, reading)
    F = -y[:, 3:]                                                   # the load: calibForce's sign
    n = len(F)
    mg = as_positive_scalar(m0, "m0") * CALIB_FORCE_G
    down = -R[:, 2, :]                                              # R^T [0, 0, -1]: rows of -R^T e3
    A = np.concatenate([F[:, 0, None, None] * np.eye(3), F[:, 1, None, None] * np.eye(3),
                        F[:, 2, None, None] * np.eye(3), np.broadcast_to(np.eye(3), (n, 3, 3))], axis=2)
    w = np.linalg.lstsq(A.reshape(3 * n, 12), down.ravel(), rcond=None)[0] * mg
    Rf = _nearest_rotation(w[:9].reshape(3, 3, order="F"))          # Rf F_i: the columns multiply F_x, F_y, F_z
    A2 = np.concatenate([-down[:, :, None], np.broadcast_to(np.eye(3), (n, 3, 3))], axis=2).reshape(3 * n, 4)
    mg, *o = np.linalg.lstsq(A2, -(F @ Rf.T).ravel(), rcond=None)[0]    # R^T e3 m g + o = -Rf F_i
    o = np.asarray(o)
    # F = -(w_f + b_f) = f_load - b_f in the sensor's axes and Rf F + o = M f_load: Rf = M and o = M b_f
    b_f = Rf.T @ o
    residual = F @ Rf.T + o - mg * down
    return ReferenceFit(mass=float(mg / CALIB_FORCE_G), com=None, b=np.r_[np.full(3, np.nan), b_f], mounting=Rf,
                        force_rms=float(np.sqrt(np.mean(residual ** 2))))
