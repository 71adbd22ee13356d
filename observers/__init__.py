"""Methods that estimate the calibration matrix ``S``, all behind one contract, :class:`Observer`.

:data:`METHODS` is the registry: every method by name, with how to build it.
"""

from fmscal.observers.adaptive import AdaptiveObserver, HighGainObserver, PaperAdaptiveObserver
from fmscal.observers.batch import LeastSquares, MaximumLikelihood
from fmscal.observers.core import (MAX_S0, Estimate, Observer, ObserverResult, RecursiveObserver, check_gains,
                                   double_pole_gains, settled)
from fmscal.observers.kalman import AugmentedEKF
from ._registry import FLOOR_METHOD, METHODS, Method, get_method, make_observer, method_label, method_names

__all__ = ["Observer", "RecursiveObserver", "Estimate", "ObserverResult", "settled", "AdaptiveObserver",
           "PaperAdaptiveObserver", "HighGainObserver", "AugmentedEKF", "LeastSquares", "MaximumLikelihood",
           "FLOOR_METHOD", "check_gains", "double_pole_gains", "METHODS", "Method", "get_method", "make_observer",
           "method_names", "method_label", "MAX_S0"]
