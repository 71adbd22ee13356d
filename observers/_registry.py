"""The registry of methods: the one list of names the toolkit knows.

Every command, table and notebook finds a method here: its name, how tables
show it, how to build it with its documented defaults, whether it needs a
noise model, whether it runs online, and what it is for. No other module
keeps a list of method names.
"""

import inspect
from collections.abc import Mapping
from dataclasses import dataclass

from fmscal.plant.numerics import FmscalError, as_bool, as_number

from fmscal.observers.core import ENGINES as _ENGINE_TABLE
from fmscal.observers.adaptive import AdaptiveObserver, HighGainObserver, PaperAdaptiveObserver, SpatialAdaptiveObserver
from fmscal.observers.batch import InverseDynamicsLeastSquares, LeastSquares, MaximumLikelihood
from fmscal.observers.kalman import AugmentedEKF

__all__ = ["Method", "METHODS", "FLOOR_METHOD", "ENGINES", "engine_class", "get_method", "make_observer",
           "method_names", "method_label"]


@dataclass(frozen=True)
class Method:
    """One method of the toolkit, as the registry knows it.

    Attributes
    ----------
    name : str
        The name commands take (``--observer NAME``) and tables print.
    label : str
        How tables and figures show it.
    cls : type
        The :class:`observers.Observer` subclass that implements it.
    defaults : dict
        Constructor settings that make this method out of ``cls`` (on top of
        the class's own documented defaults).
    needs_noise_model : bool
        It is told the noise standard deviations (or estimates them from the log).
    online : bool
        Sample by sample (``step``); False: it fits a whole log.
    role : str
        ``"design"``: an observer of the toolkit's comparison; ``"paper"``:
        a configuration kept to reproduce the paper's claims; ``"reference"``:
        an offline reference.
    calibrates : bool
        Offered by ``fmscal calibrate`` for a recorded log.
    summary : str
        One line on what it is.
    paper_claim : float or None
        E at 100 s that the paper claims for this method (section 4), where it claims one.

    Examples
    --------
    >>> from fmscal.observers import METHODS, Method
    >>> method = METHODS["ekf"]
    >>> isinstance(method, Method), method.online, method.label
    (True, True, 'ekf (after [3])')
    """

    name: str
    label: str
    cls: type
    defaults: dict
    needs_noise_model: bool
    online: bool
    role: str
    calibrates: bool
    summary: str
    paper_claim: float = None

    def build(self, model, noise=None, settings=None):
        """The method for ``model``, with its documented defaults and ``settings`` on top.

        Parameters
        ----------
        model : plant.Model or plant.Payload
            The problem (a payload stands for its case's model).
        noise : plant.NoiseSpec, optional
            What a method with a noise model is told; None: it estimates the
            noise from the log. Ignored by methods without one.
        settings : dict, optional
            Constructor keyword arguments (gains, ``offset``, ...).

        Returns
        -------
        observers.Observer

        Raises
        ------
        FmscalError
            A setting the method does not have, or of the wrong type
            (:meth:`check_settings`).
        """
        kwargs = {**self.defaults, **self.check_settings(settings)}
        if self.needs_noise_model:
            kwargs.setdefault("noise", noise)            # the method checks it against its model
        return self.cls(model, **kwargs)


    def check_settings(self, settings):
        """``settings`` as a dict, each checked against the type of its default in the constructor.

        A setting whose default is a boolean takes only ``True`` or ``False``
        (the text ``"false"`` is true to Python); one whose default is a
        number takes only a number (not text, not a boolean) or None (which
        the constructor accepts or refuses: ``t_decay=None``); one whose
        default is text takes only text. Settings whose default is None are
        checked by the constructor.

        Parameters
        ----------
        settings : mapping or None

        Returns
        -------
        dict

        Raises
        ------
        FmscalError
            Not a mapping, a name the constructor does not take, or a value of the wrong type.
        """
        if settings is None:
            return {}
        if not isinstance(settings, Mapping):
            raise FmscalError(f"settings must be a dict of constructor arguments; got {type(settings).__name__}")
        params = {k: v.default for k, v in inspect.signature(self.cls.__init__).parameters.items()
                  if k not in ("self", "model") and v.kind == v.POSITIONAL_OR_KEYWORD}
        for key, value in settings.items():
            if key not in params:
                raise FmscalError(f"{self.name}: no setting {key!r}; its settings: {', '.join(params)}")
            default = params[key]
            if isinstance(default, bool):
                as_bool(value, f"{self.name} setting {key}")
            elif isinstance(default, (int, float)) and value is not None:      # None: the constructor decides
                as_number(value, f"{self.name} setting {key}")
            elif isinstance(default, str) and not isinstance(value, str):
                raise FmscalError(f"{self.name} setting {key} must be text; got {value!r}")
        return dict(settings)


#: Every method the toolkit knows, by name: ``{name: Method}``, in the order tables show them.
METHODS = {m.name: m for m in (
    Method("adaptive", "adaptive", AdaptiveObserver, {}, needs_noise_model=False, online=True, role="design",
           calibrates=True, summary="eqs. (6)-(8) with filtered regressors and a least-squares gain: at the floor"),
    Method("adaptive-paper", "adaptive-paper", PaperAdaptiveObserver, {},
           needs_noise_model=False, online=True, role="paper", calibrates=False,
           summary="eqs. (6)-(8), (14), (15) exactly as printed", paper_claim=9.1106e-4),
    Method("high-gain", "high-gain (reconstruction of [4])", HighGainObserver, {}, needs_noise_model=False,
           online=True, role="design", calibrates=True,
           summary="high-gain adaptive observer after Parsa and Aghili, tuned by its rule"),
    Method("high-gain-ref4", "high-gain-ref4 (reconstruction of [4], as the seed paper describes it)",
           HighGainObserver, HighGainObserver.REF4_SETTINGS, needs_noise_model=False, online=True,
           role="paper", calibrates=False, summary="the high-gain observer configured as the paper describes [4]",
           paper_claim=3.6700e-2),
    Method("ekf", "ekf (after [3])", AugmentedEKF, {}, needs_noise_model=True, online=True, role="design",
           calibrates=True, summary="augmented-state extended Kalman filter after Aghili"),
    Method("least-squares", "least-squares (offline reference)", LeastSquares, {}, needs_noise_model=False,
           online=False, role="reference", calibrates=True,
           summary="offline least squares over double-integrated windows"),
    Method("max-likelihood", "max-likelihood (the floor)", MaximumLikelihood, {}, needs_noise_model=True,
           online=False, role="reference", calibrates=True,
           summary="maximum-likelihood estimate from the whole log: what the data allow"),
)}

#: Which class runs a method on a model, by what the model declares (:class:`fmscal.plant.Model`): a row
#: ``(method's class, declaration, value): engine`` says that on a model whose ``declaration`` is ``value``
#: the method runs as ``engine`` (a subclass of it); a method on a model no row matches runs as its own class.
#: Building a method's class (``LeastSquares(model)``, :meth:`Method.build`) builds its engine
#: (:meth:`observers.Observer.__new__`), and :meth:`observers.Observer.refusal` is the engine's. This table
#: and :func:`engine_class` are where the toolkit tells its cases apart: no method tests a model's name or class.
ENGINES = _ENGINE_TABLE
ENGINES.update({
    # a body in 3D (a unit-quaternion attitude): the law on its momenta about the centre of mass
    (AdaptiveObserver, "attitude", "quaternion"): SpatialAdaptiveObserver,
    # a body in 3D: least squares on smoothed inverse dynamics, linear in [S | c] (on another model on request:
    # LeastSquares(model, engine="inverse-dynamics")); the floor needs no row: fit_max_likelihood linearises
    # a model without linear channels (MaximumLikelihood(model, linearised=True) on any model)
    (LeastSquares, "attitude", "quaternion"): InverseDynamicsLeastSquares,
})


def engine_class(cls, model):
    """The class that runs the method ``cls`` on ``model``: the engine of the first row of :data:`ENGINES`
    for ``cls`` whose declaration the model makes, else ``cls`` itself.

    Parameters
    ----------
    cls : type
        A method's class (an :class:`observers.Observer` subclass).
    model : plant.Model or plant.Payload
        A payload stands for its case's model.

    Returns
    -------
    type
        ``cls`` or a subclass of it.

    Raises
    ------
    FmscalError
        ``model`` is neither a model nor a payload.
    """
    return cls.engine(model)


#: The method whose E on a log is the floor every table divides by (``E / floor``).
FLOOR_METHOD = "max-likelihood"


def get_method(name):
    """The :class:`Method` called ``name``.

    Raises
    ------
    FmscalError
        No such method; the message lists the names.

    Examples
    --------
    >>> from fmscal.observers import get_method
    >>> get_method("max-likelihood").cls.__name__
    'MaximumLikelihood'
    >>> get_method("kalman")
    Traceback (most recent call last):
        ...
    fmscal.plant...FmscalError: unknown observer 'kalman'; expected one of adaptive, ...
    """
    try:
        return METHODS[name]
    except (KeyError, TypeError):
        raise FmscalError(f"unknown observer {name!r}; expected one of {', '.join(METHODS)}") from None


def make_observer(name, model, noise=None, settings=None):
    """A method by name, with its documented defaults (:meth:`Method.build`).

    Parameters
    ----------
    name : str
        A key of :data:`METHODS`.
    model : plant.Model or plant.Payload
    noise : plant.NoiseSpec, optional
        What a method with a noise model is told; None: estimated from the log.
    settings : dict, optional
        Constructor keyword arguments.

    Returns
    -------
    observers.Observer

    Examples
    --------
    >>> from fmscal.plant import PAPER_PAYLOAD, SPATIAL_SCENARIOS
    >>> from fmscal.observers import make_observer
    >>> type(make_observer("ekf", PAPER_PAYLOAD)).__name__             # the method, with its documented defaults
    'AugmentedEKF'
    >>> model = SPATIAL_SCENARIOS["spatial-arm"].model()
    >>> type(make_observer("adaptive", model)).__name__                # the engine the model's declarations pick
    'SpatialAdaptiveObserver'
    """
    return get_method(name).build(model, noise, settings)


def method_names(role=None, online=None, calibrates=None, model=None):
    """Names of the registered methods, in registry order, optionally filtered.

    Parameters
    ----------
    role : str or tuple of str, optional
        Keep these roles (``"design"``, ``"paper"``, ``"reference"``).
    online : bool, optional
    calibrates : bool, optional
    model : plant.Model or plant.Payload, optional
        Keep the methods that run on it (:meth:`observers.Observer.runs_on`).

    Returns
    -------
    tuple of str

    Examples
    --------
    >>> from fmscal.observers import method_names
    >>> method_names(calibrates=True)[:2]
    ('adaptive', 'high-gain')
    >>> "max-likelihood" in method_names(calibrates=True)
    True
    """
    roles = (role,) if isinstance(role, str) else role
    return tuple(m.name for m in METHODS.values()
                 if (roles is None or m.role in roles) and (online is None or m.online == online)
                 and (calibrates is None or m.calibrates == calibrates)
                 and (model is None or m.cls.runs_on(model)))


def method_label(name):
    """How tables and figures show a method: its :attr:`Method.label` (``name`` itself if unregistered).

    Examples
    --------
    >>> from fmscal.observers import method_label
    >>> method_label("max-likelihood")
    'max-likelihood (the floor)'
    """
    method = METHODS.get(name)
    return name if method is None else method.label
