"""``fmscal import``: a ROS bag (ROS 1, or ROS 2 MCAP / sqlite3) into the log format."""

import json
import os
import sys
from pathlib import Path

import numpy as np

from fmscal.plant.io import RobotKinematics, atomic_write_many, format_report, import_bag
from fmscal.plant.physics import PlanarModel, SpatialModel

from ._common import CliError, Words, strict
from ._files import check_inputs, check_outputs


def add_import(sub):
    p = sub.add_parser("import", help="read a ROS bag into a log (LOG.csv and LOG.import.json)",
                       description="Read a ROS 2 bag (its folder, or its .mcap or .db3 file) or a ROS 1 .bag "
                                   "with rosbags (pip install 'fmscal[ros]'): the sensor as "
                                   "geometry_msgs/WrenchStamped (M = torque.z, fx = force.x, fy = force.y), the "
                                   "pose as PoseStamped, TransformStamped or nav_msgs/Odometry (theta the yaw, "
                                   "unwrapped); with --spatial all six components and the whole pose. Times are "
                                   "the header stamps, t = 0 at the first wrench sample; "
                                   "each pose goes to the nearest wrench sample. Writes the log, the sidecar "
                                   "LOG.import.json of what was imported, and prints the import report.")
    p.add_argument("bag", metavar="BAG", help="a ROS 2 bag's folder, its .mcap or .db3 file, or a ROS 1 .bag")
    p.add_argument("--wrench-topic", required=True, metavar="TOPIC", help="the sensor's WrenchStamped topic")
    p.add_argument("--pose-topic", required=True, metavar="TOPIC",
                   help="the payload's PoseStamped, TransformStamped or Odometry topic")
    p.add_argument("--out", required=True, metavar="LOG.csv",
                   help="the log to write; the sidecar LOG.import.json goes beside it")
    p.add_argument("--pose-offset", type=float, nargs="+", default=None, metavar=Words("DX DY | DX DY DZ"),
                   help="planar DX DY: the tracked marker frame's origin relative to the payload's centre of mass, "
                        "body frame, m; with --spatial DX DY DZ: the tracked frame's origin from the sensor point, "
                        "sensor axes, m (default zeros)")
    p.add_argument("--spatial", action="store_true",
                   help="keep the whole pose and all six wrench components: a spatial log "
                        "(t,qw,qx,qy,qz,x,y,z,tx,ty,tz,fx,fy,fz) of a 6-axis sensor")
    p.add_argument("--urdf", metavar="ROBOT.urdf",
                   help="the pose topic is the arm's sensor_msgs/JointState: the pose of --frame by forward "
                        "kinematics (pinocchio: pip install \"fmscal[robot]\"); implies --spatial")
    p.add_argument("--frame", metavar="FRAME",
                   help="the sensor's frame: in the URDF (with --urdf), or in the transform tree (with --parent)")
    p.add_argument("--parent", metavar="FRAME",
                   help="the pose topic is /tf (tf2_msgs/TFMessage, with /tf_static where the bag has it): the "
                        "pose of --frame in this frame, the chain of transforms composed; implies --spatial")
    p.add_argument("--start", type=float, metavar="S", help="keep stamps from S s after the first wrench stamp")
    p.add_argument("--end", type=float, metavar="S", help="keep stamps up to S s after the first wrench stamp")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out and its sidecar")
    p.add_argument("--json", action="store_true", help="print the import report as one JSON object")
    p.set_defaults(func=cmd_import)


def cmd_import(args):
    check_inputs([(args.bag, "the bag"), (args.urdf, "the --urdf file")], folder_ok=("the bag",))
    out = Path(args.out)
    if out.suffix != ".csv":
        raise CliError(f"--out must end in .csv; got {out}")
    sidecar = out.with_suffix(".import.json")
    bag = Path(args.bag)
    if bag.is_dir() and any(_inside(f, bag) for f in (out, sidecar)):
        raise CliError(f"--out {out} would write into the bag {bag}; choose another path")
    check_outputs([(out, "--out"), (sidecar, "--out's sidecar")], [(bag, "the bag")], overwrite=args.overwrite)
    if args.urdf is not None and args.parent is not None:
        raise CliError("--urdf (joint angles) and --parent (a transform tree) are two sources of the pose; give one")
    if (args.urdf is not None or args.parent is not None) != (args.frame is not None):
        raise CliError("--frame goes with --urdf (the sensor's frame in the URDF) or --parent (the frame whose pose "
                       "in the tree is wanted)")
    kinematics, tf_frames = None, None
    if args.parent is not None:
        if args.pose_offset is not None:
            raise CliError("--pose-offset is not taken with --parent: name the sensor's own frame with --frame")
        tf_frames, args.spatial = (args.parent, args.frame), True
    if args.urdf is not None:
        if args.pose_offset is not None:
            raise CliError("--pose-offset is not taken with --urdf: name the sensor's own frame with --frame")
        kinematics, args.spatial = RobotKinematics(args.urdf, args.frame), True
    # what --spatial (which --urdf and --parent set) makes of the import: the model of the log it writes, whose
    # pose's position columns are --pose-offset's entries, and how a message names the choice
    model, flag = {False: (PlanarModel, ""), True: (SpatialModel, " with --spatial")}[bool(args.spatial)]
    n = len(model.position_names)
    offset = tuple(args.pose_offset) if args.pose_offset is not None else (0.0,) * n
    if len(offset) != n or not all(np.isfinite(v) for v in offset):
        raise CliError(f"--pose-offset must be {n} finite numbers in m{flag}; got {list(offset)}")
    log, report = import_bag(bag, args.wrench_topic, args.pose_topic, offset, args.start, args.end,
                             spatial=args.spatial, kinematics=kinematics, tf_frames=tf_frames)
    text = json.dumps(strict({"log": out.name, "samples": len(log), "duration_s": log.duration,
                              "pose_measurements": int(log.has_pose.sum()), **report}), indent=2, allow_nan=False)
    # both or neither: the sidecar first, the log last (plant.io.atomic_write_many)
    atomic_write_many([(sidecar, lambda tmp: Path(tmp).write_text(text + "\n")), (out, log.write)])
    for warning in report["warnings"]:
        print(f"fmscal import: warning: {warning}", file=sys.stderr)
    if args.json:
        print(json.dumps(strict(report), allow_nan=False))
        return
    print(format_report(report))
    print(f"wrote {out} ({len(log)} samples, {log.duration:g} s, {int(log.has_pose.sum())} poses) and {sidecar}")


def _inside(f, folder):
    """True if ``f`` would be written inside the bag's folder."""
    if not folder.is_dir():
        return False
    return Path(os.path.realpath(folder)) in Path(os.path.realpath(f)).parents
