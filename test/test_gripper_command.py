"""control_msgs GripperCommand on ``gripper_action_controller/gripper_cmd``, over DDS.

Follows ros-controls/ros2_controllers (Jazzy), gripper_controllers:
``include/gripper_controllers/gripper_action_controller_impl.hpp`` (position_controllers/
GripperActionController) and ``src/gripper_action_controller_parameters.yaml``:

- ``accepted_callback``: the goal's ``command.position`` is the joint's position command and
  ``command.max_effort`` its effort; a new goal first ``preempt_active_goal``: the running one
  ends canceled, the new one is in force.
- ``check_for_success``: succeeded with ``reached_goal`` at the position; on a stall
  ``stalled``, and succeeded only with ``allow_stalling`` (default false), else aborted.
- ``cancel_callback``: accepted for the running goal, which ends canceled; the joint holds
  where it is (``set_hold_position``).

Where this gripper differs on purpose, the result says more: ``effort`` is the force the
sensor reads (the position controller reports the goal's max_effort), ``position`` the
measured joint position, and a stall is the supervisor's (at rest short of the goal, pressing
with the effort limit, or at rest for ``supervisor.move_stall_timeout_s``) rather than a speed
below ``stall_velocity_threshold`` for ``stall_timeout``. A goal the gripper cannot do (a
position outside the travel, an effort the motor cannot give) is rejected; nothing moves.

The graph is ``grasp_demo --serve``'s (realtime); the client is rclpy's ActionClient in
another node, over DDS.
"""
from __future__ import annotations

import math
import threading

from action_msgs.msg import GoalStatus
from gripper_ros.core.config import load_config
from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.wire import ACTION_GRIPPER_COMMAND, qualified, TimeMode
from helpers import wait_future
import pytest
from rclpy.action import ActionClient
from rclpy.parameter import Parameter

control_msgs = pytest.importorskip('control_msgs.action', reason='control_msgs is not '
                                   'installed (the ros-jazzy wheels have none; the overlay has)')

GripperCommand = control_msgs.GripperCommand
CONFIG = load_config()
P, S = CONFIG.plant, CONFIG.supervisor
TRAVEL_M = P.max_travel_m


@pytest.fixture(scope='module')
def graph():
    with GripperGraph.in_own_context(GraphOptions(namespace='gripper_command',
                                                  time_mode=TimeMode.REALTIME.parameter)) as g:
        yield g


@pytest.fixture(scope='module')
def client(graph):
    action = graph.run_in_executor(lambda: ActionClient(
        graph.client_node, GripperCommand, qualified(graph.namespace, ACTION_GRIPPER_COMMAND)))
    assert action.wait_for_server(timeout_sec=30.0)
    yield action
    graph.run_in_executor(action.destroy)


def _goal(position_m: float, max_effort_n: float = 0.0):
    goal = GripperCommand.Goal()
    goal.command.position = position_m
    goal.command.max_effort = max_effort_n
    return goal


def _send(graph, client, goal, allow_stalling=False, on_feedback=None):
    graph.move_action_server.set_parameters([Parameter('allow_stalling', value=allow_stalling)])
    feedback = []

    def take(msg):
        feedback.append(msg.feedback)
        if on_feedback is not None:
            on_feedback(msg.feedback)
    handle = wait_future(client.send_goal_async(goal, feedback_callback=take))
    return handle, feedback


def _run(graph, client, goal, allow_stalling=False):
    handle, feedback = _send(graph, client, goal, allow_stalling)
    assert handle.accepted
    wrapped = wait_future(handle.get_result_async())
    return wrapped.status, wrapped.result, feedback


def test_a_goal_moves_the_joint_to_its_position(graph, client):
    assert graph.set_object(0.0, open_fingers=True).success
    status, result, feedback = _run(graph, client, _goal(0.03))
    assert status == GoalStatus.STATUS_SUCCEEDED
    assert result.reached_goal and not result.stalled
    assert abs(result.position - 0.03) <= S.move_tolerance_m
    assert result.effort == 0.0                           # nothing between the fingers
    assert feedback and 0.0 <= feedback[0].position <= result.position   # on its way


def test_a_stall_on_an_object_presses_with_max_effort_and_aborts_unless_allowed(graph, client):
    assert graph.set_object(0.06, open_fingers=True).success
    face_m = TRAVEL_M - 0.06
    status, result, _ = _run(graph, client, _goal(0.14, max_effort_n=10.0))
    assert status == GoalStatus.STATUS_ABORTED                # allow_stalling false: as upstream
    assert result.stalled and not result.reached_goal
    assert result.position == pytest.approx(face_m, abs=1e-9)   # rigid: at the face
    assert S.move_stall_force_fraction * 10.0 <= result.effort <= 10.0 * (1 + 1e-9)
    status, result, _ = _run(graph, client, _goal(0.14, max_effort_n=10.0), allow_stalling=True)
    assert status == GoalStatus.STATUS_SUCCEEDED and result.stalled


def test_max_effort_zero_is_the_motors_limit(graph, client):
    """Zero max_effort, what MoveIt's GripperCommand handle sends by default: the motor's limit."""
    assert graph.set_object(0.06, open_fingers=True).success
    status, result, _ = _run(graph, client, _goal(0.14), allow_stalling=True)
    assert status == GoalStatus.STATUS_SUCCEEDED and result.stalled
    assert S.move_stall_force_fraction * P.max_force_n <= result.effort <= P.max_force_n * 1.001


def test_a_new_goal_preempts_the_running_one_which_ends_canceled(graph, client):
    assert graph.set_object(0.0, open_fingers=True).success
    moving = threading.Event()
    first, _ = _send(graph, client, _goal(0.14), on_feedback=lambda f: f.position > 0.005
                     and moving.set())
    assert first.accepted
    assert moving.wait(120.0), 'the first goal never moved'
    second, _ = _send(graph, client, _goal(0.0))
    assert second.accepted
    first_end = wait_future(first.get_result_async())
    second_end = wait_future(second.get_result_async())
    assert first_end.status == GoalStatus.STATUS_CANCELED
    assert not first_end.result.reached_goal
    assert first_end.result.position < 0.14 - 0.02            # stopped on its way
    assert second_end.status == GoalStatus.STATUS_SUCCEEDED and second_end.result.reached_goal
    assert abs(second_end.result.position) <= S.move_tolerance_m


def test_a_cancel_ends_the_goal_canceled_and_the_finger_holds(graph, client):
    assert graph.set_object(0.0, open_fingers=True).success
    moving = threading.Event()
    handle, _ = _send(graph, client, _goal(0.14), on_feedback=lambda f: f.position > 0.02
                      and moving.set())
    assert moving.wait(120.0), 'the goal never moved'
    cancel = wait_future(handle.cancel_goal_async())
    assert [bytes(g.goal_id.uuid) for g in cancel.goals_canceling] == [bytes(handle.goal_id.uuid)]
    end = wait_future(handle.get_result_async())
    assert end.status == GoalStatus.STATUS_CANCELED
    assert 0.02 < end.result.position < 0.14 - 0.02 and not end.result.reached_goal


@pytest.mark.parametrize('position_m, effort_n', [
    (-0.001, 0.0), (TRAVEL_M + 0.001, 0.0), (math.nan, 0.0), (0.05, -1.0), (0.05, math.inf),
    (0.05, P.max_force_n + 1.0)])
def test_a_goal_the_gripper_cannot_do_is_rejected_and_nothing_moves(
        graph, client, position_m, effort_n):
    requests = graph.supervisor.logic.grasp_id
    handle, _ = _send(graph, client, _goal(position_m, effort_n))
    assert not handle.accepted
    assert graph.supervisor.logic.grasp_id == requests          # no request was made
