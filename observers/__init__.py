"""Methods that estimate the calibration matrix ``S``, all behind one contract, :class:`Observer`.

:data:`METHODS` is the registry: every method by name, with how to build it.
"""

from fmscal.observers.core._base import MAX_S0, Estimate, Observer, RecursiveObserver
from fmscal.observers.core._result import ObserverResult
from fmscal.observers.core._convergence import settled
from fmscal.observers.adaptive._adaptive import AdaptiveObserver
from fmscal.observers.adaptive._paper import PaperAdaptiveObserver
from fmscal.observers.adaptive._highgain import HighGainObserver
from fmscal.observers.batch._least_squares import LeastSquares
from fmscal.observers.kalman._ekf import AugmentedEKF
from fmscal.observers.core._gains import check_gains, double_pole_gains
from fmscal.observers.batch._floor import MaximumLikelihood
from fmscal.observers._registry import (FLOOR_METHOD, METHODS, Method, get_method, make_observer, method_label,
                                        method_names)

__all__ = ["Observer", "RecursiveObserver", "Estimate", "ObserverResult", "settled", "AdaptiveObserver",
           "PaperAdaptiveObserver", "HighGainObserver", "AugmentedEKF", "LeastSquares", "MaximumLikelihood",
           "FLOOR_METHOD", "check_gains", "double_pole_gains", "METHODS", "Method", "get_method", "make_observer",
           "method_names", "method_label", "MAX_S0"]
