"""Newton-Euler model of the payload, eq. (1), and its state-affine split.

Eq. (1) is written once, in :func:`input_matrix`. Everything else here (the
full state derivative, the state-affine matrices of eqs. (4) and (5), the
parameter maps ``phi_1``, ``phi_2``) is built from it, and every function takes
either numbers or casadi symbols, so the simulator, the observers and the EKF's
casadi Jacobians all share the one definition.

State order throughout the toolkit: ``x = [theta, theta', X, X', Y, Y']``.
"""

import numpy as np

from fmscal.plant.numerics import is_symbolic, ops

__all__ = [
    "input_matrix",
    "acceleration",
    "state_derivative",
    "A_1", "C_1", "B_1", "A_2", "C_2", "B_2",
    "regressors", "phi_1", "phi_2", "S_from_phi",
]


def input_matrix(theta, payload):
    """The 3x3 matrix of eq. (1) mapping the wrench to accelerations.

    ``[theta'', X'', Y''] = G(theta) [M, f_x, f_y]`` with::

        G = 1/m [[m/I_G, -m rho_y/I_G, m rho_x/I_G],
                 [0,      cos(theta),  -sin(theta)],
                 [0,      sin(theta),   cos(theta)]]

    The first row is the moment about G: ``M + rho_x f_y - rho_y f_x``.

    Parameters
    ----------
    theta : float or casadi.SX
        Body angle in rad.
    payload : plant.Payload
        Mass properties.

    Returns
    -------
    ndarray or casadi.SX, shape (3, 3)
    """
    o = ops(theta)
    m, inertia = payload.mass, payload.inertia
    rho_x, rho_y = payload.rho
    c, s = o.cos(theta), o.sin(theta)
    return o.matrix([
        [1.0 / inertia, -rho_y / inertia, rho_x / inertia],
        [0.0, c / m, -s / m],
        [0.0, s / m, c / m],
    ])


def acceleration(theta, w, payload):
    """Accelerations ``[theta'', X'', Y'']`` of eq. (1) for the true wrench ``w``.

    Parameters
    ----------
    theta : float or casadi.SX
        Body angle in rad.
    w : array_like or casadi.SX, shape (3,)
        True wrench ``[M, f_x, f_y]`` in N m and N, body frame, at the sensor
        interface.
    payload : plant.Payload

    Returns
    -------
    ndarray or casadi.SX, shape (3,)
        In rad/s^2, m/s^2, m/s^2.
    """
    G = input_matrix(theta, payload)
    return ops(theta, w).dot(G, w)


def state_derivative(x, w, payload):
    """Time derivative of ``x = [theta, theta', X, X', Y, Y']`` under eq. (1).

    Parameters
    ----------
    x : array_like or casadi.SX, shape (6,)
    w : array_like or casadi.SX, shape (3,)
        True wrench.
    payload : plant.Payload

    Returns
    -------
    ndarray or casadi.SX, shape (6,)
    """
    o = ops(x, w)
    a = acceleration(x[0], w, payload)
    return o.vcat([x[1], a[0], x[3], a[1], x[5], a[2]])


# --- The state-affine split, eqs. (4) and (5) -------------------------------

#: Eq. (4): ``A_1``, double integrator of the angle.
A_1 = np.array([[0.0, 1.0], [0.0, 0.0]])
#: Eq. (4): ``C_1``, the angle is measured.
C_1 = np.array([[1.0, 0.0]])
#: Eq. (5): ``A_2 = diag(A_1, A_1)`` for ``x_2 = [X, X', Y, Y']``.
A_2 = np.block([[A_1, np.zeros((2, 2))], [np.zeros((2, 2)), A_1]])
#: Eq. (5): ``C_2`` measures ``X`` and ``Y``.
C_2 = np.block([[C_1, np.zeros((1, 2))], [np.zeros((1, 2)), C_1]])


def regressors(theta, w_hat, payload):
    """The rows of ``B_1``, ``B_2`` (eqs. 4, 5) that drive the accelerations.

    From eq. (1) (:func:`input_matrix` ``G``): ``theta'' = psi_theta . phi_1``
    with ``psi_theta = w_hat / I_G``, and ``X'' = psi_X . phi_2``,
    ``Y'' = psi_Y . phi_2`` with ``psi_X = [cos w_hat, -sin w_hat] / m``,
    ``psi_Y = [sin w_hat, cos w_hat] / m``.

    ``w_hat`` may carry a fourth component, a constant 1: the regressors then
    also drive the offset column ``c`` of ``w = S w_hat + c``.

    Parameters
    ----------
    theta : float, ndarray of shape (N,), or casadi.SX
        Body angle, rad (an array gives one regressor per sample).
    w_hat : array_like or casadi.SX, shape (n,) or (n, N)
        The raw reading, ``n`` = 3 (or 4 with the constant 1).
    payload : plant.Payload

    Returns
    -------
    psi_theta : list of n, psi_X, psi_Y : lists of 2n
        Entries are scalars, arrays of shape (N,), or casadi expressions.
    """
    G = input_matrix(theta, payload)
    n = w_hat.shape[0] if hasattr(w_hat, "shape") else len(w_hat)
    psi_theta = [G[0, 0] * w_hat[j] for j in range(n)]
    psi_X = [G[1, 1 + a] * w_hat[j] for a in range(2) for j in range(n)]
    psi_Y = [G[2, 1 + a] * w_hat[j] for a in range(2) for j in range(n)]
    return psi_theta, psi_X, psi_Y


def B_1(w_hat, payload):
    """Eq. (4): ``B_1(w_hat) = [0_3, w_hat]^T / I_G``, shape (2, 3).

    With it, ``x_1' = A_1 x_1 + B_1(w_hat) phi_1`` where ``phi_1`` is
    :func:`phi_1` of the calibration matrix. Its velocity row is
    ``psi_theta`` of :func:`regressors`.
    """
    psi_theta, _, _ = regressors(0.0, np.asarray(w_hat, dtype=float), payload)
    return np.vstack([np.zeros(len(psi_theta)), psi_theta])


def B_2(w_hat, theta, payload):
    """Eq. (5): ``B_2(w_hat, theta)``, shape (4, 6), for ``phi_2 = [s_2., s_3.]``.

    Rows ``X, X', Y, Y'``; the velocity rows are ``R(theta)/m`` (the lower
    right block of eq. (1)) times ``w_hat^T`` for each row of ``S``, that is
    ``psi_X`` and ``psi_Y`` of :func:`regressors`::

        B_2 = 1/m [[0_3,             0_3            ],
                   [w_hat cos(theta), -w_hat sin(theta)],
                   [0_3,             0_3            ],
                   [w_hat sin(theta),  w_hat cos(theta)]]
    """
    _, psi_X, psi_Y = regressors(theta, np.asarray(w_hat, dtype=float), payload)
    out = np.zeros((4, len(psi_X)))
    out[1], out[3] = psi_X, psi_Y
    return out


def phi_1(S, payload):
    """Eq. (4): ``phi_1_j = s_1j - rho_y s_2j + rho_x s_3j``, shape (3,).

    It is the first row of eq. (1) times ``I_G``, applied to ``S``.

    With an offset column (``[S | c]``, 3x4) it has 4 entries.

    Parameters
    ----------
    S : array_like, shape (3, n), or a flat (3n,) vector in row order (numbers or casadi.SX)
        ``n`` = 3, or 4 with the offset column.
    payload : plant.Payload
    """
    row = input_matrix(0.0, payload)[0] * payload.inertia   # [1, -rho_y, rho_x]
    if is_symbolic(S) or np.ndim(S) == 1:
        n = (S.shape[0] if hasattr(S, "shape") else len(S)) // 3
        return ops(S).vcat([sum(row[i] * S[n * i + j] for i in range(3)) for j in range(n)])
    return row @ np.asarray(S, dtype=float)


def phi_2(S):
    """Eq. (5): ``phi_2 = [s_21, s_22, s_23, s_31, s_32, s_33]``, rows 2 and 3 of ``S``.

    Parameters
    ----------
    S : array_like, shape (3, n), or a flat (3n,) vector in row order (numbers or casadi.SX)
        ``n`` = 3, or 4 with the offset column (``phi_2`` then has 8 entries).

    Returns
    -------
    ndarray or casadi.SX, shape (2n,)
    """
    if is_symbolic(S) or np.ndim(S) == 1:
        n = (S.shape[0] if hasattr(S, "shape") else len(S)) // 3
        return S[n:3 * n]
    return np.asarray(S, dtype=float)[1:].ravel()


def S_from_phi(phi1, phi2, payload):
    """Invert eqs. (4), (5): ``s_1j = phi_1j + rho_y s_2j - rho_x s_3j``.

    With an offset (``w = S w_hat + c``, the reading augmented by a constant
    1), ``phi_1`` has 4 entries, ``phi_2`` 8, and the result is ``[S | c]``.

    Parameters
    ----------
    phi1 : array_like or casadi.SX, shape (n,)
    phi2 : array_like or casadi.SX, shape (2n,)
        ``n`` = 3, or 4 with the offset.
    payload : plant.Payload

    Returns
    -------
    ndarray or casadi.SX
        ``S`` as a (3, n) array, or for symbols a flat (3n,) vector in row order.
    """
    o = ops(phi1, phi2)
    rho_x, rho_y = payload.rho
    n = phi1.shape[0] if hasattr(phi1, "shape") else len(phi1)
    s2 = [phi2[j] for j in range(n)]
    s3 = [phi2[n + j] for j in range(n)]
    s1 = [phi1[j] + rho_y * s2[j] - rho_x * s3[j] for j in range(n)]
    flat = o.vcat(s1 + s2 + s3)
    return flat if is_symbolic(flat) else flat.reshape(3, n)
