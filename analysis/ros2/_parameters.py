"""The node's ROS parameters: one table (name, type, default, description) and their checks.

Nothing here imports rclpy: the table is read by the node (``declare_parameter`` of each), by the guide, and
by the checks below, which turn the values the node got into :class:`Settings` or a one-line
:class:`Ros2Error`.
"""

import re
from dataclasses import dataclass

import numpy as np

from fmscal.plant.numerics import FmscalError

from .._compensate import CAUSAL_DELAY, CAUSAL_WINDOW, DIRECTIONS, FALSE_ALARM
from .._tool_change import TOOL_CHANGE
from .._motion import quaternion_to_matrix

#: A node's full name (namespaces and all, no wildcard): ``push_controller`` and the push's target.
FULL_NAME = re.compile(r"^(/[A-Za-z_][A-Za-z0-9_]*)+$")

__all__ = ["NODE_NAME", "PARAMETERS", "Parameter", "Ros2Error", "Settings", "settings", "QOS", "OUTPUT_FRAMES",
           "MOTION_SOURCES"]

#: The node's name (``--ros-args -r __node:=...`` renames it).
NODE_NAME = "fmscal_compensator"
#: The inputs' quality of service: the sensor-data profile (best effort) or reliable.
QOS = ("sensor_data", "reliable")
#: The output's axes: the sensor's, or the base's (the motion's frame; needs an attitude).
OUTPUT_FRAMES = ("sensor", "base")
#: The motion's sources, by the parameter naming each one's topic: exactly one is set.
MOTION_SOURCES = ("pose_topic", "joint_states_topic", "imu_topic")


class Ros2Error(FmscalError):
    """The node cannot start or run as configured: the message names the parameter, or the install."""


@dataclass(frozen=True)
class Parameter:
    """One ROS parameter: its name, type (``string``, ``double``, ``integer``, ``bool``, ``double_array``),
    default (None: optional, unset until given; the description says what unset means) and description."""

    name: str
    type: str
    default: object
    description: str


#: Every parameter the node declares, in the order the guide's table lists them.
PARAMETERS = (
    Parameter("calibration", "string", None, "a calibration saved by fmscal calibrate --save; unset: the payload "
              "file's sensor, S the identity (payload is then required)"),
    Parameter("payload", "string", "", "a payload file from fmscal identify-payload --save: alone, the compensation "
              "runs on it (S the identity; its offset, gravity, mounting, sign and noise; its uncertainty in the "
              "output's covariance); with calibration, in place of the calibration's payload (a tool change); "
              "empty: the calibration's"),
    Parameter("tool_radius", "double", None, "m, payload: the tool's radius about its centre of mass, which bounds "
              "an inertia the payload file does not hold (held poses never determine it); unset: twice the centre "
              "of mass's distance from the sensor, at least 5 cm"),
    Parameter("wrench_topic", "string", "/ft_sensor/wrench", "geometry_msgs/WrenchStamped in: the raw reading"),
    Parameter("pose_topic", "string", "", "geometry_msgs/PoseStamped in: the sensor frame's pose (or the tracked "
              "frame's, with pose_to_sensor_*); one motion source of three"),
    Parameter("joint_states_topic", "string", "", "sensor_msgs/JointState in, with urdf and frame; one motion "
              "source of three"),
    Parameter("urdf", "string", "", "joint_states_topic: the robot's URDF file"),
    Parameter("frame", "string", "", "joint_states_topic: the URDF frame (link) of the sensor"),
    Parameter("imu_topic", "string", "", "sensor_msgs/Imu in, an IMU on the tool (orientation, angular velocity, "
              "specific force); one motion source of three"),
    Parameter("contact_topic", "string", "/ft_sensor/contact", "geometry_msgs/WrenchStamped out: the contact "
              "wrench, the input's header stamp"),
    Parameter("covariance_topic", "string", "/ft_sensor/contact_covariance", "std_msgs/Float64MultiArray out: the "
              "contact wrench's covariance, one per output, row-major, force first (fx fy fz tx ty tz; planar "
              "fx fy M)"),
    Parameter("flags_topic", "string", "/ft_sensor/contact_flags", "diagnostic_msgs/DiagnosticArray out: one per "
              "reading taken, stamped as it: level OK for an output right within its covariance, WARN for one "
              "flagged (its message names why), ERROR for a reading given no output (withheld: the cause); the "
              "value contact, the contact test's verdict"),
    Parameter("track_offset", "bool", False, "follow the offset's drift (a random walk updated while no contact "
              "is detected)"),
    Parameter("drift_intensity", "double_array", None, "track_offset: the random walk's intensity, the reading's "
              "units per sqrt(s), one value or one per channel; unset: the reading's noise sd per sqrt(s)"),
    Parameter("contact_threshold", "double", FALSE_ALARM, "the contact test's false-alarm probability per sample"),
    Parameter("reading", "string", None, "the reading's sign convention, reaction or load; unset: the "
              "calibration's"),
    Parameter("latency", "double", None, "s, how late the motion's stamps are behind the wrench's (a motion "
              "stamped t was taken at t - latency); unset: the calibration's for pose_topic (its pose stream's), 0 "
              "for joint states and an IMU"),
    Parameter("gravity", "double_array", None, "m/s^2, gravity in the motion's frame (3 values); unset: the "
              "calibration's"),
    Parameter("direction", "string", DIRECTIONS[0], "on_tool: the wrench the environment applies to the tool; "
              "on_environment: the tool's on the environment (its negative)"),
    Parameter("output_frame", "string", OUTPUT_FRAMES[0], "sensor: the sensor's axes (the input's frame_id); "
              "base: the motion frame's axes (base_frame)"),
    Parameter("base_frame", "string", "", "output_frame base: the output's frame_id; empty: the motion "
              "message's header.frame_id"),
    Parameter("sensor_frame", "string", "", "the wrench's header.frame_id expected (fmscal import prints a bag's and "
              "records it in LOG.import.json): another is logged, said in the diagnostics and flags the outputs; "
              "empty: not checked"),
    Parameter("tool_point", "double_array", None, "m, the point the torque is taken about, in the sensor's axes "
              "(3 values); unset: the sensor's point"),
    Parameter("pose_to_sensor_rotation", "double_array", None, "pose_topic: the sensor's axes in the tracked "
              "frame's, a quaternion x y z w (scalar last); unset: identity"),
    Parameter("pose_to_sensor_translation", "double_array", None, "m, pose_topic: the sensor's point in the "
              "tracked frame (3 values); unset: zero"),
    Parameter("imu_rotation", "double_array", None, "imu_topic: the IMU's axes in the sensor's, a quaternion "
              "x y z w (scalar last); unset: identity"),
    Parameter("imu_lever_arm", "double_array", None, "m, imu_topic: the IMU's point from the sensor's, in the "
              "sensor's axes (3 values); unset: zero"),
    Parameter("qos", "string", QOS[0], "the inputs' QoS: sensor_data (best effort) or reliable (a reliable "
              "subscriber never hears a best-effort driver)"),
    Parameter("queue_depth", "integer", 1000, "the inputs' and outputs' history depth, messages (1 s at 1 kHz: a "
              "pause of the node loses nothing shorter)"),
    Parameter("window", "double", CAUSAL_WINDOW, "s, the causal filter's window over the motion"),
    Parameter("delay", "double", CAUSAL_DELAY, "s, where the causal filter is read, before the newest sample: "
              "the output's delay behind its reading"),
    Parameter("sample_time", "double", 0.0, "s, the wrench stream's period; 0: the median interval of its first "
              "stamps"),
    Parameter("max_rate", "double", 1000.0, "Hz, the fastest readings compensated: faster ones are decimated to "
              "every N-th stamp (N the smallest that brings them within it; said at start and in the diagnostics)"),
    Parameter("stale_timeout", "double", 0.5, "s, how far the motion's newest stamp may trail a reading's before "
              "the motion is stale (the reading is then not compensated)"),
    Parameter("saturation", "double_array", None, "the raw reading's range per channel (one value or one per "
              "channel, the reading's units): a reading at or beyond it is not compensated; unset: not checked"),
    Parameter("tool_change", "string", "", "a change of the payload (a part grasped) detected, said in the log and "
              "the diagnostics, the outputs flagged tool_change until it is re-identified: off, detect, or "
              "reidentify (the new payload fitted to the next held attitudes and used); empty: detect on a 6-axis "
              "reading in 3D, off otherwise"),
    Parameter("save_path", "string", "", "~/save: where the calibration is written (with a payload file alone: "
              "a payload file); empty: ~/save refuses"),
    Parameter("push_controller", "string", "", "with a payload file alone: the node of a running ros2_control "
              "force_torque_sensor_broadcaster (/force_torque_sensor_broadcaster); ~/push, and each ~/identify_payload "
              "or ~/reidentify that succeeds, set its tool.*, offset.* and multiplier.* to the payload in use (as "
              "fmscal export ros2-control --push); empty: no push"),
    Parameter("identify_buffer", "double", 120.0, "s, the motion and readings ~/identify_payload keeps, the newest"),
    Parameter("diagnostics_period", "double", 1.0, "s between two diagnostics on /diagnostics"),
    Parameter("debug_latency", "bool", False, "publish ~/latency (std_msgs/Float64MultiArray per output: s from "
              "the reading's stamp to the output's publication, s from the start of the callback that published "
              "it, the readings waiting)"),
)


@dataclass(frozen=True)
class Settings:
    """The parameters, checked: names as :data:`PARAMETERS` (optional ones None where unset), and ``source``,
    the motion's parameter (one of :data:`MOTION_SOURCES`), ``topic`` its topic."""

    values: dict
    source: str
    topic: str

    def __getattr__(self, name):
        if name.startswith("__") or name == "values":      # (pickle's lookups on an instance not yet filled)
            raise AttributeError(name)
        try:
            return self.values[name]
        except KeyError:
            raise AttributeError(name) from None


def _vector(values, name, sizes, positive=False):
    """A double_array parameter as a float array of one of ``sizes`` (None stays None)."""
    value = values[name]
    if value is None:
        return None
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 1 or len(arr) not in sizes or not np.isfinite(arr).all() or (positive and (arr <= 0).any()):
        what = " or ".join(str(s) for s in sizes)
        raise Ros2Error(f"parameter {name} must be {what} finite{' positive' if positive else ''} numbers; got "
                        f"{list(value)!r}")
    return arr


def _quaternion_matrix(xyzw, name):
    """The rotation of a unit quaternion given scalar last (ROS's order)."""
    x, y, z, w = xyzw
    norm = np.linalg.norm(xyzw)
    if abs(norm - 1) > 1e-3:
        raise Ros2Error(f"parameter {name} must be a unit quaternion x y z w; its norm is {norm:.6g}")
    return quaternion_to_matrix(np.r_[w, x, y, z])                  # fmscal's order, scalar first


def settings(values):
    """Check the parameters' values (a dict by name, None where an optional one is unset).

    Returns
    -------
    Settings
        With ``pose_to_sensor`` (None, or ``(R, t)``: the sensor's axes and point in the tracked frame's) and
        ``imu_rotation`` as a 3x3 matrix.

    Raises
    ------
    Ros2Error
        One line naming the parameter: neither a calibration nor a payload file, not exactly one motion source, a
        choice not among its options, a number out of its range.
    """
    values = dict(values)
    if not values.get("calibration") and not values.get("payload"):
        raise Ros2Error("parameter calibration or payload is required: a file saved by fmscal calibrate --save "
                        "(--ros-args -p calibration:=CAL.json), or by fmscal identify-payload --save (-p "
                        "payload:=tool.json)")
    radius = values.get("tool_radius")
    if radius is not None and not (np.isfinite(radius) and radius > 0):
        raise Ros2Error(f"parameter tool_radius must be a positive number of metres; got {radius!r}")
    if radius is not None and not values.get("payload"):
        raise Ros2Error("parameter tool_radius bounds a payload file's inertia: set payload too")
    given = [name for name in MOTION_SOURCES if values.get(name)]
    if len(given) != 1:
        raise Ros2Error(f"give exactly one motion source of {', '.join(MOTION_SOURCES)}; got "
                        f"{', '.join(given) if given else 'none'}")
    source = given[0]
    if source == "joint_states_topic" and not (values["urdf"] and values["frame"]):
        raise Ros2Error("joint_states_topic needs urdf (the robot's URDF file) and frame (the sensor's link)")
    for name, options in (("qos", QOS), ("output_frame", OUTPUT_FRAMES), ("direction", DIRECTIONS),
                          ("reading", ("reaction", "load")), ("tool_change", ("",) + TOOL_CHANGE)):
        if values[name] is not None and values[name] not in options:
            raise Ros2Error(f"parameter {name} must be one of {', '.join(o for o in options if o)}; got "
                            f"{values[name]!r}")
    for name in ("window", "delay", "stale_timeout", "identify_buffer", "diagnostics_period", "max_rate"):
        if not (np.isfinite(values[name]) and values[name] > 0) and not (name == "delay" and values[name] == 0):
            unit = "Hz" if name == "max_rate" else "seconds"
            raise Ros2Error(f"parameter {name} must be a positive number of {unit}; got {values[name]!r}")
    if not (np.isfinite(values["sample_time"]) and values["sample_time"] >= 0):
        raise Ros2Error(f"parameter sample_time must be 0 (from the stamps) or a period in s; got "
                        f"{values['sample_time']!r}")
    if not 0 < values["contact_threshold"] < 1:
        raise Ros2Error(f"parameter contact_threshold is a false-alarm probability in (0, 1); got "
                        f"{values['contact_threshold']!r}")
    if values["latency"] is not None and not np.isfinite(values["latency"]):
        raise Ros2Error(f"parameter latency must be a finite number of seconds; got {values['latency']!r}")
    if values["push_controller"] and (values.get("calibration") or not values.get("payload")):
        raise Ros2Error("parameter push_controller pushes a payload file's payload (S the identity): give payload "
                        "alone, no calibration")
    if values["push_controller"] and not FULL_NAME.match("/" + values["push_controller"].lstrip("/")):
        raise Ros2Error(f"parameter push_controller must be a node's name such as force_torque_sensor_broadcaster "
                        f"(no wildcard); got {values['push_controller']!r}")
    if values["queue_depth"] < 1:
        raise Ros2Error(f"parameter queue_depth must be at least 1; got {values['queue_depth']}")
    values["gravity"] = _vector(values, "gravity", (3,))
    values["tool_point"] = _vector(values, "tool_point", (3,))
    values["drift_intensity"] = _vector(values, "drift_intensity", (1, 3, 6))
    values["saturation"] = _vector(values, "saturation", (1, 3, 6), positive=True)
    if values["drift_intensity"] is not None and not values["track_offset"]:
        raise Ros2Error("parameter drift_intensity is the offset tracker's: set track_offset:=true too")
    rotation = _vector(values, "pose_to_sensor_rotation", (4,))
    translation = _vector(values, "pose_to_sensor_translation", (3,))
    if (rotation is not None or translation is not None) and source != "pose_topic":
        raise Ros2Error("pose_to_sensor_rotation and pose_to_sensor_translation are for pose_topic")
    values["pose_to_sensor"] = None if rotation is None and translation is None else (
        np.eye(3) if rotation is None else _quaternion_matrix(rotation, "pose_to_sensor_rotation"),
        np.zeros(3) if translation is None else translation)
    imu_rotation = _vector(values, "imu_rotation", (4,))
    values["imu_rotation"] = None if imu_rotation is None else _quaternion_matrix(imu_rotation, "imu_rotation")
    values["imu_lever_arm"] = _vector(values, "imu_lever_arm", (3,))
    if (values["imu_rotation"] is not None or values["imu_lever_arm"] is not None) and source != "imu_topic":
        raise Ros2Error("imu_rotation and imu_lever_arm are for imu_topic")
    return Settings(values=values, source=source, topic=values[source])
