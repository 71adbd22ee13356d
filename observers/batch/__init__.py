"""Whole-log estimates: least squares (one entry, two engines: double-integrated windows and smoothed inverse
dynamics), the maximum-likelihood floor (one entry: the exact filter on a model linear in its channels, the
filter linearised about the smoothed motion on any model), cluster-robust covariances and the pose stream's latency.
"""

from ._cluster_covariance import (weighted_fit, pseudo_inverse, sandwich, small_sample_factor, correlation_time,
    block_length, time_blocks, few_blocks, hotelling, MIN_BLOCKS)
from ._inverse_dynamics import (InverseDynamicsFit, fit_inverse_dynamics, fit_readings, describe_direction,
    UNDETERMINED_STD, READING_NAMES, nominal_motion, smoothed_channels, needed_wrench, needed_wrenches, reading_rate)
from ._least_squares import (LeastSquares, InverseDynamicsLeastSquares, SpatialLeastSquares, FitReport, phi_to_S_map,
                             EXCITATION_COND_LIMIT, CONSISTENCY_RATIO_LIMIT, LEAST_SQUARES_ENGINES)
from ._latency import (estimate_latency, LatencyEstimate, fit_latency, given_latency_warnings, AGREEMENT_SIGMAS,
                       CURVATURE_SIGMAS)
from ._payload_sensitivity import (PayloadSensitivity, payload_sensitivity)
from ._max_likelihood import (MaximumLikelihoodFit, fit_max_likelihood, log_steps)
from ._linearised_floor import (fit_linearised, undetermined_directions, configuration_residuals, error_layout)
from ._floor import (MaximumLikelihood)

__all__ = ["InverseDynamicsFit", "fit_inverse_dynamics", "fit_readings", "describe_direction", "LeastSquares",
           "InverseDynamicsLeastSquares", "FitReport", "estimate_latency", "LatencyEstimate", "MaximumLikelihoodFit",
           "fit_max_likelihood", "fit_linearised", "undetermined_directions", "MaximumLikelihood", "PayloadSensitivity",
           "payload_sensitivity"]
