"""The adaptive observer's law in 3D: the momenta about the centre of mass, each driven linearly by ``[S | c]``.

:class:`fmscal.observers.AdaptiveObserver` runs this on a
:class:`fmscal.plant.SpatialModel` (``AdaptiveObserver._momenta_step``), on the
model's own pieces, written once for numbers and casadi symbols
(:meth:`fmscal.plant.SpatialModel.momentum_regressor`, ``momentum_drives``,
``momentum_phi_from_params``, ``world_inverse_inertia``, ``turn``, ...); this
module holds its description and its settings. The adaptation (recursive least squares
per parameter group, the change test, the forgetting) is the planar one's,
shared. What differs is the motion the observer follows. The spatial model is
not linear in its channels (the attitude is a quaternion, Newton-Euler at the
sensor point has gyroscopic terms), but about the centre of mass ``C``
(``p_C = p + R com``) the two momenta are driven linearly by the wrench, in
the world frame (eq. (M) of the model's pieces, :class:`fmscal.plant.SpatialModel`):

    d/dt (m v_C) = R f + m g                                  (linear momentum)
    d/dt H       = R tau_C,   tau_C = tau_O - com x f          (angular momentum, H = R I_c omega)

Both right-hand sides are ``Psi(R, w_hat) phi + const``: with the reading
augmented ``w = [w_hat; 1]`` (``n`` entries) and ``Psi = R (x) w^T`` (3 x 3n,
the same for both), the force rows ``phi_f = vec(S_f)`` (``S_f`` rows 3-5 of
``[S | c]``) drive the linear momentum and the rows of the torque about ``C``,
``phi_t = vec(S_t - [com]x S_f)`` (:func:`phi_from_params`), drive ``H``: two
parameter groups of ``3n`` each (21 with the offset), as ``phi_1``, ``phi_2``
in the plane. ``R`` is the measured attitude where a pose arrives (the
pose is the configuration, as the measured angle in the plane); between
poses it is the last measured attitude turned by the observer's own turn
since that pose (``chi - chi_pose``), so that the observer's attitude error
at the pose does not enter the drives. What is left, the observer's rate
error over the gap, is not in the filters: it shrinks with faster poles,
hence the spatial default ``lam`` of :data:`SPATIAL_LAM` (what the default
reaches against the floor: docs/observers.md, ``tests/test_spatial_adaptive.py``,
``benchmarks/online_floor_3d.py``).

The outputs are the measured positions of ``C`` (``m p_C``, three double
integrators exactly as the planar X, Y channels) and the attitude. The
attitude moves with ``omega = I_c^-1 R^T H``; propagated with the measured
``R`` in that product, its error in the world frame,
``delta = 2 log(q_meas (x) q_hat*)``, obeys to first order

    delta' = M(t) H~,   H~' = Psi phi~_t,   M = R I_c^-1 R^T   (I_W^-1, the world-frame inverse inertia)

a double integrator with a known, time-varying gain ``M``. With
``nu = M H~`` it is the planar channel: the injection ``[l_1; l_2 M^-1]``
(:func:`observers.adaptive._highgain.discrete_gain`) puts each axis's sampled poles at
``exp(-lam h)``, and the sensitivity filter carries ``M``. Per step ``h``,
with ``G_p``, ``G_v`` the position and velocity increments of ``Psi``
linear over the step (:mod:`observers.core._discretise`)::

    translational (y = m p_C, l = m v_C; per axis)     rotational (q, H)
    U_y^- = U_y + h U_l + G_p                          U_d^- = U_d + M_n (h U_H + G_p)
    U_l^- = U_l + G_v                                  U_H^- = U_H + G_v
    e_y   = m p_C,meas - y^-                           e_d   = 2 log(q_meas (x) q^-*)
    U_y  <- (1 - l_1) U_y^-,  U_l <- U_l^- - l_2 U_y^-   U_d <- (1 - l_1) U_d^-,  U_H <- U_H^- - l_2 I_W U_d^-
    y    <- y^- + l_1 e_y + U_y dphi_f                  q <- exp((l_1 e_d + U_d dphi_t) / 2) (x) q^-
    l    <- l^- + l_2 e_y + U_l dphi_f                  H <- H^- + l_2 I_W e_d + U_H dphi_t

with ``dphi`` each group's recursive least-squares step on its three rows
``U_y^-`` (errors ``e_y``) and ``U_d^-`` (errors ``e_d``). The prediction
is the motion's own: ``l`` and ``H`` with their drives linear over the step,
``q`` turned by ``h (omega_n + omega_n+1) / 2 + h^2 / 12 omega_n x omega_n+1``
(the rotation vector of a body rate linear over the step, to third order).
No pose is differentiated and nothing models the noise.
"""

from fmscal.plant.physics import SpatialModel

__all__ = ["phi_from_params", "params_from_phi", "SPATIAL_LAM", "WARM_UP"]

#: The observer's poles on the spatial model, rad/s (``lam=None``): between poses the drives use the
#: observer's own turn, whose error shrinks with faster poles (module docstring).
SPATIAL_LAM = 20.0

#: The fit waits this many time constants ``1 / lam`` of the observer's poles from the first sample: the
#: observer starts at rest, the payload may not, and the error of that start is no parameters' doing.
WARM_UP = 10.0


def phi_from_params(s, n, com):
    """The two groups' parameters from ``vec([S | c])``: ``[phi_t, phi_f]`` (module docstring).

    The model's :meth:`fmscal.plant.SpatialModel.momentum_phi_from_params`:
    ``phi_f = vec(S_f)`` (rows 3-5), ``phi_t = vec(S_t - [com]x S_f)`` (the
    torque about ``C``, ``tau_C = tau_O - com x f``), row order.

    Parameters
    ----------
    s : ndarray or casadi.SX, shape (6 n,)
        ``[S | c]`` flat in row order.
    n : int
        Columns: 6, or 7 with the offset.
    com : array_like, shape (3,)
        The centre of mass in the sensor frame, m.

    Returns
    -------
    list of two vectors of 3 n entries
    """
    return SpatialModel.momentum_phi_from_params(s, n, com)


def params_from_phi(phis, n, com):
    """``vec([S | c])`` (row order) from ``[phi_t, phi_f]``: ``S_t = T + [com]x S_f``; inverse of
    :func:`phi_from_params` (:meth:`fmscal.plant.SpatialModel.momentum_params_from_phi`).

    Returns
    -------
    vector of 6 n entries
    """
    return SpatialModel.momentum_params_from_phi(phis, n, com)
