"""plant_simulator: the gripper's motor, lead screw, fingers and object, as simulated hardware.

Lockstep: it publishes the measurement of tick ``t_k`` on ``loop/tick``, takes the command of
``t_k`` from ``loop/motor_command`` (the stage the supervisor named, as the command's echo says),
holds it for the command's ``hold_s`` and publishes tick ``t_k + hold_s``. How simulated time
runs is the parameter ``time_mode`` (:mod:`gripper_ros.core.runtime.pacing`):

- ``realtime`` (default): time always advances, paced to the wall clock by ``real_time_factor``
  and never ahead of it; with no command (no supervisor yet, a FAULT, a node gone for
  ``command_timeout_s``) the motor is held at 0 V and time goes on.
- ``fast``: lockstep as fast as the graph goes while a request needs time (the command's echo
  says so, or a lift is being played out), then time pauses until the next request.
- with ``use_sim_time`` true: in step with the ``/clock`` a world simulator publishes, from the
  world's time of its first ``/clock`` on, held while the world's time stands still; it
  publishes no ``/clock`` itself. Otherwise as realtime.

``sim/pause``, ``sim/resume`` and ``sim/step`` (ticks or a duration) hold and advance time in
the first two modes. For other programs it publishes, at ``state_rate_hz`` of simulated time,
``joint_states``, ``force_sensor``, ``sim/object_state`` (ground truth of the held object) and,
with ``publish_clock``, ``/clock``; and ``sim/status`` (mode, pause, achieved real-time factor)
about once a second and on every change. ``sim/set_object`` places an object, its hold physics
and a lift, and may schedule a fault for the next grasp.

The node wires topics, services and timers to the core: when to step and with what
(:mod:`gripper_ros.core.runtime.plant_loop`), what the world may be set to
(:mod:`gripper_ros.core.runtime.world`), the simulated arm's announcements
(:mod:`gripper_ros.core.runtime.arm`).
"""
from __future__ import annotations

from collections import Counter
import sys
import time

from geometry_msgs.msg import AccelStamped
from gripper_interfaces.msg import (ForceSensor, MotorCommand, ObjectState, PlantTick, SimStatus,
                                    SupervisorStatus)
from gripper_interfaces.srv import SetObject, SimStep
from gripper_ros.core.control.factories import make_plant
from gripper_ros.core.runtime.arm import LiftAnnouncer
from gripper_ros.core.runtime.lockstep import (Command, command_problem, FOREIGN, PlantSide,
                                               REFUSED, REPEATED, side_state_published, Tick)
from gripper_ros.core.runtime.pacing import (ClockPacing, HELD, IDLE, make_pacing, NOW,
                                             step_problem, WorldTime)
from gripper_ros.core.runtime.plant_loop import Chore, PlantLoop, STEP_BATCH
from gripper_ros.core.runtime.world import placed_message, placement
from gripper_ros.nodes.gripper_node import GripperNode
from gripper_ros.nodes.loop_io import (clock_template, force_sensor_template, in_layout,
                                       joint_state_template, object_state_template,
                                       read_status, split_ns)
from gripper_ros.nodes.object_marker import ObjectMarkerPublisher
from gripper_ros.nodes.parameters import ConfigParameters, declare_prefix
from gripper_ros.nodes.process import run_node
from gripper_ros.nodes.qos import GRAPH_QOS, SERVICE_QOS
from gripper_ros.nodes.services import DeferredService
from gripper_ros.nodes.stamps import ns_to_time
from gripper_ros.nodes.startup import StartupError
from gripper_ros.wire import (CDR_LITTLE_ENDIAN, COMMAND_LAYOUT,
                              DEFAULT_STATE_RATE_HZ, FINGER_JOINT, FRAME_BASE, NODE_PLANT,
                              SERVICE_PAUSE, SERVICE_RESUME, SERVICE_SET_OBJECT, SERVICE_STEP,
                              TIME_MODE_CHOICES, TimeMode, TOPIC_CLOCK,
                              TOPIC_FORCE_SENSOR, TOPIC_JOINT_STATES, TOPIC_LOAD_ACCELERATION,
                              TOPIC_MOTOR_COMMAND, TOPIC_OBJECT_STATE,
                              TOPIC_PLANNED_ACCELERATION, TOPIC_SIM_STATUS, TOPIC_STATUS,
                              TOPIC_TICK)
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor, SetParametersResult
from rclpy.clock import Clock, ClockType, JumpThreshold
from rclpy.duration import Duration
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

HOUSEKEEPING_PERIOD_S = 0.05
"""Steady timer: republish a tick nobody answered, free-run without commands, sim/status."""
SIM_STATUS_PERIOD_S = 1.0


class PlantSimulatorNode(GripperNode):
    """The ROS face of the simulated plant: :class:`PlantLoop` over a :class:`PlantSide`."""

    def __init__(self, **kwargs):
        super().__init__(NODE_PLANT, **kwargs)
        self.parameters = ConfigParameters(
            self, (), ('plant', 'contact', 'force_sensor', 'sensor_noise', 'pad_sensor',
                       'force_control.sample_time_s'))
        self.config = self.parameters.config
        self.side = PlantSide(make_plant(self.config))
        self.plant = self.side.plant
        self.placed: tuple[int, dict | None] = (0, None)   # SetObjects accepted, the last one
        prefix = declare_prefix(self)
        self.joint_name = prefix + FINGER_JOINT
        self.frame_id = self._param('frame_id', prefix + FRAME_BASE,
                                    "frame_id of every published header (the URDF's base link)",
                                    read_only=True)
        mode = self._param('time_mode', TimeMode.REALTIME.parameter,
                           'realtime: paced to the wall clock, always advancing | fast: as '
                           'fast as the graph goes while a request runs',
                           read_only=True)
        if mode not in TIME_MODE_CHOICES:
            raise StartupError(f'parameter "time_mode" must be {" or ".join(TIME_MODE_CHOICES)}, '
                               f'got {mode!r}')
        self.time_mode = TimeMode[str(mode).upper()]
        if self.get_parameter('use_sim_time').value:
            if self.time_mode is TimeMode.FAST:
                raise StartupError('use_sim_time follows the /clock of a world simulator: '
                                   'time_mode must be realtime (the default), not fast')
            self.time_mode = TimeMode.SIM_TIME
        self.real_time_factor = self._param(
            'real_time_factor', 1.0, 'realtime: simulated seconds per wall second',
            (1e-3, 100.0))
        self.state_rate_hz = self._param(
            'state_rate_hz', DEFAULT_STATE_RATE_HZ, 'rate (per simulated second) of joint_states, '
            'force_sensor, sim/object_state and /clock', (1.0, 10000.0))
        self.command_timeout_s = self._param(
            'command_timeout_s', 1.0, 'realtime and use_sim_time: wall seconds without a '
            'command before the motor is held at 0 V and time goes on', (0.01, 600.0))
        self.publish_clock = self._param(
            'publish_clock', True, 'publish /clock (one simulator per ROS graph should; never '
            'with use_sim_time)', read_only=True) and self.time_mode is not TimeMode.SIM_TIME
        self.add_on_set_parameters_callback(self._keep_use_sim_time)
        self.add_post_set_parameters_callback(self._on_parameters_set)

        self.ticks_published = 0
        self.published: Counter = Counter()     # messages per (relative) topic
        self.commands_rejected = 0
        self.commands_ignored = 0               # stale, duplicate or superseded
        self.pacing = make_pacing(self.time_mode, self.plant.t_ns, self.real_time_factor)
        self.loop = PlantLoop(self.side, self.pacing, round(1e9 / self.state_rate_hz),
                              time.monotonic())
        self._tick_bytes = CDR_LITTLE_ENDIAN + self.side.tick_record.tobytes()
        self._step_reply = None                 # (header, response) of a running sim/step
        self._pace_wait = False                 # waiting for the pace timer
        self._last_sim_status = 0.0
        self._advancing = False
        self._held = self.pacing.held           # as the last sim/status said

        self._tick_pub = self.graph_publisher(PlantTick, TOPIC_TICK)
        self._joint_pub = self.graph_publisher(JointState, TOPIC_JOINT_STATES)
        self._force_pub = self.tapped_publisher(ForceSensor, TOPIC_FORCE_SENSOR, GRAPH_QOS)
        self._object_pub = self.tapped_publisher(ObjectState, TOPIC_OBJECT_STATE, GRAPH_QOS)
        self._marker = ObjectMarkerPublisher(self)
        self._sim_pub = self.graph_publisher(SimStatus, TOPIC_SIM_STATUS)
        self._clock_pub = self.create_publisher(ClockMsg, TOPIC_CLOCK, GRAPH_QOS) \
            if self.publish_clock else None
        self.graph_subscription(MotorCommand, TOPIC_MOTOR_COMMAND, self._on_command)
        self.graph_subscription(SupervisorStatus, TOPIC_STATUS, self._on_status)
        self.create_subscription(AccelStamped, TOPIC_LOAD_ACCELERATION,
                                 self._on_load_acceleration, GRAPH_QOS)
        self.loads_refused = 0
        self._plan_pub = self.create_publisher(AccelStamped, TOPIC_PLANNED_ACCELERATION,
                                               GRAPH_QOS)
        self.arm = LiftAnnouncer()              # the simulated arm
        self.create_service(SetObject, SERVICE_SET_OBJECT, self._on_set_object,
                            qos_profile=SERVICE_QOS)
        self.create_service(Trigger, SERVICE_PAUSE, self._on_pause, qos_profile=SERVICE_QOS)
        self.create_service(Trigger, SERVICE_RESUME, self._on_resume, qos_profile=SERVICE_QOS)
        self.step_service = DeferredService(self, SimStep, SERVICE_STEP, self._on_step)
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._pace_timer = self.create_timer(1.0, self._on_pace_timer, clock=self._steady)
        self._pace_timer.cancel()
        self.create_timer(HOUSEKEEPING_PERIOD_S, self._housekeeping, clock=self._steady)

        self._joint_layout = joint_state_template(self.joint_name, self.frame_id)
        self._force_layout = force_sensor_template(self.frame_id)
        self._object_layout = object_state_template(self.frame_id)
        self._clock_layout = clock_template()
        self._said_ready = False                # said once the process's nodes all started
        if isinstance(self.pacing, ClockPacing):    # the world's first time starts it
            self._world_jumps = self.get_clock().create_jump_callback(
                JumpThreshold(min_forward=Duration(nanoseconds=1),
                              min_backward=Duration(nanoseconds=-1), on_clock_change=False),
                post_callback=self._on_world_time)
        else:
            self._publish_tick()
            self._publish_state()
        self._publish_sim_status()

    def _param(self, name, default, description, value_range=None, read_only=False):
        descriptor = ParameterDescriptor(description=description, read_only=read_only)
        if value_range is not None:
            descriptor.floating_point_range = [FloatingPointRange(
                from_value=value_range[0], to_value=value_range[1])]
        return self.declare_parameter(name, default, descriptor).value

    def _keep_use_sim_time(self, parameters) -> SetParametersResult:
        """Refuse a change of ``use_sim_time``: the time mode is chosen at start-up."""
        for p in parameters:
            if p.name == 'use_sim_time' and \
                    bool(p.value) != (self.time_mode is TimeMode.SIM_TIME):
                return SetParametersResult(successful=False, reason=(
                    'use_sim_time is read at start-up, when the plant chooses how its time '
                    'runs: restart the gripper to change it'))
        return SetParametersResult(successful=True)

    def _on_parameters_set(self, parameters) -> None:
        """Apply accepted changes from the next tick (the descriptors refuse the rest)."""
        for p in parameters:
            if p.name == 'real_time_factor':
                self.real_time_factor = self.pacing.real_time_factor = float(p.value)
                self.pacing.restart(self.plant.t_ns)
            elif p.name == 'state_rate_hz':
                self.state_rate_hz = float(p.value)
                self.loop.state_period_ns = round(1e9 / self.state_rate_hz)
            elif p.name == 'command_timeout_s':
                self.command_timeout_s = float(p.value)

    @property
    def tick(self) -> Tick:
        """The current tick: its measurement, as published."""
        return Tick._make(self.side.tick_record[0].item())

    # ------------------------------------------------------------------ lockstep
    def _on_command(self, data: bytes) -> None:
        taken = self.side.take_command(data, self.loop.pending)
        if taken == FOREIGN:                    # another encapsulation: the general way
            taken = self.side.take_command(in_layout(COMMAND_LAYOUT, data, MotorCommand),
                                           self.loop.pending)
        if taken == REPEATED:
            self.commands_ignored += 1          # stale, for the world before, or a repeat
            return
        if taken == REFUSED:
            cmd = Command._make(self.side.offered[0].item())
            self.commands_rejected += 1
            self.get_logger().error(f'refusing the command of t={cmd.stamp_ns * 1e-9:.4f} s from '
                                    f'source {cmd.source}: {command_problem(cmd)}; motor held '
                                    'at 0 V', throttle_duration_sec=1.0)
            return
        self.loop.command_accepted()
        self._announce_if_begun()
        self._try_step()

    def _announce_if_begun(self) -> None:
        """Publish the lift's plan on arm/planned_acceleration once its hold has begun."""
        if not (self.arm.armed and self.arm.due(int(self.side.state[0]['hold_begun_for']))):
            return
        for t_ns, accel in self.plant.lift_plan():
            msg = AccelStamped()
            msg.header.stamp = ns_to_time(t_ns)
            msg.header.frame_id = self.frame_id
            msg.accel.linear.z = accel
            self._plan_pub.publish(msg)

    @property
    def plans_announced(self) -> int:
        """Lift plans the simulated arm announced."""
        return self.arm.announced

    def _on_load_acceleration(self, msg: AccelStamped) -> None:
        """Take a live arm's upward acceleration: it loads the held object's pads from now."""
        try:
            self.plant.drive_load(msg.accel.linear.z)
        except ValueError as exc:
            self.loads_refused += 1
            self.get_logger().warning(f'{TOPIC_LOAD_ACCELERATION} ignored: {exc}',
                                      throttle_duration_sec=1.0)
            return
        self._publish_state()
        self._try_step()                        # fast mode: the load needs simulated time

    def _on_status(self, data: bytes) -> None:
        self.loop.take_status(read_status(data))
        self._try_step()

    def _on_world_time(self, jump) -> None:
        """Follow the world's time: the node's ROS clock changed (a /clock, use_sim_time).

        The change is the jump's; the clock itself is read only for the first (``now()`` costs
        as much as the rest of a call, and a world may publish a thousand a second).
        """
        known_ns = self.pacing.world_ns
        world_ns = self.get_clock().now().nanoseconds if known_ns is None else \
            known_ns + jump.delta.nanoseconds
        change = self.pacing.take_world_time(world_ns)
        if change is WorldTime.START:           # the simulation starts at the world's time
            self.loop.start_at(world_ns)
            self._publish_tick()
            self._publish_state()
            self.get_logger().info(f'following /clock from t={self.loop.stamp_ns * 1e-9:.4f} s')
        elif change is WorldTime.BACK and world_ns < self.loop.stamp_ns:
            self.get_logger().warning(
                f'/clock went back to t={world_ns * 1e-9:.4f} s (a world reset?): the gripper, '
                f"at t={self.loop.stamp_ns * 1e-9:.4f} s, holds until the world's time passes "
                'its own; restart it to start over', throttle_duration_sec=5.0)
        if self._held != self.pacing.held:
            self._publish_sim_status(window=False)
        self._try_step()

    def _try_step(self) -> None:
        """Step while the pacing's gate is open; without a command, step unpowered.

        Unpowered steps come in batches of ``STEP_BATCH`` (a sim/step, a world's time far
        ahead), between which the executor serves other callbacks (a sim/pause ends the step).
        """
        batch = STEP_BATCH
        loop, pacing = self.loop, self.pacing
        while True:
            powered = loop.pending
            wait_s = loop.gate()
            if wait_s is HELD:
                return
            if wait_s > NOW:
                if wait_s == IDLE:
                    self._set_advancing(False)  # nothing needs time: it pauses here
                else:
                    self._wait(wait_s)
                return
            if not self._advancing:
                self._set_advancing(True)
            due = loop.step()
            self._publish_tick()
            if due:
                self._publish_state()
            if pacing.stepping and pacing.spend(loop.stamp_ns):
                self._end_step()
            if powered or loop.fast:
                return                          # lockstep: the next step needs its command
            batch -= 1
            if batch <= 0:
                self._wait(0.0)                 # go on after what else waits
                return

    def _set_advancing(self, advancing: bool) -> None:
        """sim/status at once when simulated time starts or stops advancing (fast mode)."""
        if advancing != self._advancing:
            self._advancing = advancing
            self._publish_sim_status(window=False)

    def _wait(self, lead_s: float) -> None:
        """Realtime: step again once the wall clock has caught up.

        One timer, re-armed: a timer made per tick costs the executor a rebuild of its entities
        every time.
        """
        if self._pace_wait:
            return
        self._pace_wait = True
        self._pace_timer.timer_period_ns = max(1, round(lead_s * 1e9))
        self._pace_timer.reset()

    def _on_pace_timer(self) -> None:
        self._pace_timer.cancel()
        if self._pace_wait:
            self._pace_wait = False
            self._try_step()

    def _publish_tick(self) -> None:
        self._tick_bytes = CDR_LITTLE_ENDIAN + self.side.tick_record.tobytes()
        self._tick_pub.publish(self._tick_bytes)
        self.loop.published(time.monotonic())
        self.ticks_published += 1
        self.published[TOPIC_TICK] += 1

    # ------------------------------------------------------------------ state topics
    def _publish_state(self) -> None:
        """joint_states, force_sensor, sim/object_state and /clock for the current tick."""
        tick = self.tick
        sec, nanosec = split_ns(tick.stamp_ns)
        side_state_published(self.side.state, self.plant.kernel, self.side.tick_record,
                             self.loop.state_period_ns)
        if self._clock_pub is not None:
            self._clock_pub.publish(self._clock_layout.pack(sec, nanosec))
            self.published[TOPIC_CLOCK] += 1
        self._joint_pub.publish(self._joint_layout.pack(
            sec, nanosec, tick.position_m, tick.velocity_mps, tick.force_n))
        self.published[TOPIC_JOINT_STATES] += 1
        self.last_state_ns = tick.stamp_ns
        self._force_pub.publish(self._force_layout.pack(
            sec, nanosec, tick.force_n, tick.peak_force_n, tick.sensor_voltage_v))
        self.published[TOPIC_FORCE_SENSOR] += 1
        state = self.plant.object_state
        self._object_pub.publish(self._object_layout.pack(
            sec, nanosec, int(state.state), state.slip_m, state.slip_speed_mps, state.load_n,
            state.capacity_n, state.lift_acceleration_mps2))
        self.published[TOPIC_OBJECT_STATE] += 1
        self._marker.publish(sec, nanosec, state.state, state.slip_m, tick.position_m)

    def _publish_sim_status(self, window: bool = True) -> None:
        """sim/status; ``window``: the periodic one, which measures the real-time factor."""
        pacing = self.pacing
        if window:
            rtf, elapsed, advanced = pacing.achieved(self.plant.t_ns)
            self._last_sim_status = time.monotonic()
        else:
            rtf, advanced = pacing.last_factor, self._advancing
        self._held = pacing.held
        msg = SimStatus(time_mode=int(self.time_mode), paused=self._held, advancing=advanced,
                        real_time_factor_target=pacing.target_factor,
                        real_time_factor=rtf, ticks=self.ticks_published)
        msg.header.stamp = ns_to_time(self.plant.t_ns)
        self._sim_pub.publish(msg)
        self.published[TOPIC_SIM_STATUS] += 1
        warning = pacing.pace_warning(self.plant.t_ns, rtf, elapsed) if window else ''
        if warning:
            self.get_logger().warning(warning)

    def _say_ready(self) -> None:
        """Say the plant is ready; the first tick goes out again to the nodes built after it."""
        self._said_ready = True
        if self.ticks_published and not (self.loop.pending or self.loop.unpowered):
            self._republish_tick(time.monotonic())
        self.get_logger().info(
            f'plant ready ({self.time_mode.text}): travel '
            f'{self.config.plant.max_travel_m:g} m, max force {self.config.plant.max_force_n:.2f} '
            f'N at {self.config.plant.voltage_limit_v:g} V')

    def _housekeeping(self) -> None:
        if not self._said_ready:                # spinning: every start-up check has passed
            self._say_ready()
        now = time.monotonic()
        if now - self._last_sim_status >= SIM_STATUS_PERIOD_S:
            self._publish_sim_status()
        elif self._held != self.pacing.held:    # the world's time stopped or went on
            self._publish_sim_status(window=False)
        chore = self.loop.chore(now, self._pace_wait, self.command_timeout_s)
        if chore is Chore.TIMED_OUT:
            self.get_logger().error(
                f'no command for t={self.loop.stamp_ns * 1e-9:.4f} s in '
                f'{self.loop.silent_s(now):.2f} s: motor held at 0 V, time goes on',
                throttle_duration_sec=5.0)
        if chore in (Chore.RUN, Chore.TIMED_OUT):
            self._try_step()                    # nobody commands: time goes on at 0 V
        elif chore is Chore.REPUBLISH:
            self._republish_tick(now)           # nobody answered: a late peer

    def _republish_tick(self, now_s: float) -> None:
        """Publish the unanswered tick again (a peer that came after it)."""
        self._tick_pub.publish(self._tick_bytes)
        self.published[TOPIC_TICK] += 1
        self.loop.republished(now_s)

    # ------------------------------------------------------------------ sim services
    def _end_step(self, cut_short: str = '') -> None:
        """Answer the running sim/step: done, or ``cut_short`` (success false) by a pause."""
        if not self.pacing.stepping:
            return
        self.pacing.end_step(self.plant.t_ns)
        reply, self._step_reply = self._step_reply, None
        if reply is not None:
            header, response = reply
            response.success = not cut_short
            response.time_s = self.plant.t_ns * 1e-9
            response.message = f'{cut_short}: ' if cut_short else ''
            response.message += f'stepped to t={response.time_s:.6f} s'
            self.step_service.reply(header, response)

    def _on_step(self, request: SimStep.Request, header) -> None:
        response = SimStep.Response()
        ticks, duration = int(request.ticks), float(request.duration_s)
        problem = self.pacing.pause_refusal() or \
            ('a step is already running' if self._step_reply is not None else '') or \
            step_problem(ticks, duration)
        if problem:
            response.success = False
            response.message = f'refused: {problem}'
            response.time_s = self.plant.t_ns * 1e-9
            self.step_service.reply(header, response)
            return
        self.pacing.start_step(ticks, duration, self.plant.t_ns)
        self._step_reply = (header, response)
        self._try_step()

    def _on_pause(self, request, response):
        refusal = self.pacing.pause_refusal()
        paused = self.pacing.paused
        response.success = not paused and not refusal
        response.message = f'refused: {refusal}' if refusal else \
            f'paused at t={self.plant.t_ns * 1e-9:.6f} s' if not paused else 'already paused'
        if refusal:
            return response
        self.pacing.paused = True
        self._end_step('ended by sim/pause')
        self._publish_sim_status()
        return response

    def _on_resume(self, request, response):
        refusal = self.pacing.pause_refusal()
        paused = self.pacing.paused
        response.success = paused and not refusal
        response.message = f'refused: {refusal}' if refusal else \
            f'resumed at t={self.plant.t_ns * 1e-9:.6f} s' if paused else 'not paused'
        if refusal:
            return response
        self.pacing.paused = False
        self.pacing.restart(self.plant.t_ns)
        self._publish_sim_status()
        self._try_step()
        return response

    @property
    def paused(self) -> bool:
        """Simulated time is held: sim/pause, or a world whose /clock stands still."""
        return self.pacing.held

    @property
    def advancing(self) -> bool:
        """Fast mode: False once nothing needs simulated time (the plant waits for a request)."""
        return self._advancing

    # ------------------------------------------------------------------ simulation set-up
    def _on_set_object(self, request: SetObject.Request,
                       response: SetObject.Response) -> SetObject.Response:
        self.deliver_queued()                   # the supervisor's word on what runs, as it stands
        busy = self.loop.busy_reason()
        if busy:
            response.success = False
            response.message = f'refused: {busy}'
            return response
        try:
            placed = placement(request, self.plant)
            self.side.set_object(placed.obj, request.open_fingers, placed.fault, lift=placed.lift)
            self.arm.arm(placed.announce_lift, int(self.side.state[0]['hold_begun_for']))
        except (ValueError, TypeError) as exc:
            response.success = False
            response.message = f'refused: {exc}'
            return response
        self.placed = (self.placed[0] + 1, {
            name: float(value) if name not in ('fault', 'lift_profile') else int(value)
            for name, value in ((n, getattr(request, n))
                                for n in request.get_fields_and_field_types())})
        self.loop.placed()
        if self.pacing.started:                 # (following /clock: once the world's came)
            self._publish_tick()
            self._publish_state()
        response.success = True
        response.message = placed_message(placed, self.plant)
        return response


def main(args=None):
    return run_node(PlantSimulatorNode, NODE_PLANT, args)


if __name__ == '__main__':
    sys.exit(main())
