"""A calibration as a file: what ``fmscal calibrate --save`` writes and ``fmscal apply`` uses.

The calibrated wrench is ``w = S (sigma w_hat - b)`` (eq. 3 with the
sensor's offset ``b``, ``b = 0`` where it was not estimated, and the
reading's sign ``sigma``). ``sigma = +1`` for a sensor that reports the
toolkit's wrench, the one the mount applies to the payload (``reading``
``"reaction"``, the default), and ``-1`` for one that reports the wrench
the tool applies to the sensor (``"load"``: ATI, Robotiq, Bota, OnRobot);
``b`` is in the sign-corrected reading ``sigma w_hat``. The file is JSON::

    {"format": "fmscal-calibration/1", "S": [[...] x3], "S_std": [[...] x3] or null,
     "b": [M, fx, fy] or null, "b_std": [...] or null, "payload": {"mass", "inertia", "rho"},
     "method": "least-squares", "log": {"name": "run.csv", "sha256": "..."},
     "latency": s or null, "date": "2026-11-22T10:00:00+00:00", "forced": false,
     "reading": "reaction"}

A spatial calibration has the same keys with ``S`` 6x6, ``b`` in the
reading's order ``tx .. fz``, and the payload's ``rho`` (3 numbers) and
``inertia`` (its 6 entries ``Ixx Iyy Izz Ixy Ixz Iyz``).

``forced`` is true when the calibration was saved although its run had not
converged (``fmscal calibrate --save --force``); files without it are read as
not forced, and files without ``reading`` as ``"reaction"`` (the only
convention before it was recorded).
"""

import datetime
import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fmscal.plant.numerics._errors import FmscalError
from fmscal.plant.io._files import atomic_write_text, not_a_file
from fmscal.plant.physics._payload import Payload
from fmscal.plant.physics._rigid_body import SpatialPayload
from fmscal.plant.physics._sensor import check_calibration

__all__ = ["Calibration", "CalibrationFileError", "file_sha256", "reading_sign", "FORMAT", "READINGS"]

#: The format tag every calibration file carries.
FORMAT = "fmscal-calibration/1"
#: A calibration file is a few kB; anything above this is refused unread.
_MAX_FILE_BYTES = 1 << 20
#: The two sign conventions of a sensor's reading: the wrench on the payload (the toolkit's), or on the sensor.
READINGS = ("reaction", "load")


class CalibrationFileError(FmscalError):
    """A calibration file that cannot be used: the message names the problem."""


def file_sha256(path):
    """SHA-256 of a file's bytes, hex."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def reading_sign(reading):
    """``sigma``, the sign that turns a reading of the convention ``reading`` into the toolkit's (module docstring).

    Parameters
    ----------
    reading : {"reaction", "load"}
        The wrench the mount applies to the payload (the toolkit's), or the
        wrench the tool applies to the sensor.

    Returns
    -------
    float
        ``+1.0`` or ``-1.0``.

    Raises
    ------
    FmscalError
        Neither convention.
    """
    if not isinstance(reading, str) or reading not in READINGS:
        raise FmscalError(f"reading must be one of {', '.join(READINGS)}; got {_short(reading)}")
    return 1.0 if reading == "reaction" else -1.0


def _matrix(value, shape, name, source):
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise CalibrationFileError(f"{source}: {name} must be numbers of shape {shape}; got {_short(value)}") from None
    if arr.shape != shape or not np.all(np.isfinite(arr)):
        raise CalibrationFileError(f"{source}: {name} must be finite numbers of shape {shape}; "
                                   f"got shape {arr.shape}")
    return arr


@dataclass(frozen=True)
class Calibration:
    """A sensor calibration: ``w = S (sigma w_hat - b)`` (module docstring).

    Parameters
    ----------
    S : array_like, shape (n, n)
        Calibration matrix, non-singular: 3x3 (planar) or 6x6 (spatial).
    payload : plant.Payload or plant.SpatialPayload
        The mass properties the calibration was estimated with (the one of
        its case).
    method : str
        The estimator (``least-squares``, ``ekf``, ...).
    S_std : array_like, shape (n, n), optional
        One-sigma uncertainty of each entry.
    b, b_std : array_like, shape (n,), optional
        Offset in the raw reading's order and units (planar ``[M, f_x,
        f_y]``, spatial ``[tx .. fz]``; N m, N) and its uncertainty; None:
        not estimated (taken as zero); in the sign-corrected reading
        ``sigma w_hat``.
    log_name, log_sha256 : str
        The log it came from, and a hash of the log file's contents.
    latency : float, optional
        Delay of the pose stream behind the sensor stream that was used, s.
    date : str, optional
        ISO 8601; default now (UTC).
    forced : bool
        True if it was saved although the run had not converged
        (``--force``): use it knowing that.
    reading : {"reaction", "load"}
        The reading's sign convention (:data:`READINGS`): ``"load"`` turns
        each reading's sign before ``S`` and ``b`` apply.
    """

    S: np.ndarray
    payload: Payload
    method: str
    S_std: np.ndarray = None
    b: np.ndarray = None
    b_std: np.ndarray = None
    log_name: str = ""
    log_sha256: str = ""
    latency: float = None
    date: str = None
    forced: bool = False
    reading: str = "reaction"

    def __post_init__(self):
        set_ = object.__setattr__
        n = 6 if np.shape(self.S) == (6, 6) else 3
        set_(self, "S", check_calibration(self.S, "S", size=n))
        kind = SpatialPayload if n == 6 else Payload
        if not isinstance(self.payload, kind):
            raise TypeError(f"payload must be a plant.{kind.__name__} for a {n}x{n} S; "
                            f"got {type(self.payload).__name__}")
        for name, shape in (("S_std", (n, n)), ("b", (n,)), ("b_std", (n,))):
            value = getattr(self, name)
            if value is not None:
                set_(self, name, _matrix(value, shape, name, "calibration"))
        if not isinstance(self.forced, (bool, np.bool_)):
            raise TypeError(f"forced must be True or False; got {self.forced!r}")
        set_(self, "forced", bool(self.forced))
        reading_sign(self.reading)
        if self.date is None:
            set_(self, "date", datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"))

    @property
    def size(self):
        """``n_w``: 3 (planar) or 6 (spatial)."""
        return self.S.shape[0]

    @property
    def offset(self):
        """``b``, zeros where it was not estimated; shape (n,)."""
        return np.zeros(self.size) if self.b is None else self.b

    def apply(self, w_hat):
        """Calibrated wrench ``w = S (sigma w_hat - b)`` (module docstring).

        Parameters
        ----------
        w_hat : array_like, shape (n,) or (N, n)
            Raw readings in the reading's order (planar ``[M, f_x, f_y]``,
            spatial ``[tx .. fz]``), N m and N.

        Returns
        -------
        ndarray, same shape as ``w_hat``
        """
        w_hat = np.asarray(w_hat, dtype=float)
        n = self.size
        if w_hat.ndim not in (1, 2) or w_hat.shape[-1] != n:
            raise FmscalError(f"w_hat must have shape ({n},) or (N, {n}); got {w_hat.shape}")
        if not np.all(np.isfinite(w_hat)):
            raise FmscalError("w_hat holds NaN or infinite values")
        return (reading_sign(self.reading) * w_hat - self.offset) @ self.S.T

    def to_dict(self):
        """The JSON document (module docstring)."""
        def listed(a):
            return None if a is None else np.asarray(a).tolist()
        return {"format": FORMAT, "S": listed(self.S), "S_std": listed(self.S_std), "b": listed(self.b),
                "b_std": listed(self.b_std), "payload": self.payload.to_dict(), "method": self.method,
                "log": {"name": self.log_name, "sha256": self.log_sha256}, "latency": self.latency,
                "date": self.date, "forced": self.forced, "reading": self.reading}

    def save(self, path):
        """Write the calibration as JSON, atomically (a temporary file, then a rename).

        A failure (a full disk, a crash) leaves any previous file at ``path``
        intact: never a truncated calibration.
        """
        atomic_write_text(path, json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n")

    @classmethod
    def load(cls, path, payload=None):
        """Read a calibration file, refusing one that is malformed or made for another payload.

        Parameters
        ----------
        path : str or Path
        payload : plant.Payload or plant.SpatialPayload, optional
            If given, the file must have been made for these mass properties.

        Returns
        -------
        Calibration

        Raises
        ------
        CalibrationFileError
            Missing file, not JSON, wrong format tag, missing keys, entries
            of the wrong shape or not finite, a singular ``S``, or another
            payload.
        """
        if payload is not None and not isinstance(payload, (Payload, SpatialPayload)):
            raise TypeError(f"payload must be a plant.Payload, a SpatialPayload or None; got {type(payload).__name__}")
        if not isinstance(path, (str, os.PathLike)):
            raise CalibrationFileError(f"a calibration path must be a file name; got {type(path).__name__}")
        path = Path(path)
        source = path.name
        problem = not_a_file(path)
        if problem == "no such file":
            raise CalibrationFileError(f"{path}: no such file")
        if problem is not None:
            raise CalibrationFileError(f"{path}: is {problem}, not a calibration file")
        if path.stat().st_size > _MAX_FILE_BYTES:
            raise CalibrationFileError(f"{source}: {path.stat().st_size} bytes is too large for a calibration "
                                       f"file (at most {_MAX_FILE_BYTES}); not an fmscal calibration")
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError) as err:
            raise CalibrationFileError(f"{source}: not a JSON calibration file ({err})") from None
        except RecursionError:
            raise CalibrationFileError(f"{source}: not a calibration file (JSON nested too deeply)") from None
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            got = data.get("format") if isinstance(data, dict) else type(data).__name__
            raise CalibrationFileError(f"{source}: not an fmscal calibration (format {got!r}; expected {FORMAT!r})")
        missing = [k for k in ("S", "payload", "method") if k not in data]
        if missing:
            raise CalibrationFileError(f"{source}: missing key(s) {', '.join(missing)}")
        n = 6 if np.shape(data["S"]) == (6, 6) else 3
        try:
            file_payload = (SpatialPayload if n == 6 else Payload).from_dict(data["payload"])
        except (KeyError, TypeError, ValueError) as err:
            raise CalibrationFileError(f"{source}: payload must hold mass, inertia and rho ({err})") from None
        if payload is not None and (type(payload) is not type(file_payload) or not file_payload.isclose(payload)):
            raise CalibrationFileError(f"{source}: made for another payload ({_describe(file_payload)}), "
                                       f"not {_describe(payload)}")
        S = _matrix(data["S"], (n, n), "S", source)
        optional = {}
        for name, shape in (("S_std", (n, n)), ("b", (n,)), ("b_std", (n,))):
            if data.get(name) is not None:
                optional[name] = _matrix(data[name], shape, name, source)
        latency = data.get("latency")
        if latency is not None and not (isinstance(latency, (int, float)) and np.isfinite(latency)):
            raise CalibrationFileError(f"{source}: latency must be a number of seconds or null; got {latency!r}")
        log = data.get("log") or {}
        if not isinstance(log, dict) or not all(isinstance(log.get(k, ""), str) for k in ("name", "sha256")):
            raise CalibrationFileError(f"{source}: log must be an object with a name and a sha256 (strings); "
                                       f"got {_short(log)}")
        forced = data.get("forced", False)
        if not isinstance(forced, bool):
            raise CalibrationFileError(f"{source}: forced must be true or false; got {_short(forced)}")
        reading = data.get("reading", "reaction")
        if reading not in READINGS:
            raise CalibrationFileError(f"{source}: reading must be one of {', '.join(READINGS)}; got {_short(reading)}")
        for key in ("method", "date"):
            if data.get(key) is not None and not isinstance(data[key], str):
                raise CalibrationFileError(f"{source}: {key} must be a string; got {_short(data[key])}")
        try:
            return cls(S=S, payload=file_payload, method=data["method"], log_name=log.get("name", ""),
                       log_sha256=log.get("sha256", ""), latency=latency, date=data.get("date"),
                       forced=forced, reading=reading, **optional)
        except ValueError as err:
            raise CalibrationFileError(f"{source}: {err}") from None


def _short(value, limit=60):
    """``repr(value)`` cut to ``limit`` characters, for messages."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def _describe(payload):
    rho = ", ".join(f"{r:g}" for r in payload.rho)
    if isinstance(payload, SpatialPayload):
        inertia = ", ".join(f"{i:g}" for i in payload.inertia)
        return f"m = {payload.mass:g} kg, rho = ({rho}) m, inertia = ({inertia}) kg m^2"
    return f"m = {payload.mass:g} kg, I_G = {payload.inertia:g} kg m^2, rho = ({rho}) m"
