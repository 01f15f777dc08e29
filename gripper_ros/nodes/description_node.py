"""description_publisher: the gripper's robot description and the transforms of its fingers.

What robot_state_publisher does for this one gripper, without xacro or a URDF parser, so that
it runs on the ros-jazzy wheels too: ``robot_description`` (std_msgs/String, latched), the URDF
written from the node's config (:mod:`gripper_ros.core.description`); ``/tf_static`` (latched)
with the fixed finger on the base, stamped with the node's time at start; and ``/tf`` with the
moving finger at the position of a ``joint_states`` message, stamped with that message's
(simulated) time, at most ``publish_frequency`` times a second of those stamps (every message
with ``ignore_timestamp``). ``prefix`` (by default
from the namespace: ``left_`` in ``/left``) goes before every name of the URDF (the xacro's
prefix) and the joint it reads, so the frames are the URDF's links; ``frame_prefix`` (default
empty) is put before every frame id on top, as robot_state_publisher's parameter of that name
does, without changing the URDF. On a system ROS 2, robot_state_publisher with
``gripper_urdf --prefix P`` publishes the same frames.
"""
from __future__ import annotations

import math
import sys

from geometry_msgs.msg import TransformStamped
from gripper_ros.core.description import finger_frames, urdf_text
from gripper_ros.nodes.gripper_node import GripperNode
from gripper_ros.nodes.loop_io import joint_state_template, transform_template
from gripper_ros.nodes.parameters import declare_config, declare_prefix
from gripper_ros.nodes.process import run_node
from gripper_ros.nodes.qos import GRAPH_QOS, LATCHED_QOS
from gripper_ros.nodes.startup import StartupError
from gripper_ros.wire import (FINGER_JOINT, FRAME_BASE, FRAME_FIXED_FINGER, FRAME_MOVING_FINGER,
                              NAME_CHARACTERS, NODE_DESCRIPTION, TOPIC_JOINT_STATES,
                              TOPIC_ROBOT_DESCRIPTION, TOPIC_TF, TOPIC_TF_STATIC)
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage


DEFAULT_PUBLISH_FREQUENCY_HZ = 20.0
"""robot_state_publisher's default ``publish_frequency``."""


def _publish_interval_ns(publish_frequency_hz: float) -> int:
    """Return the interval robot_state_publisher keeps between transforms: whole ms."""
    if not (isinstance(publish_frequency_hz, float) and 0.0 < publish_frequency_hz <= 1000.0):
        raise StartupError(f'parameter "publish_frequency" must be in (0, 1000] Hz, got '
                           f'{publish_frequency_hz!r}')
    return int(1000.0 / publish_frequency_hz) * 1_000_000


def _transform(stamp, parent: str, child: str, xyz) -> TransformStamped:
    msg = TransformStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = parent
    msg.child_frame_id = child
    msg.transform.translation.x, msg.transform.translation.y, msg.transform.translation.z = (
        float(v) for v in xyz)
    msg.transform.rotation.w = 1.0
    return msg


class DescriptionPublisher(GripperNode):
    """robot_description, /tf_static and /tf of the gripper, from its config and joint_states."""

    def __init__(self, **kwargs):
        super().__init__(NODE_DESCRIPTION, **kwargs)
        config = declare_config(self)
        name_prefix = declare_prefix(self)       # the URDF's names (the xacro's prefix)
        self.joint_name = name_prefix + FINGER_JOINT
        prefix = self.declare_parameter('frame_prefix', '', ParameterDescriptor(
            description='put before every frame id of /tf and /tf_static, not in the URDF '
                        '(as robot_state_publisher does; e.g. left/)',
            read_only=True)).value
        if not set(prefix) <= NAME_CHARACTERS | {'/'}:
            raise StartupError(f'parameter "frame_prefix" may hold only ASCII letters, digits, '
                               f'_ and /, got {prefix!r}')
        self.publish_interval_ns = _publish_interval_ns(self.declare_parameter(
            'publish_frequency', DEFAULT_PUBLISH_FREQUENCY_HZ, ParameterDescriptor(
                description='most /tf messages a second of joint_states stamps (as '
                            'robot_state_publisher; in (0, 1000])', read_only=True)).value)
        self.ignore_timestamp = self.declare_parameter(
            'ignore_timestamp', False, ParameterDescriptor(
                description='publish /tf for every joint_states message (as '
                            'robot_state_publisher)', read_only=True)).value
        self._last_tf_ns = 0                   # the stamp of the last /tf (0: none yet)
        self._last_callback_ns = 0             # the node's time at the last joint_states
        self.frames = finger_frames(config)
        self.urdf = urdf_text(config, name_prefix)
        prefix += name_prefix
        self._base = prefix + FRAME_BASE
        self._moving = prefix + FRAME_MOVING_FINGER
        self.published = {TOPIC_TF: 0, TOPIC_TF_STATIC: 0, TOPIC_ROBOT_DESCRIPTION: 0}
        self.skipped = 0                       # joint_states without a finite finger position
        self.last_state_ns: int | None = None  # the stamp of the last joint_states handled
        self._description_pub = self.tapped_publisher(String, TOPIC_ROBOT_DESCRIPTION,
                                                      LATCHED_QOS)
        self._static_pub = self.tapped_publisher(TFMessage, TOPIC_TF_STATIC, LATCHED_QOS)
        self._tf_pub = self.tapped_publisher(TFMessage, TOPIC_TF, GRAPH_QOS)
        self.graph_subscription(JointState, TOPIC_JOINT_STATES, self._on_joint_states)
        self._joint_layout = joint_state_template(self.joint_name, name_prefix + FRAME_BASE)
        self._tf_layout = transform_template(self._base, self._moving)
        self.latched = {TOPIC_ROBOT_DESCRIPTION: String(data=self.urdf),
                        TOPIC_TF_STATIC: TFMessage(transforms=[_transform(
                            self.get_clock().now().to_msg(), self._base,
                            prefix + FRAME_FIXED_FINGER, self.frames.fixed_finger_xyz)])}
        """The latched messages, as published once at start: what a recording starts with."""
        self._description_pub.publish(self.latched[TOPIC_ROBOT_DESCRIPTION])
        self._static_pub.publish(self.latched[TOPIC_TF_STATIC])
        self.published[TOPIC_ROBOT_DESCRIPTION] += 1
        self.published[TOPIC_TF_STATIC] += 1

    def _on_joint_states(self, data: bytes) -> None:
        """Publish the moving finger's transform at the joint position, at the message's stamp.

        joint_states as the plant packs it is read by layout; any other form the general way.
        A transform is due as robot_state_publisher decides it (its ``callbackJointState``):
        the stamp at least one publish interval after the last transform's stamp (or the
        node's time, if earlier), and every one again once the node's time went backwards.
        """
        values = self._joint_layout.unpack(data)
        if values is not None:
            sec, nanosec, position_m = values[:3]
        else:
            msg = deserialize_message(data, JointState)
            sec, nanosec = msg.header.stamp.sec, msg.header.stamp.nanosec
            try:
                position_m = msg.position[list(msg.name).index(self.joint_name)]
            except (ValueError, IndexError):
                position_m = math.nan
        stamp_ns = self.last_state_ns = sec * 1_000_000_000 + nanosec
        if not math.isfinite(position_m):
            self.skipped += 1
            return
        now_ns = self.get_clock().now().nanoseconds
        if self._last_callback_ns > now_ns:     # moved backwards in time: publish again
            self._last_tf_ns = 0
        self._last_callback_ns = now_ns
        last_ns = min(now_ns, self._last_tf_ns)
        if not (self.ignore_timestamp or stamp_ns >= last_ns + self.publish_interval_ns):
            return
        self._tf_pub.publish(self._tf_layout.pack(
            sec, nanosec, *self.frames.moving_finger_xyz(position_m)))
        self._last_tf_ns = stamp_ns
        self.published[TOPIC_TF] += 1


def main(args=None):
    return run_node(DescriptionPublisher, NODE_DESCRIPTION, args)


if __name__ == '__main__':
    sys.exit(main())
