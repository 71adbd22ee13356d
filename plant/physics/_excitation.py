"""Wrench excitations: the paper's eq. (13), multisines, a user's samples."""

import numpy as np

from fmscal.plant.numerics import FmscalError, as_finite_array

__all__ = ["Excitation", "PaperWrench", "Multisine", "SampledWrench"]


class Excitation:
    """A true wrench ``w(t) = [M, f_x, f_y]`` (N m, N), continuous in time."""

    def __call__(self, t):
        """Evaluate the wrench.

        Parameters
        ----------
        t : float or array_like, shape (N,)
            Time in s.

        Returns
        -------
        ndarray, shape (3,) or (N, 3)
        """
        raise NotImplementedError

    def peak(self, duration, dt=1e-3):
        """Peak absolute value of each component over ``[0, duration]``, shape (3,)."""
        t = np.arange(0.0, duration + dt / 2, dt)
        return np.max(np.abs(self(t)), axis=0)


class Multisine(Excitation):
    """A sum of sines per component: ``sum_k a_k sin(omega_k t + phase_k)``.

    Parameters
    ----------
    components : list of 3 lists of (amplitude, omega, phase)
        One list per wrench component ``M, f_x, f_y``; amplitude in N m or N,
        angular frequency ``omega`` in rad/s, phase in rad.

    Examples
    --------
    >>> w = Multisine([[(1.0, 2.0, 0.0)], [(1.0, 1.0, 0.0)], [(2.0, 3.0, 0.0)]])
    >>> w(0.0).shape
    (3,)
    """

    def __init__(self, components):
        if len(components) != 3:
            raise FmscalError(f"Multisine needs 3 components (M, fx, fy); got {len(components)}")
        self.components = []
        for i, comp in enumerate(components):
            arr = as_finite_array(comp, (-1, 3), f"component {i} (amplitude, omega, phase)")
            self.components.append(arr)

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        out = np.zeros(t.shape + (3,))
        for i, comp in enumerate(self.components):
            for a, omega, phase in comp:
                out[..., i] += a * np.sin(omega * t + phase)
        return out


class PaperWrench(Multisine):
    """The paper's wrench, eq. (13)::

        M   = sin(2t) + 0.1 cos(10t) + 0.4 sin(pi t + pi/6)
        f_x = sin(t)  + 0.1 cos(4.5t) + 0.4 sin(pi t + pi/3)
        f_y = 2 sin(3t) + 0.2 cos(5t) + 0.4 sin(7t)

    (``cos(x) = sin(x + pi/2)``.)
    """

    def __init__(self):
        h = np.pi / 2
        super().__init__([
            [(1.0, 2.0, 0.0), (0.1, 10.0, h), (0.4, np.pi, np.pi / 6)],
            [(1.0, 1.0, 0.0), (0.1, 4.5, h), (0.4, np.pi, np.pi / 3)],
            [(2.0, 3.0, 0.0), (0.2, 5.0, h), (0.4, 7.0, 0.0)],
        ])


class SampledWrench(Excitation):
    """A user's wrench samples, linearly interpolated in time.

    Parameters
    ----------
    t : array_like, shape (N,)
        Strictly increasing sample times in s.
    w : array_like, shape (N, 3)
        True wrench samples ``[M, f_x, f_y]``.
    """

    def __init__(self, t, w):
        self.t = as_finite_array(t, (-1,), "t")
        self.w = as_finite_array(w, (len(self.t), 3), "w")
        if len(self.t) < 2 or np.any(np.diff(self.t) <= 0):
            raise FmscalError("t must hold at least 2 strictly increasing times")

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        return np.stack([np.interp(t, self.t, self.w[:, i]) for i in range(3)], axis=-1)
