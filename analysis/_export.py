"""Into ros2_control: a payload file as the parameters of the force-torque broadcaster and its gravity filter.

ros2_controllers' ``force_torque_sensor_broadcaster`` reads the sensor's six channels, adds its
``offset.*`` and multiplies by its ``multiplier.*``, channel by channel, publishes that on ``~/wrench``
and passes it through its ``sensor_filter_chain`` to ``~/wrench_filtered``. control_toolbox's
``control_filters/GravityCompensationWrench`` in that chain subtracts the tool's weight, with ``R_sw``
the world's axes in the sensor's (tf, ``world_frame`` to ``sensor_frame``), ``m = tool.mass``,
``g = tool.gravity_field`` (the world's axes) and ``CoG = tool.CoG`` (the sensor's)::

    w_b = (w_hat + offset) * multiplier                                                          (X1)
    f_out = f_b - R_sw m g,     tau_out = tau_b - CoG x (R_sw m g)                                 (X2)

(X2) removes the weight from a reading of the load, the wrench the tool applies to the sensor
(``f_b = m R_sw g + f_e`` at rest): its output is the environment's wrench on the tool at the sensor's
point, in the sensor's axes, the ``w_e`` of :mod:`fmscal.analysis._compensate` (C1) at rest. fmscal's
reading model is ``w = diag(gains) S (sigma w_hat - b)`` with ``w`` the wrench the mount applies to the
tool, the negative of the load, ``sigma = +1`` for a sensor that reads that reaction and ``-1`` for one
that reads the load. With ``S = I`` (a sensor calibrated by its maker), ``sigma^2 = 1`` gives::

    -w = (w_hat - sigma b) * (-sigma gains):   offset = -sigma b,   multiplier = -sigma gains        (X3)

so a reaction sensor takes ``multiplier = -1`` (times its gains) and ``offset = -b``, a load sensor
``+1`` and ``+b``. The centre of mass goes in the sensor's own axes and gravity in the pose frame's::

    tool.CoG = M^T com,    tool.gravity_field = g,    tool.mass = m                                (X4)

(``com`` in the tracked frame's axes as the payload file holds it, ``M`` the sensor's mounting on that
frame), so that tf's ``sensor_frame`` must be the sensor's real axes and ``world_frame`` the frame the
poses were recorded in (its axes).

What the chain cannot carry, and the export states:

- ``S`` beyond its diagonal: given a calibration, the multipliers take ``D = diag(S)`` (``multiplier =
  -sigma gains D``), and the rest leaves ``e = (D S^-1 - I) w`` of a wrench ``w``; on the tool's weight,
  over every attitude, channel ``i`` is off by up to::

      e_i = | E_i [m [com]x; m I_3] | |g|,     E = D S^-1 - I                                      (X5)

- the mounting where tf lacks it: the export names ``M`` as the quaternion of a static transform;
- the dynamics, all of it (the filter is static): the wrench the tool's motion needs beyond its weight,
  at the sensor's point in the sensor's axes (Newton-Euler, :func:`fmscal.plant.physics.regressor` with
  gravity zero)::

      f_d = m a_c,    tau_d = I alpha + omega x I omega + com x m a_c                                (X6)

  ``a_c = R^T p_ddot + alpha x com + omega x (omega x com)`` the centre of mass's acceleration: stated
  at the motion of a log where one is given, as formulas otherwise.
"""

import json
import re
import textwrap
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fmscal.plant import Calibration, Log
from fmscal.plant.io import atomic_write_text, reading_sign
from fmscal.plant.numerics import FmscalError
from fmscal.plant.physics import SpatialPayload, edge, regressor, skew, spatial_motion
from fmscal.observers.payload import PayloadEstimate, inertia_turn

from ._calibrate import read_data
from ._motion import quaternion_from_matrix

__all__ = ["ros2_control_parameters", "Ros2ControlParameters", "DynamicsLeftOut", "dynamics_left_out", "ExportError",
           "ROS2_CONTROL_RELEASES", "GRAVITY_FILTER", "READ_ONLY", "RUNTIME"]

#: The releases whose parameter definitions the export writes, checked against their files
#: (tests/data/ros2_control/): ROS 2 distribution -> (control_toolbox, ros2_controllers).
ROS2_CONTROL_RELEASES = {"jazzy": ("control_toolbox 4.11.0", "ros2_controllers 4.42.1"),
                         "kilted": ("control_toolbox 5.10.0", "ros2_controllers 5.17.0")}
#: The gravity filter's plugin (control_toolbox's ``control_filters.xml``).
GRAVITY_FILTER = "control_filters/GravityCompensationWrench"
#: The filter's parameters fixed when the controller is configured (``read_only``); ``tool.*`` and the
#: broadcaster's offsets and multipliers are read again while it runs.
READ_ONLY = ("world_frame", "sensor_frame")
#: The parameters a running broadcaster reads again (their dotted names begin so, or hold the filter's ``tool``).
RUNTIME = ("offset.", "multiplier.", ".params.tool.")
#: The broadcaster's parameter of each reading channel (fmscal's order, ``tx ty tz fx fy fz``).
CHANNELS = (("torque", "x"), ("torque", "y"), ("torque", "z"), ("force", "x"), ("force", "y"), ("force", "z"))
#: The smoothing window of the log's pose differentiation, s (as :func:`fmscal.observers.payload.identify_payload`).
WINDOW = 0.2
#: A ROS 2 node name, as the key of a parameter file (a namespace, ``/**`` wildcards allowed).
_NODE_NAME = re.compile(r"^/?(\*\*|[A-Za-z_][A-Za-z0-9_]*)(/(\*\*|[A-Za-z_][A-Za-z0-9_]*))*$")


class ExportError(FmscalError):
    """Input the export cannot use: the message names the problem."""


@dataclass
class DynamicsLeftOut:
    """What the static filter leaves of the tool's motion at a log's samples, eq. (X6), sensor axes.

    Attributes
    ----------
    log : str
        The log's name.
    samples : int
        The samples counted (the smoothing window's edges left out).
    duration : float
        s.
    force_rms, force_max : float
        Of ``|f_d| = |m a_c|``, N.
    torque_rms, torque_max : float
        Of ``|tau_d|``, N m; without the inertia's share where ``inertia_counted`` is False.
    inertia_counted : bool
        The payload's inertia was determined and is in ``tau_d``.
    alpha_rms, omega_squared_rms : float
        Of ``|alpha|`` (rad/s^2) and ``|omega|^2`` (rad^2/s^2): the inertia's share ``I alpha + omega x I
        omega`` is about these times the tool's inertia (kg m^2).
    """

    log: str
    samples: int
    duration: float
    force_rms: float
    force_max: float
    torque_rms: float
    torque_max: float
    inertia_counted: bool
    alpha_rms: float
    omega_squared_rms: float


@dataclass
class Ros2ControlParameters:
    """The parameters :func:`ros2_control_parameters` writes, and what they leave out.

    Attributes
    ----------
    parameters : dict
        ``{controller: {"ros__parameters": {...}}}``, nested as a ROS 2 parameter file is.
    notes : list of str
        The signs, the axes, and what the chain cannot carry, in words (the YAML's opening comments).
    dynamics : DynamicsLeftOut or None
        The dynamics left out at a log's motion, where a log was given.
    crosstalk : ndarray, shape (6,), or None
        With a calibration: what its off-diagonal part leaves of the tool's weight, each channel's worst over
        every attitude, eq. (X5), N m and N (reading order); None without one.
    """

    parameters: dict
    notes: list = field(default_factory=list)
    dynamics: DynamicsLeftOut = None
    crosstalk: np.ndarray = None

    def to_yaml(self):
        """The parameter file: the notes as comments, then the parameters (block style, every float with a
        decimal point or an exponent, so that no YAML reader takes it for an integer or a string)."""
        comments = [textwrap.fill(note, 100, initial_indent="# ", subsequent_indent="#   ") for note in self.notes]
        return "\n".join(comments + [_yaml(self.parameters, 0)]) + "\n"

    def save(self, path):
        """Write :meth:`to_yaml` to ``path`` (atomically)."""
        atomic_write_text(path, self.to_yaml())

    def runtime(self):
        """The controller's name and the parameters it reads again while it runs (:data:`RUNTIME`): ``(controller,
        {dotted name: value})``, as :func:`fmscal.analysis.ros2.push_parameters` sets them on a running one."""
        (controller, tree), = self.parameters.items()
        found = {}

        def walk(node, prefix):
            for key, value in node.items():
                if isinstance(value, dict):
                    walk(value, f"{prefix}{key}.")
                elif any(prefix.startswith(r) or r in prefix for r in RUNTIME):
                    found[prefix + key] = value
        walk(tree["ros__parameters"], "")
        return controller, found


def ros2_control_parameters(payload, sensor_frame, world_frame, controller="force_torque_sensor_broadcaster",
                            calibration=None, sensor_name=None, log=None, window=WINDOW):
    """The broadcaster's and its gravity filter's parameters for a payload, eqs. (X1)-(X6).

    Parameters
    ----------
    payload : observers.payload.PayloadEstimate or str or Path
        A payload estimate (a fit's, or :meth:`PayloadEstimate.load`'s) or its file (format ``/2``).
    sensor_frame : str
        tf's frame of the sensor's own axes (``frame_id`` of the broadcaster and the filter's
        ``sensor_frame``).
    world_frame : str
        tf's frame whose axes the payload's poses were recorded in (gravity's frame).
    controller : str
        The broadcaster's name in the controller manager (the parameter file's key).
    calibration : plant.Calibration or str or Path, optional
        The sensor's calibration ``S`` where it is not the identity: its diagonal joins the multipliers,
        and what its off-diagonal leaves is stated (X5).
    sensor_name : str, optional
        The broadcaster's ``sensor_name`` (the state interfaces' prefix); left out where not given.
    log : plant.Log or str or Path, optional
        A spatial log of the tool's motion (such as the one it was identified on): the dynamics the filter
        leaves out are stated at its samples (X6).
    window : float
        The log's smoothing window, s.

    Returns
    -------
    Ros2ControlParameters

    Raises
    ------
    ExportError
        A payload file of the first format (no offset or sign), a payload not determined, a frame or
        controller name that is not one, a calibration that is not spatial or whose sign contradicts the
        payload's, a log that is not a spatial log (one line each).
    observers.payload.PayloadFileError
        A payload file that cannot be read.

    Examples
    --------
    >>> from fmscal.observers.payload import fit_static
    >>> from fmscal.plant.io import simulate_table
    >>> from fmscal.plant.scenarios import TOOL
    >>> fit = fit_static(simulate_table(TOOL, n=12, seed=0))
    >>> out = ros2_control_parameters(fit, "ft_sensor", "base_link")
    >>> tool = out.parameters["force_torque_sensor_broadcaster"]["ros__parameters"]["sensor_filter_chain"]
    >>> round(tool["filter1"]["params"]["tool"]["mass"], 2)
    1.2
    """
    estimate = _payload(payload)
    for name, value in (("sensor_frame", sensor_frame), ("world_frame", world_frame)):
        if not (isinstance(value, str) and value and value.isprintable() and not value.startswith("/")
                and " " not in value):
            raise ExportError(f"{name} must be a tf frame's name (not empty, no space, no leading /); got {value!r}")
    if not (isinstance(controller, str) and _NODE_NAME.match(controller)):
        raise ExportError(f"controller must be a ROS 2 node's name (letters, digits, _); got {controller!r}")
    if sensor_name is not None and not (isinstance(sensor_name, str) and sensor_name and sensor_name.isprintable()):
        raise ExportError(f"sensor_name must be a name; got {sensor_name!r}")
    S = _calibration_S(calibration, estimate)
    sigma = reading_sign(estimate.reading)
    gains = np.ones(6) if estimate.gains is None else np.asarray(estimate.gains, dtype=float)
    D = np.ones(6) if S is None else np.diag(S)
    offset = -sigma * np.asarray(estimate.b, dtype=float)                                   # (X3)
    multiplier = -sigma * gains * D
    M = np.asarray(estimate.mounting, dtype=float)
    cog = M.T @ np.asarray(estimate.com, dtype=float)                                      # (X4)
    gravity = estimate.gravity_used
    broadcaster = {"frame_id": sensor_frame}
    if sensor_name is not None:
        broadcaster["sensor_name"] = sensor_name
    broadcaster["offset"] = _by_channel(offset)
    broadcaster["multiplier"] = _by_channel(multiplier)
    broadcaster["sensor_filter_chain"] = {"filter1": {
        "name": "gravity_compensation", "type": GRAVITY_FILTER,
        "params": {"world_frame": world_frame, "sensor_frame": sensor_frame,
                   "tool": {"mass": float(estimate.mass), "CoG": [float(v) for v in cog],
                            "gravity_field": [float(v) for v in gravity]}}}}
    dynamics = None if log is None else dynamics_left_out(estimate, log, window)
    crosstalk = None if S is None else _crosstalk(estimate, S)
    notes = _notes(estimate, payload, sensor_frame, world_frame, S, dynamics, crosstalk)
    return Ros2ControlParameters({controller: {"ros__parameters": broadcaster}}, notes, dynamics, crosstalk)


def dynamics_left_out(payload, log, window=WINDOW):
    """The dynamics a static filter leaves at a log's motion, eq. (X6), as :class:`DynamicsLeftOut`.

    The wrench the motion needs beyond the weight is the regressor with gravity zero (``a_g = R^T
    p_ddot``) times the payload's inertial parameters in the sensor's axes (``M^T com``, ``M^T I M``),
    at the sensor's attitude ``R M`` (:func:`fmscal.plant.physics.regressor` with the mounting); the
    inertia's share is left out where the payload holds none.

    Parameters
    ----------
    payload : observers.payload.PayloadEstimate
        In any axes (taken to the tracked frame's, :meth:`~fmscal.observers.payload.PayloadEstimate.tracked`).
    log : plant.Log or str or Path
        A spatial log (poses with positions).
    window : float
        The smoothing window of the pose differentiation, s.

    Returns
    -------
    DynamicsLeftOut
    """
    estimate = payload.tracked()
    if isinstance(log, (str, Path)):
        log = read_data(log)
    if not isinstance(log, Log):              # a spatial_motion of a log of another model refuses in one line
        raise ExportError(f"{getattr(log, 'name', 'the log')}: the dynamics need a log of poses with their "
                          "positions (t, qw..qz, x y z, the reading); an attitude-only log or a pose table holds no "
                          "acceleration")
    M = np.eye(3) if estimate.mounting is None else np.asarray(estimate.mounting, dtype=float)
    com = M.T @ np.asarray(estimate.com, dtype=float)
    # the inertial parameters are linear in the inertia: those of the point mass (any tensor, then taken out)
    # and the inertia's own, both through SpatialPayload's (the parallel-axis theorem written once)
    unit = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    point = SpatialPayload(float(estimate.mass), unit, com).inertial_parameters - np.r_[np.zeros(4), unit]
    inertia = None if estimate.inertia is None else inertia_turn(M.T) @ np.asarray(estimate.inertia, dtype=float)
    q, omega, alpha, p_ddot = spatial_motion(log, window)
    keep = slice(edge(log, window), len(log.t) - edge(log, window))
    W = regressor(q[keep], omega[keep], alpha[keep], p_ddot[keep], np.zeros(3), M)        # gravity zero: (X6)
    wrench = W @ point
    if inertia is not None:
        wrench = wrench + W[:, :, 4:] @ inertia
    force, torque = np.linalg.norm(wrench[:, 3:], axis=1), np.linalg.norm(wrench[:, :3], axis=1)
    w_s, a_s = omega[keep] @ M, alpha[keep] @ M                                 # the sensor's axes (M^T omega)
    rms = lambda v: float(np.sqrt(np.mean(np.square(v))))                   # noqa: E731
    t = log.t[keep]
    return DynamicsLeftOut(log=log.name, samples=len(t), duration=float(t[-1] - t[0]), force_rms=rms(force),
                           force_max=float(force.max()), torque_rms=rms(torque), torque_max=float(torque.max()),
                           inertia_counted=inertia is not None, alpha_rms=rms(np.linalg.norm(a_s, axis=1)),
                           omega_squared_rms=rms(np.sum(w_s ** 2, axis=1)))


def _payload(payload):
    """The payload estimate in the tracked frame's axes, with what the chain needs (an offset, a sign)."""
    if isinstance(payload, (str, Path)):
        payload = PayloadEstimate.load(payload)
    if not hasattr(payload, "tracked"):            # a PayloadEstimate, or a table's fit (StaticFit)
        raise ExportError(f"the export takes a payload estimate or its file; got {type(payload).__name__}")
    estimate = payload.tracked()
    if not estimate.payload_determined:
        raise ExportError("the payload estimate does not determine the mass and the centre of mass: nothing to "
                          "export")
    if estimate.b is None or estimate.reading is None or estimate.mounting is None:
        raise ExportError("the payload holds no offset, sign or mounting (a file of format /1): identify the "
                          "payload again (fmscal identify-payload --save) and export that file")
    return estimate


def _calibration_S(calibration, estimate):
    """``S`` of a calibration of the payload's reading (None without one), its sign the payload's."""
    if calibration is None:
        return None
    if isinstance(calibration, (str, Path)):
        calibration = Calibration.load(calibration)
    channels = len(estimate.b)
    if not isinstance(calibration, Calibration) or calibration.size != channels:
        raise ExportError(f"calibration must be a plant.Calibration of the payload's {channels} channels "
                          f"({channels}x{channels} S) or its file")
    reading = estimate.reading
    if calibration.reading != reading:
        raise ExportError(f"the calibration reads the {calibration.reading}, the payload the {reading}: one sensor "
                          "has one sign")
    return np.asarray(calibration.S_hat, dtype=float)


def _by_channel(values):
    """``{"force": {"x": ..}, "torque": {..}}`` of six values in the reading's order."""
    out = {"force": {}, "torque": {}}
    for (kind, axis), v in zip(CHANNELS, values):
        out[kind][axis] = float(v)
    return {"force": out["force"], "torque": out["torque"]}


def _crosstalk(estimate, S):
    """Eq. (X5): each channel's worst error on the tool's weight over every attitude, of ``S`` beyond its diagonal.

    The weight's wrench at the sensor is linear in gravity's direction ``u`` in the sensor's axes, ``w = [m [com]x;
    m I] (-|g| u)``; the error ``E w`` of channel ``i`` is then largest, over unit ``u``, as the norm of its row.
    """
    E = np.diag(np.diag(S)) @ np.linalg.inv(S) - np.eye(6)
    com = np.asarray(estimate.mounting, dtype=float).T @ np.asarray(estimate.com, dtype=float)
    rows = E @ np.vstack([estimate.mass * skew(com), estimate.mass * np.eye(3)])
    return np.linalg.norm(rows, axis=1) * float(np.linalg.norm(estimate.gravity_used))


def _notes(estimate, source, sensor_frame, world_frame, S, dynamics, crosstalk):
    """The signs, the axes and what the chain leaves out, in words."""
    where = f" from {Path(source).name}" if isinstance(source, (str, Path)) else ""
    releases = "; ".join(f"ROS 2 {name.capitalize()}: {' and '.join(versions)}"
                         for name, versions in ROS2_CONTROL_RELEASES.items())
    notes = [f"Written by fmscal export ros2-control{where}: the parameters of ros2_controllers' "
             f"force_torque_sensor_broadcaster and control_toolbox's {GRAVITY_FILTER} in its sensor_filter_chain "
             f"({releases}).",
             ("The sensor reads the reaction (the wrench the mount applies to the tool): multiplier -1 turns it into "
              "the load the filter takes the weight from, and offset = -b." if estimate.reading == "reaction" else
              "The sensor reads the load (the wrench the tool applies to it), as the filter takes it: multiplier "
              "+1, offset = +b.")
             + " ~/wrench_filtered is then the environment's wrench on the tool at the sensor's point, in the "
               "sensor's axes (what fmscal compensate writes by default, at rest); ~/wrench the reading with its "
               "offset removed, as a load.",
             f"tool.CoG is in the sensor's own axes: tf's {sensor_frame} must be the sensor's real axes; "
             + _mounting_note(estimate, sensor_frame),
             f"tool.gravity_field is gravity in the frame the payload's poses were recorded in "
             f"({'estimated' if estimate.gravity is not None else 'as given'}): {world_frame}'s axes must be that "
             f"frame's.",
             f"{' and '.join(READ_ONLY)} are read-only (read when the controller is configured); tool.*, offset.* "
             "and multiplier.* are read again while it runs.",
             _calibration_note(S, crosstalk)]
    if estimate.gains is not None:
        notes.append("The multipliers carry the reading's gains per channel (" + ", ".join(
            f"{kind[0]}{axis} {g:.4g}" for (kind, axis), g in zip(CHANNELS, estimate.gains)) + ").")
    notes.append(_dynamics_note(estimate, dynamics))
    notes.append("The filter takes the values only: the payload's uncertainty (mass +- "
                 f"{estimate.mass_std:.2g} kg, centre of mass +- {1e3 * np.max(estimate.com_std):.2g} mm) is not "
                 "carried, and it detects neither a contact nor a change of tool.")
    if not estimate.converged:
        notes.append("The payload estimate did not converge: " + "; ".join(estimate.warnings or ["see its fit"]))
    return notes


def _mounting_note(estimate, sensor_frame):
    """The mounting: turned where estimated (its static transform), square where not."""
    if estimate.mounting_std_deg is None:
        return ("the payload's poses were taken as the sensor's axes (the mounting was not estimated: the "
                "identity).")
    qw, qx, qy, qz = quaternion_from_matrix(np.asarray(estimate.mounting, dtype=float)[None])[0]
    return (f"they are turned {estimate.mounting_deg:.3g} +- {estimate.mounting_std_deg:.2g} degrees from the "
            f"frame the poses were of (the estimated mounting M). If {sensor_frame} is that frame, add a frame for "
            f"the sensor's axes, a static transform from it with no translation and the rotation (qx qy qz qw) = "
            f"({qx:.6f} {qy:.6f} {qz:.6f} {qw:.6f}), and export with that frame as the sensor's.")


def _calibration_note(S, crosstalk):
    """S: the identity taken, or its diagonal in the multipliers and what its off-diagonal leaves, eq. (X5)."""
    if S is None:
        return ("S = I is taken (a sensor calibrated by its maker): the chain scales each channel alone, and holds "
                "no cross-talk.")
    E = np.diag(np.diag(S)) @ np.linalg.inv(S) - np.eye(6)
    return (f"The multipliers take S's diagonal; its off-diagonal part, which the chain cannot hold, leaves "
            f"(D S^-1 - I) w of a wrench w (entries up to {np.abs(E).max():.2g}): on the tool's weight up to "
            f"{crosstalk[:3].max():.2g} N m and {crosstalk[3:].max():.2g} N over every attitude.")


def _dynamics_note(estimate, dynamics):
    """What leaving out the dynamics costs: at a log's motion, or as formulas."""
    formulas = ("f = m a_c in N and tau = I alpha + omega x I omega + com x m a_c in N m, at the sensor's point "
                "(a_c the centre of mass's acceleration, alpha and omega the tool's angular acceleration and "
                "velocity)")
    if dynamics is None:
        return (f"The filter is static: it leaves the wrench of the tool's motion, {formulas}; nothing at rest. "
                "Give a log of the motion (--log) to state it in numbers.")
    inertia = ("" if dynamics.inertia_counted else
               f" (without the inertia's own share, not determined: about {dynamics.alpha_rms:.3g} rad/s^2 rms of "
               f"|alpha| and {dynamics.omega_squared_rms:.3g} rad^2/s^2 of |omega|^2, times the tool's inertia in "
               "kg m^2)")
    noise = ""
    if estimate.noise_sd is not None and estimate.noise_of == "sample":
        sd = np.asarray(estimate.noise_sd, dtype=float)
        noise = (f"; the reading's noise is {np.linalg.norm(sd[3:]):.2g} N and {np.linalg.norm(sd[:3]):.2g} N m "
                 "(per sample, all three axes)")
    return (f"The filter is static: it leaves the wrench of the tool's motion, {formulas}. At the motion of "
            f"{dynamics.log} ({dynamics.samples} samples, {dynamics.duration:.3g} s): |f| {dynamics.force_rms:.2g} N "
            f"rms, {dynamics.force_max:.2g} N at most; |tau| {dynamics.torque_rms:.2g} N m rms, "
            f"{dynamics.torque_max:.2g} N m at most{inertia}{noise}.")


def _yaml(value, depth):
    """``value`` as block-style YAML at ``depth`` levels of two spaces: mappings nested, lists of numbers in flow
    style, strings double-quoted (JSON's escapes are YAML's), floats always with a point or an exponent."""
    pad = "  " * depth
    lines = []
    for key, item in value.items():
        if isinstance(item, dict):
            lines.append(f"{pad}{key}:")
            lines.append(_yaml(item, depth + 1))
        else:
            lines.append(f"{pad}{key}: {_scalar(item)}")
    return "\n".join(lines)


def _scalar(v):
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_scalar(x) for x in v) + "]"
    text = repr(float(v))
    return text.replace("e", ".0e", 1) if "." not in text and "e" in text else text
