"""The log: a CSV of measured pose and raw sensor reading, and its sidecar.

Two formats (public ones: a user records them on a real rig); the header
says which case a log is (:func:`fmscal.plant.physics.model_for_columns`).

Planar (the paper's problem)::

    t,theta,x,y,M,fx,fy

in SI units (s, rad, m, N m, N). ``theta, x, y`` is the measured pose in the
inertial frame, ``theta`` continuous (one wrapped into (-pi, pi] or [0, 2 pi) is unwrapped,
with a note in :attr:`Log.notes`); ``M, fx, fy`` is the raw
sensor reading ``w_hat`` in the body frame at the sensor interface.

Spatial (a 6-axis sensor moving in 3D)::

    t,qw,qx,qy,qz,x,y,z,tx,ty,tz,fx,fy,fz

``qw, qx, qy, qz`` is the attitude of the sensor frame (origin at the
sensor's measuring point, the sensor's axes) in an inertial frame with z
up: a unit quaternion, scalar first, rotating sensor-frame vectors into the
world; ``x, y, z`` the position of the sensor point, m. ``tx, ty, tz, fx, fy,
fz`` is the raw reading, torque first. A quaternion off unit norm by more
than :data:`QUATERNION_TOLERANCE` is refused; within it, it is normalised;
``q`` and ``-q`` are one attitude, and a sequence that flips sign is made
continuous (with a note).

In both, empty pose cells on a row (all of them) mean no pose measurement at
that sample; every other cell is a finite number. Time is strictly
increasing and evenly sampled.

A file may be compressed (gzip, bzip2 or xz, told by its first bytes and
read as it is); the header, read by :func:`csv_header`, picks the case by the
columns the models declare (:data:`fmscal.plant.physics.MODELS`), in any
case, so that names in another case are named. Time that reads as Unix time
in s (a clock's stamps: a date from 2000 to 2100) is taken from its first
stamp, with a note; in ms, us or ns it is refused naming the unit.

Every log, from a file or from the simulator, is validated in one place:
:meth:`Log.__init__`. Its messages count **rows**, the samples from 1 (the
header is not a row); the file's own checks, before any row is read, count
**lines** of the file (the header is line 1, so row ``k`` is line ``k + 1``)
and say so.
"""

import bz2
import datetime
import gzip
import io
import json
import lzma
import os
import re
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fmscal.plant.numerics import FmscalError, LogError, as_finite_array, as_number, as_positive_scalar
from fmscal.plant.physics import (MODELS, QUATERNION_TOLERANCE, CalibrationSchedule, NoiseSpec, Payload,
                                  PlanarModel, SpatialModel, SpatialPayload, check_calibration, find_model,
                                  sign_continuous,
                                  unit_quaternions)
from ._files import atomic_write_text, not_a_file

__all__ = ["Log", "LogError", "Truth", "read_log", "read_readings", "read_truth", "log_kind", "csv_header",
           "COLUMNS", "SPATIAL_COLUMNS", "READING_COLUMNS", "QUATERNION_TOLERANCE", "unit_quaternions"]

#: Column names of a planar log, in order.
COLUMNS = ("t", *PlanarModel.pose_names, *PlanarModel.wrench_names)
#: Column names of a spatial log, in order.
SPATIAL_COLUMNS = ("t", *SpatialModel.pose_names, *SpatialModel.wrench_names)
_WRENCH = PlanarModel.wrench_names
_SAMPLING_TOLERANCE = 0.01        # relative spread of the time step accepted as even
MIN_SAMPLES = 10
#: Largest magnitude accepted in any column (s, rad, m, N m, N; or sensor counts).
MAX_MAGNITUDE = 1e9


class Log:
    """Measured pose and raw sensor reading on one time grid.

    Parameters
    ----------
    t : array_like, shape (N,)
        Time in s, strictly increasing, evenly sampled.
    pose : array_like, shape (N, 3) or (N, 7)
        Measured pose, a row of NaN where there was no measurement: planar
        ``[theta, X, Y]`` in rad and m, or spatial ``[qw, qx, qy, qz, x, y,
        z]`` (unit quaternion, scalar first; m).
    w_hat : array_like, shape (N, 3) or (N, 6)
        Raw reading, finite: planar ``[M, f_x, f_y]``, or spatial ``[tx, ty,
        tz, fx, fy, fz]``.
    name : str, optional
        Where the log came from (a file name).
    model : plant.Model or its class, optional
        The case the log belongs to; default planar or spatial, from the
        shapes. Another model (one of the tests' own) names its columns here.

    Attributes
    ----------
    kind : str
        The case's name (:attr:`fmscal.plant.Model.name`): ``"planar"`` or
        ``"spatial"`` from the shapes, or the given model's.
    columns : tuple of str
        The log's CSV header.
    dt : float
        The time step, s.
    has_pose : ndarray of bool, shape (N,)
        True where the pose was measured.
    notes : list of str
        What was done to the data on reading it: rows before the first pose
        dropped (a recording starts with readings), a ``theta`` wrapped into
        (-pi, pi] or [0, 2 pi) (as vision systems and quaternion-to-yaw conversions give
        it) is unwrapped, a quaternion sequence that flips sign is made
        continuous, and said so here.

    Raises
    ------
    LogError
        With a one-line message naming the problem.
    """

    def __init__(self, t, pose, w_hat, name="log", model=None):
        self.name = str(name)
        self.t = np.asarray(t, dtype=float)
        self.pose = np.asarray(pose, dtype=float)
        self.w_hat = np.asarray(w_hat, dtype=float)
        n = len(self.t)
        shapes = (self.pose.shape[-1], self.w_hat.shape[-1]) if self.pose.ndim == self.w_hat.ndim == 2 else None
        if model is not None:
            if shapes != (len(model.pose_names), len(model.wrench_names)) or self.t.ndim != 1 \
                    or self.pose.shape[0] != n or self.w_hat.shape[0] != n:
                raise LogError(f"{self.name}: a {model.name} log has t (N,), pose (N, {len(model.pose_names)}), "
                               f"w_hat (N, {len(model.wrench_names)}); got {self.t.shape}, {self.pose.shape}, "
                               f"{self.w_hat.shape}")
            case = model
        else:
            case = None if shapes is None else find_model(n_pose=shapes[0], n_w=shapes[1])
        if self.t.ndim != 1 or case is None or self.pose.shape[0] != n or self.w_hat.shape[0] != n:
            raise LogError(f"{self.name}: expected t (N,), pose (N, 3), w_hat (N, 3) (planar) or pose (N, 7), "
                           f"w_hat (N, 6) (spatial); got {self.t.shape}, {self.pose.shape}, {self.w_hat.shape}")
        self.kind = case.name
        self._model = model
        self._case = case
        self.columns = ("t", *case.pose_names, *case.wrench_names)
        pose_names, wrench_names = case.pose_names, case.wrench_names
        if n < MIN_SAMPLES:
            raise LogError(f"{self.name}: too few rows ({n}); a log needs at least {MIN_SAMPLES}")
        _check_finite(self.name, (("t", self.t), *((c, self.w_hat[:, j]) for j, c in enumerate(wrench_names))))
        self.t, clock = _from_unix_time(self.name, self.t)
        partial = np.isnan(self.pose).any(axis=1) & ~np.isnan(self.pose).all(axis=1)
        if partial.any():
            raise LogError(f"{self.name}: row {np.argmax(partial) + 1} has some but not all of {','.join(pose_names)}; "
                           f"leave all {len(pose_names)} empty where there is no pose measurement")
        if np.isinf(self.pose).any():
            raise LogError(f"{self.name}: pose has an infinite value at row {_first_bad(self.pose.sum(1))}")
        _check_magnitudes(self.name, (("t", self.t), *((c, self.pose[:, j]) for j, c in enumerate(pose_names)),
                                     *((c, self.w_hat[:, j]) for j, c in enumerate(wrench_names))))
        self.dt = _check_steps(self.name, self.t)
        self.has_pose = ~np.isnan(self.pose[:, 0])
        if self.has_pose.sum() < MIN_SAMPLES:
            raise LogError(f"{self.name}: too few pose measurements to calibrate; "
                           f"need at least {MIN_SAMPLES}, got {int(self.has_pose.sum())}")
        self.notes = [] if clock is None else [clock]
        if not self.has_pose[0]:          # a recording starts with readings before its first pose: they are dropped
            first = int(np.argmax(self.has_pose))
            self.t, self.pose, self.w_hat, self.has_pose = (a[first:] for a in (self.t, self.pose, self.w_hat,
                                                                               self.has_pose))
            self.notes.append(f"{self.name}: the first {first} row(s) come before the first pose (at t = "
                              f"{self.t[0]:g} s) and were dropped: the log starts at its first pose")
        if self.kind == "planar":
            self._unwrap_theta()
        elif self.kind == "spatial":
            self._normalise_quaternions()

    def _normalise_quaternions(self):
        """Unit quaternions within :data:`QUATERNION_TOLERANCE`, normalised and made sign-continuous (with a note)."""
        rows = np.flatnonzero(self.has_pose)
        q = unit_quaternions(self.pose[rows, :4], self.name, rows)
        flips = np.sum(q[1:] * q[:-1], axis=1) < 0
        self.pose = self.pose.copy()
        self.pose[rows, :4] = sign_continuous(q)
        if flips.any():
            first = self.t[rows[1:][flips][0]]
            self.notes.append(f"{self.name}: the quaternion changes sign {int(flips.sum())} time(s) between poses "
                              f"(q and -q are one attitude; the first at t = {first:g} s); made it continuous")

    def _unwrap_theta(self):
        """Unwrap a ``theta`` wrapped into (-pi, pi] or [0, 2 pi) (its ~2 pi jumps between poses), with a note."""
        rows = np.flatnonzero(self.has_pose)
        theta = self.pose[rows, 0]
        jumps = np.abs(np.diff(theta)) > np.pi
        if not jumps.any():
            return
        if np.max(np.abs(theta)) <= np.pi + 1e-6:
            interval = "(-pi, pi]"
        elif np.min(theta) >= -1e-6 and np.max(theta) <= 2 * np.pi + 1e-6:
            interval = "[0, 2 pi)"
        else:
            return
        self.pose = self.pose.copy()
        self.pose[rows, 0] = np.unwrap(theta)
        first = self.t[rows[1:][jumps][0]]
        self.notes.append(f"{self.name}: theta is wrapped into {interval} ({int(jumps.sum())} jump(s) of about "
                          f"2 pi between poses, the first at t = {first:g} s); unwrapped it")

    def __len__(self):
        return len(self.t)

    @property
    def duration(self):
        """Time covered, s."""
        return float(self.t[-1] - self.t[0])

    def pose_rate(self):
        """Mean rate of pose measurements, Hz."""
        return float((self.has_pose.sum() - 1) / max(self.duration, 1e-12))

    def write(self, path):
        """Write the log as CSV with its header (:attr:`columns`)."""
        data = np.column_stack([self.t, self.pose, self.w_hat])
        lines = [",".join(self.columns)]
        width = self.pose.shape[1]
        for row, ok in zip(data, self.has_pose):
            cells = [repr(float(v)) for v in row]
            if not ok:
                cells[1:1 + width] = [""] * width
            lines.append(",".join(cells))
        atomic_write_text(path, "\n".join(lines) + "\n")

    def shift_poses(self, latency):
        """The log with the pose stream moved back by ``latency`` to line up with the sensor.

        A vision system that delivers each pose ``latency`` s late logs the
        pose of ``t - latency`` at ``t``; this returns the log in which each
        pose sits at the time it was taken. A negative ``latency`` is a
        wrench stream behind the poses (a sensor's internal filter): the
        poses move forward. Each pose measurement moves by the whole samples
        nearest ``latency`` (``k = round(latency / dt)``), to row ``r``, and
        its value is the pose stream at ``t_r + latency`` (the stamp it was
        taken at), interpolated between its measurements on the attitude's
        manifold as the model declares (:meth:`fmscal.plant.Model.interpolate_pose`:
        SLERP for a unit quaternion, linear for positions and an angle); a
        whole number of samples moves the measurements unchanged. This keeps a
        multi-rate log's pattern of pose rows. A pose whose time falls before
        the first or after the last measurement is left out, and the rows
        before the first pose and after the last one are dropped.

        Interpolated, the poses' noise is smoothed (half-way between two
        measurements, a mean of two draws, correlated from row to row): a
        noise model measured on the shifted log
        (:func:`fmscal.plant.estimate_noise`) reads it smaller than it is.
        Measure it on the log before the shift and give it to the method, as
        :func:`fmscal.analysis.calibrate` does.

        Parameters
        ----------
        latency : float
            s, of either sign, less than half the log in magnitude.

        Returns
        -------
        Log

        Raises
        ------
        FmscalError
            A latency not finite, or of half the log or more.
        """
        latency = float(latency)
        if not (np.isfinite(latency) and abs(latency) < self.duration / 2):
            raise FmscalError(f"latency must be in (-{self.duration / 2:g}, {self.duration / 2:g}) s for this log; "
                              f"got {latency}")
        steps = latency / self.dt
        k = int(round(steps))
        whole = abs(steps - k) <= 1e-9 * max(1.0, abs(steps))
        if whole and k == 0:
            return self
        n = len(self)
        rows = np.flatnonzero(self.has_pose)
        target = rows - k
        inside = (target >= 0) & (target < n)
        if whole:
            values = self.pose[rows[inside]]
        else:
            pose_times = self.t[rows]
            when = self.t[np.clip(target, 0, n - 1)] + latency
            inside &= (when >= pose_times[0]) & (when <= pose_times[-1])
            values = self._case.interpolate_pose(when[inside], pose_times, self.pose[rows])
        target = target[inside]
        if len(target) == 0:
            raise FmscalError(f"{self.name}: no pose left after shifting the poses by {latency:g} s")
        pose = np.full_like(self.pose, np.nan)
        pose[target] = values
        keep = slice(int(target[0]), int(target[-1]) + 1)
        return Log(self.t[keep], pose[keep], self.w_hat[keep], self.name, model=self._model)

    def head(self, n):
        """The first ``n`` samples as a new Log."""
        return Log(self.t[:n], self.pose[:n], self.w_hat[:n], self.name, model=self._model)

    def between(self, t_start, t_end):
        """The samples with ``t_start <= t < t_end`` as a new Log (from its first pose on).

        Parameters
        ----------
        t_start, t_end : float
            s, on the log's clock.

        Returns
        -------
        Log

        Raises
        ------
        LogError
            Too few samples or poses in the window.
        """
        keep = np.flatnonzero((self.t >= t_start) & (self.t < t_end))
        poses = keep[self.has_pose[keep]]
        if len(poses) == 0:
            raise LogError(f"{self.name}: no pose measurement between t = {t_start:g} and {t_end:g} s")
        keep = keep[keep >= poses[0]]
        return Log(self.t[keep], self.pose[keep], self.w_hat[keep], self.name, model=self._model)


def _latency(value):
    """A sidecar's latency: a finite number of seconds, of either sign (negative: the wrench behind the poses)."""
    latency = as_number(value, "latency")
    if not np.isfinite(latency):
        raise FmscalError(f"latency must be a finite number of seconds; got {value!r}")
    return latency


def _check_finite(name, columns):
    """Every value of each ``(column name, values)`` finite; else a one-line :class:`LogError` naming the column
    and the first row."""
    for col, values in columns:
        if not np.all(np.isfinite(values)):
            raise LogError(f"{name}: column {col} has a missing, NaN or infinite value at row {_first_bad(values)}")


#: A first stamp that reads as a date from 2000 to 2100 in Unix time (s since 1970-01-01 UTC) is a clock's,
#: not a log's own time from its start: in s, ms, us or ns.
_UNIX_SPAN = (946684800.0, 4102444800.0)
_UNIX_UNITS = (("s", 1.0), ("ms", 1e3), ("us", 1e6), ("ns", 1e9))
#: Unix time in s is taken from its first stamp when a double resolves it to this share of the time step.
_UNIX_RESOLUTION = 1e-3


def _unix_time(t0):
    """``(unit, factor, date)`` where the stamp ``t0`` reads as a Unix time of 2000 to 2100 in that unit, else None."""
    for unit, factor in _UNIX_UNITS:
        if _UNIX_SPAN[0] <= t0 / factor <= _UNIX_SPAN[1]:
            date = datetime.datetime.fromtimestamp(t0 / factor, datetime.timezone.utc)
            return unit, factor, date.strftime("%Y-%m-%d %H:%M:%S UTC")
    return None


def _from_unix_time(name, t):
    """``t`` (finite), taken from its first stamp where it is Unix time in s, and the note saying so (else None).

    A clock's stamps (``time.time()``, a ROS header's ``sec + nanosec 1e-9``) hold the date; the log's time is
    the same less its first stamp, which changes no step: safe where a double at the first stamp resolves a
    thousandth of the step (:data:`_UNIX_RESOLUTION`; 2.4e-7 s near 2024: steps of 0.24 ms or more). Unix time
    in ms, us or ns is refused naming its unit (fmscal reads s), as is a step too fine for the double.
    """
    found = _unix_time(float(t[0])) if len(t) else None
    if found is None:
        return t, None
    unit, factor, date = found
    if unit != "s":
        raise LogError(f"{name}: t is Unix time in {unit} (its first stamp, {t[0]:.6g}, is {date}); fmscal reads "
                       f"time in s: divide t by {factor:g} (Unix time in s is then taken from its first stamp)")
    steps = np.diff(t)
    step = float(np.median(steps)) if len(steps) else 0.0
    resolution = float(np.spacing(t[0]))
    if not step * _UNIX_RESOLUTION >= resolution:
        raise LogError(f"{name}: t is Unix time in s (its first stamp is {date}), where a double resolves "
                       f"{resolution:.2g} s, over {_UNIX_RESOLUTION:g} of the time step ({step:.3g} s): write t "
                       "from the first stamp (t - t[0]) at the source")
    return t - t[0], (f"{name}: t is Unix time (its first stamp, {t[0]:.6f} s, is {date}); taken from the first "
                      "stamp, so that the log's time starts at 0")


def _check_magnitudes(name, columns):
    """No value of each ``(column name, values)`` beyond :data:`MAX_MAGNITUDE` (NaN, a missing cell, passes; an
    infinity does not); else a one-line :class:`LogError` (naming Unix time for a ``t`` that reads as one)."""
    for col, values in columns:
        big = np.abs(np.nan_to_num(values)) > MAX_MAGNITUDE
        if big.any():
            row = int(np.argmax(big))
            clock = _unix_time(float(values[row])) if col == "t" else None
            if clock is not None:
                raise LogError(f"{name}: t holds {values[row]:.6g} at row {row + 1}: Unix time in {clock[0]} "
                               f"({clock[2]}), not the log's time in s; write t in s from the first stamp")
            raise LogError(f"{name}: column {col} holds {values[row]:.3g} at row {row + 1}; values beyond "
                           f"{MAX_MAGNITUDE:.0e} are not measurements in s, rad, m, N m or N")


def _check_steps(name, t):
    """The time step of ``t`` (finite), strictly increasing and evenly sampled (every step within
    ``_SAMPLING_TOLERANCE`` of the median); else a one-line :class:`LogError`.

    Returns
    -------
    float
        The median step, s.
    """
    steps = np.diff(t)
    if np.any(steps <= 0):
        raise LogError(f"{name}: time is not strictly increasing at row {np.argmax(steps <= 0) + 2}")
    dt = float(np.median(steps))
    spread = np.max(np.abs(steps - dt)) / dt
    if spread > _SAMPLING_TOLERANCE:
        raise LogError(f"{name}: time is not evenly sampled; steps range from "
                       f"{steps.min():.6g} to {steps.max():.6g} s (resample to one step)")
    return dt


def _first_bad(values):
    return int(np.argmax(~np.isfinite(values))) + 1


_NONFINITE = re.compile(r"(?i)(^|,)\s*[+-]?(nan|inf|infinity)\s*(?=,|$)", re.M)


def read_log(path):
    """Read a log CSV (see the module docstring for the format), plain or compressed (gzip, bzip2, xz).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    plant.Log

    Raises
    ------
    LogError
        Missing or empty file, a zip or zstandard archive, missing or misnamed columns (names in another case
        named), a cell that is not a number, NaN or infinite values, time not strictly increasing or not evenly
        sampled, too few rows or pose measurements, a quaternion not of unit norm.
    """
    path = _as_path(path, "log")
    case = _header_model(csv_header(path))
    frame = _read_csv(path, ("t", *case.pose_names, *case.wrench_names),
                      "only pose cells may be empty (no measurement)")
    return Log(frame["t"].to_numpy(), frame[list(case.pose_names)].to_numpy(),
               frame[list(case.wrench_names)].to_numpy(), name=path.name)


def log_kind(path):
    """The case a log file's header names, :attr:`fmscal.plant.Model.name` (``"planar"`` or ``"spatial"``).

    Reads the first line only; a file that is neither is left to
    :func:`read_log` (its errors are then the planar format's, the default).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    str

    Raises
    ------
    LogError
        Not a readable file.
    """
    return _header_model(csv_header(_as_path(path, "log"))).name


def _header_model(header):
    """The model (:data:`fmscal.plant.physics.MODELS`) whose declared columns a header shares most, in any case.

    A spatial header with a column missing is still spatial, so that its error names the missing spatial
    column, and one written in capitals too, so that its error names the capitals; a planar header with a
    misnamed column stays planar (a tie is the first model, the planar format, the default).
    """
    cells = {h.lower() for h in header}
    shared = [len(cells & {c.lower() for c in ("t", *m.pose_names, *m.wrench_names)}) for m in MODELS]
    return MODELS[int(np.argmax(shared))]


#: Columns of a file of raw readings (``fmscal apply``); a full log has them too.
READING_COLUMNS = ("t", "M", "fx", "fy")


def read_readings(path):
    """Read raw sensor readings: a CSV with columns ``t,M,fx,fy`` or ``t,tx,ty,tz,fx,fy,fz`` (a full log will do).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    t : ndarray, shape (N,)
        s, strictly increasing (even sampling is not required).
    w_hat : ndarray, shape (N, 3) or (N, 6)
        Planar ``[M, f_x, f_y]`` or, where the header names ``tx, ty, tz``,
        spatial ``[tx, ty, tz, fx, fy, fz]``; N m and N.

    Raises
    ------
    LogError
        Missing file or columns, a cell that is empty, not a number, NaN or
        infinite, time not strictly increasing, no rows.
    """
    path = _as_path(path, "readings")
    header = set(csv_header(path))
    names = max((m.wrench_names for m in MODELS if set(m.wrench_names) <= header), key=len, default=_WRENCH)
    frame = _read_csv(path, ("t", *names), f"every t, {', '.join(names)} cell must be a number")
    t = frame["t"].to_numpy()
    w_hat = frame[list(names)].to_numpy()
    if len(t) == 0:
        raise LogError(f"{path.name}: no readings")
    for name, values in (("t", t), *((c, w_hat[:, j]) for j, c in enumerate(names))):
        if not np.all(np.isfinite(values)):
            raise LogError(f"{path.name}: column {name} has a missing, NaN or infinite value "
                           f"at row {_first_bad(values)}")
    steps = np.diff(t)
    if np.any(steps <= 0):
        raise LogError(f"{path.name}: time is not strictly increasing at row {np.argmax(steps <= 0) + 2}")
    return t, w_hat


def _as_path(path, what="log"):
    """``path`` as a Path to an existing regular file, or a one-line :class:`LogError`."""
    if not isinstance(path, (str, os.PathLike)):
        raise LogError(f"a {what} must be given as a file name; got {type(path).__name__}")
    path = Path(path)
    problem = not_a_file(path)
    if problem == "no such file":
        raise LogError(f"{_echo(str(path))}: no such file")
    if problem is not None:
        raise LogError(f"{_echo(str(path))}: is {problem}, not a {what} file")
    return path


def _echo(text, limit=80):
    """``text`` fit for a one-line message: control characters escaped, at most ``limit`` characters.

    A longer text keeps its start and its end (a path's file name is at its end).
    """
    text = text.encode("unicode_escape").decode("ascii") if not text.isprintable() else text
    half = limit // 2
    return text if len(text) <= limit else f"{text[:half]}...{text[-half:]} ({len(text)} characters)"


def _wrong_field_count(data, n):
    """The first line of CSV bytes ``data`` (1-based, after the header) without ``n`` fields, and its count.

    Counts the commas of every line at once (numpy), so that a row of a
    million cells is refused at once: pandas would take the extra cells of
    a first data row as index columns, slowly. Empty lines are skipped, as
    pandas skips them.

    Returns
    -------
    line, fields : int
        ``(0, n)`` if every line has ``n`` fields.
    """
    b = np.frombuffer(data, dtype=np.uint8)
    newlines = np.flatnonzero(b == ord("\n"))
    starts = np.concatenate([[0], newlines + 1])
    ends = np.concatenate([newlines, [len(b)]])
    ends = ends - ((ends > starts) & (b[np.maximum(ends - 1, 0)] == ord("\r")))     # CRLF line ends
    commas = np.flatnonzero(b == ord(","))
    fields = np.searchsorted(commas, ends) - np.searchsorted(commas, starts) + 1
    bad = np.flatnonzero((fields != n) & (ends > starts))
    bad = bad[bad > 0]                                  # the header is checked on its own
    return (int(bad[0]) + 1, int(fields[bad[0]])) if len(bad) else (0, n)


#: Compressed files, told by their first bytes: the compression's name and the module that reads it (None: a
#: format fmscal does not read, an archive of several files or a codec outside Python's standard library).
_COMPRESSIONS = ((b"\x1f\x8b", "gzip", gzip), (b"BZh", "bzip2", bz2), (b"\xfd7zXZ\x00", "xz", lzma),
                 (b"PK\x03\x04", "a zip archive", None), (b"\x28\xb5\x2f\xfd", "zstandard", None))


def _read_start(path, line=False):
    """The content of ``path`` (``line``: its first line, at most 64 kB), decompressed where it is gzip, bzip2
    or xz (told by its first bytes, whatever its name).

    Raises
    ------
    LogError
        A zip archive or a zstandard file (named, with what to do), or a compressed file that does not
        decompress.
    OSError
        The file cannot be read.
    """
    with open(path, "rb") as f:
        magic = f.read(6)
    name, module = next(((n, m) for start, n, m in _COMPRESSIONS if magic.startswith(start)), (None, io))
    if name is not None and module is None:
        raise LogError(f"{_echo(path.name)}: is {name if name.startswith('a ') else name + '-compressed'}, not a "
                       "CSV; decompress it first (fmscal reads a CSV as it is, or gzip, bzip2 or xz-compressed)")
    try:
        with module.open(path, "rb") as f:
            return f.readline(65536) if line else f.read()
    except (OSError, EOFError, lzma.LZMAError, zlib.error) as err:
        if name is None or isinstance(err, (FileNotFoundError, PermissionError)):
            raise
        raise LogError(f"{_echo(path.name)}: {name}-compressed, but it does not decompress "
                       f"({_echo(str(err) or type(err).__name__)}): the file is truncated or damaged") from None


def csv_header(path):
    """A CSV file's header line as its stripped column names (a UTF-8 byte-order mark dropped; the first 64 kB).

    The file may be compressed (gzip, bzip2, xz: decompressed as it is read).

    Raises
    ------
    LogError
        A zip archive, a zstandard file, or a compressed file that does not decompress.
    OSError
        The file cannot be read.
    """
    first = _read_start(Path(path), line=True)
    return [h.strip() for h in first.decode("utf-8", errors="replace").removeprefix("\ufeff").split(",")]


def _read_csv(path, required, empty_rule):
    """A CSV with the ``required`` columns, every cell a number or empty; one-line errors."""
    import pandas as pd     # heavy: only reading a CSV needs it, not importing fmscal.plant

    data = _read_start(path)
    if not data.strip():
        raise LogError(f"{_echo(path.name)}: the file is empty ({'0 bytes' if not data else 'only blank lines'}): "
                       "nothing to read; a CSV with its header on the first line is expected")
    nul = data.find(b"\0")
    if nul >= 0:
        raise LogError(f"{path.name}: holds a NUL byte at offset {nul}; not a text CSV")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise LogError(f"{path.name}: not UTF-8 text (byte 0x{data[err.start]:02x} at offset {err.start}); "
                       "save the CSV as UTF-8 (the columns are plain ASCII)") from None
    text = text.removeprefix("\ufeff")       # a byte-order mark some spreadsheets write
    first = text.split("\n", 1)[0].strip()
    if first.startswith("#"):
        raise LogError(f"{path.name}: line 1 is a comment ({_echo(first[:40])}); the column header must be the "
                       "first line: delete the comment lines")
    for name, delimiter in (("semicolons", ";"), ("tabs", "\t")):
        if "," not in first and first.count(delimiter) >= len(required) - 1:
            raise LogError(f"{path.name}: the columns are separated by {name}; fmscal reads comma-separated "
                           f"files (save it with ',' between the cells)")
    header = [h.strip() for h in first.split(",")]
    if len(header) > 2 * len(COLUMNS) + 10 or len(first) > 1000:
        raise LogError(f"{path.name}: the first line is not a CSV header ({len(header)} cells, {len(first)} "
                       f"characters: {_echo(first)}); expected {','.join(required)}")
    duplicated = sorted({h for h in header if header.count(h) > 1})
    if duplicated:
        raise LogError(f"{path.name}: column(s) {_echo(', '.join(duplicated))} appear more than once in the header "
                       f"{_echo(','.join(header))}; keep one of each")
    missing = [c for c in required if c not in header]
    other_case = [h for h in header if h not in required and h.lower() in {c.lower() for c in missing}]
    if other_case:
        absent = [c for c in missing if c.lower() not in {h.lower() for h in other_case}]
        raise LogError(f"{path.name}: column(s) {_echo(', '.join(other_case))} are named in another case; column "
                       f"names are case-sensitive: write the header as {','.join(required)}"
                       + (f" ({', '.join(absent)} missing too)" if absent else ""))
    if missing:
        raise LogError(f"{path.name}: missing column(s) {', '.join(missing)}; expected the header "
                       f"{','.join(required)} (got {_echo(','.join(header))})")
    line, fields = _wrong_field_count(data, len(header))
    del data
    if line:
        raise LogError(f"{path.name}: line {line} has {fields} fields (row {line - 1}); the header has "
                       f"{len(header)} ({_echo(','.join(header))}); every row needs one cell per column")
    body = text.find("\n") + 1                 # a NaN or an infinity has an n, a number none: the pattern only there
    match = _NONFINITE.search(text) if text.find("n", body) >= 0 or text.find("N", body) >= 0 else None
    if match:
        line = text.count("\n", 0, match.start()) + 1
        raise LogError(f"{path.name}: line {line} (row {line - 1}) holds a NaN or infinite value; {empty_rule}")
    try:
        return pd.read_csv(io.StringIO(text), skipinitialspace=True, dtype=float)
    except pd.errors.ParserError as err:
        raise LogError(f"{path.name}: not a well-formed CSV ({_echo(str(err).splitlines()[0])})") from None
    except ValueError as err:
        raise LogError(f"{path.name}: a cell is not a number ({_echo(str(err).splitlines()[0])})") from None


@dataclass
class Truth:
    """What produced a simulated log: the sidecar ``NAME.truth.json``.

    Attributes
    ----------
    scenario : str
    seed : int
    schedule : plant.CalibrationSchedule
        The true ``S`` (constant) or its schedule.
    S0 : ndarray, shape (n_w, n_w)
        The initial estimate the scenario prescribes to every observer.
    payload : plant.Payload or plant.SpatialPayload
    noise : plant.NoiseSpec
        Standard deviations of the noise added to the log.
    told_noise : float
        What a method with a noise model is told, as a multiple of ``noise``
        (1: the truth; a scenario may tell a wrong figure on purpose).
    offset : ndarray, shape (n_w,), or None
        The sensor's offset ``b`` in ``w = S (w_hat - b)``, N m and N.
    latency : float
        Delay of the pose stream behind the sensor stream, s (negative: the wrench behind the poses).
    settings : dict
        The rest of the scenario, for the record (duration, dt, pose rate,
        dropped frames, outliers, description).
    """

    scenario: str
    seed: int
    schedule: CalibrationSchedule
    S0: np.ndarray
    payload: Payload
    noise: NoiseSpec
    told_noise: float = 1.0
    offset: np.ndarray = None
    latency: float = 0.0
    settings: dict = field(default_factory=dict)

    def S_at(self, t):
        """The true ``S`` at time ``t``."""
        return self.schedule.at(t)

    def told_noise_spec(self):
        """The :class:`plant.NoiseSpec` a method with a noise model is told (``noise`` times ``told_noise``)."""
        return self.noise.scaled(self.told_noise)

    def to_json(self):
        data = {"scenario": self.scenario, "seed": self.seed}
        data.update(self.schedule.to_json())
        data["S0"] = np.asarray(self.S0).tolist()
        data.update(self.payload.to_dict())
        data["noise"] = self.noise.to_dict()
        data.update(self.settings)
        data.update({"told_noise": float(self.told_noise), "latency": float(self.latency),
                     "offset": None if self.offset is None else [float(v) for v in self.offset]})
        return data

    def write(self, path):
        """Write the sidecar as JSON (atomically)."""
        atomic_write_text(path, json.dumps(self.to_json(), indent=2) + "\n")


def read_truth(path):
    """Read a ``NAME.truth.json`` sidecar into a :class:`Truth`.

    Raises
    ------
    LogError
        Missing file, a folder, not UTF-8, not JSON (or nested too deeply), or a missing key.
    """
    path = _as_path(path, "truth")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(data, dict):
            raise LogError(f"{path.name}: not a truth sidecar (a JSON {type(data).__name__}, not an object)")
        if "S" in data:
            schedule = CalibrationSchedule(data["S"])
        else:
            schedule = CalibrationSchedule([(t0, S) for t0, S in data["S_schedule"]])
        known = {"scenario", "seed", "S", "S_schedule", "S0", "mass", "inertia", "rho", "com", "noise", "told_noise",
                 "offset", "latency"}
        offset = data.get("offset")
        spatial = schedule.size == 6
        return Truth(
            scenario=data.get("scenario", "unknown"), seed=data.get("seed"),
            schedule=schedule, S0=check_calibration(data["S0"], "S0", size=schedule.size),
            payload=(SpatialPayload if spatial else Payload).from_dict(data), noise=NoiseSpec.from_dict(data["noise"]),
            told_noise=as_positive_scalar(data.get("told_noise", 1.0), "told_noise"),
            offset=None if offset is None else as_finite_array(offset, (schedule.size,), "offset"),
            latency=_latency(data.get("latency") or 0.0),
            settings={k: v for k, v in data.items() if k not in known})
    except json.JSONDecodeError as err:
        raise LogError(f"{path.name}: not valid JSON ({err})") from None
    except RecursionError:
        raise LogError(f"{path.name}: not a truth sidecar (JSON nested too deeply)") from None
    except UnicodeDecodeError as err:
        raise LogError(f"{path.name}: not UTF-8 text (offset {err.start})") from None
    except LogError:
        raise
    except KeyError as err:
        raise LogError(f"{path.name}: missing key {err} in the truth file") from None
    except (TypeError, ValueError) as err:
        raise LogError(f"{path.name}: {str(err).splitlines()[0]}") from None
