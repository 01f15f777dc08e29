"""force_controller: PI (or MPC-PI) on the gripping force, at the force sampling time (0.1 ms).

Takes over from the position controller bumplessly: its integrator is seeded with the voltage
the motor had at the switch (``SupervisorStatus.seed_voltage_v``). Until the sensor reports
contact, its output is capped at the voltage whose stall force equals the setpoint
(``approach_force_margin`` x F_sp / (N per V), eq. 13): on a rigid object the finger then
cannot arrive pushing harder than the setpoint, which removes the paper's contact spike.
"""
from __future__ import annotations

import sys

import rclpy
from gripper_interfaces.msg import ForceSensor, MotorCommand, SupervisorStatus
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException

from gripper_ros.core.config import ConfigError
from gripper_ros.core.stages import DEFAULT_FORCE_CONTROLLER, ForceStageController, parse_kind
from gripper_ros.nodes.controller_node import LockstepController
from gripper_ros.core.controllers import ForceControllerKind
from gripper_ros.nodes.common import GRAPH_QOS, TOPIC_FORCE_SENSOR, declare_config, time_to_ns


class ForceControllerNode(LockstepController):
    source = MotorCommand.SOURCE_FORCE

    def __init__(self, **kwargs):
        super().__init__('force_controller', **kwargs)
        self.config = declare_config(self)
        kind = self.declare_parameter(
            'controller', DEFAULT_FORCE_CONTROLLER.value,
            ParameterDescriptor(description='contact_aware (default: rigid and compliant '
                                            'objects) | pi | mpc_pi (the paper\'s structure)',
                                read_only=True)).value
        self.kind = parse_kind(ForceControllerKind, kind)
        self.approach_margin = self.declare_parameter(
            'approach_force_margin', 1.0, ParameterDescriptor(
                description='pi / mpc_pi: cap before contact, margin x stall voltage of the '
                            'force setpoint; 0 disables the cap (the paper behaviour). '
                            'contact_aware caps its approach itself',
                floating_point_range=[FloatingPointRange(from_value=0.0, to_value=10.0)])).value
        self.stage = ForceStageController(self.config, self.kind, self.approach_margin)
        self.controller = self.stage.controller
        self.sample_time_s = self.stage.sample_time_s
        self.create_subscription(ForceSensor, TOPIC_FORCE_SENSOR, self._on_force, GRAPH_QOS)
        self.add_post_set_parameters_callback(self._on_parameters_set)

    def _on_parameters_set(self, parameters) -> None:
        """An accepted ``approach_force_margin`` (the descriptor's range refuses the rest)
        takes effect when the force stage next takes over (the next grasp), never mid-stage."""
        for p in parameters:
            if p.name == 'approach_force_margin':
                self.approach_margin = self.stage.approach_margin = float(p.value)

    def _on_force(self, msg: ForceSensor) -> None:
        self.on_measurement(time_to_ns(msg.header.stamp), msg.force_n)

    def activate(self, status: SupervisorStatus, measurement: float) -> None:
        """Seed bumplessly from ``status.seed_voltage_v``; cap the output until contact."""
        self.stage.activate(status, measurement)

    def compute(self, status: SupervisorStatus, measurement: float) -> tuple[float, float]:
        return self.stage.compute(status, measurement)


def main(args=None):
    rclpy.init(args=args)
    node = None
    try:
        node = ForceControllerNode()
        rclpy.spin(node)
    except (ConfigError, ParameterException) as exc:   # bad config file, parameter out of range
        print(f'force_controller: {exc}', file=sys.stderr)
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
