"""control_msgs FollowJointTrajectory on ``joint_trajectory_controller/follow_joint_trajectory``.

Follows ros-controls/ros2_controllers (Jazzy), joint_trajectory_controller:
``src/joint_trajectory_controller.cpp`` (``goal_received_callback`` and
``validate_trajectory_msg``: what is rejected; ``update``: the tolerance checks, the result's
codes and strings, the hold after it; ``goal_accepted_callback`` and ``preempt_active_goal``:
a new goal aborts the running one with INVALID_GOAL; ``goal_cancelled_callback``: canceled,
hold), ``src/trajectory.cpp`` (sampling and the splines) and
``include/joint_trajectory_controller/tolerances.hpp``, for a controller of this joint with the
command interfaces position, velocity and acceleration and default parameters otherwise.

Known answers: each sample the server sends to the position servo (``servo_setpoint``, recorded
over DDS) equals the spline of the goal's points at the sample's own time, from the state the
first update measured (its first feedback): linear in position between positions only (sent
without velocity and acceleration, NaN: the servo estimates them from the samples), cubic
with velocities, quintic with accelerations (scipy's splines of the same data); the codes and
strings of JTC's source; nothing moves for a rejected goal.

The graph is ``grasp_demo --serve``'s (realtime); the client is rclpy's ActionClient in
another node, over DDS.
"""
from __future__ import annotations

import math
import re
import threading

from action_msgs.msg import GoalStatus
from builtin_interfaces.msg import Duration
from gripper_interfaces.msg import ServoSetpoint
from gripper_ros.core.config import load_config
from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.qos import GRAPH_QOS
from gripper_ros.nodes.services import wait_until
from gripper_ros.wire import (qualified, stamp_ns, TimeMode, TOPIC_JOINT_STATES,
                              TOPIC_SERVO_SETPOINT)
from helpers import trajectory_action_client, wait_future
import numpy as np
import pytest
from rclpy.qos import qos_profile_sensor_data
from scipy.interpolate import BPoly, CubicHermiteSpline
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectoryPoint

control_msgs = pytest.importorskip('control_msgs.action', reason='control_msgs is not '
                                   'installed (the ros-jazzy wheels have none; the overlay has)')
from control_msgs.msg import JointTolerance  # noqa: E402, I100 - after the skip

FollowJointTrajectory = control_msgs.FollowJointTrajectory
Result = FollowJointTrajectory.Result
CONFIG = load_config()
P, S = CONFIG.plant, CONFIG.supervisor
TRAVEL_M = P.max_travel_m
SEC = 1_000_000_000
WAIT_S = 180.0                 # wall time a goal may take on a slow machine
PREEMPTED = 'Current goal preempted by new incoming action.'


class Recorder:
    """The samples sent to the servo and the joint_states read, over DDS, with their stamps."""

    def __init__(self, graph):
        node = graph.client_node
        self.lock = threading.Lock()
        self.setpoints: list[tuple[int, float, float, float]] = []
        self.states: list[tuple[int, float, float]] = []
        self.subs = [
            node.create_subscription(ServoSetpoint, qualified(graph.namespace,
                                                              TOPIC_SERVO_SETPOINT),
                                     self._setpoint, GRAPH_QOS),
            node.create_subscription(JointState, qualified(graph.namespace, TOPIC_JOINT_STATES),
                                     self._state, qos_profile_sensor_data)]

    def _setpoint(self, msg: ServoSetpoint) -> None:
        with self.lock:
            self.setpoints.append((stamp_ns(msg.header.stamp), msg.position_m, msg.velocity_mps,
                                   msg.acceleration_mps2))

    def _state(self, msg: JointState) -> None:
        with self.lock:
            self.states.append((stamp_ns(msg.header.stamp), msg.position[0], msg.velocity[0]))

    @property
    def t_ns(self) -> int:
        with self.lock:
            return self.states[-1][0] if self.states else -1

    def clear(self) -> None:
        with self.lock:
            self.setpoints.clear()

    def sent(self) -> list:
        with self.lock:
            return list(self.setpoints)

    def state(self) -> tuple:
        with self.lock:
            return self.states[-1]


@pytest.fixture(scope='module')
def graph():
    with GripperGraph.in_own_context(GraphOptions(namespace='follow_trajectory',
                                                  time_mode=TimeMode.REALTIME.parameter)) as g:
        yield g


@pytest.fixture(scope='module')
def client(graph):
    action = trajectory_action_client(graph)
    yield action
    graph.run_in_executor(action.destroy)


@pytest.fixture(scope='module')
def recorder(graph):
    rec = graph.run_in_executor(lambda: Recorder(graph))
    assert wait_until(lambda: rec.t_ns > 0, 30.0)
    yield rec
    for sub in rec.subs:
        graph.run_in_executor(lambda s=sub: graph.client_node.destroy_subscription(s))


@pytest.fixture
def joint(graph):
    return graph.trajectory_action_server.joint_name


def _duration(t_s: float) -> Duration:
    ns = round(t_s * SEC)
    return Duration(sec=ns // SEC, nanosec=ns % SEC)


def _goal(joint, points, path_m=0.0, goal_m=0.0, goal_time_s=0.0, names=None):
    """Return a goal of ``points``: (time_from_start s, position, velocity, acceleration).

    A velocity or acceleration None is left out of its point.
    """
    goal = FollowJointTrajectory.Goal()
    goal.trajectory.joint_names = [joint] if names is None else names
    for t_s, p, v, a in points:
        point = JointTrajectoryPoint(positions=[] if p is None else [p],
                                     time_from_start=_duration(t_s))
        if v is not None:
            point.velocities = [v]
        if a is not None:
            point.accelerations = [a]
        goal.trajectory.points.append(point)
    if path_m:
        goal.path_tolerance = [JointTolerance(name=joint, position=path_m)]
    if goal_m:
        goal.goal_tolerance = [JointTolerance(name=joint, position=goal_m)]
    goal.goal_time_tolerance = _duration(goal_time_s)
    return goal


def _send(client, goal, on_feedback=None):
    feedback = []

    def take(msg):
        feedback.append(msg.feedback)
        if on_feedback is not None:
            on_feedback(msg.feedback)
    return wait_future(client.send_goal_async(goal, feedback_callback=take), WAIT_S), feedback


def _run(client, goal):
    handle, feedback = _send(client, goal)
    assert handle.accepted
    wrapped = wait_future(handle.get_result_async(), WAIT_S)
    return wrapped.status, wrapped.result, feedback


def _quiet(graph) -> None:
    """Wait until the supervisor has taken every setpoint the server sent and nothing runs.

    An ended goal's hold may still be on its way when its result is: taken later, it would
    start a move under the next test.
    """
    server, supervisor = graph.trajectory_action_server, graph.supervisor
    assert wait_until(lambda: supervisor.joint_commands_taken + supervisor.joint_commands_refused
                      >= server.setpoints_published and not supervisor.logic.running
                      and not supervisor.logic.pending, 60.0)


def _start(graph, recorder, width_m=0.0):
    """Open the fingers with an object of ``width_m`` (0: none) and forget what was sent."""
    _quiet(graph)
    assert graph.set_object(width_m, open_fingers=True).success
    recorder.clear()


def _rest(recorder, after_ns: int) -> tuple:
    """Wait until the finger rests (a sample after ``after_ns``), return that sample."""
    def resting():
        t_ns, _, v = recorder.state()
        return t_ns > after_ns and abs(v) <= S.move_rest_speed_mps
    assert wait_until(resting, WAIT_S)
    return recorder.state()


# ====================================================================== the splines, as JTC
SMOOTH = [(0.5 * k, 0.02 + 0.015 * (1.0 - math.cos(math.pi * 0.5 * k / 2.0)),
           0.015 * math.pi / 4.0 * math.sin(math.pi * 0.5 * k / 2.0),
           0.015 * (math.pi / 4.0) ** 2 * math.cos(math.pi * 0.5 * k / 2.0)) for k in range(1, 5)]
"""Knots of a half cosine from 0.0213 m up to 0.05 m over 2 s, at rest at its end."""


def _reference(kind: str, before: tuple, start_ns: int):
    """Return f(t_ns) -> (p, v, a): the spline JTC samples for ``kind`` of the SMOOTH knots.

    ``before``: (t_ns, p, v) the first update measured, where the first segment starts.
    """
    t_before, p0, v0 = before
    knots_s = [(t_before - start_ns) / SEC] + [k[0] for k in SMOOTH]
    p = [p0] + [k[1] for k in SMOOTH]
    v = [v0] + [k[2] for k in SMOOTH[:-1]] + [0.0]
    a = [0.0] + [k[3] for k in SMOOTH[:-1]] + [0.0]
    if kind == 'accelerations':
        spline = BPoly.from_derivatives(knots_s, [list(x) for x in zip(p, v, a)])
    elif kind == 'velocities':
        spline = CubicHermiteSpline(knots_s, p, v)
    else:
        def linear(t_ns):
            t_s = (t_ns - start_ns) / SEC
            i = min(int(np.searchsorted(knots_s, t_s, side='right')) - 1, len(knots_s) - 2)
            slope = (p[i + 1] - p[i]) / (knots_s[i + 1] - knots_s[i])
            return p[i] + slope * (t_s - knots_s[i]), slope, 0.0
        return linear
    return lambda t_ns: tuple(float(spline((t_ns - start_ns) / SEC, d)) for d in range(3))


def _smooth_points(kind: str) -> list:
    last = len(SMOOTH) - 1
    return [(t, p, None if kind == 'positions' else (0.0 if i == last else v),
             (0.0 if i == last else a) if kind == 'accelerations' else None)
            for i, (t, p, v, a) in enumerate(SMOOTH)]


@pytest.mark.parametrize('kind', ['positions', 'velocities', 'accelerations'])
def test_the_samples_are_jtcs_splines_of_the_points_at_their_times(
        graph, client, recorder, joint, kind):
    _start(graph, recorder)
    status, result, feedback = _run(client, _goal(joint, _smooth_points(kind)))
    assert status == GoalStatus.STATUS_SUCCEEDED
    assert (result.error_code, result.error_string) == (Result.SUCCESSFUL,
                                                        'Goal successfully reached!')
    first = feedback[0]                   # the first update: the state before the trajectory
    t_before = stamp_ns(first.header.stamp)
    start_ns = t_before - (first.desired.time_from_start.sec * SEC
                           + first.desired.time_from_start.nanosec)
    assert start_ns == t_before            # no header stamp: the trajectory starts there
    before = (t_before, first.actual.positions[0], first.actual.velocities[0])
    reference = _reference(kind, before, start_ns)
    end_ns = start_ns + round(SMOOTH[-1][0] * SEC)
    sent = [s for s in recorder.sent() if s[0] < end_ns]
    assert len(sent) >= 150                # every 10 ms over 2 s
    for t_ns, p, v, a in sent:
        want = reference(t_ns)
        if kind == 'positions':            # a straight segment's motion: the servo's estimate
            assert math.isnan(v) and math.isnan(a)
            v, a = want[1:]
        assert (p, v, a) == pytest.approx(want, abs=1e-9), (t_ns - start_ns, kind)
    at_knots = {t_ns - start_ns: p for t_ns, p, *_ in sent}
    for t_s, p, *_ in SMOOTH:             # the points at their time_from_start
        if round(t_s * SEC) in at_knots:
            assert at_knots[round(t_s * SEC)] == pytest.approx(p, abs=1e-12)
    for t_ns, *held in recorder.sent()[len(sent):]:      # from the last point's time on
        assert t_ns >= end_ns and held == pytest.approx([SMOOTH[-1][1], 0.0, 0.0], abs=1e-12)


# ====================================================================== tolerances
def test_a_path_tolerance_violated_aborts_and_the_finger_holds_where_it_was(
        graph, client, recorder, joint):
    """0 to 0.10 m in 0.5 s needs 0.2 m/s, three times the free speed: it falls behind."""
    _start(graph, recorder)
    status, result, _ = _run(client, _goal(joint, [(0.5, 0.10, 0.0, None)], path_m=0.002))
    assert status == GoalStatus.STATUS_ABORTED
    assert result.error_code == Result.PATH_TOLERANCE_VIOLATED
    assert result.error_string.startswith('Aborted due to path tolerance violation: Position '
                                          'Error: ')
    t_hold, p_hold, v_hold, a_hold = recorder.sent()[-1]
    assert (v_hold, a_hold) == (0.0, 0.0) and p_hold < 0.10 - 0.05    # held on its way
    _, p_rest, _ = _rest(recorder, t_hold)
    assert abs(p_rest - p_hold) <= 0.01    # stopping from the free speed at 24 V: 9.5 mm


def test_outside_the_goal_tolerance_after_goal_time_the_goal_aborts(
        graph, client, recorder, joint):
    """Closing onto an object at 0.09 m towards 0.12 m: blocked 30 mm short."""
    _start(graph, recorder, width_m=TRAVEL_M - 0.09)
    goal = _goal(joint, [(3.0, 0.12, 0.0, None)], goal_m=0.001, goal_time_s=0.5)
    status, result, feedback = _run(client, goal)
    assert status == GoalStatus.STATUS_ABORTED
    assert result.error_code == Result.GOAL_TOLERANCE_VIOLATED
    late_s = float(re.match(r'Aborted due to goal_time_tolerance exceeding by (\d+\.\d+) '
                            r'seconds: Position Error: 0\.03', result.error_string).group(1))
    assert 0.5 < late_s <= 0.5 + 0.0101      # at the first update past it (every 10 ms)
    assert feedback[-1].actual.positions[0] == pytest.approx(0.09, abs=1e-6)


def test_with_default_constraints_a_trajectory_stalled_on_an_object_succeeds(
        graph, client, recorder, joint):
    """By default JTC checks no position at the goal, only stopped_velocity_tolerance (0.01)."""
    _start(graph, recorder, width_m=TRAVEL_M - 0.09)
    status, result, feedback = _run(client, _goal(joint, [(3.0, 0.12, 0.0, None)]))
    assert status == GoalStatus.STATUS_SUCCEEDED and result.error_code == Result.SUCCESSFUL
    assert feedback[-1].actual.positions[0] == pytest.approx(0.09, abs=1e-6)


def test_with_no_goal_time_it_waits_for_the_goal_tolerance_until_canceled(
        graph, client, recorder, joint):
    _start(graph, recorder, width_m=TRAVEL_M - 0.09)
    handle, feedback = _send(client, _goal(joint, [(1.0, 0.12, 0.0, None)], goal_m=0.001))
    assert handle.accepted
    assert wait_until(lambda: feedback, WAIT_S)
    start_ns = stamp_ns(feedback[0].header.stamp)
    waited_ns = start_ns + 3 * SEC                   # 2 s past the last point's time
    assert wait_until(lambda: recorder.t_ns >= waited_ns, WAIT_S)
    result = handle.get_result_async()
    assert not result.done()                          # still waiting, as JTC with goal_time 0
    wait_future(handle.cancel_goal_async())
    assert wait_future(result).status == GoalStatus.STATUS_CANCELED


# ====================================================================== rejected goals
@pytest.mark.parametrize('case', ['other joint', 'two joints', 'beyond the travel', 'nan',
                                  'final velocity', 'time not increasing', 'effort',
                                  'in the past', 'no points'])
def test_a_goal_jtc_or_the_travel_refuses_is_rejected_and_nothing_moves(
        graph, client, recorder, joint, case):
    points = [(1.0, 0.05, None, None)]
    goal = _goal(joint, points)
    if case == 'other joint':
        goal = _goal(joint, points, names=['other_joint'])
    elif case == 'two joints':
        goal.trajectory.joint_names.append('other_joint')
        goal.trajectory.points[0].positions.append(0.0)
    elif case == 'beyond the travel':
        goal = _goal(joint, [(1.0, 0.05, None, None), (2.0, TRAVEL_M + 0.01, None, None)])
    elif case == 'nan':
        goal = _goal(joint, [(1.0, math.nan, None, None)])
    elif case == 'final velocity':
        goal = _goal(joint, [(1.0, 0.05, 0.01, None)])
    elif case == 'time not increasing':
        goal = _goal(joint, [(1.0, 0.05, None, None), (1.0, 0.06, None, None)])
    elif case == 'effort':
        goal.trajectory.points[0].effort = [5.0]
    elif case == 'in the past':
        now_ns = graph.trajectory_action_server.get_clock().now().nanoseconds - 10 * SEC
        goal.trajectory.header.stamp.sec, goal.trajectory.header.stamp.nanosec = divmod(
            now_ns, SEC)
    elif case == 'no points':
        goal.trajectory.points = []
    _quiet(graph)
    recorder.clear()
    requests = graph.supervisor.logic.grasp_id
    handle, _ = _send(client, goal)
    assert not handle.accepted
    assert recorder.sent() == [] and graph.supervisor.logic.grasp_id == requests


# ====================================================================== preemption and cancel
def _moving(feedback_min_m: float):
    event = threading.Event()

    def on_feedback(f):
        if f.actual.positions[0] > feedback_min_m:
            event.set()
    return event, on_feedback


def test_a_new_goal_aborts_the_running_one_with_invalid_goal(graph, client, recorder, joint):
    _start(graph, recorder)
    moving, on_feedback = _moving(0.005)
    first, _ = _send(client, _goal(joint, [(3.0, 0.14, 0.0, None)]), on_feedback)
    assert first.accepted and moving.wait(WAIT_S)
    second, _ = _send(client, _goal(joint, [(1.0, 0.02, 0.0, None)]))
    assert second.accepted
    first_end = wait_future(first.get_result_async(), WAIT_S)
    assert first_end.status == GoalStatus.STATUS_ABORTED
    assert (first_end.result.error_code, first_end.result.error_string) == (
        Result.INVALID_GOAL, PREEMPTED)
    second_end = wait_future(second.get_result_async(), WAIT_S)
    assert second_end.status == GoalStatus.STATUS_SUCCEEDED


def test_a_cancel_ends_the_goal_canceled_holding_the_measured_position(
        graph, client, recorder, joint):
    _start(graph, recorder)
    moving, on_feedback = _moving(0.02)
    handle, _ = _send(client, _goal(joint, [(3.0, 0.14, 0.0, None)]), on_feedback)
    assert handle.accepted and moving.wait(WAIT_S)
    wait_future(handle.cancel_goal_async())
    end = wait_future(handle.get_result_async(), WAIT_S)
    assert end.status == GoalStatus.STATUS_CANCELED
    assert (end.result.error_code, end.result.error_string) == (Result.SUCCESSFUL, '')
    t_hold, p_hold, v_hold, a_hold = recorder.sent()[-1]
    measured = {t: p for t, p, _ in recorder.states}
    assert p_hold == measured[t_hold] and (v_hold, a_hold) == (0.0, 0.0)


@pytest.mark.parametrize('preempted_first', [False, True])
def test_a_request_of_another_client_takes_the_gripper_and_aborts_the_goal(
        graph, client, recorder, joint, preempted_first):
    """Also when the goal took over a preempted goal's stream (the move it retargets)."""
    _start(graph, recorder)
    moving, on_feedback = _moving(0.01)
    handle, _ = _send(client, _goal(joint, [(3.0, 0.14, 0.0, None)]), on_feedback)
    assert handle.accepted and moving.wait(WAIT_S)
    if preempted_first:
        first = handle
        handle, feedback = _send(client, _goal(joint, [(3.0, 0.12, 0.0, None)]))
        assert handle.accepted and wait_until(lambda: feedback, WAIT_S)
        assert wait_future(first.get_result_async(), WAIT_S).result.error_string == PREEMPTED
    assert graph.stop().success
    end = wait_future(handle.get_result_async(), WAIT_S)
    assert end.status == GoalStatus.STATUS_ABORTED
    assert end.result.error_code == Result.INVALID_GOAL
    assert 'the gripper was taken over' in end.result.error_string
    assert 'STOPPED: stopped on request (stop)' in end.result.error_string
    sent = len(recorder.sent())
    later_ns = recorder.t_ns + SEC // 2
    assert wait_until(lambda: recorder.t_ns >= later_ns, WAIT_S)
    assert len(recorder.sent()) == sent                # it sends no more
