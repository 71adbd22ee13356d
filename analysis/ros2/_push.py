"""A payload pushed to a running ros2_control broadcaster: its run-time parameters set over
``rcl_interfaces/SetParametersAtomically``.

The export (:func:`fmscal.analysis.ros2_control_parameters`) writes a parameter file for a broadcaster not yet
started; a running one reads again ``tool.*`` of its gravity filter and its ``offset.*`` and ``multiplier.*``
(:meth:`fmscal.analysis.Ros2ControlParameters.runtime`), and keeps its frames (``read_only``). Those are set
here in one atomic call: all of them, or none and the controller's reason.
"""

import os

from ._parameters import FULL_NAME, Ros2Error
from ._rclpy import ros

__all__ = ["push_parameters", "pushed_line"]


def push_parameters(exported, node=None, timeout=5.0, domain_id=None):
    """Set an export's run-time parameters on a running broadcaster, atomically.

    Parameters
    ----------
    exported : fmscal.analysis.Ros2ControlParameters
        What :func:`fmscal.analysis.ros2_control_parameters` returned.
    node : str, optional
        The broadcaster's node (``/namespace/name``); default the export's controller name, at the root.
    timeout : float
        s to wait for the node's parameter service, and again for its answer.
    domain_id : int, optional
        The ROS domain; default ``ROS_DOMAIN_ID``'s.

    Returns
    -------
    dict
        ``{dotted name: value}`` of the parameters set.

    Raises
    ------
    Ros2Error
        No rclpy; a node name that is not one (a wildcard); no such node answering within ``timeout``; the node
        refused the parameters (its reason, and none of them set). One line each.
    """
    controller, values = exported.runtime()
    target = node if node is not None else "/" + controller.lstrip("/")
    if not (isinstance(target, str) and FULL_NAME.match(target)):
        raise Ros2Error(f"the broadcaster's node must be a name such as /force_torque_sensor_broadcaster (no "
                        f"wildcard); got {target!r}")
    if not (isinstance(timeout, (int, float)) and timeout > 0):
        raise Ros2Error(f"timeout must be a positive number of seconds; got {timeout!r}")
    r = ros()
    from rcl_interfaces.srv import SetParametersAtomically
    context = r.Context()
    r.rclpy.init(context=context, **({} if domain_id is None else {"domain_id": int(domain_id)}))
    pusher = None
    try:
        pusher = r.Node(f"fmscal_push_{os.getpid()}", context=context)
        client = pusher.create_client(SetParametersAtomically, f"{target}/set_parameters_atomically")
        if not client.wait_for_service(timeout_sec=float(timeout)):
            raise Ros2Error(f"no node {target} answers set_parameters_atomically within {timeout:g} s: is the "
                            "broadcaster loaded (ros2 control list_controllers), under that name?")
        request = SetParametersAtomically.Request(
            parameters=[r.Parameter(name, value=value).to_parameter_msg() for name, value in values.items()])
        future = client.call_async(request)
        executor = r.Single(context=context)
        executor.add_node(pusher)
        executor.spin_until_future_complete(future, timeout_sec=float(timeout))
        if not future.done():
            raise Ros2Error(f"{target} did not answer set_parameters_atomically within {timeout:g} s")
        result = future.result().result
        if not result.successful:
            reason = " ".join((result.reason or "no reason given").split())
            raise Ros2Error(f"{target} refused the parameters, none set: {reason}")
        return values
    finally:
        if pusher is not None:
            pusher.destroy_node()
        r.rclpy.try_shutdown(context=context)


def pushed_line(node, pushed):
    """One line saying what :func:`push_parameters` set on ``node``."""
    tool = {k.rsplit(".params.", 1)[-1]: v for k, v in pushed.items() if ".params.tool." in k}
    return (f"pushed {len(pushed)} parameters to {node}: tool.mass {tool['tool.mass']:.6g} kg, tool.CoG "
            + " ".join(f"{v:.6g}" for v in tool["tool.CoG"]) + " m, and the offsets and multipliers")
