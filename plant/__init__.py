"""The physics and the sensor: eq. (1) and Newton-Euler in 3D, the models, the calibration matrix, logs, scenarios."""

from fmscal.plant.io import (COLUMNS, READING_COLUMNS, BagError, Calibration, CalibrationFileError, Log, LogError,
                             Truth, estimate_noise, file_sha256, import_bag, read_bag, read_log, read_readings,
                             read_truth)
from fmscal.plant.numerics import FmscalError, compiler
from fmscal.plant.physics import (A_1, A_2, B_1, B_2, C_1, C_2, PAPER_PAYLOAD, CalibrationSchedule, Excitation, Model,
                                  Multisine, NoiseSpec, PaperWrench, Payload, PayloadModel, PayloadStd, PlanarModel,
                                  S_from_phi, SampledWrench,
                                  SingularCalibrationError, SpatialModel, SpatialPayload, acceleration, as_model,
                                  check_calibration, input_matrix, integrate, phi_1, phi_2, regressors, rk4_step,
                                  state_derivative)
from fmscal.plant.scenarios import (PAPER_S, SCENARIOS, SPATIAL_SCENARIOS, TABLE_1, Scenario, SpatialScenario, draw_S,
                                    get_scenario)

__all__ = [
    "A_1", "A_2", "B_1", "B_2", "C_1", "C_2", "acceleration", "input_matrix",
    "phi_1", "phi_2", "regressors", "S_from_phi", "state_derivative",
    "Excitation", "Multisine", "PaperWrench", "SampledWrench",
    "Calibration", "CalibrationFileError", "file_sha256",
    "BagError", "import_bag", "read_bag",
    "COLUMNS", "READING_COLUMNS", "Log", "LogError", "Truth", "read_log", "read_readings", "read_truth",
    "PAPER_PAYLOAD", "Payload", "PayloadStd", "SpatialPayload", "Model", "PlanarModel", "SpatialModel", "PayloadModel",
    "as_model",
    "SPATIAL_SCENARIOS", "SpatialScenario",
    "PAPER_S", "SCENARIOS", "TABLE_1", "Scenario", "draw_S", "get_scenario",
    "CalibrationSchedule", "NoiseSpec", "SingularCalibrationError", "check_calibration",
    "integrate", "rk4_step", "estimate_noise", "compiler", "FmscalError",
]
