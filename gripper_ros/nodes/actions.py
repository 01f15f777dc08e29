"""What the action servers share: every goal accepted, a running goal cancelled by a stop."""
from __future__ import annotations


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
