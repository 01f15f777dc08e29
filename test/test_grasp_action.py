"""The grasp as an action (/gripper/grasp_action): result, feedback, cancel, refusals.

A real rclpy ActionClient in its own node and thread of waiting, against the graph running under
one EventsExecutor (as in grasp_demo): real DDS, real goal/result/feedback/cancel services.
"""
import math
import threading

from action_msgs.msg import GoalStatus
from gripper_interfaces.action import Grasp as GraspAction
from gripper_interfaces.msg import SupervisorStatus
from gripper_ros.core.config import load_config
from gripper_ros.nodes.graph import GripperGraph
from gripper_ros.nodes.services import wait_until
from gripper_ros.wire import ACTION_GRASP, Outcome, Phase
from helpers import step_into_phase
import pytest
from rclpy.action import ActionClient

CONFIG = load_config()
TRAVEL_M = CONFIG.plant.max_travel_m


@pytest.fixture(scope='module')
def graph():
    with GripperGraph.in_own_context() as g:
        client = ActionClient(g.client_node, GraspAction, ACTION_GRASP)
        assert client.wait_for_server(timeout_sec=10.0)
        g.action_client = client
        yield g
        client.destroy()


def _wait(future, timeout_s=120.0):
    done = threading.Event()
    future.add_done_callback(lambda _f: done.set())
    assert done.wait(timeout_s), 'no answer in time'
    return future.result()


class Goal:
    """One goal sent through the real ActionClient, feedback collected."""

    def __init__(self, graph, width_m, mass_kg):
        self.feedback = []
        self.handle = _wait(graph.action_client.send_goal_async(
            GraspAction.Goal(width_m=width_m, mass_kg=mass_kg),
            feedback_callback=lambda m: self.feedback.append(m.feedback)))
        assert self.handle.accepted

    def result(self):
        wrapped = _wait(self.handle.get_result_async())
        return wrapped.status, wrapped.result


def test_goal_holds_the_object_with_feedback_through_both_stages(graph):
    graph.set_object(0.10)
    goal = Goal(graph, 0.10, 0.75)
    status, result = goal.result()
    assert status == GoalStatus.STATUS_SUCCEEDED
    assert result.success and result.outcome == Outcome.HOLDING
    assert result.final_width_m == pytest.approx(0.10, abs=1e-9)        # the rigid face
    sup = CONFIG.supervisor
    f_sp = sup.grip_safety_factor * 0.75 * (CONFIG.plant.gravity_mps2 + sup.acceleration_mps2) \
        / (2 * sup.friction_coefficient)
    assert result.final_force_n == pytest.approx(f_sp, rel=1e-9)
    fb = goal.feedback
    phases = [f.phase for f in fb]
    assert phases[0] == SupervisorStatus.PHASE_POSITION
    assert SupervisorStatus.PHASE_FORCE in phases
    # the stages come in order, never back
    assert phases == sorted(phases)
    assert all(f.grasp_id == result.grasp_id for f in fb)
    # feedback is consistent: opening = travel - position, simulated time runs forward
    for f in fb:
        assert f.width_m == pytest.approx(TRAVEL_M - f.position_m, abs=1e-12)
        assert math.isfinite(f.force_n)
    elapsed = [f.elapsed_s for f in fb]
    assert elapsed == sorted(elapsed) and elapsed[-1] > 1.0
    # the fingers close: the opening shrinks towards the object
    assert fb[0].width_m > fb[-1].width_m >= 0.10 * 0.98


def test_cancel_stops_the_grasp_and_the_next_goal_succeeds(graph):
    """The goal is cancelled at a known tick of the approach (paused, stepped into it)."""
    graph.set_object(0.01)                       # longest approach
    assert graph.wait_still()
    assert graph.pause().success
    try:
        goal = Goal(graph, 0.01, 1.27)
        assert wait_until(lambda: graph.supervisor.logic.pending, 10.0)
        step_into_phase(graph, Phase.POSITION, ticks_into=20)
        cancel = _wait(goal.handle.cancel_goal_async())
    finally:
        assert graph.resume().success
    assert len(cancel.goals_canceling) == 1
    status, result = goal.result()
    assert status == GoalStatus.STATUS_CANCELED
    assert result.outcome == Outcome.STOPPED and not result.success
    assert result.final_width_m > 0.01 * 1.02          # stopped before reaching the object
    graph.set_object(0.10)
    status, result = Goal(graph, 0.10, 0.75).result()
    assert status == GoalStatus.STATUS_SUCCEEDED and result.outcome == Outcome.HOLDING


@pytest.mark.parametrize('width_m, mass_kg, why', [
    (math.nan, 1.0, 'width'),
    (0.05, -1.0, 'mass'),
    (TRAVEL_M, 1.0, 'width'),
    (0.05, 1e6, 'force'),
])
def test_bad_goal_is_aborted_as_refused_with_a_reason(graph, width_m, mass_kg, why):
    ticks = graph.plant.ticks_published
    status, result = Goal(graph, width_m, mass_kg).result()
    assert status == GoalStatus.STATUS_ABORTED
    assert result.outcome == Outcome.REFUSED and not result.success
    assert why in result.message
    assert graph.plant.ticks_published == ticks          # nothing moved


def test_second_goal_while_one_runs_is_refused_as_busy(graph):
    graph.set_object(0.05)
    first = Goal(graph, 0.05, 1.69)
    second_status, second = Goal(graph, 0.05, 1.69).result()
    assert second_status == GoalStatus.STATUS_ABORTED and second.outcome == Outcome.REFUSED
    assert 'already' in second.message
    status, result = first.result()
    assert status == GoalStatus.STATUS_SUCCEEDED and result.outcome == Outcome.HOLDING
