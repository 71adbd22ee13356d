"""A calibration from the estimate to the file: what ``fmscal.analysis.calibrate`` returns, ``fmscal calibrate
--save`` writes and ``fmscal apply`` uses.

The calibrated wrench is ``w = S (sigma w_hat - b)`` (eq. 3 with the
sensor's offset ``b``, ``b = 0`` where it was not estimated, and the
reading's sign ``sigma``). ``sigma = +1`` for a sensor that reports the
toolkit's wrench, the one the mount applies to the payload (``reading``
``"reaction"``, the default), and ``-1`` for one that reports the wrench
the tool applies to the sensor (``"load"``: ATI, Robotiq, Bota, OnRobot);
``b`` is in the sign-corrected reading ``sigma w_hat``.

One type, :class:`Calibration`, carries a calibration from the estimate
(with its diagnostics: ``converged``, ``warnings``, the directions left
undetermined, the method's run) to the file (:meth:`Calibration.save`) and
back (:meth:`Calibration.load`); what only the estimate has (the run, ``E``
against a truth, the least-squares fit's diagnostics) is not written.

The file is JSON, format ``fmscal-calibration/2``::

    {"format": "fmscal-calibration/2", "kind": "planar" | "spatial" | "table",
     "S": [[...] x n], "S_std": [[...] x n] or null, "b": [...] or null, "b_std": [...] or null,
     "cov": [[...]] or null, "payload": {"mass", "inertia", "rho" | "com"}, "method": "max-likelihood",
     "log": {"name": "run.csv", "sha256": "..."}, "latency": s or null, "latency_std": s or null,
     "latency_estimated": false, "gravity": [gx, gy, gz] or null, "noise": {...} or null,
     "date": "2026-11-22T10:00:00+00:00", "forced": false, "reading": "reaction",
     "converged": true, "warnings": [...], "undetermined": [...], "undetermined_directions": [[...]]}

``n`` is 3 (planar: ``b`` is ``[M, f_x, f_y]``, the payload's ``rho`` 2
numbers, the sensor from the centre of mass, and ``inertia`` 1) or 6 (spatial
and tables: ``b`` in the reading's order ``tx .. fz``, the payload's ``com`` 3
numbers, the centre of mass from the sensor, and ``inertia`` its 6 entries
``Ixx Iyy Izz Ixy Ixz Iyz``; files written before name ``com`` ``rho``, and
still read). A ``null`` entry of ``S_std`` or ``b_std`` is one the data
did not determine (infinite in memory). ``cov`` is the covariance of the
estimated entries ``[S | c]`` flat in row order (``c = -S b``; ``S`` alone
without the offset), where the method gives one. ``latency`` is signed (s,
positive: the poses arrive late). ``undetermined`` names the directions of the
reading the data left undetermined, in words; ``undetermined_directions``
holds them as unit vectors of the augmented reading ``[w_hat, 1]``.

Files of format ``fmscal-calibration/1`` (the keys up to ``reading``) still
read: the keys added by ``/2`` are then unknown (``converged`` None). In
either format, files without ``forced`` are read as not forced, and files
without ``reading`` as ``"reaction"`` (the only convention before it was
recorded).
"""

import datetime
import hashlib
import json
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from fmscal.plant.numerics import FmscalError, as_bool, numbers_only, short_repr
from fmscal.plant.physics import MODELS, NoiseSpec, Payload, check_calibration

from ._files import atomic_write_text, exclusive, not_a_file, not_an_output
from ._log import _echo

__all__ = ["Calibration", "CalibrationFileError", "NotSavedError", "file_sha256", "reading_sign", "FORMAT", "FORMATS",
           "READINGS", "KINDS", "json_ready"]

#: The format tag a calibration file is written with.
FORMAT = "fmscal-calibration/2"
#: The format tags a calibration file is read with (the older first).
FORMATS = ("fmscal-calibration/1", FORMAT)
#: The cases a calibration comes from: a planar log, a spatial log, held poses (a pose table).
KINDS = ("planar", "spatial", "table")
#: A calibration file is a few kB; anything above this is refused unread.
_MAX_FILE_BYTES = 1 << 20
#: The two sign conventions of a sensor's reading: the wrench on the payload (the toolkit's), or on the sensor.
READINGS = ("reaction", "load")


class CalibrationFileError(FmscalError):
    """A calibration file that cannot be used: the message names the problem."""


class NotSavedError(FmscalError):
    """A calibration :meth:`Calibration.save` did not write, and the keyword that would write it.

    Parameters
    ----------
    option : str
        ``"force=True"`` (the calibration did not converge) or ``"overwrite=True"`` (the file exists).
    template : str
        The message with ``{}`` where the keyword goes; ``str(err)`` names the keyword, a command line
        puts its own flag there (``err.template.format("--force")``).
    """

    def __init__(self, option, template):
        super().__init__(template.format(option))
        self.option, self.template = option, template


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
        raise FmscalError(f"reading must be one of {', '.join(READINGS)}; got {short_repr(reading)}")
    return 1.0 if reading == "reaction" else -1.0


def _matrix(value, shape, name, source, undetermined=False):
    """``value`` as a float array of ``shape``, finite (``undetermined``: +inf allowed, and NaN read as +inf).

    JSON numbers only: text (``"1.0"``) and ``true``/``false`` are refused, as ``null`` is where the
    entry must be determined.
    """
    if not numbers_only(value, undetermined):
        raise CalibrationFileError(f"{source}: {name} must be numbers of shape {shape}"
                                   f"{' (null: not determined)' if undetermined else ''}; got {short_repr(value)}")
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise CalibrationFileError(f"{source}: {name} must be numbers of shape {shape}; "
                                   f"got {short_repr(value)}") from None
    if undetermined:
        arr[np.isnan(arr)] = np.inf                          # null in a file: not determined
    ok = np.isfinite(arr) | (undetermined & (arr == np.inf))
    if arr.shape != shape or not np.all(ok):
        raise CalibrationFileError(f"{source}: {name} must be finite numbers of shape {shape}; "
                                   f"got shape {arr.shape}")
    return arr


def _listed(value):
    """An array as nested lists for JSON, None for None, a non-finite entry as None."""
    if value is None:
        return None
    return [_listed(v) for v in value] if np.ndim(value) else (float(value) if np.isfinite(value) else None)


@dataclass(frozen=True)
class Calibration:
    """A sensor calibration, ``w = S (sigma w_hat - b)``, from its estimate to its file (module docstring).

    :func:`fmscal.analysis.calibrate` returns one with every field it
    knows; :meth:`load` gives one back from a file (the fields marked *not
    saved* then take their defaults).

    Parameters
    ----------
    S : array_like, shape (n, n)
        Calibration matrix, non-singular: 3x3 (planar) or 6x6 (spatial).
        Also :attr:`S_hat`.
    payload : plant.Payload or plant.SpatialPayload or None
        The mass properties the calibration was estimated with (the one of
        its case); None only for held poses calibrated from the mass and the
        centre of mass alone (such a calibration cannot be saved).
    method : str
        The estimator (``max-likelihood``, ``least-squares``, ...).
    S_std : array_like, shape (n, n), optional
        One-sigma uncertainty of each entry; ``inf`` where the data did not
        determine it; None where the method gives none.
    b, b_std : array_like, shape (n,), optional
        Offset in the raw reading's order and units (planar ``[M, f_x,
        f_y]``, spatial ``[tx .. fz]``; N m, N) and its uncertainty; None:
        not estimated (taken as zero); in the sign-corrected reading
        ``sigma w_hat``.
    log_name, log_sha256 : str
        The log it came from, and a hash of the log file's contents.
    latency : float, optional
        Delay of the pose stream behind the sensor stream that was used, s
        (signed); None for held poses.
    date : str, optional
        ISO 8601; default now (UTC).
    forced : bool
        True if it was saved although the run had not converged
        (``--force``): use it knowing that.
    reading : {"reaction", "load"}
        The reading's sign convention (:data:`READINGS`): ``"load"`` turns
        each reading's sign before ``S`` and ``b`` apply.
    latency_std : float, optional
        One-sigma uncertainty of the latency, s, where known.
    latency_estimated : bool
        The latency was estimated from the log (True) or given.
    gravity : array_like, shape (3,), optional
        Gravity in the pose frame used, m/s^2 (spatial logs and tables).
    noise : plant.NoiseSpec, optional
        The noise model the method used (planar logs).
    cov : array_like, shape (k, k), optional
        Covariance of the estimated entries ``[S | c]`` flat in row order
        (``k = n (n + 1)``; ``n^2``, ``S`` alone, without the offset),
        where the method gives one.
    converged : bool or None
        The run converged by the rule of :func:`fmscal.analysis.calibrate`;
        None where unknown (a file of format ``/1``).
    warnings : list of str
        What the estimate found, one line each.
    undetermined : list of str
        The directions of the reading the data left undetermined, in words.
    undetermined_directions : list of array_like, shape (n + 1,)
        The same as unit vectors of the augmented reading ``[w_hat, 1]``.
    kind : {"planar", "spatial", "table"}, optional
        The case (:data:`KINDS`); default from the size of ``S``.
    noise_estimated : list of str
        *Not saved.* Which parts of ``noise`` came from the log (``"wrench"``, ``"pose"``).
    E : float, optional
        *Not saved.* E of eq. (16) against a known truth.
    E_blocks : (float, float), optional
        *Not saved.* E of the torque and of the force block (spatial, with a truth).
    poses : int, optional
        *Not saved.* The number of held poses (a table).
    fit : dict, optional
        *Not saved.* A least-squares fit's diagnostics of the same log (planar).
    units : list of str
        *Not saved.* What :func:`plant.io.diagnose_units` found wrong with
        the log's units that the method cannot absorb; empty when they look right.
    notes : list of str
        *Not saved.* What was done to the data on reading it (:attr:`plant.Log.notes`).
    run : object, optional
        *Not saved.* The method's full run: an :class:`observers.ObserverResult`
        (histories, info), or the table's fit.
    glitches : dict, optional
        *Not saved.* The samples of the reading a log's fit rejected as glitches
        (``count``, ``indices``, ``times``, ``channels``, ``size``, ``threshold``:
        :class:`fmscal.observers.core.Glitches`); None when it rejected none.
    why_unconverged : str, optional
        *Not saved.* Why ``converged`` is False, in a few words (the units,
        saturation, the other sign convention, held poses, or the run); None
        when it converged or is unknown.
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
    latency_std: float = None
    latency_estimated: bool = False
    gravity: np.ndarray = None
    noise: NoiseSpec = None
    cov: np.ndarray = None
    converged: bool = None
    warnings: list = field(default_factory=list)
    undetermined: list = field(default_factory=list)
    undetermined_directions: list = field(default_factory=list)
    kind: str = None
    noise_estimated: list = field(default_factory=list, compare=False)
    E: float = field(default=None, compare=False)
    E_blocks: tuple = field(default=None, compare=False)
    poses: int = field(default=None, compare=False)
    fit: dict = field(default=None, compare=False, repr=False)
    units: list = field(default_factory=list, compare=False)
    notes: list = field(default_factory=list, compare=False)
    run: object = field(default=None, compare=False, repr=False)
    why_unconverged: str = field(default=None, compare=False)
    glitches: dict = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        set_ = object.__setattr__
        model = _case(self.S)                        # the model whose reading S calibrates
        n = len(model.wrench_names)
        set_(self, "S", check_calibration(self.S, "S", size=n))
        kind = model.payload_type                    # held poses (under gravity) need no payload
        if not isinstance(self.payload, kind) and not (self.payload is None and model.under_gravity):
            raise TypeError(f"payload must be a plant.{kind.__name__} for a {n}x{n} S; "
                            f"got {type(self.payload).__name__}")
        for name, shape, undetermined in (("S_std", (n, n), True), ("b", (n,), False), ("b_std", (n,), True)):
            value = getattr(self, name)
            if value is not None:
                set_(self, name, _matrix(value, shape, name, "calibration", undetermined))
        if self.cov is not None:
            k = np.shape(self.cov)[0] if np.ndim(self.cov) == 2 else 0
            if k not in (n * n, n * (n + 1)):
                raise FmscalError(f"cov must be the covariance of [S | c] ({n * (n + 1)} entries square, or "
                                  f"{n * n} without the offset); got shape {np.shape(self.cov)}")
            set_(self, "cov", _matrix(self.cov, (k, k), "cov", "calibration", undetermined=True))
        if self.gravity is not None:
            set_(self, "gravity", _matrix(self.gravity, (3,), "gravity", "calibration"))
        for name in ("latency", "latency_std"):
            value = getattr(self, name)
            if value is not None:
                if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) or not np.isfinite(value):
                    raise FmscalError(f"{name} must be a finite number of seconds or None; got {short_repr(value)}")
                set_(self, name, float(value))
        if self.latency_std is not None and self.latency_std < 0:
            raise FmscalError(f"latency_std must be at least 0; got {self.latency_std}")
        if self.noise is not None and not isinstance(self.noise, NoiseSpec):
            raise TypeError(f"noise must be a plant.NoiseSpec or None; got {type(self.noise).__name__}")
        for name in ("forced", "latency_estimated"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise TypeError(f"{name} must be True or False; got {getattr(self, name)!r}")
            set_(self, name, bool(getattr(self, name)))
        if self.converged is not None:
            set_(self, "converged", bool(self.converged))
        for name in ("warnings", "undetermined", "noise_estimated", "units", "notes"):
            set_(self, name, [str(v) for v in getattr(self, name)])
        set_(self, "undetermined_directions",
             [_matrix(d, (n + 1,), "undetermined_directions", "calibration") for d in self.undetermined_directions])
        reading_sign(self.reading)
        if self.kind is None:
            set_(self, "kind", model.name)
        if not _kind_of(self.kind, model):
            raise FmscalError(f"kind must be one of {', '.join(KINDS)} (planar: a 3x3 S); got {short_repr(self.kind)}")
        if self.date is None:
            set_(self, "date", datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"))

    @property
    def S_hat(self):
        """The estimate of ``S``: :attr:`S`, shape (n, n)."""
        return self.S

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
        """The file's JSON document, format ``/2`` (module docstring); without the fields not saved."""
        return {"format": FORMAT, "kind": self.kind, "S": _listed(self.S), "S_std": _listed(self.S_std),
                "b": _listed(self.b), "b_std": _listed(self.b_std), "cov": _listed(self.cov),
                "payload": None if self.payload is None else self.payload.to_dict(), "method": self.method,
                "log": {"name": self.log_name, "sha256": self.log_sha256}, "latency": self.latency,
                "latency_std": self.latency_std, "latency_estimated": self.latency_estimated,
                "gravity": _listed(self.gravity), "noise": None if self.noise is None else self.noise.to_dict(),
                "date": self.date, "forced": self.forced, "reading": self.reading, "converged": self.converged,
                "warnings": list(self.warnings), "undetermined": list(self.undetermined),
                "undetermined_directions": [_listed(d) for d in self.undetermined_directions]}

    def to_json(self, saved=False):
        """The report ``fmscal calibrate --json`` prints: one line of strict JSON (NaN and infinity as null).

        Its keys depend on the case (:attr:`kind`): every case has
        ``observer`` (the method), ``S``, ``S_std``, ``b``, ``b_std``,
        ``latency``, ``latency_estimated``, ``converged``, ``warnings`` and
        ``saved``; a planar log adds ``noise``, ``noise_estimated``, ``fit``
        and, with a truth, ``E``; a spatial log adds ``kind``,
        ``undetermined`` (:attr:`undetermined_directions`, as vectors),
        ``reading`` and, with a truth, ``E``, ``E_torque`` and ``E_force``;
        a log whose fit rejected samples as glitches adds ``glitches``
        (:attr:`glitches`);
        a table adds ``kind``, ``poses``, ``undetermined`` and ``reading``.

        Parameters
        ----------
        saved : bool
            Whether the caller wrote the calibration to a file (the
            report's ``saved``).

        Returns
        -------
        str
        """
        head = {"observer": self.method}
        if self.kind != "planar":
            head["kind"] = self.kind
        if self.kind == "table":
            head["poses"] = self.poses
        out = {**head, "S": self.S, "S_std": self.S_std, "b": self.b, "b_std": self.b_std,
               "latency": self.latency, "latency_std": self.latency_std, "latency_estimated": self.latency_estimated,
               "converged": self.converged}
        if self.kind == "planar":
            out.update(noise=None if self.noise is None else self.noise.to_dict(),
                       noise_estimated=list(self.noise_estimated), warnings=list(self.warnings), fit=self.fit)
            if self.E is not None:
                out["E"] = self.E
        else:
            out.update(undetermined=list(self.undetermined_directions), warnings=list(self.warnings),
                       reading=self.reading)
            if self.E is not None:
                out["E"] = self.E
                out["E_torque"], out["E_force"] = self.E_blocks
        if self.glitches:                               # only a log with glitches: a clean log's report as before
            out["glitches"] = self.glitches
        out["saved"] = bool(saved)
        return json.dumps(json_ready(out), allow_nan=False)

    def save(self, path, *, force=False, overwrite=False):
        """Write the calibration as JSON, format ``/2``, atomically (a temporary file, then a rename).

        A calibration that did not converge (``converged`` False) is refused
        unless ``force``; written with it, the file records ``"forced":
        true`` (``fmscal apply`` warns on reading it). An existing file is
        refused unless ``overwrite``; without it, a file that appears at
        ``path`` while this writes is not replaced either. A failure (a full
        disk, a crash) leaves any previous file at ``path`` intact: never a
        truncated calibration. ``fmscal calibrate --save`` calls this with
        ``--force`` and ``--overwrite``.

        Parameters
        ----------
        path : str or Path
        force : bool
            Save a calibration that did not converge (marked as forced).
        overwrite : bool
            Replace a file already at ``path``.

        Raises
        ------
        NotSavedError
            Not converged without ``force``, or ``path`` exists without ``overwrite``: the message
            names the reason and the keyword.
        FmscalError
            No payload to record (held poses calibrated without the inertia), or ``path`` is a folder,
            a FIFO, a device, a symlink loop or a link to a missing file.
        """
        force, overwrite = as_bool(force, "force"), as_bool(overwrite, "overwrite")
        if self.payload is None:
            raise FmscalError("a calibration file records the payload: calibrate with the payload's inertia too "
                              "(a plant.SpatialPayload; held poses do not use it)")
        shown = _echo(str(path))
        if self.converged is False and not force:
            why = self.why_unconverged or "the calibration did not converge (see its warnings)"
            raise NotSavedError("force=True", f"did not save {shown}: {why}; add {{}} to save it anyway (marked "
                                              "as forced)")
        problem = not_an_output(path)
        if problem is not None:
            raise FmscalError(f"cannot save to {shown}: it is {problem}; choose another file")
        if os.path.lexists(path) and not overwrite:
            raise NotSavedError("overwrite=True", f"did not save {shown}: the file exists; add {{}} to replace it")
        record = self if self.converged is not False or self.forced else replace(self, forced=True)
        with exclusive(not overwrite):
            atomic_write_text(path, json.dumps(record.to_dict(), indent=1, allow_nan=False) + "\n")

    @classmethod
    def load(cls, path, payload=None):
        """Read a calibration file (format ``/1`` or ``/2``), refusing one malformed or made for another payload.

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
        if payload is not None and not isinstance(payload, tuple(m.payload_type for m in MODELS)):
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
        if not isinstance(data, dict) or data.get("format") not in FORMATS:
            got = data.get("format") if isinstance(data, dict) else type(data).__name__
            raise CalibrationFileError(f"{source}: not an fmscal calibration (format {short_repr(got)}; expected "
                                       f"{' or '.join(map(repr, FORMATS))})")
        missing = [k for k in ("S", "payload", "method") if k not in data]
        if missing:
            raise CalibrationFileError(f"{source}: missing key(s) {', '.join(missing)}")
        if not any(np.shape(data["S"]) == (len(m.wrench_names),) * 2 for m in MODELS):
            raise CalibrationFileError(f"{source}: S must be square, one row per reading component "
                                       f"({' or '.join(str(len(m.wrench_names)) for m in MODELS)}); got shape "
                                       f"{np.shape(data['S'])}")
        model = _case(data["S"])
        n = len(model.wrench_names)
        if not isinstance(data["payload"], dict):
            raise CalibrationFileError(f"{source}: payload must be an object with mass, inertia and "
                                       f"{model.payload_position}; got {short_repr(data['payload'])}")
        try:
            file_payload = model.payload_type.from_dict(data["payload"])
        except (KeyError, TypeError, ValueError) as err:
            raise CalibrationFileError(f"{source}: payload must hold mass, inertia and {model.payload_position} "
                                       f"({err})") from None
        if payload is not None and (type(payload) is not type(file_payload) or not file_payload.isclose(payload)):
            raise CalibrationFileError(f"{source}: made for another payload ({_describe(file_payload)}), "
                                       f"not {_describe(payload)}")
        S = _matrix(data["S"], (n, n), "S", source)
        second = data["format"] == FORMAT
        optional = {}
        for name, shape in (("S_std", (n, n)), ("b", (n,)), ("b_std", (n,))):
            if data.get(name) is not None:
                optional[name] = _matrix(data[name], shape, name, source, undetermined=second and name != "b")
        latency = data.get("latency")
        if latency is not None and not (isinstance(latency, (int, float)) and np.isfinite(latency)):
            raise CalibrationFileError(f"{source}: latency must be a number of seconds or null; got {latency!r}")
        log = data.get("log") or {}
        if not isinstance(log, dict) or not all(isinstance(log.get(k, ""), str) for k in ("name", "sha256")):
            raise CalibrationFileError(f"{source}: log must be an object with a name and a sha256 (strings); "
                                       f"got {short_repr(log)}")
        forced = data.get("forced", False)
        if not isinstance(forced, bool):
            raise CalibrationFileError(f"{source}: forced must be true or false; got {short_repr(forced)}")
        reading = data.get("reading", "reaction")
        if reading not in READINGS:
            raise CalibrationFileError(f"{source}: reading must be one of {', '.join(READINGS)}; "
                                       f"got {short_repr(reading)}")
        for key in ("method", "date"):
            if data.get(key) is not None and not isinstance(data[key], str):
                raise CalibrationFileError(f"{source}: {key} must be a string; got {short_repr(data[key])}")
        if second:
            optional.update(_second_format(data, model, source))
        elif model.under_gravity and data["method"] == "static-least-squares":    # /1 did not say: held poses' fit
            optional["kind"] = "table"
        try:
            return cls(S=S, payload=file_payload, method=data["method"], log_name=log.get("name", ""),
                       log_sha256=log.get("sha256", ""), latency=latency, date=data.get("date"),
                       forced=forced, reading=reading, **optional)
        except (ValueError, TypeError) as err:
            raise CalibrationFileError(f"{source}: {str(err).splitlines()[0]}") from None


def _case(S):
    """The model class (:data:`fmscal.plant.physics.MODELS`) whose reading an ``S`` of this shape calibrates;
    the first where none does (``check_calibration`` then refuses the shape)."""
    shape = np.shape(S)
    return next((m for m in MODELS if shape == (len(m.wrench_names),) * 2), MODELS[0])


def _kind_of(kind, model):
    """Whether ``kind`` (:data:`KINDS`) names a calibration of ``model``'s reading: a log of the model, or held
    poses where the model stands under gravity (they weigh the payload)."""
    return kind in KINDS and (kind == model.name or (model.under_gravity and kind == KINDS[-1]))


def _second_format(data, model, source):
    """The keys format ``/2`` added, checked: a dict of :class:`Calibration`'s arguments."""
    n = len(model.wrench_names)
    out = {}
    kind = data.get("kind")
    if kind is not None:
        if not _kind_of(kind, model):
            raise CalibrationFileError(f"{source}: kind must be one of {', '.join(KINDS)} (planar: a 3x3 S); "
                                       f"got {short_repr(kind)}")
        out["kind"] = kind
    latency_std = data.get("latency_std")
    if latency_std is not None:
        if isinstance(latency_std, bool) or not isinstance(latency_std, (int, float)) or not latency_std >= 0 \
                or not np.isfinite(latency_std):
            raise CalibrationFileError(f"{source}: latency_std must be a non-negative number of seconds or null; "
                                       f"got {short_repr(latency_std)}")
        out["latency_std"] = latency_std
    for key in ("latency_estimated", "converged"):
        value = data.get(key)
        if value is not None and not isinstance(value, bool):
            raise CalibrationFileError(f"{source}: {key} must be true, false or null; got {short_repr(value)}")
    out["latency_estimated"] = bool(data.get("latency_estimated") or False)
    out["converged"] = data.get("converged")
    if data.get("gravity") is not None:
        out["gravity"] = _matrix(data["gravity"], (3,), "gravity", source)
    if data.get("cov") is not None:
        k = len(data["cov"]) if isinstance(data["cov"], list) else 0
        if k not in (n * n, n * (n + 1)):
            raise CalibrationFileError(f"{source}: cov must be {n * (n + 1)} (or {n * n}) rows square; got {k} rows")
        out["cov"] = _matrix(data["cov"], (k, k), "cov", source, undetermined=True)
    if data.get("noise") is not None:
        try:
            out["noise"] = NoiseSpec.from_dict(data["noise"])
        except (KeyError, TypeError, ValueError, FmscalError) as err:
            raise CalibrationFileError(f"{source}: noise must hold wrench_sd, angle_sd and position_sd "
                                       f"({str(err).splitlines()[0] if str(err) else type(err).__name__})") from None
    for key in ("warnings", "undetermined"):
        value = data.get(key, [])
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise CalibrationFileError(f"{source}: {key} must be a list of strings; got {short_repr(value)}")
        out[key] = value
    directions = data.get("undetermined_directions", [])
    if not isinstance(directions, list):
        raise CalibrationFileError(f"{source}: undetermined_directions must be a list of vectors; "
                                   f"got {short_repr(directions)}")
    out["undetermined_directions"] = [_matrix(d, (n + 1,), "undetermined_directions", source) for d in directions]
    return out


def json_ready(value):
    """A JSON-ready copy of ``value``: arrays as lists, NaN and infinity as None, numpy scalars plain.

    What every file and every ``--json`` of the toolkit writes goes through it (strict JSON: no NaN).

    Examples
    --------
    >>> import numpy as np
    >>> json_ready({"S": np.eye(2), "sd": [np.inf, np.float64(0.5)], "ok": np.bool_(True)})
    {'S': [[1.0, 0.0], [0.0, 1.0]], 'sd': [None, 0.5], 'ok': True}
    """
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, dict):
        return {k: json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    return value


def _describe(payload):
    """The payload in words: its mass, centre of mass and inertia, named as its model declares them."""
    model = next(m for m in MODELS if isinstance(payload, m.payload_type))
    name = model.payload_position
    position = ", ".join(f"{r:g}" for r in getattr(payload, name))
    inertia = ", ".join(f"{n} = {i:g}" for n, i in zip(model.inertia_names, np.atleast_1d(payload.inertia)))
    return f"m = {payload.mass:g} kg, {name} = ({position}) m, {inertia} kg m^2"
