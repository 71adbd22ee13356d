"""The ROS 2 node ``fmscal_compensator`` (``fmscal ros2``): the contact wrench live, on topics.

It subscribes to a force-moment sensor's raw ``geometry_msgs/WrenchStamped`` and to one motion source (a
``PoseStamped`` of the sensor frame, ``JointState`` with a URDF, or an ``Imu`` on the tool), matches them by
their header stamps, and publishes :func:`fmscal.analysis.Compensator`'s contact wrench with the reading's
stamp, its covariance, a flag per output, and diagnostics that count every reading by its fate; services tare,
identify the payload (in a process of its own, cancellable), save and reload the calibration.
:func:`push_parameters` sets an exported payload on a running ros2_control broadcaster.
The guide page "On a running robot" (docs/guide/robot.md) lists the topics, parameters and services.

rclpy is imported when the node starts, not with this package: the wheels of the extra ``[ros2]``
(``pip install "fmscal[ros2]"``), or a system ROS 2's rclpy.
"""

from ._parameters import (MOTION_SOURCES, NODE_NAME, OUTPUT_FRAMES, PARAMETERS, QOS, Parameter, Ros2Error, Settings,
                          settings)
from ._pipeline import FLAGS, LEVELS, STATES, WITHHELD, Output, Pipeline, Snapshot, fit_held, sensor_pose
from ._node import spin, unknown_parameters
from ._push import push_parameters, pushed_line
from ._rclpy import INSTALL

__all__ = ["spin", "Pipeline", "settings", "sensor_pose", "PARAMETERS", "Parameter", "NODE_NAME", "STATES",
           "LEVELS", "WITHHELD", "FLAGS", "Snapshot", "Output", "fit_held", "unknown_parameters", "Ros2Error",
           "push_parameters", "pushed_line"]
