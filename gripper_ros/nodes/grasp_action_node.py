"""grasp_action_server: the grasp as a ROS 2 action, with feedback and cancel.

A robot program that must watch a grasp (and may abort it) wants an action, as Franka's gripper
offers one beside its services. This node is a thin front end over the graph's own interfaces:
a goal becomes a ``grasp`` service call, feedback comes from
``supervisor/status`` (phase, finger position and opening, force, contact), and a cancel
calls ``stop`` so that the grasp ends as STOPPED and the goal as canceled. Every outcome
of the service (including REFUSED for a bad request or a busy gripper) is the action's result;
the goal is *succeeded* only on HOLDING, *aborted* otherwise.

Feedback is throttled to ``feedback_period_s`` of wall time (the status comes at the
supervisor's status rate of simulated time, which in fast mode is many per wall second), and
sent on every phase change.
"""
from __future__ import annotations

import sys

from gripper_interfaces.action import Grasp as GraspAction
from gripper_interfaces.msg import SupervisorStatus
from gripper_interfaces.srv import Grasp
from gripper_ros.nodes.actions import (accept_goal, cancel_by_stop, declare_feedback_period,
                                       RunningGoal)
from gripper_ros.nodes.gripper_node import GripperNode
from gripper_ros.nodes.loop_io import read_status
from gripper_ros.nodes.parameters import declare_config, follow
from gripper_ros.nodes.process import run_node
from gripper_ros.nodes.qos import SERVICE_QOS
from gripper_ros.wire import (ACTION_GRASP, NODE_GRASP_ACTION, Outcome, Phase, SERVICE_GRASP,
                              SERVICE_STOP, stamp_ns, TOPIC_STATUS)
from rclpy.action import ActionServer
from std_srvs.srv import Trigger

_REQUEST_FIELDS = ('width_m', 'mass_kg', 'friction_coefficient', 'acceleration_mps2',
                   'timeout_s', 'width_tolerance_m')
_RESULT_FIELDS = ('success', 'outcome', 'message', 'position_setpoint_m', 'force_setpoint_n',
                  'final_position_m', 'final_width_m', 'final_force_n', 'switch_time_s',
                  'grasp_id')


class GraspActionServer(GripperNode):
    def __init__(self, **kwargs):
        super().__init__(NODE_GRASP_ACTION, **kwargs)
        self.travel_m = declare_config(self).plant.max_travel_m
        self.feedback_period_s = declare_feedback_period(self)
        follow(self, {'feedback_period_s': float})      # from the next status on
        self._grasp = self.create_client(Grasp, SERVICE_GRASP, qos_profile=SERVICE_QOS)
        self._stop = self.create_client(Trigger, SERVICE_STOP, qos_profile=SERVICE_QOS)
        self.graph_subscription(SupervisorStatus, TOPIC_STATUS, self._on_status)
        self.running = RunningGoal()
        self.own(ActionServer(self, GraspAction, ACTION_GRASP, execute_callback=self._execute,
                              goal_callback=accept_goal, cancel_callback=self._on_cancel))

    # ------------------------------------------------------------------ goals
    def _on_cancel(self, goal_handle):
        """Cancel = stop the running grasp; the service then answers STOPPED."""
        return cancel_by_stop(goal_handle, self.running.handle, self._stop)

    async def _execute(self, goal_handle) -> GraspAction.Result:
        goal = goal_handle.request
        request = Grasp.Request(**{f: getattr(goal, f) for f in _REQUEST_FIELDS})
        result = GraspAction.Result()
        if not self._grasp.service_is_ready():
            result.outcome = int(Outcome.REFUSED)
            result.message = f'{SERVICE_GRASP} is not available'
            goal_handle.abort()
            return result
        if self.running.handle is not None:
            result.outcome = int(Outcome.REFUSED)
            result.message = 'refused: a grasp goal is already executing'
            goal_handle.abort()
            return result
        self.running.start(goal_handle)
        try:
            response = await self._grasp.call_async(request)
        finally:
            self.running.end()
        for f in _RESULT_FIELDS:
            setattr(result, f, getattr(response, f))
        if goal_handle.is_cancel_requested and response.outcome == Outcome.STOPPED:
            goal_handle.canceled()
        elif response.success:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        return result

    # ------------------------------------------------------------------ feedback
    def _on_status(self, data: bytes) -> None:
        running = self.running
        if running.handle is None:
            return
        msg = read_status(data)
        if not running.feedback_due(msg, (Phase.POSITION, Phase.FORCE), self.feedback_period_s):
            return
        running.handle.publish_feedback(GraspAction.Feedback(
            grasp_id=msg.grasp_id, phase=msg.phase,
            elapsed_s=(stamp_ns(msg) - running.start_ns) * 1e-9,
            position_m=msg.position_m, width_m=self.travel_m - msg.position_m,
            force_n=msg.force_n, contact=msg.contact))


def main(args=None):
    return run_node(GraspActionServer, NODE_GRASP_ACTION, args)


if __name__ == '__main__':
    sys.exit(main())
