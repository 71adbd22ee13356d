"""What a fit's residual names: a moving offset or gain, or gravity along another direction than the one given.

The reference fit of a log under gravity (the wrench each sample needed,
``w_k``, from the smoothed poses by Newton-Euler, and ``w_k = S w_hat_k + c``
fitted by least squares, as :func:`fmscal.observers.batch.fit_readings` fits
it) leaves a residual ``r_k``. ``S`` absorbs whatever is a linear function of
the reading; two causes it cannot absorb leave each a pattern of its own:

* **a moving offset**: ``w = S (w_hat - b - db(t))`` leaves ``r_k = -S db(t_k)``,
  a function of time alone;
* **gravity along another direction** (a tilted base, a pose frame whose z is not up):
  the needed wrench is affine in gravity, ``w(g') = w(g) + D_k (g' - g)``
  with ``D_k`` eq. (G1) of :func:`fmscal.plant.physics.gravity_jacobian`, so
  that the residual is ``-D_k dg``, a function of the attitude.

Both are fitted to the residual together, beside a change of the payload's
inertial parameters other than its mass (``-W_k dpi``, ``W_k`` the
Newton-Euler regressor less its mass column, which ``S`` absorbs: a payload
given wrong leaves a residual that neither must be taken for; its motion
smoothed over :data:`PAYLOAD_WINDOW`, below), row ``i`` of
the wrench::

    r_ik = -D_ik dg - W_ik dpi + w_dot_ik dtau + T(t_k)^T beta_i + e_ik              (C1)

``w_dot`` the needed wrench's rate (a latency wrong by ``dtau`` leaves
``w_dot dtau``: a log whose latency is poorly estimated, as a tilt makes it,
keeps its cause in sight), ``T(t)`` the indicators of the last ``P - 1`` of ``P`` equal parts of the
log (:data:`fmscal.observers.diagnostics.DRIFT_PARTS`, as the planar test),
``beta_i`` the level of row ``i``'s offset in each against the first. Every
column is first projected off the augmented reading ``[w_hat_k; 1]``, as the
residual is (what ``S`` and ``c`` absorb; the Frisch-Waugh-Lovell theorem),
and each row is weighted by its residual's rms. The covariance of the
coefficients is the cluster-robust sandwich over blocks of time (eq. (U3)
of :mod:`fmscal.observers.batch._cluster_covariance`), the blocks five
correlation times of the residual that (C1) leaves with the most parts
(eq. (U2); fewer parts leave more of a moving offset in it, which would
lengthen the blocks of a short log, where it moves, until it had too few to
test); a last block under half that length joins the one before (a sliver
of a few samples is no block of time). Two Wald
tests, each a Hotelling's ``T^2`` over ``G`` blocks scaled to an ``F``, eq.
(U4) of :mod:`fmscal.observers.batch._cluster_covariance` (``K`` the
directions the covariance determines)::

    X2 = x^T C^+ x,   (G - K) / (K (G - 1)) X2 ~ F(K, G - K)                         (C2)

- the offset moves: ``x = beta_i``, ``K = P - 1``, for each row, the
  smallest p-value times the rows (Bonferroni); a row is named only where
  its levels also spread as far as :data:`MOVING_SIZE` of its residual's
  rms ``s_i`` (a size that matters, beside one the test alone finds on a
  long log; a ramp of twice the reading's noise over the log spreads the
  levels of ``P`` parts over ``(P - 1) / P`` of that)::

    max(0, beta_i) - min(0, beta_i) >= MOVING_SIZE s_i                          (C4)

- gravity is tilted: ``x`` the two components of ``dg`` across ``g``, ``K = 2``.

A row found moving may be its offset's change or ``S``'s gain's (a sensor
warming up moves either): a gain changed by ``gamma_i(t)`` leaves
``r_ik = gamma_i(t_k) w_ik``, which follows the row's needed wrench, where an
offset's change does not. Both are fitted beside (C1)'s shared columns, each
a ramp between :data:`GAIN_PARTS` ``+ 1`` knots over the log (``R(t)`` the
ramps of the last :data:`GAIN_PARTS`; a level per part would leave a drift
within each part, which the gain's columns take up where the load moves with
time)::

    r_ik = -D_ik dg - W_ik dpi + w_dot_ik dtau + R(t_k)^T beta_i
           + R(t_k)^T gamma_i (w_ik - mean(w_i)) + e_ik                              (C5)

every row's gain where the log has :data:`BLOCKS_PER_COLUMN` times (C5)'s
columns in blocks of time (their length from (C5)'s own residual, eq. (U2)),
else the moving rows' alone, else none (the row is named an offset, as
found). A row's gain is named, and not its offset, where ``gamma_i``'s test
(C2) is below half of the significance (times the rows) and its offset at no
load, ``beta_i - gamma_i mean(w_i)``, tests at or above it (not times the
rows: a guard); where both are below it, the offset is named, as found (a
step of the offset, which the ramps follow badly, leaves a share in the
gain's columns too); where the two together test below it and neither alone
does, the offset's line names either. The gain
named is ``S``'s gain on that row (``gamma_i`` at the last knot against the
first) for an ``S`` near the identity; a gain's cross-talk into another row
(through ``S``'s off-diagonal entries) is not modelled, and can leave that row
a moving offset named beside it.

Each names its cause below half of :data:`CAUSE_SIGNIFICANCE`: the
probability, for a log with one constant offset and the gravity given, of
naming either, nominal (no test with ``G`` below :data:`BLOCKS_PER_COLUMN`
times the columns of (C1); a log too short for that with ``P`` parts is
fitted with fewer, down to :data:`MIN_PARTS`). The payload's columns ``W_k``
hold the angular velocity and acceleration differentiated from the poses:
over the reference fit's window their errors in variables (the attitude's
noise, differentiated twice) move ``dg`` and ``beta`` by more than the
covariance holds, a bias of each log's motion that no block length covers
(clean logs of noisy poses named tilted); over :data:`PAYLOAD_WINDOW` their
noise is far smaller, and they still span what a payload given wrong leaves.
On a log of fewer parts than ``P`` asked, a ramp that the parts follow
badly leaves a share the tilt's columns take up: a tilt named there beside
an offset named, or beside rows whose offset test is below
:data:`SUGGESTIVE`, is ambiguous, and its line names both, the log's length
that tells them apart, and no gravity to give. Where nothing is named on such
a log, rows whose test is below :data:`SUGGESTIVE` and whose levels spread
as (C4) asks are a suggestion, not a cause: the payload's columns follow the
motion's slow changes, which a short log's few parts cannot tell from an
offset's (a ramp of twice the reading's noise over 10 s, a centre of mass
given 1 cm off), and the line names both and the length that tells them
apart; so is, where no offset is named, a tilt not named whose test is
below :data:`SUGGESTIVE` and that is at least :data:`SUGGESTED_TILT_DEG` (a
log that does not determine it, where ``S`` turns to take it up; on a short
log its line names an offset that may move too, whose drift the few parts
follow badly leaves a share the tilt takes up). The tilt the
data ask for,
and its one-sigma uncertainty::

    tilt = asin(|dg_perp| / |g|),   sd = sqrt(lambda_max(C_perp)) / |g|            (C3)

``dg_perp`` the two components of ``dg`` across ``g`` and ``C_perp`` their
covariance; the gravity found is along ``g + dg`` at the size given (``dg``
along ``g`` is the payload's mass's share, which ``S`` absorbs). The offset's
change is described as the planar test describes it (a step or a ramp, the
channel of the reading, when: :func:`describe_offset`), from the residual
less the fitted gravity and payload terms over 0.5 s windows, taken back to
the reading by ``-S^-1``.
"""

from dataclasses import dataclass, field

import numpy as np

from fmscal.plant.numerics import FmscalError
from fmscal.plant.physics import edge, gravity_jacobian, regressor, spatial_motion

from fmscal.observers.batch import block_length, hotelling, small_sample_factor
from fmscal.observers.core import reading_noise
from ._faults import DRIFT_PARTS, OffsetDrift, describe_offset

__all__ = ["Causes", "GainDrift", "GravityTilt", "fit_causes", "CAUSE_SIGNIFICANCE"]

#: The probability, for a log with a constant offset under the gravity given, of naming a moving offset or a
#: tilted gravity (each test half of it), nominal.
CAUSE_SIGNIFICANCE = 1e-3
#: A direction of eq. (C1)'s columns whose information, each column scaled to a unit one, is below this share of the
#: largest is left out: what ``S`` absorbs (the payload's mass, centre of mass and uniform inertia scale, issue
#: 46), which the errors-in-variables fit leaves near zero or below it.
ABSORBED = 1e-3
#: A row's offset is named moving only where its levels also spread over this share of its residual's rms (eq.
#: (C4)): a long log's test alone finds shifts far below the noise, which move no estimate; a ramp of twice the
#: reading's noise over the log spreads the levels of ``P`` parts over ``(P - 1) / P`` of that, about one rms of a
#: residual that the poses' noise adds to.
MOVING_SIZE = 0.5
#: No test on fewer blocks of time than this many times the columns of eq. (C1) (43 in 3D): the cluster-robust
#: covariance of that many coefficients from fewer blocks is too rough for eq. (C2)'s tails (a log of 20 s or more
#: at the usual blocks of 0.2 s).
BLOCKS_PER_COLUMN = 2
#: The fewest parts of eq. (C1) (``P``): a log too short for :data:`DRIFT_PARTS` (fewer blocks of time than
#: :data:`BLOCKS_PER_COLUMN` times its columns) is fitted with fewer, down to this many (two: 19 columns, 38 blocks,
#: about 8 s at the usual blocks of 0.2 s), its offset and its gravity's direction tested. Two parts see a change
#: between the log's halves: an offset that moves and comes back by the end is not seen there.
MIN_PARTS = 2
#: Samples fitted at most: a longer log is taken at every ``stride``-th sample (the motion smoothed on all of them
#: first), which keeps the check's cost flat beyond 20 s at 1 kHz; its blocks of time, and so its test, unchanged.
MAX_ROWS = 20000
#: On a log of fewer parts than asked, a tilt named beside an offset named, or beside rows whose offset test (times
#: the rows) is below this, is ambiguous: a ramp the few parts follow badly leaves a share the tilt's columns take up.
#: Where nothing is named there, such rows (their levels spread as eq. (C4) asks) are suggested: a moving offset,
#: or a payload given wrong, which the levels of a short log trade with; so is, on any log where no offset is named,
#: a tilt not named whose test is below this and that is at least :data:`SUGGESTED_TILT_DEG`
#: (:attr:`Causes.suggestion`).
SUGGESTIVE = 0.05
#: A tilt not named is suggested only from this many degrees (and its test below :data:`SUGGESTIVE`): under half a
#: degree gravity's direction moves the needed force by under one percent of the payload's weight, which a payload
#: given wrong (a mass 3 % high, a centre of mass 1 cm off) leaves in the tilt's columns of a short log.
SUGGESTED_TILT_DEG = 0.5
#: The segments of eq. (C5)'s ramps: a row's offset and its gain each a ramp between this many plus one knots over the
#: log, which follow a drift or a warm-up smoothly (a level per part would leave a drift within each part, which the
#: gain's columns take up where the load moves with time).
GAIN_PARTS = 3
#: The windows over which the offset's change is described, s (as the planar test's).
DESCRIBE_WINDOW = 0.5
#: The smoothing window of the motion in eq. (C1)'s payload columns ``W_k``, s: the angular acceleration and
#: velocity they hold, differentiated from noisy attitudes over the reference fit's window (0.2 s), carry errors
#: in variables that move ``dg`` and the offset's levels by more than their covariance holds; over 0.5 s the
#: second derivative's noise is some ten times smaller, and the columns still span what a payload given wrong
#: leaves.
PAYLOAD_WINDOW = 0.5


@dataclass
class GravityTilt:
    """Gravity's direction as the residual asks for it (eqs. (C1)-(C3) of :mod:`fmscal.observers.diagnostics._causes`).

    Attributes
    ----------
    gravity : ndarray, shape (3,)
        The pose frame's gravity along the direction the data ask for, ``g + dg``, at the size given (its size
        along the direction given is the payload's mass's, which ``S`` absorbs), m/s^2.
    tilt_deg, std_deg : float
        Its angle from the gravity given, and the one-sigma uncertainty across the gravity given, degrees (eq.
        (C3)).
    statistic : float
        ``X2`` of eq. (C2) on the two components across ``g``.
    p_value : float
    tilted : bool
        ``p_value`` below half of the significance: the gravity given does not explain the data.
    warning : str or None
        One line naming the tilt, where ``tilted``.
    ambiguous : bool
        Tilted on a log fitted with fewer parts than asked (``parts``), where an offset is named moving or some row's
        offset test is below :data:`SUGGESTIVE`: the tilt may be that offset's share, and the line names both and
        gives no gravity.
    suggestive : bool
        Not tilted, no offset named, its p-value below :data:`SUGGESTIVE` and the tilt at least
        :data:`SUGGESTED_TILT_DEG`: the data lean to the tilt without naming it (a log that does not determine it),
        said in :attr:`Causes.suggestion`.
    """

    gravity: np.ndarray
    tilt_deg: float
    std_deg: float
    statistic: float
    p_value: float
    tilted: bool
    warning: str = None
    ambiguous: bool = False
    suggestive: bool = False

    def to_dict(self):
        """The JSON form."""
        return {"gravity": [float(v) for v in self.gravity], "tilt_deg": float(self.tilt_deg),
                "std_deg": float(self.std_deg), "p_value": float(self.p_value), "tilted": bool(self.tilted),
                "ambiguous": bool(self.ambiguous), "suggestive": bool(self.suggestive)}


@dataclass
class GainDrift:
    """Which of a row's offset and its gain moves, where the offset's test found it moving (eq. (C5) of
    :mod:`fmscal.observers.diagnostics._causes`).

    Attributes
    ----------
    rows : list of int
        The rows whose gain moves and whose offset at no load does not: their gain's test below half of the
        significance (times the rows), their offset's beside it at or above it. Named here, not as an offset.
    changes : ndarray
        Each of ``rows``' gain change from the log's start to its end, relative (``S``'s gain on it times ``1 +
        change``).
    p_values : ndarray
        Each of ``rows``' gain test, times the rows tested.
    unresolved : list of int
        Rows found moving whose gain and offset (eq. (C5)) together move, neither alone determined (each test at or
        above half of the significance): either may move, and the offset's line says so.
    tested : bool
        Eq. (C5) was fitted: the log had the blocks of time for it (:data:`BLOCKS_PER_COLUMN` times its columns).
        Where not, a moving row is named an offset, as it was found.
    warning : str or None
        One line naming the gains, where ``rows``.
    unresolved_words : str
        The clause the offset's line takes for ``unresolved``.
    """

    rows: list
    changes: np.ndarray
    p_values: np.ndarray
    unresolved: list
    tested: bool
    warning: str = None
    unresolved_words: str = ""


@dataclass
class Causes:
    """The outcome of :func:`fit_causes`.

    Attributes
    ----------
    offset : OffsetDrift
        The moving offset's test (``constant``, ``statistic`` the largest row's ``F``, ``p_value``, ``warning``;
        ``offsets`` and ``t`` the per-window offsets of the reading it is described from). ``constant`` where no
        row's offset is named: a row found moving whose gain is named instead (``gain``) counts as constant.
    gain : GainDrift or None
        Which of a moving row's offset and gain moves (eq. (C5)); None where no row was found moving.
    gravity : GravityTilt or None
        The tilt's test; None on a model not under gravity.
    blocks : int
        ``G``, the blocks of time of the covariance.
    levels, levels_std : ndarray, shape (n_w, P - 1)
        ``beta_i`` of eq. (C1), each row in its wrench's units (N m, N): the level of the needed wrench's
        residual in each part of the log against the first, and its standard deviation.
    spreads, row_p_values : ndarray, shape (n_w,)
        Each row's levels' spread over its residual's rms (eq. (C4)) and its test's p-value times the rows.
    parts : int
        ``P``: the parts of the log the offset's levels were fitted in.
    needed : int
        The blocks of time the test asks for (:data:`BLOCKS_PER_COLUMN` times the columns of eq. (C1)); where
        ``blocks`` is fewer, nothing was tested, with the fewest parts (:data:`MIN_PARTS`).
    needed_duration : float
        The log's length that many blocks, as long as this log's, would take, s.
    asked : int or None
        The parts asked (``parts`` of :func:`fit_causes`); ``parts`` fewer on a short log; None where untested.
    suggested : list of int
        On a log fitted with fewer parts than asked, where nothing is named: the rows whose offset test is below
        :data:`SUGGESTIVE` and whose levels spread as far as eq. (C4) asks. A short log's levels trade with the
        payload's columns (a centre of mass or an inertia given wrong leaves a residual that follows the motion's
        slow changes), so that a moving offset the log cannot name is still in sight.
    suggestion : str or None
        Where nothing is named, one line for the causes the data lean to: ``suggested`` (an offset that moves, or
        a payload given wrong, and the log's length that tells them apart), and a tilt of gravity whose test is
        below :data:`SUGGESTIVE` (:attr:`GravityTilt.suggestive`; on a short log, beside an offset that may move,
        whose drift leaves a share the tilt takes up); not among :attr:`warnings`.
    """

    offset: OffsetDrift
    gravity: GravityTilt
    blocks: int
    levels: np.ndarray = None
    levels_std: np.ndarray = None
    spreads: np.ndarray = None
    row_p_values: np.ndarray = None
    parts: int = None
    needed: int = None
    needed_duration: float = None
    suggested: list = field(default_factory=list)
    suggestion: str = None
    asked: int = None
    gain: "GainDrift" = None

    @property
    def short(self):
        """Whether the log was fitted with fewer parts than asked (``parts`` below ``asked``; False untested)."""
        return self.asked is not None and self.parts < self.asked

    @property
    def tested(self):
        """Whether the log had the blocks of time to test (``blocks`` at least ``needed``)."""
        return self.needed is None or self.blocks >= self.needed

    @property
    def warnings(self):
        """The lines naming the causes found."""
        return [w for w in (None if self.gain is None else self.gain.warning, self.offset.warning,
                            None if self.gravity is None else self.gravity.warning) if w]


def fit_causes(log, model, window=0.2, parts=DRIFT_PARTS, significance=CAUSE_SIGNIFICANCE):
    """Fit a moving offset and a tilt of gravity to a log's reference residual, and test each: eqs. (C1)-(C3).

    Parameters
    ----------
    log : plant.Log
        A log of the model's case, in the toolkit's sign, its poses aligned with the reading.
    model : plant.Model
        With the attitude a unit quaternion (Newton-Euler in 3D); its payload and gravity as given.
    window : float
        Smoothing window of the pose differentiation, s.
    parts : int
        ``P`` of eq. (C1): the most; a log with too few blocks of time for them takes fewer, down to
        :data:`MIN_PARTS`.
    significance : float
        :data:`CAUSE_SIGNIFICANCE`.

    Returns
    -------
    Causes
        Nothing named (``offset.constant`` True, ``gravity.tilted`` False, NaN statistics) where the log has
        too few blocks of time to test.

    Raises
    ------
    FmscalError
        A model whose attitude is not a unit quaternion, a log of another case, or one shorter than the window.
    """
    if model.attitude != "quaternion":
        raise FmscalError(f"fit_causes takes a model under gravity in 3D; got a {model.name} model")
    model.check_log(log, "fit_causes")
    first, stop = edge(log, window), len(log.t) - edge(log, window)
    stride = max(1, -(-(stop - first) // MAX_ROWS))                          # every stride-th sample (a long log)
    trim = slice(first, stop, stride)
    q, omega, alpha, p_ddot = (a[trim] for a in spatial_motion(log, window))
    pi = model.payload.inertial_parameters
    w, w_hat, t = regressor(q, omega, alpha, p_ddot, model.gravity) @ pi, log.w_hat[trim], log.t[trim]
    # eq. (C1)'s payload columns, from the motion smoothed over PAYLOAD_WINDOW (their errors in variables)
    W = regressor(*(a[trim] for a in spatial_motion(log, max(window, PAYLOAD_WINDOW))), model.gravity)
    n, n_w = w.shape
    if n < 8 * (n_w + 1):
        raise FmscalError(f"{log.name}: too short to test the offset and gravity ({n} samples)")
    spread = np.r_[np.maximum(np.std(w_hat, axis=0), 1e-300), 1.0]
    X = np.c_[w_hat, np.ones(n)] / spread
    # the reference fit's "projection" X H X^T, H of the normal equations less the reading's noise (errors in
    # variables, as fit_readings; plain least squares shrinks S on the weak directions, and the residual it leaves
    # keeps a share of the motion that no offset or gravity makes)
    sigma = np.diag(np.r_[reading_noise(log.w_hat), 0.0] / spread) ** 2
    lam, u = np.linalg.eigh(X.T @ X - n * sigma)
    kept = lam > 1e-12 * lam.max()
    H = (u[:, kept] / lam[kept]) @ u[:, kept].T
    theta0 = H @ (X.T @ w)
    r = w - X @ theta0                                                        # the reference residual
    S = (theta0 / spread[:, None]).T[:, :n_w]                                 # S of the reference fit
    scale = np.maximum(np.sqrt(np.mean(r ** 2, axis=0)), 1e-300)
    D = gravity_jacobian(q, model.payload)                                  # (N, n_w, 3), eq. (G1)
    w_dot = np.gradient(w, t, axis=0)                                         # a latency's error, eq. (C1)
    # the blocks' length is the fit with the most parts' (a moving offset that fewer leave in the residual would
    # lengthen them), and so is G; P the most parts the log has blocks of time for: G against the columns
    fitted = _fit(t, log.dt, stride, window, parts, D, W, w_dot, X, H, r, scale)
    g, length, shared = fitted[-3], fitted[-1], fitted[7]
    p = next((p for p in range(parts, MIN_PARTS, -1) if g >= BLOCKS_PER_COLUMN * (shared + n_w * (p - 1))),
             min(MIN_PARTS, parts))
    if p != parts:
        fitted = _fit(t, log.dt, stride, window, p, D, W, w_dot, X, H, r, scale, length)
    *fitted, g, size, _ = fitted
    needed = BLOCKS_PER_COLUMN * size
    span = t[-1] - t[0] + log.dt * stride                                     # the blocks' time; the edges beside
    needed_duration = float(needed * length + (log.t[-1] - log.t[0] + log.dt) - span)
    designs, inverse, rank, theta, e, blocks, starts, shared, n_t = fitted
    if g < needed:          # the sandwich of eq. (C2) would be too rough to test on
        return Causes(offset=OffsetDrift(True, np.nan, 1.0, np.zeros((0, n_w)), np.zeros(0)),
                      gravity=_gravity_untested(model), blocks=g, needed=needed,
                      needed_duration=needed_duration)
    cov = _covariance(designs, inverse, rank, e, blocks, starts, size)
    offset, spreads, row_p, moving, tests = _offset_test(theta, cov, g, shared, n_t, scale, significance)
    gain = _gain_drift(_gain_test(t, log.dt, stride, window, D, W, w_dot, X, H, r, scale, w, moving), moving,
                       model.wrench_names, significance) if moving else None
    levels = [i for i in moving if i not in gain.rows] if moving else []     # the rows whose offset is named
    if gain is not None and gain.rows:       # the offset's test over the rows a gain does not explain
        offset = _offset_drift(tests, levels, g, among=[i for i in range(n_w) if i not in gain.rows])
    if levels:
        offset = _describe(offset, log, model, t, r, designs, theta, scale, S, shared, levels)
        offset.warning += gain.unresolved_words
    # the length that all the parts' blocks would take (as needed's), for a log fitted with fewer
    full = np.ceil(BLOCKS_PER_COLUMN * (shared + n_w * (parts - 1)) * length + (log.t[-1] - log.t[0] + log.dt) - span)
    if not model.under_gravity:
        gravity = _gravity_untested(model)
    else:
        gravity = _gravity_test(theta[:3], cov[:3, :3], g, model.gravity, significance)
        rows = list(moving) if moving else [int(i) for i in np.argsort(row_p) if row_p[i] < SUGGESTIVE]
        if gravity.tilted and n_t + 1 < parts and rows:
            gravity.ambiguous = True
            names = " or ".join(model.wrench_names[i] for i in rows)
            what = "offset or gain" if gain is not None and set(rows) & set(gain.rows) else "offset"
            gravity.warning = (f"gravity's direction, or the {what} of {names}: the data ask for gravity tilted "
                               f"{gravity.tilt_deg:.2g} degrees (+- {gravity.std_deg:.1g}; p = {gravity.p_value:.2g}), "
                               f"or the {what} of {names} moves (p = {', '.join(f'{row_p[i]:.2g}' for i in rows)}): "
                               f"{n_t + 1} parts of the log are too few to tell a drift from a tilt; record a log of "
                               f"{full:.0f} s or more ({parts} parts) to tell them apart, or estimate gravity with "
                               "fmscal identify-payload --gravity estimate")
    suggested, lines = [], []
    if not moving and not (gravity is not None and gravity.tilted) and n_t + 1 < parts:
        suggested = [int(i) for i in np.argsort(row_p) if row_p[i] < SUGGESTIVE and spreads[i] >= MOVING_SIZE]
    if suggested:
        names = " and ".join(model.wrench_names[i] for i in suggested)
        lines.append(f"the sensor's offset may move, or the payload is given wrong: the level of {names} changes "
                     f"between the log's {n_t + 1} parts (p = {', '.join(f'{row_p[i]:.2g}' for i in suggested)}; "
                     f"a moving offset is named below {significance / 2:g}), which a centre of mass or an inertia "
                     f"given wrong can also leave on a log this short; record a log of {full:.0f} s or more "
                     f"({parts} parts) to tell them apart")
    if not moving and gravity is not None and not gravity.tilted and gravity.p_value < SUGGESTIVE \
            and gravity.tilt_deg >= SUGGESTED_TILT_DEG:
        gravity.suggestive = True
        lean = (f"the data lean to gravity tilted {gravity.tilt_deg:.2g} degrees (+- {gravity.std_deg:.1g}; p = "
                f"{gravity.p_value:.2g}; a tilt is named below {significance / 2:g})")
        lines.append(f"gravity's direction may not be the one given: {lean}, which this log does not determine; "
                     "record a longer log, or estimate gravity with fmscal identify-payload --gravity estimate"
                     if n_t + 1 == parts else
                     f"gravity's direction may not be the one given, or the offset may move: {lean}, which a drift "
                     f"that the log's {n_t + 1} parts follow badly can also leave; record a log of {full:.0f} s or "
                     f"more ({parts} parts) to tell them apart, or estimate gravity with fmscal identify-payload "
                     "--gravity estimate")
    suggestion = "; or ".join(lines) or None
    beta = theta[shared:].reshape(n_w, n_t)
    beta_std = np.sqrt(np.maximum(np.diag(cov)[shared:], 0.0)).reshape(n_w, n_t)
    return Causes(offset=offset, gravity=gravity, blocks=g, levels=beta, levels_std=beta_std, spreads=spreads,
                  row_p_values=row_p, parts=n_t + 1, needed=needed, needed_duration=needed_duration,
                  suggested=suggested, suggestion=suggestion, asked=parts, gain=gain)


def _gravity_untested(model):
    """Gravity's direction not tested (None on a model not under gravity): the gravity given, NaN statistics."""
    if not model.under_gravity:
        return None
    return GravityTilt(np.asarray(model.gravity, dtype=float), np.nan, np.nan, np.nan, 1.0, False)


def _fit(t, dt, stride, window, parts, D, W, w_dot, X, H, r, scale, length=None, gains=(), w=None):
    """Eq. (C1) fitted with ``parts`` parts of the log: the rows' designs, ``A^+``, its rank, ``theta``, the scaled
    residual it leaves, the blocks of time (each sample's, and their starts), the shared columns, the columns of a
    row's offset (``P - 1``), ``G``, the columns and the blocks' length, s (eq. (U2) of that residual, or ``length``
    where given). With ``gains`` (rows), eq. (C5) instead: the offsets ramps between ``parts + 1`` knots, and
    those rows' gains the same ramps times their needed wrench ``w`` about its mean, after all the others."""
    n_w = r.shape[1]
    if gains:                                                                 # eq. (C5): ramps, (N, P)
        knots = t[0] + (t[-1] - t[0] + dt) * np.arange(parts + 1) / parts
        T = np.column_stack([np.interp(t, knots, np.eye(parts + 1)[k]) for k in range(1, parts + 1)])
    else:                                                                     # eq. (C1): levels, (N, P - 1)
        part = np.minimum((parts * (t - t[0]) / (t[-1] - t[0] + dt)).astype(int), parts - 1)
        T = (part[:, None] == np.arange(1, parts)[None, :]).astype(float)
    shared = 3 + W.shape[2] - 1 + 1              # dg, dpi less the mass, and dtau (eq. C1)
    n_t = T.shape[1]
    size = shared + n_w * n_t + len(gains) * n_t
    A, b, designs = np.zeros((size, size)), np.zeros(size), []
    for i in range(n_w):                                                      # eq. (C1), row by row
        Z = np.c_[-D[:, i], -W[:, i, 1:], w_dot[:, i], T] / scale[i]
        cols = np.r_[np.arange(shared), shared + i * n_t + np.arange(n_t)]
        if i in gains:                                                        # eq. (C5)'s gain columns
            Z = np.c_[Z, T * ((w[:, i] - w[:, i].mean()) / scale[i])[:, None]]
            cols = np.r_[cols, shared + (n_w + list(gains).index(i)) * n_t + np.arange(n_t)]
        Y = Z - X @ (H @ (X.T @ Z))                                          # what [S | c] leaves of it
        A[np.ix_(cols, cols)] += Z.T @ Y
        b[cols] += Z.T @ (r[:, i] / scale[i])
        designs.append((cols, Y))
    inverse, rank = _pseudo_inverse(A)
    theta = inverse @ b
    e = np.column_stack([r[:, i] / scale[i] - Y @ theta[cols] for i, (cols, Y) in enumerate(designs)])
    length = block_length(e, dt * stride, window) if length is None else length
    # a last block under half the length joins the one before: a sliver of a few samples is no block of time (one
    # sample had made a 10 s log a block longer, and so fitted with more parts, than the same log aligned a
    # twentieth of a sample shorter)
    last = max(1, int(np.round((t[-1] - t[0] + dt * stride) / length))) - 1
    blocks = np.minimum(((t - t[0]) // length).astype(int), last)
    starts = np.flatnonzero(np.r_[True, np.diff(blocks) != 0])
    return designs, inverse, rank, theta, e, blocks, starts, shared, n_t, len(starts), size, length


def _gain_drift(which, moving, names, significance):
    """The :class:`GainDrift` of eq. (C5)'s outcome ``which`` (:func:`_gain_test`) on the rows found moving."""
    if not which:
        return GainDrift(rows=[], changes=np.zeros(0), p_values=np.zeros(0), unresolved=[], tested=False)
    half = significance / 2
    rows = [i for i in moving if which[i][1] < half <= which[i][2]]
    unresolved = [i for i in moving if which[i][1] >= half and which[i][2] >= half and which[i][3] < half]
    out = GainDrift(rows=rows, changes=np.array([which[i][0] for i in rows]),
                    p_values=np.array([which[i][1] for i in rows]), unresolved=unresolved, tested=True)
    if rows:
        changes = " and ".join(f"on {names[i]} by {100 * which[i][0]:+.2g} % (the reading's sensitivity "
                               f"{100 * (1 / (1 + which[i][0]) - 1):+.2g} %; p = {which[i][1]:.2g})" for i in rows)
        out.warning = (f"S's gain moves during the log: its gain changes {changes} from the log's start to its end "
                       "(the residual follows the needed wrench's size along the log, beyond what a moving offset "
                       "explains); one constant S does not describe it: let the sensor warm up before recording, and "
                       "calibrate again")
    if unresolved:
        out.unresolved_words = "; " + "; ".join(
            f"{names[i]}'s row moves by its offset or by S's gain on {names[i]}, which the log does not tell apart "
            f"(p = {which[i][3]:.2g} for both; {which[i][1]:.2g} for the gain, {which[i][2]:.2g} for the offset "
            "beside it)" for i in unresolved)
    return out


def _covariance(designs, inverse, rank, e, blocks, starts, size):
    """The cluster-robust sandwich of a fit of eq. (C1) or (C5) over its blocks of time (eq. (U3))."""
    scores = np.zeros((len(starts), size))
    for i, (cols, Y) in enumerate(designs):
        scores[:, cols] += np.add.reduceat(Y * e[:, i:i + 1], starts, axis=0)
    return small_sample_factor(blocks, e.size, rank) * inverse @ (scores.T @ scores) @ inverse


def _gain_test(t, dt, stride, window, D, W, w_dot, X, H, r, scale, w, moving):
    """Eq. (C5) for the rows found moving: ``{row: (change, p_gamma, p_beta, p_both)}``, the row's gain change over
    the log (``gamma_i`` at the last knot against the first), the p-values of ``gamma_i`` (times the rows), of its
    offset at no load beside it (``beta_i - gamma_i mean(w_i)``; not times the rows: a guard, which a Bonferroni
    factor would loosen) and of both together (times the rows). Every row's gain where the log has the blocks of
    time for it, else the moving rows'; ``{}`` where it has not for those."""
    n_w, out = r.shape[1], {}
    for rows in dict.fromkeys((tuple(range(n_w)), tuple(moving))):            # every row's gain, else the moving
        fitted = _fit(t, dt, stride, window, GAIN_PARTS, D, W, w_dot, X, H, r, scale, gains=rows, w=w)
        designs, inverse, rank, theta, e, blocks, starts, shared, n_t, g, size, _ = fitted
        if g >= BLOCKS_PER_COLUMN * size:
            break
    else:
        return out
    cov = _covariance(designs, inverse, rank, e, blocks, starts, size)
    for i in moving:
        gamma = shared + (n_w + rows.index(i)) * n_t + np.arange(n_t)
        idx = np.r_[shared + i * n_t + np.arange(n_t), gamma]
        M = np.c_[np.eye(n_t), -w[:, i].mean() * np.eye(n_t)]                  # the offset at no load
        p_gamma = hotelling(theta[gamma], cov[np.ix_(gamma, gamma)], g)[2]
        p_beta = hotelling(M @ theta[idx], M @ cov[np.ix_(idx, idx)] @ M.T, g)[2]
        p_both = hotelling(theta[idx], cov[np.ix_(idx, idx)], g)[2]
        out[i] = (float(theta[gamma][-1]), min(1.0, len(moving) * p_gamma), p_beta, min(1.0, len(moving) * p_both))
    return out


def _pseudo_inverse(A):
    """``A^+`` on the directions it determines (scaled to a unit diagonal; eigenvalues below :data:`ABSORBED` of the
    largest dropped: the payload's parameters that ``S`` absorbs), and its rank."""
    d = np.sqrt(np.maximum(np.diag(A), 1e-300))
    lam, u = np.linalg.eigh(A / np.outer(d, d))
    keep = lam > ABSORBED * lam.max()
    return (u[:, keep] / lam[keep]) @ u[:, keep].T / np.outer(d, d), int(keep.sum())


def _offset_test(theta, cov, g, shared, n_t, scale, significance):
    """The moving offset's test, each row's spread and p-value, and the rows found moving: each row's ``beta_i`` of
    eq. (C1) by eq. (C2), Bonferroni over the rows; a row counts where its levels also spread over
    :data:`MOVING_SIZE` of its residual's rms (eq. (C4))."""
    n_w = len(scale)
    rows = [shared + i * n_t + np.arange(n_t) for i in range(n_w)]
    tests = [hotelling(theta[idx], cov[np.ix_(idx, idx)], g) for idx in rows]
    sizes = [np.ptp(np.r_[0.0, theta[idx]]) / scale[i] for i, idx in enumerate(rows)]
    moving = [i for i in range(n_w) if n_w * tests[i][2] < significance / 2 and sizes[i] >= MOVING_SIZE]
    return _offset_drift(tests, moving, g), np.array(sizes), \
        np.minimum(1.0, n_w * np.array([test[2] for test in tests])), moving, tests


def _offset_drift(tests, named, g, among=None):
    """The :class:`OffsetDrift` of eq. (C2)'s row ``tests``: ``F`` and the p-value (times the rows) of the row
    named (``named``) with the smallest p-value, or of the rows ``among`` (all where None) where none is; NaN and 1
    where there are none."""
    rows = named or (range(len(tests)) if among is None else among)
    statistic, k, p = min((tests[i] for i in rows), key=lambda test: test[2], default=(np.nan, 0, 1.0))
    F = (g - k) / (k * (g - 1)) * statistic if k and g > k + 1 else np.nan
    return OffsetDrift(not named, float(F), min(1.0, len(tests) * p), np.zeros((0, len(tests))), np.zeros(0))


def _describe(offset, log, model, t, r, designs, theta, scale, S, shared, moving):
    """The offset's change in words: the residual less the fitted gravity and payload terms, per window, taken to
    the reading by ``-S^-1`` (:func:`describe_offset`), on the reading's channel that a change of a row found
    moving (``moving``, rows of the wrench) moves most against its noise."""
    left = np.column_stack([r[:, i] - scale[i] * (Y[:, :shared] @ theta[:shared]) for i, (_, Y) in
                            enumerate(designs)])
    windows = ((t - t[0]) // DESCRIBE_WINDOW).astype(int)
    starts = np.flatnonzero(np.r_[True, np.diff(windows) != 0])
    counts = np.diff(np.r_[starts, len(t)])
    means = np.add.reduceat(left, starts, axis=0) / counts[:, None]
    S_inv = np.linalg.pinv(S)
    est = -means @ S_inv.T
    per_sample = S.T @ np.diag(1.0 / scale ** 2) @ S
    info = counts[:, None, None] * per_sample[None]
    sd = np.sqrt(np.maximum(np.diag(np.linalg.pinv(per_sample)), 1e-300))     # a reading channel's, per sample
    middle = np.add.reduceat(t, starts) / counts
    forces = set(model.force_channels)
    units = tuple("N" if k in forces else "N m" for k in range(len(model.wrench_names)))
    offset.offsets, offset.t = est, middle
    offset.warning = describe_offset(middle, est, info, 1.0, offset.p_value, model.wrench_names, units,
                                     "the residuals of a least-squares fit change level along the log, beyond "
                                     "what gravity's direction and the payload explain",
                                     channels=sorted({int(np.argmax(np.abs(S_inv[:, i]) / sd)) for i in moving}))
    return offset


def _across(u):
    """Two orthonormal directions across the unit vector ``u``, shape (3, 2)."""
    return np.linalg.svd(np.eye(3) - np.outer(u, u))[0][:, :2]


def _gravity_test(dg, C, g, gravity, significance):
    """The tilt's test: the two components of ``dg`` across ``g`` by eq. (C2), its angle and sd by eq. (C3)."""
    g0 = np.asarray(gravity, dtype=float)
    size = np.linalg.norm(g0)
    u = g0 / size
    A = _across(u)
    x, C_perp = A.T @ dg, A.T @ C @ A
    statistic, _, p_value = hotelling(x, C_perp, g)
    # eq. (C3): at gravity's size given (dg along g is the payload's mass's share, which S absorbs)
    across = min(float(np.linalg.norm(x)), size)
    tilt = float(np.degrees(np.arcsin(across / size)))
    std = float(np.degrees(np.sqrt(max(np.linalg.eigvalsh(C_perp).max(), 0.0)) / size))
    found = A @ x * (across / max(float(np.linalg.norm(x)), 1e-300)) + u * np.sqrt(size ** 2 - across ** 2)
    tilted = bool(p_value < significance / 2)
    out = GravityTilt(gravity=found, tilt_deg=tilt, std_deg=std, statistic=statistic, p_value=p_value,
                      tilted=tilted)
    if tilted:
        along = "-z" if np.allclose(u, [0.0, 0.0, -1.0]) else "the direction given"
        out.warning = (f"gravity's direction: the data ask for gravity tilted {tilt:.2g} degrees (+- {std:.1g}) from "
                       f"the one given (along {along}; p = {p_value:.2g}): the robot's base is tilted, or the pose "
                       f"frame's z is not up; give the gravity found (--gravity "
                       f"{' '.join(f'{v:.4g}' for v in found)}), or estimate it with fmscal identify-payload "
                       "--gravity estimate")
    return out
