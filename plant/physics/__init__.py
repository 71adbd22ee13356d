"""The physics: the paper's planar eq. (1), Newton-Euler of one rigid body in 3D, the payload, the sensor's
model ``w = S (w_hat - b)``, the models that package them, integration and excitation.
"""

from ._payload import (Payload, PAPER_PAYLOAD)
from ._sensor import (CalibrationSchedule, NoiseSpec, SingularCalibrationError, check_calibration)
from ._dynamics import (input_matrix, acceleration, state_derivative, A_1, C_1, B_1, A_2, C_2, B_2, regressors,
    phi_1, phi_2, S_from_phi)
from ._rigid_body import (regressor, gravity_jacobian, inertia_matrix, INERTIA_NAMES, SpatialPayload, PayloadSymbols,
                          GRAVITY,
                          quaternion_multiply, quaternion_conjugate, rotation_matrix, rotation_matrices,
                          unit_quaternions, sign_continuous,
                          QUATERNION_TOLERANCE, sensor_wrench, body_acceleration, prescribed_motion, skew)
from ._simulate import (integrate, rk4_step)
from ._excitation import (Excitation, PaperWrench, Multisine, SampledWrench)
from ._differentiate import (spatial_motion, smoothed_state, edge, ORDER)
from ._model import (Model, PlanarModel, SpatialModel, PayloadModel, MODELS, as_model, model_for_columns,
                     find_model)
from ._payload_std import (PayloadStd, PayloadStdError, DEFAULT_MASS_STD, DEFAULT_COM_STD, DEFAULT_INERTIA_STD,
    DEFAULT_GRAVITY_STD)

__all__ = ["Payload", "CalibrationSchedule", "NoiseSpec", "SingularCalibrationError", "check_calibration",
           "input_matrix", "acceleration", "state_derivative", "regressors", "phi_1", "phi_2", "S_from_phi",
           "regressor", "gravity_jacobian", "inertia_matrix", "SpatialPayload", "quaternion_multiply",
           "quaternion_conjugate",
           "rotation_matrix", "rotation_matrices", "unit_quaternions", "sign_continuous", "sensor_wrench",
           "body_acceleration", "prescribed_motion", "skew",
           "integrate", "rk4_step", "Excitation", "PaperWrench", "Multisine", "SampledWrench", "spatial_motion",
           "smoothed_state", "Model", "PlanarModel", "SpatialModel", "PayloadModel", "MODELS", "as_model",
           "PayloadStd", "find_model"]
