"""Newton-Euler for one rigid body at the sensor point, in sensor axes (the spatial case).

A 6-axis force-torque sensor sits between a mount and a rigid payload that
moves in 3D under gravity. Conventions (fixed by the spatial log format):

- sensor frame ``B``: origin at the sensor's measuring point ``O``, the
  sensor's axes; world frame ``W``: inertial, z up, gravity ``g`` in ``W``;
- attitude ``q = (qw, qx, qy, qz)``, unit, scalar first, rotating ``B``
  vectors into ``W`` (``v_W = R(q) v_B``);
- wrench ``w = [tau_O, f]``, torque first as the planar ``[M, f_x, f_y]``:
  the wrench the mount applies to the payload, in ``B``, the torque about
  ``O``;
- payload: mass ``m``, centre of mass ``com`` (``C`` in ``B``), inertia
  ``I_c`` about ``C`` in ``B`` axes (:class:`SpatialPayload`).

With ``omega``, ``alpha`` the angular velocity and acceleration in ``B`` and
``a_g = R^T (p_ddot - g)`` the origin's acceleration less gravity in ``B``,
the wrench a motion needs is (inverse dynamics, :func:`sensor_wrench`)::

    f     = m (a_g + alpha x com + omega x (omega x com))
    tau_O = I_c alpha + omega x (I_c omega) + com x f

and the motion a wrench makes (forward dynamics, :func:`body_acceleration`)
solves the same two lines for ``alpha`` and ``p_ddot``. Both are written
once, with the operations of :mod:`fmscal.plant.numerics._backend`, so the same lines
give numbers and casadi expressions, as eq. (1) does for the planar case.

The motion state is ``x = [p (3, W, m), q (4), v = p_dot (3, W, m/s),
omega (3, B, rad/s)]``: 13 numbers for 12 degrees of freedom (``nq = 7``
configuration numbers, ``nv = 6`` velocities). :func:`rk4_step` advances it
by one step with the classical Runge-Kutta scheme and renormalises ``q``.
"""

from dataclasses import dataclass

import casadi as ca
import numpy as np

from fmscal.plant.numerics import FmscalError, LogError, as_finite_array, as_positive_scalar, is_symbolic, ops

__all__ = ["regressor", "INERTIA_NAMES",
    "SpatialPayload", "PayloadSymbols", "GRAVITY",
    "sign_continuous", "quaternion_multiply", "quaternion_conjugate", "rotation_matrix", "rotation_matrices",
    "unit_quaternions",
    "QUATERNION_TOLERANCE",
    "sensor_wrench", "body_acceleration", "state_derivative", "rk4_step", "prescribed_motion", "skew",
    "NQ", "NV", "NX",
]

#: Gravity in the world frame (z up), m/s^2.
GRAVITY = (0.0, 0.0, -9.81)
#: Configuration size: the position (3) and the unit quaternion (4).
NQ = 7
#: Velocity size: the velocity of the sensor point (3, world) and the angular velocity (3, sensor axes).
NV = 6
#: Motion state size, ``NQ + NV``.
NX = NQ + NV
#: Largest departure of a logged quaternion's norm from 1 that is taken for rounding (and normalised).
QUATERNION_TOLERANCE = 1e-3


def inertia_matrix(entries):
    """The symmetric tensor from ``Ixx Iyy Izz Ixy Ixz Iyz`` (the tensor's own entries)."""
    ixx, iyy, izz, ixy, ixz, iyz = entries
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


@dataclass(frozen=True)
class SpatialPayload:
    """Mass properties of a rigid payload on a 6-axis sensor.

    Parameters
    ----------
    mass : float
        Mass ``m`` in kg, positive.
    inertia : array_like, shape (6,) or (3, 3)
        Inertia tensor about ``C`` in ``B`` axes, kg m^2: either the six
        entries ``Ixx Iyy Izz Ixy Ixz Iyz`` (the tensor's own entries, as
        URDF's ``inertia`` and MuJoCo's ``fullinertia`` write them, not the
        negated products of inertia) or the symmetric 3x3 matrix. It must be
        positive definite and its principal moments must satisfy the
        triangle inequality (``I_1 + I_2 >= I_3``), as every real body does.
    com : array_like, shape (3,)
        Centre of mass ``C`` seen from the sensor: its position in the
        sensor frame ``B``, in m. (The planar :class:`~fmscal.plant.Payload`'s
        ``rho`` is the opposite vector, the sensor seen from the centre of
        mass, as the paper writes it.)

    Attributes
    ----------
    I_c : ndarray, shape (3, 3)
        The inertia tensor about ``C``.

    Examples
    --------
    >>> p = SpatialPayload(1.2, [2e-3, 2e-3, 1e-3, 0, 0, 0], [0.0, 0.01, 0.05])
    >>> p.I_c.shape
    (3, 3)
    >>> p.com
    (0.0, 0.01, 0.05)
    """

    mass: float
    inertia: tuple
    com: tuple

    def __post_init__(self):
        object.__setattr__(self, "mass", as_positive_scalar(self.mass, "mass"))
        com = as_finite_array(self.com, (3,), "com")
        object.__setattr__(self, "com", tuple(float(r) for r in com))
        inertia = np.array(self.inertia, dtype=float) if np.size(self.inertia) in (6, 9) else None
        if inertia is None or inertia.shape not in ((6,), (3, 3)):
            shape = "x".join(str(s) for s in np.shape(self.inertia)) or "scalar"
            raise FmscalError(f"inertia has the wrong shape; expected 6 entries "
                              f"(Ixx Iyy Izz Ixy Ixz Iyz) or 3x3 instead of {shape}")
        I_c = inertia_matrix(inertia) if inertia.shape == (6,) else inertia
        if not np.all(np.isfinite(I_c)):
            raise FmscalError(f"inertia must be finite; got {inertia.tolist()}")
        if not np.allclose(I_c, I_c.T, rtol=0, atol=1e-12 * max(1.0, np.abs(I_c).max())):
            raise FmscalError("inertia must be a symmetric tensor; got an asymmetric 3x3 matrix")
        principal = np.linalg.eigvalsh(I_c)
        if principal[0] <= 0:
            raise FmscalError(f"inertia must be positive definite; its principal moments are "
                              f"{', '.join(f'{p:.3g}' for p in principal)} kg m^2")
        if principal[0] + principal[1] < principal[2] * (1 - 1e-9):
            raise FmscalError(f"inertia breaks the triangle inequality (I1 + I2 >= I3) no body can: "
                              f"principal moments {', '.join(f'{p:.3g}' for p in principal)} kg m^2")
        entries = (I_c[0, 0], I_c[1, 1], I_c[2, 2], I_c[0, 1], I_c[0, 2], I_c[1, 2])
        object.__setattr__(self, "inertia", tuple(float(e) for e in entries))

    @classmethod
    def check(cls, payload, who):
        """``payload`` if it is a :class:`SpatialPayload`, else a one-line :class:`FmscalError` naming ``who``."""
        if not isinstance(payload, cls):
            raise FmscalError(f"{who} takes a SpatialPayload; got {type(payload).__name__}")
        return payload

    @property
    def I_c(self):
        """The inertia tensor about the centre of mass, ``B`` axes, shape (3, 3)."""
        return inertia_matrix(self.inertia)

    @property
    def I_c_inv(self):
        """``I_c^-1``, shape (3, 3): what the forward dynamics (:func:`body_acceleration`) divides by."""
        return np.linalg.inv(self.I_c)

    def as_vector(self):
        """The mass properties as the numbers a compiled step takes at run time (:class:`PayloadSymbols`).

        Returns
        -------
        ndarray, shape (22,)
            ``m`` (kg), ``com`` (3, m), ``I_c`` (9, row by row, kg m^2) and ``I_c^-1`` (9, row by row).
        """
        return np.r_[self.mass, self.com, self.I_c.ravel(), self.I_c_inv.ravel()]

    @property
    def I_O(self):
        """The inertia tensor about the sensor point: ``I_c - m [com]x^2`` (parallel axes), shape (3, 3)."""
        r = skew(self.com)
        return self.I_c - self.mass * r @ r

    @property
    def inertial_parameters(self):
        """``pi = (m, m com, I_O)``: the ten parameters the wrench is linear in, ``I_O`` as its six entries."""
        I_O = self.I_O
        return np.r_[self.mass, self.mass * np.asarray(self.com),
                     I_O[0, 0], I_O[1, 1], I_O[2, 2], I_O[0, 1], I_O[0, 2], I_O[1, 2]]

    @classmethod
    def from_inertial_parameters(cls, pi):
        """The payload of ``pi = (m, h, I_O)`` (:attr:`inertial_parameters`): ``com = h / m``,
        ``I_c = I_O + m [com]x^2``. Two bodies held together are the payload of their parameters' sum."""
        pi = as_finite_array(pi, (10,), "pi")
        com = pi[1:4] / pi[0] if pi[0] > 0 else pi[1:4]
        r = skew(com)
        return cls(float(pi[0]), inertia_matrix(pi[4:]) + pi[0] * r @ r, com)

    def to_dict(self):
        """Return ``{"mass", "inertia", "com"}`` (inertia as the six entries) for JSON files."""
        return {"mass": self.mass, "inertia": list(self.inertia), "com": list(self.com)}

    @classmethod
    def from_dict(cls, data):
        """Build from a mapping with keys ``mass``, ``inertia``, ``com`` (or ``rho``, the name files written
        before took for the centre of mass)."""
        return cls(data["mass"], data["inertia"], data["rho"] if "rho" in data and "com" not in data else data["com"])

    def isclose(self, other, rtol=1e-9):
        """Return True if ``other`` has the same mass properties."""
        return bool(np.isclose(self.mass, other.mass, rtol=rtol)
                    and np.allclose(self.com, other.com, rtol=rtol, atol=1e-12)
                    and np.allclose(self.inertia, other.inertia, rtol=rtol, atol=1e-15))


def skew(v):
    """``[v]x``, the cross-product matrix (``[v]x u = v x u``), for one vector or every row of many.

    Parameters
    ----------
    v : array_like, shape (3,) or (N, 3)

    Returns
    -------
    ndarray, shape (3, 3) or (N, 3, 3)
    """
    v = np.asarray(v, dtype=float)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    zero = np.zeros_like(x)
    return np.stack([np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1), np.stack([-y, x, zero], -1)], -2)


def _cross(a, b, o):
    """``a x b`` for 3-vectors of numbers or casadi symbols."""
    return o.vcat([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _mv(M, v, o):
    """Matrix times vector; a numeric matrix is lifted for casadi."""
    if isinstance(M, ca.SX):
        return o.dot(M, v)
    return o.dot(ca.DM(M), v) if is_symbolic(v) else np.asarray(M) @ v


def _vector(values, o):
    """A constant vector in the backend of ``o`` (a casadi expression as it is)."""
    if isinstance(values, ca.SX):
        return values
    return o.vcat([float(v) for v in values])


class PayloadSymbols:
    """A payload's mass properties as casadi expressions, read from a vector (:meth:`SpatialPayload.as_vector`).

    The dynamics written on it (:func:`body_acceleration`, :func:`sensor_wrench`) take the payload at run
    time: a step built on it is compiled once for every payload, where a :class:`SpatialPayload`'s numbers
    would be constants of the generated C, built again for each payload.

    Parameters
    ----------
    values : casadi.SX, shape (22,)
        In the order of :meth:`SpatialPayload.as_vector`.

    Attributes
    ----------
    mass : casadi.SX
    com : casadi.SX, shape (3,)
    I_c, I_c_inv : casadi.SX, shape (3, 3)
    """

    size = 22

    def __init__(self, values):
        if not isinstance(values, ca.SX) or values.numel() != self.size:
            got = f"a casadi.SX of {values.numel()} entries" if isinstance(values, ca.SX) else type(values).__name__
            raise ValueError(f"PayloadSymbols takes a casadi.SX of {self.size} entries; got {got}")
        self.mass = values[0]
        self.com = values[1:4]
        self.I_c = ca.reshape(values[4:13], 3, 3).T               # casadi reshapes column by column
        self.I_c_inv = ca.reshape(values[13:22], 3, 3).T


def _com(payload):
    """The centre of mass ``com``: numbers as an array, or a :class:`PayloadSymbols`' expression."""
    return payload.com if isinstance(payload.com, ca.SX) else np.array(payload.com)


def unit_quaternions(q, name, rows=None, hint=""):
    """Quaternions within :data:`QUATERNION_TOLERANCE` of unit norm, normalised; else a one-line :class:`LogError`.

    Parameters
    ----------
    q : ndarray, shape (N, 4)
    name : str
        The data's name, for the message.
    rows : ndarray of int, shape (N,), optional
        Each quaternion's row (from 0) in the data; default ``0 .. N-1``.
    hint : str
        Appended to the message inside its parenthesis.

    Returns
    -------
    ndarray, shape (N, 4)
    """
    norm = np.linalg.norm(q, axis=1)
    off = np.abs(norm - 1) > QUATERNION_TOLERANCE
    if off.any():
        k = int(np.argmax(off))
        row = (k if rows is None else int(rows[k])) + 1
        raise LogError(f"{name}: the quaternion qw,qx,qy,qz at row {row} has norm {norm[k]:.6g}; "
                       f"expected a unit quaternion (norm 1 within {QUATERNION_TOLERANCE:g}{hint})")
    return q / norm[:, None]


def sign_continuous(q, previous=None):
    """Rows of quaternions made sign-continuous: each turned into its predecessor's hemisphere.

    ``q`` and ``-q`` are one attitude; a recorded sequence may give either (an IMU, a tracker). Smoothed,
    differenced or interpolated component by component, two rows of opposite signs would pass near zero, not
    through the turn between them: each row whose dot product with the previous row is negative is negated
    (and so are the rows after it, with it). Rows with a NaN are kept as they are and skipped.

    Parameters
    ----------
    q : array_like, shape (N, 4)
    previous : array_like, shape (4,), optional
        The quaternion before the first row (a stream's last one); None: the first row is kept.

    Returns
    -------
    ndarray, shape (N, 4)
        A copy.
    """
    q = np.array(q, dtype=float).reshape(-1, 4)
    if len(q) == 1 and previous is not None:                         # a stream's newest: one product
        return -q if float(q[0] @ previous) < 0 else q
    rows = np.flatnonzero(np.isfinite(q).all(axis=1))
    if not len(rows):
        return q
    before = q[rows[:-1]] if previous is None else np.vstack([np.asarray(previous, dtype=float)[None], q[rows[:-1]]])
    after = q[rows[1:]] if previous is None else q[rows]
    flips = np.einsum("ij,ij->i", after, before) < 0
    sign = np.cumprod(np.where(flips, -1.0, 1.0))
    q[rows[1:] if previous is None else rows] *= sign[:, None]
    return q


def quaternion_multiply(p, q):
    """Hamilton product ``p (x) q`` of quaternions, scalar first.

    Parameters
    ----------
    p, q : array_like or casadi.SX, shape (4,), or ndarray, shape (4, N)
        One quaternion each, or (numbers only) one per column.

    Returns
    -------
    ndarray or casadi.SX, shape (4,) or (4, N)
    """
    pw, px, py, pz = p[0], p[1], p[2], p[3]
    qw, qx, qy, qz = q[0], q[1], q[2], q[3]
    stack = ops(p, q).vcat if is_symbolic(p, q) else np.stack
    return stack([
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    ])


def quaternion_conjugate(q):
    """The conjugate ``q* = (qw, -qx, -qy, -qz)``: the inverse rotation of a unit ``q``."""
    o = ops(q)
    return o.vcat([q[0], -q[1], -q[2], -q[3]])


def rotation_matrix(q):
    """Rotation matrix ``R(q)`` taking ``B`` vectors into ``W``, for a unit ``q`` (scalar first).

    Parameters
    ----------
    q : array_like or casadi.SX, shape (4,)

    Returns
    -------
    ndarray or casadi.SX, shape (3, 3)
    """
    o = ops(q)
    w, x, y, z = q[0], q[1], q[2], q[3]
    return o.matrix([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def rotation_matrices(quaternions, normalise=False):
    """:func:`rotation_matrix` of each row of quaternions, at once (numbers only).

    Parameters
    ----------
    quaternions : array_like, shape (N, 4) or (4,)
        Scalar first; unit quaternions, or any non-zero ones with ``normalise``.
    normalise : bool
        Divide each row by its norm first.

    Returns
    -------
    ndarray, shape (N, 3, 3)
    """
    q = np.asarray(quaternions, dtype=float).reshape(-1, 4)
    if normalise:
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
    return np.moveaxis(np.asarray(rotation_matrix(q.T), dtype=float), -1, 0).reshape(-1, 3, 3)


def sensor_wrench(q, omega, alpha, p_ddot, payload, gravity=GRAVITY):
    """Inverse dynamics: the wrench ``w = [tau_O, f]`` a motion needs, in ``B``.

    Newton-Euler at the sensor point, in sensor axes::

        a_g   = R^T (p_ddot - g)
        f     = m (a_g + alpha x com + omega x (omega x com))
        tau_O = I_c alpha + omega x (I_c omega) + com x f

    Parameters
    ----------
    q : array_like or casadi.SX, shape (4,)
        Attitude, unit quaternion, scalar first, ``B`` to ``W``.
    omega, alpha : array_like or casadi.SX, shape (3,)
        Angular velocity (rad/s) and acceleration (rad/s^2) in ``B``.
    p_ddot : array_like or casadi.SX, shape (3,)
        Acceleration of the origin ``O`` in ``W``, m/s^2.
    payload : SpatialPayload or PayloadSymbols
    gravity : array_like or casadi.SX, shape (3,)
        Gravity in ``W``, m/s^2.

    Returns
    -------
    ndarray or casadi.SX, shape (6,)
        ``[tau_x, tau_y, tau_z, f_x, f_y, f_z]`` in N m and N, torque about ``O``.
    """
    o = ops(q, omega, alpha, p_ddot)
    if not is_symbolic(q, omega, alpha, p_ddot):
        q, omega, alpha, p_ddot = (np.asarray(v, dtype=float) for v in (q, omega, alpha, p_ddot))
    com = _com(payload)
    a_g = o.dot(rotation_matrix(q).T, p_ddot - _vector(gravity, o))
    f = payload.mass * (a_g + _cross(alpha, com, o) + _cross(omega, _cross(omega, com, o), o))
    tau_O = _mv(payload.I_c, alpha, o) + _cross(omega, _mv(payload.I_c, omega, o), o) + _cross(com, f, o)
    return o.vcat([tau_O, f])


def body_acceleration(q, omega, w, payload, gravity=GRAVITY):
    """Forward dynamics: the accelerations a wrench ``w = [tau_O, f]`` makes.

    The two lines of :func:`sensor_wrench` solved for the motion. The torque
    about the centre of mass ``tau_C = tau_O - com x f`` turns the body::

        alpha  = I_c^-1 (tau_C - omega x (I_c omega))
        a_g    = f / m - alpha x com - omega x (omega x com)
        p_ddot = R a_g + g

    Parameters
    ----------
    q : array_like or casadi.SX, shape (4,)
        Attitude, unit quaternion, scalar first.
    omega : array_like or casadi.SX, shape (3,)
        Angular velocity in ``B``, rad/s.
    w : array_like or casadi.SX, shape (6,)
        True wrench ``[tau_O, f]`` in ``B``, N m and N.
    payload : SpatialPayload or PayloadSymbols
    gravity : array_like or casadi.SX, shape (3,)

    Returns
    -------
    alpha : ndarray or casadi.SX, shape (3,)
        Angular acceleration in ``B``, rad/s^2.
    p_ddot : ndarray or casadi.SX, shape (3,)
        Acceleration of ``O`` in ``W``, m/s^2.
    """
    o = ops(q, omega, w)
    if not is_symbolic(q, omega, w):
        q, omega, w = (np.asarray(v, dtype=float) for v in (q, omega, w))
    com = _com(payload)
    tau_O, f = w[0:3], w[3:6]
    tau_C = tau_O - _cross(com, f, o)
    alpha = _mv(payload.I_c_inv, tau_C - _cross(omega, _mv(payload.I_c, omega, o), o), o)
    a_g = f / payload.mass - _cross(alpha, com, o) - _cross(omega, _cross(omega, com, o), o)
    return alpha, o.dot(rotation_matrix(q), a_g) + _vector(gravity, o)


def state_derivative(x, w, payload, gravity=GRAVITY):
    """Time derivative of the motion state ``x = [p, q, v, omega]`` under the wrench ``w``.

    ``p_dot = v``, ``q_dot = 1/2 q (x) (0, omega)``, and ``v_dot``,
    ``omega_dot`` from :func:`body_acceleration`.

    Parameters
    ----------
    x : array_like or casadi.SX, shape (13,)
    w : array_like or casadi.SX, shape (6,)
    payload : SpatialPayload or PayloadSymbols
    gravity : array_like or casadi.SX, shape (3,)

    Returns
    -------
    ndarray or casadi.SX, shape (13,)
    """
    o = ops(x, w)
    if not is_symbolic(x, w):
        x, w = np.asarray(x, dtype=float), np.asarray(w, dtype=float)
    q, v, omega = x[3:7], x[7:10], x[10:13]
    alpha, p_ddot = body_acceleration(q, omega, w, payload, gravity)
    q_dot = 0.5 * quaternion_multiply(q, o.vcat([0.0, omega]))
    return o.vcat([v, q_dot, p_ddot, alpha])


def rk4_step(x, w, dt, payload, gravity=GRAVITY):
    """One classical Runge-Kutta step of :func:`state_derivative`, the wrench held over the step.

    The quaternion is renormalised after the step (RK4 leaves it off the unit
    sphere by O(dt^5)).

    Parameters
    ----------
    x : array_like or casadi.SX, shape (13,)
    w : array_like or casadi.SX, shape (6,)
        Wrench held constant over the step (zero-order hold), ``B``.
    dt : float
        Step in s, positive.
    payload : SpatialPayload or PayloadSymbols
    gravity : array_like or casadi.SX, shape (3,)

    Returns
    -------
    ndarray or casadi.SX, shape (13,)
    """
    o = ops(x, w)
    if not is_symbolic(x, w):
        x = np.asarray(x, dtype=float)
    k1 = state_derivative(x, w, payload, gravity)
    k2 = state_derivative(x + 0.5 * dt * k1, w, payload, gravity)
    k3 = state_derivative(x + 0.5 * dt * k2, w, payload, gravity)
    k4 = state_derivative(x + dt * k3, w, payload, gravity)
    x_next = x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    q = x_next[3:7]
    norm = o.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return o.vcat([x_next[0:3], q / norm, x_next[7:13]])


def prescribed_motion(t, position, attitude, payload, gravity=GRAVITY):
    """The state and the wrench it needs, for a motion given as functions of time.

    A robot arm or a motion-capture rig imposes the payload's motion; the
    sensor then reads the wrench that motion needs. Given the position of
    ``O`` and the attitude as casadi expressions of the time symbol ``t``,
    the velocities and accelerations are differentiated exactly (casadi's
    algorithmic differentiation), with ``omega = 2 vec(q* (x) q_dot)`` and
    ``alpha = 2 vec(q* (x) q_ddot)``, and the wrench follows from
    :func:`sensor_wrench`.

    Parameters
    ----------
    t : casadi.SX
        The time symbol, s.
    position : casadi.SX, shape (3,)
        Position of ``O`` in ``W`` as an expression of ``t``, m.
    attitude : casadi.SX, shape (4,)
        Unit quaternion (scalar first) as an expression of ``t``.
    payload : SpatialPayload
    gravity : array_like, shape (3,)

    Returns
    -------
    casadi.Function
        ``t -> (x, w)``: the state ``[p, q, v, omega]`` (13) and the wrench
        ``[tau_O, f]`` (6). ``Function.map(N)`` evaluates a whole log at once.
    """
    if not is_symbolic(t, position, attitude):
        raise FmscalError("prescribed_motion takes casadi expressions of a time symbol")
    q_dot = ca.jacobian(attitude, t)
    q_ddot = ca.jacobian(q_dot, t)
    v = ca.jacobian(position, t)
    p_ddot = ca.jacobian(v, t)
    q_conj = quaternion_conjugate(attitude)
    omega = 2 * quaternion_multiply(q_conj, q_dot)[1:]
    alpha = 2 * quaternion_multiply(q_conj, q_ddot)[1:]
    w = sensor_wrench(attitude, omega, alpha, p_ddot, payload, gravity)
    return ca.Function("prescribed_motion", [t], [ca.vertcat(position, attitude, v, omega), w], ["t"], ["x", "w"])


#: The order of the inertia's six entries in the regressor's columns and in printed payloads.
INERTIA_NAMES = ("Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz")


def _inertia_map(v):
    """``L(v)`` with ``I v = L(v) [Ixx, Iyy, Izz, Ixy, Ixz, Iyz]`` for every row of ``v``: (N, 3, 6)."""
    z = np.zeros(len(v))
    x, y, w = v[:, 0], v[:, 1], v[:, 2]
    return np.stack([np.stack([x, z, z, y, w, z], 1), np.stack([z, y, z, x, z, w], 1),
                     np.stack([z, z, w, z, x, y], 1)], 1)


def regressor(q, omega, alpha, p_ddot, gravity=GRAVITY, mounting=None):
    """The Newton-Euler regressor ``W`` with ``[tau_O; f] = W pi``, for every sample.

    Newton-Euler at the sensor point, in sensor axes, with ``a_g = R^T (p_ddot - g)``::

        tau_O = h x a_g + I_O alpha + omega x (I_O omega)
        f     = m a_g + alpha x h + omega x (omega x h)

    Parameters
    ----------
    q : ndarray, shape (N, 4)
        Attitudes of the tracked frame, unit quaternions, scalar first.
    omega, alpha : ndarray, shape (N, 3)
        Angular velocity and acceleration in the tracked frame's axes, rad/s and rad/s^2.
    p_ddot : ndarray, shape (N, 3)
        Acceleration of the sensor point in the pose frame, m/s^2.
    gravity : array_like, shape (3,)
        m/s^2, pose frame.
    mounting : ndarray, shape (3, 3), optional
        The sensor's axes on the tracked frame (sensor vectors to tracked-frame
        vectors, ``M``): the sensor's attitude is ``R M``, its rates
        ``M^T omega`` and ``M^T alpha``. Default the identity.

    Returns
    -------
    ndarray, shape (N, 6, 10)
        Columns ``m, h (3), I_O (6, :data:`INERTIA_NAMES` order)``.
    """
    R = np.moveaxis(rotation_matrix(q.T), -1, 0)                         # (N, 3, 3), one per sample
    if mounting is not None:                                             # the sensor's axes: R M, M^T omega
        R, omega, alpha = R @ mounting, omega @ mounting, alpha @ mounting
    a_g = np.einsum("nji,nj->ni", R, p_ddot - np.asarray(gravity, dtype=float))
    A, Om = skew(alpha), skew(omega)
    W = np.zeros((len(q), 6, 10))
    W[:, :3, 1:4] = -skew(a_g)                                          # h x a_g
    W[:, :3, 4:] = _inertia_map(alpha) + Om @ _inertia_map(omega)       # I_O alpha + omega x (I_O omega)
    W[:, 3:, 0] = a_g                                                   # m a_g
    W[:, 3:, 1:4] = A + Om @ Om                                         # alpha x h + omega x (omega x h)
    return W
