"""plant_simulator: the gripper's motor, lead screw, fingers and object, as simulated hardware.

Lockstep: it publishes the measurement of tick ``t_k`` on ``loop/tick``, takes the command of
``t_k`` from ``loop/motor_command`` (the stage the supervisor named, as the command's echo says),
holds it for the command's ``hold_s`` and publishes tick ``t_k + hold_s``. How simulated time
runs is the parameter ``time_mode``:

- ``realtime`` (default): time always advances, paced to the wall clock by ``real_time_factor``
  and never ahead of it; with no command (no supervisor yet, a FAULT, a node gone for
  ``command_timeout_s``) the motor is held at 0 V and time goes on.
- ``fast``: lockstep as fast as the graph goes while a request needs time (the command's echo
  says so, or a lift is being played out), then time pauses until the next request.

``sim/pause``, ``sim/resume`` and ``sim/step`` (ticks or a duration) hold and advance time in
either mode. For other programs it publishes, at ``state_rate_hz`` of simulated time,
``joint_states``, ``force_sensor``, ``sim/object_state`` (ground truth of the held object) and,
with ``publish_clock``, ``/clock``; and ``sim/status`` (mode, pause, achieved real-time factor)
about once a second. ``sim/set_object`` places an object, its hold physics and a lift, and may
schedule a fault for the next grasp.
"""
from __future__ import annotations

from collections import Counter
import math
import sys
import time

from geometry_msgs.msg import AccelStamped
from gripper_interfaces.msg import (ForceSensor, MotorCommand, ObjectState, PlantTick, SimStatus,
                                    SupervisorStatus)
from gripper_interfaces.srv import SetObject, SimStep
from gripper_ros.core.control.factories import make_plant
from gripper_ros.core.physics.plant import check_fault, GraspObject, Lift
from gripper_ros.core.runtime.lockstep import (Command, command_problem, FOREIGN, PlantSide,
                                               REFUSED, REPEATED, side_state_published, Tick)
from gripper_ros.nodes.gripper_node import GripperNode
from gripper_ros.nodes.loop_io import (clock_template, force_sensor_template, in_layout,
                                       joint_state_template, object_state_template,
                                       read_status, split_ns, StatusView)
from gripper_ros.nodes.object_marker import ObjectMarkerPublisher
from gripper_ros.nodes.parameters import ConfigParameters, declare_prefix
from gripper_ros.nodes.process import run_node
from gripper_ros.nodes.qos import GRAPH_QOS, SERVICE_QOS
from gripper_ros.nodes.services import DeferredService
from gripper_ros.nodes.stamps import ns_to_time
from gripper_ros.nodes.startup import StartupError
from gripper_ros.wire import (CDR_LITTLE_ENDIAN, COMMAND_LAYOUT, Controller,
                              DEFAULT_STATE_RATE_HZ, FINGER_JOINT, FORCE_SAMPLE_S, FRAME_BASE,
                              NODE_PLANT, Outcome, Phase, REPUBLISH_AFTER_S,
                              SERVICE_PAUSE, SERVICE_RESUME, SERVICE_SET_OBJECT, SERVICE_STEP,
                              TIME_MODE_CHOICES, TimeMode, TOPIC_CLOCK,
                              TOPIC_FORCE_SENSOR, TOPIC_JOINT_STATES, TOPIC_LOAD_ACCELERATION,
                              TOPIC_MOTOR_COMMAND, TOPIC_OBJECT_STATE,
                              TOPIC_PLANNED_ACCELERATION, TOPIC_SIM_STATUS, TOPIC_STATUS,
                              TOPIC_TICK)
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.clock import Clock, ClockType
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

HOUSEKEEPING_PERIOD_S = 0.05
"""Steady timer: republish a tick nobody answered, free-run without commands, sim/status."""
SIM_STATUS_PERIOD_S = 1.0
RTF_WARN_FRACTION = 0.95
"""Realtime: warn (throttled) when the achieved real-time factor falls below this x target."""
RTF_WARN_PERIOD_S = 10.0
RTF_WARN_GRACE_S = 3.0
"""No pace warning this soon after start: the first ticks wait for the peers' discovery."""
MAX_LAG_S = 0.1
"""Realtime: behind the wall clock by up to this (the process was not scheduled for a while, a
bag closed), simulated time catches up at the loop's own pace; behind by more (a real stall),
pacing starts afresh from now rather than rushing, and the achieved real-time factor shows the
loss."""
SLEEP_LIMIT_S = 0.001
"""Realtime pacing: a wait this short is slept in place; a longer one is a timer."""
STEP_BATCH = 100
"""sim/step without commands: unpowered ticks taken in one callback before yielding."""
MAX_STEP_S = 600.0
"""sim/step: the most simulated time one request may ask for (duration_s)."""
MAX_STEP_TICKS = round(MAX_STEP_S / FORCE_SAMPLE_S)
"""sim/step: the most ticks one request may ask for (MAX_STEP_S of force samples)."""


class PlantSimulatorNode(GripperNode):
    """Thin ROS wrapper around :class:`gripper_ros.core.physics.plant.GripperPlant`."""

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
        try:
            self.time_mode = TimeMode[str(mode).upper()]
        except KeyError:
            raise StartupError(f'parameter "time_mode" must be {" or ".join(TIME_MODE_CHOICES)}, '
                               f'got {mode!r}') from None
        self.real_time_factor = self._param(
            'real_time_factor', 1.0, 'realtime: simulated seconds per wall second',
            (1e-3, 100.0))
        self.state_rate_hz = self._param(
            'state_rate_hz', DEFAULT_STATE_RATE_HZ, 'rate (per simulated second) of joint_states, '
            'force_sensor, sim/object_state and /clock', (1.0, 10000.0))
        self.command_timeout_s = self._param(
            'command_timeout_s', 1.0, 'realtime: wall seconds without a command before the '
            'motor is held at 0 V and time goes on', (0.01, 600.0))
        self.publish_clock = self._param(
            'publish_clock', True, 'publish /clock (one simulator per ROS graph should)',
            read_only=True)
        self.add_post_set_parameters_callback(self._on_parameters_set)

        self.ticks_published = 0
        self.published: Counter = Counter()     # messages per (relative) topic
        self.commands_rejected = 0
        self.commands_ignored = 0               # stale, duplicate or superseded
        self._pending = False                   # a command accepted for the current tick
        self._echoed = False                    # a command was ever accepted (its echo counts)
        self.side.tick()
        self._tick_bytes = CDR_LITTLE_ENDIAN + self.side.tick_record.tobytes()
        self._stamp_ns = self.tick.stamp_ns     # the current tick's
        self._tick_wall = time.monotonic()      # when the current tick was (re)published
        self._tick_first_wall = self._tick_wall  # when it was first published
        self._woken = False                     # a request is waiting for simulated time
        self._paused = False
        self._budget: tuple[str, int] | None = None    # sim/step: ('ticks', n) or ('until', ns)
        self._step_reply = None                 # (header, response) of a running sim/step
        self._unpowered = self.time_mode is TimeMode.REALTIME   # nobody commands (yet)
        self._status: StatusView | None = None
        self._pacing = False                    # realtime: waiting for the wall clock
        self._anchor()
        self._state_period_ns = round(1e9 / self.state_rate_hz)
        self._rtf = (time.monotonic(), self.plant.t_ns, 0.0)   # window start; last achieved
        self._last_rtf_warning = time.monotonic() - RTF_WARN_PERIOD_S + RTF_WARN_GRACE_S
        self._last_sim_status = 0.0
        self._advancing = False

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
        # the simulated arm: it announces a lift asked to be announced as the hold begins
        self._plan_pub = self.create_publisher(AccelStamped, TOPIC_PLANNED_ACCELERATION,
                                               GRAPH_QOS)
        self._announce_lift = False
        self._announced_for = -1                # the grasp whose lift was announced
        self.plans_announced = 0
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
        self.get_logger().info(
            f'plant ready ({self.time_mode.name.lower()} time): travel '
            f'{self.config.plant.max_travel_m:g} m, max force {self.config.plant.max_force_n:.2f} '
            f'N at {self.config.plant.voltage_limit_v:g} V')
        self._publish_tick()
        self._publish_state()
        self._publish_sim_status()

    def _param(self, name, default, description, value_range=None, read_only=False):
        descriptor = ParameterDescriptor(description=description, read_only=read_only)
        if value_range is not None:
            descriptor.floating_point_range = [FloatingPointRange(
                from_value=value_range[0], to_value=value_range[1])]
        return self.declare_parameter(name, default, descriptor).value

    def _on_parameters_set(self, parameters) -> None:
        """Apply accepted changes from the next tick (the descriptors refuse the rest)."""
        for p in parameters:
            if p.name == 'real_time_factor':
                self.real_time_factor = float(p.value)
                self._anchor()
            elif p.name == 'state_rate_hz':
                self.state_rate_hz = float(p.value)
                self._state_period_ns = round(1e9 / self.state_rate_hz)
            elif p.name == 'command_timeout_s':
                self.command_timeout_s = float(p.value)

    @property
    def tick(self) -> Tick:
        """The current tick: its measurement, as published."""
        return Tick._make(self.side.tick_record[0].item())

    # ------------------------------------------------------------------ lockstep
    def _on_command(self, data: bytes) -> None:
        taken = self.side.take_command(data, self._pending)
        if taken == FOREIGN:                    # another encapsulation: the general way
            taken = self.side.take_command(in_layout(COMMAND_LAYOUT, data, MotorCommand),
                                           self._pending)
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
        self._pending = self._echoed = True
        self._unpowered = False
        self._announce_if_begun()
        self._try_step()

    def _announce_if_begun(self) -> None:
        """Publish the lift's plan on arm/planned_acceleration once its hold has begun."""
        begun = int(self.side.state[0]['hold_begun_for'])
        if not self._announce_lift or begun == self._announced_for or begun < 0:
            return
        self._announced_for = begun
        for t_ns, accel in self.plant.lift_plan():
            msg = AccelStamped()
            msg.header.stamp = ns_to_time(t_ns)
            msg.header.frame_id = self.frame_id
            msg.accel.linear.z = accel
            self._plan_pub.publish(msg)
        self.plans_announced += 1

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
        msg = read_status(data)
        previous, self._status = self._status, msg
        if previous is None or msg.grasp_id != previous.grasp_id:
            if msg.mass_kg > 0.0:
                self.side.grasp_mass_kg = msg.mass_kg
        if msg.active_controller == Controller.NONE and not self._pending:
            self._unpowered = True              # nobody will command: 0 V, when time runs
        if msg.pending_request:
            self._woken = True
        self._try_step()

    def _anchor(self) -> None:
        """Realtime pacing counts from here: simulated time now = wall time now."""
        self._wall_anchor = time.monotonic()
        self._sim_anchor_ns = self.plant.t_ns

    def _lead_s(self, t_next_ns: int) -> float:
        """Wall seconds until simulated time ``t_next_ns`` may be published (realtime)."""
        wall_s = time.monotonic() - self._wall_anchor
        return (t_next_ns - self._sim_anchor_ns) * 1e-9 / self.real_time_factor - wall_s

    def _try_step(self) -> None:
        """Step when the gate of the time mode is open; without a command, step unpowered.

        Unpowered steps of a sim/step come in batches of ``STEP_BATCH``, between which the
        executor serves other callbacks (a sim/pause ends the step).
        """
        batch = STEP_BATCH
        fast = self.time_mode is TimeMode.FAST
        while True:
            powered = self._pending
            if not powered and not self._unpowered:
                return
            hold_ns = round(float(self.side.command_record[0]['hold_s']) * 1e9) if powered \
                else self._state_period_ns
            if self._budget is not None:
                pass                            # sim/step: advance now, in either mode
            elif self._paused:
                return
            elif fast:
                if not (self._woken or (powered and self.side.command_needs_time())):
                    self._set_advancing(False)
                    return                      # nothing needs time: it pauses here
            else:
                lead_s = self._lead_s(self._stamp_ns + hold_ns)
                if lead_s < -MAX_LAG_S:         # fell behind (a stall): no burst to catch up
                    self._anchor()
                    lead_s = self._lead_s(self._stamp_ns + hold_ns)
                if lead_s > 0.0:
                    if lead_s > SLEEP_LIMIT_S:
                        self._wait(lead_s)
                        return
                    time.sleep(lead_s)
            self._woken = False
            self._pending = False
            if not self._advancing:
                self._set_advancing(True)
            self._stamp_ns, due = self.side.step_due() if powered else \
                self.side.step_unpowered_due(hold_ns)
            self._publish_tick()
            if due:
                self._publish_state()
            if self._budget is not None:
                self._spend_budget()
            if powered or fast:
                return                          # lockstep: the next step needs its command
            batch -= 1
            if self._budget is not None and batch <= 0:
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
        if self._pacing:
            return
        self._pacing = True
        self._pace_timer.timer_period_ns = max(1, round(lead_s * 1e9))
        self._pace_timer.reset()

    def _on_pace_timer(self) -> None:
        self._pace_timer.cancel()
        if self._pacing:
            self._pacing = False
            self._try_step()

    def _publish_tick(self) -> None:
        self._tick_bytes = CDR_LITTLE_ENDIAN + self.side.tick_record.tobytes()
        self._tick_pub.publish(self._tick_bytes)
        self._tick_wall = self._tick_first_wall = time.monotonic()
        self.ticks_published += 1
        self.published[TOPIC_TICK] += 1

    # ------------------------------------------------------------------ state topics
    def _publish_state(self) -> None:
        """joint_states, force_sensor, sim/object_state and /clock for the current tick."""
        tick = self.tick
        sec, nanosec = split_ns(tick.stamp_ns)
        side_state_published(self.side.state, self.plant.kernel, self.side.tick_record,
                             self._state_period_ns)
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
        now = time.monotonic()
        wall0, sim0, rtf = self._rtf
        elapsed = now - wall0
        if window:
            rtf = (self.plant.t_ns - sim0) * 1e-9 / elapsed if elapsed > 0.0 else 0.0
            self._rtf = (now, self.plant.t_ns, rtf)
            self._last_sim_status = now
        msg = SimStatus(time_mode=int(self.time_mode), paused=self._paused,
                        advancing=self._advancing if not window else self.plant.t_ns > sim0,
                        real_time_factor_target=self.real_time_factor
                        if self.time_mode is TimeMode.REALTIME else 0.0,
                        real_time_factor=rtf, ticks=self.ticks_published)
        msg.header.stamp = ns_to_time(self.plant.t_ns)
        self._sim_pub.publish(msg)
        self.published[TOPIC_SIM_STATUS] += 1
        if window and self.time_mode is TimeMode.REALTIME and not self._paused and \
                rtf < RTF_WARN_FRACTION * self.real_time_factor and \
                now - self._last_rtf_warning > RTF_WARN_PERIOD_S and elapsed > 0.5:
            self._last_rtf_warning = now
            self.get_logger().warning(
                f'the graph cannot keep pace: achieved real-time factor {rtf:.2f} against '
                f'{self.real_time_factor:g} over the last {elapsed:.1f} s')

    def _housekeeping(self) -> None:
        now = time.monotonic()
        if now - self._last_sim_status >= SIM_STATUS_PERIOD_S:
            self._publish_sim_status()
        if self._pending or self._paused:
            return
        if self._unpowered and self.time_mode is TimeMode.REALTIME and not self._pacing:
            self._try_step()                    # nobody commands: time goes on at 0 V
            return
        silent_s = now - self._tick_first_wall  # a republished tick is no answer
        if self.time_mode is TimeMode.REALTIME and not self._unpowered and \
                silent_s >= self.command_timeout_s:
            self._unpowered = True
            self.get_logger().error(
                f'no command for t={self._stamp_ns * 1e-9:.4f} s in {silent_s:.2f} s: '
                'motor held at 0 V, time goes on', throttle_duration_sec=5.0)
            self._try_step()
        elif now - self._tick_wall >= REPUBLISH_AFTER_S and not self._unpowered:
            self._tick_pub.publish(self._tick_bytes)      # nobody answered: a late peer
            self.published[TOPIC_TICK] += 1
            self._tick_wall = now

    # ------------------------------------------------------------------ sim services
    def _budget_done(self) -> bool:
        kind, value = self._budget
        return value <= 0 if kind == 'ticks' else self._stamp_ns >= value

    def _spend_budget(self) -> None:
        if self._budget is None:
            return
        if self._budget[0] == 'ticks':
            self._budget = ('ticks', self._budget[1] - 1)
        if self._budget_done():
            self._end_step()

    def _end_step(self, cut_short: str = '') -> None:
        """Answer the running sim/step: done, or ``cut_short`` (success false) by a pause."""
        if self._budget is None:
            return
        self._budget = None
        self._anchor()
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
        problem = ''
        if self._step_reply is not None:
            problem = 'a step is already running'
        elif not math.isfinite(duration) or duration < 0.0:
            problem = f'duration_s must be finite and >= 0, got {duration!r}'
        elif (ticks > 0) == (duration > 0.0):
            problem = f'give exactly one of ticks ({ticks}) and duration_s ({duration:g}) > 0'
        elif duration > MAX_STEP_S:
            problem = f'duration_s must be <= {MAX_STEP_S:g} s, got {duration:g}'
        elif ticks > MAX_STEP_TICKS:
            problem = f'ticks must be <= {MAX_STEP_TICKS}, got {ticks}'
        if problem:
            response.success = False
            response.message = f'refused: {problem}'
            response.time_s = self.plant.t_ns * 1e-9
            self.step_service.reply(header, response)
            return
        self._budget = ('ticks', ticks) if ticks else \
            ('until', self.plant.t_ns + round(duration * 1e9))
        self._step_reply = (header, response)
        self._try_step()

    def _on_pause(self, request, response):
        response.success = not self._paused
        response.message = f'paused at t={self.plant.t_ns * 1e-9:.6f} s' if not self._paused \
            else 'already paused'
        self._paused = True
        self._end_step('ended by sim/pause')
        self._publish_sim_status()
        return response

    def _on_resume(self, request, response):
        response.success = self._paused
        response.message = f'resumed at t={self.plant.t_ns * 1e-9:.6f} s' if self._paused \
            else 'not paused'
        self._paused = False
        self._anchor()
        self._publish_sim_status()
        self._try_step()
        return response

    @property
    def paused(self) -> bool:
        return self._paused

    @property
    def advancing(self) -> bool:
        """Fast mode: False once nothing needs simulated time (the plant waits for a request)."""
        return self._advancing

    # ------------------------------------------------------------------ simulation set-up
    def _busy_reason(self) -> str:
        """Say why the world may not be changed now ('' when it may).

        The supervisor's newest word on it counts: its status, or the echo of the last command,
        whichever is later.
        """
        echo = Command._make(self.side.command_record[0].item()) if self._echoed else None
        status = self._status
        state = echo
        if status is not None and (echo is None or (status.grasp_id, status.stage_id) >=
                                   (echo.grasp_id, echo.stage_id)):
            state = status
        if state is None:
            return ''
        if state.running or getattr(state, 'pending_request', 0):
            return 'a grasp or release is running'
        if state.phase == Phase.HOLDING and \
                state.outcome in (Outcome.HOLDING, Outcome.OVERLOADED):
            return 'an object is held (release or stop first)'
        return ''

    def _on_set_object(self, request: SetObject.Request,
                       response: SetObject.Response) -> SetObject.Response:
        self.deliver_queued()                   # the supervisor's word on what runs, as it stands
        busy = self._busy_reason()
        if busy:
            response.success = False
            response.message = f'refused: {busy}'
            return response
        try:
            obj = GraspObject(request.width_m, request.stiffness_n_per_m,
                              request.damping_n_s_per_m, request.mass_kg,
                              request.static_friction, request.kinetic_friction,
                              request.pad_length_m)
            lift = Lift(request.lift_acceleration_mps2, request.lift_delay_s,
                        request.lift_duration_s, request.lift_profile,
                        request.lift_frequency_hz, request.lift_off_s) \
                if request.lift_duration_s > 0.0 else None
            kind, tau = check_fault(request.fault, request.fault_at_s,
                                    request.fault_time_constant_s, obj.rigid)
            self.side.set_object(obj, request.open_fingers, (kind, request.fault_at_s, tau),
                                 lift=lift)
            self._announce_lift = bool(request.announce_lift) and lift is not None
            self._announced_for = int(self.side.state[0]['hold_begun_for'])
        except (ValueError, TypeError) as exc:
            response.success = False
            response.message = f'refused: {exc}'
            return response
        self.placed = (self.placed[0] + 1, {
            name: float(value) if name not in ('fault', 'lift_profile') else int(value)
            for name, value in ((n, getattr(request, n))
                                for n in request.get_fields_and_field_types())})
        self._pending = False                   # the command was for the world before
        self._stamp_ns = self.side.tick().stamp_ns
        self._publish_tick()
        self._publish_state()
        response.success = True
        response.message = (f'object width {request.width_m:g} m, contact at '
                            f'{self.plant.contact_position_m:.4f} m')
        if kind.value:
            response.message += (f'; fault {kind.name} {request.fault_at_s:g} s after the start '
                                 f'of the next grasp')
        return response


def main(args=None):
    return run_node(PlantSimulatorNode, NODE_PLANT, args)


if __name__ == '__main__':
    sys.exit(main())
