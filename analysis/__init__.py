"""Workflows on logs and scenarios, the paper's metric, plots, and the ``fmscal`` command line.

Everything the command line does is a call here, and the command line prints what it returns:
calibrate a sensor from a log, a pose table or joint angles (:func:`calibrate`, the files read by
:func:`read_data`), compare methods on identical data (:func:`compare`, :func:`summarise`), sweep
them over seeds and settings (:func:`sweep`), reproduce the paper's section 4 (:func:`reproduce`),
ablate the adaptive observer (:func:`ablation`), measure the speed (:func:`run_bench`), and score an
estimate with eq. (16) (:func:`calibration_error`), and write a payload as ros2_control's parameters
(:func:`ros2_control_parameters`). The command line is :mod:`fmscal.analysis.cli`.
"""

from ._metrics import (CONVERGENCE_THRESHOLD, block_errors, calibration_error, convergence_time, error_history,
                       tail_median, tail_seen)
from ._calibrate import (DEFAULT_MAX_LATENCY, DEFAULT_METHOD, TABLE_METHOD, DivergedError, OptionError, calibrate,
                         read_data)
from ._comparison import compare, summarise, summary_markdown
from ._sweep import sweep
from ._reproduce import PAPER_CLAIMS, reproduce
from ._ablation import ablation
from ._sensitivity import PARAMETERS, sensitivity, tolerable_error
from ._bench import BenchSettings, run_bench
from ._compensate import (CAUSAL_DELAY, CAUSAL_WINDOW, DRIFT_INTENSITY, FALSE_ALARM, Compensation, Compensator,
                          ContactSample, compensate)
from ._motion import ImuMotion, JointMotion, PoseMotion
from ._tool_change import TOOL_CHANGE, ToolChange
from ._export import (GRAVITY_FILTER, ROS2_CONTROL_RELEASES, DynamicsLeftOut, ExportError, Ros2ControlParameters,
                      dynamics_left_out, ros2_control_parameters)
from ._plots import plot_S_entries, plot_calibration, plot_comparison, plot_error_histories

__all__ = ["calibration_error", "block_errors", "error_history", "tail_median", "tail_seen", "convergence_time",
           "CONVERGENCE_THRESHOLD", "calibrate", "read_data", "DivergedError", "OptionError", "compare", "summarise",
           "summary_markdown", "sweep", "reproduce", "ablation", "sensitivity", "tolerable_error", "BenchSettings",
           "run_bench", "plot_S_entries", "plot_calibration", "plot_comparison", "plot_error_histories",
           "compensate", "Compensation", "Compensator", "ContactSample", "PoseMotion", "JointMotion", "ImuMotion",
           "CAUSAL_WINDOW", "CAUSAL_DELAY", "FALSE_ALARM", "DRIFT_INTENSITY", "ToolChange", "TOOL_CHANGE",
           "ros2_control_parameters", "Ros2ControlParameters", "DynamicsLeftOut", "dynamics_left_out", "ExportError",
           "ROS2_CONTROL_RELEASES", "GRAVITY_FILTER"]
