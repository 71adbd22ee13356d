"""Observers that estimate the motion and the calibration matrix ``S``."""

from .adaptive import AdaptiveObserver
from .highgain import HighGainObserver
from .least_squares import LeastSquares
from .ekf import AugmentedEKF
from .base import Observer, ObserverResult, settled
from .gains import check_gains, double_pole_gains

__all__ = ["Observer", "ObserverResult", "settled", "AdaptiveObserver", "HighGainObserver", "AugmentedEKF", "LeastSquares", "check_gains", "double_pole_gains"]
