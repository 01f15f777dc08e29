"""supervisor: serves ``grasp``, ``release``, ``move`` and ``stop``; decides who drives.

Tick by tick, it names the one stage that drives the motor.

For every ``loop/tick`` it steps :class:`gripper_ros.core.supervision.supervisor.GraspSupervisor`
and sends the tick's reference (setpoints and the measurement) to the one stage it names, on
``loop/position_reference`` or ``loop/force_reference``. A request is accepted at once and
starts at the next tick; the grasp service answers when the grasp is HOLDING (the hold goes on
until ``release``, ``stop`` or the next grasp) or has ended otherwise, with one explicit
outcome. A bad request, or one while another runs, is refused at once with ``success=false``
and a message, and nothing moves. ``release`` (std_srvs/Trigger) opens the fingers under
position control and answers when they are open. ``move`` (srv/Move) drives the finger to a
width at most at a speed and an effort and answers MOVED (reached_goal) or STALLED.

``joint_commands`` (sensor_msgs/JointState, what ros2_control's JointStateTopicSystem publishes)
is a position servo: the newest setpoint is in force at once. While its move runs, a new one
changes the move's goal and limits in place (the position stage follows without restarting); a
running grasp, release or move of a service ends STOPPED (preempted) and the setpoint's move
starts at the next tick. A repeat of the setpoint in force is no new request; a bad one is
refused with one warning line and changes nothing. ``servo_setpoint`` (ServoSetpoint, from
``trajectory_action_server``) is the same servo's input with the setpoint's own velocity and
acceleration: each message is a new setpoint. A service request preempts a running
setpoint's move in turn; between service requests, one at a time (the next is refused).

``supervisor/status`` carries the state for other programs: at ``status_rate_hz`` of simulated
time, on every change, and once a second of wall time as a heartbeat. Each answer and each
later loss is also latched on ``supervisor/outcome``. A request that makes no progress for
``tick_timeout_s`` of wall time (a node gone) ends as FAULT naming who went silent; while the
plant says on ``sim/status`` that simulated time is paused (``sim/pause``), no wall time counts.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import fields
import math
import sys
import time

from geometry_msgs.msg import AccelStamped
from gripper_interfaces.msg import (PlantTick, ServoSetpoint, SimStatus, StageReference,
                                    SupervisorStatus)
from gripper_interfaces.srv import Grasp, Move
from gripper_ros.core.runtime.lockstep import (ACTIVE_SHIFT, ANSWERED, FOREIGN, NAMED, PROGRESS,
                                               STATUS_DUE, SupervisorSide, Tick)
from gripper_ros.core.supervision.gripper_command import JointCommandStream
from gripper_ros.core.supervision.requests import (GraspRequest, MoveRequest, RequestError,
                                                   validate_move, validate_request)
from gripper_ros.core.supervision.supervisor import GraspSupervisor, load_law, RequestKind
from gripper_ros.nodes.gripper_node import GripperNode
from gripper_ros.nodes.loop_io import in_layout, split_ns, status_message, status_template
from gripper_ros.nodes.names import GraspIds
from gripper_ros.nodes.parameters import ConfigParameters, declare_prefix, follow
from gripper_ros.nodes.process import run_node
from gripper_ros.nodes.qos import GRAPH_QOS, LATCHED_QOS, SERVICE_QOS
from gripper_ros.nodes.services import DeferredService
from gripper_ros.nodes.watchdog import ExecutorSilence
from gripper_ros.text import one_line
from gripper_ros.wire import (CDR_LITTLE_ENDIAN, FINGER_JOINT, GRAPH_NOT_READY, NODE_PLANT,
                              NODE_SUPERVISOR,
                              Outcome, REPUBLISH_AFTER_S, SERVICE_GRASP, SERVICE_MOVE,
                              SERVICE_RELEASE, SERVICE_STOP, STAGE_NODES, STAGE_REFERENCE_TOPICS,
                              stamp_ns, STATUS_HEARTBEAT_S, TICK_LAYOUT, TOPIC_JOINT_COMMANDS,
                              TOPIC_MOTOR_COMMAND, TOPIC_OUTCOME, TOPIC_PLANNED_ACCELERATION,
                              TOPIC_POSITION_REFERENCE, TOPIC_SERVO_SETPOINT,
                              TOPIC_SIM_STATUS, TOPIC_STATUS, TOPIC_TICK)
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.clock import Clock, ClockType
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

DEFAULT_TICK_TIMEOUT_S = 2.0
WATCHDOG_PERIOD_S = 0.1
SUPERVISOR_READS = ('plant', 'contact', 'force_control.sample_time_s', 'pad_sensor',
                    'load_grip')
"""Config sections the supervisor reads and does not change: the plant, and what the
load-tracking grip needs (the pads' stiffness and sensing, the force stage's period)."""


class SupervisorNode(GripperNode):
    def __init__(self, **kwargs):
        super().__init__(NODE_SUPERVISOR, **kwargs)
        self.parameters = ConfigParameters(self, ('supervisor',), SUPERVISOR_READS,
                                           on_change=self._on_config_change)
        self.config = self.parameters.config
        self.logic = GraspSupervisor(self.config.plant, self.config.supervisor,
                                     load_law(self.config))
        # ids go on from the last one this namespace gave, across restarts of the supervisor
        self._ids = GraspIds(self.context.get_domain_id(), self.get_namespace(),
                             self.get_logger().warning)
        self.logic.continue_ids_after(self._ids.last())
        self.accepted_grasp: tuple[int, dict] | None = None    # id and fields, the last one
        self._side = SupervisorSide(self.logic)
        self.tick_timeout_s = self.declare_parameter(
            'tick_timeout_s', DEFAULT_TICK_TIMEOUT_S, ParameterDescriptor(
                description='wall seconds without progress (a tick commanded by the named '
                            'stage) during a grasp or release before FAULT',
                floating_point_range=[FloatingPointRange(from_value=0.05, to_value=600.0)])).value
        self.status_rate_hz = self.declare_parameter(
            'status_rate_hz', 100.0, ParameterDescriptor(
                description='supervisor/status per simulated second (and on every change)',
                floating_point_range=[FloatingPointRange(from_value=1.0,
                                                         to_value=10000.0)])).value
        follow(self, {'tick_timeout_s': float, 'status_rate_hz': float})   # next check
        self._has_tick = False                              # a tick was decided
        self._ref_bytes: bytes | None = None                # the reference sent for it
        self._ref_topic = None
        self._waiting: tuple[object, object] | None = None  # (request header, response)
        self.response_notes: list[str] = []    # appended to the next answer (e.g. recording)
        self.statuses_published = 0
        self.references_published = 0
        self.published: Counter = Counter()     # messages per (relative) topic
        self._status_now = (0, None, '')          # the newest status: stamp, numbers, text
        self._refs = {controller: self.graph_publisher(StageReference, topic)
                      for controller, topic in STAGE_REFERENCE_TOPICS.items()}
        self._ref_name = TOPIC_POSITION_REFERENCE
        self._status_pub = self.graph_publisher(SupervisorStatus, TOPIC_STATUS)
        self._outcome_pub = self.create_publisher(SupervisorStatus, TOPIC_OUTCOME, LATCHED_QOS)
        self.graph_subscription(PlantTick, TOPIC_TICK, self._on_tick)
        self.sim_paused = False                 # the plant's sim/status says time is held
        self._last_tick_wall = time.monotonic()  # any tick, a republished one included
        self._tripped_wall: float | None = None  # when the watchdog found this silence too long
        self.graph_subscription(SimStatus, TOPIC_SIM_STATUS, self._on_sim_status, raw=False)
        self.create_subscription(AccelStamped, TOPIC_PLANNED_ACCELERATION, self._on_plan,
                                 GRAPH_QOS)
        self.plan_breakpoints = 0               # announced breakpoints taken
        self.grasp_service = DeferredService(self, Grasp, SERVICE_GRASP, self._on_grasp)
        self.release_service = DeferredService(self, Trigger, SERVICE_RELEASE, self._on_release)
        self.move_service = DeferredService(self, Move, SERVICE_MOVE, self._on_move)
        self.create_service(Trigger, SERVICE_STOP, self._on_stop, qos_profile=SERVICE_QOS)
        self.joint_name = declare_prefix(self) + FINGER_JOINT
        self._commands = JointCommandStream(self.config.plant, self.joint_name)
        self.joint_commands_taken = 0           # setpoints put in force
        self.joint_commands_refused = 0
        self.joint_command_handled_ns = -1      # the stamp of the newest one taken or refused
        self.create_subscription(JointState, TOPIC_JOINT_COMMANDS, self._on_joint_command,
                                 GRAPH_QOS)
        self.graph_subscription(ServoSetpoint, TOPIC_SERVO_SETPOINT, self._on_servo_setpoint,
                                raw=False)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._silence = ExecutorSilence()       # executor-running wall time without progress
        self.create_timer(WATCHDOG_PERIOD_S, self._watchdog, clock=steady)
        self.create_timer(STATUS_HEARTBEAT_S, self._heartbeat, clock=steady)

    def _on_config_change(self, config, keys, _checked) -> None:
        """Apply new thresholds from the next tick; a running request keeps its setpoints.

        A new force law applies to the next request.
        """
        self.config = config
        self.logic.params = config.supervisor
        self.get_logger().info(f'{", ".join(keys)} changed: in effect from the next tick')

    def _on_sim_status(self, msg: SimStatus) -> None:
        """Follow sim/pause: simulated time held is no silence, so the watchdog waits with it."""
        if self.sim_paused and not msg.paused:
            self._silence.reset()
        self.sim_paused = msg.paused

    def _on_plan(self, msg: AccelStamped) -> None:
        """Take a breakpoint of the arm's plan: the grip anticipates the load it brings."""
        try:
            self.logic.announce(stamp_ns(msg.header.stamp), msg.accel.linear.z)
        except ValueError as exc:
            self.get_logger().warning(f'{TOPIC_PLANNED_ACCELERATION} ignored: {exc}',
                                      throttle_duration_sec=1.0)
            return
        self.plan_breakpoints += 1

    # ------------------------------------------------------------------ the tick
    @property
    def measured(self) -> bool:
        """Whether a tick of the plant has been decided: requests can start."""
        return self._has_tick

    @property
    def _tick(self) -> Tick | None:
        """The newest tick decided (None before the first)."""
        return Tick._make(self._side.tick_record[0].item()) if self._has_tick else None

    def _on_tick(self, data: bytes) -> None:
        self._last_tick_wall = time.monotonic()   # a repeat too: the plant is alive
        side = self._side
        flags = side.take_tick(data)
        if flags == -FOREIGN:                   # another encapsulation: the general way
            flags = side.take_tick(in_layout(TICK_LAYOUT, data, PlantTick))
        if flags < 0:                           # decided: the plant is still waiting
            if self._ref_bytes is not None:
                self._ref_topic.publish(self._ref_bytes)
                self.published[self._ref_name] += 1
            return
        self._has_tick = True
        if flags & PROGRESS:
            self._silence.reset()               # the named stage's command moved the plant
        if flags & NAMED:
            active = flags >> ACTIVE_SHIFT
            self._ref_topic = self._refs[active]
            self._ref_name = STAGE_REFERENCE_TOPICS[active]
            self._ref_bytes = CDR_LITTLE_ENDIAN + side.reference_record.tobytes()
            self._ref_topic.publish(self._ref_bytes)
            self.references_published += 1
            self.published[self._ref_name] += 1
        else:
            self._ref_bytes = None
        if flags & STATUS_DUE:
            self._publish_status(int(side.tick_record[0]['stamp_ns']))
        if flags & ANSWERED:
            self._complete(self.logic.decision)

    def _publish_status(self, t_ns: int) -> None:
        """Publish the status now: at its rate, on every change, a heartbeat, a request."""
        d = self.logic
        self._side.status_published(t_ns, round(1e9 / self.status_rate_hz))
        tg = d.targets
        position_m, force_n = self._side.good_readings
        values = (int(d.phase), int(d.active), int(d.switch_criterion), d.grasp_id, d.stage_id,
                  int(d.outcome), d.running, int(d.pending_request),
                  tg.position_setpoint_m if tg else 0.0, tg.approach_setpoint_m if tg else 0.0,
                  d.force_setpoint_n if tg else 0.0, d.mass_kg, position_m, force_n,
                  self.config.plant.max_travel_m - position_m, d.contact_ns is not None)
        message = d.message if d.outcome is not Outcome.UNKNOWN else ''
        self._status_now = (t_ns, values, message)
        self._status_pub.publish(status_template().pack(*split_ns(t_ns), *values, text=message))
        self.statuses_published += 1
        self.published[TOPIC_STATUS] += 1

    def _heartbeat(self) -> None:
        self._publish_status(self._tick.stamp_ns if self._tick else 0)

    # ------------------------------------------------------------------ requests
    def _refusal(self, kind: str, preempts: bool = False) -> str:
        """Why a request of ``kind`` cannot start now ('' when it can).

        ``preempts``: it ends what runs (a setpoint); a service request ends only a setpoint's
        move, and waits for nothing else.
        """
        busy = self.logic.running or self.logic.pending
        if busy and not (preempts or self.logic.servo):
            what = self.logic.kind if self.logic.running else 'request'
            return (f'refused: a {what} is running (grasp {self.logic.grasp_id}, phase '
                    f'{self.logic.phase.name}); call {self.resolve_service_name(SERVICE_STOP)} '
                    'first'
                    if kind == RequestKind.RELEASE else
                    f'refused: a {what} is {"running" if self.logic.running else "waiting"}')
        missing = self._missing_peers()
        if missing:
            return f'refused: {GRAPH_NOT_READY}, not yet discovered: {missing}'
        tick = self._tick
        if tick is None:
            return f'refused: {GRAPH_NOT_READY}, no measurement from {NODE_PLANT} yet'
        if not math.isfinite(tick.position_m):
            what = {RequestKind.RELEASE: 'opening', RequestKind.MOVE: 'a move'}.get(
                kind, 'a grasp')
            return (f'refused: the finger position sensor reads {tick.position_m!r} m (sensor '
                    f'dropout); {what} under position control needs it')
        if kind == RequestKind.GRASP and not (math.isfinite(tick.force_n)
                                              and math.isfinite(tick.sensor_voltage_v)):
            return (f'refused: the force sensor reads force {tick.force_n!r} N, voltage '
                    f'{tick.sensor_voltage_v!r} V (sensor dropout); a grasp needs it')
        return ''

    def _missing_peers(self) -> str:
        """Lockstep cannot recover a lost tick: start only when every peer is discovered."""
        missing = []
        for controller, pub in self._refs.items():
            if pub.get_subscription_count() < 1:
                missing.append(f'{pub.topic_name} subscriber ({STAGE_NODES[controller]})')
        if self.count_publishers(TOPIC_MOTOR_COMMAND) < 2:
            missing.append(f'{self.resolve_topic_name(TOPIC_MOTOR_COMMAND)} publishers (both '
                           'controllers)')
        return '; '.join(missing)

    def _accept(self, kind: str, service, header, response, start, on_refusal=None):
        """Start a request, or answer its refusal at once.

        ``start()`` validates and starts the request and returns its targets (RequestError
        refuses it). Return the targets, or None once refused; an accepted request is answered
        in _complete().
        """
        message = self._refusal(kind)
        if not message:
            try:
                targets = start()
            except RequestError as exc:
                message = f'refused: {exc}'
            else:
                ended = self.logic.take_preempted()
                if ended is not None:              # a setpoint's move, answered first
                    self._publish_status(self._tick.stamp_ns)
                    self._complete(ended)
                self._ids.save(self.logic.grasp_id + 1)
                return targets
        response.success = False
        if hasattr(response, 'outcome'):
            response.outcome = Outcome.REFUSED
        response.message = message
        if on_refusal is not None:
            on_refusal(response)
        self.get_logger().warning(f'{kind} {message}')
        service.reply(header, response)
        return None

    def _await_answer(self, header, response) -> None:
        """Hold the accepted request's reply until it ends; the status wakes a paused sim."""
        self._waiting = (header, response)
        self._silence.reset()
        self._publish_status(self._tick.stamp_ns)

    def _on_grasp(self, request: Grasp.Request, header) -> None:
        """Accept a grasp, or refuse it at once."""
        response = Grasp.Response()
        plant, sup = self.config.plant, self.config.supervisor
        targets = self._accept(RequestKind.GRASP, self.grasp_service, header, response,
                               lambda: self.logic.request_grasp(validate_request(GraspRequest(
                                   request.width_m, request.mass_kg,
                                   request.friction_coefficient, request.acceleration_mps2,
                                   request.timeout_s, request.width_tolerance_m), plant, sup,
                                   self.config.load_grip),
                                   request.mass_kg, after_ns=self._tick.stamp_ns))
        if targets is None:
            return
        response.grasp_id = self.logic.grasp_id + 1
        self.accepted_grasp = (response.grasp_id, {
            f.name: float(getattr(request, f.name)) for f in fields(GraspRequest)})
        response.position_setpoint_m = targets.position_setpoint_m
        response.force_setpoint_n = targets.force_setpoint_n
        self.get_logger().info(
            f'grasp {response.grasp_id}: width {request.width_m:g} m, mass {request.mass_kg:g} '
            f'kg -> position {targets.position_setpoint_m:.4f} m, force '
            f'{targets.force_setpoint_n:.3f} N')
        self._await_answer(header, response)

    def _on_release(self, request: Trigger.Request, header) -> None:
        """Open the fingers (position stage to fully open), or refuse at once."""
        response = Trigger.Response()
        if self._accept(RequestKind.RELEASE, self.release_service, header, response,
                        lambda: self.logic.request_release(after_ns=self._tick.stamp_ns)) is None:
            return
        self.get_logger().info(f'release {self.logic.grasp_id + 1}: opening from '
                               f'{self._tick.position_m:.5f} m')
        self._await_answer(header, response)

    def _on_move(self, request: Move.Request, header) -> None:
        """Accept a move, or refuse it at once."""
        response = Move.Response()
        plant, sup = self.config.plant, self.config.supervisor
        targets = self._accept(RequestKind.MOVE, self.move_service, header, response,
                               lambda: self.logic.request_move(validate_move(MoveRequest(
                                   request.width_m, request.speed_mps, request.max_effort_n,
                                   request.timeout_s), plant, sup),
                                   after_ns=self._tick.stamp_ns),
                               self._fill_move_state)
        if targets is None:
            return
        self.get_logger().info(
            f'move {self.logic.grasp_id + 1}: width {request.width_m:g} m -> position '
            f'{targets.position_setpoint_m:.4f} m at most at {targets.speed_mps:g} m/s, '
            f'{targets.max_effort_n:.3f} N')
        self._await_answer(header, response)

    def _on_joint_command(self, msg: JointState) -> None:
        """Take a joint_commands message, then note its stamp: a world in step waits on it."""
        try:
            self._take_joint_command(msg)
        finally:
            self.joint_command_handled_ns = stamp_ns(msg.header.stamp)

    def _take_joint_command(self, msg: JointState) -> None:
        """Put a new setpoint in force; refuse a bad one with one line, changing nothing."""
        sample_ns = stamp_ns(msg.header.stamp) or None   # when it was sampled, if stamped
        try:
            move = self._commands.take(msg)
            if move is None:                    # the setpoint in force, again: it stands
                self.logic.servo_repeated(sample_ns)
                return
            targets = self._setpoint_targets(move)
        except RequestError as exc:
            self.joint_commands_refused += 1
            self.get_logger().warning(f'{TOPIC_JOINT_COMMANDS} refused: {one_line(exc)}',
                                      throttle_duration_sec=1.0)
            return
        self._commands.accept(move)
        self._put_setpoint(targets, TOPIC_JOINT_COMMANDS, move.width_m, sample_ns=sample_ns)

    def _on_servo_setpoint(self, msg: ServoSetpoint) -> None:
        """Put a setpoint with its velocity and acceleration in force, or refuse it in a line."""
        plant = self.config.plant
        try:
            if msg.name != self.joint_name:
                raise RequestError(f'setpoint for joint {msg.name!r}; this gripper has one '
                                   f'joint, {self.joint_name!r}')
            position_m = msg.position_m
            if not (math.isfinite(position_m) and 0.0 <= position_m <= plant.max_travel_m):
                raise RequestError(f'position of {self.joint_name!r} must be in '
                                   f'[0, {plant.max_travel_m:g}] m, got {position_m!r}')
            move = MoveRequest(plant.max_travel_m - position_m, msg.speed_mps, msg.max_effort_n)
            targets = self._setpoint_targets(move)
        except RequestError as exc:
            self.joint_commands_refused += 1
            self.get_logger().warning(f'{TOPIC_SERVO_SETPOINT} refused: {one_line(exc)}',
                                      throttle_duration_sec=1.0)
            return
        self._put_setpoint(targets, TOPIC_SERVO_SETPOINT, move.width_m,
                           velocity_mps=msg.velocity_mps, acceleration_mps2=msg.acceleration_mps2,
                           sample_ns=stamp_ns(msg.header.stamp) or None)

    def _setpoint_targets(self, move: MoveRequest):
        """Return a setpoint's move as targets, or raise RequestError why it cannot preempt."""
        targets = validate_move(move, self.config.plant, self.config.supervisor)
        refusal = self._refusal(RequestKind.MOVE, preempts=True)
        if refusal:
            raise RequestError(refusal.removeprefix('refused: '))
        return targets

    def _put_setpoint(self, targets, topic: str, width_m: float, *,
                      velocity_mps: float = math.nan, acceleration_mps2: float = math.nan,
                      sample_ns: int | None = None) -> None:
        """Put a checked setpoint of ``topic`` in force.

        With its velocity and acceleration (NaN: estimated from the stream) and its sample's
        instant (None: not known). What it ends is answered; a new move is logged and wakes a
        paused simulation.
        """
        ended = self.logic.request_servo(
            targets, after_ns=self._tick.stamp_ns,
            message=f'preempted by a setpoint on {self.resolve_topic_name(topic)}',
            velocity_mps=velocity_mps, acceleration_mps2=acceleration_mps2, sample_ns=sample_ns)
        self.joint_commands_taken += 1
        if ended is not None:
            self._publish_status(self._tick.stamp_ns)
            self._complete(ended)
        if self.logic.pending:                  # a new move (not the running one retargeted)
            self._ids.save(self.logic.grasp_id + 1)
            self.get_logger().info(
                f'move {self.logic.grasp_id + 1}: {topic} width '
                f'{width_m:g} m -> position {targets.position_setpoint_m:.4f} m at most '
                f'at {targets.speed_mps:g} m/s, {targets.max_effort_n:.3f} N')
            self._silence.reset()
            self._publish_status(self._tick.stamp_ns)   # wakes a paused simulation

    def _fill_move_state(self, response: Move.Response) -> None:
        """Fill in a move's answer the finger's state: the last finite readings."""
        position_m, response.effort_n = self._side.good_readings
        response.position_m = position_m
        response.width_m = self.config.plant.max_travel_m - position_m

    def _on_stop(self, request: Trigger.Request, response: Trigger.Response):
        """End the running request or the hold now; the position stage then holds the finger."""
        what = self.logic.kind or 'grasp'
        decision = self.stop_grasp('stopped on request (stop)')
        if decision is None:
            response.success = False
            response.message = ('nothing to stop: no grasp, hold, release or move is running, '
                                'no stalled move presses')
            return response
        response.success = True
        response.message = f'{what} {self.logic.grasp_id} stopped'
        return response

    def stop_grasp(self, message: str = 'stopped on request'):
        """End the running request (STOPPED); the decision, or None with nothing to stop."""
        decision = self.logic.stop(message)
        if decision is not None:
            self._publish_status(self._tick.stamp_ns if self._tick else 0)
            self._complete(decision)
        return decision

    def _complete(self, decision) -> None:
        """Latch an answer and answer the waiting request with it."""
        self._outcome_pub.publish(status_message(*self._status_now))
        what = self.logic.kind or 'grasp'
        self.get_logger().info(f'{what} {self.logic.grasp_id}: {decision.answer.name}: '
                               f'{decision.message}')
        waiting, self._waiting = self._waiting, None
        if waiting is None:
            return
        header, response = waiting
        notes, self.response_notes = self.response_notes, []
        message = '; '.join([decision.message, *notes])
        if isinstance(response, Trigger.Response):            # a release
            response.success = decision.answer is Outcome.RELEASED
            response.message = f'{decision.answer.name}: {message}'
            self.release_service.reply(header, response)
            return
        if isinstance(response, Move.Response):
            response.outcome = int(decision.answer)
            response.reached_goal = response.success = decision.answer is Outcome.MOVED
            response.stalled = decision.answer is Outcome.STALLED
            response.message = message
            response.grasp_id = self.logic.grasp_id
            self._fill_move_state(response)
            self.move_service.reply(header, response)
            return
        logic = self.logic
        response.success = decision.answer is Outcome.HOLDING
        response.outcome = int(decision.answer)
        response.message = message
        response.grasp_id = logic.grasp_id
        position_m, response.final_force_n = self._side.good_readings   # the last finite
        response.final_position_m = position_m
        response.final_width_m = self.config.plant.max_travel_m - position_m
        if logic.switch_ns is not None:
            response.switch_time_s = (logic.switch_ns - logic.start_ns) * 1e-9
        self.grasp_service.reply(header, response)

    # ------------------------------------------------------------------ watchdog
    def _watchdog(self) -> None:
        """Lockstep stalls if a node dies: end the request as FAULT, naming who went silent.

        Only time in which the executor demonstrably ran counts (``ExecutorSilence``): after a
        stall of the whole process, ticks queued behind this timer are not silence. A plant
        still discovered is told alive or gone by its republished ticks: the fault waits for
        the next one (due within ``REPUBLISH_AFTER_S``) or for their silence.
        """
        running = self.logic.running
        silent_s = self._silence.check(counting=running and not self.sim_paused)
        if not running or silent_s < self.tick_timeout_s:
            self._tripped_wall = None
            return
        now = time.monotonic()
        if self._tripped_wall is None:
            self._tripped_wall = now
        expected = STAGE_NODES.get(self.logic.active, '?')
        commanders = {i.node_name for i in self.get_publishers_info_by_topic(
            self.resolve_topic_name(TOPIC_MOTOR_COMMAND))}
        plants = {i.node_name for i in self.get_publishers_info_by_topic(
            self.resolve_topic_name(TOPIC_TICK))}
        tick_silent_s = now - self._last_tick_wall
        if expected not in commanders:
            who = f'{expected} is gone (no publisher on {TOPIC_MOTOR_COMMAND})'
        elif NODE_PLANT not in plants:
            who = f'{NODE_PLANT} is gone (no publisher on {TOPIC_TICK})'
        elif tick_silent_s >= max(self.tick_timeout_s, 2 * REPUBLISH_AFTER_S):
            # a live plant publishes an unanswered tick again every REPUBLISH_AFTER_S
            who = (f'{NODE_PLANT} is gone or hung (no tick at all for {tick_silent_s:.2f} s; '
                   f'a killed process stays discovered for a while)')
        elif self._last_tick_wall <= self._tripped_wall:
            return                              # no tick since: alive or gone, the next says
        else:
            who = f'{expected} did not answer or {NODE_PLANT} did not advance'
        t_ns = self._tick.stamp_ns if self._tick else 0
        message = (f'fault: no progress for {silent_s:.2f} s of wall time at '
                   f't={t_ns * 1e-9:.4f} s: {who}')
        self.get_logger().error(message)
        decision = self.logic.fault(message)
        self._side.expect_nobody()
        self._publish_status(t_ns)
        self._complete(decision)


def main(args=None):
    return run_node(SupervisorNode, NODE_SUPERVISOR, args, (SERVICE_GRASP,))


if __name__ == '__main__':
    sys.exit(main())
