"""The one step discretisation every method shares: a double integrator driven linearly over a step.

Eq. (1) makes each channel a double integrator, ``p'' = a``. With ``a``
linear over a step ``h`` between its values ``a_k`` and ``a_k+1`` (the
reading at both ends of the step, as every method takes it), the step is
exact::

    p_{k+1} = p_k + h v_k + h^2 (2 a_k + a_{k+1}) / 6
    v_{k+1} = v_k + h (a_k + a_{k+1}) / 2

A regressor ``psi`` with ``a = psi . phi`` moves the same way, so the
recursive observers (:mod:`fmscal.observers.adaptive._adaptive`,
:mod:`fmscal.observers.adaptive._highgain`), the filter pieces
(:mod:`fmscal.observers.kalman._filter`) and least squares' double integrals
(:mod:`fmscal.observers.batch._least_squares`) all call these two functions.

On a configuration that does not move additively (a unit quaternion),
:func:`move` takes the same step on the model's manifold: the configuration
by :meth:`fmscal.plant.SpatialModel.integrate` of the position increment, the
velocity additively. The spatial floor (:mod:`fmscal.observers.batch._linearised_floor`)
and the spatial EKF (:mod:`fmscal.observers.kalman._error_state`) step with it.

Where a run's motion starts, (D1): the velocity at the first pose, fitted to the
moves of the first poses from it with a constant acceleration
(:func:`start_velocity`), so that a run on a payload already moving does not
start its first step at rest.
"""

import numpy as np

__all__ = ["position_increment", "velocity_increment", "move", "start_velocity", "START_WINDOW"]


def position_increment(h, a0, a1):
    """``h^2 (2 a_k + a_{k+1}) / 6``: what the acceleration adds to the position over the step.

    Parameters
    ----------
    h : float, ndarray or casadi.SX
        The step, s.
    a0, a1 : float, ndarray or casadi.SX
        The acceleration (or a regressor entry) at the step's start and end;
        arrays elementwise.

    Returns
    -------
    float, ndarray or casadi.SX
    """
    return h * h * (2 * a0 + a1) / 6


def velocity_increment(h, a0, a1):
    """``h (a_k + a_{k+1}) / 2``: what the acceleration adds to the velocity over the step.

    Parameters
    ----------
    h : float, ndarray or casadi.SX
        The step, s.
    a0, a1 : float, ndarray or casadi.SX
        The acceleration (or a regressor entry) at the step's start and end.

    Returns
    -------
    float, ndarray or casadi.SX
    """
    return h * (a0 + a1) / 2


def move(model, x, a0, a1, h):
    """The state ``x`` moved over a step ``h`` with the acceleration linear from ``a0`` to ``a1``.

    The two increments above, on the model's configuration::

        q_{k+1}  = q_k (+) (h nu_k + h^2 (2 a_k + a_{k+1}) / 6)
        nu_{k+1} = nu_k + h (a_k + a_{k+1}) / 2

    ``(+)`` is :meth:`fmscal.plant.SpatialModel.integrate` (in space a turn about
    the sensor's axes, so that ``h omega`` turns the body as the angular
    velocity does; in the plane an addition).

    Parameters
    ----------
    model : plant.Model
    x : ndarray or casadi.SX, shape (nx,)
        The state at the step's start.
    a0, a1 : ndarray or casadi.SX, shape (nv,)
        The accelerations at the step's start and end.
    h : float or casadi.SX
        The step, s.

    Returns
    -------
    ndarray or casadi.SX, shape (nx,)
    """
    nu = model.velocity(x)
    q = model.integrate(model.configuration(x), position_increment(h, a0, a1) + h * nu)
    return model.state_from(q, nu + velocity_increment(h, a0, a1))


#: The stretch at a log's start whose poses give the velocity a run starts from (:func:`start_velocity`), s.
START_WINDOW = 0.1


def start_velocity(log, model, window=START_WINDOW):
    """The velocity at a log's first pose, from its first poses: where a run's motion starts (eq. D1).

    A method that starts its motion at rest makes, on a payload already
    moving, a first step whose error is the velocity times the step: at a
    few tens of Hz and poses good to microradians, thousands of the poses'
    standard deviations, far beyond what a linearisation about the nominal
    holds. The poses of the first ``window`` seconds (at least three) give
    it, each as the move from the first, ``dq_j = difference(q_0, q_j)`` (on
    the model's manifold: in 3D ``[dp (world), dphi (sensor axes)]``, the
    velocity's own axes), fitted by least squares with a constant
    acceleration over the window::

        dq_j = nu_0 tau_j + a_0 tau_j^2 / 2,      tau_j = t_j - t_0          (D1)

    With two poses only, ``dq_1 / tau_1``; with one, rest.

    Parameters
    ----------
    log : plant.Log
        A log of ``model``'s case, starting at its first pose.
    model : plant.Model
    window : float
        s.

    Returns
    -------
    ndarray, shape (nv,)
        ``nu_0`` in the model's velocity layout (:meth:`fmscal.plant.Model.velocity`).
    """
    rows = np.flatnonzero(log.has_pose)
    far = int(np.searchsorted(log.t[rows], log.t[rows[0]] + window, side="right"))
    rows = rows[:max(far, 3)]
    if len(rows) < 2:
        return np.zeros(model.nv)
    q0 = model.configuration(model.rest_state(log.pose[rows[0]]))
    dq = np.array([np.ravel(model.difference(q0, model.configuration(model.rest_state(log.pose[r]))))
                   for r in rows[1:]], dtype=float)
    tau = log.t[rows[1:]] - log.t[rows[0]]
    columns = np.c_[tau, tau ** 2 / 2] if len(tau) >= 2 else tau[:, None]
    fit, *_ = np.linalg.lstsq(columns, dq, rcond=None)
    return fit[0]
