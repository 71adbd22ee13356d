"""When a payload counts as determined: by what its uncertainty does to the compensated wrench.

Compensation removes the payload's wrench from the reading; at rest, with ``S`` known (eq. (P0) of
:class:`fmscal.plant.PayloadModel`), it subtracts what the fit predicts the reading to be at the attitude
``R``, ``y(R; theta) = [com x f; f / g] + c`` with ``f = m M^T R^T (-g_pose)`` (the static model of
:mod:`fmscal.observers.payload._static_fit`: the mass, the centre of mass, the offset, the force gains and,
where estimated, gravity's direction and the mounting). The compensated wrench ``diag(g) (y - c) - W_p``
then errs by ``diag(g)`` times the prediction's error, whose standard deviation in channel ``i`` is::

    sd_i(R) = g_i sqrt([J(R) C J(R)^T]_ii),     J = d y(R; theta) / d theta                       (E1)

``C`` the fit's covariance. The payload's effect is its largest over the attitudes the compensation is
promised for, those whose gravity directions lie within the cone the data span in the sensor frame
(:func:`cone_attitudes`), torques and forces apart::

    e_tau = max_{R in cone, i torque} sd_i(R)  [N m],    e_f = max_{R in cone, i force} sd_i(R)  [N]   (E2)

and the payload is determined when both are within the tolerance, ``e_f <= tol_f`` and ``e_tau <=
tol_tau`` (E3). The tolerance is the user's (``tolerance=(N, N m)``; ``--tolerance N NM``), by default
:data:`DEFAULT_TOLERANCE` times the reading's noise, one standard deviation (E4): a log's reading's
sample-to-sample scatter (third differences', :func:`reading_noise`; each channel, their rms over the torques
and over the forces), :data:`TABLE_TOLERANCE` times a table's rows' scatter about the fit (eq. N2 of
:mod:`fmscal.observers.payload._static_fit`; a table's rows are averages, and a reading's own noise, which
the compensation of a running robot sees, is larger: a row that averages ``n >= 4`` readings has at most
half their sd, so that twice its scatter is at most one sd of a reading, the same promise as a log's), or,
for the held segments of an attitude-only log, whose raw readings are at hand, the log's reading's noise
(:func:`reading_noise`). Where the payload is not
determined, :func:`judge` names the reason:

- **the cone**: the effect at the data's own attitudes is within the tolerance and beyond it elsewhere in
  the cone (attitudes the data cover thinly), or the data leave a direction not determined at all, as
  poses turned about one axis only do (their gravity directions on one circle: a force gain, and with it
  the mass, is then not determined off that circle; where the gains are not estimated, such poses are
  refused whatever the effect, since nothing tests the gains off the circle);
- **the gains**: with the force gains known (their uncertainty taken out of ``C``) the effect would be
  within it;
- **the noise**: beyond it at the data's own attitudes.

More poses help in each case (the next poses say which). On a log whose residuals exceed the reading's
noise more than :data:`MISFIT_RATIO` times, the reason is **the model**: it does not fit (cross-talk or
torque gains of ``S``, which the payload cannot take up), more data do not lower that, and the line says
what compensation will leave and advises no poses. A log's inertia keeps its own rule (a standard deviation within 2 %
of the mean diagonal) and must also leave the compensated torque within the tolerance at the recorded
motion (:func:`inertia_effect`).
"""

from typing import NamedTuple

import numpy as np

from fmscal.plant.numerics import FmscalError

from ._coverage import effect_sd, rotation

__all__ = ["Effect", "DEFAULT_TOLERANCE", "TABLE_TOLERANCE",
           "check_tolerance", "reading_noise", "cone_attitudes", "static_effect",
           "inertia_effect", "judge", "circle_axis", "CIRCLE_DEG", "GRID_RINGS", "GRID_TURNS", "MISFIT_RATIO"]

#: The default tolerance, in standard deviations of the reading's noise (eq. E4).
DEFAULT_TOLERANCE = 1.0
#: A table's default tolerance, in standard deviations of its rows' scatter (eq. E4): a row averages 4 readings
#: or more, so this is at most :data:`DEFAULT_TOLERANCE` sd of a reading.
TABLE_TOLERANCE = 2.0
#: A log's residuals beyond this many times the reading's noise (the rms over the forces, or over the torques) are
#: a model that does not fit (:func:`judge`).
MISFIT_RATIO = 1.5
#: Gravity directions within this many degrees (rms) of one circle in the sensor frame are turned about one
#: axis only (:func:`circle_axis`).
CIRCLE_DEG = 2.0
#: The grid of gravity directions that fills the cone (:func:`cone_attitudes`): rings of polar angle out to the
#: cone's half-angle, and directions on each ring.
GRID_RINGS = 6
GRID_TURNS = 12


class Effect(NamedTuple):
    """What a payload's uncertainty does to the compensated wrench (eqs. E1, E2), ``(N, N m)`` each.

    Attributes
    ----------
    cone : ndarray, shape (2,)
        The largest standard deviation over the attitudes within the data's cone: forces (N), torques (N m).
    data : ndarray, shape (2,)
        The same at the data's own attitudes.
    known_gains : ndarray, shape (2,), or None
        Over the cone with the force gains known (their uncertainty taken out); None where they are not
        estimated.
    """

    cone: np.ndarray
    data: np.ndarray
    known_gains: np.ndarray


def check_tolerance(tolerance, name="tolerance"):
    """``tolerance`` as two positive finite numbers ``(N, N m)``, or None; else a one-line :class:`FmscalError`."""
    if tolerance is None:
        return None
    try:
        values = np.array(tolerance, dtype=float)
    except (TypeError, ValueError):
        values = np.array(np.nan)
    if isinstance(tolerance, (str, bytes)) or values.shape != (2,) or not np.all(np.isfinite(values)) \
            or not np.all(values > 0):
        raise FmscalError(f"{name} must be two positive numbers, N and N m (the forces' and the torques' "
                          f"largest standard deviation the payload may add); got {str(tolerance)[:60]}")
    return values


def reading_noise(w_hat, S=None, samples=None):
    """The reading's noise per sample, eq. (E4), forces and torques: each channel's scatter turned by ``S`` (``S``
    times the raw reading; its sign does not change a scatter), then their rms over the forces and over the
    torques.

    A log's consecutive readings (``samples`` None): the rms of their third differences over ``sqrt 20`` (white
    noise's third difference has ``C(6, 3) = 20`` times its variance; the motion's share of it falls as ``dt^3``,
    where a first difference keeps ``dt``'s: at 25 Hz the wrench's change between readings is many times the
    noise). Held segments' rows (``samples``
    given): ``w_hat`` is then their standard errors (:func:`fmscal.plant.io.held_table`'s ``noise``), each the
    scatter within its segment over the square root of its samples, and the scatter is ``sqrt(mean(se^2)
    samples)``, ``samples`` the mean count a row averages (segments of equal length: exact).

    Parameters
    ----------
    w_hat : ndarray, shape (N, 6)
        Consecutive raw readings, or the held rows' standard errors; reading order (torques first).
    S : array_like, shape (6, 6), optional
        The calibration (default: the identity).
    samples : float, optional
        With standard errors: the samples a row averages, on average.

    Returns
    -------
    ndarray, shape (2,)
        Forces (N), torques (N m).
    """
    w_hat = np.asarray(w_hat, dtype=float)
    S = np.eye(6) if S is None else np.asarray(S, dtype=float)
    variance = np.mean(np.diff(w_hat, n=3, axis=0) ** 2, axis=0) / 20 if samples is None else \
        np.mean(w_hat ** 2, axis=0) * float(samples)
    channel = np.sqrt(np.maximum(np.diag(S @ np.diag(variance) @ S.T), 0.0))
    return np.array([np.sqrt(np.mean(channel[3:] ** 2)), np.sqrt(np.mean(channel[:3] ** 2))])


def cone_attitudes(R, M, d, cone):
    """The data's attitudes and attitudes that fill the cone of gravity directions they span (eq. E2).

    The cone is the half-angle ``cone`` around the mean of the sensor-frame directions ``u_k = M^T R_k^T
    (-d)`` (:func:`fmscal.observers.payload.cone_deg`); it is filled by :data:`GRID_RINGS` rings of
    :data:`GRID_TURNS` directions each. Each direction ``v`` is reached from the data attitude nearest it,
    turned in the sensor frame by the least rotation ``Q`` taking ``u_k`` onto ``v``: ``R' = R_k M Q^T M^T``
    (then ``M^T R'^T (-d) = Q u_k = v``).

    Parameters
    ----------
    R : ndarray, shape (N, 3, 3)
        The tracked frame's attitudes.
    M : ndarray, shape (3, 3)
        The mounting (sensor axes on the tracked frame).
    d : ndarray, shape (3,)
        Gravity's unit direction in the pose frame.
    cone : float
        The cone's half-angle, degrees.

    Returns
    -------
    ndarray, shape (N + K, 3, 3)
        The data's attitudes first.
    """
    u = np.einsum("ji,nkj,k->ni", M, R, -np.asarray(d, dtype=float))
    u /= np.linalg.norm(u, axis=1)[:, None]
    mean = u.mean(axis=0)
    mean = mean / np.linalg.norm(mean) if np.linalg.norm(mean) > 1e-9 else u[0]
    e1 = np.cross(mean, np.eye(3)[int(np.argmin(np.abs(mean)))])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(mean, e1)
    out = []
    for polar in np.radians(cone) * np.arange(GRID_RINGS + 1) / GRID_RINGS:
        for turn in 2 * np.pi * np.arange(GRID_TURNS if polar > 0 else 1) / GRID_TURNS:
            v = np.cos(polar) * mean + np.sin(polar) * (np.cos(turn) * e1 + np.sin(turn) * e2)
            k = int(np.argmax(u @ v))
            axis = np.cross(u[k], v)
            angle = np.arctan2(np.linalg.norm(axis), float(u[k] @ v))
            if np.linalg.norm(axis) < 1e-12:                 # v is u_k (or opposite it: any axis across)
                axis = np.cross(u[k], np.eye(3)[int(np.argmin(np.abs(u[k])))])
            Q = rotation(angle * axis / np.linalg.norm(axis))
            out.append(R[k] @ M @ Q.T @ M.T)
    return np.concatenate([R, np.array(out).reshape(-1, 3, 3)])


def static_effect(model, theta, cov, attitudes, n_data):
    """The payload's effect on the compensated wrench, eqs. (E1), (E2), over the cone and at the data.

    Parameters
    ----------
    model : fmscal.observers.payload._static_fit._Model
        Its ``jacobian(theta, R)`` gives the predicted reading's rows at attitudes ``R``, its
        ``channel_gains`` the gains and its ``gain_index`` their numbers in ``theta``.
    theta : ndarray, shape (p,)
        ``(m, com, c, angles, gains)`` in the model's layout.
    cov : ndarray, shape (p, p)
        Their covariance (infinite entries: not determined).
    attitudes : ndarray, shape (K, 3, 3)
        :func:`cone_attitudes`: the data's attitudes first.
    n_data : int
        How many of them are the data's.

    Returns
    -------
    Effect
    """
    J = model.jacobian(theta, R=attitudes).reshape(len(attitudes), 6, -1)
    gains = model.channel_gains(theta)
    cov = np.asarray(cov, dtype=float)
    known = None
    index = list(model.gain_index)
    if index and np.all(np.isfinite(cov)):
        others = [i for i in range(len(theta)) if i not in index]
        C_og = cov[np.ix_(others, index)]
        conditional = np.zeros_like(cov)
        conditional[np.ix_(others, others)] = cov[np.ix_(others, others)] - C_og @ np.linalg.pinv(
            cov[np.ix_(index, index)]) @ C_og.T
        known = effect_sd(J, conditional, gains)
    return Effect(effect_sd(J, cov, gains), effect_sd(J[:n_data], cov, gains), known)


def inertia_effect(W_inertia, cov):
    """The largest standard deviation the inertia's uncertainty leaves in the compensated torque at the recorded
    motion, N m: ``I alpha + omega x (I omega)`` (:func:`fmscal.plant.physics.regressor`'s inertia columns)
    at each sample, over the inertia's covariance.

    Parameters
    ----------
    W_inertia : ndarray, shape (N, 3, 6)
        The torque rows of the regressor's inertia columns at each sample.
    cov : ndarray, shape (6, 6)
        The inertia's covariance, kg^2 m^4.

    Returns
    -------
    float
    """
    if not np.all(np.isfinite(cov)):
        return float("inf")
    return float(np.sqrt(np.maximum(np.sum((W_inertia @ cov) * W_inertia, axis=2), 0.0).max()))


def circle_axis(u):
    """The axis about which the unit directions ``u`` (N, 3) turn, where they lie on one circle; else None.

    On one circle: within :data:`CIRCLE_DEG` (rms) of the plane nearest them (through their mean), and spread
    within it across the chord by more than that (an arc, not a cone narrower than a few degrees).

    Returns
    -------
    ndarray, shape (3,), or None
        The circle's axis (the plane's unit normal, its largest component positive).
    """
    centred = u - u.mean(axis=0)
    lam, vec = np.linalg.eigh(centred.T @ centred / len(u))
    off, across = np.sqrt(np.maximum(lam[:2], 0.0))
    if off > np.sin(np.radians(CIRCLE_DEG)) or across < np.sin(np.radians(CIRCLE_DEG)):
        return None
    axis = vec[:, 0]
    return axis * np.sign(axis[np.argmax(np.abs(axis))])


def _pair(values):
    return f"{values[0]:.2g} N and {values[1]:.2g} N m"


def judge(effect, tolerance, tolerance_words, cone, undetermined=False, axis=None, gains_estimated=True,
          misfit=None, identity=True):
    """Whether the payload is determined (eq. E3), and, where not, why in one line.

    Parameters
    ----------
    effect : Effect
    tolerance : ndarray, shape (2,)
        N, N m.
    tolerance_words : str
        Where the tolerance comes from ("1 sd of the reading's noise", "given").
    cone : float
        The data's cone, degrees.
    undetermined : bool
        The data leave a direction of the parameters not determined at all.
    axis : ndarray, shape (3,), or None
        :func:`circle_axis` of the data's gravity directions: named as the reason where the payload is not
        determined; refused whatever the effect where the gains were not estimated (nothing then tests them
        off the circle).
    gains_estimated : bool
    misfit : (ndarray (2,), ndarray (2,)), optional
        A log's residuals' rms and the reading's noise, forces (N) and torques (N m): where the residuals
        exceed the noise more than :data:`MISFIT_RATIO` times, the model does not fit (``S``'s cross-talk or
        torque gains, which the payload cannot take up), and more data do not mend it: that is the reason
        given, with what compensation will leave.
    identity : bool
        ``S = I`` was taken (the line's advice).

    Returns
    -------
    determined : bool
    why : str or None
        The reason, naming the model's misfit, the cone, the gains or the noise, and what would help.
    helps : bool
        More poses would help (not where the model does not fit).
    """
    if np.all(effect.cone <= tolerance) and (axis is None or gains_estimated):
        return True, None, True
    told = f"beyond the tolerance of {_pair(tolerance)} ({tolerance_words})"
    if misfit is not None and np.max(misfit[0] / misfit[1]) > MISFIT_RATIO:
        residual, noise = misfit
        cause = "S = I may be wrong: calibrate S (fmscal calibrate) and pass it" if identity else \
            "the calibration given may be wrong"
        ratio = residual / noise
        adds = (f"the payload adds up to {_pair(effect.cone)} (1 sd) within the cone of {cone:.0f} degrees, "
                f"{told}") if np.all(np.isfinite(effect.cone)) else \
            f"the data leave part of the payload not determined within the cone of {cone:.0f} degrees"  # no inf
        return False, (f"the model does not fit: the fit leaves {_pair(residual)} (rms), {ratio[0]:.2g} and "
                       f"{ratio[1]:.2g} times the reading's noise, which more data do not lower (cross-talk or "
                       f"torque gains of S, which the payload cannot take up), and {adds}: compensation will "
                       f"leave about the residual; {cause}, or give a tolerance that accepts it"), False
    if axis is not None:
        return False, (f"the poses turn gravity about one axis only (its directions in the sensor frame lie on one "
                       f"circle, about the axis {' '.join(f'{v:+.2f}' for v in axis)}): off that circle, within "
                       f"the cone of {cone:.0f} degrees they span, the payload is not known (a force gain, and with "
                       "it the mass, is not determined); tilt the tool about another axis (see the next poses)"), True
    if undetermined or not np.all(np.isfinite(effect.cone)):
        return False, (f"the data leave part of the payload not determined (see the warnings): within the cone of "
                       f"{cone:.0f} degrees it spans, the payload is not known; turn gravity through more "
                       "directions in the sensor frame (see the next poses)"), True
    if np.all(effect.data <= tolerance):
        return False, (f"the payload adds up to {_pair(effect.cone)} (1 sd) to the compensated wrench within the "
                       f"cone of {cone:.0f} degrees the data span, {told}, though only {_pair(effect.data)} at "
                       "the recorded attitudes: the cone is covered thinly; record poses across it (see the next "
                       "poses)"), True
    if effect.known_gains is not None and np.all(effect.known_gains <= tolerance):
        return False, (f"the payload adds up to {_pair(effect.cone)} (1 sd) to the compensated wrench within the "
                       f"cone of {cone:.0f} degrees, {told}; the force gains, estimated with it, leave most of "
                       f"that (known, {_pair(effect.known_gains)}): turn each force axis through gravity, up "
                       "and down (see the next poses)"), True
    return False, (f"the payload adds up to {_pair(effect.cone)} (1 sd) to the compensated wrench within the cone "
                   f"of {cone:.0f} degrees, {told}, {_pair(effect.data)} at the recorded attitudes: the "
                   "noise; record more poses (see the next poses), or give a tolerance from the sensor's noise"), True
