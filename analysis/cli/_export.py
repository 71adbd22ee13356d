"""``fmscal export``: a payload as another tool's parameters (``ros2-control``: ros2_controllers' force-torque
broadcaster and control_toolbox's gravity compensation filter, :func:`fmscal.analysis.ros2_control_parameters`)."""

import sys

from .._export import GRAVITY_FILTER, ros2_control_parameters
from ..ros2 import push_parameters, pushed_line
from ._common import CliError
from ._files import check_outputs

__all__ = ["add_export"]


def add_export(sub):
    """Add ``fmscal export`` and its targets to the subcommands ``sub``."""
    p = sub.add_parser("export", help="write a payload as another tool's parameters (ros2-control)",
                       description="Write a payload saved by fmscal identify-payload --save as the parameters of "
                                   "another tool.")
    targets = p.add_subparsers(dest="target", required=True, metavar="TARGET")
    r = targets.add_parser("ros2-control", help="force_torque_sensor_broadcaster with the gravity compensation "
                                                "filter (ROS 2 Jazzy, Kilted)",
                           description="Write the parameters of ros2_controllers' force_torque_sensor_broadcaster "
                                       f"with control_toolbox's {GRAVITY_FILTER} in its sensor_filter_chain: the "
                                       "tool's mass, centre of mass (the sensor's axes) and gravity, and the "
                                       "broadcaster's offset and multiplier (the reading's sign and gains). The "
                                       "file opens with what the chain cannot carry (cross-talk, the dynamics).")
    r.add_argument("payload", metavar="PAYLOAD.json", help="a payload saved by fmscal identify-payload --save")
    r.add_argument("--sensor-frame", required=True, metavar="NAME",
                   help="tf's frame of the sensor's own axes (the broadcaster's frame_id and the filter's "
                        "sensor_frame)")
    r.add_argument("--world-frame", required=True, metavar="NAME",
                   help="tf's frame whose axes the payload's poses were recorded in (the robot's base): gravity's")
    r.add_argument("--controller", default="force_torque_sensor_broadcaster", metavar="NAME",
                   help="the broadcaster's name in the controller manager (default force_torque_sensor_broadcaster)")
    r.add_argument("--sensor-name", metavar="NAME", help="the broadcaster's sensor_name (its state interfaces' "
                                                         "prefix); left out by default")
    r.add_argument("--calibration", metavar="CAL.json",
                   help="the sensor's calibration S where it is not the identity: its diagonal joins the "
                        "multipliers, and what its cross-talk leaves is stated")
    r.add_argument("--log", metavar="LOG.csv",
                   help="a spatial log of the tool's motion: state the dynamics the static filter leaves there "
                        "(N, N m)")
    r.add_argument("--out", metavar="PARAMS.yaml", help="the parameter file to write (default: print it)")
    r.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    r.add_argument("--push", action="store_true",
                   help="also set the run-time parameters (tool.*, offset.*, multiplier.*) on the running "
                        "broadcaster --controller (its node at the root; the domain ROS_DOMAIN_ID's), atomically: "
                        "all or none (rclpy: pip install \"fmscal[ros2]\")")
    r.add_argument("--push-timeout", type=float, default=5.0, metavar="S",
                   help="s to wait for the broadcaster's parameter service, and for its answer (default 5)")
    r.set_defaults(func=cmd_export_ros2_control)


def cmd_export_ros2_control(args):
    """``fmscal export ros2-control``: print or write what :func:`ros2_control_parameters` returns."""
    if args.out is not None and not args.out.endswith((".yaml", ".yml")):
        raise CliError(f"--out must end in .yaml; got {args.out}")
    check_outputs([(args.out, "--out")], [(args.payload, "the payload"), (args.calibration, "the --calibration "
                                                                                            "file"),
                                          (args.log, "the log")], overwrite=args.overwrite)
    exported = ros2_control_parameters(args.payload, args.sensor_frame, args.world_frame, controller=args.controller,
                                       calibration=args.calibration, sensor_name=args.sensor_name, log=args.log)
    if args.out is None:
        sys.stdout.write(exported.to_yaml())
    else:
        exported.save(args.out)
        for note in exported.notes:
            print(f"note: {note}")
        print(f"wrote {args.out} (the parameters of {args.controller})")
    if args.push:
        node = "/" + args.controller.lstrip("/")
        print(pushed_line(node, push_parameters(exported, node=node, timeout=args.push_timeout)))
