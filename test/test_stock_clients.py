"""ros2_control's stock clients on ``joint_commands``, emulated from their source, over DDS.

The hardware is JointStateTopicSystem (ros-controls/topic_based_hardware_interfaces,
``joint_state_topic_hardware_interface/src/joint_state_topic_hardware_interface.cpp``): at every
controller-manager update (100 Hz) ``read()`` takes the newest ``joint_states`` (SensorDataQoS)
into the state interfaces, the controller updates the command interfaces, and ``write()`` publishes
the command interfaces (position, velocity, effort, in that order of fields) on ``joint_commands``
with QoS depth 1 unless they differ from the states by at most ``trigger_joint_command_threshold``
(1e-5) in sum; a NaN command (a command interface before any controller set it) differs, so it is
published. Its header is stamped with the node's clock, ``now()``. The updates are clocked on the
``joint_states`` stamps, and so are the stamps: a controller manager on a world simulator's
``/clock``, as ``use_sim_time`` gives.

The graph is ``grasp_demo --serve``'s on that world's clock (:mod:`world_clock`, Gazebo's, here
at the wall clock's pace). A stream runs in step with the world, as gz_ros2_control runs a
controller manager (:class:`WorldInStep`): each update's command reaches the gripper before the
world's next step, so that nothing depends on the machine's speed. The controllers are
emulated from ros-controls/ros2_controllers: forward_command_controller,
joint_trajectory_controller's linear interpolation of a position-only trajectory and its
sampling of a smooth one at each update (trapezoids, sines, splines of
``studies/servo_runs.py``), parallel_gripper_action_controller's goal handling.
The plant is the paper's (J_m 0.0043 kg m^2 at the motor): its mechanical time constant of
1.13 s and free speed of 0.069 m/s at 24 V bound how fast any finger can turn or catch up a
ramp; the bounds below are computed from them.
"""
from __future__ import annotations

import math
import threading

from diagnostic_msgs.msg import DiagnosticStatus
from gripper_interfaces.msg import SupervisorStatus
from gripper_ros.core.config import load_config
from gripper_ros.nodes.qos import GRAPH_QOS, LATCHED_QOS
from gripper_ros.nodes.services import wait_until
from gripper_ros.nodes.stamps import ns_to_time
from gripper_ros.studies.servo_runs import needed_peak_v, Sine, Spline, Trapezoid
from gripper_ros.wire import (DEFAULT_NAMESPACE, FINGER_JOINT, qualified, TOPIC_GRIPPER_STATUS,
                              TOPIC_JOINT_COMMANDS, TOPIC_JOINT_STATES, TOPIC_STATUS)
from helpers import in_executor
import numpy as np
import pytest
from rclpy.qos import qos_profile_sensor_data, QoSProfile
from sensor_msgs.msg import JointState
from world_clock import following, World

CONFIG = load_config()
P = CONFIG.plant
TRAVEL_M = P.max_travel_m
UPDATE_NS = 10_000_000                   # controller_manager update_rate: 100 Hz
THRESHOLD = 1e-5                         # trigger_joint_command_threshold's default
WAIT_S = 120.0                           # wall time a step may take on a slow machine
POLL_S = 2e-4                            # in step: how often the world looks for the gripper
NAN = math.nan


@pytest.fixture(scope='module')
def world():
    """Run a world simulator's /clock at the wall clock's pace, from before the gripper starts."""
    w = World((DEFAULT_NAMESPACE,), pace=1.0)
    yield w
    w.close()


@pytest.fixture(scope='module')
def graph(world):
    """Start the graph on the world's clock, given ``use_sim_time`` as launch gives it."""
    with following() as g:
        yield g


class TopicSystem:
    """JointStateTopicSystem's read() and write() around one controller, at 100 Hz.

    Follows joint_state_topic_hardware_interface.cpp: the command interfaces start NaN (no
    controller has set them); write() sums |state - command| over the command interfaces.
    """

    def __init__(self, graph, controller, interfaces=('position',)):
        node = graph.client_node
        self.controller, self.interfaces = controller, interfaces
        self.command = dict.fromkeys(interfaces, NAN)
        self.samples: list[tuple] = []   # (t_ns, position, velocity, effort) read
        self.published: list[tuple] = []  # (t_ns, JointState) written
        self.lock = threading.Lock()
        self.done_ns = -1                # the newest sample read, its update written
        self._next_ns: int | None = None
        commands = qualified(graph.namespace, TOPIC_JOINT_COMMANDS)
        self.pub = node.create_publisher(JointState, commands, QoSProfile(depth=1))
        self.sub = node.create_subscription(JointState, qualified(graph.namespace,
                                                                  TOPIC_JOINT_STATES),
                                            self._read, qos_profile_sensor_data)
        assert wait_until(lambda: self.pub.get_subscription_count() > 0, 10.0)

    @property
    def t_ns(self) -> int:
        with self.lock:
            return self.samples[-1][0] if self.samples else -1

    def _read(self, msg: JointState) -> None:
        t_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        state = {'position': msg.position[0], 'velocity': msg.velocity[0],
                 'effort': msg.effort[0]}
        with self.lock:
            self.samples.append((t_ns, state['position'], state['velocity'], state['effort']))
        if self._next_ns is None or t_ns >= self._next_ns:
            self._next_ns = t_ns - t_ns % UPDATE_NS + UPDATE_NS
            self.command.update(self.controller.update(t_ns, state))
            self._write(t_ns, state)
        with self.lock:
            self.done_ns = t_ns

    def _write(self, t_ns: int, state: dict) -> None:
        diff = 0.0
        for name in self.interfaces:
            diff += abs(state[name] - self.command[name])
        if diff <= THRESHOLD:
            return
        msg = JointState(name=[FINGER_JOINT])
        msg.header.stamp = ns_to_time(t_ns)          # now(), on the simulated clock
        for name in self.interfaces:
            getattr(msg, name).append(self.command[name])
        self.pub.publish(msg)
        with self.lock:
            self.published.append((t_ns, msg))

    def wait_for(self, t_ns: int) -> None:
        """Wait until a joint_states sample of simulated time ``t_ns`` or later has been read."""
        assert wait_until(lambda: self.t_ns >= t_ns, WAIT_S), (self.t_ns, t_ns)

    def series(self, since_ns: int = 0) -> list[tuple]:
        with self.lock:
            return [s for s in self.samples if s[0] >= since_ns]

    def close(self, graph) -> None:
        """Stop reading and writing, in the executor's thread: no callback is left half-way."""
        def destroy():
            graph.client_node.destroy_subscription(self.sub)
            graph.client_node.destroy_publisher(self.pub)
        in_executor(graph.executor, destroy)


class WorldInStep:
    """The world steps once the gripper has the hardware's command, as gz_ros2_control runs.

    Follows gz_ros2_control_plugin.cpp: after a physics step of the control period, PostUpdate
    calls the controller manager's read() and update(), and PreUpdate its write() before the
    next step. The physics here is the gripper: the world's time stands (paused, and still
    published, as gz-sim's is) while the hardware reads the sample of that time, updates and
    writes; once the supervisor has handled what was written, the world steps one update.
    """

    def __init__(self, world: World, system: TopicSystem, supervisor):
        self.world, self.system, self.supervisor = world, system, supervisor
        self.t_ns = -1

    def start(self) -> int:
        """Pause the world, step it onto the update grid, and return that time once updated."""
        paused_ns = self.world.pause()
        self.t_ns = self.world.step(UPDATE_NS - paused_ns % UPDATE_NS)
        self.run_until(self.t_ns)
        return self.t_ns

    def run_until(self, t_ns: int) -> None:
        """Step the world until its time is ``t_ns`` or later and that update has been taken."""
        system, supervisor = self.system, self.supervisor
        while True:
            now_ns = self.t_ns
            assert wait_until(lambda: system.done_ns >= now_ns, WAIT_S, POLL_S), \
                (system.done_ns, now_ns)
            with system.lock:
                wrote = bool(system.published) and system.published[-1][0] == now_ns
            if wrote:
                assert wait_until(lambda: supervisor.joint_command_handled_ns >= now_ns,
                                  WAIT_S, POLL_S), (supervisor.joint_command_handled_ns, now_ns)
            if now_ns >= t_ns:
                return
            self.t_ns = self.world.step(UPDATE_NS)

    def stop(self) -> None:
        """Let the world run on at its pace."""
        self.world.resume()


class ForwardCommand:
    """forward_command_controller (forward_controllers_base.cpp): the newest command, held.

    Until a command comes (reset_controller_reference_msg: NaN), update() writes nothing.
    """

    def __init__(self):
        self.position = NAN

    def update(self, t_ns: int, state: dict) -> dict:
        return {} if math.isnan(self.position) else {'position': self.position}


class TrajectoryController:
    """joint_trajectory_controller with position-only points (trajectory.cpp).

    Active: holds the position it read first. A trajectory is sampled from the state read at
    the update after it came (``state_before_traj_msg_``), interpolating linearly between
    points that give positions alone; past the last point, that point is held.
    """

    def __init__(self):
        self.hold_m: float | None = None
        self.points: list[tuple[float, float]] | None = None   # (time_from_start_s, position)
        self.start: tuple[int, float] | None = None

    def send(self, points) -> None:
        self.points, self.start = list(points), None

    def update(self, t_ns: int, state: dict) -> dict:
        if self.hold_m is None:
            self.hold_m = state['position']
        if self.points is None:
            return {'position': self.hold_m}
        if self.start is None:
            self.start = (t_ns, state['position'])
        t0_ns, p0 = self.start
        t_s = (t_ns - t0_ns) * 1e-9
        before_s, before_m = 0.0, p0
        for at_s, position_m in self.points:
            if t_s < at_s:
                share = (t_s - before_s) / (at_s - before_s)
                return {'position': before_m + share * (position_m - before_m)}
            before_s, before_m = at_s, position_m
        return {'position': before_m}

    def reference(self, t_ns: int) -> float:
        """Return the position the trajectory asks for at ``t_ns`` (after it started)."""
        return self.update(t_ns, {'position': NAN})['position']


class TrajectorySampler:
    """joint_trajectory_controller following a smooth trajectory, sampled at each update.

    From the update after it came, its position at each update (trajectory.cpp's sample at the
    update's time); its end held after it. The trajectory is planned from where the finger
    stands when it starts (as a planner starts at the current state): its shape moved by the
    finger's offset from its start, within the move's tolerance.
    """

    def __init__(self):
        self.hold_m: float | None = None
        self.trajectory = None
        self.start_ns: int | None = None
        self.offset_m = 0.0

    def send(self, trajectory) -> None:
        self.trajectory, self.start_ns = trajectory, None

    def update(self, t_ns: int, state: dict) -> dict:
        if self.hold_m is None:
            self.hold_m = state['position']
        if self.trajectory is None:
            return {'position': self.hold_m}
        if self.start_ns is None:
            self.start_ns = t_ns
            self.offset_m = self.hold_m - self.trajectory.start_m
        return {'position': self.reference(t_ns)}

    def reference(self, t_ns: int) -> float:
        return float(self.trajectory.at((t_ns - self.start_ns) * 1e-9)[0]) + self.offset_m


class ParallelGripperAction:
    """parallel_gripper_action_controller (parallel_gripper_action_controller_impl.hpp).

    With ``max_velocity_interface`` and ``max_effort_interface`` set to the joint's velocity
    and effort command interfaces: on_activate() holds the position read, at the parameters'
    ``max_velocity`` and ``max_effort``; an accepted goal preempts the active one (canceled)
    and sets position, velocity and effort from its command; update() writes all three and
    checks success (``goal_tolerance``) or a stall (slower than ``stall_velocity_threshold``
    for ``stall_timeout``).
    """

    def __init__(self, max_velocity=0.1, max_effort=10.0, goal_tolerance=0.01,
                 stall_velocity_threshold=0.001, stall_timeout_s=1.0):
        self.max_velocity, self.max_effort = max_velocity, max_effort
        self.goal_tolerance = goal_tolerance
        self.stall_velocity_threshold, self.stall_timeout_s = stall_velocity_threshold, \
            stall_timeout_s
        self.command: dict | None = None
        self.goal: dict | None = None        # the active goal: its result once it ends
        self.results: list[dict] = []
        self._new: dict | None = None
        self._last_movement_ns = 0

    def send_goal(self, position_m, velocity_mps, effort_n) -> dict:
        goal = {'command': {'position': position_m, 'velocity': velocity_mps,
                            'effort': effort_n}, 'status': 'executing'}
        self._new = goal
        return goal

    def update(self, t_ns: int, state: dict) -> dict:
        if self.command is None:                              # on_activate
            self.command = {'position': state['position'], 'velocity': self.max_velocity,
                            'effort': self.max_effort}
        if self._new is not None:                             # accepted_callback
            if self.goal is not None:
                self.goal['status'] = 'canceled'              # preempt_active_goal
            self.goal, self._new = self._new, None
            self.command = dict(self.goal['command'])
            self._last_movement_ns = t_ns
        goal = self.goal
        if goal is not None:                                  # check_for_success
            error = self.command['position'] - state['position']
            if abs(error) < self.goal_tolerance:
                goal.update(status='succeeded', reached_goal=True, stalled=False,
                            position=state['position'])
                self.goal = None
            elif abs(state['velocity']) > self.stall_velocity_threshold:
                self._last_movement_ns = t_ns
            elif (t_ns - self._last_movement_ns) * 1e-9 > self.stall_timeout_s:
                goal.update(status='aborted', reached_goal=False, stalled=True,
                            position=state['position'], effort=state['effort'])
                self.goal = None
        return dict(self.command)


def _status_listener(graph):
    seen: list[DiagnosticStatus] = []
    sub = graph.client_node.create_subscription(
        DiagnosticStatus, qualified(graph.namespace, TOPIC_GRIPPER_STATUS), seen.append,
        LATCHED_QOS)
    return seen, sub


def _values(status: DiagnosticStatus) -> dict:
    return {kv.key: kv.value for kv in status.values}


def _reset(graph, object_width_m: float = 0.0) -> None:
    """Place the object (0: none) with the fingers fully open, at rest.

    A command the last test's client wrote just before it closed may still be on its way and
    start a move after a stop: that one is stopped too (a client writes nothing once closed).
    """
    for _ in range(3):
        if graph.supervisor.logic.running:      # a test that failed half-way, or a late command
            graph.stop()
        placed = graph.set_object(object_width_m, open_fingers=True)
        if placed.success:
            return
    assert placed.success, placed.message


def _reversal_s(speed_mps: float, effort_n: float) -> float:
    """Return the least time to reverse a finger moving at ``speed_mps`` under an effort limit.

    The drive against it is at most the effort's stall voltage (24 V at most), whose free
    speed is v_e. On the first-order model of the finger's speed (time constant tau_m),
    v(t) = -v_e + (v0 + v_e) exp(-t / tau_m) crosses 0 at tau_m ln((v0 + v_e) / v_e).
    """
    volts = min(P.voltage_limit_v, effort_n / P.stall_force_per_volt_n)
    v_e = P.free_speed_per_volt_mps * volts
    return P.mechanical_time_constant_s * math.log((abs(speed_mps) + v_e) / v_e)


def _farthest_m(t_s: float, speed_limit_mps: float) -> float:
    """Return the farthest a finger at rest gets in ``t_s``: 24 V until the speed limit.

    x(t) = v_max (t - tau_m (1 - exp(-t / tau_m))) until the speed v_max (1 - exp(-t /
    tau_m)) reaches the limit, at t_1 = tau_m ln(v_max / (v_max - limit)); at the limit after.
    """
    v_max, tau = P.max_free_speed_mps, P.mechanical_time_constant_s
    t_1 = tau * math.log(v_max / (v_max - speed_limit_mps))
    at = min(t_s, t_1)
    return v_max * (at - tau * (1.0 - math.exp(-at / tau))) + speed_limit_mps * (t_s - at)


def _stopping_m(speed_mps: float) -> float:
    """Return how far a finger at ``speed_mps`` runs on with 24 V against it until at rest."""
    v_max, tau = P.max_free_speed_mps, P.mechanical_time_constant_s
    t_s = _reversal_s(speed_mps, P.max_force_n)
    return -v_max * t_s + (speed_mps + v_max) * tau * (1.0 - math.exp(-t_s / tau))


def test_forward_command_controller_holds_one_position_and_an_out_of_range_one_moves_nothing(
        graph):
    """Hold one position, forward_command_controller's way; 0.38 m moves nothing.

    Follows forward_controllers_base.cpp's update() under JointStateTopicSystem, driven as the
    interface's own gripper test drives it (joint_state_topic_hardware_interface/test/gripper/
    test_gripper.cpp, which sends 0.38 m, beyond this gripper's travel). Before the first command
    the hardware publishes NaN: refused, nothing moves. One target 0.10 m from open is reached and
    held; 0.38 m is refused and the finger stays where it is.
    """
    _reset(graph)
    supervisor = graph.supervisor
    controller = ForwardCommand()
    system = TopicSystem(graph, controller)
    try:
        refused = supervisor.joint_commands_refused
        t0 = system.t_ns if system.t_ns >= 0 else 0
        system.wait_for(t0 + 20 * UPDATE_NS)               # NaN commands, 100 Hz
        # the first that reaches the supervisor (its subscription may match after the
        # hardware's publisher does) is refused
        assert wait_until(lambda: supervisor.joint_commands_refused > refused, WAIT_S)
        assert all(abs(p) < 1e-9 for _, p, _, _ in system.series()), 'NaN moved the finger'
        taken = supervisor.joint_commands_taken
        controller.position = 0.10
        start = system.t_ns
        assert wait_until(lambda: abs(system.series()[-1][1] - 0.10) <= 5e-4 and
                          abs(system.series()[-1][2]) < CONFIG.supervisor.move_rest_speed_mps,
                          WAIT_S), system.series()[-1]
        assert supervisor.joint_commands_taken == taken + 1   # its repeats are no requests
        reached = system.t_ns
        with system.lock:                # the update that read ``start`` may still be NaN's
            published = [m.position[0] for t, m in system.published if t > start]
        assert len(published) >= 10 and set(published) == {0.10}
        # the out-of-range command, published at every update: refused, nothing moves
        refused = supervisor.joint_commands_refused
        controller.position = 0.38
        t1 = system.t_ns
        system.wait_for(t1 + 50 * UPDATE_NS)
        assert supervisor.joint_commands_refused > refused
        assert supervisor.joint_commands_taken == taken + 1
        held = system.series(reached)
        assert max(abs(p - 0.10) for _, p, _, _ in held) <= 5e-4
        assert max(abs(v) for _, _, v, _ in system.series(t1)) < \
            CONFIG.supervisor.move_rest_speed_mps
    finally:
        system.close(graph)


def test_joint_trajectory_controller_ramp_is_one_move_that_follows_each_update(world, graph):
    """Follow joint_trajectory_controller's 0.04 m/s ramp as one move, in step with the world.

    Follows joint_trajectory_controller.cpp and trajectory.cpp: a position-only trajectory is
    interpolated linearly and written at every update, here a ramp for 2 s. The stream is one
    request (not a move per setpoint) that takes every command the hardware wrote: the
    supervisor's position setpoint takes each update's position, never one the trajectory has
    not reached. The finger never runs ahead of the ramp and lags it by at most 3 mm more than a
    finger at 24 V from rest, within the speed limit (the default 0.05 m/s), could. Stopped at
    0.04 m/s by the end of the ramp, it runs on at most the stopping distance at 24 V, and comes
    back to rest at the end, in the same request.
    """
    _reset(graph)
    supervisor = graph.supervisor
    controller = TrajectoryController()
    system = TopicSystem(graph, controller)
    in_step = WorldInStep(world, system, supervisor)
    setpoints: list[tuple[int, float]] = []
    status_sub = graph.client_node.create_subscription(
        SupervisorStatus, qualified(graph.namespace, TOPIC_STATUS),
        lambda m: setpoints.append((m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec,
                                    m.position_setpoint_m, m.grasp_id)), GRAPH_QOS)
    try:
        system.wait_for(max(system.t_ns, 0) + 5 * UPDATE_NS)   # active, holding
        taken = supervisor.joint_commands_taken
        ramp_mps, ramp_s, end_m = 0.04, 2.0, 0.08
        sent_ns = in_step.start()
        controller.send([(ramp_s, end_m)])
        in_step.run_until(sent_ns + UPDATE_NS)
        t0_ns, p0 = controller.start
        assert t0_ns == sent_ns + UPDATE_NS                   # the update after it came
        assert p0 == pytest.approx(0.0, abs=1e-6)
        in_step.run_until(t0_ns + round(0.05e9))
        first_id = supervisor.logic.grasp_id
        in_step.run_until(t0_ns + round(ramp_s * 1e9))
        assert supervisor.logic.grasp_id == first_id          # one move for the whole ramp
        assert supervisor.logic.kind == 'move' and supervisor.logic.servo
        with system.lock:
            written = [t for t, _ in system.published if t0_ns <= t <= t0_ns + ramp_s * 1e9]
        assert len(written) >= round(ramp_s * 1e9 / UPDATE_NS)   # a setpoint at each update
        assert supervisor.joint_commands_taken - taken == len(written)   # every one taken
        during = [(t, sp, i) for t, sp, i in list(setpoints)
                  if t0_ns + UPDATE_NS < t <= t0_ns + ramp_s * 1e9]
        assert {i for _, _, i in during} == {first_id}         # from its first setpoint on
        ramp = [(t, sp) for t, sp, _ in during]
        # the reference follows them: it changes at most updates (statuses read over DDS)
        assert len(ramp) >= 50 and len({sp for _, sp in ramp}) >= 0.5 * len(ramp)
        assert all(sp <= controller.reference(t) + 1e-12 for t, sp in ramp)
        limit_mps = CONFIG.supervisor.move_default_speed_mps
        errors = [(t - t0_ns, controller.reference(t) - p, v)
                  for t, p, v, _ in system.series(t0_ns) if t - t0_ns <= ramp_s * 1e9]
        assert all(e >= -1e-3 for _, e, _ in errors)           # never ahead of the ramp
        assert max(v for _, _, v in errors) <= limit_mps * 1.01
        late = [(dt * 1e-9, e) for dt, e, _ in errors if dt >= 0.3e9]
        least = [ramp_mps * t - _farthest_m(t, limit_mps) for t, _ in late]
        worst_t, worst = max(late, key=lambda x: x[1])
        print(f'ramp {ramp_mps} m/s from rest: worst lag after 0.3 s {worst * 1e3:.2f} mm at '
              f'{worst_t:.2f} s, {late[-1][1] * 1e3:.2f} mm at its end; 24 V from rest within '
              f'{limit_mps} m/s lags {max(least) * 1e3:.2f} and {least[-1] * 1e3:.2f} mm at best')
        assert all(e <= bound + 3e-3 for (_, e), bound in zip(late, least))
        # the end held: the finger reaches it within the move's tolerance, one move still
        settle_ns = in_step.t_ns + round(10e9)
        while supervisor.logic.outcome.name != 'MOVED' and in_step.t_ns < settle_ns:
            in_step.run_until(in_step.t_ns + UPDATE_NS)
        assert supervisor.logic.outcome.name == 'MOVED', supervisor.logic.message
        assert supervisor.logic.grasp_id == first_id
        overshoot = max(p for _, p, _, _ in system.series(t0_ns)) - end_m
        print(f'runs on {overshoot * 1e3:.2f} mm past the end; stopping at 24 V from '
              f'{ramp_mps} m/s takes {_stopping_m(ramp_mps) * 1e3:.2f} mm')
        assert overshoot <= _stopping_m(limit_mps)
        assert system.series()[-1][1] == pytest.approx(
            end_m, abs=CONFIG.supervisor.move_tolerance_m)
    finally:
        in_step.stop()
        graph.client_node.destroy_subscription(status_sub)
        system.close(graph)


STREAMS = {
    'trapezoid': Trapezoid(0.01, 0.14, 0.036, 0.015),
    'sine': Sine(0.075, 0.06, 9.0),
    'spline': Spline(((0.0, 0.02), (4.0, 0.08), (6.0, 0.07), (10.0, 0.135), (14.0, 0.02))),
}


@pytest.mark.parametrize('name', sorted(STREAMS))
def test_joint_trajectory_controller_streams_within_80_percent_of_24_v_are_tracked_within_1_mm(
        world, graph, name):
    """Track a trapezoid, a sine and a spline across the travel within 1 mm, as one move.

    Each needs at most 80 % of the voltage limit at any instant (its feed-forward's peak,
    ``k_v v + k_a a``). joint_trajectory_controller (trajectory.cpp) samples it at each 100 Hz
    update and JointStateTopicSystem publishes the positions alone, stamped, in step with the
    world; the finger, moved to its start first, is held to the trajectory at every
    joint_states sample. One move follows it until its last moments: the hardware falls silent
    once the finger is within its threshold of the slowing command, the move ends MOVED at
    rest there, and the hardware's next command is a new move.
    """
    trajectory = STREAMS[name]
    needed_v = needed_peak_v(CONFIG, trajectory)
    assert needed_v <= 0.8 * P.voltage_limit_v
    _reset(graph)
    moved = graph.move(TRAVEL_M - trajectory.start_m, 0.05)
    assert moved.reached_goal, moved.message
    supervisor = graph.supervisor
    controller = TrajectorySampler()
    system = TopicSystem(graph, controller)
    in_step = WorldInStep(world, system, supervisor)
    try:
        system.wait_for(max(system.t_ns, 0) + 5 * UPDATE_NS)
        sent_ns = in_step.start()
        controller.send(trajectory)
        in_step.run_until(sent_ns + UPDATE_NS)
        start_ns = controller.start_ns
        assert start_ns == sent_ns + UPDATE_NS              # the update after it came
        in_step.run_until(start_ns + round(0.05e9))
        first_id = supervisor.logic.grasp_id
        last_moments_s = CONFIG.supervisor.servo_rate_window_s + 0.1
        in_step.run_until(start_ns + round((trajectory.duration_s - last_moments_s) * 1e9))
        assert supervisor.logic.grasp_id == first_id        # one move for the stream
        in_step.run_until(start_ns + round(trajectory.duration_s * 1e9))
        errors = np.array([controller.reference(t) - p for t, p, _, _ in system.series(start_ns)
                           if t - start_ns <= trajectory.duration_s * 1e9])
        worst = np.max(np.abs(errors))
        print(f'{trajectory.name}: needs {needed_v:.2f} V of {P.voltage_limit_v:g} V, '
              f'{errors.size} joint_states samples, worst error {worst * 1e3:.3f} mm')
        assert errors.size == round(trajectory.duration_s * 100) + 1   # every update's sample
        assert worst <= 1e-3
    finally:
        in_step.stop()
        system.close(graph)


def test_parallel_gripper_action_controller_presses_with_its_effort_and_a_new_goal_preempts(
        world, graph):
    """Press with parallel_gripper_action_controller's effort; a new goal turns the finger.

    Follows parallel_gripper_action_controller_impl.hpp: goal position with max_effort and
    max_velocity on the joint's effort and velocity command interfaces, written at every
    update. On an object the finger presses with at most the goal's effort (joint_states'
    effort), the controller sees the stall, gripper_status says stalled and object_detected.
    Then a goal closing at 0.05 m/s is preempted 0.3 s in by one opening, in step with the world
    (:class:`WorldInStep`): the finger slows within 0.1 s and reverses within 0.1 s of the least
    time the effort's voltage (10 N: 7.2 V) takes to reverse it.
    """
    object_width_m, effort_n = 0.06, 10.0
    _reset(graph, object_width_m)
    face_m = TRAVEL_M - object_width_m
    controller = ParallelGripperAction(max_velocity=0.1, max_effort=effort_n)
    system = TopicSystem(graph, controller, ('position', 'velocity', 'effort'))
    seen, status_sub = _status_listener(graph)
    in_step = WorldInStep(world, system, graph.supervisor)
    try:
        system.wait_for(max(system.t_ns, 0) + 5 * UPDATE_NS)
        press = controller.send_goal(0.14, 0.05, effort_n)   # past the object's face
        assert wait_until(lambda: press['status'] != 'executing', WAIT_S), press
        assert press['status'] == 'aborted' and press['stalled'], press   # allow_stalling false
        assert press['position'] == pytest.approx(face_m, abs=1e-4)
        efforts = [e for _, _, _, e in system.series()]
        assert max(efforts) <= effort_n * 1.05, max(efforts)
        assert system.series()[-1][3] >= 0.9 * effort_n
        assert wait_until(lambda: seen and _values(seen[-1])['outcome'] == 'STALLED', 10.0), \
            [s.message for s in seen]
        assert _values(seen[-1])['object_detected'] == 'true'
        # preemption, with nothing in the way
        _reset(graph)
        open_goal = controller.send_goal(0.04, 0.05, effort_n)
        assert wait_until(lambda: open_goal['status'] == 'succeeded', WAIT_S), open_goal
        t_sent = in_step.start()
        closing = controller.send_goal(0.14, 0.05, effort_n)
        in_step.run_until(t_sent + UPDATE_NS)
        assert controller.goal is closing                     # taken at the next update
        in_step.run_until(t_sent + UPDATE_NS + round(0.3e9))
        t_sent = in_step.t_ns
        opening = controller.send_goal(0.02, 0.05, effort_n)
        in_step.run_until(t_sent + UPDATE_NS)
        assert controller.goal is opening and closing['status'] == 'canceled'
        with system.lock:
            t_preempt = next(t for t, m in system.published if m.position[0] == 0.02)
        assert t_preempt == t_sent + UPDATE_NS
        in_step.run_until(t_preempt + round(1.0e9))
        in_step.stop()
        after = system.series(t_preempt)
        v0 = after[0][2]
        assert v0 > 0.005, v0                                  # it was closing
        peak_ns = max(after, key=lambda s: s[2])[0]
        assert peak_ns - t_preempt <= 0.1e9, (peak_ns - t_preempt) * 1e-9   # slows at once
        turn_ns = next(t for t, _, v, _ in after if v < 0.0)
        turn_s = (turn_ns - t_preempt) * 1e-9
        print(f'preempted at {v0:.4f} m/s: slowing after {(peak_ns - t_preempt) * 1e-9:.3f} s, '
              f'reversed after {turn_s:.3f} s ({_reversal_s(v0, effort_n):.3f} s at best)')
        assert turn_s <= _reversal_s(v0, effort_n) + 0.1
        assert wait_until(lambda: opening['status'] == 'succeeded', WAIT_S), opening
    finally:
        in_step.stop()
        graph.client_node.destroy_subscription(status_sub)
        system.close(graph)
