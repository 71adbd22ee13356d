"""Gain checks on python-control: poles of A - K C, observability, Lyapunov P."""

from dataclasses import dataclass

import numpy as np

from fmscal.plant import A_1, A_2, C_1, C_2
from fmscal.plant.numerics import as_finite_array, as_positive_scalar

__all__ = ["double_pole_gains", "check_gains", "GainReport", "SubsystemGains", "sampled_poles"]


def double_pole_gains(lam):
    """Injection gains placing both poles of each channel at ``-lam``.

    For the double integrator with position output, ``K = [2 lam, lam^2]^T``
    gives ``det(sI - A + K C) = (s + lam)^2``.

    Parameters
    ----------
    lam : float
        Pole magnitude in rad/s, positive.

    Returns
    -------
    K1 : ndarray, shape (2, 1)
        For the angular observer, eq. (6).
    K2 : ndarray, shape (4, 2)
        For the translational observer, eq. (7), decoupled in X and Y.

    Examples
    --------
    >>> from fmscal.observers import check_gains, double_pole_gains
    >>> K1, K2 = double_pole_gains(5.0)
    >>> K1.ravel().tolist()
    [10.0, 25.0]
    >>> check_gains(K1, K2).angular.poles.real.round(6).tolist()
    [-5.0, -5.0]
    """
    lam = as_positive_scalar(lam, "lam")
    K1 = np.array([[2 * lam], [lam ** 2]])
    K2 = np.zeros((4, 2))
    K2[0, 0] = K2[2, 1] = 2 * lam
    K2[1, 0] = K2[3, 1] = lam ** 2
    return K1, K2


@dataclass(frozen=True)
class SubsystemGains:
    """The gains of one subsystem (eq. (6): the angle; eq. (7): the position), as :func:`check_gains` finds them.

    Attributes
    ----------
    poles : ndarray
        The poles of ``A - K C``, sorted by real then imaginary part.
    n : int
        The subsystem's state size.
    obsv_rank : int
        The rank of ``obsv(A, C)``.
    observable, stable : bool
        Full rank; every pole in the open left half-plane.
    sym_eigs : ndarray
        The eigenvalues of the symmetric part of ``A - K C``.
    assumption_2_holds : bool
        Theorem 1's assumption 2 with ``P = I``: every ``sym_eigs`` negative (``V_1 = e'e/2`` decreasing).
    P : ndarray or None
        The Lyapunov ``P`` of ``(A-KC)' P + P (A-KC) = -I`` (None where ``A - K C`` is not stable).
    """

    poles: np.ndarray
    n: int
    obsv_rank: int
    observable: bool
    stable: bool
    sym_eigs: np.ndarray
    assumption_2_holds: bool
    P: np.ndarray = None

    def to_json(self):
        """The subsystem as JSON-ready values (``fmscal check-gains --json``): poles as ``[re, im]`` pairs."""
        return {"poles": [[complex(p).real, complex(p).imag] for p in self.poles], "observable": self.observable,
                "stable": self.stable, "sym_eigs": self.sym_eigs.tolist(),
                "assumption_2_holds": self.assumption_2_holds}


@dataclass(frozen=True)
class GainReport:
    """What :func:`check_gains` returns: the angular subsystem (eq. (6)) and the translational one (eq. (7)).

    Attributes
    ----------
    angular, translational : SubsystemGains
    """

    angular: SubsystemGains
    translational: SubsystemGains

    def to_json(self):
        """Both subsystems as JSON-ready values (``fmscal check-gains --json``)."""
        return {"angular": self.angular.to_json(), "translational": self.translational.to_json()}

    def __str__(self):
        lines = []
        for key in ("angular", "translational"):
            r = getattr(self, key)
            lines.append(f"{key} subsystem, eq. ({'6' if key == 'angular' else '7'}):")
            lines.append(f"  poles of A - K C: {_fmt(r.poles)}")
            lines.append(f"  observable (rank of obsv(A, C) = {r.obsv_rank} of {r.n}): "
                         f"{'yes' if r.observable else 'no'}")
            lines.append(f"  stable: {'yes' if r.stable else 'no'}")
            lines.append(f"  eigenvalues of the symmetric part of A - K C: {_fmt(r.sym_eigs)}")
            lines.append(f"  assumption 2 of Theorem 1 with P = I (V_1 = e'e/2 decreasing): "
                         f"{'holds' if r.assumption_2_holds else 'does NOT hold'}")
            if r.P is not None:
                eigenvalues = _fmt(np.linalg.eigvalsh(r.P))
                lines.append(f"  Lyapunov P of (A-KC)' P + P (A-KC) = -I: eigenvalues {eigenvalues}")
        return "\n".join(lines)


def _fmt(values):
    return "[" + ", ".join(f"{v.real:.4g}{'' if abs(v.imag) < 1e-12 else f'{v.imag:+.4g}j'}"
                           if np.iscomplexobj(v) else f"{v:.4g}" for v in values) + "]"


def _check(A, C, K):
    import control              # here, not at the top: it takes a second to import, and only checks need it
    F = A - K @ C
    poles = np.linalg.eigvals(F)
    poles = poles[np.lexsort((poles.imag, poles.real))]
    rank = int(np.linalg.matrix_rank(control.obsv(A, C)))
    stable = bool(np.all(poles.real < 0))
    sym_eigs = np.linalg.eigvalsh(F + F.T) / 2
    P = control.lyap(F.T, np.eye(len(A))) if stable else None
    return SubsystemGains(poles=poles, n=len(A), obsv_rank=rank, observable=rank == len(A), stable=stable,
                          sym_eigs=sym_eigs, assumption_2_holds=bool(np.all(sym_eigs < 0)), P=P)


def check_gains(K1, K2):
    """Check the injection gains of eq. (14) with python-control.

    Parameters
    ----------
    K1 : array_like, shape (2, 1)
    K2 : array_like, shape (4, 2)

    Returns
    -------
    GainReport
        For ``"angular"`` and ``"translational"``: ``poles`` of ``A - K C``,
        ``observable`` (rank of ``control.obsv``), ``stable``, ``sym_eigs``
        (eigenvalues of the symmetric part of ``A - K C``),
        ``assumption_2_holds`` (``V_1 = e^T e / 2`` decreases for every
        error, i.e. the symmetric part is negative definite: assumption 2 of
        Theorem 1 with ``P = I``), and ``P`` from ``control.lyap``.

    Examples
    --------
    >>> from fmscal.plant import PAPER_PAYLOAD
    >>> from fmscal.observers import PaperAdaptiveObserver, check_gains
    >>> paper = PaperAdaptiveObserver(PAPER_PAYLOAD)
    >>> report = check_gains(paper.K1, paper.K2)          # the paper's eq. (14) gains
    >>> report.angular.stable, report.angular.assumption_2_holds
    (True, False)
    """
    K1 = as_finite_array(K1, (2, 1), "K1")
    K2 = as_finite_array(K2, (4, 2), "K2")
    return GainReport(angular=_check(A_1, C_1, K1), translational=_check(A_2, C_2, K2))


def sampled_poles(K1, dt):
    """Poles of one channel ``A_1 - K_1 C_1`` sampled at ``dt``, by python-control.

    The sampled images ``exp(p dt)`` of the continuous poles: where the
    high-gain observer (:class:`observers.HighGainObserver`) places the
    eigenvalues of its discrete error recursion.

    Parameters
    ----------
    K1 : array_like, shape (2, 1)
    dt : float
        Sample time, s.

    Returns
    -------
    ndarray, shape (2,)
    """
    K1 = as_finite_array(K1, (2, 1), "K1")
    dt = as_positive_scalar(dt, "dt")
    import control              # slow to import (as above)
    closed = control.ss(A_1 - K1 @ C_1, np.zeros((2, 1)), C_1, 0)
    return np.sort_complex(control.sample_system(closed, dt).poles())
