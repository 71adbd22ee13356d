"""What compensation runs on: a calibration of ``S``, or a payload file with the sensor's own ``S``.

Most wrist sensors come calibrated by their maker: ``S`` is the identity (or the maker's matrix), and what a user
identifies is the tool (``fmscal identify-payload``, :class:`fmscal.observers.payload.PayloadEstimate`): its mass,
centre of mass, inertia where the motion determined it, the sensor's offset, gravity, the sensor's mounting, the
reading's sign, the reading's noise, per-channel gains, and the covariance of them all. Compensation takes either:

- a :class:`fmscal.plant.Calibration` (``fmscal calibrate --save``): its ``S``, offset, payload, gravity, latency,
  noise model and the covariance of ``[S | c]``, as before;
- a :class:`~fmscal.observers.payload.PayloadEstimate` (``identify-payload --save``): the calibration it stands for
  is, with ``M`` the sensor's mounting on the tracked frame (sensor axes to tracked axes; the identity where it was
  not estimated), ``G = diag(gains)`` and ``S_0`` the sensor's own matrix (the identity, or a calibration's given
  with it)::

      S = blockdiag(M, M) G S_0,   b, the reading's sign, gravity: the file's                      (K1)

  so that ``S (sigma w_hat - b)`` is the wrench in the tracked frame's axes, where the file's payload is
  (:meth:`~fmscal.observers.payload.PayloadEstimate.tracked`) and the poses move; the output is turned back into
  the sensor's own axes (:attr:`Setup.axes`, (C8)).

**The payload's uncertainty** is carried into the compensated wrench's covariance. The payload's wrench is linear
in the inertial parameters ``pi = (m, h = m c, I_O)`` (Newton-Euler at the sensor point, the regressor ``Y`` of
:func:`fmscal.plant.physics.regressor`): with ``theta = (m, c, I_c)`` the file's parameters, ``J = d pi / d theta``
(``h = m c``, ``I_O = I_c + m (|c|^2 I - c c^T)``) and the offset's ``d w_e / d b = S``::

    Cov_payload = [Y J, S] Sigma [Y J, S]^T                                                         (K2)

``Sigma`` the covariance of ``(theta, b)`` (the file's, its undetermined entries replaced as below; the offset's
block left out where the offset's tracker carries it). It is the fourth term of (C3).

**An inertia the poses did not determine** (held attitudes never do) is taken from a bound, not left out: a body
whose mass lies within ``r`` of its centre of mass has principal moments in ``[0, m r^2]``; the inertia is taken
as ``m r^2 / 3`` on each axis, each of its diagonal entries with sd ``m r^2 / 3`` and its products with sd
``m r^2 / 6``, uncorrelated (K3). ``r`` is the tool's radius (``tool_radius``, m), by default
:data:`TOOL_RADIUS_FACTOR` times the centre of mass's distance from the sensor, at least
:data:`MIN_TOOL_RADIUS`. The motion's inertial share is then in the covariance (K2): slow motion costs little, a
fast turn widens the contact test's bound, and a contact is still found where it is beyond that.
"""

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fmscal.plant import Calibration
from fmscal.plant.io import CalibrationFileError, not_a_file
from fmscal.plant.numerics import FmscalError
from fmscal.plant.physics import GRAVITY, NoiseSpec, SpatialPayload, find_model
from fmscal.observers.payload import PAYLOAD_FORMAT, PayloadEstimate, StaticFit

__all__ = ["Setup", "setup", "load_setup", "TOOL_RADIUS_FACTOR", "MIN_TOOL_RADIUS", "payload_jacobian"]

#: How the warning on an inertia the poses did not determine (K3) begins.
INERTIA_NOTE = "the payload's inertia was not determined"
#: (K3): the tool's radius about its centre of mass, by default this many times the centre of mass's distance from
#: the sensor ...
TOOL_RADIUS_FACTOR = 2.0
#: ... and at least this, m.
MIN_TOOL_RADIUS = 0.05


#: What a payload estimate may be: a log's fit or a saved file's (:class:`PayloadEstimate`), a table's
#: (:class:`~fmscal.observers.payload.StaticFit`).
_ESTIMATES = (PayloadEstimate, StaticFit)


class SetupError(FmscalError):
    """What compensation cannot run on: the message names the problem."""


@dataclass
class Setup:
    """A compensation's calibration and what a payload file adds to it.

    Attributes
    ----------
    calibration : plant.Calibration
        ``S``, ``b``, the reading's sign, the payload, gravity, latency, noise model (K1 for a payload file).
    payload : plant.Payload or plant.SpatialPayload, optional
        Replaces the calibration's (checked against its case where the model is built).
    cov : ndarray, shape (16, 16), or None
        A payload file's covariance of ``(m, c, I_c, b)`` in the tracked frame's axes (K2, K3); None otherwise.
    axes : ndarray, shape (3, 3), or None
        The sensor's axes in the frame the compensation runs in (``M^T``: tracked to sensor axes); None: the same.
    pose_noise_known : bool
        The noise model holds the poses' noise (a calibration's); False: estimated from the poses (a payload file).
    inertia_bounded : bool
        The payload's inertia is the bound (K3): compensation learns it from the motion (L1 of
        :mod:`fmscal.analysis._compensate`).
    held_noise : plant.NoiseSpec or None
        The noise of one held pose's reading (a table's payload file): the noise a pose table's rows are checked
        against (:class:`fmscal.analysis.HeldPoses` compensation); None where the file's noise is a sample's.
    warnings : list of str
    source : str
        What it came from, for messages.
    inertia_note : str
        The warning of :attr:`warnings` that says the inertia is the bound (K3), "" where it is not: held poses
        leave it out (:meth:`warnings_for`).
    """

    calibration: Calibration
    payload: object = None
    cov: np.ndarray = None
    axes: np.ndarray = None
    pose_noise_known: bool = True
    inertia_bounded: bool = False
    held_noise: NoiseSpec = None
    warnings: list = field(default_factory=list)
    source: str = "the calibration"
    inertia_note: str = ""

    def warnings_for(self, moves=True):
        """The warnings for a source that moves, or (``moves`` False: held poses) without the inertia's bound,
        which does not enter a static wrench."""
        return [w for w in self.warnings if moves or w != self.inertia_note]


def payload_jacobian(mass, com):
    """``J = d pi / d theta`` (K2): the inertial parameters ``pi = (m, h, I_O)`` against ``theta = (m, c, I_c)``,
    both with the inertia's entries in :data:`fmscal.plant.physics.INERTIA_NAMES` order; shape (10, 10)."""
    c = np.asarray(com, dtype=float)
    J = np.zeros((10, 10))
    J[0, 0] = 1.0
    J[1:4, 0], J[1:4, 1:4] = c, mass * np.eye(3)
    pairs = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))               # Ixx Iyy Izz Ixy Ixz Iyz
    for row, (i, j) in enumerate(pairs):
        J[4 + row, 4 + row] = 1.0
        # I_O[i, j] = I_c[i, j] + m (|c|^2 delta_ij - c_i c_j)
        J[4 + row, 0] = (c @ c if i == j else 0.0) - c[i] * c[j]
        for k in range(3):
            J[4 + row, 1 + k] = mass * ((2 * c[k] if i == j else 0.0) - (c[j] if k == i else 0.0)
                                        - (c[i] if k == j else 0.0))
    return J


def _inertia_bound(mass, com, tool_radius):
    """(K3): the inertia ``m r^2 / 3`` on each axis and its covariance (6, 6); ``r`` the tool's radius."""
    r = tool_radius if tool_radius is not None else max(TOOL_RADIUS_FACTOR * float(np.linalg.norm(com)),
                                                        MIN_TOOL_RADIUS)
    scale = mass * r ** 2
    sd = np.r_[np.full(3, scale / 3), np.full(3, scale / 6)]
    return np.r_[np.full(3, scale / 3), np.zeros(3)], np.diag(sd ** 2), r


def setup(calibration, payload=None, sensor=None, tool_radius=None):
    """What compensation runs on, from what the user gives (module docstring).

    Parameters
    ----------
    calibration : plant.Calibration or observers.payload.PayloadEstimate
        A calibration of ``S``, or a payload file's estimate (K1).
    payload : plant.Payload, plant.SpatialPayload or PayloadEstimate, optional
        With a calibration: replaces its payload (a tool change); an estimate's uncertainty is carried (K2).
    sensor : plant.Calibration, optional
        With a payload estimate: the sensor's own ``S`` (its calibration; default the identity) and latency.
    tool_radius : float, optional
        A payload estimate whose inertia is undetermined: the tool's radius about its centre of mass, m (K3).

    Returns
    -------
    Setup
    """
    if tool_radius is not None and not (isinstance(tool_radius, (int, float)) and np.isfinite(tool_radius)
                                        and tool_radius > 0):
        raise SetupError(f"tool_radius must be a positive number of metres; got {tool_radius!r}")
    if isinstance(calibration, Calibration):
        if sensor is not None:
            raise SetupError("calibration= gives a payload estimate its sensor's S; a calibration holds its own")
        if not isinstance(payload, _ESTIMATES):
            if tool_radius is not None:
                raise SetupError("tool_radius bounds a payload estimate's undetermined inertia; none is given")
            return Setup(calibration, payload=payload)
        tracked = payload.tracked()                         # its payload only: S and b are the calibration's
        tool, theta_cov, note = _tool(tracked, tool_radius)
        cov = np.zeros((16, 16))
        cov[:10, :10] = _with_fit(theta_cov, tracked, slice(0, 10))
        return Setup(calibration, payload=tool, cov=cov, inertia_bounded=tracked.inertia is None,
                     warnings=[note] if note else [], source="the payload file", inertia_note=note)
    if not isinstance(calibration, _ESTIMATES):
        raise SetupError(f"compensate takes a plant.Calibration or a payload estimate (observers.payload."
                         f"PayloadEstimate, or a StaticFit); got {type(calibration).__name__}")
    if payload is not None:
        raise SetupError("payload= replaces a calibration's payload; a payload estimate is the payload itself")
    if sensor is not None and not isinstance(sensor, Calibration):
        raise SetupError(f"calibration= must be a plant.Calibration (the sensor's S); got {type(sensor).__name__}")
    if sensor is not None and find_model(n_w=sensor.size, estimates="mass") is None:
        raise SetupError(f"a payload estimate is a 6-axis sensor's; the calibration given is of a {sensor.size}-axis "
                         "reading")
    estimate = calibration
    if getattr(estimate, "b", None) is None:
        raise SetupError("the payload file holds no offset (written by an fmscal before fmscal-payload/2): identify "
                         "the payload again (fmscal identify-payload --save)")
    tracked = estimate.tracked()
    tool, theta_cov, note = _tool(tracked, tool_radius)
    M = getattr(estimate, "mounting", None)
    M = np.eye(3) if M is None else np.asarray(M, dtype=float)
    gains = getattr(estimate, "gains", None)
    G = np.diag(np.ones(6) if gains is None else np.asarray(gains, dtype=float))
    S0 = np.eye(6) if sensor is None else np.asarray(sensor.S, dtype=float)
    B = np.zeros((6, 6))
    B[:3, :3] = B[3:, 3:] = M
    cov = np.zeros((16, 16))
    cov[:10, :10] = theta_cov
    sd = getattr(estimate, "b_std", None)
    cov[10:, 10:] = np.zeros((6, 6)) if sd is None else np.diag(np.square(np.asarray(sd, dtype=float)))
    cov = _with_fit(cov, tracked, slice(0, 16))
    noise_sd = getattr(estimate, "noise_sd", None)         # a log's fit: of a sample; a table's: of a held pose
    held = None
    if getattr(estimate, "noise_of", "sample") != "sample":
        held = None if noise_sd is None else NoiseSpec(tuple(float(v) for v in noise_sd))
        noise_sd = None
    gravity = getattr(estimate, "gravity_used", None)        # a file's: the estimated, else the given
    gravity = (GRAVITY if estimate.gravity is None else estimate.gravity) if gravity is None else gravity
    cal = Calibration(S=B @ G @ S0, payload=tool, method="payload", b=np.asarray(estimate.b, dtype=float),   # (K1)
                      reading=getattr(estimate, "reading", None) or "reaction",
                      gravity=np.asarray(gravity, dtype=float), latency=0.0 if sensor is None else sensor.latency,
                      noise=None if noise_sd is None else NoiseSpec(tuple(float(v) for v in noise_sd)),
                      converged=bool(estimate.converged))
    return Setup(cal, cov=cov, axes=None if np.allclose(M, np.eye(3)) else M.T, pose_noise_known=False,
                 inertia_bounded=tracked.inertia is None, held_noise=held, warnings=[note] if note else [],
                 source="the payload file", inertia_note=note)


def _with_fit(cov, tracked, rows):
    """``cov`` with the entries the estimate's own covariance (``PayloadEstimate.cov``, the fit's, correlations
    and all; tracked axes) determines put in its place, for the parameters ``rows``: an undetermined inertia keeps
    the bound (K3)."""
    full = getattr(tracked, "cov", None)
    if full is None:
        return cov
    full = np.asarray(full, dtype=float)[rows, rows]
    kept = np.isfinite(np.diag(full))
    if tracked.inertia is None:
        kept[4:10] = False
    both = np.ix_(kept, kept)
    out = cov.copy()
    out[both] = full[both]
    return out


def _tool(t, tool_radius):
    """The payload of an estimate ``t`` in the tracked frame's axes (the bound (K3) for an inertia not determined),
    the covariance of ``theta = (m, c, I_c)`` from its sds, and the inertia's note (the bound's warning, "" where
    the estimate holds an inertia)."""
    com = np.asarray(t.com, dtype=float)
    cov = np.zeros((10, 10))
    cov[0, 0] = float(t.mass_std) ** 2
    cov[1:4, 1:4] = np.diag(np.square(np.asarray(t.com_std, dtype=float)))
    note = ""
    if t.inertia is None:
        inertia, cov[4:, 4:], r = _inertia_bound(t.mass, com, tool_radius)
        note = (f"{INERTIA_NOTE} (held poses): it starts at {inertia[0]:.3g} kg m^2 on each axis with an sd as large, "
                f"the bound of a tool of radius {r:.3g} m about its centre of mass (tool_radius), and is learned from "
                "the motion; its uncertainty is in the covariance")
    else:
        if tool_radius is not None:
            raise SetupError("tool_radius bounds an inertia the payload file does not hold; this one holds it")
        inertia = np.asarray(t.inertia, dtype=float)
        if t.inertia_std is not None:
            cov[4:, 4:] = np.diag(np.square(np.asarray(t.inertia_std, dtype=float)))
    try:
        tool = SpatialPayload(float(t.mass), inertia, com)
    except FmscalError as err:
        raise SetupError(f"the payload file's inertia is not a body's: {str(err).splitlines()[0]}") from None
    return tool, cov, note


def load_setup(path):
    """A calibration or a payload file, told by its format tag: a :class:`fmscal.plant.Calibration` or a
    :class:`fmscal.observers.payload.PayloadEstimate`.

    Raises
    ------
    FmscalError
        A missing file, neither format (one line naming the formats).
    """
    if not isinstance(path, (str, os.PathLike)):
        raise SetupError(f"a calibration or payload file must be a file name; got {type(path).__name__}")
    problem = not_a_file(Path(path))
    if problem is not None:
        raise SetupError(f"{path}: {'no such file' if problem == 'no such file' else 'is ' + problem}")
    tag = None
    try:
        with open(path, encoding="utf-8") as f:
            head = f.read(1 << 20)
        tag = json.loads(head).get("format") if head.lstrip().startswith("{") else None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, AttributeError):
        tag = None
    if isinstance(tag, str) and tag.startswith(PAYLOAD_FORMAT.split("/")[0] + "/"):
        return PayloadEstimate.load(path)
    try:
        return Calibration.load(path)
    except CalibrationFileError as err:
        raise SetupError(f"{Path(path).name}: neither an fmscal calibration (fmscal calibrate --save) nor a payload "
                         f"file (fmscal identify-payload --save): {str(err).splitlines()[0]}") from None
