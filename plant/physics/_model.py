"""The problem's shape in one object: sizes, layouts, columns, measurement, dynamics.

A calibration problem is a rigid payload on a force-moment sensor whose raw
reading ``w_hat`` (``n_w`` components) gives the true wrench through
``w = S w_hat + c`` (``S`` n_w x n_w; ``c = -S b`` with ``b`` the sensor's
offset), while a tracker measures the payload's pose. A :class:`Model` says
what the problem is, as pinocchio's ``Model`` says what a robot is:

- the sizes: the wrench ``n_w``, the configuration ``nq`` and velocity
  ``nv`` (they differ when the configuration holds a unit quaternion), the
  motion state ``nx = nq + nv``, the parameters ``[S | c]``;
- named layouts of the motion state and of the pose, and the log's columns;
- the measurement map (the pose a state shows) and the state at rest at a
  measured pose;
- ``integrate`` and ``difference`` on the configuration (an angle and a
  position in the plane; a position and a unit quaternion in space);
- the dynamics, affine in the wrench: ``a = A(x) w + d(x)`` for the
  accelerations ``a`` (``nv``), and from it the regressor of ``[S | c]``.
  They are written once per case (:mod:`fmscal.plant.physics._dynamics`, eq. (1);
  :mod:`fmscal.plant.physics._rigid_body`, Newton-Euler) for numbers and casadi
  symbols alike.

Two models estimate ``S``: :class:`PlanarModel` (the paper's problem: ``[M, f_x, f_y]``,
pose ``theta, X, Y``) and :class:`SpatialModel` (a 6-axis sensor: ``[tau,
f]``, pose ``q, p``, under gravity). A third takes ``S`` as known and
estimates the payload: :class:`PayloadModel` (the everyday job of a wrist
sensor calibrated by its maker, eq. (P0)). :func:`find_model` is the one
place a model is looked up by what it declares: a log's columns, a
reading's size, a payload's class or its position vector's name, and what it
estimates.
"""

import copy

import casadi as ca
import numpy as np

from fmscal.plant.numerics import FmscalError, StateLayout, as_finite_array, is_symbolic, ops
from . import _dynamics as dynamics, _rigid_body as rigid_body, _simulate as simulate
from ._payload import Payload
from ._rigid_body import SpatialPayload
from ._sensor import NoiseSpec, check_calibration

__all__ = ["Model", "PlanarModel", "SpatialModel", "PayloadModel", "MODELS", "as_model", "model_for_columns",
           "find_model"]


class Model:
    """What every case shares; a case sets the class attributes and the dynamics.

    Attributes
    ----------
    name : str
        ``"planar"`` or ``"spatial"``.
    wrench_names, pose_names : tuple of str
        The reading's and the pose's columns in a log, in order.
    nq, nv : int
        Configuration and velocity sizes.
    state : StateLayout
        The motion state ``x`` (``nx = nq + nv`` entries) by name.
    payload
        The payload's mass properties.
    """

    name = ""
    wrench_names = ()
    pose_names = ()
    #: The pose's angle and position columns, for the noise model (:meth:`pose_sd`); a
    #: quaternion's columns are neither (the spatial model says how its noise spreads).
    angle_names = ()
    position_names = ()
    nq = nv = 0
    state = None
    #: True where the configuration moves additively, the pose is the configuration, the
    #: accelerations have no drift and ``A`` depends on the configuration only: the model is
    #: then linear in the state and in ``[S | c]`` once the configuration in ``A`` is taken from
    #: the measured poses, which the floor (:mod:`fmscal.observers.batch._max_likelihood`), least
    #: squares and the EKF's filter pieces need.
    linear_channels = False
    #: How the configuration holds the attitude: ``None`` (none: positions only), ``"angle"`` (one angle,
    #: moving additively) or ``"quaternion"`` (a unit quaternion, moved by a rotation vector). With
    #: :attr:`linear_channels` it says which engine runs a method on the model
    #: (:data:`fmscal.observers._registry.ENGINES`): no method tests the model's name or class.
    attitude = None
    #: True where the model is the paper's planar problem, eq. (1) with the parameters ``phi_1``, ``phi_2``
    #: of eqs. (4), (5) (:mod:`fmscal.plant.physics._dynamics`), which the methods written on the printed
    #: equations (the paper's observer, the high-gain observer of [4], ``LeastSquares.offset_bias``) and the
    #: scale the poses imply (:func:`fmscal.plant.io.implied_scale`) read directly.
    paper_equations = False
    #: How a figure shows :meth:`pose_residuals`: one ``(name, unit, columns)`` per panel, the unit
    #: ``"mrad"`` for a turn (rad) and ``"mm"`` for a move (m), each column of the residual shown times 1e3.
    residual_panels = ()

    # --- what a calibration of a log of this model takes and checks (fmscal.analysis.calibrate) -----
    #: The payload's class: what the model is built on, ``cls(payload)`` (and ``cls(payload, gravity)``
    #: where :attr:`under_gravity`).
    payload_type = None
    #: The payload's position vector: its field's name, and the command line's flag (``--rho``, ``--com``):
    #: ``"rho"`` the planar payload's (the paper's: the sensor seen from the centre of mass), ``"com"`` the
    #: spatial one's (the centre of mass seen from the sensor, the opposite vector).
    payload_position = None
    #: The numbers that vector and the inertia take, by name (:meth:`payload_from`'s ``position`` and
    #: ``inertia``, a command line's ``--rho`` or ``--com``, and ``--inertia``).
    payload_position_names = inertia_names = ()
    #: The model takes the gravity in the pose frame (``cls(payload, gravity)``, attribute ``gravity``).
    under_gravity = False
    #: The reading's sign is a convention the caller states (``"reaction"`` or ``"load"``,
    #: :func:`fmscal.plant.io.reading_sign`); False: the toolkit's own sign, never turned.
    signed_reading = False
    #: A calibration may leave the sensor's offset out (``offset=False``); False: it is always estimated.
    optional_offset = False
    #: A calibration takes a noise model given by the caller (the pose's and the reading's standard
    #: deviations, :class:`NoiseSpec`), and estimates what is not given; False: the method estimates it.
    given_noise = False
    #: The reading's force channels (indices into :attr:`wrench_names`): a negative trace of ``S`` on them
    #: is a reading in the other sign convention.
    force_channels = ()
    #: Blocks of the reading with one unit each, ``(name, channels)``: E of eq. (16) is reported on each
    #: too (``I - S_hat S^-1`` restricted to the block's rows and columns); none where E is reported whole.
    reading_blocks = ()
    #: The checks a calibration of a log of this model makes after the run, in the order their warnings
    #: are reported (``"run"``: the method's own warnings); :func:`fmscal.analysis.calibrate` documents
    #: each. ``converged`` is the run's flag and every check passed.
    calibration_checks = ()
    #: The checks of the log's units and conventions a calibration makes BEFORE the fit (a fit of a log in
    #: the wrong units can run for minutes), each refusing in one line that names the unit;
    #: :func:`fmscal.analysis.calibrate` documents each.
    input_checks = ()
    #: What the problem estimates from a log: ``"S"`` and ``"offset"`` (a calibration's ``[S | c]``, the
    #: methods of :mod:`fmscal.observers` run on it), or the payload's ``"mass"``, ``"com"``, ``"inertia"``,
    #: the ``"offset"`` and the ``"force gains"`` with ``S`` known (:class:`PayloadModel`: no method of the
    #: registry runs on it). :func:`find_model` looks a model up by it.
    estimates = ("S", "offset")

    def __init__(self, payload):
        self.payload = payload

    @classmethod
    def payload_from(cls, mass, inertia, position):
        """The payload of ``mass`` (kg), ``inertia`` (kg m^2) and ``position`` (m, the vector
        :attr:`payload_position` names), in the order of :attr:`inertia_names` and
        :attr:`payload_position_names`; the payload class checks them (one-line :class:`FmscalError`
        naming ``mass``, ``inertia``, ``rho`` or ``com``)."""
        raise NotImplementedError

    def __repr__(self):
        return f"{type(self).__name__}({self.payload!r})"

    def _key(self):
        """What makes two models the same problem (compiled steps are cached by it)."""
        return type(self), self.payload

    def __eq__(self, other):
        return isinstance(other, Model) and self._key() == other._key()

    def __hash__(self):
        return hash(self._key())

    # --- the payload at run time ------------------------------------------------------------------
    #: Numbers :meth:`payload_vector` gives (0: the payload is compiled into each step as constants).
    payload_size = 0

    def payload_vector(self):
        """The payload's mass properties (and the gravity) as the numbers a compiled step takes at run time.

        Returns
        -------
        ndarray, shape (payload_size,)
            Empty where the model's steps take the payload as constants.
        """
        return np.empty(0)

    def compiled_key(self):
        """What a compiled step written on this model depends on (its cache key): the model itself, less what
        :meth:`payload_vector` carries where the step reads that at run time."""
        return self._key()

    def payload_parts(self):
        """The part :meth:`payload_vector` takes in a compiled step's parameters (a
        :class:`~fmscal.plant.numerics.StateLayout` part): ``[("payload", payload_size)]``, or none at size 0."""
        return [("payload", self.payload_size)] if self.payload_size else []

    def payload_values(self):
        """:meth:`payload_vector` by that part's name, for ``StateLayout.pack``: ``{"payload": ...}``, or none."""
        return {"payload": self.payload_vector()} if self.payload_size else {}

    def with_payload_symbols(self, values):
        """The model with its payload (and gravity) read from the casadi expression ``values``.

        A step built on it takes :meth:`payload_vector` as an input, and one build serves every payload.

        Parameters
        ----------
        values : casadi.SX, shape (payload_size,), or None where ``payload_size`` is 0

        Returns
        -------
        Model
            This model itself where ``payload_size`` is 0.
        """
        return self

    # --- the payload's numbers, as its uncertainty is stated (fmscal.plant.physics.PayloadStd) ----------
    @classmethod
    def payload_parameter_names(cls):
        """The numbers a payload's uncertainty is stated on, in order: ``"mass"`` (kg), the position vector's
        (:attr:`payload_position_names`, m), the inertia's (:attr:`inertia_names`, kg m^2) and, for a model
        :attr:`under_gravity`, ``"gravity"`` (its size, m/s^2).

        Returns
        -------
        tuple of str
        """
        return ("mass", *cls.payload_position_names, *cls.inertia_names) + (("gravity",) if cls.under_gravity else ())

    def payload_parameters(self):
        """The values of :meth:`payload_parameter_names` for this model, shape (k,)."""
        p = self.payload
        gravity = [float(np.linalg.norm(self.gravity))] if self.under_gravity else []
        return np.array([p.mass, *getattr(p, self.payload_position), *np.atleast_1d(p.inertia), *gravity], dtype=float)

    def with_payload_parameters(self, values):
        """This model with the payload (and gravity's size, its direction kept) at ``values``.

        Parameters
        ----------
        values : array_like, shape (k,)
            In the order of :meth:`payload_parameter_names`.

        Returns
        -------
        Model
            A copy; the payload class checks the values (one-line :class:`FmscalError`).
        """
        values = np.asarray(values, dtype=float)
        k_pos, k_in = len(self.payload_position_names), len(self.inertia_names)
        model = copy.copy(self)
        model.payload = self.payload_from(values[0], values[1 + k_pos:1 + k_pos + k_in], values[1:1 + k_pos])
        if self.under_gravity:
            g = np.asarray(self.gravity, dtype=float)
            model.gravity = tuple(float(v) for v in g * (values[-1] / np.linalg.norm(g)))
        return model

    def inertia_scale(self):
        """The scale each inertia entry's relative uncertainty is of (:class:`fmscal.plant.physics.PayloadStd`),
        kg m^2, shape (len(inertia_names),): by default each entry's own size."""
        return np.abs(np.atleast_1d(np.asarray(self.payload.inertia, dtype=float)))

    # --- sizes ------------------------------------------------------------------------------------
    @property
    def n_w(self):
        """Components of the wrench and of the reading."""
        return len(self.wrench_names)

    @property
    def n_pose(self):
        """Numbers in one pose measurement (its columns in a log)."""
        return len(self.pose_names)

    @property
    def nx(self):
        """Size of the motion state."""
        return self.nq + self.nv

    @property
    def columns(self):
        """The log's header: ``t``, the pose, the reading."""
        return ("t", *self.pose_names, *self.wrench_names)

    def n_params(self, offset=False):
        """Entries of ``[S | c]``: ``n_w^2``, plus ``n_w`` with the offset column."""
        return self.n_w * (self.n_w + int(bool(offset)))

    def params(self, offset=False):
        """The layout of ``vec([S | c])``, row by row (the order every method packs ``S`` in).

        Returns
        -------
        StateLayout
            One part a row of ``[S | c]``: ``row0``, ``row1``, ... each of
            ``n_w`` entries, or ``n_w + 1`` with the offset column.
        """
        width = self.n_w + int(bool(offset))
        return StateLayout(*((f"row{i}", width) for i in range(self.n_w)))

    @property
    def input_layout(self):
        """One sample as a recursive method's step reads it: ``[has_pose, pose, w_hat]``.

        Pose entries are zero where the sample has none (``has_pose`` 0).
        """
        return StateLayout(("has_pose", 1), ("pose", self.n_pose), ("w_hat", self.n_w))

    def pose_sd(self, noise):
        """Each pose column's noise standard deviation, shape (n_pose,).

        Parameters
        ----------
        noise : NoiseSpec
            ``angle_sd`` for the angle columns, ``position_sd`` for the
            position columns.
        """
        sd = {**{k: noise.angle_sd for k in self.angle_names}, **{k: noise.position_sd for k in self.position_names}}
        return np.array([sd[k] for k in self.pose_names])

    def check_noise(self, noise, name="noise"):
        """``noise`` as this model's :class:`NoiseSpec` (``n_w`` reading entries), or a one-line error.

        Raises
        ------
        TypeError
            ``noise`` is not a :class:`NoiseSpec`.
        FmscalError
            It holds another number of reading components.
        """
        if not isinstance(noise, NoiseSpec):
            raise TypeError(f"{name} must be a plant.NoiseSpec or None; got {type(noise).__name__}")
        if len(noise.wrench_sd) != self.n_w:
            raise FmscalError(f"{name}.wrench_sd has the wrong shape; expected {self.n_w} ({self.name}: "
                              f"{', '.join(self.wrench_names)}) instead of {len(noise.wrench_sd)}")
        return noise

    def check_log(self, log, who="this method"):
        """``log`` if it is a log of this model's case, else a one-line :class:`FmscalError`.

        Parameters
        ----------
        log : Log
        who : str
            Who asks, for the message.
        """
        if getattr(log, "kind", None) != self.name:
            raise FmscalError(f"{log.name}: {who} is set up for {self.name} logs "
                              f"({','.join(self.columns)}); got a {getattr(log, 'kind', '?')} log "
                              f"({','.join(getattr(log, 'columns', ()))})")
        return log

    # --- the state's parts ---------------------------------------------------------------------------
    #: Indices of the configuration and of the velocity in the motion state.
    q_index = v_index = ()

    def configuration(self, x):
        """The configuration part of the state, ``nq`` entries."""
        return ops(x).vcat([x[k] for k in self.q_index])

    def velocity(self, x):
        """The velocity part of the state, ``nv`` entries."""
        return ops(x).vcat([x[k] for k in self.v_index])

    def state_from(self, q, v):
        """The motion state with configuration ``q`` (``nq``) and velocity ``v`` (``nv``), numbers or symbols."""
        where = {**{k: q[i] for i, k in enumerate(self.q_index)}, **{k: v[i] for i, k in enumerate(self.v_index)}}
        return ops(q, v).vcat([where[k] for k in range(self.nx)])

    def state_integrate(self, x, dx):
        """The state ``x`` moved by an error state ``dx = [dq, dnu]`` (``2 nv``): ``x (+) dx``.

        The configuration by :meth:`integrate`, the velocity additively;
        numbers or casadi symbols.

        Parameters
        ----------
        x : ndarray or casadi.SX, shape (nx,)
        dx : ndarray or casadi.SX, shape (2 nv,)

        Returns
        -------
        ndarray or casadi.SX, shape (nx,)
        """
        o = ops(x, dx)
        dq = o.vcat([dx[i] for i in range(self.nv)])
        dnu = o.vcat([dx[self.nv + i] for i in range(self.nv)])
        return self.state_from(self.integrate(self.configuration(x), dq), self.velocity(x) + dnu)

    def state_difference(self, x0, x1):
        """The error state taking ``x0`` to ``x1``: ``x1 (-) x0 = [difference(q0, q1), nu1 - nu0]``, shape (2 nv,).

        The inverse of :meth:`state_integrate`; numbers or casadi symbols.
        """
        o = ops(x0, x1)
        return o.vcat([self.difference(self.configuration(x0), self.configuration(x1)),
                       self.velocity(x1) - self.velocity(x0)])

    @classmethod
    def interpolate_pose(cls, times, pose_times, poses):
        """The measured pose stream at ``times``, interpolated between its measurements.

        Each pose column linearly, ``p(t) = (1 - u) p_i + u p_{i+1}`` with
        ``u = (t - t_i) / (t_{i+1} - t_i)``: positions, and an angle (a log's
        ``theta`` is unwrapped on reading, so that the line between two
        measurements is the shorter turn). A model whose attitude lives on
        another manifold overrides it (:class:`SpatialModel`: SLERP). Used to
        shift a pose stream by a fraction of a sample
        (:meth:`fmscal.plant.Log.shift_poses`).

        Parameters
        ----------
        times : ndarray, shape (M,)
            s, each within ``[pose_times[0], pose_times[-1]]``.
        pose_times : ndarray, shape (P,)
            The measurements' times, s, increasing.
        poses : ndarray, shape (P, n_pose)
            The measured poses, log columns.

        Returns
        -------
        ndarray, shape (M, n_pose)
        """
        return np.column_stack([np.interp(times, pose_times, poses[:, j]) for j in range(poses.shape[1])])

    def pose_configuration(self, pose):
        """The configuration (``nq``) a measured pose (log columns, ``n_pose``) shows; numbers or symbols.

        The inverse of :meth:`measure` on the configuration. Default: the
        pose is the configuration.
        """
        return ops(pose).vcat([pose[i] for i in range(self.nq)])

    def pose_residuals(self, states, poses):
        """The measured poses less the poses the states show, in the configuration's tangent space.

        Row ``k`` is ``difference(configuration(x_k), pose_configuration(pose_k))`` (:meth:`difference`):
        what moves the state's configuration onto the measured one.

        Parameters
        ----------
        states : ndarray, shape (M, nx)
        poses : ndarray, shape (M, n_pose)
            Measured poses in the log's columns.

        Returns
        -------
        ndarray, shape (M, nv)
        """
        rows = [np.asarray(self.difference(self.configuration(np.asarray(x, dtype=float)),
                                           self.pose_configuration(np.asarray(p, dtype=float))), dtype=float).ravel()
                for x, p in zip(states, poses)]
        return np.array(rows).reshape(len(rows), self.nv)

    def channel(self, k):
        """The velocity channel (``0 .. nv-1``) state entry ``k`` belongs to, for a model with
        :attr:`linear_channels` (entry ``q_index[c]`` or ``v_index[c]`` is channel ``c``)."""
        return self.q_index.index(k) if k in self.q_index else self.v_index.index(k)

    def rk4_step(self, x, w0, w_mid, w1, dt):
        """One classical RK4 step of :meth:`state_derivative`, the wrench at the step's start, middle and end.

        Parameters
        ----------
        x : ndarray or casadi.SX, shape (nx,)
        w0, w_mid, w1 : ndarray or casadi.SX, shape (n_w,)
            The true wrench at ``t``, ``t + dt/2`` and ``t + dt``.
        dt : float or casadi.SX
            The step, s.

        Returns
        -------
        ndarray or casadi.SX, shape (nx,)
        """
        k1 = self.state_derivative(x, w0)
        k2 = self.state_derivative(x + dt / 2 * k1, w_mid)
        k3 = self.state_derivative(x + dt / 2 * k2, w_mid)
        k4 = self.state_derivative(x + dt * k3, w1)
        return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    # --- the channels' parameters (linear-channel models) -------------------------------------------
    def parameter_groups(self):
        """The velocity channels that share a set of linear parameters ``phi``.

        Least squares fits each group alone (they share no unknown), and the
        adaptive observer (:class:`fmscal.observers.AdaptiveObserver`) runs
        one recursive fit per group. The default is one group, all channels,
        in the parameters ``s = vec([S | c])`` themselves.

        Returns
        -------
        list of list of int
            Each group's channels (``0 .. nv-1``), every channel in one group.
        """
        return [list(range(self.nv))]

    def channel_regressor_rows(self, q, w_aug):
        """Each channel's regressor in its group's parameters at one sample: ``a_c = psi_c . phi``.

        Written for numbers and casadi symbols alike, so that a recursive
        method's compiled step reads its regressors from the model.

        Parameters
        ----------
        q : ndarray or casadi.SX, shape (nq,)
            The configuration (for a model with :attr:`linear_channels`, the
            measured pose).
        w_aug : ndarray or casadi.SX, shape (n,)
            The reading, ``n = n_w``, or ``n_w + 1`` with a trailing constant
            1 for the offset column.

        Returns
        -------
        list of list
            One list per velocity channel (``nv``), of its group's parameter
            count (``len(phi)``), entries numbers or casadi expressions. By
            default ``phi = s`` and ``psi_c`` is row ``c`` of :meth:`regressor`
            at rest at ``q``.
        """
        o = ops(q, w_aug)
        x = self.state_from(q, o.vcat([0.0] * self.nv))
        U = self.regressor(x, w_aug)
        m = U.shape[1]
        return [[U[c, j] for j in range(m)] for c in range(self.nv)]

    def channel_regressors(self, q, w_aug):
        """Each channel's regressor over a whole log (numpy): :meth:`channel_regressor_rows` per sample.

        Parameters
        ----------
        q : ndarray, shape (nq, N)
            The configuration at each sample (from the measured poses).
        w_aug : ndarray, shape (n, N)
            The reading, with a trailing row of ones for the offset column.

        Returns
        -------
        list of ndarray, each shape (N, len(phi) of its group)
            One per velocity channel.
        """
        rows = [self.channel_regressor_rows(q[:, k], w_aug[:, k]) for k in range(q.shape[1])]
        return [np.array([r[c] for r in rows], dtype=float) for c in range(self.nv)]

    def phi_from_params(self, s, n):
        """Each group's parameters from ``vec([S | c])`` (row order); linear, inverse of :meth:`params_from_phi`.

        Parameters
        ----------
        s : ndarray or casadi.SX, shape (n_w n,)
            The flat ``[S | c]``, numbers or symbols.
        n : int
            Columns of ``[S | c]``: ``n_w``, or ``n_w + 1`` with the offset.

        Returns
        -------
        list of ndarray or casadi.SX
            One vector per :meth:`parameter_groups` group. Default: ``[s]``.
        """
        return [s]

    def params_from_phi(self, phis, n):
        """``[S | c]`` from each group's parameters; linear. Default: ``phi = s``.

        Parameters
        ----------
        phis : list of ndarray or casadi.SX
            One vector per :meth:`parameter_groups` group.
        n : int
            Columns of ``[S | c]``.

        Returns
        -------
        ndarray, shape (n_w, n), or casadi.SX, shape (n_w n,)
            Numbers as a matrix; symbols as a flat vector in row order.
        """
        if is_symbolic(*phis):
            return ops(*phis).vcat(phis)
        return np.asarray(phis[0], dtype=float).reshape(self.n_w, n)

    def reading_scale(self, log):
        """The scale of each reading component in ``log``, in which a method's settling and evidence
        are judged (``S`` as ``D^-1 S D``); None: ``S`` as it is (the planar default).

        Parameters
        ----------
        log : plant.Log

        Returns
        -------
        ndarray, shape (n_w,), or None
        """
        return None

    # --- checks -----------------------------------------------------------------------------------
    def check_matrix(self, S, name="S"):
        """``S`` as a finite ``n_w x n_w`` float array, or a one-line :class:`FmscalError`."""
        return as_finite_array(S, (self.n_w, self.n_w), name)

    def check_pose(self, pose, name="pose"):
        """One pose as ``n_pose`` finite numbers, or a one-line :class:`FmscalError`."""
        return as_finite_array(pose, (self.n_pose,), name)

    # --- the dynamics, affine in the wrench --------------------------------------------------------
    def acceleration(self, x, w):
        """Accelerations ``a`` (``nv``) the wrench ``w`` makes in state ``x``: ``A(x) w + d(x)``."""
        o = ops(x, w)
        A, d = self.input_matrix(x), self.drift(x)
        return o.dot(A, w) + d

    def regressor(self, x, w_hat):
        """The regressor ``U`` of ``s = vec([S | c])`` (row order): ``a = U s + d(x)``.

        Since ``S w_hat = (I (x) w_hat^T) s``, ``U = A(x) (I_nw (x) w_hat^T)``.

        Parameters
        ----------
        x : ndarray or casadi.SX, shape (nx,)
        w_hat : ndarray or casadi.SX, shape (n_w,) or (n_w + 1,)
            The reading; with a trailing constant 1 the offset column ``c``
            is in ``s`` too.

        Returns
        -------
        ndarray or casadi.SX, shape (nv, n_w * len(w_hat))
        """
        A = self.input_matrix(x)
        m = w_hat.shape[0] if hasattr(w_hat, "shape") else len(w_hat)
        if is_symbolic(x, w_hat):
            return ca.horzcat(*[A[:, i] * w_hat[j] for i in range(self.n_w) for j in range(m)])
        w_hat = np.asarray(w_hat, dtype=float)
        return np.hstack([np.outer(A[:, i], w_hat) for i in range(self.n_w)])


class PlanarModel(Model):
    """The paper's planar problem: reading ``[M, f_x, f_y]``, pose ``theta, X, Y`` (eq. 1).

    The motion state is ``[theta, theta', X, X', Y, Y']`` (the toolkit's
    order since the first release); the configuration is ``[theta, X, Y]``
    and it moves additively.

    Parameters
    ----------
    payload : Payload

    Examples
    --------
    >>> from fmscal.plant import PAPER_PAYLOAD
    >>> model = PlanarModel(PAPER_PAYLOAD)
    >>> model.n_w, model.nq, model.nv, model.columns
    (3, 3, 3, ('t', 'theta', 'x', 'y', 'M', 'fx', 'fy'))
    """

    name = "planar"
    wrench_names = ("M", "fx", "fy")
    pose_names = ("theta", "x", "y")
    angle_names, position_names = ("theta",), ("x", "y")
    linear_channels = True
    attitude = "angle"
    paper_equations = True
    residual_panels = (("theta", "mrad", (0,)), ("X", "mm", (1,)), ("Y", "mm", (2,)))
    payload_type = Payload
    payload_position, payload_position_names, inertia_names = "rho", ("RX", "RY"), ("I_G",)
    optional_offset = True
    given_noise = True
    force_channels = (1, 2)
    calibration_checks = ("units", "reference", "run", "evidence", "consistency", "saturation", "offset_drift",
                          "disagreement", "latency")
    nq = nv = 3
    state = StateLayout(("theta", 1), ("theta_dot", 1), ("X", 1), ("X_dot", 1), ("Y", 1), ("Y_dot", 1))
    q_index, v_index = (0, 2, 4), (1, 3, 5)

    def __init__(self, payload):
        if not isinstance(payload, Payload):
            raise FmscalError(f"PlanarModel takes a plant.Payload; got {type(payload).__name__}")
        super().__init__(payload)

    @classmethod
    def payload_from(cls, mass, inertia, position):
        """The :class:`Payload` of ``mass`` (kg), ``inertia`` ``(I_G,)`` (kg m^2) and ``position``, its ``rho``
        ``(RX, RY)`` (m, the sensor from the centre of mass)."""
        return Payload(mass, inertia[0], tuple(position))

    def measure(self, x):
        """The pose ``[theta, X, Y]`` the state shows (the measurement map, ``C_1``, ``C_2`` of eqs. 4, 5)."""
        return self.configuration(x)

    def rest_state(self, pose):
        """The state at rest at a measured pose: ``[theta, 0, X, 0, Y, 0]``."""
        theta, X, Y = self.check_pose(pose)
        return np.array([theta, 0.0, X, 0.0, Y, 0.0])

    def integrate(self, q, dq):
        """The configuration ``q`` moved by ``dq`` (additive in the plane)."""
        return q + dq

    def difference(self, q0, q1):
        """The move ``dq`` taking ``q0`` to ``q1``: ``q1 - q0``."""
        return q1 - q0

    def pose_residuals(self, states, poses):
        """:meth:`Model.pose_residuals` in one product: ``pose - [theta, X, Y]`` of each state, shape (M, 3)."""
        return np.asarray(poses, dtype=float) - np.asarray(states, dtype=float)[:, list(self.q_index)]

    def input_matrix(self, x):
        """``A(x) = G(theta)`` of eq. (1), shape (3, 3): ``[theta'', X'', Y''] = G w``."""
        return dynamics.input_matrix(x[0], self.payload)

    def drift(self, x):
        """``d(x) = 0``: in the plane the accelerations are linear in the wrench."""
        return ops(x).vcat([0.0, 0.0, 0.0])

    def state_derivative(self, x, w):
        """``x'`` under eq. (1) (:func:`fmscal.plant.state_derivative`)."""
        return dynamics.state_derivative(x, w, self.payload)

    def rk4_step(self, x, w0, w_mid, w1, dt):
        """RK4 on eq. (1): :func:`fmscal.plant.rk4_step` (the simulator's own step)."""
        return simulate.rk4_step(x, w0, w_mid, w1, dt, self.payload)

    def parameter_groups(self):
        """``phi_1`` drives ``theta`` alone, ``phi_2`` drives ``X`` and ``Y`` (eqs. 4, 5): two groups."""
        return [[0], [1, 2]]

    def channel_regressor_rows(self, q, w_aug):
        """``psi_theta``, ``psi_X``, ``psi_Y`` of eqs. (4), (5) (:func:`fmscal.plant.regressors`).

        ``q`` may also hold one angle per sample (``q[0]`` of shape (N,),
        ``w_aug`` (n, N)): the entries are then arrays of shape (N,).
        """
        return list(dynamics.regressors(q[0], w_aug, self.payload))

    def channel_regressors(self, q, w_aug):
        """``psi_theta``, ``psi_X``, ``psi_Y`` of eqs. (4), (5) over a whole log, in one call."""
        return [np.array(v).T for v in self.channel_regressor_rows(q, w_aug)]

    def phi_from_params(self, s, n):
        """``phi_1``, ``phi_2`` of eqs. (4), (5) (:func:`fmscal.plant.phi_1`, ``phi_2``)."""
        return [dynamics.phi_1(s, self.payload), dynamics.phi_2(s)]

    def params_from_phi(self, phis, n):
        """``[S | c]`` from ``phi_1``, ``phi_2`` (eqs. 4, 5 inverted, :func:`fmscal.plant.S_from_phi`)."""
        return dynamics.S_from_phi(phis[0], phis[1], self.payload)


class SpatialModel(Model):
    """A 6-axis sensor on a payload moving in 3D under gravity (Newton-Euler).

    Reading ``[tx, ty, tz, fx, fy, fz]`` (torque about the sensor point first,
    sensor axes); pose ``[qw, qx, qy, qz, x, y, z]`` of the sensor frame in
    the world (unit quaternion, scalar first; position in m). The motion
    state is ``[p, q, v, omega]`` (:mod:`fmscal.plant.physics._rigid_body`):
    ``nq = 7``, ``nv = 6``, velocities ``[v (world), omega (sensor axes)]``.

    Parameters
    ----------
    payload : SpatialPayload
    gravity : array_like, shape (3,)
        Gravity in the world frame, m/s^2.
    """

    name = "spatial"
    wrench_names = ("tx", "ty", "tz", "fx", "fy", "fz")
    pose_names = ("qw", "qx", "qy", "qz", "x", "y", "z")
    position_names = ("x", "y", "z")
    attitude = "quaternion"
    residual_panels = (("x, y, z", "mm", (0, 1, 2)), ("about the sensor axes", "mrad", (3, 4, 5)))
    payload_type = SpatialPayload
    payload_position, payload_position_names = "com", ("X", "Y", "Z")
    inertia_names = ("IXX", "IYY", "IZZ", "IXY", "IXZ", "IYZ")
    under_gravity = True
    signed_reading = True
    force_channels = (3, 4, 5)
    reading_blocks = (("torque", (0, 1, 2)), ("force", (3, 4, 5)))
    calibration_checks = ("saturation", "causes", "run", "evidence", "flipped_gain", "latency", "misfit",
                          "gains")
    input_checks = ("spatial_units",)
    nq, nv = rigid_body.NQ, rigid_body.NV
    state = StateLayout(("p", 3), ("q", 4), ("v", 3), ("omega", 3))
    q_index, v_index = tuple(range(7)), tuple(range(7, 13))

    def __init__(self, payload, gravity=rigid_body.GRAVITY):
        if not isinstance(payload, SpatialPayload):
            raise FmscalError(f"SpatialModel takes a plant.SpatialPayload; got {type(payload).__name__}")
        super().__init__(payload)
        self.gravity = tuple(float(g) for g in as_finite_array(gravity, (3,), "gravity"))

    @classmethod
    def payload_from(cls, mass, inertia, position):
        """The :class:`SpatialPayload` of ``mass`` (kg), ``inertia`` ``(IXX, IYY, IZZ, IXY, IXZ, IYZ)`` (kg m^2,
        about the centre of mass, sensor axes) and ``position``, its ``com`` ``(X, Y, Z)`` (m, sensor frame)."""
        return SpatialPayload(mass, tuple(inertia), tuple(position))

    def _key(self):
        return type(self), self.payload, self.gravity

    def compiled_key(self):
        """:meth:`Model.compiled_key`: the key without the payload and the gravity (a compiled step reads them)."""
        key = self._key()
        return (key[0], *key[3:])

    #: The payload's 22 numbers (:meth:`SpatialPayload.as_vector`), the two 3x6 blocks of ``A`` the payload
    #: alone makes (:meth:`input_matrix`) and the gravity's 3.
    payload_size = rigid_body.PayloadSymbols.size + 36 + 3

    def payload_vector(self):
        """The payload and the gravity as a compiled step takes them.

        Returns
        -------
        ndarray, shape (61,)
            ``m`` (kg), ``com`` (m), ``I_c`` and ``I_c^-1`` row by row (:meth:`SpatialPayload.as_vector`),
            the two 3x6 blocks of ``A`` the payload alone makes, row by row (:meth:`input_matrix`), and the
            gravity (m/s^2, world frame).
        """
        top, bottom = self._input_blocks()
        return np.r_[self.payload.as_vector(), top.ravel(), bottom.ravel(), self.gravity]

    def with_payload_symbols(self, values):
        """This model with the payload and the gravity read from ``values``.

        The dynamics on it are casadi expressions of them (:class:`rigid_body.PayloadSymbols`), with the
        numbers' own operations: ``A``'s blocks are read from the vector, as the numbers' path computes
        them once. The model is for writing a step, not for a cache key (casadi symbols do not hash).

        Parameters
        ----------
        values : casadi.SX, shape (61,)
            In :meth:`payload_vector`'s order.

        Returns
        -------
        SpatialModel
        """
        k = rigid_body.PayloadSymbols.size
        model = copy.copy(self)                        # every attribute of this model; the payload's replaced
        model.payload = rigid_body.PayloadSymbols(values[0:k])
        model._blocks = (ca.reshape(values[k:k + 18], 6, 3).T, ca.reshape(values[k + 18:k + 36], 6, 3).T)
        model.gravity = values[k + 36:self.payload_size]
        return model

    def inertia_scale(self):
        """Each inertia entry's scale, ``Ixx Iyy Izz`` and ``sqrt(Ixx Iyy)``, ``sqrt(Ixx Izz)``, ``sqrt(Iyy Izz)``
        for the products (kg m^2, shape (6,)): a product of inertia may be zero, its uncertainty is not."""
        ixx, iyy, izz = self.payload.inertia[:3]
        return np.sqrt([ixx * ixx, iyy * iyy, izz * izz, ixx * iyy, ixx * izz, iyy * izz])

    def reading_scale(self, log):
        """Each reading component's spread in ``log`` (N m, N), shape (6,).

        Torque and force differ by two orders of magnitude: in SI units a
        2-norm of ``S`` is the force-from-torque entries' alone. Settling and
        evidence are judged on ``D^-1 S D``, ``D`` these spreads.
        """
        spread = np.std(log.w_hat, axis=0)
        return np.maximum(spread, 1e-12 * max(float(spread.max()), 1e-300))

    def pose_sd(self, noise):
        """Each pose column's noise: a turn of ``angle_sd`` about each axis moves each quaternion
        component by about ``angle_sd / 2``; ``position_sd`` on ``x, y, z``. Shape (7,)."""
        return np.r_[np.full(4, noise.angle_sd / 2), np.full(3, noise.position_sd)]

    def measure(self, x):
        """The pose ``[q, p]`` (log order) the state shows."""
        o = ops(x)
        return o.vcat([x[3:7], x[0:3]])

    @classmethod
    def interpolate_pose(cls, times, pose_times, poses):
        """The measured pose stream at ``times``: the position linearly, the attitude by SLERP.

        Between measurements ``i`` and ``i + 1`` (``u`` as in
        :meth:`Model.interpolate_pose`), the unit quaternion turns at a
        constant rate about one axis: ``q(u) = (sin((1 - u) W) q_i + sin(u W)
        q_{i+1}) / sin W``, ``cos W = q_i . q_{i+1}`` (the sign of ``q_{i+1}``
        taken so that the dot product is not negative: the shorter turn); for
        ``W`` below 1e-9 rad, the normalised linear blend.
        """
        poses = np.asarray(poses, dtype=float)
        out = np.empty((len(times), poses.shape[1]))
        out[:, 4:] = Model.interpolate_pose(times, pose_times, poses[:, 4:])
        i = np.clip(np.searchsorted(pose_times, times, side="right") - 1, 0, max(len(pose_times) - 2, 0))
        j = np.minimum(i + 1, len(pose_times) - 1)
        span = pose_times[j] - pose_times[i]
        u = np.where(span > 0, (times - pose_times[i]) / np.where(span > 0, span, 1.0), 0.0)[:, None]
        q0, q1 = poses[i, :4], poses[j, :4]
        dot = np.sum(q0 * q1, axis=1, keepdims=True)
        q1 = np.where(dot < 0, -q1, q1)
        turn = np.arccos(np.clip(np.abs(dot), -1.0, 1.0))
        small = turn < 1e-9
        sin = np.where(small, 1.0, np.sin(turn))
        a = np.where(small, 1 - u, np.sin((1 - u) * turn) / sin)
        b = np.where(small, u, np.sin(u * turn) / sin)
        q = a * q0 + b * q1
        out[:, :4] = q / np.linalg.norm(q, axis=1, keepdims=True)
        return out

    def pose_configuration(self, pose):
        """The configuration ``[p, q]`` of a measured pose ``[q, p]`` (log order); numbers or symbols."""
        o = ops(pose)
        return o.vcat([pose[4:7], pose[0:4]])

    def check_pose(self, pose, name="pose"):
        """One pose as 7 finite numbers whose quaternion is of unit norm (within
        :data:`fmscal.plant.physics.QUATERNION_TOLERANCE`), or a one-line :class:`FmscalError`.

        The pose is returned as it is: :meth:`difference` reads a quaternion's
        direction only, and :meth:`rest_state` normalises it.
        """
        pose = super().check_pose(pose, name)
        rigid_body.unit_quaternions(pose[None, :4], name)
        return pose

    def rest_state(self, pose):
        """The state at rest at a measured pose ``[q, p]``: ``[p, q, 0, 0]``."""
        pose = self.check_pose(pose)
        q = pose[:4] / np.linalg.norm(pose[:4])
        return np.r_[pose[4:], q, np.zeros(6)]

    def integrate(self, q, dq):
        """The configuration ``[p, q]`` moved by ``dq = [dp (world), dphi (sensor axes)]``.

        ``p + dp`` and ``q (x) exp(dphi / 2)``: the rotation vector ``dphi``
        turns the body about its own axes, as ``omega dt`` does. Numbers or
        casadi symbols; differentiable at ``dphi = 0`` (the small-angle series
        there reads no square root).
        """
        o = ops(q, dq)
        dphi = dq[3:6]
        angle2 = dphi[0] * dphi[0] + dphi[1] * dphi[1] + dphi[2] * dphi[2]
        angle = o.sqrt(o.fmax(angle2, 1e-300))
        half = 0.5 * angle
        # sin(angle/2)/angle, its series below 1e-8 rad (exact to rounding there)
        k = o.if_else(angle > 1e-8, o.sin(half) / angle, 0.5 - angle2 / 48.0)
        step = o.vcat([o.cos(half), k * dphi[0], k * dphi[1], k * dphi[2]])
        return o.vcat([q[0:3] + dq[0:3], rigid_body.quaternion_multiply(q[3:7], step)])

    def difference(self, q0, q1):
        """The move ``dq = [dp, dphi]`` taking ``q0`` to ``q1`` (inverse of :meth:`integrate`).

        ``dphi = 2 log(q0* (x) q1)``, taken on the short way round (``q`` and
        ``-q`` are one attitude). Numbers or casadi symbols.
        """
        o = ops(q0, q1)
        if not is_symbolic(q0, q1):
            q0, q1 = np.asarray(q0, dtype=float), np.asarray(q1, dtype=float)
        rel = rigid_body.quaternion_multiply(rigid_body.quaternion_conjugate(q0[3:7]), q1[3:7])
        sign = o.if_else(rel[0] < 0, -1.0, 1.0)
        w = sign * rel[0]
        s2 = rel[1] * rel[1] + rel[2] * rel[2] + rel[3] * rel[3]
        s = o.sqrt(o.fmax(s2, 1e-300))
        # 2 atan2(s, w) / s, its series 2/w (1 - s^2 / (3 w^2)) where s is tiny
        k = sign * o.if_else(s > 1e-8, 2.0 * o.atan2(s, w) / s, 2.0 / w * (1.0 - s2 / (3.0 * w * w)))
        return o.vcat([q1[0:3] - q0[0:3], k * rel[1], k * rel[2], k * rel[3]])

    def input_matrix(self, x):
        """``A(x)``, shape (6, 6): ``[p_ddot; alpha] = A(x) [tau_O; f] + d(x)``.

        From :func:`fmscal.plant.physics.body_acceleration`, with
        ``K = I_c^-1``::

            alpha  = K tau_O - K [com]x f + alpha_0
            p_ddot = R ([com]x K tau_O + (I/m - [com]x K [com]x) f) + ...
        """
        R = rigid_body.rotation_matrix(x[3:7])
        if isinstance(self.payload, rigid_body.PayloadSymbols):              # read at run time
            top, bottom = self._blocks
            return ca.vertcat(ca.mtimes(R, top), bottom)
        top, bottom = self._input_blocks()
        if is_symbolic(x):
            return ca.vertcat(ca.mtimes(R, ca.DM(top)), ca.DM(bottom))
        return np.vstack([R @ top, bottom])

    def _input_blocks(self):
        """The blocks of :meth:`input_matrix` the payload alone makes, ``K = I_c^-1``:
        ``[[com]x K, I/m - [com]x K [com]x]`` and ``[K, -K [com]x]``, each shape (3, 6)."""
        K = self.payload.I_c_inv
        r = rigid_body.skew(self.payload.com)
        top = np.hstack([r @ K, np.eye(3) / self.payload.mass - r @ K @ r])
        bottom = np.hstack([K, -K @ r])
        return top, bottom

    def drift(self, x):
        """``d(x)``: gravity and the gyroscopic and centripetal terms, shape (6,)."""
        o = ops(x)
        zero = o.vcat([0.0] * 6)
        alpha_0, p_ddot_0 = rigid_body.body_acceleration(x[3:7], x[10:13], zero, self.payload, self.gravity)
        return o.vcat([p_ddot_0, alpha_0])

    def state_derivative(self, x, w):
        """``x'`` under Newton-Euler (:func:`fmscal.plant.physics._rigid_body.state_derivative`)."""
        return rigid_body.state_derivative(x, w, self.payload, self.gravity)

    # --- the momenta about the centre of mass (what a law linear in [S | c] reads in 3D) ------------------
    # About the centre of mass C (p_C = p + R com) the two momenta are driven linearly by the wrench, in the
    # world frame (what the adaptive observer's law in 3D reads, fmscal.observers.AdaptiveObserver):
    #     d/dt (m v_C) = R f + m g,    d/dt H = R tau_C,    tau_C = tau_O - com x f,    H = R I_c omega     (M)
    # Each method below is written once for numbers and casadi symbols; com is taken as numbers.
    def momentum_groups(self):
        """The momenta's channels that share a parameter set: ``H`` (0-2, driven by ``phi_t``) and ``m v_C``
        (3-5, driven by ``phi_f``), as :meth:`Model.parameter_groups` for linear channels.

        Returns
        -------
        list of two lists of int
        """
        return [[0, 1, 2], [3, 4, 5]]

    @staticmethod
    def momentum_phi_from_params(s, n, com):
        """The two groups' parameters from ``vec([S | c])`` (row order): ``[phi_t, phi_f]`` of eq. (M).

        ``phi_f = vec(S_f)`` (rows 3-5 of ``[S | c]``), ``phi_t = vec(S_t - [com]x S_f)`` (the rows of the
        torque about ``C``, ``tau_C = tau_O - com x f``), row order; linear, inverse of
        :meth:`momentum_params_from_phi`.

        Parameters
        ----------
        s : ndarray or casadi.SX, shape (6 n,)
        n : int
            Columns of ``[S | c]``: 6, or 7 with the offset.
        com : array_like, shape (3,)
            The centre of mass in the sensor frame, m (numbers).

        Returns
        -------
        list of two ndarray or casadi.SX, each shape (3 n,)
        """
        o = ops(s)
        S = _as_rows(o, s, 6, n)
        S_t, S_f = S[0:3, :], S[3:6, :]
        return [_flat(o, S_t - o.dot(_constant(o, rigid_body.skew(com)), S_f)), _flat(o, S_f)]

    @staticmethod
    def momentum_params_from_phi(phis, n, com):
        """``vec([S | c])`` (row order) from ``[phi_t, phi_f]``: ``S_t = T + [com]x S_f``, eq. (M) inverted
        (:meth:`momentum_phi_from_params`).

        Returns
        -------
        ndarray or casadi.SX, shape (6 n,)
        """
        o = ops(*phis)
        T, S_f = _as_rows(o, phis[0], 3, n), _as_rows(o, phis[1], 3, n)
        return o.vcat([_flat(o, T + o.dot(_constant(o, rigid_body.skew(com)), S_f)), _flat(o, S_f)])

    def momentum_regressor(self, R, w_aug):
        """``Psi = R (x) w^T`` (3 x 3 n): the drive of either momentum of eq. (M), ``Psi phi`` = ``R (Phi w)``
        for the 3 x n block ``Phi`` whose rows ``phi`` holds; entry ``(i, j n + l)`` is ``R_ij w_l``.

        Parameters
        ----------
        R : ndarray or casadi.SX, shape (3, 3)
            The attitude, ``B`` to ``W``.
        w_aug : ndarray or casadi.SX, shape (n,)
            The reading, with a trailing 1 for the offset column.

        Returns
        -------
        ndarray or casadi.SX, shape (3, 3 n)
        """
        n = w_aug.shape[0]
        return ops(R, w_aug).matrix([[R[i, j] * w_aug[v] for j in range(3) for v in range(n)] for i in range(3)])

    def momentum_drives(self, R, w_aug, phis):
        """The momenta's rates of eq. (M) at one sample: ``[R (T w), R (S_f w) + m g]``, each shape (3,).

        Parameters
        ----------
        R : ndarray or casadi.SX, shape (3, 3)
        w_aug : ndarray or casadi.SX, shape (n,)
        phis : list of two vectors of 3 n
            ``[phi_t, phi_f]`` (:meth:`momentum_phi_from_params`).
        """
        o = ops(R, w_aug, *phis)
        n = w_aug.shape[0]
        torque, force = (o.dot(R, o.dot(_as_rows(o, phi, 3, n), w_aug)) for phi in phis)
        return [torque, force + self.payload.mass * _constant(o, self.gravity)]

    def world_inverse_inertia(self, R):
        """``I_W^-1 = R I_c^-1 R^T``, shape (3, 3), symmetric: ``omega_W = I_W^-1 H`` (eq. (M)); numbers or
        symbols."""
        return _sandwich(ops(R), R, self.payload.I_c_inv)

    def world_inertia(self, R):
        """``I_W = R I_c R^T``, shape (3, 3), symmetric; numbers or symbols."""
        return _sandwich(ops(R), R, self.payload.I_c)

    def world_rate(self, R, H):
        """``omega_W = R (I_c^-1 (R^T H))``, shape (3,): the world-frame angular velocity of the angular
        momentum ``H`` about ``C`` (eq. (M)) at the attitude ``R``; numbers or symbols."""
        o = ops(R, H)
        return o.dot(R, o.dot(_constant(o, self.payload.I_c_inv), o.dot(R.T, H)))

    @staticmethod
    def turned_rotation(R, rate, h):
        """``R + h [rate]x R``: the rotation ``R`` turned at the world-frame angular velocity ``rate`` over a step
        ``h``, to first order (the exponential's first two terms); numbers or symbols."""
        o = ops(R, rate, h)
        return o.matrix([[R[i, j] + h * (rate[(i + 1) % 3] * R[(i + 2) % 3, j] - rate[(i + 2) % 3] * R[(i + 1) % 3, j])
                          for j in range(3)] for i in range(3)])

    @staticmethod
    def turn_over_step(spin0, spin1, h):
        """The rotation vector of a world-frame angular velocity linear over a step ``h`` from ``spin0`` to
        ``spin1``, to third order (Magnus): ``h (spin0 + spin1) / 2 - h^2 / 12 spin0 x spin1``; numbers or
        symbols."""
        o = ops(spin0, spin1, h)
        return h / 2 * (spin0 + spin1) - h * h / 12 * _cross(o, spin0, spin1)

    def centre_of_mass_momentum(self, pose):
        """``m p_C = m (p + R com)`` of a measured pose ``[q, p]`` (log order), shape (3,); numbers or symbols."""
        o = ops(pose)
        R = rigid_body.rotation_matrix(pose[0:4])
        return self.payload.mass * (pose[4:7] + o.dot(R, _constant(o, self.payload.com)))

    def state_from_momenta(self, y, lin, q, H):
        """The motion state ``[p, q, v, omega]`` from the motion about ``C`` (eq. (M) read back).

        ``omega = I_c^-1 R^T H``, ``p = y / m - R com``, ``v = l / m - R (omega x com)``.

        Parameters
        ----------
        y, lin : vectors of 3
            ``m p_C`` and ``m v_C``, world frame.
        q : vector of 4
            The attitude, a unit quaternion.
        H : vector of 3
            The angular momentum about ``C``, world frame.
        """
        o = ops(y, lin, q, H)
        m, com = self.payload.mass, _constant(o, self.payload.com)
        R = rigid_body.rotation_matrix(q)
        omega = o.dot(_constant(o, self.payload.I_c_inv), o.dot(R.T, H))
        return o.vcat([y / m - o.dot(R, com), q, lin / m - o.dot(R, _cross(o, omega, com)), omega])

    def turn(self, q, R, v):
        """``exp(v / 2) (x) q``: the attitude ``q`` (rotation ``R``) turned by the rotation vector ``v`` (world
        frame), as ``q`` turned by ``R^T v`` about its own axes (:meth:`integrate`); numbers or symbols."""
        o = ops(q, R, v)
        return self.integrate(o.vcat([0.0, 0.0, 0.0, q]), o.vcat([0.0, 0.0, 0.0, o.dot(R.T, v)]))[3:7]


class PayloadModel(Model):
    """The payload with ``S`` known: a 6-axis sensor calibrated by its maker (or by ``fmscal calibrate``) and a
    tool to weigh, the everyday job of a wrist sensor.

    The reading corrected by the known ``S``, ``y = sigma S w_hat`` (``sigma`` the reading's sign), is the
    payload's wrench at the sensor point plus the offset ``c = S b``, each force channel read with its own
    gain ``g_j`` relative to the force gains' mean (the sensor's gains, where ``S`` is the maker's, disagree
    by a few percent), the torque channels with one common gain ``g_tau``::

        diag(g) (y - c) = [tau_O; f] = W pi,     pi = (m, h = m com, I_O)                       (P0)
        g = (g_tau, g_tau, g_tau, 1 + e_x, 1 + e_y, 1 - e_x - e_y),   g_tau = 1 + e_tau

    ``W`` the Newton-Euler regressor (:func:`fmscal.plant.physics.regressor`), linear in ``pi`` for given
    gains. The mean force gain is one: a common scale of the three is the mass's (the payload is weighed in
    the force channels' mean units). Held poses never tell the torque gains: their common scale is the
    centre of mass's, and each is seen only through the centre of mass across its axis (for a tool whose
    centre of mass lies on its axis, the gain about that axis not at all); they are taken as one there
    (``e = (e_x, e_y)``). Motion ties the torques' common scale to the forces': ``h`` is in both, ``alpha x
    h`` in the forces and ``h x a_g`` in the torques, so a log's fit estimates ``e_tau`` too (``e = (e_x,
    e_y, e_tau)``), where the motion tells it from zero. The compensated wrench is then ``w = diag(g) S
    (sigma w_hat - b)``. The model fits no ``S`` (:attr:`estimates`): no method of the registry runs on it;
    :func:`fmscal.observers.payload.identify_payload` estimates its parameters from a log or from held
    poses.

    Parameters
    ----------
    S : array_like, shape (6, 6), optional
        The known calibration (default the identity).
    gravity : array_like, shape (3,)
        Gravity in the pose frame, m/s^2.

    Examples
    --------
    >>> model = PayloadModel()
    >>> model.n_w, model.estimates[:2], model.wrench_names == SpatialModel.wrench_names
    (6, ('mass', 'com'), True)
    >>> model.gains([0.02, -0.01])
    array([1.  , 1.  , 1.  , 1.02, 0.99, 0.99])
    >>> model.gains([0.02, -0.01, 0.005])
    array([1.005, 1.005, 1.005, 1.02 , 0.99 , 0.99 ])
    """

    name = "payload"
    wrench_names, pose_names = SpatialModel.wrench_names, SpatialModel.pose_names
    position_names = SpatialModel.position_names
    attitude = "quaternion"
    payload_type = SpatialPayload
    payload_position, payload_position_names = SpatialModel.payload_position, SpatialModel.payload_position_names
    inertia_names = SpatialModel.inertia_names
    under_gravity = True
    signed_reading = True
    force_channels = SpatialModel.force_channels
    reading_blocks = SpatialModel.reading_blocks
    input_checks = SpatialModel.input_checks
    estimates = ("mass", "com", "inertia", "offset", "force gains")
    #: The gains' free numbers, ``e_x, e_y`` (the force gains) and ``e_tau`` (the torques' common gain: motion
    #: only) of eq. (P0), by name.
    gain_names = ("gain_x", "gain_y", "gain_torque")

    def __init__(self, S=None, gravity=rigid_body.GRAVITY):
        super().__init__(None)                          # the payload is what the model estimates
        self.S = np.eye(self.n_w) if S is None else check_calibration(S, "S", size=self.n_w)
        self.gravity = tuple(float(g) for g in as_finite_array(gravity, (3,), "gravity"))

    @classmethod
    def payload_from(cls, mass, inertia, position):
        """:meth:`SpatialModel.payload_from`: the :class:`SpatialPayload` this model estimates."""
        return SpatialModel.payload_from(mass, inertia, position)

    def _key(self):
        return type(self), self.S.tobytes(), self.gravity

    def __repr__(self):
        return f"PayloadModel(S={'I' if np.array_equal(self.S, np.eye(self.n_w)) else '...'}, gravity={self.gravity})"

    def corrected(self, w_hat, sign=1.0):
        """The reading corrected by the known ``S``: ``y = sigma S w_hat`` (eq. P0), shape (N, 6).

        Parameters
        ----------
        w_hat : array_like, shape (N, 6)
        sign : float
            ``sigma``: +1 for a reaction reading (the toolkit's), -1 for a load reading.
        """
        return sign * np.asarray(w_hat, dtype=float) @ self.S.T

    def gains(self, e):
        """The six channel gains ``g`` of eq. (P0) from their free numbers ``e = (e_x, e_y)`` or ``(e_x, e_y,
        e_tau)``.

        Returns
        -------
        ndarray, shape (6,)
            Force gains ``1 + e_x, 1 + e_y, 1 - e_x - e_y`` (their mean 1); torque gains ``1 + e_tau`` (1
            without it).
        """
        e = np.asarray(e, dtype=float)
        g = np.full(self.n_w, 1.0 + (e[2] if len(e) > 2 else 0.0))
        g[list(self.force_channels)] = 1.0 + self.gain_map() @ e[:2]
        return g

    def gain_map(self):
        """``d g_force / d e``, shape (3, 2): each force gain's derivative in ``e_x, e_y`` (the last one takes
        minus their sum, so that the mean stays one)."""
        return np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, -1.0]])

    def wrench_regressor(self, q, omega, alpha, p_ddot, gravity=None, mounting=None):
        """``W`` of eq. (P0) at each sample (:func:`fmscal.plant.physics.regressor`), the model's gravity unless
        ``gravity`` is given, shape (N, 6, 10)."""
        g = self.gravity if gravity is None else gravity
        return rigid_body.regressor(q, omega, alpha, p_ddot, g, mounting)


def _cross(o, a, b):
    """``a x b`` for 3-vectors of numbers or casadi symbols."""
    return o.vcat([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _sandwich(o, R, K):
    """``R K R^T`` for a rotation ``R`` and a constant symmetric ``K``: its upper triangle, mirrored."""
    RK = o.dot(R, _constant(o, K))
    upper = {(i, j): sum(RK[i, b] * R[j, b] for b in range(3)) for i in range(3) for j in range(i, 3)}
    return o.matrix([[upper[min(i, j), max(i, j)] for j in range(3)] for i in range(3)])


def _as_rows(o, flat, rows, cols):
    """A ``rows x cols`` matrix from its entries in row order (numbers or symbols)."""
    if is_symbolic(flat):
        return o.matrix([[flat[cols * i + j] for j in range(cols)] for i in range(rows)])
    return np.asarray(flat, dtype=float).reshape(rows, cols)


def _flat(o, M):
    """A matrix's entries in row order, as a flat vector (numbers or symbols)."""
    if is_symbolic(M):
        return o.vcat([M[i, j] for i in range(M.shape[0]) for j in range(M.shape[1])])
    return np.ravel(M)


def _constant(o, value):
    """A constant (numbers, or a casadi expression as it is) in the back end of ``o``."""
    if isinstance(value, ca.SX):
        return value
    value = np.asarray(value, dtype=float)
    return ca.DM(value) if o is ops(ca.SX()) else value


#: The toolkit's models: the two that estimate ``S`` (one a case) and the one that takes it known. A model is
#: looked up among them by what it declares, in one place: :func:`find_model`.
MODELS = (PlanarModel, SpatialModel, PayloadModel)


def find_model(*, columns=None, n_w=None, n_pose=None, payload=None, position=None, estimates="S", every=False):
    """The model class that declares what is given: the one place a model is looked up.

    Every criterion given must hold; those not given are not asked. Among :data:`MODELS`, only those whose
    :attr:`Model.estimates` hold ``estimates``: ``"S"`` (the default) for what a calibration, a log's case or
    a truth is of, ``"mass"`` for the payload with ``S`` known (:class:`PayloadModel`).

    Parameters
    ----------
    columns : sequence of str, optional
        A log's header: the model whose columns (:attr:`Model.columns`) it holds (others may come too).
    n_w : int, optional
        The reading's size (a calibration's ``S`` is ``n_w x n_w``; a truth's schedule is of its size).
    n_pose : int, optional
        Numbers in one pose.
    payload : object, optional
        A payload: the model whose :attr:`Model.payload_type` it is an instance of.
    position : str, optional
        The payload's position vector by name, ``"rho"`` or ``"com"`` (:attr:`Model.payload_position`).
    estimates : str
        What the model must estimate (:attr:`Model.estimates`).
    every : bool
        Return every model that matches, not the first.

    Returns
    -------
    type or None, or tuple of type
        A :class:`Model` subclass; None where none matches (the caller words its refusal). With ``every``, a
        tuple (empty where none matches).

    Examples
    --------
    >>> find_model(n_w=6).name, find_model(position="rho").name, find_model(n_w=6, estimates="mass").name
    ('spatial', 'planar', 'payload')
    >>> find_model(n_w=4) is None
    True
    """
    header = None if columns is None else set(columns)
    found = tuple(m for m in MODELS
                  if estimates in m.estimates
                  and (header is None or {"t", *m.pose_names, *m.wrench_names} <= header)
                  and (n_w is None or len(m.wrench_names) == n_w)
                  and (n_pose is None or len(m.pose_names) == n_pose)
                  and (payload is None or isinstance(payload, m.payload_type))
                  and (position is None or m.payload_position == position))
    if every:
        return found
    return found[0] if found else None


def as_model(model, who="a method"):
    """The :class:`Model` a method is built on: a model, or a payload (the model of its case).

    Parameters
    ----------
    model : Model, Payload or SpatialPayload
        A payload stands for :class:`PlanarModel` or :class:`SpatialModel` of it.
    who : str
        Who asks, for the message.

    Returns
    -------
    Model

    Raises
    ------
    FmscalError
        ``model`` is none of these (a model-less call).
    """
    if isinstance(model, Model):
        return model
    if isinstance(model, Payload):
        return PlanarModel(model)
    if isinstance(model, SpatialPayload):
        return SpatialModel(model)
    raise FmscalError(f"{who} needs a model (plant.PlanarModel, plant.SpatialModel) or a payload "
                      f"(plant.Payload, plant.SpatialPayload); got {type(model).__name__}")


def model_for_columns(header):
    """Which case a log's header belongs to: ``"planar"`` or ``"spatial"`` (:func:`find_model`).

    Parameters
    ----------
    header : sequence of str
        The column names of a log.

    Returns
    -------
    str

    Raises
    ------
    FmscalError
        The header holds neither case's columns.
    """
    found = find_model(columns=header)
    if found is not None:
        return found.name
    expected = " or ".join(f"{','.join(('t', *m.pose_names, *m.wrench_names))} ({m.name})"
                           for m in find_model(every=True))
    raise FmscalError(f"a log's header is {expected}; got {','.join(header)[:200]}")
