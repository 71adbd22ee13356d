"""The physics and the sensor: eq. (1) and Newton-Euler in 3D, the models, the calibration matrix, logs, scenarios."""

from fmscal.plant.physics._dynamics import (A_1, A_2, B_1, B_2, C_1, C_2, acceleration, input_matrix,
                       phi_1, phi_2, regressors, S_from_phi, state_derivative)
from fmscal.plant.physics._excitation import Excitation, Multisine, PaperWrench, SampledWrench
from fmscal.plant.io._calibration import Calibration, CalibrationFileError, file_sha256
from fmscal.plant.io._bag import BagError, import_bag, read_bag
from fmscal.plant.io._log import COLUMNS, READING_COLUMNS, Log, LogError, Truth, read_log, read_readings, read_truth
from fmscal.plant.physics._payload import PAPER_PAYLOAD, Payload
from fmscal.plant.physics._rigid_body import SpatialPayload
from fmscal.plant.physics._model import Model, PlanarModel, SpatialModel, as_model
from fmscal.plant.scenarios._spatial import SPATIAL_SCENARIOS, SpatialScenario
from fmscal.plant.scenarios._planar import PAPER_S, SCENARIOS, TABLE_1, Scenario, draw_S, get_scenario
from fmscal.plant.physics._sensor import CalibrationSchedule, NoiseSpec, SingularCalibrationError, check_calibration
from fmscal.plant.physics._simulate import integrate, rk4_step
from fmscal.plant.io._noise import estimate_noise
from fmscal.plant.numerics._errors import FmscalError
from fmscal.plant.numerics._compile import compiler

__all__ = [
    "A_1", "A_2", "B_1", "B_2", "C_1", "C_2", "acceleration", "input_matrix",
    "phi_1", "phi_2", "regressors", "S_from_phi", "state_derivative",
    "Excitation", "Multisine", "PaperWrench", "SampledWrench",
    "Calibration", "CalibrationFileError", "file_sha256",
    "BagError", "import_bag", "read_bag",
    "COLUMNS", "READING_COLUMNS", "Log", "LogError", "Truth", "read_log", "read_readings", "read_truth",
    "PAPER_PAYLOAD", "Payload", "SpatialPayload", "Model", "PlanarModel", "SpatialModel", "as_model",
    "SPATIAL_SCENARIOS", "SpatialScenario",
    "PAPER_S", "SCENARIOS", "TABLE_1", "Scenario", "draw_S", "get_scenario",
    "CalibrationSchedule", "NoiseSpec", "SingularCalibrationError", "check_calibration",
    "integrate", "rk4_step", "estimate_noise", "compiler", "FmscalError",
]
