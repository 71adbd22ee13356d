"""The EKF's predict and update, written once for numpy and casadi (in the manner of filterpy's ``kalman_filter.py``).

Both EKF paths call these: the readable one on numpy arrays, through
filterpy's ``ExtendedKalmanFilter`` object (:class:`observers.kalman.AugmentedEKF`,
``compiled=False``, and :meth:`~observers.Observer.step`), and the compiled
whole step on casadi symbols (:func:`observers.kalman.whole_error_step`), for
every model (the error state ``e``, ``H = [I_nv 0]``), one equation a line::

    x-  = f(x)                                     (K1, predict)
    P-  = F P F^T + Q                              (K2, its lower triangle mirrored)
    V   = H P- H^T + R                             (K3, update)
    K   = P- H^T V^-1                              (K4)
    x   = x- + K y                                 (K5)
    P   = (I - K H) P- (I - K H)^T + K R K^T       (K6, Joseph form)
    nis = y^T V^-1 y                               (K7, normalised innovation squared)
    P   = G P G^T                                  (K8, reset after an injection)

``H`` selects entries of the state (the pose is part of it), so it is given
as their indices ``pose``: ``P H^T = P[:, pose]``. ``y`` is the innovation,
the pose less the pose the predicted state shows (``z - h(x-)``), formed by
the caller, which knows the attitude (an angle's difference, a turn's).
``has`` (1 or 0) switches the update on; at 0, ``K = 0`` leaves ``x`` and
``P`` as they were (a sample without a pose, on the compiled path, which
cannot branch).

``P-`` is made symmetric by mirroring its lower triangle, on both paths:
the Joseph form (K6) keeps ``P`` positive definite for any ``K`` only if
``P-`` is symmetric, and an asymmetry left at rounding grows from step to
step through (K6) as it is written here; the compiled path forms only the
lower triangle.

Columns throughout: ``x`` and ``y`` of shape (d, 1) and (k, 1) on numpy.
"""

import numpy as np

from fmscal.plant.numerics import is_symbolic, ops

from ._filter import pack_lower, spd_inverse, unpack_lower

__all__ = ["predict", "update", "reset", "symmetric"]


def symmetric(P):
    """``P``'s lower triangle mirrored onto its upper (module docstring), numbers or casadi symbols."""
    if is_symbolic(P):                     # casadi: the upper triangle is never formed
        d = P.shape[0]
        return unpack_lower(ops(P), pack_lower(P, d), d)
    return np.tril(P) + np.tril(P, -1).T


def predict(x_next, P, F, Q):
    """Eqs. (K1, K2): the predicted state and its covariance.

    Parameters
    ----------
    x_next : ndarray or casadi.SX, shape (d, 1)
        ``f(x)``, the model's step (the state after it).
    P, F, Q : ndarray or casadi.SX, shape (d, d)
        The covariance at the step's start, the step's Jacobian, the process noise.

    Returns
    -------
    x, P : the predicted state ``x-`` and ``P-`` (symmetric: its lower triangle mirrored).
    """
    x = x_next                                   # (K1) x- = f(x)
    P = symmetric(F @ (P @ F.T) + Q)             # (K2) P- = F P F^T + Q
    return x, P


def update(o, x, P, y, R, pose, has=1.0):
    """Eqs. (K3-K7): the update with a pose, ``H`` selecting the state's entries ``pose``, in Joseph form.

    Parameters
    ----------
    o : plant.numerics ops
        numpy's or casadi's (:func:`fmscal.plant.numerics.ops`).
    x : ndarray or casadi.SX, shape (d, 1)
        The predicted state ``x-``.
    P : ndarray or casadi.SX, shape (d, d)
        ``P-``, symmetric.
    y : ndarray or casadi.SX, shape (k, 1)
        The innovation ``z - h(x-)``.
    R : ndarray or casadi.SX, shape (k, k)
        The pose noise covariance, symmetric positive definite.
    pose : list of int
        The ``k`` entries of the state ``H`` selects.
    has : float or casadi.SX
        1 to update, 0 to leave ``x`` and ``P`` as they are.

    Returns
    -------
    x : shape (d, 1)
    P : shape (d, d), symmetric positive definite (Joseph form) for any ``K``.
    nis : float or casadi.SX
        ``y^T V^-1 y``, whether or not ``has``.
    """
    PHT = P[:, pose]                                  # P- H^T
    SI = spd_inverse(o, PHT[pose, :] + R, len(pose))   # (K3) V^-1 = (H P- H^T + R)^-1
    K = has * (PHT @ SI)                              # (K4) K = P- H^T V^-1
    x = x + K @ y                                     # (K5) x = x- + K y
    A = P - K @ PHT.T                                 # (I - K H) P-
    P = A - (A[:, pose] - K @ R) @ K.T                # (K6) (I - K H) P- (I - K H)^T + K R K^T
    nis = (y.T @ SI @ y)[0, 0]                        # (K7) y^T V^-1 y
    return x, P, nis


def reset(P, G):
    """Eq. (K8): ``P`` after an error state is injected into the nominal, ``G`` the Jacobian of the error
    after the injection with respect to the error before it (the identity where the state is a vector)."""
    return G @ P @ G.T                                # (K8) P = G P G^T
