"""The paper's Lyapunov adaptive observer exactly as printed: eqs. (6)-(8), (14), (15).

How the paper's garbled equations are read: ``docs/paper/reading-the-paper.md``. In
matrix form, with ``G(theta)`` the matrix of eq. (1) (:func:`plant.input_matrix`):

* eqs. (6), (7): ``x_hat' = A x_hat + G(theta) S_hat w_hat + K C e``, since
  ``B_1(w_hat) phi_1 = [0, row 1 of G S w_hat]`` and likewise ``B_2 phi_2``;
* eq. (8): ``S_hat' = delta G(theta)^T W e_v w_hat^T``, where
  ``e_v = [e_theta', e_X', e_Y']`` are the velocity errors (true minus
  estimate) and ``W = diag(1, m, m)`` for the law as printed (no ``1/m`` on
  the translational terms). Written out, row 2 is
  ``s_2j' = delta w_hat_j [-rho_y e_theta'/I_G + (e_X' cos + e_Y' sin)]``,
  exactly the printed eq. (8);
* eq. (15): the velocity errors by the backward difference of the position
  errors, the step absorbed in ``delta``.
"""

import numpy as np

from fmscal.plant import input_matrix
from fmscal.plant.numerics import as_finite_array, as_positive_scalar, ops

from fmscal.observers.core import INPUT, RecursiveObserver, StateLayout, matrix as mx

__all__ = ["PaperAdaptiveObserver", "PAPER_K1", "PAPER_K2", "PAPER_DELTA", "injection_matrix", "output_error"]

#: Eq. (14): ``K_1 = [25, 25]^T``, rows theta, theta'.
PAPER_K1 = np.array([[25.0], [25.0]])
#: Eq. (14): ``K_2``, rows X, X', Y, Y'; columns the X and Y output errors.
PAPER_K2 = np.array([[5.0, 5.0], [10.0, 5.0], [2.0, 15.0], [5.0, 15.0]])
#: Section 4: the stiffness constant, with the time step absorbed (eq. 15).
PAPER_DELTA = 20.0


def injection_matrix(K1, K2):
    """``K`` of eqs. (6), (7) as one 6x3 gain on the output errors ``[e_theta, e_X, e_Y]``.

    Parameters
    ----------
    K1 : ndarray, shape (2, 1)
    K2 : ndarray, shape (4, 2)

    Returns
    -------
    ndarray, shape (6, 3)
        Rows in the state order ``[theta, theta', X, X', Y, Y']``.
    """
    K = np.zeros((6, 3))
    K[0:2, 0] = K1[:, 0]
    K[2:6, 1:3] = K2
    return K


def output_error(o, x, sample):
    """Output errors ``e = y - C x_hat`` (true minus estimate, the proof's sign) and the angle of eq. (5).

    Parameters
    ----------
    o : ops namespace
    x : vector, shape (6,)
        ``x_hat`` at the sample.
    sample : namespace
        The sample, :data:`observers.core._state.INPUT` unpacked.

    Returns
    -------
    e : vector, shape (3,)
        ``[e_theta, e_X, e_Y]``; zero without a pose.
    theta : scalar
        The measured angle where there is a pose, else the estimate.
    """
    has, pose = sample.has_pose, sample.pose
    e = has * o.vcat([pose[0] - x[0], pose[1] - x[2], pose[2] - x[4]])
    return e, has * pose[0] + (1 - has) * x[0]


class PaperAdaptiveObserver(RecursiveObserver):
    """The paper's observer as printed (``adaptive-paper``): eqs. (6)-(8), (14), (15).

    Forward Euler at the log's step, ``delta = 20`` absorbing the step, ``K_1``,
    ``K_2`` as printed (eq. 14), velocity errors by the backward difference of
    the position errors (eq. 15, ``e_v = e(n) - e(n-1)`` per step), and the law
    as printed (``W = diag(1, m, m)``, module docstring). Under the paper's
    noise it does not converge (docs/paper/index.md).

    Parameters
    ----------
    model : plant.PlanarModel or plant.Payload
        The planar problem (a payload stands for its planar model).
    K1 : array_like, shape (2, 1), optional
        Injection gain of the angular observer (6); default the paper's.
    K2 : array_like, shape (4, 2), optional
        Injection gain of the translational observer (7); default the paper's.
    delta : float
        Stiffness constant of eq. (8), step absorbed.
    offset : bool
        Also estimate the sensor's offset ``b`` (``result.b``): the law runs
        on ``[S | c]`` and the reading ``[w_hat, 1]``.

    Examples
    --------
    >>> from fmscal.plant import PAPER_PAYLOAD, get_scenario
    >>> log, truth, _ = get_scenario("paper").with_(duration=2.0).generate(0)
    >>> PaperAdaptiveObserver(PAPER_PAYLOAD).run(log, truth.S0).S_hat.shape
    (3, 3)
    """

    name = "adaptive-paper"
    paper_equations_only = True        # eqs. (4)-(8): the paper's planar structure

    def __init__(self, model, K1=None, K2=None, delta=PAPER_DELTA, offset=False):
        self.K1 = as_finite_array(PAPER_K1 if K1 is None else K1, (2, 1), "K1")
        self.K2 = as_finite_array(PAPER_K2 if K2 is None else K2, (4, 2), "K2")
        self.delta = as_positive_scalar(delta, "delta")
        self.K = injection_matrix(self.K1, self.K2)
        super().__init__(model, offset=offset)

    def _layout(self):
        # e_prev: the output error at the previous pose, for the backward difference of eq. (15)
        return StateLayout(("x", 6), ("S", 3 * self.n_cols), ("e_prev", 3))

    def _initial_state(self, S0, u):
        x = self.model.rest_state(u.pose)
        return self.state.pack(None, x=x, S=self._initial_S(S0), e_prev=np.zeros(3))

    def _transition(self, z, u_prev, u, dt):
        """Eqs. (6), (7), (14) by forward Euler; eq. (8) with eq. (15)."""
        o = ops(z, u)
        s, now = self.state.unpack(z), INPUT.unpack(u_prev)
        x = s.x
        w = self._augmented(o, now.w_hat)
        e, theta = output_error(o, x, now)
        G = input_matrix(theta, self.payload)
        S_mat = mx.as_matrix(o, s.S, 3, self.n_cols)
        # eq. (15): velocity errors by backward difference, step absorbed in delta
        e_v = now.has_pose * (e - s.e_prev)
        # eq. (8) as printed: S_hat += delta G^T diag(1, m, m) e_v w_hat^T
        W_e_v = o.vcat([e_v[0], self.payload.mass * e_v[1], self.payload.mass * e_v[2]])
        S_next = S_mat + self.delta * o.dot(mx.col(o.dot(G.T, W_e_v)), mx.row(w))
        # eqs. (6), (7), (14): x_hat' = A x_hat + G S_hat w_hat + K C e, forward Euler
        a = o.dot(G, o.dot(S_mat, w))
        x_dot = o.vcat([x[1], a[0], x[3], a[1], x[5], a[2]]) + o.dot(self.K, e)
        e_keep = now.has_pose * e + (1 - now.has_pose) * s.e_prev
        return self.state.pack(o, x=x + dt * x_dot, S=mx.flat(o, S_next), e_prev=e_keep)
