"""What goes over the wire: topic and service names, and the codes the messages carry.

The one home of every name and code the nodes, the numeric core and the bag tools share. It
imports no rclpy, so the core and the bag readers use it without a ROS installation; a test
ties each code to the constant generated from its ``.msg`` / ``.srv`` file.
"""
from __future__ import annotations

import enum

TOPIC_CLOCK = '/clock'
TOPIC_JOINT_STATES = '/gripper/joint_states'
TOPIC_FORCE_SENSOR = '/gripper/force_sensor'
TOPIC_MOTOR_STATE = '/gripper/motor_state'
TOPIC_STATUS = '/gripper/supervisor/status'
TOPIC_MOTOR_COMMAND = '/gripper/motor_command'
TOPIC_OUTCOME = '/gripper/supervisor/outcome'
"""The final status of the last grasp or release, latched (transient local, depth 1)."""

SERVICE_GRASP = '/gripper/grasp'
SERVICE_STOP = '/gripper/stop'
SERVICE_RELEASE = '/gripper/release'
SERVICE_SET_OBJECT = '/gripper/sim/set_object'
ACTION_GRASP = '/gripper/grasp_action'

FINGER_JOINT = 'finger_joint'

GRAPH_TOPICS: dict[str, str] = {
    TOPIC_CLOCK: 'rosgraph_msgs/msg/Clock',
    TOPIC_JOINT_STATES: 'sensor_msgs/msg/JointState',
    TOPIC_FORCE_SENSOR: 'gripper_interfaces/msg/ForceSensor',
    TOPIC_MOTOR_STATE: 'gripper_interfaces/msg/MotorState',
    TOPIC_STATUS: 'gripper_interfaces/msg/SupervisorStatus',
    TOPIC_MOTOR_COMMAND: 'gripper_interfaces/msg/MotorCommand',
}
"""Every topic the lockstep graph publishes, with its type: what a grasp bag records."""


class Phase(enum.IntEnum):
    """``SupervisorStatus.PHASE_*``: where the supervisor's state machine stands."""

    IDLE = 0
    POSITION = 1
    FORCE = 2
    HOLDING = 3
    DONE = 4
    FAILED = 5
    RELEASING = 6


class Controller(enum.IntEnum):
    """``SupervisorStatus.CONTROLLER_*`` and ``MotorCommand.SOURCE_*``: who drives the motor."""

    NONE = 0
    POSITION = 1
    FORCE = 2


class SwitchCriterion(enum.IntEnum):
    """``SupervisorStatus.SWITCH_*``: what ended the position stage."""

    NONE = 0
    POSITION_TOLERANCE = 1
    SENSOR_VOLTAGE = 2


class Outcome(enum.IntEnum):
    """``Grasp.Response.OUTCOME_*``: how a grasp or release ended."""

    UNKNOWN = 0
    HOLDING = 1
    NO_OBJECT = 2
    OBJECT_LOST = 3
    TIMEOUT = 4
    STOPPED = 5
    REFUSED = 6
    FAULT = 7
    RELEASED = 8


class FaultKind(enum.IntEnum):
    """``SetObject.Request.FAULT_*``: a fault the simulator injects at an exact instant."""

    NONE = 0
    OBJECT_REMOVED = 1
    OBJECT_SLIPPING = 2
    SENSOR_DROPOUT = 3


WIRE_CODES = (
    (Phase, 'gripper_interfaces.msg', 'SupervisorStatus', 'PHASE_'),
    (Controller, 'gripper_interfaces.msg', 'SupervisorStatus', 'CONTROLLER_'),
    (Controller, 'gripper_interfaces.msg', 'MotorCommand', 'SOURCE_'),
    (SwitchCriterion, 'gripper_interfaces.msg', 'SupervisorStatus', 'SWITCH_'),
    (Outcome, 'gripper_interfaces.srv', 'Grasp.Response', 'OUTCOME_'),
    (FaultKind, 'gripper_interfaces.srv', 'SetObject.Request', 'FAULT_'),
)
"""Each code enum and the generated constants it mirrors: (enum, module, class, prefix)."""


def enum_name(enum_cls: type[enum.IntEnum], value: int) -> str:
    """The member name of ``value``, or the number itself for a code this version lacks."""
    try:
        return enum_cls(int(value)).name
    except ValueError:
        return str(int(value))
