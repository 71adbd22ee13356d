"""How well a payload's mass properties are known: :class:`PayloadStd`, and the defaults a calibration takes.

A calibration fits ``S`` to the wrench the payload's motion needs, so a
payload given wrong moves ``S`` (:mod:`fmscal.observers.batch._payload_sensitivity`):
``S_std`` carries the payload's uncertainty, stated here. Where the user
states none, the defaults below are how tools' mass properties are known in
practice; each is one standard deviation:

- **the mass, 0.5 %** (:data:`DEFAULT_MASS_STD`, relative): a tool weighed on
  a bench scale. The scale reads a 1 kg tool to about 1 g (0.1 %); what is
  weighed is rarely exactly what hangs on the sensor (the adapter plate, its
  screws, the cable's share), so the top of a scale's 0.1-0.5 %. A mass from
  CAD is off by a few per cent (the same parts, paint, densities taken as
  nominal): state it (``mass=``, ``--mass-std``).
- **the centre of mass, 1 mm on each axis** (:data:`DEFAULT_COM_STD`): a CAD
  model's, within a millimetre or two on a wrist tool (a cable or a connector
  moves it).
- **the inertia, 15 % of each entry's scale** (:data:`DEFAULT_INERTIA_STD`):
  CAD's inertia is off by 10-20 % (what CAD leaves out weighs most at the
  tool's ends); each entry independently, its scale ``I_ii`` on the
  diagonal and ``sqrt(I_ii I_jj)`` for a product of inertia
  (:meth:`fmscal.plant.Model.inertia_scale`).
- **gravity's size, 0.02 m/s^2** (:data:`DEFAULT_GRAVITY_STD`), where it is
  not measured: ``g`` at sea level runs from 9.78 m/s^2 at the equator to 9.83
  at the poles and falls 0.003 m/s^2 a kilometre up; the 9.81 taken without
  a local value is within about 0.02 of it. A local value (a gravity map,
  a survey) is good to 1e-4: state it.

The covariance a calibration takes (:meth:`PayloadStd.covariance`) is over the
model's :meth:`~fmscal.plant.Model.payload_parameter_names` (mass, the position
vector, the inertia's entries, gravity's size); what is stated replaces the
default of its block, and a covariance given whole (a payload estimate's, with
its correlations) replaces the defaults of every number it states.
"""

from dataclasses import dataclass

import numpy as np

from fmscal.plant.numerics import FmscalError, short_repr

__all__ = ["PayloadStd", "PayloadStdError", "DEFAULT_MASS_STD", "DEFAULT_COM_STD", "DEFAULT_INERTIA_STD",
           "DEFAULT_GRAVITY_STD"]

#: The mass's standard deviation where none is stated, relative to the mass (a tool weighed on a scale).
DEFAULT_MASS_STD = 0.005
#: The centre of mass's standard deviation on each axis where none is stated, m (CAD's).
DEFAULT_COM_STD = 0.001
#: Each inertia entry's standard deviation where none is stated, relative to its scale (CAD's).
DEFAULT_INERTIA_STD = 0.15
#: Gravity's size's standard deviation where none is stated, m/s^2 (9.81 taken for the local value).
DEFAULT_GRAVITY_STD = 0.02


class PayloadStdError(FmscalError):
    """A payload uncertainty refused: ``field`` names the field (``"mass"``, ``"com"``, ``"inertia"``,
    ``"gravity"``, ``"cov"``), the message starts with ``payload_std.<field>``."""

    def __init__(self, field, message):
        super().__init__(f"payload_std.{field} {message}")
        self.field, self.message = field, message


def _sd(value, name, unit):
    """``value`` as a non-negative finite float, or a one-line error."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) or not np.isfinite(value) \
            or value < 0:
        raise PayloadStdError(name, f"must be a non-negative number ({unit}); got {short_repr(value)}")
    return float(value)


def _sds(value, name, unit, matrix=False):
    """A number, a vector or (``matrix``) a covariance of non-negative finite numbers, as a float array."""
    if np.ndim(value) == 0:
        return np.array(_sd(value, name, unit))
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise PayloadStdError(name, f"must be numbers ({unit}); got {short_repr(value)}") from None
    if arr.ndim == 1 and np.all(np.isfinite(arr)) and np.all(arr >= 0):
        return arr
    if matrix and arr.ndim == 2 and arr.shape[0] == arr.shape[1] and np.all(np.isfinite(arr)) \
            and np.allclose(arr, arr.T, rtol=1e-9, atol=0) and np.linalg.eigvalsh((arr + arr.T) / 2).min() \
            >= -1e-12 * max(np.abs(arr).max(), 1e-300):
        return (arr + arr.T) / 2
    what = " or their covariance (symmetric, positive semi-definite)" if matrix else ""
    raise PayloadStdError(name, f"must be a non-negative number or one per entry{what} ({unit}); got "
                                f"{short_repr(value)}")


@dataclass(frozen=True)
class PayloadStd:
    """The one-sigma uncertainty of a payload's mass properties and of gravity's size.

    Each field left None takes its default (module docstring) unless ``cov``
    states it.

    Parameters
    ----------
    mass : float, optional
        kg (default :data:`DEFAULT_MASS_STD` of the mass).
    com : float or array_like, optional
        m: one standard deviation for each axis of the centre of mass, one
        per axis, or their covariance (m^2, square); the planar payload's
        ``rho`` (the same vector seen from the other end) takes the same
        (default :data:`DEFAULT_COM_STD`).
    inertia : float or array_like, optional
        Relative: each inertia entry's standard deviation over its scale
        (:meth:`fmscal.plant.Model.inertia_scale`), one number for every
        entry or one per entry (default :data:`DEFAULT_INERTIA_STD`).
    gravity : float, optional
        m/s^2, of gravity's size (models under gravity, a model with none
        takes only 0; default :data:`DEFAULT_GRAVITY_STD`).
    cov : array_like, shape (k, k), optional
        A covariance over the model's
        :meth:`~fmscal.plant.Model.payload_parameter_names` (a payload
        estimate's, with its correlations): it replaces the defaults of every
        number whose variance it states (NaN on its diagonal: not stated;
        infinite: not determined). The fields above replace its blocks.

    Examples
    --------
    >>> from fmscal.plant import SpatialModel, SpatialPayload
    >>> tool = SpatialModel(SpatialPayload(1.2, (4e-3, 5e-3, 2.5e-3, 0, 0, 0), (0.01, 0.0, 0.06)))
    >>> cov = PayloadStd(mass=0.002, inertia=0.1).covariance(tool)
    >>> tool.payload_parameter_names()[:2], np.sqrt(np.diag(cov))[:2].round(4).tolist()
    (('mass', 'X'), [0.002, 0.001])
    >>> PayloadStd.exact().covariance(tool).any()
    np.False_
    """

    mass: float = None
    com: object = None
    inertia: object = None
    gravity: float = None
    cov: object = None

    def __post_init__(self):
        set_ = object.__setattr__
        if self.mass is not None:
            set_(self, "mass", _sd(self.mass, "mass", "kg"))
        if self.gravity is not None:
            set_(self, "gravity", _sd(self.gravity, "gravity", "m/s^2"))
        if self.com is not None:
            set_(self, "com", _sds(self.com, "com", "m", matrix=True))
        if self.inertia is not None:
            set_(self, "inertia", _sds(self.inertia, "inertia", "relative to each entry's scale"))
        if self.cov is not None:
            try:
                cov = np.array(self.cov, dtype=float)
            except (TypeError, ValueError):
                cov = np.array(np.nan)
            if cov.ndim != 2 or cov.shape[0] != cov.shape[1]:
                raise PayloadStdError("cov", f"must be a square covariance; got {short_repr(self.cov)}")
            set_(self, "cov", cov)

    @classmethod
    def exact(cls):
        """The payload taken as exact: every standard deviation zero (for either model)."""
        return cls(mass=0.0, com=0.0, inertia=0.0, gravity=0.0)

    def covariance(self, model):
        """The covariance of the model's :meth:`~fmscal.plant.Model.payload_parameter_names`, shape (k, k).

        The defaults (module docstring), then ``cov``'s block for the numbers
        it states, then each field given in place of its block (its
        correlations with the others dropped).

        Parameters
        ----------
        model : plant.Model
            The payload (and gravity) the calibration takes.

        Raises
        ------
        FmscalError
            A field or ``cov`` of the wrong size for the model, or ``gravity`` on a model not under gravity.
        """
        names = model.payload_parameter_names()
        k, n_pos, n_in = len(names), len(model.payload_position_names), len(model.inertia_names)
        mass, position, inertia = [0], list(range(1, 1 + n_pos)), list(range(1 + n_pos, 1 + n_pos + n_in))
        scale = model.inertia_scale()
        cov = np.zeros((k, k))
        cov[0, 0] = (DEFAULT_MASS_STD * model.payload.mass) ** 2
        cov[position, position] = DEFAULT_COM_STD ** 2
        cov[inertia, inertia] = (DEFAULT_INERTIA_STD * scale) ** 2
        if model.under_gravity:
            cov[-1, -1] = DEFAULT_GRAVITY_STD ** 2
        if self.cov is not None:
            if self.cov.shape != (k, k):
                raise PayloadStdError("cov", f"must be {k}x{k} ({', '.join(names)}); got "
                                             f"{'x'.join(map(str, self.cov.shape))}")
            stated = ~np.isnan(np.diag(self.cov))
            cov[np.ix_(stated, stated)] = np.nan_to_num(self.cov[np.ix_(stated, stated)], nan=0.0, posinf=np.inf)
        blocks = []
        if self.mass is not None:
            blocks.append((mass, np.array([[self.mass ** 2]])))
        if self.com is not None:
            blocks.append((position, _block(self.com, n_pos, "com", model)))
        if self.inertia is not None:
            relative = np.broadcast_to(self.inertia, (n_in,)) if self.inertia.size in (1, n_in) else None
            if relative is None:
                raise PayloadStdError("inertia", f"must be one number or {n_in} for a {model.name} payload "
                                                 f"({', '.join(model.inertia_names)}); got {self.inertia.size}")
            blocks.append((inertia, np.diag((relative * scale) ** 2)))
        if self.gravity is not None and not model.under_gravity:
            if self.gravity > 0:                       # exact() states 0 for every model
                raise PayloadStdError("gravity", f"is for a model under gravity; a {model.name} payload moves "
                                                 "with none")
        elif self.gravity is not None:
            blocks.append(([k - 1], np.array([[self.gravity ** 2]])))
        for where, block in blocks:
            cov[where, :] = 0.0
            cov[:, where] = 0.0
            cov[np.ix_(where, where)] = block
        return cov

    def to_dict(self):
        """The fields as JSON-ready numbers and lists (None where not stated)."""
        def listed(v):
            return None if v is None else (np.asarray(v).tolist() if np.ndim(v) else float(v))
        return {"mass": self.mass, "com": listed(self.com), "inertia": listed(self.inertia), "gravity": self.gravity,
                "cov": listed(self.cov)}


def _block(value, size, name, model):
    """The position's covariance block from a number, ``size`` numbers or a ``size x size`` covariance."""
    if value.ndim == 0 or value.size == 1:
        return np.eye(size) * float(np.ravel(value)[0]) ** 2
    if value.shape == (size,):
        return np.diag(value ** 2)
    if value.shape == (size, size):
        return value
    raise PayloadStdError(name, f"must be one number, {size} or a {size}x{size} covariance for a {model.name} "
                                f"payload ({', '.join(model.payload_position_names)}); got shape "
                                f"{'x'.join(map(str, value.shape))}")
