"""Files in and out: logs and their truth sidecars, pose and joint tables, ROS bags, saved calibrations,
the noise and units a log shows.
"""

from ._files import (atomic_write, atomic_write_text, atomic_write_many, exclusive, claim_folder, not_a_file,
    OutputExistsError, not_an_output, LOCK_NAME)
from ._log import (Log, LogError, Truth, read_log, read_readings, read_truth, log_kind, csv_header, COLUMNS,
    SPATIAL_COLUMNS, READING_COLUMNS, QUATERNION_TOLERANCE, unit_quaternions, MIN_SAMPLES)
from ._noise import (estimate_noise, difference_noise, wrench_noise, reading_colour, colour_samples)
from ._units import (implied_scale, diagnose_units, UnitFinding, COUNTS)
from ._spatial_units import (UnitsError, check_spatial_log_units, check_poses_move, stalled_poses, check_gravity,
    check_table_units, check_imu_units, STALL_SPREAD, EARTH_G, MAX_WRIST_MASS, MAX_LEVER_ARM, MAX_ACCELERATION,
    MAX_STEP)
from ._calibration import (json_ready, Calibration, CalibrationFileError, NotSavedError, file_sha256, reading_sign,
    FORMAT, READINGS)
from ._pose_table import (PoseTable, read_pose_table, write_pose_table, is_pose_table, simulate_table, AttitudeLog,
    read_attitude_log, is_attitude_log, held_table, simulate_attitude_log, TABLE_COLUMNS, ATTITUDE_COLUMNS,
    MIN_POSES, HOLD_RATE, HOLD_WINDOW, MIN_HOLD)
from ._tf_chain import (chain_poses)
from ._kinematics import (RobotKinematics, joint_columns, read_joint_data, JointLog, read_joint_log)
from ._imu_log import (ImuLog, read_imu_log, IMU_COLUMNS)
from ._bag_write import write_bag, write_tf_bag
from ._bag import (BagError, import_bag, read_bag, format_report, WRENCH_TYPE, POSE_TYPES, JOINT_TYPE, TF_TYPE,
    MAX_WRENCH_GAP, MAX_TILT_DEG, MAX_OUT_OF_PLANE)

__all__ = ["json_ready", "write_bag", "write_tf_bag", "Log", "LogError", "Truth", "read_log", "read_readings",
           "read_truth", "log_kind", "unit_quaternions", "estimate_noise", "difference_noise", "wrench_noise",
           "reading_colour", "colour_samples", "diagnose_units", "UnitFinding",
           "UnitsError", "check_spatial_log_units", "check_poses_move", "stalled_poses", "STALL_SPREAD",
           "check_gravity",
           "check_table_units", "check_imu_units",
           "Calibration", "CalibrationFileError", "NotSavedError", "file_sha256", "reading_sign", "PoseTable",
           "read_pose_table",
           "write_pose_table", "is_pose_table", "simulate_table", "AttitudeLog", "read_attitude_log",
           "is_attitude_log", "held_table", "simulate_attitude_log", "chain_poses", "RobotKinematics",
           "read_joint_data", "JointLog", "read_joint_log", "csv_header", "ImuLog", "read_imu_log", "IMU_COLUMNS",
           "BagError", "import_bag", "read_bag", "format_report"]
