"""The interface every observer shares, and the machinery that runs them.

An observer is a discrete-time system with a packed state vector ``z``. Each
implementation writes its update once, in :meth:`Observer._transition`, with
operations that work on numpy arrays and on casadi symbols. :meth:`Observer.run`
then either loops over the log in numpy (the readable path) or compiles the
same transition with casadi and runs it in chunks (the fast path): both give the
same numbers.
"""

import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from plant import Log, Payload
from plant._compile import BufferedCall, compile_function
from plant.sensor import check_calibration
from plant.errors import FmscalError

__all__ = ["Observer", "ObserverResult", "settled", "check_sample", "initial_calibration", "split_calibration",
           "offset_from_c", "offset_std", "DIVERGENCE_BOUND", "SETTLE_FRACTION", "SETTLE_TOLERANCE"]

#: A run whose calibration estimate has an entry beyond this is declared diverged.
DIVERGENCE_BOUND = 1e3
#: ``converged`` looks at this final fraction of the run ...
SETTLE_FRACTION = 0.2
#: ... and asks that ``S_hat`` stay within this relative 2-norm distance of its final value.
SETTLE_TOLERANCE = 0.05
_CHUNK = 1000          # steps per compiled call


def settled(S_history, fraction=SETTLE_FRACTION, tolerance=SETTLE_TOLERANCE):
    """Whether an estimate settled: no truth needed.

    True when, over the last ``fraction`` of the run, every ``S_hat(t)`` is
    within ``tolerance`` of the final ``S_hat`` in relative induced 2-norm.

    Parameters
    ----------
    S_history : ndarray, shape (N, 3, 3)

    Returns
    -------
    bool
    """
    n = len(S_history)
    tail = S_history[int(n * (1 - fraction)):]
    final = S_history[-1]
    bound = tolerance * max(np.linalg.norm(final, 2), 1e-12)
    gap = tail - final
    # the 2-norm never exceeds the Frobenius norm: take SVDs only where the cheap bound fails
    unsure = np.sqrt(np.einsum("nij,nij->n", gap, gap)) > bound
    return bool(not unsure.any() or np.max(np.linalg.norm(gap[unsure], ord=2, axis=(1, 2))) <= bound)


@dataclass
class ObserverResult:
    """What an observer's :meth:`Observer.run` returns.

    Attributes
    ----------
    observer : str
        Name used in tables: ``adaptive``, ``adaptive-paper``, ``high-gain``,
        ``ekf``, ``least-squares``.
    t : ndarray, shape (N,)
        Times, s. Shorter than the log's if the run diverged and stopped.
    S_hat : ndarray, shape (3, 3)
        The final estimate of ``S``.
    S_hat_history : ndarray, shape (N, 3, 3)
    x_hat_history : ndarray, shape (N, 6)
        ``[theta, theta', X, X', Y, Y']``.
    S_std : ndarray, shape (3, 3), or None
        One-sigma uncertainty of each entry, where the method has one.
    diverged : bool
        The estimate left ``|s_ij| < DIVERGENCE_BOUND`` or became non-finite;
        the run stopped at the last finite step.
    converged : bool
        Not diverged, and the estimate settled (:func:`settled`) over the
        last 20 % of the run.
    wall_time : float
        Seconds of computation.
    info : dict
        Method-specific extras (noise estimates, fit diagnostics, ...).
    b : ndarray, shape (3,), or None
        The sensor's offset in ``w = S (w_hat - b)`` (N m, N), where the
        method was asked to estimate it; None otherwise.
    b_std : ndarray, shape (3,), or None
        Its one-sigma uncertainty, where the method has one.
    """

    observer: str
    t: np.ndarray
    S_hat: np.ndarray
    S_hat_history: np.ndarray
    x_hat_history: np.ndarray
    S_std: np.ndarray = None
    diverged: bool = False
    converged: bool = False
    wall_time: float = 0.0
    info: dict = field(default_factory=dict)
    b: np.ndarray = None
    b_std: np.ndarray = None


class Observer:
    """Base class: estimates the motion and ``S`` from pose and raw reading.

    Subclasses set :attr:`name`, the slice :attr:`_X` (6 motion states) of
    the packed state, keep ``[S_hat | c_hat]`` (``3 x n`` row order, ``n`` =
    :attr:`n_cols`) right after it, and implement :meth:`_initial_state` and
    :meth:`_transition`.

    Parameters
    ----------
    payload : plant.Payload
        The payload's known mass properties.
    offset : bool
        Also estimate the sensor's offset ``b`` in ``w = S (w_hat - b)``:
        the observer runs on ``w = S w_hat + c`` (the reading augmented by a
        constant 1, ``[S | c]`` in place of ``S``) and reports
        ``b = -S^-1 c`` in ``result.b``. Off by default, as in the paper.

    Notes
    -----
    Step-by-step use for a live sensor::

        obs.reset(S0)                # S0=None: identity, a sensor's nominal calibration
        for dt, pose, w_hat in stream:
            x_hat, S_hat = obs.step(dt, pose, w_hat)   # pose=None: no measurement

    The first :meth:`step` after :meth:`reset` only takes the first sample
    (it needs a pose) and ignores ``dt``.
    """

    name = "observer"
    _X = slice(0, 6)

    def __init__(self, payload, offset=False):
        if not isinstance(payload, Payload):
            raise TypeError(f"payload must be a plant.Payload; got {type(payload).__name__}")
        self.payload = payload
        self.offset = bool(offset)
        #: Columns of the estimated ``[S | c]``: 3, or 4 with the offset.
        self.n_cols = 4 if self.offset else 3
        self._S = slice(6, 6 + 3 * self.n_cols)
        self._compiled = None
        self.reset()

    # --- to implement -------------------------------------------------------
    def _initial_state(self, S0, pose, w_hat):
        """Packed state ``z`` at the first sample (numpy)."""
        raise NotImplementedError

    def _transition(self, z, u, dt):
        """One step: ``z`` at sample n, ``u = [has_pose, theta, X, Y, M, fx, fy]``
        at sample n+1 (pose zeros where ``has_pose`` is 0), ``dt`` in s.
        Returns ``z`` at n+1. Must work on numpy arrays and casadi SX."""
        raise NotImplementedError

    # --- step-by-step -------------------------------------------------------
    def reset(self, S0=None):
        """Forget the run; the next :meth:`step` starts from ``S0`` (default identity)."""
        self._S0 = np.eye(3) if S0 is None else check_calibration(S0, "S0", max_cond=np.inf)
        self._z = None

    def step(self, dt, pose, w_hat):
        """Take one sample.

        Parameters
        ----------
        dt : float
            Time since the previous sample, s (ignored on the first call).
        pose : array_like, shape (3,), or None
            Measured ``[theta, X, Y]`` (rad, m), or None when the vision
            system gave none: the observer predicts without correcting.
        w_hat : array_like, shape (3,)
            Raw sensor reading ``[M, f_x, f_y]``.

        Returns
        -------
        x_hat : ndarray, shape (6,)
        S_hat : ndarray, shape (3, 3)
        """
        pose, w_hat = check_sample(dt, pose, w_hat, first=self._z is None)
        if self._z is None:
            self._z = self._initial_state(self._S0, pose, w_hat)
        else:
            self._z = self._transition(self._z, _pack_input(pose, w_hat), float(dt))
        return self._z[self._X].copy(), self._z[self._S].reshape(3, self.n_cols)[:, :3].copy()

    # --- whole log ----------------------------------------------------------
    def run(self, log, S0=None, compiled=True):
        """Run over a whole log.

        Parameters
        ----------
        log : plant.Log
        S0 : array_like, shape (3, 3), optional
            Initial estimate of ``S``; default the identity.
        compiled : bool
            True (default): the transition compiled by casadi; False: the
            same transition in numpy, step by step. Results agree to 1e-9.

        Returns
        -------
        ObserverResult
        """
        if not isinstance(log, Log):
            raise TypeError(f"log must be a plant.Log; got {type(log).__name__}")
        start = time.perf_counter()
        self.reset(S0)
        self._prepare(log)
        z0 = self._initial_state(self._S0, log.pose[0], log.w_hat[0])
        U = np.column_stack([log.has_pose, np.nan_to_num(log.pose), log.w_hat])
        Z = self._run_compiled(z0, U, log.dt) if compiled else self._run_numpy(z0, U, log.dt)
        n_ok = _finite_prefix(Z, self._S)
        Z = Z[:n_ok]
        self._z = Z[-1].copy()
        result = self._result(log, Z, diverged=n_ok < len(log))
        result.wall_time = time.perf_counter() - start
        return result

    def _prepare(self, log):
        """Hook: look at the whole log before the run (noise estimates, ...)."""

    def _run_numpy(self, z0, U, dt):
        Z = np.empty((len(U), len(z0)))
        Z[0] = z = z0
        for k in range(1, len(U)):
            z = self._transition(z, U[k], dt)
            Z[k] = z
            if not _healthy(z, self._S):
                return Z[:k + 1]
        return Z

    def _compiled_chunk(self, nz):
        """The transition accumulated over ``_CHUNK`` steps, compiled to C once, bound to buffers."""
        if self._compiled is None:
            z = ca.SX.sym("z", nz)
            u = ca.SX.sym("u", 7)
            dt = ca.SX.sym("dt")
            ident = self.name.replace("-", "_")
            step = ca.Function(f"{ident}_step", [z, u, dt], [ca.densify(self._transition(z, u, dt))])
            chunk = step.mapaccum(f"{ident}_chunk", _CHUNK)
            self._compiled = BufferedCall(compile_function(chunk))
        return self._compiled

    def _run_compiled(self, z0, U, dt):
        call = self._compiled_chunk(len(z0))
        z_in, U_in, dt_in = call.inputs
        Z_out = call.outputs[0].reshape(_CHUNK, len(z0))      # column-major (nz, CHUNK)
        U_in = U_in.reshape(_CHUNK, 7)
        n = len(U)
        Z = np.empty((n, len(z0)))
        Z[0] = z0
        z_in[:] = z0
        dt_in[:] = dt                                  # mapped: one per step
        for k0 in range(1, n, _CHUNK):
            k1 = min(k0 + _CHUNK, n)
            U_in[:k1 - k0] = U[k0:k1]
            U_in[k1 - k0:] = U[k1 - 1]                  # padding past the end, discarded
            call()
            Z[k0:k1] = Z_out[:k1 - k0]
            z_in[:] = Z_out[k1 - k0 - 1]
            if not _healthy(z_in, self._S) or not np.all(np.isfinite(Z[k0:k1])):
                return Z[:k1]
        return Z

    def _augmented(self, o, w_hat):
        """The reading the model multiplies: ``w_hat``, or ``[w_hat, 1]`` with the offset."""
        return o.vcat([w_hat, 1.0]) if self.offset else w_hat

    def _initial_S(self, S0):
        """``[S0 | 0]`` flat in row order (:func:`initial_calibration`)."""
        return initial_calibration(S0, self.offset)

    def _result(self, log, Z, diverged):
        S_hist, b = split_calibration(Z[:, self._S], self.n_cols)
        if diverged:
            b = None
        return ObserverResult(
            observer=self.name, t=log.t[:len(Z)].copy(), S_hat=S_hist[-1].copy(),
            S_hat_history=S_hist, x_hat_history=Z[:, self._X].copy(),
            S_std=self._S_std(Z[-1]), diverged=bool(diverged),
            converged=bool(not diverged and settled(S_hist)), info=self._info(), b=b)

    def _S_std(self, z):
        return None

    def _info(self):
        return {}


def initial_calibration(S0, offset):
    """The calibration entries an estimator starts from: ``S0``, or ``[S0 | 0]`` with the offset.

    Returns
    -------
    ndarray, shape (9,) or (12,)
        Row order.
    """
    return np.column_stack([S0, np.zeros(3)]).ravel() if offset else np.ravel(S0)


def split_calibration(history, n_cols):
    """``S_hat`` history and the final offset from a history of ``[S_hat | c_hat]``.

    Parameters
    ----------
    history : ndarray, shape (N, 3 n_cols)
        Calibration entries in row order, per sample.
    n_cols : int
        3, or 4 with the offset column.

    Returns
    -------
    S_history : ndarray, shape (N, 3, 3)
    b : ndarray, shape (3,), or None
        :func:`offset_from_c` of the last sample; None without the offset.
    """
    aug = history.reshape(-1, 3, n_cols)
    S_hist = aug[:, :, :3]
    return S_hist, (offset_from_c(S_hist[-1], aug[-1, :, 3]) if n_cols == 4 else None)


def offset_from_c(S, c):
    """The sensor's offset ``b = -S^-1 c`` from ``w = S w_hat + c = S (w_hat - b)``; shape (3,).

    NaN where ``S`` is singular (the offset is then undefined).
    """
    try:
        return -np.linalg.solve(S, c)
    except np.linalg.LinAlgError:
        return np.full(3, np.nan)


def offset_std(S, b, cov_aug):
    """One-sigma uncertainty of ``b = -S^-1 c``, linearised.

    ``db = -S^-1 (dc + dS b)``: the column of entry ``(i, j)`` of ``[S | c]``
    is ``-S^-1 e_i`` times ``b_j`` (``j < 3``) or 1 (the offset column).

    Parameters
    ----------
    S : ndarray, shape (3, 3)
    b : ndarray, shape (3,)
    cov_aug : ndarray, shape (12, 12)
        Covariance of ``[S | c]`` in row order.

    Returns
    -------
    ndarray, shape (3,)
        NaN where ``S`` is singular (as :func:`offset_from_c`).
    """
    try:
        S_inv = np.linalg.inv(S)
    except np.linalg.LinAlgError:
        return np.full(3, np.nan)
    J = np.zeros((3, 12))
    for i in range(3):
        for j in range(4):
            J[:, 4 * i + j] = -S_inv[:, i] * (b[j] if j < 3 else 1.0)
    return np.sqrt(np.maximum(np.diag(J @ cov_aug @ J.T), 0))


def check_sample(dt, pose, w_hat, first):
    """Validate one live sample for :meth:`Observer.step`; return ``(pose, w_hat)`` as arrays.

    Raises
    ------
    ValueError
        ``w_hat`` not 3 finite numbers, ``pose`` neither None nor 3 finite
        numbers, no pose on the first sample, or ``dt`` not positive after it.
    """
    w_hat = np.asarray(w_hat, dtype=float)
    if w_hat.shape != (3,) or not np.all(np.isfinite(w_hat)):
        raise FmscalError(f"w_hat must be 3 finite numbers; got {w_hat!r}")
    if pose is not None:
        pose = np.asarray(pose, dtype=float)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise FmscalError(f"pose must be 3 finite numbers or None; got {pose!r}")
    if first:
        if pose is None:
            raise FmscalError("the first sample after reset() needs a pose measurement")
    elif not (np.isfinite(dt) and dt > 0):
        raise FmscalError(f"dt must be positive; got {dt!r}")
    return pose, w_hat


def _pack_input(pose, w_hat):
    if pose is None:
        return np.concatenate([[0.0], np.zeros(3), w_hat])
    return np.concatenate([[1.0], pose, w_hat])


def _healthy(z, S_slice):
    return bool(np.all(np.isfinite(z)) and np.max(np.abs(z[S_slice])) < DIVERGENCE_BOUND)


def _finite_prefix(Z, S_slice):
    """Number of leading rows that are finite and within the divergence bound."""
    with np.errstate(invalid="ignore"):
        bad = ~np.all(np.isfinite(Z), axis=1) | (np.max(np.abs(Z[:, S_slice]), axis=1) >= DIVERGENCE_BOUND)
    return int(np.argmax(bad)) if bad.any() else len(Z)
