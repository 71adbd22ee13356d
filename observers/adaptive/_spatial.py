"""The adaptive observer's law in 3D: the momenta about the centre of mass, each driven linearly by ``[S | c]``.

:class:`fmscal.observers.AdaptiveObserver` runs this on a
:class:`fmscal.plant.SpatialModel`; the adaptation (recursive least squares
per parameter group, the change test, the forgetting) is the planar one's,
shared. What differs is the motion the observer follows. The spatial model is
not linear in its channels (the attitude is a quaternion, Newton-Euler at the
sensor point has gyroscopic terms), but about the centre of mass ``C``
(``p_C = p + R rho``) the two momenta are driven linearly by the wrench, in
the world frame:

    d/dt (m v_C) = R f + m g                                  (linear momentum)
    d/dt H       = R tau_C,   tau_C = tau_O - rho x f          (angular momentum, H = R I_c omega)

Both right-hand sides are ``Psi(R, w_hat) phi + const``: with the reading
augmented ``w = [w_hat; 1]`` (``n`` entries) and ``Psi = R (x) w^T`` (3 x 3n,
the same for both), the force rows ``phi_f = vec(S_f)`` (``S_f`` rows 3-5 of
``[S | c]``) drive the linear momentum and the rows of the torque about ``C``,
``phi_t = vec(S_t - [rho]x S_f)`` (:func:`phi_from_params`), drive ``H``: two
parameter groups of ``3n`` each (21 with the offset), as ``phi_1``, ``phi_2``
in the plane. ``R`` is the measured attitude where a pose arrives (the
pose is the configuration, as the measured angle in the plane); between
poses it is the last measured attitude turned by the observer's own turn
since that pose (``chi - chi_pose``), so that the observer's attitude error
at the pose does not enter the drives. What is left, the observer's rate
error over the gap, is not in the filters: it shrinks with faster poles,
hence the spatial default ``lam`` of :data:`SPATIAL_LAM` (what the default
reaches against the floor: docs/observers.md, ``tests/test_spatial_adaptive.py``,
``benchmarks/online_floor_3d.py``).

The outputs are the measured positions of ``C`` (``m p_C``, three double
integrators exactly as the planar X, Y channels) and the attitude. The
attitude moves with ``omega = I_c^-1 R^T H``; propagated with the measured
``R`` in that product, its error in the world frame,
``delta = 2 log(q_meas (x) q_hat*)``, obeys to first order

    delta' = M(t) H~,   H~' = Psi phi~_t,   M = R I_c^-1 R^T   (I_W^-1, the world-frame inverse inertia)

a double integrator with a known, time-varying gain ``M``. With
``nu = M H~`` it is the planar channel: the injection ``[l_1; l_2 M^-1]``
(:func:`observers.adaptive._highgain.discrete_gain`) puts each axis's sampled poles at
``exp(-lam h)``, and the sensitivity filter carries ``M``. Per step ``h``,
with ``G_p``, ``G_v`` the position and velocity increments of ``Psi``
linear over the step (:mod:`observers.core._discretise`)::

    translational (y = m p_C, l = m v_C; per axis)     rotational (q, H)
    U_y^- = U_y + h U_l + G_p                          U_d^- = U_d + M_n (h U_H + G_p)
    U_l^- = U_l + G_v                                  U_H^- = U_H + G_v
    e_y   = m p_C,meas - y^-                           e_d   = 2 log(q_meas (x) q^-*)
    U_y  <- (1 - l_1) U_y^-,  U_l <- U_l^- - l_2 U_y^-   U_d <- (1 - l_1) U_d^-,  U_H <- U_H^- - l_2 I_W U_d^-
    y    <- y^- + l_1 e_y + U_y dphi_f                  q <- exp((l_1 e_d + U_d dphi_t) / 2) (x) q^-
    l    <- l^- + l_2 e_y + U_l dphi_f                  H <- H^- + l_2 I_W e_d + U_H dphi_t

with ``dphi`` each group's recursive least-squares step on its three rows
``U_y^-`` (errors ``e_y``) and ``U_d^-`` (errors ``e_d``). The prediction
is the motion's own: ``l`` and ``H`` with their drives linear over the step,
``q`` turned by ``h (omega_n + omega_n+1) / 2 + h^2 / 12 omega_n x omega_n+1``
(the rotation vector of a body rate linear over the step, to third order).
No pose is differentiated and nothing models the noise.
"""

import numpy as np

from fmscal.plant.physics import rotation_matrix, skew

from fmscal.observers.core import position_increment, velocity_increment
from ._highgain import discrete_gain

__all__ = ["phi_from_params", "params_from_phi", "regressor_rows", "SpatialLaw", "SPATIAL_LAM", "WARM_UP"]

#: The observer's poles on the spatial model, rad/s (``lam=None``): between poses the drives use the
#: observer's own turn, whose error shrinks with faster poles (module docstring).
SPATIAL_LAM = 20.0

#: The fit waits this many time constants ``1 / lam`` of the observer's poles from the first sample: the
#: observer starts at rest, the payload may not, and the error of that start is no parameters' doing.
WARM_UP = 10.0


def _rows(M):
    """A 3x3 matrix (numpy or casadi) as a list of three lists of entries."""
    return [[M[i, j] for j in range(3)] for i in range(3)]


def _mat_vec(A, v):
    return [sum(A[i][j] * v[j] for j in range(3)) for i in range(3)]


def _mat_t_vec(A, v):
    return [sum(A[j][i] * v[j] for j in range(3)) for i in range(3)]


def _sandwich(R, K):
    """``R K R^T`` for a rotation ``R`` (list of rows) and a constant symmetric ``K`` (ndarray), list of rows."""
    RK = [[sum(R[i][a] * K[a, b] for a in range(3)) for b in range(3)] for i in range(3)]
    upper = {(i, j): sum(RK[i][b] * R[j][b] for b in range(3)) for i in range(3) for j in range(i, 3)}
    return [[upper[min(i, j), max(i, j)] for j in range(3)] for i in range(3)]


def _mat_rows(A, U, k):
    """``A U`` for a 3x3 ``A`` (list of rows) and 3 rows ``U`` of ``k``."""
    return [[sum(A[i][a] * U[a][j] for a in range(3)) for j in range(k)] for i in range(3)]


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def phi_from_params(s, n, rho):
    """The two groups' parameters from ``vec([S | c])``: ``[phi_t, phi_f]`` (module docstring).

    ``phi_f = vec(S_f)`` (rows 3-5), ``phi_t = vec(S_t - [rho]x S_f)`` (the
    torque about ``C``, ``tau_C = tau_O - rho x f``), row order.

    Parameters
    ----------
    s : ndarray or casadi.SX, shape (6 n,)
        ``[S | c]`` flat in row order.
    n : int
        Columns: 6, or 7 with the offset.
    rho : array_like, shape (3,)
        The centre of mass in the sensor frame, m.

    Returns
    -------
    list of two lists of 3 n entries
    """
    r = skew(rho)
    S_t = [[s[i * n + j] for j in range(n)] for i in range(3)]
    S_f = [[s[(3 + i) * n + j] for j in range(n)] for i in range(3)]
    T = [[S_t[i][j] - sum(r[i, a] * S_f[a][j] for a in range(3)) for j in range(n)] for i in range(3)]
    return [[v for row in T for v in row], [v for row in S_f for v in row]]


def params_from_phi(phis, n, rho):
    """``vec([S | c])`` (row order) from ``[phi_t, phi_f]``: ``S_t = T + [rho]x S_f``; inverse of
    :func:`phi_from_params`.

    Returns
    -------
    list of 6 n entries
    """
    r = skew(rho)
    T = [[phis[0][i * n + j] for j in range(n)] for i in range(3)]
    S_f = [[phis[1][i * n + j] for j in range(n)] for i in range(3)]
    S_t = [[T[i][j] + sum(r[i, a] * S_f[a][j] for a in range(3)) for j in range(n)] for i in range(3)]
    return [v for row in S_t + S_f for v in row]


def regressor_rows(R, w):
    """``Psi = R (x) w^T``: row ``i`` holds ``R_ij w_l`` at ``j n + l`` (3 rows of ``3 n``).

    The drive of either momentum, ``Psi phi`` = ``R (Phi w)`` for the 3 x n
    block ``Phi`` whose rows ``phi`` holds (module docstring).

    Parameters
    ----------
    R : list of three lists of 3
        The attitude's rotation matrix, ``B`` to ``W``.
    w : list of n
        The augmented reading.
    """
    return [[R[i][j] * v for j in range(3) for v in w] for i in range(3)]


class SpatialLaw:
    """The spatial law of :class:`fmscal.observers.AdaptiveObserver` (module docstring).

    Mixed into :class:`observers.adaptive._adaptive.SpatialAdaptiveObserver`,
    the class ``AdaptiveObserver(model)`` builds on a model whose attitude is
    a unit quaternion: it reads the observer's settings (``lam``, ``track``,
    ...), its shared adaptation (``_adapt``) and the packed state's layout.
    """

    def _spatial_structure(self):
        """Two groups of ``3 n``: the torque about ``C`` (channels 0-2, the attitude) and the force
        (channels 3-5, ``m p_C``)."""
        k = 3 * self.n_cols
        return [([0, 1, 2], k), ([3, 4, 5], k)]

    def _spatial_parts(self):
        """The packed state's parts beyond the planar ones: the motion about ``C`` and the four filters.

        ``chi`` is the observer's turn (the integral of its world rate), ``chi_ref`` the measured turn at the
        last pose (``q_ref``), ``chi_pose`` the observer's turn just after that pose's correction.
        """
        k = 3 * self.n_cols
        return [("age", 1), ("y", 3), ("l", 3), ("chi", 3), ("chi_ref", 3), ("chi_pose", 3), ("q_ref", 4), ("H", 3),
                ("ups_y", 3 * k), ("ups_l", 3 * k), ("ups_d", 3 * k), ("ups_H", 3 * k)]

    def _spatial_initial(self, pose, w):
        """The motion about ``C`` at rest at the first pose, and each group's prior information.

        Returns
        -------
        parts : dict
        info : list of 2 float
            ``|Psi|^2 / k / lam^4`` (the size of ``H = C Upsilon``); the
            attitude's rows carry ``M`` too (``trace(I_c^-2) / 3``).
        """
        p = self.payload
        pose = np.asarray(pose, dtype=float)
        q = pose[:4] / np.linalg.norm(pose[:4])
        R = rotation_matrix(q)
        k = 3 * self.n_cols
        psi = np.array(regressor_rows(_rows(R), list(w)))
        base = max(float(np.sum(psi * psi)) / k, 1e-12) / self.lam ** 4
        K = np.linalg.inv(p.I_c)
        info = [base * float(np.trace(K @ K)) / 3, base]
        parts = {"age": 0.0, "y": p.mass * (pose[4:] + R @ np.asarray(p.rho)), "l": np.zeros(3), "chi": np.zeros(3),
                 "chi_ref": np.zeros(3), "chi_pose": np.zeros(3), "q_ref": q, "H": np.zeros(3),
                 **{name: np.zeros(3 * k) for name in ("ups_y", "ups_l", "ups_d", "ups_H")}}
        return parts, info

    def _spatial_state(self, o, y, lin, q, H):
        """The model's state ``[p, q, v, omega]`` from the motion about ``C``.

        ``omega = I_c^-1 R^T H``, ``p = y / m - R rho``, ``v = l / m - R (omega x rho)``.
        """
        p = self.payload
        R = _rows(rotation_matrix(q))
        omega = _mat_vec(self._K, _mat_t_vec(R, H))
        arm = _mat_vec(R, list(p.rho))
        turn = _mat_vec(R, _cross(omega, list(p.rho)))
        return o.vcat([y[i] / p.mass - arm[i] for i in range(3)] + [q[i] for i in range(4)]
                      + [lin[i] / p.mass - turn[i] for i in range(3)] + omega)

    def _turned(self, o, q, R, v):
        """``exp(v / 2) (x) q``: the attitude ``q`` (rotation ``R``) turned by the rotation vector ``v``
        (world frame), as ``q`` turned by ``R^T v`` about its own axes (:meth:`fmscal.plant.SpatialModel.integrate`)."""
        at = o.vcat([0.0, 0.0, 0.0, q[0], q[1], q[2], q[3]])
        return self.model.integrate(at, o.vcat([0.0] * 3 + _mat_t_vec(R, v)))[3:7]

    def _spatial_transition(self, o, st, now, nxt, dt):
        """One step of the spatial law (module docstring); returns the packed state at n+1."""
        model, p, n = self.model, self.payload, self.n_cols
        k = 3 * n
        m, K, I_c = p.mass, self._K, p.I_c
        has, has_next = now.has_pose[0], nxt.has_pose[0]
        H, y, lin, chi, chi_ref, q_ref = st.H, st.y, st.l, st.chi, st.chi_ref, st.q_ref
        w0, w1 = self._augmented(o, now.w_hat), self._augmented(o, nxt.w_hat)
        w0, w1 = [w0[j] for j in range(n)], [w1[j] for j in range(n)]
        R_ref = _rows(rotation_matrix(q_ref))
        # the attitude in the drives: the measured one where a pose arrives (q_ref), else the last measured one
        # turned by the observer's own turn since it (chi - chi_pose), not by its error at that pose
        q0 = self._turned(o, q_ref, R_ref, [(1 - has) * (chi[i] - st.chi_pose[i]) for i in range(3)])
        R0 = _rows(rotation_matrix(q0))
        M0 = _sandwich(R0, K)                                        # I_W^-1 at n
        spin0 = _mat_vec(M0, [H[i] for i in range(3)])               # omega in the world frame
        # at n+1: measured, else turned by omega over the step (first order)
        R_next = _rows(rotation_matrix(nxt.pose[0:4]))
        turned = [[R0[i][j] + dt * (spin0[(i + 1) % 3] * R0[(i + 2) % 3][j] - spin0[(i + 2) % 3] * R0[(i + 1) % 3][j])
                   for j in range(3)] for i in range(3)]
        R1 = [[has_next * R_next[i][j] + (1 - has_next) * turned[i][j] for j in range(3)] for i in range(3)]
        # the drives: Psi phi, linear over the step (translational: plus m g)
        phis = phi_from_params(st.S, n, p.rho)
        blocks = [[[phi[i * n + j] for j in range(n)] for i in range(3)] for phi in phis]
        drive = [[_mat_vec(R, [sum(B[i][j] * w[j] for j in range(n)) for i in range(3)])
                  for R, w in ((R0, w0), (R1, w1))] for B in blocks]    # [group][end] -> 3 world entries
        g = [m * v for v in model.gravity]
        a0 = [drive[1][0][i] + g[i] for i in range(3)]
        a1 = [drive[1][1][i] + g[i] for i in range(3)]
        y_pred = [y[i] + dt * lin[i] + position_increment(dt, a0[i], a1[i]) for i in range(3)]
        l_pred = [lin[i] + velocity_increment(dt, a0[i], a1[i]) for i in range(3)]
        H_pred = [H[i] + velocity_increment(dt, drive[0][0][i], drive[0][1][i]) for i in range(3)]
        spin1 = _mat_vec(R1, _mat_vec(K, _mat_t_vec(R1, H_pred)))
        # the rotation vector of a world rate linear over the step, to third order (Magnus)
        twist = _cross(spin0, spin1)
        chi_pred = [chi[i] + dt / 2 * (spin0[i] + spin1[i]) - dt * dt / 12 * twist[i] for i in range(3)]
        # the filters' prediction
        psi0, psi1 = regressor_rows(R0, w0), regressor_rows(R1, w1)
        G_p = [[position_increment(dt, psi0[i][j], psi1[i][j]) for j in range(k)] for i in range(3)]
        G_v = [[velocity_increment(dt, psi0[i][j], psi1[i][j]) for j in range(k)] for i in range(3)]
        unpack = lambda v: [[v[i * k + j] for j in range(k)] for i in range(3)]
        U_y, U_l, U_d, U_H = (unpack(getattr(st, f"ups_{name}")) for name in ("y", "l", "d", "H"))
        U_y = [[U_y[i][j] + dt * U_l[i][j] + G_p[i][j] for j in range(k)] for i in range(3)]
        U_l = [[U_l[i][j] + G_v[i][j] for j in range(k)] for i in range(3)]
        U_d = [[U_d[i][j] + v for j, v in enumerate(row)] for i, row in
               enumerate(_mat_rows(M0, [[dt * U_H[i][j] + G_p[i][j] for j in range(k)] for i in range(3)], k))]
        U_H = [[U_H[i][j] + G_v[i][j] for j in range(k)] for i in range(3)]
        # a priori errors at n+1, zero without a pose: the unwrapped attitude's (the measured turn from the last
        # pose, in the world frame, added to chi_ref), m p_C's
        q_meas = [has_next * nxt.pose[i] + (1 - has_next) * q_ref[i] for i in range(4)]     # no pose: no turn
        body = model.difference(o.vcat([0.0, 0.0, 0.0, q_ref[0], q_ref[1], q_ref[2], q_ref[3]]),
                                o.vcat([0.0, 0.0, 0.0, q_meas[0], q_meas[1], q_meas[2], q_meas[3]]))[3:6]
        chi_meas = [chi_ref[i] + v for i, v in enumerate(_mat_vec(R_ref, [body[i] for i in range(3)]))]
        e_d = [has_next * (chi_meas[i] - chi_pred[i]) for i in range(3)]
        arm = _mat_vec(R_next, list(p.rho))
        e_y = [has_next * (m * (nxt.pose[4 + i] + arm[i]) - y_pred[i]) for i in range(3)]
        # the fit starts once the observer's own transient from rest has decayed (WARM_UP poles' time constants)
        age = st.age[0] + dt
        fit = has_next * (age >= WARM_UP / self.lam)
        rows = [[fit * v for v in r] for r in U_d + U_y]
        h = st.since[0] + dt
        d_phis, parts = self._adapt(o, st, rows, [fit * v for v in e_d + e_y], fit * h, st.scale)
        # the correction: the filters, then the motion with the filters' share of the parameters' step
        l1, l2 = discrete_gain(o, self.lam, h)
        l1, l2 = has_next * l1, has_next * l2
        l2_IW = [[l2 * v for v in row] for row in _sandwich(R1, I_c)]
        U_d_new = [[(1 - l1) * v for v in row] for row in U_d]
        U_H_new = [[U_H[i][j] - v for j, v in enumerate(row)] for i, row in enumerate(_mat_rows(l2_IW, U_d, k))]
        U_y_new = [[(1 - l1) * v for v in row] for row in U_y]
        U_l_new = [[U_l[i][j] - l2 * U_y[i][j] for j in range(k)] for i in range(3)]
        dot = lambda a, b: sum(a[j] * b[j] for j in range(k))
        d_t, d_f = d_phis
        chi_new = [chi_pred[i] + l1 * e_d[i] + dot(U_d_new[i], d_t) for i in range(3)]
        IWe = _mat_vec(l2_IW, e_d)
        H_new = [H_pred[i] + IWe[i] + dot(U_H_new[i], d_t) for i in range(3)]
        y_new = [y_pred[i] + l1 * e_y[i] + dot(U_y_new[i], d_f) for i in range(3)]
        l_new = [l_pred[i] + l2 * e_y[i] + dot(U_l_new[i], d_f) for i in range(3)]
        # the last pose becomes the reference (sign-continuous), and the observer's attitude is it turned
        sign = o.if_else(sum(q_meas[i] * q_ref[i] for i in range(4)) < 0, -1.0, 1.0)
        q_ref_new = [has_next * sign * q_meas[i] + (1 - has_next) * q_ref[i] for i in range(4)]
        chi_ref_new = [has_next * chi_meas[i] + (1 - has_next) * chi_ref[i] for i in range(3)]
        R_ref_new = [[has_next * R_next[i][j] + (1 - has_next) * R_ref[i][j] for j in range(3)] for i in range(3)]
        q_new = self._turned(o, q_ref_new, R_ref_new, [chi_new[i] - chi_ref_new[i] for i in range(3)])
        chi_pose_new = [has_next * chi_new[i] + (1 - has_next) * st.chi_pose[i] for i in range(3)]
        S_next = o.vcat(params_from_phi([[phis[g][j] + d_phis[g][j] for j in range(k)] for g in range(2)], n, p.rho))
        flat = lambda U: o.vcat([v for row in U for v in row])
        return self.state.pack(o, x=self._spatial_state(o, y_new, l_new, q_new, H_new), S=S_next,
                               since=(1 - has_next) * h, scale=st.scale, age=age, y=o.vcat(y_new), l=o.vcat(l_new),
                               chi=o.vcat(chi_new), chi_ref=o.vcat(chi_ref_new), chi_pose=o.vcat(chi_pose_new),
                               q_ref=o.vcat(q_ref_new),
                               H=o.vcat(H_new), ups_y=flat(U_y_new), ups_l=flat(U_l_new),
                               ups_d=flat(U_d_new), ups_H=flat(U_H_new), **parts)
