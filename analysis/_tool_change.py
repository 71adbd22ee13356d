"""A tool change, noticed: a persistent change of the payload found in the compensated wrench, reported, and the
new payload re-identified from the next held attitudes.

A gripper that grasps a part changes the payload by ``dpi = (dm, dh, dI_O)`` (the inertial parameters of
:func:`fmscal.plant.physics.regressor`: mass, first moment ``h = m c`` and inertia about the sensor point). The
mount then drives the payload and the part, so from the change's time ``tau`` on the compensated wrench
``w_e = W_p - w_s`` ((C1) of :mod:`fmscal.analysis._compensate`, in the model's axes) holds the part's wrench::

    w_e,k = -Y_k dpi + e_k          (k >= tau),      w_e,k = e_k  (k < tau)                         (T1)

``Y_k`` the Newton-Euler regressor at the sample's motion and ``e_k`` the noise of (C3). The part's weight
follows gravity across attitudes (the mass column is ``a_g = R^T (p_ddot - g)``, the first moment's torque
``h x a_g``); a contact's wrench does not: it is fixed in the sensor's axes (a tool pressed on, a cable pulling),
or in the world's.

**Blocks.** The detector works on means over blocks of :data:`BLOCK` s (``n`` samples): for block ``j``, the
mean wrench ``r_j``, the mean design ``X_j = [-mean(Y_k), I_6]`` (the ten inertial parameters, then a constant
wrench: the offset) and the mean's noise from the samples' own (the reading's and the motion's noise of (C3),
the share independent from sample to sample, ``Cov_noise,k``; the offset's tracker, the calibration's and the
payload's covariance are left out: they are constant over a window, and the nuisance below carries them), with
the further share of the readings' long-run variance where their noise is correlated in time (a sensor's filter,
an average: ``Sigma_lr = S diag(sd^2 (tau - 1)) S^T``, eq. (D6) of :mod:`fmscal.analysis._compensate`; zero for
white noise)::

    Sigma_j = sum_k Cov_noise,k / n^2 + Sigma_lr / n,
    z_j = L_j^-1 r_j,   A_j = L_j^-1 X_j,   L_j L_j^T = Sigma_j                                     (T2)

Without ``Sigma_lr`` the blocks' scatter is about ``sqrt(tau)`` times their stated sd: for readings filtered at
30 Hz and read at 1 kHz (``tau = (1 + a) / (1 - a)``, ``a = exp(-2 pi 30 h)``, about 10.6 samples) the misfit is
beyond what (T6) allows, and no change is ever declared. The causal filter's noise on the
accelerations is correlated over its window too; over blocks of 0.1 s and more the blocks' scatter is within about
1.3x the stated sd (``benchmarks/tool_change.py --noise`` prints it), and the misfit's scale below absorbs it.

**The hypotheses.** For a candidate time ``tau`` (a block's start), the window is :data:`PRE` s before
``tau`` (less a guard of :data:`GUARD` s just before it, where a grasp is under way) and every block since; where
fewer blocks are kept before it (the first ``PRE + GUARD`` s of a stream, or of a restart), those there are, at least
:data:`MIN_PRE` s: a part grasped then is tested against blocks without it, not against blocks that already hold
its weight (a window that holds the part's weight at one attitude before ``tau`` sees, once the arm turns, a payload
step plus a constant wrench, which neither ``H_1`` nor ``H_c`` below fits)::

    z_j = A_j beta + A_j,K phi [j >= tau] + eps_j,   eps_j ~ N(0, I)                               (T3)

``beta`` a nuisance constant over the window (the payload's and the offset's errors, sixteen numbers), ``K`` the
columns that step at ``tau``: ``H_0`` none;
``H_I`` the inertia only (the inertia a tracker is learning, (L1)); ``H_1`` the payload, ``(m, h, I_O)``;
``H_c`` the inertia and a constant wrench (a contact, or an offset that jumped). Each is fitted by least squares
on the window's normal equations (summed per block, the nuisance eliminated by its Schur complement):
``RSS_H``. The nuisance's mass and first moment are the payload in use's errors, drawn from their covariance
(``Sigma_0``: the payload file's, (K2) of :mod:`fmscal.analysis._setup`, and at least :data:`PRIOR_MASS` of the
mass and :data:`PRIOR_COM` m of its centre of mass)::

    RSS_H = min sum_j |z_j - ...|^2 + beta_mh^T Sigma_0^-1 beta_mh                                 (T3')

without it, a window whose blocks before ``tau`` hold one attitude could not tell a new payload from an old one
that was always so with an offset that jumped. The inertia and the offset's errors are free. The misfit
per degree of freedom of ``H_1`` (``n_tau`` the window's blocks) and the change's time::

    kappa(tau) = RSS_1(tau) / (6 n_tau - 26),    tau_hat = argmax {Lambda(tau) : kappa(tau) <= kappa_max}   (T4)

(``Lambda`` of (T5); where no candidate's misfit is within (T6), the least misfit's) over the candidates of the
last :data:`SEARCH` s (and the last significant one, kept while it is younger than
:data:`MAX_AGE` s: a part grasped at rest is found when the arm moves). The candidates are evaluated only
while the contact test (C4) flags a block among them (more of its samples than false alarms give but with
probability :data:`FLAGGED`), or one is kept: a change too small for (C4) to flag is
not looked for (with the offset tracked, the tracker takes such a change for drift anyway), and free motion
costs the blocks' means alone.

**The decision.** A change is declared at ``tau_hat`` where all three hold (``kappa' = max(kappa, 1)``, the
noise scale taken from the misfit where it exceeds the stated one, as an F test does):

- the ratio: a step in the mass and the first moment beats none (a generalised likelihood ratio, chi-square of
  4 degrees of freedom at a fixed ``tau``)::

      Lambda = (RSS_I - RSS_1) / kappa' > h,   h = chi2_4.isf(alpha / (E n_c))                   (T5)

  ``alpha`` the false alarms per hour :data:`FALSE_ALARM_RATE` allows, ``E`` the evaluations per hour (one a
  block) and ``n_c`` the candidates each (a union bound: the tests overlap, so the rate is an upper bound on
  the noise model);
- it explains the wrench: the misfit is the noise's, up to :data:`MISFIT` (the model's own errors, the part's
  transients)::

      kappa(tau_hat) <= kappa_max                                                                 (T6)

- it is determined: the attitudes since ``tau_hat`` turned gravity enough that the payload's step explains
  the wrench better than a constant wrench's (a contact's) by the same margin::

      Lambda_c = (RSS_c - RSS_1) / kappa' > h                                                      (T7)

- while a declared change is not yet re-identified, a mass changed again: the step's mass beyond
  :data:`MASS_SIGMAS` of its standard deviation (a step in the first moment alone is then the declared
  change's estimate, made at few attitudes, a little off as the arm turns: not a new part)::

      |dm_hat| > MASS_SIGMAS sd(dm_hat)                                                           (T7')

At a held attitude a part's weight is a constant wrench, and the two cannot be told apart: (T7) waits for the
arm to turn (the change is pending meanwhile, its time kept). A contact fixed in the sensor's axes fits ``H_c``
and never passes (T7). A contact fixed in the world (the tool pressed on a surface while the arm turns) turns
with the sensor as a weight does: it is told apart where its force is not along gravity (a weight's is, so
(T6) fails), or by the accelerations (a part's wrench holds ``m p_ddot`` and ``I alpha``, a contact's does not);
a vertical push held still at one point of the tool during slow motion is, to the sensor, a weight, and is
declared as one.

**What is reported** (:class:`ToolChange`): ``tau_hat``, the time it was declared, the change ``phi_hat`` of
``H_1`` (its covariance ``kappa' (A_K^T P A_K)^-1``, ``P`` the projection off the nuisance), and the new total
from the payload in use::

    m' = m + dm,    c' = (m c + dh) / m'                                                           (T8)

(in the model's axes; a payload file's with a mounting: the tracked frame's, as its ``com``).

**Re-identification** (:meth:`fmscal.analysis.Compensator.reidentify`, or ``tool_change="reidentify"`` after
each declared change). The blocks' mean attitudes and raw readings since the change are an attitude-only log;
its held segments (:func:`fmscal.plant.io.held_table`) are fitted statically (:func:`fmscal.observers.payload.
fit_static`, with ``S``, gravity and the reading's sign of the compensation): the new total's mass, centre of
mass and offset. With at least :data:`REIDENTIFY_POSES` held attitudes and the fit's payload determined, the
compensation goes on with it, its inertia bounded by (K3) of :mod:`fmscal.analysis._setup` and learned by (L1),
the offset the tracker's (a tool change does not move the sensor's offset). The detector then starts again.
"""

from collections import deque
from dataclasses import dataclass, replace

import numpy as np
from scipy.stats import binom, chi2

from fmscal.plant.io import AttitudeLog, held_table
from fmscal.plant.numerics import FmscalError
from fmscal.plant.physics import regressor
from fmscal.observers.payload import fit_static

from ._motion import quaternion_from_matrix
from ._setup import payload_jacobian, setup

__all__ = ["ToolChange", "TOOL_CHANGE", "BLOCK", "PRE", "GUARD", "SEARCH", "MAX_AGE", "FALSE_ALARM_RATE",
           "MISFIT", "PRIOR_MASS", "PRIOR_COM", "REIDENTIFY_POSES", "REIDENTIFY_BUFFER"]

#: ``tool_change``: no detection; detect and report; detect, report and re-identify from the next held attitudes.
TOOL_CHANGE = ("off", "detect", "reidentify")
#: The blocks the detector averages, s (T2).
BLOCK = 0.1
#: The window before a candidate change, s (T3) ...
PRE = 1.0
#: ... less this guard just before it, s: a grasp under way is left out.
GUARD = 0.2
#: The candidate times: the blocks of the last this many seconds (T4) ...
SEARCH = 3.0
#: ... and the last significant one, kept this long while the change is not yet determined, s.
MAX_AGE = 60.0
#: The false alarms per hour (T5) allows on the noise model: an upper bound (a union bound over the tests).
FALSE_ALARM_RATE = 1e-3
#: The misfit per degree of freedom a declared change may leave, in the stated noise's variance (T6).
MISFIT = 4.0
#: A change's last blocks: at least this many since ``tau`` before it is tested, s.
MIN_POST = 0.2
#: The shortest window before a candidate (T3), s, where fewer than :data:`PRE` s of blocks are kept (the stream's
#: start, a restart): with :data:`MIN_POST` after it, more blocks than the hypotheses' 26 numbers (T4).
MIN_PRE = 0.3
#: The nuisance's payload errors (T3'): at least this share of the mass, and this distance of the centre of mass, m.
PRIOR_MASS = 0.01
PRIOR_COM = 0.002
#: A block counts as flagged where more of its samples are flagged (C4) than false alarms give but with this chance.
FLAGGED = 1e-6
#: (T7'): while a declared change awaits re-identification, a further change is declared only where its mass step
#: is beyond this many of its sd (a step in the first moment alone is the declared change's estimate settling).
MASS_SIGMAS = 5.0
#: Held attitudes after a change before it is re-identified automatically (``tool_change="reidentify"``).
REIDENTIFY_POSES = 6
#: The blocks kept for a re-identification, s.
REIDENTIFY_BUFFER = 120.0

_STEP = list(range(10))                          # H_1: the payload's ten inertial parameters
_INERTIA = list(range(4, 10))                    # H_I: its inertia
_CONTACT = list(range(4, 16))                    # H_c: the inertia and a constant wrench
_RIDGE = 1e-10


class ToolChangeError(FmscalError):
    """A tool change that cannot be detected or re-identified here: the message names the reason."""


@dataclass
class ToolChange:
    """One declared change of the payload (module docstring).

    Attributes
    ----------
    t : float
        The change's time ``tau_hat`` (T4), s: the start of the block where the new payload's wrench begins.
    declared : float
        The time of the newest sample when it was declared, s.
    mass_change, mass_change_sd : float
        ``dm`` and its sd, kg (T8): positive for a part grasped.
    moment_change : ndarray, shape (3,)
        ``dh``, kg m (model axes).
    mass, com, com_sd : float, ndarray (3,), ndarray (3,)
        The new total's mass (kg) and centre of mass (m, model axes) from the payload in use and the change (T8).
    part_com : ndarray, shape (3,)
        ``dh / dm``, m: where the part's mass sits (a grasp's part).
    statistic, threshold : float
        ``Lambda`` of (T5) and ``h``.
    misfit : float
        ``kappa(tau_hat)`` of (T6).
    versus_contact : float
        ``Lambda_c`` of (T7).
    span_deg : float
        The largest angle gravity's direction (``a_g``) turned in the sensor's axes since ``tau_hat``, degrees.
    reidentified : observers.payload.StaticFit or None
        The held attitudes' fit of the new total (module docstring), where one was made.
    poses : int
        The held attitudes it was fitted to.
    reidentified_at : float or None
        s: when the compensation went on with it (None: reported only, or not re-identified).
    """

    t: float
    declared: float
    mass_change: float
    mass_change_sd: float
    moment_change: np.ndarray
    mass: float
    com: np.ndarray
    com_sd: np.ndarray
    part_com: np.ndarray
    statistic: float
    threshold: float
    misfit: float
    versus_contact: float
    span_deg: float
    reidentified: object = None
    poses: int = 0
    reidentified_at: float = None

    def describe(self):
        """One line naming the time, the change and the new total (and its re-identification)."""
        line = (f"tool change at {self.t:.3f} s (declared at {self.declared:.3f} s): mass {self.mass_change:+.4g} "
                f"+- {self.mass_change_sd:.2g} kg, now {self.mass:.4g} kg with its centre of mass at "
                + " ".join(f"{v:.4g}" for v in self.com) + " m (+- " + " ".join(f"{v:.2g}" for v in self.com_sd)
                + f"); gravity turned {self.span_deg:.0f} deg since")
        fit = self.reidentified
        if fit is not None:
            line += (f"; re-identified from {self.poses} held attitudes: mass {fit.mass:.4g} +- {fit.mass_std:.2g} "
                     "kg, centre of mass " + " ".join(f"{v:.4g}" for v in fit.com) + " m"
                     + ("" if self.reidentified_at is None else f", in use from {self.reidentified_at:.3f} s"))
        return line


def threshold(evaluations_per_hour, candidates, rate=FALSE_ALARM_RATE):
    """``h`` of (T5): the chi-square quantile (4 degrees of freedom) at ``rate / (E n_c)``."""
    return float(chi2.isf(rate / (evaluations_per_hour * candidates), 4))


def check_mode(tool_change, model):
    """The mode ``tool_change`` asks for on ``model``: None is "detect" where the model has the spatial regressor
    (a 6-axis reading in 3D), "off" elsewhere; an explicit mode on another model is refused."""
    regressor = model.attitude == "quaternion"        # the model declares attitudes in 3D: the regressor (T1)
    if tool_change is None:
        return TOOL_CHANGE[1] if regressor else TOOL_CHANGE[0]
    if not (isinstance(tool_change, str) and tool_change in TOOL_CHANGE):
        raise ToolChangeError(f"tool_change must be one of {', '.join(TOOL_CHANGE)} (or None); got {tool_change!r}")
    if tool_change != TOOL_CHANGE[0] and not regressor:
        raise ToolChangeError(f"a tool change is detected on a 6-axis reading in 3D (the Newton-Euler regressor); "
                              f"this is a {model.name} reading: leave tool_change None or 'off'")
    return tool_change


def _quaternions(R):
    """Rows' attitude quaternions (N, 4) from a source's own attitudes ``R`` (N, 3, 3; an IMU's, NaN where none)."""
    q = np.full((len(R), 4), np.nan)
    good = np.isfinite(R).all(axis=(1, 2))
    if good.any():
        q[good] = quaternion_from_matrix(R[good])
    return q


class _Detector:
    """(T1)-(T8) over a stream of compensated rows, a block at a time; the held attitudes kept for (T9).

    ``model`` the compensation's (its gravity and payload), ``dt`` the rows' sample time, ``mode`` one of
    :data:`TOOL_CHANGE` (not "off"), ``cov`` a payload file's covariance of ``(m, c, I_c, b)`` (K2) or None,
    ``false_alarm`` the contact test's (C4)."""

    def __init__(self, model, dt, mode, cov=None, false_alarm=1e-3):
        self.mode = mode
        self._prior(model, cov)
        self.n = max(1, int(round(BLOCK / dt)))
        self.block_s = self.n * dt
        self.P, self.G = int(round(PRE / self.block_s)), int(round(GUARD / self.block_s))
        self.S, self.min_post = int(round(SEARCH / self.block_s)), max(1, int(round(MIN_POST / self.block_s)))
        self.min_pre = min(self.P, max(1, int(round(MIN_PRE / self.block_s))))
        self.max_age = int(round(MAX_AGE / self.block_s))
        self.h = threshold(3600.0 / self.block_s, self.S + 1)
        self.events = []
        self._rows = []                                    # the open block's rows
        self._held = deque(maxlen=int(round(REIDENTIFY_BUFFER / self.block_s)))   # (t, q, w_hat) per block
        self._held_count = self._held_tried = 0
        #: The newest evaluation: (time, tau_hat's time, Lambda, kappa, Lambda_c or None where (T5) failed).
        self.latest = None
        self._count = 0                                    # rows in the open block
        self._long_run = None                              # the readings' long-run share, (D6) of _compensate
        self._flags, self._last_flag = 0, None             # samples flagged (C4) in it; the last block flagged
        self._flag_bound = binom.isf(FLAGGED, self.n, false_alarm)
        self.reset()

    def reset(self):
        """Start again (a declared change, a new payload): the window emptied."""
        self._blocks = deque(maxlen=self.max_age + self.P + self.G + 1)          # (t, G, g, s, a_g) per block
        self._first = 0                                    # the absolute index of the deque's first block
        self._pinned = None
        self._last_flag = None                             # (an index of the window emptied: none of the new)

    # --- rows in --------------------------------------------------------------------------------------------
    def add(self, t, w_hat, motion, rows):
        """Rows of one :func:`~fmscal.analysis._compensate._step`: their times, raw readings, motion and
        :class:`~fmscal.analysis._compensate._Rows`. Returns the count of changes declared after each row."""
        m = len(t)
        counts = np.empty(m, dtype=int)
        R = motion.R
        i = 0
        while i < m:
            j = min(m, i + self.n - self._count)
            self._rows.append((t[i:j], rows.w_e[i:j], rows.noise[i:j], motion.x[i:j], motion.a[i:j],
                               None if R is None else R[i:j], w_hat[i:j]))
            self._long_run = rows.long_run
            self._flags += int(np.count_nonzero(rows.contact[i:j]))
            self._count += j - i
            if self._count >= self.n:
                self._close()
            counts[i:j] = len(self.events)
            i = j
        return counts

    def _close(self):
        """The open block's means (T2), kept; then an evaluation."""
        parts = list(zip(*self._rows))
        t, r, noise, x, a, w_hat = (np.concatenate(parts[k]) for k in (0, 1, 2, 3, 4, 6))
        R = None if parts[5][0] is None else np.concatenate(parts[5])
        self._rows, self._count = [], 0
        if self._flags > self._flag_bound:                                     # more than false alarms give
            self._last_flag = self._first + len(self._blocks)           # this block's absolute index
        self._flags = 0
        n = len(t)
        model = self.model
        qx = x[:, 3:7] / np.linalg.norm(x[:, 3:7], axis=1, keepdims=True)
        Y = regressor(qx, x[:, 10:13], a[:, 3:], a[:, :3], model.gravity)                    # (T1)
        X = np.concatenate([-Y.mean(axis=0), np.eye(6)], axis=1)
        Sigma = noise.mean(axis=0) if self._long_run is None else noise.mean(axis=0) + self._long_run
        L = np.linalg.cholesky(Sigma / n)                                                     # (T2)
        A = np.linalg.solve(L, np.concatenate([X, r.mean(axis=0)[:, None]], axis=1))
        A, z = A[:, :16], A[:, 16]
        if len(self._blocks) == self._blocks.maxlen:
            self._first += 1                               # the oldest block drops out
        self._blocks.append((float(t.mean()), A.T @ A, A.T @ z, float(z @ z), Y[:, 3:, 0].mean(axis=0)))
        q = qx if R is None else _quaternions(R)
        good = np.isfinite(q).all(axis=1)
        if good.sum() > n // 2:
            qq = q[good] * np.sign(q[good] @ q[good][0])[:, None]
            mean = qq.mean(axis=0)
            self._held.append((float(t.mean()), mean / np.linalg.norm(mean), w_hat[good].mean(axis=0)))
            self._held_count += 1
        self._evaluate()

    # --- (T3)-(T8) ----------------------------------------------------------------------------------------------
    def _evaluate(self):
        blocks, first = self._blocks, self._first
        end = first + len(blocks)                          # absolute index one past the newest block
        # the earliest candidate: its whole pre-window kept; before PRE s of blocks since the reset, the shorter
        # pre-window of the blocks there are, MIN_PRE s at least (T3)
        lowest = first + self.P + self.G if first else self.min_pre + self.G
        if self._pinned is not None and self._pinned < lowest:
            self._pinned = None                            # older than the blocks kept (MAX_AGE): given up
        if self._pinned is None and (self._last_flag is None or self._last_flag < end - self.S - 1):
            return                                         # no sample flagged (C4) in the candidates' span
        taus = list(range(max(lowest, end - self.S), end - self.min_post + 1))
        if self._pinned is not None and lowest <= self._pinned < (taus[0] if taus else end):
            taus.insert(0, self._pinned)
        if not taus:
            return
        taus = np.array(taus)
        starts = np.maximum(taus - self.P - self.G, 0)     # each candidate's pre-window, from the reset's block on
        lo = int(starts.min())
        kept = list(blocks)[lo - first:]
        G = np.array([b[1] for b in kept])
        g = np.array([b[2] for b in kept])
        cG = np.concatenate([np.zeros((1, 16, 16)), np.cumsum(G, axis=0)])
        cg = np.concatenate([np.zeros((1, 16)), np.cumsum(g, axis=0)])
        cs = np.r_[0.0, np.cumsum([b[3] for b in kept])]
        k, e = taus - lo, end - lo                          # relative indices
        w0, w1 = starts - lo, k - self.G
        Np, bp, sp = cG[e] - cG[k], cg[e] - cg[k], cs[e] - cs[k]
        Nw = Np + cG[w1] - cG[w0] + self._information                                         # (T3')
        bw, sw = bp + cg[w1] - cg[w0] + self._prior_b, sp + cs[w1] - cs[w0] + self._prior_s
        d = np.sqrt(np.maximum(np.einsum("nii->ni", Nw), 1e-300))                               # Jacobi scaling
        dd = d[:, :, None] * d[:, None, :]
        Np_s, bw_s, bp_s = Np / dd, bw / d, bp / d
        solved = np.linalg.solve(Nw / dd + _RIDGE * np.eye(16), np.concatenate([Np_s, bw_s[:, :, None]], axis=2))
        rss0 = sw - np.einsum("ni,ni->n", bw_s, solved[:, :, 16])
        schur = Np_s - np.einsum("nji,njk->nik", Np_s, solved[:, :, :16])                   # the step's, beta out
        reduced = bp_s - np.einsum("nji,nj->ni", Np_s, solved[:, :, 16])

        def fit(K, rows):
            """RSS of the step in the columns ``K`` at the candidates ``rows``; its estimate and information."""
            M = schur[rows][:, K][:, :, K] + _RIDGE * np.eye(len(K))
            phi = np.linalg.solve(M, reduced[rows][:, K][:, :, None])[:, :, 0]
            return rss0[rows] - np.einsum("ni,ni->n", reduced[rows][:, K], phi), phi, M
        every = np.arange(len(taus))
        rss1, phi, M1 = fit(_STEP, every)
        kappa = rss1 / (6 * (e - k + w1 - w0) - 26)
        scales = np.maximum(kappa, 1.0)
        ratios = (fit(_INERTIA, every)[0] - rss1) / scales                                     # (T5)
        explained = kappa <= MISFIT
        i = int(np.argmax(np.where(explained, ratios, -np.inf)) if explained.any() else np.argmin(kappa))   # (T4)
        at = np.array([i])
        scale, ratio = float(scales[i]), float(ratios[i])
        tau = int(taus[i])
        self.latest = (blocks[-1][0], blocks[tau - first][0], ratio, float(kappa[i]), None)
        if ratio <= self.h:
            return
        versus = float(fit(_CONTACT, at)[0][0] - rss1[i]) / scale                              # (T7)
        self.latest = self.latest[:4] + (versus,)
        if not (kappa[i] <= MISFIT and versus > self.h):                                       # (T6), (T7)
            self._pinned = tau                         # significant, not yet determined: kept as a candidate
            return
        K = list(_STEP)
        step, cov = phi[i] / d[i, K], np.linalg.inv(M1[i]) * scale / np.outer(d[i, K], d[i, K])
        pending = bool(self.events) and self.events[-1].reidentified_at is None
        if pending and abs(step[0]) <= MASS_SIGMAS * np.sqrt(max(cov[0, 0], 0.0)):               # (T7')
            return                             # the last change's estimate settling as the arm turns: no new part
        self._declare(tau, step, cov, ratio, float(kappa[i]), versus)

    def _declare(self, tau, phi, cov, ratio, kappa, versus):
        """A :class:`ToolChange` (T8) at the absolute block ``tau``; the window restarted."""
        blocks = list(self._blocks)
        start = blocks[tau - self._first]
        post = np.array([b[4] for b in blocks[tau - self._first:]])
        u = post / np.linalg.norm(post, axis=1, keepdims=True)
        span = float(np.degrees(np.arccos(np.clip(u @ u[0], -1.0, 1.0)).max()))
        payload = self.model.payload                   # and the changes declared since it was identified
        m, h = payload.mass + self._mean[0], payload.mass * np.asarray(payload.com, dtype=float) + self._mean[1:4]
        mass = m + phi[0]
        com = (h + phi[1:4]) / mass
        J = np.concatenate([-com[:, None], np.eye(3)], axis=1) / mass                          # d c' / d (dm, dh)
        com_sd = np.sqrt(np.maximum(np.diag(J @ cov[:4, :4] @ J.T), 0.0))
        self.events.append(ToolChange(
            t=start[0] - 0.5 * self.block_s, declared=blocks[-1][0] + 0.5 * self.block_s, mass_change=float(phi[0]),
            mass_change_sd=float(np.sqrt(max(cov[0, 0], 0.0))), moment_change=phi[1:4].copy(), mass=float(mass),
            com=com, com_sd=com_sd, part_com=phi[1:4] / phi[0] if phi[0] else np.full(3, np.nan),
            statistic=ratio, threshold=self.h, misfit=kappa, versus_contact=versus, span_deg=span))
        # until re-identified, the payload is the model's and the changes: the prior of (T3') moves to it
        self._prior(self.model, self._cov, self._mean + phi[:4], self._more + cov[:4, :4])
        self.reset()

    # --- (T9) ---------------------------------------------------------------------------------------------------
    def reidentify(self, calibration, since=None, poses=None, until=np.inf):
        """The static fit of the held attitudes from ``since`` to ``until`` (default since the last change's time,
        else the oldest kept), with ``calibration``'s ``S`` and sign: ``(fit, table)``. Raises
        :class:`ToolChangeError` where fewer than ``poses`` (or :data:`fmscal.plant.io.MIN_POSES`) are held or the
        fit does not determine the payload."""
        if since is None:
            since = self.events[-1].t + GUARD if self.events else -np.inf
        kept = [b for b in self._held if since <= b[0] < until]
        if len(kept) < 2:
            raise ToolChangeError(f"re-identification needs held attitudes: {len(kept)} blocks of attitudes kept "
                                  f"since {since:.3f} s (hold the tool still at several attitudes, a second or "
                                  "more each)")
        t, q, w = (np.array(v) for v in zip(*kept))
        try:
            table, _, _ = held_table(AttitudeLog(t, q, w, name="the held attitudes"))
            if poses is not None and len(table.q) < poses:
                raise ToolChangeError(f"{len(table.q)} held attitudes since {since:.3f} s; re-identification "
                                      f"waits for {poses}")
            fit = fit_static(table, S=calibration.S, gravity=self.model.gravity,
                             reading=calibration.reading or "reaction")
        except ToolChangeError:
            raise
        except FmscalError as err:
            raise ToolChangeError("re-identification refused: " + str(err).splitlines()[0]) from None
        if not fit.payload_determined:
            raise ToolChangeError(f"re-identification: {len(table.q)} held attitudes do not determine the payload "
                                  f"(mass {fit.mass:.4g} +- {fit.mass_std:.2g} kg; "
                                  + (fit.warnings[0] if fit.warnings else "turn the tool further between them")
                                  + ")")
        return fit, table

    def due(self):
        """``tool_change="reidentify"``: a declared change not yet re-identified, and a new block held since the
        last try."""
        if self.mode != TOOL_CHANGE[2] or not self.events or self.events[-1].reidentified_at is not None:
            return False
        if self._held_count < self._held_tried + int(round(1.0 / self.block_s)):      # a try a second at most
            return False
        self._held_tried = self._held_count
        return True

    def use(self, model, cov=None):
        """Go on with a new payload's model and covariance (a re-identification): the window restarted."""
        self._prior(model, cov)
        self.reset()

    def _prior(self, model, cov, mean=None, more=None):
        """(T3')'s terms in the normal equations, for ``model``'s payload: ``Sigma_0^-1`` (16, 16), ``Sigma_0^-1 mu``
        and ``mu^T Sigma_0^-1 mu``; ``mean`` the payload's (m, h) from the model's (a change declared and not
        re-identified: the payload is then the model's and the change), ``more`` that change's covariance."""
        self.model, self._cov = model, cov
        m, com = model.payload.mass, np.asarray(model.payload.com, dtype=float)
        sigma = np.diag(np.r_[(PRIOR_MASS * m) ** 2, np.full(3, (PRIOR_COM * m) ** 2)])
        if cov is not None:
            J = payload_jacobian(m, com)[:4, :4]                                               # (K2)
            sigma = sigma + J @ np.asarray(cov, dtype=float)[:4, :4] @ J.T
        self._more = np.zeros((4, 4)) if more is None else more
        self._sigma = sigma + self._more
        self._mean = np.zeros(4) if mean is None else np.asarray(mean, dtype=float)
        inverse = np.linalg.inv(self._sigma)
        self._information = np.zeros((16, 16))
        self._information[:4, :4] = inverse
        self._prior_b = np.r_[inverse @ self._mean, np.zeros(12)]
        self._prior_s = float(self._mean @ inverse @ self._mean)


def new_setup(old, calibration, fit):
    """The :class:`~fmscal.analysis._setup.Setup` a re-identified payload gives (K3 for its inertia), the old
    one's axes and pose noise kept."""
    st = setup(calibration, payload=fit)
    return replace(st, axes=old.axes, pose_noise_known=old.pose_noise_known, warnings=[])
