"""Calibrate recorded data: one call for every case, the fit diagnostics, and how far to trust the answer.

:func:`calibrate` does what ``fmscal calibrate`` does, on a planar log, a
spatial log, a pose table, an attitude-only log's held segments, or a log or
table of joint angles turned into poses (:func:`read_data` reads any of
them), and returns one :class:`fmscal.plant.Calibration`: the estimate with
its diagnostics, ready to ``save``.
"""

import copy
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from fmscal.observers import FLOOR_METHOD, LeastSquares, get_method, make_observer, method_names
from fmscal.observers.batch import (describe_direction, estimate_latency, fit_latency, given_latency_warnings,
                                   payload_sensitivity)
from fmscal.observers.core import (EVIDENCE_TOLERANCE, SETTLE_FRACTION, SETTLE_TOLERANCE, bridge_glitches,
                                   calibration_uncertainty)
from fmscal.observers.diagnostics import (centre_of_mass_words, consistency_check, fit_causes, has_evidence,
                                          inertia_note, misfit, offset_drift, saturation)
from fmscal.observers.diagnostics import inflate as inflate_misfit
from fmscal.observers.payload import PayloadEstimate, StaticFit, other_convention
from fmscal.observers.payload import calibrate_table as fit_table
from fmscal.plant import (Calibration, FmscalError, Log, Model, NoiseSpec, PayloadStd, SingularCalibrationError,
                          SpatialPayload, Truth, estimate_noise, read_log, read_truth)
from fmscal.plant.io import (COUNTS, AttitudeLog, LogError, PoseTable, RobotKinematics, check_poses_move,
                             check_spatial_log_units,
                             check_table_units, diagnose_units, held_table, is_attitude_log, is_pose_table, not_a_file,
                             read_attitude_log, read_joint_data, read_pose_table, reading_sign)
from fmscal.plant.numerics import as_bool, as_number
from fmscal.plant.physics import GRAVITY, PayloadStdError, as_model, find_model

from ._metrics import calibration_error

__all__ = ["DEFAULT_METHOD", "DEFAULT_MAX_LATENCY", "TABLE_METHOD", "calibrate", "read_data", "DivergedError",
           "OptionError"]

#: The default: the maximum-likelihood estimate, at the information floor by construction, on
#: full-rate and multi-rate logs, with offset and latency; its noise model is estimated from the
#: log when not given (docs/comparison.md, "Which observer to trust").
DEFAULT_METHOD = FLOOR_METHOD
#: Largest magnitude of the pose-stream delay searched when the latency is estimated, s (either sign).
DEFAULT_MAX_LATENCY = 0.1
#: The one fit of held poses (a pose table): least squares on the weight's wrench.
TABLE_METHOD = "static-least-squares"
#: A method's estimate disagrees with the least-squares fit of the same log when an entry differs by more
#: than this many (combined) standard deviations ...
AGREEMENT_SIGMAS = 6.0
#: ... and the two calibrations differ by more than this E (eq. 16, one against the other).
AGREEMENT_E = 0.01


class DivergedError(FmscalError):
    """The estimate diverged: there is no calibration to report."""


class OptionError(FmscalError):
    """An option refused, named in the message as the caller names it.

    Parameters
    ----------
    option : str
        The keyword argument (``"pose_noise"``, ``"offset=False"``).
    template : str
        The message with ``{}`` where the option's name goes; ``str(err)``
        names the keyword; a command line puts its own flag there
        (``err.template.format("--pose-noise")``).
    """

    def __init__(self, option, template):
        super().__init__(template.format(option))
        self.option, self.template = option, template


def read_data(path, urdf=None, frame=None):
    """Read any file :func:`calibrate` takes, the case told by its header.

    Parameters
    ----------
    path : str or Path
        A planar log (``t,theta,x,y,M,fx,fy``), a spatial log
        (``t,qw,qx,qy,qz,x,y,z,tx,ty,tz,fx,fy,fz``), a pose table (the
        spatial header without ``t``: one row per held pose), an
        attitude-only log (no ``x,y,z``), or, with ``urdf``, a log or table
        whose pose columns are the robot's joint angles.
    urdf : str or Path, optional
        The robot's URDF: the pose columns are joint angles (rad), turned
        into poses of ``frame`` by forward kinematics
        (:class:`fmscal.plant.io.RobotKinematics`; pinocchio).
    frame : str, optional
        The sensor's frame in the URDF (with ``urdf``).

    Returns
    -------
    plant.Log or plant.io.PoseTable or plant.io.AttitudeLog

    Raises
    ------
    FmscalError
        The file's problems (one line), or one of ``urdf`` and ``frame`` without the other.
    """
    if (urdf is None) != (frame is None):
        raise OptionError("urdf and frame", "{} go together: the robot's URDF and the sensor's frame in it")
    if not isinstance(path, (str, os.PathLike)):
        raise LogError(f"a log must be given as a file name; got {type(path).__name__}")
    problem = not_a_file(Path(path))
    if problem is not None:
        what = "no such file" if problem == "no such file" else f"is {problem}, not a log file"
        raise LogError(f"{str(path)[:80]}: {what}")
    if urdf is not None:
        return read_joint_data(path, RobotKinematics(urdf, frame))
    if is_pose_table(path):
        return read_pose_table(path)
    if is_attitude_log(path):
        return read_attitude_log(path)
    return read_log(path)


def calibrate(data, payload, *, observer=None, reading=None, gravity=None, latency=None, max_latency=None,
              offset=True, pose_noise=None, wrench_noise=None, truth=None, max_mass=None, payload_std=None,
              method=None):
    """Estimate ``S`` and the sensor's offset from recorded data, with diagnostics: ``fmscal calibrate`` in Python.

    The case comes from ``data``:

    - a **planar log**: every method runs on the log with its pose stream
      moved back by the latency (given, or estimated to a fraction of a
      sample with its standard deviation, of either sign,
      :func:`fmscal.observers.batch.estimate_latency`; its variance is then
      carried into ``S_std``, ``b_std`` and ``cov``,
      and a latency the log does not determine, or one that steps mid-log,
      leaves ``converged`` False). Where the maximum-likelihood floor is
      the method, its own likelihood checks the estimate: where it prefers
      a latency more than :data:`fmscal.observers.batch.AGREEMENT_SIGMAS`
      of the estimate's standard deviations away, the log is fitted again
      at the floor's latency, and a note says so (rule 8 of
      :mod:`fmscal.observers.batch._latency`). A latency given is checked
      against the estimate (a warning naming both beyond
      :data:`~fmscal.observers.batch.AGREEMENT_SIGMAS` standard deviations)
      and ``converged`` is False where the fit at it is measurably worse:
      the floor's own step from it beyond that many of its standard
      deviations, for another method the estimate that far (rule 9).
      The noise model not given is estimated from the log as recorded,
      before its poses are moved (interpolated between measurements, a
      fraction of a sample, their noise is smoothed, and a method measuring
      it on them would take it for less);
    - a **spatial log**: the same in 3D (the maximum-likelihood floor by
      default, or least squares, or an online method that runs in 3D), the
      reading's sign turned first for ``reading="load"``;
    - **held poses** (a pose table, an attitude-only log's held segments):
      ``S`` and the offset from the weight's wrench at each pose
      (:func:`fmscal.observers.payload.calibrate_table`). Held poses never
      determine ``S`` in full: the directions of the reading they leave
      undetermined are named and ``converged`` is False.

    An option the case does not take is refused in one line.

    Parameters
    ----------
    data : plant.Log, plant.io.PoseTable, plant.io.AttitudeLog, str or Path
        What was recorded; a path is read by :func:`read_data`.
    payload : plant.Payload, plant.SpatialPayload, plant.Model, observers.payload.PayloadEstimate or (float, array_like)
        The payload's mass properties: a planar log takes a
        :class:`~fmscal.plant.Payload` (or a :class:`~fmscal.plant.PlanarModel`), a
        spatial log a :class:`~fmscal.plant.SpatialPayload` (or a
        :class:`~fmscal.plant.SpatialModel`, which brings its gravity). Held poses
        use only the mass and the centre of mass: a ``SpatialPayload``, or
        the pair ``(mass, com)`` (kg, and m in the sensor frame; the result then has no
        payload and cannot be saved). A :class:`~fmscal.observers.payload.PayloadEstimate`
        (``identify_payload``'s, or one read by ``PayloadEstimate.load``) stands for its payload
        in the tracked frame's axes, and brings the gravity it estimated.
    observer : str, optional
        The method, by its name: one offered for calibration in the case
        (``observers.method_names(calibrates=True, model=...)``); default
        :data:`DEFAULT_METHOD`. Held poses have one fit (:data:`TABLE_METHOD`).
        The keyword is the command line's flag (``--observer``), as in
        :func:`fmscal.analysis.compare` and :func:`fmscal.analysis.sweep` (``observers``).
    reading : {"reaction", "load"}, optional
        Spatial logs and held poses: the reading's sign, the wrench the mount
        applies to the payload (the default) or the wrench the tool applies
        to the sensor (as ATI, Robotiq, Bota and OnRobot report); recorded
        in the calibration. ``data`` itself is never changed.
    gravity : array_like, shape (3,), optional
        Spatial logs and held poses: gravity in the pose frame, m/s^2
        (default ``(0, 0, -9.81)``).
    latency : float, optional
        Logs: delay of the pose stream behind the sensor stream, s, any
        fraction of a sample; negative: the wrench stream behind the poses
        (a sensor's internal filter); less than half the log in magnitude.
        None: estimated. Given, it is checked against the log's own estimate (above).
    max_latency : float, optional
        Logs: the largest magnitude of the delay searched when it is
        estimated, s, either sign (default :data:`DEFAULT_MAX_LATENCY`).
    offset : bool
        Estimate the sensor's offset ``b`` in ``w = S (w_hat - b)`` with
        ``S`` (the default: a real sensor reads non-zero under no load, and an
        offset left out biases ``S_hat`` far more than estimating a few more
        numbers costs). Only planar logs take False: in 3D it is always estimated.
    pose_noise : (float, float), optional
        Planar logs: standard deviations of the angle (rad) and of the positions (m).
    wrench_noise : (float, float, float), optional
        Planar logs: standard deviations of the raw reading ``[M, f_x, f_y]``
        (N m, N). Noise not given is estimated from the log and reported.
    truth : plant.Truth or str or Path, optional
        Logs: the truth (or its sidecar file, ``fmscal simulate``'s), for E of eq. (16).
    max_mass : float, optional
        Spatial logs and held poses: the heaviest payload taken, kg (default
        :data:`fmscal.plant.io.MAX_WRIST_MASS`); a mass given beyond it is refused as a slipped unit (g).
    payload_std : plant.PayloadStd, optional
        Logs: how well the payload is known (the mass's, the centre of mass's
        and the inertia's standard deviations, and gravity's size's). What is
        not stated takes the defaults of :mod:`fmscal.plant.physics._payload_std`
        (a weighed mass, a CAD centre of mass and inertia, ``g`` not measured),
        or a :class:`~fmscal.observers.payload.PayloadEstimate`'s own (its
        covariance where it has one). Carried into ``S_std``, ``b_std`` and
        ``cov`` (eq. (Y1) of :mod:`fmscal.observers.batch._payload_sensitivity`);
        ``PayloadStd.exact()`` takes the payload as exact. Held poses take
        the payload as exact (refused).
    method : str, optional
        ``observer``'s former name, still taken (an alias: give one of the two).

    Returns
    -------
    plant.Calibration
        ``S_hat``, ``S_std``, ``b``, ``b_std``, ``cov`` (where the method
        gives one), ``latency``, ``latency_std`` (estimated: its standard
        deviation, else None) and ``latency_estimated``, ``reading``,
        ``gravity``, ``method``, ``payload``, ``noise`` (the noise model the
        method was given, else the log's measured by
        :func:`fmscal.plant.estimate_noise`; the compensation's covariance
        reads it), ``converged``, ``warnings``, ``undetermined`` (in words) and
        ``undetermined_directions``, ``E`` with a truth, ``notes`` and the
        method's full ``run``; ``save(path)`` writes it, ``to_json()`` is
        ``fmscal calibrate --json``'s report. On a log, ``S_std`` is the
        statistical part (the log's noise, the latency's uncertainty, a
        misfit's widening: ``S_std_statistical``) and the payload's
        (``S_std_payload``, from ``payload_cov``, the payload's covariance
        over the model's :meth:`~fmscal.plant.Model.payload_parameter_names`)
        in quadrature; ``cov`` holds both.

        ``converged``, on a planar log: the method's ``converged`` flag
        (:class:`fmscal.observers.ObserverResult`), and the log's units look right
        (``units`` empty), a least-squares fit of it finds it exciting every entry and
        matching the model, the log is consistent with one constant ``S``
        (:func:`fmscal.observers.diagnostics.consistency_check`), no channel
        of the reading saturates (:func:`fmscal.observers.diagnostics.saturation`), the
        offset keeps one level (:func:`fmscal.observers.diagnostics.offset_drift`), and the
        method's estimate agrees with the least-squares fit (within
        :data:`AGREEMENT_SIGMAS` standard deviations or an E of
        :data:`AGREEMENT_E`). On a spatial log: the method's flag, no
        saturation, the log pins ``S`` down for a method that gives no
        ``S_std`` (:func:`fmscal.observers.diagnostics.has_evidence`: the
        run judged settling alone), the offset keeps one level, ``S``'s gain one
        value, and gravity is along the direction given
        (:func:`fmscal.observers.diagnostics.fit_causes`: else a warning names
        the moving offset or gain, or the base's tilt), a positive
        force gain (``trace S_ff > 0``: else the reading follows the other sign
        convention), and the model
        fits the log (:func:`fmscal.observers.diagnostics.misfit`; where it
        does not, ``S_std`` is widened and the warning says by how much the
        residual exceeds the noise; an inertia whose shape the log's torques
        put beyond its stated uncertainty is named); a diagonal gain of ``S`` the log
        determines further than :data:`FAR_GAIN` from 1 adds a warning naming
        the payload's mass or the units, and leaves ``converged`` as it is.
        Held poses: never. Each failure adds a warning that names it.

        A log's steps are chosen by what its model declares
        (:class:`fmscal.plant.Model`: the options it takes, ``under_gravity``,
        ``signed_reading``, ``given_noise``, ``optional_offset``, and its
        ``calibration_checks``, each documented in this module), not by the
        case's name or class.

    Raises
    ------
    DivergedError
        The method's estimate diverged.
    plant.io.UnitsError
        A spatial log's or held poses' unit slip or convention, named in one line
        before any fit (the model's ``input_checks``; :func:`fmscal.plant.io.check_spatial_log_units`,
        :func:`fmscal.plant.io.check_table_units`).
    FmscalError
        Bad input (among it a reading channel that never changes), an option
        the case does not take, or an estimate of ``S`` that is singular (one
        line each).
    """
    offset = as_bool(offset, "offset")                  # text ("False") is refused, not taken as true
    if isinstance(payload, StaticFit):                  # a pose table's fit stands for its payload as a log's does
        payload = payload.tracked()
    try:
        calibration = _calibrate_data(data, payload, _observer(observer, method), reading, gravity, latency,
                                      max_latency, offset, pose_noise, wrench_noise, truth, max_mass, payload_std)
    except OptionError as err:                          # the method refused: named by the keyword the caller gave
        if err.option == "observer" and observer is None and method is not None:
            raise OptionError("method", err.template) from None
        raise
    if isinstance(payload, PayloadEstimate) and not payload.converged:
        # the payload is the model's: a fit that did not converge (a rotation it could not settle, too few poses)
        # leaves every S estimated with it in doubt, whatever the log says
        calibration = replace(calibration, converged=False, warnings=[
            *calibration.warnings, "the payload estimate did not converge (identify-payload's warnings say why): "
            "a calibration with its mass properties is not converged either"])
    return calibration


def _observer(observer, method):
    """The method's name from ``observer=`` or its alias ``method=`` (None: the default); both given must agree."""
    if method is not None and observer is not None and method != observer:
        raise OptionError("observer", f"{{}} {observer!r} and method {method!r} name one option (method= is "
                          "observer='s former name): give observer only")
    return method if observer is None else observer


def _calibrate_data(data, payload, method, reading, gravity, latency, max_latency, offset, pose_noise, wrench_noise,
                    truth, max_mass=None, payload_std=None):
    """:func:`calibrate` on its inputs, the payload estimate's own convergence aside."""
    if payload_std is not None and not isinstance(payload_std, PayloadStd):
        raise OptionError("payload_std", f"{{}} must be a plant.PayloadStd or None; got {type(payload_std).__name__}")
    if isinstance(data, (str, os.PathLike)):
        data = read_data(data)
    if isinstance(data, (AttitudeLog, PoseTable)):
        _refuse("held poses", [(payload_std is not None, "payload_std", "their fit takes the payload as exact; S is "
                                "never converged from held poses")])
    if isinstance(data, AttitudeLog):
        table, _, note = held_table(data)
        return _calibrate_table(table, payload, method, reading, gravity, latency, max_latency, offset, pose_noise,
                                wrench_noise, truth, [note], "attitude-only log, its held segments", max_mass)
    if isinstance(data, PoseTable):
        return _calibrate_table(data, payload, method, reading, gravity, latency, max_latency, offset, pose_noise,
                                wrench_noise, truth, [], "pose table", max_mass)
    if not isinstance(data, Log):
        raise FmscalError(f"data must be a plant.Log, a pose table, an attitude-only log or a file name; "
                          f"got {type(data).__name__}")
    if latency is not None and not _number(latency):
        raise OptionError("latency", f"{{}} must be a number of seconds (negative: the wrench behind the poses); "
                          f"got {latency}")
    if latency is not None and not abs(latency) < data.duration / 2:
        raise OptionError("latency", f"{{}} must be less than half the log ({data.duration / 2:g} s) in magnitude: "
                          f"the poses are shifted by it; got {latency:g} s")
    if max_latency is not None and not (_number(max_latency) and max_latency > 0):
        raise OptionError("max_latency", f"{{}} must be positive; got {max_latency}")
    return _calibrate_log(data, log_model_class(data), payload, method, reading, gravity, latency, max_latency, offset,
                          pose_noise, wrench_noise, truth, max_mass, payload_std)


def _number(value):
    return isinstance(value, (int, float, np.number)) and not isinstance(value, bool) and bool(np.isfinite(value))


def _noise(values, size, name):
    """``values`` as ``size`` non-negative standard deviations, or None."""
    if values is None:
        return None
    values = tuple(values) if np.ndim(values) == 1 else ()
    if len(values) != size or not all(_number(v) and v >= 0 for v in values):
        raise OptionError(name, f"{{}} must be {size} non-negative standard deviations; got {values or 'a scalar'}")
    return values


def _truth(truth, model):
    """``truth`` (a Truth, its file, or None) of a log of ``model``, or a one-line refusal."""
    if truth is None:
        return None
    if isinstance(truth, (str, os.PathLike)):
        source, truth = str(truth), read_truth(truth)
    elif isinstance(truth, Truth):
        source = f"truth (scenario {truth.scenario!r})"
    else:
        raise FmscalError(f"truth must be a plant.Truth or its file; got {type(truth).__name__}")
    if truth.schedule.size != model.n_w:
        other = getattr(find_model(n_w=truth.schedule.size), "name", "another")
        raise FmscalError(f"{source} is the truth of a {other} log; this log is {model.name}")
    return truth


def _refuse(case, given):
    """One line for the first option in ``given`` (``(present, name, why)``) that ``case`` does not take."""
    for present, name, why in given:
        if present:
            raise OptionError(name, f"{{}} is not taken on {case} ({why})")


def _gravity(gravity):
    """``gravity`` (m/s^2, the pose frame's) as three floats, or the default."""
    g = GRAVITY if gravity is None else gravity
    if np.shape(g) != (3,) or not (all(_number(v) for v in g) and 0 < np.linalg.norm(g) < 1e3):
        raise OptionError("gravity", "{} must be three finite numbers in m/s^2 (the pose frame's gravity); got "
                          f"{np.asarray(g).tolist() if np.size(g) < 10 else np.shape(g)}")
    return tuple(float(v) for v in g)


def _estimate_payload(estimate):
    """A :class:`PayloadEstimate` as ``(mass, com, SpatialPayload or None, gravity or None)``, tracked-frame axes."""
    tracked = estimate.tracked()
    if not tracked.payload_determined:
        raise FmscalError("the payload estimate does not determine the mass and the centre of mass: no payload "
                          "to calibrate with")
    spatial = None if tracked.inertia is None else SpatialPayload(tracked.mass, tuple(tracked.inertia),
                                                                  tuple(tracked.com))
    return tracked.mass, np.asarray(tracked.com, dtype=float), spatial, tracked.gravity


def _merge_gravity(given, estimated):
    """The gravity given, else the one a payload estimate brings; both: they must agree."""
    if estimated is None:
        return given
    estimated = tuple(float(v) for v in estimated)
    if given is not None and not np.allclose(_gravity(given), estimated, rtol=1e-6, atol=1e-9):
        raise FmscalError("gravity contradicts the gravity the payload estimate holds; give one of them")
    return estimated


def log_model_class(log):
    """The class of the model whose columns ``log``'s are (:func:`fmscal.plant.physics.find_model`), or a refusal.

    Parameters
    ----------
    log : plant.Log

    Returns
    -------
    type
        A :class:`fmscal.plant.Model` subclass.

    Raises
    ------
    FmscalError
        No model declares the log's columns.
    """
    cls = find_model(columns=log.columns)
    if cls is not None:
        return cls
    raise FmscalError(f"{log.name}: a {log.kind} log; calibrate takes a planar or a spatial one")


def _log_payload_model(cls, payload, gravity):
    """The model a log of the model class ``cls`` is calibrated on, or a one-line refusal.

    ``payload`` (a model, a payload, or a :class:`PayloadEstimate` standing for its payload) is taken
    through :func:`fmscal.plant.physics.as_model` and must declare ``cls``'s columns; ``gravity`` is taken
    where ``cls`` is :attr:`~fmscal.plant.Model.under_gravity` (a model given brings its own).
    """
    what = f"a {cls.name} log"
    refusal = (f"{what} takes a plant.{cls.payload_type.__name__} (or a plant.{cls.__name__}); got "
               f"{type(payload).__name__}")
    given = payload
    if isinstance(payload, PayloadEstimate):       # a payload weighed under gravity, in the tracked frame's axes
        if not cls.under_gravity:
            raise FmscalError(refusal)
        _, _, estimated_payload, estimated = _estimate_payload(payload)
        if estimated_payload is None:
            raise FmscalError(f"{what} needs the payload's inertia, which the payload estimate does not hold; "
                              f"give a plant.{cls.payload_type.__name__}")
        gravity = _merge_gravity(gravity, estimated)
        given = estimated_payload
    try:
        model = as_model(given)
    except FmscalError:
        model = None
    if model is None or (model.pose_names, model.wrench_names) != (cls.pose_names, cls.wrench_names):
        raise FmscalError(refusal)
    if not cls.under_gravity:
        if gravity is not None:
            raise OptionError("gravity", "{} is for spatial logs; a planar log moves in a plane with no gravity in "
                              "it")
        return model
    if isinstance(given, Model):
        if gravity is not None and _gravity(gravity) != model.gravity:
            raise FmscalError(f"gravity is the model's: give the plant.{cls.__name__} with that gravity, or a "
                              f"plant.{cls.payload_type.__name__} and gravity")
        return model
    return cls(model.payload, _gravity(gravity))


def _calibrate_log(log, cls, payload, method, reading, gravity, latency, max_latency, offset, pose_noise,
                   wrench_noise, truth, max_mass=None, payload_std=None):
    """:func:`calibrate` on a log of the model class ``cls``: one workflow, each step as the model declares.

    The options the model does not take are refused (``signed_reading``, ``given_noise``,
    ``optional_offset``, ``under_gravity``); the reading is turned into the toolkit's sign; the noise
    model given is completed from the log (``given_noise``); the latency is estimated if not given; the
    method runs on the log with its poses moved back by it; then the model's ``calibration_checks`` run
    in their order (:data:`_CHECKS`), and ``converged`` is the run's flag and every check passed; last, the
    payload's uncertainty is carried into the result (:func:`_with_payload_uncertainty`).
    """
    model = _log_payload_model(cls, payload, gravity)
    payload_cov = _payload_covariance(model, _payload_std(payload, payload_std))
    case = f"a {cls.name} log"
    constant = [name for name, column in zip(model.wrench_names, log.w_hat.T) if np.ptp(column) == 0]
    if constant:                        # no real channel reads one value to the last bit: nothing to fit
        raise FmscalError(f"{log.name}: column(s) {', '.join(constant)} of the reading never change (every row "
                          f"{log.w_hat[0, model.wrench_names.index(constant[0])]:g}): a channel not connected or "
                          "a column written empty; check the recording")
    check_poses_move(log, model.wrench_names)         # a stalled tracker, before any fit
    if reading is not None and not model.signed_reading:
        raise OptionError("reading", "{} is taken on a spatial log or a pose table; a planar log's sign is the "
                          "toolkit's")
    if max_mass is not None and "spatial_units" not in model.input_checks:
        raise OptionError("max_mass", f"{{}} is taken on a spatial log or a pose table; {case} has no mass limit")
    for check in model.input_checks:                    # before any fit: a slipped unit is named in one line
        _INPUT_CHECKS[check](log, model, max_mass=max_mass)
    name = DEFAULT_METHOD if method is None else method
    get_method(name)                                    # an unknown name: FmscalError naming the methods
    offered = method_names(calibrates=True, model=model)
    if name not in offered:
        raise OptionError("observer", f"{{}} {name} does not run on {case} yet; {case} takes {', '.join(offered)} "
                          f"(default {DEFAULT_METHOD})")
    _refuse(case, [
        (pose_noise is not None and not model.given_noise, "pose_noise", "the noise is estimated from the log"),
        (wrench_noise is not None and not model.given_noise, "wrench_noise", "the noise is estimated from the log"),
        (not offset and not model.optional_offset, "offset=False", "the offset is always estimated in 3D")])
    pose_noise = _noise(pose_noise, 2, "pose_noise")
    wrench_noise = _noise(wrench_noise, model.n_w, "wrench_noise")
    max_latency = DEFAULT_MAX_LATENCY if max_latency is None else max_latency
    truth = _truth(truth, model)
    reading = "reaction" if reading is None else reading
    signed = copy.copy(log)                               # the caller's log keeps its reading
    signed.w_hat = reading_sign(reading) * log.w_hat      # the toolkit's sign: S and b are of sigma w_hat
    # the reading's glitches bridged once, for the latency search and every method (observers.core.bridge_glitches)
    signed, glitches = bridge_glitches(signed, model.wrench_names)
    noise, noise_estimated = None, []
    if model.given_noise:
        noise, noise_estimated = _noise_model(log, model, pose_noise, wrench_noise)
    latency_estimated = latency is None
    # the log's own latency: the one used where none is given, else what the one given is checked against
    timing = _latency_estimate(signed, model, max_latency, offset, latency_estimated)
    latency = timing.latency if latency_estimated else float(latency)
    # the noise of the poses as recorded: moved by a fraction of a sample, they are interpolated between
    # measurements, which smooths their noise, and a method's own estimate from them would take it for less
    told = noise if noise is not None else estimate_noise(signed)
    reference = LeastSquares(model, offset=offset) if "reference" in model.calibration_checks else None
    aligned, ls_result, result = _run_aligned(signed, latency, model, name, told, offset, glitches, reference)
    moved = fit_latency(timing, result.info.get("latency_step")) if latency_estimated else None
    if moved is not None:                # the fit's own likelihood prefers another latency (rule 8): fitted there
        timing, latency = moved, moved.latency
        aligned, ls_result, result = _run_aligned(signed, latency, model, name, told, offset, glitches, reference)
    result = _with_latency_uncertainty(result, timing if latency_estimated else None)
    try:                                # how S moves with the payload: its uncertainty's way into S_std (eq. Y1)
        # the misfit's noise (its eq. (M1)): a coloured reading's standard deviation is the noise model's (eq. (N2)
        # of plant/io/_noise.py), which the scatter about neighbouring samples reads small
        sensitivity = payload_sensitivity(aligned, model, offset=offset,
                                          wrench_sd=None if told.white else told.wrench_sd)
    except FmscalError as err:
        sensitivity, payload_problem = None, str(err)
    run = _Run(log, signed, aligned, model, name, result, ls_result, offset, reading, glitches=glitches,
               latency=timing, latency_given=None if latency_estimated else latency,
               sensitivity=sensitivity, payload_cov=payload_cov)
    warnings, why = [], None
    if sensitivity is None:
        warnings.append(f"the payload's uncertainty could not be carried into S_std ({payload_problem}): S_std takes "
                        "the payload as exact")
        why = "S_std does not carry the payload's uncertainty"
    if glitches.found and get_method(name).online:     # a live run of the method would take them as they came
        warnings.append(f"{glitches.summary()}; {name} ran on the bridged log, where a live run would take the "
                        "glitches as they came")
    converged = bool(result.converged)
    if glitches.unbridged:             # a frozen stretch longer than a bridge holds (observers.core, eq. (F3))
        why = (f"{glitches.frozen_summary(glitches.unbridged)} too long to bridge from the samples around "
               "them (or at the log's end): the reading there is not known; check the sensor's driver and "
               "connection, or calibrate on a log without them")
        warnings.append(why)
        converged = False
    for check in model.calibration_checks:
        found, passed, reason = _CHECKS[check](run, warnings)
        warnings += found
        converged = converged and passed
        why = why or (None if passed else reason)
    converged = converged and sensitivity is not None
    if not converged:
        why = why or _UNSETTLED
    notes = list(signed.notes)
    effects = _effects_of_the_cause(run, name, warnings)
    warnings = [w for w in warnings if w not in effects]
    notes += [f"after the cause named: {w}" for w in effects]
    shape = getattr(run.misfit, "inertia", None)
    # the shape the log sees, in words; a cause named (a moving offset, gravity, a centre of mass), or a misfit on
    # one force channel alone, which no inertia leaves, is why it did not converge; a latency's step gone at the
    # centre of mass the log prefers (M5) is the centre of mass's (or a turn of the poses' frame, which moves it)
    com = getattr(run.misfit, "centre_of_mass", None)
    explained = run.named or getattr(run.misfit, "alone", None) is not None
    if not converged and not explained and why == _LATENCY_STEP and _step_of_the_centre_of_mass(run, com,
                                                                                                 max_latency):
        step = run.latency.step                     # the latency's step, the centre of mass's (eq. M5)
        warnings = [w for w in warnings if w not in run.latency.warnings]
        warnings.insert(0, f"{_step_words(step)} is gone at the centre of mass the log prefers: the payload's, not "
                           f"the stamps'; {centre_of_mass_words(com)}")
        why, explained = _CENTRE_OF_MASS, True
    said = inertia_note(shape, converged or explained)
    if said and not converged and not explained and why == _LATENCY_STEP and _step_of_the_inertia(run, shape,
                                                                                                  max_latency):
        step = run.latency.step                     # the latency's step, the shape's: named with the inertia
        warnings = [w for w in warnings if w not in run.latency.warnings]
        said += f"; {_step_words(step)} is gone at that inertia: the shape's, not the stamps'"
        why = _UNSETTLED
    if said and (converged or explained):
        notes.append(said)
    elif said:                          # the likely cause of a fit that did not settle: a longer log would not help
        warnings = [w for w in warnings if w != _not_settled(name)] + [said]
        why = "the payload's inertia's shape moves the fit (see the warnings)" if why == _UNSETTLED else why
    suggestion = getattr(run.causes, "suggestion", None)
    if suggestion and not converged and not run.named and why in (_UNSETTLED, _MISFIT):
        warnings.insert(0, suggestion)      # no cause named, none by another check: what the log leans to, first
        why = _suggested_why(run.causes, why)
    statistical = run.result.S_std
    run.result, payload_part = _with_payload_uncertainty(run.result, sensitivity, payload_cov)
    # the noise model recorded with the calibration (compensation's covariance needs it): the one the method was
    # told, the log's own where none was given (measured on the poses as recorded, the glitches bridged)
    recorded = told
    own, result = result, run.result     # a check may have widened the uncertainty (a copy: the method's own kept)
    E, E_blocks = _errors(truth, result, model, log)
    directions = [np.asarray(d, dtype=float) for d in result.info.get("undetermined", [])]
    return _calibration(result, name, dict(
        payload=model.payload, method=name, latency=float(latency), latency_estimated=latency_estimated,
        latency_std=None if not latency_estimated or not np.isfinite(timing.std) else float(timing.std),
        reading=reading, gravity=model.gravity if model.under_gravity else None, noise=recorded,
        noise_estimated=noise_estimated if noise is not None else ["wrench", "pose"], converged=converged,
        warnings=warnings, units=run.units,
        fit=None if reference is None else {k: v for k, v in reference.report.to_dict().items() if k != "warnings"},
        undetermined=[describe_direction(d) for d in directions], undetermined_directions=directions,
        E=E, E_blocks=E_blocks, notes=notes + (timing.notes if latency_estimated else []), kind=cls.name, run=own,
        why_unconverged=None if converged else why, glitches=glitches.to_dict() if glitches.found else None,
        S_std_statistical=statistical, S_std_payload=payload_part, payload_cov=payload_cov))


def _latency_estimate(signed, model, max_latency, offset, required):
    """The log's own latency (:func:`fmscal.observers.batch.estimate_latency`). Where a latency is given
    (``required`` False) it is only what the one given is checked against: a log the search cannot take (too
    short for ``max_latency``) gives None instead of an error."""
    if required:
        return estimate_latency(signed, model, max_latency, offset=offset)
    try:
        return estimate_latency(signed, model, max_latency, offset=offset)
    except FmscalError:
        return None


def _run_aligned(signed, latency, model, name, noise, offset, glitches, reference):
    """The method (and the least-squares reference, where the model declares one) on the log with its poses
    moved back by ``latency``; ``(aligned, reference's result or None, result)``. A diverging estimate is an
    error, never an answer."""
    aligned = signed.shift_poses(latency)
    # the glitches bridged before are the ones each run reports (the search is not repeated)
    ls_result = None if reference is None else reference.run(aligned, glitches=glitches)
    if reference is not None and name == reference.name:
        result = ls_result
    else:
        result = make_observer(name, model, noise, {"offset": offset}).run(aligned, glitches=glitches)
    if result.diverged:
        raise DivergedError(f"{name} diverged on {signed.name} at t = {result.t[-1]:.3f} s"
                            + (f": {result.warnings[-1]}" if result.warnings else "")
                            + "; no calibration (check the mass properties, units and excitation)")
    return aligned, ls_result, result


def _noise_model(log, model, pose_noise, wrench_noise):
    """The noise model of a log of a model that takes one given: what is not given estimated from the log.

    Returns ``(NoiseSpec, names of the parts estimated)``; refuses a log whose pose does not move.
    """
    estimated = estimate_noise(log)
    noise = NoiseSpec(tuple(wrench_noise) if wrench_noise is not None else estimated.wrench_sd,
                      pose_noise[0] if pose_noise is not None else estimated.angle_sd,
                      pose_noise[1] if pose_noise is not None else estimated.position_sd,
                      estimated.wrench_tau if wrench_noise is None else None)   # a given noise: white
    noise_estimated = [name for name, given in (("wrench", wrench_noise), ("pose", pose_noise)) if given is None]
    spread = np.ptp(log.pose[log.has_pose], axis=0)
    if np.all(spread <= 10 * model.pose_sd(noise)):
        names = ", ".join(model.pose_names[:-1]) + " and " + model.pose_names[-1]
        raise FmscalError(f"{log.name}: the pose does not move ({names} each stay within 10 noise standard "
                          "deviations): a payload at rest does not excite S; record it moving")
    return noise, noise_estimated


def _errors(truth, result, model, log):
    """E of eq. (16) against the truth at the log's end, and on each of the model's ``reading_blocks``."""
    if truth is None:
        return None, None
    S = truth.S_at(log.t[-1])
    E = calibration_error(result.S_hat, S)
    if not model.reading_blocks:
        return E, None
    D = np.eye(model.n_w) - np.asarray(result.S_hat, dtype=float) @ np.linalg.inv(S)
    return E, tuple(float(np.linalg.norm(D[np.ix_(c, c)], 2)) for _, c in model.reading_blocks)


@dataclass
class _Run:
    """What a calibration's checks read: the log as recorded, in the toolkit's sign and aligned, the model,
    the method's result and the least-squares reference (None where the model declares no ``"reference"``)."""

    log: Log
    signed: Log
    aligned: Log
    model: Model
    method: str
    result: object
    reference: object
    offset: bool
    reading: str
    units: list = field(default_factory=list)
    glitches: object = None
    misfit: object = None
    latency: object = None
    sensitivity: object = None
    payload_cov: object = None
    latency_given: float = None
    causes: object = None
    named: bool = False


def _check_units(run, warnings):
    """``"units"``: the log's units look right (:func:`fmscal.plant.io.diagnose_units`); a reading in counts
    does not stop a batch method (it fits any scale), only an online one."""
    findings = diagnose_units(run.log, run.model.payload)
    online = get_method(run.method).online
    run.units = [f.message for f in findings if f.kind != COUNTS or online]
    why = "the log's units look wrong (" + run.units[0].split(":")[0] + ")" if run.units else None
    return [f.message for f in findings], not run.units, why


def _check_reference(run, warnings):
    """``"reference"``: a least-squares fit of the log finds it exciting every entry and matching the model."""
    return list(run.reference.warnings), not run.reference.warnings, None


def _check_run(run, warnings):
    """``"run"``: the method's own warnings (those not said already)."""
    return [w for w in run.result.warnings if w not in warnings], True, None


def _check_consistency(run, warnings):
    """``"consistency"``: one constant ``S`` explains the log
    (:func:`fmscal.observers.diagnostics.consistency_check`)."""
    try:
        consistency = consistency_check(run.aligned, run.model, offset=run.offset)
    except FmscalError as err:            # a half too short to fit: nothing says S stayed constant
        return [f"the log is too short to check that one constant S explains it ({err})"], False, None
    return ([] if consistency.consistent else [consistency.warning]), consistency.consistent, None


def _check_saturation(run, warnings):
    """``"saturation"``: no channel of the reading saturates (:func:`fmscal.observers.diagnostics.saturation`)."""
    saturated = saturation(run.signed)
    return saturated, not saturated, "the reading saturates"


def _check_offset_drift(run, warnings):
    """``"offset_drift"``: the offset keeps one level under the reference fit
    (:func:`fmscal.observers.diagnostics.offset_drift`)."""
    drift = offset_drift(run.aligned, run.model.payload, run.reference.S_hat, run.reference.b)
    return ([drift.warning] if drift.warning else []), not drift.warning, None


def _check_causes(run, warnings):
    """``"causes"``: the residual of the reference fit of a log under gravity names no moving offset or gain and no
    gravity along another direction than the one given (:func:`fmscal.observers.diagnostics.fit_causes`, eqs.
    (C1)-(C5)); any found is a warning naming it, and not converged: ``S`` took up what the cause left (the
    gains check then blames no mass). A log too short to test passes with nothing said."""
    try:
        found = fit_causes(run.aligned, run.model)
    except FmscalError:
        return [], True, None
    run.causes = found
    run.named = bool(found.warnings)
    tilted = found.gravity is not None and found.gravity.tilted
    gain = found.gain is not None and bool(found.gain.rows)
    why = ("the sensor's offset and S's gain move during the log" if gain and not found.offset.constant else
           "S's gain moves during the log" if gain else
           "the sensor's offset moves during the log" if not found.offset.constant else
           "gravity's direction is not the one given, or the offset moves (the log is too short to tell)"
           if tilted and found.gravity.ambiguous else "gravity's direction is not the one given" if tilted else None)
    return found.warnings, why is None, why


def _check_disagreement(run, warnings):
    """``"disagreement"``: the method's estimate agrees with the reference fit (:data:`AGREEMENT_SIGMAS`,
    :data:`AGREEMENT_E`)."""
    disagreement = _disagreement(run.result, run.reference)
    return ([disagreement] if disagreement else []), not disagreement, None


def _check_evidence(run, warnings):
    """``"evidence"``: the log pinned ``S`` down (:func:`fmscal.observers.diagnostics.has_evidence`, asked for a
    method that gives no ``S_std``: the run alone judged its ``converged``); a run that did not settle without
    saying why is told why."""
    result = run.result
    evident = result.S_std is not None or has_evidence(result, run.aligned, run.model, offset=run.offset)
    found = [] if (result.converged and evident) or result.warnings else [_not_settled(result.observer)]
    return found, evident, None


#: A force block of ``S`` whose nearest rotation (its polar factor) turns further than this, degrees, is named a
#: sensor turned from the frame the poses give.
TURNED_DEG = 20.0
#: Where the ``"causes"`` check named a cause, ``S`` turns to take it up (a base tilted 5 degrees turned it 32 on a
#: 10 s log): a turn is named only beyond this, degrees, which no such cause reaches.
CAUSED_TURN_DEG = 90.0


def _check_flipped_gain(run, warnings):
    """``"flipped_gain"``: the force block of ``S`` (on the ``force_channels``) is near the identity, else one line
    naming why, and not converged:

    - a force channel along a direction the log leaves undetermined, and a force gain negative: too little rotation
      to tell the reading's sign (no advice on ``reading``, which the next run would reverse);
    - the polar factor ``R`` of the block (``S_ff = R P``, ``R`` orthogonal) a rotation turning more than
      :data:`TURNED_DEG`: the sensor is turned about an axis from the frame the poses give;
    - ``det R < 0`` with a negative trace: the reading follows the other sign convention.

    A turn beyond :data:`TURNED_DEG` and up to :data:`CAUSED_TURN_DEG` where the ``"causes"`` check leans to a
    tilt of gravity it does not name (:attr:`fmscal.observers.diagnostics.GravityTilt.suggestive`) names both (on
    a log that does not determine the tilt, ``S`` turns to take it up), and on a log fitted with fewer parts than
    asked an offset that moves too.

    Where the ``"causes"`` check named a cause (a moving offset or gain, gravity's direction), ``S`` turns to take
    it up: a turn is named only beyond :data:`CAUSED_TURN_DEG`. A reversed sign is no cause's, and is named beside
    it.
    """
    channels = list(run.model.force_channels)
    S_f = np.asarray(run.result.S_hat, dtype=float)[np.ix_(channels, channels)]
    untold = any(np.abs(np.asarray(d, dtype=float)[channels]).max() > 0.1 for d in run.result.info.get("undetermined",
                                                                                                        []))
    U, _, Vt = np.linalg.svd(S_f)
    R = U @ Vt
    rotvec = Rotation.from_matrix(R).as_rotvec() if np.linalg.det(R) > 0 else None
    if untold and np.all(np.diag(S_f) > 0):    # nothing to say of the sign, nor of a turn, where the gains are
        return [], True, None                  # unknown and none is negative (a mass given wrong: the gains' check)
    if untold:
        run.named = True
        return [f"{run.log.name}: the log holds too little rotation to tell the reading's sign (the force gains are "
                "not determined: see the directions above); record a log that turns the payload through tens of "
                "degrees about two axes, then judge the reading's sign convention"], False, \
            "the log holds too little rotation to tell the reading's sign"
    angle = float(np.degrees(np.linalg.norm(rotvec))) if rotvec is not None else 0.0
    if angle > (CAUSED_TURN_DEG if _cause_named(run) else TURNED_DEG):    # S took up the cause named: a turn is its
        run.named = True
        axis = rotvec / np.linalg.norm(rotvec)
        k = int(np.argmax(np.abs(axis)))
        about = ("xyz"[k] if abs(axis[k]) > 0.95 else "(" + ", ".join(f"{a:.2f}" for a in axis) + ")")
        gravity = getattr(run.causes, "gravity", None)
        if angle <= CAUSED_TURN_DEG and getattr(gravity, "suggestive", False):   # S turns to take up a tilt
            drift = ", or the offset moves" if run.causes.short else ""
            return [f"{run.log.name}: the reading's axes are turned {angle:.0f} degrees about the sensor's {about} "
                    f"from the frame the poses give, or gravity's direction is not the one given (the data lean to "
                    f"gravity tilted {gravity.tilt_deg:.2g} degrees, +- {gravity.std_deg:.1g}; p = "
                    f"{gravity.p_value:.2g}){drift}: S turns to take a tilt up, and this log does not tell them "
                    "apart; record a longer log, or estimate gravity with fmscal identify-payload --gravity "
                    "estimate, before mounting the sensor anew"], False, \
                _TURN_TILT_OR_OFFSET if run.causes.short else _TURN_OR_TILT
        return [f"{run.log.name}: the reading's axes are turned {angle:.0f} degrees about the sensor's {about} from "
                "the frame the poses give (S's force block is that turn): the sensor is mounted turned, or the poses "
                "are of another frame; mount it as the poses assume, or record the poses of the sensor's own frame "
                "(the reading's sign convention is not the cause)"], False, \
            "the sensor is turned from the frame the poses give"
    flipped = bool(rotvec is None and np.trace(S_f) < 0)         # a reflection, not a turn (det R < 0)
    found = [other_convention(run.log.name, None, run.reading)] if flipped else []
    if flipped:
        run.named = True
    return found, not flipped, "the reading follows the other sign convention"


_TURN_OR_TILT = ("the sensor is turned from the frame the poses give, or gravity's direction is not the one given "
                "(the log does not tell them apart)")
_TURN_TILT_OR_OFFSET = ("the sensor is turned from the frame the poses give, gravity's direction is not the one given, "
                        "or the offset moves (the log is too short to tell)")


def _check_latency(run, warnings):
    """``"latency"``: the log determines the pose stream's latency and keeps one along it
    (:class:`fmscal.observers.batch.LatencyEstimate`: a clear minimum, its standard deviation within a few
    samples, no step mid-log). A latency given is checked against the log's estimate and the fit's own
    (:func:`fmscal.observers.batch.given_latency_warnings`, rule 9 of :mod:`fmscal.observers.batch._latency`):
    fails where the fit at the latency given is measurably worse."""
    found = run.latency
    if run.latency_given is not None:
        found, worse = given_latency_warnings(run.latency_given, found, run.result.info.get("latency_step"))
        return found, not worse, "the latency given does not fit the log" if worse else None
    why = None if found.determined else (_LATENCY_STEP if found.step is not None
                                         else "the log does not determine the pose stream's latency")
    return list(found.warnings), found.determined, why


_LATENCY_STEP = "the latency changes along the log"


def _step_of_the_inertia(run, shape, max_latency):
    """Whether the latency's step along the log (:attr:`LatencyEstimate.step`) is the payload's inertia's shape:
    the latency estimated again with the inertia the log prefers (:attr:`InertiaShape.preferred`, eq. (M4) of
    :mod:`fmscal.observers.diagnostics._misfit`) is determined, with no step. An inertia's shape leaves a residual
    that moves with the motion, which a latency's search along the log can read as a step."""
    if shape is None or shape.preferred is None or run.latency is None:
        return False
    theta = run.model.payload_parameters()
    k = 1 + len(run.model.payload_position_names)
    theta[k:k + len(shape.preferred)] = shape.preferred
    return _no_step_at(run, theta, max_latency)


def _step_words(step):
    """The latency's step along the log (:attr:`LatencyEstimate.step`) in words."""
    return (f"the latency's step along the log ({step['before'] * 1e3:.3g} ms before t = {step['t']:.3g} s, "
            f"{step['after'] * 1e3:.3g} ms after)")


#: Why a calibration did not converge, where the latency's step along the log is the centre of mass's.
_CENTRE_OF_MASS = "the payload's centre of mass is not the one given, or the poses' frame is turned"


def _step_of_the_centre_of_mass(run, com, max_latency):
    """Whether the latency's step along the log is the payload's centre of mass: the log sees one other than the
    one given, beyond its stated uncertainty (:class:`fmscal.observers.diagnostics.CentreOfMass`, eq. (M5)), and
    the latency estimated again at it is determined, with no step."""
    if com is None or not com.seen or com.covered or run.latency is None:
        return False
    theta = run.model.payload_parameters()
    theta[1:1 + len(com.preferred)] = com.preferred
    return _no_step_at(run, theta, max_latency)


def _no_step_at(run, theta, max_latency):
    """The latency estimated again with the payload's numbers ``theta``: determined, with no step."""
    try:
        again = estimate_latency(run.signed, run.model.with_payload_parameters(theta), max_latency,
                                 offset=run.offset)
    except FmscalError:
        return False
    return bool(again.determined and again.step is None)


def _with_latency_uncertainty(result, found):
    """The result with the latency's uncertainty carried into its covariance, ``S_std`` and ``b_std``.

    ``cov += J J^T var(latency)``, ``J = d vec([S | c]) / d latency`` (row order; ``S`` alone without the
    offset) of the least-squares fit at the estimate (:attr:`LatencyEstimate.dS_dlatency`, eq. (L4) of
    :mod:`fmscal.observers.batch._latency`); ``S_std`` and ``b_std`` follow from it
    (:func:`fmscal.observers.core.calibration_uncertainty`). A method without a covariance but with
    ``S_std`` gets ``S_std^2 += (dS/dlatency)^2 var(latency)``. Unchanged where the latency was given.
    """
    if found is None or found.dS_dlatency is None or result.S_std is None:
        return result
    var = found.std ** 2 if np.isfinite(found.std) else np.inf
    n_w = result.S_hat.shape[0]
    dS = np.asarray(found.dS_dlatency, dtype=float)
    if result.cov is None:
        return replace(result, S_std=np.sqrt(result.S_std ** 2 + dS[:, :n_w] ** 2 * var))
    cov = np.asarray(result.cov, dtype=float)
    offset = cov.shape[0] == n_w * (n_w + 1)
    J = (dS if offset else dS[:, :n_w]).ravel()
    with np.errstate(invalid="ignore"):
        cov = cov + np.outer(J, J) * var
    if not np.isfinite(var):
        cov[~np.isfinite(cov)] = np.inf
    c = -result.S_hat @ result.b if offset and result.b is not None else None
    S_aug = np.c_[result.S_hat, c] if c is not None else result.S_hat
    S_std, _, b_std = calibration_uncertainty(S_aug, cov, c is not None)
    return replace(result, cov=cov, S_std=S_std, b_std=b_std if c is not None else result.b_std)


def _payload_std(payload, given):
    """The payload's uncertainty a log's calibration takes: ``given`` (a :class:`~fmscal.plant.PayloadStd`, its
    fields left None filled by the defaults), over a payload estimate's own where the payload is one."""
    if not isinstance(payload, PayloadEstimate):
        return PayloadStd() if given is None else given
    tracked = payload.tracked()
    if payload.mounting is None:            # the tracked frame's axes are the estimate's: its covariance as it is
        tracked.cov = getattr(tracked, "cov", None) if getattr(tracked, "cov", None) is not None \
            else getattr(payload, "cov", None)
    if getattr(tracked, "gravity_std", None) is None:
        tracked.gravity_std = getattr(payload, "gravity_std", None)
    estimated = _estimate_std(tracked)
    if given is None:
        return estimated
    return replace(estimated, **{name: getattr(given, name) for name in ("mass", "com", "inertia", "gravity", "cov")
                                 if getattr(given, name) is not None})


def _estimate_std(estimate):
    """A :class:`~fmscal.observers.payload.PayloadEstimate`'s uncertainty as a :class:`~fmscal.plant.PayloadStd`
    over the spatial model's ``mass, X, Y, Z, IXX .. IYZ, gravity``: its covariance's block of the mass, the
    centre of mass and the inertia where it has one (``cov``, over ``PAYLOAD_PARAMETERS``, whose first ten
    are these), else its standard deviations; gravity's size's (``gravity_std``) where it has one. What it does
    not state (NaN) takes the defaults."""
    cov = np.zeros((11, 11))
    full = getattr(estimate, "cov", None)
    if full is not None and np.shape(full)[0] >= 10:
        cov[:10, :10] = np.asarray(full, dtype=float)[:10, :10]
    else:
        inertia_std = np.full(6, np.nan) if estimate.inertia_std is None else np.ravel(estimate.inertia_std)
        np.fill_diagonal(cov[:10, :10], np.square(np.r_[estimate.mass_std, np.ravel(estimate.com_std), inertia_std]))
    gravity_std = getattr(estimate, "gravity_std", None)
    cov[10, 10] = np.nan if gravity_std is None else float(gravity_std) ** 2
    return PayloadStd(cov=cov)


def _payload_covariance(model, std):
    """The payload's covariance over ``model.payload_parameter_names()`` (:meth:`~fmscal.plant.PayloadStd.covariance`),
    a field that does not fit the model refused as the option (``payload_std.com``: ``--com-std``)."""
    try:
        return std.covariance(model)
    except PayloadStdError as err:
        raise OptionError(f"payload_std.{err.field}", f"{{}} {err.message}") from None


def _with_payload_uncertainty(result, sensitivity, payload_cov):
    """The result with the payload's uncertainty carried in, and ``S_std``'s payload part, eq. (Y1).

    ``cov += D Sigma_theta D^T`` (:meth:`fmscal.observers.batch.PayloadSensitivity.covariance`, the rows of ``D``
    without the offset's column where the result has none); ``S_std`` and ``b_std`` follow from it
    (:func:`fmscal.observers.core.calibration_uncertainty`). A method without a covariance but with ``S_std``
    gets ``S_std^2 += `` the payload's part. Without a sensitivity (it could not be computed): unchanged, None.

    Returns
    -------
    (result, ndarray shape (n_w, n_w) or None)
    """
    if sensitivity is None:
        return result, None
    n_w = result.S_hat.shape[0]
    n = sensitivity.readings.shape[1]
    cov_payload = sensitivity.covariance(payload_cov)
    with np.errstate(invalid="ignore"):
        part = np.sqrt(np.maximum(np.diag(cov_payload), 0.0)).reshape(n_w, n)[:, :n_w]
    if result.S_std is None:
        return result, part
    if result.cov is None:
        return replace(result, S_std=np.sqrt(np.square(result.S_std) + np.square(part))), part
    cov = np.asarray(result.cov, dtype=float)
    offset = cov.shape[0] == n_w * (n_w + 1)
    if not offset and n == n_w + 1:                           # the result holds S alone: the offset's rows dropped
        keep = np.ravel(np.arange(n_w * n).reshape(n_w, n)[:, :n_w])
        cov_payload = cov_payload[np.ix_(keep, keep)]
    with np.errstate(invalid="ignore"):
        cov = cov + cov_payload
    cov[np.isnan(cov)] = np.inf
    c = -result.S_hat @ result.b if offset and result.b is not None else None
    S_std, _, b_std = calibration_uncertainty(np.c_[result.S_hat, c] if c is not None else result.S_hat, cov,
                                              c is not None)
    return replace(result, cov=cov, S_std=S_std, b_std=b_std if c is not None else result.b_std), part


def _check_misfit(run, warnings):
    """``"misfit"``: the model fits the log (:func:`fmscal.observers.diagnostics.misfit`: the reference fit's
    residual against the noise measured from the log, and one ``S`` for slow and fast motion). Where it does
    not, a warning in words and the uncertainty widened (eq. (M3), :func:`fmscal.observers.diagnostics.inflate`):
    ``run.result`` becomes a copy whose ``S_std``, ``cov`` (each row of ``[S | c]`` by its entries' factors, the
    offset's column by the row's largest) and ``b_std`` say so; the method's own result is left as it was. A
    gross misfit is not converged, and so is an inertia whose shape the log puts beyond its stated uncertainty
    (eq. (M4)). A log too short to measure it passes with nothing said."""
    try:
        found = misfit(run.aligned, run.model, sensitivity=run.sensitivity, payload_cov=run.payload_cov)
    except FmscalError:
        return [], True, None
    run.misfit = found
    result = run.result
    if not found.fits and result.S_std is not None:
        widened = inflate_misfit(result.S_std, found)
        with np.errstate(invalid="ignore", divide="ignore"):
            factor = np.where(np.isfinite(result.S_std) & (result.S_std > 0), widened / result.S_std, 1.0)
        if result.cov is None:
            run.result = replace(result, S_std=widened)
        else:
            n_w = run.model.n_w
            offset = result.cov.shape[0] == n_w * (n_w + 1)
            scale = np.c_[factor, factor.max(axis=1)] if offset else factor
            cov = np.asarray(result.cov, dtype=float) * np.outer(scale.ravel(), scale.ravel())
            c = -result.S_hat @ result.b if offset and result.b is not None else None
            S_std, _, b_std = calibration_uncertainty(np.c_[result.S_hat, c] if c is not None else result.S_hat,
                                                      cov, c is not None)
            run.result = replace(result, cov=cov, S_std=S_std, b_std=b_std if c is not None else result.b_std)
    return ([] if found.fits else [found.warning]), not found.gross, _MISFIT


_MISFIT = "the model does not fit the log"
#: Why a run that did not converge, where the ``"causes"`` check leans to a cause it does not name: a moving offset
#: on a short log, or a tilt of gravity.
_OFFSET_OR_PAYLOAD = "the sensor's offset may move, or the payload is given wrong (the log is too short to tell)"
_TILT_SUGGESTED = "gravity's direction may not be the one given (the log does not determine it)"
_TILT_OR_OFFSET = "gravity's direction may not be the one given, or the offset may move (the log is too short to tell)"
_ALL_SUGGESTED = ("the sensor's offset may move, the payload may be given wrong, or gravity's direction may not be the "
                  "one given (the log is too short to tell)")


def _suggested_why(causes, why):
    """``why_unconverged`` for a suggestion (:attr:`fmscal.observers.diagnostics.Causes.suggestion`) put first in
    place of ``why``, :data:`_UNSETTLED` or :data:`_MISFIT`: an offset suggested names the payload beside it (and
    a tilt, where both are suggested); a tilt alone keeps a misfit's why (a payload given wrong misfits too), and
    on a log fitted with fewer parts than asked names the offset."""
    tilt = bool(getattr(causes.gravity, "suggestive", False))
    if causes.suggested:
        return _ALL_SUGGESTED if tilt else _OFFSET_OR_PAYLOAD
    if why == _MISFIT:
        return why
    return _TILT_OR_OFFSET if causes.short else _TILT_SUGGESTED


#: A force or torque gain of ``S`` further than this factor from 1 (either way) is remarked on.
FAR_GAIN = 1.5


def _check_gains(run, warnings):
    """``"gains"``: each diagonal gain of ``S`` within a factor :data:`FAR_GAIN` of 1, else a warning naming
    the likely cause: the payload's mass (force gains) or its centre of mass and inertia (torque gains), or
    the reading's units; force gains uneven among themselves (:data:`UNEVEN_GAIN`), which neither a mass nor a unit
    makes, name the one channel far from 1 (its offset moving, and where the log was too short for the
    ``"causes"`` check to test it, the length it would take; or its gain), or, where no one channel is or the
    torque gains are far too, the centre of mass. Only gains the log determines count: a channel no undetermined
    direction holds (a share above 0.1), a standard deviation under a tenth of the gain and a gain three of them
    from 1 (a method without ``S_std``: a converged run). ``converged`` is not
    changed: ``S`` is what the data determine for the payload given (a sensor read in other units is
    calibrated so); the warning says the payload or the units may be wrong. Nothing is said where the
    ``"causes"`` or ``"flipped_gain"`` check named a cause: the gains are then that cause's."""
    S = np.asarray(run.result.S_hat, dtype=float)
    if run.result.S_std is None:
        std = np.zeros(len(S)) if run.result.converged else np.full(len(S), np.inf)
    else:
        std = np.diag(np.asarray(run.result.S_std, dtype=float))
    for d in run.result.info.get("undetermined", []):   # a channel the undetermined directions hold: its gain is not
        std = np.where(np.abs(np.asarray(d, dtype=float)[:len(S)]) > 0.1, np.inf, std)
    if run.named:                  # a cause named (an offset, a gain, gravity, the sign, a turn) moved the gains
        return [], True, None
    forces = list(run.model.force_channels)
    split = {part: (channels, np.diag(S)[channels], std[channels]) for part, channels in
             (("force", forces), ("torque", [k for k in range(len(S)) if k not in forces]))}
    far = {part: ((gains < 1 / FAR_GAIN) | (gains > FAR_GAIN)) & (sd < 0.1 * np.abs(gains))
           & (np.abs(gains - 1) > 3 * sd) for part, (_, gains, sd) in split.items()}
    found = []
    for part, (channels, gains, sd) in split.items():
        if not channels or np.all(gains <= 0) or not far[part].any():
            continue
        names = ", ".join(run.model.wrench_names[k] for k in channels)
        listed = ", ".join(f"{g:.3g}" for g in gains)
        uneven, odd = _uneven(gains, sd) if part == "force" else (False, None)
        if uneven and odd is not None and not far["torque"].any():
            name = run.model.wrench_names[channels[odd]]
            cause = (f"they differ from each other, which neither a mass given wrong nor a unit does (both scale "
                     f"the three alike): {name}'s offset may move along the log{_too_short(run.causes)}, or {name} "
                     "is read with another gain than the others")
        elif uneven:
            cause = ("they differ from each other, which neither a mass given wrong nor a unit does (both scale the "
                     "three alike): the payload's centre of mass may be wrong (S trades force gains against the "
                     "torques' for it)")
        elif part == "force":
            mass = run.model.payload.mass
            cause = (f"the payload's mass may be wrong (the mass given is {mass:.4g} kg; force gains near "
                     f"{np.mean(gains):.3g} say the data weigh it at about {mass / np.mean(gains):.4g} kg), or the "
                     f"readings are not in N")
        else:
            cause = "the payload's centre of mass or inertia may be wrong, or the torques are not in N m"
        found.append(f"the {part} gains of S ({names}: {listed}) are far from 1: {cause}")
    return found, True, None


#: Force gains of ``S`` whose largest is more than this factor of the smallest (each determined, and apart by more
#: than three of their combined standard deviations) are not a mass's: a mass given wrong by a factor ``k`` scales
#: the force block by ``k`` (``S' = [[I, (k-1)[c]x], [0, kI]] S``), and a unit all three alike.
UNEVEN_GAIN = 1.25


def _uneven(gains, sd):
    """Whether the determined force gains are uneven (:data:`UNEVEN_GAIN`), and the one channel among them (an
    index into ``gains``) beyond that factor of 1 while the others are within it; None where there is no such one."""
    kept = np.flatnonzero(np.isfinite(sd) & (gains > 0))
    if len(kept) < 2:
        return False, None
    low, high = kept[np.argmin(gains[kept])], kept[np.argmax(gains[kept])]
    if gains[high] < UNEVEN_GAIN * gains[low] or gains[high] - gains[low] < 3 * np.hypot(sd[high], sd[low]):
        return False, None
    beyond = kept[np.abs(np.log(gains[kept])) > np.log(UNEVEN_GAIN)]
    return True, (int(beyond[0]) if len(beyond) == 1 else None)


def _too_short(causes):
    """Where the log was too short to test a moving offset: a clause saying so, with the length it would take."""
    if causes is None or causes.tested:
        return ""
    return (f" (the log is too short to test that: {causes.blocks} blocks of time where the test asks for "
            f"{causes.needed}, a log of about {causes.needed_duration:.0f} s)")


def _check_spatial_units(log, model, max_mass=None):
    """``"spatial_units"`` (an input check): a spatial log's units and conventions, against the model's
    gravity and payload, the mass held to ``max_mass`` (:func:`fmscal.plant.io.check_spatial_log_units`): one line
    naming the slip."""
    check_spatial_log_units(log, model.gravity, model.payload.mass, model.payload.com, max_mass=max_mass)


#: The checks a model may declare in :attr:`fmscal.plant.Model.input_checks`: each takes the log, the model and
#: ``max_mass=`` before the fit and refuses in one line.
_INPUT_CHECKS = {"spatial_units": _check_spatial_units}

#: The checks a model may declare in :attr:`fmscal.plant.Model.calibration_checks`: each takes the run and
#: the warnings so far and gives ``(its warnings, passed, why it failed or None)``.
_CHECKS = {"units": _check_units, "reference": _check_reference, "run": _check_run,
           "consistency": _check_consistency, "saturation": _check_saturation, "offset_drift": _check_offset_drift,
           "causes": _check_causes,
           "disagreement": _check_disagreement, "evidence": _check_evidence, "flipped_gain": _check_flipped_gain,
           "latency": _check_latency, "misfit": _check_misfit, "gains": _check_gains}


def _calibration(result, method, fields):
    """The :class:`Calibration` of a run, or a one-line error for a singular ``S``."""
    try:
        return Calibration(S=result.S_hat, S_std=result.S_std, b=result.b, b_std=result.b_std, cov=result.cov,
                           **fields)
    except SingularCalibrationError as err:
        raise FmscalError(f"the {method} estimate of S is singular ({str(err).split('(')[-1].split(')')[0]}): the "
                          "log does not excite every entry of S, or holds an outlier (a reading far from the "
                          "rest)") from None


def _cause_named(run):
    """Whether the ``"causes"`` check named a cause (a moving offset or gain, gravity's direction) on this run."""
    causes = getattr(run, "causes", None)
    return causes is not None and bool(causes.warnings)


#: Why a calibration did not converge where no check said why.
_UNSETTLED = "the run did not converge (see the warnings)"


def _effects_of_the_cause(run, name, warnings):
    """The warnings that a cause named by the ``"causes"`` check (a moving offset or gain, gravity's direction)
    explains, kept as notes: the fit not settling, and the latency estimated but not determined under it (its
    advice, a latency given, would not mend the cause). A latency that steps along the log, a search too narrow and a
    latency given that the log disagrees with stay warnings."""
    if not _cause_named(run):
        return []
    latency = [] if run.latency_given is not None else getattr(run.latency, "unresolved", [])
    return [w for w in warnings if w == _not_settled(name) or w in latency]


def _not_settled(method):
    """Why a run with every direction determined did not converge: the log was too short to pin ``S`` down."""
    return (f"{method}: S_hat did not settle within {SETTLE_TOLERANCE:.0%} over the last {SETTLE_FRACTION:.0%} of "
            f"the log, or its uncertainty is above {EVIDENCE_TOLERANCE:.0%} of it (each reading component in its "
            f"own scale): record a longer log, or one that turns the payload faster")


def _calibrate_table(table, payload, method, reading, gravity, latency, max_latency, offset, pose_noise,
                     wrench_noise, truth, notes, what, max_mass=None):
    """:func:`calibrate` on held poses."""
    _refuse("a pose table", [
        (method not in (None, TABLE_METHOD), "observer", "held poses have one fit, least squares"),
        (latency is not None, "latency", "held poses have no time"),
        (max_latency is not None, "max_latency", "held poses have no time"),
        (truth is not None, "truth", "a pose table has no truth sidecar"),
        (pose_noise is not None, "pose_noise", "held poses are taken as exact"),
        (wrench_noise is not None, "wrench_noise", "the noise is estimated from the residuals"),
        (not offset, "offset=False", "the offset is always estimated in 3D")])
    mass, com, spatial, estimated = _table_payload(payload)
    gravity = _gravity(_merge_gravity(gravity, estimated))
    reading = "reaction" if reading is None else reading
    check_table_units(table, gravity, mass, com, max_mass=max_mass)          # a slipped unit named in one line
    fit = fit_table(table, mass, com, gravity, reading)
    directions = [np.asarray(d, dtype=float) for d in fit.undetermined]
    return Calibration(S=fit.S_hat, payload=spatial, method=TABLE_METHOD, S_std=fit.S_std, b=fit.b, b_std=fit.b_std,
                       latency=None, latency_estimated=False, reading=reading, gravity=gravity, converged=False,
                       warnings=list(fit.warnings), undetermined=[describe_direction(d, held=True) for d in directions],
                       undetermined_directions=directions, kind="table", poses=len(table), notes=notes, run=fit,
                       why_unconverged="held poses never determine S in full (see the warnings)")


def _table_payload(payload):
    """``(mass, com, SpatialPayload or None, gravity or None)`` of what held poses take as the payload.

    A model or a payload is taken through :func:`fmscal.plant.physics.as_model`: held poses weigh the
    payload, so its model must stand :attr:`~fmscal.plant.Model.under_gravity` (a model given brings its
    gravity).
    """
    if isinstance(payload, PayloadEstimate):
        return _estimate_payload(payload)
    try:
        model = as_model(payload)
    except FmscalError:
        model = None
    if model is not None:
        if not model.under_gravity:
            raise FmscalError("a pose table takes a plant.SpatialPayload, or the mass and the centre of mass X Y Z "
                              "(the sensor frame); got a planar payload")
        held = model.payload
        return held.mass, np.array(held.com), held, model.gravity if isinstance(payload, Model) else None
    try:
        mass, com = payload
        com = np.asarray(com, dtype=float)
    except (TypeError, ValueError):
        raise FmscalError(f"a pose table takes a plant.SpatialPayload or (mass, com); got {type(payload).__name__}") \
            from None
    mass = as_number(mass, "the payload's mass")     # its value is checked with the units (plant.io.check_mass)
    if com.shape != (3,):
        raise FmscalError(f"a pose table takes com X Y Z (3 numbers, m, the centre of mass in the sensor frame); "
                          f"got {com.size}")
    return mass, com, None, None


def _disagreement(result, reference):
    """A warning when ``result``'s estimate is far from the least-squares fit ``reference``; else None."""
    if result is reference:
        return None
    var = np.square(reference.S_std) + (0.0 if result.S_std is None else np.square(result.S_std))
    with np.errstate(divide="ignore", invalid="ignore"):
        z = float(np.nanmax(np.abs(result.S_hat - reference.S_hat) / np.sqrt(var)))
    try:
        E = calibration_error(result.S_hat, reference.S_hat)
    except (np.linalg.LinAlgError, FmscalError):
        E = float("inf")
    if z > AGREEMENT_SIGMAS and E > AGREEMENT_E:
        return (f"the {result.observer} estimate is far from a least-squares fit of the same log (E between "
                f"them {E:.3g}, an entry {z:.3g} sigma off): it has not converged to what the data say "
                "(a gain too small, or a run too short)")
    return None
