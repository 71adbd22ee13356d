"""The augmented EKF after Aghili, one filter on an error state for every model (filterpy and compiled, one
predict and one update for both), the separate-bias filter pieces, the noise level and the errors-in-variables
compensation.
"""

from ._filter import (filter_layout, input_layout, params_layout, initial_state, filter_step, bias_matrix,
    information_factor, information_pull, correction_limit, pack_lower, unpack_lower, cholesky, cholesky_apply,
    cholesky_solve, spd_inverse, solve_information, V0_SD, POSE_SD_FLOOR)
from ._noise_level import (NoiseLevel, NIS_DOF, DEFAULT_TOLERANCE, DEFAULT_Q_START, level_update)
from ._eiv import (EivCompensation, compensation_layout, regressor_step, copy_predict, error_variances,
    beta_from_copy)
from ._kalman import (predict, update, reset, symmetric)
from ._error_state import (error_step, wrench_noise, injection, whole_error_step, error_state_layout,
    error_params_layout, output_layout, copy_layout, eiv_copy)
from ._ekf import (AugmentedEKF, FilterRun)

__all__ = ["NoiseLevel", "EivCompensation", "predict", "update", "AugmentedEKF", "FilterRun"]
