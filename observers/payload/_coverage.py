"""What the data covered, and the poses to record next: one machinery for a pose table and for a log.

The cone of gravity directions the data hold in the sensor frame (the
half-angle around their mean, :func:`cone_deg`); the parameters the data
leave undetermined or poorly determined, in words (:func:`weak_directions`,
:func:`describe`); and the held poses that would most lower the payload's
effect on the compensated wrench (:func:`next_poses`): candidate turns of 45, 90 and 180
degrees about the sensor's axes from reference attitudes (a table's poses, or
attitudes along a log), each scored by the covariance the fit would have with
the pose's rows added to its information::

    cov(R_c) = s^2 (F + r J_c^T J_c)^-1                                      (N1)

``F`` the fit's weighted information over the parameters a held pose
informs (mass, centre of mass, offset, gravity's and the mounting's
angles where estimated, the force gains), ``J_c`` the held pose's six weighted rows
(:class:`fmscal.observers.payload._static_fit._Model`), ``r`` how many times they
count (one row of a table; the samples of a held pose of a log) and ``s^2``
the weighted residuals' variance per degree of freedom.
"""

import numpy as np

from fmscal.plant.physics import skew

__all__ = ["cone_deg", "covariance", "weak_directions", "describe", "in_words", "effect_sd", "next_poses",
           "rotation", "TURNS"]

#: The turns about a sensor axis the next poses are drawn from, degrees.
TURNS = (45.0, 90.0, 180.0, -45.0, -90.0)
_AXES = ("x", "y", "z")
_OFFSET_NAMES = ("tx", "ty", "tz", "fx", "fy", "fz")
_INERTIA = ("Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz")
_PRETTY = {"m": "the mass", **{f"c_{n}": f"the offset's {n}" for n in _OFFSET_NAMES},
           **{f"com_{a}": f"the centre of mass along {a}" for a in _AXES},
           **{f"I_{n}": f"the inertia's {n}" for n in _INERTIA},
           "gravity_1": "gravity's direction", "gravity_2": "gravity's direction",
           **{f"mount_{a}": f"the mounting about {a}" for a in _AXES},
           "gain_x": "the force gains", "gain_y": "the force gains"}
_PREFIXES = ("the inertia's ", "the offset's ", "the centre of mass along ", "the mounting about ")


def rotation(v):
    """The rotation matrix of the rotation vector ``v`` (Rodrigues).

    Parameters
    ----------
    v : array_like, shape (3,)
        Axis times angle, rad.

    Returns
    -------
    ndarray, shape (3, 3)
    """
    angle = float(np.linalg.norm(v))
    K = skew(np.asarray(v, dtype=float))
    if angle < 1e-12:
        return np.eye(3) + K
    return np.eye(3) + np.sin(angle) / angle * K + (1 - np.cos(angle)) / angle ** 2 * K @ K


def cone_deg(a):
    """Half-angle of the cone of directions ``a`` around their mean, degrees (180 when they surround it).

    Parameters
    ----------
    a : ndarray, shape (N, 3)
        Directions (any length but zero).

    Returns
    -------
    float
    """
    u = a / np.linalg.norm(a, axis=1)[:, None]
    mean = u.mean(axis=0)
    if np.linalg.norm(mean) < 1e-9:
        return 180.0
    mean /= np.linalg.norm(mean)
    return float(np.degrees(np.max(np.arccos(np.clip(u @ mean, -1.0, 1.0)))))


def covariance(information, s2):
    """``s^2 F^-1`` on the determined directions (scaled to a unit diagonal), and the weak directions.

    A direction of the scaled information whose eigenvalue is below ``1e-10``
    of the largest is not determined: its parameters' variances are infinite.

    Parameters
    ----------
    information : ndarray, shape (p, p)
        The weighted information ``F = J^T J``.
    s2 : float
        The weighted residuals' variance per degree of freedom.

    Returns
    -------
    cov : ndarray, shape (p, p)
    weak : list of ndarray, shape (p,)
        Unit directions (in the parameters scaled to a unit diagonal of ``F``) not determined.
    """
    d = np.sqrt(np.maximum(np.diag(information), 1e-300))
    scaled = information / np.outer(d, d)
    lam, u = np.linalg.eigh(scaled)
    weak_mask = lam < 1e-10 * lam[-1]
    keep = ~weak_mask
    inverse = (u[:, keep] / lam[keep]) @ u[:, keep].T
    cov = s2 * inverse / np.outer(d, d)
    touched = np.abs(u[:, weak_mask]).max(axis=1) > 1e-3 if weak_mask.any() else np.zeros(len(d), dtype=bool)
    cov[touched, :] = np.inf
    cov[:, touched] = np.inf
    return cov, [u[:, k] for k in np.flatnonzero(weak_mask)]


def weak_directions(information, s2, scale):
    """The directions the data do not determine, and those they determine worse than ``scale``.

    The first are :func:`covariance`'s; the others the eigenvectors of the
    covariance scaled by ``scale`` (``diag(1/scale) cov diag(1/scale)``, over
    the parameters of finite variance) whose eigenvalue exceeds one: along
    them the one-sigma uncertainty is beyond what counts as determined.

    Parameters
    ----------
    information : ndarray, shape (p, p)
    s2 : float
    scale : ndarray, shape (p,)
        What counts as determined, per parameter (``inf``: never poorly determined alone).

    Returns
    -------
    list of (ndarray (p,), float)
        Each direction (unit, in the scaled parameters) and its scaled
        one-sigma uncertainty (``inf`` where not determined), worst first.
    """
    cov, weak = covariance(information, s2)
    out = [(v, np.inf) for v in weak]
    finite = np.isfinite(np.diag(cov))
    if finite.any():
        inv_scale = np.where(np.isfinite(scale), 1.0 / scale, 0.0)[finite]
        lam, u = np.linalg.eigh(cov[np.ix_(finite, finite)] * np.outer(inv_scale, inv_scale))
        for k in np.flatnonzero(lam > 1.0)[::-1]:
            v = np.zeros(len(scale))
            v[finite] = u[:, k]
            out.append((v, float(np.sqrt(lam[k]))))
    return out


def describe(names, direction, size=np.inf, source="these poses", up_to=False):
    """A weak direction in words: the parameters it mixes and what to record.

    Parameters
    ----------
    names : sequence of str
        The parameters (``m``, ``com_x``, ``I_Ixx``, ``c_fz``, ``gravity_1``, ``mount_x``, ...).
    direction : ndarray, shape (p,)
        The direction; its components above 0.2 are named.
    size : float
        Its scaled one-sigma uncertainty (:func:`weak_directions`): ``inf``, not determined.
    source : {"these poses", "this log"}
        What the data are.
    up_to : bool
        ``size`` is the largest of several directions said together.

    Returns
    -------
    str
    """
    big = [names[i] for i in np.argsort(-np.abs(direction)) if abs(direction[i]) > 0.2]
    parts = list(dict.fromkeys(_PRETTY.get(n, n) for n in big))
    they = "they turn" if source == "these poses" else "it turns"
    if not np.isfinite(size):
        verb = "is not determined" if len(parts) == 1 else "are not separated"
    else:
        verb = (f"{'is' if len(parts) == 1 else 'are'} poorly determined ({'up to ' if up_to else ''}{size:.2g} "
                "times what counts as determined)")
    if all(n.startswith("I_") for n in big):
        advice = f"{they} the tool too little; turn it faster, about more axes"
    else:
        advice = (f"{they} gravity through too few directions in the sensor frame; tilt the tool about another axis "
                  "(see the next poses)")
    return f"{_joined(parts)} {verb} by {source}: {advice}"


def _joined(parts):
    """Parts in words, a shared prefix said once: "the inertia's Ixx and Iyz", "the mass and the offset's fz"."""
    groups = {}
    for part in parts:
        prefix = next((p for p in _PREFIXES if part.startswith(p)), part)
        groups.setdefault(prefix, []).append(part[len(prefix):] if prefix != part else "")
    said = [prefix + _and(rest) if rest != [""] else prefix for prefix, rest in groups.items()]
    return _and(said)


def _and(items):
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def in_words(names, found, source="these poses"):
    """The directions of :func:`weak_directions` in words (:func:`describe`), those of the inertia alone in one line.

    Parameters
    ----------
    names : sequence of str
    found : list of (ndarray, float)
        Directions and their scaled uncertainties, worst first.
    source : {"these poses", "this log"}

    Returns
    -------
    list of str
    """
    alone = [all(names[i].startswith("I_") for i in np.flatnonzero(np.abs(v) > 0.2)) for v, _ in found]
    lines = [describe(names, v, size, source) for (v, size), inertia in zip(found, alone) if not inertia]
    if any(alone):
        together = np.max([np.abs(v) for (v, _), inertia in zip(found, alone) if inertia], axis=0)
        worst = max(size for (_, size), inertia in zip(found, alone) if inertia)
        lines.append(describe(names, together, worst, source, up_to=sum(alone) > 1))
    return lines


def effect_sd(J, cov, gains):
    """The largest standard deviation of the forces and of the torques a covariance leaves in predicted readings,
    eq. (E1) of :mod:`fmscal.observers.payload._effect`: ``(forces N, torques N m)``.

    Parameters
    ----------
    J : ndarray, shape (K, 6, p)
        The predicted reading's rows (reading order) at ``K`` attitudes.
    cov : ndarray, shape (p, p)
        The parameters' covariance; infinite where not determined (a row that reaches it: infinite).
    gains : ndarray, shape (6,)
        The channels' gains (the compensated wrench is ``diag(gains)`` times the corrected reading).

    Returns
    -------
    ndarray, shape (2,)
    """
    finite = np.isfinite(np.diag(cov))
    C = np.where(np.outer(finite, finite), cov, 0.0)
    var = np.sum((J @ C) * J, axis=2)
    reaches = np.abs(J[:, :, ~finite]).max(axis=2) > 0 if (~finite).any() else np.zeros(var.shape, dtype=bool)
    sd = np.where(reaches, np.inf, np.sqrt(np.maximum(var, 0.0))) * gains
    return np.array([sd[:, 3:].max(), sd[:, :3].max()])


def _candidates(references, labels):
    """Poses the user can reach: turns of :data:`TURNS` about a sensor axis from each reference attitude.

    Returns
    -------
    list of (str, ndarray (3, 3))
        Each described in words and as the tracked frame's attitude.
    """
    out = []
    for label, Rk in zip(labels, references):
        for i, axis in enumerate(_AXES):
            for angle in TURNS:
                turn = rotation(np.radians(angle) * np.eye(3)[i])
                out.append((f"from {label}, turn the tool {angle:+g} degrees about its {axis} axis", Rk @ turn))
    return out


def next_poses(model, theta, information, weights, s2, references, labels, attitudes, tolerance, rows=1.0, held="",
               count=3, widened=None):
    """The candidate poses that most lower the payload's effect on the compensated wrench, best first, eq. (N1).

    Each candidate is scored by the largest standard deviation the payload would leave in the compensated
    wrench (eq. E1 of :mod:`fmscal.observers.payload._effect`) over ``attitudes`` (the cone's) and the pose
    itself, forces and torques each over their tolerance, with the covariance the fit would have with the
    pose's rows added (eq. N1; the model-based ``s^2 F^-1``). A pose outside the cone widens it, and the
    payload is then promised over the wider cone: with ``widened``, the best ``3 count`` candidates are scored
    again over the attitudes it gives for each (the cone the data would span with the pose).

    Parameters
    ----------
    model : fmscal.observers.payload._static_fit._Model
        Its ``jacobian(theta, R)`` gives a held pose's rows, its ``channel_gains`` the gains.
    theta : ndarray, shape (p,)
        ``(m, com, c, angles, gains)``.
    information : ndarray, shape (p, p)
        The fit's weighted information over ``theta``.
    weights : ndarray, shape (6,)
        Each reading channel's weight.
    s2 : float
        The weighted residuals' variance per degree of freedom.
    references : ndarray, shape (K, 3, 3)
        The attitudes the turns start from.
    labels : sequence of str
        Their names in words ("pose 3", "the attitude at t = 4.0 s").
    attitudes : ndarray, shape (A, 3, 3)
        The attitudes the effect is taken over (:func:`fmscal.observers.payload._effect.cone_attitudes`).
    tolerance : ndarray, shape (2,)
        N, N m.
    widened : callable, optional
        ``widened(R)``: the attitudes of the cone the data would span with the pose ``R`` added (A', 3, 3).
    rows : float
        How many times a held pose's rows count.
    held : str
        Words appended to each turn (how long to hold it).
    count : int

    Returns
    -------
    list of str
        Each with the factor by which the effect falls; only poses that lower it by more than 1 % (or make it
        finite where it is not): empty when no single pose would.
    """
    gains = model.channel_gains(theta)
    p = len(theta)
    J_cone = model.jacobian(theta, R=attitudes).reshape(len(attitudes), 6, p)

    def score(cov, J_pose=None, J_over=None):
        J = J_cone if J_over is None else J_over
        J = J if J_pose is None else np.concatenate([J, J_pose[None]])
        return float(np.max(effect_sd(J, cov, gains) / tolerance))

    worst_now = score(covariance(information, s2)[0])
    candidates = _candidates(references, labels)
    rows_each = model.jacobian(theta, R=np.array([Rc for _, Rc in candidates])).reshape(len(candidates), 6, p)
    scored = []
    for (words, Rc), J in zip(candidates, rows_each):                   # each pose's six rows
        Jw = J * weights[:, None]
        cov, _ = covariance(information + rows * Jw.T @ Jw, s2)
        scored.append((score(cov, J), words, cov, J, Rc))
    scored.sort(key=lambda item: item[0])
    if widened is not None:                 # the best again, over the cone the data would span with each
        best = scored[:3 * count]
        over = [model.jacobian(theta, R=widened(Rc)).reshape(-1, 6, p) for _, _, _, _, Rc in best]
        scored = sorted([(score(cov, J, J_over), words, cov, J, Rc)
                         for (_, words, cov, J, Rc), J_over in zip(best, over)], key=lambda item: item[0])
    best = []
    for worst, words, *_ in scored:
        if words in (w for _, w in best):
            continue
        if (np.isfinite(worst_now) and worst >= 0.99 * worst_now) or not np.isfinite(worst):
            break                           # sorted: no later pose lowers it, or none makes it finite
        best.append((worst, words))
        if len(best) == count:
            break
    return [f"{words}{held} (the payload's largest effect on the compensated wrench {_ratio(worst_now, worst)})"
            for worst, words in best]


def _ratio(before, after):
    if not np.isfinite(before):
        return "becomes finite"
    return f"falls to {after / before:.0%} of what it is"
