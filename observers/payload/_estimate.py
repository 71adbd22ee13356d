"""What a payload fit reports, and its file: :class:`PayloadEstimate` (``fmscal identify-payload --save``).

Gravity, the sensor's mounting and what a fit records of the reading (its sign, its noise, its gains) are
fields the payload fit of a log and the static fit of a pose table share (``_Rotations``); the payload in the
tracked frame's axes (:meth:`PayloadEstimate.tracked`) is what ``fmscal calibrate --payload`` takes, and what
the file holds.

The covariance of a payload (:attr:`PayloadEstimate.cov`) is over the sixteen parameters
:data:`PAYLOAD_PARAMETERS`: the mass, the centre of mass, the inertia about it and the offset. A fit
estimates other parameters (a log's ``pi = (m, h = m com, I_O)`` and ``c = S b``; a table's ``m``, ``com``,
``c`` and the angles of gravity and the mounting); their covariance ``C`` is taken to these by the
Jacobian ``T`` of the map (the delta method)::

    cov = T C T^T                                                                           (E1)

A parameter the fit did not determine has an infinite variance: every output that depends on it
(``T_ij != 0``) gets an infinite row and column, the rest is (E1) over the determined ones; the inertia of
held poses, which a table's fit does not estimate at all, is infinite too. Turned into the tracked frame's
axes (:meth:`PayloadEstimate.tracked`) by (E1) again, ``T = blockdiag(1, M, L(M), I_6)`` with ``L(M)`` the
linear map of the inertia's six entries under ``I -> M I M^T`` (eq. E2).
"""

import copy
import datetime
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fmscal.plant.io import READINGS, atomic_write_text, check_gravity, not_a_file
from fmscal.plant.numerics import FmscalError, numbers_only
from fmscal.plant.physics import GRAVITY, INERTIA_NAMES, inertia_matrix

__all__ = ["PayloadEstimate", "PayloadFileError", "PAYLOAD_FORMAT", "PAYLOAD_FORMATS", "PAYLOAD_PARAMETERS",
           "NOISE_OF", "propagate_covariance", "inertia_turn"]

#: The format tag of a saved payload estimate (:meth:`PayloadEstimate.save`).
PAYLOAD_FORMAT = "fmscal-payload/2"
#: The formats :meth:`PayloadEstimate.load` reads: ``/1`` (mass, centre of mass, inertia, gravity where
#: estimated) and ``/2`` (everything compensation needs, with the covariance).
PAYLOAD_FORMATS = ("fmscal-payload/1", PAYLOAD_FORMAT)
#: The parameters of :attr:`PayloadEstimate.cov`, in its order: mass (kg), centre of mass (m), the inertia
#: about it (kg m^2, :data:`fmscal.plant.physics.INERTIA_NAMES`), the offset ``b`` (N m, N; reading order).
PAYLOAD_PARAMETERS = ("mass", "com_x", "com_y", "com_z", *INERTIA_NAMES, "b_tx", "b_ty", "b_tz", "b_fx", "b_fy", "b_fz")
#: What :attr:`PayloadEstimate.noise_sd` is the noise of: one sample of a log's reading, or one row of a
#: pose table (a held pose's reading averaged over its samples).
NOISE_OF = ("sample", "pose")
#: The rows of the inertia in :data:`PAYLOAD_PARAMETERS`.
INERTIA_ROWS = range(4, 10)
#: A payload file is a few kB; anything above this is refused unread.
_MAX_FILE_BYTES = 1 << 20
#: How far a saved standard deviation may sit from the square root of its variance in ``cov`` (relative):
#: both are written from one computation, so only an edit moves them apart.
_STD_RTOL = 1e-6


def _angle_deg(R):
    """The angle of a rotation matrix, degrees."""
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))))


def _axis(M):
    """The unit axis of the rotation ``M`` (any unit vector for no rotation)."""
    v = np.array([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]])
    if np.linalg.norm(v) < 1e-12:
        _, u = np.linalg.eigh(M + M.T)
        return u[:, -1]
    return v / np.linalg.norm(v)


def propagate_covariance(T, cov, unknown=()):
    """``T cov T^T``, eq. (E1), with infinite variances carried to every output that depends on them.

    Parameters
    ----------
    T : ndarray, shape (k, p)
        The Jacobian of the ``k`` outputs in the ``p`` parameters.
    cov : ndarray, shape (p, p)
        The parameters' covariance; a parameter with a non-finite variance is undetermined.
    unknown : sequence of int
        Outputs undetermined whatever ``cov`` says (not estimated at all).

    Returns
    -------
    ndarray, shape (k, k)
        Infinite in the rows and columns of the outputs that depend on an undetermined parameter
        (``T_ij != 0``) or are ``unknown``.
    """
    T, cov = np.asarray(T, dtype=float), np.asarray(cov, dtype=float)
    bad = ~np.isfinite(np.diag(cov))
    out = T @ np.where(np.outer(~bad, ~bad), cov, 0.0) @ T.T
    infinite = np.any(T[:, bad] != 0, axis=1)
    infinite[list(unknown)] = True
    out[infinite, :] = np.inf
    out[:, infinite] = np.inf
    return out


def inertia_turn(M):
    """``L(M)``: the inertia's six entries (:data:`fmscal.plant.physics.INERTIA_NAMES`) under ``I -> M I M^T``.

    Linear in the entries, so a matrix, eq. (E2): ``entries(M I M^T) = L(M) entries(I)``.

    Parameters
    ----------
    M : array_like, shape (3, 3)

    Returns
    -------
    ndarray, shape (6, 6)
    """
    M = np.asarray(M, dtype=float)
    L = np.empty((6, 6))
    for k, unit in enumerate(np.eye(6)):
        turned = M @ inertia_matrix(unit) @ M.T
        L[:, k] = [turned[0, 0], turned[1, 1], turned[2, 2], turned[0, 1], turned[0, 2], turned[1, 2]]
    return L


@dataclass(kw_only=True)
class _Rotations:
    """Gravity, the sensor's mounting and what a fit records of the reading: the fields both payload fits share.

    Attributes
    ----------
    gravity : ndarray, shape (3,), or None
        Gravity in the pose frame, m/s^2, where the fit estimated its direction (None otherwise: ``gravity_given``).
    gravity_std_deg : float or None
        One-sigma uncertainty of its direction about each of the two axes across it (their rms), degrees.
    gravity_given : ndarray, shape (3,), or None
        The gravity the fit took as given (its direction not estimated), pose frame, m/s^2; None where estimated
        or not recorded.
    gravity_std : float or None
        One-sigma uncertainty of gravity's size, m/s^2, where it was measured; None: its size taken as given.
    mounting : ndarray, shape (3, 3), or None
        The sensor's axes on the tracked frame (sensor vectors to tracked-frame vectors).
    mounting_deg, mounting_std_deg : float or None
        The mounting's angle, and the one-sigma uncertainty of its rotation about each axis (their rms), degrees.
    mounting_axis : ndarray, shape (3,), or None
        The mounting's unit axis (tracked-frame axes).
    noise_sd : ndarray, shape (6,), or None
        The noise the fit weighed the corrected reading ``sigma S w_hat`` by, N m and N, reading order: of one
        sample of a log, or of one row of a table (``noise_of``); the fit's residual scatter, so what the model
        leaves is in it too.
    gains : ndarray, shape (6,), or None
        The reading's gains relative to ``S``, per channel: ``w = diag(gains) S (sigma w_hat - b)``; None where
        not estimated (all one).
    axes : {"sensor", "tracked"}
        The axes the centre of mass, the inertia and their covariance are in: the sensor's (a fit's) or the
        tracked frame's (:meth:`tracked`, and a file's).
    """

    gravity: np.ndarray = None
    gravity_std_deg: float = None
    gravity_given: np.ndarray = None
    gravity_std: float = None
    mounting: np.ndarray = None
    mounting_deg: float = None
    mounting_std_deg: float = None
    mounting_axis: np.ndarray = None
    noise_sd: np.ndarray = None
    gains: np.ndarray = None
    axes: str = "sensor"

    @property
    def gravity_used(self):
        """Gravity in the pose frame the payload was weighed under, m/s^2: the estimated one, else the one
        given, else (neither recorded) :data:`fmscal.plant.physics.GRAVITY`."""
        for g in (self.gravity, self.gravity_given, GRAVITY):
            if g is not None:
                return np.asarray(g, dtype=float)

    def payload_covariance(self):
        """The covariance over :data:`PAYLOAD_PARAMETERS` in :attr:`axes`, or None where not recorded."""
        return self.cov

    def tracked(self):
        """The payload in the axes of the frame the poses track: what ``calibrate`` takes (a :class:`PayloadEstimate`).

        ``calibrate`` estimates ``S`` in full, which absorbs the sensor's
        mounting ``M`` (sensor axes to the tracked frame's), so it works in
        the tracked frame's axes: the centre of mass ``M com``, the inertia
        ``M I M^T`` and the covariance turned with them by (E1) with
        ``T = blockdiag(1, M, L(M), I_6)`` (eq. E2; the offset is the
        reading's, not turned), the standard deviations its diagonal's roots.
        The mounting is kept (:attr:`mounting`, the identity where it was
        not estimated), with gravity, the reading's sign, noise and gains.
        Without a covariance (an estimate made by hand), the variances of the
        turned vector's components ``(M * M) var``, the inertia's dropped
        under a mounting. An estimate already in the tracked axes: a copy.

        Returns
        -------
        PayloadEstimate
        """
        if self.axes == "tracked":
            return copy.deepcopy(self)
        M = np.eye(3) if self.mounting is None else np.asarray(self.mounting, dtype=float)
        L = inertia_turn(M)
        inertia = None if self.inertia is None else L @ np.asarray(self.inertia, dtype=float)
        cov = self.payload_covariance()
        if cov is not None:
            T = np.zeros((16, 16))
            T[0, 0], T[1:4, 1:4], T[4:10, 4:10], T[10:, 10:] = 1.0, M, L, np.eye(6)
            cov = propagate_covariance(T, cov)
            std = np.sqrt(np.maximum(np.diag(cov), 0))
            mass_std, com_std = float(std[0]), std[1:4]
            inertia_std = None if inertia is None else std[4:10]
        else:
            mass_std = float(self.mass_std)
            com_std = np.sqrt((M * M) @ np.square(np.asarray(self.com_std, dtype=float)))
            inertia_std = self.inertia_std if self.mounting is None else None     # a tensor's needs its covariance
        return PayloadEstimate(mass=float(self.mass), mass_std=mass_std, com=M @ np.asarray(self.com, dtype=float),
                               com_std=com_std, inertia=inertia, inertia_std=inertia_std, b=self.b, b_std=self.b_std,
                               residual_rms=self.residual_rms, warnings=list(self.warnings),
                               converged=bool(self.converged), payload_determined=bool(self.payload_determined),
                               cone_deg=self.cone_deg, undetermined=list(self.undetermined),
                               next_poses=list(self.next_poses), gravity=self.gravity,
                               gravity_std_deg=self.gravity_std_deg, gravity_given=self.gravity_given,
                               gravity_std=self.gravity_std, mounting=M, mounting_deg=self.mounting_deg,
                               mounting_std_deg=self.mounting_std_deg, mounting_axis=self.mounting_axis,
                               noise_sd=self.noise_sd, gains=self.gains, reading=self.reading,
                               noise_of=self.noise_of, inertia_reason=self.inertia_reason, cov=cov, axes="tracked",
                               gains_std=self.gains_std, effect=self.effect, tolerance=self.tolerance,
                               why_undetermined=self.why_undetermined, notes=list(self.notes))

    def save(self, path):
        """Write the payload, in the tracked frame's axes (:meth:`tracked`), as JSON: everything compensation needs.

        The file, format ``fmscal-payload/2`` (:data:`PAYLOAD_FORMAT`)::

            {"format": "fmscal-payload/2", "axes": "tracked",
             "mass": kg, "mass_std": kg, "com": [x, y, z], "com_std": [...],
             "inertia": [Ixx, Iyy, Izz, Ixy, Ixz, Iyz] or null, "inertia_std": [...] or null,
             "inertia_note": why the inertia is null, or null,
             "b": [tx, ty, tz, fx, fy, fz], "b_std": [...],
             "gravity": [gx, gy, gz], "gravity_std_deg": degrees or null, "gravity_std": m/s^2 or null,
             "mounting": [[...], [...], [...]], "mounting_std_deg": degrees or null,
             "reading": "reaction" or "load", "noise_sd": [6 numbers], "noise_of": "sample" or "pose",
             "gains": [6 numbers] or null,
             "parameters": ["mass", "com_x", ..., "b_fz"], "cov": 16 rows of 16 (numbers or null), or null,
             "cone_deg": degrees or null, "converged": bool, "warnings": [...], "date": "..."}

        ``com`` is the centre of mass and ``inertia`` the inertia about it
        in the tracked frame's axes, m and kg m^2 (``calibrate --payload``
        takes them as they are; the sensor's own axes are ``M^T com`` and
        ``M^T I M``); ``mounting`` is ``M``, the sensor's axes on the tracked
        frame (sensor vectors to tracked-frame vectors; the identity, with
        ``mounting_std_deg`` null, where it was not estimated). ``b`` is the
        offset in ``w = diag(gains) S (sigma w_hat - b)`` (reading order,
        N m and N) with ``sigma`` of ``reading``. ``gravity`` is the pose
        frame's gravity the payload was weighed under: estimated where
        ``gravity_std_deg`` is a number, given where it is null;
        ``gravity_std``, its size's uncertainty, null where it was not
        measured. ``noise_sd`` is :attr:`noise_sd`, of one sample or of one
        held pose's row (``noise_of``). ``cov`` is :attr:`PayloadEstimate.cov`
        over ``parameters`` (:data:`PAYLOAD_PARAMETERS`) in the same axes;
        JSON holds no infinity, so an undetermined parameter (the inertia
        where it is null) has its whole row and column null: an infinite
        variance and no correlation. A fit's estimate holds everything; one
        made by hand may lack the covariance and the noise (``cov`` and
        ``noise_sd`` null: not recorded). Written atomically.

        Raises
        ------
        FmscalError
            The payload is not determined (``payload_determined`` False): the message gives
            ``why_undetermined``. The offset is not determined, or the estimate holds no offset or sign (one
            read from a ``/1`` file).
        """
        if not self.payload_determined:
            raise FmscalError("the payload is not determined: no payload to save ("
                              + (self.why_undetermined or "see the warnings") + ")")
        t = self.tracked()
        missing = [name for name in ("b", "b_std", "reading") if getattr(t, name) is None]
        if missing:
            raise FmscalError(f"the payload estimate holds no {', '.join(missing)} (read from a format /1 file?): a "
                              "payload file needs them; identify the payload again")
        if not np.all(np.isfinite(t.b_std)):
            raise FmscalError("the offset is not separated from the weight: no payload to save (turn gravity "
                              "through more directions in the sensor frame)")

        def listed(v):
            return None if v is None else [float(x) for x in np.ravel(v)]
        document = {"format": PAYLOAD_FORMAT, "axes": "tracked", "mass": t.mass, "mass_std": t.mass_std,
                    "com": listed(t.com), "com_std": listed(t.com_std), "inertia": listed(t.inertia),
                    "inertia_std": None if t.inertia is None else listed(t.inertia_std),
                    "inertia_note": None if t.inertia is not None else (t.inertia_reason or "not determined"),
                    "b": listed(t.b), "b_std": listed(t.b_std), "gravity": listed(t.gravity_used),
                    "gravity_std_deg": None if t.gravity is None else _number(t.gravity_std_deg),
                    "gravity_std": _number(t.gravity_std), "mounting": np.asarray(t.mounting, dtype=float).tolist(),
                    "mounting_std_deg": _number(t.mounting_std_deg), "reading": t.reading,
                    "noise_sd": listed(t.noise_sd), "noise_of": t.noise_of, "gains": listed(t.gains),
                    "parameters": list(PAYLOAD_PARAMETERS),
                    "cov": None if t.cov is None else [[float(v) if np.isfinite(v) else None for v in row]
                                                       for row in np.asarray(t.cov, dtype=float)],
                    "cone_deg": _number(t.cone_deg), "converged": bool(t.converged), "warnings": list(t.warnings),
                    "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
        atomic_write_text(path, json.dumps(document, indent=1, allow_nan=False) + "\n")

    def rotations_dict(self):
        """The six fields as JSON-ready numbers and lists (None where not estimated)."""
        return {"gravity": None if self.gravity is None else [float(v) for v in self.gravity],
                "gravity_std_deg": self.gravity_std_deg,
                "mounting": None if self.mounting is None else np.asarray(self.mounting).tolist(),
                "mounting_deg": self.mounting_deg, "mounting_std_deg": self.mounting_std_deg,
                "mounting_axis": None if self.mounting_axis is None else [float(v) for v in self.mounting_axis]}


def _number(v):
    """``float(v)``, or None for None."""
    return None if v is None else float(v)


@dataclass
class PayloadEstimate(_Rotations):
    """The payload's mass properties and the sensor's offset, with one-sigma uncertainties and their covariance.

    Attributes
    ----------
    mass, mass_std : float
        kg.
    com, com_std : ndarray, shape (3,)
        Centre of mass in the sensor frame (the tracked frame's axes where :attr:`axes` says so), m.
    inertia, inertia_std : ndarray, shape (6,), or None
        Inertia about the centre of mass, the same axes (:data:`INERTIA_NAMES`),
        kg m^2; None where the log does not determine it (:attr:`inertia_reason` says why).
    b, b_std : ndarray, shape (6,)
        The sensor's offset in ``w = S (w_hat - b)``, reading order, N m and N.
    residual_rms : ndarray, shape (6,)
        Of the fit, per channel of the corrected reading, N m and N.
    warnings : list of str
        What the log did not determine, in words a user acts on.
    converged : bool
        Every group (mass, centre of mass, inertia, offset) determined.
    payload_determined : bool
        The payload (mass, centre of mass, offset, force gains) determined by its effect on the compensated
        wrench: within ``tolerance`` over the cone of attitudes the data span (eq. E3 of
        :mod:`fmscal.observers.payload._effect`).
    block : float or None
        Length of the blocks of time of the cluster-robust covariance, s
        (:func:`fmscal.observers.batch.block_length`).
    cone_deg : float or None
        Half-angle of the cone of gravity directions the log holds in the sensor frame, degrees.
    undetermined : list of str
        The parameters the log determines poorly or not at all, in words.
    next_poses : list of str
        The held poses to record next, best first, as a table's (:mod:`fmscal.observers.payload._coverage`).
    reading : {"reaction", "load"} or None
        The reading's sign convention the fit used (None: not recorded, a ``/1`` file).
    noise_of : {"sample", "pose"} or None
        What :attr:`noise_sd` is the noise of (:data:`NOISE_OF`).
    inertia_reason : str or None
        Why the inertia is None, in words.
    cov : ndarray, shape (16, 16), or None
        Covariance over :data:`PAYLOAD_PARAMETERS` (mass, centre of mass, inertia, offset) in the axes of
        :attr:`com`, eq. (E1); an undetermined parameter's row and column infinite. None: not recorded.
    gravity, gravity_std_deg, gravity_given, gravity_std, mounting, mounting_deg, mounting_std_deg, mounting_axis
        Gravity and the sensor's mounting (:class:`_Rotations`): gravity in the pose frame (m/s^2) where
        estimated, its direction's uncertainty, the gravity given where not, its size's uncertainty where
        measured; the sensor's axes on the tracked frame (3x3), its angle, uncertainty (degrees) and unit axis.
    noise_sd, gains, axes
        The reading's noise and per-channel gains, and the axes of the estimate (:class:`_Rotations`).
    gains_std : ndarray, shape (6,), or None
        The standard deviations of ``gains``: each reading channel's gain, in
        ``w = diag(gains) S (sigma w_hat - b)`` (eq. P0 of :class:`fmscal.plant.PayloadModel`): the force gains
        relative to their mean (their mean 1), the torque gains 1 (``gains_std`` 0 there); the reading's
        channels, the sensor's axes. None where not estimated (too few poses for them with the rotations asked).
    effect : ndarray, shape (2,), or None
        The payload's largest effect on the compensated wrench within the cone, one standard deviation: forces
        (N), torques (N m) (eq. E2).
    tolerance : ndarray, shape (2,), or None
        What ``effect`` is held to: forces (N), torques (N m); given, or one standard deviation of the
        reading's noise (eq. E4).
    why_undetermined : str or None
        Why the payload is not determined, in one line naming the cone, the gains or the noise.
    notes : list of str
        What was done to the data (rows dropped, a log's held segments taken as a table).
    """

    mass: float
    mass_std: float
    com: np.ndarray
    com_std: np.ndarray
    inertia: np.ndarray
    inertia_std: np.ndarray
    b: np.ndarray
    b_std: np.ndarray
    residual_rms: np.ndarray
    warnings: list = field(default_factory=list)
    converged: bool = False
    payload_determined: bool = False
    block: float = None
    cone_deg: float = None
    undetermined: list = field(default_factory=list)
    next_poses: list = field(default_factory=list)
    reading: str = "reaction"
    noise_of: str = "sample"
    inertia_reason: str = None
    cov: np.ndarray = None
    gains_std: np.ndarray = None
    effect: np.ndarray = None
    tolerance: np.ndarray = None
    why_undetermined: str = None
    notes: list = field(default_factory=list)

    def to_dict(self):
        """The fields as JSON-ready numbers and lists (None where undetermined)."""
        def listed(v):
            return None if v is None else [float(x) for x in np.ravel(v)]
        return {"mass": float(self.mass), "mass_std": float(self.mass_std), "com": listed(self.com),
                "com_std": listed(self.com_std), "inertia": listed(self.inertia),
                "inertia_std": listed(self.inertia_std), "b": listed(self.b), "b_std": listed(self.b_std),
                "residual_rms": listed(self.residual_rms), "warnings": list(self.warnings),
                "converged": bool(self.converged), **self.rotations_dict(),
                "cone_deg": None if self.cone_deg is None else float(self.cone_deg),
                "undetermined": list(self.undetermined), "next_poses": list(self.next_poses),
                "gains": listed(self.gains), "gains_std": listed(self.gains_std), "effect": listed(self.effect),
                "tolerance": listed(self.tolerance), "payload_determined": bool(self.payload_determined),
                "why_undetermined": self.why_undetermined, "notes": list(self.notes)}

    @classmethod
    def load(cls, path):
        """Read a payload file written by :meth:`save` (``fmscal identify-payload --save``).

        Both formats read (:data:`PAYLOAD_FORMATS`). A ``/2`` file gives
        every field :meth:`save` writes, checked: shapes, signs, a rotation
        for the mounting, a covariance that is symmetric, positive
        semi-definite, null exactly in the rows and columns of an inertia
        that is null, and whose diagonal's roots are the standard deviations
        the file gives. A ``/1`` file gives the mass, the centre of mass, the
        inertia and gravity where estimated (else ``gravity_given`` the
        default, as the format said); its offset, sign, noise, mounting and
        covariance, which it never held, are None.

        Returns
        -------
        PayloadEstimate
            In the tracked frame's axes (:attr:`axes` ``"tracked"``),
            ``payload_determined`` True; the residuals, not saved, None.

        Raises
        ------
        PayloadFileError
            A missing file, not JSON, another format, or a value of the wrong shape (one line).
        """
        if not isinstance(path, (str, os.PathLike)):
            raise PayloadFileError(f"a payload path must be a file name; got {type(path).__name__}")
        path = Path(path)
        problem = not_a_file(path)
        if problem is not None:
            raise PayloadFileError(f"{path}: {'no such file' if problem == 'no such file' else 'is ' + problem}")
        if path.stat().st_size > _MAX_FILE_BYTES:
            raise PayloadFileError(f"{path.name}: too large for a payload file; not an fmscal payload")
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as err:
            raise PayloadFileError(f"{path.name}: not a JSON payload file ({str(err)[:80]})") from None
        if not isinstance(data, dict) or data.get("format") not in PAYLOAD_FORMATS:
            got = data.get("format") if isinstance(data, dict) else type(data).__name__
            raise PayloadFileError(f"{path.name}: not an fmscal payload (format {str(got)[:60]!r}; expected "
                                   f"{' or '.join(repr(f) for f in PAYLOAD_FORMATS)})")
        read = _Reader(path.name, data)
        if data.get("axes", "tracked") != "tracked":
            read.fail(f"axes must be \"tracked\" (the payload in the tracked frame's axes, as identify-payload "
                      f"--save writes it); got {str(data.get('axes'))[:40]!r}")
        converged = data.get("converged", False)
        if not isinstance(converged, bool):
            read.fail(f"converged must be true or false; got {str(converged)[:40]!r}")
        mass = float(read.numbers("mass", ()))
        if not mass > 0:
            read.fail(f"mass must be positive; got {mass}")
        warnings = data.get("warnings", [])
        if not isinstance(warnings, list) or not all(isinstance(w, str) for w in warnings):
            read.fail("warnings must be a list of strings")
        if data["format"] != PAYLOAD_FORMAT:
            return read.first_format(cls, mass, converged, warnings)
        return read.second_format(cls, mass, converged, warnings)


class _Reader:
    """The checks of a payload file's fields, each failure one :class:`PayloadFileError` line naming the file."""

    def __init__(self, name, data):
        self.name, self.data = name, data

    def fail(self, message):
        raise PayloadFileError(f"{self.name}: {message}")

    def gravity_size(self, gravity):
        """Gravity's size Earth's, in m/s^2 (:func:`fmscal.plant.io.check_gravity`: a unit named), or :meth:`fail`."""
        try:
            check_gravity(gravity)
        except FmscalError as err:
            self.fail(f"gravity: {err}")

    def numbers(self, key, shape, optional=False, nonnegative=False, positive=False):
        """``data[key]`` as finite numbers of ``shape`` (None for null where ``optional``)."""
        value = self.data.get(key)
        if value is None and optional:
            return None
        if not numbers_only(value):                 # text ("1.2") and true are not numbers
            value = None
        try:
            arr = np.array(value, dtype=float)
        except (TypeError, ValueError):
            arr = np.array(np.nan)
        if arr.shape != shape or not np.all(np.isfinite(arr)):
            self.fail(f"{key} must be {int(np.prod(shape)) or 1} finite number(s)" + (" or null" if optional else ""))
        if positive and not np.all(arr > 0):
            self.fail(f"{key} must be positive; got {np.round(arr, 6).tolist()}")
        if nonnegative and not np.all(arr >= 0):
            self.fail(f"{key} must not be negative; got {np.round(arr, 6).tolist()}")
        return arr

    def text(self, key, choices, optional=False):
        value = self.data.get(key)
        if value is None and optional:
            return None
        if not isinstance(value, str) or value not in choices:
            self.fail(f"{key} must be one of {', '.join(choices)}" + (" or null" if optional else "")
                      + f"; got {str(value)[:40]!r}")
        return value

    def first_format(self, cls, mass, converged, warnings):
        """A ``/1`` file: mass, centre of mass (``rho`` in files written before), inertia, gravity where estimated."""
        legacy = "com" not in self.data and "rho" in self.data
        gravity = self.numbers("gravity", (3,), True)
        if gravity is not None:
            self.gravity_size(gravity)
        return cls(mass=mass, mass_std=float(self.numbers("mass_std", ())),
                   com=self.numbers("rho" if legacy else "com", (3,)),
                   com_std=self.numbers("rho_std" if legacy else "com_std", (3,)),
                   inertia=self.numbers("inertia", (6,), True), inertia_std=self.numbers("inertia_std", (6,), True),
                   b=None, b_std=None, residual_rms=None, warnings=warnings, converged=converged,
                   payload_determined=True, gravity=gravity,
                   gravity_given=np.array(GRAVITY, dtype=float) if gravity is None else None,
                   reading=None, noise_of=None, axes="tracked")

    def second_format(self, cls, mass, converged, warnings):
        """A ``/2`` file: every field :meth:`PayloadEstimate.save` writes, checked."""
        n = self.numbers
        inertia = n("inertia", (6,), True)
        inertia_std = n("inertia_std", (6,), True, nonnegative=True)
        note = self.data.get("inertia_note")
        if inertia is None and inertia_std is not None:
            self.fail("inertia_std must be null where the inertia is")
        if inertia is None and not (isinstance(note, str) and note):
            self.fail("inertia_note must say why the inertia is null")
        gravity = n("gravity", (3,))
        self.gravity_size(gravity)
        gravity_std_deg = n("gravity_std_deg", (), True, nonnegative=True)
        M = n("mounting", (3, 3))
        if not (np.allclose(M @ M.T, np.eye(3), atol=1e-6) and np.linalg.det(M) > 0):
            self.fail("mounting must be a rotation matrix (orthonormal rows, determinant +1)")
        estimate = cls(mass=mass, mass_std=float(n("mass_std", (), nonnegative=True)),
                       com=n("com", (3,)), com_std=n("com_std", (3,), nonnegative=True),
                       inertia=inertia, inertia_std=inertia_std, b=n("b", (6,)),
                       b_std=n("b_std", (6,), nonnegative=True), residual_rms=None, warnings=warnings,
                       converged=converged, payload_determined=True,
                       cone_deg=_number(n("cone_deg", (), True, nonnegative=True)),
                       gravity=gravity if gravity_std_deg is not None else None,
                       gravity_std_deg=_number(gravity_std_deg),
                       gravity_given=gravity if gravity_std_deg is None else None,
                       gravity_std=_number(n("gravity_std", (), True, nonnegative=True)),
                       mounting=M, mounting_deg=_angle_deg(M),
                       mounting_std_deg=_number(n("mounting_std_deg", (), True, nonnegative=True)),
                       mounting_axis=_axis(M), reading=self.text("reading", READINGS),
                       noise_sd=n("noise_sd", (6,), True, positive=True), noise_of=self.text("noise_of", NOISE_OF),
                       gains=n("gains", (6,), True, positive=True),
                       inertia_reason=note if inertia is None else None, axes="tracked")
        estimate.cov = self.covariance(estimate)
        return estimate

    def covariance(self, estimate):
        """``cov`` over ``parameters``: null rows and columns those of a null inertia, symmetric, positive
        semi-definite, its diagonal's roots the standard deviations given; None where ``cov`` is null."""
        if self.data.get("parameters") != list(PAYLOAD_PARAMETERS):
            self.fail(f"parameters must be {list(PAYLOAD_PARAMETERS)} (the order of cov)")
        rows = self.data.get("cov")
        if rows is None:
            return None
        k = len(PAYLOAD_PARAMETERS)
        if not (isinstance(rows, list) and len(rows) == k and all(isinstance(r, list) and len(r) == k for r in rows)
                and all(v is None or numbers_only(v) for r in rows for v in r)):
            self.fail(f"cov must be {k} rows of {k} numbers (null in an undetermined parameter's row and column), "
                      "or null")
        null = np.array([[v is None for v in r] for r in rows])
        unknown = np.zeros(k, dtype=bool)
        if estimate.inertia is None:
            unknown[list(INERTIA_ROWS)] = True
        if not np.array_equal(null, unknown[:, None] | unknown[None, :]):
            self.fail("cov must be null exactly in the rows and columns of an inertia that is null")
        cov = np.array([[np.inf if v is None else float(v) for v in r] for r in rows])
        known = cov[np.ix_(~unknown, ~unknown)]
        if not np.all(np.isfinite(known)):
            self.fail("cov must hold finite numbers (null only where the inertia is null)")
        scale = np.sqrt(np.maximum(np.diag(known), 1e-300))
        corr = known / np.outer(scale, scale)
        if not (np.all(np.diag(known) >= 0) and np.allclose(corr, corr.T, atol=1e-9)
                and np.linalg.eigvalsh((corr + corr.T) / 2)[0] > -1e-8):
            self.fail("cov must be a symmetric positive semi-definite matrix")
        std = np.sqrt(np.diag(cov))
        given = [("mass_std", [estimate.mass_std], std[:1]), ("com_std", estimate.com_std, std[1:4]),
                 ("inertia_std", estimate.inertia_std, std[4:10]), ("b_std", estimate.b_std, std[10:])]
        for key, value, root in given:
            if value is not None and not np.allclose(value, root, rtol=_STD_RTOL, atol=1e-300):
                self.fail(f"{key} disagrees with the square roots of cov's diagonal")
        return cov


class PayloadFileError(FmscalError):
    """A payload file that cannot be used: the message names the problem."""
