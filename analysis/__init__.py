"""Metrics, comparison, plots and the ``fmscal`` command line."""

from .metrics import CONVERGENCE_THRESHOLD, calibration_error, convergence_time, error_history

__all__ = ["calibration_error", "error_history", "convergence_time", "CONVERGENCE_THRESHOLD"]
