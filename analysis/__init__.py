"""Metrics, comparison, plots, the calibration workflow and the ``fmscal`` command line."""

from fmscal.analysis._metrics import (CONVERGENCE_THRESHOLD, block_errors, calibration_error, convergence_time,
                                      error_history)
from fmscal.analysis._calibrate import (DEFAULT_MAX_LATENCY, DEFAULT_METHOD, TABLE_METHOD, DivergedError, OptionError,
                                        calibrate, read_data)

__all__ = ["calibration_error", "block_errors", "error_history", "convergence_time", "CONVERGENCE_THRESHOLD",
           "calibrate", "read_data", "DivergedError", "OptionError"]
