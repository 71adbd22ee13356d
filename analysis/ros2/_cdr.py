"""The node's hot messages as bytes: the inputs decoded and the outputs encoded without rclpy's message objects.

rclpy converts every message between its C structure and a Python object field by field, through the fields'
checking setters, on each take and each publish. At 1 kHz the node takes two messages and publishes three or four
per output, so its poll thread takes the inputs serialized and publishes the outputs serialized
(``python benchmarks/ros2_latency.py`` measures the node whole: docs/guide/robot.md, "What it costs").

Inputs. Decoded here where they are plain CDR, little endian (the encapsulation ``00 01``, the one ROS 2's
middlewares send): a header (the stamp, ``sec`` and ``nanosec``, then ``frame_id``), then the fields, each
aligned to its size counted from the end of the 4-byte encapsulation. Any other encapsulation goes to rclpy's
``deserialize_message`` and then to the same plain values (:func:`plain`), as the messages an executor hands do.
A string is read as rclpy reads it (up to its first NUL). A message that does not parse (too short for its
fields, a string or a sequence longer than the message), or that rclpy cannot read, raises ``ValueError``.

Outputs. Each output type's bytes are serialized once by rclpy (``serialize_message``) for each set of its
strings (the frame, a status's text) and kept as a template, its stamp and its numbers then written in place: the
layout is always rclpy's own. The places are found by serializing the template with marker values and looking
for their bytes (:class:`Template`); where they cannot be found, each output is serialized whole by rclpy.
"""

import struct

import numpy as np

__all__ = ["PLAIN_LE", "Template", "decoder", "plain"]

#: The encapsulation of plain CDR, little endian: the inputs this module decodes itself.
PLAIN_LE = b"\x00\x01"

_STAMP = struct.Struct("<iI")
_U32 = struct.Struct("<I")
_DOUBLES = {n: struct.Struct(f"<{n}d") for n in (6, 7, 37)}

#: The number of doubles after the header: a wrench (force, torque), a pose (position, orientation x y z w), an
#: IMU sample (orientation x y z w, its covariance, the rate, its covariance, the acceleration, its covariance).
_AFTER_HEADER = {"wrench": 6, "pose": 7, "imu": 37}


def _align(pos, size):
    """``pos`` moved on to a multiple of ``size`` counted from the encapsulation's end (byte 4)."""
    return pos + (-(pos - 4)) % size


def _string(data, pos):
    """A CDR string at ``pos`` (its length, counting a terminating NUL, then its bytes) and the position after; read
    as rclpy reads it, up to its first NUL."""
    pos = _align(pos, 4)
    (n,) = _U32.unpack_from(data, pos)
    end = pos + 4 + n
    if end > len(data):
        raise ValueError("a CDR string longer than its message")
    text = data[pos + 4:end]
    cut = text.find(b"\0")
    return (text if cut < 0 else text[:cut]).decode("utf-8", "replace"), end


def _header(data):
    """``(sec, nanosec, frame_id, position after it)`` of a plain little-endian CDR message's header."""
    sec, nanosec = _STAMP.unpack_from(data, 4)
    frame_id, pos = _string(data, 12)
    return sec, nanosec, frame_id, pos


def _doubles(data, pos, n):
    """``n`` doubles at ``pos`` (aligned to 8) as a tuple, and the position after them."""
    pos = _align(pos, 8)
    return _DOUBLES[n].unpack_from(data, pos), pos + 8 * n


def _double_sequence(data, pos):
    """A CDR ``sequence<double>`` at ``pos`` (its count, then the doubles aligned to 8) and the position after."""
    pos = _align(pos, 4)
    (n,) = _U32.unpack_from(data, pos)
    pos += 4
    if not n:
        return np.empty(0), pos
    pos = _align(pos, 8)
    if pos + 8 * n > len(data):
        raise ValueError("a CDR sequence longer than its message")
    return np.frombuffer(data, "<f8", n, pos), pos + 8 * n


def _fixed(kind):
    n = _AFTER_HEADER[kind]

    def decode(data):
        sec, nanosec, frame_id, pos = _header(data)
        values, _ = _doubles(data, pos, n)
        return (sec, nanosec), frame_id, values
    return decode


def _joint_state(data):
    sec, nanosec, frame_id, pos = _header(data)
    pos = _align(pos, 4)
    (count,) = _U32.unpack_from(data, pos)
    pos += 4
    if count > len(data):
        raise ValueError("a CDR sequence longer than its message")
    names = []
    for _ in range(count):
        name, pos = _string(data, pos)
        names.append(name)
    position, pos = _double_sequence(data, pos)
    velocity, pos = _double_sequence(data, pos)
    _double_sequence(data, pos)                        # the efforts: not used, but there in full
    return (sec, nanosec), frame_id, (names, position, velocity)


_DECODERS = {"wrench": _fixed("wrench"), "pose": _fixed("pose"), "imu": _fixed("imu"), "joints": _joint_state}


def plain(kind, msg):
    """A message object's plain values, as :func:`decoder`'s gives them from its bytes: ``((sec, nanosec),
    frame_id, values)``, ``values`` a wrench's six (force then torque), a pose's seven (position, then the
    orientation x y z w), an IMU sample's 37 (orientation x y z w, its covariance, the rate, its covariance, the
    acceleration, its covariance), or a joint state's ``(names, position, velocity)``."""
    stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
    if kind == "wrench":
        f, t = msg.wrench.force, msg.wrench.torque
        values = (f.x, f.y, f.z, t.x, t.y, t.z)
    elif kind == "pose":
        p, o = msg.pose.position, msg.pose.orientation
        values = (p.x, p.y, p.z, o.x, o.y, o.z, o.w)
    elif kind == "imu":
        o, w, a = msg.orientation, msg.angular_velocity, msg.linear_acceleration
        values = ((o.x, o.y, o.z, o.w) + tuple(msg.orientation_covariance) + (w.x, w.y, w.z)
                  + tuple(msg.angular_velocity_covariance) + (a.x, a.y, a.z)
                  + tuple(msg.linear_acceleration_covariance))
    else:
        values = (list(msg.name), np.asarray(msg.position, dtype=float), np.asarray(msg.velocity, dtype=float))
    return stamp, msg.header.frame_id, values


def decoder(kind, message_type, deserialize):
    """A function of a message's bytes (``kind`` one of wrench, pose, imu, joints) giving its plain values
    (:func:`plain`): decoded here where plain little-endian CDR, by ``deserialize(data, message_type)``
    (rclpy's ``deserialize_message``) otherwise; ``ValueError`` where neither can read them."""
    fast = _DECODERS[kind]

    def decode(data):
        if data[:2] == PLAIN_LE:
            try:
                return fast(data)
            except struct.error:
                raise ValueError(f"a {message_type.__name__} message shorter than its fields") from None
        try:
            msg = deserialize(data, message_type)
        except Exception as err:                      # rclpy's RMWError: a message it cannot read
            raise ValueError(f"a {message_type.__name__} message rclpy cannot read ({type(err).__name__})") from None
        return plain(kind, msg)
    return decode


class Template:
    """One output type's bytes: rclpy's serialization of a message, kept per set of its strings, with its stamp
    and its numbers written in place.

    Parameters
    ----------
    build : callable
        ``build(stamp, numbers, *strings)`` gives the message object: ``stamp`` ``(sec, nanosec)``, ``numbers``
        a sequence of floats (their count fixed for the type).
    count : int
        How many numbers.
    serialize : callable
        rclpy's ``serialize_message``.
    stamped : bool
        Whether the message has a header's stamp.
    kept : int
        The most sets of strings kept (beyond, each output is serialized whole).
    """

    _MARK_STAMP = (0x5EC0_1D5, 0x0ABC_DEF1)

    def __init__(self, build, count, serialize, stamped=True, kept=64):
        self.build, self.count, self.serialize, self.kept = build, count, serialize, kept
        self.stamped = stamped
        self._layouts = {}
        self._numbers = struct.Struct(f"<{count}d")

    def _layout(self, strings):
        """``(template bytes, stamp's place, numbers' place)`` for ``strings``; None where the places are not
        found (numbers not in one little-endian run, a stamp not where a header puts it)."""
        marks = [1.0 + (i + 1) * 2.0 ** -20 + 2.0 ** -45 for i in range(self.count)]
        data = bytes(self.serialize(self.build(self._MARK_STAMP, marks, *strings)))
        stamp_at = data.find(_STAMP.pack(*self._MARK_STAMP)) if self.stamped else None
        numbers_at = data.find(self._numbers.pack(*marks)) if self.count else None
        if stamp_at == -1 or numbers_at == -1:
            return None
        return bytearray(data), stamp_at, numbers_at

    def __call__(self, stamp, numbers=(), *strings):
        """The bytes of the message with ``stamp``, ``numbers`` and ``strings``."""
        layout = self._layouts.get(strings, False)
        if layout is False:
            layout = self._layout(strings) if len(self._layouts) < self.kept else None
            if len(self._layouts) < self.kept:
                self._layouts[strings] = layout
        if layout is None:
            return bytes(self.serialize(self.build(stamp, list(numbers), *strings)))
        data, stamp_at, numbers_at = layout
        if stamp_at is not None:
            _STAMP.pack_into(data, stamp_at, *stamp)
        if numbers_at is not None:
            self._numbers.pack_into(data, numbers_at, *numbers)
        return bytes(data)
