"""``fmscal ros2``: the ROS 2 node, its ROS arguments handed to rclpy."""

import argparse

from ..ros2 import NODE_NAME, spin
from ._files import check_inputs

__all__ = ["add_ros2"]


def add_ros2(sub):
    p = sub.add_parser("ros2", help="the ROS 2 node: the contact wrench of a live sensor on topics",
                       description=f"Start the ROS 2 node {NODE_NAME}: it compensates a WrenchStamped stream "
                                   "with a saved calibration and one motion source (a pose, joint states with a "
                                   "URDF, or an IMU), and publishes the contact wrench with its covariance and "
                                   "diagnostics. Parameters by --ros-args -p name:=value or a params YAML "
                                   "(docs/guide/robot.md lists them). Needs rclpy: pip install \"fmscal[ros2]\", "
                                   "or a sourced ROS 2.")
    p.add_argument("--params-file", metavar="FILE.yaml", help="a ROS 2 params YAML (the node's name as its key, or "
                   "/**)")
    p.add_argument("--ros-args", nargs=argparse.REMAINDER, default=[], metavar="ARG",
                   help="everything after it goes to rclpy: -p name:=value, --params-file FILE, -r remappings")
    # ~/save writes save_path as often as it is called: the node replaces its own file
    p.set_defaults(func=cmd_ros2, overwrite=True)


def cmd_ros2(args):
    files = [args.params_file] + [v for k, v in zip(args.ros_args, args.ros_args[1:]) if k == "--params-file"]
    check_inputs([(f, "the params file") for f in files])
    ros_args = ["--ros-args"]
    if args.params_file is not None:
        ros_args += ["--params-file", args.params_file]
    spin(ros_args + list(args.ros_args))
