"""The one contract every method of the toolkit follows: :class:`Observer`.

Every method (the observers, the EKF, the offline references) is an
:class:`Observer`: built as ``Method(model, ..., offset=False)`` on the
problem's :class:`fmscal.plant.Model` (a payload stands for its case's model),
run on a whole log with ``run(log, S0=None) -> ObserverResult``. Every size
(the wrench, the motion state, the calibration entries) comes from the model.
An observer holds its settings; what one run holds (the start, the divergence
bound, the previous sample, the noise model used, the build time) lives in a
:class:`RunData` that :meth:`Observer.reset` and :meth:`Observer.run` create,
as pinocchio's ``model.createData()``. The base class does
what they share, once: input validation, timing, the offset ``b`` from
``[S | c]``, the uncertainties from a covariance, the ``converged`` and
``diverged`` flags (``converged`` from the run alone: :class:`Observer`, Notes). A method writes only what is its own:

* an online method implements :meth:`Observer._start` (the first sample),
  :meth:`Observer._advance` (one step) and :meth:`Observer._current` (its
  estimate now); :meth:`Observer.reset` / :meth:`Observer.step` then work
  sample by sample for a live sensor, and :meth:`Observer.run` loops the same
  three over a log. :class:`RecursiveObserver` goes further: its step is one
  function of numbers or casadi symbols, compiled and run in chunks;
* an offline method (``online = False``) implements
  :meth:`Observer._estimate` over the whole log, and has no ``step``.
"""

import math
import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from fmscal.plant import Log
from fmscal.plant.numerics import ChunkedSteps, FmscalError, as_bool, build_once, compiler
from fmscal.plant.physics import as_model, check_calibration

from ._glitches import Glitches, bridge_glitches
from ._convergence import DIVERGENCE_GRACE, divergence_bound, informed, moved, settled
from ._progress import EVERY, progress_bar
from ._result import ObserverResult, calibration_uncertainty, initial_calibration, split_calibration
from ._samples import check_sample, pack_input

__all__ = ["Observer", "RecursiveObserver", "Estimate", "RunData", "log_inputs", "MAX_S0", "ENGINES"]

#: Largest magnitude of an entry of an initial estimate ``S0``: the readings' scale (log values up to
#: 1e9, :data:`plant.io._log.MAX_MAGNITUDE`) times it stays far from overflow in every observer.
MAX_S0 = 1e9

_CHUNK = 1000          # steps per compiled call
_CHUNKED = {}          # a step function (serialized) -> its ChunkedSteps, this process: one build per setting
_CHUNKED_MAX = 64


@dataclass
class Estimate:
    """What a method's whole-log pass produces, before the base turns it into a result.

    Attributes
    ----------
    calibration : ndarray, shape (N, n_w n)
        ``[S_hat | c_hat]`` after each sample, row order (``n`` = ``n_w``, or
        ``n_w + 1`` with the offset). Shorter than the log where the run diverged.
    x : ndarray, shape (N, nx)
        The motion estimate in the model's state layout.
    cov : ndarray, shape (n_w n, n_w n), or None
        Covariance of the final ``[S_hat | c_hat]`` (row order), where the
        method has one: gives ``S_std`` and ``b_std``.
    diverged : bool
    checks_passed : bool
        The method's own diagnostics of the log (excitation, consistency)
        found nothing wrong.
    info : dict
    warnings : list of str

    Examples
    --------
    >>> from fmscal.plant import PAPER_PAYLOAD, get_scenario
    >>> log, truth, _ = get_scenario("paper").with_(duration=2.0).generate(0)
    >>> from fmscal.observers import Estimate, LeastSquares
    >>> observer = LeastSquares(PAPER_PAYLOAD)
    >>> estimate = observer._estimate(log, None)     # what a subclass's whole-log pass returns to the base
    >>> isinstance(estimate, Estimate), estimate.calibration.shape == (len(log), 9)
    (True, True)
    """

    calibration: np.ndarray
    x: np.ndarray
    cov: np.ndarray = None
    diverged: bool = False
    checks_passed: bool = True
    info: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)


@dataclass
class RunData:
    """What one run of an :class:`Observer` holds, apart from its settings.

    Created by :meth:`Observer.reset` (a live sensor) and :meth:`Observer.run`
    (a log); an observer's settings never change while it runs.

    Attributes
    ----------
    S0 : ndarray, shape (n_w, n_w)
        The start.
    bound : float
        The divergence bound on ``max |s_ij|`` (:func:`observers.core.divergence_bound`).
    grace : int
        Steps judged on finiteness only (:data:`observers.core._convergence.DIVERGENCE_GRACE`).
    u_prev : ndarray or None
        The previous sample's input (:attr:`fmscal.plant.Model.input_layout`); None before the first.
    compiled : bool
        The compiled path (True) or the readable one.
    noise : plant.NoiseSpec or None
        The noise model this run uses, where the method has one.
    state : object
        The method's own running state: the packed vector of a
        :class:`RecursiveObserver`, the filter of the EKF; None before the
        first sample.
    build_time : float
        Seconds spent building a compiled step (not the run's cost).
    """

    S0: np.ndarray
    bound: float
    grace: int = 0
    u_prev: np.ndarray = None
    compiled: bool = True
    noise: object = None
    state: object = None
    build_time: float = 0.0


def log_inputs(log):
    """Every sample's step input ``[has_pose, pose, w_hat]``, shape (N, 1 + n_pose + n_w).

    Pose entries are zero where the log has no pose (:attr:`fmscal.plant.Model.input_layout`;
    planar: ``[has_pose, theta, X, Y, M, f_x, f_y]``).
    """
    return np.column_stack([log.has_pose, np.nan_to_num(log.pose), log.w_hat])


#: The engines, ``{(method class, model declaration, value): engine class}``: on a model whose
#: ``declaration`` attribute equals ``value``, the method runs as the engine class (a subclass of it).
#: Empty here; :mod:`fmscal.observers._registry`, the one table where the toolkit tells its cases
#: apart, fills it when :mod:`fmscal.observers` is imported.
ENGINES = {}


class Observer:
    """Base class of every method: estimates ``S`` (and the motion) from poses and raw readings.

    Parameters
    ----------
    model : plant.Model, plant.Payload or plant.SpatialPayload
        The problem: its sizes, layouts and dynamics, with the payload's
        known mass properties. A payload stands for its case's model
        (:func:`fmscal.plant.as_model`).
    offset : bool
        Also estimate the sensor's offset ``b`` in ``w = S (w_hat - b)``:
        the method runs on ``w = S w_hat + c`` (the reading augmented by a
        constant 1, ``[S | c]`` in place of ``S``) and reports
        ``b = -S^-1 c`` in ``result.b``. Off by default, as in the paper.

    Attributes
    ----------
    name : str
        The method's name in the registry (:data:`observers.METHODS`).
    online : bool
        True: works sample by sample (:meth:`reset`, :meth:`step`); False:
        fits a whole log (:meth:`run` only).
    paper_equations_only : bool
        The method reads the paper's equations directly: it needs a model
        with :attr:`fmscal.plant.Model.paper_equations` (the planar one).
        The paper's observer and the high-gain observer of [4] are planar
        by definition.
    linear_channels_only : bool
        The method needs a model linear in its channels
        (:attr:`fmscal.plant.Model.linear_channels`: the planar one).
        :meth:`runs_on` reads both.
    model : plant.Model
    payload
        The model's payload.
    n_w : int
        Components of the wrench (3 planar, 6 spatial).
    n_cols : int
        Columns of the estimated ``[S | c]``: ``n_w``, or ``n_w + 1`` with the offset.
    run_data : RunData
        What the current run holds.

    Notes
    -----
    Step-by-step use of an online method for a live sensor::

        obs.reset(S0)                # S0=None: identity, a sensor's nominal calibration
        for dt, pose, w_hat in stream:
            x_hat, S_hat = obs.step(dt, pose, w_hat)   # pose=None: no measurement

    The first :meth:`step` after :meth:`reset` only takes the first sample
    (it needs a pose) and ignores ``dt``. After :meth:`run`, :meth:`step`
    continues from the end of the log.

    A method's class is built on every model, and the class that runs it is
    the engine the registry lists for what the model declares
    (:func:`fmscal.observers._registry.engine_class`: ``AdaptiveObserver(model)``
    is a ``SpatialAdaptiveObserver`` on a model with a quaternion attitude); no method
    tests the model's name or class.

    Convergence: :meth:`run` judges ``converged`` from the run alone, at the cost of the
    run: not diverged, the method's own checks of the log passed, ``S_hat``
    settled over the last :data:`observers.core.SETTLE_FRACTION` of the run
    (:func:`observers.settled`) after leaving ``S0`` (an online method,
    :func:`observers.core.moved`), and, where the method reports an
    uncertainty ``S_std``, that uncertainty finite, non-zero and at most
    :data:`observers.core.EVIDENCE_TOLERANCE` of ``S_hat``
    (``||S_std||_2 <= tol ||S_hat||_2``, :func:`observers.core.informed`).

    A method without an uncertainty of its own (the adaptive and high-gain
    observers) can show only that it settled: an estimate also stands still
    where the log never excited it. Whether the log pinned ``S`` down is a
    question about the log, which :meth:`run` does not ask (answering it fits
    least squares to the log: work a bare run was not asked for); the
    workflow that decides convergence asks it,
    ``result.converged and observers.diagnostics.has_evidence(result, log, model, offset)``
    (the workflows in :mod:`fmscal.analysis` do: calibrate, compare, sweep, reproduce).

    Examples
    --------
    >>> from fmscal.plant import PAPER_PAYLOAD, get_scenario
    >>> log, truth, _ = get_scenario("paper").with_(duration=2.0).generate(0)
    >>> from fmscal.observers import AdaptiveObserver
    >>> observer = AdaptiveObserver(PAPER_PAYLOAD)         # every method is an Observer
    >>> result = observer.run(log)                          # the whole log at once
    >>> result.S_hat.shape, result.diverged
    ((3, 3), False)
    >>> observer.reset()                                    # or online, one sample at a time
    >>> x_hat, S_hat = observer.step(log.t[1] - log.t[0], log.pose[1], log.w_hat[1])
    >>> x_hat.shape, S_hat.shape
    ((6,), (3, 3))
    """

    name = "observer"
    online = True
    paper_equations_only = False
    linear_channels_only = False

    def __new__(cls, model=None, *args, **kwargs):
        """An instance of the class that runs this method on ``model`` (:meth:`engine`); of ``cls`` without
        a model (a copy, an unpickled instance)."""
        return super().__new__(cls if model is None else cls.engine(model))

    @classmethod
    def engine(cls, model):
        """The class that runs this method on ``model``: ``cls``, or the subclass the registry lists for what
        the model declares (:func:`fmscal.observers._registry.engine_class`).

        Parameters
        ----------
        model : plant.Model or plant.Payload

        Returns
        -------
        type
        """
        model = as_model(model, cls.__name__)
        return next((engine for (method, declaration, value), engine in ENGINES.items()
                     if method is cls and getattr(model, declaration) == value), cls)

    def __init__(self, model, offset=False):
        self.model = as_model(model, type(self).__name__)
        refusal = self.refusal(self.model)
        if refusal is not None:
            raise FmscalError(refusal)
        self.payload = self.model.payload
        self.offset = as_bool(offset, "offset")
        self.n_w = self.model.n_w
        self.n_cols = self.n_w + int(self.offset)
        self.run_data = self._new_run(None)

    @classmethod
    def refusal(cls, model):
        """Why the method does not run on ``model``, in one line; None where it does.

        The refusal of the class that runs the method on ``model``
        (:meth:`engine`), by its :meth:`_refusal`.

        Parameters
        ----------
        model : plant.Model

        Returns
        -------
        str or None
        """
        return cls.engine(model)._refusal(model)

    @classmethod
    def _refusal(cls, model):
        """This class's own limits on ``model``: a model that estimates no ``S`` (:attr:`~fmscal.plant.Model.
        estimates`), and :attr:`paper_equations_only` and :attr:`linear_channels_only`; a class with other limits
        extends it. One line, or None."""
        if "S" not in model.estimates:
            return (f"{cls.__name__} estimates S; the {model.name} model takes S as known (its parameters: "
                    "fmscal.observers.payload.identify_payload)")
        if cls.paper_equations_only and not model.paper_equations:
            return f"{cls.__name__} is defined for planar models; got a {model.name} model"
        if cls.linear_channels_only and not model.linear_channels:
            return (f"{cls.__name__} needs a model linear in its channels (planar); it does not run on a "
                    f"{model.name} model yet")
        return None

    @classmethod
    def runs_on(cls, model):
        """Whether the method runs on ``model`` (:meth:`refusal` is None).

        Parameters
        ----------
        model : plant.Model or plant.Payload
            A payload stands for its case's model.

        Returns
        -------
        bool
        """
        return cls.refusal(as_model(model, cls.__name__)) is None

    def _new_run(self, S0, compiled=True):
        """A fresh :class:`RunData` from ``S0`` (default the identity)."""
        S0 = np.eye(self.n_w) if S0 is None else S0
        return RunData(S0=S0, bound=divergence_bound(S0), compiled=bool(compiled))

    # --- the whole log --------------------------------------------------------
    def run(self, log, S0=None, compiled=True, glitches=None):
        """Run over a whole log.

        Parameters
        ----------
        log : plant.Log
            A log of the model's case.
        S0 : array_like, shape (n_w, n_w), optional
            Initial estimate of ``S`` for an online method (default the
            identity). An offline method needs none and refuses one.
        compiled : bool
            True (default): the method's step compiled by casadi and run in
            chunks, where it has one (the recursive observers, the EKF, the
            floor); False: its readable path, step by step (numpy; the EKF's
            on filterpy). Results agree to rounding. Least squares has one path.
        glitches : Glitches, optional
            The reading's glitches already found and bridged in ``log`` by
            the caller (:func:`fmscal.observers.core.bridge_glitches`): the
            search is not repeated, and these are the ones reported in
            ``info["glitches"]``.

        Returns
        -------
        ObserverResult
            An offline method's (``online = False``) fits the log with the
            reading's glitches bridged (:mod:`fmscal.observers.core._glitches`:
            single samples far from their neighbours, eqs. (G1), (G2); and
            runs of the reading held at its last value, eqs. (F1)-(F3) of
            :mod:`fmscal.observers.core._frozen`), and ``info["glitches"]``
            lists them (``count``, ``indices``, ``times``, and ``frozen`` where
            there are any; a log with none is fitted as it is).

        Raises
        ------
        TypeError
            ``log`` is not a :class:`plant.Log`.
        FmscalError
            A log of another case than the model's, or ``S0`` for an offline method.
        """
        if not isinstance(log, Log):
            raise TypeError(f"log must be a plant.Log; got {type(log).__name__}")
        self.model.check_log(log, self.name)
        if S0 is not None and not self.online:
            raise FmscalError(f"{self.name} fits the whole log and takes no starting estimate; got S0, "
                              "pass S0=None")
        start = time.perf_counter()
        if self.online:
            self.reset(S0)                             # checks S0; a new run
            run = self.run_data
            run.bound = divergence_bound(run.S0, log, self.model)           # relative to the data's scale
            run.grace = int(round(DIVERGENCE_GRACE / log.dt))               # steps judged on finiteness only
            run.compiled = bool(compiled)
        else:
            self.run_data = run = self._new_run(None, compiled=compiled)
        if glitches is not None and not isinstance(glitches, Glitches):
            raise TypeError(f"glitches must be a Glitches (observers.core.bridge_glitches); got "
                            f"{type(glitches).__name__}")
        if glitches is None and not self.online:     # a batch fit: the reading's glitches bridged first (_glitches)
            log, glitches = bridge_glitches(log, self.model.wrench_names)
        estimate = self._estimate(log, run.S0)
        result = self._result(log, estimate)
        if glitches is not None:
            result.info["glitches"] = glitches.to_dict()
        result.wall_time = time.perf_counter() - start - run.build_time
        if run.build_time:
            result.info["build_time"] = run.build_time
        return result

    def _estimate(self, log, S0):
        """The pass over the whole log. Online default: :meth:`_start`, then :meth:`_advance` per sample."""
        U = log_inputs(log)
        n, d = len(U), self.n_w * self.n_cols
        calibration, x = np.empty((n, d)), np.empty((n, self.model.nx))
        diverged = False
        # a step that overflows is a diverging run, which _healthy stops at and the result reports (diverged, not
        # converged): numpy's overflow warnings would only repeat it, and the compiled path gives none
        with progress_bar(n, self.name) as bar, np.errstate(over="ignore", invalid="ignore"):
            for k in range(n):
                if k == 0:
                    self._start(U[0])
                else:
                    self._advance(U[k - 1], U[k], log.dt)
                x[k], calibration[k] = self._current()
                if not self._healthy(x[k], calibration[k], k):
                    diverged = True
                    break
                if k % EVERY == EVERY - 1:
                    bar.update(EVERY)
        if diverged:                        # keep the last healthy estimate; row k is the bad one
            k = max(k, 1)
            calibration, x = calibration[:k], x[:k]
        self.run_data.u_prev = U[len(calibration) - 1]
        return Estimate(calibration, x, cov=self._covariance(), diverged=diverged)

    # --- sample by sample -------------------------------------------------------
    def reset(self, S0=None):
        """Forget the run; the next :meth:`step` starts from ``S0`` (default identity).

        Parameters
        ----------
        S0 : array_like, shape (n_w, n_w), optional
            A non-singular initial estimate of ``S``, entries at most
            :data:`MAX_S0` in magnitude.

        Raises
        ------
        FmscalError
            ``S0`` not a finite ``n_w x n_w`` matrix of numbers, or an entry beyond :data:`MAX_S0`.
        """
        self._require_online("reset")
        S0 = np.eye(self.n_w) if S0 is None else check_calibration(S0, "S0", max_cond=np.inf, size=self.n_w)
        if np.max(np.abs(S0)) > MAX_S0:
            raise FmscalError(f"S0 entries must be at most {MAX_S0:g} in magnitude (N and N m per unit of the reading; "
                              f"beyond it the observers' products overflow); got {np.max(np.abs(S0)):.3g}")
        self.run_data = self._new_run(S0)

    def step(self, dt, pose, w_hat):
        """Take one sample.

        Parameters
        ----------
        dt : float
            Time since the previous sample, s (ignored on the first call).
        pose : array_like, shape (n_pose,), or None
            The measured pose (planar ``[theta, X, Y]``, rad and m), or None
            when the tracker gave none: the method predicts without correcting.
        w_hat : array_like, shape (n_w,)
            Raw sensor reading (planar ``[M, f_x, f_y]``).

        Returns
        -------
        x_hat : ndarray, shape (nx,)
        S_hat : ndarray, shape (n_w, n_w)
        """
        self._require_online("step")
        run = self.run_data
        pose, w_hat = check_sample(dt, pose, w_hat, first=run.u_prev is None, model=self.model)
        u = pack_input(pose, w_hat, self.model)
        if run.u_prev is None:
            self._start(u)
        else:
            self._advance(run.u_prev, u, float(dt))
        run.u_prev = u
        x, calibration = self._current()
        return np.array(x, dtype=float), np.reshape(calibration, (self.n_w, self.n_cols))[:, :self.n_w].copy()

    def _require_online(self, what):
        if not self.online:
            raise TypeError(f"{self.name} is an offline method: it fits a whole log with run(log) "
                            f"and has no {what}()")

    # --- to implement (online) ------------------------------------------------------
    def _start(self, u):
        """Take the first sample ``u`` (:attr:`fmscal.plant.Model.input_layout`, with a pose), from
        ``self.run_data.S0``."""
        raise NotImplementedError

    def _advance(self, u_prev, u, dt):
        """One step from sample ``u_prev`` to sample ``u``, ``dt`` s apart."""
        raise NotImplementedError

    def _current(self):
        """The estimate now: ``x_hat`` (nx,) and ``[S_hat | c_hat]`` (n_w n,), row order."""
        raise NotImplementedError

    def _covariance(self):
        """Covariance of the current ``[S_hat | c_hat]``, where the method has one."""
        return None

    def _healthy(self, x, calibration, k=None):
        """Finite, and (from step ``k`` = the grace on) every entry of ``S_hat`` within the divergence
        bound (:func:`observers.core.divergence_bound`, :data:`observers.core._convergence.DIVERGENCE_GRACE`)."""
        # a NaN or inf anywhere makes the sum non-finite: one reduction per array
        if not math.isfinite(float(x.sum()) + float(calibration.sum())):
            return False
        if k is not None and k < self.run_data.grace:
            return True
        n_w = self.n_w
        return float(np.abs(calibration.reshape(n_w, self.n_cols)[:, :n_w]).max()) < self.run_data.bound

    def _healthy_rows(self, values, calibration, k0, bad=None):
        """Leading rows that :meth:`_healthy` would pass, for a chunk of a compiled run.

        Parameters
        ----------
        values : ndarray, shape (M, k)
            Every number of each row, all of which must be finite.
        calibration : ndarray, shape (M, n_w n)
            ``[S_hat | c_hat]`` of each row (row order), within the divergence bound from the grace on.
        k0 : int
            The rows are steps ``k0 + 1`` on.
        bad : ndarray of bool, shape (M,), optional
            Rows a method's own test fails.

        Returns
        -------
        int
        """
        n_w, M = self.n_w, len(calibration)
        S = calibration.reshape(M, n_w, self.n_cols)[:, :, :n_w].reshape(M, n_w * n_w)
        steps = k0 + 1 + np.arange(M)
        run = self.run_data
        with np.errstate(invalid="ignore"):
            bad = (~np.all(np.isfinite(values), axis=1) | ((np.max(np.abs(S), axis=1) >= run.bound)
                                                           & (steps >= run.grace))
                   | (False if bad is None else bad))
        return int(np.argmax(bad)) if bad.any() else len(calibration)

    # --- shared ---------------------------------------------------------------------
    def _augmented(self, o, w_hat):
        """The reading the model multiplies: ``w_hat``, or ``[w_hat, 1]`` with the offset."""
        return o.vcat([w_hat, 1.0]) if self.offset else w_hat

    def _initial_S(self, S0):
        """``[S0 | 0]`` flat in row order (:func:`observers.core.initial_calibration`)."""
        return initial_calibration(S0, self.offset)

    def _result(self, log, est):
        """The :class:`ObserverResult` of an estimate: offset, uncertainties and flags, for every method."""
        S_hist, _ = split_calibration(est.calibration, self.n_cols, self.offset)
        final = np.reshape(est.calibration[-1], (self.n_w, self.n_cols))
        S_std, b, b_std = calibration_uncertainty(final, None if est.diverged else est.cov, self.offset)
        if est.diverged:
            b = None
        honest = S_std is None or bool(np.all(np.isfinite(S_std)) and np.all(S_std > 0))
        # settling and the method's own uncertainty are judged in the reading's own scale where the model has
        # one (3D: N m and N); a method without an uncertainty is judged on settling alone (class docstring)
        scale = self.model.reading_scale(log)
        judged = S_hist if scale is None else S_hist * scale[None, None, :] / scale[None, :, None]
        judged_std = S_std if (scale is None or S_std is None) else S_std * scale[None, :] / scale[:, None]
        converged = bool(not est.diverged and est.checks_passed and honest and settled(judged)
                         and (not self.online or moved(judged))
                         and (judged_std is None or informed(judged[-1], judged_std)))
        return ObserverResult(
            observer=self.name, t=log.t[:len(S_hist)].copy(), S_hat=S_hist[-1].copy(),
            S_hat_history=S_hist, x_hat_history=np.asarray(est.x), S_std=S_std,
            diverged=bool(est.diverged), converged=converged, info=est.info, b=b, b_std=b_std,
            warnings=list(est.warnings), cov=None if est.diverged or est.cov is None else np.asarray(est.cov))


class RecursiveObserver(Observer):
    """An online method whose step is one function of numbers or casadi symbols.

    A subclass names the parts of its packed state in :attr:`state` (a
    :class:`observers.core.StateLayout` with at least ``x``, the ``nx``
    motion states, and ``S``, the ``n_w n`` calibration entries) and implements
    :meth:`_initial_state` and :meth:`_transition`. The transition is
    written once with :func:`plant.numerics.ops`: :meth:`run` either loops it
    in numpy (``compiled=False``, the readable path) or compiles it with
    casadi and runs it in chunks (:class:`plant.numerics.ChunkedSteps`); both
    give the same numbers to 1e-9.

    Examples
    --------
    >>> from fmscal.plant import PAPER_PAYLOAD, get_scenario
    >>> log, truth, _ = get_scenario("paper").with_(duration=2.0).generate(0)
    >>> from fmscal.observers import AdaptiveObserver, RecursiveObserver
    >>> observer = AdaptiveObserver(PAPER_PAYLOAD)
    >>> isinstance(observer, RecursiveObserver)
    True
    >>> import numpy as np                                  # compiled and readable paths agree
    >>> fast, slow = observer.run(log), observer.run(log, compiled=False)
    >>> bool(np.allclose(fast.S_hat, slow.S_hat, atol=1e-9))
    True
    """

    def __init__(self, model, offset=False):
        super().__init__(model, offset)
        self.state = self._layout()
        self._chunks = None

    # --- to implement ----------------------------------------------------------------
    def _layout(self):
        """The :class:`observers.core.StateLayout` of the packed state."""
        raise NotImplementedError

    def _initial_state(self, S0, u):
        """Packed state at the first sample ``u`` (numpy)."""
        raise NotImplementedError

    def _transition(self, z, u_prev, u, dt):
        """One step: ``z`` at sample n, the inputs at samples n (``u_prev``) and n+1 (``u``),
        ``[has_pose, pose, w_hat]`` (:attr:`fmscal.plant.Model.input_layout`), ``dt`` in s.
        Returns ``z`` at n+1. Must work on numpy arrays and casadi SX."""
        raise NotImplementedError

    # --- Observer --------------------------------------------------------------------
    def _estimate(self, log, S0):
        if not self.run_data.compiled:
            return super()._estimate(log, S0)
        U = log_inputs(log)
        self._start(U[0])
        z0 = self.run_data.state
        with progress_bar(len(U), self.name) as bar:
            z, (XS,) = self._compiled_steps().run(z0, [U[:-1], U[1:], np.full((len(U) - 1, 1), log.dt)],
                                                  healthy=self._healthy_prefix, progress=bar.update,
                                                  outputs=True, states=False)
        XS = np.vstack([self._reported(z0)[None, :], XS])
        diverged = len(XS) < len(U)
        self.run_data.state = z
        self.run_data.u_prev = U[len(XS) - 1]
        nx = self.model.nx
        return Estimate(XS[:, nx:], XS[:, :nx], cov=self._covariance(), diverged=diverged)

    def _start(self, u):
        u = self.model.input_layout.unpack(np.asarray(u, dtype=float))
        self.run_data.state = self._initial_state(self.run_data.S0, u)

    def _advance(self, u_prev, u, dt):
        self.run_data.state = self._transition(self.run_data.state, u_prev, u, dt)

    def _current(self):
        s = self.state.unpack(self.run_data.state)
        return s.x, s.S

    def _reported(self, z):
        """``[x, S]`` of a packed state (numpy or casadi): what a compiled run keeps of each step."""
        sl = self.state.slices
        return ca.vertcat(z[sl["x"]], z[sl["S"]]) if isinstance(z, ca.SX) else np.r_[z[sl["x"]], z[sl["S"]]]

    def _healthy_prefix(self, XS, k0):
        """Leading rows of ``XS`` (``[x, S]`` of steps ``k0 + 1`` on) that :meth:`Observer._healthy` would pass."""
        return self._healthy_rows(XS, XS[:, self.model.nx:], k0)

    def _compiled_steps(self):
        """The transition compiled once per observer (:class:`plant.numerics.ChunkedSteps`)."""
        if self._chunks is None:
            start = time.perf_counter()
            z = ca.SX.sym("z", self.state.size)
            u_prev = ca.SX.sym("u_prev", self.model.input_layout.size)
            u = ca.SX.sym("u", self.model.input_layout.size)
            dt = ca.SX.sym("dt")
            ident = self.name.replace("-", "_")
            z_next = ca.cse(ca.densify(self._transition(z, u_prev, u, dt)))     # each repeated expression once
            # the next state, and what the run keeps of it (x and S): the whole state is carried, not written out
            step = ca.Function(f"{ident}_step", [z, u_prev, u, dt], [z_next, self._reported(z_next)])
            key = (compiler(), step.serialize())      # observers of the same settings share one build
            self._chunks = build_once(_CHUNKED, key, lambda: ChunkedSteps(step, _CHUNK, keep_states=False),
                                      _CHUNKED_MAX)
            self.run_data.build_time = time.perf_counter() - start       # one-off: not the run's cost
        return self._chunks
