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
"""

__all__ = ["position_increment", "velocity_increment", "move"]


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
