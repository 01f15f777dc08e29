"""What the action servers share: every goal accepted, the running goal and its feedback.

A running goal is cancelled by a stop.
"""
from __future__ import annotations

import time

from gripper_ros.nodes.loop_io import StatusView
from gripper_ros.wire import stamp_ns


def accept_goal(_goal_request):
    """Accept every action goal: the supervisor decides (a refusal is a REFUSED result)."""
    from rclpy.action import GoalResponse
    return GoalResponse.ACCEPT


def cancel_by_stop(goal_handle, running_goal, stop_client):
    """Cancel the running goal by calling the supervisor's stop (its service answers STOPPED)."""
    from rclpy.action import CancelResponse
    from std_srvs.srv import Trigger
    if goal_handle is running_goal and stop_client.service_is_ready():
        stop_client.call_async(Trigger.Request())
        return CancelResponse.ACCEPT
    return CancelResponse.REJECT


def end_preempted(goal_handle) -> None:
    """End an executing goal CANCELED because a newer goal took its place.

    rclcpp_action's ``canceled()`` (what ros2_controllers' ``preempt_active_goal`` calls) passes
    an executing goal through CANCELING to CANCELED; rclpy's handle has no public step into
    CANCELING, so this makes the one rclpy's own cancel service makes.
    """
    from rclpy.action.server import GoalEvent
    if goal_handle.is_active and not goal_handle.is_cancel_requested:
        goal_handle._update_state(GoalEvent.CANCEL_GOAL)
    goal_handle.canceled()


class NewestJoint:
    """The newest joint_states sample naming one joint, kept raw and read when needed.

    joint_states remapped to a robot's ``/joint_states`` carries other joints too: a sample
    whose bytes lack the joint's name is not kept.
    """

    def __init__(self, joint_name: str):
        self.joint_name = joint_name
        self._name_bytes = joint_name.encode()
        self.data: bytes | None = None

    def keep(self, data: bytes) -> bool:
        """Keep ``data`` if it names the joint; return whether it did."""
        if self._name_bytes not in data:
            return False
        self.data = data
        return True

    def read(self):
        """Return the newest ``JointState`` and the joint's index in it; None before one."""
        if self.data is None:
            return None
        from rclpy.serialization import deserialize_message
        from sensor_msgs.msg import JointState
        msg = deserialize_message(self.data, JointState)
        names = list(msg.name)
        if self.joint_name not in names:
            return None
        return msg, names.index(self.joint_name)


def joint_velocity_mps(msg, i: int) -> float | None:
    """Return joint ``i``'s velocity in a ``JointState``; None where it carries none."""
    return float(msg.velocity[i]) if len(msg.velocity) > i else None


FEEDBACK_PERIOD_S = 0.05
"""Default of ``feedback_period_s``: feedback within a phase at most this often (wall)."""


def declare_feedback_period(node) -> float:
    """Declare ``feedback_period_s`` on an action server ``node`` and return it."""
    from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
    return node.declare_parameter('feedback_period_s', FEEDBACK_PERIOD_S, ParameterDescriptor(
        description='minimum wall seconds between two feedback messages of one phase',
        floating_point_range=[FloatingPointRange(from_value=0.0, to_value=10.0)])).value


class RunningGoal:
    """The goal an action server executes, and when its request's statuses become feedback.

    The request is the first one whose status shows one of the phases it starts in; feedback
    comes at each phase change and at most every ``period_s`` of wall time within a phase.
    """

    def __init__(self):
        self.handle = None                     # the goal handle being executed
        self.grasp_id: int | None = None       # its request, once a status showed it
        self.start_ns: int | None = None       # the simulated time that status had
        self.feedback_published = 0
        self._last_phase: int | None = None
        self._last_feedback_wall = 0.0

    def start(self, handle) -> None:
        """Execute ``handle``: its request is the next one that starts."""
        self.handle = handle
        self.grasp_id = self.start_ns = self._last_phase = None

    def end(self) -> None:
        self.handle = None

    def feedback_due(self, status: StatusView, start_phases: tuple, period_s: float) -> bool:
        """Tell whether ``status`` is feedback for the running goal now (counted when it is)."""
        goal = self.handle
        if goal is None or not goal.is_active:
            return False
        if self.grasp_id is None:
            if status.phase not in start_phases:
                return False                    # a status of an earlier request
            self.grasp_id = status.grasp_id
            self.start_ns = stamp_ns(status)
        if status.grasp_id != self.grasp_id:
            return False
        now = time.monotonic()
        if status.phase == self._last_phase and now - self._last_feedback_wall < period_s:
            return False
        self._last_phase, self._last_feedback_wall = status.phase, now
        self.feedback_published += 1
        return True
