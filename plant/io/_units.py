"""Which units a log is in, told from the data: angles in degrees, positions in mm, readings in counts.

The poses imply the wrench that moved the payload (eq. 1 inverted,
:func:`plant.input_matrix`); the raw reading is that wrench through
``S^-1`` (eq. 3). For a sensor read in N m and N, ``S`` is of order one, so
the ratio of the implied wrench to the reading estimates the size of ``S``
channel by channel. A ratio near 1000 on the forces alone says the positions
are in millimetres; near 57 on the moment alone, that theta is in degrees;
both far below one, that the readings are in other units (sensor counts).
"""

from typing import NamedTuple

import numpy as np

from fmscal.plant.physics import input_matrix

__all__ = ["implied_scale", "diagnose_units", "UnitFinding", "COUNTS"]

#: The kind of :class:`UnitFinding` for readings in sensor counts: only the online methods,
#: which start from an ``S0`` of order one, are hurt by it.
COUNTS = "counts"

#: Window over which poses are smoothed before differentiating twice, s.
_WINDOW = 0.05
#: A ratio further than this from 1 (either way) is reported.
_FAR = 30.0


def _coarse(log, window):
    """Poses (interpolated over the measured ones) and mean readings on a grid of step ``window``."""
    k = max(1, int(round(window / log.dt)))
    n = len(log) // k
    if n < 5:
        return None
    t = log.t[:n * k].reshape(n, k).mean(axis=1)
    have = log.has_pose
    pose = np.column_stack([np.interp(t, log.t[have], log.pose[have, j]) for j in range(3)])
    w_hat = log.w_hat[:n * k].reshape(n, k, 3).mean(axis=1)
    return t, pose, w_hat, k * log.dt


def implied_scale(log, payload, window=_WINDOW):
    """Size of the wrench the poses imply against the size of the readings, per channel.

    Parameters
    ----------
    log : plant.Log
    payload : plant.Payload
    window : float
        Poses are taken on a grid of this step (s) before differentiating
        twice (noise on 1 kHz poses would swamp a second difference).

    Returns
    -------
    (float, float) or None
        ``(moment_ratio, force_ratio)``: the standard deviation of the
        moment and of the force magnitude implied by the poses, each over
        that of the reading. About the size of ``S``'s entries for a log in
        SI units; None if the log is too short or does not move.
    """
    coarse = _coarse(log, window)
    if coarse is None:
        return None
    _, pose, w_hat, h = coarse
    acc = np.diff(pose, n=2, axis=0) / h ** 2                # [theta'', X'', Y''] at the inner points
    with np.errstate(all="ignore"):
        G = np.moveaxis(input_matrix(pose[1:-1, 0], payload), -1, 0)      # (N, 3, 3): eq. (1) per sample
        w = np.linalg.solve(G, acc[:, :, None])[:, :, 0]
        w_hat = w_hat[1:-1]
        moment = np.std(w[:, 0]) / np.std(w_hat[:, 0])
        force = np.sqrt(np.var(w[:, 1]) + np.var(w[:, 2])) / np.sqrt(np.var(w_hat[:, 1]) + np.var(w_hat[:, 2]))
    if not (np.isfinite(moment) and np.isfinite(force) and moment > 0 and force > 0):
        return None
    return float(moment), float(force)


class UnitFinding(NamedTuple):
    """A unit the data says is not rad, m, N m, N: what it is, and the one-line message."""

    #: ``"degrees"`` (theta), ``"millimetres"`` (x, y) or :data:`COUNTS` (the readings).
    kind: str
    message: str


def diagnose_units(log, payload):
    """Findings naming units the data says are not rad, m, N m, N.

    Parameters
    ----------
    log : plant.Log
    payload : plant.Payload

    Returns
    -------
    list of UnitFinding
        Empty when the log looks like SI units (or when it cannot tell).
    """
    scale = implied_scale(log, payload)
    if scale is None:
        return []
    moment, force = scale
    if 20 < moment / force < 160 and 1 / _FAR < force < _FAR:
        return [UnitFinding("degrees", f"theta looks like degrees, not radians: the moment the poses imply is "
                f"{moment / force:.0f} times the force's share (57 for degrees); convert theta to rad")]
    # both far, and alike: the readings' scale (x and y in mm scale the force only, the moment in part)
    if force > _FAR and moment > _FAR and 0.6 < moment / force < 1.7:
        return [UnitFinding(COUNTS, f"the readings are about {1 / np.sqrt(force * moment):.3g} times the wrench "
                f"the poses imply: S's entries will be near {np.sqrt(force * moment):.3g} (readings not in N m and "
                f"N?); methods that start from S0 of order one (adaptive, high-gain, ekf) may not reach it: use "
                f"least-squares, or give the readings in N m and N")]
    if force > _FAR:
        return [UnitFinding("millimetres", f"x and y look like millimetres, not metres: the forces the poses imply "
                f"are {force:.3g} times the readings (1000 for mm; else the readings are not in N); convert x and y "
                f"to m")]
    if force < 1 / _FAR and moment < 1 / _FAR:
        size = np.sqrt(force * moment)
        return [UnitFinding(COUNTS, f"the readings are about {1 / size:.3g} times the wrench the poses imply: S's "
                f"entries will be near {size:.3g} (readings in sensor counts?); methods that start from S0 of "
                f"order one (adaptive, high-gain, ekf) may not reach it: use least-squares, or give the readings "
                f"in N m and N")]
    return []
