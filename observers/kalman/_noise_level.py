"""Adjustable-level process noise for the EKF's random walk on ``S``.

A change in the sensor's calibration shows in the pose innovations before
it shows anywhere else: their normalized innovation squared (NIS)
``eps = nu^T S_nu^-1 nu`` is chi-square with 3 degrees of freedom (the
planar pose; 6 for a spatial pose, ``dof``) while the filter's model
holds, and grows while its ``S_hat`` lags the true ``S``.
:class:`NoiseLevel` watches a fading-memory average of the NIS and raises
the random-walk intensity while that average is above its bound, lowering
it back to the base level otherwise: the adjustable-level process noise of
maneuvering-target tracking (Bar-Shalom, Li and Kirubarajan, *Estimation
with Applications to Tracking and Navigation*, 2001, ch. 11), applied to
the calibration states. The filter then averages like a constant-``S``
fit while nothing changes, and re-opens its calibration states when the
innovations say that something did.
"""

from scipy.stats import chi2, norm

from fmscal.plant.numerics import FmscalError, ops

__all__ = ["NoiseLevel", "NIS_DOF", "DEFAULT_TOLERANCE", "DEFAULT_Q_START", "level_update"]

#: Degrees of freedom of the planar pose innovation ``[theta, X, Y]`` (the default ``dof``).
NIS_DOF = 3
#: One NIS sample counts at most this much (the 99.9 % point of chi-square(3)),
#: so that a single outlier in the poses cannot raise the level.
NIS_CLIP = float(chi2.ppf(0.999, NIS_DOF))
#: Relative error of the noise standard deviations tolerated by default (25 %).
DEFAULT_TOLERANCE = 0.25
#: Intensity the first alarm starts a zero base level at, 1/s (about 0.006 of wander an hour).
DEFAULT_Q_START = 1e-8
#: The bound is the 99.9 % point of the average under a consistent filter.
_Z = float(norm.ppf(0.999))


class NoiseLevel:
    """The random-walk intensity of ``S``, raised while the innovations say ``S`` moved.

    With ``eps_k`` the NIS of pose ``k`` (clipped at :data:`NIS_CLIP`) and
    ``h`` the time since the previous pose,

    - ``a = exp(-h / window)``, ``eps_bar_k = a eps_bar_{k-1} + (1 - a) eps_k``
      (starting at ``dof`` = 3, its mean under a consistent filter);
    - ``bound = (1 + tolerance)^2 (3 + z sqrt(6 (1 - a) / (1 + a)))`` (with
      ``dof`` degrees of freedom ``dof + z sqrt(2 dof (1 - a) / (1 + a))``), with
      ``z`` the 99.9 % normal point: the 99.9 % bound of ``eps_bar`` for a
      consistent filter, widened for a noise model whose standard deviations
      are off by up to ``tolerance``;
    - while ``eps_bar > bound`` the intensity is raised: ``q`` becomes
      ``max(q, q_start) exp(rise h)``, at most ``q_max`` (a base level of
      zero cannot be multiplied up, so the first alarm starts it at
      ``q_start``);
    - otherwise it decays: ``q exp(-fall h)``, and once below ``q_start``
      it drops back to ``q_base`` (never below ``q_base``).

    The level is thus ``q_base`` while nothing changes (0 by default in the
    EKF: a constant ``S``, the constant-``S`` accuracy) and somewhere in
    ``[q_start, q_max]`` while, and shortly after, the innovations say that
    ``S`` moved.

    Parameters
    ----------
    q_base : float
        Intensity while nothing changes, 1/s (>= 0).
    q_max : float
        Largest intensity, 1/s (>= ``q_start`` and ``q_base``).
    tolerance : float
        Relative error of the noise model's standard deviations that does not
        raise the level (0.25: a model 25 % too small is still tolerated).
    window : float
        Time constant of the NIS average, s.
    rise, fall : float
        Rates at which the intensity grows and decays, 1/s (a factor of 10
        in 0.23 s and in 2.3 s by default).
    q_start : float, optional
        Intensity an alarm starts from, 1/s (> 0); default ``q_base`` if
        that is positive, else :data:`DEFAULT_Q_START`.

    Attributes
    ----------
    q : float
        The current intensity, 1/s.
    eps_bar : float
        The current NIS average.
    ``dof`` (default :data:`NIS_DOF`) is the pose innovation's size: 6 for
    a spatial pose in the error state ``[dp, dphi]``. The NIS is clipped at
    the 99.9 % point of chi-square(``dof``).
    """

    def __init__(self, q_base, q_max, tolerance=DEFAULT_TOLERANCE, window=1.0, rise=10.0, fall=1.0,
                 q_start=None, dof=NIS_DOF):
        self.dof = int(dof)
        self.q_base, self.q_max = float(q_base), float(q_max)
        if q_start is None:
            q_start = self.q_base if self.q_base > 0 else DEFAULT_Q_START
        self.q_start = float(q_start)
        if not (self.q_base >= 0 and self.q_start > 0 and self.q_max >= max(self.q_start, self.q_base)):
            raise FmscalError(f"NoiseLevel needs 0 <= q_base, 0 < q_start <= q_max; got q_base={self.q_base:g}, "
                              f"q_start={self.q_start:g}, q_max={self.q_max:g}")
        self.inflation = (1.0 + float(tolerance)) ** 2
        self.window, self.rise, self.fall = float(window), float(rise), float(fall)
        self.reset()

    def reset(self):
        """Back to the base intensity and a NIS average of ``dof``."""
        self.q = self.q_base
        self.eps_bar = float(self.dof)

    @property
    def settings(self):
        """``(q_base, q_start, q_max, inflation, window, rise, fall)``, as :func:`level_update` takes them."""
        return (self.q_base, self.q_start, self.q_max, self.inflation, self.window, self.rise, self.fall)

    def bound(self, a):
        """The alarm bound of the NIS average for a forgetting factor ``a``."""
        return _bound(ops(a), a, self.inflation, self.dof)

    def update(self, nis, h):
        """Take the NIS of one pose, ``h`` seconds after the previous one; return the new intensity.

        Parameters
        ----------
        nis : float
            ``nu^T S_nu^-1 nu`` of this pose's innovation.
        h : float
            Time since the previous pose, s (> 0).

        Returns
        -------
        float
            The random-walk intensity for the following predictions, 1/s.
        """
        q, eps_bar = level_update(self.q, self.eps_bar, nis, h, self.settings, self.dof)
        self.q, self.eps_bar = float(q), float(eps_bar)
        return self.q

    @property
    def raised(self):
        """True while the intensity is above its base level."""
        return self.q > self.q_base


def _bound(o, a, inflation, dof=NIS_DOF):
    """The 99.9 % bound of the NIS average for a forgetting factor ``a``, widened by ``inflation`` (class docstring)."""
    return inflation * (dof + _Z * o.sqrt(2 * dof * (1 - a) / (1 + a)))


def level_update(q, eps_bar, nis, h, settings, dof=NIS_DOF):
    """One pose's update of the level (:class:`NoiseLevel`), for numbers or casadi symbols alike.

    Parameters
    ----------
    q, eps_bar : float or casadi.SX
        The intensity (1/s) and the NIS average before the pose.
    nis : float or casadi.SX
        ``nu^T S_nu^-1 nu`` of the pose's innovation.
    h : float or casadi.SX
        Time since the previous pose, s.
    settings : tuple
        ``(q_base, q_start, q_max, inflation, window, rise, fall)`` (:attr:`NoiseLevel.settings`).
    dof : int
        The pose innovation's size (:attr:`NoiseLevel.dof`).

    Returns
    -------
    q, eps_bar
        After the pose.
    """
    q_base, q_start, q_max, inflation, window, rise, fall = settings
    o = ops(q, eps_bar, nis, h, *settings)
    a = o.exp(-h / window)
    clip = NIS_CLIP if dof == NIS_DOF else float(chi2.ppf(0.999, dof))
    eps_bar = a * eps_bar + (1 - a) * o.fmin(nis, clip)
    raised = o.fmin(o.fmax(q, q_start) * o.exp(rise * h), q_max)
    fallen = q * o.exp(-fall * h)
    fallen = o.if_else(fallen >= o.fmax(q_start, q_base), fallen, q_base)
    q = o.if_else(eps_bar > _bound(o, a, inflation, dof), raised, o.if_else(q > q_base, fallen, q))
    return q, eps_bar
