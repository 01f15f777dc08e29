"""position_controller: MPC-PD (DMC over PD, Table II) for the position stage, at 10 ms.

Answers each lockstep tick in which the supervisor names it active with the armature voltage
for the next ``sample_time_s``. ``controller`` selects ``mpc_pd`` (default), ``pd`` or ``pid``.
"""
from __future__ import annotations

import sys

import rclpy
from gripper_interfaces.msg import MotorCommand, SupervisorStatus
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from sensor_msgs.msg import JointState

from gripper_ros.core.config import ConfigError
from gripper_ros.core.stages import PositionStageController, parse_kind
from gripper_ros.nodes.controller_node import LockstepController
from gripper_ros.core.controllers import PositionControllerKind
from gripper_ros.nodes.common import GRAPH_QOS, TOPIC_JOINT_STATES, declare_config, time_to_ns


class PositionControllerNode(LockstepController):
    source = MotorCommand.SOURCE_POSITION

    def __init__(self, **kwargs):
        super().__init__('position_controller', **kwargs)
        self.config = declare_config(self)
        kind = self.declare_parameter(
            'controller', PositionControllerKind.MPC_PD.value,
            ParameterDescriptor(description='mpc_pd | pd | pid', read_only=True)).value
        self.kind = parse_kind(PositionControllerKind, kind)
        self.stage = PositionStageController(self.config, self.kind)   # the control law
        self.controller = self.stage.controller
        self.sample_time_s = self.stage.sample_time_s
        self.create_subscription(JointState, TOPIC_JOINT_STATES, self._on_joint_state, GRAPH_QOS)

    def _on_joint_state(self, msg: JointState) -> None:
        position = msg.position[0] if msg.position else float('nan')
        self.on_measurement(time_to_ns(msg.header.stamp), position)

    def activate(self, status: SupervisorStatus, measurement: float) -> None:
        """Start from rest at the measured position with the motor off."""
        self.stage.activate(status, measurement)

    def compute(self, status: SupervisorStatus, measurement: float) -> tuple[float, float]:
        return self.stage.compute(status, measurement)


def main(args=None):
    rclpy.init(args=args)
    node = None
    try:
        node = PositionControllerNode()
        rclpy.spin(node)
    except (ConfigError, ParameterException) as exc:   # bad config file, parameter out of range
        print(f'position_controller: {exc}', file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
