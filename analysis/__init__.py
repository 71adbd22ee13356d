"""Metrics, comparison, plots and the ``fmscal`` command line."""

from ._metrics import CONVERGENCE_THRESHOLD, block_errors, calibration_error, convergence_time, error_history

__all__ = ["calibration_error", "block_errors", "error_history", "convergence_time", "CONVERGENCE_THRESHOLD"]
