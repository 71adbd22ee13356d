"""A stand-in for a running ros2_control ``force_torque_sensor_broadcaster`` with the gravity filter in its chain:
an rclpy node that declares the parameters of a release's definition files (tests/data/ros2_control/<release>/),
typed and ``read_only`` as they say, the filter's under ``sensor_filter_chain.filter1.params.``, as the
broadcaster does. ``python tests/ros2_standin.py [--name N] [--release kilted] [--no-filter]`` (the domain from
``ROS_DOMAIN_ID``); prints ``ready`` once its services are up and spins until stopped. ``--no-filter``: a chain
without the gravity filter (its ``tool.*`` undeclared).
"""

import argparse
import sys
from pathlib import Path

import rclpy
from rclpy.node import Node
from rcl_interfaces.msg import ParameterDescriptor

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_export import definitions  # noqa: E402

DATA = Path(__file__).resolve().parent / "data" / "ros2_control"
DEFAULTS = {"double": 0.0, "double_array": [0.0, 0.0, 0.0], "string": "", "bool": False, "integer": 0,
            "string_array": [""]}


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--name", default="force_torque_sensor_broadcaster")
    p.add_argument("--release", default="kilted")
    p.add_argument("--no-filter", action="store_true")
    args = p.parse_args()
    rclpy.init()
    node = Node(args.name)
    folder = DATA / args.release
    specs = dict(definitions(folder / "force_torque_sensor_broadcaster_parameters.yaml"))
    if not args.no_filter:
        specs.update({f"sensor_filter_chain.filter1.params.{k}": v for k, v in
                      definitions(folder / "gravity_compensation_filter_parameters.yaml").items()})
    for name, spec in specs.items():
        if spec["type"] not in DEFAULTS:              # a placeholder of the library's (type none): no parameter
            continue
        value = spec.get("default_value", DEFAULTS[spec["type"]])
        if spec["type"].startswith("double"):
            value = [float(v) for v in value] if isinstance(value, list) else float(value)
        if name.endswith("_frame") or name == "frame_id":
            value = "ft_sensor" if "sensor" in name or name == "frame_id" else "base_link"
        node.declare_parameter(name, value, ParameterDescriptor(read_only=bool(spec.get("read_only", False))))
    print("ready", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
