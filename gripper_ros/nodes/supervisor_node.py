"""supervisor: serves ``/gripper/grasp`` and decides, tick by tick, which controller drives.

For every plant tick it reads the joint state, force sensor and motor state of that tick, steps
:class:`gripper_ros.core.supervisor.GraspSupervisor` and publishes the decision on
``/gripper/supervisor/status`` (phase, active controller, both setpoints). The grasp service
answers when the grasp has ended, with one explicit outcome; a bad request or a request while a
grasp runs is refused at once with ``success=false`` and a message, and nothing moves.

Each ended grasp or release is also published, latched, on ``/gripper/supervisor/outcome``.

``/gripper/release`` (std_srvs/Trigger) opens the fingers: the position stage drives the finger
to the fully-open position (phase RELEASING) and the call is answered when it is there (outcome
RELEASED on the status). It is refused while a grasp or release runs (call ``/gripper/stop``
first): a release never silently ends a grasp.
"""
from __future__ import annotations

import math
import sys

import rclpy
from gripper_interfaces.msg import ForceSensor, MotorState, SupervisorStatus
from gripper_interfaces.srv import Grasp
from std_srvs.srv import Trigger
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from sensor_msgs.msg import JointState

from gripper_ros.core.config import ConfigError
from gripper_ros.core.supervisor import (Decision, GraspRequest, GraspSupervisor, Outcome, Phase, RequestError,
                          validate_request)
from gripper_ros.nodes.common import (GRAPH_QOS, LATCHED_QOS, SERVICE_GRASP, SERVICE_RELEASE, SERVICE_STOP,
                         TOPIC_FORCE_SENSOR, TOPIC_JOINT_STATES, TOPIC_OUTCOME,
                         TOPIC_MOTOR_COMMAND, TOPIC_MOTOR_STATE, TOPIC_STATUS,
                         DeferredService, ExecutorSilence, declare_config,
                         ns_to_time, time_to_ns)


class SupervisorNode(Node):
    def __init__(self, **kwargs):
        super().__init__('supervisor', **kwargs)
        self.config = declare_config(self)
        self.logic = GraspSupervisor(self.config.plant, self.config.supervisor)
        self._joint: JointState | None = None
        self._force: ForceSensor | None = None
        # the last finite reading of each number the status and the Grasp response carry: a
        # non-finite measurement (sensor dropout) is never published, the last good one is
        self._good_position_m = 0.0
        self._good_force_n = 0.0
        self._good_voltage_v = 0.0
        self._last_decided_ns: int | None = None
        self._grasp_id = 0
        # (request header, response): Grasp.Response for a grasp, Trigger.Response for a release
        self._pending: tuple[object, object] | None = None
        self._status_msg = SupervisorStatus()
        self.statuses_published = 0
        self._status_pub = self.create_publisher(SupervisorStatus, TOPIC_STATUS, GRAPH_QOS)
        self._outcome_pub = self.create_publisher(SupervisorStatus, TOPIC_OUTCOME, LATCHED_QOS)
        self.create_subscription(JointState, TOPIC_JOINT_STATES, self._on_joint, GRAPH_QOS)
        self.create_subscription(ForceSensor, TOPIC_FORCE_SENSOR, self._on_force, GRAPH_QOS)
        self.create_subscription(MotorState, TOPIC_MOTOR_STATE, self._on_motor, GRAPH_QOS)
        self.grasp_service = DeferredService(self, Grasp, SERVICE_GRASP, self._on_grasp)
        self.tick_timeout_s = self.declare_parameter(
            'tick_timeout_s', 2.0, ParameterDescriptor(
                description='wall seconds without a new tick during a grasp before FAULT',
                floating_point_range=[FloatingPointRange(from_value=0.05, to_value=600.0)])).value
        self.add_post_set_parameters_callback(self._on_parameters_set)
        # executor-running wall time without a new tick (see _watchdog)
        self._silence = ExecutorSilence()
        self.create_timer(0.1, self._watchdog, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.create_service(Trigger, SERVICE_STOP, self._on_stop)
        self.release_service = DeferredService(self, Trigger, SERVICE_RELEASE, self._on_release)

    def _on_parameters_set(self, parameters) -> None:
        """An accepted ``tick_timeout_s`` (the descriptor's range refuses the rest) applies from
        the watchdog's next check on."""
        for p in parameters:
            if p.name == 'tick_timeout_s':
                self.tick_timeout_s = float(p.value)

    def _progress(self) -> None:
        """A tick was decided (or a grasp started): the watchdog's silence starts afresh."""
        self._silence.reset()

    # ------------------------------------------------------------------ measurements
    def _on_joint(self, msg: JointState) -> None:
        self._joint = msg
        if msg.position and math.isfinite(msg.position[0]):
            self._good_position_m = msg.position[0]
        self._try_decide()

    def _on_force(self, msg: ForceSensor) -> None:
        self._force = msg
        if math.isfinite(msg.force_n):
            self._good_force_n = msg.force_n
        self._try_decide()

    def _on_motor(self, msg: MotorState) -> None:
        if math.isfinite(msg.voltage_v):
            self._good_voltage_v = msg.voltage_v

    def _latest_tick(self) -> int | None:
        """Stamp of the newest tick for which both measurements are here, else None."""
        j, f = self._joint, self._force
        if j is None or f is None:
            return None
        t_ns = time_to_ns(j.header.stamp)
        return t_ns if t_ns == time_to_ns(f.header.stamp) else None

    def _try_decide(self) -> None:
        t_ns = self._latest_tick()
        if t_ns is None or t_ns == self._last_decided_ns or not self.logic.busy:
            return
        self._last_decided_ns = t_ns
        self._progress()
        position = self._joint.position[0] if self._joint.position else math.nan
        speed = self._joint.velocity[0] if self._joint.velocity else 0.0
        decision = self.logic.step(t_ns, position, self._force.force_n, self._force.voltage_v,
                                   speed)
        self._publish(t_ns, decision)
        if decision.finished:
            self._complete(decision)

    def _publish(self, t_ns: int, d: Decision) -> None:
        m = self._status_msg
        m.header.stamp = ns_to_time(t_ns)
        m.phase = int(d.phase)
        m.active_controller = int(d.active)
        m.switch_criterion = int(d.switch_criterion)
        m.grasp_id = self._grasp_id
        m.outcome = int(d.outcome)
        m.position_setpoint_m = d.position_setpoint_m
        m.approach_setpoint_m = d.approach_setpoint_m
        m.force_setpoint_n = d.force_setpoint_n
        # the last finite readings: a non-finite one (sensor dropout) is never passed on
        m.position_m = self._good_position_m
        m.force_n = self._good_force_n
        m.width_m = self.config.plant.max_travel_m - m.position_m
        m.contact = self.logic.contact_ns is not None
        m.seed_voltage_v = self._good_voltage_v
        m.message = d.message if d.finished else ''
        self._status_pub.publish(m)
        self.statuses_published += 1
        if d.finished:
            self._outcome_pub.publish(m)     # latched: the last outcome, for late subscribers

    # ------------------------------------------------------------------ service
    def _on_grasp(self, request: Grasp.Request, header) -> None:
        """Start a grasp, or refuse it at once; a started grasp is answered in _complete()."""
        response = Grasp.Response()
        message = self._start(request, response)
        if message:
            response.success = False
            response.outcome = Grasp.Response.OUTCOME_REFUSED
            response.message = message
            self.get_logger().warn(f'grasp {message}')
            self.grasp_service.reply(header, response)
        else:
            self._pending = (header, response)

    def _start(self, request: Grasp.Request, response: Grasp.Response) -> str:
        """Validate and start; returns a refusal message, or '' when the grasp has started."""
        if self.logic.busy:
            return ('refused: a release is running' if self.logic.releasing
                    else 'refused: a grasp is already running')
        try:
            targets = validate_request(
                GraspRequest(request.width_m, request.mass_kg, request.friction_coefficient,
                             request.acceleration_mps2, request.timeout_s,
                             request.width_tolerance_m),
                self.config.plant, self.config.supervisor)
        except RequestError as exc:
            return f'refused: {exc}'
        missing = self._missing_peers()
        if missing:
            return f'refused: graph not ready, not yet discovered: {missing}'
        t_ns = self._latest_tick()
        if t_ns is None:
            return 'refused: no measurement from plant_simulator yet'
        if not (math.isfinite(self._force.force_n) and math.isfinite(self._force.voltage_v)):
            return (f'refused: the force sensor reads force {self._force.force_n!r} N, voltage '
                    f'{self._force.voltage_v!r} V (sensor dropout); a grasp needs it')
        position = self._joint.position[0] if self._joint.position else math.nan
        if not math.isfinite(position):
            return (f'refused: the finger position sensor reads {position!r} m (sensor dropout); '
                    'a grasp needs it')
        self._grasp_id += 1
        response.grasp_id = self._grasp_id
        response.position_setpoint_m = targets.position_setpoint_m
        response.force_setpoint_n = targets.force_setpoint_n
        self.get_logger().info(
            f'grasp {self._grasp_id}: width {request.width_m:g} m, mass {request.mass_kg:g} kg '
            f'-> position {targets.position_setpoint_m:.4f} m, force '
            f'{targets.force_setpoint_n:.3f} N')
        decision = self.logic.start(targets, t_ns, self._force.voltage_v)
        self._last_decided_ns = t_ns
        self._progress()
        self._publish(t_ns, decision)
        return ''

    def _watchdog(self) -> None:
        """Lockstep stalls if a node dies: end the grasp as FAULT, naming who went silent.

        Only time in which the executor demonstrably ran counts (``ExecutorSilence``, shared
        with the controllers' status watchdog): after a stall of the whole process, ticks queued
        behind this timer are not silence."""
        busy = self.logic.busy
        silent_s = self._silence.check(counting=busy)
        if not busy or silent_s < self.tick_timeout_s:
            return
        active = self._status_msg.active_controller
        expected = {SupervisorStatus.CONTROLLER_POSITION: 'position_controller',
                    SupervisorStatus.CONTROLLER_FORCE: 'force_controller'}.get(active, '?')
        commanders = {i.node_name for i in self.get_publishers_info_by_topic(TOPIC_MOTOR_COMMAND)}
        plants = {i.node_name for i in self.get_publishers_info_by_topic(TOPIC_JOINT_STATES)}
        if expected not in commanders:
            who = f'{expected} is gone (no publisher on {TOPIC_MOTOR_COMMAND})'
        elif 'plant_simulator' not in plants:
            who = 'plant_simulator is gone (no publisher on ' + TOPIC_JOINT_STATES + ')'
        else:
            who = f'{expected} did not answer or plant_simulator did not advance'
        message = (f'fault: no new tick for {silent_s:.2f} s of wall time at '
                   f't={(self._last_decided_ns or 0) * 1e-9:.4f} s: {who}')
        self.get_logger().error(message)
        decision = self.logic.fault(message)
        self._publish(self._last_decided_ns or 0, decision)
        self._complete(decision)

    def _missing_peers(self) -> str:
        """Lockstep cannot recover a lost tick: start only when every peer is discovered."""
        missing = []
        if self.count_subscribers(TOPIC_STATUS) < 3:          # plant + both controllers
            missing.append(f'{TOPIC_STATUS} subscribers (plant_simulator, position_controller, '
                           'force_controller)')
        if self.count_publishers(TOPIC_MOTOR_COMMAND) < 2:
            missing.append(f'{TOPIC_MOTOR_COMMAND} publishers (both controllers)')
        return '; '.join(missing)

    def _complete(self, decision: Decision) -> None:
        """The grasp has ended: answer the waiting request with its outcome."""
        pending, self._pending = self._pending, None
        what = 'release' if self.logic.phase is Phase.RELEASING or \
            decision.outcome is Outcome.RELEASED else 'grasp'
        self.get_logger().info(f'{what} {self._grasp_id}: {decision.outcome.name}: '
                               f'{decision.message}')
        if pending is None:
            return
        header, response = pending
        if isinstance(response, Trigger.Response):            # a release
            response.success = decision.outcome is Outcome.RELEASED
            response.message = f'{decision.outcome.name}: {decision.message}'
            self.release_service.reply(header, response)
            return
        response.success = decision.outcome is Outcome.HOLDING
        response.outcome = int(decision.outcome)
        response.message = decision.message
        position = self._good_position_m            # the last finite readings
        response.final_position_m = position
        response.final_width_m = self.config.plant.max_travel_m - position
        response.final_force_n = self._good_force_n
        if self.logic.switch_ns is not None:
            response.switch_time_s = (self.logic.switch_ns - self.logic.start_ns) * 1e-9
        self.grasp_service.reply(header, response)

    def _on_release(self, request: Trigger.Request, header) -> None:
        """Open the fingers (position stage to fully open), or refuse at once; answered in
        _complete() when the finger is there."""
        response = Trigger.Response()
        message = ''
        if self.logic.busy:
            message = (f'refused: a {"release" if self.logic.releasing else "grasp"} is running '
                       f'(grasp {self._grasp_id}, phase {self.logic.phase.name}); call '
                       f'{SERVICE_STOP} first')
        else:
            missing = self._missing_peers()
            t_ns = self._latest_tick()
            if missing:
                message = f'refused: graph not ready, not yet discovered: {missing}'
            elif t_ns is None:
                message = 'refused: no measurement from plant_simulator yet'
            else:
                p = self._joint.position[0] if self._joint.position else math.nan
                if not math.isfinite(p):
                    message = (f'refused: the finger position sensor reads {p!r} m (sensor '
                               'dropout); opening under position control needs it')
        if message:
            response.success = False
            response.message = message
            self.get_logger().warn(f'release {message}')
            self.release_service.reply(header, response)
            return
        self._grasp_id += 1
        self.get_logger().info(f'release {self._grasp_id}: opening from '
                               f'{self._joint.position[0]:.5f} m')
        decision = self.logic.start_release(t_ns)
        self._pending = (header, response)
        self._last_decided_ns = t_ns
        self._progress()
        self._publish(t_ns, decision)

    def _on_stop(self, request: Trigger.Request, response: Trigger.Response):
        """Stop the running grasp now: no controller drives the motor from this tick on."""
        if not self.logic.busy:
            response.success = False
            response.message = 'no grasp is running'
            return response
        what = 'release' if self.logic.releasing else 'grasp'
        self.stop_grasp('stopped on request (/gripper/stop)')
        response.success = True
        response.message = f'{what} {self._grasp_id} stopped'
        return response

    def destroy_node(self):
        self.grasp_service.destroy()
        self.release_service.destroy()
        return super().destroy_node()

    def stop_grasp(self, message: str = 'stopped on request') -> None:
        """End the running grasp (STOPPED); the plant stops advancing."""
        if not self.logic.busy:
            return
        decision = self.logic.stop(message)
        t_ns = self._last_decided_ns or 0
        self._publish(t_ns, decision)
        self._complete(decision)


def main(args=None):
    rclpy.init(args=args)
    node = None
    try:
        node = SupervisorNode()
        rclpy.spin(node)
    except ConfigError as exc:
        print(f'supervisor: {exc}', file=sys.stderr)
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
