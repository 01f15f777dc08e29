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
from rclpy.executors import ExternalShutdownException

from .config import ConfigError
from .controller_node_base import LockstepController
from .controllers import ForceControllerKind, make_force_controller
from .ros_common import GRAPH_QOS, TOPIC_FORCE_SENSOR, declare_config, time_to_ns


class ForceControllerNode(LockstepController):
    source = MotorCommand.SOURCE_FORCE

    def __init__(self, **kwargs):
        super().__init__('force_controller', **kwargs)
        self.config = declare_config(self)
        kind = self.declare_parameter(
            'controller', ForceControllerKind.PI.value,
            ParameterDescriptor(description='pi | mpc_pi', read_only=True)).value
        try:
            self.kind = ForceControllerKind(kind)
        except ValueError:
            raise ConfigError(f'parameter "controller" must be one of '
                              f'{[k.value for k in ForceControllerKind]}, got {kind!r}') from None
        self.approach_margin = self.declare_parameter(
            'approach_force_margin', 1.0, ParameterDescriptor(
                description='cap before contact: margin x stall voltage of the force setpoint; '
                            '0 disables the cap (the paper behaviour)',
                floating_point_range=[FloatingPointRange(from_value=0.0, to_value=10.0)])).value
        self.controller = make_force_controller(self.config, self.kind)
        self._pi = self.controller.inner if self.kind is ForceControllerKind.MPC_PI \
            else self.controller
        self._full_limits = self._pi.output_limits
        self.sample_time_s = self.config.force.sample_time_s
        self._contact = False
        self.create_subscription(ForceSensor, TOPIC_FORCE_SENSOR, self._on_force, GRAPH_QOS)

    def _on_force(self, msg: ForceSensor) -> None:
        self.on_measurement(time_to_ns(msg.header.stamp), msg.force_n)

    def activate(self, status: SupervisorStatus, measurement: float) -> None:
        self._contact = False
        self._apply_limits(status)
        if self.kind is ForceControllerKind.MPC_PI:
            self.controller.reset(measurement, status.seed_voltage_v)
        else:
            self.controller.reset(status.seed_voltage_v, status.force_setpoint_n, measurement)

    def _apply_limits(self, status: SupervisorStatus) -> None:
        low, high = self._full_limits
        if not self._contact and self.approach_margin > 0.0:
            cap = (self.approach_margin * status.force_setpoint_n
                   / self.config.plant.stall_force_per_volt_n)
            high = min(high, cap)
        self._pi.output_limits = (low, high)

    def compute(self, status: SupervisorStatus, measurement: float) -> tuple[float, float]:
        if not self._contact and status.contact:
            self._contact = True
            self._apply_limits(status)
        voltage = self.controller.step(status.force_setpoint_n, measurement)
        inner = getattr(self.controller, 'last_inner_setpoint', status.force_setpoint_n)
        return voltage, inner


def main(args=None):
    rclpy.init(args=args)
    node = None
    try:
        node = ForceControllerNode()
        rclpy.spin(node)
    except ConfigError as exc:
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
