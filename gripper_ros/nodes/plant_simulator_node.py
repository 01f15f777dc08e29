"""plant_simulator: the gripper's motor, lead screw, fingers and object, in lockstep sim time.

Publishes ``/clock``, the finger joint state, the force sensor (force and FSR voltage) and the
motor state for tick ``t_k``; then waits for the command of tick ``t_k`` from the controller the
supervisor named active for ``t_k``, holds it for the command's ``hold_s`` and publishes tick
``t_k + hold_s``. Simulated time stands still while nobody commands.

``/gripper/sim/set_object`` places an object and may schedule a fault (``SetObject.FAULT_*``):
it is armed when the next grasp starts (the first status of a new grasp, phase POSITION) at
``fault_at_s`` after that status' stamp, and dropped if that grasp ends before it fires. The
fault's numerics live in :mod:`gripper_ros.core.plant` and :mod:`gripper_ros.core.force_sensor`.
"""
from __future__ import annotations

import math
import sys

import rclpy
from gripper_interfaces.msg import ForceSensor, MotorCommand, MotorState, SupervisorStatus
from gripper_interfaces.srv import SetObject
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from gripper_ros.core.config import ConfigError
from gripper_ros.core.controllers import make_plant
from gripper_ros.core.plant import FaultKind, GraspObject, PlantSample, check_fault
from gripper_ros.nodes.common import (FINGER_JOINT, GRAPH_QOS, SERVICE_SET_OBJECT, TOPIC_CLOCK,
                         TOPIC_FORCE_SENSOR, TOPIC_JOINT_STATES, TOPIC_MOTOR_COMMAND,
                         TOPIC_MOTOR_STATE, TOPIC_STATUS, declare_config, ns_to_time, time_to_ns)

MAX_HOLD_S = 1.0  # a command held longer than this is refused as malformed


class PlantSimulatorNode(Node):
    """Thin ROS wrapper around :class:`gripper_ros.core.plant.GripperPlant`."""

    def __init__(self, **kwargs):
        super().__init__('plant_simulator', **kwargs)
        self.config = declare_config(self)
        self.plant = make_plant(self.config)
        self.frame_id = self.declare_parameter('frame_id', 'gripper_base', ParameterDescriptor(
            description='frame_id of every published header, read once at start-up',
            read_only=True)).value
        self._status: SupervisorStatus | None = None
        self._command: MotorCommand | None = None
        self.ticks_published = 0
        self.commands_rejected = 0
        self._pending_fault: tuple[FaultKind, float, float] | None = None  # (kind, at_s, tau)
        self._fault_grasp_id: int | None = None   # the grasp the armed fault belongs to

        self._clock_pub = self.create_publisher(Clock, TOPIC_CLOCK, GRAPH_QOS)
        self._joint_pub = self.create_publisher(JointState, TOPIC_JOINT_STATES, GRAPH_QOS)
        self._force_pub = self.create_publisher(ForceSensor, TOPIC_FORCE_SENSOR, GRAPH_QOS)
        self._motor_pub = self.create_publisher(MotorState, TOPIC_MOTOR_STATE, GRAPH_QOS)
        self.create_subscription(SupervisorStatus, TOPIC_STATUS, self._on_status, GRAPH_QOS)
        self.create_subscription(MotorCommand, TOPIC_MOTOR_COMMAND, self._on_command, GRAPH_QOS)
        self.create_service(SetObject, SERVICE_SET_OBJECT, self._on_set_object)

        self._clock_msg = Clock()
        self._joint = JointState(name=[FINGER_JOINT], position=[0.0], velocity=[0.0],
                                 effort=[0.0])
        self._joint.header.frame_id = self.frame_id
        self._force = ForceSensor()
        self._force.header.frame_id = self.frame_id
        self._motor = MotorState()
        self._motor.header.frame_id = self.frame_id
        self.get_logger().info(
            f'plant ready: travel {self.config.plant.max_travel_m:g} m, '
            f'max force {self.config.plant.max_force_n:.2f} N at '
            f'{self.config.plant.voltage_limit_v:g} V')
        self.publish_sample(self.plant.sample())

    # ------------------------------------------------------------------ lockstep
    def _on_status(self, msg: SupervisorStatus) -> None:
        self._status = msg
        if self._pending_fault is not None and msg.phase == SupervisorStatus.PHASE_POSITION \
                and msg.outcome == 0:
            kind, at_s, tau = self._pending_fault
            self._pending_fault = None
            self._fault_grasp_id = msg.grasp_id
            fault = self.plant.schedule_fault(
                kind, time_to_ns(msg.header.stamp) + round(at_s * 1e9), tau)
            self.get_logger().info(f'grasp {msg.grasp_id}: fault {kind.name} scheduled at '
                                   f't={fault.at_ns * 1e-9:.4f} s')
        elif msg.outcome != 0 and self.plant.scheduled_fault is not None and \
                msg.grasp_id == self._fault_grasp_id:
            self.plant.cancel_fault()             # the grasp ended before its fault fired
        self._try_step()

    def _on_command(self, msg: MotorCommand) -> None:
        self._command = msg
        self._try_step()

    def _try_step(self) -> None:
        status, command = self._status, self._command
        if status is None or command is None:
            return
        now_ns = self.plant.t_ns
        if time_to_ns(status.header.stamp) != now_ns or time_to_ns(command.header.stamp) != now_ns:
            return
        if status.active_controller == SupervisorStatus.CONTROLLER_NONE:
            return
        if command.source != status.active_controller or command.grasp_id != status.grasp_id:
            self.commands_rejected += 1
            self.get_logger().warn(
                f'ignoring command from source {command.source} (grasp {command.grasp_id}): '
                f'controller {status.active_controller} of grasp {status.grasp_id} is active',
                throttle_duration_sec=1.0)
            return
        if not (math.isfinite(command.voltage_v) and math.isfinite(command.hold_s)
                and 0.0 < command.hold_s <= MAX_HOLD_S):
            self.commands_rejected += 1
            self.get_logger().error(
                f'refusing malformed command voltage={command.voltage_v!r} '
                f'hold={command.hold_s!r}; motor held at 0 V', throttle_duration_sec=1.0)
            return
        self._command = None
        self.publish_sample(self.plant.step(command.voltage_v, command.hold_s))

    def publish_sample(self, s: PlantSample) -> None:
        """Publish one tick: /clock first, so sim-time nodes see the tick's time."""
        stamp = ns_to_time(s.t_ns)
        self._clock_msg.clock = stamp
        self._clock_pub.publish(self._clock_msg)
        j = self._joint
        j.header.stamp = stamp
        j.position[0] = s.position_m
        j.velocity[0] = s.velocity_mps
        j.effort[0] = s.force_n
        self._motor.header.stamp = stamp
        self._motor.voltage_v = s.voltage_v
        self._motor.current_a = s.current_a
        self._motor.speed_rad_s = s.speed_rad_s
        self._motor_pub.publish(self._motor)
        f = self._force
        f.header.stamp = stamp
        f.force_n = s.force_n
        f.peak_force_n = s.peak_force_n
        f.voltage_v = s.sensor_voltage_v
        self._force_pub.publish(f)
        self._joint_pub.publish(j)
        self.ticks_published += 1

    # ------------------------------------------------------------------ simulation set-up
    def _on_set_object(self, request: SetObject.Request,
                       response: SetObject.Response) -> SetObject.Response:
        status = self._status
        if status is not None and status.active_controller != SupervisorStatus.CONTROLLER_NONE:
            response.success = False
            response.message = 'refused: a grasp is running'
            return response
        try:
            obj = GraspObject(request.width_m, request.stiffness_n_per_m,
                              request.damping_n_s_per_m)
            kind, tau = check_fault(request.fault, request.fault_at_s,
                                    request.fault_time_constant_s, obj.rigid)
            if request.open_fingers:
                self.plant.reset(open_fingers=True)
            self.plant.set_object(obj)                       # also clears earlier faults
        except ValueError as exc:
            response.success = False
            response.message = f'refused: {exc}'
            return response
        self._pending_fault = None if kind is FaultKind.NONE else \
            (kind, request.fault_at_s, tau)
        response.success = True
        response.message = (f'object width {request.width_m:g} m, contact at '
                            f'{self.plant.contact_position_m:.4f} m')
        if self._pending_fault is not None:
            response.message += (f'; fault {kind.name} {request.fault_at_s:g} s after the start '
                                 f'of the next grasp')
        self.publish_sample(self.plant.sample())
        return response


def main(args=None):
    rclpy.init(args=args)
    node = None
    try:
        node = PlantSimulatorNode()
        rclpy.spin(node)
    except ConfigError as exc:
        print(f'plant_simulator: {exc}', file=sys.stderr)
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
