"""rclpy and the ROS 2 messages the node and the push use, imported when they run (not with the package)."""

from types import SimpleNamespace

from ._parameters import Ros2Error

__all__ = ["ros", "INSTALL"]

#: How to get rclpy, as the one-line error says where it is missing.
INSTALL = 'pip install "fmscal[ros2]" (-e ".[ros2]" in a clone), or source a ROS 2 install (Humble, Jazzy)'


def ros():
    """rclpy and the messages the node uses, imported now; a one-line :class:`Ros2Error` where missing."""
    try:
        import rclpy
        import rclpy.node
        from rclpy.context import Context
        from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
        from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
        from rclpy.parameter import Parameter
        from rclpy.qos import QoSProfile, ReliabilityPolicy, HistoryPolicy, DurabilityPolicy
        from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
        from geometry_msgs.msg import PoseStamped, WrenchStamped
        from sensor_msgs.msg import Imu, JointState
        from std_msgs.msg import Float64MultiArray, MultiArrayDimension
        from std_srvs.srv import Trigger
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
        from builtin_interfaces.msg import Time
        from rclpy.serialization import deserialize_message, serialize_message
    except ImportError as err:
        raise Ros2Error(f"fmscal ros2 needs rclpy and the ROS 2 messages ({err.name or err} not found): "
                        f"{INSTALL}") from None
    try:                                       # rclpy's wait set (private; Humble and later have it)
        from rclpy.impl.implementation_singleton import rclpy_implementation
        WaitSet = rclpy_implementation.WaitSet
    except (ImportError, AttributeError):
        WaitSet = None
    try:                                       # the subscriptions' QoS events (Iron and later: matched too)
        from rclpy.event_handler import SubscriptionEventCallbacks
        from rclpy.event_handler import qos_policy_name_from_kind
    except ImportError:
        SubscriptionEventCallbacks = qos_policy_name_from_kind = None
    return SimpleNamespace(rclpy=rclpy, Node=rclpy.node.Node, WaitSet=WaitSet, Context=Context,
                           Group=MutuallyExclusiveCallbackGroup, Events=SubscriptionEventCallbacks,
                           policy_name=qos_policy_name_from_kind,
                           Shutdown=ExternalShutdownException, Executor=MultiThreadedExecutor,
                           Single=SingleThreadedExecutor, Parameter=Parameter,
                           QoSProfile=QoSProfile, Reliability=ReliabilityPolicy, History=HistoryPolicy,
                           Durability=DurabilityPolicy, Descriptor=ParameterDescriptor,
                           SetResult=SetParametersResult, PoseStamped=PoseStamped,
                           WrenchStamped=WrenchStamped, Imu=Imu, JointState=JointState, Array=Float64MultiArray,
                           Dimension=MultiArrayDimension, Trigger=Trigger, DiagnosticArray=DiagnosticArray,
                           DiagnosticStatus=DiagnosticStatus, KeyValue=KeyValue, Time=Time,
                           serialize=serialize_message, deserialize=deserialize_message)
