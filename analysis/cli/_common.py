"""What every ``fmscal`` command shares: the user-error type, the help's formatter and small input helpers."""

import argparse

import numpy as np

from fmscal.plant import SCENARIOS
from fmscal.plant.io import MAX_WRIST_MASS
from fmscal.plant.io import json_ready as strict
from fmscal.plant.numerics import FmscalError
from fmscal.plant.physics import MODELS

from fmscal.observers import METHODS

from .._comparison import case_scenario

__all__ = ["CliError", "Words", "HelpFormatter", "RawDescriptionHelpFormatter", "INERTIA_METAVAR", "position_values",
           "flag_payload", "positive", "strict", "add_scenarios_and_observers", "check_sizes",
           "check_seeds", "MAX_SEEDS"]

#: Most seeds a compare or sweep runs (each seed simulates every scenario).
MAX_SEEDS = 100_000


class CliError(FmscalError):
    """A user error: printed as one line, exit status 2."""


class Words(str):
    """A metavar printed as it is written, for a flag that takes one of a few fixed counts of values.

    argparse prints ``nargs="+"`` as ``V [V ...]``, which hides the count (``--inertia I [I ...]`` for one
    number or six): a ``Words`` metavar, ``"I_G | IXX IYY IZZ IXY IXZ IYZ"``, shows every form. A flag of
    one fixed count takes ``nargs=N`` and a tuple metavar, unless a wrong count is better told by the
    command (``--com X Y Z``: a spatial log's, where three numbers after ``--rho`` are named as such).
    """


class HelpFormatter(argparse.HelpFormatter):
    """argparse's formatter, printing a :class:`Words` metavar as it is written (usage and help alike)."""

    def _format_args(self, action, default_metavar):
        if isinstance(action.metavar, Words):
            return str(action.metavar)
        return super()._format_args(action, default_metavar)


class RawDescriptionHelpFormatter(HelpFormatter, argparse.RawDescriptionHelpFormatter):
    """:class:`HelpFormatter` with the description and epilog printed as written (``fmscal simulate``'s lists)."""


#: ``--inertia``'s values: one form per model, as each declares its inertia's entries (planar ``I_G``, spatial six).
INERTIA_METAVAR = Words(" | ".join(" ".join(m.inertia_names) for m in MODELS))


def position_values(name):
    """``nargs`` and ``metavar`` of ``--rho`` or ``--com`` (``name``): the names the model declares, as many as it
    declares. The count is checked by :func:`flag_payload`, not by argparse, so that the other case's flag with its
    own count (``--rho`` given three numbers on a spatial log) is told the flag it wants, not ``unrecognized
    arguments``."""
    model = next(m for m in MODELS if m.payload_position == name)
    return {"nargs": "+", "metavar": Words(" ".join(model.payload_position_names))}


#: What each payload's position vector is, in words (the models' :attr:`~fmscal.plant.Model.payload_position`).
POSITION_WORDS = {"rho": "the sensor's position from the centre of mass, body frame",
                  "com": "the centre of mass in the sensor frame"}


def position_flag(model, rho, com, what=None):
    """The payload's position vector from ``--rho`` or ``--com``: the one ``model`` declares, else a one-line error.

    ``--rho RX RY`` is the planar payload's (the paper's ``rho``, the sensor from the centre of mass), ``--com
    X Y Z`` the spatial one's (the centre of mass from the sensor, the opposite vector): a log given the
    other case's flag is told its own. ``what`` names the input (default: ``a <case> log``). None where
    neither is given.
    """
    given = {"rho": rho, "com": com}
    name = model.payload_position
    wrong = next((n for n, v in given.items() if n != name and v is not None), None)
    if wrong is not None:
        names = " ".join(model.payload_position_names)
        other = next(m for m in MODELS if m.payload_position == wrong)
        raise CliError(f"{what or 'a ' + model.name + ' log'} takes --{name} {names} (m, {POSITION_WORDS[name]}); "
                       f"--{wrong} is the {other.name} payload's ({POSITION_WORDS[wrong]})")
    return given[name]


def flag_payload(model, mass, inertia, position):
    """The payload of the model class ``model`` from ``--mass``, ``--inertia`` and ``--rho`` or ``--com``.

    ``inertia`` and ``position`` (the vector :attr:`fmscal.plant.Model.payload_position` names, its flag)
    must hold the numbers the model declares (:attr:`~fmscal.plant.Model.inertia_names`,
    :attr:`~fmscal.plant.Model.payload_position_names`); the payload class checks their values, its
    message turned into the flag's. Else a one-line :class:`CliError`.
    """
    position, inertia = list(position or ()), list(inertia or ())
    flag, names = f"--{model.payload_position}", model.payload_position_names
    if (len(position), len(inertia)) != (len(names), len(model.inertia_names)):
        others = " and ".join(f"--{m.payload_position} {' '.join(m.payload_position_names)} and --inertia "
                              f"{' '.join(m.inertia_names)} are for a {m.name} log" for m in MODELS if m is not model)
        raise CliError(f"a {model.name} log takes {flag} {' '.join(names)} ({len(names)} numbers, m) and "
                       f"--inertia {' '.join(model.inertia_names)} "
                       f"({len(model.inertia_names)} number{'s' if len(model.inertia_names) > 1 else ''}, kg m^2, "
                       f"about the centre of mass); got {len(position)} and {len(inertia)}"
                       + (f" ({others})" if others else ""))
    positive(mass, "--mass")
    try:
        return model.payload_from(mass, inertia, position)
    except FmscalError as err:                      # "inertia must be ...": the flag's name
        raise CliError(f"--{err}") from None


def add_max_mass(p, cases=""):
    """``--max-mass KG`` (``max_mass=`` of calibrate, identify_payload and fit_static), ``cases`` saying where."""
    p.add_argument("--max-mass", type=float, default=None, metavar="KG",
                   help=f"{cases}the heaviest payload taken, kg (default {MAX_WRIST_MASS:g}, what a wrist sensor "
                        "carries); a mass beyond it is refused as a unit slip")


def max_mass(args):
    """``--max-mass`` checked: None, or a positive number."""
    return None if args.max_mass is None else positive(args.max_mass, "--max-mass")


def positive(value, name):
    """``value`` if it is a positive finite number, else a :class:`CliError` naming ``name``."""
    if not np.isfinite(value) or value <= 0:
        raise CliError(f"{name} must be positive; got {value}")
    return value


def add_scenarios_and_observers(p, default_observers):
    """``--scenario`` and ``--observer`` (several names each), as compare and sweep take them."""
    p.add_argument("--scenario", nargs="+", default=["paper"], metavar="NAME",
                   help="one or more of: " + ", ".join(SCENARIOS) + ", or the spatial ones (fmscal simulate --help "
                        "lists them all); a method that does not run in 3D is reported not applicable there")
    p.add_argument("--observer", nargs="+", default=list(default_observers), metavar="NAME",
                   help="one or more of: " + ", ".join(METHODS) + f" (default: {' '.join(default_observers)})")


def check_sizes(scenarios, duration=None):
    """Refuse, before any work, a run whose simulated logs would exceed :data:`plant.scenarios._planar.MAX_SAMPLES`."""
    for name in scenarios:
        sc = case_scenario(name)
        (sc.with_(duration=duration) if duration is not None else sc).check_size()


def check_seeds(seed=None, seeds=None):
    """Refuse a negative ``--seed``, and a ``--seeds`` count outside 1 .. :data:`MAX_SEEDS`."""
    if seed is not None and seed < 0:
        raise CliError(f"--seed must be a non-negative integer; got {seed}")
    if seeds is not None and not 1 <= seeds <= MAX_SEEDS:
        raise CliError(f"--seeds must be at least 1 and at most {MAX_SEEDS}; got {seeds}")


def add_jobs(p):
    """The ``--jobs`` option of a command that runs on local worker processes."""
    p.add_argument("--jobs", type=int, default=-1, metavar="N", help="local worker processes (default -1: every core)")


def check_jobs(jobs):
    """Refuse a ``--jobs`` that is neither a positive count nor -1 (every core)."""
    if jobs == 0 or jobs < -1:
        raise CliError(f"--jobs must be a positive number of processes or -1 (every core); got {jobs}")
