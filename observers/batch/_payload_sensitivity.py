"""How the fitted ``S`` moves with the payload's mass properties: what carries their uncertainty into ``S_std``.

A calibration fits ``[S | c]`` so that ``S w_hat + c`` is the wrench the
logged motion needs, and that wrench is the payload's: its mass ``m``, its
centre of mass (or the planar ``rho``), its inertia and, under gravity,
gravity's size ``|g|`` (the model's :meth:`~fmscal.plant.Model.payload_parameter_names`,
``theta``). A payload given wrong moves ``S`` with it. Some errors no log
can see (torques first, then forces, ``[c]x`` the cross-product matrix):

- the mass by a factor ``k``: ``S' = [[I, (k - 1) [c]x], [0, k I]] S`` exactly;
- a uniform scale ``k`` of the inertia: ``S' = [[k I, (1 - k) [c]x], [0, I]] S`` exactly;
- the centre of mass moved by ``d``: nearly ``[[I, [d]x], [0, I]] S`` (the
  force's own change, ``m (alpha x d + omega x (omega x d))``, is left);

the inertia's shape (a non-uniform error) and gravity's size leave a residual
the fit can only partly absorb. Either way the estimate moves, and only the
payload's stated uncertainty can cover it. To first order::

    d vec([S | c]) = D d theta,   cov_payload = D Sigma_theta D^T                          (Y1)

``Sigma_theta`` the payload's covariance (:class:`fmscal.plant.physics.PayloadStd`).

The sensitivity ``D``, column ``j``, is the least-squares fit of the needed
wrench's change on the readings, as the latency's (eq. (L4) of
:mod:`fmscal.observers.batch._latency`)::

    d w_k / d theta_j = (w_k(theta + h_j e_j) - w_k(theta - h_j e_j)) / (2 h_j)            (Y2)
    D_j = vec((X^T X - N Sigma)^+ X^T (d w / d theta_j))^T,    X = [w_hat_k; 1]            (Y3)

with ``w_k(theta)`` the wrench the smoothed motion needs
(:func:`fmscal.observers.batch.needed_wrenches`: one smoothing for every
``theta``) and ``Sigma`` the reading's noise (Deming's regression, as
:func:`fmscal.observers.batch.fit_readings`; the constant's column only where
the offset is fitted). The wrench is affine in the inertia's entries and
quadratic in the mass and the position (Newton-Euler; eq. (1) in the plane),
so (Y2) is exact to rounding; its steps are a millionth of each number's
scale, taken on one side where the other is not a valid payload (an inertia
at the triangle inequality's edge). It is affine in gravity too: gravity's
size is stepped to zero, one side only (one more smoothing-free regressor,
not two). Where a change of the payload is a
linear map of the wrench (the mass, the inertia's scale), (Y3) returns that
map times ``[S | c]``, the exact transformation above; elsewhere it is the
part of the change the fit absorbs. The maximum-likelihood floor absorbs it
with other weights than least squares; the two agree within a few tenths of
the floor's statistical standard deviation on a 10 s ``spatial-arm`` log,
for errors far larger than their sds (a 30 % error of one inertia entry,
1.1 % of gravity; ``tests/test_payload_std.py``).

What the fit cannot absorb is the residual of (Y3), ``r_j = d w / d theta_j
- X D_j``: a log's torques can tell an inertia's shape, and only its shape
(:func:`fmscal.observers.diagnostics.misfit`, eq. (M4)).
"""

from dataclasses import dataclass

import numpy as np

from fmscal.plant.numerics import FmscalError

from fmscal.observers.core import reading_noise
from ._inverse_dynamics import needed_wrenches

__all__ = ["PayloadSensitivity", "payload_sensitivity"]

#: The step of (Y2), relative to each number's scale: small enough that a tensor at the edge of the triangle
#: inequality stays within its tolerance under a product of inertia's step (a second-order change).
_STEP = 1e-6


@dataclass
class PayloadSensitivity:
    """How a log's least-squares ``[S | c]`` moves with the payload (module docstring).

    Attributes
    ----------
    names : tuple of str
        The payload's numbers (:meth:`fmscal.plant.Model.payload_parameter_names`).
    values : ndarray, shape (k,)
        Their values.
    D : ndarray, shape (n_w n, k)
        ``d vec([S | c]) / d theta`` (row order; ``n = n_w + 1`` with the offset, ``n_w`` without), eq. (Y3).
    rows : slice
        The log's rows the smoothing's edges leave.
    wrench : ndarray, shape (M, n_w)
        The wrench the motion needs at ``values`` on those rows, N m and N.
    columns : ndarray, shape (M, n_w, k)
        ``d w / d theta_j`` on those rows, eq. (Y2).
    readings : ndarray, shape (M, n)
        The regressor ``X`` of (Y3): the readings on those rows, and the constant 1 with the offset.
    wrench_sd : ndarray, shape (n_w,)
        The reading's noise (Deming's ``Sigma``), N m and N.
    """

    names: tuple
    values: np.ndarray
    D: np.ndarray
    rows: slice
    wrench: np.ndarray
    columns: np.ndarray
    readings: np.ndarray
    wrench_sd: np.ndarray

    @property
    def offset(self):
        """True where the constant column (the offset) was fitted."""
        return self.readings.shape[1] == self.wrench.shape[1] + 1

    def unabsorbed(self, which):
        """The part of ``d w / d theta_j`` the readings cannot absorb, ``d w / d theta_j - X D_j`` (eq. (Y3)).

        Parameters
        ----------
        which : sequence of int
            Indices into :attr:`names`.

        Returns
        -------
        ndarray, shape (M, n_w, len(which))
        """
        n_w, n = self.wrench.shape[1], self.readings.shape[1]
        D = self.D[:, list(which)].reshape(n_w, n, len(which))                 # [i, l, j]
        return self.columns[:, :, list(which)] - np.einsum("ml,ilj->mij", self.readings, D)

    def covariance(self, cov_theta):
        """``D Sigma_theta D^T`` (eq. (Y1)): the payload's part of the covariance of ``vec([S | c])``.

        An infinite variance of ``theta`` (a number not determined) gives an infinite variance to every entry
        it moves, and none to the others.

        Parameters
        ----------
        cov_theta : ndarray, shape (k, k)

        Returns
        -------
        ndarray, shape (n_w n, n_w n)
        """
        cov_theta = np.asarray(cov_theta, dtype=float)
        infinite = ~np.isfinite(np.diag(cov_theta))
        finite = np.where(np.isfinite(cov_theta), cov_theta, 0.0)
        out = self.D @ finite @ self.D.T
        if infinite.any():
            moved = np.any(np.abs(self.D[:, infinite]) > 0, axis=1)
            out[np.ix_(moved, moved)] = np.inf
        return out


def payload_sensitivity(log, model, offset=True, window=0.2, wrench_sd=None):
    """The sensitivity of a log's fitted ``[S | c]`` to the payload's numbers: eqs. (Y2), (Y3).

    Parameters
    ----------
    log : plant.Log
        A log of the model's case, its poses aligned with the reading (the latency taken out), in the toolkit's
        sign.
    model : plant.Model
        Its payload (and gravity) as given.
    offset : bool
        The fit takes the offset column ``c``.
    window : float
        Smoothing window of the pose differentiation, s.
    wrench_sd : array_like, shape (n_w,), optional
        The reading's noise; default measured from the log (:func:`fmscal.observers.core.reading_noise`).

    Returns
    -------
    PayloadSensitivity

    Raises
    ------
    FmscalError
        A log of another case or shorter than the window.
    """
    model.check_log(log, "the payload's sensitivity")
    theta = model.payload_parameters()
    names = model.payload_parameter_names()
    k = len(theta)
    scale = np.abs(theta)
    n_pos, n_in = len(model.payload_position_names), len(model.inertia_names)
    scale[1:1 + n_pos] = max(np.linalg.norm(theta[1:1 + n_pos]), 0.01)          # a position: its length, >= 1 cm
    scale[1 + n_pos:1 + n_pos + n_in] = model.inertia_scale()
    steps = _STEP * np.maximum(scale, 1e-12)
    models, pairs = [model], []
    for j in range(k):                                # (Y2): both sides where both are valid payloads, else one
        if names[j] == "gravity":                     # affine in gravity: the difference to none at all
            steps[j], signs = theta[j], (-1.0,)
        else:
            signs = (1.0, -1.0)
        sides = []
        for sign in signs:
            try:
                sides.append((sign, model.with_payload_parameters(theta + sign * steps[j] * np.eye(k)[j])))
            except FmscalError:
                continue
        if not sides:
            raise FmscalError(f"the payload's {names[j]} cannot be moved by a millionth either way and stay a "
                              "valid payload")
        pairs.append([(sign, len(models) + i) for i, (sign, _) in enumerate(sides)])
        models += [m for _, m in sides]
    rows, wrenches = needed_wrenches(log, models, window)
    w0 = wrenches[0]
    columns = np.empty((len(w0), model.n_w, k))
    for j, sides in enumerate(pairs):
        if len(sides) == 2:
            columns[:, :, j] = (wrenches[sides[0][1]] - wrenches[sides[1][1]]) / (2 * steps[j])
        else:
            sign, i = sides[0]
            columns[:, :, j] = sign * (wrenches[i] - w0) / steps[j]
    w_hat = log.w_hat[rows]
    X = np.c_[w_hat, np.ones(len(w_hat))] if offset else np.array(w_hat, dtype=float)
    wrench_sd = reading_noise(log.w_hat) if wrench_sd is None else np.asarray(wrench_sd, dtype=float)
    return PayloadSensitivity(names=names, values=theta, D=_absorbed(columns, X, wrench_sd), rows=rows, wrench=w0,
                              columns=columns, readings=X, wrench_sd=wrench_sd)


def _absorbed(columns, X, wrench_sd):
    """``D`` of eq. (Y3) for every column at once, in the row order of ``[S | c]``."""
    M, n_w, k = columns.shape
    n = X.shape[1]
    spread = np.std(X, axis=0)
    spread[n_w:] = 1.0                                              # the constant's column
    spread[spread <= 0] = 1.0
    Xs = X / spread
    noise = np.r_[wrench_sd, np.zeros(n - n_w)] / spread
    information = Xs.T @ Xs - M * np.diag(noise ** 2)               # Deming: the reading's noise taken out
    lam, u = np.linalg.eigh(information)
    kept = lam > 1e-12 * lam.max()
    inverse = (u[:, kept] / lam[kept]) @ u[:, kept].T
    # (n, n_w k): column (i, j) is row i of D_j; X^T F taken as (F^T X)^T, whose product BLAS runs as a few long
    # dot products (the other order, threaded, took 100 times as long on a 60 s log)
    theta = inverse @ (columns.reshape(M, n_w * k).T @ Xs).T
    coefficients = (theta / spread[:, None]).reshape(n, n_w, k)      # [l, i, j]: d [S | c]_il / d theta_j
    return coefficients.transpose(1, 0, 2).reshape(n_w * n, k)
