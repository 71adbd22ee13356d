"""Methods that estimate the calibration matrix ``S``, all behind one contract, :class:`Observer`.

:data:`METHODS` is the registry: every method by name, with how to build it.
"""

from .base import MAX_S0, Estimate, Observer, RecursiveObserver
from .result import ObserverResult
from .convergence import settled
from .adaptive import AdaptiveObserver
from .adaptive_paper import PaperAdaptiveObserver
from .highgain import HighGainObserver
from .least_squares import LeastSquares
from .ekf import AugmentedEKF
from .gains import check_gains, double_pole_gains
from .floor import MaximumLikelihood
from .registry import FLOOR_METHOD, METHODS, Method, get_method, make_observer, method_label, method_names

__all__ = ["Observer", "RecursiveObserver", "Estimate", "ObserverResult", "settled", "AdaptiveObserver",
           "PaperAdaptiveObserver", "HighGainObserver", "AugmentedEKF", "LeastSquares", "MaximumLikelihood",
           "FLOOR_METHOD", "check_gains", "double_pole_gains", "METHODS", "Method", "get_method", "make_observer",
           "method_names", "method_label", "MAX_S0"]
