"""What a payload fit reports, and its file: :class:`PayloadEstimate` (``fmscal identify-payload --save``).

Gravity's direction and the sensor's mounting where a fit estimated them are fields the payload fit of a
log and the static fit of a pose table share (``_Rotations``); the payload in the tracked frame's axes
(:meth:`PayloadEstimate.tracked`) is what ``fmscal calibrate --payload`` takes.
"""

import datetime
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fmscal.plant.io import atomic_write_text, not_a_file
from fmscal.plant.numerics import FmscalError, numbers_only
from fmscal.plant.physics import inertia_matrix

__all__ = ["PayloadEstimate", "PayloadFileError", "PAYLOAD_FORMAT"]

#: The format tag of a saved payload estimate (:meth:`PayloadEstimate.save`).
PAYLOAD_FORMAT = "fmscal-payload/1"
#: A payload file is a few kB; anything above this is refused unread.
_MAX_FILE_BYTES = 1 << 20


@dataclass(kw_only=True)
class _Rotations:
    """Gravity's direction and the sensor's mounting where a fit estimated them (None otherwise).

    Attributes
    ----------
    gravity : ndarray, shape (3,), or None
        Gravity in the pose frame, m/s^2.
    gravity_std_deg : float or None
        One-sigma uncertainty of its direction about each of the two axes across it (their rms), degrees.
    mounting : ndarray, shape (3, 3), or None
        The sensor's axes on the tracked frame (sensor vectors to tracked-frame vectors).
    mounting_deg, mounting_std_deg : float or None
        The mounting's angle, and the one-sigma uncertainty of its rotation about each axis (their rms), degrees.
    mounting_axis : ndarray, shape (3,), or None
        The mounting's unit axis (tracked-frame axes).
    """

    gravity: np.ndarray = None
    gravity_std_deg: float = None
    mounting: np.ndarray = None
    mounting_deg: float = None
    mounting_std_deg: float = None
    mounting_axis: np.ndarray = None

    def tracked(self):
        """The payload in the axes of the frame the poses track: what ``calibrate`` takes (a :class:`PayloadEstimate`).

        ``calibrate`` estimates ``S`` in full, which absorbs the sensor's
        mounting ``M`` (sensor axes to the tracked frame's), so it works in
        the tracked frame's axes: the centre of mass ``M com``, the inertia
        ``M I M^T`` and their uncertainties turned with them (the variances
        of a rotated vector's components: ``(M * M) var``, the correlations
        dropped), the mounting then the identity (None) and gravity as
        estimated. Without an estimated mounting, the same values.

        Returns
        -------
        PayloadEstimate
        """
        M = np.eye(3) if self.mounting is None else np.asarray(self.mounting, dtype=float)
        inertia = getattr(self, "inertia", None)
        inertia_std = getattr(self, "inertia_std", None)
        if inertia is not None:
            I_c = M @ inertia_matrix(inertia) @ M.T
            inertia = np.array([I_c[0, 0], I_c[1, 1], I_c[2, 2], I_c[0, 1], I_c[0, 2], I_c[1, 2]])
        if inertia_std is not None and self.mounting is not None:
            inertia_std = None                 # turning a tensor's uncertainty needs its covariance: not kept
        turn = lambda std: np.sqrt((M * M) @ np.square(np.asarray(std, dtype=float)))  # noqa: E731
        return PayloadEstimate(mass=float(self.mass), mass_std=float(self.mass_std),
                               com=M @ np.asarray(self.com, dtype=float), com_std=turn(self.com_std),
                               inertia=inertia, inertia_std=inertia_std, b=self.b, b_std=self.b_std,
                               residual_rms=self.residual_rms, warnings=list(self.warnings),
                               converged=bool(self.converged), payload_determined=bool(self.payload_determined),
                               cone_deg=self.cone_deg, undetermined=list(self.undetermined),
                               next_poses=list(self.next_poses), gravity=self.gravity,
                               gravity_std_deg=self.gravity_std_deg, gains=self.gains, gains_std=self.gains_std,
                               effect=self.effect, tolerance=self.tolerance, why_undetermined=self.why_undetermined,
                               notes=list(self.notes))

    def save(self, path):
        """Write the payload, in the tracked frame's axes (:meth:`tracked`), as JSON for ``fmscal calibrate --payload``.

        The file, format ``fmscal-payload/1`` (:data:`PAYLOAD_FORMAT`)::

            {"format": "fmscal-payload/1", "axes": "tracked", "mass": kg, "mass_std": kg,
             "com": [x, y, z], "com_std": [...], "inertia": [Ixx, Iyy, Izz, Ixy, Ixz, Iyz] or null,
             "inertia_std": [...] or null, "gravity": [gx, gy, gz] or null, "converged": bool,
             "warnings": [...], "date": "..."}

        ``com`` is the centre of mass in the sensor frame, m (files written
        before name it ``rho``, ``rho_std``, and still read), the inertia
        about the centre of mass in kg m^2 (null: not determined, as from
        held poses), gravity in the pose frame in m/s^2 where it was
        estimated (null: the default was used). Written atomically.

        Raises
        ------
        FmscalError
            The payload is not determined (``payload_determined`` False): the message gives
            ``why_undetermined``.
        """
        if not self.payload_determined:
            raise FmscalError("the payload is not determined: no payload to save ("
                              + (self.why_undetermined or "see the warnings") + ")")
        t = self.tracked()

        def listed(v):
            return None if v is None else [float(x) for x in np.ravel(v)]
        document = {"format": PAYLOAD_FORMAT, "axes": "tracked", "mass": t.mass, "mass_std": t.mass_std,
                    "com": listed(t.com), "com_std": listed(t.com_std), "inertia": listed(t.inertia),
                    "inertia_std": listed(t.inertia_std), "gravity": listed(t.gravity),
                    "converged": bool(t.converged), "warnings": list(t.warnings),
                    "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
        atomic_write_text(path, json.dumps(document, indent=1, allow_nan=False) + "\n")

    def rotations_dict(self):
        """The six fields as JSON-ready numbers and lists (None where not estimated)."""
        return {"gravity": None if self.gravity is None else [float(v) for v in self.gravity],
                "gravity_std_deg": self.gravity_std_deg,
                "mounting": None if self.mounting is None else np.asarray(self.mounting).tolist(),
                "mounting_deg": self.mounting_deg, "mounting_std_deg": self.mounting_std_deg,
                "mounting_axis": None if self.mounting_axis is None else [float(v) for v in self.mounting_axis]}


@dataclass
class PayloadEstimate(_Rotations):
    """The payload's mass properties and the sensor's offset, with one-sigma uncertainties.

    Attributes
    ----------
    mass, mass_std : float
        kg.
    com, com_std : ndarray, shape (3,)
        Centre of mass in the sensor frame, m.
    inertia, inertia_std : ndarray, shape (6,), or None
        Inertia about the centre of mass, sensor axes (:data:`INERTIA_NAMES`),
        kg m^2; None where the log does not determine it.
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
    gravity, gravity_std_deg, mounting, mounting_deg, mounting_std_deg, mounting_axis
        Gravity's direction and the sensor's mounting, where estimated
        (:meth:`rotations_dict`): gravity in the pose frame (m/s^2), its
        direction's uncertainty, the sensor's axes on the tracked frame
        (3x3), its angle, uncertainty (degrees) and unit axis; None otherwise.
    gains, gains_std : ndarray, shape (6,), or None
        Each reading channel's gain, in ``w = diag(gains) S (sigma w_hat - b)`` (eq. P0 of
        :class:`fmscal.plant.PayloadModel`): the force gains relative to their mean (their mean 1), the
        torque gains 1 (``gains_std`` 0 there); the reading's channels, the sensor's axes. None where not
        estimated (too few poses for them with the rotations asked).
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
    gains: np.ndarray = None
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

        Returns
        -------
        PayloadEstimate
            In the tracked frame's axes (no mounting), ``payload_determined``
            True; the offset and the residuals, not saved, None.

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
        if not isinstance(data, dict) or data.get("format") != PAYLOAD_FORMAT:
            got = data.get("format") if isinstance(data, dict) else type(data).__name__
            raise PayloadFileError(f"{path.name}: not an fmscal payload (format {str(got)[:60]!r}; expected "
                                   f"{PAYLOAD_FORMAT!r})")

        if data.get("axes", "tracked") != "tracked":
            raise PayloadFileError(f"{path.name}: axes must be \"tracked\" (the payload in the tracked frame's "
                                   f"axes, as identify-payload --save writes it); got {str(data.get('axes'))[:40]!r}")
        converged = data.get("converged", False)
        if not isinstance(converged, bool):
            raise PayloadFileError(f"{path.name}: converged must be true or false; got {str(converged)[:40]!r}")

        def numbers(key, shape, optional=False):
            value = data.get(key)
            if value is None and optional:
                return None
            if not numbers_only(value):                 # text ("1.2") and true are not numbers
                value = None
            try:
                arr = np.array(value, dtype=float)
            except (TypeError, ValueError):
                arr = np.array(np.nan)
            if arr.shape != shape or not np.all(np.isfinite(arr)):
                raise PayloadFileError(f"{path.name}: {key} must be {int(np.prod(shape)) or 1} finite number(s)"
                                       + (" or null" if optional else ""))
            return arr
        mass = float(numbers("mass", ()))
        if not mass > 0:
            raise PayloadFileError(f"{path.name}: mass must be positive; got {mass}")
        warnings = data.get("warnings", [])
        if not isinstance(warnings, list) or not all(isinstance(w, str) for w in warnings):
            raise PayloadFileError(f"{path.name}: warnings must be a list of strings")
        legacy = "com" not in data and "rho" in data          # files written before named the centre of mass rho
        return cls(mass=mass, mass_std=float(numbers("mass_std", ())), com=numbers("rho" if legacy else "com", (3,)),
                   com_std=numbers("rho_std" if legacy else "com_std", (3,)), inertia=numbers("inertia", (6,), True),
                   inertia_std=numbers("inertia_std", (6,), True), b=None, b_std=None, residual_rms=None,
                   warnings=warnings, converged=converged, payload_determined=True,
                   gravity=numbers("gravity", (3,), True))


class PayloadFileError(FmscalError):
    """A payload file that cannot be used: the message names the problem."""
